"""Hostile and broken scene files, each read in a child process under limits.

Every probe below writes a small file (or a few) at test time and reads it
in a forked child of a server process that runs under a 2 GiB address-space
limit (``RLIMIT_AS``); the parent kills a child still running after 30 s.
Each probe must end in a ``ValueError`` or ``TypeError`` whose message names
the file and the element (the probe's pattern), or load where the file is
valid. None may be killed (by the limit, a signal or the timeout), and none
may raise its peak resident memory by more than twice what the scene
legitimately needs plus 64 MiB: the floor covers a Python exception, the
readers' lazily imported modules and numpy's temporaries.

``python -m pytest -s tests/test_hostile_files.py`` prints the table.
"""

from __future__ import annotations

import base64
import json
import os
import struct
import subprocess
import sys
import textwrap
import zlib
from pathlib import Path

import numpy as np
import pytest

LIMIT_AS = 2 << 30
TIMEOUT_S = 30
FLOOR_MB = 64
LOADS = None  # the pattern of a probe whose file is valid

#: name -> (build(folder) -> (call, path, kwargs), pattern or LOADS, legitimate MB)
PROBES: dict = {}


def probe(name: str, pattern: str | None, need_mb: float = 0.0):
    def register(build):
        PROBES[name] = (build, pattern, need_mb)
        return build

    return register


# -- small files -------------------------------------------------------------------


def _xml(folder: Path, body: str, name: str = "scene.xml") -> Path:
    path = folder / name
    path.write_text(f'<scene version="3.0.0">\n{body}\n</scene>\n')
    return path


RECT = '<shape type="rectangle"/>'
TRI_OBJ = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"


def _png(path: Path, width: int, height: int, mode: str = "L", rows: bool = True) -> Path:
    """A PNG of zeros written row by row (no image in memory); ``rows=False``
    writes the header and a token of pixel data (a file refused from its header)."""
    colour, channels = {"L": (0, 1), "RGB": (2, 3)}[mode]

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data))
            + kind
            + data
            + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
        )

    ihdr = struct.pack(">IIBBBBB", width, height, 8, colour, 0, 0, 0)
    z = zlib.compressobj(9)
    row = bytes(1 + width * channels)
    data = b""
    if rows:
        block = row * max(1, (1 << 22) // len(row))
        per = len(block) // len(row)
        parts = [z.compress(block) for _ in range(height // per)]
        parts.append(z.compress(row * (height % per)))
        data = b"".join(parts)
    data += z.flush()
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", data) + chunk(b"IEND", b"")
    )
    return path


def _serialized(nv: int, nf: int, payload: bytes = b"", extra_zeros: int = 0) -> bytes:
    """One version-4 serialized mesh whose header claims ``nv`` vertices and ``nf``
    triangles, followed by ``payload`` and ``extra_zeros`` zero bytes in the stream."""
    z = zlib.compressobj(9)
    out = z.compress(struct.pack("<I", 0x1000) + b"m\0" + struct.pack("<QQ", nv, nf) + payload)
    if extra_zeros:
        # after a full flush the compressor starts afresh: every later block of
        # zeros deflates to the same bytes (the stream's checksum is then wrong,
        # which a reader that stops at the header's counts never reaches)
        chunk = bytes(1 << 22)
        out += z.compress(chunk) + z.flush(zlib.Z_FULL_FLUSH)
        again = z.compress(chunk) + z.flush(zlib.Z_FULL_FLUSH)
        out += again * (extra_zeros // len(chunk) - 1)
    return struct.pack("<HH", 0x041C, 4) + out + z.flush()


def _tri_payload() -> bytes:
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "<f4")
    return v.tobytes() + np.array([[0, 1, 2]], "<u4").tobytes()


def _gltf(folder: Path, patch=None, name: str = "scene.gltf") -> Path:
    """A one-triangle glTF (buffer in a data URI), changed by ``patch(doc)``."""
    blob = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "<f4").tobytes()
    blob += np.array([0, 1, 2, 0], "<u2").tobytes()
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [
            {
                "byteLength": len(blob),
                "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode(),
            }
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 6},
        ],
        "accessors": [
            {
                "bufferView": 0,
                "componentType": 5126,
                "count": 3,
                "type": "VEC3",
                "min": [0, 0, 0],
                "max": [1, 1, 0],
            },
            {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"},
        ],
        "materials": [{"name": "m", "pbrMetallicRoughness": {"metallicFactor": 0}}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}],
        "scene": 0,
    }
    if patch is not None:
        patch(doc)
    path = folder / name
    path.write_text(json.dumps(doc))
    return path


def _toml(folder: Path, text: str, mesh: str | None = "tri.obj") -> Path:
    if mesh == "tri.obj":
        (folder / "tri.obj").write_text(TRI_OBJ)
    path = folder / "scene.toml"
    path.write_text(text)
    return path


def _load(path, **kw):
    return ("load", str(path), kw)


# -- Mitsuba XML --------------------------------------------------------------------


