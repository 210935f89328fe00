"""voxgi's TOML scene files: the schema read by :meth:`voxgi.Scene.load` and
:meth:`voxgi.Scene.from_dict`, written by :meth:`voxgi.Scene.save`.

The functions fill a scene given to them (anything with the ``add``,
``add_light``, ``camera`` and ``environment`` of :class:`voxgi.Scene`), so
that this package never imports :mod:`voxgi.scene`.
"""

from __future__ import annotations

import io
import math
import sys
from pathlib import Path

import numpy as np
import trimesh

from .. import _validate
from ..camera import Camera
from ..io import atomic_path
from ..lights import DirectionalLight, Environment, PointLight, SpotLight
from ..materials import AshikhminShirley, Material

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


def load_toml(scene, path: Path):
    """Fill ``scene`` from the TOML file ``path`` (:meth:`voxgi.Scene.load`); returns it."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FileNotFoundError(f"scene file not found: {path}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"scene file {path}: cannot be read ({exc})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"scene file {path}: malformed TOML: {exc}") from None
    except RecursionError:
        raise ValueError(
            f"scene file {path}: arrays or tables nested too deeply to be a scene file"
        ) from None
    try:
        return fill_scene(scene, data, base_dir=path.parent, source=str(path))
    except ValueError as exc:
        line = _error_line(text, data, str(exc))
        if line is None:
            raise
        raise ValueError(f"{exc} (line {line})") from None


def fill_scene(scene, data: dict, base_dir=".", source: str = "<dict>"):
    """Fill ``scene`` from the parsed contents of a TOML scene file; returns it."""
    base_dir = Path(base_dir)
    _check_top_level(data, source)
    if "camera" in data:
        scene.camera = camera_from_dict(data["camera"], source)
    materials = _materials_from_dict(data.get("materials", {}), source)
    objs = data.get("object", [])
    if not isinstance(objs, list):
        raise ValueError(f"{source}: 'object' must be an array of tables ([[object]])")
    for k, o in enumerate(objs):
        _add_object_from_dict(scene, o, f"{source}: object #{k}", materials, base_dir)
    lights = data.get("light", [])
    if not isinstance(lights, list):
        raise ValueError(f"{source}: 'light' must be an array of tables ([[light]])")
    for k, entry in enumerate(lights):
        scene.add_light(light_from_dict(entry, f"{source}: light #{k}"))
    if "environment" in data:
        scene.environment = environment_from_dict(data["environment"], source, base_dir)
    return scene


def save_toml(scene, path: Path) -> Path:
    """Write ``scene`` as a TOML file with one OBJ file per object beside it
    (:meth:`voxgi.Scene.save`)."""
    import tomli_w  # (writes any name as valid TOML: control characters escaped)

    path.parent.mkdir(parents=True, exist_ok=True)
    doc: dict = {}
    if scene.camera is not None:
        doc["camera"] = _camera_to_dict(scene.camera)
    objects = []
    for i, o in enumerate(scene.objects):
        fname = f"{path.stem}_{i:03d}.obj"
        with atomic_path(path.parent / fname) as tmp:
            tmp.write_text(_obj_text(o.vertices, o.faces))
        objects.append(_object_to_dict(o, fname))
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
    spec = o.material.specular
    if spec is not None:
        entry["specular"] = {
            "rs": [float(x) for x in spec.rs],
            "nu": float(spec.nu),
            "nv": float(spec.nv),
        }
    return entry


def _obj_text(vertices: np.ndarray, faces: np.ndarray) -> str:
    """OBJ text of a mesh, every float with 17 significant digits.

    ``%.17g`` reads back as the same float64 at any magnitude (a fixed
    number of decimals would not, below 0.1).
    """
    buf = io.StringIO()
    np.savetxt(buf, vertices, fmt="v %.17g %.17g %.17g")
    np.savetxt(buf, faces + 1, fmt="f %d %d %d")
    return buf.getvalue()


# Mesh formats that are text only: trimesh guesses the encoding of any
# other bytes with an optional package and reports that package missing.
_TEXT_MESH_FORMATS = {".obj", ".off"}


#: Keys of an ``[[object]]`` table that give its material inline.
_OBJECT_MATERIAL_KEYS = {"albedo", "emission", "specular"}
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
} | _OBJECT_MATERIAL_KEYS


def _check_top_level(data, source: str) -> None:
    """Raise unless ``data`` is a table with only the known top-level keys."""
    if not isinstance(data, dict):
        raise TypeError(f"{source}: expected a table at the top level")
    unknown = set(data) - {"camera", "materials", "object", "light", "environment"}
    if unknown:
        raise ValueError(
            f"{source}: unknown top-level key(s) {sorted(unknown)}; "
            "expected camera, materials, object, light, environment"
        )


#: The ``[[light]]`` types and the class of each.
_LIGHT_TYPES = {"point": PointLight, "spot": SpotLight, "directional": DirectionalLight}


def light_from_dict(entry, where: str):
    """The light of one ``[[light]]`` table: ``type`` and the class's fields."""
    if not isinstance(entry, dict):
        raise ValueError(f"{where}: must be a table")
    kind = entry.get("type")
    if kind not in _LIGHT_TYPES:
        raise ValueError(f"{where}: 'type' must be one of {sorted(_LIGHT_TYPES)}, got {kind!r}")
    cls = _LIGHT_TYPES[kind]
    fields = {k: v for k, v in entry.items() if k != "type"}
    allowed = set(cls.__dataclass_fields__)
    bad = set(fields) - allowed
    if bad:
        raise ValueError(
            f"{where} ({kind}): unknown key(s) {sorted(bad)}; expected {sorted(allowed)}"
        )
    try:
        return cls(**fields)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where} ({kind}): {exc}") from None


