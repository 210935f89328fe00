"""Direct light on the records by shadow rays (voxgi.direct) against closed forms."""

import math

import numpy as np
import pytest
import trimesh

import voxgi
from voxgi.direct import EmitterSampler, direct_irradiance


def _quad(corners, facing):
    m = trimesh.Trimesh(corners, [[0, 1, 2], [0, 2, 3]], process=False)
    if np.dot(m.face_normals[0], np.asarray(facing) - m.triangles_center[0]) < 0:
        m = trimesh.Trimesh(corners, [[0, 2, 1], [0, 3, 2]], process=False)
    return m


def _corner_form_factor(x, y, h):
    """Point-to-parallel-rectangle form factor, the rectangle [0, x] x [0, y] at height h
    with one corner above the point (Howell's catalogue, configuration B-3); signed in x, y."""
    X, Y = x / h, y / h
    sx, sy = math.sqrt(1 + X * X), math.sqrt(1 + Y * Y)
    return (X / sx * math.atan(Y / sx) + Y / sy * math.atan(X / sy)) / (2 * math.pi)


def _rectangle_irradiance(p, lo, hi, h, radiance):
    """Irradiance at floor point p (x, z) from a downward Lambertian rectangle [lo, hi]
    (x, z) at height h above it: pi L F, F summed over the four corner rectangles."""
    f = 0.0
    for cx, sx in ((hi[0], 1), (lo[0], -1)):
        for cz, sz in ((hi[1], 1), (lo[1], -1)):
            f += sx * sz * _corner_form_factor(cx - p[0], cz - p[1], h)
    return math.pi * radiance * f


def _lamp_over_floor(blocker=False):
    sc = voxgi.Scene()
    sc.add(
        _quad([(-1, 0, -1), (1, 0, -1), (1, 0, 1), (-1, 0, 1)], (0, 1, 0)),
        voxgi.Material(albedo=0.5),
        name="floor",
    )
    sc.add(
        _quad([(-0.2, 1, -0.3), (0.2, 1, -0.3), (0.2, 1, 0.3), (-0.2, 1, 0.3)], (0, 0, 0)),
        voxgi.Material(albedo=0.0, emission=2.0),
        name="lamp",
    )
    if blocker:
        sc.add(
            _quad(
                [(-0.25, 0.5, -0.35), (0.0, 0.5, -0.35), (0.0, 0.5, 0.35), (-0.25, 0.5, 0.35)],
                (0, 0, 0),
            ),
            voxgi.Material(albedo=0.5),
            name="blocker",
            two_sided=True,
        )
    return sc


def test_closed_emitting_enclosure_gives_pi_le():
    # Every direction from a point inside a closed enclosure of radiance Le sees Le, so the
    # irradiance is pi Le whatever the shape; for a sphere cos_x cos_y / r^2 = 1 / (4 R^2) on
    # every pair, so the estimate hardly varies between records.
    sc = voxgi.scenes.furnace_sphere(albedo=0.5, emission=1.5)
    vox = voxgi.voxelize(sc, resolution=16)
    E, stats = direct_irradiance(sc, vox, samples=32, threads=1)
    front = ~vox.back & (vox.area > 0)
    ratio = E[front] / (math.pi * 1.5)
    assert stats["rays"] >= front.sum() * 32
    w = vox.area[front]
    assert np.sum(w * ratio[:, 1]) / np.sum(w) == pytest.approx(1.0, abs=2e-3)
    assert np.all(np.abs(ratio - 1.0) < 0.03)
    assert np.all(E[vox.back] == 0.0)  # black back records need no direct light


def test_rectangle_lamp_matches_form_factor():
    sc = _lamp_over_floor()
    vox = voxgi.voxelize(sc, resolution=32)
    E, _ = direct_irradiance(sc, vox, samples=256, seed=3, threads=2)
    floor = np.flatnonzero((vox.object_id == 0) & ~vox.back & (vox.area > 0))
    p = vox.centroid[floor]
    exact = np.array(
        [_rectangle_irradiance((x, z), (-0.2, -0.3), (0.2, 0.3), 1.0 - y, 2.0) for x, y, z in p]
    )
    rel = E[floor, 0] / exact - 1.0
    # 256 stratified samples: a standard error of about 0.4% per record, so the
    # largest of the 1089 floor records stays within ~4 of them; unbiased on average
    assert np.max(np.abs(rel)) < 0.02
    assert np.mean(np.abs(rel)) < 0.005
    assert np.mean(rel) == pytest.approx(0.0, abs=1e-3)


