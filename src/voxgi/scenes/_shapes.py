"""Meshes the built-in scenes are made of: quads wound toward a point, boxes, rooms."""

from __future__ import annotations

import math

import numpy as np
import trimesh


def _oriented_quads(
    quads: np.ndarray, inside: np.ndarray | None = None, outside: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate planar quads (Q, 4, 3), winding each so its normal points
    toward ``inside`` (a point) or away from ``outside``."""
    quads = np.asarray(quads, dtype=np.float64)
    verts, faces = [], []
    for q in quads:
        n = np.cross(q[1] - q[0], q[2] - q[0])
        c = q.mean(axis=0)
        want = (inside - c) if inside is not None else (c - outside)
        if np.dot(n, want) < 0:
            q = q[::-1]
        base = len(verts) * 4
        verts.append(q)
        faces += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return np.concatenate(verts), np.asarray(faces, dtype=np.int64)


def _mesh(quads, **kw) -> trimesh.Trimesh:
    v, f = _oriented_quads(
        np.asarray(quads) * 1e-3, **{k: np.asarray(p) * 1e-3 for k, p in kw.items()}
    )
    return trimesh.Trimesh(v, f, process=False)


def _inward(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    # A new mesh with reversed winding (trimesh's invert() may keep stale
    # cached face normals; docs/design.md §2).
    return trimesh.Trimesh(np.array(mesh.vertices), np.array(mesh.faces)[:, ::-1], process=False)


def _box(extents, centre, rotate_y_deg: float = 0.0) -> trimesh.Trimesh:
    b = trimesh.creation.box(extents=extents)
    if rotate_y_deg:
        b.apply_transform(
            trimesh.transformations.rotation_matrix(math.radians(rotate_y_deg), [0, 1, 0])
        )
    b.apply_translation(centre)
    return trimesh.Trimesh(b.vertices, b.faces, process=False)


def _room(size, albedo, open_top: bool = False) -> tuple[trimesh.Trimesh, np.ndarray]:
    """A closed (or roofless) box room with inward normals, floor at y = 0."""
    _, sy, _ = size
    room = trimesh.creation.box(extents=size)
    room.apply_translation([0.0, sy / 2, 0.0])
    room = _inward(room)
    if open_top:
        keep = room.triangles_center[:, 1] < sy - 1e-9
        room = trimesh.Trimesh(room.vertices, room.faces[keep], process=False)
    return room, np.array(size, dtype=np.float64)


def _ceiling_light(cx, cz, w, d, y) -> trimesh.Trimesh:
    """A one-sided quad light facing down (-y)."""
    v = [
        [cx - w / 2, y, cz - d / 2],
        [cx + w / 2, y, cz - d / 2],
        [cx + w / 2, y, cz + d / 2],
        [cx - w / 2, y, cz + d / 2],
    ]
    return trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False)


def _quad(corners, toward) -> trimesh.Trimesh:
    """A planar quad (4, 3) wound so that its normal points toward a point."""
    c = np.asarray(corners, dtype=np.float64)
    if np.dot(np.cross(c[1] - c[0], c[2] - c[0]), np.asarray(toward) - c.mean(axis=0)) < 0:
        c = c[::-1]
    return trimesh.Trimesh(c, [[0, 1, 2], [0, 2, 3]], process=False)


def _slab(lo, hi) -> trimesh.Trimesh:
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    return _box(hi - lo, (lo + hi) / 2)
