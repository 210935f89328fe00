"""Scene files of other renderers: Mitsuba 3 XML, OBJ with MTL, glTF 2.0.

Each loader reads one file into a :class:`SceneData`: plain arrays and
numbers that :meth:`voxgi.Scene.load` turns into a scene (this module never
imports :mod:`voxgi.scene`, so that ``Scene.load`` can dispatch here). What
voxgi cannot represent exactly (glossy BSDFs, textures, point lights, ...) is
approximated or dropped, and listed in one :class:`SceneWarning` per kind;
the conventions are in docs/design.md §12.

Examples
--------
>>> from voxgi import formats
>>> sorted(formats.LOADERS)
['.glb', '.gltf', '.obj', '.xml']
>>> formats.spectrum_to_rgb([400, 700], [0.5, 0.5]).round(3)
array([0.498, 0.5  , 0.497])
"""

from __future__ import annotations

import json
import math
import re
import struct
import warnings
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from xml.parsers import expat

import numpy as np
import trimesh

__all__ = [
    "LOADERS",
    "MeshData",
    "SceneData",
    "SceneWarning",
    "load_gltf",
    "load_mitsuba",
    "load_obj",
    "read_serialized",
    "spectrum_to_rgb",
]


class SceneWarning(UserWarning):
    """A scene file held something voxgi approximated or left out."""


@dataclass
class MeshData:
    """One mesh of a loaded scene, in world space.

    ``vertices`` (V, 3) float64, ``faces`` (F, 3) int64 (counter-clockwise
    around the front normal), ``albedo`` and ``emission`` (3,) float64 linear
    RGB (emission is radiance), ``two_sided`` as :meth:`voxgi.Scene.add`.
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    albedo: np.ndarray
    emission: np.ndarray
    two_sided: bool = False
    source: str | None = None


@dataclass
class SceneData:
    """What a loader read: meshes, the keyword arguments of a Camera (or None),
    and the lights in the tables of a TOML scene."""

    meshes: list[MeshData] = field(default_factory=list)
    camera: dict | None = None
    #: ``[[light]]`` tables of a TOML scene (``type`` and the light's fields)
    lights: list[dict] = field(default_factory=list)
    #: the ``[environment]`` table of a TOML scene, or None
    environment: dict | None = None


#: Largest albedo a Material holds (below 1 in float32, docs/design.md §12).
ALBEDO_MAX = float(np.nextafter(np.float32(1.0), np.float32(0.0)))


class _Notes:
    """What a loader approximated or dropped, for one warning per kind."""

    def __init__(self, path: Path):
        self.path = path
        self.approximated: list[str] = []
        self.unsupported: list[str] = []

    def approx(self, what: str) -> None:
        if what not in self.approximated:
            self.approximated.append(what)

    def drop(self, what: str) -> None:
        if what not in self.unsupported:
            self.unsupported.append(what)

    def emit(self) -> None:
        # stacklevel 4: the warning points at the caller of Scene.load
        if self.approximated:
            warnings.warn(
                SceneWarning(f"{self.path}: approximated: " + "; ".join(self.approximated)),
                stacklevel=4,
            )
        if self.unsupported:
            warnings.warn(
                SceneWarning(
                    f"{self.path}: not supported, left out: " + "; ".join(self.unsupported)
                ),
                stacklevel=4,
            )


# -- colour ----------------------------------------------------------------

_CIE: np.ndarray | None = None
# CIE XYZ to linear sRGB (D65 white), the matrix Mitsuba 3's xyz_to_srgb uses.
_XYZ_TO_SRGB = np.array(
    [
        [3.240479, -1.537150, -0.498535],
        [-0.969256, 1.875991, 0.041556],
        [0.055648, -0.204043, 1.057311],
    ]
)
_CIE_MIN, _CIE_MAX = 360.0, 830.0
# 1 / integral of y over [360, 830] nm (Mitsuba 3's MI_CIE_Y_NORMALIZATION);
# the D65 table is scaled so that y * D65 has the same integral.
_CIE_Y_NORM = 0.009367658735689113


def _cie_table() -> np.ndarray:
    """(95, 5) wavelength, x, y, z, D65 at 5 nm (src/voxgi/data/cie1931_d65.csv)."""
    global _CIE
    if _CIE is None:
        _CIE = np.loadtxt(
            Path(__file__).parent / "data" / "cie1931_d65.csv", delimiter=",", skiprows=5
        )
    return _CIE


def spectrum_to_rgb(wavelengths, values, *, emitter: bool = False) -> np.ndarray:
    """Linear sRGB of a piecewise-linear spectrum, as Mitsuba 3's RGB variants read it.

    Parameters
    ----------
    wavelengths : (N,) float
        Increasing wavelengths in nm (N >= 2).
    values : (N,) float
        The spectrum at those wavelengths; zero outside them.
    emitter : bool
        A radiance (integrated against the CIE matching functions, unclamped)
        instead of a reflectance (weighted by the D65 illuminant so that a flat
        spectrum stays grey, clamped to [0, 1]).

    Returns
    -------
    (3,) float64

    Notes
    -----
    docs/design.md §12: 1000 samples between 360 and 830 nm, the CIE 1931
    2-degree observer, normalised by the integral of ``y`` (``y * D65`` for a
    reflectance), then XYZ to linear sRGB.
    """
    w = np.asarray(wavelengths, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    if w.ndim != 1 or w.shape != v.shape or len(w) < 2 or np.any(np.diff(w) <= 0):
        raise ValueError(
            f"spectrum: need >= 2 increasing wavelengths with one value each, got {w.tolist()}"
        )
    t = _cie_table()
    x = _CIE_MIN + np.arange(1000) / 999.0 * (_CIE_MAX - _CIE_MIN)
    x = x[(x >= w[0]) & (x <= w[-1])]
    y = np.interp(x, w, v)
    xyz = np.stack([np.interp(x, t[:, 0], t[:, k]) for k in (1, 2, 3)], axis=1)
    if not emitter:
        xyz *= np.interp(x, t[:, 0], t[:, 4])[:, None]
    # (the sum is a Riemann sum of step (830 - 360) / 1000 nm)
    norm = (_CIE_MAX - _CIE_MIN) / 1000 * _CIE_Y_NORM
    rgb = _XYZ_TO_SRGB @ ((xyz * y[:, None]).sum(axis=0) * norm)
    return rgb if emitter else np.clip(rgb, 0.0, 1.0)


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _image_mean(image, raw: bool = False) -> np.ndarray:
    """Mean linear RGB of an 8-bit sRGB image (a PIL image or an array)."""
    a = np.asarray(image.convert("RGB") if hasattr(image, "convert") else image)
    a = a.reshape(-1, a.shape[-1])[:, :3].astype(np.float64) / 255.0
    return (a if raw else _srgb_to_linear(a)).mean(axis=0)


def _clamp_albedo(albedo, what: str, notes: _Notes) -> np.ndarray:
    a = np.asarray(albedo, dtype=np.float64)
    if np.any(a > ALBEDO_MAX):
        notes.approx(f"{what}: albedo {a.tolist()} clamped below 1")
        a = np.minimum(a, ALBEDO_MAX)
    return a


# -- Mitsuba 3 XML ---------------------------------------------------------


@dataclass
class _Node:
    tag: str
    attrs: dict
    line: int
    children: list = field(default_factory=list)


def _parse_xml(path: Path) -> _Node:
    """A tree of :class:`_Node` with line numbers (ElementTree has none)."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise FileNotFoundError(f"scene file not found: {path}") from None
    except OSError as exc:
        raise ValueError(f"scene file {path}: cannot be read ({exc})") from None
    parser = expat.ParserCreate()
    stack: list[_Node] = []
    root: list[_Node] = []

    def start(tag, attrs):
        node = _Node(tag, dict(attrs), parser.CurrentLineNumber)
        (stack[-1].children if stack else root).append(node)
        stack.append(node)

    parser.StartElementHandler = start
    parser.EndElementHandler = lambda tag: stack.pop()
    try:
        parser.Parse(data, True)
    except expat.ExpatError as exc:
        raise ValueError(
            f"scene file {path}: malformed XML: {expat.ErrorString(exc.code)} "
            f"(line {exc.lineno}, column {exc.offset + 1})"
        ) from None
    if root[0].tag != "scene":
        raise ValueError(
            f"scene file {path}: line {root[0].line}: expected a <scene> root, got <{root[0].tag}>"
        )
    return root[0]


