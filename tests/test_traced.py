"""voxgi.traced: records' radiosity gathered by rays against the exact triangles."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from conftest import closed_slabs, irradiance_from_quad, quad

import voxgi
from voxgi import Material
from voxgi.traced import TracedGather, record_grid, traced_irradiance


def _corner_factor(a: float, b: float, h: float) -> float:
    """Form factor from a point to the rectangle [0, a] x [0, b] parallel to
    it at height h, with the point under the rectangle's corner (odd in a
    and in b, so rectangles elsewhere follow by superposition)."""
    A, B = a / h, b / h
    sa, sb = math.sqrt(1 + A * A), math.sqrt(1 + B * B)
    return (A / sa * math.atan(B / sa) + B / sb * math.atan(A / sb)) / (2 * math.pi)


def _parallel_squares(h: float = 0.5, top_albedo: float = 0.5):
    """A unit floor square facing up and a unit ceiling square h above it facing down."""
    floor = np.array([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], float)
    scene = voxgi.Scene()
    scene.add(trimesh.Trimesh(floor, [[0, 1, 2], [0, 2, 3]], process=False), Material(0.5), "floor")
    top = floor + np.array([0.0, 0.0, h])
    scene.add(
        trimesh.Trimesh(top, [[0, 2, 1], [0, 3, 2]], process=False), Material(top_albedo), "top"
    )
    return scene


def test_a_point_under_a_square_gathers_its_form_factor():
    # Radiosity 1 on the top square, 0 on the floor: a floor record gathers
    # the point-to-rectangle form factor at its surface point. Rays drawn
    # uniformly over the hemisphere instead of by cos θ would give the solid
    # angle's share, 0.37 against 0.55 under the middle.
    h = 0.5
    scene = _parallel_squares(h)
    vox = voxgi.voxelize(scene, 8, progress=False)
    values = np.where((vox.object_id == 1)[:, None], 1.0, 0.0) * np.ones((1, 3))
    floor = np.flatnonzero((vox.object_id == 0) & ~vox.back & (vox.area > 0))
    with TracedGather(scene, vox, threads=2) as g:
        H = g(values, 4096, seed=3)
        assert g.rays == 4096 * np.count_nonzero((vox.area > 0) & (vox.albedo[:, 0] > 0))
    for r in floor:
        x, y = vox.centroid[r, :2]
        F = (
            _corner_factor(1 - x, 1 - y, h)
            - _corner_factor(-x, 1 - y, h)
            - _corner_factor(1 - x, -y, h)
            + _corner_factor(-x, -y, h)
        )
        sigma = math.sqrt(F * (1 - F) / 4096)
        assert abs(H[r, 0] - F) < 4 * sigma + 1e-6, (r, H[r, 0], F)
    np.testing.assert_array_equal(H[:, 0], H[:, 1])


def test_a_lamp_loaded_with_its_back_lights_the_floor_by_its_form_factor():
    # A file's two-sided emitter loads as the one-sided lamp and a reversed
    # copy of it, its back (docs/design.md §12): two coincident faces that
    # rays meet at the same distance. The floor's rays must meet the lamp's
    # front, not the back's black reverse side: where either was taken, the
    # floor gathered about half the lamp's form factor.
    h = 0.5
    floor = np.array([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], float)
    top = floor + np.array([0.0, 0.0, h])
    faces = np.array([[0, 2, 1], [0, 3, 2]])
    scene = voxgi.Scene()
    scene.add(trimesh.Trimesh(floor, [[0, 1, 2], [0, 2, 3]], process=False), Material(0.5), "floor")
    scene.add(trimesh.Trimesh(top, faces, process=False), Material(0.0, emission=1.0), "lamp")
    scene.add(trimesh.Trimesh(top, faces[:, ::-1], process=False), Material(0.0), "lamp_back")
    vox = voxgi.voxelize(scene, 8, progress=False)
    values = np.where((vox.object_id == 1)[:, None], 1.0, 0.0) * np.ones((1, 3))
    floor_recs = np.flatnonzero((vox.object_id == 0) & ~vox.back & (vox.area > 0))
    H, _ = traced_irradiance(scene, vox, values, samples=1024, seed=5, threads=2)
    F = np.array(
        [
            _corner_factor(1 - x, 1 - y, h)
            - _corner_factor(-x, 1 - y, h)
            - _corner_factor(1 - x, -y, h)
            + _corner_factor(-x, -y, h)
            for x, y in vox.centroid[floor_recs, :2]
        ]
    )
    # the mean over the floor's 64 records, each of 1024 rays: a standard
    # error of about 0.2% of F
    assert abs(H[floor_recs, 0].mean() / F.mean() - 1) < 0.01, (H[floor_recs, 0].mean(), F.mean())


def test_the_gather_does_not_depend_on_the_thread_count():
    scene = _parallel_squares()
    vox = voxgi.voxelize(scene, 8, progress=False)
    values = np.random.default_rng(0).random((len(vox), 3))
    one, _ = traced_irradiance(scene, vox, values, samples=32, threads=1)
    two, st = traced_irradiance(scene, vox, values, samples=32, threads=2)
    np.testing.assert_array_equal(one, two)
    assert st["rays"] > 0


def test_records_that_reflect_nothing_gather_nothing():
    scene = _parallel_squares(top_albedo=0.0)
    vox = voxgi.voxelize(scene, 8, progress=False)
    H, _ = traced_irradiance(scene, vox, np.ones((len(vox), 3)), samples=8)
    assert np.all(H[vox.object_id == 1] == 0)
    assert np.all(H[(vox.object_id == 0) & ~vox.back & (vox.area > 0)] > 0)


def test_bad_values_and_scenes_are_refused():
    scene = _parallel_squares()
    vox = voxgi.voxelize(scene, 8, progress=False)
    with pytest.raises(ValueError, match=r"values: expected shape"):
        traced_irradiance(scene, vox, np.ones((3, 3)))
    with pytest.raises(ValueError, match="samples"):
        traced_irradiance(scene, vox, np.ones((len(vox), 3)), samples=0)
    with pytest.raises(ValueError, match="another scene"):
        traced_irradiance(voxgi.scenes.furnace_box(), vox, np.ones((len(vox), 3)))
    with pytest.raises(TypeError, match="scene"):
        traced_irradiance("room.obj", vox, np.ones((len(vox), 3)))


def _open_box():
    """A closed unit box of six one-sided quads facing in; only the ceiling
    reflects (the records that gather), the rest is black."""
    quads = {
        "floor": [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)],
        "ceiling": [(0, 0, 1), (0, 1, 1), (1, 1, 1), (1, 0, 1)],
        "x0": [(0, 0, 0), (0, 1, 0), (0, 1, 1), (0, 0, 1)],
        "x1": [(1, 0, 0), (1, 0, 1), (1, 1, 1), (1, 1, 0)],
        "y0": [(0, 0, 0), (0, 0, 1), (1, 0, 1), (1, 0, 0)],
        "y1": [(0, 1, 0), (1, 1, 0), (1, 1, 1), (0, 1, 1)],
    }
    scene = voxgi.Scene()
    for name, corners in quads.items():
        mesh = trimesh.Trimesh(np.array(corners, float), [[0, 1, 2], [0, 2, 3]], process=False)
        scene.add(mesh, Material(0.5 if name == "ceiling" else 0.0), name)
    return scene


def test_a_small_bright_patch_lights_the_ceiling_without_fans():
    # A 4 x 4-voxel square of the floor has radiosity 1, the rest 0: the
    # ceiling's irradiance is the square's form factor, smooth. The lines
    # carry the square's light along the R 8 directions only, so the ceiling
    # receives it in fans (33% RMS error, 62% at worst, whatever the number
    # of samples); the traced gather's error is noise, which falls with the
    # rays (12% at 1024 rays a record, 4% at 4096).
    from voxgi.directions import direction_set
    from voxgi.radiosity import line_system

    scene = _open_box()
    vox = voxgi.voxelize(scene, 16, progress=False)
    p, o = vox.pitch, np.asarray(vox.origin).reshape(3)
    a = o[0] + p * np.floor((0.375 - o[0]) / p)
    b = a + 4 * p
    c = vox.centroid
    square = (vox.object_id == 0) & ~vox.back
    square &= (c[:, 0] > a) & (c[:, 0] < b) & (c[:, 1] > a) & (c[:, 1] < b)
    assert square.sum() == 16
    values = square[:, None] * np.ones((1, 3))
    ceiling = np.flatnonzero((vox.object_id == 1) & ~vox.back & (vox.area > 0))
    exact = np.array(
        [
            _corner_factor(b - x, b - y, 1.0)
            - _corner_factor(a - x, b - y, 1.0)
            - _corner_factor(b - x, a - y, 1.0)
            + _corner_factor(a - x, a - y, 1.0)
            for x, y in c[ceiling, :2]
        ]
    )

    def rms(H):
        return float(np.sqrt(np.mean((H - exact) ** 2)) / exact.mean())

    ds = direction_set(8)
    lines = line_system(vox)
    every = np.arange(len(ds.families), dtype=np.int64)
    sums, _, _ = lines.gather(ds.families, ds.weights, values.astype(np.float32), every, False, 2)
    by_lines = sums[:, 0] / lines.normalisation(ds.families, ds.weights, 2)
    traced = {n: traced_irradiance(scene, vox, values, samples=n)[0][:, 0] for n in (1024, 4096)}
    assert rms(by_lines[ceiling]) > 0.25  # the fans this test is about
    assert rms(traced[1024][ceiling]) < 0.16
    assert rms(traced[4096][ceiling]) < 0.6 * rms(traced[1024][ceiling])


def test_a_grid_over_2_to_the_24_cells_finds_its_records_by_search():
    # Up to 2^24 cells of the records' bounding grid, a dense table gives each
    # voxel's first record; beyond, the kernels find a hit's voxel by binary
    # search over the sorted keys. Two 0.1 squares 0.05 apart, and a speck
    # at (1, 1, 1) that stretches the grid to 300^3 cells at resolution 300:
    # a floor record still gathers its form factor from the top square.
    from voxgi.traced import _record_grid, _voxel_order

    h, a = 0.05, 0.1
    floor = np.array([(0, 0, 0), (a, 0, 0), (a, a, 0), (0, a, 0)], float)
    scene = voxgi.Scene()
    scene.add(trimesh.Trimesh(floor, [[0, 1, 2], [0, 2, 3]], process=False), Material(0.5), "floor")
    top = floor + np.array([0.0, 0.0, h])
    scene.add(trimesh.Trimesh(top, [[0, 2, 1], [0, 3, 2]], process=False), Material(0.5), "top")
    speck = np.array([(1, 1, 1), (0.999, 1, 1), (1, 0.999, 1)], float)
    scene.add(trimesh.Trimesh(speck, [[0, 1, 2]], process=False), Material(0.0), "speck")
    vox = voxgi.voxelize(scene, 300)
    grid = _record_grid(
        vox, np.zeros(3), np.zeros((len(vox), 3), np.float32), None, _voxel_order(vox)
    )
    assert int(np.prod(grid["grid_dims"])) > 1 << 24
    assert grid["rec_cell_start"].size == 0  # the search, not the table
    values = np.where((vox.object_id == 1)[:, None], 1.0, 0.0) * np.ones((1, 3))
    n = 512
    H, _ = traced_irradiance(scene, vox, values, samples=n, threads=2)
    floor_rec = np.flatnonzero((vox.object_id == 0) & ~vox.back & (vox.area > 0))
    for r in floor_rec[:: max(1, len(floor_rec) // 40)]:
        x, y = vox.centroid[r, :2]
        F = (
            _corner_factor(a - x, a - y, h)
            - _corner_factor(-x, a - y, h)
            - _corner_factor(a - x, -y, h)
            + _corner_factor(-x, -y, h)
        )
        sigma = math.sqrt(F * (1 - F) / n)
        assert abs(H[r, 0] - F) < 4 * sigma + 1e-6, (r, H[r, 0], F)


def test_the_record_lookup_by_key_search_answers_as_the_dense_table():
    # Up to DENSE_TABLE_CELLS cells (2^24) a gather ray finds its voxel's
    # records through a dense table; above, by binary search over the sorted
    # voxel keys. Forced to search on a small grid, the lookup must find the
    # same records: the same gathered light, bit for bit.
    from voxgi import traced

    scene = voxgi.scenes.cornell_box()
    vox = voxgi.voxelize(scene, 16, progress=False)
    values = np.random.default_rng(4).random((len(vox), 3))
    with TracedGather(scene, vox, threads=2) as g:
        assert len(g._grid["rec_cell_start"]) == np.prod(g._grid["grid_dims"]) + 1
        # every landing searched, not read from its piece's record
        g._grid = {k: v for k, v in g._grid.items() if not k.startswith("piece_")}
        dense = g(values, 16, seed=2)
        order = traced._voxel_order(vox)
        g._grid = traced._record_grid(
            vox, g.tracer.centre, np.zeros((len(vox), 3)), None, order, dense_cells=0
        )
        assert len(g._grid["rec_cell_start"]) == 0
        search = g(values, 16, seed=2)
    assert np.count_nonzero(dense[:, 0]) > len(vox) // 4
    np.testing.assert_array_equal(search, dense)


def test_the_display_gathers_the_same_light_with_the_key_search(monkeypatch):
    # The display's gather rays, MIS-weighted against the VPLs, through the
    # same two lookups: the same image.
    import functools

    from voxgi.display import shader

    scene = voxgi.scenes.cornell_box(width=24, height=24)
    sol = voxgi.solve(voxgi.voxelize(scene, 16, progress=False), progress=False)
    kw = dict(max_frames=2, tol=0.0, progress=False, tuning=voxgi.RenderTuning(gather=9))
    dense = voxgi.display.render(scene, sol, **kw)
    monkeypatch.setattr(shader, "record_grid", functools.partial(record_grid, dense_cells=0))
    search = voxgi.display.render(scene, sol, **kw)
    assert dense.stats["gather_rays"] == search.stats["gather_rays"] > 0
    np.testing.assert_array_equal(search.image, dense.image)


def _pane_over_floor():
    """The parallel squares with a coloured glass pane between them: the
    rays from the floor to the top cross it and carry its transmittance, a
    factor per channel."""
    scene = _parallel_squares()
    pane = np.array([(0, 0, 0.25), (1, 0, 0.25), (1, 1, 0.25), (0, 1, 0.25)], float)
    glass = Material(albedo=0.0, transmittance=(0.9, 0.5, 0.2))
    mesh = trimesh.Trimesh(pane, [[0, 1, 2], [0, 2, 3]], process=False)
    scene.add(mesh, glass, "pane", two_sided=True)
    return scene


@pytest.mark.parametrize("scene", [voxgi.scenes.cornell_box, _pane_over_floor])
def test_the_kept_rays_apply_the_same_pass_to_other_values(scene):
    # A pass kept as a sparse matrix is the same rays: applied to any values
    # it gives what tracing them again gives (the weights rounded to float32,
    # the sums in another order), with each channel's transmittance.
    scene = scene()
    vox = voxgi.voxelize(scene, 8, progress=False)
    rng = np.random.default_rng(1)
    a, b = rng.random((len(vox), 3)), rng.random((len(vox), 3))
    with TracedGather(scene, vox, threads=2) as g:
        Ha = g(a, 64, seed=7, keep=True)
        rays = g.rays
        Hb = g(b, 64, seed=7)
        row_ptr, column, weight = g.matrix
        np.testing.assert_allclose(g.apply(a), Ha, rtol=1e-6, atol=1e-7)
        np.testing.assert_allclose(g.apply(b), Hb, rtol=1e-6, atol=1e-7)
        assert g.rays == 2 * rays  # apply traces nothing
    # no more entries than rays, one per distinct record read, ascending
    assert len(column) <= rays
    assert np.all(np.diff(row_ptr) >= 0)
    assert row_ptr[-1] == len(column)
    for p in range(len(vox)):
        assert np.all(np.diff(column[row_ptr[p] : row_ptr[p + 1]]) > 0)
    # the pane's colour: some rays read through it, their weights differ per channel
    coloured = np.any(weight[:, 0] != weight[:, 2])
    assert coloured == (scene.objects[-1].name == "pane")


def test_a_pass_not_kept_cannot_be_applied():
    scene = _parallel_squares()
    vox = voxgi.voxelize(scene, 8, progress=False)
    with TracedGather(scene, vox, threads=1) as g:
        with pytest.raises(RuntimeError, match="keep=True"):
            g.apply(np.ones((len(vox), 3)))
        g(np.ones((len(vox), 3)), 4, seed=0, keep=True)
        with pytest.raises(ValueError, match="values: expected shape"):
            g.apply(np.ones((3, 3)))


def test_the_kept_rays_do_not_depend_on_the_thread_count():
    scene = voxgi.scenes.cornell_box()
    vox = voxgi.voxelize(scene, 8, progress=False)
    values = np.random.default_rng(2).random((len(vox), 3))
    out = []
    for threads in (1, 2):
        with TracedGather(scene, vox, threads=threads) as g:
            g(values, 16, seed=1, keep=True)
            out.append((*g.matrix, g.apply(values)))
    for x, y in zip(*out, strict=True):
        np.testing.assert_array_equal(x, y)


def test_a_kept_matrix_with_a_column_out_of_range_is_refused():
    from voxgi import _core

    row_ptr = np.array([0, 1, 2], np.int64)
    weight = np.ones((2, 3), np.float32)
    out = np.empty((2, 3))
    ok = np.array([1, 0], np.int32)
    _core.transport_apply(row_ptr, ok, weight, np.arange(6.0).reshape(2, 3), out)
    np.testing.assert_array_equal(out, [[3, 4, 5], [0, 1, 2]])
    for bad in ([1, 2], [-1, 0]):
        with pytest.raises(ValueError, match="column"):
            _core.transport_apply(row_ptr, np.array(bad, np.int32), weight, np.ones((2, 3)), out)


#: A near-perfect mirror: a smooth conductor whose Fresnel reflectance is 1.
MIRROR = voxgi.Microfacet("conductor", alpha=0.02, eta=(0.0, 0.0, 0.0), k=(1.0, 1.0, 1.0))
#: A lamp of radiance 1 hanging over the mirror floor at x >= 0.5, facing down.
LAMP = [[0.5, 2.0, -3.0], [3.0, 2.0, -3.0], [3.0, 2.0, 3.0], [0.5, 2.0, 3.0]]


def _wall_on_a_mirror_floor(facing: float):
    """The default solve (resolution 64) of a grey wall (albedo 0.5) standing
    on a mirror floor at x = -0.3 facing +x, towards the lamp and its image
    in the mirror (``facing`` 1), or at x = +0.3 facing -x, away from both
    (-1): the solution and the wall's records away from its edges."""
    x0 = -0.3 * facing
    sc = voxgi.Scene()
    floor = [[-3, 0, -3], [-3, 0, 3], [3, 0, 3], [3, 0, -3]]
    sc.add(quad(floor), Material(0.5, specular=MIRROR), name="floor")
    wall = [[x0, 0.2, -0.5], [x0, 1.2, -0.5], [x0, 1.2, 0.5], [x0, 0.2, 0.5]]
    sc.add(quad(wall if facing > 0 else wall[::-1]), Material(0.5), name="wall")
    sc.add(quad(LAMP), Material(0.0, emission=1.0), name="lamp")
    sol = voxgi.solve(voxgi.voxelize(sc, resolution=64), progress=False)
    c = np.asarray(sol.vox.centroid)
    inner = (
        (np.asarray(sol.vox.object_id) == 1)
        & (np.asarray(sol.vox.normal)[:, 0] * facing > 0.9)  # its lit face, not its back
        & (np.abs(c[:, 2]) < 0.35)
        & (c[:, 1] > 0.35)
        & (c[:, 1] < 1.05)
    )
    return sol, inner


