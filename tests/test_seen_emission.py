"""The emission seen directly, integrated over each pixel (voxgi.display.seen_emission)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

import voxgi
from voxgi import _core
from voxgi.display.samples import camera_arguments
from voxgi.display.settings import _Experiment
from voxgi.display.shader import _Tracer

#: The lamp's radiance and where its outline lies on the image, in pixels
#: from the top-left corner: every edge and corner pixel is partly covered.
LE = (4.0, 2.0, 1.0)
U0, U1, V0, V1 = 7.3, 23.85, 5.6, 17.2
W, H = 32, 24
TAN = math.tan(math.radians(40.0) / 2)


def _lamp_scene(pixel_filter: str = "box", aperture: float = 0.0) -> voxgi.Scene:
    """A one-sided emitting rectangle facing a pinhole camera square on, at
    distance 1, nothing else in view: the image is the lamp's radiance times
    each pixel's covered share."""
    cam = voxgi.Camera(
        eye=(0.0, 0.0, 1.0),
        target=(0.0, 0.0, 0.0),
        up=(0.0, 1.0, 0.0),
        fov=40.0,
        width=W,
        height=H,
        pixel_filter=pixel_filter,
        aperture=aperture,
        focus_distance=1.0 if aperture else None,
    )
    aspect = W / H
    x0, x1 = ((2 * u / W - 1) * TAN * aspect for u in (U0, U1))
    y1, y0 = ((1 - 2 * v / H) * TAN for v in (V0, V1))
    quad = trimesh.Trimesh(
        [(x0, y0, 0.0), (x1, y0, 0.0), (x1, y1, 0.0), (x0, y1, 0.0)],
        [[0, 1, 2], [0, 2, 3]],
        process=False,
    )
    scene = voxgi.Scene(cam)
    scene.add(quad, voxgi.Material(albedo=0.0, emission=LE), name="lamp")
    return scene


def _coverage() -> np.ndarray:
    """(H, W) share of each pixel inside the lamp's outline, exactly."""
    j, i = np.arange(W), np.arange(H)
    cx = np.clip(np.minimum(j + 1, U1) - np.maximum(j, U0), 0, 1)
    cy = np.clip(np.minimum(i + 1, V1) - np.maximum(i, V0), 0, 1)
    return cy[:, None] * cx[None, :]


def _triangles(scene, tr) -> tuple:
    """The scene tables of the camera kernels, as the display makes them."""
    return (
        np.ascontiguousarray(tr.tris, np.float64),
        np.ascontiguousarray(tr.ng, np.float64),
        None,
        np.ascontiguousarray(tr.obj, np.int32),
        np.array([o.two_sided for o in scene.objects], np.uint8),
        np.array([o.material.emission for o in scene.objects], np.float32),
    )


def test_the_mean_seen_emission_is_the_lamps_covered_share():
    from voxgi.display.seen_emission import seen_emission

    scene = _lamp_scene()
    tr = _Tracer(scene, 2)
    try:
        out = seen_emission(scene.camera, tr, _triangles(scene, tr), None, seed=3, threads=2)
    finally:
        tr.close()
    cov = _coverage().ravel()
    partial = np.flatnonzero((cov > 0) & (cov < 1))
    # every pixel the outline crosses is controlled, and besides them only
    # their neighbours (one on each side of an edge)
    assert np.isin(partial, out.pixels).all()
    assert len(out.pixels) <= 3 * len(partial) + 8
    assert out.samples == 256
    assert out.rays == W * H + 256 * len(out.pixels)
    want = cov[out.pixels, None] * np.array(LE)
    # 256 points of a (0, 2)-sequence: an axis-aligned outline's share is
    # counted to within 1/256 per edge crossing the pixel (two at a corner)
    np.testing.assert_allclose(out.mean, want, rtol=0, atol=2 / 256 * max(LE) + 1e-6)
    assert np.abs(out.mean - want).max() > 0  # not a closed form in disguise


