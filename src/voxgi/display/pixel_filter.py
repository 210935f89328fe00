"""Reconstruction filters: how one frame's samples make its pixels
(``Camera.pixel_filter``, ``docs/design.md`` §6)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["GAUSSIAN_TAPS", "gaussian_norms", "gaussian_pixel_filter", "gaussian_weights"]

#: Pixels from a sample's own to the farthest pixel a reconstruction filter
#: weights it into (``Camera.pixel_filter``).
_FILTER_REACH = {"box": 0, "gaussian": 2}


#: Mitsuba 3's ``gaussian`` filter: standard deviation and radius, pixels.
_SIGMA = 0.5
_RADIUS = 4 * _SIGMA
#: Sample pixel minus output pixel, within the Gaussian filter's radius.
GAUSSIAN_TAPS = np.arange(-_FILTER_REACH["gaussian"], _FILTER_REACH["gaussian"] + 1)


def gaussian_weights(offset: float) -> np.ndarray:
    """(len(GAUSSIAN_TAPS),) weights of a sample at sub-pixel ``offset`` (one
    axis) in the pixels ``-t`` from its own, ``t`` in :data:`GAUSSIAN_TAPS`:
    ``max(0, exp(-x²/2σ²) - exp(-r²/2σ²))``, ``x`` the distance from the
    sample to the pixel's centre."""
    x = GAUSSIAN_TAPS + float(offset) - 0.5
    w = np.exp(-(x * x) / (2 * _SIGMA**2)) - math.exp(-(_RADIUS**2) / (2 * _SIGMA**2))
    return np.where(np.abs(x) < _RADIUS, np.maximum(w, 0.0), 0.0)


def gaussian_norms(offset: float, n: int) -> np.ndarray:
    """(n,) the weights each of ``n`` pixels along one axis receives from the
    samples at ``offset`` (fewer near the image's edge), which
    :func:`gaussian_pixel_filter` divides by."""
    w = gaussian_weights(offset)
    out = np.zeros(n)
    for t, wt in zip(GAUSSIAN_TAPS, w, strict=True):
        out[max(0, -t) : min(n, n - t)] += wt
    return out


def gaussian_pixel_filter(frame: np.ndarray, width: int, height: int, offset) -> np.ndarray:
    """One frame's samples, taken at ``offset`` in every pixel, weighted into
    the pixels around them by Mitsuba 3's Gaussian reconstruction filter.

    The filter is separable, ``w(x) = max(0, exp(-x²/2σ²) - exp(-r²/2σ²))``
    with σ = 0.5 pixel and r = 4σ, ``x`` the distance from the sample to a
    pixel's centre; each pixel is normalised by the weights it received, so
    the image edge needs no samples outside it (``docs/design.md`` §6).

    Parameters
    ----------
    frame : (H*W, C) array
        The frame, row-major pixels.
    width, height : int
    offset : (2,) float
        The frame's sub-pixel sample position (x right, y down) in [0, 1)².

    Returns
    -------
    (H*W, C) float32
    """

    def along(img: np.ndarray, w: np.ndarray, axis: int) -> np.ndarray:
        n = img.shape[axis]
        out = np.zeros_like(img)
        for t, wt in zip(GAUSSIAN_TAPS, w, strict=True):
            if wt == 0.0:
                continue
            # the output pixel i takes the sample of pixel i + t
            dst = [slice(None)] * img.ndim
            src = [slice(None)] * img.ndim
            dst[axis] = slice(max(0, -t), min(n, n - t))
            src[axis] = slice(max(0, t), min(n, n + t))
            out[tuple(dst)] += wt * img[tuple(src)]
        return out

    c = frame.shape[1]
    img = frame.reshape(height, width, c).astype(np.float64)
    ox, oy = float(offset[0]), float(offset[1])
    img = along(along(img, gaussian_weights(ox), 1), gaussian_weights(oy), 0)
    img /= gaussian_norms(oy, height)[:, None, None] * gaussian_norms(ox, width)[None, :, None]
    return img.reshape(-1, c).astype(np.float32)
