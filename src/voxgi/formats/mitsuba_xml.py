"""Mitsuba 3 XML to plugins: elements with line numbers, defaults and ``$var``,
includes, references, values and transforms (docs/design.md §12)."""

from __future__ import annotations

import io
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from xml.parsers import expat

import numpy as np
import trimesh

from ._common import Notes
from ._paths import FileAccess
from .spectra import CIE_MAX, CIE_MIN, spectrum_to_rgb


@dataclass
class Node:
    tag: str
    attrs: dict
    line: int
    children: list = field(default_factory=list)


#: Deepest nesting of elements in one XML file (Mitsuba scenes nest a few levels).
MAX_XML_DEPTH = 256


def parse_xml(path: Path, access: FileAccess) -> Node:
    """A tree of :class:`Node` with line numbers (ElementTree has none).

    The file is read through ``access`` (its path policy and size limit);
    its elements count towards the scene's ``Limits.elements``; entity
    declarations (which Mitsuba never writes, and which can expand a few
    bytes into gigabytes) and nesting deeper than :data:`MAX_XML_DEPTH` are
    refused.
    """
    data = access.read_bytes(path, "scene file")
    parser = expat.ParserCreate()
    stack: list[Node] = []
    root: list[Node] = []

    def start(tag, attrs):
        line = parser.CurrentLineNumber
        access.count("elements", 1, f"{path}: line {line}: <{tag}>")
        if len(stack) >= MAX_XML_DEPTH:
            raise ValueError(
                f"{path}: line {line}: <{tag}>: elements nested more than {MAX_XML_DEPTH} deep"
            )
        node = Node(tag, dict(attrs), line)
        (stack[-1].children if stack else root).append(node)
        stack.append(node)

    def entity(name, *_):
        raise ValueError(
            f"{path}: line {parser.CurrentLineNumber}: <!ENTITY {name}>: entity declarations "
            "are not part of Mitsuba XML"
        )

    parser.StartElementHandler = start
    parser.EndElementHandler = lambda tag: stack.pop()
    parser.EntityDeclHandler = entity
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
    version = root[0].attrs.get("version")
    if version is not None and _version(version, path, root[0]) < (2, 0, 0):
        _upgrade_names(root[0])
    return root[0]


def _version(text: str, path: Path, node: Node) -> tuple[int, int, int]:
    """A file's ``version="major.minor.patch"`` as a tuple."""
    m = re.fullmatch(r"\s*(\d+)(?:\.(\d+))?(?:\.(\d+))?\s*", text)
    if m is None:
        raise ValueError(
            f"scene file {path}: line {node.line}: <scene version={text!r}>: "
            "not a version number like 0.5.0 or 3.0.0"
        )
    return tuple(int(g or 0) for g in m.groups())


def _underscore_case(name: str) -> str:
    """Mitsuba 3's upgrade of a camelCase parameter name: an underscore and
    lower case where a lower-case letter meets an upper-case one, the rest of
    that upper-case run lowered too (``toWorld`` to ``to_world``, ``intIOR`` to
    ``int_ior``; ``IOR`` and ``to_world`` stay)."""
    return re.sub(r"(?<=[a-z])([A-Z]+)", lambda m: "_" + m.group(1).lower(), name)


def _upgrade_names(node: Node) -> None:
    """Upgrade a Mitsuba 0.x file's tree in place, as Mitsuba 3 does for files
    of version below 2.0.0: every property name of every object in
    underscore_case, and a ``diffuse`` BSDF's ``diffuse_reflectance`` becomes
    its ``reflectance``. (Mitsuba 3 also turns a texture's ``uoffset``,
    ``vscale``, ... into ``to_uv``; voxgi reduces textures to their mean
    colour, which no placement changes.)"""
    for child in node.children:
        name = child.attrs.get("name")
        if name is not None and node.tag in PLUGIN_TAGS:
            name = _underscore_case(name)
            if node.attrs.get("type") == "diffuse" and name == "diffuse_reflectance":
                name = "reflectance"
            child.attrs["name"] = name
        _upgrade_names(child)


