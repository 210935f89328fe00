"""The voxel resolution a scene needs: solutions at doubling resolutions
until two give the same indirect light (``docs/design.md`` §7).

The display computes the light of the emitters exactly at every pixel; the
solution enters a picture through the light that arrives after a bounce,
which the display gathers from the records (their VPLs and its gather rays).
How fine the records must be therefore depends on the scene, not on the
picture's size: in an empty box a grid of 16 voxels gives the same picture as
one of 64 at a tenth of the solve's time, where a cluttered kitchen is still
darker at 64 than at 128. :func:`solve_scene` finds out by solving at 16, 32,
... voxels and comparing each solution with the one before it through
:func:`solution_difference`: the indirect light both give at the finer
records' surfaces, gathered by the same rays.
"""

from __future__ import annotations

import time

import numpy as np

from . import _validate
from .incidence import incidence_response
from .radiosity import Solution, SolveTuning
from .radiosity import solve as radiosity_solve
from .scene import Scene
from .traced import TracedGather
from .voxels import DEFAULT_RESOLUTION, voxelize

__all__ = [
    "AGREEMENT_SHARE",
    "CROWDED_RECORDS",
    "CROWDED_SHARE",
    "PROBE_SAMPLES",
    "RESOLVED_GROWTH",
    "START_RESOLUTION",
    "crowded_share",
    "resolutions",
    "solution_difference",
    "solve_scene",
]

#: The coarsest resolution :func:`solve_scene` tries.
START_RESOLUTION = 16

#: Cosine-distributed rays per probe of :func:`solution_difference`. The rays
#: are the same for both solutions, so what they sample of the scene cancels
#: in the difference; what is left is the records' own difference averaged
#: over these rays.
PROBE_SAMPLES = 16

#: Least growth of the record count from one resolution to the next, as a
#: share of the square of their ratio, for the coarser one to be tried.
#: Surfaces larger than the coarse voxels give about four times the records
#: at twice the resolution (3.2-3.8 in the built-in rooms: 0.8-0.95); where
#: voxels hold clutter finer than themselves the count grows more slowly
#: (1.9-2.6 in a staircase and a living room of Bitterli's: 0.5-0.65), and
#: such a coarse solve is costly (its traced passes converge slowly) and
#: rarely agrees with the finer one.
RESOLVED_GROWTH = 0.75

#: Records in a voxel from which it counts as crowded (a flat wall gives 1-2
#: a voxel, a corner 3, clutter tens to hundreds).
CROWDED_RECORDS = 4

#: Share of the finest grid's surface in crowded voxels above which the
#: coarser grids are not even voxelized: the clutter that crowds them is
#: finer still than their voxels (0.5-5% in the built-in rooms, 14-41% in
#: Bitterli's staircases and living room, 24% in the Sponza-like atrium),
#: and a voxelization of such a scene has a fixed cost (its closed objects'
#: solids) of seconds.
CROWDED_SHARE = 0.1

#: Share of the display's tolerance that two successive solutions may differ
#: by (:func:`solution_difference`) for the finer one to be kept. The
#: difference weighs every surface by its area, seen or not, and counts both
#: solutions' errors; the pictures of two such solutions differed by about
#: half of it (``docs/design.md`` §7), so the finer solution's part of the
#: picture's relMSE is about a quarter of the tolerance.
AGREEMENT_SHARE = 0.5

#: The relMSE's floor in the denominator, as :func:`voxgi.metrics.rel_mse`.
_REL_EPS = 0.01


def _reflected(sol: Solution) -> np.ndarray:
    """(N, 3) float64 reflected radiosity ``B - π E`` of each record, >= 0."""
    b = np.asarray(sol.radiosity, np.float64)
    e = np.pi * np.asarray(sol.vox.emission, np.float64)
    return np.maximum(b - e, 0.0)


