"""voxgi's TOML scene files: the schema read by :meth:`voxgi.Scene.load` and
:meth:`voxgi.Scene.from_dict` (written by :mod:`voxgi.formats.toml_write`).

The functions fill a scene given to them (anything with the ``add``,
``add_light``, ``camera`` and ``environment`` of :class:`voxgi.Scene`), so
that this package never imports :mod:`voxgi.scene`. An error in a table
carries the table and key it concerns; :func:`load_toml` turns them into the
line of the file, from an index of the file's tables and keys (``tomllib``
keeps no positions).
"""

from __future__ import annotations

import dataclasses
import math
import re
import sys
import warnings
from pathlib import Path

import numpy as np
import trimesh

from .. import _validate
from ..camera import Camera
from ..lights import Environment
from ..materials import AshikhminShirley, Material
from ..microfacet import Microfacet
from ._common import SceneWarning, load_trimesh
from ._limits import RefusedError
from ._paths import FileAccess
from .textures import check_image_size
from .toml_write import LIGHT_TYPES, save_toml

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = [
    "camera_from_dict",
    "environment_from_dict",
    "fill_scene",
    "light_from_dict",
    "load_toml",
    "save_toml",
]


class _Located(ValueError):
    """An error in one table (and key) of a TOML scene: ``table`` is ``()`` for
    the top level, ``("camera",)``, ``("environment",)``, ``("materials", name)``,
    ``("object", k)`` or ``("light", k)``."""

    def __init__(self, msg: str, table: tuple = (), key: str | None = None):
        super().__init__(msg)
        self.table = table
        self.key = key


def load_toml(scene, path: Path, access: FileAccess):
    """Fill ``scene`` from the TOML file ``path`` (:meth:`voxgi.Scene.load`); returns it."""
    try:
        text = access.read_bytes(path, "scene file").decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"scene file {path}: cannot be read ({exc})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        if path.suffix.lower() != ".toml":
            raise ValueError(
                f"scene file {path}: not a scene file voxgi reads: the suffix picks the "
                "reader, .toml (voxgi's TOML), .xml (Mitsuba 3), .obj (with MTL), .gltf or "
                f".glb; read as TOML, it is malformed: {exc}"
            ) from None
        raise ValueError(f"scene file {path}: malformed TOML: {exc}") from None
    except RecursionError:
        raise ValueError(
            f"scene file {path}: arrays or tables nested too deeply to be a scene file"
        ) from None
    try:
        return fill_scene(scene, data, source=str(path), access=access)
    except _Located as exc:
        line = _key_lines(text).get((exc.table, exc.key)) or _key_lines(text).get((exc.table, None))
        if line is None:
            raise ValueError(str(exc)) from None
        raise ValueError(f"{exc} (line {line})") from None


def fill_scene(
    scene, data: dict, base_dir=".", source: str = "<dict>", *, access: FileAccess | None = None
):
    """Fill ``scene`` from the parsed contents of a TOML scene file; returns it.

    Files are read through ``access`` (by default: the path policy rooted at
    ``base_dir``, docs/scene-files.md).
    """
    if access is None:
        access = FileAccess(Path(base_dir) / "scene.toml")
    base_dir = access.scene_file.parent
    _check_top_level(data, source)
    if "camera" in data:
        scene.camera = _camera(data["camera"], source)
    materials = _materials_from_dict(data.get("materials", {}), source)
    objs = data.get("object", [])
    if not isinstance(objs, list):
        raise _Located(f"{source}: 'object' must be an array of tables ([[object]])", (), "object")
    for k, o in enumerate(objs):
        _add_object_from_dict(scene, o, f"{source}: object #{k}", k, materials, access)
    lights = data.get("light", [])
    if not isinstance(lights, list):
        raise _Located(f"{source}: 'light' must be an array of tables ([[light]])", (), "light")
    for k, entry in enumerate(lights):
        try:
            scene.add_light(_light(entry, f"{source}: light #{k}"))
        except _Located as exc:
            raise _Located(str(exc), ("light", k), exc.key) from None
    if "environment" in data:
        scene.environment = _environment(data["environment"], source, base_dir, access)
    return scene


