"""Scene to image in one call: voxelize, solve and display with the defaults.

This module sits above the stages (:mod:`voxgi.voxels`, :mod:`voxgi.radiosity`,
:mod:`voxgi.display`) and only calls their public functions. ``voxgi.render``
is :func:`render` from here: it accepts ``sol=None`` and then voxelizes and
solves the scene first.
"""

from __future__ import annotations

import time

from .display import RenderResult
from .display import render as display_render
from .radiosity import Solution, solve
from .scene import Scene
from .voxels import VoxelSet, voxelize

__all__ = ["RENDER_DIRECTIONS", "RENDER_RESOLUTION", "RENDER_SOLVE_TOL", "render", "solve_for_display"]

#: Voxel resolution and gathering radius used by ``render(scene)`` without a
#: solution and by ``voxgi render``. On the Cornell box at 256x256 against a
#: converged path-traced reference (``benchmarks/time_vs_error.py``), the
#: picture's relMSE is 5.5e-4 at resolution 48, 3.5e-4 at 64 and 3.3e-4 at 96
#: (R 8), so past 64 the display's noise at its default tolerance (about
#: 1e-3) sets the error, not the voxels.
RENDER_RESOLUTION = 64
RENDER_DIRECTIONS = 8
#: The solve's ``tol`` in that pipeline: a solve to 1e-3 instead of 1e-4
#: changes the Cornell box's radiosity by 8e-5 (relative, area-weighted) and
#: its picture's error not at all, with 10 bounces instead of 13.
RENDER_SOLVE_TOL = 1e-3


def solve_for_display(vox: VoxelSet, *, directions: int | None = None,
                      threads: int | None = None, progress: bool = True,
                      client=None) -> Solution:
    """Solve ``vox`` as the display needs it: ``RENDER_SOLVE_TOL``, no diagnostic passes.

    Parameters
    ----------
    vox : VoxelSet
        Records from :func:`voxgi.voxelize`.
    directions : int or None
        Gathering radius R (None: :data:`RENDER_DIRECTIONS`).
    threads, progress, client
        As for :func:`voxgi.solve`.
    """
    return solve(vox, directions=RENDER_DIRECTIONS if directions is None else directions,
                 tol=RENDER_SOLVE_TOL, threads=threads, progress=progress, client=client,
                 diagnostics=False)


def render(scene: Scene, sol: Solution | None = None, vpls_per_frame: int = 16,
           max_frames: int | None = None, tol: float | None = None, seed: int = 0,
           progress: bool = True, threads: int | None = None, client=None, *,
           resolution: int | None = None, directions: int | None = None,
           **display_options) -> RenderResult:
    """Render ``scene``; with ``sol=None``, voxelize and solve it first.

    Takes the arguments of :func:`voxgi.display.render` (the keyword-only
    ones through ``display_options``), and when ``sol`` is None also
    ``resolution`` (default :data:`RENDER_RESOLUTION`) and ``directions``
    (default :data:`RENDER_DIRECTIONS`). The result's ``solution`` is the
    solution displayed, and ``stats["seconds"]`` includes ``voxelize`` and
    ``solve`` when they ran here.
    """
    seconds = {}
    if sol is None:
        if not isinstance(scene, Scene):
            raise TypeError(f"scene: expected voxgi.Scene, got {type(scene).__name__}")
        t0 = time.perf_counter()
        vox = voxelize(scene, resolution=RENDER_RESOLUTION if resolution is None else resolution)
        seconds["voxelize"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        sol = solve_for_display(vox, directions=directions, threads=threads, progress=progress,
                                client=client)
        seconds["solve"] = time.perf_counter() - t0
    out = display_render(scene, sol, vpls_per_frame, max_frames, tol, seed, progress, threads,
                         client, **display_options)
    if seconds:
        s = out.stats["seconds"]
        s.update(seconds)
        s["total"] = s.get("total", 0.0) + seconds["voxelize"] + seconds["solve"]
    return out
