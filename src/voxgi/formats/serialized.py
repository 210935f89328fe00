"""Mitsuba's ``.serialized`` meshes: zlib-compressed streams of positions and indices."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

__all__ = ["read_serialized"]


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
