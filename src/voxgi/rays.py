"""Embree ray queries on a scene's triangles, shared by the direct light and the display.

Rays are traced in a frame centred on the scene: Embree takes float32, whose
spacing at 1e7 is 1, so a scene far from the origin would lose its detail in
world coordinates. Callers subtract :attr:`Tracer.centre` from their points.

The queries run in the compiled core, on C++ threads with the GIL released,
against the Embree library that the embreex wheel ships (found by
:func:`embree_library`). Where that library cannot be found they fall back on
embreex's own Python calls, split over a thread pool: the same answers, with
more overhead per batch.
"""

from __future__ import annotations

import functools
import itertools
import os
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from . import _core
from .scene import Scene

__all__ = ["Tracer", "embree_library"]


@functools.cache
def embree_library() -> str | None:
    """Path of the Embree 4 shared library that embreex loads, or None.

    auditwheel and delocate put a wheel's bundled libraries beside the
    package (``embreex.libs``, ``embreex/.dylibs``); a source build of
    embreex links a system Embree, which the dynamic loader finds by name.
    """
    if sys.platform == "win32":
        return None
    try:
        import embreex
    except ImportError:
        return None
    pkg = Path(embreex.__file__).parent
    for folder, pattern in (
        (pkg.parent / "embreex.libs", "libembree4*.so*"),
        (pkg / ".dylibs", "libembree4*.dylib"),
    ):
        found = sorted(folder.glob(pattern)) if folder.is_dir() else []
        if found:
            return os.fspath(found[0])
    return "libembree4.dylib" if sys.platform == "darwin" else "libembree4.so.4"


class Tracer:
    """Occlusion and first-hit queries on ``scene``'s triangles, split over threads.

    Parameters
    ----------
    scene : Scene
        Its triangles, in the order of :meth:`Scene.triangles`, are the
        primitives; a query's answer is an index into them.
    threads : int
        Worker threads for large batches (1: the calling thread only).
    native : bool, optional
        Trace in the compiled core where :func:`embree_library` finds Embree
        (default); False: always through embreex's Python calls.

    Attributes
    ----------
    centre : (3,) float64
        The frame's origin in world coordinates (the middle of the scene's bounds).
    tris : (F, 3, 3) float64
        The triangles' corners in the centred frame.
    native : voxgi._core.RayScene or None
        The compiled scene, which the display and the direct light also hand
        to their kernels; None on the embreex path.
    why_not_native : str or None
        Why the queries go through embreex's Python calls (slower, the same
        answers), or None when they do not.
    """

    def __init__(self, scene: Scene, threads: int, *, native: bool = True):
        self.centre = scene.bounds.mean(axis=0)
        self.tris = np.concatenate([o.vertices[o.faces] for o in scene.objects]) - self.centre
        self._tri32 = np.ascontiguousarray(self.tris, dtype=np.float32)
        self.threads = max(1, int(threads))
        self._pool = None
        self.native = None
        self.why_not_native = None
        lib = embree_library() if native else None
        if not native:
            self.why_not_native = "the caller asked for embreex's calls (native=False)"
        elif lib is None:
            self.why_not_native = "no Embree 4 library found beside embreex"
        else:
            try:
                self.native = _core.RayScene(lib, self._tri32)
            except RuntimeError as e:  # not an Embree 4 we can open: embreex's calls below
                self.why_not_native = str(e)
        if self.native is None:
            from embreex import rtcore_scene
            from embreex.mesh_construction import TriangleMesh

            self.embree = rtcore_scene.EmbreeScene()
            self._mesh = TriangleMesh(self.embree, self._tri32)
            self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None

    def close(self) -> None:
        """Release the worker threads."""
        if self._pool is not None:
            self._pool.shutdown()

    def __enter__(self) -> Tracer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def occluded(self, org: np.ndarray, dirs: np.ndarray, length: np.ndarray) -> np.ndarray:
        """(R,) int32: -1 where nothing lies on the segment [org, org + length * dirs)."""
        if self.native is not None:
            hit = self.native.occluded(_f32(org), _f32(dirs), _f32(length), self.threads)
            return hit.astype(np.int32) - 1

        def one(a: int, b: int) -> np.ndarray:
            hit = self.embree.run(org[a:b], dirs[a:b], query="OCCLUDED", dists=length[a:b])
            return np.asarray(hit, np.int32)

        return self._split(len(org), one, np.concatenate)

    def intersect(self, org: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """(R,) int32 index of the first triangle each ray meets, -1 for a miss."""
        if self.native is not None:
            return self.native.intersect(_f32(org), _f32(dirs), False, self.threads)[0]

        def one(a: int, b: int) -> np.ndarray:
            return np.asarray(self.embree.run(org[a:b], dirs[a:b], query="INTERSECT"), np.int32)

        return self._split(len(org), one, np.concatenate)

    def first_hit(self, org: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, ...]:
        """(R,) int32 first triangle (-1: none) and float32 barycentrics u, v there."""
        if self.native is not None:
            return self.native.intersect(_f32(org), _f32(dirs), True, self.threads)

        def one(a: int, b: int):
            h = self.embree.run(org[a:b], dirs[a:b], query="INTERSECT", output=1)
            return np.asarray(h["primID"], np.int32), h["u"], h["v"]

        def join(parts):
            return tuple(np.concatenate([p[i] for p in parts]) for i in range(3))

        return self._split(len(org), one, join)

    def _split(self, n: int, one, join):
        """``one(a, b)`` over [0, n) in one slice per thread (small batches whole)."""
        if self._pool is None or n < 4096:
            return one(0, n)
        cuts = np.linspace(0, n, self.threads + 1).astype(np.int64)
        futs = [self._pool.submit(one, int(a), int(b)) for a, b in itertools.pairwise(cuts)]
        return join([f.result() for f in futs])


def _f32(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32)
