"""Denoising a rendered image with Intel Open Image Denoise (OIDN).

OIDN's ``RT`` filter, on the CPU, through the ``mitsuba-oidn`` binding (the
optional extra ``pip install "voxgi[denoise]"``), fed with the render's own
pixel AOVs: the albedo and shading normal of each pixel's first hits,
averaged over the same camera samples and pixel filter as the image
(:class:`voxgi.display.RenderResult`). Those AOVs carry no sampling noise of
their own (they come from the camera hits, not from the lighting), so OIDN
is told they are clean and does not prefilter them.

The emitted radiance a pixel sees directly (a lamp, a window, the sky) is
kept out of the denoiser: it is exact in voxgi's image (controlled where a
pixel sees it unevenly), and OIDN, whose albedo guide cannot tell a black
emitter from a black frame, would spread a bright window's light over the
thin dark bars beside it. Only the reflected light, the image less its
``emission`` AOV, is denoised; the emission is added back unchanged.
"""

from __future__ import annotations

import numpy as np

__all__ = ["available", "denoise", "load_oidn"]

_EXTRA = 'pip install "voxgi[denoise]"'


def load_oidn():
    """The ``mitsuba_oidn`` module; ImportError naming the extra without it."""
    try:
        import mitsuba_oidn
    except ImportError as exc:
        raise ImportError(
            "voxgi.denoise needs Intel Open Image Denoise through the mitsuba-oidn "
            f"package, which is not installed: {_EXTRA}"
        ) from exc
    return mitsuba_oidn


def available() -> bool:
    """True when OIDN can be imported (the ``denoise`` extra is installed)."""
    try:
        load_oidn()
    except ImportError:
        return False
    return True


def _rgb(a, name: str, shape=None) -> np.ndarray:
    arr = np.asarray(a)
    if arr.dtype == object or not np.issubdtype(arr.dtype, np.number):
        raise TypeError(f"{name}: expected a numeric array, got dtype {arr.dtype}")
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.shape[0] == 0 or arr.shape[1] == 0:
        raise ValueError(f"{name}: expected shape (H, W, 3), got {arr.shape}")
    if shape is not None and arr.shape != shape:
        raise ValueError(f"{name}: expected the image's shape {shape}, got {arr.shape}")
    arr = np.ascontiguousarray(arr, dtype=np.float32)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: holds NaN or infinite values")
    return arr


def denoise(
    image, albedo=None, normal=None, *, emission=None, clean_aux: bool = True
) -> np.ndarray:
    """Denoise a linear HDR image with OIDN, guided by albedo and normal.

    Parameters
    ----------
    image : (H, W, 3) array or RenderResult
        Linear radiance (non-negative). A :class:`voxgi.display.RenderResult`
        brings its own ``albedo``, ``normal`` and ``emission`` when they
        are not given, and its image before any denoising.
    albedo : (H, W, 3) array, optional
        Reflectance in [0, 1] of the surface each pixel sees.
    normal : (H, W, 3) array, optional
        Shading normals in [-1, 1] (any fixed space; averaged normals shorter
        than 1 are what an anti-aliased buffer holds); needs ``albedo``.
    emission : (H, W, 3) array, optional
        The part of ``image`` that is emitted radiance seen directly
        (non-negative): only ``image - emission`` is denoised, and
        ``emission`` is added back unchanged. None: all of it is denoised.
    clean_aux : bool, optional
        The AOVs have no noise of their own (True for voxgi's, which are
        exact up to anti-aliasing); False lets OIDN prefilter them.

    Returns
    -------
    denoised : (H, W, 3) float32

    Raises
    ------
    ImportError
        If the ``denoise`` extra (``mitsuba-oidn``) is not installed.
    ValueError, TypeError
        If an array has another shape, is not numeric, or holds NaN or
        infinity; or ``normal`` comes without ``albedo``.
    """
    if hasattr(image, "image") and hasattr(image, "frames"):  # a RenderResult
        albedo = getattr(image, "albedo", None) if albedo is None else albedo
        normal = getattr(image, "normal", None) if normal is None else normal
        emission = getattr(image, "emission", None) if emission is None else emission
        undenoised = getattr(image, "undenoised", None)
        image = image.image if undenoised is None else undenoised
    color = _rgb(image, "image")
    seen = None if emission is None else _rgb(emission, "emission", color.shape)
    if seen is not None and np.any(seen < 0.0):
        raise ValueError("emission: holds negative values")
    if normal is not None and albedo is None:
        raise ValueError("normal: OIDN takes a normal buffer only together with an albedo buffer")
    aux = [
        None if a is None else _rgb(a, n, color.shape)
        for a, n in ((albedo, "albedo"), (normal, "normal"))
    ]
    oidn = load_oidn()
    reflected = color if seen is None else color - seen
    out = oidn.denoise(
        np.maximum(reflected, 0.0),
        aux[0],
        aux[1],
        hdr=True,
        clean_aux=bool(clean_aux) and aux[0] is not None,
    )
    out = np.ascontiguousarray(np.asarray(out), dtype=np.float32)
    if seen is not None:
        out += seen
    return out
