"""glTF 2.0 (``.gltf`` and ``.glb``): one mesh per primitive, the first
perspective camera."""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import trimesh

from ._common import MeshData, Notes, SceneData, clamp_albedo
from ._limits import RefusedError
from ._paths import FileAccess
from .gltf_document import check_document, read_document
from .textures import image_mean

__all__ = ["load_gltf"]


def _gltf_node_matrix(node: dict, where: str) -> np.ndarray:
    if "matrix" in node:
        m = np.asarray(node["matrix"], np.float64)
        if m.shape != (16,):
            raise ValueError(f"{where}: 'matrix' needs 16 numbers")
        return m.reshape(4, 4).T  # column-major
    t = np.asarray(node.get("translation", [0, 0, 0]), np.float64)
    q = np.asarray(node.get("rotation", [0, 0, 0, 1]), np.float64)  # x, y, z, w
    s = np.asarray(node.get("scale", [1, 1, 1]), np.float64)
    if t.shape != (3,) or q.shape != (4,) or s.shape != (3,):
        raise ValueError(f"{where}: translation/rotation/scale have the wrong length")
    r = trimesh.transformations.quaternion_matrix([q[3], q[0], q[1], q[2]])
    return trimesh.transformations.translation_matrix(t) @ r @ np.diag([*s, 1.0])


def _gltf_camera(doc: dict, path: Path) -> dict | None:
    """Camera keyword arguments of the first node holding a perspective camera."""
    nodes = doc.get("nodes", [])
    parents = {c: i for i, n in enumerate(nodes) for c in n.get("children", [])}
    for i, node in enumerate(nodes):
        if "camera" not in node:
            continue
        cam = doc["cameras"][node["camera"]]  # (indices checked by check_document)
        if cam.get("type") != "perspective":
            continue
        persp = cam.get("perspective", {})
        yfov = persp["yfov"]
        m, j = np.eye(4), i
        while j is not None:
            m = _gltf_node_matrix(nodes[j], f"scene file {path}: /nodes/{j}") @ m
            j = parents.get(j)
        aspect = float(persp.get("aspectRatio", 1.0))
        height = 512
        # glTF cameras look down -z with +y up.
        eye = m[:3, 3]
        fwd = -m[:3, 2] / np.linalg.norm(m[:3, 2])
        return {
            "eye": tuple(eye.tolist()),
            "target": tuple((eye + fwd).tolist()),
            "up": tuple(m[:3, 1].tolist()),
            "fov": math.degrees(yfov),
            "width": max(1, round(height * aspect)),
            "height": height,
        }
    return None


def _gltf_material(m: dict | None, tm, where: str, path: Path, notes: Notes, doc=None):
    """(albedo, emission, two_sided, texture or None) of a primitive: its glTF
    material ``m`` when its name is unique, else trimesh's reading ``tm`` of it."""
    if m is not None:
        pbr = m.get("pbrMetallicRoughness", {})
        base = np.asarray(pbr.get("baseColorFactor", [1, 1, 1, 1]), np.float64)[:3]
        emission = np.asarray(m.get("emissiveFactor", [0, 0, 0]), np.float64)
        strength = m.get("extensions", {}).get("KHR_materials_emissive_strength", {})
        emission = emission * float(strength.get("emissiveStrength", 1.0))
        two_sided = bool(m.get("doubleSided", False))
        if "metallicRoughnessTexture" in pbr:
            notes.approx(f"{where}: metallicRoughnessTexture read as its factors")
        extra = sorted(
            {*m.get("extensions", {}), "emissiveTexture" in m and "emissiveTexture"}
            - {"KHR_materials_emissive_strength", False}
        )
        if extra:
            notes.approx(f"{where}: {', '.join(extra)} left out")
        if (
            base.shape != (3,)
            or emission.shape != (3,)
            or not np.all(np.isfinite(np.r_[base, emission]))
        ):
            raise ValueError(f"scene file {path}: {where}: bad baseColorFactor or emissiveFactor")
        has_texture = "baseColorTexture" in pbr
    elif tm is not None and hasattr(tm, "baseColorFactor"):
        # materials without a unique name: trimesh's (8-bit) factors
        base = (
            np.asarray(
                tm.baseColorFactor if tm.baseColorFactor is not None else [255] * 4, np.float64
            )[:3]
            / 255
        )
        emission = np.asarray(
            tm.emissiveFactor if tm.emissiveFactor is not None else [0, 0, 0], np.float64
        )
        two_sided = bool(tm.doubleSided)
        has_texture = tm.baseColorTexture is not None
    else:
        base, emission, two_sided, has_texture = np.ones(3), np.zeros(3), False, False
    texture = None
    if has_texture:
        image = getattr(tm, "baseColorTexture", None)
        if image is not None and m is not None and doc is not None:
            texture = _base_color_texture(m, image, base, doc, where, notes)
        if texture is not None:
            base = texture.mean()
        elif image is not None:
            base = base * image_mean(image)
            notes.approx(f"{where}: baseColorTexture reduced to its mean colour")
        else:
            notes.approx(f"{where}: baseColorTexture unreadable: factor 1")
    return base, emission, two_sided, texture


