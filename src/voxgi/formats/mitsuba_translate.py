"""Mitsuba 3 plugins to voxgi: BSDFs to albedos, emitters to radiance and
lights, shapes to meshes, the sensor to a camera (docs/design.md §12)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import trimesh

from .. import _validate
from ._common import MeshData, Notes, SceneData, clamp_albedo, load_trimesh
from ._paths import FileAccess
from .mitsuba_xml import PLUGIN_TAGS, Node, Plugin, XmlReader, parse_xml
from .serialized import read_serialized
from .textures import decode_rgb, texture_file_mean

__all__ = ["load_mitsuba"]


#: BSDFs that hold another (the one whose albedo is used).
_WRAPPER_BSDFS = {"twosided", "mask", "bumpmap", "normalmap"}
#: BSDFs that scatter on both sides by themselves.
_TWO_SIDED_BSDFS = {"dielectric", "thindielectric", "roughdielectric"}
#: Glass: a shape with one of these is a transmitting sheet (docs/design.md §13).
_GLASS_BSDFS = _TWO_SIDED_BSDFS
#: Mitsuba 3's named indices of refraction (its ior.h table).
_NAMED_IOR = {
    "vacuum": 1.0, "helium": 1.00004, "hydrogen": 1.00013, "air": 1.00028,
    "carbon dioxide": 1.00045, "water": 1.333, "acetone": 1.36, "ethanol": 1.361,
    "carbon tetrachloride": 1.461, "glycerol": 1.4729, "benzene": 1.501,
    "silicone oil": 1.52045, "bromine": 1.661, "water ice": 1.31, "fused quartz": 1.458,
    "pyrex": 1.47, "acrylic glass": 1.49, "polypropylene": 1.49, "bk7": 1.5046,
    "sodium chloride": 1.544, "amber": 1.55, "pet": 1.575, "diamond": 2.419,
}  # fmt: skip
#: BSDFs read as a microfacet lobe over a diffuse base (docs/design.md §14).
_LOBE_BSDFS = {"roughplastic", "plastic", "roughconductor", "conductor"}
#: Roughness of the lobe that stands for a smooth surface's mirror reflection.
SMOOTH_ALPHA = 0.02
#: Properties whose colour approximates another BSDF's diffuse albedo.
_ALBEDO_KEYS = ("reflectance", "diffuse_reflectance", "base_color")


def _colour(v, p: Plugin, key: str, notes: Notes) -> np.ndarray:
    """An RGB colour from a float, an rgb/spectrum value or a texture plugin."""
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return np.full(3, float(v))
    if isinstance(v, np.ndarray):
        return v.astype(np.float64)
    if isinstance(v, Plugin) and v.tag == "texture":
        if v.type == "bitmap" and "filename" in v.props:
            if getattr(notes, "textured", False):
                return _bitmap_texture(v, notes).mean()  # (decoded once, for the texture)
            img_path = Path(v.props["filename"])
            try:
                mean = texture_file_mean(img_path, v.access, raw=bool(v.props.get("raw", False)))
            except (OSError, ValueError) as exc:
                raise ValueError(f"{v.where()}: cannot read bitmap {img_path}: {exc}") from None
            if not getattr(notes, "textured", False):
                notes.approx(f"{v.label()}: bitmap {img_path.name} reduced to its mean colour")
            return mean
        if v.type == "checkerboard":
            c0 = _colour(v.props.get("color0", 0.4), v, "color0", notes)
            c1 = _colour(v.props.get("color1", 0.2), v, "color1", notes)
            notes.approx(f"{v.label()}: checkerboard reduced to its mean colour")
            return 0.5 * (c0 + c1)
        notes.approx(f"{v.label()}: texture replaced by grey 0.5")
        return np.full(3, 0.5)
    raise ValueError(f"{p.where()}: property {key!r} is not a colour: {v!r}")


#: Mitsuba's bitmap filter_type and wrap_mode values voxgi's Texture holds.
_FILTERS = ("bilinear", "nearest")
_WRAPS = ("repeat", "mirror", "clamp")


def _bitmap_texture(v, notes: Notes):
    """The voxgi.Texture of a ``bitmap`` texture plugin (its filter, wrap mode
    and to_uv, or Mitsuba 0.5's uoffset/voffset/uscale/vscale), or None for
    anything else."""
    if not (isinstance(v, Plugin) and v.tag == "texture" and v.type == "bitmap"):
        return None
    if "filename" not in v.props:
        return None
    # one Texture a plugin, however many shapes refer to its BSDF
    cache = notes.__dict__.setdefault("texture_cache", {})
    if id(v) in cache:
        return cache[id(v)][1]
    cache[id(v)] = (v, _read_bitmap(v))
    return cache[id(v)][1]


def _read_bitmap(v: Plugin):
    from ..textures import Texture

    img_path = Path(v.props["filename"])
    filt = str(v.props.get("filter_type", "bilinear")).lower()
    wrap = str(v.props.get("wrap_mode", "repeat")).lower()
    if filt not in _FILTERS:
        raise ValueError(f"{v.where()}: filter_type={filt!r}; expected one of {_FILTERS}")
    if wrap not in _WRAPS:
        raise ValueError(f"{v.where()}: wrap_mode={wrap!r}; expected one of {_WRAPS}")
    m4 = np.asarray(v.props.get("to_uv", np.eye(4)), np.float64)
    to_uv = np.array([[m4[0, 0], m4[0, 1], m4[0, 3]], [m4[1, 0], m4[1, 1], m4[1, 3]], [0, 0, 1]])
    # Mitsuba 0.5: uv * (uscale, vscale) + (uoffset, voffset)
    su, sv = v.number("uscale", 1.0), v.number("vscale", 1.0)
    ou, ov = v.number("uoffset", 0.0), v.number("voffset", 0.0)
    to_uv = np.array([[su, 0, ou], [0, sv, ov], [0, 0, 1]]) @ to_uv
    try:
        texels = decode_rgb(img_path, v.access)
    except (OSError, ValueError) as exc:
        raise ValueError(f"{v.where()}: cannot read bitmap {img_path}: {exc}") from None
    return Texture(
        texels,
        filter=filt,
        wrap=wrap,
        to_uv=to_uv,
        raw=bool(v.props.get("raw", False)),
        path=str(img_path.absolute()),
    )


def _bsdf_texture(p: Plugin, notes: Notes):
    """The bitmap of a BSDF's diffuse albedo (through its wrappers), or None."""
    if p.type in _WRAPPER_BSDFS:
        nested = p.nested("bsdf")
        return _bsdf_texture(nested[0], notes) if nested else None
    if p.type in _TWO_SIDED_BSDFS or p.type == "blendbsdf":
        return None
    key = next((k for k in _ALBEDO_KEYS if k in p.props), None)
    return None if key is None else _bitmap_texture(p.props[key], notes)


def _bsdf(p: Plugin, notes: Notes) -> tuple[np.ndarray, bool]:
    """(albedo, two_sided) of a BSDF plugin (docs/design.md §12)."""
    nested = p.nested("bsdf")
    if p.type == "diffuse":
        return _colour(p.props.get("reflectance", 0.5), p, "reflectance", notes), False
    if p.type in _WRAPPER_BSDFS:
        if not nested:
            raise ValueError(f"{p.where()}: needs a nested <bsdf>")
        albedo, _ = _bsdf(nested[0], notes)
        if p.type == "twosided":
            if len(nested) > 1:
                notes.approx(f"{p.label()}: its back BSDF replaced by the front one")
            return albedo, True
        notes.approx(f"{p.label()}: replaced by its nested BSDF")
        return albedo, False
    if p.type == "blendbsdf" and len(nested) == 2:
        w = p.props.get("weight", 0.5)
        w = (
            float(w)
            if isinstance(w, (int, float))
            else float(_colour(w, p, "weight", notes).mean())
        )
        (a0, s0), (a1, s1) = _bsdf(nested[0], notes), _bsdf(nested[1], notes)
        notes.approx(f"{p.label()}: the blend of its BSDFs' albedos")
        return (1 - w) * a0 + w * a1, s0 and s1
    if p.type in ("plastic", "roughplastic"):
        return _colour(
            p.props.get("diffuse_reflectance", 0.5), p, "diffuse_reflectance", notes
        ), False
    if p.type in ("conductor", "roughconductor"):
        return np.zeros(3), False  # (no base: the material sets the lobe's albedo)
    if p.type in _TWO_SIDED_BSDFS:
        # (a shape's own glass BSDF is a sheet, _sheet; this is glass inside another BSDF)
        notes.approx(
            f"glass {p.label()} inside another BSDF: an opaque diffuse surface of albedo 0.5"
        )
        return np.full(3, 0.5), True
    key = next((k for k in _ALBEDO_KEYS if k in p.props), None)
    albedo = np.full(3, 0.5) if key is None else _colour(p.props[key], p, key, notes)
    notes.approx(f"{p.label()}: diffuse with albedo {'0.5' if key is None else key}")
    return albedo, p.type in _TWO_SIDED_BSDFS


def _lobe(p: Plugin, notes: Notes):
    """The :class:`voxgi.Microfacet` of a BSDF plugin (through ``twosided``),
    or None (docs/design.md §14)."""
    while p.type == "twosided" and p.nested("bsdf"):
        p = p.nested("bsdf")[0]
    if p.type not in _LOBE_BSDFS:
        return None
    from ..microfacet import CONDUCTORS, Microfacet

    smooth = p.type in ("plastic", "conductor")
    alpha = SMOOTH_ALPHA
    if not smooth:
        if "alpha_u" in p.props or "alpha_v" in p.props:
            au, av = p.number("alpha_u", 0.1), p.number("alpha_v", 0.1)
            alpha = math.sqrt(au * av)
            if au != av:
                notes.approx(f"{p.label()}: anisotropic roughness as its mean alpha {alpha:.3g}")
        else:
            alpha = p.number("alpha", 0.1)
        if not 0.0 <= alpha <= 4.0:
            raise ValueError(f"{p.where()}: alpha {alpha} is outside [0, 4]")
    dist = "ggx" if smooth else str(p.props.get("distribution", "beckmann")).strip().lower()
    if dist not in ("ggx", "beckmann"):
        raise ValueError(f"{p.where()}: distribution {dist!r} is neither 'beckmann' nor 'ggx'")
    spec = _colour(p.props.get("specular_reflectance", 1.0), p, "specular_reflectance", notes)
    kw = {"alpha": max(alpha, 1e-4), "distribution": dist, "specular_reflectance": spec}
    if p.type.endswith("plastic"):
        ior = _ior(p, "int_ior", 1.49) / _ior(p, "ext_ior", 1.000277)
        if ior == 1.0:
            raise ValueError(f"{p.where()}: int_ior equals ext_ior (Mitsuba rejects it)")
        lobe = Microfacet("plastic", ior=ior, nonlinear=bool(p.props.get("nonlinear", False)), **kw)
    else:
        if "eta" in p.props or "k" in p.props:
            eta = _colour(p.props.get("eta", 0.0), p, "eta", notes)
            k = _colour(p.props.get("k", 1.0), p, "k", notes)
        else:
            name = str(p.props.get("material", "none")).strip()
            if name not in CONDUCTORS:
                raise ValueError(
                    f"{p.where()}: material {name!r} is not one of Mitsuba's conductors "
                    f"({', '.join(sorted(CONDUCTORS))})"
                )
            eta, k = CONDUCTORS[name]
        lobe = Microfacet("conductor", eta=eta, k=k, **kw)
    if smooth:
        notes.approx(
            f"{p.label()}: its mirror reflection as a GGX lobe of alpha {SMOOTH_ALPHA} "
            "(the display's reflections of other surfaces read their records)"
        )
    return lobe


def _ior(p: Plugin, key: str, default: float) -> float:
    """Index of refraction ``key`` of a dielectric: a number or one of Mitsuba's names."""
    v = p.props.get(key, default)
    if isinstance(v, str):
        if v.strip().lower() not in _NAMED_IOR:
            raise ValueError(
                f"{p.where()}: {key} {v!r} is neither a number nor one of Mitsuba's named "
                f"indices ({', '.join(sorted(_NAMED_IOR))})"
            )
        return _NAMED_IOR[v.strip().lower()]
    n = p.number(key, default)
    if not 1.0 <= n <= 10.0:
        raise ValueError(f"{p.where()}: {key} {n} is outside [1, 10]")
    return n


def _sheet(p: Plugin, notes: Notes) -> np.ndarray | None:
    """The straight-through transmittance of a glass BSDF (``dielectric``,
    ``roughdielectric``, ``thindielectric``, or one in ``twosided``), None
    for any other (docs/design.md §13)."""
    while p.type == "twosided" and p.nested("bsdf"):
        p = p.nested("bsdf")[0]
    if p.type not in _GLASS_BSDFS:
        return None
    from ..materials import glass_transmittance

    n = _ior(p, "int_ior", 1.5046) / _ior(p, "ext_ior", 1.000277)
    thin = p.type == "thindielectric"
    t = glass_transmittance(max(n, 1.0 / n), thin=thin)
    tint = _colour(p.props.get("specular_transmittance", 1.0), p, "specular_transmittance", notes)
    if thin:
        notes.approx(
            f"glass {p.label()}: a transmitting sheet, {t:.3f} of the light straight through "
            "(a thin slab's Fresnel transmittance, mean over the hemisphere), no reflection"
        )
    else:
        notes.approx(
            f"glass {p.label()}: each crossing of its surface a transmitting sheet, {t:.3f} "
            "of the light straight through (one interface's Fresnel transmittance, mean over "
            "the hemisphere; a closed pane passes its square), no refraction, no reflection"
        )
    return np.clip(t * np.asarray(tint, np.float64), 0.0, 1.0)


def _emission(p: Plugin, notes: Notes) -> np.ndarray:
    """Radiance of an emitter attached to a shape (only ``area`` is one)."""
    if p.type != "area":
        notes.drop(f"{p.label()} on a shape")
        return np.zeros(3)
    if "radiance" not in p.props:
        raise ValueError(f"{p.where()}: missing property 'radiance'")
    return _colour(p.props["radiance"], p, "radiance", notes)


def _scene_emitter(p: Plugin, data: SceneData, notes: Notes) -> None:
    """A scene-level emitter: Mitsuba's ``point``, ``spot``, ``directional``,
    ``constant`` and ``envmap`` become voxgi's lights in their own units
    (``docs/design.md`` §11, §12); any other is listed as left out."""
    m = np.asarray(p.props.get("to_world", np.eye(4)), np.float64)

    def colour(key: str) -> list[float]:
        return [float(x) for x in _colour(p.props.get(key, 1.0), p, key, notes)]

    def unit(v) -> list[float]:
        v = np.asarray(v, np.float64)
        n = float(np.linalg.norm(v))
        if not n > 0:
            raise ValueError(f"{p.where()}: a zero direction")
        return [float(x) for x in v / n]

    if p.type == "point":
        pos = p.props.get("position", m[:3, 3])
        data.lights.append(
            {"type": "point", "position": [float(x) for x in pos], "intensity": colour("intensity")}
        )
    elif p.type == "spot":
        # Mitsuba's spot shines along its local +z from its local origin.
        cutoff = p.number("cutoff_angle", 20.0)
        data.lights.append(
            {
                "type": "spot",
                "position": [float(x) for x in m[:3, 3]],
                "direction": unit(m[:3, 2]),
                "intensity": colour("intensity"),
                "cutoff_angle": cutoff,
                "beam_width": p.number("beam_width", 0.75 * cutoff),
            }
        )
    elif p.type == "directional":
        d = p.props.get("direction", m[:3, 2])
        data.lights.append(
            {"type": "directional", "direction": unit(d), "irradiance": colour("irradiance")}
        )
    elif p.type in ("constant", "envmap"):
        if data.environment is not None:
            notes.drop(f"{p.label()} at line {p.line} (only the first environment is used)")
            return
        if p.type == "constant":
            data.environment = {"radiance": colour("radiance")}
        else:
            if "filename" not in p.props:
                raise ValueError(f"{p.where()}: missing property 'filename'")
            # (absolute: the TOML rule would read a relative path from the scene's folder)
            image = Path(p.props["filename"]).absolute()
            data.environment = {
                "image": str(image),
                "scale": p.number("scale", 1.0),
                "to_world": m.tolist(),
            }
    else:
        notes.drop(f"{p.label()} at line {p.line}")


def _unit_disk(n: int = 128) -> tuple[np.ndarray, np.ndarray]:
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    v = np.concatenate([[[0.0, 0.0, 0.0]], np.stack([np.cos(t), np.sin(t), 0 * t], 1)])
    i = np.arange(n)
    return v, np.stack([np.zeros(n, np.int64), 1 + i, 1 + (i + 1) % n], 1)


def _canonical_shape(p: Plugin) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, faces, object-to-world) of Mitsuba's built-in shapes."""
    to_world = p.props.get("to_world", np.eye(4))
    if p.type == "rectangle":
        v = np.array([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])
        return v, np.array([[0, 1, 2], [0, 2, 3]]), to_world
    if p.type == "cube":
        box = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
        return np.asarray(box.vertices), np.asarray(box.faces), to_world
    if p.type == "disk":
        v, f = _unit_disk()
        return v, f, to_world
    # sphere: the unit sphere placed by center and radius, then to_world
    s = trimesh.creation.icosphere(subdivisions=4)
    center = p.props.get("center", np.zeros(3))
    radius = p.number("radius", 1.0)
    place = trimesh.transformations.translation_matrix(center) @ np.diag([radius] * 3 + [1.0])
    return np.asarray(s.vertices), np.asarray(s.faces), to_world @ place