def _light_to_dict(light) -> dict:
    kind = next(k for k, c in _LIGHT_TYPES.items() if isinstance(light, c))
    out: dict = {"type": kind}
    for name in light.__dataclass_fields__:
        v = getattr(light, name)
        out[name] = [float(x) for x in v] if isinstance(v, tuple) else float(v)
    return out


def environment_from_dict(env, source: str, base_dir: Path) -> Environment:
    where = f"{source}: [environment]"
    if not isinstance(env, dict):
        raise ValueError(f"{where} must be a table")
    bad = set(env) - {"radiance", "image", "scale", "to_world"}
    if bad:
        raise ValueError(
            f"{where}: unknown key(s) {sorted(bad)}; expected radiance or image, scale, to_world"
        )
    if ("radiance" in env) == ("image" in env):
        raise ValueError(f"{where}: give exactly one of 'radiance' (RGB) and 'image' (a path)")
    try:
        if "image" in env:
            if not isinstance(env["image"], str):
                raise ValueError(f"'image' must be a path string, got {env['image']!r}")
            img = Path(env["image"])
            radiance = img if img.is_absolute() else base_dir / img
        else:
            radiance = env["radiance"]
        return Environment(radiance, to_world=env.get("to_world"), scale=env.get("scale", 1.0))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


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


def camera_from_dict(cam, source: str) -> Camera:
    """The :class:`Camera` of a ``[camera]`` table."""
    if not isinstance(cam, dict):
        raise ValueError(f"{source}: [camera] must be a table")
    try:
        return Camera(**cam)
    except TypeError as exc:
        raise ValueError(f"{source}: [camera]: {exc}") from None
    except ValueError as exc:
        raise ValueError(f"{source}: [camera]: {exc}") from None


def _materials_from_dict(mats, source: str) -> dict[str, Material]:
    """The named materials of a ``[materials]`` table."""
    if not isinstance(mats, dict):
        raise ValueError(f"{source}: [materials] must be a table of tables")
    return {
        mname: _material_from_dict(m, f"{source}: [materials.{mname}]") for mname, m in mats.items()
    }


def _check_object_keys(o, where: str) -> str:
    """Check an ``[[object]]`` table's keys and types; returns ``where`` with its name."""
    if not isinstance(o, dict):
        raise ValueError(f"{where}: must be a table")
    if "name" in o:
        where += f" ({o['name']!r})"
    bad = set(o) - _OBJECT_KEYS
    if bad:
        raise ValueError(f"{where}: unknown key(s) {sorted(bad)}")
    if "mesh" not in o:
        raise ValueError(f"{where}: missing key 'mesh'")
    for key in ("mesh", "material", "name"):
        if key in o and not isinstance(o[key], str):
            raise ValueError(
                f"{where}: '{key}' must be a string, got {type(o[key]).__name__} {o[key]!r}"
            )
    return where


def _object_material(o: dict, where: str, materials: dict[str, Material]) -> Material:
    """An object's material: a named one from ``[materials]`` or its inline keys."""
    if "material" not in o:
        return _material_from_dict({k: o[k] for k in _OBJECT_MATERIAL_KEYS if k in o}, where)
    if set(o) & _OBJECT_MATERIAL_KEYS:
        raise ValueError(f"{where}: give either 'material' or inline albedo/emission")
    if o["material"] not in materials:
        raise ValueError(
            f"{where}: unknown material {o['material']!r}; defined: {sorted(materials)}"
        )
    return materials[o["material"]]


def _add_object_from_dict(
    scene, o, where: str, materials: dict[str, Material], base_dir: Path
) -> None:
    """Load, transform and add to ``scene`` the mesh of one ``[[object]]`` table."""
    where = _check_object_keys(o, where)
    mat = _object_material(o, where, materials)
    mesh_path = Path(o["mesh"])
    if not mesh_path.is_absolute():
        mesh_path = base_dir / mesh_path
    if not mesh_path.exists():
        raise ValueError(f"{where}: mesh file not found: {mesh_path}")
    mesh = _load_mesh(mesh_path, where)
    matrix = _transform_from_dict(o, where)
    if matrix is not None:
        mesh = mesh.copy()
        mesh.apply_transform(matrix)
    name = o.get("name", mesh_path.stem)
    try:
        obj = scene.add(mesh, mat, name=name, two_sided=o.get("two_sided", False))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None
    obj.source = str(o["mesh"])
    obj.transform = matrix