def test_a_glint_seen_by_few_samples_takes_more():
    """A lamp strip 0.03 of a pixel wide down column 2, rows 2-9, beside the
    wide lamp: about 8 of a strip pixel's 256 first samples see it, too few
    for its mean to be trusted in general (a bright sky through a gap). Those
    pixels, and only those, take 1024 samples (the rays say so), and their
    means come out within 2/1024 of the lamp's radiance of the exact share;
    the wide lamp's edge pixels keep their 256. (Here the 256 samples of a
    (0, 2)-sequence already met that bound: the rays and the count are what
    fail without the refinement.)"""
    from voxgi.display.seen_emission import seen_emission

    scene = _lamp_scene()
    aspect = W / H
    x0, x1 = ((2 * u / W - 1) * TAN * aspect for u in (2.0, 2.03))
    y1, y0 = ((1 - 2 * v / H) * TAN for v in (2.0, 10.0))
    strip = trimesh.Trimesh(
        [(x0, y0, 0.0), (x1, y0, 0.0), (x1, y1, 0.0), (x0, y1, 0.0)],
        [[0, 1, 2], [0, 2, 3]],
        process=False,
    )
    scene.add(strip, voxgi.Material(albedo=0.0, emission=LE), name="strip")
    tr = _Tracer(scene, 2)
    try:
        out = seen_emission(scene.camera, tr, _triangles(scene, tr), None, seed=3, threads=2)
    finally:
        tr.close()
    mean = dict(zip(out.pixels.tolist(), out.mean, strict=True))
    strip_pixels = [i * W + 2 for i in range(2, 10)]  # rows 2-9: the strip spans them
    assert out.few == len(strip_pixels)
    assert out.rays == W * H + 256 * len(out.pixels) + (1024 - 256) * out.few
    got = np.array([mean[p] for p in strip_pixels])
    want = np.broadcast_to(0.03 * np.array(LE), got.shape)
    np.testing.assert_allclose(got, want, rtol=0, atol=2 / 1024 * max(LE))
    cov = _coverage().ravel()
    edges = [p for p in np.flatnonzero((cov > 0) & (cov < 1)).tolist()]
    want = cov[edges, None] * np.array(LE)
    got = np.array([mean[p] for p in edges])
    np.testing.assert_allclose(got, want, rtol=0, atol=2 / 256 * max(LE) + 1e-6)


@pytest.mark.parametrize("samples", [64, 256])
def test_the_means_estimated_error_bounds_their_error_on_a_lamps_outline(monkeypatch, samples):
    """Every frame shares a controlled pixel's mean, so its error is no
    frame noise: ``variance`` estimates it by the mean's squared gap to the
    mean of its first half. Over 32 scrambles of the footprint samples the
    summed estimate must cover the summed squared error against the
    outline's exact share, and not by more than 4 times: measured 2.3 and
    3.5 times at 64 and 256 samples (the (0, 2)-sequence's error on an
    axis-aligned outline falls faster than independent samples' would).
    The samples' spread over their count, the variance of the mean for
    independent samples, comes out 50-100 times the error here."""
    from voxgi.display import seen_emission as se

    monkeypatch.setattr(se, "_MOST", samples)
    monkeypatch.setattr(se, "_FEWEST", samples)
    scene = _lamp_scene()
    cov = _coverage().ravel()
    estimated = measured = 0.0
    tr = _Tracer(scene, 2)
    try:
        for seed in range(32):
            out = se.seen_emission(scene.camera, tr, _triangles(scene, tr), None, seed, 2)
            want = cov[out.pixels, None] * np.array(LE)
            measured += float(((out.mean - want) ** 2).sum())
            estimated += float(out.variance.sum())
    finally:
        tr.close()
    assert out.samples == samples
    assert measured > 0
    assert measured <= estimated <= 4 * measured


def test_the_means_error_is_in_the_render_stats():
    # the relMSE the means add: their estimated squared error over the
    # image's level squared plus relMSE's epsilon, over every pixel
    from voxgi.display.seen_emission import seen_emission

    scene = _lamp_scene()
    out = voxgi.render(scene, max_frames=2, tol=0.0, progress=False, threads=2)
    tr = _Tracer(scene, 2)
    try:
        ctl = seen_emission(scene.camera, tr, _triangles(scene, tr), None, 0, 2)
    finally:
        tr.close()
    level = out.image.reshape(-1, 3)[ctl.pixels].astype(np.float64)
    want = (ctl.variance / (level**2 + 0.01)).sum() / out.image.size
    assert want > 0
    np.testing.assert_allclose(out.stats["seen_emission"]["est_rel_mse"], want, rtol=1e-5)


@pytest.mark.parametrize("control", [True, False])
def test_a_lamps_outline_is_exact_in_eight_frames_with_the_control(control):
    scene = _lamp_scene()
    out = voxgi.render(
        scene,
        max_frames=8,
        tol=0.0,
        progress=False,
        threads=2,
        tuning=_Experiment(control_emission=control),
    )
    want = _coverage()[..., None] * np.array(LE)
    err = np.abs(out.image - want).max()
    bound = 2 / 256 * max(LE) + 1e-5
    if control:
        assert out.stats["seen_emission"]["pixels"] >= 2 * (W + H) - 20
        assert err <= bound
    else:
        # each frame's one offset per pixel: eight samples of the outline's share
        assert out.stats["seen_emission"] is None
        assert "switched off" in out.stats["skipped"][-1]
        assert err > 4 * bound