def solution_difference(
    scene: Scene,
    coarse: Solution,
    fine: Solution,
    *,
    samples: int = PROBE_SAMPLES,
    seed: int = 0,
    threads: int | None = None,
) -> dict:
    """How differently two solutions of one scene light its surfaces after a bounce.

    From every reflecting front record of ``fine`` (the probes),
    ``samples`` cosine-distributed rays find the first triangle; each ray
    reads there the reflected radiosity ``B - πE`` of the record that stands
    for the hit point, once in ``coarse`` and once in ``fine``. With ``ρ``
    the probe's albedo and ``H`` the rays' mean, the light a probe reflects
    after a bounce is ``ρ H / π``: the part of a pixel's radiance the
    display takes from the solution. The difference is the relMSE of the
    coarse solution's against the fine one's, over the probes' area and the
    three channels, each relative to the probe's own radiance as
    :func:`voxgi.metrics.rel_mse` weighs a pixel (``(L² + 0.01)``):

    .. math:: D = \\frac{\\sum_x a_x \\, (\\rho_x (H_c - H_f) / \\pi)^2 / (L_x^2 + 0.01)}
              {3 \\sum_x a_x}

    It is what a picture that sees every surface in proportion to its area
    would measure between the two solutions' indirect light. Where the
    solutions' error falls as the voxel's size (first order), the finer
    solution's own error is about the difference between the two.

    Parameters
    ----------
    scene : Scene
        The scene both solutions were solved for.
    coarse, fine : Solution
        Two solutions of ``scene`` (at any two resolutions).
    samples : int
        Rays per probe (1 to 4096).
    seed : int
        Seeds the rays.
    threads : int or None
        Worker threads (None: all cores).

    Returns
    -------
    dict
        ``rel_mse`` (D), ``brightness`` (the coarse solution's reflected
        light over the fine one's, area-weighted over the probes, per
        channel), ``probes``, ``rays`` and ``seconds``.
    """
    for name, sol in (("coarse", coarse), ("fine", fine)):
        if not isinstance(sol, Solution):
            raise TypeError(f"{name}: expected voxgi.Solution, got {type(sol).__name__}")
    samples = _validate.integer(samples, "samples", low=1, high=4096)
    seed = _validate.integer(seed, "seed")
    threads = _validate.threads(threads)
    t0 = time.perf_counter()
    vox = fine.vox
    response = incidence_response(scene, vox)
    with TracedGather(scene, vox, threads=threads, response=response) as own:
        h_fine = own(_reflected(fine), samples, seed)
        rays = own.rays
    with TracedGather(scene, vox, threads=threads, source=coarse.vox, response=response) as other:
        h_coarse = other(_reflected(coarse), samples, seed)
        rays += other.rays
    area = np.asarray(vox.area, np.float64)
    albedo = np.asarray(vox.albedo, np.float64)
    probe = (area > 0) & np.any(albedo > 0, axis=1) & ~np.asarray(vox.back, bool)
    a = area[probe][:, None]
    rho = albedo[probe] / np.pi
    lc, lf = rho * h_coarse[probe], rho * h_fine[probe]
    radiance = np.asarray(fine.radiosity, np.float64)[probe] / np.pi
    rel = (lc - lf) ** 2 / (radiance**2 + _REL_EPS)
    total = float(np.sum(a)) * 3
    lit = np.sum(a * lf, axis=0)
    return {
        "rel_mse": float(np.sum(a * rel) / total) if total > 0 else 0.0,
        "brightness": [
            float(c / f) if f > 0 else 1.0 for c, f in zip(np.sum(a * lc, axis=0), lit, strict=True)
        ],
        "probes": int(np.count_nonzero(probe)),
        "rays": int(rays),
        "seconds": time.perf_counter() - t0,
    }


def crowded_share(vox) -> float:
    """The share of the records' area that lies in voxels holding more than
    :data:`CROWDED_RECORDS` records."""
    ijk = np.asarray(vox.ijk, np.int64)
    if not len(ijk):
        return 0.0
    ijk = ijk - ijk.min(axis=0)
    dims = ijk.max(axis=0) + 1
    key = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    _, inverse, count = np.unique(key, return_inverse=True, return_counts=True)
    area = np.asarray(vox.area, np.float64)
    total = float(area.sum())
    crowded = count[inverse.reshape(-1)] > CROWDED_RECORDS
    return float(area[crowded].sum()) / total if total > 0 else 0.0


def resolutions(max_resolution: int, start: int = START_RESOLUTION) -> list[int]:
    """The resolutions :func:`solve_scene` tries: ``start``, twice it, ...,
    below ``max_resolution``, then ``max_resolution`` itself.

    >>> resolutions(64), resolutions(48), resolutions(12)
    ([16, 32, 64], [16, 32, 48], [12])
    """
    out, r = [], int(start)
    while r < max_resolution:
        out.append(r)
        r *= 2
    out.append(int(max_resolution))
    return out


