"""A glTF 2.0 document read and checked before any of it is used.

Every part voxgi reads (meshes, accessors, buffer views, buffers, materials,
textures, images, nodes, cameras, lights) is checked for its JSON type,
its indices and its numbers, and an error names the file and the element's
JSON pointer (RFC 6901, ``/materials/0/extensions``). Buffers and images
are read through the scene's path policy and limits; an image's pixel count
is checked from its header.
"""

from __future__ import annotations

import base64
import binascii
import json
import math
import struct
from pathlib import Path

from ._limits import RefusedError
from ._paths import FileAccess
from .textures import open_image

__all__ = ["check_document", "read_document"]

#: The arrays of objects at the top of a glTF document that voxgi reads.
_TABLES = (
    "accessors",
    "bufferViews",
    "buffers",
    "cameras",
    "images",
    "materials",
    "meshes",
    "nodes",
    "samplers",
    "scenes",
    "textures",
)


def read_document(path: Path, access: FileAccess) -> tuple[dict, bytes, bytes | None]:
    """``(document, file bytes, GLB binary chunk or None)`` of a ``.gltf`` or ``.glb``."""
    buf = access.read_bytes(path, "scene file")
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
    except RecursionError:
        raise ValueError(
            f"scene file {path}: arrays or objects nested too deeply to be a glTF document"
        ) from None
    if not isinstance(doc, dict) or not isinstance(doc.get("asset"), dict):
        raise ValueError(f"scene file {path}: not a glTF 2.0 document (no 'asset' object)")
    return doc, buf, binary


class _Checker:
    """JSON-type, index and number checks that name the element by its pointer."""

    def __init__(self, doc: dict, path: Path):
        self.doc = doc
        self.path = path

    def fail(self, ptr: str, msg: str):
        raise ValueError(f"scene file {self.path}: {ptr or '/'}: {msg}")

    def kind(self, v, want: type | tuple, ptr: str, name: str):
        if isinstance(v, bool) and want is not bool and bool not in _tuple(want):
            self.fail(ptr, f"expected {name}, got {json.dumps(v)}")
        if not isinstance(v, want):
            self.fail(ptr, f"expected {name}, got {_json_kind(v)}")
        return v

    def obj(self, parent: dict, key: str, ptr: str) -> dict:
        return self.kind(parent.get(key, {}), dict, f"{ptr}/{key}", "an object")

    def objects(self, parent: dict, key: str, ptr: str) -> list[dict]:
        items = self.kind(parent.get(key, []), list, f"{ptr}/{key}", "an array")
        for i, item in enumerate(items):
            self.kind(item, dict, f"{ptr}/{key}/{i}", "an object")
        return items

    def index(self, parent: dict, key: str, table: str, ptr: str) -> None:
        if key in parent:
            self.ref(parent[key], table, f"{ptr}/{key}")

    def ref(self, v, table: str, ptr: str) -> None:
        """``v`` must index the array ``/table``."""
        n = len(self.doc.get(table, []))
        if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v < n:
            self.fail(ptr, f"{table[:-1]} {json.dumps(v)} not in /{table} ({n} of them)")

    def numbers(self, parent: dict, key: str, n: int, ptr: str, low=-math.inf) -> None:
        if key not in parent:
            return
        v = parent[key]
        ok = isinstance(v, list) and len(v) == n
        ok = ok and all(_finite(x) and x >= low for x in v)
        if not ok:
            rule = f"{n} finite numbers" + (f" >= {low:g}" if low > -math.inf else "")
            self.fail(f"{ptr}/{key}", f"expected {rule}, got {json.dumps(v)[:80]}")

    def number(self, parent: dict, key: str, ptr: str, low=-math.inf, high=math.inf) -> None:
        if key in parent and not (_finite(parent[key]) and low <= parent[key] <= high):
            self.fail(
                f"{ptr}/{key}",
                f"expected a finite number in [{low:g}, {high:g}], got {json.dumps(parent[key])}",
            )

    def count(self, parent: dict, key: str, ptr: str) -> None:
        v = parent.get(key, 0)
        if isinstance(v, bool) or not isinstance(v, int) or v < 0:
            self.fail(f"{ptr}/{key}", f"expected an integer >= 0, got {json.dumps(v)}")


