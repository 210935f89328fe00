"""Tasks farmed out to a client's workers and their results collected in order."""

from __future__ import annotations

import hashlib
import threading
import time

import numpy as np

from .client import _workers, check_client


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
            "resent": 0,
        }
        self._sent: dict = {}  # key: (future, value) of what _send scattered
        self._resent: dict = {}  # a lost future's key: the future sent in its place

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

    def _send(self, value):
        """Scatter ``value`` to every worker; return its future.

        Dask's active memory manager (its ``ReduceReplicas`` policy, on by
        default) drops the copies of a broadcast value that no task waits
        for, down to one; a worker killed then takes the last copy with it.
        The farm keeps the value so that :meth:`_map` can send it again.
        """
        fut = self.client.scatter([value], broadcast=True, hash=False)[0]
        self._sent[fut.key] = (fut, value)
        return fut

    def _live(self, x):
        """``x``, or the future sent in its place if ``x`` was lost."""
        while getattr(x, "key", None) in self._resent:
            x = self._resent[x.key]
        return x

    def _resend_lost(self) -> int:
        """Scatter again every sent value whose data the cluster lost."""
        n = 0
        for key, (fut, value) in list(self._sent.items()):
            if fut.status != "finished":
                del self._sent[key]
                self._resent[key] = self._send(value)
                n += 1
        self.stats["resent"] += n
        return n

    def _unsend(self, fut) -> None:
        """Release a sent value (and whatever was sent in its place)."""
        while fut is not None:
            self._sent.pop(fut.key, None)
            fut.release()
            fut = self._resent.pop(fut.key, None)

    def _map(self, fn, chunks, *common, key_prefix: str):
        """Run ``fn(*common, *chunk)`` for every chunk, one worker each (loosely:
        another may take over if it dies); return the results in chunk order."""
        from distributed import as_completed

        def submit(i):
            return self.client.submit(
                fn,
                *(self._live(x) for x in common),
                *(self._live(x) for x in chunks[i]),
                workers=[self.workers[i % len(self.workers)]],
                allow_other_workers=True,
                pure=False,
                key=f"{key_prefix}-{i}-{_uid()}",
            )

        futs = [submit(i) for i in range(len(chunks))]
        self.stats["tasks"] += len(futs)
        out = [None] * len(futs)
        where = {f.key: i for i, f in enumerate(futs)}
        resubmitted = 0
        bar = None
        if self.progress and len(futs) > 1:
            from .. import _progress

            bar = _progress.bar(self.desc, len(futs), unit="task")
        t = time.perf_counter()
        try:
            pending = as_completed(futs)
            for fut in pending:
                i = where[fut.key]
                if fut.cancelled() and resubmitted < len(futs):
                    # A worker killed while another fetched a result from it
                    # can leave the scheduler forgetting that task ("already
                    # forgotten"), or take with it the last copy of an input
                    # ("lost dependencies"): send what was lost, run it again.
                    resubmitted += 1
                    self._resend_lost()
                    again = submit(i)
                    where[again.key] = i
                    pending.add(again)
                    continue
                out[i] = fut.result()
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


def _token(*arrays) -> str:
    """A hash of the records: the key of a worker's cached LineSystem."""
    h = hashlib.blake2b(digest_size=16)
    for a in arrays:
        h.update(str(a.shape).encode())
        h.update(str(a.dtype).encode())
        h.update(np.ascontiguousarray(a).view(np.uint8).data)
    return h.hexdigest()