def test_blocker_casts_umbra_and_penumbra():
    sc = _lamp_over_floor(blocker=True)
    vox = voxgi.voxelize(sc, resolution=32)
    # 4096 samples: in the deep penumbra (a fifth of the lamp seen) 512 leave
    # a standard error of 1.9%, about the tolerance (measured over 8 seeds)
    E, _ = direct_irradiance(sc, vox, samples=4096, threads=1)
    floor = (vox.object_id == 0) & ~vox.back & (vox.area > 0)
    x, z = vox.centroid[:, 0], vox.centroid[:, 2]
    # A ray from floor point p to lamp point L (lamp x in [-0.2, 0.2] at height 1) crosses
    # the blocker's height 0.5 at (p + L) / 2: the blocker (x in [-0.25, 0]) hides the whole
    # lamp from p in [-0.3, -0.2] (umbra), the part x < -p of it from p in [-0.2, 0.2]
    # (penumbra), none of it from p > 0.2; near z = 0 the blocker spans the lamp's depth.
    umbra = floor & (np.abs(x + 0.25) < 0.03) & (np.abs(z) < 0.05)
    assert umbra.any()
    assert np.all(E[umbra] == 0.0)
    open_ = floor & (x > 0.25) & (np.abs(z) < 0.3)
    exact = np.array(
        [
            _rectangle_irradiance((a, c), (-0.2, -0.3), (0.2, 0.3), 1.0 - b, 2.0)
            for a, b, c in vox.centroid[open_]
        ]
    )
    assert np.allclose(E[open_, 0], exact, rtol=0.02)
    # In the penumbra the record sees the rectangle x in [-p, 0.2] of the lamp.
    penumbra = floor & (np.abs(x) < 0.15) & (np.abs(z) < 0.05)
    assert penumbra.sum() >= 4
    exact = np.array(
        [
            _rectangle_irradiance((a, c), (-a, -0.3), (0.2, 0.3), 1.0 - b, 2.0)
            for a, b, c in vox.centroid[penumbra]
        ]
    )
    assert np.allclose(E[penumbra, 0], exact, rtol=0.02)


def test_emitter_sampler_draws_by_power_and_area():
    sc = _lamp_over_floor()
    sc.add(
        _quad([(-1, 2, -1), (1, 2, -1), (1, 2, 1), (-1, 2, 1)], (0, 0, 0)),
        voxgi.Material(albedo=0.0, emission=0.5),
        name="dim",
    )
    em = EmitterSampler(sc)
    # lamp: area 0.24 x radiance 2; dim: area 4 x 0.5: shares 0.24 / 2.24 and 2 / 2.24
    lamp = np.isclose(em.triangles[:, 0, 1], 1.0)
    assert em.probability[lamp].sum() == pytest.approx(0.48 / 2.48)
    u = np.random.default_rng(1).random((200_000, 3))
    idx, y = em.sample(u)
    assert np.mean(lamp[idx]) == pytest.approx(0.48 / 2.48, abs=4e-3)
    # uniform in area: the mean point of the lamp's draws is its centre
    assert np.allclose(y[lamp[idx]].mean(axis=0), (0.0, 1.0, 0.0), atol=5e-3)


def test_no_emitter_gives_zero():
    sc = voxgi.Scene()
    sc.add(
        _quad([(-1, 0, -1), (1, 0, -1), (1, 0, 1), (-1, 0, 1)], (0, 1, 0)),
        voxgi.Material(albedo=0.5),
    )
    vox = voxgi.voxelize(sc, resolution=8)
    E, stats = direct_irradiance(sc, vox)
    assert not E.any()
    assert stats["rays"] == 0


def test_bad_arguments():
    sc = _lamp_over_floor()
    vox = voxgi.voxelize(sc, resolution=8)
    with pytest.raises(ValueError, match="samples"):
        direct_irradiance(sc, vox, samples=0)
    with pytest.raises(TypeError, match="vox"):
        direct_irradiance(sc, "records")
    other = voxgi.scenes.furnace_sphere()
    with pytest.raises(ValueError, match="another scene"):
        direct_irradiance(other, vox)


def test_box_enclosure_edges_stay_bounded():
    # Records next to a box's edges see the adjacent emitting wall at grazing distance: area
    # samples of that wall alone give a heavy-tailed estimate there (single records off by a
    # factor of several at 64 samples). Combined with hemisphere samples, every sample is
    # bounded by a few pi Le / samples, so each record stays close to pi Le.
    sc = voxgi.scenes.furnace_box(albedo=0.5, emission=1.0)
    vox = voxgi.voxelize(sc, resolution=16)
    E, _ = direct_irradiance(sc, vox, samples=64, threads=2)
    front = ~vox.back & (vox.area > 0)
    ratio = E[front, 0] / math.pi
    assert np.sum(vox.area[front] * ratio) / np.sum(vox.area[front]) == pytest.approx(1.0, abs=3e-3)
    assert np.all(np.abs(ratio - 1.0) < 0.1)


