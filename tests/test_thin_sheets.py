"""No light through a wall thinner than a voxel.

A closed box is split into two rooms by a wall that lies off the voxel grid
(at 0.4137 of the box, turned 3° and 2° off its axes, so that no voxel face
lines up with it), either a zero-thickness two-sided sheet or a slab a third
of a voxel thick whose two faces share voxels. Light of one room must reach
the other by no path: not the direct light's shadow rays, not a traced
ray's hit read from a record of the other side, not a record that stands
for both faces of the slab (``docs/design.md`` §2 and §6).
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import voxgi
from voxgi.direct import direct_irradiance
from voxgi.traced import TracedGather

RES = 32
#: where the wall crosses the box's x axis, as a share of the box
AT = 0.4137
#: slab thickness: a third of a voxel at RES
SLAB = 0.01


def _wall_normal() -> np.ndarray:
    a, b = np.radians(3.0), np.radians(2.0)
    return np.array([np.cos(a) * np.cos(b), np.sin(b), np.sin(a) * np.cos(b)])


def _wall_quad(offset: float, toward: np.ndarray) -> trimesh.Trimesh:
    """The plane n·x = d + offset inside the box [-0.5, 0.5]³, wound toward ``toward``."""
    n, d = _wall_normal(), -0.5 + AT + offset
    corners = np.array(
        [
            ((d - n[1] * y - n[2] * z) / n[0], y, z)
            for y, z in ((-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5))
        ]
    )
    faces = [[0, 1, 2], [0, 2, 3]]
    if np.dot(np.cross(corners[1] - corners[0], corners[2] - corners[0]), toward) < 0:
        faces = [[0, 2, 1], [0, 3, 2]]
    return trimesh.Trimesh(corners, faces, process=False)


def split_box(wall: str, furnace: bool = False) -> voxgi.Scene:
    """The unit box split by ``wall`` ("sheet": zero thickness, two-sided;
    "slab": two one-sided faces SLAB apart; "two-sided slab": the same
    faces two-sided). ``furnace``: every surface emits 1 with albedo 0.8
    and a small box stands in the lit room; otherwise albedo 0.7 and a lamp
    under the lit room's ceiling."""
    rho, le = (0.8, 1.0) if furnace else (0.7, 0.0)
    scene = voxgi.scenes.furnace_box(albedo=rho, emission=le)
    mat = voxgi.Material(albedo=rho, emission=le)
    n = _wall_normal()
    if wall == "sheet":
        scene.add(_wall_quad(0.0, n), mat, name="wall", two_sided=True)
    else:
        faces = trimesh.util.concatenate([_wall_quad(-SLAB / 2, -n), _wall_quad(SLAB / 2, n)])
        scene.add(faces, mat, name="wall", two_sided=wall == "two-sided slab")
    if furnace:
        small = trimesh.creation.box(extents=[0.15, 0.15, 0.15])
        small.apply_translation([0.2, -0.3, 0.1])
        scene.add(small, mat, name="small_box")
    else:
        y = 0.45
        lamp = np.array([(0.1, y, -0.15), (0.4, y, -0.15), (0.4, y, 0.15), (0.1, y, 0.15)])
        scene.add(
            trimesh.Trimesh(lamp, [[0, 1, 2], [0, 2, 3]], process=False),
            voxgi.Material(albedo=0.0, emission=10.0),
            name="lamp",
        )
    return scene


def rooms(vox: voxgi.VoxelSet, wall: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(dark, lit, inside): the records with area in front of the wall's
    two sides, and those between a slab's faces, by a point a thousandth of
    a voxel in front of each record's centroid."""
    half = 0.0 if wall == "sheet" else SLAB / 2
    p = np.asarray(vox.centroid, np.float64) + 1e-3 * vox.pitch * vox.normal
    s = p @ _wall_normal() - (-0.5 + AT)
    live = np.asarray(vox.area) > 0
    return live & (s < -half), live & (s > half), live & (np.abs(s) <= half)


@pytest.fixture(scope="module", params=["sheet", "slab", "two-sided slab"])
def split(request):
    scene = split_box(request.param)
    return request.param, scene, voxgi.voxelize(scene, RES, progress=False)


def test_direct_light_reaches_nothing_behind_the_wall(split):
    wall, scene, vox = split
    dark, lit, inside = rooms(vox, wall)
    E, _ = direct_irradiance(scene, vox, samples=16, receivers="all")
    assert E[lit].max() > 0
    assert np.count_nonzero(E[dark | inside]) == 0


def test_a_traced_pass_reads_nothing_across_the_wall(split):
    # One pass of the traced gather with light on the lit room's records
    # alone: every ray that reaches a record of the dark room, or of a
    # slab's inside, read a record of its own side.
    wall, scene, vox = split
    dark, lit, inside = rooms(vox, wall)
    values = np.where(lit[:, None], 1.0, 0.0) * np.ones((1, 3))
    with TracedGather(scene, vox, threads=2) as trace:
        H = trace(values, 64, seed=1)
    assert H[lit].max() > 0
    assert np.count_nonzero(H[dark | inside]) == 0


def test_the_solve_keeps_the_dark_room_dark():
    # The solve's defaults (the render's): the exact direct light and the
    # traced passes leave in the dark room only what the lines' first guess
    # put there, shrunk pass by pass.
    vox = voxgi.voxelize(split_box("sheet"), RES, progress=False)
    dark, lit, _ = rooms(vox, "sheet")
    sol = voxgi.solve(vox, progress=False)
    L = sol.radiance.mean(axis=1) * vox.area
    ratio = (L[dark].sum() / vox.area[dark].sum()) / (L[lit].sum() / vox.area[lit].sum())
    assert ratio <= 1e-3


@pytest.mark.parametrize("wall", ["slab", "two-sided slab"])
def test_the_furnace_reads_only_the_room_a_ray_is_in(wall):
    # A uniform furnace: every record outside the slab has radiosity
    # π Le / (1 - ρ), so one traced pass must bring every such record exactly
    # that, whatever the records between the slab's faces (set to 0) hold.
    scene = split_box(wall, furnace=True)
    vox = voxgi.voxelize(scene, RES, progress=False)
    dark, lit, _ = rooms(vox, wall)
    outside = (dark | lit) & ~vox.back
    exact = np.pi / (1 - 0.8)
    values = np.where(outside[:, None], exact, 0.0) * np.ones((1, 3))
    with TracedGather(scene, vox, threads=2) as trace:
        H = trace(values, 64, seed=1)
    np.testing.assert_allclose(H[outside & (vox.albedo[:, 0] > 0)], exact, rtol=1e-5)
