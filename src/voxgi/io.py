"""Files: OpenEXR for data (linear float32), PNG for eyes (tone-mapped sRGB), and
``.npz`` arrays read with their shapes checked before their data.

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

__all__ = [
    "atomic_path",
    "check_solution_records",
    "is_read_only",
    "read_exr",
    "read_exr_header",
    "read_npz",
    "to_srgb8",
    "write_exr",
    "write_png",
]


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


def is_read_only(path) -> bool:
    """Whether ``path`` is an existing file that must not be replaced: one without
    any write permission bit, or one this process may not write."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return False
    return not (mode & 0o222) or not os.access(path, os.W_OK)


@contextlib.contextmanager
def atomic_path(path) -> Iterator[Path]:
    """Write a file all at once: yield a temporary path, then rename it onto ``path``.

    The temporary file lies in ``path``'s folder (so the rename is atomic on
    one file system) and keeps ``path``'s extension (writers that choose the
    format from it still work). When the ``with`` body completes, the file
    is flushed to disk and moved onto ``path`` with :func:`os.replace`; when
    it raises (including ``KeyboardInterrupt``), the temporary file is
    removed and ``path`` is left untouched. A read-only ``path`` (no write
    permission bit) is refused with ``PermissionError`` before the body
    runs. The new file gets the old one's permission bits, or the usual
    ``0o666 & ~umask``; a symbolic link is kept and the file it points to is
    replaced.

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
    # a read-only file stays as it is (the owner's choice, honoured even for root)
    if is_read_only(path):
        raise PermissionError(f"{path}: the file is read-only")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(
        prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}", dir=path.parent
    )
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        # flushed while the temporary file is still the owner's to write; its
        # final permission bits (perhaps read-only) come after
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        try:
            mode = path.stat().st_mode & 0o7777
        except OSError:
            mode = 0o666 & ~_umask()
        os.chmod(tmp, mode)
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


def read_npz(
    path, arrays: dict, *, max_bytes: int = 1 << 34, max_ratio: float | None = None
) -> dict[str, np.ndarray]:
    """Read named arrays of a ``.npz`` file, each checked before its data is read.

    Parameters
    ----------
    path : str or Path
        The ``.npz`` (a zip of ``.npy`` members, as :func:`numpy.savez` writes).
    arrays : dict
        ``{name: (shape, dtype)}`` of the members to read (``dtype`` may be a
        tuple of the dtypes allowed). A shape is a tuple
        of ints, ``-1`` (any length) and ``"n"`` (the record count: the length
        the first member with an ``"n"`` has, which every later one must
        share). A member missing from the file is left out of the result.
    max_bytes : int
        Largest size of one member, as its header declares it.
    max_ratio : float, optional
        Largest ratio of the members' declared sizes, all together, to the
        file's size (plus 64 MiB): a zip bomb declares a thousand times its
        size, a voxgi solution file tens of times. Default: the environment
        variable ``VOXGI_MAX_NPZ_RATIO``, else 256.

    Returns
    -------
    dict of numpy.ndarray

    Raises
    ------
    ValueError
        Naming the file and member: not a zip, a member whose ``.npy``
        header declares another dtype or shape, a record count that differs,
        a declared size over ``max_bytes`` or over what the zip entry holds,
        a truncated or corrupt member.

    Notes
    -----
    Only the ``.npy`` header of a member is read before its shape and dtype
    are checked, and then exactly the bytes that shape needs: a header that
    claims billions of values, or a member that inflates far beyond its
    declared size (a zip bomb), is refused without allocating it.
    """
    import zipfile
    import zlib

    path = Path(path)
    out: dict[str, np.ndarray] = {}
    n = None
    try:
        zf = zipfile.ZipFile(path)
    except (OSError, zipfile.BadZipFile, ValueError) as exc:
        raise ValueError(f"{path}: not a .npz file ({exc})") from None
    with zf:
        names = set(zf.namelist())
        if max_ratio is None:
            max_ratio = float(os.environ.get("VOXGI_MAX_NPZ_RATIO", 256))
        declared = sum(zf.getinfo(f"{k}.npy").file_size for k in arrays if f"{k}.npy" in names)
        size = path.stat().st_size
        if declared > max_ratio * size + (64 << 20):
            raise ValueError(
                f"{path}: its arrays declare {declared:,} bytes in a file of {size:,} "
                f"(more than {max_ratio:g} times; raise VOXGI_MAX_NPZ_RATIO to read it)"
            )
        for name, (shape, dtype) in arrays.items():
            member = f"{name}.npy"
            if member not in names:
                continue
            where = f"{path}: {name}"
            info = zf.getinfo(member)
            if info.file_size > max_bytes:
                raise ValueError(f"{where}: {info.file_size:,} bytes, above {max_bytes:,}")
            try:
                with zf.open(member) as fh:
                    got_shape, arr = _read_npy(fh, info.file_size, shape, dtype, n, where)
            except (OSError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
                raise ValueError(f"{where}: unreadable ({type(exc).__name__}: {exc})") from None
            if n is None and "n" in shape:
                n = got_shape[shape.index("n")]
            out[name] = arr
    return out


def _read_npy(fh, stored: int, shape: tuple, dtype, n, where: str):
    """The array of one ``.npy`` stream, its header checked against ``shape`` and
    ``dtype`` (``n``: the record count so far) and the entry's ``stored`` size."""
    fmt = np.lib.format
    try:
        version = fmt.read_magic(fh)
        if version == (1, 0):
            got, fortran, got_dtype = fmt.read_array_header_1_0(fh, max_header_size=1 << 16)
        else:
            got, fortran, got_dtype = fmt.read_array_header_2_0(fh, max_header_size=1 << 16)
    except ValueError as exc:
        raise ValueError(f"{where}: not an .npy member ({exc})") from None
    allowed = [np.dtype(d) for d in (dtype if isinstance(dtype, tuple) else (dtype,))]
    kinds = {d.kind for d in allowed}
    names = " or ".join(d.name for d in allowed)
    if len(allowed) > 1 and kinds == {"f"}:
        names = "floats"
    ok = got_dtype in allowed and not got_dtype.hasobject
    ok = ok and len(got) == len(shape)
    ok = ok and all(
        w == -1 or (w == "n" and (n is None or g == n)) or g == w
        for g, w in zip(got, shape, strict=False)
    )
    if not ok:
        rule = tuple(("N" if n is None else n) if w == "n" else w for w in shape)
        rule_text = "(" + ", ".join("any" if w == -1 else str(w) for w in rule)
        rule_text += ",)" if len(rule) == 1 else ")"
        count = "" if n is None or "n" not in shape else f" for {n} records"
        raise ValueError(
            f"{where} must be {names} of shape {rule_text}{count}, got {got_dtype} {got}"
        )
    want = got_dtype
    nbytes = int(np.prod(got, dtype=np.int64)) * want.itemsize
    if nbytes > stored:
        raise ValueError(
            f"{where}: its header declares {nbytes:,} bytes, the zip entry holds {stored:,}"
        )
    data = bytearray(nbytes)
    view, done = memoryview(data), 0
    while done < nbytes:
        k = fh.readinto(view[done:])
        if not k:
            raise ValueError(f"{where}: truncated ({done:,} of {nbytes:,} bytes)")
        done += k
    return got, np.frombuffer(data, want).reshape(got, order="F" if fortran else "C")