def gltf_lobe(m: dict | None, base, where: str, notes: Notes):
    """The microfacet lobe of a glTF metallic-roughness material (None for a
    material voxgi reads only through trimesh): alpha = roughness², a metal
    (metallic >= 0.5) a conductor whose normal reflectance is the base colour,
    a dielectric a plastic coat of index 1.5 over it (docs/design.md §14)."""
    if m is None:
        return None
    from ..microfacet import Microfacet

    pbr = m.get("pbrMetallicRoughness", {})
    metallic = float(pbr.get("metallicFactor", 1.0))
    if "metallicFactor" not in pbr:
        # glTF's default is 1, a metal; exporters that leave it out mostly
        # mean a dielectric (a textured asset would lose its texture)
        notes.approx(f"{where}: no metallicFactor (glTF's default 1, a metal) read as 0")
        metallic = 0.0
    roughness = float(pbr.get("roughnessFactor", 1.0))
    if not (0.0 <= metallic <= 1.0 and 0.0 <= roughness <= 1.0):
        raise ValueError(f"{where}: metallicFactor or roughnessFactor outside [0, 1]")
    alpha = max(roughness * roughness, 1e-4)
    if metallic >= 0.5:
        # F0 = k² / (4 + k²) at eta 1: k from the base colour
        f0 = np.clip(np.asarray(base, np.float64), 0.0, 0.999)
        k = 2.0 * np.sqrt(f0 / (1.0 - f0))
        notes.approx(
            f"{where}: metallic {metallic:g} as a GGX conductor of alpha roughness² "
            f"{alpha:.3g} whose normal reflectance is the base colour (eta 1)"
        )
        return Microfacet("conductor", alpha=alpha, eta=(1.0, 1.0, 1.0), k=k)
    if metallic > 0.0:
        notes.approx(f"{where}: metallic {metallic:g} read as 0 (a dielectric)")
    notes.approx(
        f"{where}: a dielectric as a GGX plastic coat of index 1.5 and alpha roughness² "
        f"{alpha:.3g} over the base colour"
    )
    return Microfacet("plastic", alpha=alpha, ior=1.5)


#: glTF sampler codes: magFilter, and wrapS / wrapT.
_GL_FILTER = {9728: "nearest", 9729: "bilinear"}
_GL_WRAP = {10497: "repeat", 33648: "mirror", 33071: "clamp"}


def _base_color_texture(m: dict, image, base, doc: dict, where: str, notes: Notes):
    """The Texture of a material's ``baseColorTexture`` (its sampler's filter
    and wrap, times baseColorFactor), or None where voxgi reads only its
    mean (another texCoord set than 0, a texture transform)."""
    from ..textures import Texture

    ref = m["pbrMetallicRoughness"]["baseColorTexture"]
    if ref.get("texCoord", 0) != 0 or "KHR_texture_transform" in ref.get("extensions", {}):
        return None
    tex = doc.get("textures", [])[ref["index"]]
    sampler = doc.get("samplers", [])[tex["sampler"]] if "sampler" in tex else {}
    filt = _GL_FILTER.get(sampler.get("magFilter"), "bilinear")
    ws, wt = sampler.get("wrapS", 10497), sampler.get("wrapT", 10497)
    if ws != wt:
        notes.approx(f"{where}: wrapT {wt} read as wrapS {ws}")
    texels = np.asarray(image.convert("RGB"), np.uint8)
    return Texture(texels, filter=filt, wrap=_GL_WRAP.get(ws, "repeat"), factor=np.minimum(base, 1))


