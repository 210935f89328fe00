"""voxgi.resolution: two solutions compared through the light they reflect,
and the coarsest resolution whose solution the next one agrees with."""

import numpy as np
import pytest
import trimesh

import voxgi
from voxgi.metrics import rel_mse
from voxgi.resolution import (
    AGREEMENT_SHARE,
    CROWDED_SHARE,
    RESOLVED_GROWTH,
    crowded_share,
    resolutions,
    solution_difference,
    solve_scene,
)

RHO, LE = 0.5, 1.0


def _furnace(resolution: int):
    """The closed furnace box and its exact solution at ``resolution``: every
    record's radiosity ``π Le / (1 - ρ)``."""
    scene = voxgi.scenes.furnace_box(albedo=RHO, emission=LE)
    vox = voxgi.voxelize(scene, resolution, progress=False)
    b = np.full((len(vox), 3), np.pi * LE / (1 - RHO), np.float32)
    b[np.asarray(vox.back)] = 0.0
    return scene, voxgi.Solution(vox=vox, radiosity=b)


def _scaled_reflection(sol, factor):
    """``sol`` with its reflected radiosity ``B - π Le`` times ``factor``."""
    e = np.pi * np.asarray(sol.vox.emission, np.float64)
    b = e + factor * (np.asarray(sol.radiosity, np.float64) - e)
    return voxgi.Solution(vox=sol.vox, radiosity=b.astype(np.float32))


def test_exact_solutions_on_two_grids_agree():
    # every ray from inside the closed box lands on a record, which reads the
    # same radiosity on either grid: the lookup across grids is exact
    scene, coarse = _furnace(8)
    _, fine = _furnace(16)
    d = solution_difference(scene, coarse, fine, threads=2)
    assert d["rel_mse"] < 1e-10
    assert np.allclose(d["brightness"], 1.0, atol=1e-6)
    assert d["probes"] > 0
    assert d["rays"] == 2 * 16 * d["probes"]


def test_the_difference_of_a_scaled_reflection_is_its_closed_form():
    # coarse reflects (1 + δ) times the light: every probe's reflected light
    # ρ H / π differs by δ ρ R / π, R = π Le ρ / (1 - ρ) the reflected
    # radiosity, over L² + 0.01 with L = Le / (1 - ρ)
    scene, coarse = _furnace(8)
    _, fine = _furnace(16)
    delta = 0.1
    d = solution_difference(scene, _scaled_reflection(coarse, 1 + delta), fine, threads=2)
    reflected = np.pi * LE * RHO / (1 - RHO)
    radiance = LE / (1 - RHO)
    want = (delta * RHO * reflected / np.pi) ** 2 / (radiance**2 + 0.01)
    assert d["rel_mse"] == pytest.approx(want, rel=1e-4)
    assert np.allclose(d["brightness"], 1 + delta, rtol=1e-5)
    # the other way round: coarse is the darker one
    d = solution_difference(scene, _scaled_reflection(coarse, 1 - delta), fine, threads=2)
    assert d["rel_mse"] == pytest.approx(want, rel=1e-4)


def test_the_rays_are_shared_so_the_difference_has_no_noise_of_its_own():
    # a Cornell box solved once, compared with itself on another grid's
    # records: the same seed gives the same difference, another seed nearly
    scene = voxgi.scenes.cornell_box(width=16, height=16)
    a = voxgi.solve(voxgi.voxelize(scene, 16, progress=False), progress=False, threads=2)
    b = voxgi.solve(voxgi.voxelize(scene, 32, progress=False), progress=False, threads=2)
    d0 = solution_difference(scene, a, b, threads=2)["rel_mse"]
    assert solution_difference(scene, a, b, threads=1)["rel_mse"] == d0
    d1 = solution_difference(scene, a, b, seed=1, threads=2)["rel_mse"]
    assert d1 == pytest.approx(d0, rel=0.2)
    assert solution_difference(scene, b, b, threads=2)["rel_mse"] == 0.0


