"""Writing voxgi's TOML scene files (:meth:`voxgi.Scene.save`)."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from ..camera import Camera
from ..io import atomic_path
from ..lights import DirectionalLight, Environment, PointLight, SpotLight
from ..microfacet import Microfacet

__all__ = ["save_toml"]

#: The ``[[light]]`` types and the class of each.
LIGHT_TYPES = {"point": PointLight, "spot": SpotLight, "directional": DirectionalLight}


def save_toml(scene, path: Path) -> Path:
    """Write ``scene`` as a TOML file with one OBJ file per object beside it
    (:meth:`voxgi.Scene.save`)."""
    import tomli_w  # (writes any name as valid TOML: control characters escaped)

    path.parent.mkdir(parents=True, exist_ok=True)
    doc: dict = {}
    if scene.camera is not None:
        doc["camera"] = _camera_to_dict(scene.camera)
    objects = []
    images: dict[int, str] = {}  # texture id -> its file beside the scene file
    for i, o in enumerate(scene.objects):
        fname = f"{path.stem}_{i:03d}.obj"
        tex = o.material.texture
        with atomic_path(path.parent / fname) as tmp:
            tmp.write_text(_obj_text(o.vertices, o.faces, o.uv if tex is not None else None))
        entry = _object_to_dict(o, fname)
        if tex is not None:
            if id(tex) not in images:
                images[id(tex)] = _write_texture_image(tex, path, len(images))
            entry["texture"] = _texture_to_dict(tex, images[id(tex)])
        objects.append(entry)
    if objects:
        doc["object"] = objects
    if scene.lights:
        doc["light"] = [_light_to_dict(light) for light in scene.lights]
    if scene.environment is not None:
        doc["environment"] = _environment_to_dict(scene.environment, path)
    text = tomli_w.dumps(doc)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


def _camera_to_dict(c: Camera) -> dict:
    out: dict = {f: [float(x) for x in getattr(c, f)] for f in ("eye", "target", "up")}
    out.update(fov=float(c.fov), aperture=float(c.aperture), width=c.width, height=c.height)
    if c.focus_distance is not None:
        out["focus_distance"] = float(c.focus_distance)
    if c.pixel_filter != "box":
        out["pixel_filter"] = c.pixel_filter
    return out


def _object_to_dict(o, fname: str) -> dict:
    entry = {
        "name": o.name,
        "mesh": fname,
        "albedo": [float(x) for x in o.material.albedo],
        "emission": [float(x) for x in o.material.emission],
        "two_sided": bool(o.two_sided),
    }
    if o.material.is_sheet:
        entry["transmittance"] = [float(x) for x in o.material.transmittance]
    spec = o.material.specular
    if isinstance(spec, Microfacet):
        entry["specular"] = {
            "type": "rough" + spec.kind,
            "alpha": float(spec.alpha),
            "distribution": spec.distribution,
            "specular_reflectance": [float(x) for x in spec.specular_reflectance],
        }
        if spec.kind == "plastic":
            entry["specular"].update(int_ior=float(spec.ior), nonlinear=spec.nonlinear)
        else:
            entry["specular"].update(eta=[float(x) for x in spec.eta], k=[float(x) for x in spec.k])
    elif spec is not None:
        entry["specular"] = {
            "rs": [float(x) for x in spec.rs],
            "nu": float(spec.nu),
            "nv": float(spec.nv),
        }
    return entry


def _obj_text(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray | None = None) -> str:
    """OBJ text of a mesh, every float with 17 significant digits, with its
    UVs as ``vt`` (v turned to the OBJ's convention, 0 at the image's bottom).

    ``%.17g`` reads back as the same float64 at any magnitude (a fixed
    number of decimals would not, below 0.1).
    """
    buf = io.StringIO()
    np.savetxt(buf, vertices, fmt="v %.17g %.17g %.17g")
    if uv is None:
        np.savetxt(buf, faces + 1, fmt="f %d %d %d")
    else:
        np.savetxt(buf, np.stack([uv[:, 0], 1.0 - uv[:, 1]], 1), fmt="vt %.17g %.17g")
        np.savetxt(buf, np.repeat(faces + 1, 2, axis=1), fmt="f %d/%d %d/%d %d/%d")
    return buf.getvalue()


def _write_texture_image(tex, path: Path, k: int) -> str:
    """A texture's image beside the scene file: a copy of the file it was read
    from (the same bytes another renderer reads), else its texels as PNG."""
    src = Path(tex.path) if tex.path else None
    if src is not None and src.is_file():
        fname = f"{path.stem}_texture{k:02d}_{src.name}"
        with atomic_path(path.parent / fname) as tmp:
            tmp.write_bytes(src.read_bytes())
        return fname
    from PIL import Image

    fname = f"{path.stem}_texture{k:02d}.png"
    with atomic_path(path.parent / fname) as tmp:
        Image.fromarray(tex.texels).save(tmp, format="PNG")
    return fname


def _texture_to_dict(tex, fname: str) -> dict:
    out = {"file": fname, "filter": tex.filter, "wrap": tex.wrap}
    if not np.array_equal(tex.to_uv, np.eye(3)):
        out["to_uv"] = [[float(x) for x in row] for row in tex.to_uv]
    if tex.raw:
        out["raw"] = True
    if tex.factor != (1.0, 1.0, 1.0):
        out["factor"] = [float(x) for x in tex.factor]
    return out


def _light_to_dict(light) -> dict:
    kind = next(k for k, c in LIGHT_TYPES.items() if isinstance(light, c))
    out: dict = {"type": kind}
    for name in light.__dataclass_fields__:
        v = getattr(light, name)
        out[name] = [float(x) for x in v] if isinstance(v, tuple) else float(v)
    return out


def _environment_to_dict(env: Environment, path: Path) -> dict:
    """An ``[environment]`` table; an image is written as an EXR beside the scene file."""
    out: dict = {}
    if env.constant is not None and env.image.shape[:2] == (1, 1):
        out["radiance"] = [float(x) for x in env.image[0, 0]]
    else:
        from ..io import write_exr

        fname = f"{path.stem}_environment.exr"
        write_exr(path.parent / fname, env.image.astype(np.float32))
        out["image"] = fname
    if not np.array_equal(env.to_world, np.eye(3)):
        out["to_world"] = [[float(x) for x in row] for row in env.to_world]
    return out
