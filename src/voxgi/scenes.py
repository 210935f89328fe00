"""Built-in scenes: the Cornell box, analytic furnaces, the bunny in a room.

Every function returns a fresh :class:`voxgi.Scene` with a camera set.
"""

from __future__ import annotations

import itertools
import math
from importlib import resources

import numpy as np
import trimesh

from . import _validate
from .lights import DirectionalLight, Environment, PointLight
from .scene import Camera, Material, Scene

__all__ = [
    "bunny_room",
    "cap_sphere",
    "cornell_box",
    "emission",
    "furnace_box",
    "furnace_sphere",
    "geometric",
    "get",
    "labyrinth",
    "load_bunny",
    "names",
    "point_lit_box",
    "shadow",
    "sky_objects",
    "sponza_atrium",
    "sun_room",
    "window_room",
]

# Cornell box reflectances and light radiance as in Mitsuba 3's
# ``mi.cornell_box()`` (RGB fits of the measured spectra), so that the
# reference renders compare like with like.
CORNELL_WHITE = (0.885809, 0.698859, 0.666422)
CORNELL_GREEN = (0.105421, 0.37798, 0.076425)
CORNELL_RED = (0.570068, 0.0430135, 0.0443706)
CORNELL_LIGHT = (18.387, 13.9873, 6.75357)


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


#: The Cornell box's walls (mm): each a quad, in the order they join the scene.
_CORNELL_CENTRE = np.array([278.0, 274.4, 279.6])
_CORNELL_WALLS = {
    "floor": [[552.8, 0, 0], [0, 0, 0], [0, 0, 559.2], [549.6, 0, 559.2]],
    "ceiling": [[556.0, 548.8, 0], [556.0, 548.8, 559.2], [0, 548.8, 559.2], [0, 548.8, 0]],
    "back": [[549.6, 0, 559.2], [0, 0, 559.2], [0, 548.8, 559.2], [556.0, 548.8, 559.2]],
    "red": [[552.8, 0, 0], [549.6, 0, 559.2], [556.0, 548.8, 559.2], [556.0, 548.8, 0]],
    "green": [[0, 0, 559.2], [0, 0, 0], [0, 548.8, 0], [0, 548.8, 559.2]],
}
_CORNELL_FRONT = [[0, 0, 0], [552.8, 0, 0], [556.0, 548.8, 0], [0, 548.8, 0]]
#: The two blocks: their quads (mm) and a point inside each.
_CORNELL_BLOCKS = {
    "short_block": (
        [
            [[130, 165, 65], [82, 165, 225], [240, 165, 272], [290, 165, 114]],
            [[290, 0, 114], [290, 165, 114], [240, 165, 272], [240, 0, 272]],
            [[130, 0, 65], [130, 165, 65], [290, 165, 114], [290, 0, 114]],
            [[82, 0, 225], [82, 165, 225], [130, 165, 65], [130, 0, 65]],
            [[240, 0, 272], [240, 165, 272], [82, 165, 225], [82, 0, 225]],
        ],
        [186.0, 82.5, 169.0],
    ),
    "tall_block": (
        [
            [[423, 330, 247], [265, 330, 296], [314, 330, 456], [472, 330, 406]],
            [[423, 0, 247], [423, 330, 247], [472, 330, 406], [472, 0, 406]],
            [[472, 0, 406], [472, 330, 406], [314, 330, 456], [314, 0, 456]],
            [[314, 0, 456], [314, 330, 456], [265, 330, 296], [265, 0, 296]],
            [[265, 0, 296], [265, 330, 296], [423, 330, 247], [423, 0, 247]],
        ],
        [368.5, 165.0, 351.25],
    ),
}


def cornell_box(
    width: int = 512,
    height: int = 512,
    light_offset: float = 0.01,
    *,
    blocks: bool = True,
    closed: bool = False,
    area_light: bool = True,
) -> Scene:
    """The Cornell box with its published dimensions, in metres.

    Geometry from the Cornell Program of Computer Graphics' measured data
    (floor 552.8 × 559.2 mm, height 548.8 mm, two blocks); camera at
    (278, 273, −800) mm looking down +z with a 35 mm lens on a 25 mm film
    (vertical fov 39.3°). The box is open toward the camera. Reflectances
    and light radiance are Mitsuba 3's ``cornell_box()`` RGB values.

    Parameters
    ----------
    width, height : int
        Image size of the camera.
    light_offset : float
        How far (metres) the one-sided light quad hangs under the ceiling.
    blocks : bool
        Include the two blocks (default).
    closed : bool
        Close the box with a white fourth wall at z = 0 (object ``front``):
        nothing escapes, so every emitted watt must be absorbed (energy
        studies; the camera then sees the wall's black back).
    area_light : bool
        Include the emitting quad under the ceiling (default; without it the
        box is dark until lights are added, as in :func:`point_lit_box`).

    Returns
    -------
    Scene
        Objects ``floor``, ``ceiling``, ``back``, ``red`` (left), ``green``
        (right), ``short_block``, ``tall_block``, ``light``.
    """
    s = Scene(
        Camera(
            eye=(0.278, 0.273, -0.800),
            target=(0.278, 0.273, 0.0),
            up=(0, 1, 0),
            fov=39.3,
            width=width,
            height=height,
        )
    )
    white = Material(albedo=CORNELL_WHITE)
    colour = {"red": Material(albedo=CORNELL_RED), "green": Material(albedo=CORNELL_GREEN)}
    for name, q in _CORNELL_WALLS.items():
        s.add(_mesh([q], inside=_CORNELL_CENTRE), colour.get(name, white), name=name)
    if blocks:
        for name, (quads, centre) in _CORNELL_BLOCKS.items():
            s.add(_mesh(quads, outside=np.array(centre)), white, name=name)
    if closed:
        s.add(_mesh([_CORNELL_FRONT], inside=_CORNELL_CENTRE), white, name="front")
    if not area_light:
        return s
    y = 548.8 - light_offset * 1e3
    light = [[[343.0, y, 227.0], [343.0, y, 332.0], [213.0, y, 332.0], [213.0, y, 227.0]]]
    s.add(
        _mesh(light, inside=np.array([278.0, 0.0, 279.5])),
        Material(albedo=0.0, emission=CORNELL_LIGHT),
        name="light",
    )
    return s


