"""A box split into two rooms by a wall thinner than a voxel, off the voxel grid."""

from __future__ import annotations

import numpy as np
import trimesh

from ..materials import Material
from ..scene import Scene
from .furnaces import furnace_box

__all__ = ["SPLIT_AT", "SPLIT_SLAB", "split_box", "split_normal"]

#: Where the wall crosses the box's x axis, as a share of the box: no voxel
#: face of a power-of-two or round resolution lines up with it.
SPLIT_AT = 0.4137
#: Thickness of the slab walls: a third of a voxel at resolution 32.
SPLIT_SLAB = 0.01


def split_normal() -> np.ndarray:
    """(3,) float64 unit normal of the wall, turned 3° and 2° off the x axis,
    so that the wall lies along no grid plane."""
    a, b = np.radians(3.0), np.radians(2.0)
    return np.array([np.cos(a) * np.cos(b), np.sin(b), np.sin(a) * np.cos(b)])


def _wall_quad(offset: float, toward: np.ndarray) -> trimesh.Trimesh:
    """The plane n·x = d + offset inside the box [-0.5, 0.5]³, wound toward ``toward``."""
    n, d = split_normal(), -0.5 + SPLIT_AT + offset
    yz = ((-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5))
    corners = np.array([((d - n[1] * y - n[2] * z) / n[0], y, z) for y, z in yz])
    faces = [[0, 1, 2], [0, 2, 3]]
    if np.dot(np.cross(corners[1] - corners[0], corners[2] - corners[0]), toward) < 0:
        faces = [[0, 2, 1], [0, 3, 2]]
    return trimesh.Trimesh(corners, faces, process=False)


def split_box(
    wall: str = "sheet", furnace: bool = False, width: int = 64, height: int = 64
) -> Scene:
    """The unit box split into two rooms by a wall off the voxel grid.

    Light of one room can reach the other by no path, so every record of the
    dark room must stay dark; as a furnace every record's radiance is
    ``Le / (1 - rho)`` exactly. Both hold whatever the wall's thickness
    against the voxels (``docs/design.md`` §2 and §6).

    Parameters
    ----------
    wall : {"sheet", "slab", "two-sided slab"}
        A two-sided sheet of zero thickness, or two one-sided faces
        :data:`SPLIT_SLAB` apart, or the same faces two-sided.
    furnace : bool
        Every surface emits 1 with albedo 0.8 and a small box stands in the
        lit room; otherwise albedo 0.7 and a lamp (radiance 10) under the lit
        room's ceiling.
    width, height : int
        Image size of the camera, in pixels.

    Returns
    -------
    Scene
        The box, the wall (object ``"wall"``) and the lamp or small box.
    """
    if wall not in ("sheet", "slab", "two-sided slab"):
        raise ValueError(f"wall: expected 'sheet', 'slab' or 'two-sided slab', got {wall!r}")
    rho, le = (0.8, 1.0) if furnace else (0.7, 0.0)
    scene = furnace_box(albedo=rho, emission=le, width=width, height=height)
    mat = Material(albedo=rho, emission=le)
    n = split_normal()
    if wall == "sheet":
        scene.add(_wall_quad(0.0, n), mat, name="wall", two_sided=True)
    else:
        halves = [_wall_quad(-SPLIT_SLAB / 2, -n), _wall_quad(SPLIT_SLAB / 2, n)]
        scene.add(trimesh.util.concatenate(halves), mat, name="wall", two_sided=wall != "slab")
    if furnace:
        small = trimesh.creation.box(extents=[0.15, 0.15, 0.15])
        small.apply_translation([0.2, -0.3, 0.1])
        scene.add(small, mat, name="small_box")
    else:
        y = 0.45
        lamp = np.array([(0.1, y, -0.15), (0.4, y, -0.15), (0.4, y, 0.15), (0.1, y, 0.15)])
        scene.add(
            trimesh.Trimesh(lamp, [[0, 1, 2], [0, 2, 3]], process=False),
            Material(albedo=0.0, emission=10.0),
            name="lamp",
        )
    return scene
