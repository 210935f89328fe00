"""UV-mapped bitmap textures of a surface's diffuse albedo.

A :class:`Texture` holds a bitmap's 8-bit RGB codes (row 0 the image's top
row) and how it is looked up: Mitsuba 3's ``bitmap`` conventions, so that a
scene exported by :func:`voxgi.mitsuba.to_mitsuba` renders the same albedo
there. A lookup at texture coordinates ``(u, v)`` first maps them by the
affine ``to_uv``, then filters the texels around ``(u' W, v' H)``: each texel
decoded to linear RGB first (sRGB codes through the sRGB curve, as Mitsuba
decodes an 8-bit image; ``raw`` codes as code / 255), then interpolated
bilinearly between texel centres or taken from the nearest texel, the
texel index wrapped (``repeat``, ``mirror`` or ``clamp``), and the result
multiplied by ``factor`` (an MTL ``Kd`` or glTF ``baseColorFactor``).

The texels stay in 8 bits (3 bytes a texel, the size ``Limits.texture_pixels``
bounds); no float copy of an image is kept. The display evaluates the
texture at every camera hit and gather-ray hit, and each voxel record takes
its mean over the record's own surface (docs/design.md §12).
"""

from __future__ import annotations

import hashlib
import weakref
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["FILTERS", "WRAPS", "Texture", "surface_tables"]

#: Filters, in the kernels' numbering.
FILTERS = ("nearest", "bilinear")
#: Wrap modes, in the kernels' numbering.
WRAPS = ("repeat", "mirror", "clamp")


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


#: The linear value of each 8-bit code, sRGB-decoded and raw, in float32 as
#: the kernels hold them.
_LINEAR = {
    False: _srgb_to_linear(np.arange(256) / 255.0).astype(np.float32),
    True: (np.arange(256) / 255.0).astype(np.float32),
}


