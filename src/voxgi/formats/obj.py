"""Wavefront OBJ with its MTL materials: one mesh per material."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import trimesh

from ._common import MeshData, Notes, SceneData, clamp_albedo, load_trimesh
from ._limits import RefusedError
from ._paths import FileAccess
from .textures import decode_rgb, texture_mean

__all__ = ["load_obj"]


def _phong_lobe(m: dict, what: str, notes: Notes):
    """The microfacet lobe standing for an MTL material's Phong highlight
    (``Ks``, exponent ``Ns``), or None without one (docs/design.md §14)."""
    ks = np.asarray(m.get("Ks", np.zeros(3)), np.float64)
    if not np.any(ks > 0):
        return None
    from ..microfacet import Microfacet

    ns = float(m.get("Ns", 0.0))
    alpha = float(np.clip(math.sqrt(2.0 / (ns + 2.0)), 1e-4, 1.0))
    notes.approx(
        f"{what}: its Phong highlight (Ks, Ns {ns:g}) as a GGX plastic coat of alpha "
        f"sqrt(2 / (Ns + 2)) = {alpha:.3g}, index 1.5, specular_reflectance Ks"
    )
    return Microfacet("plastic", alpha=alpha, ior=1.5, specular_reflectance=np.minimum(ks, 1.0))


def _parse_mtl(path: Path, text: str) -> dict[str, dict]:
    """``{material: {"Kd": (3,), "Ke": (3,), "Ks": (3,), "Ns": float, "map_Kd": Path}}``
    of an MTL file's text."""
    mats: dict[str, dict] = {}
    cur = None
    for k, line in enumerate(text.splitlines(), 1):
        parts = line.split("#", 1)[0].split()
        if not parts:
            continue
        key = parts[0]
        if key == "newmtl":
            cur = mats.setdefault(" ".join(parts[1:]), {})
        elif cur is None:
            continue
        elif key == "Ns":
            try:
                ns = float(parts[1])
            except (IndexError, ValueError):
                raise ValueError(f"{path}: line {k}: Ns: not a number: {line.strip()!r}") from None
            if not (np.isfinite(ns) and ns >= 0):
                raise ValueError(f"{path}: line {k}: Ns: expected a number >= 0: {line.strip()!r}")
            cur["Ns"] = ns
        elif key in ("Kd", "Ke", "Ks"):
            try:
                c = np.array([float(x) for x in parts[1:4]], np.float64)
            except ValueError:
                raise ValueError(
                    f"{path}: line {k}: {key}: not numbers: {line.strip()!r}"
                ) from None
            if c.size == 1:
                c = np.repeat(c, 3)
            if c.shape != (3,) or not np.all(np.isfinite(c)) or np.any(c < 0):
                raise ValueError(
                    f"{path}: line {k}: {key}: expected 3 numbers >= 0: {line.strip()!r}"
                )
            cur[key] = c
        elif key == "map_Kd":
            cur["map_Kd"] = path.parent / parts[-1]
    return mats


def _absolute_obj_indices(text: str) -> str:
    """OBJ text with relative (negative) face indices made absolute.

    In OBJ, ``f -4 -3 -2 -1`` names the last four vertices defined *before*
    the face; trimesh counts them back from the end of the file instead.
    Only the face lines holding a negative index are rewritten.
    """
    if not re.search(r"^f[ \t][^\n]*(?<![\d/])-\d", text, flags=re.MULTILINE):
        return text
    starts = [
        np.array([m.start() for m in re.finditer(rf"^{k}[ \t]", text, flags=re.MULTILINE)])
        for k in ("v", "vt", "vn")
    ]

    def line(m):
        # counts of v, vt, vn defined before this face
        n = [int(np.searchsorted(s, m.start())) for s in starts]

        def token(t):
            parts = t.group(0).split("/")
            return "/".join(
                str(int(q) + n[i] + 1) if q.startswith("-") else q for i, q in enumerate(parts)
            )

        return m.group(1) + re.sub(r"\S+", token, m.group(2))

    return re.sub(r"^(f[ \t]+)([^\n]*)", line, text, flags=re.MULTILINE)


class _Libraries(trimesh.resolvers.Resolver):
    """What trimesh may read beside an OBJ: the material libraries voxgi read
    already (through the path policy), and nothing else (textures are
    reduced by voxgi itself)."""

    def __init__(self, texts: dict[str, str]):
        self.texts = texts

    def get(self, name):
        return self.texts[str(name)].encode("utf-8")

    def keys(self):  # pragma: no cover - trimesh asks only for named files
        return iter(self.texts)

    def write(self, name, data):  # pragma: no cover - voxgi only reads scenes
        raise ValueError("a scene reader does not write files")

    def namespaced(self, namespace):  # pragma: no cover
        return self


