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
    with pytest.raises(ValueError, match="emission: expected the image's shape"):
        denoise.denoise(noisy, albedo, normal, emission=noisy[:4])
    with pytest.raises(ValueError, match="emission: holds negative values"):
        denoise.denoise(noisy, albedo, normal, emission=-noisy)


def test_oidn_removes_white_noise_guided_by_albedo_and_normal(rng):
    pytest.importorskip("mitsuba_oidn")
    clean, noisy, albedo, normal = _scene(rng)
    before = metrics.rel_mse(noisy, clean)
    out = denoise.denoise(noisy, albedo, normal)
    assert out.dtype == np.float32
    assert out.shape == noisy.shape
    # OIDN 2.5 takes this relMSE from 7e-2 to about 1e-3: a factor over 10
    assert metrics.rel_mse(out, clean) < before / 10


def test_seen_emission_is_kept_out_of_the_denoiser(rng):
    """A window of radiance 30 (an emitter: albedo 0) split by a one-pixel
    bar of radiance 0.01 (albedo 0.006), over a noisy floor. The albedo
    guide cannot tell the bar from the window, so OIDN given the whole image
    spreads the window over the bar; given only the reflected light (the
    image less the emission AOV) it keeps both exact."""
    pytest.importorskip("mitsuba_oidn")
    n = 48
    y, x = np.mgrid[0:n, 0:n]
    upper, floor = y < n // 2, y >= n // 2
    bar = (x == 20) & upper
    window = upper & ~bar
    albedo = np.zeros((n, n, 3), np.float32)
    albedo[x == 20] = 0.006
    albedo[floor] = 0.5
    normal = np.zeros((n, n, 3), np.float32)
    normal[..., 2] = 1.0
    emission = np.zeros((n, n, 3), np.float32)
    emission[window] = 30.0
    clean = emission.copy()
    clean[bar] = 0.01
    clean[floor] = albedo[floor]
    noisy = clean.copy()
    noisy[floor] *= 1 + 0.3 * rng.standard_normal(noisy[floor].shape)
    noisy = np.clip(noisy, 0, None)
    split = denoise.denoise(noisy, albedo, normal, emission=emission)
    whole = denoise.denoise(noisy, albedo, normal)
    # OIDN 2.5: the bar 0.004-0.009 with the split (OIDN's own error on so
    # faint a signal), 0.55 on average and up to 1 without
    assert split[bar].max() < 0.02
    assert whole[bar].mean() > 0.1
    # the window is its emission plus OIDN's output for zero reflected light
    np.testing.assert_allclose(split[window], 30.0, atol=0.02)
    assert np.abs(whole[window] - 30.0).max() > 1.0
    floor_err = [metrics.rel_mse(d[floor][None], clean[floor][None]) for d in (split, whole)]
    assert floor_err[0] < floor_err[1]


@pytest.fixture(scope="module")
def small_cornell():
    import voxgi

    scene = voxgi.scenes.cornell_box(48, 48)
    sol = voxgi.solve(voxgi.voxelize(scene, 16), progress=False)
    return scene, sol


def test_render_tuning_denoise_checks_before_any_frame(monkeypatch, small_cornell):
    import voxgi

    scene, sol = small_cornell
    with pytest.raises(TypeError, match="denoise: expected True or False"):
        voxgi.render(scene, sol, tuning=voxgi.RenderTuning(denoise="yes"), progress=False)
    monkeypatch.setitem(sys.modules, "mitsuba_oidn", None)
    with pytest.raises(ImportError, match=r"voxgi\[denoise\]"):
        voxgi.render(scene, sol, tuning=voxgi.RenderTuning(denoise=True), progress=False)


def test_cli_denoise_without_oidn_is_a_usage_error(monkeypatch, tmp_path, capsys):
    from voxgi import cli

    monkeypatch.setitem(sys.modules, "mitsuba_oidn", None)
    with pytest.raises(SystemExit) as exc:
        cli.main(["render", "cornell-box", "-o", str(tmp_path / "a.exr"), "--denoise", "-q"])
    assert exc.value.code == 2
    assert 'pip install "voxgi[denoise]"' in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_denoised_render_keeps_the_undenoised_image_and_is_closer(small_cornell):
    pytest.importorskip("mitsuba_oidn")
    import voxgi

    scene, sol = small_cornell
    kw = {"tol": 0, "max_frames": 4, "seed": 2, "progress": False}
    # denoising turns the indirect filter off by default and takes the
    # filtered render's ray budget (the Cornell box's light is concentrated)
    cheap = {"indirect_filter": 0, "vpls_per_frame": 8, "gather": 4}
    plain = voxgi.render(scene, sol, tuning=voxgi.RenderTuning(**cheap), **kw)
    out = voxgi.render(scene, sol, tuning=voxgi.RenderTuning(denoise=True), **kw)
    assert out.stats["indirect_filter"] == 0
    assert (out.stats["vpls_per_frame"], out.stats["gather_per_frame"]) == (8, 4)
    np.testing.assert_array_equal(out.undenoised, plain.image)
    np.testing.assert_array_equal(out.stderr, plain.stderr)
    assert out.stats["denoised"] is True
    assert plain.stats["denoised"] is False
    assert plain.undenoised is None
    assert "denoise" in out.stats["seconds"]
    ref = voxgi.render(scene, sol, tol=0, max_frames=64, seed=1000, progress=False).image
    assert metrics.rel_mse(out.image, ref) < metrics.rel_mse(plain.image, ref)
    layers = out.exr_layers()
    np.testing.assert_array_equal(layers["undenoised.G"], plain.image[..., 1])


def test_denoised_estimate_of_a_linear_denoiser_is_the_mean_variance(monkeypatch):
    # With the identity as the denoiser, the spread between the first h of n
    # frames and all n is the mean's own: E|m_h - m_n|² = σ² (1/h - 1/n),
    # so the estimate is DENOISED_FACTOR σ² / n / (L² + 0.01) for white
    # frames of value L and deviation σ, whatever the split (12 frames: 6 in
    # the first half of the batches; 24: 8 of 16 after the merge... all h/n).
    import voxgi.denoise as dn
    from voxgi.display import estimate

    monkeypatch.setattr(
        dn, "denoise", lambda img, a=None, n=None, emission=None: np.asarray(img, np.float32)
    )
    rng = np.random.default_rng(5)
    h, w, L, sigma = 64, 64, 0.5, 0.2
    for frames in (8, 13, 40):
        acc = estimate._Mean.empty(h * w)
        for _ in range(frames):
            acc.add(L + sigma * rng.standard_normal((h * w, 3)))
        est, image = estimate.denoised_estimate(acc, (h, w, 3), None, None)
        want = estimate.DENOISED_FACTOR * sigma**2 / frames / (L * L + 0.01)
        assert est == pytest.approx(want, rel=0.05), (frames, est / want)
        np.testing.assert_allclose(image.reshape(-1, 3), acc.mean, rtol=1e-6)


def test_denoised_render_stops_on_the_denoised_estimate(small_cornell):
    pytest.importorskip("mitsuba_oidn")
    import voxgi

    scene, sol = small_cornell
    tol = 2e-3
    out = voxgi.render(
        scene, sol, tol=tol, seed=3, progress=False, tuning=voxgi.RenderTuning(denoise=True)
    )
    s = out.stats
    assert s["indirect_filter"] == 0
    assert out.frames < 256
    assert s["est_rel_mse_denoised"] <= tol
    assert s["denoise_checks"] >= 1
    assert s["seconds"]["denoise"] > 0
