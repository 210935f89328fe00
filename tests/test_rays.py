"""Embree ray queries (voxgi.rays): the compiled scene, checked against embreex's own calls."""

from __future__ import annotations

import ctypes.util

import numpy as np
import pytest

import voxgi
from voxgi import _core
from voxgi.rays import Tracer, embree_library, embree_version


def unit_square_scene() -> voxgi.Scene:
    """Two triangles covering [0, 1]² at z = 0: (0,0,0)-(1,0,0)-(1,1,0) and
    (0,0,0)-(1,1,0)-(0,1,0)."""
    import trimesh

    sq = trimesh.Trimesh(
        vertices=[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],
        faces=[[0, 1, 2], [0, 2, 3]],
        process=False,
    )
    scene = voxgi.Scene()
    scene.add(sq, voxgi.Material(albedo=0.5), name="square")
    return scene


def test_the_compiled_path_is_the_one_that_traces():
    # The rays go through the compiled core and the Embree 4 of embreex, or
    # nothing works: a render says nothing about another path.
    assert embree_version().split(".")[0] == "4"
    scene = voxgi.scenes.cornell_box(width=8, height=8)
    with Tracer(scene, 1) as tr:
        assert isinstance(tr.native, _core.RayScene)
        assert tr.native.embree_version == embree_version()
    vox = voxgi.voxelize(scene, resolution=8, progress=False)
    sol = voxgi.solve(vox, radius=4, progress=False)
    out = voxgi.display.render(scene, sol, max_frames=1, progress=False)
    assert not any("embreex" in s or "compiled" in s for s in out.stats["skipped"])


def test_rays_down_onto_a_square_hit_the_right_triangle_at_the_right_point():
    scene = unit_square_scene()
    with Tracer(scene, 2) as tr:
        rng = np.random.default_rng(1)
        xy = rng.uniform(0.02, 0.98, (5000, 2))
        xy = xy[np.abs(xy[:, 0] - xy[:, 1]) > 1e-3]  # off the shared diagonal
        world = np.column_stack([xy, np.full(len(xy), 1.0)])
        org = (world - tr.centre).astype(np.float32)
        down = np.tile(np.float32([0, 0, -1]), (len(org), 1))
        prim, u, v = tr.first_hit(org, down)
        # below the diagonal x > y lies triangle 0, above it triangle 1
        np.testing.assert_array_equal(prim, np.where(xy[:, 0] > xy[:, 1], 0, 1))
        # barycentrics of corners (v0, v1, v2): point = v0 + u (v1 - v0) + v (v2 - v0)
        t0 = prim == 0
        np.testing.assert_allclose(u[t0], xy[t0, 0] - xy[t0, 1], atol=2e-6)
        np.testing.assert_allclose(v[t0], xy[t0, 1], atol=2e-6)
        np.testing.assert_allclose(u[~t0], xy[~t0, 0], atol=2e-6)
        np.testing.assert_allclose(v[~t0], xy[~t0, 1] - xy[~t0, 0], atol=2e-6)
        np.testing.assert_array_equal(tr.intersect(org, down), prim)
        # the square lies 1 below: a segment of 0.99 misses it, one of 1.01 does not
        short = np.full(len(org), 0.99, np.float32)
        occ = tr.occluded(org, down, short)
        assert occ.dtype == np.uint8
        assert not np.any(occ)
        assert np.all(tr.occluded(org, down, short + 0.02) == 1)
        # upward rays meet nothing
        up = -down
        assert np.all(tr.intersect(org, up) == -1)
        assert np.all(tr.occluded(org, up, np.full(len(org), np.inf, np.float32)) == 0)