def check_solution_records(vox, radiosity, where: str, n_objects: int | None = None) -> None:
    """Range and consistency checks of a loaded solution's records.

    Parameters
    ----------
    vox : VoxelSet
        Its arrays already of the documented shapes and dtypes.
    radiosity : (N, 3) float32
    where : str
        Named in messages (the file).
    n_objects : int, optional
        Objects of the scene voxelized, when known: ``object_id`` must index them.

    Raises
    ------
    ValueError
        Naming the array, the first bad record and its value: ``ijk`` outside
        ``[0, resolution]``, a normal that is not unit length, a negative or
        non-finite area, albedo outside ``[0, 1)``, negative or non-finite
        emission or radiosity, a negative ``object_id`` (or one past
        ``n_objects``), a ``side`` other than 0 and 1, or a side-1 record
        that does not follow its side-0 record in the same voxel.
    """

    def first(name: str, bad: np.ndarray, values: np.ndarray, rule: str) -> None:
        if bad.any():
            k = int(np.flatnonzero(bad.reshape(len(bad), -1).any(axis=1))[0])
            raise ValueError(
                f"{where}: {name} of record {k} is {np.asarray(values[k]).tolist()}; {rule}"
            )

    res = int(vox.resolution)
    first("vox_ijk", (vox.ijk < 0) | (vox.ijk > res), vox.ijk, f"expected 0 to {res}")
    length = np.linalg.norm(vox.normal.astype(np.float64), axis=1)
    first("vox_normal", ~(np.abs(length - 1) < 1e-3), vox.normal, "expected a unit vector")
    first("vox_area", ~(vox.area >= 0), vox.area, "expected >= 0")
    first("vox_albedo", ~((vox.albedo >= 0) & (vox.albedo < 1)), vox.albedo, "expected [0, 1)")
    first("vox_emission", ~(vox.emission >= 0), vox.emission, "expected >= 0 and finite")
    first("radiosity", ~(radiosity >= 0) | ~np.isfinite(radiosity), radiosity, "expected >= 0")
    high = n_objects if n_objects is not None else np.iinfo(np.int32).max
    bad_id = (vox.object_id < 0) | (vox.object_id >= high)
    first("vox_object_id", bad_id, vox.object_id, f"expected 0 to {high - 1}")
    if vox.side is not None:
        side = vox.side
        first("vox_side", (side != 0) & (side != 1), side, "expected 0 or 1")
        one = np.flatnonzero(side == 1)
        lone = (one == 0) | (side[np.maximum(one - 1, 0)] != 0)
        lone |= np.any(vox.ijk[one] != vox.ijk[np.maximum(one - 1, 0)], axis=1)
        if lone.any():
            raise ValueError(
                f"{where}: vox_side: record {int(one[lone][0])} is a reverse side (1) that "
                "does not follow a front record (0) of the same voxel"
            )