def test_bad_arguments_are_refused():
    scene, sol = _furnace(8)
    with pytest.raises(TypeError, match="coarse"):
        solution_difference(scene, sol.radiosity, sol)
    with pytest.raises(ValueError, match="samples"):
        solution_difference(scene, sol, sol, samples=0)
    other = voxgi.scenes.furnace_box(albedo=0.3)
    with pytest.raises(ValueError, match="another scene"):
        solution_difference(other, sol, sol)
    with pytest.raises(ValueError, match="tol"):
        solve_scene(scene, tol=0.0)
    with pytest.raises(TypeError, match="scene"):
        solve_scene(sol)


def test_resolutions_double_up_to_the_largest():
    assert resolutions(64) == [16, 32, 64]
    assert resolutions(40) == [16, 32, 40]
    assert resolutions(16) == [16]
    assert resolutions(8) == [8]


@pytest.fixture(scope="module")
def cornell():
    scene = voxgi.scenes.cornell_box(width=48, height=48)
    return scene, solve_scene(scene, tol=1e-3, max_resolution=64, progress=False, threads=2)


def test_the_cornell_box_stops_where_two_resolutions_agree(cornell):
    scene, sol = cornell
    r = sol.stats["resolution"]
    assert [lv["resolution"] for lv in r["levels"]] == [16, 32]
    assert r["chosen"] == 32 == sol.vox.resolution
    assert 0 < r["levels"][1]["difference"] <= AGREEMENT_SHARE * 1e-3
    assert all(g >= RESOLVED_GROWTH for g in r["growth"])
    assert "64" in sol.stats["skipped"]["resolutions"]
    # the solution kept is the one voxgi.solve gives at that resolution
    again = voxgi.solve(voxgi.voxelize(scene, 32, progress=False), progress=False, threads=2)
    assert np.array_equal(again.radiosity, sol.radiosity)


def test_the_picture_of_the_resolution_kept_is_the_finest_ones(cornell):
    # the claim the choice rests on: the picture from the 32 grid and from
    # the 64 grid differ by less than the share of the tolerance it allows
    # (same seeds; each picture's own noise at 64 frames is about 1e-4)
    scene, sol = cornell
    fine = voxgi.solve(voxgi.voxelize(scene, 64, progress=False), progress=False, threads=2)
    kw = dict(max_frames=64, tol=0.0, seed=3, progress=False, threads=2)
    a = voxgi.render(scene, sol, **kw).image
    b = voxgi.render(scene, fine, **kw).image
    assert rel_mse(a, b) <= AGREEMENT_SHARE * 1e-3  # measured 4e-5
    # a solution whose reflected light is 20% low fails the same bound
    # (measured 3.8e-3), and the difference sees it
    dark = _scaled_reflection(sol, 0.8)
    assert rel_mse(voxgi.render(scene, dark, **kw).image, b) > 2 * AGREEMENT_SHARE * 1e-3
    assert solution_difference(scene, dark, fine, threads=2)["rel_mse"] > AGREEMENT_SHARE * 1e-3


def test_a_tighter_tolerance_solves_every_resolution():
    scene = voxgi.scenes.cornell_box(width=16, height=16)
    sol = solve_scene(scene, tol=1e-6, max_resolution=32, progress=False, threads=2)
    r = sol.stats["resolution"]
    assert [lv["resolution"] for lv in r["levels"]] == [16, 32]
    assert r["levels"][1]["difference"] > AGREEMENT_SHARE * 1e-6
    assert r["chosen"] == 32
    assert "more than" in r["reason"]
    assert "resolutions" not in sol.stats["skipped"]


def test_clutter_finer_than_the_voxels_goes_straight_to_the_finest():
    # a box holding an 8 x 8 x 8 lattice of cubes smaller than a voxel at 16
    # and at 32: each gives about as many records at either resolution, so
    # the records grow slowly and the coarse solve is skipped
    scene = voxgi.scenes.furnace_box(albedo=0.5, width=8, height=8)
    mat = voxgi.Material(albedo=0.5)
    for i in range(8):
        for j in range(8):
            for k in range(8):
                cube = trimesh.creation.box(extents=[0.01] * 3)
                cube.apply_translation((np.array([i, j, k]) - 3.5) * 0.11)
                scene.add(cube, mat)
    sol = solve_scene(scene, max_resolution=32, progress=False, threads=2)
    r = sol.stats["resolution"]
    assert r["growth"][0] < RESOLVED_GROWTH
    assert [lv["resolution"] for lv in r["levels"]] == [32]
    assert "16 not solved" in sol.stats["skipped"]["resolutions"]
    assert "surfaces finer" in r["reason"]


