"""Image files: OpenEXR for data (linear float32), PNG for eyes (tone-mapped sRGB).

Every file voxgi writes (images here, solutions, scene files) goes through
:func:`atomic_path`: it is written under a temporary name in the target's
folder and renamed over the target only once complete, so a failed or
interrupted write (disk full, file-size limit, Ctrl-C) leaves the earlier
file as it was.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

__all__ = ["atomic_path", "read_exr", "read_exr_header", "to_srgb8", "write_exr", "write_png"]


def _umask() -> int:
    """The process's umask, read without changing it where the OS allows."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):  # pragma: no cover - not Linux
        pass
    mask = os.umask(0o022)  # pragma: no cover
    os.umask(mask)  # pragma: no cover
    return mask  # pragma: no cover


@contextlib.contextmanager
def atomic_path(path) -> Iterator[Path]:
    """Write a file all at once: yield a temporary path, then rename it onto ``path``.

    The temporary file lies in ``path``'s folder (so the rename is atomic on
    one file system) and keeps ``path``'s extension (writers that choose the
    format from it still work). When the ``with`` body completes, the file
    is flushed to disk and moved onto ``path`` with :func:`os.replace`; when
    it raises (including ``KeyboardInterrupt``), the temporary file is
    removed and ``path`` is left untouched. The new file gets the old one's
    permission bits, or the usual ``0o666 & ~umask``; a symbolic link is
    kept and the file it points to is replaced.

    Examples
    --------
    >>> with atomic_path("out.txt") as tmp:                 # doctest: +SKIP
    ...     tmp.write_text("complete or not at all")
    """
    path = Path(path)
    if path.is_symlink():  # replace the file the link points to, and keep the link
        path = Path(os.path.realpath(path))
    if path.is_dir():
        raise IsADirectoryError(f"{path}: is a folder, expected a file name")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(
        prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}", dir=path.parent
    )
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        try:
            mode = path.stat().st_mode & 0o7777
        except OSError:
            mode = 0o666 & ~_umask()
        os.chmod(tmp, mode)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def _check_image(image, what: str = "image") -> np.ndarray:
    arr = np.asarray(image)
    if arr.dtype == object or not np.issubdtype(arr.dtype, np.number):
        raise TypeError(f"{what}: expected a numeric array, got dtype {arr.dtype}")
    if arr.ndim == 2:
        arr = np.repeat(arr[:, :, None], 3, axis=2)
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.shape[0] == 0 or arr.shape[1] == 0:
        raise ValueError(f"{what}: expected shape (H, W, 3) or (H, W), got {arr.shape}")
    return np.ascontiguousarray(arr, dtype=np.float32)


def write_exr(path, image, metadata: dict | None = None, *, stderr=None) -> Path:
    """Write a linear RGB float32 OpenEXR file (ZIP compression).

    Parameters
    ----------
    path : str or Path
    image : (H, W, 3) or (H, W) array
        Linear radiance; ``image[0, 0]`` is the top-left pixel.
    metadata : dict, optional
        Extra header attributes, stored as ``voxgi_<key>`` strings (values
        that are not strings are JSON-encoded): settings and timings.
    stderr : array of ``image``'s shape, optional
        Per-pixel standard error of ``image`` (``RenderResult.stderr``),
        written as the channels ``stderr.R``, ``stderr.G``, ``stderr.B``
        (read back with ``read_exr(path, layer="stderr")``).
    """
    import OpenEXR

    img = _check_image(image)
    channels = {"RGB": img}
    if stderr is not None:
        se = _check_image(stderr, "stderr")
        if se.shape != img.shape:
            raise ValueError(f"stderr: expected the image's shape {img.shape}, got {se.shape}")
        channels.update(
            {f"stderr.{c}": np.ascontiguousarray(se[:, :, i]) for i, c in enumerate("RGB")}
        )
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for k, v in (metadata or {}).items():
        header[f"voxgi_{k}"] = v if isinstance(v, str) else json.dumps(v, default=float)
    path = Path(path)
    with atomic_path(path) as tmp, OpenEXR.File(header, channels) as f:
        try:
            f.write(str(tmp))
        except RuntimeError as exc:  # OpenEXR reports a failed write (disk full...) this way
            raise OSError(f"{path}: cannot write the EXR file ({exc})") from None
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


def read_exr(path, layer: str | None = None) -> np.ndarray:
    """Read an OpenEXR file's RGB channels as (H, W, 3) float32.

    ``layer`` reads the channels ``<layer>.R``, ``<layer>.G``, ``<layer>.B``
    instead (``"stderr"``: the error estimate :func:`write_exr` stores).
    """
    path = Path(path)
    with _open_exr(path) as f:
        ch = f.channels()
        if layer is not None:
            if layer in ch and ch[layer].pixels.ndim == 3:
                px = ch[layer].pixels
            elif all(f"{layer}.{c}" in ch for c in "RGB"):
                px = np.stack([ch[f"{layer}.{c}"].pixels for c in "RGB"], axis=-1)
            else:
                raise ValueError(f"{path}: no {layer}.R/G/B channels (has {sorted(ch)})")
        elif "RGB" in ch:
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
    srgb = to_srgb8(image, exposure)
    with atomic_path(path) as tmp:
        imsave(str(tmp), srgb, check_contrast=False)
    return path