@probe(
    'xml: <point x="abc"/>',
    r"scene\.xml: line 3: <point name=\"position\">: x='abc' is not a number",
)
def _(d):
    return _load(
        _xml(d, '<emitter type="point">\n<point name="position" x="abc"/></emitter>' + RECT)
    )


@probe("xml: unclosed element", r"scene\.xml: malformed XML.*line")
def _(d):
    (d / "scene.xml").write_text('<scene version="3.0.0"><shape type="rectangle">')
    return _load(d / "scene.xml")


@probe("xml: root not <scene>", r"scene\.xml: line 1: expected a <scene> root")
def _(d):
    (d / "scene.xml").write_text("<mesh/>")
    return _load(d / "scene.xml")


@probe("xml: unknown plugin", r"scene\.xml: line 2: <shape type=\"teapot\">: unknown shape plugin")
def _(d):
    return _load(_xml(d, '<shape type="teapot"/>'))


@probe("xml: unknown reference", r"scene\.xml: line 2: <ref id=\"nowhere\">: unknown id")
def _(d):
    return _load(_xml(d, '<shape type="rectangle"><ref id="nowhere"/></shape>'))


@probe(
    "xml: 9 files including the next 10 times", r"inc\d\.xml: line 2: <include>: 10,001 included"
)
def _(d):
    for k in range(1, 9):
        (d / f"inc{k}.xml").write_text(
            '<scene version="3.0.0">\n'
            + f'<include filename="inc{k + 1}.xml"/>' * 10
            + "\n</scene>"
        )
    _xml(d, RECT, "inc9.xml")
    return _load(_xml(d, '<include filename="inc1.xml"/>'))


@probe("xml: include /dev/zero", r"scene\.xml: line 2: <include>: included file /dev/zero: outside")
def _(d):
    return _load(_xml(d, '<include filename="/dev/zero"/>' + RECT))


@probe("xml: include /dev/zero, outside allowed", r"/dev/zero: not a regular file \(a device\)")
def _(d):
    return _load(_xml(d, '<include filename="/dev/zero"/>' + RECT), allow_outside=True)


@probe("xml: include a FIFO", r"fifo\.xml: not a regular file \(a FIFO\)")
def _(d):
    os.mkfifo(d / "fifo.xml")
    return _load(_xml(d, '<include filename="fifo.xml"/>' + RECT))


@probe("xml: include itself", r"scene\.xml: line 2: <include>: includes nested more than 8 deep")
def _(d):
    return _load(_xml(d, '<include filename="scene.xml"/>' + RECT))


@probe("xml: include missing", r"scene\.xml: line 2: <include>: included file not found")
def _(d):
    return _load(_xml(d, '<include filename="gone.xml"/>' + RECT))


@probe("xml: include ../", r"scene\.xml: line 2: <include>: included file .*other\.xml: outside")
def _(d):
    (d / "sub").mkdir()
    _xml(d, RECT, "other.xml")
    return _load(_xml(d / "sub", '<include filename="../other.xml"/>'))


@probe("xml: include a symlink that leaves the folder", r"link\.xml: outside the folders")
def _(d):
    (d / "sub").mkdir()
    _xml(d, RECT, "other.xml")
    (d / "sub" / "link.xml").symlink_to(d / "other.xml")
    return _load(_xml(d / "sub", '<include filename="link.xml"/>'))


@probe("xml: include ../ from a search path", LOADS)
def _(d):
    (d / "sub").mkdir()
    _xml(d, RECT, "other.xml")
    return _load(_xml(d / "sub", '<include filename="../other.xml"/>'), search_paths=[d])


@probe("xml: entity expansion", r"scene\.xml: line 2: <!ENTITY a>: entity declarations")
def _(d):
    (d / "scene.xml").write_text(
        '<?xml version="1.0"?>\n<!DOCTYPE scene [<!ENTITY a "aaaaaaaaaa">'
        + "".join(
            f'<!ENTITY {c} "&{p};&{p};&{p};&{p};&{p};&{p};&{p};&{p};&{p};&{p};">'
            for p, c in zip("abcdefgh", "bcdefghi", strict=True)
        )
        + ']>\n<scene version="3.0.0"><string name="x" value="&i;"/></scene>'
    )
    return _load(d / "scene.xml")


@probe("xml: 100,000 nested elements", r"scene\.xml: line 1: <bsdf>: elements nested more than 256")
def _(d):
    (d / "scene.xml").write_text('<scene version="3.0.0">' + "<bsdf>" * 100_000)
    return _load(d / "scene.xml")


@probe("xml: 20,000 elements, limit 10,000", r"scene\.xml: line 1: <shape>: 10,001 XML elements")
def _(d):
    from voxgi.formats import Limits

    path = _xml(d, "")
    path.write_text('<scene version="3.0.0">' + RECT * 20_000 + "</scene>")
    return _load(path, limits=Limits(elements=10_000))


@probe(
    "xml: mesh /dev/zero, outside allowed",
    r"scene\.xml: line 2: <shape type=\"obj\">: mesh file /dev/zero: not a regular",
)
def _(d):
    body = '<shape type="obj"><string name="filename" value="/dev/zero"/></shape>'
    return _load(_xml(d, body), allow_outside=True)


