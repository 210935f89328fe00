"""Interiors whose light passes through openings thinner than a voxel."""

from __future__ import annotations

import math

import trimesh

from ..camera import Camera
from ..materials import Material
from ..scene import Scene
from ._shapes import _box, _quad, _slab


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


def door_room(width: int = 256, height: int = 256, gap: float = 0.05) -> Scene:
    """Two 4 x 2.6 x 4 m rooms joined by a door left ajar; the lamp is in the far one.

    A 1 x 2 m doorway in the 10 cm wall between the rooms holds a 4 cm door
    swung open by ``gap`` metres at its edge, so the lit room's light reaches
    the camera's room only through a slit narrower than a voxel at the default
    resolution (8 m / 64 = 0.125 m), mostly after bounces. The lamp is a 2 x 2
    m ceiling panel; every surface is diffuse (0.7). It shows what gaps
    thinner than a voxel do to light carried along discrete lines
    (``docs/design.md`` §10).

    Parameters
    ----------
    width, height : int
        Image size of the camera, in pixels.
    gap : float
        Opening between the door's free edge and the wall (metres).

    Returns
    -------
    Scene
        A new scene with its camera set.
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