def test_thread_count_changes_nothing():
    # each record's samples are summed by one task, and the sample points do
    # not depend on how the records are split over threads
    sc = voxgi.scenes.cornell_box(width=16, height=16)
    vox = voxgi.voxelize(sc, resolution=16)
    one, _ = direct_irradiance(sc, vox, samples=16, threads=1)
    two, _ = direct_irradiance(sc, vox, samples=16, threads=2)
    assert np.array_equal(one, two)


def test_far_from_the_origin_gives_the_same_light():
    # the rays are traced in a frame centred on the scene: moving it by 1e7
    # (float32 spacing there: 1) changes nothing but rounding
    near = _lamp_over_floor(blocker=True)
    far = voxgi.Scene()
    for o in near.objects:
        far.add(
            trimesh.Trimesh(o.vertices + 1e7, o.faces, process=False),
            o.material,
            name=o.name,
            two_sided=o.two_sided,
        )
    e_near, _ = direct_irradiance(near, voxgi.voxelize(near, resolution=16), samples=32)
    e_far, _ = direct_irradiance(far, voxgi.voxelize(far, resolution=16), samples=32)
    assert np.allclose(e_far, e_near, rtol=1e-3, atol=1e-6)


def test_sobol_points_are_scipys_sequence():
    # The record samples' base sequence is Sobol' (Joe-Kuo direction
    # numbers); scipy draws the same points in Gray-code order.
    from scipy.stats import qmc

    from voxgi._qmc import sobol
    from voxgi.direct import _sequence

    for m in (0, 3, 10):
        i = np.arange(1 << m)
        want = qmc.Sobol(5, scramble=False).random_base2(m)
        np.testing.assert_array_equal(sobol(i ^ (i >> 1)) / 2.0**32, want)
    # the digital shift keeps the stratification: 16 points fill the 16
    # intervals of every dimension, and the 4x4 cells of the first two
    x = _sequence(16, seed=7)
    for a in range(5):
        assert len(np.unique(np.floor(x[:, a] * 16))) == 16, a
    assert len(np.unique(np.floor(x[:, 0] * 4) * 4 + np.floor(x[:, 1] * 4))) == 16


def test_direct_light_kernels_hold_the_emitter_arrays_they_convert():
    # The kernels take the emitters as a tuple of arrays. One that has to be
    # converted (Fortran order, strided) becomes a new array that only the
    # binding holds, and it must hold it while the kernel runs: under
    # scripts/sanitize.sh a dropped one aborts the run (heap-use-after-free).
    from voxgi import _core

    # hundreds of emitting triangles: arrays too large for NumPy's cache of
    # small buffers, so that a dropped one goes back to the allocator
    scene = voxgi.scenes.cap_sphere(subdivisions=3)
    em = EmitterSampler(scene)
    assert em.arrays[0].nbytes > 1 << 14
    rng = np.random.default_rng(0)
    n = 4000
    point = (rng.random((n, 3)) - 0.5) * 0.5
    normal = np.tile([0.0, 0.0, 1.0], (n, 1))
    shift, seq = rng.random((n, 5)), rng.random((16, 5))
    corners, nrm, two, rad, cdf, dens = em.arrays
    converted = (
        np.repeat(corners, 2, axis=0)[::2],
        np.asfortranarray(nrm),
        two,
        np.asfortranarray(rad),
        np.repeat(cdf, 2)[::2],
        np.repeat(dens, 2)[::2],
    )
    with voxgi.rays.Tracer(scene, 1) as tr:
        args = (point, normal, shift, seq, 1e-4, em.emitter_of, tr.native)
        want = _core.direct_light_traced(em.arrays, *args)
        got = _core.direct_light_traced(converted, *args)
    assert np.count_nonzero(want[0][:, 0] > 0) > n // 4
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g, w)


def test_hemisphere_rays_meet_the_emitters_first_only_where_few_triangles_emit():
    # A lamp of 2 triangles among 30: hemisphere rays go to the emitters'
    # own scene first; in a furnace, where every triangle emits, they go
    # to their first hit in the scene.
    from voxgi.direct import _Rays

    for scene, want in ((voxgi.scenes.cornell_box(), 2), (voxgi.scenes.furnace_box(), None)):
        vox = voxgi.voxelize(scene, resolution=8, progress=False)
        with _Rays(scene, vox, EmitterSampler(scene), 1e-4, 1) as rays:
            got = rays.emitter_scene
            assert (None if got is None else got.triangle_count) == want


