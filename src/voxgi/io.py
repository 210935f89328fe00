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
    "TONEMAPS",
    "atomic_path",
    "auto_exposure",
    "check_solution_records",
    "is_read_only",
    "read_exr",
    "read_exr_channels",
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


def write_exr(
    path, image, metadata: dict | None = None, *, stderr=None, layers: dict | None = None
) -> Path:
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
    layers : dict, optional
        More channels, ``name -> (H, W) array`` of the image's height and
        width, written as float32 (``RenderResult.exr_layers()``: the pixel
        AOVs ``albedo.R``, ``normal.X``, ``depth.Z``, ...); read back with
        :func:`read_exr_channels`, or ``read_exr(path, layer="albedo")``.
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
    for name, a in (layers or {}).items():
        if not isinstance(name, str) or not name or name in channels or name in "RGB":
            raise ValueError(f"layers: bad or repeated channel name {name!r}")
        arr = np.asarray(a)
        if arr.dtype == object or not np.issubdtype(arr.dtype, np.number):
            raise TypeError(f"layers[{name!r}]: expected a numeric array, got dtype {arr.dtype}")
        if arr.shape != img.shape[:2]:
            raise ValueError(f"layers[{name!r}]: expected shape {img.shape[:2]}, got {arr.shape}")
        channels[name] = np.ascontiguousarray(arr, dtype=np.float32)
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


def _open_exr(path: Path, **options):
    """Open an EXR for reading: FileNotFoundError if absent, ValueError if unreadable."""
    import OpenEXR

    if not path.exists():
        raise FileNotFoundError(f"EXR file not found: {path}")
    try:
        return OpenEXR.File(str(path), **options)
    except RuntimeError as exc:  # not an EXR, truncated, unreadable
        raise ValueError(f"{path}: cannot be read as OpenEXR ({exc})") from None


def read_exr(path, layer: str | None = None) -> np.ndarray:
    """Read an OpenEXR file's RGB channels as (H, W, 3) float32.

    ``layer`` reads the channels ``<layer>.R``, ``<layer>.G``, ``<layer>.B``
    (or ``.X``, ``.Y``, ``.Z``) instead (``"stderr"``: the error estimate
    :func:`write_exr` stores; ``"albedo"``, ``"normal"``: the pixel AOVs).
    """
    path = Path(path)
    with _open_exr(path) as f:
        ch = f.channels()
        if layer is not None:
            if layer in ch and ch[layer].pixels.ndim == 3:
                px = ch[layer].pixels
            elif all(f"{layer}.{c}" in ch for c in "RGB"):
                px = np.stack([ch[f"{layer}.{c}"].pixels for c in "RGB"], axis=-1)
            elif all(f"{layer}.{c}" in ch for c in "XYZ"):
                px = np.stack([ch[f"{layer}.{c}"].pixels for c in "XYZ"], axis=-1)
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


def read_exr_channels(path) -> dict:
    """Every channel of an EXR file, by its full name (``R``, ``stderr.R``,
    ``albedo.R``, ``depth.Z``, ...), as (H, W) float32."""
    path = Path(path)
    with _open_exr(path, separate_channels=True) as f:
        return {
            name: np.ascontiguousarray(c.pixels, dtype=np.float32)
            for name, c in f.channels().items()
        }


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


TONEMAPS = ("reinhard", "clip")
"""The PNG preview's tone curves (:func:`to_srgb8`)."""

_KEY = 0.18  # Reinhard et al. 2002: the "normal" key, middle grey
_WHITE_PERCENTILE = 99.9  # the white point ignores the brightest 0.1% (fireflies)
_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709 / sRGB primaries


def _finite_image(image) -> np.ndarray:
    img = _check_image(image).astype(np.float64)
    return np.clip(np.nan_to_num(img, nan=0.0, posinf=0.0, neginf=0.0), 0.0, None)


def _check_exposure(exposure) -> float:
    if isinstance(exposure, bool) or not isinstance(exposure, (int, float, np.number)):
        raise TypeError(f"exposure: expected a number, got {exposure!r}")
    if not np.isfinite(exposure):
        raise ValueError(f"exposure: must be finite, got {exposure}")
    return float(exposure)


def auto_exposure(image) -> float:
    """The exposure, in stops, that maps an image's log-average luminance to
    middle grey (0.18).

    Parameters
    ----------
    image : (H, W, 3) or (H, W) array
        Linear radiance; NaN, infinite and negative values count as 0.

    Returns
    -------
    exposure : float
        ``log2(0.18 / Lavg)`` with ``Lavg = exp(mean(log(1e-6 + L)))`` over
        the pixels' luminance ``L`` (Reinhard et al. 2002, "Photographic Tone
        Reproduction for Digital Images", eq. 1-2); 0 for a black image.
    """
    lum = _finite_image(image) @ _LUMINANCE
    if not np.any(lum > 0.0):
        return 0.0
    log_average = float(np.exp(np.mean(np.log(1e-6 + lum))))
    return float(np.log2(_KEY / log_average))


def to_srgb8(image, exposure: float = 0.0, tonemap: str = "clip") -> np.ndarray:
    """Tone-map linear radiance to 8-bit sRGB.

    Parameters
    ----------
    image : (H, W, 3) or (H, W) array
        Linear radiance. NaN and negative values map to black, +inf to white.
    exposure : float, optional
        Scale by ``2**exposure`` first.
    tonemap : {"clip", "reinhard"}, optional
        ``"clip"``: clip to [0, 1]. ``"reinhard"``: Reinhard et al.'s extended
        curve ``x (1 + x / w²) / (1 + x)`` per channel, with the white point
        ``w`` the larger of 1 and the 99.9th percentile of the exposed
        luminance: the identity where nothing exceeds 1, otherwise the
        highlights are compressed so that only the brightest 0.1% reach white.
        Then the sRGB transfer curve.

    Returns
    -------
    srgb : (H, W, 3) uint8
    """
    exposure = _check_exposure(exposure)
    if tonemap not in TONEMAPS:
        raise ValueError(f"tonemap: expected one of {TONEMAPS}, got {tonemap!r}")
    # Bounded so that the curve's x² stays finite in float64 for any exposure.
    img = np.minimum(_finite_image(image) * (2.0**exposure), 1e150)
    burnt = np.isposinf(_check_image(image))
    if tonemap == "reinhard":
        white = max(1.0, float(np.percentile(img @ _LUMINANCE, _WHITE_PERCENTILE)))
        img = img / (1.0 + img) * (1.0 + img / (white * white))
    img = np.where(burnt, 1.0, np.clip(img, 0.0, 1.0))
    srgb = np.where(img <= 0.0031308, 12.92 * img, 1.055 * np.power(img, 1 / 2.4) - 0.055)
    return np.round(srgb * 255.0).astype(np.uint8)


def write_png(path, image, exposure: float | None = None, tonemap: str = "reinhard") -> Path:
    """Write a tone-mapped 8-bit sRGB PNG preview of a linear image.

    Parameters
    ----------
    path : str or Path
    image : (H, W, 3) or (H, W) array
        Linear radiance.
    exposure : float, optional
        Exposure in stops; ``None`` chooses it from the image
        (:func:`auto_exposure`).
    tonemap : {"reinhard", "clip"}, optional
        The tone curve (:func:`to_srgb8`).
    """
    from skimage.io import imsave

    path = Path(path)
    if exposure is None:
        exposure = auto_exposure(image)
    srgb = to_srgb8(image, exposure, tonemap)
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
