"""What runs in a worker process: the cached LineSystems and frame shaders, the tasks."""

from __future__ import annotations

import threading
from collections import OrderedDict

import numpy as np

from ..display import FrameShaderSpec
from ..radiosity import LineRecords

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
