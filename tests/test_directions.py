"""Discrete direction sets (voxgi.directions): docs/design.md §3."""

from __future__ import annotations

import numpy as np
import pytest

from voxgi import _core
from voxgi.directions import direction_set, sphere


@pytest.mark.parametrize(("radius", "count"), [(8, 762), (16, 3338), (22, 5982), (35, 15194)])
def test_counts(radius, count):
    # the counts of docs/design.md §3 (integer v with round(|v|) = R)
    v = sphere(radius)
    assert v.shape == (count, 3)
    n = np.linalg.norm(v, axis=1)
    assert np.all(np.round(n) == radius)
    assert len(np.unique(v, axis=0)) == count


@pytest.mark.parametrize("radius", [1, 2, 8, 22])
def test_families_and_solid_angles(radius):
    ds = direction_set(radius)
    v = ds.vectors
    # symmetric: -v is in the set for every v
    assert set(map(tuple, (-v).tolist())) == set(map(tuple, v.tolist()))
    assert len(ds.families) * 2 == len(v)
    m = np.argmax(np.abs(ds.families), axis=1)
    assert np.all(ds.families[np.arange(len(m)), m] > 0)
    # Voronoi cells tile the sphere: 4π to rounding
    assert ds.solid_angle.sum() == pytest.approx(4 * np.pi, rel=1e-12)
    assert ds.weights.sum() * 2 * np.pi == pytest.approx(4 * np.pi, rel=1e-12)
    assert np.all(ds.solid_angle > 0)


@pytest.mark.parametrize("radius", [8, 22])
def test_no_two_vectors_share_a_direction(radius):
    # the argument of the module docstring: non-primitive vectors keep their own cell
    ds = direction_set(radius)
    u = ds.vectors / np.linalg.norm(ds.vectors, axis=1, keepdims=True)
    assert len(np.unique(np.round(u, 9), axis=0)) == len(u)
    g = np.gcd.reduce(np.abs(ds.vectors), axis=1)
    assert ds.non_primitive == np.count_nonzero(g > 1) > 0


@pytest.mark.parametrize(("radius", "spread"), [(8, 4e-3), (22, 6e-4)])
def test_raw_hemisphere_sums(rng, radius, spread):
    # S(n) = Σ_{n·σ>0} cos ΔΩ/π is near 1 over these normals (axis normals
    # are the worst: their equator holds many directions)
    ds = direction_set(radius)
    n = rng.normal(size=(4000, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n = np.concatenate([n, np.eye(3), -np.eye(3)])
    S = ds.raw_sums(n)
    assert np.all(np.abs(S - 1) < spread)
    # the kernel's normalisation agrees with numpy's, also where records
    # share a normal (the kernel sums once per distinct normal)
    n = np.concatenate([n, n[::7], np.eye(3)])
    s = _core.LineSystem(
        np.zeros((len(n), 3), np.int32), n.astype(np.float32), np.zeros((len(n), 3), np.float32)
    )
    Sk = s.normalisation(ds.families, ds.weights)
    assert np.allclose(Sk, ds.raw_sums(n.astype(np.float32)), rtol=1e-6, atol=0)


def test_bad_radius():
    with pytest.raises(ValueError, match="radius"):
        direction_set(0)
    with pytest.raises(TypeError, match="radius"):
        direction_set(2.5)
    with pytest.raises(TypeError, match="radius"):
        sphere("8")
