"""Discrete direction sets: the integer sphere of radius R (docs/design.md §3).

The directions of radius ``R`` are the integer vectors ``v`` with
``round(|v|) = R`` (R = 8: 762 of them; 16: 3338; 22: 5982; 35: 15194).
``v`` and ``-v`` partition space into the same naive discrete lines, so the
propagation walks one *family* per ± pair.

Solid angles: the area of the spherical Voronoi cell of each ``v/|v|``
(:class:`scipy.spatial.SphericalVoronoi`); they sum to ``4π``. The cells of
``v`` and ``-v`` are mirror images, so a family carries one weight,
``ΔΩ/π`` for each of its two directions (the mean of the two cells, equal to
rounding).

Non-primitive vectors (``v = k·p`` with ``k > 1``, e.g. ``(8, 0, 0)``): no two
vectors of one shell share a unit vector (``k|p|`` and ``(k+1)|p|`` differ by
``|p| >= 1``, so they cannot both round to R), so every vector keeps its own
Voronoi cell and solid angle; nothing is merged or dropped. Its naive lines are
exactly those of its primitive vector ``p`` (the key
``floor((a·y - b·x + ⌊a/2⌋)/a)`` is unchanged when ``(a, b)`` is scaled by
``k``, because ``a·y - b·x`` is an integer and ``⌊ka/2⌋/(ka)`` and
``⌊a/2⌋/a`` round it the same way), so the line walk is the primitive one's.
:attr:`DirectionSet.non_primitive` counts them.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from . import _validate

__all__ = ["DirectionSet", "direction_set", "sphere"]


def sphere(radius: int) -> np.ndarray:
    """All integer vectors ``v`` with ``round(|v|) == radius``.

    Parameters
    ----------
    radius : int
        Radius R >= 1 of the discrete sphere.

    Returns
    -------
    v : (D, 3) int32
        The vectors, in lexicographic order. ``|v|`` is never a half-integer
        (``sqrt(n) = k + 1/2`` has no integer solution), so rounding has no ties.
    """
    r = _validate.integer(radius, "radius", low=1, high=1024)
    lim = r + 1
    ax = np.arange(-lim, lim + 1)
    x, y, z = np.meshgrid(ax, ax, ax, indexing="ij")
    n2 = x * x + y * y + z * z
    # round(sqrt(n2)) == r  <=>  (r - 1/2)^2 <= n2 < (r + 1/2)^2, in integers:
    # 4 n2 >= (2r - 1)^2 and 4 n2 < (2r + 1)^2
    keep = (4 * n2 >= (2 * r - 1) ** 2) & (4 * n2 < (2 * r + 1) ** 2)
    return np.stack([x[keep], y[keep], z[keep]], axis=1).astype(np.int32)


@dataclass(frozen=True)
class DirectionSet:
    """The direction families of one radius.

    Attributes
    ----------
    radius : int
        Radius R of the discrete sphere.
    vectors : (D, 3) int32
        Every direction of the sphere.
    solid_angle : (D,) float64
        Spherical Voronoi cell area of each direction, steradians; sums to 4π.
    families : (F, 3) int32
        One vector per ± pair, ``F = D / 2``, main component (largest
        ``|v_i|``, lowest ``i`` on ties) positive: the form the kernels take.
    weights : (F,) float64
        ``ΔΩ / π`` of each of the family's two directions.
    non_primitive : int
        Number of vectors that are integer multiples of a shorter one.
    """

    radius: int
    vectors: np.ndarray
    solid_angle: np.ndarray
    families: np.ndarray
    weights: np.ndarray
    non_primitive: int

    def __len__(self) -> int:
        return int(self.vectors.shape[0])

    @property
    def unit_families(self) -> np.ndarray:
        """(F, 3) float64 unit vectors of the families."""
        f = self.families.astype(np.float64)
        return f / np.linalg.norm(f, axis=1, keepdims=True)

    def raw_sums(self, normals: np.ndarray) -> np.ndarray:
        """Raw hemisphere sums ``S(n) = Σ_{n·σ>0} (n·σ̂) ΔΩ/π`` (numpy reference).

        Parameters
        ----------
        normals : (M, 3) float
            Unit normals.

        Returns
        -------
        S : (M,) float64
            Near 1; dividing by it makes a record gather exactly a continuous
            hemisphere's worth (the furnace demands it).
        """
        n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        return np.abs(n @ self.unit_families.T) @ self.weights


@functools.lru_cache(maxsize=16)
def _cached(radius: int) -> DirectionSet:
    from scipy.spatial import SphericalVoronoi

    v = sphere(radius)
    u = v / np.linalg.norm(v, axis=1, keepdims=True)
    sv = SphericalVoronoi(u, radius=1.0, center=np.zeros(3))
    omega = sv.calculate_areas()
    # one family per ± pair: keep the rows whose main component is positive
    m = np.argmax(np.abs(v), axis=1)
    rep = v[np.arange(len(v)), m] > 0
    fam = v[rep]
    # solid angle of -v: find its row (the set is symmetric)
    index = {tuple(x): i for i, x in enumerate(v.tolist())}
    opp = np.array([index[(-a, -b, -c)] for a, b, c in fam.tolist()])
    w = 0.5 * (omega[rep] + omega[opp]) / np.pi
    g = np.gcd.reduce(np.abs(v), axis=1)
    for arr in (v, omega, fam, w):
        arr.setflags(write=False)
    return DirectionSet(
        radius=radius,
        vectors=v,
        solid_angle=omega,
        families=np.ascontiguousarray(fam, dtype=np.int32),
        weights=np.ascontiguousarray(w, dtype=np.float64),
        non_primitive=int(np.count_nonzero(g > 1)),
    )


def direction_set(radius: int) -> DirectionSet:
    """The direction families of radius ``radius`` (cached per radius).

    Parameters
    ----------
    radius : int
        Radius R >= 1 of the discrete sphere.

    Returns
    -------
    DirectionSet
        Vectors, Voronoi solid angles, families and their weights.

    Raises
    ------
    TypeError, ValueError
        If ``radius`` is not an integer >= 1.

    Examples
    --------
    >>> len(direction_set(8)), direction_set(8).families.shape
    (762, (381, 3))
    """
    return _cached(_validate.integer(radius, "radius", low=1, high=1024))
