"""Furnaces: closed shapes seen from inside whose radiance has a closed form."""

from __future__ import annotations

import math

import numpy as np
import trimesh

from .. import _validate
from ..camera import Camera
from ..materials import Material
from ..scene import Scene
from ._shapes import _inward


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
