"""The solve's passes on Dask workers: a LineSystem whose work is farmed out."""

from __future__ import annotations

import time

import numpy as np

from ..radiosity import LineRecords
from .client import _workers
from .farm import _Farm, _token
from .worker import _task_gather, _task_normalisation, _task_shoot

# Bytes a worker holds per record: the scattered copy of ijk, normal and
# point (36) and what the worker's LineSystem and one call need, the growth
# of the peak resident set over building a LineSystem, one gather (R 22,
# with visibility) and one shoot (R 35) on one thread: 213 B for the system
# (three axis orders of order, X, Y, Z, normal, point and the packed 32-byte
# line), the values in each axis order, the one-pass walk's 64-byte record
# lines and global-order sums, float64 sums and visibility out; 470 bounds
# it. Each further thread of the worker adds its own record lines and sums,
# about 100 B.
_BYTES_PER_RECORD = 36 + 470
_BYTES_PER_RECORD_THREAD = 100


def estimate_worker_bytes(n_records: int, box=(0, 0, 0), threads: int = 1) -> int:
    """Bytes one worker needs for the records of a distributed solve.

    Parameters
    ----------
    n_records : int
        Records N.
    box : (3,) int
        Extent of the records' voxel box (the shooting occupancy bitset
        takes one bit per voxel of it).
    threads : int
        The worker's threads (each gathers into its own record lines).

    Returns
    -------
    int
        ``N × (506 + 100 × (threads - 1))`` bytes (scattered records, the
        worker's LineSystem, one call's values and sums; see
        ``_BYTES_PER_RECORD``) plus the occupancy bitset, rounded up. The
        worker process itself (Python, numpy, Dask: ~100-150 MB) comes on top.
    """
    cells = int(np.prod(np.asarray(box, dtype=np.int64) + 1))
    per = _BYTES_PER_RECORD + _BYTES_PER_RECORD_THREAD * (max(1, int(threads)) - 1)
    return int(n_records) * per + cells // 8 + 1