def _shape_mesh(p: Plugin):
    """World-space (vertices, faces, source file, uv or None) of a shape plugin."""
    uv = None
    if p.type in ("rectangle", "cube", "sphere", "disk"):
        v, f, m = _canonical_shape(p)
        source = None
        if p.type == "rectangle":
            uv = (v[:, :2] + 1.0) / 2.0  # Mitsuba's rectangle: uv = (x + 1, y + 1) / 2
    else:
        if "filename" not in p.props:
            raise ValueError(f"{p.where()}: missing property 'filename'")
        mesh_path = Path(p.props["filename"])
        try:
            data = p.access.read_bytes(mesh_path, "mesh file")
        except FileNotFoundError:
            raise ValueError(f"{p.where()}: mesh file not found: {mesh_path}") from None
        except ValueError as exc:
            raise ValueError(f"{p.where()}: {exc}") from None
        if p.type == "serialized":
            try:
                v, f = read_serialized(
                    mesh_path,
                    p.number("shape_index", 0, int),
                    data=data,
                    limits=p.access.limits,
                )
            except ValueError as exc:
                raise ValueError(f"{p.where()}: {exc}") from None
        else:
            v, f, uv = _mesh_file(data, mesh_path, p)
        if len(f) == 0:
            raise ValueError(f"{p.where()}: mesh {mesh_path} has no triangles")
        m = p.props.get("to_world", np.eye(4))
        source = str(mesh_path)
    v = np.asarray(v, np.float64) @ m[:3, :3].T + m[:3, 3]
    f = np.asarray(f, np.int64)
    # Mitsuba's analytic rectangle, disk and sphere carry their normal through
    # to_world as a normal, so a mirroring transform keeps their front; a
    # mesh's front follows its winding, which the mirror turns (§12).
    if p.type in ("rectangle", "disk", "sphere") and np.linalg.det(m[:3, :3]) < 0:
        f = f[:, ::-1]
    if p.props.get("flip_normals", False):
        f = f[:, ::-1]
    return v, np.ascontiguousarray(f), source, uv