def _inward(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    # A new mesh with reversed winding (trimesh's invert() may keep stale
    # cached face normals; docs/design.md §2).
    return trimesh.Trimesh(np.array(mesh.vertices), np.array(mesh.faces)[:, ::-1], process=False)


def _furnace_camera(width: int, height: int, eye=(0.0, 0.0, 0.0)) -> Camera:
    eye = np.asarray(eye, dtype=np.float64)
    return Camera(
        eye=tuple(eye),
        target=tuple(eye + np.array([0.3, -0.2, -1.0])),
        up=(0, 1, 0),
        fov=90.0,
        width=width,
        height=height,
    )


def furnace_sphere(
    albedo=0.5,
    emission=1.0,
    radius: float = 1.0,
    subdivisions: int = 4,
    inner: bool = False,
    width: int = 64,
    height: int = 64,
) -> Scene:
    """A closed sphere seen from inside, uniform emission and albedo.

    Every point has radiance ``Le / (1 - rho)`` (the furnace test).

    Parameters
    ----------
    albedo, emission : float or (3,) float
        Uniform albedo ``rho`` in [0, 1) and emitted radiance ``Le``.
    radius : float
        Sphere radius (scene units).
    subdivisions : int
        Icosphere subdivision level (4: 5120 triangles).
    inner : bool
        Add a closed box inside with the same material (the answer must not change).
    width, height : int
        Image size of the camera, in pixels.
    """
    _validate.integer(subdivisions, "subdivisions", low=0, high=7)
    radius = _validate.real(radius, "radius", low=0.0, low_open=True)
    mat = Material(albedo=albedo, emission=emission)
    s = Scene(_furnace_camera(width, height, eye=(0.0, 0.0, 0.55 * radius if inner else 0.0)))
    s.add(
        _inward(trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)),
        mat,
        name="sphere",
    )
    if inner:
        box = trimesh.creation.box(extents=[0.5 * radius, 0.35 * radius, 0.4 * radius])
        box.apply_transform(trimesh.transformations.rotation_matrix(0.4, [1, 1, 0.3]))
        box.apply_translation([0.05 * radius, -0.1 * radius, -0.1 * radius])
        s.add(trimesh.Trimesh(box.vertices, box.faces, process=False), mat, name="inner_box")
    return s


def furnace_box(
    albedo=0.5,
    emission=1.0,
    size: float = 1.0,
    inner: bool = False,
    width: int = 64,
    height: int = 64,
) -> Scene:
    """A closed cube seen from inside, uniform emission and albedo.

    Every point has radiance ``Le / (1 - rho)``. With ``inner=True`` a closed
    sphere with the same material sits inside.

    Parameters
    ----------
    albedo, emission : float or (3,) float
        Uniform albedo ``rho`` in [0, 1) and emitted radiance ``Le``.
    size : float
        Edge length of the cube (scene units).
    inner : bool
        Add a closed sphere inside with the same material (the answer must
        not change).
    width, height : int
        Image size of the camera, in pixels.

    Returns
    -------
    Scene
        A new scene with its camera set.
    """
    size = _validate.real(size, "size", low=0.0, low_open=True)
    mat = Material(albedo=albedo, emission=emission)
    s = Scene(_furnace_camera(width, height, eye=(0.0, 0.0, 0.3 * size if inner else 0.0)))
    s.add(_inward(trimesh.creation.box(extents=[size] * 3)), mat, name="box")
    if inner:
        ball = trimesh.creation.icosphere(subdivisions=3, radius=0.2 * size)
        ball.apply_translation([-0.1 * size, -0.15 * size, -0.1 * size])
        s.add(ball, mat, name="inner_sphere")
    return s