class DistributedLineSystem(_Farm):
    """A :class:`voxgi._core.LineSystem` whose work runs on Dask workers.

    Same ``size``, ``normalisation``, ``gather`` and ``shoot`` as the local
    one (``threads`` is ignored: each task uses its worker's thread slots),
    so :func:`voxgi.solve` runs its loop unchanged on it.

    Parameters
    ----------
    client : dask.distributed.Client
    records : voxgi.radiosity.LineRecords
        What the workers build their LineSystem from (:func:`voxgi.radiosity.line_records`).
    progress : bool
        A progress bar over each call's tasks (on a terminal or in a notebook).

    Raises
    ------
    ImportError
        dask.distributed is not installed.
    TypeError
        ``client`` is not a Client.
    MemoryError
        A worker's memory_limit is under :func:`estimate_worker_bytes`.
    """

    def __init__(self, client, records: LineRecords, *, progress: bool = False):
        super().__init__(client, progress, "gather tasks")
        ijk = np.ascontiguousarray(records.ijk, dtype=np.int32)
        normal = np.ascontiguousarray(records.normal, dtype=np.float32)
        point = np.ascontiguousarray(records.point, dtype=np.float32)
        epsilon, history = float(records.epsilon), int(records.history)
        self.size = len(ijk)
        box = ijk.max(axis=0) - ijk.min(axis=0) if len(ijk) else np.zeros(3)
        info = _workers(client)
        threads = max((int(info[a].get("nthreads", 1) or 1) for a in self.workers), default=1)
        self._check_memory(
            estimate_worker_bytes(self.size, box, threads), f"a solve of {self.size} records"
        )
        self.key = _token(ijk, normal, point, np.float32([epsilon, history]))
        records = LineRecords(ijk, normal, point, epsilon, history)
        t = time.perf_counter()
        # once, to every worker, kept to be sent again should a killed worker
        # take the cluster's last copy with it
        self._records = self._send(records)
        self.stats["seconds_scatter"] = time.perf_counter() - t
        self.stats["bytes_scattered"] = int(ijk.nbytes + normal.nbytes + point.nbytes)
        self._stand_in_cache = None  # (token, future) of the last stand-in flags sent

    def _chunks(self, n: int):
        return [c for c in np.array_split(np.arange(n), len(self.workers)) if len(c)]

    def _values(self, values):
        v = np.ascontiguousarray(values, dtype=np.float32)
        if v.shape != (self.size, 3):
            raise ValueError(f"values: expected shape ({self.size}, 3), got {v.shape}")
        # once per call to every worker, not once per task
        fut = self._send(v)
        self.stats["bytes_sent"] += v.nbytes * len(self.workers)
        return fut

    def normalisation(self, families, weights, threads: int = 0) -> np.ndarray:
        """Raw S(n) per record, (N,) float64 (see LineSystem.normalisation)."""
        chunks = [(families[c], weights[c]) for c in self._chunks(len(families))]
        parts = self._map(
            _task_normalisation, chunks, self._records, self.key, key_prefix="voxgi-normalisation"
        )
        out = np.zeros(self.size)
        for p in parts:  # fixed order: chunk order
            out += p
        return out

    def _stand_in(self, stand_in):
        """The stand-in flags, (N,) bool or None, scattered once per distinct array."""
        if stand_in is None:
            return None
        sb = np.ascontiguousarray(stand_in, dtype=np.bool_)
        if sb.shape != (self.size,):
            raise ValueError(f"stand_in: expected shape ({self.size},), got {sb.shape}")
        tok = _token(sb)
        if self._stand_in_cache is None or self._stand_in_cache[0] != tok:
            if self._stand_in_cache is not None:
                self._unsend(self._stand_in_cache[1])
            fut = self._send(sb)
            self.stats["bytes_sent"] += sb.nbytes * len(self.workers)
            self._stand_in_cache = (tok, fut)
        return self._stand_in_cache[1]

    def gather(
        self, families, weights, values, family_indices, want_vis=False, threads=0, stand_in=None
    ):
        """Jacobi gathering over ``families[family_indices]``: (sums, vis, lines)."""
        sel = np.asarray(family_indices, dtype=np.int64)
        fams = np.ascontiguousarray(families[sel])
        wts = np.ascontiguousarray(weights[sel])
        vfut = self._values(values)
        sfut = self._stand_in(stand_in)
        chunks = [(fams[c], wts[c], vfut, bool(want_vis), sfut) for c in self._chunks(len(sel))]
        try:
            parts = self._map(
                _task_gather, chunks, self._records, self.key, key_prefix="voxgi-gather"
            )
        finally:
            self._unsend(vfut)
        sums = np.zeros((self.size, 3))
        vis = np.zeros(self.size) if want_vis else None
        lines = 0
        for s, v, nl in parts:  # fixed order: chunk order
            sums += s
            if want_vis:
                vis += v
            lines += int(nl)
        self.stats["bytes_received"] += sum(p[0].nbytes for p in parts)
        return sums, vis, lines

    def shoot(
        self,
        emitters,
        families,
        weights,
        values,
        threads=0,
        coverage=None,
        stand_in=None,
        object=None,
        sil_area=None,
        back=None,
    ):
        """Shooting from ``emitters`` split by direction families: (hd, unfound, rays, steps)."""
        em = np.ascontiguousarray(emitters, dtype=np.int32)
        cov = None if coverage is None else np.ascontiguousarray(coverage, dtype=np.float64)
        vfut = self._values(values)
        sfut = self._stand_in(stand_in)
        sil = None
        if object is not None:
            sil = dict(
                object=np.ascontiguousarray(object, dtype=np.int32),
                sil_area=np.ascontiguousarray(sil_area, dtype=np.float64),
                back=np.ascontiguousarray(back, dtype=np.bool_),
            )
        chunks = [
            (np.ascontiguousarray(families[c]), np.ascontiguousarray(weights[c]), vfut, sfut, sil)
            for c in self._chunks(len(families))
        ]
        try:
            parts = self._map(
                _task_shoot, chunks, self._records, self.key, em, cov, key_prefix="voxgi-shoot"
            )
        finally:
            self._unsend(vfut)
        hd = np.zeros((self.size, 3))
        unfound = np.zeros(len(em))
        rays = steps = 0
        for h, u, r, st in parts:  # fixed order: chunk order
            hd += h
            unfound += u
            rays += int(r)
            steps += int(st)
        self.stats["bytes_received"] += sum(p[0].nbytes for p in parts)
        return hd, unfound, rays, steps

    def close(self) -> None:
        """Release the scattered records (the workers' caches keep at most two systems)."""
        self._unsend(self._records)
        if self._stand_in_cache is not None:
            self._unsend(self._stand_in_cache[1])
            self._stand_in_cache = None
