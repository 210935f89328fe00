"""Hostile probes of Mitsuba XML (with serialized meshes and textures) and OBJ + MTL."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from hostile_common import (
    LOADS,
    RECT,
    TRI_OBJ,
    _load,
    _obj,
    _png,
    _serialized,
    _tri_payload,
    _xml,
    probe,
)

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
    "xml: 9 files including the next 10 times",
    r"inc\d\.xml: line 2: <include>: 10,001 included",
    slow=True,  # 10,001 files parsed: about 5 s
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


# (kept as the texture of the rectangle: 3 bytes a texel)
@probe("xml: 12000x12000 PNG texture (140 KB)", LOADS, need_mb=432, slow=True)  # about 5 s
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


@probe(
    'xml: fov "abc"',
    r"scene\.xml: line 2: <sensor type=\"perspective\">: property 'fov' = 'abc' is not a number",
)
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