def _read_libraries(path: Path, text: str, access: FileAccess, notes: Notes):
    """The ``mtllib`` files an OBJ names: ``(materials, {name: text})``."""
    mats: dict[str, dict] = {}
    texts: dict[str, str] = {}
    for k, line in enumerate(text.splitlines(), 1):
        if not line.startswith("mtllib"):
            continue
        for name in line.split()[1:]:
            try:
                texts[name] = access.read_text(path.parent / name, "material library")
            except FileNotFoundError:
                notes.approx(f"material library {name} not found: grey 0.5")
                continue
            except ValueError as exc:
                raise ValueError(f"{path}: line {k}: mtllib {name}: {exc}") from None
            mats.update(_parse_mtl(path.parent / name, texts[name]))
    return mats, texts


def _map_kd(m: dict, g, access: FileAccess, notes: Notes, what: str):
    """(Texture, uv) of a material's ``map_Kd`` on mesh ``g`` (its factor
    ``Kd``, its vt turned to v = 0 at the image's top), or (None, None) where
    the mesh has no UVs (the texture's mean colour is used then)."""
    from ..textures import Texture

    uv = getattr(g.visual, "uv", None)
    if uv is None or len(uv) != len(g.vertices) or not np.all(np.isfinite(uv)):
        notes.approx(f"{what}: no texture coordinates, texture reduced to its mean colour")
        return None, None
    cache = notes.__dict__.setdefault("texture_cache", {})
    key = (str(m["map_Kd"]), tuple(np.asarray(m.get("Kd", np.full(3, 0.8))).tolist()))
    if key not in cache:
        try:
            texels = decode_rgb(m["map_Kd"], access)
        except RefusedError:
            raise
        except (OSError, ValueError):
            return None, None  # texture_mean says why
        kd = np.minimum(np.asarray(key[1], np.float64), 1.0)
        cache[key] = Texture(texels, factor=kd, path=str(m["map_Kd"]))
    uv = np.array(uv, np.float64)
    uv[:, 1] = 1.0 - uv[:, 1]
    return cache[key], uv


def load_obj(path, *, search_paths=(), allow_outside=False, limits=None) -> SceneData:
    """Read an OBJ file and its MTL materials: one mesh per material.

    ``Kd`` is the albedo (default 0.8 when the MTL gives none), ``Ke`` the
    emitted radiance; a ``map_Kd`` texture is the albedo, times ``Kd``, looked
    up by the mesh's ``vt`` (bilinear, repeating; its mean colour times
    ``Kd`` when the mesh has none). A missing MTL file or material gives grey 0.5. All
    surfaces are one-sided (OBJ has no flag for it).

    Parameters
    ----------
    path : str or Path
    search_paths, allow_outside, limits
        As :meth:`voxgi.Scene.load` (docs/scene-files.md).

    Raises
    ------
    FileNotFoundError, ValueError
        As :func:`load_mitsuba`, naming the OBJ or MTL file.
    """
    path = Path(path)
    access = FileAccess(path, search_paths, allow_outside, limits)
    notes = Notes(path)
    try:
        text = access.read_bytes(path, "scene file").decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"scene file {path}: cannot be read as OBJ text ({exc})") from None
    mats, texts = _read_libraries(path, text, access, notes)
    try:
        loaded = load_trimesh(
            _absolute_obj_indices(text).encode("utf-8"),
            "obj",
            resolver=_Libraries(texts),
            group_material=True,
        )
    except Exception as exc:
        raise ValueError(f"scene file {path}: cannot load OBJ: {exc}") from None
    geoms = (
        list(loaded.geometry.items())
        if isinstance(loaded, trimesh.Scene)
        else [(path.stem, loaded)]
    )
    data = SceneData()
    for gname, g in geoms:
        if not isinstance(g, trimesh.Trimesh) or len(g.faces) == 0:
            continue
        mat = getattr(getattr(g.visual, "material", None), "name", None)
        m = mats.get(mat)
        if m is None:
            if mats:
                notes.approx(f"material {mat!r} not in the MTL: grey 0.5")
            albedo, emission = np.full(3, 0.5), np.zeros(3)
        else:
            albedo = m.get("Kd", np.full(3, 0.8))
            emission = m.get("Ke", np.zeros(3))
            if "map_Kd" in m:
                texture, uv = _map_kd(m, g, access, notes, f"material {mat!r}")
                if texture is None:
                    albedo = albedo * texture_mean(m["map_Kd"], access, notes, f"material {mat!r}")
                else:
                    albedo = texture.mean()
        albedo = clamp_albedo(albedo, f"material {mat!r}", notes)
        lobe = _phong_lobe(m, f"material {mat!r}", notes) if m is not None else None
        if m is None or "map_Kd" not in m:
            texture, uv = None, None
        data.meshes.append(
            MeshData(
                str(mat or gname),
                np.asarray(g.vertices, np.float64),
                np.asarray(g.faces, np.int64),
                albedo,
                emission,
                False,
                str(path),
                texture=texture,
                uv=uv,
                specular=lobe,
            )
        )
    if not data.meshes:
        raise ValueError(f"scene file {path}: the OBJ holds no faces")
    notes.emit()
    return data
