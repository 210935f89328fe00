"""Radiosity on voxels: discrete-line propagation (shooting, then gathering).

The discretised radiosity equation (``docs/design.md`` §1)

    B(x) = E(x) + ρ(x) Σ_σ B(I(x,σ)) (n_x·σ̂) ΔΩ(σ) / (π S(n_x))

is solved on the records of a :class:`~voxgi.VoxelSet`, ``I(x,σ)`` the first
record seen from ``x`` along the discrete line of direction σ (found for all
records at once in O(N) per direction family, :class:`voxgi._core.LineSystem`)
and ``S(n)`` the raw cos-weighted hemisphere sum of the direction set, so that
every record gathers exactly one hemisphere (``docs/design.md`` §3).

Bookkeeping (``docs/design.md`` §5): *shooting* gives every record its direct
irradiance ``H_d`` from the emitters with the finer radius (default 35);
*gathering* (default 22) then propagates only the reflected radiosity
``R = B − E``, so that ``B = E + ρ (H_d + H_gathered)`` and direct light is not
counted twice.

Ray counts (``Solution.stats``): a *gathering ray* is one record meeting one
direction family (both of its directions) in one iteration; a *shooting ray*
is one emitter record and one direction it faces.

Where the passes run is an *executor*'s choice (``docs/design.md`` §8): any
object with a ``line_system(records, *, progress)`` method returning an object
with the :class:`voxgi._core.LineSystem` methods ``size``, ``normalisation``,
``gather`` and ``shoot`` (:class:`LineExecutor`). The default runs them here;
:mod:`voxgi.distributed` runs them on a Dask cluster.
"""

from __future__ import annotations

from ..solution import Solution
from .linesystem import (
    LineExecutor,
    LineRecords,
    LocalExecutor,
    gather_partial,
    line_records,
    line_system,
    pair_table_bytes,
)
from .memory import solve_memory
from .solver import solve
from .tuning import SolveTuning

__all__ = [
    "LineExecutor",
    "LineRecords",
    "LocalExecutor",
    "Solution",
    "SolveTuning",
    "gather_partial",
    "line_records",
    "line_system",
    "pair_table_bytes",
    "solve",
    "solve_memory",
]
