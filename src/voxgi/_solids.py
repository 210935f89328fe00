"""Closed objects' solids: which records face into them (``docs/design.md`` §2).

A closed mesh bounds a solid that no light path enters. The records of other
surfaces pressed against it (buried records) and the inner side of a closed
two-sided object (sealed objects) face that solid; they are made black, and
the solve's lines let them stand in for their outer twin (§5).
"""

from __future__ import annotations

import numpy as np


def is_closed(obj) -> bool:
    """True when an object's mesh is watertight with consistent winding."""
    m = obj.to_trimesh()
    return bool(m.is_watertight and m.is_winding_consistent)


#: Directions of the rays of :func:`inside`: fixed, and none along an axis or
#: a face or cube diagonal, along which built scenes line up their edges.
_PARITY_DIRECTIONS = np.array(
    [[0.5286, 0.6213, 0.5784], [-0.7071, 0.1612, 0.6885], [0.2195, -0.8416, 0.4935]]
)


#: Crossings counted along one ray at most (as many as trimesh counts).
_MAX_CROSSINGS = 100


class _ParityRays:
    """Rays through one closed mesh that count every crossing, in Embree
    (embreex) as ``trimesh``'s ``mesh.ray.intersects_id(..., multiple_hits=True)``
    counts them: the mesh moved to its lowest corner and scaled to about
    100 units in float32, each ray stepped past the plane of every face it
    crosses by a millionth of the mesh's size, a ray stuck on one face
    doubling its step. The same arithmetic, without trimesh's per-call
    checks of its cached arrays, which cost most of a call here; and the
    same answer whatever trimesh's version."""

    def __init__(self, mesh):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        vertices = np.asarray(mesh.vertices, np.float64)
        self.scale = 100.0 / float(mesh.scale)
        self.origin = vertices.min(axis=0)
        self.scene = rtcore_scene.EmbreeScene()
        TriangleMesh(
            scene=self.scene,
            vertices=((vertices - self.origin) * self.scale).astype(np.float32),
            indices=np.asarray(mesh.faces).astype(np.int32),
        )
        self.plane_origins = np.asarray(mesh.triangles[:, 0, :], np.float64)
        self.plane_normals = np.asarray(mesh.face_normals, np.float64)
        self.offset = max(1e-8, float(mesh.scale) * 1e-6)

    def _first(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        scaled = (origins - self.origin) * self.scale
        return self.scene.run(scaled.astype(np.float32), directions.astype(np.float32))

    def crossings(self, points: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """(P,) int64: the faces each ray from ``points`` (P, 3) along
        ``directions`` (P, 3) crosses. Each ray is traced as if alone, so
        rays of many directions share the calls into Embree."""
        from trimesh.intersections import planes_lines
        from trimesh.util import unitize

        n = len(points)
        origins = np.array(points, dtype=np.float64)
        directions = unitize(np.array(directions, dtype=np.float64))
        offsets = directions * self.offset
        counts = np.zeros(n, np.int64)
        last = np.full(n, -1, np.int64)
        live = np.arange(n)
        for _ in range(_MAX_CROSSINGS):
            query = self._first(origins[live], directions[live])
            hit = query != -1
            if not hit.any():
                break
            rays, tris = live[hit], query[hit]
            # a ray that meets the face it met last is stuck on it
            stuck = last[rays] == tris
            last[rays] = tris
            ok_rays, ok_tris, stuck_rays = rays[~stuck], tris[~stuck], rays[stuck]
            at, valid = planes_lines(
                plane_origins=self.plane_origins[ok_tris],
                plane_normals=self.plane_normals[ok_tris],
                line_origins=origins[ok_rays],
                line_directions=directions[ok_rays],
            )
            ok_rays = ok_rays[valid]
            counts += np.bincount(ok_rays, minlength=n)
            origins[ok_rays] = at + offsets[ok_rays]
            offsets[ok_rays] = directions[ok_rays] * self.offset
            offsets[stuck_rays] *= 2.0
            origins[stuck_rays] += offsets[stuck_rays]
            live = np.concatenate([ok_rays, stuck_rays])
        return counts


def _parity_rays(mesh) -> _ParityRays:
    """The mesh's :class:`_ParityRays`, kept in the mesh's own cache, which
    trimesh empties when the mesh changes (the voxelization asks about one
    mesh several times)."""
    rays = mesh._cache["voxgi_parity_rays"]
    if rays is None:
        rays = mesh._cache["voxgi_parity_rays"] = _ParityRays(mesh)
    return rays


def inside(mesh, points: np.ndarray) -> np.ndarray:
    """(P,) bool: whether each point lies inside the closed ``mesh``, by the
    parity of the crossings along rays, as ``trimesh.Trimesh.contains``
    decides it, but with the same answer on every call.

    For each of three fixed directions, the crossings forward and backward
    (:class:`_ParityRays`): no crossing either way says outside; equal
    parities say what they say; unequal ones (a ray through an edge or a
    vertex counted a crossing twice or not at all) say nothing. The most
    votes win, ties outside. ``contains`` settles such rays with a random
    direction instead.
    """
    n = len(points)
    points = np.asarray(points, np.float64)
    inside = np.zeros(n, np.int64)
    outside = np.zeros(n, np.int64)
    if n == 0:
        return inside > outside
    # every point's six rays (three directions, forward and back) in one batch
    dirs = _PARITY_DIRECTIONS / np.linalg.norm(_PARITY_DIRECTIONS, axis=1)[:, None]
    dirs = np.concatenate([dirs[:, None, :], -dirs[:, None, :]], axis=1).reshape(6, 1, 3)
    counts = (
        _parity_rays(mesh)
        .crossings(np.tile(points, (6, 1)), np.broadcast_to(dirs, (6, n, 3)).reshape(-1, 3))
        .reshape(3, 2, n)
    )
    for fwd, back in counts:
        free = (fwd == 0) | (back == 0)
        agree = ~free & (fwd % 2 == back % 2)
        inside += agree & (fwd % 2 == 1)
        outside += free | (agree & (fwd % 2 == 0))
    return inside > outside


def bury(res: dict, scene, closed: list[int], pitch: float, sealed: dict | None = None) -> int:
    """Make black the records that face into another object's closed volume.

    Where a closed object touches another surface (a wall slab built against
    the ceiling and the side walls, a box standing on a floor), junction
    cutting leaves pieces of that surface against the object's faces, facing
    its inside. No light reaches them, but on the discrete lines they pair
    with records on both sides of the object and carry light through it. A
    record is buried when a point a thousandth of a voxel in front of it
    lies in the solid of a closed object of another id (inside it, or
    outside it when its faces point inwards); only records in voxels that
    hold records of that object are tested. The two-sided objects of
    ``sealed`` (:func:`seal`, object id to its merged mesh) bury alike,
    their solid the inside of that mesh. Returns how many were made black.
    """
    sealed = sealed or {}
    if not closed and not sealed:
        return 0
    ijk = res["ijk"].astype(np.int64)
    key = (ijk[:, 0] << 42) | (ijk[:, 1] << 21) | ijk[:, 2]
    oid = res["object_id"]
    buried = np.zeros(len(key), bool)
    for k in sorted(set(closed) | set(sealed)):
        idx = np.flatnonzero(np.isin(key, np.unique(key[oid == k])) & (oid != k) & ~buried)
        if not len(idx):
            continue
        probe = res["centroid"][idx] + 1e-3 * pitch * res["normal"][idx].astype(np.float64)
        if k in sealed:
            solid = inside(sealed[k], probe)
        else:
            mesh = scene.objects[k].to_trimesh()
            # the solid side: inside an outward-wound mesh, outside an inward
            # one (a room seen from within)
            solid = inside(mesh, probe) != (mesh.volume < 0)
        buried[idx[solid]] = True
    res["albedo"][buried] = 0.0
    res["emission"][buried] = 0.0
    return int(buried.sum())


def surface_without_boundary(obj):
    """The object's mesh with coincident vertices merged, or None when some
    edge of it is shared by an odd number of faces (a hole or a rim).

    Meshes exported with split vertices (a seam of normals or UVs) count as
    closed once merged; an edge shared by four faces (two shells touching
    along it) leaves the parity of a ray's crossings well defined, so only an
    odd count says that the surface has a boundary."""
    import trimesh

    m = trimesh.Trimesh(obj.vertices.copy(), obj.faces.copy(), process=False)
    m.merge_vertices(merge_tex=True, merge_norm=True)
    if len(m.faces) == 0:
        return None
    # each undirected edge as one integer: sorting those is several times
    # faster than sorting the (E, 2) rows
    edges = m.edges_sorted.astype(np.int64)
    _, uses = np.unique(edges[:, 0] * len(m.vertices) + edges[:, 1], return_counts=True)
    return None if np.any(uses % 2) else m


#: Vertices of another object tested against a closed object's solid
#: (:func:`seal`): a fixed sample of at most this many.
_OCCUPANT_SAMPLES = 64


def object_bounds(scene) -> np.ndarray:
    """(n_objects, 2, 3): each object's vertex bounds, lowest then highest
    (an object without vertices: an empty box, near nothing)."""
    out = np.empty((len(scene.objects), 2, 3))
    out[:, 0], out[:, 1] = np.inf, -np.inf
    for j, o in enumerate(scene.objects):
        v = np.asarray(o.vertices, np.float64).reshape(-1, 3)
        if len(v):
            out[j] = v.min(axis=0), v.max(axis=0)
    return out


def occupied(scene, k: int, mesh, bounds: np.ndarray | None = None) -> bool:
    """Whether anything that can be seen or that shines lies inside the solid
    of object ``k``: the camera's eye, a point or spot light, or another object
    of which more than half of the sampled vertices lie inside (a room
    modelled as one closed two-sided box holds its furniture and camera).
    Another object merely touching or piercing the solid (a leg under a
    cushion) does not occupy it. ``bounds`` (:func:`object_bounds`) spares
    a caller that asks about many objects recomputing them each time."""
    lo, hi = mesh.bounds
    points = []
    if scene.camera is not None:
        points.append(np.asarray(scene.camera.eye, np.float64))
    points += [
        np.asarray(li.position, np.float64) for li in scene.lights if hasattr(li, "position")
    ]
    if points:
        pts = np.array(points)
        box = np.all((pts >= lo) & (pts <= hi), axis=1)
        if box.any() and inside(mesh, pts[box]).any():
            return True
    if bounds is None:
        bounds = object_bounds(scene)
    near = ~(np.any(bounds[:, 1] < lo, axis=1) | np.any(bounds[:, 0] > hi, axis=1))
    near[k] = False
    samples, owner = [], []
    for j in np.flatnonzero(near):
        o = scene.objects[j]
        if o.material.is_sheet:
            continue
        v = o.vertices[:: max(1, len(o.vertices) // _OCCUPANT_SAMPLES)]
        samples.append(v)
        owner.append(np.full(len(v), j))
    if not samples:
        return False
    # one parity test for every candidate's samples: each point's answer
    # is its own, and a call costs far more than a point; a point outside
    # the solid's bounding box is outside it and needs none
    owner = np.concatenate(owner)
    points = np.concatenate(samples)
    boxed = np.flatnonzero(np.all((points >= lo) & (points <= hi), axis=1))
    n = len(scene.objects)
    counts = np.bincount(owner, minlength=n)
    if not np.any(2 * np.bincount(owner[boxed], minlength=n) > counts):
        return False
    within = boxed[inside(mesh, points[boxed])]
    return bool(np.any(2 * np.bincount(owner[within], minlength=n) > counts))


def seal(res: dict, scene, pitch: float) -> tuple[dict, int]:
    """Make the inner side of closed two-sided objects black back records.

    A two-sided object whose surface has no boundary (:func:`surface_without_boundary`)
    and whose solid holds nothing (:func:`occupied`) shows only its outside:
    no light path from the scene reaches its inner side. Left live, those
    records gather only what the discrete lines carry through the object
    between its two faces, and at albedo near 1 that light rings inside
    for thousands of iterations. A record is inner when a point a thousandth
    of a voxel in front of its centroid lies in the solid (the parity of
    :func:`inside`, whatever the winding); it becomes what the inside of a
    one-sided closed object is: a black back record, the stand-in of its
    twin on the lines (``docs/design.md`` §2, §5). Returns the objects so
    sealed (id to merged mesh) and how many records were made black.
    """
    oid = res["object_id"]
    sealed, count = {}, 0
    bounds = object_bounds(scene)
    for k, o in enumerate(scene.objects):
        if not o.two_sided or o.material.is_sheet:
            continue
        idx = np.flatnonzero(oid == k)
        if not len(idx):
            continue
        mesh = surface_without_boundary(o)
        if mesh is None or occupied(scene, k, mesh, bounds):
            continue
        probe = res["centroid"][idx] + 1e-3 * pitch * res["normal"][idx].astype(np.float64)
        inner = idx[inside(mesh, probe)]
        if not len(inner):
            continue
        res["albedo"][inner] = 0.0
        res["emission"][inner] = 0.0
        res["back"][inner] = True
        sealed[k] = mesh
        count += len(inner)
    return sealed, count
