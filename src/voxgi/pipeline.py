"""Scene to image: ``voxgi.solve`` and ``voxgi.render``, with one set of defaults.

This module sits above the stages (:mod:`voxgi.voxels`, :mod:`voxgi.radiosity`,
:mod:`voxgi.display`) and only calls their public functions. :func:`solve`
is :func:`voxgi.radiosity.solve` with ``client=``, a
``dask.distributed.Client`` or an executor (:func:`voxgi.distributed.executor`);
:func:`render` displays a solution, and with ``sol=None`` first solves the
scene at the resolution its picture needs (:func:`voxgi.resolution.solve_scene`,
with :func:`solve`'s defaults), so that
``render(scene, voxgi.resolution.solve_scene(scene, tol=tol))`` is
``render(scene, tol=tol)``.
"""

from __future__ import annotations

import time

from . import distributed
from .display import RenderResult, RenderTuning
from .display import render as display_render
from .display.settings import DEFAULT_TOL
from .radiosity import Solution, SolveTuning
from .radiosity import solve as radiosity_solve
from .resolution import solve_scene
from .scene import Camera, Scene
from .voxels import VoxelSet

__all__ = ["render", "solve"]


def solve(
    vox: VoxelSet,
    *,
    radius: int | None = None,
    tol: float | None = None,
    max_bounces: int | None = None,
    threads: int | None = None,
    progress: bool = True,
    client=None,
    tuning: SolveTuning | None = None,
) -> Solution:
    """Solve the radiosity of every record of ``vox``.

    By default the accurate pipeline, the one :func:`render` solves with:
    direct light by shadow rays to the exact emitters, the reflected light
    gathered along the discrete lines and then finished by passes of rays
    against the exact triangles, to a remaining error of 1e-3
    (``docs/design.md`` §5). ``tuning=voxgi.SolveTuning.paper()`` runs the
    paper's method instead (shooting, lines only, radius 22, tol 1e-4).

    Parameters
    ----------
    vox : VoxelSet
        Records from :func:`voxgi.voxelize`; left unchanged.
    radius : int or None
        Radius R >= 1 of the gathering direction set (R 4: 210 directions,
        R 8: 762, R 22: 5982). None: ``tuning.radius``, else 4 where traced
        passes finish the reflected light and 8 where the lines alone carry
        it (the records carry no scene, ``indirect_light="lines"``, or
        ``max_bounces`` is set).
    tol : float or None
        Bound on the estimated remaining relative error of the reflected
        light (area-weighted), for the lines and then for the traced passes.
        None: ``tuning.tol`` (1e-3; the paper's 1e-4).
    max_bounces : int or None
        At most this many gathering iterations along the lines, and then no
        traced passes (None: until converged; 0: direct light only).
    threads : int or None
        Threads (None: all hardware threads). Results do not depend on it.
    progress : bool
        Show a progress bar over the iterations (on a terminal or in a notebook).
    client : dask.distributed.Client, executor or None
        Where the passes run: None here; a Dask client or any
        :class:`voxgi.radiosity.LineExecutor` (``pip install "voxgi[dask]"``;
        :mod:`voxgi.distributed`). The answer is the local one to float rounding.
    tuning : SolveTuning or None
        What the solve computes and how (None: ``SolveTuning()``, the
        accurate pipeline; :meth:`SolveTuning.paper`: the paper's method).

    Returns
    -------
    Solution
        ``radiosity`` (N, 3) float32 per record, ``bounces``, ``residuals``
        and ``stats`` (ray counts, seconds per phase, what was skipped and why).

    Raises
    ------
    TypeError, ValueError, MemoryError
        Bad arguments; a memory estimate over what is available.

    Examples
    --------
    >>> import voxgi
    >>> vox = voxgi.voxelize(voxgi.scenes.furnace_box(albedo=0.5), resolution=8)
    >>> sol = voxgi.solve(vox, progress=False)
    >>> bool(sol.radiosity.max() > 0)
    True
    """
    return radiosity_solve(
        vox,
        radius=radius,
        tol=tol,
        max_bounces=max_bounces,
        threads=threads,
        executor=distributed.executor(client),
        progress=progress,
        tuning=tuning,
    )