def cap_sphere(
    albedo=0.5,
    emission=1.0,
    cap_angle: float = 60.0,
    radius: float = 1.0,
    subdivisions: int = 5,
    width: int = 64,
    height: int = 64,
) -> Scene:
    """A closed sphere seen from inside whose polar cap alone emits.

    Inside a sphere every pair of points has the same form-factor kernel
    ``cos θx cos θy / (π r²) = 1 / A``, so
    ``L(x) = Le(x) + rho * Le_mean / (1 - rho)`` with ``Le_mean`` the
    area-weighted mean emission (docs/design.md §1). Triangles whose centroid
    lies within ``cap_angle`` degrees of +y form the object ``cap``.

    Parameters
    ----------
    albedo, emission : float or (3,) float
        Uniform albedo ``rho`` in [0, 1), and the emitted radiance ``Le`` of
        the cap (the rest emits nothing).
    cap_angle : float
        Half-angle of the emitting cap around +y, in degrees.
    radius : float
        Sphere radius (scene units).
    subdivisions : int
        Icosphere subdivision level (5: 20,480 triangles).
    width, height : int
        Image size of the camera, in pixels.

    Returns
    -------
    Scene
        A new scene with its camera set.
    """
    cap_angle = _validate.real(
        cap_angle, "cap_angle", low=0.0, high=180.0, low_open=True, high_open=True
    )
    sph = _inward(trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius))
    c = sph.triangles_center
    in_cap = c[:, 1] / np.linalg.norm(c, axis=1) > math.cos(math.radians(cap_angle))
    s = Scene(_furnace_camera(width, height))
    for name, sel, mat in (
        ("cap", in_cap, Material(albedo=albedo, emission=emission)),
        ("rest", ~in_cap, Material(albedo=albedo)),
    ):
        s.add(trimesh.Trimesh(sph.vertices, sph.faces[sel], process=False), mat, name=name)
    return s


def load_bunny() -> trimesh.Trimesh:
    """The Stanford bunny shipped with voxgi (3674 triangles, closed)."""
    ref = resources.files("voxgi") / "data" / "bunny.ply"
    with resources.as_file(ref) as p:
        return trimesh.load(p, force="mesh", process=False)


def bunny_room(
    width: int = 512,
    height: int = 512,
    bunny_albedo=0.75,
    room_albedo=0.7,
    light_radiance=(12.0, 12.0, 12.0),
) -> Scene:
    """The Stanford bunny on the floor of a closed room lit by a ceiling light.

    A 4 × 3 × 4 room (scene units), normals inward; the bunny is 1.8 units
    wide; a one-sided 1 × 1 area light hangs 0.01 under the ceiling.

    Parameters
    ----------
    width, height : int
        Image size of the camera, in pixels.
    bunny_albedo, room_albedo : float or (3,) float
        Albedo of the bunny and of the room's walls, in [0, 1).
    light_radiance : (3,) float
        Emitted radiance of the ceiling light (W/(m² sr) per channel).

    Returns
    -------
    Scene
        A new scene with its camera set.
    """
    s = Scene(
        Camera(
            eye=(0.0, 1.5, 1.9),
            target=(0.0, 0.6, 0.0),
            up=(0, 1, 0),
            fov=50.0,
            width=width,
            height=height,
        )
    )
    room = trimesh.creation.box(extents=[4.0, 3.0, 4.0])
    room.apply_translation([0.0, 1.5, 0.0])
    s.add(_inward(room), Material(albedo=room_albedo), name="room")
    bunny = load_bunny()
    lo, hi = bunny.bounds
    scale = 1.8 / (hi - lo)[0]
    v = (np.asarray(bunny.vertices) - [(lo[0] + hi[0]) / 2, lo[1], (lo[2] + hi[2]) / 2]) * scale
    s.add(
        trimesh.Trimesh(v, bunny.faces, process=False), Material(albedo=bunny_albedo), name="bunny"
    )
    y = 2.99
    light = trimesh.Trimesh(
        [[-0.5, y, -0.5], [0.5, y, -0.5], [0.5, y, 0.5], [-0.5, y, 0.5]],
        [[0, 1, 2], [0, 2, 3]],
        process=False,
    )  # normal -y
    s.add(light, Material(albedo=0.0, emission=light_radiance), name="light")
    return s


# -- The paper's test scenes, rebuilt procedurally ---------------------------
# Piwowar & Malgouyres test on Labyrinth, Emission, Shadow, Geometric (after
# Smits & Jensen's "Global illumination test scenes", 2000), the bunny and
# Sponza, none of whose geometry was published. These are look-alikes of the
# same kind and similar record counts at resolution ~128-256: a comparison
# with the paper's tables is by kind, not exact.


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


