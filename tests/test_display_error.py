"""The display's error estimate (batch means, heavy-tail guard), its stopping
rule and the EXR channels that carry it (docs/design.md §6)."""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import paper
from test_display import triangle_solution

import voxgi
from voxgi.display.estimate import _Mean
from voxgi.display.settings import _Experiment


def fold(frames: np.ndarray) -> _Mean:
    """All of ``frames`` (n, P, 3) into a fresh running mean."""
    acc = _Mean.empty(frames.shape[1])
    for x in frames:
        acc.add(x)
    return acc


def test_iid_frames_give_the_variance_of_the_mean(rng):
    # 64 frames of N(1, 0.1²) per pixel and channel: the mean's variance is
    # 0.01 / 64. The store then holds 16 batches of 4 frames; each pixel's
    # estimate has a relative sd of sqrt(2/15) = 0.37, so the average over
    # 6,000 estimates has 0.47%: 3% is six of those.
    n, p, sigma = 64, 2000, 0.1
    acc = fold(1.0 + sigma * rng.standard_normal((n, p, 3)))
    assert (acc.count, acc.size) == (16, 4)
    ratio = np.mean(acc.se**2) / (sigma**2 / n)
    assert abs(ratio - 1.0) < 0.03, ratio
    assert acc.est == pytest.approx(np.mean(acc.se**2 / (acc.mean**2 + 0.01)))