#: Plugin tags of Mitsuba 3 XML (objects with a ``type``).
_PLUGIN_TAGS = {
    "bsdf",
    "emitter",
    "film",
    "integrator",
    "medium",
    "phase",
    "rfilter",
    "sampler",
    "sensor",
    "shape",
    "texture",
    "volume",
}
#: Mitsuba 3's plugins of the kinds voxgi reads (a name outside them is an
#: error, a known one voxgi cannot represent a warning).
_MITSUBA_PLUGINS = {
    "shape": {
        "obj", "ply", "serialized", "rectangle", "cube", "sphere", "disk", "cylinder",
        "shapegroup", "instance", "bsplinecurve", "linearcurve", "sdfgrid", "ellipsoids",
        "ellipsoidsmesh", "merge",
    },
    "bsdf": {
        "diffuse", "twosided", "plastic", "roughplastic", "conductor", "roughconductor",
        "dielectric", "roughdielectric", "thindielectric", "principled", "principledthin",
        "pplastic", "measured", "measured_polarized", "mask", "bumpmap", "normalmap",
        "blendbsdf", "null", "polarizer", "retarder", "circular", "hair",
    },
    "emitter": {
        "area", "point", "spot", "directional", "directionalarea", "constant", "envmap",
        "projector", "sunsky",
    },
    "sensor": {
        "perspective", "thinlens", "orthographic", "radiancemeter", "irradiancemeter",
        "distant", "batch",
    },
}  # fmt: skip
_VALUE_TAGS = {"float", "integer", "boolean", "string", "rgb", "spectrum", "point", "vector"}


@dataclass
class _Plugin:
    tag: str
    type: str
    id: str | None
    line: int
    file: Path
    props: dict = field(default_factory=dict)
    children: list = field(default_factory=list)

    def where(self) -> str:
        ident = f' id="{self.id}"' if self.id else ""
        return f'{self.file}: line {self.line}: <{self.tag} type="{self.type}"{ident}>'

    def label(self) -> str:
        return f"{self.tag} {self.type!r}" + (f" (id {self.id!r})" if self.id else "")