def camera_from_dict(cam, source: str) -> Camera:
    """The :class:`voxgi.Camera` of a ``[camera]`` table (or a reader's camera)."""
    try:
        return _camera(cam, source)
    except _Located as exc:
        raise ValueError(str(exc)) from None


def light_from_dict(entry, where: str):
    """The light of one ``[[light]]`` table: ``type`` and the class's fields."""
    try:
        return _light(entry, where)
    except _Located as exc:
        raise ValueError(str(exc)) from None


def environment_from_dict(
    env, source: str, base_dir: Path, access: FileAccess | None = None
) -> Environment:
    """The :class:`voxgi.Environment` of an ``[environment]`` table (an image path is
    relative to ``base_dir`` and read through ``access``)."""
    try:
        return _environment(env, source, base_dir, access)
    except _Located as exc:
        raise ValueError(str(exc)) from None


# -- which key failed -----------------------------------------------------

#: Values that make a light's required fields valid, to try one key at a time.
_NEUTRAL = {"position": (0.0, 0.0, 0.0), "direction": (0.0, -1.0, 0.0)}


def _build(factory, kw: dict, where: str, table: tuple):
    """``factory(**kw)``; a failure is located at the first key that fails on its own."""
    try:
        return factory(**kw)
    except (TypeError, ValueError) as exc:
        key = None
        for k in kw:
            trial = {n: v for n, v in _NEUTRAL.items() if n in factory.__dataclass_fields__}
            try:
                factory(**{**trial, k: kw[k]})
            except (TypeError, ValueError):
                key = k
                break
        raise _Located(f"{where}: {exc}", table, key) from None


def _key_lines(text: str) -> dict:
    """``{(table, key): line}`` and ``{(table, None): header line}`` of a TOML text
    (1-based), for the tables :class:`_Located` names."""
    out: dict = {}
    table: tuple | None = ()
    count = {"object": -1, "light": -1}
    for i, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if h := re.match(r"^\[\[\s*(object|light)\s*\]\]", line):
            count[h.group(1)] += 1
            table = (h.group(1), count[h.group(1)])
        elif h := re.match(r"^\[\s*materials\.\s*[\"']?([^\]\"']+)[\"']?\s*\]", line):
            table = ("materials", h.group(1).strip())
        elif h := re.match(r"^\[\s*(camera|environment)\s*\]", line):
            table = (h.group(1),)
        elif h := re.match(r"^\[+\s*[\"']?([^\].\"']+)", line):
            out.setdefault(((), h.group(1).strip()), i)
            table = None  # a table voxgi's errors do not name
            continue
        elif table is not None and (k := re.match(r"^[\"']?([\w-]+)[\"']?\s*=", line)):
            out.setdefault((table, k.group(1)), i)
            continue
        else:
            continue
        out.setdefault((table, None), i)
    return out


# -- tables -----------------------------------------------------------------

#: Keys of an ``[[object]]`` table that give its material inline.
_OBJECT_MATERIAL_KEYS = {"albedo", "emission", "specular", "transmittance"}
#: Every key an ``[[object]]`` table may have.
_OBJECT_KEYS = {
    "mesh",
    "material",
    "name",
    "two_sided",
    "translate",
    "rotate",
    "scale",
    "matrix",
    "texture",
} | _OBJECT_MATERIAL_KEYS
#: Keys of an object's ``texture`` table.
_TEXTURE_KEYS = {"file", "filter", "wrap", "to_uv", "raw", "factor"}
# Mesh formats that are text only: trimesh guesses the encoding of any
# other bytes with an optional package and reports that package missing.
_TEXT_MESH_FORMATS = {".obj", ".off"}


def _check_top_level(data, source: str) -> None:
    """Raise unless ``data`` is a table with only the known top-level keys."""
    if not isinstance(data, dict):
        raise TypeError(f"{source}: expected a table at the top level")
    unknown = set(data) - {"camera", "materials", "object", "light", "environment"}
    if unknown:
        raise _Located(
            f"{source}: unknown top-level key(s) {sorted(unknown)}; "
            "expected camera, materials, object, light, environment",
            (),
            sorted(unknown)[0],
        )