def _kernel_irradiance(scene, vox, rec, samples, scale=None, strategies=False, seed=0):
    """The direct-light kernel on records ``rec`` with ``samples`` samples each."""
    from voxgi import _core
    from voxgi.direct import _sequence

    em = EmitterSampler(scene)
    with voxgi.rays.Tracer(scene, 2) as tr:
        c = tr.centre
        rng = np.random.default_rng(seed)
        hs = None if scale is None else np.full(len(rec), float(scale))
        return _core.direct_light_traced(
            (em.arrays[0] - c, *em.arrays[1:]),
            np.ascontiguousarray(vox.centroid[rec] - c),
            np.ascontiguousarray(vox.normal[rec], np.float64),
            rng.random((len(rec), 5)),
            _sequence(samples, seed),
            1e-4,
            em.emitter_of,
            tr.native,
            threads=2,
            hemisphere_scale=hs,
            strategies=strategies,
        )


@pytest.mark.parametrize("scale", [0.01, 1.0, 100.0])
def test_any_weight_on_the_hemisphere_samples_keeps_the_form_factor(scale):
    # The power heuristic with the hemisphere density scaled: a direction's
    # two weights still sum to 1, so the estimate stays unbiased, whatever
    # the weight; 1024 samples under the rectangular lamp. Weighing the
    # cosine-distributed samples, which seldom meet a small lamp, a hundred
    # times more costs variance (up to 11% on a record), not bias.
    sc = _lamp_over_floor()
    vox = voxgi.voxelize(sc, resolution=16)
    floor = np.flatnonzero((vox.object_id == 0) & ~vox.back & (vox.area > 0))[::7]
    E = _kernel_irradiance(sc, vox, floor, 1024, scale)[0]
    p = vox.centroid[floor]
    exact = np.array(
        [_rectangle_irradiance((x, z), (-0.2, -0.3), (0.2, 0.3), 1.0 - y, 2.0) for x, y, z in p]
    )
    rel = E[:, 0] / exact - 1.0
    assert np.mean(rel) == pytest.approx(0.0, abs=1e-2)
    assert np.max(np.abs(rel)) < (0.2 if scale > 1 else 0.02)


def test_inside_an_enclosure_of_emitters_the_hemisphere_samples_are_exact():
    # Every cosine-distributed ray from inside a closed box of uniform
    # emitters meets Le: the hemisphere samples' own estimate, pi Le, does not
    # vary, the light samples' (1/r² towards the nearby walls) does. Weighing
    # the hemisphere samples by the ratio of the two variances makes each
    # record's 16 samples nearly exact.
    sc = voxgi.scenes.furnace_box(albedo=0.5, emission=1.0)
    vox = voxgi.voxelize(sc, resolution=16)
    rec = np.flatnonzero(~vox.back & (vox.area > 0))
    _, _, var = _kernel_irradiance(sc, vox, rec, 16, strategies=True)
    assert np.all(var[:, 1] < 1e-9)
    assert np.median(var[:, 0]) > 0.1
    plain = _kernel_irradiance(sc, vox, rec, 16)[0][:, 0] / math.pi - 1.0
    weighted = _kernel_irradiance(sc, vox, rec, 16, scale=100.0)[0][:, 0] / math.pi - 1.0
    assert np.std(plain) > 0.01
    assert np.std(weighted) < 0.1 * np.std(plain)


def test_the_pilot_weighs_each_objects_better_strategy():
    from voxgi.direct import _Estimate, _hemisphere_scale

    # a small distant lamp: the light samples win (weight under 1); an
    # enclosure of emitters: the hemisphere samples win (the upper bound)
    lamp = _lamp_over_floor()
    box = voxgi.scenes.furnace_box(albedo=0.5, emission=1.0)
    for scene, floor_wins in ((lamp, "light"), (box, "hemisphere")):
        vox = voxgi.voxelize(scene, resolution=16)
        rec = np.flatnonzero(~vox.back & (vox.area > 0) & (vox.albedo[:, 0] > 0))
        pilot = _Estimate(len(vox))
        E, sq, var = _kernel_irradiance(scene, vox, rec, 4, strategies=True)
        pilot.add(rec, E, sq, 4, var)
        scale = _hemisphere_scale(pilot, rec, np.asarray(vox.object_id))
        if floor_wins == "light":
            assert np.all(scale[rec] < 1.0)
        else:
            assert np.all(scale[rec] == 100.0)
