"""Reconstruction filters: how one frame's samples make its pixels
(``Camera.pixel_filter``, ``docs/design.md`` §6)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["gaussian_pixel_filter"]

#: Pixels from a sample's own to the farthest pixel a reconstruction filter
#: weights it into (``Camera.pixel_filter``).
_FILTER_REACH = {"box": 0, "gaussian": 2}


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
    sigma = 0.5
    radius = 4 * sigma
    reach = _FILTER_REACH["gaussian"]
    taps = np.arange(-reach, reach + 1)  # sample pixel minus output pixel, within the radius

    def weights(o: float) -> np.ndarray:
        x = taps + o - 0.5
        w = np.exp(-(x * x) / (2 * sigma**2)) - math.exp(-(radius**2) / (2 * sigma**2))
        return np.where(np.abs(x) < radius, np.maximum(w, 0.0), 0.0)

    def along(img: np.ndarray, w: np.ndarray, axis: int) -> np.ndarray:
        n = img.shape[axis]
        out = np.zeros_like(img)
        for t, wt in zip(taps, w, strict=True):
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
    img = np.concatenate(
        [frame.reshape(height, width, c).astype(np.float64), np.ones((height, width, 1))], axis=2
    )
    wx, wy = weights(float(offset[0])), weights(float(offset[1]))
    img = along(along(img, wx, 1), wy, 0)
    return (img[..., :c] / img[..., c:]).reshape(-1, c).astype(np.float32)