def labyrinth(width: int = 512, height: int = 512, cells: int = 6, seed: int = 3) -> Scene:
    """A closed maze lit from one corner cell: light must turn many corners.

    A ``cells`` × ``cells`` perfect maze (depth-first, seeded) of thin walls in
    a closed 6 × 1 × 6 room; a small ceiling light over cell (0, 0); the camera
    looks down into the maze from above the far corner. Long light paths
    (the paper's Labyrinth has light path length 9).

    Parameters
    ----------
    width, height : int
        Image size of the camera, in pixels.
    cells : int
        Cells along each side of the maze.
    seed : int
        Seed of the maze's depth-first construction.

    Returns
    -------
    Scene
        A new scene with its camera set.
    """
    _validate.integer(cells, "cells", low=2, high=32)
    rng = np.random.default_rng(seed)
    n, size, wall_h, t = cells, 6.0, 1.0, 0.06
    c = size / n
    s = Scene(
        Camera(
            eye=(2.8, 1.35, 2.8),
            target=(-1.0, 0.0, -1.0),
            up=(0, 1, 0),
            fov=75.0,
            width=width,
            height=height,
        )
    )
    room, _ = _room((size, wall_h * 1.4, size), 0.7)
    s.add(room, Material(albedo=0.7), name="room")
    # Perfect maze by randomized depth-first search over cells.
    east = np.ones((n, n), bool)  # wall on the +x side of cell (i, j)
    south = np.ones((n, n), bool)  # wall on the +z side
    seen = np.zeros((n, n), bool)
    stack = [(0, 0)]
    seen[0, 0] = True
    while stack:
        i, j = stack[-1]
        nb = [
            (i + di, j + dj)
            for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1))
            if 0 <= i + di < n and 0 <= j + dj < n and not seen[i + di, j + dj]
        ]
        if not nb:
            stack.pop()
            continue
        a, b = nb[rng.integers(len(nb))]
        if a != i:
            east[min(a, i), j] = False
        else:
            south[i, min(b, j)] = False
        seen[a, b] = True
        stack.append((a, b))
    walls = []
    x0 = -size / 2

    def span(k):  # a wall along one cell, overlapping its neighbours, clipped to the room
        lo, hi = max(x0 + k * c - t / 2, x0), min(x0 + (k + 1) * c + t / 2, -x0)
        return hi - lo, (lo + hi) / 2

    for i in range(n):
        for j in range(n):
            if east[i, j] and i < n - 1:
                ln, mid = span(j)
                walls.append(_box([t, wall_h, ln], [x0 + (i + 1) * c, wall_h / 2, mid]))
            if south[i, j] and j < n - 1:
                ln, mid = span(i)
                walls.append(_box([ln, wall_h, t], [mid, wall_h / 2, x0 + (j + 1) * c]))
    s.add(trimesh.util.concatenate(walls), Material(albedo=0.75), name="walls")
    s.add(
        _ceiling_light(x0 + c / 2, x0 + c / 2, 0.5 * c, 0.5 * c, wall_h * 1.4 - 0.005),
        Material(albedo=0.0, emission=60.0),
        name="light",
    )
    return s


def emission(width: int = 512, height: int = 512) -> Scene:
    """Emitters of different sizes, colours and shapes in a closed grey room.

    A small intense quad, a large dim panel on a wall, and a glowing sphere
    (emission tests of Smits & Jensen): the display must sample small bright
    emitters without fireflies.

    Parameters
    ----------
    width, height : int
        Image size of the camera, in pixels.

    Returns
    -------
    Scene
        A new scene with its camera set.
    """
    s = Scene(
        Camera(
            eye=(0.0, 1.2, 2.7),
            target=(0.0, 0.8, 0.0),
            up=(0, 1, 0),
            fov=55.0,
            width=width,
            height=height,
        )
    )
    room, _ = _room((4.0, 2.5, 6.0), 0.7)
    s.add(room, Material(albedo=0.7), name="room")
    s.add(
        _ceiling_light(-1.0, -1.0, 0.2, 0.2, 2.49),
        Material(albedo=0.0, emission=(200, 180, 150)),
        name="small_light",
    )
    panel = trimesh.Trimesh(
        [[1.99, 0.6, -2.0], [1.99, 0.6, -0.5], [1.99, 1.6, -0.5], [1.99, 1.6, -2.0]],
        [[0, 2, 1], [0, 3, 2]],
        process=False,
    )  # faces -x
    s.add(panel, Material(albedo=0.0, emission=(0.5, 1.5, 3.0)), name="panel_light")
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.25)
    ball.apply_translation([-0.6, 0.25, -1.2])
    s.add(ball, Material(albedo=0.5, emission=(4.0, 1.0, 0.3)), name="glow_ball")
    s.add(_box([0.6, 0.9, 0.6], [0.5, 0.45, -1.6], 20), Material(albedo=0.8), name="block")
    return s