@dataclass(frozen=True, eq=False)
class Texture:
    """A bitmap of diffuse albedo, looked up by a mesh's UVs.

    Parameters
    ----------
    texels : (H, W, 3) uint8
        RGB codes, row 0 the image's top row (UV ``v = 0``).
    filter : {"bilinear", "nearest"}
    wrap : {"repeat", "mirror", "clamp"}
    to_uv : (3, 3) float, optional
        Affine map of the mesh's UVs before the lookup (Mitsuba's ``to_uv``);
        the identity by default.
    raw : bool
        The codes are linear values times 255, not sRGB.
    factor : float or (3,) float
        Multiplies the filtered value.
    path : str, optional
        The image file it was read from (kept by ``Scene.save`` and
        :func:`voxgi.mitsuba.to_mitsuba`).
    """

    texels: np.ndarray = field(repr=False)
    filter: str = "bilinear"
    wrap: str = "repeat"
    to_uv: np.ndarray = field(default_factory=lambda: np.eye(3), repr=False)
    raw: bool = False
    factor: tuple[float, float, float] = (1.0, 1.0, 1.0)
    path: str | None = None

    def __post_init__(self):
        t = np.asarray(self.texels)
        if t.dtype != np.uint8 or t.ndim != 3 or t.shape[2] != 3 or 0 in t.shape:
            raise ValueError(f"Texture.texels: expected (H, W, 3) uint8, got {t.dtype} {t.shape}")
        t = np.ascontiguousarray(t)
        t.setflags(write=False)
        object.__setattr__(self, "texels", t)
        if self.filter not in FILTERS:
            raise ValueError(f"Texture.filter: {self.filter!r}; expected one of {FILTERS}")
        if self.wrap not in WRAPS:
            raise ValueError(f"Texture.wrap: {self.wrap!r}; expected one of {WRAPS}")
        m = np.array(self.to_uv, np.float64)
        if m.shape != (3, 3) or not np.all(np.isfinite(m)):
            raise ValueError(f"Texture.to_uv: expected a finite (3, 3) matrix, got {m.shape}")
        object.__setattr__(self, "to_uv", m)
        f = np.broadcast_to(np.asarray(self.factor, np.float64), (3,))
        if not np.all(np.isfinite(f)) or np.any(f < 0):
            raise ValueError(f"Texture.factor: {f.tolist()} must be finite and >= 0")
        object.__setattr__(self, "factor", tuple(float(x) for x in f))
        object.__setattr__(self, "raw", bool(self.raw))

    @property
    def width(self) -> int:
        return int(self.texels.shape[1])

    @property
    def height(self) -> int:
        return int(self.texels.shape[0])

    def mean(self) -> np.ndarray:
        """(3,) float64 mean linear albedo over the whole image, times the factor."""
        cached = self.__dict__.get("_mean")
        if cached is None:
            # a strip of rows at a time: bincount takes its input as int64
            counts = np.zeros((3, 256), np.int64)
            rows = max(1, (1 << 20) // self.width)
            for y in range(0, self.height, rows):
                strip = self.texels[y : y + rows].reshape(-1, 3)
                for c in range(3):
                    counts[c] += np.bincount(strip[:, c], minlength=256)
            cached = counts @ _LINEAR[self.raw].astype(np.float64) / counts[0].sum()
            object.__setattr__(self, "_mean", cached)
        return cached * self.factor

    def linear_texels(self) -> np.ndarray:
        """(H, W, 3) float32 linear texels times the factor (a float copy: for
        an export, not kept)."""
        return _LINEAR[self.raw][self.texels] * np.asarray(self.factor, np.float32)

    def eval(self, uv) -> np.ndarray:
        """The filtered albedo at UVs ``uv`` (N, 2): (N, 3) float64 (a reference
        of the kernels' lookup, in numpy)."""
        uv = np.asarray(uv, np.float64).reshape(-1, 2)
        m = self.to_uv
        u = m[0, 0] * uv[:, 0] + m[0, 1] * uv[:, 1] + m[0, 2]
        v = m[1, 0] * uv[:, 0] + m[1, 1] * uv[:, 1] + m[1, 2]
        lin = _LINEAR[self.raw]
        W, H = self.width, self.height

        def texel(x, y):
            return lin[self.texels[self._wrap(y, H), self._wrap(x, W)]].astype(np.float64)

        if self.filter == "nearest":
            out = texel(np.floor(u * W).astype(np.int64), np.floor(v * H).astype(np.int64))
        else:
            x, y = u * W - 0.5, v * H - 0.5
            x0, y0 = np.floor(x), np.floor(y)
            ax, ay = (x - x0)[:, None], (y - y0)[:, None]
            x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
            top = texel(x0, y0) * (1 - ax) + texel(x0 + 1, y0) * ax
            bot = texel(x0, y0 + 1) * (1 - ax) + texel(x0 + 1, y0 + 1) * ax
            out = top * (1 - ay) + bot * ay
        return out * np.asarray(self.factor)

    def _wrap(self, i: np.ndarray, n: int) -> np.ndarray:
        if self.wrap == "clamp":
            return np.clip(i, 0, n - 1)
        if self.wrap == "mirror":
            m = np.mod(i, 2 * n)
            return np.where(m < n, m, 2 * n - 1 - m)
        return np.mod(i, n)

    def digest(self) -> str:
        """A hash of the texels and the lookup (for scene fingerprints)."""
        # the texels are read-only and the fields frozen: hash the image once
        texel_hash = self.__dict__.get("_texel_hash")
        if texel_hash is None:
            texel_hash = hashlib.sha1(self.texels.data)
            object.__setattr__(self, "_texel_hash", texel_hash)
        h = texel_hash.copy()
        h.update(repr((self.texels.shape, self.filter, self.wrap, self.raw, self.factor)).encode())
        h.update(self.to_uv.tobytes())
        return h.hexdigest()[:16]

    def info_row(self) -> np.ndarray:
        """(12,) float64 row of the kernels' ``tex_info``: filter, wrap, raw,
        the first two rows of to_uv, factor."""
        return np.array(
            [
                FILTERS.index(self.filter),
                WRAPS.index(self.wrap),
                float(self.raw),
                *self.to_uv[:2].ravel(),
                *self.factor,
            ],
            np.float64,
        )

    @classmethod
    def from_file(cls, path, access=None, **kwargs) -> Texture:
        """The texture of an image file (PNG, JPEG, ... as Pillow reads them),
        its size checked against ``Limits.texture_pixels`` before decoding;
        ``kwargs`` as the constructor's. ValueError names the file."""
        from .formats._paths import FileAccess
        from .formats.textures import decode_rgb

        path = Path(path)
        if access is None:
            access = FileAccess(path, (), True, None)
        return cls(decode_rgb(path, access), path=str(path), **kwargs)


# scene -> (its fingerprint, its surface_tables)
_TABLES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def surface_tables(scene) -> dict | None:
    """The textures of a scene's objects as the kernels take them (the
    ``tex_texels``, ``tex_info``, ``obj_texture`` and ``corner_uv``
    arguments of ``camera_hits`` and ``voxelize``), or None when no object
    has one. Built on first use and kept, read-only, while ``scene`` lives
    and its fingerprint stays the same: the voxelization and the display
    read the same tables (each triangle's corners' UVs, 35 MB on a scene
    of 1.4 M triangles)."""
    objs = scene.objects
    if not any(o.material.texture is not None for o in objs):
        return None
    key = scene.fingerprint()
    kept = _TABLES.get(scene)
    if kept is not None and kept[0] == key:
        return kept[1]
    tables = _surface_tables(objs)
    for v in tables.values():
        if isinstance(v, np.ndarray):
            v.flags.writeable = False
    _TABLES[scene] = (key, tables)
    return tables


def _surface_tables(objs) -> dict:
    """:func:`surface_tables` of these objects, built."""
    textures: list[Texture] = []
    index: dict[int, int] = {}
    obj_texture = np.full(len(objs), -1, np.int32)
    corner = []
    for i, o in enumerate(objs):
        t = o.material.texture
        if t is not None:
            if id(t) not in index:
                index[id(t)] = len(textures)
                textures.append(t)
            obj_texture[i] = index[id(t)]
        uv = o.uv if o.uv is not None and t is not None else None
        corner.append(np.zeros((len(o.faces), 3, 2), np.float32) if uv is None else uv[o.faces])
    return {
        "tex_texels": [t.texels for t in textures],
        "tex_info": np.stack([t.info_row() for t in textures]),
        "obj_texture": obj_texture,
        "corner_uv": np.ascontiguousarray(np.concatenate(corner), np.float32),
    }