def test_a_wall_facing_away_from_a_lamp_gets_no_light_from_a_mirror_floor():
    # Every ray from the wall that the mirror reflects goes on away from the
    # lamp, into the open: the wall's records must stay dark. Read as its
    # record's mean, the mirror's light (its records lit by the lamp) would
    # reach them from every direction: 11% of the lit wall's light.
    dark, inner_dark = _wall_on_a_mirror_floor(-1.0)
    lit, inner_lit = _wall_on_a_mirror_floor(1.0)
    assert inner_dark.sum() > 20
    assert inner_lit.sum() > 20
    b_dark = np.asarray(dark.radiosity)[inner_dark].mean(axis=0)
    b_lit = np.asarray(lit.radiosity)[inner_lit].mean(axis=0)
    assert np.all(b_dark < 0.01 * b_lit)


def test_a_wall_facing_a_lamp_over_a_mirror_floor_gets_the_lamps_image_too():
    # The wall facing the lamp takes the lamp's light straight (its direct
    # light, by shadow rays) and through the lamp's image below the mirror,
    # which no shadow ray finds: B = ρ (E_lamp + R E_image), Lambert's
    # formula for both quads at each record's point, R the mirror's
    # directional albedo at about 45°, where the image's light meets it.
    sol, inner = _wall_on_a_mirror_floor(1.0)
    n = np.array([1.0, 0.0, 0.0])
    image = [[a, -b, c] for a, b, c in LAMP]
    r = float(MIRROR.directional_albedo((0.5,) * 3, [math.sqrt(0.5)])[0, 1])
    want = [
        0.5 * (irradiance_from_quad(x, n, LAMP) + r * irradiance_from_quad(x, n, image))
        for x in np.asarray(sol.vox.centroid)[inner]
    ]
    got = np.asarray(sol.radiosity, np.float64)[inner]
    np.testing.assert_allclose(got.mean(axis=0), np.mean(want), rtol=0.02)