def _tuple(want) -> tuple:
    return want if isinstance(want, tuple) else (want,)


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _json_kind(v) -> str:
    return {dict: "an object", list: "an array", str: "a string", type(None): "null"}.get(
        type(v), f"{type(v).__name__} {json.dumps(v)[:40]}"
    )


def check_document(doc: dict, path: Path, access: FileAccess, binary: bytes | None) -> None:
    """Check the parts of ``doc`` voxgi reads; ValueError naming file and pointer."""
    c = _Checker(doc, path)
    for key in _TABLES:
        c.objects(doc, key, "")
    ext = c.obj(doc, "extensions", "")
    lights = c.obj(ext, "KHR_lights_punctual", "/extensions")
    c.objects(lights, "lights", "/extensions/KHR_lights_punctual")
    _check_meshes(c, doc)
    _check_buffers(c, doc, access)
    _check_materials(c, doc)
    _check_nodes(c, doc)
    _check_cameras(c, doc)
    _check_images(c, doc, access, binary)


def _check_meshes(c: _Checker, doc: dict) -> None:
    for m, mesh in enumerate(doc.get("meshes", [])):
        for k, prim in enumerate(c.objects(mesh, "primitives", f"/meshes/{m}")):
            ptr = f"/meshes/{m}/primitives/{k}"
            attrs = c.obj(prim, "attributes", ptr)
            for name in attrs:
                c.index(attrs, name, "accessors", f"{ptr}/attributes")
            c.index(prim, "indices", "accessors", ptr)
            c.index(prim, "material", "materials", ptr)
    for a, acc in enumerate(doc.get("accessors", [])):
        c.index(acc, "bufferView", "bufferViews", f"/accessors/{a}")
        c.count(acc, "count", f"/accessors/{a}")
        c.count(acc, "byteOffset", f"/accessors/{a}")


def _check_buffers(c: _Checker, doc: dict, access: FileAccess) -> None:
    buffers = doc.get("buffers", [])
    for b, buf in enumerate(buffers):
        ptr = f"/buffers/{b}"
        c.count(buf, "byteLength", ptr)
        access.limits.check("file_bytes", buf.get("byteLength", 0), f"{c.path}: {ptr}/byteLength")
        uri = buf.get("uri")
        if uri is not None:
            c.kind(uri, str, f"{ptr}/uri", "a string")
            if not uri.startswith("data:"):
                _check_file(c, access, uri, f"{ptr}/uri", "buffer")
    for v, view in enumerate(doc.get("bufferViews", [])):
        ptr = f"/bufferViews/{v}"
        if "buffer" not in view:
            c.fail(ptr, "missing 'buffer'")
        c.index(view, "buffer", "buffers", ptr)
        c.count(view, "byteOffset", ptr)
        c.count(view, "byteLength", ptr)
        size = buffers[view["buffer"]].get("byteLength", 0)
        if view.get("byteOffset", 0) + view.get("byteLength", 0) > size:
            c.fail(ptr, f"byteOffset + byteLength beyond its buffer's byteLength {size}")


def _check_file(c: _Checker, access: FileAccess, uri: str, ptr: str, what: str) -> None:
    file = c.path.parent / uri
    try:
        access.check(file, what)
    except ValueError as exc:
        c.fail(ptr, str(exc))
    if not file.exists():
        c.fail(ptr, f"file not found: {file}")


