"""The display's frames on Dask workers, handed back in frame order."""

from __future__ import annotations

import time

import numpy as np

from ..display import FrameShaderSpec
from .client import _workers
from .farm import _Farm, _uid
from .worker import _task_frame


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
        self._payload = self._send(spec)  # kept, to be sent again if the cluster loses it
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
            self._futs[f] = self._submit(f, seed, workers=[w], allow_other_workers=True)
            self._next += 1

    def _submit(self, f: int, seed: int, **where):
        self.stats["tasks"] += 1
        return self.client.submit(
            _task_frame,
            self._live(self._payload),
            self.key,
            f,
            seed,
            pure=False,
            key=f"voxgi-frame-{f}-{_uid()}",
            **where,
        )

    def frame(self, f: int, seed: int) -> np.ndarray:
        """(H*W, 3) float32 radiance of frame ``f`` (computed on a worker)."""
        from distributed import as_completed

        self._submit_upto(f + self.ahead, seed)
        if f not in self._futs:  # asked out of order: compute it alone
            self._futs[f] = self._submit(f, seed)
        t = time.perf_counter()
        fut = self._futs.pop(f)
        for _ in range(len(self.workers)):
            next(as_completed([fut]))  # done, or cancelled (where wait() raises)
            if not fut.cancelled():
                break
            # forgotten or lost with a killed worker (see _Farm._map): again
            self._resend_lost()
            fut = self._submit(f, seed)
        x, self.surface, counts, secs = fut.result()
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
        self._unsend(self._payload)
