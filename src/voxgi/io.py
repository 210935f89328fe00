"""Image files: OpenEXR for data (linear float32), PNG for eyes (tone-mapped sRGB)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

__all__ = ["read_exr", "read_exr_header", "to_srgb8", "write_exr", "write_png"]


def _check_image(image, what: str = "image") -> np.ndarray:
    arr = np.asarray(image)
    if arr.dtype == object or not np.issubdtype(arr.dtype, np.number):
        raise TypeError(f"{what}: expected a numeric array, got dtype {arr.dtype}")
    if arr.ndim == 2:
        arr = np.repeat(arr[:, :, None], 3, axis=2)
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.shape[0] == 0 or arr.shape[1] == 0:
        raise ValueError(f"{what}: expected shape (H, W, 3) or (H, W), got {arr.shape}")
    return np.ascontiguousarray(arr, dtype=np.float32)


def write_exr(path, image, metadata: dict | None = None) -> Path:
    """Write a linear RGB float32 OpenEXR file (ZIP compression).

    Parameters
    ----------
    path : str or Path
    image : (H, W, 3) or (H, W) array
        Linear radiance; ``image[0, 0]`` is the top-left pixel.
    metadata : dict, optional
        Extra header attributes, stored as ``voxgi_<key>`` strings (values
        that are not strings are JSON-encoded): settings and timings.
    """
    import OpenEXR

    img = _check_image(image)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for k, v in (metadata or {}).items():
        header[f"voxgi_{k}"] = v if isinstance(v, str) else json.dumps(v, default=float)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with OpenEXR.File(header, {"RGB": img}) as f:
        f.write(str(path))
    return path


def _open_exr(path: Path):
    """Open an EXR for reading: FileNotFoundError if absent, ValueError if unreadable."""
    import OpenEXR

    if not path.exists():
        raise FileNotFoundError(f"EXR file not found: {path}")
    try:
        return OpenEXR.File(str(path))
    except RuntimeError as exc:  # not an EXR, truncated, unreadable
        raise ValueError(f"{path}: cannot be read as OpenEXR ({exc})") from None


def read_exr(path) -> np.ndarray:
    """Read an OpenEXR file's RGB channels as (H, W, 3) float32."""
    path = Path(path)
    with _open_exr(path) as f:
        ch = f.channels()
        if "RGB" in ch:
            px = ch["RGB"].pixels
        elif all(c in ch for c in "RGB"):
            px = np.stack([ch[c].pixels for c in "RGB"], axis=-1)
        elif "Y" in ch:
            px = np.repeat(ch["Y"].pixels[:, :, None], 3, axis=2)
        else:
            raise ValueError(f"{path}: no RGB or Y channels (has {sorted(ch)})")
    return np.ascontiguousarray(px, dtype=np.float32)


def read_exr_header(path) -> dict:
    """The ``voxgi_*`` attributes of an EXR written by :func:`write_exr`."""
    path = Path(path)
    with _open_exr(path) as f:
        h = dict(f.header())  # the File's header dict is emptied on close
    out = {}
    for k, v in h.items():
        if isinstance(k, str) and k.startswith("voxgi_"):
            try:
                out[k[6:]] = json.loads(v)
            except (TypeError, ValueError):
                out[k[6:]] = v
    return out


def to_srgb8(image, exposure: float = 0.0) -> np.ndarray:
    """Tone-map linear radiance to 8-bit sRGB: scale by ``2**exposure``,
    clip to [0, 1], apply the sRGB transfer curve. NaN maps to 0."""
    if isinstance(exposure, bool) or not isinstance(exposure, (int, float, np.number)):
        raise TypeError(f"exposure: expected a number, got {exposure!r}")
    if not np.isfinite(exposure):
        raise ValueError(f"exposure: must be finite, got {exposure}")
    img = _check_image(image).astype(np.float64) * (2.0 ** float(exposure))
    img = np.clip(np.nan_to_num(img, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    srgb = np.where(img <= 0.0031308, 12.92 * img, 1.055 * np.power(img, 1 / 2.4) - 0.055)
    return np.round(srgb * 255.0).astype(np.uint8)


def write_png(path, image, exposure: float = 0.0) -> Path:
    """Write a tone-mapped 8-bit sRGB PNG preview of a linear image."""
    from skimage.io import imsave

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    imsave(str(path), to_srgb8(image, exposure), check_contrast=False)
    return path
