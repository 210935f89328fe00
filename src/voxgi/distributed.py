"""Solve and render on a Dask cluster (``pip install "voxgi[dask]"``).

:class:`DaskExecutor` is an executor the stages accept
(:class:`voxgi.radiosity.LineExecutor`, :class:`voxgi.display.FrameExecutor`):
nothing here has a loop of its own over iterations or frames;
:func:`voxgi.radiosity.solve` and :func:`voxgi.display.render` run their usual
loops on the objects it hands them, which farm the work out.
``voxgi.solve(..., client=c)`` and ``voxgi.render(..., client=c)`` wrap a
``dask.distributed.Client`` with :func:`executor`.

Solve (``docs/design.md`` §8): :class:`DistributedLineSystem` stands in for
:class:`voxgi._core.LineSystem`. The records (ijk, normal, surface point:
36 bytes each) are scattered once to every worker (``broadcast=True``: a
killed worker is survived, because another one still holds a copy, and
scattered data has no lineage from which Dask could rebuild it); each worker
builds its LineSystem once and caches it, keyed by a hash of the records.
Within a Jacobi iteration the direction families are independent: every
call to ``gather``/``shoot``/``normalisation`` splits the families into one
contiguous chunk per worker, each task returns its partial sums, and the
sums are added here in chunk order, so the result does not depend on which
worker ran what, nor (beyond float64 rounding of the additions) on the
number of workers. Per iteration a worker receives the values being
propagated (N × 3 float32) and returns N × 3 float64 partial sums.

Render: :class:`DistributedFrames` stands in for the display's per-frame
shader. Frames are independent (each has its own VPL subset, sub-pixel
offset and gather-ray seed), so whole frames are the tasks: the
:class:`voxgi.display.FrameShaderSpec` (scene, camera, VPL sampler) goes to
every worker once, each worker builds its shader once, frames are computed
ahead on the workers and handed back to the render loop in frame order. The
accumulation and the stopping rule stay in :func:`voxgi.display.render`, so
with the same seed the image is the local one.
"""

from __future__ import annotations

import hashlib
import threading
import time
from collections import OrderedDict

import numpy as np

from .display import FrameShaderSpec
from .radiosity import LineRecords

__all__ = [
    "DaskExecutor",
    "DistributedFrames",
    "DistributedLineSystem",
    "check_client",
    "estimate_worker_bytes",
    "executor",
]

_EXTRA_HINT = 'pip install "voxgi[dask]"'

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


def _require_distributed():
    """Import dask.distributed or raise an ImportError that names the extra."""
    try:
        import distributed
    except ImportError as exc:
        raise ImportError(
            "client=: distributed solving and rendering need Dask's distributed scheduler, "
            f"which is not installed; install the extra with: {_EXTRA_HINT}"
        ) from exc
    return distributed


def check_client(client):
    """Return ``client`` if it is a ``dask.distributed.Client``.

    Raises
    ------
    ImportError
        If dask.distributed is not installed (the message names the extra).
    TypeError
        If ``client`` is not a Client.
    ValueError
        If the client's cluster has no worker.
    """
    distributed = _require_distributed()
    if not isinstance(client, distributed.Client):
        raise TypeError(
            f"client: expected a dask.distributed.Client, an executor or None, got "
            f"{type(client).__name__}"
        )
    return client


def executor(client):
    """The executor for ``client=``: None for None, an executor as it is
    (an object with a ``line_system`` or a ``frames`` method, see
    :class:`voxgi.radiosity.LineExecutor` and :class:`voxgi.display.FrameExecutor`),
    a ``dask.distributed.Client`` wrapped in a :class:`DaskExecutor`.

    >>> executor(None) is None
    True

    Raises
    ------
    ImportError
        A Client-like argument while dask.distributed is not installed.
    TypeError
        Neither an executor nor a Client.
    """
    if client is None:
        return None
    if any(callable(getattr(client, m, None)) for m in ("line_system", "frames")):
        return client
    return DaskExecutor(check_client(client))


class DaskExecutor:
    """Solve passes and render frames on the workers of a Dask cluster.

    Parameters
    ----------
    client : dask.distributed.Client
    """

    def __init__(self, client):
        self.client = check_client(client)

    def line_system(self, records: LineRecords, *, progress: bool = False):
        """A :class:`DistributedLineSystem` of ``records`` (see
        :class:`voxgi.radiosity.LineExecutor`)."""
        return DistributedLineSystem(self.client, records, progress=progress)

    def frames(self, spec: FrameShaderSpec, max_frames: int, *, threads: int = 1):
        """A :class:`DistributedFrames` of ``spec`` (see
        :class:`voxgi.display.FrameExecutor`; each task uses its worker's threads)."""
        return DistributedFrames(self.client, spec, max_frames)


def _workers(client) -> dict:
    info = (
        client.scheduler_info(n_workers=-1) if _takes_n_workers(client) else client.scheduler_info()
    )
    workers = info.get("workers", {})
    if not workers:
        raise ValueError("client: the cluster has no worker (start some, or wait for them)")
    return workers