def _load_mesh(mesh_path: Path, where: str) -> trimesh.Trimesh:
    """Read a mesh file through trimesh; ValueError naming the file if it cannot."""
    kind = mesh_path.suffix.lower()
    if kind in _TEXT_MESH_FORMATS:
        try:
            data = mesh_path.read_bytes()
        except OSError as exc:
            raise ValueError(f"{where}: cannot read mesh file {mesh_path}: {exc}") from None
        try:
            data.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise ValueError(
                f"{where}: mesh file {mesh_path} is not UTF-8 text (byte "
                f"{exc.start}), so not a {kind[1:].upper()} file"
            ) from None
    try:
        return trimesh.load(mesh_path, force="mesh", process=False, maintain_order=True)
    except ImportError as exc:  # an optional decoder trimesh wanted for odd content
        raise ValueError(
            f"{where}: cannot load mesh {mesh_path}: unreadable content ({exc})"
        ) from None
    except Exception as exc:
        raise ValueError(f"{where}: cannot load mesh {mesh_path}: {exc}") from None


def _error_line(text: str, data, msg: str) -> int | None:
    """1-based line of the table and key that a :meth:`Scene.from_dict` error names.

    The message names the table (``object #k``, ``[camera]``,
    ``[materials.NAME]``) and usually a key; the line is the key's ``key =``
    line within that table, else the table's header line.
    """
    import re

    m = re.search(r"(object|light) #(\d+)", msg)
    if m:
        want, table = (m.group(1), int(m.group(2))), None
        objs = data.get(m.group(1)) if isinstance(data, dict) else None
        table = objs[want[1]] if isinstance(objs, list) and want[1] < len(objs) else None
    elif m := re.search(r"\[materials\.([^\]]+)\]", msg):
        want = ("materials", m.group(1))
        mats = data.get("materials") if isinstance(data, dict) else None
        table = mats.get(want[1]) if isinstance(mats, dict) else None
    elif "[camera]" in msg:
        want, table = ("camera",), data.get("camera") if isinstance(data, dict) else None
    elif "[environment]" in msg:
        want = ("environment",)
        table = data.get("environment") if isinstance(data, dict) else None
    else:
        want, table = (None,), data
    # the key named in the message (longest first, so "focus_distance" beats "focus")
    keys = sorted(table, key=len, reverse=True) if isinstance(table, dict) else []
    key = next(
        (
            k
            for k in keys
            if re.search(rf"(?<!\w){re.escape(str(k))}(?!\w)", msg.split(": ", 1)[-1])
        ),
        None,
    )
    section: tuple = (None,)
    n_obj = {"object": -1, "light": -1}
    header = None
    for i, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if h := re.match(r"^\[\[\s*(object|light)\s*\]\]", line):
            n_obj[h.group(1)] += 1
            section = (h.group(1), n_obj[h.group(1)])
        elif h := re.match(r"^\[\s*materials\.\s*[\"']?([^\]\"']+)[\"']?\s*\]", line):
            section = ("materials", h.group(1).strip())
        elif h := re.match(r"^\[\s*(camera|environment)\s*\]", line):
            section = (h.group(1),)
        elif line.startswith("["):
            section = ("other",)
        else:
            if (
                section == want
                and key is not None
                and re.match(rf"^[\"']?{re.escape(str(key))}[\"']?\s*=", line)
            ):
                return i
            continue
        if section == want and header is None:
            header = i
    return header


def _material_from_dict(m, where: str) -> Material:
    if not isinstance(m, dict):
        raise ValueError(f"{where}: material must be a table")
    bad = set(m) - {"albedo", "emission", "specular"}
    if bad:
        raise ValueError(f"{where}: unknown material key(s) {sorted(bad)}")
    spec = m.get("specular")
    try:
        if spec is not None:
            if not isinstance(spec, dict):
                raise ValueError("specular must be a table {rs, nu, nv}")
            spec = AshikhminShirley(**spec)
        kw = {k: m[k] for k in ("albedo", "emission") if k in m}
        return Material(specular=spec, **kw)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


def _transform_from_dict(o: dict, where: str) -> np.ndarray | None:
    keys = {"translate", "rotate", "scale", "matrix"} & set(o)
    if not keys:
        return None
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
            s = np.broadcast_to(np.asarray(o["scale"], dtype=np.float64), (3,))
            if not np.all(np.isfinite(s)) or np.any(s == 0):
                raise ValueError(f"scale must be finite and non-zero, got {o['scale']!r}")
            m = np.diag([*s, 1.0]) @ m
        if "rotate" in o:
            r = np.asarray(o["rotate"], dtype=np.float64)
            if r.shape != (4,) or not np.all(np.isfinite(r)) or np.linalg.norm(r[1:]) == 0:
                raise ValueError(f"rotate must be [degrees, ax, ay, az], got {o['rotate']!r}")
            m = trimesh.transformations.rotation_matrix(math.radians(r[0]), r[1:]) @ m
        if "translate" in o:
            t = _validate.vec3(o["translate"], "translate")
            m = trimesh.transformations.translation_matrix(t) @ m
        return m
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None