@probe(
    "xml: mesh /etc/passwd",
    r"scene\.xml: line 2: <string name=\"filename\">: file /etc/passwd: outside",
)
def _(d):
    return _load(_xml(d, '<shape type="obj"><string name="filename" value="/etc/passwd"/></shape>'))


@probe("xml: mesh missing", r"scene\.xml: line 2: <shape type=\"ply\">: mesh file not found")
def _(d):
    return _load(_xml(d, '<shape type="ply"><string name="filename" value="gone.ply"/></shape>'))


def _serialized_scene(d: Path, data: bytes) -> tuple:
    (d / "m.serialized").write_bytes(data)
    body = '<shape type="serialized"><string name="filename" value="m.serialized"/></shape>'
    return _load(_xml(d, body))


@probe(
    "serialized: header claims 6 GiB",
    r"m\.serialized: mesh 0 \(536,870,912 vertices.*above the limit",
)
def _(d):
    return _serialized_scene(d, _serialized(1 << 29, 0))


@probe(
    "serialized: header claims 1 GiB from 1 KiB", r"m\.serialized: mesh 0 .*more than zlib can hold"
)
def _(d):
    return _serialized_scene(d, _serialized(1 << 26, 1 << 24))


@probe(
    "serialized: 256 MiB of zeros behind a one-triangle header",
    r"m\.serialized: mesh 0: the stream holds more data",
)
def _(d):
    return _serialized_scene(d, _serialized(3, 1, _tri_payload(), extra_zeros=256 << 20))


@probe("serialized: truncated stream", r"m\.serialized: mesh 0: truncated")
def _(d):
    return _serialized_scene(d, _serialized(3, 1, _tri_payload())[:-12])


@probe(
    "serialized: face index past the vertices",
    r"m\.serialized: mesh 0: face index 7 >= vertex count 3",
)
def _(d):
    v = np.zeros((3, 3), "<f4").tobytes() + np.array([[0, 1, 7]], "<u4").tobytes()
    return _serialized_scene(d, _serialized(3, 1, v))


@probe("serialized: not serialized", r"m\.serialized: not a Mitsuba serialized file")
def _(d):
    return _serialized_scene(d, b"PK\x03\x04 a zip, say")


@probe("serialized: one valid triangle", LOADS)
def _(d):
    return _serialized_scene(d, _serialized(3, 1, _tri_payload()))


def _bitmap_scene(d: Path, image: str) -> tuple:
    body = (
        f'<shape type="rectangle"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
        f'<string name="filename" value="{image}"/></texture></bsdf></shape>'
    )
    return _load(_xml(d, body))


@probe("xml: 12000x12000 PNG texture (140 KB)", LOADS, need_mb=144)
def _(d):
    _png(d / "big.png", 12000, 12000)
    return _bitmap_scene(d, "big.png")


@probe(
    "xml: 20000x20000 PNG texture",
    r"line 2: <texture type=\"bitmap\">: cannot read bitmap .*huge\.png.*400,000,000 pixels, above the limit",  # noqa: E501
)
def _(d):
    _png(d / "huge.png", 20000, 20000, rows=False)
    return _bitmap_scene(d, "huge.png")


@probe(
    "xml: texture that is not an image",
    r"<texture type=\"bitmap\">: cannot read bitmap .*notes\.png: .*not an image",
)
def _(d):
    (d / "notes.png").write_text("just text")
    return _bitmap_scene(d, "notes.png")


@probe(
    "xml: texture a FIFO", r"<texture type=\"bitmap\">: cannot read bitmap .*pipe\.png: .*a FIFO"
)
def _(d):
    os.mkfifo(d / "pipe.png")
    return _bitmap_scene(d, "pipe.png")


@probe(
    "xml: spectrum file a FIFO",
    r"scene\.xml: line 3: <spectrum name=\"reflectance\">: cannot read spectrum file .*spd: .*a FIFO",  # noqa: E501
)
def _(d):
    os.mkfifo(d / "a.spd")
    return _load(
        _xml(
            d,
            '<shape type="rectangle"><bsdf type="diffuse">\n'
            '<spectrum name="reflectance" filename="a.spd"/></bsdf></shape>',
        )
    )


@probe("xml: emission 3e38", r"scene\.xml: mesh 'rectangle0': emission .*beyond float32")
def _(d):
    body = '<shape type="rectangle"><emitter type="area"><rgb name="radiance" value="3e38"/></emitter></shape>'  # noqa: E501
    return _load(_xml(d, body + '<shape type="cube"/>'))


@probe("xml: camera at scale 1e-30", LOADS)
def _(d):
    body = (
        '<sensor type="perspective"><transform name="to_world">'
        '<lookat origin="0, 0, 1e-30" target="0, 0, 0" up="0, 1, 0"/></transform></sensor>'
        '<shape type="rectangle"><transform name="to_world"><scale value="1e-30"/></transform></shape>'  # noqa: E501
    )
    return _load(_xml(d, body))


