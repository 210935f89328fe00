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


def _ar1_field(rng, n: int, rho: float) -> np.ndarray:
    """A stationary unit-variance field whose correlation between pixels
    (dy, dx) apart is rho^|dx| rho^|dy|: AR(1) along rows, then columns."""
    x = rng.standard_normal((n, n))
    s = np.sqrt(1.0 - rho * rho)
    for j in range(1, n):
        x[:, j] = rho * x[:, j - 1] + s * x[:, j]
    for i in range(1, n):
        x[i] = rho * x[i - 1] + s * x[i]
    return x


def test_error_autocorrelation_of_white_noise_is_zero(rng):
    ref = np.full((256, 256, 3), 2.0)
    img = ref * (1.0 + 0.05 * rng.standard_normal(ref.shape))
    rho = metrics.error_autocorrelation(img, ref)
    # 2 * 3 * 256 * 255 pairs per lag: the estimate's standard deviation ~1/sqrt(392k)
    assert np.all(np.abs(rho) < 0.01), rho


def test_error_autocorrelation_of_ar1_field_is_rho_to_the_lag(rng):
    rho = 0.6
    ref = np.ones((384, 384))
    img = ref + 0.01 * _ar1_field(rng, 384, rho)
    got = metrics.error_autocorrelation(img, ref, lags=(1, 2, 3, 4))
    # the sample's correlation at lag k has a spread of about
    # sqrt((1 + rho²) / (1 - rho²) / pairs) ~ 0.005 here
    np.testing.assert_allclose(got, rho ** np.arange(1, 5), atol=0.03)


def test_error_autocorrelation_counts_an_error_the_whole_image_shares(rng):
    # relative error: an offset c = 0.02 plus white noise of s = 0.02:
    # E[e_i e_j] = c², E[e²] = c² + s², so rho = 1/2 at every lag
    ref = np.full((256, 256, 3), 1.0)
    img = ref * (1.02 + 0.02 * rng.standard_normal(ref.shape))
    rho = metrics.error_autocorrelation(img, ref, eps=0.0)
    np.testing.assert_allclose(rho, 0.5, atol=0.01)


def test_error_autocorrelation_sees_a_pattern_of_interleaved_groups(rng):
    # 16 pixel groups on a 4x4 tile, each erring by its own amount: the error
    # repeats every 4 pixels, so lag 4 correlates fully.
    tile = rng.standard_normal((4, 4))
    ref = np.full((64, 64, 3), 0.5)
    img = ref + 0.01 * np.tile(tile, (16, 16))[..., None]
    rho = metrics.error_autocorrelation(img, ref, lags=(4, 8))
    np.testing.assert_allclose(rho, 1.0, atol=1e-12)


def test_error_autocorrelation_mask_and_bad_input(rng):
    ref = np.ones((32, 32))
    noise = rng.standard_normal((32, 32))
    img = ref + 0.01 * noise
    img[:, 16:] = 1.5  # a constant offset outside the mask
    mask = np.zeros((32, 32), bool)
    mask[:, :16] = True
    rho_masked = metrics.error_autocorrelation(img, ref, lags=(1, 3), mask=mask)
    assert np.all(np.abs(rho_masked) < 0.15)
    # the mask's pairs are those of the crop to it
    crop = metrics.error_autocorrelation(img[:, :16], ref[:, :16], lags=(1, 3))
    np.testing.assert_allclose(rho_masked, crop, rtol=1e-12)
    assert metrics.error_autocorrelation(img, ref, lags=(1,))[0] > 0.9
    with pytest.raises(ValueError, match="lags"):
        metrics.error_autocorrelation(img, ref, lags=(0,))
    with pytest.raises(ValueError, match="lags"):
        metrics.error_autocorrelation(img, ref, lags=(32,))
    with pytest.raises(ValueError, match="mask"):
        metrics.error_autocorrelation(img, ref, mask=mask[:4])
    with pytest.raises(ValueError, match="no pixel"):
        metrics.error_autocorrelation(img, ref, mask=np.zeros((32, 32), bool))
    with pytest.raises(ValueError, match="error is 0"):
        metrics.error_autocorrelation(ref, ref)