def _furnace_with_slats(emits: bool = True) -> voxgi.Scene:
    """The furnace box (albedo 0.5, every surface emitting radiance 1) with
    six closed slabs 2 cm wide, 2 mm thick and 1.5 cm apart inside, of the
    same material: several slabs to a voxel at resolution 32."""
    scene = voxgi.scenes.furnace_box(albedo=0.5, emission=1.0)
    slats = closed_slabs(6, 0.02, 0.002, 0.015, 40.0, (0.0, -0.04, 0.0))
    scene.add(slats, Material(0.5, emission=1.0 if emits else 0.0), name="slats")
    return scene


def test_the_stacked_records_are_the_slats_sheets():
    # The slats' faces share voxels, one above the other: they are a stack;
    # the box's walls, one face to a voxel, are not.
    vox = voxgi.voxelize(_furnace_with_slats(), 32, progress=False)
    stacked = voxgi.traced.stacked_records(vox)
    slats = np.asarray(vox.object_id) == 1
    assert stacked[slats].mean() > 0.5
    assert not stacked[~slats].any()


def test_a_furnace_with_stacked_slats_stays_exact():
    # Every surface emits L = 1 and reflects 0.5: B = π L / (1 - ρ) = 2π at
    # every record. A ray landing on a slat reads the slat's albedo times
    # what one more ray finds there, the reflected light of a record and,
    # in the first pass, the emitted: ρ (R + E) = R, exactly, whatever the
    # ray. Measured: mean 1.00001 of 2π, every record within 0.97% (as
    # with the stacked records read as their means: the lines' junctions).
    # Dropping the emitted part those rays find: mean 0.993, the slats
    # 3.4% dark on average and one record 10%.
    scene = _furnace_with_slats()
    vox = voxgi.voxelize(scene, 32, progress=False)
    with TracedGather(scene, vox, go_on=True) as g:
        assert g.sheets > 0
    sol = voxgi.solve(vox, progress=False)
    inside = (np.asarray(vox.area) > 0) & (np.asarray(vox.emission).max(axis=1) > 0)
    b = np.asarray(sol.radiosity, np.float64)[inside]
    assert b.mean() == pytest.approx(2 * np.pi, rel=1e-3)
    np.testing.assert_allclose(b, 2 * np.pi, rtol=0.02)


