"""Image error metrics: relMSE and RMSE on linear radiance, PSNR and SSIM on
tone-mapped images (scikit-image)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

__all__ = ["ErrorTime", "psnr", "rel_mse", "rmse", "ssim"]


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
    """
    a, b = _pair(img, ref)
    return float(np.mean((a - b) ** 2 / (b * b + eps)))


def rmse(img, ref) -> float:
    """Root-mean-square error on linear radiance."""
    a, b = _pair(img, ref)
    return float(np.sqrt(np.mean((a - b) ** 2)))


def _tonemapped(img, ref, exposure: float):
    from .io import to_srgb8

    a, b = _pair(img, ref)
    if a.ndim == 2:
        a, b = a[..., None].repeat(3, -1), b[..., None].repeat(3, -1)
    return to_srgb8(a, exposure), to_srgb8(b, exposure)


def psnr(img, ref, *, exposure: float = 0.0) -> float:
    """PSNR (dB) between the 8-bit sRGB tone-mapped images (scikit-image)."""
    from skimage.metrics import peak_signal_noise_ratio

    a, b = _tonemapped(img, ref, exposure)
    if np.array_equal(a, b):
        return float("inf")
    return float(peak_signal_noise_ratio(b, a, data_range=255))


def ssim(img, ref, *, exposure: float = 0.0) -> float:
    """Structural similarity of the 8-bit sRGB tone-mapped images (scikit-image)."""
    from skimage.metrics import structural_similarity

    a, b = _tonemapped(img, ref, exposure)
    win = min(7, a.shape[0], a.shape[1])
    win -= (win + 1) % 2  # odd
    return float(structural_similarity(b, a, channel_axis=-1, data_range=255, win_size=max(win, 3)))


def flip(img, ref, *, exposure: float = 0.0) -> float | None:
    """Mean LDR-FLIP error of the 8-bit sRGB tone-mapped images (0: equal,
    1: most different), or None when ``flip-evaluator`` is not installed."""
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