def _check_materials(c: _Checker, doc: dict) -> None:
    for k, m in enumerate(doc.get("materials", [])):
        ptr = f"/materials/{k}"
        if "name" in m:
            c.kind(m["name"], str, f"{ptr}/name", "a string")
        pbr = c.obj(m, "pbrMetallicRoughness", ptr)
        c.numbers(pbr, "baseColorFactor", 4, f"{ptr}/pbrMetallicRoughness", low=0.0)
        c.number(pbr, "metallicFactor", f"{ptr}/pbrMetallicRoughness", 0.0, 1.0)
        tex = c.obj(pbr, "baseColorTexture", f"{ptr}/pbrMetallicRoughness")
        c.index(tex, "index", "textures", f"{ptr}/pbrMetallicRoughness/baseColorTexture")
        c.numbers(m, "emissiveFactor", 3, ptr, low=0.0)
        if "doubleSided" in m:
            c.kind(m["doubleSided"], bool, f"{ptr}/doubleSided", "true or false")
        ext = c.obj(m, "extensions", ptr)
        strength = c.obj(ext, "KHR_materials_emissive_strength", f"{ptr}/extensions")
        c.number(
            strength, "emissiveStrength", f"{ptr}/extensions/KHR_materials_emissive_strength", 0.0
        )
    for t, tex in enumerate(doc.get("textures", [])):
        c.index(tex, "source", "images", f"/textures/{t}")


def _check_nodes(c: _Checker, doc: dict) -> None:
    nodes = doc.get("nodes", [])
    parent: dict[int, int] = {}
    for i, node in enumerate(nodes):
        ptr = f"/nodes/{i}"
        children = c.kind(node.get("children", []), list, f"{ptr}/children", "an array")
        for j in range(len(children)):
            c.ref(children[j], "nodes", f"{ptr}/children/{j}")
            if children[j] in parent:
                c.fail(f"{ptr}/children/{j}", f"node {children[j]} has two parents")
            parent[children[j]] = i
        c.index(node, "camera", "cameras", ptr)
        c.index(node, "mesh", "meshes", ptr)
        c.numbers(node, "matrix", 16, ptr)
        c.numbers(node, "translation", 3, ptr)
        c.numbers(node, "rotation", 4, ptr)
        c.numbers(node, "scale", 3, ptr)
    for i in range(len(nodes)):
        j, steps = i, 0
        while j in parent:
            j, steps = parent[j], steps + 1
            if steps > len(nodes):
                c.fail(f"/nodes/{i}", "the node hierarchy holds a cycle")
    for s, scene in enumerate(doc.get("scenes", [])):
        ids = c.kind(scene.get("nodes", []), list, f"/scenes/{s}/nodes", "an array")
        for j in range(len(ids)):
            c.ref(ids[j], "nodes", f"/scenes/{s}/nodes/{j}")


def _check_cameras(c: _Checker, doc: dict) -> None:
    for k, cam in enumerate(doc.get("cameras", [])):
        ptr = f"/cameras/{k}"
        if cam.get("type") != "perspective":
            continue
        persp = c.obj(cam, "perspective", ptr)
        yfov = persp.get("yfov")
        if not _finite(yfov) or not 0 < yfov < math.pi:
            c.fail(f"{ptr}/perspective/yfov", f"{json.dumps(yfov)} must be in (0, pi) radians")
        # the image is 512 pixels high; its width must stay within a Camera's
        c.number(persp, "aspectRatio", f"{ptr}/perspective", 1 / 512, 64.0)


def _check_images(c: _Checker, doc: dict, access: FileAccess, binary: bytes | None) -> None:
    for k, image in enumerate(doc.get("images", [])):
        ptr = f"/images/{k}"
        uri = image.get("uri")
        if uri is not None:
            c.kind(uri, str, f"{ptr}/uri", "a string")
            if uri.startswith("data:"):
                try:
                    data = base64.b64decode(uri.split(",", 1)[-1], validate=False)
                except (binascii.Error, ValueError):
                    c.fail(f"{ptr}/uri", "malformed data URI")
            else:
                _check_file(c, access, uri, f"{ptr}/uri", "image")
                data = access.read_bytes(c.path.parent / uri, "image")
        elif "bufferView" in image:
            c.index(image, "bufferView", "bufferViews", ptr)
            view = doc["bufferViews"][image["bufferView"]]
            if binary is None or view["buffer"] != 0 or "uri" in doc["buffers"][0]:
                continue  # an external buffer: trimesh reads it through the policy
            start = view.get("byteOffset", 0)
            data = binary[start : start + view.get("byteLength", 0)]
        else:
            continue
        try:
            open_image(data, f"{c.path}: {ptr}", access.limits)
        except RefusedError:
            raise
        except ValueError:
            continue  # an unreadable image: the material's texture factor is left at 1