def _light(entry, where: str):
    """The light of one ``[[light]]`` table: ``type`` and the class's fields."""
    if not isinstance(entry, dict):
        raise _Located(f"{where}: must be a table")
    kind = entry.get("type")
    if kind not in LIGHT_TYPES:
        raise _Located(
            f"{where}: 'type' must be one of {sorted(LIGHT_TYPES)}, got {kind!r}", (), "type"
        )
    cls = LIGHT_TYPES[kind]
    fields = {k: v for k, v in entry.items() if k != "type"}
    allowed = set(cls.__dataclass_fields__)
    bad = set(fields) - allowed
    if bad:
        raise _Located(
            f"{where} ({kind}): unknown key(s) {sorted(bad)}; expected {sorted(allowed)}",
            (),
            sorted(bad)[0],
        )
    return _build(cls, fields, f"{where} ({kind})", ())


def _environment(env, source: str, base_dir: Path, access: FileAccess | None = None):
    """The :class:`voxgi.Environment` of an ``[environment]`` table (an image path is
    relative to ``base_dir`` and read through ``access``)."""
    where, table = f"{source}: [environment]", ("environment",)
    if not isinstance(env, dict):
        raise _Located(f"{where} must be a table", table)
    bad = set(env) - {"radiance", "image", "scale", "to_world"}
    if bad:
        raise _Located(
            f"{where}: unknown key(s) {sorted(bad)}; expected radiance or image, scale, to_world",
            table,
            sorted(bad)[0],
        )
    if ("radiance" in env) == ("image" in env):
        raise _Located(f"{where}: give exactly one of 'radiance' (RGB) and 'image' (a path)", table)
    radiance = env.get("radiance")
    if "image" in env:
        if not isinstance(env["image"], str):
            raise _Located(f"{where}: 'image' must be a path string, got {env['image']!r}", table)
        img = Path(env["image"])
        radiance = img if img.is_absolute() else Path(base_dir) / img
        try:
            access = access or FileAccess(Path(base_dir) / "scene.toml")
            access.check_file(radiance, "environment image")
            check_image_size(radiance, access)
        except (FileNotFoundError, ValueError) as exc:
            raise _Located(f"{where}: {exc}", table, "image") from None
    kw = {"to_world": env.get("to_world"), "scale": env.get("scale", 1.0)}
    try:
        return Environment(radiance, **kw)
    except (TypeError, ValueError) as exc:
        key = "image" if "image" in env else "radiance"
        for k in ("to_world", "scale"):
            try:
                Environment(1.0, **{k: kw[k]})
            except (TypeError, ValueError):
                key = k
                break
        raise _Located(f"{where}: {exc}", table, key) from None


def _camera(cam, source: str) -> Camera:
    if not isinstance(cam, dict):
        raise _Located(f"{source}: [camera] must be a table", ("camera",))
    return _build(Camera, cam, f"{source}: [camera]", ("camera",))


def _materials_from_dict(mats, source: str) -> dict[str, Material]:
    """The named materials of a ``[materials]`` table."""
    if not isinstance(mats, dict):
        raise _Located(f"{source}: [materials] must be a table of tables", (), "materials")
    return {
        name: _material_from_dict(m, f"{source}: [materials.{name}]", ("materials", name))
        for name, m in mats.items()
    }


def _microfacet(spec: dict) -> Microfacet:
    """A ``specular = {type = "roughplastic" | "roughconductor", ...}`` table,
    in the names of Mitsuba's plugins (``docs/design.md`` §14)."""
    spec = dict(spec)
    kind = {"roughplastic": "plastic", "roughconductor": "conductor"}.get(spec.pop("type"))
    if kind is None:
        raise ValueError("specular.type must be 'roughplastic' or 'roughconductor'")
    keys = {"alpha", "distribution", "specular_reflectance"}
    keys |= {"int_ior", "nonlinear"} if kind == "plastic" else {"eta", "k"}
    bad = set(spec) - keys
    if bad:
        raise ValueError(f"specular: unknown key(s) {sorted(bad)} for type {kind!r}")
    if "int_ior" in spec:
        spec["ior"] = spec.pop("int_ior")
    return Microfacet(kind, **spec)