def test_tracers_of_one_scene_share_its_compiled_scene_until_it_changes(monkeypatch):
    """The BVH is built once per scene; an object added, its vertices moved in
    place or its transmittance changed gives a new one that sees the change."""
    import trimesh

    import voxgi.rays as rays

    builds = []
    build = rays.ray_scene
    monkeypatch.setattr(rays, "ray_scene", lambda *a: builds.append(1) or build(*a))
    scene = unit_square_scene()
    a, b = Tracer(scene, 1), Tracer(scene, 2)
    assert len(builds) == 1
    assert a.native is b.native
    assert a.tris is b.tris
    assert not a.tris.flags.writeable  # shared: no tracer may edit it
    down = np.float32([[0.25, 0.75, 1.0]]) - a.centre.astype(np.float32)
    dirs = np.float32([[0, 0, -1]])
    assert Tracer(scene, 1).intersect(down, dirs)[0] == 1
    # a square above the first: the next tracer meets it first
    above = trimesh.Trimesh(
        vertices=[[0, 0, 0.5], [1, 0, 0.5], [1, 1, 0.5], [0, 1, 0.5]],
        faces=[[0, 1, 2], [0, 2, 3]],
        process=False,
    )
    scene.add(above, voxgi.Material(albedo=0.5), name="above")
    t = Tracer(scene, 1)
    assert len(builds) == 2
    assert t.intersect(np.float32([[0.25, 0.75, 1.0]]) - t.centre.astype(np.float32), dirs)[0] == 3
    # the upper square moved away in place, sideways out of the ray's way
    scene.objects[1].vertices[:, 0] += 5.0
    t = Tracer(scene, 1)
    assert len(builds) == 3
    assert t.intersect(np.float32([[0.25, 0.75, 1.0]]) - t.centre.astype(np.float32), dirs)[0] == 1
    # the same scene again: no build
    Tracer(scene, 1)
    assert len(builds) == 3
    # the lower square made a pane of glass: the ray passes it
    scene.objects[0].material = voxgi.Material(albedo=0.0, transmittance=0.9)
    t = Tracer(scene, 1)
    assert len(builds) == 4
    assert t.has_sheets
    prim, T = t.intersect(
        np.float32([[0.25, 0.75, 1.0]]) - t.centre.astype(np.float32), dirs, through=True
    )
    assert prim[0] == -1
    np.testing.assert_allclose(T[0], 0.9, rtol=1e-6)


def test_the_compiled_scene_answers_as_embreex_does():
    scene = voxgi.scenes.cornell_box()
    rng = np.random.default_rng(0)
    n = 20000
    ext = np.ptp(scene.bounds, axis=0)
    org = (rng.uniform(-0.45, 0.45, (n, 3)) * ext).astype(np.float32)
    d = rng.normal(size=(n, 3))
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    length = rng.uniform(0.0, 0.6 * ext.max(), n).astype(np.float32)
    # embreex's own Python calls on the same triangles, with the robust flag
    # the compiled scene sets, are the reference
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    with Tracer(scene, 1) as tr:
        ref = rtcore_scene.EmbreeScene()
        TriangleMesh(ref, np.ascontiguousarray(tr.tris, np.float32))
        hit = ref.run(org, d, query="INTERSECT", output=1)
        blocked = np.asarray(ref.run(org, d, query="OCCLUDED", dists=length)) != -1
        answers = [
            (blocked.astype(np.uint8), np.asarray(hit["primID"], np.int32), hit["u"], hit["v"])
        ]
    for threads in (1, 2):
        with Tracer(scene, threads) as tr:
            answers.append((tr.occluded(org, d, length), *tr.first_hit(org, d)))
    # a mixture of hits and misses, of blocked and free segments
    assert 0.3 < np.mean(answers[0][1] >= 0) < 1.0
    assert 0.1 < np.mean(answers[0][0]) < 0.9
    for other in answers[1:]:
        for a, b in zip(answers[0], other, strict=True):
            np.testing.assert_array_equal(a, b)


def test_an_empty_or_degenerate_query_meets_nothing():
    tris = np.zeros((0, 3, 3), np.float32)
    s = _core.RayScene(embree_library(), tris)
    org = np.zeros((3, 3), np.float32)
    d = np.tile(np.float32([0, 0, 1]), (3, 1))
    assert s.triangle_count == 0
    assert np.all(s.intersect(org, d)[0] == -1)
    assert np.all(s.occluded(org, d, np.ones(3, np.float32)) == 0)
    # a triangle straight ahead, but a segment of zero or NaN length
    tri = np.array([[[-1, -1, 1], [1, -1, 1], [0, 1, 1]]], np.float32)
    s = _core.RayScene(embree_library(), tri)
    length = np.array([0.0, np.nan, 2.0], np.float32)
    np.testing.assert_array_equal(s.occluded(org, d, length), [0, 0, 1])


