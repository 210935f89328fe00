"""Scenes lit by a point light, the sun or a sky instead of emitting surfaces."""

from __future__ import annotations

import trimesh

from ..camera import Camera
from ..lights import DirectionalLight, Environment, PointLight
from ..materials import Material
from ..scene import Scene
from ._shapes import _box, _quad
from .cornell import CORNELL_LIGHT, cornell_box
from .interiors import window_room


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