def _takes_n_workers(client) -> bool:
    import inspect

    try:
        return "n_workers" in inspect.signature(client.scheduler_info).parameters
    except (TypeError, ValueError):
        return False


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


def _token(*arrays) -> str:
    """A hash of the records: the key of a worker's cached LineSystem."""
    h = hashlib.blake2b(digest_size=16)
    for a in arrays:
        h.update(str(a.shape).encode())
        h.update(str(a.dtype).encode())
        h.update(np.ascontiguousarray(a).view(np.uint8).data)
    return h.hexdigest()


# ----------------------------------------------------------------------------- worker side

# Per worker process: LineSystems (and frame shaders) already built, by key.
# Only the latest few are kept, so a long study does not pile them up.
_CACHE: OrderedDict = OrderedDict()
_CACHE_LOCK = threading.Lock()
_CACHE_SIZE = 2
_FRAME_LOCK = threading.Lock()  # a shader reuses its buffers: one frame at a time


def _cached(key, build):
    with _CACHE_LOCK:
        if key in _CACHE:
            _CACHE.move_to_end(key)
            return _CACHE[key]
        obj = build()
        _CACHE[key] = obj
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
        return obj


def _worker_threads() -> int:
    """The worker's thread slots: the cores Dask gave this worker."""
    try:
        from distributed import get_worker

        w = get_worker()
        n = getattr(w, "nthreads", None) or getattr(getattr(w, "state", None), "nthreads", 1)
        return max(1, int(n))
    except (ImportError, ValueError):
        return 1


def _system(records: LineRecords, key):
    return _cached(("lines", key), records.build)


def _task_gather(records, key, families, weights, values, want_vis, stand_in=None):
    s = _system(records, key)
    idx = np.arange(len(families), dtype=np.int64)
    return s.gather(families, weights, values, idx, want_vis, _worker_threads(), stand_in=stand_in)


def _task_shoot(
    records, key, emitters, coverage, families, weights, values, stand_in=None, sil=None
):
    s = _system(records, key)
    return s.shoot(
        emitters,
        families,
        weights,
        values,
        _worker_threads(),
        coverage=coverage,
        stand_in=stand_in,
        **(sil or {}),
    )


def _task_normalisation(records, key, families, weights):
    return _system(records, key).normalisation(families, weights, _worker_threads())


def _task_frame(spec: FrameShaderSpec, key, f, seed):
    shader = _cached(("frame", key), lambda: spec.build(_worker_threads()))
    with _FRAME_LOCK:
        before = (shader.primary_rays, shader.shadow_rays, shader.gather_rays, dict(shader.seconds))
        x = shader.frame(f, seed)
        counts = (
            shader.primary_rays - before[0],
            shader.shadow_rays - before[1],
            shader.gather_rays - before[2],
        )
        secs = {k: v - before[3].get(k, 0.0) for k, v in shader.seconds.items()}
    obj, ng = shader.surface
    return x, (obj, ng.astype(np.float16)), counts, secs


# ----------------------------------------------------------------------------- client side


class _Farm:
    """What both backends share: the client, the workers, ordered collection."""

    def __init__(self, client, progress: bool, desc: str):
        self.client = check_client(client)
        self.workers = sorted(_workers(client))
        self.progress = bool(progress)
        self.desc = desc
        self.stats = {
            "workers": len(self.workers),
            "tasks": 0,
            "bytes_scattered": 0,
            "bytes_sent": 0,
            "bytes_received": 0,
            "seconds_waiting": 0.0,
        }

    def _check_memory(self, need: int, what: str) -> None:
        """Refuse before any work when a worker's memory_limit is under ``need``.

        A worker stops taking tasks once its memory passes the ``pause``
        fraction of its limit (Dask's ``distributed.worker.memory.pause``,
        0.8 by default): that share of the limit is what counts.
        """
        import dask

        pause = dask.config.get("distributed.worker.memory.pause", 0.8)
        frac = float(pause) if isinstance(pause, (int, float)) and 0 < pause <= 1 else 1.0
        info = _workers(self.client)
        for addr in self.workers:
            limit = int(info[addr].get("memory_limit") or 0)  # 0: no limit set
            if 0 < limit * frac < need:
                raise MemoryError(
                    f"client: worker {addr} has memory_limit {limit / 2**20:.1f} MiB (it pauses "
                    f"at {frac:.0%} of it), but {what} needs about {need / 2**20:.1f} MiB on every "
                    "worker; give the workers more memory (memory_limit=...) or use a coarser "
                    "resolution"
                )
        self.stats["bytes_per_worker_estimate"] = int(need)

    def _map(self, fn, chunks, *common, key_prefix: str):
        """Run ``fn(*common, *chunk)`` for every chunk, one worker each (loosely:
        another may take over if it dies); return the results in chunk order."""
        from distributed import as_completed

        futs = []
        for i, chunk in enumerate(chunks):
            w = self.workers[i % len(self.workers)]
            futs.append(
                self.client.submit(
                    fn,
                    *common,
                    *chunk,
                    workers=[w],
                    allow_other_workers=True,
                    pure=False,
                    key=f"{key_prefix}-{i}-{_uid()}",
                )
            )
        self.stats["tasks"] += len(futs)
        out = [None] * len(futs)
        where = {f.key: i for i, f in enumerate(futs)}
        bar = None
        if self.progress and len(futs) > 1:
            from . import _progress

            bar = _progress.bar(self.desc, len(futs), unit="task")
        t = time.perf_counter()
        try:
            for fut in as_completed(futs):
                out[where[fut.key]] = fut.result()
                if bar is not None:
                    bar.update(1)
        finally:
            if bar is not None:
                bar.close()
            self.stats["seconds_waiting"] += time.perf_counter() - t
        return out


