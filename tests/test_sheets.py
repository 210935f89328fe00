"""Transmitting sheets (glass, docs/design.md §13): light crosses a sheet
straight, scaled by its transmittance T, on every ray the solve and the
display trace.

The closed forms: where every path from the light to a surface crosses one
sheet, and nothing the sheet lets pass is reflected back to it, the
surface's light is T times that of the same scene with T = 1 (the same
geometry, hence the same voxels, rays and samples); seen through the sheet
it is T twice. The comparison with Mitsuba renders the same export.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import voxgi
from voxgi.rays import Tracer


def _quad(z, half, up: bool, cx=0.0, cy=0.0):
    """A square of side 2 half at height z, facing +z (up) or -z."""
    v = [[cx - half, cy - half, z], [cx + half, cy - half, z], [cx + half, cy + half, z],
         [cx - half, cy + half, z]]  # fmt: skip
    f = [[0, 1, 2], [0, 2, 3]] if up else [[0, 2, 1], [0, 3, 2]]
    return trimesh.Trimesh(v, f, process=False)


def _box(lo, hi):
    return trimesh.creation.box(bounds=np.array([lo, hi], np.float64))


def _render_at_64(scene, **kw):
    """``voxgi.render`` of ``scene`` solved at resolution 64: two variants of
    a scene compared record by record need the same grid, which
    ``render(scene)`` would choose for each on its own."""
    sol = voxgi.solve(voxgi.voxelize(scene, 64, progress=False), progress=False, threads=1)
    return voxgi.render(scene, sol, **kw)


def _pane_scene(through, *, pane_box=False, width=24, height=24):
    """A floor (albedo 0.5) under a lamp facing down; between them a pane of
    transmittance ``through`` (a sheet, or a closed glass box around the
    lamp) that every ray from the lamp to the floor crosses once. The lamp
    reflects nothing, so the floor's light is the lamp's direct light only.
    A camera between the pane and the lamp (under the glass box) looks down
    at the floor."""
    s = voxgi.Scene()
    s.add(_quad(0.0, 1.0, up=True), voxgi.Material(albedo=0.5), name="floor")
    s.add(
        _quad(1.0, 0.2, up=False),
        voxgi.Material(albedo=0.0, emission=(4.0, 4.0, 4.0)),
        name="lamp",
    )
    glass = voxgi.Material(albedo=0.0, transmittance=through)
    if pane_box:
        s.add(_box([-0.3, -0.3, 0.7], [0.3, 0.3, 1.05]), glass, name="glass box")
    else:
        # under the lamp, wide enough that no line from it to the floor misses it
        s.add(_quad(0.5, 0.65, up=True), glass, name="pane", two_sided=True)
    s.camera = voxgi.Camera(
        eye=(0.0, 0.0, 0.6), target=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), fov=120.0,
        width=width, height=height,
    )  # fmt: skip
    return s


def test_rays_cross_sheets_scaled_by_their_transmittance():
    s = voxgi.Scene()
    s.add(_quad(0.0, 1.0, up=True), voxgi.Material(albedo=0.0, transmittance=(0.5, 0.25, 1.0)))
    s.add(_quad(1.0, 1.0, up=True), voxgi.Material(albedo=0.0, transmittance=0.5))
    s.add(_quad(2.0, 1.0, up=True), voxgi.Material(albedo=0.5), name="wall")
    tr = Tracer(s, 1)
    assert tr.has_sheets
    org = np.array([[0.1, 0.2, -1.0], [0.1, 0.2, -1.0], [0.1, 0.2, 0.5], [0.1, 0.2, 3.0]])
    org = org - tr.centre
    dirs = np.array([[0, 0, 1.0], [0, 0, -1.0], [0, 0, 1.0], [0, 0, -1.0]])
    t = tr.transmittance(org, dirs, np.array([2.5, 2.0, 1.0, 0.5]))
    np.testing.assert_array_equal(t, [[0.25, 0.125, 0.5], [1, 1, 1], [0.5, 0.5, 0.5], [1, 1, 1]])
    # past the wall: blocked; the sheets do not block
    t = tr.transmittance(org, dirs, np.array([5.0, 2.0, 5.0, 5.0]))
    np.testing.assert_array_equal(t, [[0, 0, 0], [1, 1, 1], [0, 0, 0], [0, 0, 0]])
    assert tr.occluded(org, dirs, np.array([2.5, 2.0, 1.0, 5.0])).tolist() == [0, 0, 0, 1]
    # first hits: the wall's own triangles (indices 4, 5 of the scene), through the sheets
    prim, through = tr.intersect(org, dirs, through=True)
    assert prim[0] in (4, 5)
    assert prim[2] in (4, 5)
    assert prim[3] in (4, 5)
    assert prim[1] == -1
    np.testing.assert_array_equal(
        through, [[0.25, 0.125, 0.5], [1, 1, 1], [0.5, 0.5, 0.5], [1, 1, 1]]
    )


def test_a_scene_without_sheets_has_none():
    s = voxgi.scenes.cornell_box(width=8, height=8)
    tr = Tracer(s, 1)
    assert not tr.has_sheets
    assert not s.has_sheets
    org = np.zeros((2, 3))
    dirs = np.array([[0, 1.0, 0], [0, -1.0, 0]])
    np.testing.assert_array_equal(
        tr.transmittance(org, dirs, np.array([0.01, 10.0])), [[1, 1, 1], [0, 0, 0]]
    )


def test_sheets_are_not_voxelized_and_do_not_change_the_records():
    a = voxgi.voxelize(_pane_scene(1.0), resolution=16, progress=False)
    b = voxgi.voxelize(_pane_scene(0.5), resolution=16, progress=False)
    assert 2 not in set(np.asarray(a.object_id).tolist())  # the pane (object 2) has no records
    np.testing.assert_array_equal(a.ijk, b.ijk)
    np.testing.assert_array_equal(a.centroid, b.centroid)


@pytest.mark.parametrize("pane_box", [False, True])
def test_light_through_a_sheet_is_its_transmittance_times_the_light(pane_box):
    T = np.array([0.8, 0.5, 0.25])
    kw = dict(max_frames=8, tol=0.0, threads=1, progress=False)
    clear = _render_at_64(_pane_scene(1.0, pane_box=pane_box), **kw)
    glass = _render_at_64(_pane_scene(T, pane_box=pane_box), **kw)
    # the solve: every floor record's light crossed the pane once
    b0, b1 = clear.solution.radiance, glass.solution.radiance
    lit = (np.asarray(clear.solution.vox.object_id) == 0) & (b0.max(axis=1) > 0)  # the floor
    assert lit.sum() > 50
    np.testing.assert_allclose(b1[lit], b0[lit] * T, rtol=2e-5)
    # the display: the floor seen through the pane (the light crossed it
    # twice), or under the glass box (once). The pixels' sampling differs
    # between the two renders (the VPLs are drawn by power, and the floor's
    # power changed), so the image's mean is compared: within 6e-4 at 8
    # frames (measured), where T^2 for T would be 20% off.
    want = T if pane_box else T * T
    mean0, mean1 = clear.image.mean(axis=(0, 1)), glass.image.mean(axis=(0, 1))
    np.testing.assert_allclose(mean1, mean0 * want, rtol=1e-3)


def test_the_environment_and_lights_through_a_sheet():
    # A floor under a sky and a point light, inside a closed glass box:
    # every ray from the floor to the sky or the light crosses it once.
    def scene(through):
        s = voxgi.Scene()
        s.add(_quad(0.0, 1.0, up=True), voxgi.Material(albedo=0.5), name="floor")
        glass = voxgi.Material(albedo=0.0, transmittance=through)
        s.add(_box([-1.1, -1.1, -0.1], [1.1, 1.1, 0.5]), glass, name="glass box")
        s.environment = voxgi.Environment(1.0)
        s.add_light(voxgi.PointLight(position=(0.2, 0.1, 2.0), intensity=(3.0, 3.0, 3.0)))
        s.camera = voxgi.Camera(eye=(0.0, 0.0, 0.4), target=(0.0, 0.0, 0.0), up=(0, 1, 0),
                                fov=60.0, width=16, height=16)  # fmt: skip
        return s

    T = np.array([0.9, 0.6, 0.3])
    kw = dict(max_frames=8, tol=0.0, threads=1, progress=False)
    clear, glass = _render_at_64(scene(1.0), **kw), _render_at_64(scene(T), **kw)
    b0, b1 = clear.solution.radiance, glass.solution.radiance
    lit = b0.max(axis=1) > 0  # (the floor's back is black)
    assert lit.sum() > 1000
    np.testing.assert_allclose(b1[lit], b0[lit] * T, rtol=1e-4)
    np.testing.assert_allclose(
        glass.image.mean(axis=(0, 1)), clear.image.mean(axis=(0, 1)) * T, rtol=1e-3
    )


def test_a_sheet_must_neither_reflect_nor_emit():
    with pytest.raises(ValueError, match="neither reflects nor emits"):
        voxgi.Material(transmittance=0.5)  # (the default albedo 0.8)
    with pytest.raises(ValueError, match="transmittance"):
        voxgi.Material(albedo=0.0, transmittance=1.5)
    assert not voxgi.Material().is_sheet


def test_glass_transmittance_closed_forms():
    # at index 1 nothing is reflected; the hemispherical means at 1.5
    assert voxgi.glass_transmittance(1.0) == 1.0
    assert voxgi.glass_transmittance(1.5) == pytest.approx(0.84456, abs=1e-5)
    assert voxgi.glass_transmittance(1.5, thin=False) == pytest.approx(0.90822, abs=1e-5)
    # the slab sums its inner reflections: 1 - 2R/(1+R) where R is one face's
    r = 1.0 - voxgi.glass_transmittance(1.5, thin=False)
    assert voxgi.glass_transmittance(1.5) < 1.0 - 2 * r / (1 + r) + 0.02


def test_a_sheet_survives_the_toml_round_trip(tmp_path):
    s = _pane_scene((0.8, 0.5, 0.25))
    path = s.save(tmp_path / "pane.toml")
    back = voxgi.Scene.load(path)
    assert back.fingerprint() == s.fingerprint()
    assert back.objects[2].material.transmittance == (0.8, 0.5, 0.25)
    assert _pane_scene(0.5).fingerprint() != _pane_scene(0.25).fingerprint()


@pytest.mark.slow
def test_a_glass_pane_against_mitsuba_of_the_same_export():
    # A Cornell box with a tinted pane across it, under the lamp: the light
    # crosses it on its way down and back.
    pytest.importorskip("mitsuba")
    from voxgi import mitsuba as vm

    scene = voxgi.scenes.cornell_box(width=48, height=48)
    lo, hi = scene.bounds
    y = lo[1] + 0.8 * (hi[1] - lo[1])
    c = (lo + hi) / 2
    h = 0.5 * (hi - lo) * 0.999
    pane = trimesh.Trimesh(
        [[c[0] - h[0], y, c[2] - h[2]], [c[0] + h[0], y, c[2] - h[2]],
         [c[0] + h[0], y, c[2] + h[2]], [c[0] - h[0], y, c[2] + h[2]]],
        [[0, 1, 2], [0, 2, 3]], process=False,
    )  # fmt: skip
    scene.add(pane, voxgi.Material(albedo=0.0, transmittance=(0.8, 0.7, 0.6)), name="pane",
              two_sided=True)  # fmt: skip
    out = voxgi.render(scene, max_frames=64, tol=0.0, progress=False)
    mi = vm.mitsuba_module()
    ref = np.array(mi.render(mi.load_dict(vm.to_mitsuba(scene, spp=4096))))
    # The means per channel, and the pixels' relative MSE. Measured: the
    # means within 0.3%, relMSE 4.3e-3, where two Mitsuba seeds differ by
    # 8.4e-3 (its light reaches the box through the pane by BSDF sampling
    # only); an opaque pane leaves the box dark.
    np.testing.assert_allclose(out.image.mean(axis=(0, 1)), ref.mean(axis=(0, 1)), rtol=0.02)
    rel = np.mean((out.image - ref) ** 2 / (ref**2 + 1e-2))
    assert rel < 1e-2