def load_gltf(path, *, search_paths=(), allow_outside=False, limits=None) -> SceneData:
    """Read a glTF 2.0 scene (``.gltf`` or ``.glb``): one mesh per primitive.

    The albedo is ``baseColorFactor`` times ``baseColorTexture`` looked up by
    ``TEXCOORD_0`` with its sampler's filter and wrap (its mean colour for
    another texture coordinate set or a texture transform), the radiance ``emissiveFactor`` times
    ``KHR_materials_emissive_strength``; ``doubleSided`` gives a two-sided
    surface; node transforms are applied; the first perspective camera
    (``yfov``, ``aspectRatio``, 512 pixels high) becomes the camera.

    Parameters
    ----------
    path : str or Path
    search_paths, allow_outside, limits
        As :meth:`voxgi.Scene.load` (docs/scene-files.md).

    Raises
    ------
    FileNotFoundError, ValueError
        As :func:`load_mitsuba`, naming the file and the glTF element by its
        JSON pointer (``/materials/0/extensions``).
    """
    path = Path(path)
    access = FileAccess(path, search_paths, allow_outside, limits)
    doc, buf, binary = read_document(path, access)
    check_document(doc, path, access, binary)
    notes = Notes(path)
    by_name: dict[str, list] = {}
    for k, m in enumerate(doc.get("materials", [])):
        by_name.setdefault(m.get("name", f"material{k}"), []).append(m)
    try:
        loaded = trimesh.load(
            io.BytesIO(buf),
            file_type=path.suffix.lower()[1:],
            resolver=access.resolver(path.parent, "file named by a glTF"),
            force="scene",
            process=False,
        )
        geoms = loaded.dump()
    except RefusedError:
        raise
    except Exception as exc:
        raise ValueError(f"scene file {path}: malformed glTF: {exc}") from None
    data = SceneData(camera=_gltf_camera(doc, path))
    lights = doc.get("extensions", {}).get("KHR_lights_punctual", {}).get("lights", [])
    for k, light in enumerate(lights):
        # (where punctual lights would become voxgi lights)
        notes.drop(f"KHR_lights_punctual light {k} ({light.get('type', '?')})")
    for k, g in enumerate(geoms):
        if not isinstance(g, trimesh.Trimesh) or len(g.faces) == 0:
            continue
        tm = getattr(g.visual, "material", None)
        mname = getattr(tm, "name", None)
        found = by_name.get(mname, [])
        m = found[0] if len(found) == 1 else None
        where = f"material {mname!r}"
        base, emission, two_sided, texture = _gltf_material(m, tm, where, path, notes, doc)
        base = clamp_albedo(base, where, notes)
        lobe = gltf_lobe(m, base, where, notes)
        if lobe is not None and lobe.kind == "conductor":
            texture = None  # (a metal's base colour is its specular reflectance: its mean)
        uv = getattr(g.visual, "uv", None) if texture is not None else None
        if texture is not None and (uv is None or len(uv) != len(g.vertices)):
            notes.approx(f"{where}: no TEXCOORD_0, baseColorTexture reduced to its mean colour")
            texture, uv = None, None
        if uv is not None:
            uv = np.array(uv, np.float64)
            uv[:, 1] = 1.0 - uv[:, 1]  # (trimesh turns glTF's v; glTF's is voxgi's)
        name = str(g.metadata.get("name") or mname or f"primitive{k}")
        data.meshes.append(
            MeshData(
                name,
                np.asarray(g.vertices, np.float64),
                np.asarray(g.faces, np.int64),
                base,
                emission,
                two_sided,
                str(path),
                texture=texture,
                uv=uv,
                specular=lobe,
            )
        )
    if not data.meshes:
        raise ValueError(f"scene file {path}: the glTF holds no triangles")
    notes.emit()
    return data
