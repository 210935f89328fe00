"""Mitsuba's ``.serialized`` meshes: zlib-compressed streams of positions and indices.

Each stream is inflated piece by piece into arrays sized from its header's
vertex and triangle counts, after those counts are checked against
``Limits.mesh_bytes`` and against what zlib can hold in the compressed bytes
at hand, so that a small file cannot make voxgi inflate gigabytes.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

from ._limits import Limits
from ._paths import FileAccess

__all__ = ["read_serialized"]

#: Compressed bytes handed to zlib at once.
_IN_CHUNK = 1 << 20
#: Largest expansion of a deflate stream (RFC 1951's 258-byte runs in a
#: 1-bit code plus block overhead; zlib's documented bound is 1032:1).
_MAX_RATIO = 1032
#: Longest mesh name read from a version 4 header.
_MAX_NAME = 1 << 16


class _Inflate:
    """One zlib stream of ``buf`` from ``start``, read in exact sizes."""

    def __init__(self, buf: bytes, start: int, bad):
        self.d = zlib.decompressobj()
        self.buf = memoryview(buf)
        self.pos = start
        self.tail = b""
        self.bad = bad

    def _feed(self) -> None:
        if self.pos >= len(self.buf):
            self.bad("truncated zlib stream")
        self.tail = self.buf[self.pos : self.pos + _IN_CHUNK]
        self.pos += len(self.tail)

    def read(self, n: int, keep: bool = True) -> bytearray | None:
        """The next ``n`` bytes of output (None, reading and dropping them, if not ``keep``)."""
        out = bytearray(n) if keep else None
        view = memoryview(out) if keep else None
        done = 0
        while done < n:
            if self.d.eof:
                self.bad("truncated data: the stream ends before its header's counts")
            if not self.tail:
                self._feed()
            try:
                piece = self.d.decompress(self.tail, min(n - done, _IN_CHUNK * 8))
            except zlib.error as exc:
                self.bad(f"corrupt zlib stream ({exc})")
            self.tail = self.d.unconsumed_tail
            if keep:
                view[done : done + len(piece)] = piece
            done += len(piece)
        return out

    def read_name(self) -> None:
        """Skip a NUL-terminated name (at most :data:`_MAX_NAME` bytes)."""
        for _ in range(_MAX_NAME):
            if self.read(1)[0] == 0:
                return
        self.bad(f"mesh name longer than {_MAX_NAME} bytes")

    def finish(self) -> int:
        """Check the stream ends here; returns the offset of the byte after it."""
        while not self.d.eof:
            if not self.tail:
                self._feed()
            try:
                piece = self.d.decompress(self.tail, 1)
            except zlib.error as exc:
                self.bad(f"corrupt zlib stream ({exc})")
            self.tail = self.d.unconsumed_tail
            if piece:
                self.bad("the stream holds more data than its header's counts")
        return self.pos - len(self.d.unused_data)


def read_serialized(
    path, shape_index: int = 0, *, data: bytes | None = None, limits: Limits | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of one mesh of a Mitsuba ``.serialized`` file.

    Parameters
    ----------
    path : str or Path
        The file (named in messages; read unless ``data`` is given).
    shape_index : int
        Which mesh of the file (0-based).
    data : bytes, optional
        The file's bytes, already read.
    limits : Limits, optional
        ``mesh_bytes`` bounds each mesh's decompressed size (default:
        :meth:`Limits.from_env`).

    Returns
    -------
    vertices : (V, 3) float64
    faces : (F, 3) int64

    Notes
    -----
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
    limits = Limits.from_env() if limits is None else limits
    if data is None:
        data = FileAccess(path, allow_outside=True, limits=limits).read_bytes(path, "mesh file")

    def bad(msg):
        raise ValueError(f"serialized mesh {path}: {msg}")

    if isinstance(shape_index, bool) or not isinstance(shape_index, (int, np.integer)):
        bad(f"shape_index {shape_index!r} must be an integer")
    if shape_index < 0:
        bad(f"shape_index {shape_index} must be >= 0")
    offset = 0
    for k in range(shape_index + 1):
        if offset + 4 > len(data) or struct.unpack_from("<H", data, offset)[0] != 0x041C:
            if k == 0:
                bad("not a Mitsuba serialized file (no 0x041C header)")
            bad(f"shape_index {shape_index} out of range: the file holds {k} mesh(es)")
        version = struct.unpack_from("<H", data, offset + 2)[0]
        if version not in (3, 4):
            bad(f"mesh {k}: unsupported version {version}")
        stream = _Inflate(data, offset + 4, lambda msg, k=k: bad(f"mesh {k}: {msg}"))
        layout = _header(stream, version, len(data) - offset, k, path, limits)
        if k < shape_index:
            stream.read(sum(n for n, _ in layout.values()), keep=False)
            offset = stream.finish()
    return _arrays(stream, layout, lambda msg: bad(f"mesh {shape_index}: {msg}"))


def _header(stream: _Inflate, version: int, compressed: int, k: int, path: Path, limits: Limits):
    """``{part: (bytes, dtype)}`` of a mesh's payload, from its header's counts,
    checked before any of it is inflated."""
    flags = struct.unpack("<I", stream.read(4))[0]
    if version == 4:
        stream.read_name()
    nv, nf = struct.unpack("<QQ", stream.read(16))
    real = np.dtype(np.float64 if flags & 0x2000 else np.float32)
    index = np.dtype(np.uint64 if nv > 0xFFFFFFFF else np.uint32)
    layout = {"vertices": (nv * 3 * real.itemsize, real)}
    for flag, name, width in ((0x0001, "normals", 3), (0x0002, "uv", 2), (0x0008, "colors", 3)):
        if flags & flag:
            layout[name] = (nv * width * real.itemsize, real)
    layout["faces"] = (nf * 3 * index.itemsize, index)
    total = sum(n for n, _ in layout.values())
    where = f"serialized mesh {path}: mesh {k} ({nv:,} vertices, {nf:,} triangles)"
    limits.check("mesh_bytes", total, where)
    if total > _MAX_RATIO * compressed + 1024:
        raise ValueError(
            f"{where}: its header claims {total:,} bytes, more than zlib can hold in the "
            f"{compressed:,} compressed bytes of the file"
        )
    return layout


def _arrays(stream: _Inflate, layout: dict, bad) -> tuple[np.ndarray, np.ndarray]:
    """Inflate a mesh's payload part by part; (vertices float64, faces int64)."""
    out = {}
    for name, (n, dtype) in layout.items():
        raw = stream.read(n, keep=name in ("vertices", "faces"))
        if raw is not None:
            out[name] = np.frombuffer(raw, dtype)
    stream.finish()
    v = out["vertices"].reshape(-1, 3).astype(np.float64)
    f = out["faces"].reshape(-1, 3)
    if len(f) and f.max() >= len(v):
        bad(f"face index {int(f.max())} >= vertex count {len(v)}")
    return v, f.astype(np.int64)