def _mesh_file(data: bytes, mesh_path: Path, p: Plugin):
    """(vertices, faces, uv or None) of an ``obj`` or ``ply`` shape's file, read
    from ``data`` (an OBJ's material library is not read: the shape's BSDF
    replaces it)."""
    try:
        mesh = load_trimesh(data, p.type, force="mesh")
    except Exception as exc:
        raise ValueError(f"{p.where()}: cannot load mesh {mesh_path}: {exc}") from None
    uv = getattr(getattr(mesh, "visual", None), "uv", None)
    if uv is not None:
        uv = np.array(uv, np.float64)
        if uv.shape != (len(mesh.vertices), 2) or not np.all(np.isfinite(uv)):
            uv = None
        elif p.type == "obj":
            uv[:, 1] = 1.0 - uv[:, 1]  # as Mitsuba reads an OBJ's vt: v = 0 the image's top
    return np.asarray(mesh.vertices), np.asarray(mesh.faces), uv


def _shape(p: Plugin, index: int, notes: Notes) -> list[MeshData]:
    """The meshes of a shape plugin: one, or two for a two-sided emitter."""
    if p.type not in ("obj", "ply", "serialized", "rectangle", "cube", "sphere", "disk"):
        notes.drop(f"{p.label()} at line {p.line}")
        return []
    bsdfs, emitters = p.nested("bsdf"), p.nested("emitter")
    for c in [*p.children, *(v for v in p.props.values() if isinstance(v, Plugin))]:
        if c.tag not in ("bsdf", "emitter"):
            notes.drop(f"{c.label()} inside {p.label()}")
    emission = np.zeros(3)
    for e in emitters:
        emission = emission + _emission(e, notes)
    v, f, source, uv = _shape_mesh(p)
    through = _sheet(bsdfs[0], notes) if bsdfs else None
    texture = None
    if bsdfs and through is None and not emitters:
        texture = _bsdf_texture(bsdfs[0], notes)
    if texture is not None and uv is None:
        notes.approx(
            f"{p.label()}: bitmap {Path(texture.path).name} reduced to its mean colour "
            "(the mesh has no UVs)"
        )
        texture = None
    lobe = _lobe(bsdfs[0], notes) if bsdfs and through is None else None
    if lobe is not None and lobe.kind == "conductor" and texture is not None:
        texture = None  # (a texture there is of the specular reflectance: reduced to its mean)
    if through is not None:
        albedo, two_sided = np.zeros(3), True
    elif bsdfs:
        notes.textured = texture is not None
        try:
            albedo, two_sided = _bsdf(bsdfs[0], notes)
        finally:
            notes.textured = False
    else:
        # Mitsuba's default BSDF: diffuse 0.5, black on an emitter.
        albedo, two_sided = np.full(3, 0.0 if emitters else 0.5), False
    name = p.id or (Path(source).stem if source else f"{p.type}{index}")
    if not _validate.nondegenerate(v, f).any():
        # Mitsuba loads such a mesh and it draws nothing; so does voxgi
        notes.drop(f"{p.label()} {name!r}: every face has zero area")
        return []
    if through is not None and np.max(through) > 0:
        if max(emission) > 0:
            notes.drop(f"{p.label()} {name!r}: the emission of a glass shape")
        return [MeshData(name, v, f, np.zeros(3), np.zeros(3), True, source, transmittance=through)]
    albedo = clamp_albedo(albedo, p.label(), notes)
    if max(emission) > 0 and two_sided:
        # Mitsuba's area emitter lights the front side only, whatever the
        # BSDF: the back becomes a second, reflecting-only surface (§12).
        return [
            MeshData(name, v, f, albedo, emission, False, source),
            MeshData(
                name + "_back",
                v,
                np.ascontiguousarray(f[:, ::-1]),
                albedo,
                np.zeros(3),
                False,
                source,
            ),
        ]
    return [
        MeshData(
            name, v, f, albedo, emission, two_sided, source, texture=texture, uv=uv, specular=lobe
        )
    ]