def _material_from_dict(m, where: str, table: tuple) -> Material:
    if not isinstance(m, dict):
        raise _Located(f"{where}: material must be a table", table)
    bad = set(m) - {"albedo", "emission", "specular", "transmittance"}
    if bad:
        raise _Located(f"{where}: unknown material key(s) {sorted(bad)}", table, sorted(bad)[0])
    kw = {k: m[k] for k in ("albedo", "emission", "transmittance") if k in m}
    spec = m.get("specular")
    if spec is not None:
        if not isinstance(spec, dict):
            raise _Located(
                f"{where}: specular must be a table {{rs, nu, nv}} or {{type, alpha, ...}}",
                table,
                "specular",
            )
        try:
            if "type" in spec:
                kw["specular"] = _microfacet(spec)
            else:
                kw["specular"] = AshikhminShirley(**spec)
        except (TypeError, ValueError) as exc:
            raise _Located(f"{where}: {exc}", table, "specular") from None
    return _build(Material, kw, where, table)


def _check_object_keys(o, where: str, table: tuple) -> str:
    """Check an ``[[object]]`` table's keys and types; returns ``where`` with its name."""
    if not isinstance(o, dict):
        raise _Located(f"{where}: must be a table", table)
    if "name" in o:
        where += f" ({o['name']!r})"
    bad = set(o) - _OBJECT_KEYS
    if bad:
        raise _Located(f"{where}: unknown key(s) {sorted(bad)}", table, sorted(bad)[0])
    if "mesh" not in o:
        raise _Located(f"{where}: missing key 'mesh'", table)
    for key in ("mesh", "material", "name"):
        if key in o and not isinstance(o[key], str):
            raise _Located(
                f"{where}: '{key}' must be a string, got {type(o[key]).__name__} {o[key]!r}",
                table,
                key,
            )
    return where


def _object_material(o: dict, where: str, table: tuple, materials: dict) -> Material:
    """An object's material: a named one from ``[materials]`` or its inline keys."""
    if "material" not in o:
        inline = {k: o[k] for k in _OBJECT_MATERIAL_KEYS if k in o}
        return _material_from_dict(inline, where, table)
    if set(o) & _OBJECT_MATERIAL_KEYS:
        raise _Located(
            f"{where}: give either 'material' or inline albedo/emission", table, "material"
        )
    if o["material"] not in materials:
        raise _Located(
            f"{where}: unknown material {o['material']!r}; defined: {sorted(materials)}",
            table,
            "material",
        )
    return materials[o["material"]]


def _add_object_from_dict(
    scene, o, where: str, k: int, materials: dict, access: FileAccess
) -> None:
    """Load, transform and add to ``scene`` the mesh of one ``[[object]]`` table."""
    table = ("object", k)
    where = _check_object_keys(o, where, table)
    mat = _object_material(o, where, table, materials)
    mesh_path = Path(o["mesh"])
    if not mesh_path.is_absolute():
        mesh_path = access.scene_file.parent / mesh_path
    mesh = _load_mesh(mesh_path, where, table, access)
    matrix = _transform_from_dict(o, where, table)
    if matrix is not None:
        mesh = mesh.copy()
        mesh.apply_transform(matrix)
    name = o.get("name", mesh_path.stem)
    if _validate.all_degenerate(mesh.vertices, mesh.faces):
        warnings.warn(
            SceneWarning(f"{where}: mesh {mesh_path.name}: every face is degenerate; left out"),
            stacklevel=4,
        )
        return
    two_sided = o.get("two_sided", False)
    if not isinstance(two_sided, bool):
        raise _Located(
            f"{where}: two_sided must be true or false, got {two_sided!r}", table, "two_sided"
        )
    if "texture" in o:
        mat = dataclasses.replace(mat, texture=_texture(o["texture"], where, table, access))
    try:
        obj = scene.add(mesh, mat, name=name, two_sided=two_sided)
    except (TypeError, ValueError) as exc:
        raise _Located(f"{where}: {exc}", table, "mesh") from None
    obj.source = str(o["mesh"])
    obj.transform = matrix