def shadow(width: int = 512, height: int = 512) -> Scene:
    """Small occluders at several heights under one area light (penumbrae).

    Thin plates and a sphere hang above the floor of a closed room; the
    shadows' penumbrae widen with the gap, which the display must resolve.

    Parameters
    ----------
    width, height : int
        Image size of the camera, in pixels.

    Returns
    -------
    Scene
        A new scene with its camera set.
    """
    s = Scene(
        Camera(
            eye=(0.0, 2.2, 2.4),
            target=(0.0, 0.2, 0.0),
            up=(0, 1, 0),
            fov=50.0,
            width=width,
            height=height,
        )
    )
    room, _ = _room((5.0, 3.0, 5.0), 0.75)
    s.add(room, Material(albedo=0.75), name="room")
    s.add(
        _ceiling_light(0.0, 0.0, 0.8, 0.8, 2.99), Material(albedo=0.0, emission=25.0), name="light"
    )
    plates = [
        _box([0.5, 0.02, 0.5], [x, y, z])
        for x, y, z in ((-1.2, 0.15, 0.3), (0.0, 0.6, 0.3), (1.2, 1.2, 0.3))
    ]
    s.add(trimesh.util.concatenate(plates), Material(albedo=(0.8, 0.3, 0.3)), name="plates")
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.3)
    ball.apply_translation([0.0, 0.9, -1.0])
    s.add(ball, Material(albedo=(0.3, 0.3, 0.8)), name="ball")
    return s


def geometric(width: int = 512, height: int = 512) -> Scene:
    """Varied geometry: curved, thin, concave and small features in one room.

    A torus, a cylinder, a cone, a thin slab leaning on a wall, a concave
    open box and a cluster of small cubes, under a ceiling light.

    Parameters
    ----------
    width, height : int
        Image size of the camera, in pixels.

    Returns
    -------
    Scene
        A new scene with its camera set.
    """
    s = Scene(
        Camera(
            eye=(0.0, 1.8, 2.8),
            target=(0.0, 0.5, 0.0),
            up=(0, 1, 0),
            fov=55.0,
            width=width,
            height=height,
        )
    )
    room, _ = _room((5.0, 3.0, 6.0), 0.7)
    s.add(room, Material(albedo=0.7), name="room")
    s.add(
        _ceiling_light(0.0, 0.0, 1.0, 1.0, 2.99), Material(albedo=0.0, emission=18.0), name="light"
    )
    torus = trimesh.creation.torus(
        major_radius=0.45, minor_radius=0.15, major_sections=48, minor_sections=24
    )
    torus.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, [1, 0, 0]))
    torus.apply_translation([-1.3, 0.15, -0.5])
    s.add(torus, Material(albedo=(0.8, 0.6, 0.2)), name="torus")
    cyl = trimesh.creation.cylinder(radius=0.3, height=1.2, sections=48)
    cyl.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, [1, 0, 0]))
    cyl.apply_translation([0.0, 0.6, -1.5])
    s.add(cyl, Material(albedo=(0.3, 0.7, 0.4)), name="cylinder")
    cone = trimesh.creation.cone(radius=0.35, height=0.9, sections=48)
    cone.apply_transform(trimesh.transformations.rotation_matrix(-math.pi / 2, [1, 0, 0]))
    cone.apply_translation([1.2, 0.0, -0.6])
    s.add(cone, Material(albedo=(0.3, 0.4, 0.8)), name="cone")
    slab = _box([1.2, 1.6, 0.04], [1.6, 0.82, -2.6], 0)
    slab.apply_transform(
        trimesh.transformations.rotation_matrix(0.25, [1, 0, 0], point=[1.6, 0.0, -2.6])
    )
    s.add(slab, Material(albedo=0.85), name="thin_slab")
    cup = [
        _box([0.8, 0.04, 0.8], [-0.4, 0.02, 0.8]),
        _box([0.04, 0.5, 0.8], [-0.8, 0.25, 0.8]),
        _box([0.04, 0.5, 0.8], [0.0, 0.25, 0.8]),
        _box([0.8, 0.5, 0.04], [-0.4, 0.25, 0.4]),
    ]
    s.add(trimesh.util.concatenate(cup), Material(albedo=0.6), name="open_box")
    rng = np.random.default_rng(7)
    cubes = [
        _box(
            [0.08] * 3,
            [0.7 + 0.2 * (k % 4), 0.04 + 0.08 * (k // 8), 0.7 + 0.2 * (k // 4 % 2)],
            float(rng.uniform(0, 90)),
        )
        for k in range(16)
    ]
    s.add(trimesh.util.concatenate(cubes), Material(albedo=(0.9, 0.9, 0.5)), name="small_cubes")
    return s


def sponza_atrium(
    width: int = 512, height: int = 512, columns_per_side: int = 7, sections: int = 24
) -> Scene:
    """A Sponza-like atrium: a two-storey arcade round an open courtyard.

    Columns (cylinders) carry arches (segmented half-rings) on two storeys
    around a 10 × 4 courtyard; a large emitting "sky" quad covers the opening.
    Built from primitives, several thousand triangles.

    Parameters
    ----------
    width, height : int
        Image size of the camera, in pixels.
    columns_per_side : int
        Columns along each long side of the courtyard.
    sections : int
        Segments of each arch's half-ring.

    Returns
    -------
    Scene
        A new scene with its camera set.
    """
    _validate.integer(columns_per_side, "columns_per_side", low=2, high=40)
    _validate.integer(sections, "sections", low=6, high=128)
    L, W, storey = 14.0, 6.0, 3.0
    s = Scene(
        Camera(
            eye=(-6.2, 1.6, 0.0),
            target=(3.0, 2.8, 0.0),
            up=(0, 1, 0),
            fov=65.0,
            width=width,
            height=height,
        )
    )
    hall, _ = _room((L, 2 * storey, W), 0.7, open_top=True)
    s.add(hall, Material(albedo=(0.75, 0.7, 0.62)), name="hall")
    parts = []
    for level in range(2):
        y0 = level * storey
        for side in (-1, 1):
            z = side * (W / 2 - 1.0)
            xs = np.linspace(-L / 2 + 1.5, L / 2 - 1.5, columns_per_side)
            for x in xs:
                col = trimesh.creation.cylinder(
                    radius=0.18, height=storey * 0.62, sections=sections
                )
                col.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, [1, 0, 0]))
                col.apply_translation([x, y0 + storey * 0.31, z])
                parts.append(col)
            span = xs[1] - xs[0]
            for a, b in itertools.pairwise(xs):  # an arch of 8 voussoir blocks
                r = span / 2
                for k in range(8):
                    t0, t1 = math.pi * k / 8, math.pi * (k + 1) / 8
                    tm = (t0 + t1) / 2
                    cx = (a + b) / 2 - r * math.cos(tm)
                    cy = y0 + storey * 0.62 + r * math.sin(tm) * 0.5
                    blk = _box([r * (t1 - t0) * 1.05, 0.25, 0.3], [0, 0, 0])
                    blk.apply_transform(
                        trimesh.transformations.rotation_matrix(math.pi / 2 - tm, [0, 0, 1])
                    )
                    blk.apply_translation([cx, cy, z])
                    parts.append(blk)
            # the storey's floor slab / balcony over the arcade
            if level == 0:
                parts.append(_box([L - 0.02, 0.2, 1.0], [0.0, storey, side * (W / 2 - 0.5)]))
    s.add(trimesh.util.concatenate(parts), Material(albedo=(0.7, 0.65, 0.55)), name="arcades")
    sky = _ceiling_light(0.0, 0.0, L, W, 2 * storey)
    s.add(sky, Material(albedo=0.0, emission=(2.2, 2.4, 3.0)), name="sky")
    return s