def test_a_crowded_finest_grid_is_the_only_one_voxelized():
    # 1728 cubes smaller than a voxel, as one closed object: each voxel that
    # holds one holds its six faces' records, and those voxels hold 15% of
    # the finest grid's surface, so no coarser grid is even voxelized
    scene = voxgi.scenes.furnace_box(albedo=0.5, width=8, height=8)
    cubes = []
    for i in range(12):
        for j in range(12):
            for k in range(12):
                cube = trimesh.creation.box(extents=[0.01] * 3)
                cube.apply_translation((np.array([i, j, k]) - 5.5) * 0.075)
                cubes.append(cube)
    scene.add(trimesh.util.concatenate(cubes), voxgi.Material(albedo=0.5))
    sol = solve_scene(scene, max_resolution=32, progress=False, threads=2)
    r = sol.stats["resolution"]
    assert r["crowded_share"] > CROWDED_SHARE
    assert r["growth"] == []
    assert [lv["resolution"] for lv in r["levels"]] == [32]
    assert "were not voxelized" in r["reason"]
    # the Cornell box's finest grid is not crowded
    box = voxgi.scenes.cornell_box(width=8, height=8)
    assert crowded_share(voxgi.voxelize(box, 32, progress=False)) < 0.05


def test_render_solves_as_solve_scene_does():
    scene = voxgi.scenes.cornell_box(width=16, height=16)
    kw = dict(max_frames=2, tol=2e-3, seed=1, progress=False, threads=2)
    out = voxgi.render(scene, **kw)
    sol = solve_scene(scene, tol=2e-3, progress=False, threads=2)
    assert out.solution.stats["resolution"]["chosen"] == sol.vox.resolution
    assert np.array_equal(out.solution.radiosity, sol.radiosity)
    assert np.array_equal(voxgi.render(scene, sol, **kw).image, out.image)
    s = out.stats["seconds"]
    assert s["voxelize"] > 0
    assert s["solve"] > 0


def test_a_looser_picture_takes_a_lighter_solve_that_keeps_its_picture():
    # SolveTuning.for_picture: a picture of relMSE 5e-3 stops the traced
    # passes at 5e-3 and starts them with 16 rays a record, not 64; its
    # picture stays within 2% of that tolerance of the defaults' (measured
    # 1.8e-5, same seeds), where stopping the passes at 0.3 does not
    # (3.5e-4; one ray a record at 5e-3: 5.0e-4)
    scene = voxgi.scenes.cornell_box(width=32, height=32)
    vox = voxgi.voxelize(scene, 32, progress=False)
    kw = dict(max_frames=64, tol=0.0, seed=3, progress=False, threads=2)
    light = voxgi.SolveTuning.for_picture(5e-3)
    assert (light.tol, light.traced_samples) == (5e-3, 16)
    assert voxgi.SolveTuning.for_picture(1e-3) == voxgi.SolveTuning()
    assert voxgi.SolveTuning.for_picture(1.0).tol == 1e-2
    full = voxgi.solve(vox, progress=False, threads=2)
    sol = voxgi.solve(vox, tuning=light, progress=False, threads=2)
    assert sol.stats["traced"]["rays"] < full.stats["traced"]["rays"] / 2
    reference = voxgi.render(scene, full, **kw).image
    assert rel_mse(voxgi.render(scene, sol, **kw).image, reference) <= 0.02 * 5e-3
    broken = voxgi.solve(
        vox, tuning=voxgi.SolveTuning(tol=0.3, traced_samples=16), progress=False, threads=2
    )
    assert rel_mse(voxgi.render(scene, broken, **kw).image, reference) > 0.02 * 5e-3
    # solve_scene, and so voxgi.render without a solution, solves so
    chosen = solve_scene(scene, tol=5e-3, progress=False, threads=2).stats["resolution"]
    assert chosen["solve_tuning"] == {"tol": 5e-3, "traced_samples": 16}