def solve_scene(
    scene: Scene,
    *,
    tol: float = 1e-3,
    max_resolution: int = DEFAULT_RESOLUTION,
    radius: int | None = None,
    threads: int | None = None,
    progress: bool = True,
    executor=None,
    tuning: SolveTuning | None = None,
) -> Solution:
    """Voxelize and solve ``scene`` at the coarsest resolution its picture needs.

    Voxelizes at ``max_resolution`` and, unless more than
    :data:`CROWDED_SHARE` of that grid's surface lies in crowded voxels, at
    each coarser one of :func:`resolutions` (16, 32, ...). From the coarsest
    resolution on which the records
    grow about as the square of the resolution (:data:`RESOLVED_GROWTH`:
    the surfaces are larger than its voxels), it solves each in turn with
    the solve this tolerance needs (``tuning``; None:
    :meth:`SolveTuning.for_picture`, :func:`voxgi.solve`'s defaults at
    the default tolerance and under it) and stops at the first solution whose
    :func:`solution_difference` from the one before is at most
    ``AGREEMENT_SHARE · tol``: the two light the surfaces alike, so a finer
    grid would not change the picture at that tolerance. Where every level
    is solved, the coarser ones cost about a third of the finest.

    Parameters
    ----------
    scene : Scene
    tol : float
        The picture's tolerance (relMSE), as :func:`voxgi.render`'s ``tol``.
    max_resolution : int
        The finest resolution tried (voxels along the scene's longest side).
    radius, threads, progress
        As :func:`voxgi.solve`.
    tuning : SolveTuning or None
        As :func:`voxgi.solve`; None: ``SolveTuning.for_picture(tol)``.
    executor : LineExecutor or None
        Where the passes run (:func:`voxgi.distributed.executor`).

    Returns
    -------
    Solution
        The solution kept. Its ``stats["resolution"]`` holds ``chosen``,
        ``max_resolution``, ``tol``, ``crowded_share`` (of the finest grid,
        :func:`crowded_share`), ``growth`` (the record count's growth from
        each resolution to the next, over the square of their ratio; empty
        where the finest grid is crowded and no other was voxelized),
        ``levels`` (per resolution solved: ``resolution``, ``records``,
        ``voxelize_seconds``, ``solve_seconds`` and, from the second on,
        ``difference`` from the one before, its ``brightness`` and
        ``difference_seconds``), ``voxelize_seconds`` (every grid),
        ``reason`` and ``solve_tuning`` (the tuning's ``tol`` and
        ``traced_samples``); ``stats["skipped"]`` names the resolutions
        left out.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected voxgi.Scene, got {type(scene).__name__}")
    tol = _validate.real(tol, "tol", low=0.0, low_open=True)
    max_resolution = _validate.integer(max_resolution, "max_resolution", low=2)
    if tuning is None:
        tuning = SolveTuning.for_picture(tol)
    tried = resolutions(max_resolution)
    limit = AGREEMENT_SHARE * tol
    # The finest grid first, then, unless it is crowded, the coarser ones:
    # their record counts say from which resolution on the surfaces are
    # resolved (a fraction of the solves' time where they are; a scene's
    # fixed cost per voxelization, such as its closed objects' solids, where
    # the finest grid already says they are not).
    grids, voxelize_seconds = [None] * len(tried), [0.0] * len(tried)
    for i in reversed(range(len(tried))):
        t0 = time.perf_counter()
        grids[i] = voxelize(scene, tried[i], threads=threads, progress=progress)
        voxelize_seconds[i] = time.perf_counter() - t0
        if i == len(tried) - 1:
            crowded = crowded_share(grids[i])
            if crowded > CROWDED_SHARE:
                break
    growth = [
        len(b) / max(len(a), 1) / (rb / ra) ** 2
        for a, b, ra, rb in zip(grids[:-1], grids[1:], tried[:-1], tried[1:], strict=True)
        if a is not None
    ]
    first = len(tried) - 1
    while first > 0 and growth and growth[first - 1] >= RESOLVED_GROWTH:
        first -= 1
    levels, prev, sol, agreed = [], None, None, False
    for i in range(first, len(tried)):
        t0 = time.perf_counter()
        sol = radiosity_solve(
            grids[i],
            radius=radius,
            threads=threads,
            executor=executor,
            progress=progress,
            tuning=tuning,
        )
        level = {
            "resolution": tried[i],
            "records": len(grids[i]),
            "voxelize_seconds": voxelize_seconds[i],
            "solve_seconds": time.perf_counter() - t0,
        }
        levels.append(level)
        if prev is not None:
            d = solution_difference(scene, prev, sol, threads=threads)
            level["difference"] = d["rel_mse"]
            level["brightness"] = d["brightness"]
            level["difference_seconds"] = d["seconds"]
            agreed = d["rel_mse"] <= limit
            if agreed:
                break
        prev = sol
    chosen = levels[-1]["resolution"]
    if len(tried) == 1:
        reason = f"resolution {chosen}: the only one allowed (max_resolution {max_resolution})"
    elif not growth:
        reason = (
            f"resolution {chosen}: {crowded:.0%} of its surface lies in voxels of more than "
            f"{CROWDED_RECORDS} records (over {CROWDED_SHARE:.0%}): clutter finer than the "
            "coarser voxels, which were not voxelized"
        )
    elif len(levels) == 1:
        reason = (
            f"resolution {chosen}: from resolution {tried[-2]} the records grow "
            f"{growth[-1]:.2f} times the square of the resolutions' ratio (under "
            f"{RESOLVED_GROWTH}): surfaces finer than the coarser voxels"
        )
    else:
        word = "at most" if agreed else "more than"
        reason = (
            f"resolution {chosen}: its solution differs from resolution "
            f"{levels[-2]['resolution']}'s by relMSE {levels[-1]['difference']:.2e}, "
            f"{word} {AGREEMENT_SHARE} x tol ({limit:.2e})"
        )
    sol.stats["resolution"] = {
        "chosen": chosen,
        "max_resolution": max_resolution,
        "tol": tol,
        "growth": growth,
        "crowded_share": crowded,
        "levels": levels,
        "voxelize_seconds": float(sum(voxelize_seconds)),
        "reason": reason,
        "solve_tuning": {"tol": tuning.tol, "traced_samples": tuning.traced_samples},
    }
    left = [r for r in tried if r != chosen and r not in [lv["resolution"] for lv in levels]]
    if left:
        skipped = sol.stats.setdefault("skipped", {})
        skipped["resolutions"] = (
            f"{', '.join(map(str, left))} not solved: {reason.split(': ', 1)[1]}"
        )
    return sol