class _XmlReader:
    """Mitsuba 3 XML to plugins: defaults, ``$var``, includes, refs, values."""

    def __init__(self, path: Path):
        self.path = path
        self.defaults: dict[str, str] = {}
        self.ids: dict[str, _Plugin] = {}
        self.notes = _Notes(path)
        self.search: list[Path] = []  # <path> folders, searched after the file's own
        self.pending: dict[str, tuple[Path, _Node]] = {}  # top-level ids not read yet

    def resolve(self, file: Path, name: str) -> Path:
        """A file named in ``file``: beside it, the scene or a ``<path>`` folder."""
        for folder in [file.parent, self.path.parent, *self.search]:
            if (folder / name).exists():
                return folder / name
        return file.parent / name

    def fail(self, file: Path, node: _Node, msg: str):
        ident = "".join(
            f' {k}="{node.attrs[k]}"' for k in ("type", "name", "id") if k in node.attrs
        )
        raise ValueError(f"{file}: line {node.line}: <{node.tag}{ident}>: {msg}")

    def attr(self, file: Path, node: _Node, key: str, default=None) -> str | None:
        v = node.attrs.get(key, default)
        if v is None:
            return None

        def sub(m):
            if m.group(1) not in self.defaults:
                self.fail(file, node, f"undefined parameter ${m.group(1)} in {key}={v!r}")
            return self.defaults[m.group(1)]

        return re.sub(r"\$(\w+)", sub, v)

    def need(self, file: Path, node: _Node, key: str) -> str:
        v = self.attr(file, node, key)
        if v is None:
            self.fail(file, node, f"missing attribute {key!r}")
        return v

    def numbers(self, file: Path, node: _Node, text: str, what: str) -> np.ndarray:
        try:
            out = np.array([float(s) for s in re.split(r"[,\s]+", text.strip()) if s], np.float64)
        except ValueError:
            self.fail(file, node, f"{what}={text!r} is not a list of numbers")
        if not np.all(np.isfinite(out)):
            self.fail(file, node, f"{what}={text!r} is not finite")
        return out

    # -- top level --------------------------------------------------------
    def scene_children(self, file: Path, root: _Node, depth: int = 0) -> list[tuple[Path, _Node]]:
        """Top-level elements, includes spliced in, defaults recorded."""
        out = []
        for node in root.children:
            if node.tag == "default":
                name = self.need(file, node, "name")
                self.defaults.setdefault(name, self.need(file, node, "value"))
            elif node.tag == "path":
                self.search.append(file.parent / self.need(file, node, "value"))
            elif node.tag == "include":
                if depth > 8:
                    self.fail(file, node, "includes nested more than 8 deep")
                sub = self.resolve(file, self.need(file, node, "filename"))
                if not sub.exists():
                    self.fail(file, node, f"included file not found: {sub}")
                out += self.scene_children(sub, _parse_xml(sub), depth + 1)
            else:
                out.append((file, node))
        return out

    # -- plugins and values -------------------------------------------------
    def plugin(self, file: Path, node: _Node, emitter: bool = False) -> _Plugin:
        kind = self.attr(file, node, "type")
        if kind is None:
            self.fail(file, node, "missing attribute 'type'")
        known = _MITSUBA_PLUGINS.get(node.tag)
        if known is not None and kind not in known:
            self.fail(file, node, f"unknown {node.tag} plugin {kind!r}")
        p = _Plugin(node.tag, kind, self.attr(file, node, "id"), node.line, file)
        emitter = emitter or node.tag == "emitter"
        for child in node.children:
            name = self.attr(file, child, "name")
            if child.tag in _PLUGIN_TAGS:
                sub = self.plugin(file, child, emitter)
                if name is None:
                    p.children.append(sub)
                else:
                    p.props[name] = sub
            elif child.tag == "ref":
                ref_id = self.need(file, child, "id")
                if ref_id not in self.ids and ref_id in self.pending:
                    self.plugin(*self.pending.pop(ref_id))  # a reference ahead of its object
                if ref_id not in self.ids:
                    self.fail(file, child, f"unknown id {ref_id!r}; defined: {sorted(self.ids)}")
                if name is None:
                    p.children.append(self.ids[ref_id])
                else:
                    p.props[name] = self.ids[ref_id]
            elif child.tag == "transform":
                if name is None:
                    self.fail(file, child, "missing attribute 'name'")
                p.props[name] = self.transform(file, child)
            elif child.tag in _VALUE_TAGS:
                if name is None:
                    self.fail(file, child, "missing attribute 'name'")
                p.props[name] = self.value(file, child, emitter)
                if name == "filename" and child.tag == "string":
                    p.props[name] = str(self.resolve(file, p.props[name]))
            else:
                self.fail(file, child, f"unknown element <{child.tag}> inside <{node.tag}>")
        if p.id is not None:
            self.ids[p.id] = p
        return p

    def value(self, file: Path, node: _Node, emitter: bool):
        tag = node.tag
        if tag in ("point", "vector"):
            if "value" in node.attrs:
                v = self.numbers(file, node, self.attr(file, node, "value"), "value")
            else:
                v = np.array(
                    [float(self.attr(file, node, k, "0")) for k in ("x", "y", "z")], np.float64
                )
            if v.shape != (3,):
                self.fail(file, node, f"expected 3 coordinates, got {v.tolist()}")
            return v
        text = self.attr(file, node, "value")
        if tag == "spectrum" and "type" in node.attrs:
            self.fail(file, node, f"spectrum plugin {node.attrs['type']!r} is not supported")
        if tag == "spectrum" and text is None and "filename" in node.attrs:
            spd = self.resolve(file, self.attr(file, node, "filename"))
            try:
                pairs = np.loadtxt(spd, comments="#", ndmin=2)
            except (OSError, ValueError) as exc:
                self.fail(file, node, f"cannot read spectrum file {spd}: {exc}")
            return spectrum_to_rgb(pairs[:, 0], pairs[:, 1], emitter=emitter)
        if text is None:
            self.fail(file, node, "missing attribute 'value'")
        try:
            if tag == "float":
                return float(text)
            if tag == "integer":
                return int(text)
        except ValueError:
            self.fail(
                file,
                node,
                f"value={text!r} is not a{'n integer' if tag == 'integer' else ' number'}",
            )
        if tag == "boolean":
            if text.lower() not in ("true", "false"):
                self.fail(file, node, f"value={text!r} is not true or false")
            return text.lower() == "true"
        if tag == "string":
            return text
        if tag == "rgb":
            v = self.numbers(file, node, text, "value")
            if v.shape == (1,):
                v = np.repeat(v, 3)
            if v.shape != (3,):
                self.fail(file, node, f"value={text!r}: expected 1 or 3 numbers")
            return v
        # spectrum: one number (uniform) or "wavelength:value, ..."
        if ":" not in text:
            v = self.numbers(file, node, text, "value")
            if v.shape != (1,):
                self.fail(
                    file, node, f"value={text!r}: expected one number or wavelength:value pairs"
                )
            # Mitsuba's RGB variants: a uniform reflectance stays grey; a
            # uniform radiance is an equal-energy spectrum (docs/design.md §12).
            if emitter:
                return spectrum_to_rgb([_CIE_MIN, _CIE_MAX], [v[0], v[0]], emitter=True)
            return np.repeat(v, 3)
        try:
            pairs = np.array(
                [[float(a) for a in s.split(":")] for s in re.split(r"\s*,\s*", text.strip()) if s]
            )
            if pairs.ndim != 2 or pairs.shape[1] != 2:
                raise ValueError
            return spectrum_to_rgb(pairs[:, 0], pairs[:, 1], emitter=emitter)
        except ValueError:
            self.fail(
                file, node, f"value={text[:60]!r}: not wavelength:value pairs in increasing order"
            )

    def transform(self, file: Path, node: _Node) -> np.ndarray:
        """A ``<transform>``: each element applied after (left of) the ones before."""
        m = np.eye(4)
        for op in node.children:
            a = lambda k, d="0", op=op: float(self.attr(file, op, k, d))  # noqa: E731
            try:
                if op.tag == "translate":
                    if "value" in op.attrs:
                        t = self.numbers(file, op, self.attr(file, op, "value"), "value")
                    else:
                        t = np.array([a("x"), a("y"), a("z")])
                    step = trimesh.transformations.translation_matrix(t)
                elif op.tag == "scale":
                    if "value" in op.attrs:
                        s = self.numbers(file, op, self.attr(file, op, "value"), "value")
                        s = np.broadcast_to(s, (3,)) if s.size in (1, 3) else s
                    else:
                        s = np.array([a("x", "1"), a("y", "1"), a("z", "1")])
                    step = np.diag([*s, 1.0])
                elif op.tag == "rotate":
                    if "value" in op.attrs:
                        axis = self.numbers(file, op, self.attr(file, op, "value"), "value")
                    else:
                        axis = np.array([a("x"), a("y"), a("z")])
                    if np.linalg.norm(axis) == 0:
                        self.fail(file, op, "rotation axis is zero")
                    step = trimesh.transformations.rotation_matrix(math.radians(a("angle")), axis)
                elif op.tag == "matrix":
                    v = self.numbers(file, op, self.need(file, op, "value"), "value")
                    if v.size == 9:
                        step = np.eye(4)
                        step[:3, :3] = v.reshape(3, 3)
                    elif v.size == 16:
                        step = v.reshape(4, 4)
                    else:
                        self.fail(file, op, f"expected 9 or 16 numbers, got {v.size}")
                elif op.tag == "lookat":
                    step = _look_at(
                        *(
                            self.numbers(file, op, self.need(file, op, k), k)
                            for k in ("origin", "target")
                        ),
                        self.numbers(file, op, self.attr(file, op, "up", "0, 1, 0"), "up"),
                        lambda msg, op=op: self.fail(file, op, msg),
                    )
                else:
                    self.fail(file, op, "unknown transform element")
            except ValueError as exc:
                if str(exc).startswith(str(file)):
                    raise
                self.fail(file, op, str(exc))
            m = step @ m
        if not np.all(np.isfinite(m)) or abs(np.linalg.det(m[:3, :3])) < 1e-300:
            self.fail(file, node, "transform is singular or not finite")
        return m