#: Plugin tags of Mitsuba 3 XML (objects with a ``type``).
PLUGIN_TAGS = {
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
class Plugin:
    tag: str
    type: str
    id: str | None
    line: int
    file: Path
    props: dict = field(default_factory=dict)
    children: list = field(default_factory=list)
    #: how the scene's files are read (path policy and limits)
    access: FileAccess | None = field(default=None, repr=False)

    def number(self, key: str, default=None, kind=float):
        """Property ``key`` (``default`` when absent) as a finite ``kind``; a
        ValueError naming the element when it is not one (a ``<string>``
        where a number belongs, say)."""
        v = self.props.get(key, default)
        try:
            if isinstance(v, (bool, np.ndarray, Plugin)):
                raise TypeError
            out = kind(v)
            if not math.isfinite(out):
                raise ValueError
        except (TypeError, ValueError, OverflowError):
            raise ValueError(f"{self.where()}: property {key!r} = {v!r} is not a number") from None
        return out

    def where(self) -> str:
        ident = f' id="{self.id}"' if self.id else ""
        return f'{self.file}: line {self.line}: <{self.tag} type="{self.type}"{ident}>'

    def label(self) -> str:
        return f"{self.tag} {self.type!r}" + (f" (id {self.id!r})" if self.id else "")

    def nested(self, tag: str) -> list[Plugin]:
        """The objects of kind ``tag`` inside, in the file's order, whether
        nested bare or by name (``<ref name="bsdf" id="..."/>``)."""
        return [
            c for c in [*self.children, *self.props.values()]
            if isinstance(c, Plugin) and c.tag == tag
        ]  # fmt: skip


class XmlReader:
    """Mitsuba 3 XML to plugins: defaults, ``$var``, includes, refs, values."""

    def __init__(self, path: Path, access: FileAccess):
        self.path = path
        self.access = access
        self.defaults: dict[str, str] = {}
        self.ids: dict[str, Plugin] = {}
        self.notes = Notes(path)
        self.search: list[Path] = []  # <path> folders, searched after the file's own
        self.pending: dict[str, tuple[Path, Node]] = {}  # top-level ids not read yet

    def resolve(self, file: Path, name: str) -> Path:
        """A file named in ``file``: beside it, the scene or a ``<path>`` folder.

        Only the places the path policy allows are looked at; when none
        holds the file, the path beside ``file`` (which reading then refuses
        or reports missing).
        """
        for folder in [file.parent, self.path.parent, *self.search]:
            candidate = folder / name
            if self.access.allowed(candidate) and candidate.exists():
                return candidate
        return file.parent / name

    def fail(self, file: Path, node: Node, msg: str):
        ident = "".join(
            f' {k}="{node.attrs[k]}"' for k in ("type", "name", "id") if k in node.attrs
        )
        raise ValueError(f"{file}: line {node.line}: <{node.tag}{ident}>: {msg}")

    def attr(self, file: Path, node: Node, key: str, default=None) -> str | None:
        v = node.attrs.get(key, default)
        if v is None:
            return None

        def sub(m):
            if m.group(1) not in self.defaults:
                self.fail(file, node, f"undefined parameter ${m.group(1)} in {key}={v!r}")
            return self.defaults[m.group(1)]

        return re.sub(r"\$(\w+)", sub, v)

    def need(self, file: Path, node: Node, key: str) -> str:
        v = self.attr(file, node, key)
        if v is None:
            self.fail(file, node, f"missing attribute {key!r}")
        return v

    def number(self, file: Path, node: Node, key: str, default: str) -> float:
        """The number in attribute ``key`` (``default`` when absent)."""
        text = self.attr(file, node, key, default)
        try:
            v = float(text)
        except ValueError:
            self.fail(file, node, f"{key}={text!r} is not a number")
        if not math.isfinite(v):
            self.fail(file, node, f"{key}={text!r} is not finite")
        return v

    def numbers(self, file: Path, node: Node, text: str, what: str) -> np.ndarray:
        try:
            out = np.array([float(s) for s in re.split(r"[,\s]+", text.strip()) if s], np.float64)
        except ValueError:
            self.fail(file, node, f"{what}={text!r} is not a list of numbers")
        if not np.all(np.isfinite(out)):
            self.fail(file, node, f"{what}={text!r} is not finite")
        return out

    # -- top level --------------------------------------------------------
    def scene_children(self, file: Path, root: Node, depth: int = 0) -> list[tuple[Path, Node]]:
        """Top-level elements, includes spliced in, defaults recorded."""
        out = []
        for node in root.children:
            if node.tag == "default":
                name = self.need(file, node, "name")
                self.defaults.setdefault(name, self.need(file, node, "value"))
            elif node.tag == "path":
                folder = file.parent / self.need(file, node, "value")
                try:
                    self.search.append(self.access.check(folder, "folder"))
                except ValueError as exc:
                    self.fail(file, node, str(exc))
            elif node.tag == "include":
                if depth > 8:
                    self.fail(file, node, "includes nested more than 8 deep")
                self.access.count("includes", 1, f"{file}: line {node.line}: <include>")
                sub = self.resolve(file, self.need(file, node, "filename"))
                try:
                    self.access.check(sub, "included file")
                except ValueError as exc:
                    self.fail(file, node, str(exc))
                try:
                    tree = parse_xml(sub, self.access)
                except FileNotFoundError:
                    self.fail(file, node, f"included file not found: {sub}")
                except ValueError as exc:
                    if str(exc).startswith((str(sub), f"scene file {sub}")):
                        raise
                    self.fail(file, node, str(exc))
                out += self.scene_children(sub, tree, depth + 1)
            else:
                out.append((file, node))
        return out

    # -- plugins and values -------------------------------------------------
    def plugin(self, file: Path, node: Node, emitter: bool = False) -> Plugin:
        kind = self.attr(file, node, "type")
        if kind is None:
            self.fail(file, node, "missing attribute 'type'")
        known = _MITSUBA_PLUGINS.get(node.tag)
        if known is not None and kind not in known:
            self.fail(file, node, f"unknown {node.tag} plugin {kind!r}")
        p = Plugin(node.tag, kind, self.attr(file, node, "id"), node.line, file)
        p.access = self.access
        emitter = emitter or node.tag == "emitter"
        for child in node.children:
            name = self.attr(file, child, "name")
            if child.tag in PLUGIN_TAGS:
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
                    named = self.resolve(file, p.props[name])
                    try:
                        p.props[name] = str(self.access.check(named, "file"))
                    except ValueError as exc:
                        self.fail(file, child, str(exc))
            else:
                self.fail(file, child, f"unknown element <{child.tag}> inside <{node.tag}>")
        if p.id is not None:
            self.ids[p.id] = p
        return p

    def value(self, file: Path, node: Node, emitter: bool):
        tag = node.tag
        if tag in ("point", "vector"):
            if "value" in node.attrs:
                v = self.numbers(file, node, self.attr(file, node, "value"), "value")
            else:
                v = np.array([self.number(file, node, k, "0") for k in ("x", "y", "z")])
            if v.shape != (3,):
                self.fail(file, node, f"expected 3 coordinates, got {v.tolist()}")
            return v
        text = self.attr(file, node, "value")
        if tag == "spectrum" and "type" in node.attrs:
            self.fail(file, node, f"spectrum plugin {node.attrs['type']!r} is not supported")
        if tag == "spectrum" and text is None and "filename" in node.attrs:
            spd = self.resolve(file, self.attr(file, node, "filename"))
            try:
                text = self.access.read_text(spd, "spectrum file")
                pairs = np.loadtxt(io.StringIO(text), comments="#", ndmin=2)
                if pairs.shape[1] != 2:
                    raise ValueError(f"expected 2 columns, got {pairs.shape[1]}")
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
                return spectrum_to_rgb([CIE_MIN, CIE_MAX], [v[0], v[0]], emitter=True)
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

    def transform(self, file: Path, node: Node) -> np.ndarray:
        """A ``<transform>``: each element applied after (left of) the ones before."""
        m = np.eye(4)
        for op in node.children:
            a = lambda k, d="0", op=op: self.number(file, op, k, d)  # noqa: E731
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
                    step = look_at(
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
        # singular relative to its own scale (a scene in any unit has transforms)
        lin = m[:3, :3] / max(float(np.abs(m[:3, :3]).max()), 1e-300)
        det, norms = abs(np.linalg.det(lin)), np.prod(np.linalg.norm(lin, axis=0))
        if not np.all(np.isfinite(m)) or not det > 1e-12 * norms:
            self.fail(file, node, "transform is singular or not finite")
        return m


def look_at(origin, target, up, fail) -> np.ndarray:
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