def test_bad_libraries_and_arrays_are_named():
    tri = np.zeros((1, 3, 3), np.float32)
    with pytest.raises(RuntimeError, match="cannot open the Embree library /no/such/libembree"):
        _core.RayScene("/no/such/libembree4.so", tri)
    libm = ctypes.util.find_library("m")
    if libm is not None:
        with pytest.raises(RuntimeError, match="has no symbol rtcNewDevice"):
            _core.RayScene(libm, tri)
    with pytest.raises(ValueError, match="tris must have shape"):
        _core.RayScene(embree_library(), np.zeros((2, 9), np.float32))
    bad = tri.copy()
    bad[0, 1, 2] = np.inf
    with pytest.raises(ValueError, match="finite"):
        _core.RayScene(embree_library(), bad)
    s = _core.RayScene(embree_library(), tri)
    with pytest.raises(ValueError, match="dirs must have shape"):
        s.intersect(np.zeros((4, 3), np.float32), np.zeros((3, 3), np.float32))
    with pytest.raises(ValueError, match="length must have shape"):
        s.occluded(
            np.zeros((4, 3), np.float32), np.zeros((4, 3), np.float32), np.zeros(3, np.float32)
        )


def test_a_library_that_cannot_be_opened_is_named(monkeypatch, tmp_path):
    # A file that is not Embree where the library should be: the tracer
    # refuses with an ImportError that names the file and the embreex range.
    fake = tmp_path / "libembree4.so.4"
    fake.write_bytes(b"not a shared library")
    monkeypatch.setattr(voxgi.rays, "embree_library", lambda: str(fake))
    with pytest.raises(ImportError, match=r"embreex>=4\.4,<5") as info:
        Tracer(unit_square_scene(), 1)
    assert str(fake) in str(info.value)


def test_a_ray_meets_the_face_of_coincident_reversed_triangles_turned_to_it():
    # A one-sided surface and its reversed copy (a lamp and its back, as a
    # file's two-sided emitter loads) lie at the same distance on every ray;
    # the first hit is the one whose front faces the ray, at the same point.
    import trimesh

    square = unit_square_scene()
    sq = square.objects[0]
    scene = voxgi.Scene()
    scene.add(trimesh.Trimesh(sq.vertices, sq.faces, process=False), voxgi.Material(0.5), "up")
    # the back's triangles split the square along the other diagonal's
    # reverse, starting at another corner: the twin is found by its corners
    back = np.array([[2, 1, 0], [3, 2, 0]])
    scene.add(trimesh.Trimesh(sq.vertices, back, process=False), voxgi.Material(0.5), "down")
    rng = np.random.default_rng(0)
    n = 2000
    xy = rng.uniform(0.1, 0.9, (n, 2))
    with Tracer(scene, 2) as tr:
        assert tr.native.twin_count == 4
        for z, obj_wanted in ((1.0, 0), (-1.0, 1)):
            org = np.column_stack([xy, np.full(n, z)]) - tr.centre
            dirs = np.column_stack([rng.uniform(-0.09, 0.09, (n, 2)), np.full(n, -z)])
            dirs /= np.linalg.norm(dirs, axis=1)[:, None]
            prim, u, v = tr.first_hit(org, dirs)
            assert (prim >= 0).all()
            obj = scene.triangles()["object"][prim]
            np.testing.assert_array_equal(obj, obj_wanted)
            t = -(org[:, 2] + tr.centre[2]) / dirs[:, 2]
            want = org + t[:, None] * dirs
            tri = tr.tris[prim]
            got = (
                tri[:, 0]
                + u[:, None] * (tri[:, 1] - tri[:, 0])
                + v[:, None] * (tri[:, 2] - tri[:, 0])
            )
            np.testing.assert_allclose(got, want, atol=1e-5)