def _look_at(origin, target, up, fail) -> np.ndarray:
    """Mitsuba's look-at frame: columns left, up, forward, origin."""
    if origin.shape != (3,) or target.shape != (3,) or up.shape != (3,):
        fail("origin, target and up need 3 numbers each")
    d = target - origin
    if np.linalg.norm(d) == 0:
        fail("origin and target coincide")
    d = d / np.linalg.norm(d)
    left = np.cross(up, d)
    if np.linalg.norm(left) < 1e-12 * max(np.linalg.norm(up), 1e-300):
        fail("up is zero or parallel to the view direction")
    left /= np.linalg.norm(left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, np.cross(d, left), d, origin
    return m


#: BSDFs that hold another (the one whose albedo is used).
_WRAPPER_BSDFS = {"twosided", "mask", "bumpmap", "normalmap"}
#: BSDFs that scatter on both sides by themselves.
_TWO_SIDED_BSDFS = {"dielectric", "thindielectric", "roughdielectric"}
#: Properties whose colour approximates another BSDF's diffuse albedo.
_ALBEDO_KEYS = ("reflectance", "diffuse_reflectance", "base_color")


def _colour(v, p: _Plugin, key: str, notes: _Notes) -> np.ndarray:
    """An RGB colour from a float, an rgb/spectrum value or a texture plugin."""
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return np.full(3, float(v))
    if isinstance(v, np.ndarray):
        return v.astype(np.float64)
    if isinstance(v, _Plugin) and v.tag == "texture":
        if v.type == "bitmap" and "filename" in v.props:
            img_path = v.file.parent / str(v.props["filename"])
            try:
                from PIL import Image  # (a scikit-image dependency)

                with Image.open(img_path) as im:
                    mean = _image_mean(im, raw=bool(v.props.get("raw", False)))
                notes.approx(f"{v.label()}: bitmap {img_path.name} reduced to its mean colour")
                return mean
            except (OSError, ValueError) as exc:
                raise ValueError(f"{v.where()}: cannot read bitmap {img_path}: {exc}") from None
        if v.type == "checkerboard":
            c0 = _colour(v.props.get("color0", 0.4), v, "color0", notes)
            c1 = _colour(v.props.get("color1", 0.2), v, "color1", notes)
            notes.approx(f"{v.label()}: checkerboard reduced to its mean colour")
            return 0.5 * (c0 + c1)
        notes.approx(f"{v.label()}: texture replaced by grey 0.5")
        return np.full(3, 0.5)
    raise ValueError(f"{p.where()}: property {key!r} is not a colour: {v!r}")


def _bsdf(p: _Plugin, notes: _Notes) -> tuple[np.ndarray, bool]:
    """(albedo, two_sided) of a BSDF plugin (docs/design.md §12)."""
    nested = [c for c in p.children if c.tag == "bsdf"]
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
    key = next((k for k in _ALBEDO_KEYS if k in p.props), None)
    albedo = np.full(3, 0.5) if key is None else _colour(p.props[key], p, key, notes)
    notes.approx(f"{p.label()}: diffuse with albedo {'0.5' if key is None else key}")
    return albedo, p.type in _TWO_SIDED_BSDFS


def _emission(p: _Plugin, notes: _Notes) -> np.ndarray:
    """Radiance of an emitter attached to a shape (only ``area`` is one)."""
    if p.type != "area":
        notes.drop(f"{p.label()} on a shape")
        return np.zeros(3)
    if "radiance" not in p.props:
        raise ValueError(f"{p.where()}: missing property 'radiance'")
    return _colour(p.props["radiance"], p, "radiance", notes)


def _scene_emitter(p: _Plugin, data: SceneData, notes: _Notes) -> None:
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
        cutoff = float(p.props.get("cutoff_angle", 20.0))
        data.lights.append(
            {
                "type": "spot",
                "position": [float(x) for x in m[:3, 3]],
                "direction": unit(m[:3, 2]),
                "intensity": colour("intensity"),
                "cutoff_angle": cutoff,
                "beam_width": float(p.props.get("beam_width", 0.75 * cutoff)),
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
            image = p.file.parent / str(p.props["filename"])
            data.environment = {
                "image": str(image),
                "scale": float(p.props.get("scale", 1.0)),
                "to_world": m.tolist(),
            }
    else:
        notes.drop(f"{p.label()} at line {p.line}")


def _unit_disk(n: int = 128) -> tuple[np.ndarray, np.ndarray]:
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    v = np.concatenate([[[0.0, 0.0, 0.0]], np.stack([np.cos(t), np.sin(t), 0 * t], 1)])
    i = np.arange(n)
    return v, np.stack([np.zeros(n, np.int64), 1 + i, 1 + (i + 1) % n], 1)


def _canonical_shape(p: _Plugin) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
    radius = float(p.props.get("radius", 1.0))
    place = trimesh.transformations.translation_matrix(center) @ np.diag([radius] * 3 + [1.0])
    return np.asarray(s.vertices), np.asarray(s.faces), to_world @ place


def _shape_mesh(p: _Plugin) -> tuple[np.ndarray, np.ndarray, str | None]:
    """World-space (vertices, faces, source file) of a shape plugin."""
    if p.type in ("rectangle", "cube", "sphere", "disk"):
        v, f, m = _canonical_shape(p)
        source = None
    else:
        if "filename" not in p.props:
            raise ValueError(f"{p.where()}: missing property 'filename'")
        mesh_path = p.file.parent / str(p.props["filename"])
        if not mesh_path.exists():
            raise ValueError(f"{p.where()}: mesh file not found: {mesh_path}")
        if p.type == "serialized":
            v, f = read_serialized(mesh_path, int(p.props.get("shape_index", 0)))
        else:
            try:
                mesh = trimesh.load(
                    mesh_path, file_type=p.type, force="mesh", process=False, maintain_order=True
                )
                v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
            except Exception as exc:
                raise ValueError(f"{p.where()}: cannot load mesh {mesh_path}: {exc}") from None
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
    return v, np.ascontiguousarray(f), source


def _shape(p: _Plugin, index: int, notes: _Notes) -> list[MeshData]:
    """The meshes of a shape plugin: one, or two for a two-sided emitter."""
    if p.type not in ("obj", "ply", "serialized", "rectangle", "cube", "sphere", "disk"):
        notes.drop(f"{p.label()} at line {p.line}")
        return []
    bsdfs = [c for c in p.children if c.tag == "bsdf"]
    emitters = [c for c in p.children if c.tag == "emitter"]
    for c in p.children:
        if c.tag not in ("bsdf", "emitter"):
            notes.drop(f"{c.label()} inside {p.label()}")
    emission = np.zeros(3)
    for e in emitters:
        emission = emission + _emission(e, notes)
    if bsdfs:
        albedo, two_sided = _bsdf(bsdfs[0], notes)
    else:
        # Mitsuba's default BSDF: diffuse 0.5, black on an emitter.
        albedo, two_sided = np.full(3, 0.0 if emitters else 0.5), False
    v, f, source = _shape_mesh(p)
    name = p.id or (Path(source).stem if source else f"{p.type}{index}")
    albedo = _clamp_albedo(albedo, p.label(), notes)
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
    return [MeshData(name, v, f, albedo, emission, two_sided, source)]


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


def _sensor(p: _Plugin, notes: _Notes) -> dict | None:
    """Camera keyword arguments of a ``perspective`` or ``thinlens`` sensor."""
    if p.type not in ("perspective", "thinlens"):
        notes.drop(f"{p.label()} (no camera)")
        return None
    films = [c for c in p.children if c.tag == "film"]
    width = int(films[0].props.get("width", 768)) if films else 768
    height = int(films[0].props.get("height", 576)) if films else 576
    if width < 1 or height < 1:
        raise ValueError(f"{p.where()}: film size {width}x{height} must be positive")
    filters = [c for c in films[0].children if c.tag == "rfilter"] if films else []
    rfilter = filters[0].type if filters else "gaussian"  # Mitsuba's default
    pixel_filter = "box"
    if (
        rfilter == "gaussian"
        and float(filters[0].props.get("stddev", 0.5) if filters else 0.5) == 0.5
    ):
        pixel_filter = "gaussian"
    elif rfilter != "box":
        notes.approx(f"film rfilter {rfilter!r} (voxgi's pixels are box-filtered)")
    axis = str(p.props.get("fov_axis", "x")).lower()
    if axis not in ("x", "y", "smaller", "larger", "diagonal"):
        raise ValueError(
            f"{p.where()}: fov_axis={axis!r}; expected x, y, smaller, larger or diagonal"
        )
    if "fov" in p.props:
        fov = float(p.props["fov"])
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
        if float(p.props.get(k, 0.0)) != 0.0:
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
        cam["aperture"] = float(p.props.get("aperture_radius", 0.0))
        if "focus_distance" in p.props:
            cam["focus_distance"] = float(p.props["focus_distance"])
    return cam


def load_mitsuba(path) -> SceneData:
    """Read a Mitsuba 3 XML scene.

    Parameters
    ----------
    path : str or Path
        The ``.xml`` file; mesh, include and texture files are relative to
        the file that names them.

    Returns
    -------
    SceneData

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        Malformed XML, unknown elements or ids, bad values, missing mesh
        files: the message names the file, line and element.

    Warns
    -----
    SceneWarning
        One listing the approximated BSDFs and textures, one listing what was
        left out (emitters other than ``area``, other shapes and sensors).
    """
    path = Path(path)
    reader = _XmlReader(path)
    root = _parse_xml(path)
    version = root.attrs.get("version", "")
    # Mitsuba 2 and 3 share their XML; 0.x spelled property names differently
    if version and not version.startswith(("2.", "3.")):
        reader.notes.approx(f"scene version {version} read as Mitsuba 3 XML")
    try:
        return _read_mitsuba(reader, path, root)
    except RecursionError:
        raise ValueError(f"scene file {path}: elements nested too deeply") from None


def _read_mitsuba(reader: _XmlReader, path: Path, root: _Node) -> SceneData:
    data = SceneData()
    children = reader.scene_children(path, root)
    for file, node in children:
        if node.tag in _PLUGIN_TAGS and "id" in node.attrs:
            reader.pending[reader.attr(file, node, "id")] = (file, node)
    for file, node in children:
        if node.tag not in _PLUGIN_TAGS:
            reader.fail(file, node, "unknown top-level element")
        ident = reader.attr(file, node, "id")
        if ident in reader.ids and ident not in reader.pending:
            p = reader.ids[ident]  # read already, through a reference
        else:
            reader.pending.pop(ident, None)
            p = reader.plugin(file, node)
        if p.tag == "shape":
            data.meshes += _shape(p, len(data.meshes), reader.notes)
        elif p.tag == "sensor":
            if data.camera is None:
                data.camera = _sensor(p, reader.notes)
            else:
                reader.notes.drop(f"{p.label()} (only the first sensor is used)")
        elif p.tag == "emitter":
            if p.type != "area":  # (an area emitter is attached to shapes by reference)
                _scene_emitter(p, data, reader.notes)
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


def read_serialized(path, shape_index: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of one mesh of a Mitsuba ``.serialized`` file.

    The layout (Mitsuba's serialized shape documentation): per mesh a
    little-endian ``uint16`` 0x041C and version (3 or 4), then a zlib stream
    with ``uint32`` flags, (version 4) a NUL-terminated name, ``uint64``
    vertex and triangle counts, positions (float32, or float64 with flag
    0x2000), optional normals (0x0001), texture coordinates (0x0002) and
    colours (0x0008), then ``uint32`` indices (``uint64`` past 2^32
    vertices). Meshes are found by walking the streams from the start (each
    zlib stream knows its end), so the optional table of offsets at the end
    of the file is not needed.
    """
    path = Path(path)
    buf = path.read_bytes()

    def bad(msg):
        raise ValueError(f"serialized mesh {path}: {msg}")

    if shape_index < 0:
        bad(f"shape_index {shape_index} must be >= 0")
    offset, raw, version = 0, b"", 0
    for k in range(shape_index + 1):
        if offset + 4 > len(buf) or struct.unpack_from("<H", buf, offset)[0] != 0x041C:
            if k == 0:
                bad("not a Mitsuba serialized file (no 0x041C header)")
            bad(f"shape_index {shape_index} out of range: the file holds {k} mesh(es)")
        version = struct.unpack_from("<H", buf, offset + 2)[0]
        if version not in (3, 4):
            bad(f"mesh {k}: unsupported version {version}")
        stream = zlib.decompressobj()
        try:
            raw = stream.decompress(buf[offset + 4 :])
        except zlib.error as exc:
            bad(f"mesh {k}: corrupt zlib stream ({exc})")
        if not stream.eof:
            bad(f"mesh {k}: truncated zlib stream")
        offset = len(buf) - len(stream.unused_data)
    pos = 0

    def take(n):
        nonlocal pos
        if pos + n > len(raw):
            bad(f"mesh {shape_index}: truncated data")
        pos += n
        return raw[pos - n : pos]

    flags = struct.unpack("<I", take(4))[0]
    if version == 4:
        end = raw.find(b"\0", pos)
        if end < 0:
            bad(f"mesh {shape_index}: unterminated name")
        pos = end + 1
    nv, nf = struct.unpack("<QQ", take(16))
    real = np.float64 if flags & 0x2000 else np.float32
    rsize = np.dtype(real).itemsize
    v = np.frombuffer(take(nv * 3 * rsize), real).reshape(nv, 3).astype(np.float64)
    for flag, width in ((0x0001, 3), (0x0002, 2), (0x0008, 3)):
        if flags & flag:
            take(nv * width * rsize)
    itype = np.uint64 if nv > 0xFFFFFFFF else np.uint32
    f = np.frombuffer(take(nf * 3 * np.dtype(itype).itemsize), itype).reshape(nf, 3)
    if nf and f.max() >= nv:
        bad(f"mesh {shape_index}: face index {int(f.max())} >= vertex count {nv}")
    return v, f.astype(np.int64)


# -- OBJ with MTL ----------------------------------------------------------


def _parse_mtl(path: Path, notes: _Notes) -> dict[str, dict]:
    """``{material: {"Kd": (3,), "Ke": (3,), "map_Kd": Path}}`` of an MTL file."""
    mats: dict[str, dict] = {}
    cur = None
    for k, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
        parts = line.split("#", 1)[0].split()
        if not parts:
            continue
        key = parts[0]
        if key == "newmtl":
            cur = mats.setdefault(" ".join(parts[1:]), {})
        elif cur is None:
            continue
        elif key in ("Kd", "Ke"):
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


def load_obj(path) -> SceneData:
    """Read an OBJ file and its MTL materials: one mesh per material.

    ``Kd`` is the albedo (default 0.8 when the MTL gives none), ``Ke`` the
    emitted radiance; a ``map_Kd`` texture multiplies ``Kd`` by its mean
    linear colour. A missing MTL file or material gives grey 0.5. All
    surfaces are one-sided (OBJ has no flag for it).

    Raises
    ------
    FileNotFoundError, ValueError
        As :func:`load_mitsuba`, naming the OBJ or MTL file.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"scene file not found: {path}")
    notes = _Notes(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"scene file {path}: cannot be read as OBJ text ({exc})") from None
    mats: dict[str, dict] = {}
    for line in text.splitlines():
        if line.startswith("mtllib"):
            for name in line.split()[1:]:
                mtl = path.parent / name
                if mtl.exists():
                    mats.update(_parse_mtl(mtl, notes))
                else:
                    notes.approx(f"material library {name} not found: grey 0.5")
    try:
        loaded = trimesh.load(
            trimesh.util.wrap_as_stream(_absolute_obj_indices(text)),
            file_type="obj",
            resolver=trimesh.resolvers.FilePathResolver(path),
            process=False,
            group_material=True,
            maintain_order=True,
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
                albedo = albedo * _texture_mean(m["map_Kd"], path, notes, f"material {mat!r}")
        albedo = _clamp_albedo(albedo, f"material {mat!r}", notes)
        data.meshes.append(
            MeshData(
                str(mat or gname),
                np.asarray(g.vertices, np.float64),
                np.asarray(g.faces, np.int64),
                albedo,
                emission,
                False,
                str(path),
            )
        )
    if not data.meshes:
        raise ValueError(f"scene file {path}: the OBJ holds no faces")
    notes.emit()
    return data


def _texture_mean(img_path: Path, path: Path, notes: _Notes, what: str) -> np.ndarray:
    try:
        from PIL import Image  # (a scikit-image dependency)

        with Image.open(img_path) as im:
            mean = _image_mean(im)
    except (OSError, ValueError) as exc:
        notes.approx(f"{what}: texture {img_path.name} unreadable ({exc}): factor 1")
        return np.ones(3)
    notes.approx(f"{what}: texture {img_path.name} reduced to its mean colour")
    return mean


# -- glTF 2.0 --------------------------------------------------------------


def _gltf_json(path: Path) -> tuple[dict, bytes | None]:
    """The glTF JSON document (and a GLB's binary chunk)."""
    buf = path.read_bytes()
    binary = None
    if buf[:4] == b"glTF":
        if len(buf) < 20:
            raise ValueError(f"scene file {path}: truncated GLB header")
        n, kind = struct.unpack_from("<I4s", buf, 12)
        if kind != b"JSON":
            raise ValueError(f"scene file {path}: GLB's first chunk is not JSON")
        text = buf[20 : 20 + n]
        rest = buf[20 + n :]
        if len(rest) >= 8 and rest[4:8] == b"BIN\0":
            binary = rest[8 : 8 + struct.unpack_from("<I", rest, 0)[0]]
    else:
        text = buf
    try:
        doc = json.loads(text.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"scene file {path}: malformed glTF JSON: {exc}") from None
    if not isinstance(doc, dict) or "asset" not in doc:
        raise ValueError(f"scene file {path}: not a glTF 2.0 document (no 'asset')")
    return doc, binary


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
        try:
            cam = doc["cameras"][node["camera"]]
        except (KeyError, IndexError, TypeError):
            raise ValueError(
                f"scene file {path}: nodes[{i}]: camera {node['camera']!r} not in 'cameras'"
            ) from None
        if cam.get("type") != "perspective":
            continue
        persp = cam.get("perspective", {})
        where = f"scene file {path}: cameras[{node['camera']}]"
        yfov = persp.get("yfov")
        if not isinstance(yfov, (int, float)) or not 0 < yfov < math.pi:
            raise ValueError(f"{where}: yfov {yfov!r} must be in (0, pi) radians")
        m, j = np.eye(4), i
        while j is not None:
            m = _gltf_node_matrix(nodes[j], f"scene file {path}: nodes[{j}]") @ m
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


def _check_gltf_references(doc: dict, path: Path) -> None:
    """ValueError naming the element when a mesh or buffer points nowhere."""

    def table(key):
        t = doc.get(key, [])
        if not isinstance(t, list):
            raise ValueError(f"scene file {path}: '{key}' must be an array")
        return t

    accessors, views, buffers = table("accessors"), table("bufferViews"), table("buffers")

    def need(index, items, key, where):
        if not isinstance(index, int) or not 0 <= index < len(items):
            raise ValueError(
                f"scene file {path}: {where}: {key} {index!r} not in '{key}s' "
                f"({len(items)} of them)"
            )

    for m, mesh in enumerate(table("meshes")):
        for k, prim in enumerate(mesh.get("primitives", [])):
            where = f"meshes[{m}].primitives[{k}]"
            for name, index in prim.get("attributes", {}).items():
                need(index, accessors, "accessor", f"{where}.attributes.{name}")
            if "indices" in prim:
                need(prim["indices"], accessors, "accessor", f"{where}.indices")
    for a, acc in enumerate(accessors):
        if "bufferView" in acc:
            need(acc["bufferView"], views, "bufferView", f"accessors[{a}]")
    for v, view in enumerate(views):
        need(view.get("buffer"), buffers, "buffer", f"bufferViews[{v}]")
    for b, buf in enumerate(buffers):
        uri = buf.get("uri")
        if isinstance(uri, str) and not uri.startswith("data:"):
            if not (path.parent / uri).exists():
                raise ValueError(
                    f"scene file {path}: buffers[{b}]: file not found: {path.parent / uri}"
                )


def load_gltf(path) -> SceneData:
    """Read a glTF 2.0 scene (``.gltf`` or ``.glb``): one mesh per primitive.

    The albedo is ``baseColorFactor`` (times the mean linear colour of
    ``baseColorTexture``), the radiance ``emissiveFactor`` times
    ``KHR_materials_emissive_strength``; ``doubleSided`` gives a two-sided
    surface; node transforms are applied; the first perspective camera
    (``yfov``, ``aspectRatio``, 512 pixels high) becomes the camera.

    Raises
    ------
    FileNotFoundError, ValueError
        As :func:`load_mitsuba`, naming the file and the glTF element.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"scene file not found: {path}")
    doc, _ = _gltf_json(path)
    _check_gltf_references(doc, path)
    notes = _Notes(path)
    by_name: dict[str, list] = {}
    for k, m in enumerate(doc.get("materials", [])):
        by_name.setdefault(m.get("name", f"material{k}"), []).append(m)
    try:
        loaded = trimesh.load(path, force="scene", process=False)
        geoms = loaded.dump()
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
        if m is not None:
            pbr = m.get("pbrMetallicRoughness", {})
            base = np.asarray(pbr.get("baseColorFactor", [1, 1, 1, 1]), np.float64)[:3]
            emission = np.asarray(m.get("emissiveFactor", [0, 0, 0]), np.float64)
            strength = m.get("extensions", {}).get("KHR_materials_emissive_strength", {})
            emission = emission * float(strength.get("emissiveStrength", 1.0))
            two_sided = bool(m.get("doubleSided", False))
            # glTF's metallicFactor defaults to 1: a metal, read as diffuse
            metallic = pbr.get("metallicFactor", 1.0)
            if metallic or "metallicRoughnessTexture" in pbr:
                notes.approx(f"{where}: metallic {metallic} read as diffuse base colour")
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
                raise ValueError(
                    f"scene file {path}: {where}: bad baseColorFactor or emissiveFactor"
                )
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
        if has_texture:
            image = getattr(tm, "baseColorTexture", None)
            if image is not None:
                base = base * _image_mean(image)
                notes.approx(f"{where}: baseColorTexture reduced to its mean colour")
            else:
                notes.approx(f"{where}: baseColorTexture unreadable: factor 1")
        base = _clamp_albedo(base, where, notes)
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
            )
        )
    if not data.meshes:
        raise ValueError(f"scene file {path}: the glTF holds no triangles")
    notes.emit()
    return data


#: Loaders by file suffix (``.toml`` is read by :meth:`voxgi.Scene.load` itself).
LOADERS = {".xml": load_mitsuba, ".obj": load_obj, ".gltf": load_gltf, ".glb": load_gltf}
