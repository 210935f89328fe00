"""voxgi.traced: records' radiosity gathered by rays against the exact triangles."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

import voxgi
from voxgi import Material
from voxgi.traced import TracedGather, traced_irradiance


def _corner_factor(a: float, b: float, h: float) -> float:
    """Form factor from a point to the rectangle [0, a] x [0, b] parallel to
    it at height h, with the point under the rectangle's corner (odd in a
    and in b, so rectangles elsewhere follow by superposition)."""
    A, B = a / h, b / h
    sa, sb = math.sqrt(1 + A * A), math.sqrt(1 + B * B)
    return (A / sa * math.atan(B / sa) + B / sb * math.atan(A / sb)) / (2 * math.pi)


def _parallel_squares(h: float = 0.5, top_albedo: float = 0.5):
    """A unit floor square facing up and a unit ceiling square h above it facing down."""
    floor = np.array([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], float)
    scene = voxgi.Scene()
    scene.add(trimesh.Trimesh(floor, [[0, 1, 2], [0, 2, 3]], process=False), Material(0.5), "floor")
    top = floor + np.array([0.0, 0.0, h])
    scene.add(
        trimesh.Trimesh(top, [[0, 2, 1], [0, 3, 2]], process=False), Material(top_albedo), "top"
    )
    return scene


@pytest.mark.parametrize("native", [True, False])
def test_a_point_under_a_square_gathers_its_form_factor(native):
    # Radiosity 1 on the top square, 0 on the floor: a floor record gathers
    # the point-to-rectangle form factor at its surface point. Rays drawn
    # uniformly over the hemisphere instead of by cos θ would give the solid
    # angle's share, 0.37 against 0.55 under the middle.
    h = 0.5
    scene = _parallel_squares(h)
    vox = voxgi.voxelize(scene, 8, progress=False)
    values = np.where((vox.object_id == 1)[:, None], 1.0, 0.0) * np.ones((1, 3))
    floor = np.flatnonzero((vox.object_id == 0) & ~vox.back & (vox.area > 0))
    with TracedGather(scene, vox, threads=2, native=native) as g:
        H = g(values, 4096, seed=3)
        assert g.rays == 4096 * np.count_nonzero((vox.area > 0) & (vox.albedo[:, 0] > 0))
    for r in floor:
        x, y = vox.centroid[r, :2]
        F = (
            _corner_factor(1 - x, 1 - y, h)
            - _corner_factor(-x, 1 - y, h)
            - _corner_factor(1 - x, -y, h)
            + _corner_factor(-x, -y, h)
        )
        sigma = math.sqrt(F * (1 - F) / 4096)
        assert abs(H[r, 0] - F) < 4 * sigma + 1e-6, (r, H[r, 0], F)
    np.testing.assert_array_equal(H[:, 0], H[:, 1])


def test_the_gather_does_not_depend_on_the_thread_count():
    scene = _parallel_squares()
    vox = voxgi.voxelize(scene, 8, progress=False)
    values = np.random.default_rng(0).random((len(vox), 3))
    one, _ = traced_irradiance(scene, vox, values, samples=32, threads=1)
    two, st = traced_irradiance(scene, vox, values, samples=32, threads=2)
    np.testing.assert_array_equal(one, two)
    assert st["rays"] > 0


def test_records_that_reflect_nothing_gather_nothing():
    scene = _parallel_squares(top_albedo=0.0)
    vox = voxgi.voxelize(scene, 8, progress=False)
    H, _ = traced_irradiance(scene, vox, np.ones((len(vox), 3)), samples=8)
    assert np.all(H[vox.object_id == 1] == 0)
    assert np.all(H[(vox.object_id == 0) & ~vox.back & (vox.area > 0)] > 0)


def test_bad_values_and_scenes_are_refused():
    scene = _parallel_squares()
    vox = voxgi.voxelize(scene, 8, progress=False)
    with pytest.raises(ValueError, match=r"values: expected shape"):
        traced_irradiance(scene, vox, np.ones((3, 3)))
    with pytest.raises(ValueError, match="samples"):
        traced_irradiance(scene, vox, np.ones((len(vox), 3)), samples=0)
    with pytest.raises(ValueError, match="another scene"):
        traced_irradiance(voxgi.scenes.furnace_box(), vox, np.ones((len(vox), 3)))
    with pytest.raises(TypeError, match="scene"):
        traced_irradiance("room.obj", vox, np.ones((len(vox), 3)))
