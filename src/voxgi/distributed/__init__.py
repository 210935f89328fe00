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

from .client import check_client
from .executor import DaskExecutor, executor
from .frames import DistributedFrames
from .lines import DistributedLineSystem, estimate_worker_bytes

__all__ = [
    "DaskExecutor",
    "DistributedFrames",
    "DistributedLineSystem",
    "check_client",
    "estimate_worker_bytes",
    "executor",
]
