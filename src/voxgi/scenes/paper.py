"""The paper's test scenes, rebuilt procedurally, and the Stanford bunny.

Piwowar & Malgouyres test on Labyrinth, Emission, Shadow, Geometric (after
Smits & Jensen's "Global illumination test scenes", 2000), the bunny and
Sponza, none of whose geometry was published. These are look-alikes of the
same kind and similar record counts at resolution ~128-256: a comparison
with the paper's tables is by kind, not exact.
"""

from __future__ import annotations

import itertools
import math
from importlib import resources

import numpy as np
import trimesh

from .. import _validate
from ..camera import Camera
from ..materials import Material
from ..scene import Scene
from ._shapes import _box, _ceiling_light, _inward, _room


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


def _maze(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A perfect ``n`` x ``n`` maze by randomized depth-first search over cells.

    Returns ``east`` and ``south`` (n, n) bool: cell (i, j) has a wall on its
    +x side, its +z side.
    """
    east = np.ones((n, n), bool)
    south = np.ones((n, n), bool)
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
    return east, south


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
    east, south = _maze(n, rng)
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