def render(
    scene: Scene,
    sol: Solution | None = None,
    *,
    tol: float | None = None,
    max_frames: int | None = None,
    camera: Camera | None = None,
    seed: int = 0,
    threads: int | None = None,
    progress: bool = True,
    client=None,
    tuning: RenderTuning | None = None,
) -> RenderResult:
    """Render ``scene`` from its camera; with ``sol=None``, voxelize and solve it first.

    Each pixel sees the scene's surfaces lit by the records of the solution,
    each a virtual point light, in progressive frames averaged until the
    estimated noise falls under ``tol`` (:func:`voxgi.display.render`,
    ``docs/design.md`` §6). Without a solution the scene is solved at the
    coarsest resolution the picture needs, 16, 32 or
    :data:`voxgi.voxels.DEFAULT_RESOLUTION` (64), with :func:`solve`'s
    defaults (:func:`voxgi.resolution.solve_scene` with this ``tol``), so
    that ``render(scene, voxgi.resolution.solve_scene(scene, tol=tol))``
    gives the same picture; ``out.solution.stats["resolution"]`` says which
    and why. For a resolution of your choice, a radius or a solve tuning,
    call :func:`voxgi.voxelize` and :func:`solve` and pass ``sol``; do so
    too where two variants of a scene are compared record by record, as
    each would otherwise get the grid it needs.

    Parameters
    ----------
    scene : Scene
        The scene, with a camera (``scene.camera``, or ``camera=``).
    sol : Solution or None
        The radiosity of ``scene``'s records (:func:`solve`); None: voxelize
        and solve here.
    tol : float or None
        Bound on the estimated relMSE of the picture's remaining noise
        (None: 1e-3; 0: run ``max_frames`` frames).
    max_frames : int or None
        At most this many frames (None: 256).
    camera : Camera or None
        Overrides ``scene.camera``.
    seed : int
        Seeds the VPL, sub-pixel and lens sequences: the same seed, the same
        picture, whatever the threads.
    threads : int or None
        Threads (None: all hardware threads).
    progress : bool
        Show progress bars, the solve's and the frames' (on a terminal or in a
        notebook).
    client : dask.distributed.Client, executor or None
        Where the solve's passes and the frames run (None: here;
        :mod:`voxgi.distributed`). The picture is the local one.
    tuning : RenderTuning or None
        The display's expert settings (:class:`voxgi.RenderTuning`).

    Returns
    -------
    RenderResult
        ``image`` (H, W, 3) float32 linear radiance, ``stderr``, ``frames``,
        ``solution`` (the one displayed) and ``stats``, whose ``seconds``
        include ``voxelize`` and ``solve`` when they ran here (every
        resolution tried).

    Raises
    ------
    TypeError, ValueError
        Not a scene, no camera, a solution of another scene, bad arguments.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected voxgi.Scene, got {type(scene).__name__}")
    ex = distributed.executor(client)
    seconds = {}
    if sol is None:
        t0 = time.perf_counter()
        sol = solve_scene(
            scene,
            tol=DEFAULT_TOL if not tol else tol,
            threads=threads,
            progress=progress,
            executor=ex,
        )
        seconds["voxelize"] = sol.stats["resolution"]["voxelize_seconds"]
        seconds["solve"] = time.perf_counter() - t0 - seconds["voxelize"]
    out = display_render(
        scene,
        sol,
        max_frames=max_frames,
        tol=tol,
        seed=seed,
        progress=progress,
        threads=threads,
        executor=ex,
        camera=camera,
        tuning=tuning,
    )
    if seconds:
        s = out.stats["seconds"]
        s.update(seconds)
        s["total"] = s.get("total", 0.0) + seconds["voxelize"] + seconds["solve"]
    return out