@probe('xml: fov "abc"', r"scene\.xml: line 2: <sensor type=\"perspective\">: could not convert")
def _(d):
    return _load(
        _xml(d, '<sensor type="perspective"><string name="fov" value="abc"/></sensor>' + RECT)
    )


@probe(
    "xml: integer 1.5",
    r"scene\.xml: line 3: <integer name=\"width\">: value='1\.5' is not an integer",
)
def _(d):
    return _load(
        _xml(
            d,
            '<sensor type="perspective"><film type="hdrfilm">\n'
            '<integer name="width" value="1.5"/></film></sensor>' + RECT,
        )
    )


@probe("xml: film 10^9 pixels wide", r"scene\.xml: \[camera\]: Camera\.width: must be <= 32768")
def _(d):
    return _load(
        _xml(
            d,
            '<sensor type="perspective"><film type="hdrfilm">'
            '<integer name="width" value="1000000000"/></film></sensor>' + RECT,
        )
    )


@probe("xml: scale 0", r"scene\.xml: line 2: <transform name=\"to_world\">: transform is singular")
def _(d):
    return _load(
        _xml(
            d,
            '<shape type="rectangle"><transform name="to_world"><scale value="0"/></transform></shape>',  # noqa: E501
        )
    )


@probe("xml: <path> to /", r"scene\.xml: line 2: <path>: folder /: outside")
def _(d):
    return _load(_xml(d, '<path value="/"/>' + RECT))


@probe("xml: relative path from another folder", LOADS)
def _(d):
    (d / "room" / "models").mkdir(parents=True)
    (d / "room" / "models" / "m.obj").write_text(TRI_OBJ)
    _xml(d / "room", '<shape type="obj"><string name="filename" value="models/m.obj"/></shape>')
    return ("load_relative", str(d), {"path": "room/scene.xml"})


