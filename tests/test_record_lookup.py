"""The record a gather ray's hit reads: the kernels' lookup against a
straightforward one (every candidate in visiting order, each asking every
other record of its voxel), on scenes of thin walls, folds and junctions."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import closed_slabs

import voxgi
from voxgi import traced
from voxgi._core import testing
from voxgi.rays import Tracer
from voxgi.traced import record_grid


def _hits_of_rays(scene, vox, rng, count, *, triangles=False):
    """Hits of cosine-distributed rays from random records, as the traced
    passes make them: the point on the hit triangle's plane, its normal on the
    ray's side, its object; with ``triangles`` also the triangle and whether
    its winding faces the ray (int32, uint8)."""
    with Tracer(scene, 1) as tr:
        pick = rng.integers(0, len(vox), count)
        nrm = np.asarray(vox.normal, np.float64)[pick]
        org = np.asarray(vox.centroid, np.float64)[pick] - tr.centre
        d = rng.normal(size=(count, 3))
        d = nrm + d / np.linalg.norm(d, axis=1, keepdims=True)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        org = org + 1e-4 * float(np.linalg.norm(np.ptp(scene.bounds, axis=0))) * nrm
        prim, _, _ = tr.first_hit(org, d)
        ok = prim >= 0
        t = tr.tris[prim[ok]]
        org, d = org[ok], d[ok]
        nt = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        nt /= np.linalg.norm(nt, axis=1, keepdims=True)
        dn = np.einsum("ij,ij->i", d, nt)
        tt = np.einsum("ij,ij->i", t[:, 0] - org, nt) / dn
        y = org + tt[:, None] * d
        n = -np.sign(dn)[:, None] * nt
        obj = np.asarray(scene.triangles()["object"], np.int32)[prim[ok]]
        if triangles:
            return y, n, obj, tr.centre, prim[ok].astype(np.int32), (dn < 0).astype(np.uint8)
        return y, n, obj, tr.centre


def _surface_points(scene, centre, rng, count):
    """Points on the triangles (by area, many near an edge or a corner), seen
    from either side."""
    tri = scene.triangles()
    v = np.asarray(tri["triangles"], np.float64)
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    f = rng.choice(len(v), count, p=area / area.sum())
    b = rng.uniform(size=(count, 2))
    b = np.where(b.sum(axis=1, keepdims=True) > 1, 1 - b, b)
    edge = rng.uniform(size=count) < 0.5  # within a thousandth of an edge
    b[edge, 0] *= 1e-3
    y = v[f, 0] + b[:, :1] * (v[f, 1] - v[f, 0]) + b[:, 1:] * (v[f, 2] - v[f, 0]) - centre
    nt = np.cross(v[f, 1] - v[f, 0], v[f, 2] - v[f, 0])
    nt /= np.linalg.norm(nt, axis=1, keepdims=True)
    side = np.where(rng.uniform(size=count) < 0.5, -1.0, 1.0)
    return y, side[:, None] * nt, np.asarray(tri["object"], np.int32)[f]


@pytest.mark.parametrize("name", ["split-box", "door-room", "cornell-box", "bunny-room"])
def test_lookup_matches_the_straightforward_one(name):
    scene = voxgi.scenes.get(name)
    vox = voxgi.voxelize(scene, resolution=48, progress=False)
    rng = np.random.default_rng(7)
    y1, n1, o1, centre = _hits_of_rays(scene, vox, rng, 40_000)
    y2, n2, o2 = _surface_points(scene, centre, rng, 40_000)
    y, n, obj = np.concatenate([y1, y2]), np.concatenate([n1, n2]), np.concatenate([o1, o2])
    grid = record_grid(vox, centre, np.zeros((len(vox), 3), np.float32))
    args = (grid["rec_sorted_key"], grid["rec_cell_start"], grid["rec_packed"],
            grid["grid_dims"], grid["grid_lo"], grid["grid_origin"], grid["pitch"],
            np.ascontiguousarray(y), np.ascontiguousarray(n, np.float32),
            np.ascontiguousarray(obj))  # fmt: skip
    got = testing.record_lookup(*args)
    want = testing.record_lookup(*args, reference=True)
    # the hits reach records of every kind the lookup tells apart
    assert np.count_nonzero(want < 0) < len(want) // 2
    bad = np.flatnonzero(got != want)
    assert bad.size == 0, (
        f"{bad.size} of {len(want)} hits read another record, e.g. hit {bad[0]} at "
        f"{y[bad[0]]} (normal {n[bad[0]]}, object {obj[bad[0]]}): {got[bad[0]]} "
        f"instead of {want[bad[0]]}"
    )


def test_lookup_without_the_dense_table_is_the_same():
    scene = voxgi.scenes.get("door-room")
    vox = voxgi.voxelize(scene, resolution=32, progress=False)
    rng = np.random.default_rng(3)
    y, n, obj, centre = _hits_of_rays(scene, vox, rng, 20_000)
    dense = record_grid(vox, centre, np.zeros((len(vox), 3), np.float32))
    searched = record_grid(vox, centre, np.zeros((len(vox), 3), np.float32), dense_cells=0)
    hits = (np.ascontiguousarray(y), np.ascontiguousarray(n, np.float32), obj)
    keys = ("rec_sorted_key", "rec_cell_start", "rec_packed", "grid_dims", "grid_lo",
            "grid_origin", "pitch")  # fmt: skip
    a = testing.record_lookup(*(dense[k] for k in keys), *hits)
    b = testing.record_lookup(*(searched[k] for k in keys), *hits)
    assert searched["rec_cell_start"].size == 0
    np.testing.assert_array_equal(a, b)


def _thin_closed_slats(thickness=1e-3, spacing=0.02, tilt=30.0):
    """A box room with a stack of 12 closed slabs `thickness` thick and
    `spacing` apart, tilted: at resolution 16 three slabs, six faces of one
    object and two orientations, to a voxel."""
    scene = voxgi.scenes.furnace_box(albedo=0.7, emission=0.0, width=8, height=8)
    slabs = closed_slabs(12, 0.3, thickness, spacing, tilt, (0.1, -0.12, 0.0))
    scene.add(slabs, voxgi.Material(albedo=0.9), name="slats")
    return scene


def test_a_ray_reads_the_record_its_landing_piece_went_to():
    # Rays land on faces of slabs thinner than a voxel, several to a voxel:
    # given the triangle and side, the lookup reads the record the
    # voxelization put that face's piece in, in the hit's voxel and on the
    # face's own plane, never a neighbouring slab's or another voxel's
    # (a search by the records' points alone picks those for some hits).
    scene = _thin_closed_slats()
    vox = voxgi.voxelize(scene, resolution=16, progress=False)
    assert vox.stats["layer_records"] > 0
    rng = np.random.default_rng(5)
    y, n, obj, centre, tri, front = _hits_of_rays(scene, vox, rng, 60_000, triangles=True)
    grid = record_grid(vox, centre, np.zeros((len(vox), 3), np.float32))
    pieces = traced._piece_table(vox, *traced._voxel_order(vox)[2:])
    args = (grid["rec_sorted_key"], grid["rec_cell_start"], grid["rec_packed"],
            grid["grid_dims"], grid["grid_lo"], grid["grid_origin"], grid["pitch"],
            np.ascontiguousarray(y), np.ascontiguousarray(n, np.float32), obj)  # fmt: skip
    got = testing.record_lookup(*args, tri=tri, front=front, **pieces)
    slat = obj == scene.objects.index(next(o for o in scene.objects if o.name == "slats"))
    assert slat.sum() > 5_000
    rec = grid["rec_packed"][got[slat]]
    # its own voxel
    cell = np.floor((y[slat] - grid["grid_origin"]) / grid["pitch"]).astype(np.int64)
    rel = cell - grid["grid_lo"]
    dims = grid["grid_dims"]
    key = (rel[:, 0] * dims[1] + rel[:, 1]) * dims[2] + rel[:, 2]
    first = pieces["piece_first"]
    piece_tri = np.repeat(np.arange(len(first) - 1), np.diff(first))
    listed = np.isin(key * (1 << 31) + tri[slat], pieces["piece_key"] * (1 << 31) + piece_tri)
    assert listed.mean() > 0.9
    np.testing.assert_array_equal(grid["rec_sorted_key"][got[slat]][listed], key[listed])
    # on the face's plane, facing the ray
    off = np.abs(np.einsum("ij,ij->i", y[slat] - rec[:, 0:3], rec[:, 3:6]))
    assert off[listed].max() < 1e-4 * grid["pitch"]
    assert np.all(np.einsum("ij,ij->i", rec[:, 3:6], n[slat]) > 0.99)
    # without the triangle the lookup searches, as before
    searched = testing.record_lookup(*args)
    np.testing.assert_array_equal(testing.record_lookup(*args, **pieces), searched)


def test_a_ray_on_a_split_piece_reads_the_part_on_its_side_of_the_cut():
    # A floor under a wall 1 cm thick, off the voxel faces: in the wall's
    # column of voxels each floor piece is cut by both wall faces into three
    # records (left room, under the wall, right room). A point of the floor
    # in either room reads that room's record.
    import trimesh

    floor = trimesh.Trimesh(
        np.array([[0, 0, 0], [0, 0, 1], [1, 0, 1], [1, 0, 0]], float), [[0, 1, 2], [0, 2, 3]]
    )
    wall = trimesh.creation.box(extents=[0.01, 0.5, 1.0])
    wall.apply_translation([0.5, 0.25, 0.5])
    scene = voxgi.Scene()
    scene.add(floor, voxgi.Material(albedo=0.5), name="floor")
    scene.add(wall, voxgi.Material(albedo=0.5), name="wall")
    vox = voxgi.voxelize(scene, resolution=16, progress=False)
    assert np.count_nonzero(np.diff(vox.piece_plane_first)) > 0
    rng = np.random.default_rng(2)
    x = np.where(rng.uniform(size=4000) < 0.5, 0.5 - 0.005, 0.5 + 0.005)
    x += np.sign(x - 0.5) * rng.uniform(1e-6, 0.02, size=4000)  # either room, near the wall
    z = rng.uniform(0.01, 0.99, size=4000)
    y = np.stack([x, np.zeros_like(x), z], axis=1)
    tri = np.where(x > z, 1, 0).astype(np.int32)  # (0, 1, 2) holds x <= z, (0, 2, 3) x >= z
    centre = np.zeros(3)
    grid = record_grid(vox, centre, np.zeros((len(vox), 3), np.float32))
    pieces = traced._piece_table(vox, *traced._voxel_order(vox)[2:])
    n = np.tile(np.array([0.0, 1.0, 0.0], np.float32), (len(y), 1))
    args = (grid["rec_sorted_key"], grid["rec_cell_start"], grid["rec_packed"],
            grid["grid_dims"], grid["grid_lo"], grid["grid_origin"], grid["pitch"],
            np.ascontiguousarray(y), n, np.zeros(len(y), np.int32))  # fmt: skip
    got = testing.record_lookup(*args, tri=tri, front=np.ones(len(y), np.uint8), **pieces)
    cx = grid["rec_packed"][got, 0]
    np.testing.assert_array_equal(np.sign(cx - 0.5), np.sign(x - 0.5))
    assert np.all(np.abs(cx - 0.5) > 0.005)
