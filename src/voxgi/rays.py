"""Embree ray queries on a scene's triangles, shared by the direct light and the display.

Rays are traced in a frame centred on the scene: Embree takes float32, whose
spacing at 1e7 is 1, so a scene far from the origin would lose its detail in
world coordinates. Callers subtract :attr:`Tracer.centre` from their points.

The queries run in the compiled core, on C++ threads with the GIL released,
against the Embree 4 library that the embreex wheel ships (found by
:func:`embree_library`). There is no other path: where that library cannot
be opened, or is not Embree 4, :class:`Tracer` raises an :class:`ImportError`
that says which file and why.

One convention for occlusion everywhere: a query answers (R,) uint8, 1 where
no light passes the segment, 0 where some does, as the compiled kernels take
it. Transmitting sheets (glass, ``docs/design.md`` §13) are in a scene of
their own: no query stops at one; :meth:`Tracer.transmittance` and
``through`` give the product of the transmittances of the sheets crossed.

A scene's compiled Embree scene is built once and kept while the scene lives
(:func:`compiled_scene`): the voxelization's direct light, the solve's traced
passes and the display all trace the same triangles, and building the
hierarchy of a million of them takes about half a second.
"""

from __future__ import annotations

import functools
import os
import sys
import weakref
from pathlib import Path

import numpy as np

from . import _core
from .scene import Scene

__all__ = [
    "EMBREEX_RANGE",
    "Tracer",
    "compiled_scene",
    "embree_library",
    "embree_version",
    "ray_scene",
]

#: The embreex releases whose bundled Embree the compiled core loads
#: (``pyproject.toml`` pins the same range).
EMBREEX_RANGE = ">=4.4,<5"


@functools.cache
def embree_library() -> str:
    """Path of the Embree 4 shared library that embreex loads.

    auditwheel and delocate put a wheel's bundled libraries beside the
    package (``embreex.libs``, ``embreex/.dylibs``); a source build of
    embreex links a system Embree, which the dynamic loader finds by name.

    Raises
    ------
    ImportError
        Without embreex, or on Windows, where the core cannot open Embree at
        run time.
    """
    if sys.platform == "win32":
        raise ImportError(
            "voxgi traces rays with the Embree 4 library opened at run time, "
            "which is not supported on Windows"
        )
    try:
        import embreex
    except ImportError as e:
        raise ImportError(
            f"voxgi needs embreex{EMBREEX_RANGE} for its Embree 4 library: "
            f"pip install 'embreex{EMBREEX_RANGE}' ({e})"
        ) from None
    pkg = Path(embreex.__file__).parent
    for folder, pattern in (
        (pkg.parent / "embreex.libs", "libembree4*.so*"),
        (pkg / ".dylibs", "libembree4*.dylib"),
    ):
        found = sorted(folder.glob(pattern)) if folder.is_dir() else []
        if found:
            return os.fspath(found[0])
    return "libembree4.dylib" if sys.platform == "darwin" else "libembree4.so.4"


def ray_scene(tris: np.ndarray, transmittance: np.ndarray | None = None) -> _core.RayScene:
    """The compiled Embree scene of triangles ``tris`` (F, 3, 3) float32;
    ``transmittance`` (F, 3) float32 or None: the triangles with a channel
    above 0 are sheets that rays cross.

    Raises
    ------
    ImportError
        Naming the library and what went wrong where it cannot be opened or
        is not Embree 4.
    """
    lib = embree_library()
    try:
        return _core.RayScene(lib, tris, transmittance)
    except RuntimeError as e:
        try:
            from importlib.metadata import version

            have = f"embreex {version('embreex')}"
        except Exception:
            have = "this embreex"
        raise ImportError(
            f"voxgi cannot trace rays: {e}. It needs the Embree 4 library of "
            f"embreex{EMBREEX_RANGE}; {have} gave {lib}"
        ) from None


@functools.cache
def embree_version() -> str:
    """The version ("major.minor.patch") of the Embree library the rays go through.

    Raises
    ------
    ImportError
        Where the library cannot be opened or is not Embree 4.
    """
    return ray_scene(np.eye(3, dtype=np.float32)[None]).embree_version