def _texture(t, where: str, table: tuple, access: FileAccess):
    """The Texture of an object's ``texture`` table; its file relative to the
    scene file, read through the path policy."""
    from ..textures import Texture

    if not isinstance(t, dict) or "file" not in t:
        raise _Located(f"{where}: texture must be a table with a 'file'", table, "texture")
    bad = set(t) - _TEXTURE_KEYS
    if bad:
        raise _Located(
            f"{where}: texture: unknown key(s) {sorted(bad)}; expected {sorted(_TEXTURE_KEYS)}",
            table,
            "texture",
        )
    img = Path(t["file"])
    if not img.is_absolute():
        img = access.scene_file.parent / img
    kw = {k: t[k] for k in ("filter", "wrap", "to_uv", "raw", "factor") if k in t}
    try:
        return Texture.from_file(img, access, **kw)
    except RefusedError as exc:
        raise _Located(f"{where}: {exc}", table, "texture") from None
    except (OSError, TypeError, ValueError) as exc:
        raise _Located(f"{where}: texture {img}: {exc}", table, "texture") from None


def _load_mesh(mesh_path: Path, where: str, table: tuple, access: FileAccess) -> trimesh.Trimesh:
    """Read a mesh file through the path policy and trimesh; ValueError naming the file."""
    try:
        data = access.read_bytes(mesh_path, "mesh file")
    except FileNotFoundError:
        raise _Located(f"{where}: mesh file not found: {mesh_path}", table, "mesh") from None
    except ValueError as exc:
        raise _Located(f"{where}: {exc}", table, "mesh") from None
    kind = mesh_path.suffix.lower()
    if kind in _TEXT_MESH_FORMATS:
        try:
            data.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise _Located(
                f"{where}: mesh file {mesh_path} is not UTF-8 text (byte "
                f"{exc.start}), so not a {kind[1:].upper()} file",
                table,
                "mesh",
            ) from None
    try:
        return load_trimesh(
            data, kind[1:], resolver=access.resolver(mesh_path.parent), force="mesh"
        )
    except RefusedError as exc:
        raise _Located(f"{where}: {exc}", table, "mesh") from None
    except ImportError as exc:  # an optional decoder trimesh wanted for odd content
        raise _Located(
            f"{where}: cannot load mesh {mesh_path}: unreadable content ({exc})", table, "mesh"
        ) from None
    except Exception as exc:
        raise _Located(f"{where}: cannot load mesh {mesh_path}: {exc}", table, "mesh") from None


def _transform_from_dict(o: dict, where: str, table: tuple) -> np.ndarray | None:
    """The 4x4 matrix of an object's ``matrix`` or ``scale``, ``rotate``, ``translate``."""
    keys = {"translate", "rotate", "scale", "matrix"} & set(o)
    if not keys:
        return None
    key = "matrix"
    try:
        if "matrix" in o:
            if keys - {"matrix"}:
                raise ValueError("give either 'matrix' or translate/rotate/scale")
            m = np.asarray(o["matrix"], dtype=np.float64)
            if m.shape != (4, 4) or not np.all(np.isfinite(m)):
                raise ValueError(f"matrix must be 4x4 finite, got shape {m.shape}")
            return m
        m = np.eye(4)
        if "scale" in o:
            key = "scale"
            s = np.broadcast_to(np.asarray(o["scale"], dtype=np.float64), (3,))
            if not np.all(np.isfinite(s)) or np.any(s == 0):
                raise ValueError(f"scale must be finite and non-zero, got {o['scale']!r}")
            m = np.diag([*s, 1.0]) @ m
        if "rotate" in o:
            key = "rotate"
            r = np.asarray(o["rotate"], dtype=np.float64)
            if r.shape != (4,) or not np.all(np.isfinite(r)) or np.linalg.norm(r[1:]) == 0:
                raise ValueError(f"rotate must be [degrees, ax, ay, az], got {o['rotate']!r}")
            m = trimesh.transformations.rotation_matrix(math.radians(r[0]), r[1:]) @ m
        if "translate" in o:
            key = "translate"
            t = _validate.vec3(o["translate"], "translate")
            m = trimesh.transformations.translation_matrix(t) @ m
        return m
    except (TypeError, ValueError) as exc:
        raise _Located(f"{where}: {exc}", table, key) from None