def _fov_y(fov: float, axis: str, width: int, height: int) -> float:
    """Vertical field of view (degrees) of Mitsuba's ``fov`` along ``fov_axis``."""
    if axis == "smaller":
        axis = "x" if width < height else "y"
    elif axis == "larger":
        axis = "x" if width > height else "y"
    t = math.tan(math.radians(fov) / 2)
    if axis == "x":
        t *= height / width
    elif axis == "diagonal":
        t *= height / math.hypot(width, height)
    return math.degrees(2 * math.atan(t))


def _sensor(p: Plugin, notes: Notes) -> dict | None:
    """Camera keyword arguments of a ``perspective`` or ``thinlens`` sensor."""
    if p.type not in ("perspective", "thinlens"):
        notes.drop(f"{p.label()} (no camera)")
        return None
    films = p.nested("film")
    width = films[0].number("width", 768, int) if films else 768
    height = films[0].number("height", 576, int) if films else 576
    if width < 1 or height < 1:
        raise ValueError(f"{p.where()}: film size {width}x{height} must be positive")
    filters = films[0].nested("rfilter") if films else []
    rfilter = filters[0].type if filters else "gaussian"  # Mitsuba's default
    pixel_filter = "box"
    if rfilter == "gaussian" and (filters[0].number("stddev", 0.5) if filters else 0.5) == 0.5:
        pixel_filter = "gaussian"
    elif rfilter != "box":
        notes.approx(f"film rfilter {rfilter!r} (voxgi's pixels are box-filtered)")
    axis = str(p.props.get("fov_axis", "x")).lower()
    if axis not in ("x", "y", "smaller", "larger", "diagonal"):
        raise ValueError(
            f"{p.where()}: fov_axis={axis!r}; expected x, y, smaller, larger or diagonal"
        )
    if "fov" in p.props:
        fov = p.number("fov")
    else:
        fl = str(p.props.get("focal_length", "50mm"))
        m = re.fullmatch(r"\s*([0-9.eE+-]+)\s*(mm)?\s*", fl)
        if m is None or float(m.group(1)) <= 0:
            raise ValueError(f"{p.where()}: focal_length={fl!r} is not a length like '50mm'")
        # 35 mm film equivalent: a 36 mm wide frame
        fov = math.degrees(2 * math.atan(36.0 / (2 * float(m.group(1)))))
    if not 0 < fov < 180:
        raise ValueError(f"{p.where()}: fov={fov} must be in (0, 180) degrees")
    for k in ("principal_point_offset_x", "principal_point_offset_y"):
        if p.number(k, 0.0) != 0.0:
            notes.drop(f"{p.label()}: {k}")
    m4 = p.props.get("to_world", np.eye(4))
    lin = m4[:3, :3]
    if np.linalg.det(lin) < 0:
        notes.approx(f"{p.label()}: its to_world mirrors the image; voxgi renders it unmirrored")
    eye = m4[:3, 3]
    fwd = lin @ np.array([0.0, 0.0, 1.0])
    fwd /= np.linalg.norm(fwd)
    cam = {
        "eye": tuple(eye.tolist()),
        "target": tuple((eye + fwd).tolist()),
        "up": tuple((lin @ np.array([0.0, 1.0, 0.0])).tolist()),
        "fov": _fov_y(fov, axis, width, height),
        "width": width,
        "height": height,
        "pixel_filter": pixel_filter,
    }
    if p.type == "thinlens":
        cam["aperture"] = p.number("aperture_radius", 0.0)
        if "focus_distance" in p.props:
            cam["focus_distance"] = p.number("focus_distance")
    return cam


