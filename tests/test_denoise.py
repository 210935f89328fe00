"""OIDN through voxgi.denoise (the optional ``denoise`` extra)."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from voxgi import denoise, metrics


def _scene(rng, n: int = 96):
    """Two albedos under a smooth light, and its copy with 30% white noise."""
    y, x = np.mgrid[0:n, 0:n] / n
    albedo = np.where((x > 0.5)[..., None], [0.7, 0.2, 0.2], [0.2, 0.6, 0.3]).astype(np.float32)
    normal = np.zeros((n, n, 3), np.float32)
    normal[..., 2] = 1.0
    light = (0.5 + 3.0 * np.exp(-((x - 0.3) ** 2 + (y - 0.3) ** 2) / 0.02))[..., None]
    clean = (albedo * light).astype(np.float32)
    noisy = np.clip(clean * (1 + 0.3 * rng.standard_normal(clean.shape)), 0, None)
    return clean, noisy.astype(np.float32), albedo, normal


def test_absent_oidn_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "mitsuba_oidn", None)  # import fails
    assert denoise.available() is False
    with pytest.raises(ImportError, match=r'pip install "voxgi\[denoise\]"'):
        denoise.denoise(np.ones((4, 4, 3)))


def test_bad_buffers(rng):
    _, noisy, albedo, normal = _scene(rng, 8)
    with pytest.raises(ValueError, match="albedo: expected the image's shape"):
        denoise.denoise(noisy, albedo[:4])
    with pytest.raises(ValueError, match="normal: OIDN takes"):
        denoise.denoise(noisy, None, normal)
    with pytest.raises(ValueError, match="image: holds NaN"):
        denoise.denoise(np.full((4, 4, 3), np.nan))
    with pytest.raises(TypeError, match="image: expected a numeric"):
        denoise.denoise(np.array([["a"]]))


def test_oidn_removes_white_noise_guided_by_albedo_and_normal(rng):
    pytest.importorskip("mitsuba_oidn")
    clean, noisy, albedo, normal = _scene(rng)
    before = metrics.rel_mse(noisy, clean)
    out = denoise.denoise(noisy, albedo, normal)
    assert out.dtype == np.float32
    assert out.shape == noisy.shape
    # OIDN 2.5 takes this relMSE from 7e-2 to about 1e-3: a factor over 10
    assert metrics.rel_mse(out, clean) < before / 10
