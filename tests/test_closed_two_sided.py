"""A closed two-sided object shows only its outside.

Bitterli's living room has a sofa of albedo 1 whose cushions are closed,
two-sided meshes. Left live, their inner faces gather only the light that
the discrete lines carry through the cushion between its faces, and at
albedo 1 it rings there: the lines took 1404 iterations. The same object
seen from outside is a one-sided closed mesh, so both must give one answer,
in the iterations that the one-sided mesh needs (``docs/design.md`` §2).
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import voxgi
from voxgi.scenes._shapes import _box, _inward

RES = 32
#: The largest albedo a record takes (1 clamped below 1, as the sofa's).
WHITE = float(np.nextafter(np.float32(1), np.float32(0)))


def room_with_box(two_sided: bool, box: trimesh.Trimesh | None = None) -> voxgi.Scene:
    """The window room (lit through its window; light leaves through the
    emitter, which absorbs) with a closed white box standing on the floor,
    turned off the grid and 0.12 m thick, under a voxel at resolution 32
    (0.156 m) for most lines that cross it."""
    scene = voxgi.scenes.window_room(width=32, height=32)
    if box is None:
        box = _box((1.2, 0.5, 0.12), (2.0, 0.25, 3.0), rotate_y_deg=31.0)
    scene.add(box, voxgi.Material(albedo=WHITE), name="box", two_sided=two_sided)
    return scene


def outside_mean(vox: voxgi.VoxelSet, sol: voxgi.Solution, which: np.ndarray) -> np.ndarray:
    """Area-weighted mean radiosity (RGB) of the records of ``which`` that
    face away from the box's solid (a point a thousandth of a voxel in front
    of each lies outside it)."""
    box = _box((1.2, 0.5, 0.12), (2.0, 0.25, 3.0), rotate_y_deg=31.0)
    probe = vox.centroid + 1e-3 * vox.pitch * vox.normal.astype(np.float64)
    out = which & ~box.contains(probe)
    a = vox.area[out, None]
    return (sol.radiosity[out] * a).sum(axis=0) / a.sum()


@pytest.fixture(scope="module")
def solves():
    """The voxels and default solve of the room with a two-sided box and
    with the same box one-sided (outward)."""
    out = {}
    for two_sided in (True, False):
        scene = room_with_box(two_sided)
        vox = voxgi.voxelize(scene, resolution=RES, progress=False)
        out[two_sided] = (scene, vox, voxgi.solve(vox, progress=False))
    return out


def test_a_closed_two_sided_box_has_black_inner_records(solves):
    scene, vox, sol = solves[True]
    k = len(scene.objects) - 1
    assert vox.stats["sealed_objects"] == [k]
    assert k in vox.stats["closed_objects"]
    mine = vox.object_id == k
    inner = mine & vox.back
    # one side of every record pair is inside: as many inner records as outer
    assert vox.stats["inner_records"] == inner.sum() == (mine & ~vox.back).sum() > 50
    assert np.all(vox.albedo[inner] == 0)
    assert f"{inner.sum()} records on the inner side" in sol.stats["skipped"]["inner_records"]
    # the one-sided box's records: the same, record for record
    _, one, _ = solves[False]
    np.testing.assert_array_equal(vox.back, one.back)
    np.testing.assert_array_equal(vox.albedo, one.albedo)


def test_a_closed_two_sided_box_of_albedo_one_converges_as_the_one_sided_box(solves):
    # With the inner faces live the lines took 1339 iterations here, against
    # 28 for the one-sided box, and the box's outside came out 0.39% brighter
    # (0.74778 against 0.74487): light from inside leaked out.
    _, vox2, sol2 = solves[True]
    _, vox1, sol1 = solves[False]
    assert sol1.bounces <= 60
    assert sol2.bounces <= sol1.bounces
    assert sol2.stats["traced"]["passes"] <= sol1.stats["traced"]["passes"]
    k = vox2.object_id.max()
    for which in (lambda v: v.object_id == k, lambda v: v.object_id != k):
        b2 = outside_mean(vox2, sol2, which(vox2))
        b1 = outside_mean(vox1, sol1, which(vox1))
        # the same records and rays: only rounding may differ
        np.testing.assert_allclose(b2, b1, rtol=1e-5)


def test_a_closed_two_sided_box_that_holds_the_camera_stays_two_sided():
    # A room modelled as one closed two-sided box is seen from inside: the
    # side facing its solid is the one the camera sees.
    scene = voxgi.Scene(camera=voxgi.Camera(eye=(0.5, 0.5, 0.9), target=(0.5, 0.5, 0.0)))
    room = _inward(_box((1.0, 1.0, 1.0), (0.5, 0.5, 0.5)))
    scene.add(room, voxgi.Material(albedo=0.5), name="room", two_sided=True)
    scene.add(_box((0.2, 0.2, 0.2), (0.5, 0.3, 0.5)), voxgi.Material(emission=1.0), name="lamp")
    vox = voxgi.voxelize(scene, resolution=16, progress=False)
    assert vox.stats["sealed_objects"] == []
    assert vox.stats["inner_records"] == 0
    assert not vox.back[vox.object_id == 0].any()


def test_a_closed_mesh_with_split_vertices_is_sealed():
    # OBJ exports split vertices along seams of normals or UVs: the mesh is
    # closed once coincident vertices are merged.
    box = _box((1.2, 0.5, 0.12), (2.0, 0.25, 3.0), rotate_y_deg=31.0)
    tris = box.vertices[box.faces]
    split = trimesh.Trimesh(
        tris.reshape(-1, 3), np.arange(3 * len(tris)).reshape(-1, 3), process=False
    )
    scene = room_with_box(True, split)
    vox = voxgi.voxelize(scene, resolution=RES, progress=False)
    assert vox.stats["sealed_objects"] == [len(scene.objects) - 1]


def test_an_open_two_sided_box_stays_two_sided():
    # Without its top, light enters the box: its inside is seen.
    box = _box((1.2, 0.5, 0.12), (2.0, 0.25, 3.0), rotate_y_deg=31.0)
    keep = box.triangles_center[:, 1] < 0.5 - 1e-9
    scene = room_with_box(True, trimesh.Trimesh(box.vertices, box.faces[keep], process=False))
    vox = voxgi.voxelize(scene, resolution=RES, progress=False)
    assert vox.stats["sealed_objects"] == []
    assert vox.stats["inner_records"] == 0


def _room_holding(box: trimesh.Trimesh) -> voxgi.Scene:
    """A closed two-sided room seen from outside it (the camera's eye and no
    light inside), holding ``box``: only the furniture says it is occupied."""
    scene = voxgi.Scene(camera=voxgi.Camera(eye=(0.5, 0.5, 3.0), target=(0.5, 0.5, 0.0)))
    room = _inward(_box((1.0, 1.0, 1.0), (0.5, 0.5, 0.5)))
    scene.add(room, voxgi.Material(albedo=0.5), name="room", two_sided=True)
    scene.add(box, voxgi.Material(emission=1.0), name="furniture")
    scene.add(_box((0.2, 0.2, 0.2), (0.5, 0.5, 1.6)), voxgi.Material(albedo=0.5), name="outside")
    return scene


def test_a_closed_two_sided_room_holding_furniture_stays_two_sided():
    # The furniture's vertices lie inside the room's solid: what the room
    # holds is seen, so its inner side must stay live.
    scene = _room_holding(_box((0.2, 0.2, 0.2), (0.5, 0.3, 0.5)))
    vox = voxgi.voxelize(scene, resolution=16, progress=False)
    assert vox.stats["sealed_objects"] == []
    assert not vox.back[vox.object_id == 0].any()


def test_a_box_piercing_a_closed_two_sided_object_does_not_occupy_it():
    # A leg under a cushion: a box with half its vertices outside the
    # room's solid does not keep it live; the room is sealed.
    scene = _room_holding(_box((0.2, 0.2, 1.6), (0.5, 0.5, 1.2)))
    vox = voxgi.voxelize(scene, resolution=16, progress=False)
    assert vox.stats["sealed_objects"] == [0]
    assert vox.back[vox.object_id == 0].any()


def test_a_voxelization_leaves_no_embree_scene_of_its_parity_tests_alive():
    # Each mesh the parity tests trace holds an embreex Embree scene in a
    # reference cycle; left to the cycle collector, the thousands of a
    # cluttered scene (Bitterli's Contemporary Bathroom: 2134 tests) made its second
    # voxelization in one process crash inside embreex. With the collector
    # switched off, none may outlive the voxelization.
    import gc

    from embreex.rtcore_scene import EmbreeScene

    def alive() -> int:
        return sum(isinstance(o, EmbreeScene) for o in gc.get_objects())

    scene = room_with_box(True)
    gc.collect()
    before = alive()
    gc.disable()
    try:
        vox = voxgi.voxelize(scene, RES, progress=False)
        assert vox.stats["sealed_objects"] == [len(scene.objects) - 1]
        assert alive() == before
    finally:
        gc.enable()