def test_through_the_gaussian_filter_eight_frames_are_the_converged_outline():
    # Each frame weights its samples into the pixels around them by their
    # offset; the mean of the filtered frames is what the control stands in
    # for. 256 frames without it converge to that mean (their offsets are
    # the first 256 of a (0, 2)-sequence); 8 frames without it do not.
    scene = _lamp_scene("gaussian")
    sol = voxgi.solve(voxgi.voxelize(scene, resolution=8), progress=False)

    def image(frames, control):
        tuning = _Experiment(control_emission=control)
        out = voxgi.render(
            scene, sol, max_frames=frames, tol=0.0, progress=False, threads=2, tuning=tuning
        )
        return out.image, out.stats

    converged, _ = image(256, False)
    eight, stats = image(8, True)
    plain, _ = image(8, False)
    # both sides of the comparison count an outline to about a 256th
    bound = 2 / 256 * max(LE)
    assert stats["seen_emission"]["pixels"] > 0
    assert np.abs(eight - converged).max() <= bound
    assert np.abs(plain - converged).max() > 3 * bound
    # the filter spreads the lamp past its outline, and the control follows
    assert np.abs(eight - converged)[_coverage() == 0].max() <= bound
    assert eight[_coverage() == 0].max() > 0.01 * max(LE)


def test_what_the_control_does_not_cover_is_said():
    for scene, why in ((_lamp_scene(aperture=0.01), "aperture"), (_dark_scene(), "no emitter")):
        out = voxgi.render(scene, max_frames=2, tol=0.0, progress=False, threads=2)
        assert out.stats["seen_emission"] is None
        assert any(s.startswith("seen emission:") and why in s for s in out.stats["skipped"])


def _dark_scene() -> voxgi.Scene:
    """The lamp's rectangle lit by a point light, emitting nothing."""
    scene = _lamp_scene()
    scene.objects[0].material = voxgi.Material(albedo=0.5)
    scene.add_light(voxgi.PointLight(position=(0.0, 0.0, 0.5), intensity=1.0))
    return scene


def test_the_kernel_sees_what_the_camera_hits_see():
    scene = voxgi.scenes.cornell_box(width=20, height=15)
    cam = scene.camera.replace(aperture=0.03, focus_distance=0.9)
    tr = _Tracer(scene, 2)
    n_obj = len(scene.objects)
    tables = list(_triangles(scene, tr))
    tables[4] = (np.arange(n_obj) % 2).astype(np.uint8)
    tables[5] = np.arange(1, 3 * n_obj + 1, dtype=np.float32).reshape(n_obj, 3)
    camera = camera_arguments(cam, tr.centre)
    pixels = np.array([0, 7, 150, 299], np.int64)
    samples = np.array([[0.3, 0.8, 0.6, -0.5], [0.0, 0.999, 0.0, 0.0]])
    try:
        le, wo, prim, through = _core.camera_emission(
            *camera, pixels, samples, *tables, tr.native, threads=2
        )
        for k, s in enumerate(samples):
            h = _core.camera_hits(
                *camera, tuple(s[:2]), tuple(s[2:]), *tables, tr.native, threads=2
            )
            np.testing.assert_array_equal(le[k::2], h[5][pixels])
            np.testing.assert_array_equal(prim[k::2], h[6][pixels])
            np.testing.assert_array_equal(wo[k::2], h[3][pixels])
        assert through is None
        # emitting and black hits both
        assert np.any(le > 0)
        assert np.any(le == 0)
        with pytest.raises(ValueError, match="pixel 300 outside the 20x15 image"):
            _core.camera_emission(*camera, np.array([300]), samples, *tables, tr.native)
        far = samples.copy()
        far[1, 0] = 1.5
        with pytest.raises(ValueError, match="offset 1 outside"):
            _core.camera_emission(*camera, pixels, far, *tables, tr.native)
        wide = samples.copy()
        wide[0, 2:] = (1.0, 1.0)
        with pytest.raises(ValueError, match="lens point 0 outside the unit disc"):
            _core.camera_emission(*camera, pixels, wide, *tables, tr.native)
        with pytest.raises(ValueError, match=r"samples must have shape \(K, 4\) or \(K, 6\)"):
            _core.camera_emission(*camera, pixels, samples[:, :2].copy(), *tables, tr.native)
    finally:
        tr.close()