def load_mitsuba(path, *, search_paths=(), allow_outside=False, limits=None) -> SceneData:
    """Read a Mitsuba 3 XML scene.

    Parameters
    ----------
    path : str or Path
        The ``.xml`` file; mesh, include and texture files are relative to
        the file that names them.
    search_paths, allow_outside, limits
        Where the scene's files may lie and how much may be read, as
        :meth:`voxgi.Scene.load` (docs/scene-files.md).

    Returns
    -------
    SceneData

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        Malformed XML, unknown elements or ids, bad values, missing mesh
        files, a file outside the allowed folders, a limit exceeded: the
        message names the file, line and element.

    Warns
    -----
    SceneWarning
        One listing the approximated BSDFs and textures, one listing what was
        left out (emitters other than ``area``, other shapes and sensors).
    """
    path = Path(path)
    access = FileAccess(path, search_paths, allow_outside, limits)
    reader = XmlReader(path, access)
    root = parse_xml(path, access)
    try:
        return _read_mitsuba(reader, path, root)
    except RecursionError:
        raise ValueError(f"scene file {path}: elements nested too deeply") from None


def _read_mitsuba(reader: XmlReader, path: Path, root: Node) -> SceneData:
    data = SceneData()
    children = reader.scene_children(path, root)
    for file, node in children:
        if node.tag in PLUGIN_TAGS and "id" in node.attrs:
            reader.pending[reader.attr(file, node, "id")] = (file, node)
    for file, node in children:
        if node.tag not in PLUGIN_TAGS:
            reader.fail(file, node, "unknown top-level element")
        ident = reader.attr(file, node, "id")
        if ident in reader.ids and ident not in reader.pending:
            p = reader.ids[ident]  # read already, through a reference
        else:
            reader.pending.pop(ident, None)
            p = reader.plugin(file, node)
        if p.tag == "shape":
            data.meshes += _located(p, _shape, len(data.meshes), reader.notes)
        elif p.tag == "sensor":
            if data.camera is None:
                data.camera = _located(p, _sensor, reader.notes)
            else:
                reader.notes.drop(f"{p.label()} (only the first sensor is used)")
        elif p.tag == "emitter":
            if p.type != "area":  # (an area emitter is attached to shapes by reference)
                _located(p, _scene_emitter, data, reader.notes)
        elif p.tag == "integrator":
            # voxgi is its own integrator and computes every bounce
            depth = p.props.get("max_depth", -1)
            if depth != -1:
                reader.notes.drop(f"{p.label()}: max_depth {depth} (voxgi computes every bounce)")
        elif p.tag in ("bsdf", "texture"):
            pass  # used through refs
        else:
            reader.notes.drop(f"{p.label()} at line {p.line}")
    if not data.meshes:
        raise ValueError(f"{path}: no shape voxgi can read")
    reader.notes.emit()
    return data


def _located(p: Plugin, translate, *args):
    """``translate(p, *args)``, its errors naming the file, line and element of ``p``
    (a value of the wrong kind, such as a string where a number belongs, is
    found only here)."""
    try:
        return translate(p, *args)
    except (TypeError, ValueError) as exc:
        msg = str(exc)
        if msg.startswith(str(p.file)):
            raise ValueError(msg) from None
        raise ValueError(f"{p.where()}: {msg}") from None
