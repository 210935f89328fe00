"""Error metrics."""

from __future__ import annotations

import numpy as np
import pytest

from voxgi import metrics


def test_rel_mse_closed_form():
    ref = np.full((4, 4, 3), 2.0)
    img = ref + 0.1
    # (0.1)^2 / (4 + 0.01)
    assert metrics.rel_mse(img, ref) == pytest.approx(0.01 / 4.01)
    assert metrics.rmse(img, ref) == pytest.approx(0.1)
    assert metrics.rel_mse(ref, ref) == 0.0


def test_psnr_ssim_identical_and_different(rng):
    ref = rng.random((32, 32, 3)).astype(np.float32)
    assert metrics.psnr(ref, ref) == float("inf")
    assert metrics.ssim(ref, ref) == pytest.approx(1.0)
    noisy = ref + 0.1 * rng.standard_normal(ref.shape).astype(np.float32)
    assert 10 < metrics.psnr(noisy, ref) < 40
    assert metrics.ssim(noisy, ref) < 0.95


def test_metrics_bad_input():
    with pytest.raises(ValueError, match="shape"):
        metrics.rel_mse(np.zeros((2, 2, 3)), np.zeros((3, 2, 3)))
    with pytest.raises(ValueError, match="NaN"):
        metrics.rmse(np.full((2, 2, 3), np.nan), np.zeros((2, 2, 3)))


def test_error_time_record(rng):
    ref = rng.random((8, 8, 3))
    r = metrics.ErrorTime.measure("voxgi", 1.0, ref * 1.01, ref, resolution=64)
    d = r.to_dict()
    assert d["method"] == "voxgi"
    assert d["params"] == {"resolution": 64}
    assert d["rel_mse"] > 0
