"""The registry and the small-file writers of the hostile-file probes
(tests/test_hostile_files.py runs them)."""

from __future__ import annotations

import base64
import json
import struct
import zlib
from pathlib import Path

import numpy as np

LOADS = None  # the pattern of a probe whose file is valid

#: name -> (build(folder) -> (call, path, kwargs), pattern or LOADS, legitimate MB)
PROBES: dict = {}
#: the probes that take seconds to read (run with the long tests, ``-m slow``)
SLOW: set = set()


def probe(name: str, pattern: str | None, need_mb: float = 0.0, slow: bool = False):
    def register(build):
        PROBES[name] = (build, pattern, need_mb)
        if slow:
            SLOW.add(name)
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


def _obj(d: Path, head: str = "", body: str = TRI_OBJ) -> Path:
    path = d / "mesh.obj"
    path.write_text(head + body)
    return path