_UID = [0]
_UID_LOCK = threading.Lock()


def _uid() -> str:
    with _UID_LOCK:
        _UID[0] += 1
        return f"{_UID[0]:x}-{time.monotonic_ns():x}"


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
        # once, to every worker: a killed worker's tasks find a copy elsewhere
        # (in a list: a container itself would be scattered value by value)
        self._records = client.scatter([records], broadcast=True, hash=False)[0]
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
        fut = self.client.scatter(v, broadcast=True, hash=False)
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
            fut = self.client.scatter(sb, broadcast=True, hash=False)
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
        parts = self._map(_task_gather, chunks, self._records, self.key, key_prefix="voxgi-gather")
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
        parts = self._map(
            _task_shoot, chunks, self._records, self.key, em, cov, key_prefix="voxgi-shoot"
        )
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
        self._records.release()
        if self._stand_in_cache is not None:
            self._stand_in_cache[1].release()
            self._stand_in_cache = None


class DistributedFrames(_Farm):
    """Stands in for the display's frame shader: whole frames on the workers.

    ``frame(f, seed)`` returns frame ``f`` as the local shader would; frames
    ``f + 1 …`` are already being computed (up to two per worker thread
    slot in flight), so the render loop's stopping rule, applied in frame
    order, sees exactly the local sequence of frames.

    Parameters
    ----------
    client : dask.distributed.Client
    spec : voxgi.display.FrameShaderSpec
        Scene, camera, VPL sampler and settings, sent once to every worker.
    max_frames : int
        Frames the render may ask for (none is submitted past it).
    """

    def __init__(self, client, spec: FrameShaderSpec, max_frames: int):
        super().__init__(client, False, "frames")
        n = len(spec.sampler.vox)
        cam = spec.camera
        # the sampler's arrays (~100 B a record), the scene's triangles (72 B
        # each in float64, three copies), and one frame (H·W·3 float32) plus
        # the shader's hit buffers (~100 B a pixel)
        need = n * 100 + spec.scene.n_triangles * 72 * 3 + cam.width * cam.height * 112
        self._check_memory(need, f"a {cam.width}x{cam.height} render of {n} records")
        self.key = "frames-" + _uid()
        t = time.perf_counter()
        self._payload = client.scatter([spec], broadcast=True, hash=False)[0]
        self.stats["seconds_scatter"] = time.perf_counter() - t
        slots = sum(int(v.get("nthreads", 1)) for v in _workers(client).values())
        self.ahead = max(2, 2 * slots)
        self.max_frames = int(max_frames)
        self._futs: dict = {}
        self._next = 0
        self.primary_rays = self.shadow_rays = self.gather_rays = 0
        self.seconds = {k: 0.0 for k in ("primary", "shadow", "gather")}
        self.surface = None  # the last frame's, as the local shader keeps it

    def _submit_upto(self, last: int, seed: int) -> None:
        while self._next <= min(last, self.max_frames - 1):
            f = self._next
            w = self.workers[f % len(self.workers)]
            self._futs[f] = self.client.submit(
                _task_frame,
                self._payload,
                self.key,
                f,
                seed,
                workers=[w],
                allow_other_workers=True,
                pure=False,
                key=f"voxgi-frame-{f}-{_uid()}",
            )
            self.stats["tasks"] += 1
            self._next += 1

    def frame(self, f: int, seed: int) -> np.ndarray:
        """(H*W, 3) float32 radiance of frame ``f`` (computed on a worker)."""
        self._submit_upto(f + self.ahead, seed)
        if f not in self._futs:  # asked out of order: compute it alone
            self._futs[f] = self.client.submit(
                _task_frame,
                self._payload,
                self.key,
                f,
                seed,
                pure=False,
                key=f"voxgi-frame-{f}-{_uid()}",
            )
        t = time.perf_counter()
        x, self.surface, counts, secs = self._futs.pop(f).result()
        self.stats["seconds_waiting"] += time.perf_counter() - t
        self.stats["bytes_received"] += x.nbytes + sum(a.nbytes for a in self.surface)
        self.primary_rays += counts[0]
        self.shadow_rays += counts[1]
        self.gather_rays += counts[2]
        for k, v in secs.items():  # summed over workers: compute seconds, not wall
            self.seconds[k] = self.seconds.get(k, 0.0) + v
        return x

    def close(self) -> None:
        """Cancel the frames computed ahead that the render did not need."""
        if self._futs:
            self.client.cancel(list(self._futs.values()))
            self._futs.clear()
        self._payload.release()
