"""Scene to image in one call: voxelize, solve and display with the defaults.

This module sits above the stages (:mod:`voxgi.voxels`, :mod:`voxgi.radiosity`,
:mod:`voxgi.display`) and only calls their public functions. ``voxgi.solve``
and ``voxgi.render`` are :func:`solve` and :func:`render` from here: they
take ``client=``, a ``dask.distributed.Client`` or an executor, and hand the
stages its executor (:func:`voxgi.distributed.executor`); :func:`render`
also accepts ``sol=None`` and then voxelizes and solves the scene first.
"""

from __future__ import annotations

import time
from dataclasses import replace

from . import distributed
from .display import RenderResult, RenderTuning
from .display import render as display_render
from .radiosity import Solution, SolveTuning
from .radiosity import solve as radiosity_solve
from .scene import Camera, Scene
from .voxels import VoxelSet, voxelize

__all__ = [
    "RENDER_DIRECTIONS",
    "RENDER_DIRECTIONS_LINES_ONLY",
    "RENDER_RESOLUTION",
    "RENDER_SOLVE_TOL",
    "RENDER_SOLVE_TUNING",
    "render",
    "solve",
    "solve_for_display",
]

#: Voxel resolution used by ``render(scene)`` without a solution and by
#: ``voxgi render``: on the Cornell box at 256x256 against a converged
#: path-traced reference (``benchmarks/time_vs_error.py``), past resolution
#: 64 the display's noise at its default tolerance, not the voxels, sets the
#: picture's error.
RENDER_RESOLUTION = 64
#: Gathering radius of that solve. Its traced passes (below) carry the
#: reflected light; the lines only give them a start, and a coarse start
#: costs them nothing: against R 12, solutions at R 4 gave pictures within
#: 1.1e-4 relMSE of theirs in six scenes (at most a ninth of the default
#: tolerance; the door room, lit through a slit, the farthest) and the same
#: error against the path-traced references of the Cornell box, ``shadow``
#: and ``geometric``, for a solve about 25% shorter (``docs/design.md`` §5).
#: R 3 takes a third traced pass and no less time.
RENDER_DIRECTIONS = 4
#: The radius when the records carry no scene to trace, so the lines alone
#: carry the reflected light.
RENDER_DIRECTIONS_LINES_ONLY = 8
#: The solve's ``tol`` in that pipeline: tighter changes the picture's error
#: by nothing the display can show, and costs more bounces.
RENDER_SOLVE_TOL = 1e-3
#: The rest of that solve's settings: no diagnostic passes, and direct light
#: by shadow rays to the exact emitters (``docs/design.md`` §5), which thin
#: occluders in front of a lamp or window cannot swallow, and whose cost does
#: not grow with the number of emitter records. 16 sample pairs a record are
#: enough for the picture: on the Cornell box at 256x256 its error after 64
#: frames is that of 64 pairs (the display averages many records), and the
#: solve takes less time than with the shooting. The reflected light then
#: takes traced passes too (``docs/design.md`` §5): gaps, bars and walls
#: thinner than a voxel act as they are, for 0.1-0.35 s at resolution 64
#: in the built-in interiors.
RENDER_SOLVE_TUNING = SolveTuning(
    diagnostics=False, direct_light="exact", direct_samples=16, indirect_light="traced"
)


def solve(
    vox: VoxelSet,
    directions: int = 22,
    max_bounces: int | None = None,
    tol: float = 1e-4,
    threads: int | None = None,
    client=None,
    *,
    progress: bool = True,
    tuning: SolveTuning | None = None,
) -> Solution:
    """Solve the radiosity of ``vox``: :func:`voxgi.radiosity.solve`, whose
    arguments these are, with ``client`` a ``dask.distributed.Client`` or an
    executor (:mod:`voxgi.distributed`; ``pip install "voxgi[dask]"``) to
    run the passes on.

    >>> import voxgi
    >>> vox = voxgi.voxelize(voxgi.scenes.furnace_box(albedo=0.5), resolution=8, progress=False)
    >>> sol = voxgi.solve(vox, directions=4, progress=False,
    ...                   tuning=voxgi.SolveTuning(shoot_directions=4))
    >>> bool(sol.radiosity.max() > 0)
    True
    """
    return radiosity_solve(
        vox,
        directions,
        max_bounces,
        tol,
        threads,
        distributed.executor(client),
        progress=progress,
        tuning=tuning,
    )


def solve_for_display(
    vox: VoxelSet,
    *,
    directions: int | None = None,
    threads: int | None = None,
    progress: bool = True,
    client=None,
) -> Solution:
    """Solve ``vox`` as the display needs it: :data:`RENDER_SOLVE_TOL` and
    :data:`RENDER_SOLVE_TUNING` (exact direct light, no diagnostic passes).

    Parameters
    ----------
    vox : VoxelSet
        Records from :func:`voxgi.voxelize`.
    directions : int or None
        Gathering radius R (None: :data:`RENDER_DIRECTIONS`, or
        :data:`RENDER_DIRECTIONS_LINES_ONLY` when ``vox.scene`` is None).
    threads, progress, client
        As for :func:`solve`.
    """
    if directions is None:
        traced = getattr(vox, "scene", None) is not None
        directions = RENDER_DIRECTIONS if traced else RENDER_DIRECTIONS_LINES_ONLY
    return solve(
        vox,
        directions=directions,
        tol=RENDER_SOLVE_TOL,
        threads=threads,
        progress=progress,
        client=client,
        tuning=RENDER_SOLVE_TUNING,
    )


def render(
    scene: Scene,
    sol: Solution | None = None,
    vpls_per_frame: int | None = None,
    max_frames: int | None = None,
    tol: float | None = None,
    seed: int = 0,
    progress: bool = True,
    threads: int | None = None,
    client=None,
    *,
    camera: Camera | None = None,
    tuning: RenderTuning | None = None,
    resolution: int | None = None,
    directions: int | None = None,
) -> RenderResult:
    """Render ``scene``; with ``sol=None``, voxelize and solve it first.

    Takes the arguments of :func:`voxgi.display.render`, with ``client`` a
    ``dask.distributed.Client`` or an executor, and when ``sol`` is None also
    ``resolution`` (default :data:`RENDER_RESOLUTION`) and ``directions``
    (default :data:`RENDER_DIRECTIONS`). The result's ``solution`` is the
    solution displayed, and ``stats["seconds"]`` includes ``voxelize`` and
    ``solve`` when they ran here.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected voxgi.Scene, got {type(scene).__name__}")
    ex = distributed.executor(client)
    seconds = {}
    if sol is None:
        t0 = time.perf_counter()
        vox = voxelize(scene, resolution=RENDER_RESOLUTION if resolution is None else resolution)
        seconds["voxelize"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        sol = solve_for_display(
            vox, directions=directions, threads=threads, progress=progress, client=ex
        )
        seconds["solve"] = time.perf_counter() - t0
    if vpls_per_frame is not None:
        tuning = replace(tuning or RenderTuning(), vpls_per_frame=vpls_per_frame)
    out = display_render(
        scene,
        sol,
        tol=tol,
        max_frames=max_frames,
        camera=camera,
        seed=seed,
        threads=threads,
        progress=progress,
        executor=ex,
        tuning=tuning,
    )
    if seconds:
        s = out.stats["seconds"]
        s.update(seconds)
        s["total"] = s.get("total", 0.0) + seconds["voxelize"] + seconds["solve"]
    return out