def test_the_sheet_codes_stop_a_walk_at_an_emitter():
    # 1: a stacked sheet a bounced ray walks on through; 2: one that emits,
    # where a walk stops and reads its light; 0: any other record.
    for emits, code in ((False, 1), (True, 2)):
        vox = voxgi.voxelize(_furnace_with_slats(emits), 32, progress=False)
        stacked = voxgi.traced.stacked_records(vox)
        codes = voxgi.traced.sheet_codes(vox, stacked)
        # (the slabs' inner sides are black back records, which emit nothing)
        slats = (np.asarray(vox.object_id) == 1) & ~np.asarray(vox.back, bool)
        assert set(np.unique(codes[stacked & slats])) == {code}
        assert not codes[~stacked].any()


def test_the_display_grid_reads_pieces_only_to_walk_the_sheets():
    # The display's gather rays search for the record they land on, as they
    # always have, and read the pieces only to tell a stacked sheet and walk
    # it; the solve's rays read the pieces everywhere.
    vox = voxgi.voxelize(_furnace_with_slats(False), 32, progress=False)
    stacked = voxgi.traced.stacked_records(vox)
    centre = np.zeros(3)
    radiance = np.ones((len(vox), 3), np.float32)
    display = record_grid(vox, centre, radiance, stacked=stacked, pieces="sheets")
    solve = record_grid(vox, centre, radiance, stacked=stacked, pieces=True)
    assert display["pieces_for_sheets"] is True
    assert "piece_first" in display
    assert "pieces_for_sheets" not in solve
    assert "piece_first" in solve
    assert "piece_first" not in record_grid(vox, centre, radiance)
    np.testing.assert_array_equal(display["rec_stacked"], solve["rec_stacked"])