def _quad(corners, toward) -> trimesh.Trimesh:
    """A planar quad (4, 3) wound so that its normal points toward a point."""
    c = np.asarray(corners, dtype=np.float64)
    if np.dot(np.cross(c[1] - c[0], c[2] - c[0]), np.asarray(toward) - c.mean(axis=0)) < 0:
        c = c[::-1]
    return trimesh.Trimesh(c, [[0, 1, 2], [0, 2, 3]], process=False)


def _slab(lo, hi) -> trimesh.Trimesh:
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    return _box(hi - lo, (lo + hi) / 2)


def window_room(
    width: int = 256, height: int = 256, bar: float = 0.02, window_radiance: float | None = 6.0
) -> Scene:
    """A 4 x 2.6 x 5 m room lit only through a barred window, with a thin-legged table.

    The window (1.6 x 1.2 m, in the wall z = 0) is a diffuse emitter 0.3 m
    outside the opening, seen through a reveal (the wall's thickness) and
    four sash bars ``bar`` metres wide, thinner than a voxel at the default
    resolution (5 m / 64 = 0.078 m). Every surface is diffuse (walls 0.75,
    reveal 0.5). It shows what sub-voxel occluders in front of an aperture
    do to direct light carried along discrete lines (``docs/design.md`` §5).
    ``window_radiance=None`` leaves the opening open, for a sun or sky
    outside (:func:`sun_room`).

    Parameters
    ----------
    width, height : int
        Image size of the camera, in pixels.
    bar : float
        Width of the window's four sash bars (metres).
    window_radiance : float or None
        Radiance of the emitter outside the window; None leaves the opening
        open (no emitter).

    Returns
    -------
    Scene
        A new scene with its camera set.
    """
    W, H, D = 4.0, 2.6, 5.0
    x0, x1, y0, y1, t = 1.2, 2.8, 0.9, 2.1, -0.3
    inside = (W / 2, H / 2, D / 2)
    white, grey = Material(albedo=0.75), Material(albedo=0.5)
    cam = Camera(
        eye=(W / 2, 1.3, D - 0.1), target=(W / 2, 1.0, 0.0), fov=70, width=width, height=height
    )
    scene = Scene(camera=cam)
    walls = {
        "floor": [(0, 0, 0), (W, 0, 0), (W, 0, D), (0, 0, D)],
        "ceiling": [(0, H, 0), (W, H, 0), (W, H, D), (0, H, D)],
        "left": [(0, 0, 0), (0, H, 0), (0, H, D), (0, 0, D)],
        "right": [(W, 0, 0), (W, H, 0), (W, H, D), (W, 0, D)],
        "front": [(0, 0, D), (W, 0, D), (W, H, D), (0, H, D)],
        "wall_below": [(0, 0, 0), (W, 0, 0), (W, y0, 0), (0, y0, 0)],
        "wall_above": [(0, y1, 0), (W, y1, 0), (W, H, 0), (0, H, 0)],
        "wall_left": [(0, y0, 0), (x0, y0, 0), (x0, y1, 0), (0, y1, 0)],
        "wall_right": [(x1, y0, 0), (W, y0, 0), (W, y1, 0), (x1, y1, 0)],
    }
    for name, q in walls.items():
        scene.add(_quad(q, inside), white, name=name)
    middle = ((x0 + x1) / 2, (y0 + y1) / 2, t / 2)
    reveal = [
        [(x0, y0, t), (x1, y0, t), (x1, y0, 0), (x0, y0, 0)],
        [(x0, y1, t), (x1, y1, t), (x1, y1, 0), (x0, y1, 0)],
        [(x0, y0, t), (x0, y1, t), (x0, y1, 0), (x0, y0, 0)],
        [(x1, y0, t), (x1, y1, t), (x1, y1, 0), (x1, y0, 0)],
    ]
    scene.add(trimesh.util.concatenate([_quad(q, middle) for q in reveal]), grey, name="reveal")
    if window_radiance is not None:
        window = _quad([(x0, y0, t), (x1, y0, t), (x1, y1, t), (x0, y1, t)], inside)
        scene.add(window, Material(albedo=0.0, emission=window_radiance), name="window")
    z0, z1, xm, ym = -0.08, -0.04, (x0 + x1) / 2, (y0 + y1) / 2
    bars = [
        _slab((xm - bar / 2, y0, z0), (xm + bar / 2, y1, z1)),
        _slab((x0, ym - bar / 2, z0), (x1, ym + bar / 2, z1)),
    ]
    for x in (x0 + (x1 - x0) / 4, x0 + 3 * (x1 - x0) / 4):
        bars.append(_slab((x - bar / 2, y0, z0), (x + bar / 2, y1, z1)))
    scene.add(trimesh.util.concatenate(bars), white, name="bars")
    scene.add(_slab((1.3, 0.72, 1.6), (2.7, 0.76, 2.6)), white, name="table_top")
    legs = [
        _slab((x, 0, z), (x + 0.04, 0.72, z + 0.04)) for x in (1.35, 2.61) for z in (1.65, 2.51)
    ]
    scene.add(trimesh.util.concatenate(legs), white, name="table_legs")
    return scene


