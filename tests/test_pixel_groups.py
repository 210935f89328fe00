"""The display's VPL sets: dealt to the pixels at random each frame, in
equal shares, so that no pattern and no whole frame errs together."""

from __future__ import annotations

import numpy as np

import voxgi
from voxgi.display.shader import _FrameShader


def _set_image(cam, n, rng=None) -> np.ndarray:
    perm, cuts = _FrameShader._pixel_groups(cam, n, rng)
    key = np.empty(cam.width * cam.height, int)
    for g in range(len(cuts) - 1):
        key[perm[cuts[g] : cuts[g + 1]]] = g
    return key.reshape(cam.height, cam.width)


def test_vpl_sets_are_dealt_at_random_in_equal_shares():
    cam = voxgi.Camera(width=64, height=48)
    assert _FrameShader.vpl_sets(cam) == min(_FrameShader.VPL_SETS, 64 * 48 // 16)
    assert _FrameShader.vpl_sets(voxgi.Camera(width=2, height=2)) == 1
    a = _set_image(cam, 192, np.random.default_rng(1))
    b = _set_image(cam, 192, np.random.default_rng(2))
    for img in (a, b):
        np.testing.assert_array_equal(np.bincount(img.ravel()), np.full(192, 16))
        # neighbours share a set about once in 192, at any lag: no pattern
        for lag in (1, 2, 4):
            assert np.mean(img[:, lag:] == img[:, :-lag]) < 0.02
            assert np.mean(img[lag:] == img[:-lag]) < 0.02
    assert not np.array_equal(a, b)


def test_without_the_filter_the_error_has_no_period_of_four():
    scene = voxgi.scenes.cornell_box(64, 64)
    sol = voxgi.solve(voxgi.voxelize(scene, 16), progress=False)
    kw = {"tuning": voxgi.RenderTuning(indirect_filter=0), "tol": 0, "progress": False}
    ref = voxgi.render(scene, sol, max_frames=64, seed=1000, **kw).image
    img = voxgi.render(scene, sol, max_frames=8, seed=0, **kw).image
    rho = voxgi.metrics.error_autocorrelation(img, ref)
    # with the sets fixed on a 4-periodic pattern, lag 4 stands out (0.3 here
    # against 0.05-0.1 at lags 1-3; 0.3-0.5 at 256x256); dealt at random,
    # it is like its neighbours
    assert rho[3] < 0.15, rho
    assert rho[3] < max(rho[:3]) + 0.03, rho