# scene -> (its fingerprint, centre, centred float64 triangles, RayScene)
_COMPILED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def compiled_scene(scene: Scene) -> tuple[np.ndarray, np.ndarray, _core.RayScene]:
    """The frame centre, the centred (F, 3, 3) float64 triangles and the
    compiled Embree scene of ``scene``, built on first use and kept while
    ``scene`` lives and its fingerprint (geometry, materials) stays the same.

    The triangles are read-only: every tracer of the scene shares them.

    Raises
    ------
    ImportError
        Where the Embree 4 library cannot be opened (:func:`embree_library`).
    """
    # the fingerprint covers vertices, faces and materials, sheets'
    # transmittances included: an object added, replaced or edited in place
    # gives a new key
    key = scene.fingerprint()
    kept = _COMPILED.get(scene)
    if kept is not None and kept[0] == key:
        return kept[1:]
    through = None
    if scene.has_sheets:
        through = np.concatenate(
            [
                np.broadcast_to(np.float32(o.material.transmittance), (len(o.faces), 3))
                for o in scene.objects
            ]
        )
    centre = scene.bounds.mean(axis=0)
    tris = np.concatenate([o.vertices[o.faces] for o in scene.objects]) - centre
    tris.flags.writeable = False
    native = ray_scene(np.ascontiguousarray(tris, dtype=np.float32), through)
    _COMPILED[scene] = (key, centre, tris, native)
    return centre, tris, native


class Tracer:
    """Occlusion and first-hit queries on ``scene``'s triangles, on C++ threads.

    Parameters
    ----------
    scene : Scene
        Its triangles, in the order of :meth:`Scene.triangles`, are the
        primitives; a query's answer is an index into them.
    threads : int
        Worker threads of the queries (1: the calling thread only).

    Attributes
    ----------
    centre : (3,) float64
        The frame's origin in world coordinates (the middle of the scene's bounds).
    tris : (F, 3, 3) float64, read-only
        The triangles' corners in the centred frame.
    native : voxgi._core.RayScene
        The compiled scene, which the display and the direct light also hand
        to their kernels; shared by every tracer of the scene
        (:func:`compiled_scene`).

    Raises
    ------
    ImportError
        Where the Embree 4 library cannot be opened (:func:`embree_library`).
    """

    def __init__(self, scene: Scene, threads: int):
        self.centre, self.tris, self.native = compiled_scene(scene)
        self.threads = max(1, int(threads))

    @property
    def has_sheets(self) -> bool:
        """Whether the scene has transmitting sheets."""
        return bool(self.native.has_sheets)

    def close(self) -> None:
        """Nothing to release: the compiled scene goes with the tracer."""

    def __enter__(self) -> Tracer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def occluded(self, org: np.ndarray, dirs: np.ndarray, length: np.ndarray) -> np.ndarray:
        """(R,) uint8: 1 where an opaque triangle lies on the segment
        [org, org + length * dirs), else 0 (sheets do not block it)."""
        return self.native.occluded(_f32(org), _f32(dirs), _f32(length), self.threads)

    def transmittance(self, org: np.ndarray, dirs: np.ndarray, length: np.ndarray) -> np.ndarray:
        """(R, 3) float32: the light that passes [org, org + length * dirs): 0
        where an opaque triangle lies on it, else the product of the
        transmittances of the sheets on it (1 without)."""
        return self.native.transmittance(_f32(org), _f32(dirs), _f32(length), self.threads)

    def intersect(self, org: np.ndarray, dirs: np.ndarray, *, through: bool = False):
        """(R,) int32 index of the first opaque triangle each ray meets, -1 for
        a miss; with ``through``, also (R, 3) float32: the product of the
        transmittances of the sheets before it."""
        if not through:
            return self.native.intersect(_f32(org), _f32(dirs), False, self.threads)[0]
        prim, _, _, T = self.native.intersect(_f32(org), _f32(dirs), False, self.threads, True)
        return prim, T

    def first_hit(self, org: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, ...]:
        """(R,) int32 first opaque triangle (-1: none) and float32 barycentrics u, v there."""
        return self.native.intersect(_f32(org), _f32(dirs), True, self.threads)


def _f32(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32)