def point_lit_box(width: int = 256, height: int = 256) -> Scene:
    """The Cornell box lit by a point light instead of its area light.

    The point light hangs 15 cm under the centre of the ceiling with the
    on-axis intensity of the area light it replaces (its radiance times its
    area, W/sr): the same light straight down, more to the sides.

    Parameters
    ----------
    width, height : int
        Image size of the camera, in pixels.

    Returns
    -------
    Scene
        A new scene with its camera set.
    """
    s = cornell_box(width, height, area_light=False)
    area = 0.130 * 0.105
    s.add_light(PointLight((0.278, 0.40, 0.2795), tuple(area * c for c in CORNELL_LIGHT)))
    return s


def sun_room(width: int = 256, height: int = 256, irradiance: float = 20.0) -> Scene:
    """The room of :func:`window_room` with its window open and a sun shining in.

    The sun (:class:`voxgi.DirectionalLight`, ``irradiance`` W/m² on a
    surface facing it) comes in through the window at about 30° below the
    horizon, so a patch of sunlight, striped by the sash bars' shadows, falls
    on the floor and the table; the rest of the room is lit by its bounces.

    Parameters
    ----------
    width, height : int
        Image size of the camera, in pixels.
    irradiance : float
        Irradiance of the sun on a surface facing it (W/m²).

    Returns
    -------
    Scene
        A new scene with its camera set.
    """
    s = window_room(width, height, window_radiance=None)
    s.add_light(DirectionalLight((0.25, -0.55, 1.0), irradiance))
    return s


def sky_objects(width: int = 256, height: int = 256, sky: float = 1.0) -> Scene:
    """A box and a sphere on a square ground plane under a uniform white sky.

    Ground 8 x 8 m (albedo 0.5), a 1 m box (0.7, reddish) and a sphere of
    radius 0.6 m (0.7, bluish), lit only by a constant environment of
    radiance ``sky``; the camera sees the horizon, so some pixels see the sky.

    Parameters
    ----------
    width, height : int
        Image size of the camera, in pixels.
    sky : float
        Radiance of the constant environment (W/(m² sr)).

    Returns
    -------
    Scene
        A new scene with its camera set.
    """
    cam = Camera(eye=(0.0, 1.6, 4.5), target=(0.0, 0.4, 0.0), fov=45, width=width, height=height)
    s = Scene(camera=cam)
    ground = _quad([(-4, 0, -4), (4, 0, -4), (4, 0, 4), (-4, 0, 4)], (0.0, 1.0, 0.0))
    s.add(ground, Material(albedo=0.5), name="ground")
    box = _box((1.0, 1.0, 1.0), (-0.8, 0.5, 0.0), rotate_y_deg=25.0)
    s.add(box, Material(albedo=(0.7, 0.35, 0.3)), name="box")
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.6)
    ball.apply_translation((0.9, 0.6, 0.3))
    s.add(ball, Material(albedo=(0.3, 0.4, 0.7)), name="sphere")
    s.environment = Environment(sky)
    return s


