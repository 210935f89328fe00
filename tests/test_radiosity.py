"""voxgi.solve: shooting + gathering against analytic answers (DESIGN-NOTES §1, §5).

Synthetic records (tests/test_core_propagate.py) keep the default run fast and
independent of the voxelizer; the built-in scenes run through voxgi.voxelize.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from test_core_propagate import sphere_records, voxelset

import voxgi
from voxgi.radiosity import gather_partial, line_system


def _voxelize(scene, resolution):
    return voxgi.voxelize(scene, resolution=resolution)


@pytest.fixture(scope="module")
def sphere32():
    return sphere_records(32)


def _cap(rec):
    up = (rec["point"][:, 1] - rec["centre"][1]) / rec["radius"]
    return (~rec["back"]) & (up < -0.5)  # a 60° polar cap


def _cap_exact(vox, rho):
    # inside a sphere every pair has kernel 1/A: L = Le + rho * mean(Le) / (1 - rho)
    front = ~vox.back
    Le = vox.emission.astype(np.float64)
    A = vox.area.astype(np.float64)
    Lm = (Le * A[:, None])[front].sum(axis=0) / A[front].sum()
    return Le + rho * Lm / (1 - rho)


@pytest.mark.parametrize("rho", [0.3, 0.9])
def test_furnace_sphere(sphere32, rho):
    # uniform Le = 1, albedo rho: L = 1 / (1 - rho) everywhere (back records aside).
    # Measured at res 32, R = 8 (shooting and gathering), lost fraction
    # δ = 5.7e-4: mean |err| 0.05% / 0.43%, max 0.62% / 2.15% for rho 0.3 / 0.9;
    # the error grows like rho δ / (1 - rho) (DESIGN-NOTES §5).
    vox = voxelset(sphere32, albedo=rho)
    sol = voxgi.solve(vox, directions=8, shoot_directions=8, progress=False, tol=1e-6)
    front = ~vox.back
    err = np.abs(sol.radiance[front] * (1 - rho) - 1)
    assert err.mean() < {0.3: 1e-3, 0.9: 6e-3}[rho]
    assert err.max() < {0.3: 1e-2, 0.9: 3e-2}[rho]
    assert np.all(sol.radiosity[~front] == 0)  # black back records stay black
    st = sol.stats
    assert 0 < st["lost_fraction"] < 1e-3
    assert st["rays"] == st["shoot_rays"] + st["gather_rays"]
    assert st["gather_rays"] == len(vox) * 381 * sol.bounces  # R = 8: 381 families
    assert set(st["seconds"]) >= {"shoot", "gather", "total"}


def test_cap_sphere_and_acceleration(sphere32):
    # rho = 0.99: plain Jacobi would need ~ log(1e-7)/log(0.99) = 1600
    # iterations for the error estimate r·99 < 1e-5; the geometric-tail
    # extrapolation gets there in 15 (measured)
    rho = 0.99
    vox = voxelset(sphere32, albedo=rho, emit_mask=_cap(sphere32))
    sol = voxgi.solve(vox, directions=8, shoot_directions=8, progress=False, tol=1e-5)
    assert sol.bounces <= 25
    assert sol.residuals[-1] * 99 < 1e-5
    front = ~vox.back
    err = np.abs(sol.radiance / _cap_exact(vox, rho) - 1)[front]
    # measured: mean 3.4%, max 5.4% (R = 8 direct-light aliasing at the cap's
    # rim + 99 δ); without extrapolation 200 iterations leave 15% error
    assert err.mean() < 0.05
    assert err.max() < 0.08
    plain = voxgi.solve(
        vox,
        directions=8,
        shoot_directions=8,
        progress=False,
        tol=1e-5,
        accelerate=False,
        max_bounces=25,
    )
    err_plain = np.abs(plain.radiance / _cap_exact(vox, rho) - 1)[front]
    assert err_plain.mean() > 5 * err.mean()


def test_gauss_seidel_matches_jacobi(sphere32):
    vox = voxelset(sphere32, albedo=0.6, emit_mask=_cap(sphere32))
    kw = dict(directions=6, shoot_directions=6, progress=False, tol=1e-7, accelerate=False)
    j = voxgi.solve(vox, **kw)
    g = voxgi.solve(vox, method="gauss-seidel", **kw)
    # both solve the same linear system; tol 1e-7 leaves ~1e-6 of difference
    assert np.allclose(g.radiosity, j.radiosity, rtol=1e-5, atol=1e-6)
    assert g.bounces <= j.bounces


def test_coarser_later_bounces(sphere32):
    # Piwowar & Malgouyres 2009: bounces after the second with fewer
    # directions. Bounce by bounce, so the answer stays near the fine one
    # (measured on this cap sphere: 0.056% mean), whereas the coarse set
    # everywhere is further off (0.21% mean); gathering rays drop 3.4x.
    vox = voxelset(sphere32, albedo=0.7, emit_mask=_cap(sphere32))
    kw = dict(shoot_directions=8, progress=False, tol=1e-6)
    fine = voxgi.solve(vox, directions=8, **kw)
    later = voxgi.solve(vox, directions=8, later_directions=3, **kw)
    coarse = voxgi.solve(vox, directions=3, **kw)
    front = ~vox.back
    e_later = np.abs(later.radiosity[front] / fine.radiosity[front] - 1).mean()
    e_coarse = np.abs(coarse.radiosity[front] / fine.radiosity[front] - 1).mean()
    assert e_later < 0.5 * e_coarse
    assert later.stats["gather_rays"] < fine.stats["gather_rays"]
    with pytest.raises(ValueError, match="later_directions"):
        voxgi.solve(vox, later_directions=4, method="gauss-seidel")


def test_threads_do_not_change_the_answer(sphere32):
    vox = voxelset(sphere32, albedo=0.5, emit_mask=_cap(sphere32))
    kw = dict(directions=5, shoot_directions=5, progress=False, max_bounces=3)
    a = voxgi.solve(vox, threads=1, **kw)
    b = voxgi.solve(vox, threads=2, **kw)
    assert np.allclose(a.radiosity, b.radiosity, rtol=1e-6, atol=0)


@pytest.mark.parametrize(
    "kw",
    [dict(), dict(method="gauss-seidel", gs_blocks=3), dict(later_directions=3)],
    ids=["jacobi", "gauss-seidel", "later"],
)
def test_recorded_pairs_give_the_same_solution(sphere32, kw):
    # the solve's later passes replay the pairs its first pass over each
    # direction set recorded: the same answer to float rounding, passes
    # replayed and the table's size said in the statistics
    vox = voxelset(sphere32, albedo=0.7, emit_mask=_cap(sphere32))
    base = dict(directions=6, shoot_directions=6, progress=False, tol=1e-6, **kw)
    walk = voxgi.solve(vox, pair_cache=False, **base)
    rep = voxgi.solve(vox, **base)
    assert rep.bounces == walk.bounces
    assert np.allclose(rep.radiosity, walk.radiosity, rtol=1e-6, atol=1e-9)
    # the recording pass leaves the visibility sums to the first replay: the
    # same lost fraction and energy balance as the walk's
    assert rep.stats["lost_fraction"] == pytest.approx(walk.stats["lost_fraction"], rel=1e-9)
    assert np.allclose(rep.stats["energy"]["escaping"], walk.stats["energy"]["escaping"], rtol=1e-6)
    assert "visibility" not in rep.stats["seconds"]
    pc = rep.stats["pair_cache"]
    assert pc["replayed_passes"] >= rep.bounces - 1
    assert all(e["recorded"] for e in pc["sets"])
    assert pc["bytes"] > 0
    assert "line_walks" in rep.stats["skipped"]
    assert walk.stats["pair_cache"] == {"recorded": False, "reason": "pair_cache=False"}
    assert "line_walks" not in walk.stats["skipped"]
    # over the budget: every pass walks the lines, and the reason is given
    tight = voxgi.solve(vox, max_cache_bytes=1000, **base)
    assert np.array_equal(tight.radiosity, walk.radiosity)
    assert "budget" in tight.stats["pair_cache"]["sets"][0]["reason"]
    # one pass over the set: nothing to replay, nothing recorded
    no_tol = {k: v for k, v in base.items() if k != "tol"}
    once = voxgi.solve(vox, max_bounces=1, diagnostics=False, **no_tol)
    assert once.stats["pair_cache"]["sets"][0]["reason"] == "one pass only"
    # one bounce and the diagnostics pass: the bounce records, so the
    # visibility sums come from a replayed pass of their own
    one = voxgi.solve(vox, max_bounces=1, **no_tol)
    one_walk = voxgi.solve(vox, max_bounces=1, pair_cache=False, **no_tol)
    assert "visibility" in one.stats["seconds"]
    assert one.stats["pair_cache"]["replayed_passes"] >= 1
    assert one.stats["lost_fraction"] == pytest.approx(one_walk.stats["lost_fraction"], rel=1e-9)


def test_pair_cache_arguments_are_checked(sphere32):
    vox = voxelset(sphere32, albedo=0.5)
    with pytest.raises(TypeError, match="pair_cache"):
        voxgi.solve(vox, pair_cache="yes", progress=False)
    with pytest.raises(ValueError, match="max_cache_bytes"):
        voxgi.solve(vox, max_cache_bytes=-1, progress=False)


def test_pair_table_bytes_is_what_the_table_takes(sphere32):
    from voxgi.directions import direction_set
    from voxgi.radiosity import pair_table_bytes

    s = line_system(voxelset(sphere32))
    for R in (3, 8):
        ds = direction_set(R)
        tab = s.make_pair_table(ds.families, ds.weights, False)
        assert tab.nbytes == pair_table_bytes(s.size, ds.families)
    # 150k records at R 22 (the throughput benchmark): 3 bytes x 149,716
    # records x 3024 columns (2991 families, each axis's padded to 16) = 1.36 GB
    assert pair_table_bytes(149716, direction_set(22).families) == 3 * 149716 * 3024


def test_gather_partial_adds_up(sphere32):
    vox = voxelset(sphere32, albedo=0.5)
    rng = np.random.default_rng(7)
    B = rng.random((len(vox), 3)).astype(np.float32)
    s = line_system(vox)
    full = gather_partial(vox, B, np.arange(381), 8, system=s)
    parts = sum(
        gather_partial(vox, B, idx, 8, system=s) for idx in np.array_split(rng.permutation(381), 3)
    )
    assert np.allclose(parts, full, rtol=1e-12, atol=1e-14)


def test_open_box_energy_balance():
    # a box open on one side, lit by a lamp patch on its ceiling: power
    # emitted = absorbed + escaping (escaping counted on the sender side:
    # rays that meet nobody). The imbalance is a discretisation error (the
    # discrete transfer is not exactly reciprocal); measured for this box
    # scaled by 1, 2, 4 (res ~22, 42, 82) at R = 8: 1.2%, 0.97%, 0.004%;
    # at R = 16: 0.06%, 0.72%, 0.03% (rho = 0.7). Here: scale 1, R = 8.
    from test_core_propagate import box_records

    rec = box_records([1.3, 1.4, 1.6], [20.7, 18.2, 19.4], back=True)
    keep = ~((np.abs(rec["normal"][:, 2]) > 0.5) & (rec["point"][:, 2] < 1.7))  # open at z = lo
    rec = {k: v[keep] for k, v in rec.items()}
    lamp = (
        (~rec["back"])
        & (rec["normal"][:, 1] < -0.5)
        & (np.abs(rec["point"][:, 0] - 11) < 3)
        & (np.abs(rec["point"][:, 2] - 10) < 3)
    )
    vox = voxelset(rec, albedo=0.7, emit_mask=lamp, emission=5.0)
    sol = voxgi.solve(vox, directions=8, shoot_directions=8, progress=False, tol=1e-7)
    e = sol.stats["energy"]
    assert e["escaping"][0] > 0.1 * e["emitted"][0]
    assert abs(e["imbalance"][0]) < 0.02


def test_no_emitter_warns_and_returns_zero(sphere32):
    vox = voxelset(sphere32, albedo=0.5, emission=0.0)
    with pytest.warns(RuntimeWarning, match="no emitter"):
        sol = voxgi.solve(vox, progress=False)
    assert sol.radiosity.shape == (len(vox), 3)
    assert not sol.radiosity.any()
    assert sol.stats["rays"] == 0


def test_direct_only_and_black_scene(sphere32):
    # albedo 0: B = E exactly, gathering skipped
    vox = voxelset(sphere32, albedo=0.0)
    sol = voxgi.solve(vox, directions=4, shoot_directions=4, progress=False)
    assert np.array_equal(sol.radiosity, np.float32(np.pi) * vox.emission)
    assert sol.bounces == 0
    assert "gathering" in sol.stats["skipped"]


def test_save_load_roundtrip(tmp_path, sphere32):
    vox = voxelset(sphere32, albedo=0.5, emit_mask=_cap(sphere32))
    sol = voxgi.solve(vox, directions=4, shoot_directions=4, progress=False, max_bounces=2)
    p = sol.save(tmp_path / "sol")
    back = voxgi.Solution.load(p)
    assert np.array_equal(back.radiosity, sol.radiosity)
    assert np.array_equal(back.vox.ijk, vox.ijk)
    assert np.array_equal(back.vox.back, vox.back)
    assert back.vox.pitch == vox.pitch
    assert back.bounces == sol.bounces
    assert back.residuals == sol.residuals
    assert back.stats["gather_rays"] == sol.stats["gather_rays"]


def test_bad_input(sphere32):
    vox = voxelset(sphere32, albedo=0.5)
    with pytest.raises(TypeError, match="VoxelSet"):
        voxgi.solve({"ijk": vox.ijk})
    with pytest.raises(ValueError, match="directions"):
        voxgi.solve(vox, directions=0)
    with pytest.raises(TypeError, match="directions"):
        voxgi.solve(vox, directions=8.5)
    with pytest.raises(ValueError, match="tol"):
        voxgi.solve(vox, tol=0)
    with pytest.raises(ValueError, match="method"):
        voxgi.solve(vox, method="sor")
    # not a Client: TypeError (ImportError naming the extra where Dask is absent)
    with pytest.raises((TypeError, ImportError), match="client"):
        voxgi.solve(vox, client=object())
    import dataclasses

    bad = dataclasses.replace(vox, area=vox.area[:-1])
    with pytest.raises(ValueError, match=r"vox\.area"):
        voxgi.solve(bad)
    bad = dataclasses.replace(vox, albedo=np.full_like(vox.albedo, 1.5))
    with pytest.raises(ValueError, match="albedo"):
        voxgi.solve(bad)
    bad = dataclasses.replace(vox, normal=vox.normal * 2)
    with pytest.raises(ValueError, match="unit"):
        voxgi.solve(bad)
    # the caller's arrays are not modified
    before = vox.emission.copy()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        voxgi.solve(vox, directions=3, shoot_directions=3, progress=False, max_bounces=1)
    assert np.array_equal(before, vox.emission)


# ----------------------------------------------------------------- built-in scenes


def _direct_imbalance(vox, **kw):
    # all albedos 0: the balance is the shooting's alone
    import dataclasses

    v0 = dataclasses.replace(vox, albedo=np.zeros_like(vox.albedo))
    sol = voxgi.solve(v0, directions=8, shoot_directions=16, progress=False, **kw)
    return sol.stats["energy"]["imbalance"][0], sol


def test_flat_lamp_in_closed_box_conserves_energy():
    # A flat lamp (the Cornell light quad) in a closed box of black walls:
    # absorbed = emitted. Measured at res 32: imbalance -0.0003 with the
    # partial-coverage shooting, -0.52 with the paper's whole-line rule (the
    # lamp's one-voxel band seen edge-on by the walls sends as if it were a
    # voxel thick); at res 64: 0.0014 and -0.23.
    scene = voxgi.scenes.cornell_box(width=32, height=32, blocks=False, closed=True)
    vox = _voxelize(scene, 32)
    imb, sol = _direct_imbalance(vox)
    assert sol.stats["flat_emitter_objects"] == [int(vox.object_id[vox.is_emitter][0])]
    assert abs(imb) < 2e-3
    imb_line, _ = _direct_imbalance(vox, shoot_coverage=False)
    assert imb_line < -0.3


def test_cornell_blocks_silhouettes_conserve_direct_light():
    # The closed Cornell box with its blocks, albedo 0: absorbed = emitted.
    # A shooting line that clips a block's rim had its rim records take their
    # area's share and was then stopped whole by the block's far side, so
    # shadows came out a voxel too wide (benchmarks/energy_silhouette.py,
    # res 32, against an Embree reference: floor -1.9%, back -0.6%, red -0.8%
    # of the emitted power, the floor's loss 83% in its penumbra). The
    # silhouette rule carries the uncovered share past the block. Measured
    # (R 8, shooting 16): +0.0346 -> +0.0029 at res 32, +0.0204 -> +0.0043 at
    # 64; without blocks -0.0003 / +0.0014 either way.
    scene = voxgi.scenes.cornell_box(width=32, height=32, closed=True)
    vox = _voxelize(scene, 32)
    imb, sol = _direct_imbalance(vox)
    assert sol.stats["shoot_silhouettes"]
    assert abs(imb) < 5e-3
    assert sol.stats["energy"]["escaping"][0] < 1e-4 * sol.stats["energy"]["emitted"][0]
    imb_old, _ = _direct_imbalance(vox, shoot_silhouettes=False)
    assert imb_old > 0.03


def test_closed_black_cornell_box_direct_light_balances_to_1e4_at_res128():
    # The shooting alone (albedo 0) in the closed Cornell box: absorbed =
    # emitted. A line running along a block's face, nearly parallel to it,
    # meets one back twin a voxel; 16 of them filled the history and stopped
    # the lamp's light with nothing received, 0.08% of the emitted power.
    # Measured (R 8, shooting 16; benchmarks/energy_direct.py): +0.00102
    # before, +0.00012 with a coplanar run kept as its first and latest
    # record (res 256: +0.00094 -> +0.00000).
    scene = voxgi.scenes.cornell_box(width=32, height=32, closed=True)
    vox = _voxelize(scene, 128)
    imb, sol = _direct_imbalance(vox)
    assert sol.stats["energy"]["escaping"][0] < 1e-4 * sol.stats["energy"]["emitted"][0]
    assert abs(imb) < 4e-4


@pytest.mark.slow
def test_cornell_box_energy_balance_converges():
    # Cornell box (open front): (emitted - absorbed - escaping) / emitted,
    # escaping counted on the sender side. Measured (R = 8, shooting 16,
    # benchmarks/propagation.py cornell): +0.033 at res 32, +0.025 at 64 with
    # the partial-coverage shooting (-0.37, -0.15 with the whole-line rule).
    # What is left is light that grazes the blocks' edges: the edge records
    # take the share of the line their area covers and the blocks' far side
    # stops the rest (closed box, albedo 0: 0.035 / 0.020 with the blocks,
    # -0.0003 / 0.0014 without). Not 1e-3: see the closing note. The test
    # holds the sign and the trend (here, R 6 and 12: 0.046 at res 24, 0.022 at
    # 48): it falls with the pitch. With the shooting's silhouette rule
    # (default since): 0.0088 at res 24, 0.0021 at 48 (0.0026 at 32, 0.009 at
    # 64 with R 8 and 16: the gathering still stops grazing lines whole).
    # The convergence study (R 8, 16, tol 1e-5, benchmarks/propagation.py
    # energy), red: 0.25% / 0.85% / 0.52% / 0.025% / -0.015% / 0.022% at res
    # 32 / 64 / 128 / 256 / 512 / 768 (it levelled off near 0.1% before the
    # shooting kept coplanar runs of F records in its history).
    scene = voxgi.scenes.cornell_box(width=32, height=32)
    imb = []
    for res in (24, 48):
        vox = _voxelize(scene, res)
        sol = voxgi.solve(vox, directions=6, shoot_directions=12, progress=False, tol=1e-4)
        e = sol.stats["energy"]
        assert np.all(np.array(e["escaping"]) > 0)
        imb.append(e["imbalance"][0])
    assert 0 < imb[1] < 0.6 * imb[0]
    assert imb[0] < 0.015
    assert imb[1] < 5e-3


@pytest.mark.slow
def test_cornell_box_energy_balance_meets_the_issue_at_res256():
    # Issue 3: power emitted = absorbed + escaping through the open side, to
    # 1e-3. Measured (R 8, shooting 16, tol 1e-5; benchmarks/propagation.py
    # energy): 0.025% / 0.042% / 0.009% (R / G / B) at res 256, and within
    # 0.04% at 512 and 768; 0.52% at 128, where the gathering's silhouettes
    # still dominate. The bound is the issue's.
    scene = voxgi.scenes.cornell_box(width=32, height=32)
    vox = _voxelize(scene, 256)
    sol = voxgi.solve(vox, directions=8, shoot_directions=16, progress=False, tol=1e-5)
    e = sol.stats["energy"]
    assert np.all(np.array(e["escaping"]) > 0.2 * np.array(e["emitted"]))  # 25-36%
    assert np.all(np.abs(e["imbalance"]) < 1e-3)


def test_furnace_sphere_rho099_meets_the_issue_at_res96():
    # Issue 3's furnace at rho 0.99: 0.5% mean needs a lost fraction δ under
    # about 5e-5 (the error is about 99 δ). The sphere's δ falls fast with
    # the resolution (res 48: 2.45e-4, mean |err| 1.64%; res 96: 3.3e-5,
    # mean 0.28%, max 0.60%, 4 iterations with the geometric-tail
    # extrapolation; benchmarks/furnace_inner.py --res 96). The bounds are
    # the issue's acceptance, not the measurement.
    rho = 0.99
    vox = _voxelize(voxgi.scenes.furnace_sphere(albedo=rho, emission=1.0), 96)
    sol = voxgi.solve(vox, directions=8, shoot_directions=8, progress=False)
    front = ~vox.back
    err = np.abs(sol.radiance[front].astype(np.float64) * (1 - rho) - 1)
    assert err.mean() < 5e-3
    assert err.max() < 2e-2
    assert sol.stats["lost_fraction"] < 5e-5
    assert sol.bounces <= 36  # a few dozen, not the ~900 of plain Jacobi


@pytest.mark.parametrize("rho", [0.5])
def test_furnace_box_with_inner_sphere(rho):
    vox = _voxelize(voxgi.scenes.furnace_box(albedo=rho, emission=1.0, inner=True), 32)
    sol = voxgi.solve(vox, directions=8, shoot_directions=8, progress=False, tol=1e-6)
    front = ~vox.back
    err = np.abs(sol.radiance[front] * (1 - rho) - 1)
    assert err.mean() < 5e-3
    assert err.max() < 2e-2


def test_furnace_box_closed_inner_sphere_rho09():
    # Issue 3: a closed inner object (same Le, rho) must not lose light through
    # naive lines that clip its band where only its near side lies on the
    # line (they reach its black back records, its inside). Measured at res
    # 32, R = 8, rho = 0.9: closed=None mean |err| 2.8%, max 5.7%, back_fraction
    # 3.3e-3 (x ~9 at rho 0.9); closed=True mean 0.016%, max 0.35%. The bounds
    # are the issue's acceptance (0.5% mean, 2% max), well above the measured.
    rho = 0.9
    vox = _voxelize(voxgi.scenes.furnace_box(albedo=rho, emission=1.0, inner=True), 32)
    front = ~vox.back
    assert vox.stats["closed_objects"] == [0, 1]  # both meshes found watertight
    open_ = voxgi.solve(vox, directions=8, shoot_directions=8, progress=False, tol=1e-6,
                        closed=False)
    assert open_.stats["back_fraction"] > 1e-3  # the loss is visible in the stats
    assert open_.stats["closed_back_records"] == 0
    sol = voxgi.solve(vox, directions=8, shoot_directions=8, progress=False, tol=1e-6, closed=True)
    err = np.abs(sol.radiance[front] * (1 - rho) - 1)
    assert err.mean() < 5e-3
    assert err.max() < 2e-2
    assert sol.stats["closed_back_records"] == int(vox.back.sum())
    # the default (closed=None) takes the watertight objects found by voxelize
    auto = voxgi.solve(vox, directions=8, shoot_directions=8, progress=False, tol=1e-6)
    np.testing.assert_array_equal(auto.radiosity, sol.radiosity)
    assert sol.stats["back_fraction"] == 0.0  # every back record stands in for its twin
    assert np.all(sol.radiosity[~front] == 0)  # back records themselves stay black
    # closed=[ids] picks objects: only the inner sphere (object 1)
    part = voxgi.solve(vox, directions=8, shoot_directions=8, progress=False, tol=1e-6, closed=[1])
    assert part.stats["closed_back_records"] == int((vox.back & (vox.object_id == 1)).sum())


def test_furnace_sphere_closed_inner_box_edges_rho09():
    # Issue 3: at the convex edges of a closed inner box, two back records of
    # the box (stand-ins for their front twins) faced each other along a
    # line and paired; the answered back F then occluded the box's front
    # records behind it from the enclosure (a box front record lost up to a
    # quarter of its hemisphere). Stand-ins now never pair. Measured at res
    # 32, R = 8, rho = 0.9, tol 1e-6 (closed by default): before, box records
    # mean err -2.72%, max |err| 23.6%, all front records mean |err| 1.56%,
    # lost_fraction 8.5e-4; after, box mean -0.29%, max 0.54%, all front mean
    # |err| 0.33%, max 1.8% (a sphere record), lost_fraction 3.2e-4.
    rho = 0.9
    vox = _voxelize(voxgi.scenes.furnace_sphere(albedo=rho, emission=1.0, inner=True), 32)
    assert vox.stats["closed_objects"] == [0, 1]
    sol = voxgi.solve(vox, directions=8, shoot_directions=8, progress=False, tol=1e-6)
    assert sol.stats["closed_back_records"] == int(vox.back.sum())
    front = ~vox.back
    err = sol.radiance[:, 0] * (1 - rho) - 1
    box = front & (vox.object_id == 1)
    assert box.sum() > 400
    assert np.abs(err[box]).max() < 2e-2  # was 23.6%
    assert np.abs(err[box].mean()) < 5e-3  # was 2.7%
    assert np.abs(err[front]).mean() < 5e-3  # was 1.56%
    assert np.abs(err[front]).max() < 3e-2
    assert sol.stats["lost_fraction"] < 5e-4  # was 8.5e-4


def test_stand_ins_never_pair():
    # The kernels' stand_in flags, on one line along +x as at a convex edge
    # of a closed box: A (front, facing +x, value 1), SF (stand-in, facing
    # +x, 2), SB (stand-in, tilted, facing -x, 4; A lies behind its plane),
    # D (front, facing -x, 8). Without flags SB and SF pair and the answered
    # SF occludes A from D: A gets nothing. With them SB looks past SF (and
    # A does not face it), D answers SF and then A. Both gather variants
    # agree; shooting from SF no longer reaches SB.
    ijk = np.array([[0, 0, 0], [2, 0, 0], [3, 0, 0], [5, 0, 0]], np.int32)
    nsb = np.array([-0.2, 0.98, 0.0]) / np.hypot(0.2, 0.98)
    normal = np.array([[1, 0, 0], [1, 0, 0], nsb, [-1, 0, 0]], np.float32)
    point = np.array([[0.5, 0.0, 0.5], [2.5, 0.9, 0.5], [3.5, 0.9, 0.5], [5.5, 0.5, 0.5]],
                     np.float32)
    s = voxgi._core.LineSystem(ijk, normal, point, epsilon=0.02, history=16)
    fam, w, idx = np.array([[1, 0, 0]], np.int32), np.ones(1), np.zeros(1, np.int64)
    vals = np.zeros((4, 3), np.float32)
    vals[:, 0] = [1, 2, 4, 8]
    sb = np.array([False, True, True, False])
    csb = -float(normal[2, 0])  # SB's cosine along -x
    for alg in ("onepass", "sort"):
        plain, _, _ = s.gather(fam, w, vals, idx, False, 1, alg)
        np.testing.assert_allclose(plain[:, 0], [0, 4, 2 * csb, 2], rtol=1e-6)
        out, _, _ = s.gather(fam, w, vals, idx, False, 1, alg, stand_in=sb)
        np.testing.assert_allclose(out[:, 0], [8, 8, 0, 2], rtol=1e-6)
    em = np.array([1], np.int32)
    hd, _, _, _ = s.shoot(em, fam, w, vals, 1)
    np.testing.assert_allclose(hd[:, 0], [0, 0, 2 * csb, 2], rtol=1e-6)
    hd, _, _, _ = s.shoot(em, fam, w, vals, 1, stand_in=sb)
    np.testing.assert_allclose(hd[:, 0], [0, 0, 0, 2], rtol=1e-6)
    with pytest.raises(ValueError, match="stand_in"):
        s.gather(fam, w, vals, idx, False, 1, stand_in=sb[:3])
