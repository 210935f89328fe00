"""Hostile probes of glTF, TOML, solution files and the command line."""

from __future__ import annotations

import os
import struct
import zlib
from pathlib import Path

import numpy as np
from hostile_common import (
    LOADS,
    _gltf,
    _load,
    _obj,
    _png,
    _toml,
    probe,
)

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


@probe(
    "toml: environment EXR whose header claims 10^10 pixels",
    r"scene\.toml: \[environment\]: image .*sky\.exr \(100000x100000\): 10,000,000,000 pixels",
)
def _(d):
    from voxgi import io

    io.write_exr(d / "sky.exr", np.ones((1, 1, 3), np.float32))
    raw = (d / "sky.exr").read_bytes()
    at = raw.index(b"dataWindow\0box2i\0") + len(b"dataWindow\0box2i\0") + 4
    raw = raw[:at] + struct.pack("<iiii", 0, 0, 99_999, 99_999) + raw[at + 16 :]
    (d / "sky.exr").write_bytes(raw)
    return _load(_toml(d, '[[object]]\nmesh = "tri.obj"\n\n[environment]\nimage = "sky.exr"\n'))


@probe("toml: PLY whose header claims 10^12 vertices", r"scene\.toml: object #0: .*a\.ply")
def _(d):
    (d / "a.ply").write_text(
        "ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\n"
        "property float x\nproperty float y\nproperty float z\nelement face 1\n"
        "property list uchar int vertex_indices\nend_header\n"
    )
    return _load(_toml(d, '[[object]]\nmesh = "a.ply"\n', mesh=None))


@probe("toml: STL whose header claims 4e9 triangles", r"scene\.toml: object #0: .*c\.stl")
def _(d):
    (d / "c.stl").write_bytes(bytes(80) + struct.pack("<I", 4_000_000_000) + bytes(50))
    return _load(_toml(d, '[[object]]\nmesh = "c.stl"\n', mesh=None))


@probe("toml: OBJ face index 3e9", r"scene\.toml: object #0: cannot load mesh .*d\.obj")
def _(d):
    (d / "d.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3000000000\n")
    return _load(_toml(d, '[[object]]\nmesh = "d.obj"\n', mesh=None))


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
