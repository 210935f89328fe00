"""The line system of a solve and where its passes run.

:class:`LineRecords` is what a :class:`voxgi._core.LineSystem` is built
from (orders, occupancy; O(N) once, ``docs/design.md`` §4); an executor
(:class:`LineExecutor`) builds it where the passes run; :class:`Gatherer`
runs a solve's gathering passes on it, recording the pairs of a direction
set once and replaying them (:func:`pair_table_bytes`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from .. import _core, _validate
from ..directions import direction_set
from ..voxels import VoxelSet
from .records import check_vox

__all__ = [
    "Gatherer",
    "LineExecutor",
    "LineRecords",
    "LocalExecutor",
    "gather_partial",
    "line_records",
    "line_system",
    "pair_table_bytes",
]


@dataclass(frozen=True, eq=False)
class LineRecords:
    """What a line system is built from; picklable, so an executor can ship it.

    Attributes
    ----------
    ijk : (N, 3) int32
        Voxel coordinates.
    normal : (N, 3) float32
        Unit normals.
    point : (N, 3) float32
        Surface points in voxel units (voxel ``ijk`` spans ``[ijk, ijk + 1]``).
    epsilon : float
        Facing-rule margin, in voxels (``docs/design.md`` §4).
    history : int
        F records a receiver passes over in its search along a line (1..32;
        a run of them in one plane counts once).
    """

    ijk: np.ndarray
    normal: np.ndarray
    point: np.ndarray
    epsilon: float = 0.02
    history: int = 16

    def __len__(self) -> int:
        return len(self.ijk)

    def build(self) -> _core.LineSystem:
        """The prepared :class:`voxgi._core.LineSystem` (orders, occupancy; O(N))."""
        return _core.LineSystem(
            self.ijk,
            self.normal,
            self.point,
            epsilon=float(self.epsilon),
            history=int(self.history),
        )


def line_records(vox: VoxelSet, *, epsilon: float = 0.02, history: int = 16) -> LineRecords:
    """The :class:`LineRecords` of a VoxelSet (validated, C-contiguous).

    >>> import voxgi
    >>> vox = voxgi.voxelize(voxgi.scenes.furnace_box(), resolution=8, progress=False)
    >>> len(line_records(vox)) == len(vox)
    True
    """
    a = check_vox(vox)
    eps = _validate.real(epsilon, "epsilon", low=0.0)
    hist = _validate.integer(history, "history", low=1, high=32)
    return LineRecords(a["ijk"], a["normal"], a["point"], eps, hist)


def line_system(vox: VoxelSet, *, epsilon: float = 0.02, history: int = 16) -> _core.LineSystem:
    """The prepared line system of a VoxelSet (orders, occupancy; O(N) once).

    Parameters
    ----------
    vox : VoxelSet
        Records.
    epsilon : float
        Facing-rule margin, in voxels (``docs/design.md`` §4).
    history : int
        F records a receiver passes over in its search along a line (1..32;
        a run of them in one plane counts once).
    """
    return line_records(vox, epsilon=epsilon, history=history).build()


class LineExecutor(Protocol):
    """Where a solve's passes run (``docs/design.md`` §8).

    ``line_system(records, progress=...)`` returns an object with the
    :class:`voxgi._core.LineSystem` interface that :func:`solve` uses:
    ``size``, ``normalisation``, ``gather`` and ``shoot`` (and, to record
    and replay the pairs of a direction set, ``make_pair_table`` and
    ``gather_recorded``). Results must be the local ones to float rounding.
    """

    def line_system(self, records: LineRecords, *, progress: bool = False): ...


class LocalExecutor:
    """The default executor: every pass in this process, on ``threads`` threads.

    >>> LocalExecutor().line_system  # doctest: +ELLIPSIS
    <bound method LocalExecutor.line_system of <...LocalExecutor object at ...>>
    """

    def line_system(self, records: LineRecords, *, progress: bool = False) -> _core.LineSystem:
        """Build the line system here (``progress`` has no bar to drive)."""
        return records.build()


def gather_partial(
    vox: VoxelSet,
    radiosity,
    family_indices,
    directions: int = 22,
    *,
    threads: int | None = None,
    epsilon: float = 0.02,
    history: int = 16,
    system: _core.LineSystem | None = None,
) -> np.ndarray:
    """One Jacobi gathering pass over a subset of the direction families.

    Partial sums over disjoint subsets of families add up to the full pass.

    Parameters
    ----------
    vox : VoxelSet
        Records.
    radiosity : (N, 3) array_like
        Values to propagate (for the solver, the reflected radiosity ``B - E``).
    family_indices : (K,) array_like of int
        Indices into ``direction_set(directions).families``.
    directions : int
        Radius of the direction sphere.
    threads : int or None
        Threads (None: all).
    system : LineSystem, optional
        A prepared :func:`line_system` of ``vox`` to reuse.

    Returns
    -------
    sums : (N, 3) float64
        ``Σ radiosity[partner] · cos · ΔΩ/π`` over the selected families (both
        signs), not yet divided by the records' ``S(n)``.
    """
    ds = direction_set(directions)
    s = system if system is not None else line_system(vox, epsilon=epsilon, history=history)
    vals = _validate.as_c_array(radiosity, np.float32, (s.size, 3), "radiosity")
    idx = _validate.as_c_array(family_indices, np.int64, (-1,), "family_indices")
    if idx.size and (idx.min() < 0 or idx.max() >= len(ds.families)):
        raise ValueError(f"family_indices: must lie in [0, {len(ds.families)})")
    sums, _, _ = s.gather(ds.families, ds.weights, vals, idx, False, _validate.threads(threads))
    return sums


def pair_table_bytes(n: int, families: np.ndarray) -> int:
    """Bytes of the recorded pairs of ``n`` records over ``families``: 3 per
    record and family, each main axis's families padded to tiles of 16.

    >>> from voxgi.directions import direction_set
    >>> pair_table_bytes(1000, direction_set(4).families)
    384000
    """
    fam = np.asarray(families)
    if len(fam) == 0:
        return 0
    m = np.argmax(np.abs(fam), axis=1)
    tile = _core.PairTable.TILE
    cols = sum(-(-int(np.sum(m == a)) // tile) * tile for a in range(3))
    return _core.PairTable.ENTRY_BYTES * int(n) * cols


class Gatherer:
    """The gathering passes of one solve. The first pass over a direction
    set walks the lines and, where the budget allows, records the pairs it
    finds (:class:`voxgi._core.PairTable`); later passes over recorded
    families replay them: visibility does not change between iterations,
    so only the first pass pays for it."""

    def __init__(self, sysm, nthreads: int, stand_in, budget: int | None, passes: dict):
        self.sysm = sysm
        self.nthreads = nthreads
        self.stand_in = stand_in
        self.budget = budget  # None: never record
        self.passes = passes  # id(ds) -> expected passes over that set
        self.tables: dict = {}
        self.used = 0
        self.info: dict = {"bytes": 0, "sets": []}
        self.replayed = 0

    def _why_not(self, ds, need: int) -> str | None:
        """Why the pairs of ``ds`` are not recorded (None: they are)."""
        if self.sysm.size > _core.PairTable.MAX_RECORDS:
            return f"more than {_core.PairTable.MAX_RECORDS} records"
        if self.passes.get(id(ds), 0) < 2:
            return "one pass only"
        if self.used + need > self.budget:
            return f"needs {need / 2**30:.2f} GiB, budget {self.budget / 2**30:.2f} GiB"
        return None

    def _table(self, ds):
        key = id(ds)
        if key in self.tables:
            return self.tables[key]
        tab = None
        need = pair_table_bytes(self.sysm.size, ds.families)
        entry = {"radius": int(ds.radius), "bytes": need}
        why = None if self.budget is None else self._why_not(ds, need)
        if self.budget is None:
            entry["recorded"] = False
        elif why is not None:
            entry["recorded"] = False
            entry["reason"] = why
        else:
            tab = self.sysm.make_pair_table(ds.families, ds.weights, self.stand_in is not None)
            self.used += need
            entry["recorded"] = True
            self.info["bytes"] = self.used
        self.info["sets"].append(entry)
        self.tables[key] = tab
        return tab

    def __call__(self, ds, values, sel, want_vis, defer_vis=True):
        """(sums, vis, lines walked) of one pass over ``ds.families[sel]``.

        With ``defer_vis``, a pass that records leaves ``vis`` (None) to the
        next pass, which replays and sums it at no cost."""
        tab = self._table(ds)
        if tab is not None and np.all(tab.recorded_mask[sel]):
            sums, vis = self.sysm.gather_recorded(tab, values, sel, want_vis, self.nthreads)
            self.replayed += 1
            return sums, vis, 0
        if tab is not None and defer_vis:
            want_vis = False
        return self.sysm.gather(
            ds.families,
            ds.weights,
            values,
            sel,
            want_vis,
            self.nthreads,
            stand_in=self.stand_in,
            **({"record": tab} if tab is not None else {}),
        )