def door_room(width: int = 256, height: int = 256, gap: float = 0.05) -> Scene:
    """Two 4 x 2.6 x 4 m rooms joined by a door left ajar; the lamp is in the far one.

    A 1 x 2 m doorway in the 10 cm wall between the rooms holds a 4 cm door
    swung open by ``gap`` metres at its edge, so the lit room's light reaches
    the camera's room only through a slit narrower than a voxel at the default
    resolution (8 m / 64 = 0.125 m), mostly after bounces. The lamp is a 2 x 2
    m ceiling panel; every surface is diffuse (0.7). It shows what gaps
    thinner than a voxel do to light carried along discrete lines
    (``docs/design.md`` §10).
    """
    W, H, D, t = 4.0, 2.6, 4.0, 0.1  # each room W x H x D; the wall spans z in [D, D + t]
    Z = 2 * D + t
    white = Material(albedo=0.7)
    cam = Camera(eye=(0.4, 1.5, 0.3), target=(2.6, 1.0, D), fov=75, width=width, height=height)
    scene = Scene(camera=cam)
    mid = (W / 2, H / 2, Z / 2)
    shell = {
        "floor": [(0, 0, 0), (W, 0, 0), (W, 0, Z), (0, 0, Z)],
        "ceiling": [(0, H, 0), (W, H, 0), (W, H, Z), (0, H, Z)],
        "left": [(0, 0, 0), (0, H, 0), (0, H, Z), (0, 0, Z)],
        "right": [(W, 0, 0), (W, H, 0), (W, H, Z), (W, 0, Z)],
        "near": [(0, 0, 0), (W, 0, 0), (W, H, 0), (0, H, 0)],
        "far": [(0, 0, Z), (W, 0, Z), (W, H, Z), (0, H, Z)],
    }
    for name, q in shell.items():
        scene.add(_quad(q, mid), white, name=name)
    x0, x1, dh = 2.0, 3.0, 2.0  # the doorway
    wall = [
        _slab((0, 0, D), (x0, H, D + t)),
        _slab((x1, 0, D), (W, H, D + t)),
        _slab((x0, dh, D), (x1, H, D + t)),
    ]
    scene.add(trimesh.util.concatenate(wall), white, name="wall")
    # The door, hinged at x1 on the lit side, its free edge `gap` from the wall.
    angle = math.asin(min(1.0, gap / (x1 - x0)))
    door = _box((x1 - x0, dh - 0.01, 0.04), ((x1 - x0) / 2, dh / 2, 0.02))
    rot = trimesh.transformations.rotation_matrix(-angle, (0, 1, 0))
    door.apply_transform(rot).apply_translation((x0 - 0.0, 0.0, D + t))
    scene.add(door, white, name="door")
    lamp = _quad(
        [
            (1.0, H - 0.01, D + t + 1.0),
            (3.0, H - 0.01, D + t + 1.0),
            (3.0, H - 0.01, D + t + 3.0),
            (1.0, H - 0.01, D + t + 3.0),
        ],
        (2.0, 0.0, D + 2),
    )
    scene.add(lamp, Material(albedo=0.0, emission=150.0), name="lamp")
    return scene


_REGISTRY = {
    "cornell-box": cornell_box,
    "furnace-sphere": furnace_sphere,
    "furnace-box": furnace_box,
    "cap-sphere": cap_sphere,
    "bunny-room": bunny_room,
    "labyrinth": labyrinth,
    "emission": emission,
    "shadow": shadow,
    "geometric": geometric,
    "sponza-atrium": sponza_atrium,
    "window-room": window_room,
    "point-lit-box": point_lit_box,
    "sun-room": sun_room,
    "sky-objects": sky_objects,
    "door-room": door_room,
}


def names() -> list[str]:
    """Names of the built-in scenes, as the command line spells them."""
    return sorted(_REGISTRY)


def get(name: str, **kwargs) -> Scene:
    """A built-in scene by its command-line name (``cornell-box``, ...).

    Parameters
    ----------
    name : str
        A name of :func:`names` (``cornell-box``; underscores are accepted).
    **kwargs
        Passed to the scene's function (``width=``, ``height=``, ...).

    Returns
    -------
    Scene
        A new scene with its camera set.

    Raises
    ------
    ValueError
        If ``name`` is not a built-in scene's name.
    """
    key = name.replace("_", "-").lower()
    if key not in _REGISTRY:
        raise ValueError(f"unknown built-in scene {name!r}; known: {', '.join(names())}")
    return _REGISTRY[key](**kwargs)
