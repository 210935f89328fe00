"""Image error metrics: relMSE and RMSE on linear radiance, PSNR and SSIM on
tone-mapped images (scikit-image), and the error's spatial autocorrelation."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

__all__ = ["ErrorTime", "error_autocorrelation", "psnr", "rel_mse", "rmse", "ssim"]


def _pair(img, ref) -> tuple[np.ndarray, np.ndarray]:
    a = np.asarray(img, dtype=np.float64)
    b = np.asarray(ref, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"image shape {a.shape} differs from reference shape {b.shape}")
    if a.size == 0:
        raise ValueError("images are empty")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise ValueError("images contain NaN or infinity")
    return a, b


def rel_mse(img, ref, *, eps: float = 0.01) -> float:
    """Relative MSE: mean over pixels and channels of ``(x - r)² / (r² + eps)``.

    ``eps = 0.01`` as in ``docs/design.md`` §9.

    Parameters
    ----------
    img, ref : array_like
        The image and the reference, of one shape (e.g. (H, W, 3)), linear
        radiance.
    eps : float
        Added to ``r²`` so that black reference pixels count as absolute errors.

    Returns
    -------
    float
        The relMSE (0 for equal images).
    """
    a, b = _pair(img, ref)
    return float(np.mean((a - b) ** 2 / (b * b + eps)))


def error_autocorrelation(img, ref, lags=(1, 2, 3, 4), *, eps: float = 0.01, mask=None):
    """Spatial autocorrelation of the relative error image at pixel lags.

    The correlation a denoiser relies on being absent: a per-pixel
    independent error gives 0 at every lag; an error that neighbours share
    (a pattern, a blur, a whole frame off) gives a large value.

    Parameters
    ----------
    img, ref : (H, W, 3) or (H, W) arrays
        The image and its reference (linear radiance).
    lags : sequence of int, optional
        Pixel offsets, each at least 1 and less than both image sides.
    eps : float, optional
        The error is taken relative, ``e = (x - r) / sqrt(r² + eps)``, as in
        :func:`rel_mse`, so that each pixel weighs what it weighs in relMSE.
    mask : (H, W) bool array, optional
        Pixels to use (e.g. leave out the emitters, whose error is 0); a pair
        counts only if both of its pixels are in the mask.

    Returns
    -------
    rho : (len(lags),) float64
        For each lag ``k``, ``sum(e_i e_j) / sqrt(sum(e_i²) sum(e_j²))`` over
        the pairs of pixels ``k`` apart, horizontal and vertical, and the
        channels together. The error's mean is not removed: an error the
        whole image shares (every frame off by one factor, a bias) is
        correlated error, and no denoiser removes it; white noise of zero
        mean gives 0, an offset ``c`` plus white noise of variance ``s²``
        gives ``c² / (c² + s²)``.

    Raises
    ------
    ValueError
        If the shapes differ, a lag is out of range, the mask has another
        shape, or the error is 0 on every pair of some lag.
    """
    a, b = _pair(img, ref)
    if a.ndim == 2:
        a, b = a[..., None], b[..., None]
    h, w = a.shape[:2]
    m = np.ones((h, w), bool) if mask is None else np.asarray(mask)
    if m.dtype != bool or m.shape != (h, w):
        raise ValueError(f"mask: expected a bool array of shape {(h, w)}, got {m.dtype} {m.shape}")
    lags = [int(k) for k in lags]
    if not lags or min(lags) < 1 or max(lags) >= min(h, w):
        raise ValueError(f"lags: expected integers in [1, {min(h, w) - 1}], got {lags}")
    if not m.any():
        raise ValueError("mask selects no pixel")
    e = (a - b) / np.sqrt(b * b + eps)
    rho = []
    for k in lags:
        num = sq0 = sq1 = 0.0
        for e0, e1, both in (
            (e[:, :-k], e[:, k:], m[:, :-k] & m[:, k:]),
            (e[:-k], e[k:], m[:-k] & m[k:]),
        ):
            x0, x1 = e0[both], e1[both]
            num += float(np.sum(x0 * x1))
            sq0 += float(np.sum(x0 * x0))
            sq1 += float(np.sum(x1 * x1))
        if sq0 == 0.0 or sq1 == 0.0:
            raise ValueError(f"the error is 0 on every pair {k} pixels apart")
        rho.append(num / np.sqrt(sq0 * sq1))
    return np.array(rho)


def rmse(img, ref) -> float:
    """Root-mean-square error on linear radiance.

    Parameters
    ----------
    img, ref : array_like
        The image and the reference, of one shape (e.g. (H, W, 3)), linear
        radiance.

    Returns
    -------
    float
        ``sqrt(mean((img - ref)²))`` in radiance units.
    """
    a, b = _pair(img, ref)
    return float(np.sqrt(np.mean((a - b) ** 2)))


def _tonemapped(img, ref, exposure: float):
    from .io import to_srgb8

    a, b = _pair(img, ref)
    if a.ndim == 2:
        a, b = a[..., None].repeat(3, -1), b[..., None].repeat(3, -1)
    return to_srgb8(a, exposure), to_srgb8(b, exposure)


def psnr(img, ref, *, exposure: float = 0.0) -> float:
    """PSNR (dB) between the 8-bit sRGB tone-mapped images (scikit-image).

    Parameters
    ----------
    img, ref : array_like
        The image and the reference, of one shape (e.g. (H, W, 3)), linear
        radiance.
    exposure : float
        Exposure in stops applied to both before the sRGB tone mapping
        (:func:`voxgi.io.to_srgb8`).

    Returns
    -------
    float
        Peak signal-to-noise ratio in dB; ``inf`` for equal 8-bit images.
    """
    from skimage.metrics import peak_signal_noise_ratio

    a, b = _tonemapped(img, ref, exposure)
    if np.array_equal(a, b):
        return float("inf")
    return float(peak_signal_noise_ratio(b, a, data_range=255))


def ssim(img, ref, *, exposure: float = 0.0) -> float:
    """Structural similarity of the 8-bit sRGB tone-mapped images (scikit-image).

    Parameters
    ----------
    img, ref : array_like
        The image and the reference, of one shape (e.g. (H, W, 3)), linear
        radiance.
    exposure : float
        Exposure in stops applied to both before the sRGB tone mapping
        (:func:`voxgi.io.to_srgb8`).

    Returns
    -------
    float
        SSIM in [-1, 1], 1 for equal images (a window of at most 7 pixels).
    """
    from skimage.metrics import structural_similarity

    a, b = _tonemapped(img, ref, exposure)
    win = min(7, a.shape[0], a.shape[1])
    win -= (win + 1) % 2  # odd
    return float(structural_similarity(b, a, channel_axis=-1, data_range=255, win_size=max(win, 3)))


def flip(img, ref, *, exposure: float = 0.0) -> float | None:
    """Mean LDR-FLIP error of the 8-bit sRGB tone-mapped images (0: equal,
    1: most different), or None when ``flip-evaluator`` is not installed.

    Parameters
    ----------
    img, ref : array_like
        The image and the reference, of one shape (e.g. (H, W, 3)), linear
        radiance.
    exposure : float
        Exposure in stops applied to both before the sRGB tone mapping
        (:func:`voxgi.io.to_srgb8`).

    Returns
    -------
    float or None
        The mean FLIP error.
    """
    try:
        import flip_evaluator
    except ImportError:
        return None
    a, b = _tonemapped(img, ref, exposure)
    to_unit = lambda x: np.ascontiguousarray(x, np.float32) / 255.0  # noqa: E731
    _, mean, _ = flip_evaluator.evaluate(to_unit(b), to_unit(a), "LDR", applyMagma=False)
    return float(mean)


@dataclass
class ErrorTime:
    """One point of a time-versus-error study, shared by benchmarks and notebooks."""

    method: str
    seconds: float
    rel_mse: float
    params: dict = field(default_factory=dict)
    rmse: float | None = None
    psnr: float | None = None
    ssim: float | None = None

    @classmethod
    def measure(cls, method: str, seconds: float, img, ref, **params) -> ErrorTime:
        return cls(
            method=method,
            seconds=float(seconds),
            rel_mse=rel_mse(img, ref),
            rmse=rmse(img, ref),
            psnr=psnr(img, ref),
            ssim=ssim(img, ref),
            params=params,
        )

    def to_dict(self) -> dict:
        return asdict(self)
