"""The solve: direct light, the gathering iteration, the traced passes."""

from __future__ import annotations

import time

import numpy as np

from ..incidence import base_radiosity
from ..solution import Solution
from ..voxels import VoxelSet
from .diagnostics import back_fraction, energy_balance, lost_fraction
from .direct_strategies import direct_light
from .iteration import State, iterate
from .linesystem import Gatherer, LineExecutor, LocalExecutor
from .memory import check_memory
from .problem import Problem, build_problem, gatherer, normalise, open_backend, zero_solution
from .records import check_vox
from .traced_passes import traced_bounces
from .tuning import Settings, SolveTuning, gathering_radius, settings

__all__ = ["solve"]


def _check_executor(executor, vox: VoxelSet, opt: Settings, tuning) -> LineExecutor:
    """The executor given, or the local one for None (whose memory estimate
    is checked here, before anything is allocated)."""
    if executor is None:
        executor = LocalExecutor()
    if isinstance(executor, LocalExecutor):
        check_memory(vox, opt, tuning)
        return executor
    if not callable(getattr(executor, "line_system", None)):
        raise TypeError(
            f"executor: expected an object with a line_system(records, progress=...) method "
            f"(voxgi.radiosity.LineExecutor) or None, got {type(executor).__name__}; "
            "voxgi.solve also takes a dask.distributed.Client as client="
        )
    return executor


def _statistics(p: Problem, gather: Gatherer, s: State, shoot_rays: int) -> None:
    """Ray counts, phases, pair cache and what was skipped, into ``p.stats``."""
    p.stats.update(
        rays=int(shoot_rays + s.gather_rays),
        shoot_rays=int(shoot_rays),
        gather_rays=int(s.gather_rays),
        seconds=p.seconds,
        bounces=s.it,
        lines_walked=int(s.lines_walked),
        pair_cache=p.stats.get("pair_cache", {**gather.info, "replayed_passes": gather.replayed}),
        epsilon=p.opt.epsilon,
        history=p.opt.history,
    )
    if s.it and p.lds is not None:
        p.stats["skipped"]["finer_directions_after"] = p.opt.later_after
    if gather.replayed:
        p.stats["skipped"]["line_walks"] = (
            f"{gather.replayed} gathering passes replayed the recorded pairs"
        )


def solve(
    vox: VoxelSet,
    *,
    radius: int | None = None,
    tol: float | None = None,
    max_bounces: int | None = None,
    threads: int | None = None,
    executor: LineExecutor | None = None,
    progress: bool = True,
    tuning: SolveTuning | None = None,
) -> Solution:
    """Solve the discrete radiosity equation on the records of ``vox``.

    Direct light first (by default shadow rays to the exact emitters; the
    paper's shooting with :meth:`SolveTuning.paper`), then Jacobi gathering
    of the reflected light along the discrete lines with geometric-tail
    extrapolation until the estimated remaining error falls under ``tol``,
    then, by default, traced passes against the exact triangles
    (``docs/design.md`` §5). :func:`voxgi.solve` is this function with a
    ``client=`` for a Dask cluster.

    Parameters
    ----------
    vox : VoxelSet
        Records from :func:`voxgi.voxelize`; left unchanged.
    radius : int or None
        Radius R >= 1 of the gathering direction set (R 4: 210 directions,
        R 22: 5982). None: ``tuning.radius``, else 4 where traced passes
        finish the reflected light and 8 where the lines alone carry it
        (:func:`voxgi.radiosity.tuning.gathering_radius`).
    tol : float or None
        Bound on the estimated remaining relative error ``r λ / (1 − λ)``, ``r``
        the area-weighted residual (``residuals``), ``λ`` the largest albedo,
        for the lines and then for the traced passes (the lines stop at 100
        times it where the traced passes keep their rays, and at most at
        1e-3 where they trace fresh rays; ``stats["lines_tol"]`` says where
        it differs). None: ``tuning.tol`` (1e-3; the
        paper's 1e-4).
    max_bounces : int or None
        At most this many gathering iterations along the lines, and then no
        traced passes (None: until converged; 0: direct light only).
    threads : int or None
        Threads (None: all hardware threads). Results do not depend on it.
    executor : LineExecutor or None
        Where the passes run (None: here, after checking the memory estimate
        of :func:`solve_memory`).
    progress : bool
        Show a progress bar over the iterations (on a terminal or in a notebook).
    tuning : SolveTuning or None
        What the solve computes and how (None: ``SolveTuning()``, the
        accurate pipeline; :meth:`SolveTuning.paper`: the paper's method).

    Returns
    -------
    Solution
        ``radiosity`` (N, 3) float32, always finite; ``stats`` with ray counts,
        ``seconds``, ``lost_fraction``, ``energy`` (of the lines), ``skipped``,
        ``stopped`` (why the lines stopped short, with a warning), or
        ``lines_stopped`` where traced passes followed a stall of the lines
        (no warning: the passes sum the rest from any start) and, after
        traced bounces, ``traced`` (passes, rays,
        residuals, the change of the reflected power against the lines, and
        the records whose sum came out negative and were set to zero).

    Raises
    ------
    TypeError, ValueError, MemoryError
        Bad arguments; an estimate (:func:`solve_memory`) over the memory available.

    Warns
    -----
    RuntimeWarning
        No emitter; not converged; stalled (unless traced passes follow)
        or non-finite (the last finite iterate is returned).
    """
    t_start = time.perf_counter()
    a = check_vox(vox)
    R = gathering_radius(radius, tuning, vox, max_bounces)
    opt = settings(R, max_bounces, tol, threads, tuning)
    executor = _check_executor(executor, vox, opt, tuning)
    p = build_problem(vox, a, opt)
    if p.stats["emitters"] == 0 and not p.lights:
        return zero_solution(p)
    open_backend(p, executor, progress)
    try:
        normalise(p)
        Hd, shoot_escape, shoot_rays = direct_light(p)
        gather = gatherer(p)
        s = iterate(p, gather, Hd, progress)
        p.stats["energy"] = energy_balance(p, Hd, s, lost_fraction(p, gather, s.vis), shoot_escape)
        back_fraction(p, gather)
        s.R = traced_bounces(p, Hd, s.R, s.mode)
    finally:
        if hasattr(p.sysm, "close"):
            p.sysm.close()
    p.seconds["total"] = time.perf_counter() - t_start
    _statistics(p, gather, s, shoot_rays)
    B = (p.E + s.R).astype(np.float32)
    base = None
    if p.direct_base is not None:
        base = base_radiosity(vox.scene, vox, p.response, s.R, Hd, p.direct_base)
    return Solution(
        vox=vox,
        radiosity=B,
        bounces=s.it,
        residuals=s.residuals,
        stats=p.stats,
        base_radiosity=base,
    )