@probe("xml: one mesh all degenerate beside a good one", LOADS)
def _(d):
    (d / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    body = '<shape type="obj" id="flat"><string name="filename" value="flat.obj"/></shape>'
    return _load(_xml(d, body + RECT))


# -- OBJ and MTL ------------------------------------------------------------------


def _obj(d: Path, head: str = "", body: str = TRI_OBJ) -> Path:
    path = d / "mesh.obj"
    path.write_text(head + body)
    return path


@probe(
    "obj: mtllib /dev/zero",
    r"mesh\.obj: line 1: mtllib /dev/zero: material library /dev/zero: outside",
)
def _(d):
    return _load(_obj(d, "mtllib /dev/zero\n"))


@probe(
    "obj: mtllib /dev/zero, outside allowed",
    r"mesh\.obj: line 1: mtllib /dev/zero: .*not a regular file",
)
def _(d):
    return _load(_obj(d, "mtllib /dev/zero\n"), allow_outside=True)


@probe("obj: mtllib ../", r"mesh\.obj: line 1: mtllib \.\./m\.mtl: .*outside")
def _(d):
    (d / "sub").mkdir()
    (d / "m.mtl").write_text("newmtl a\nKd 1 0 0\n")
    return _load(_obj(d / "sub", "mtllib ../m.mtl\n"))


@probe("obj: Kd not numbers", r"m\.mtl: line 2: Kd: not numbers")
def _(d):
    (d / "m.mtl").write_text("newmtl a\nKd red green blue\n")
    return _load(_obj(d, "mtllib m.mtl\nusemtl a\n"))


def _mtl_texture(d: Path, image: str) -> tuple:
    (d / "m.mtl").write_text(f"newmtl a\nKd 1 1 1\nmap_Kd {image}\n")
    return _load(_obj(d, "mtllib m.mtl\nusemtl a\n"))


@probe(
    "obj: map_Kd 20000x20000 PNG",
    r"texture .*huge\.png \(20000x20000\): 400,000,000 pixels, above the limit",
)
def _(d):
    _png(d / "huge.png", 20000, 20000, rows=False)
    return _mtl_texture(d, "huge.png")


@probe("obj: map_Kd 6000x6000 RGB PNG", LOADS, need_mb=108)
def _(d):
    _png(d / "big.png", 6000, 6000, mode="RGB")
    return _mtl_texture(d, "big.png")


@probe("obj: binary bytes", r"mesh\.obj: cannot be read as OBJ text")
def _(d):
    (d / "mesh.obj").write_bytes(bytes(range(256)) * 4)
    return _load(d / "mesh.obj")


@probe("obj: no faces", r"mesh\.obj: the OBJ holds no faces")
def _(d):
    return _load(_obj(d, body="v 0 0 0\nv 1 0 0\n"))


@probe("obj: NaN vertex", r"mesh\.obj: mesh .*vertex 2 is not finite")
def _(d):
    return _load(_obj(d, body="v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n"))


@probe("obj: every face degenerate", r"mesh\.obj: no mesh with a face that is not degenerate")
def _(d):
    return _load(_obj(d, body="v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n"))


@probe("obj: the scene file is a FIFO", r"mesh\.obj: not a regular file \(a FIFO\)")
def _(d):
    os.mkfifo(d / "mesh.obj")
    return _load(d / "mesh.obj")


@probe("obj: the scene file is a folder", r"mesh\.obj: not a regular file \(a folder\)")
def _(d):
    (d / "mesh.obj").mkdir()
    return _load(d / "mesh.obj")


@probe("obj: emission 3e38", r"mesh\.obj: mesh 'a': emission .*beyond float32")
def _(d):
    (d / "m.mtl").write_text("newmtl a\nKd 0.5 0.5 0.5\nKe 3e38 3e38 3e38\n")
    return _load(_obj(d, "mtllib m.mtl\nusemtl a\n"))


# -- glTF ---------------------------------------------------------------------------


@probe('gltf: "extensions": []', r"scene\.gltf: /extensions: expected an object, got an array")
def _(d):
    return _load(_gltf(d, lambda doc: doc.update(extensions=[])))


@probe('gltf: "materials": [1]', r"scene\.gltf: /materials/0: expected an object, got int 1")
def _(d):
    return _load(_gltf(d, lambda doc: doc.update(materials=[1])))


@probe('gltf: "primitives": [1]', r"scene\.gltf: /meshes/0/primitives/0: expected an object")
def _(d):
    return _load(_gltf(d, lambda doc: doc["meshes"][0].update(primitives=[1])))


@probe(
    "gltf: aspectRatio Infinity",
    r"scene\.gltf: /cameras/0/perspective/aspectRatio: expected a finite number",
)
def _(d):
    def patch(doc):
        doc["cameras"] = [
            {"type": "perspective", "perspective": {"yfov": 0.8, "aspectRatio": float("inf")}}
        ]
        doc["nodes"].append({"camera": 0})

    return _load(_gltf(d, patch))


@probe("gltf: JSON nested 100,000 deep", r"scene\.gltf: arrays or objects nested too deeply")
def _(d):
    (d / "scene.gltf").write_text('{"asset": ' + "[" * 100_000 + "]" * 100_000 + "}")
    return _load(d / "scene.gltf")


@probe("gltf: buffer ../", r"scene\.gltf: /buffers/0/uri: buffer .*b\.bin: outside")
def _(d):
    (d / "sub").mkdir()
    (d / "b.bin").write_bytes(bytes(44))
    return _load(_gltf(d / "sub", lambda doc: doc["buffers"][0].update(uri="../b.bin")))


@probe("gltf: buffer /dev/zero, outside allowed", r"/dev/zero: not a regular file")
def _(d):
    return _load(
        _gltf(d, lambda doc: doc["buffers"][0].update(uri="/dev/zero")), allow_outside=True
    )


@probe("gltf: buffer missing", r"scene\.gltf: /buffers/0/uri: file not found")
def _(d):
    return _load(_gltf(d, lambda doc: doc["buffers"][0].update(uri="gone.bin")))


@probe(
    "gltf: accessor out of range",
    r"scene\.gltf: /meshes/0/primitives/0/attributes/POSITION: accessor 9",
)
def _(d):
    return _load(
        _gltf(d, lambda doc: doc["meshes"][0]["primitives"][0]["attributes"].update(POSITION=9))
    )


@probe(
    "gltf: node hierarchy with a cycle", r"scene\.gltf: /nodes/0: the node hierarchy holds a cycle"
)
def _(d):
    return _load(
        _gltf(d, lambda doc: doc.update(nodes=[{"mesh": 0, "children": [1]}, {"children": [0]}]))
    )


@probe(
    "gltf: bufferView beyond its buffer",
    r"scene\.gltf: /bufferViews/0: byteOffset \+ byteLength beyond",
)
def _(d):
    return _load(_gltf(d, lambda doc: doc["bufferViews"][0].update(byteLength=4000)))


@probe("gltf: image 20000x20000", r"scene\.gltf: /images/0 \(20000x20000\): 400,000,000 pixels")
def _(d):
    _png(d / "huge.png", 20000, 20000, rows=False)
    return _load(_gltf(d, lambda doc: doc.update(images=[{"uri": "huge.png"}])))


@probe(
    "gltf: emissiveStrength Infinity",
    r"scene\.gltf: /materials/0/extensions/KHR_materials_emissive_strength/emissiveStrength",
)
def _(d):
    ext = {"KHR_materials_emissive_strength": {"emissiveStrength": float("inf")}}
    return _load(_gltf(d, lambda doc: doc["materials"][0].update(extensions=ext)))


@probe("gltf: yfov 4", r"scene\.gltf: /cameras/0/perspective/yfov: 4 must be in \(0, pi\)")
def _(d):
    def patch(doc):
        doc["cameras"] = [{"type": "perspective", "perspective": {"yfov": 4}}]
        doc["nodes"].append({"camera": 0})

    return _load(_gltf(d, patch))


@probe("glb: truncated header", r"scene\.glb: truncated GLB header")
def _(d):
    (d / "scene.glb").write_bytes(b"glTF\x02\x00\x00\x00")
    return _load(d / "scene.glb")


@probe("gltf: one valid triangle", LOADS)
def _(d):
    return _load(_gltf(d))


# -- TOML -----------------------------------------------------------------------


@probe(
    "toml: mesh /dev/zero", r"scene\.toml: object #0: mesh file /dev/zero: outside .* \(line 2\)"
)
def _(d):
    return _load(_toml(d, '[[object]]\nmesh = "/dev/zero"\n', mesh=None))


@probe(
    "toml: mesh /dev/zero, outside allowed",
    r"scene\.toml: object #0: mesh file /dev/zero: not a regular file .*\(line 2\)",
)
def _(d):
    return _load(_toml(d, '[[object]]\nmesh = "/dev/zero"\n', mesh=None), allow_outside=True)


@probe(
    "toml: mesh a FIFO",
    r"scene\.toml: object #0: mesh file .*pipe\.obj: not a regular file \(a FIFO\)",
)
def _(d):
    os.mkfifo(d / "pipe.obj")
    return _load(_toml(d, '[[object]]\nmesh = "pipe.obj"\n', mesh=None))


@probe("toml: arrays nested 100,000 deep", r"scene\.toml: arrays or tables nested too deeply")
def _(d):
    return _load(_toml(d, "a = " + "[" * 100_000 + "]" * 100_000 + "\n", mesh=None))


@probe(
    "toml: a JSON file",
    r"scene\.json: not a scene file voxgi reads: .*\.toml.*\.xml.*\.obj.*\.gltf",
)
def _(d):
    (d / "scene.json").write_text('{"object": []}')
    return _load(d / "scene.json")


@probe(
    "toml: albedo 2 on line 4",
    r"scene\.toml: object #0: Material\.albedo: value 2\.0 is outside .*\(line 4\)",
)
def _(d):
    return _load(_toml(d, '[[object]]\nmesh = "tri.obj"\n\nalbedo = 2.0\n'))


@probe(
    "toml: environment image a FIFO",
    r"scene\.toml: \[environment\]: environment image .*sky\.exr: not a regular file \(a FIFO\) \(line 5\)",  # noqa: E501
)
def _(d):
    os.mkfifo(d / "sky.exr")
    return _load(_toml(d, '[[object]]\nmesh = "tri.obj"\n\n[environment]\nimage = "sky.exr"\n'))


@probe("toml: emission 3e38", r"scene\.toml: mesh 'lamp': emission .*beyond float32")
def _(d):
    return _load(_toml(d, '[[object]]\nmesh = "tri.obj"\nname = "lamp"\nemission = 3e38\n'))


@probe("toml: point light 1e38 W/sr", r"scene\.toml: light #0: intensity .* beyond float32")
def _(d):
    text = '[[object]]\nmesh = "tri.obj"\n[[light]]\ntype = "point"\nposition = [0, 1, 0]\nintensity = 1e38\n'  # noqa: E501
    return _load(_toml(d, text))


@probe("toml: camera at scale 1e-30", LOADS)
def _(d):
    text = '[camera]\neye = [0, 0, 1e-30]\ntarget = [0, 0, 0]\n[[object]]\nmesh = "tri.obj"\nscale = 1e-30\n'  # noqa: E501
    return _load(_toml(d, text))


@probe("toml: mesh with every face degenerate beside a good one", LOADS)
def _(d):
    (d / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    return _load(_toml(d, '[[object]]\nmesh = "tri.obj"\n[[object]]\nmesh = "flat.obj"\n'))


# -- solution files ------------------------------------------------------------------


def _solution(d: Path, tamper=None) -> tuple:
    """A small solution file (records of a voxelized box, radiosity = emission),
    its arrays changed by ``tamper(arrays)``."""
    import voxgi

    scene = voxgi.scenes.cornell_box()
    vox = voxgi.voxelize(scene, resolution=8, threads=1)
    sol = voxgi.Solution(vox=vox, radiosity=np.pi * vox.emission, bounces=0, residuals=[], stats={})
    path = sol.save(d / "sol.npz")
    if tamper is not None:
        with np.load(path) as z:
            arrays = dict(z)
        tamper(arrays)
        np.savez_compressed(path, **arrays)
    return ("solution", str(path), {})


def _set(name, index, value):
    def tamper(arrays):
        arrays[name] = arrays[name].copy()
        arrays[name][index] = value

    return tamper


@probe(
    "npz: ijk beyond the resolution", r"sol\.npz: vox_ijk of record 0 is \[99, .*expected 0 to 8"
)
def _(d):
    return _solution(d, _set("vox_ijk", (0, 0), 99))


@probe("npz: albedo 5", r"sol\.npz: vox_albedo of record 3 is .*5\.0.*expected \[0, 1\)")
def _(d):
    return _solution(d, _set("vox_albedo", (3, 1), 5.0))


@probe("npz: object_id 10^6", r"sol\.npz: vox_object_id of record 0 is 1000000; expected 0 to 7")
def _(d):
    return _solution(d, _set("vox_object_id", 0, 10**6))


@probe("npz: object_id -5", r"sol\.npz: vox_object_id of record 2 is -5")
def _(d):
    return _solution(d, _set("vox_object_id", 2, -5))


@probe("npz: side 7", r"sol\.npz: vox_side of record 1 is 7; expected 0 or 1")
def _(d):
    return _solution(d, _set("vox_side", 1, 7))


@probe("npz: radiosity NaN", r"sol\.npz: radiosity has values that are not finite")
def _(d):
    return _solution(d, _set("radiosity", (4, 0), np.nan))


@probe(
    "npz: header claims 6e9 floats", r"sol\.npz: .*radiosity.*must be floats of shape \(\d+, 3\)"
)
def _(d):
    def tamper(arrays):
        arrays["radiosity"] = np.zeros((3, 3), np.float32)

    path = Path(_solution(d, tamper)[1])
    # rewrite the member's .npy header to claim 2e9 x 3 floats
    import zipfile

    with zipfile.ZipFile(path) as z:
        members = {i.filename: z.read(i.filename) for i in z.infolist()}
    raw = members["radiosity.npy"]
    members["radiosity.npy"] = raw.replace(b"(3, 3)", b"(2000000000, 3)".ljust(6), 1)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in members.items():
            z.writestr(name, data)
    return ("solution", str(path), {})


def _zip(members: dict) -> bytes:
    """A zip of ``{name: (deflated bytes, uncompressed size, crc)}``, written by hand
    so that a member may declare the size of what it inflates to without the
    test inflating it."""
    local, central = b"", b""
    for name, (data, size, crc) in members.items():
        head = struct.pack(
            "<IHHHHHIIIHH", 0x04034B50, 20, 0, 8, 0, 0x21, crc, len(data), size, len(name), 0
        )
        central += (
            struct.pack(
                "<IHHHHHHIIIHHHHHII",
                0x02014B50,
                20,
                20,
                0,
                8,
                0,
                0x21,
                crc,
                len(data),
                size,
                len(name),
                0,
                0,
                0,
                0,
                0,
                len(local),
            )
            + name.encode()
        )
        local += head + name.encode() + data
    end = struct.pack(
        "<IHHHHIIH", 0x06054B50, 0, 0, len(members), len(members), len(central), len(local), 0
    )
    return local + central + end


def _deflate(data: bytes) -> bytes:
    c = zlib.compressobj(9, zlib.DEFLATED, -15)
    return c.compress(data) + c.flush()


@probe("npz: 3 MB zip bomb", r"sol\.npz: its arrays declare 3,\d{3},\d{3},\d{3} bytes")
def _(d):
    import zipfile

    path = Path(_solution(d)[1])
    with zipfile.ZipFile(path) as z:
        members = {
            i.filename: (_deflate(z.read(i.filename)), i.file_size, i.CRC) for i in z.infolist()
        }
    # 3 GiB of zeros deflated: after a full flush the compressor starts afresh,
    # so every later 16 MiB block deflates to the same bytes
    c = zlib.compressobj(9, zlib.DEFLATED, -15)
    zeros = bytes(1 << 24)
    first = c.compress(zeros) + c.flush(zlib.Z_FULL_FLUSH)
    again = c.compress(zeros) + c.flush(zlib.Z_FULL_FLUSH)
    data = first + again * ((3 << 6) - 1) + c.flush()
    # (its CRC is left 0: the reader refuses it from the sizes, before any CRC)
    members["radiosity.npy"] = (data, 3 << 30, 0)
    path.write_bytes(_zip(members))
    return ("solution", str(path), {})


@probe("npz: a valid solution", LOADS)
def _(d):
    return _solution(d)


# -- the command line -----------------------------------------------------------------


@probe(
    "cli: voxgi render scene.json",
    r"voxgi render: error: scene file scene\.json: not a scene file voxgi reads.*exit 1",
)
def _(d):
    (d / "scene.json").write_text("{}")
    return ("cli", str(d), {"argv": ["render", "scene.json", "-q"]})


@probe(
    "cli: voxgi render mesh.obj (no camera)",
    r"voxgi render: error: scene file mesh\.obj: has no camera.*exit 1",
)
def _(d):
    _obj(d)
    return ("cli", str(d), {"argv": ["render", "mesh.obj", "-q"]})


@probe(
    "cli: -o onto a read-only file",
    r"voxgi render: error: cannot write out\.exr: the file is read-only.*exit 2",
)
def _(d):
    (d / "out.exr").write_bytes(b"old")
    (d / "out.exr").chmod(0o444)
    return ("cli", str(d), {"argv": ["render", "cornell-box", "-o", "out.exr", "-q"]})


@probe(
    "cli: -o inside a file",
    r"voxgi render: error: cannot write a\.txt/out\.exr: a\.txt is a file, not a folder.*exit 2",
)
def _(d):
    (d / "a.txt").write_text("a file, not a folder")
    return ("cli", str(d), {"argv": ["render", "cornell-box", "-o", "a.txt/out.exr", "-q"]})


# -- the child ------------------------------------------------------------------------

SERVER = (
    textwrap.dedent(
        r"""
    import contextlib, io, json, os, resource, signal, sys, time, traceback, warnings
    resource.setrlimit(resource.RLIMIT_AS, (__LIMIT__, __LIMIT__))
    import numpy as np
    import voxgi, voxgi.cli, voxgi.formats, trimesh
    import trimesh.exchange.gltf, trimesh.exchange.obj, trimesh.exchange.ply
    from PIL import Image
    Image.init()

    def status(key):
        for line in open("/proc/self/status"):
            if line.startswith(key):
                return int(line.split()[1]) / 1024

    def run(call, path, kw):
        if call == "load":
            kw = dict(kw)
            if "limits" in kw:
                kw["limits"] = voxgi.formats.Limits(**kw["limits"])
            voxgi.Scene.load(path, **kw)
        elif call == "load_relative":
            os.chdir(path)
            voxgi.Scene.load(kw["path"])
        elif call == "solution":
            voxgi.Solution.load(path)
        else:
            os.chdir(path)
            err = io.StringIO()
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                try:
                    code = voxgi.cli.main(kw["argv"])
                except SystemExit as exc:
                    code = exc.code if isinstance(exc.code, int) else 1
                    if not isinstance(exc.code, int):
                        print(exc.code, file=err)
            raise ValueError(f"{err.getvalue().strip()} (exit {code})")

    for spec in json.loads(sys.stdin.read()):
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:
            os.close(r)
            try:
                with open("/proc/self/clear_refs", "w") as fh:
                    fh.write("5")  # the peak resident size starts again from here
            except OSError:
                pass
            base = status("VmRSS")
            out = {"name": spec["name"]}
            with warnings.catch_warnings(record=True):
                warnings.simplefilter("always")
                try:
                    run(spec["call"], spec["path"], spec["kw"])
                    out["outcome"] = "loads"
                except BaseException as exc:
                    out["outcome"] = type(exc).__name__
                    out["kind"] = next(
                        (k.__name__ for k in (ValueError, TypeError) if isinstance(exc, k)), None
                    )
                    out["message"] = str(exc)
            out["extra_mb"] = status("VmHWM") - base
            os.write(w, json.dumps(out).encode())
            os._exit(0)
        os.close(w)
        t0, res = time.monotonic(), None
        while time.monotonic() - t0 < __TIMEOUT__:
            done, st = os.waitpid(pid, os.WNOHANG)
            if done:
                res = st
                break
            time.sleep(0.02)
        data = b""
        if res is None:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            out = {"name": spec["name"], "outcome": "killed (timeout)"}
        else:
            while chunk := os.read(r, 1 << 16):
                data += chunk
            out = json.loads(data) if data else {"name": spec["name"], "outcome": f"killed ({res})"}
        os.close(r)
        out["seconds"] = time.monotonic() - t0
        print(json.dumps(out), flush=True)
    """
    )
    .replace("__LIMIT__", str(LIMIT_AS))
    .replace("__TIMEOUT__", str(TIMEOUT_S))
)


def _run_servers(specs: list, chunks: int = 2) -> dict:
    """Run the probes in ``chunks`` servers at once; returns the outcome of each by name."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    procs = []
    for k in range(chunks):
        mine = specs[k::chunks]
        p = subprocess.Popen(
            [sys.executable, "-c", SERVER],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        procs.append((p, json.dumps(mine)))
    results, failed = {}, []
    for p, payload in procs:
        out, err = p.communicate(payload, timeout=TIMEOUT_S * len(specs))
        if p.returncode != 0:
            failed.append(err[-2000:])
        for line in out.splitlines():
            r = json.loads(line)
            results[r["name"]] = r
    assert not failed, failed
    return results


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory):
    specs = []
    for k, (name, (build, _, _)) in enumerate(PROBES.items()):
        folder = tmp_path_factory.mktemp(f"probe{k:03d}")
        call, path, kw = build(folder)
        if "limits" in kw:
            kw["limits"] = {f: getattr(kw["limits"], f) for f in kw["limits"].__dataclass_fields__}
        if "search_paths" in kw:
            kw["search_paths"] = [str(p) for p in kw["search_paths"]]
        specs.append({"name": name, "call": call, "path": path, "kw": kw})
    results = _run_servers(specs)
    print()
    print(f"{'probe':<58} {'outcome':<12} {'MiB':>6} {'s':>5}  message")
    for name in PROBES:
        r = results.get(name, {"outcome": "missing"})
        msg = r.get("message", "").replace(str(Path.home()), "~")
        msg = msg if len(msg) < 150 else msg[:147] + "..."
        print(
            f"{name:<58} {r['outcome']:<12} {r.get('extra_mb', 0):6.0f} "
            f"{r.get('seconds', 0):5.2f}  {msg}"
        )
    return results


def test_there_are_at_least_60_probes():
    assert len(PROBES) >= 60


@pytest.mark.parametrize("name", list(PROBES))
def test_probe(outcomes, name):
    _, pattern, need_mb = PROBES[name]
    r = outcomes[name]
    assert not r["outcome"].startswith("killed"), r
    if pattern is LOADS:
        assert r["outcome"] == "loads", r
    else:
        assert r.get("kind") in ("ValueError", "TypeError"), r
        import re

        assert re.search(pattern, r["message"]), (pattern, r["message"])
    assert r["extra_mb"] <= 2 * need_mb + FLOOR_MB, r