def test_correlated_frames_batch_variance_is_unbiased(rng):
    # Groups of 4 consecutive frames share a component c ~ N(0, tau²) (as
    # frames that share a sequence's strata or samples), plus iid N(0, s²).
    # Over n = 64 frames (16 groups) the mean's variance is tau²/16 + s²/64;
    # the spread between single frames would give (tau² + s²)/64, about a
    # third of it here. The batches of 4 are aligned with the groups; the
    # average of 6,000 estimates from 16 batches is good to 0.47%.
    n, p, tau, s = 64, 2000, 0.1, 0.05
    shared = np.repeat(tau * rng.standard_normal((n // 4, p, 3)), 4, axis=0)
    acc = fold(1.0 + shared + s * rng.standard_normal((n, p, 3)))
    truth = tau**2 / 16 + s**2 / 64
    ratio = np.mean(acc.se**2) / truth
    assert abs(ratio - 1.0) < 0.03, ratio


def test_mean_relmse_sees_errors_that_cancel_within_aligned_blocks(rng):
    # Each aligned block of 4 frames carries a component that sums to zero
    # over the block (as the errors at an edge under the four sub-pixel
    # offsets of a (0, 2)-sequence block), of sd s, plus iid noise of sd t.
    # Over 16 frames the mean's variance is t²/16 alone; the spread between
    # single frames gives (3s²/4 + t²)/16, four times that here. The mean
    # relMSE must rest on the blocks: 4 blocks a pixel, 12,000 estimates of
    # relative sd 0.82 each, so their average is good to 0.75%; 4% is 5 sd.
    n, p, s, t = 16, 4000, 0.2, 0.1
    a = s * rng.standard_normal((n // 4, 4, p, 3))
    a -= a.mean(axis=1, keepdims=True)
    frames = 1.0 + a.reshape(n, p, 3) + t * rng.standard_normal((n, p, 3))
    acc = fold(frames)
    truth = np.mean(t**2 / n / (acc.mean**2 + 0.01))
    assert abs(acc.est / truth - 1.0) < 0.04, acc.est / truth
    # the per-pixel error, from single-frame batches, does not see it
    assert np.mean(acc.se**2 / (acc.mean**2 + 0.01)) > 3.0 * truth


def flat(p: int, obj=None) -> tuple[np.ndarray, np.ndarray]:
    """A frame's surfaces: every pixel on object ``obj`` (0), facing +z."""
    obj = np.zeros(p, np.int32) if obj is None else obj.astype(np.int32)
    return obj, np.tile(np.float16([0.0, 0.0, 1.0]), (p, 1))


def test_inside_surfaces_the_relmse_rests_on_single_frames(rng):
    # Every pixel shares one N(0, 0.1²) draw per frame (as all pixels that
    # share a frame's VPLs err together), so each trial's image estimate has
    # the degrees of freedom of one pixel's: 7 from 8 single frames, 1 from
    # two blocks of 4. Over 400 trials the estimate's relative sd is
    # sqrt(2/7) = 0.53 against sqrt(2) = 1.41 (within about 7% each), and
    # both average the mean's variance 0.01/8 to within 10% (3.5 sd of the
    # blocks' average).
    n, p, sigma = 8, 20, 0.1
    with_surface, without = [], []
    for _ in range(400):
        frames = 1.0 + np.repeat(sigma * rng.standard_normal((n, 1, 3)), p, axis=1)
        a, b = _Mean.empty(p), _Mean.empty(p)
        for x in frames:
            a.add(x, flat(p))
            b.add(x)
        den = np.mean(1.0 / (a.mean**2 + 0.01))
        with_surface.append(a.est / den)
        without.append(b.est / den)
        assert a.edge is not None
        assert not a.edge.any()
        assert b.edge is None
    truth = sigma**2 / n
    for est in (with_surface, without):
        assert abs(np.mean(est) / truth - 1.0) < 0.1, np.mean(est) / truth
    assert np.std(with_surface) < 0.5 * np.std(without)


def _cover(c: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The area of {x u + y v < c} in the pixel [-1/2, 1/2]², v >= 0: the
    fraction along the axis of the larger component is a clipped linear
    function of the other coordinate, integrated by the midpoint rule on 1024
    points (within 5e-4 of a 512x512 grid's count)."""
    s = (np.arange(1024) + 0.5) / 1024 - 0.5
    along_x = v >= np.abs(u)
    big, small = np.where(along_x, v, u), np.where(along_x, u, v)
    t = (c[:, None] - s[None] * small[:, None]) / big[:, None]
    return np.clip(np.where(big[:, None] > 0, t + 0.5, 0.5 - t), 0.0, 1.0).mean(axis=1)


def test_at_edges_the_blocks_spread_is_shrunk_and_still_errs_high(rng):
    # Each pixel is split by a straight edge (a random line through it) into
    # radiance 1 and 0.2; the frames' sub-pixel offsets are the display's
    # (0, 2)-sequence, so a pixel's 8 or 16 frames are strata, not
    # independent draws. The blocks of 4 overstate the mean's error (1.8x at
    # 8 frames, 2.4x at 16); shrunk by 1/sqrt(blocks) the estimate comes
    # closer (0.88 and 0.63 of the blocks') and stays above the truth (1.6x,
    # 1.5x). Averages over the sequences of seeds 0-9 for 4000 pixels (within
    # 0.01 of the ratios over seeds 0-19); the truth is each pixel's error
    # against its exact coverage.
    p = 4000
    for n in (8, 16):
        shrunk, blocks = [], []
        for seed in range(10):
            c, th = rng.random(p) - 0.5, rng.random(p) * np.pi
            u, v = np.cos(th), np.sin(th)
            cover = _cover(c, u, v)
            a, b = _Mean.empty(p), _Mean.empty(p)
            for f in range(n):
                (ox, oy), _ = voxgi.display.frame_samples(f, seed)
                side = (ox - 0.5) * u + (oy - 0.5) * v < c
                x = np.repeat(np.where(side, 1.0, 0.2)[:, None], 3, axis=1)
                a.add(x, flat(p, side))  # two objects meet at the edge
                b.add(x)
            m = a.mean[:, 0]
            truth = np.mean((m - (0.2 + 0.8 * cover)) ** 2 / (m * m + 0.01))
            shrunk.append(a.est / truth)
            blocks.append(b.est / truth)
        assert 1.0 < np.mean(shrunk) < 0.9 * np.mean(blocks), (n, np.mean(shrunk), np.mean(blocks))


def test_the_exact_coverage_is_a_fine_grids_count(rng):
    c, th = rng.random(50) - 0.5, rng.random(50) * np.pi
    u, v = np.cos(th), np.sin(th)
    g = (np.arange(256) + 0.5) / 256 - 0.5
    gx, gy = (a.ravel() for a in np.meshgrid(g, g))
    count = np.mean(gx[None] * u[:, None] + gy[None] * v[:, None] < c[:, None], axis=1)
    assert np.abs(_cover(c, u, v) - count).max() < 2e-3


@pytest.fixture(scope="module")
def cornell16(cornell):
    """The Cornell box solved coarsely at resolution 16 (for what the
    surfaces and frames do, whatever the light)."""
    vox = voxgi.voxelize(cornell, resolution=16)
    return voxgi.solve(vox, radius=3, progress=False, tuning=paper(shoot_radius=3))


def test_furnace_has_no_edges_and_the_cornell_box_its_outlines(cornell, cornell16):
    # Seen from its centre, the furnace sphere is one smooth object: no pixel
    # is at an edge. The Cornell box has its boxes' outlines and the room's
    # corners: a few percent of the pixels, not most. (The edges are the
    # surfaces', whatever the light: a coarse solve of the sphere will do.)
    scene = voxgi.scenes.furnace_sphere(albedo=0.5, width=32, height=24)
    vox = voxgi.voxelize(scene, resolution=16)
    sol = voxgi.solve(vox, radius=3, progress=False, tuning=paper(shoot_radius=3))
    out = voxgi.render(scene, sol, max_frames=8, tol=0.0, progress=False)
    assert out.stats["edge_pixels"] == 0
    sol = cornell16
    out = voxgi.render(cornell, sol, max_frames=8, tol=0.0, progress=False)
    pixels = cornell.camera.width * cornell.camera.height
    assert 0.02 * pixels < out.stats["edge_pixels"] < 0.3 * pixels
    # Mitsuba's Gaussian filter carries each edge 2 pixels further
    cam = dataclasses.replace(cornell.camera, pixel_filter="gaussian")
    wide = voxgi.render(cornell, sol, camera=cam, max_frames=8, tol=0.0, progress=False)
    assert wide.stats["edge_pixels"] > 2 * out.stats["edge_pixels"]


def test_a_pixel_filter_spreads_the_edges_over_its_reach():
    # Mitsuba's Gaussian filter weights a sample into the pixels up to 2
    # away, so a pixel next to an edge mixes the edge's samples into every
    # frame: one edge pixel in a 9x9 image makes a 5x5 square of them, cut
    # to 3x3 by the image's border in a corner (the two share one pixel).
    acc = _Mean.empty(81, reach=(9, 9, 2))
    obj = np.zeros(81, np.int32)
    acc.add(np.ones((81, 3)), flat(81, obj))
    obj[4 * 9 + 4] = 1
    obj[8 * 9 + 0] = 1
    acc.add(np.ones((81, 3)), flat(81, obj))
    assert np.count_nonzero(acc.edge) == 2
    edges = acc.edges().reshape(9, 9)
    assert edges[2:7, 2:7].all()
    assert edges[6:, :3].all()
    assert np.count_nonzero(edges) == 25 + 9 - 1


class _NoSurfaces:
    """A frame executor whose frames come without their surfaces."""

    class _Source:
        def __init__(self, shader):
            self.shader = shader

        def __getattr__(self, name):
            if name == "surface":
                raise AttributeError(name)
            return getattr(self.shader, name)

    def frames(self, spec, max_frames, *, threads=1):
        return self._Source(spec.build(threads))


def test_frames_without_surfaces_leave_the_estimate_to_the_blocks(cornell, cornell16):
    # Same frames, same image; without the surfaces no pixel is known to be
    # inside a surface, so every pixel takes the blocks' spread and the
    # estimate is not the local render's.
    sol = cornell16
    kw = dict(max_frames=8, tol=0.0, progress=False)
    local = voxgi.render(cornell, sol, **kw)
    bare = voxgi.display.render(cornell, sol, executor=_NoSurfaces(), **kw)
    np.testing.assert_array_equal(bare.image, local.image)
    assert bare.stats["edge_pixels"] is None
    assert local.stats["edge_pixels"] > 0
    assert bare.stats["est_rel_mse"] != local.stats["est_rel_mse"]


def test_one_outlier_batch_is_flagged_and_bounds_the_error(rng):
    # 200 pixels of N(1, 0.01²) over 64 frames; pixel 7 gets +1 in one frame.
    # Its mean is then 1/64 off, 25 of its own standard errors: the guard
    # flags it and its error estimate covers that jump.
    n, p = 64, 200
    frames = 1.0 + 0.01 * rng.standard_normal((n, p, 3))
    frames[37, 7] += 1.0
    acc = fold(frames)
    err = np.abs(acc.mean - 1.0)
    assert 1 <= acc.flagged <= 3  # the pixel, and at most a rare chance flag (0.3% each)
    assert np.all(acc.se[7] >= 0.9 * err[7]), (acc.se[7], err[7])
    # the same batch store without the outlier flags nothing that large
    clean = fold(np.delete(frames, 7, axis=1))
    assert clean.flagged < acc.flagged
    assert np.max(clean.se) < 0.2 * np.min(acc.se[7])
    assert acc.worst == pytest.approx(np.max(acc.se / np.sqrt(acc.mean**2 + 0.01)))


def test_stopping_rule_waits_for_batches_and_the_worst_pixel():
    opt = SimpleNamespace(tol=1e-3, pixel_factor=1.0)
    acc = _Mean.empty(4)
    for f in range(3):  # the estimate after 3 batches is not yet trusted
        acc.add(np.full((4, 3), 1.0 + 1e-6 * (-1) ** f))
        assert not acc.done(opt)
    acc.add(np.ones((4, 3)))
    assert acc.done(opt)  # 4 batches, tiny relMSE, no pixel off
    # one pixel of four alternates by ±20%: the mean relMSE (6.6e-4) is
    # within tol, that pixel's (2.6e-3) is not
    frames = np.ones((16, 4, 3))
    frames[:, 2] += 0.2 * (-1.0) ** np.arange(16)[:, None]
    acc = fold(frames)
    assert acc.est <= 1e-3 < acc.worst**2
    assert not acc.done(opt)
    assert acc.done(SimpleNamespace(tol=1e-3, pixel_factor=math.inf))


def test_stopping_rule_lets_one_pixel_in_1000_exceed_the_bound():
    # 2000 pixels, 16 frames: one noisy pixel (±20%) may stay over the bound
    # (at most 1 in 1000 may), two may not; pixel_share 0 asks every pixel.
    opt = SimpleNamespace(tol=1e-3, pixel_factor=1.0)
    frames = np.ones((16, 2000, 3))
    frames[:, 5] += 0.2 * (-1.0) ** np.arange(16)[:, None]
    assert fold(frames).done(opt)
    every = _Mean.empty(2000, share=0.0)
    for x in frames:
        every.add(x)
    assert not every.done(opt)
    frames[:, 9] += 0.2 * (-1.0) ** np.arange(16)[:, None]
    assert not fold(frames).done(opt)


@pytest.mark.parametrize("rho", [0.5, 0.9])
def test_furnace_stops_with_every_pixel_within_the_rule(rho):
    # Exact radiosity on the triangles, so the only error is the display's
    # noise (and the bounded-G loss near contact, < 0.1%). The rule, asked for
    # every pixel (pixel_share 0), stops when no pixel's estimated relative
    # error exceeds c = pixel_factor·sqrt(tol) = 0.63%; the worst pixel of the
    # furnace is one where a VPL landed next to the shaded point, whose error
    # its estimate covers (error ≈ estimate, docs/design.md §6), so no pixel
    # may be off by more than 2c.
    le, tol, factor = 1.0, 1e-3, 0.2
    scene = voxgi.scenes.furnace_sphere(albedo=rho, emission=le, width=32, height=24)
    scene.camera = scene.camera.replace(eye=(0.5, 0.1, 0.2), target=(1.0, 0.0, 0.1))
    sol = triangle_solution(scene, lambda v: np.full((len(v), 3), math.pi * le / (1 - rho)))
    out = voxgi.render(
        scene,
        sol,
        tol=tol,
        progress=False,
        tuning=_Experiment(pixel_factor=factor, pixel_share=0.0),
    )
    c = factor * math.sqrt(tol)
    assert out.frames < 256  # stopped by the rule, not the cap
    err = np.abs(out.image * (1 - rho) / le - 1.0)
    assert err.max() < 2 * c, (err.max(), out.frames)


def test_the_stats_say_why_the_frames_ended(cornell, cornell16, capsys, tmp_path):
    # At tol 1e-2 the rule stops the Cornell box's frames; at 1e-6 the cap
    # of 8 frames comes first and the image is short of tol; tol 0 asks for
    # the cap.
    from voxgi import cli

    def stopped(**kw):
        return voxgi.render(cornell, cornell16, progress=False, **kw).stats

    met = stopped(tol=1e-2)
    assert met["stopped"] == "tol"
    assert met["frames"] < 256
    short = stopped(tol=1e-6, max_frames=8)
    assert short["stopped"] == "max_frames"
    assert short["est_rel_mse"] > 1e-6
    assert stopped(tol=0, max_frames=2)["stopped"] == "max_frames"
    # the command line says when the cap left the image short of --tol
    args = ["render", "furnace-sphere", "--resolution", "12", "--radius", "4"]
    args += ["--width", "8", "--height", "6", "--frames", "4"]
    for tol, said in (("1e-9", True), ("0", False)):
        capsys.readouterr()  # (clears what came before)
        assert cli.main([*args, "-o", str(tmp_path / f"{tol}.exr"), "--tol", tol]) == 0
        out = capsys.readouterr()
        assert ("stopped at the frame cap" in out.out) == said


def test_the_command_line_says_what_the_seen_emissions_means_add(tmp_path, capsys):
    # The Cornell box's lamp outline: its pixels' means add 7.2e-7
    # of relMSE, said where that passes a quarter of --tol, not at 1e-2.
    from voxgi import cli

    args = ["render", "cornell-box", "--resolution", "8", "--radius", "3"]
    args += ["--width", "32", "--height", "32", "--frames", "4"]
    for tol, said in (("1e-9", True), ("1e-2", False)):
        capsys.readouterr()
        assert cli.main([*args, "-o", str(tmp_path / f"{tol}.exr"), "--tol", tol]) == 0
        out = capsys.readouterr().out
        assert ("the mean emission seen across pixels adds" in out) == said, out


def test_exr_stderr_channels_round_trip(tmp_path, rng):
    img = rng.random((5, 7, 3)).astype(np.float32)
    se = (0.01 * rng.random((5, 7, 3))).astype(np.float32)
    path = voxgi.io.write_exr(tmp_path / "a.exr", img, stderr=se)
    np.testing.assert_array_equal(voxgi.io.read_exr(path), img)
    np.testing.assert_array_equal(voxgi.io.read_exr(path, layer="stderr"), se)
    plain = voxgi.io.write_exr(tmp_path / "b.exr", img)
    with pytest.raises(ValueError, match=r"no stderr\.R/G/B channels"):
        voxgi.io.read_exr(plain, layer="stderr")
    with pytest.raises(ValueError, match="stderr: expected the image's shape"):
        voxgi.io.write_exr(tmp_path / "c.exr", img, stderr=se[:4])


def test_render_stderr_goes_to_the_exr(tmp_path):
    scene = voxgi.scenes.furnace_sphere(albedo=0.5, width=12, height=10)
    sol = triangle_solution(scene, lambda v: np.full((len(v), 3), 2 * math.pi))
    out = voxgi.render(scene, sol, max_frames=12, tol=0.0, progress=False)
    assert out.stderr.shape == out.image.shape
    assert out.stats["batches"] == 12
    assert out.stats["batch_frames"] == 1
    path = voxgi.io.write_exr(tmp_path / "r.exr", out.image, stderr=out.stderr)
    np.testing.assert_array_equal(voxgi.io.read_exr(path, layer="stderr"), out.stderr)


@pytest.mark.parametrize(
    ("tuning", "match"),
    [
        ({"pixel_factor": 0.0}, "pixel_factor: must be > 0"),
        ({"pixel_factor": "10"}, "pixel_factor: expected a number"),
        ({"pixel_share": 1.0}, "pixel_share: must be < 1"),
        ({"pixel_share": -0.1}, "pixel_share: must be >= 0"),
    ],
)
def test_bad_stopping_rule_settings_are_named(tuning, match):
    scene = voxgi.scenes.furnace_sphere(albedo=0.5, width=8, height=6)
    sol = triangle_solution(scene, lambda v: np.full((len(v), 3), 2 * math.pi))
    with pytest.raises((TypeError, ValueError), match=match):
        voxgi.render(scene, sol, progress=False, tuning=_Experiment(**tuning))


def test_cli_writes_the_stderr_channels(tmp_path):
    from voxgi import cli

    out = tmp_path / "f.exr"
    args = ["render", "furnace-sphere", "-o", str(out), "--resolution", "12", "--radius"]
    args += ["4", "--frames", "6", "--width", "8", "--height", "6", "-q"]
    assert cli.main(args) == 0
    se = voxgi.io.read_exr(out, layer="stderr")
    assert se.shape == (6, 8, 3)
    assert np.all(np.isfinite(se))
    assert np.all(se >= 0)
    assert voxgi.io.read_exr_header(out)["est_max_rel_err"] > 0


def test_outlier_thresholds_are_student_t_quantiles():
    from scipy.stats import t

    from voxgi.display.estimate import _BATCH_SLOTS, _OUTLIER_ALPHA, _outlier_threshold

    for k in range(4, _BATCH_SLOTS + 1):
        want = t.ppf(1.0 - _OUTLIER_ALPHA / (2 * k), k - 2)
        assert _outlier_threshold(k) == pytest.approx(want, rel=1e-5), k


def test_batch_error_kernel_is_the_batch_means_formula(rng):
    # The compiled kernel against the formula written out in numpy, with a
    # few pixels given one far-off batch (flagged, their error raised to it).
    from voxgi import _core
    from voxgi.display.estimate import _outlier_threshold

    k, p, size, frames = 12, 3000, 2, 27
    b = (1.0 + 0.1 * rng.standard_normal((k, p, 3))).astype(np.float32)
    b[5, :40, 1] += 3.0
    crit = _outlier_threshold(k)
    se, flagged = _core.batch_error(b, size, frames, crit)
    x = b.astype(np.float64)
    dev = x - x.mean(axis=0)
    ss = np.einsum("kpc,kpc->pc", dev, dev)
    want = np.sqrt(ss / (k - 1) * size / frames)
    jump = np.abs(dev).max(axis=0)
    rest = np.maximum(ss - jump**2 * k / (k - 1), 0.0)
    tail = jump > crit * np.sqrt(rest / (k - 2) * (k - 1) / k)
    want = np.where(tail, np.maximum(want, jump * size / frames), want)
    np.testing.assert_allclose(se, want, rtol=1e-12)
    np.testing.assert_array_equal(flagged.astype(bool), tail)
    assert tail[:40, 1].all()
    assert tail.sum() < 60  # the test flags few others (alpha 1e-3 over 12 batches)
    # without the test (k < 4, or crit inf) nothing is flagged
    se3, f3 = _core.batch_error(b[:3], size, 3 * size, math.inf)
    assert not f3.any()
    np.testing.assert_allclose(se3, np.sqrt(x[:3].var(axis=0, ddof=1) * size / (3 * size)))
    with pytest.raises(ValueError, match="at least 2 batches"):
        _core.batch_error(b[:1], size, frames, crit)


def test_estimate_read_late_is_the_one_made_at_its_batch(rng):
    # The estimate is worked out when read. Read after any frame, it must be
    # the one made when the last batch completed, also once batches hold two
    # or four frames (past 32 and 64 frames) and frames that open a batch
    # have changed the running sums since.
    frames = 1.0 + 0.1 * rng.standard_normal((80, 50, 3))
    frames[45, 3] += 2.0  # one pixel's outlier, flagged by the heavy-tail test
    eager, late = _Mean.empty(50), _Mean.empty(50)
    for f, x in enumerate(frames):
        eager.add(x)
        eager._refresh()
        late.add(x)
        if f % 7 == 6 or f == len(frames) - 1:
            assert (late.est, late.worst, late.tail, late.flagged) == (
                eager.est,
                eager.worst,
                eager.tail,
                eager.flagged,
            ), f
            np.testing.assert_array_equal(late.se, eager.se)
    assert late.size == 4
    assert late.flagged >= 1
