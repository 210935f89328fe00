"""Textures reduced to the mean linear colour a diffuse albedo can hold.

A texture is opened from its header first: its pixel count is checked
against ``Limits.texture_pixels`` before any pixel is decoded. Its mean is
then taken from Pillow's histogram of the 8-bit values and a 256-entry table
of their linear values, so that the memory beyond the decoded 8-bit image is
at most a strip of rows, never a float copy of the whole image.
"""

from __future__ import annotations

import io
import threading
import warnings
from pathlib import Path

import numpy as np

from ._common import Notes
from ._limits import Limits, RefusedError
from ._paths import FileAccess

#: Pixels per strip of rows whose histogram is taken at once.
_STRIP_PIXELS = 1 << 22
_PIL_LOCK = threading.Lock()


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


#: Linear value of each 8-bit sRGB code, and of each raw code.
_LINEAR = _srgb_to_linear(np.arange(256) / 255.0)
_RAW = np.arange(256) / 255.0


def image_mean(image, raw: bool = False) -> np.ndarray:
    """Mean linear RGB of an 8-bit sRGB image (a PIL image or an array)."""
    table = _RAW if raw else _LINEAR
    if not hasattr(image, "convert"):
        a = np.asarray(image)
        a = a.reshape(-1, a.shape[-1])[:, :3]
        counts = np.array([np.bincount(a[:, c].astype(np.uint8), minlength=256) for c in range(3)])
    else:
        counts = _histogram(image)
    total = counts[0].sum()
    return (counts @ table) / max(int(total), 1)


def _histogram(image) -> np.ndarray:
    """(3, 256) counts of each 8-bit value of R, G and B, taken by Pillow in C
    (no copy of the image); other modes are converted a strip at a time."""
    mode = image.mode
    if mode in ("RGB", "RGBA", "RGBX"):
        return np.array(image.histogram()[:768], np.int64).reshape(3, 256)
    if mode in ("L", "LA"):
        return np.tile(np.array(image.histogram()[:256], np.int64), (3, 1))
    if mode == "P" and image.palette is not None:
        idx = np.array(image.histogram()[:256], np.int64)
        pal = np.array(image.getpalette()[:768], np.int64).reshape(-1, 3)
        n = min(len(pal), 256)
        return np.array(
            [np.bincount(pal[:n, c], weights=idx[:n], minlength=256) for c in range(3)]
        ).astype(np.int64)
    w, h = image.size
    rows = max(1, _STRIP_PIXELS // max(w, 1))
    counts = np.zeros((3, 256), np.int64)
    for y in range(0, h, rows):
        strip = image.crop((0, y, w, min(h, y + rows))).convert("RGB")
        counts += np.array(strip.histogram(), np.int64).reshape(3, 256)
    return counts


def open_image(data: bytes, what: str, limits: Limits):
    """A PIL image of encoded bytes, its size checked against ``limits`` from its
    header alone; Pillow's own bound on pixels is replaced by that limit."""
    from PIL import Image  # (a scikit-image dependency)

    with _PIL_LOCK, warnings.catch_warnings():
        warnings.simplefilter("error", Image.DecompressionBombWarning)
        saved = Image.MAX_IMAGE_PIXELS
        Image.MAX_IMAGE_PIXELS = limits.texture_pixels
        try:
            im = Image.open(io.BytesIO(data))
        except (Image.DecompressionBombWarning, Image.DecompressionBombError):
            im = None
        except Exception as exc:  # Pillow raises many kinds for a broken file
            raise ValueError(f"{what}: not an image Pillow reads ({exc})") from None
        finally:
            Image.MAX_IMAGE_PIXELS = saved
    if im is None:
        # Pillow refused from the header: ask it the size without its check
        with _PIL_LOCK:
            saved, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None
            try:
                im = Image.open(io.BytesIO(data))
            finally:
                Image.MAX_IMAGE_PIXELS = saved
    w, h = im.size
    limits.check("texture_pixels", w * h, f"{what} ({w}x{h})")
    return im


def texture_file_mean(path: Path, access: FileAccess, raw: bool = False) -> np.ndarray:
    """Mean linear RGB of an image file read through ``access``; ValueError if it
    cannot be read or exceeds a limit."""
    im = open_image(access.read_bytes(path, "texture"), f"texture {path}", access.limits)
    try:
        with im:
            im.load()
            return image_mean(im, raw=raw)
    except (OSError, ValueError, SyntaxError) as exc:
        raise ValueError(f"texture {path}: cannot be decoded ({exc})") from None


def decode_rgb(path: Path, access: FileAccess) -> np.ndarray:
    """(H, W, 3) uint8 RGB codes of an image file read through ``access``, row 0
    the image's top; its size checked against ``Limits.texture_pixels`` from
    its header first. ValueError names the file."""
    im = open_image(access.read_bytes(path, "texture"), f"texture {path}", access.limits)
    try:
        with im:
            im.load()
            w, h = im.size
            if im.mode in ("L", "LA", "I;16"):
                grey = im.convert("L") if im.mode != "L" else im
                lum = np.frombuffer(grey.tobytes(), np.uint8).reshape(h, w)
                return np.repeat(lum[:, :, None], 3, axis=2)
            if im.mode != "RGB":
                im = im.convert("RGB")
            # one copy of the pixels beside Pillow's (np.asarray would make two)
            return np.frombuffer(im.tobytes(), np.uint8).reshape(h, w, 3)
    except (OSError, ValueError, SyntaxError) as exc:
        raise ValueError(f"texture {path}: cannot be decoded ({exc})") from None


def texture_mean(img_path: Path, access: FileAccess, notes: Notes, what: str) -> np.ndarray:
    """An OBJ material's texture factor: its mean colour, or 1 (with a note) when
    the file cannot be read; a file outside the policy or over a limit is an
    error."""
    try:
        mean = texture_file_mean(img_path, access)
    except RefusedError:
        raise
    except (OSError, ValueError) as exc:
        notes.approx(f"{what}: texture {img_path.name} unreadable ({exc}): factor 1")
        return np.ones(3)
    notes.approx(f"{what}: texture {img_path.name} reduced to its mean colour")
    return mean


def check_image_size(path: Path, access: FileAccess) -> None:
    """Refuse an image file (an environment map) whose header declares more pixels
    than ``Limits.texture_pixels``, before a reader decodes it."""
    if path.suffix.lower() == ".exr":
        import OpenEXR

        try:
            with OpenEXR.File(str(path), header_only=True) as f:
                lo, hi = f.header()["dataWindow"]
        except (RuntimeError, KeyError, ValueError):
            return  # not an EXR: the reader names what is wrong
        w, h = int(hi[0]) - int(lo[0]) + 1, int(hi[1]) - int(lo[1]) + 1
    else:
        try:
            im = open_image(access.read_bytes(path, "image"), f"image {path}", access.limits)
        except RefusedError:
            raise
        except ValueError:
            return  # a format Pillow does not read (.hdr): its reader checks it
        w, h = im.size
    access.limits.check("texture_pixels", max(w, 0) * max(h, 0), f"image {path} ({w}x{h})")
