"""The reflected light finished by passes of rays against the exact
triangles (``docs/design.md`` §5)."""

from __future__ import annotations

import time
import warnings

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order

from ..traced import TracedGather, stacked_records, transport_bytes
from ..voxels import available_memory
from .problem import Problem

__all__ = ["traced_bounces"]

#: At most this many traced passes of fresh rays; each shrinks the change by
#: about the albedo, so 32 leave 0.8^32 ≈ 8e-4 of it at ρ = 0.8 before the tail.
_TRACED_PASSES = 32

#: The share of the remaining change that the passes left before the cap
#: would keep, from which they are not run: they would change the answer by
#: less than what is left, and the tail (:func:`_tail`) extrapolates the
#: rest in any case (``docs/design.md`` §5).
_FUTILE_SHARE = 0.5

#: Passes through the kept rays over which the measured ratio must hold
#: still, twice over, before the geometric tail is trusted to stand for the
#: rest (:func:`traced_bounces`).
_STEADY_PASSES = 8

#: At most this many passes through the kept rays (a product with a sparse
#: matrix each, milliseconds): 1024 leave 0.99^1024 ≈ 3e-5 of the change of a
#: mode of ratio 0.99 (a room of white walls) before the tail.
_KEPT_PASSES = 1024


def why_not_traced(p: Problem) -> str | None:
    """Why the lines alone carry the reflected light though traced passes were
    asked for (None: the passes run)."""
    if getattr(p.vox, "scene", None) is None:
        return "the records carry no scene (vox.scene is None)"
    if p.opt.max_bounces is not None:
        return f"max_bounces={p.opt.max_bounces} fixes the bounces the lines gather"
    if p.limit == 0:
        return "all albedos are zero"
    return None


#: Rays per record of the pass that measures the mean albedo each record
#: sees (:func:`_dominant_ratio`); its noise averages out over the records.
_ALBEDO_SAMPLES = 4


def _dominant_ratio(p: Problem, seen_albedo: np.ndarray, mode: np.ndarray | None) -> np.ndarray:
    """Per channel, the ratio by which the slowest-fading part of the
    changes shrinks a pass (``docs/design.md`` §5).

    For a nonnegative ``v`` the power of ``ρ T v`` is exactly
    ``Σ ΔA_j v_j g_j``, ``g_j = (T ρ)_j`` the mean albedo that record j's
    rays land on (reciprocity, ``ΔA_i F_ij = ΔA_j F_ji``); so the ratio of
    the lines' last positive update ``mode``, close to the slowest mode,
    weighs ``g`` by where that mode lives. ``g`` itself comes from one pass of
    rays; in a closed room of one albedo ρ every ray lands on ρ, and the
    ratio is ρ exactly.
    """
    if mode is None:
        mode = p.rho
    w = p.area[:, None] * np.maximum(mode, 0.0)
    den = w.sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = np.where(den > 0, (w * seen_albedo).sum(axis=0) / den, 0.0)
    return lam


def _tail(p: Problem, d: np.ndarray, lam: np.ndarray, mode: np.ndarray | None) -> np.ndarray:
    """The rest of the series after the change ``d``: its power times
    ``λ / (1 − λ)``, per channel, in the shape of the slowest mode, but
    nowhere more than twice a record's own ``|d|`` times ``λ / (1 − λ)``.

    What is left after a few passes is that mode (the parts that fade faster
    are gone by then), so the tail takes its shape from the lines' last
    positive update rather than from ``d``: a junction record whose own
    correction is still fading fast, or the noise of the last pass, is not
    multiplied by ``λ / (1 − λ)``. Where the lines' mode holds light that the
    rays' changes do not (what the lines carried through a wall thinner
    than a voxel), the record's own change bounds it.
    """
    area = p.area[:, None]
    if mode is None:
        return d * (lam / (1 - lam))
    shape = np.maximum(mode, 0.0)
    norm = (area * shape).sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(norm > 0, (area * d).sum(axis=0) / norm, 0.0)
    smooth = scale * shape
    bounded = np.sign(smooth) * np.minimum(np.abs(smooth), 2.0 * np.abs(d))
    return np.where(norm > 0, bounded, d) * (lam / (1 - lam))


#: A record whose kept rays carry at least ``1 − _TRAP_LOSS`` of its
#: reflected light back onto records of such a set belongs to a trap
#: (:func:`trapped_records`).
_TRAP_LOSS = 0.02

#: Largest record albedo up to which the lines stop early (at
#: :data:`~voxgi.radiosity.iteration.LINES_TOL_FACTOR` times ``tol``) ahead
#: of kept rays: no record of a lower albedo can return ``1 − _TRAP_LOSS``
#: of its light; above it the kept rays may turn out trapped, and the fresh
#: passes that then follow should start from lines converged to ``tol``.
_KEPT_ALBEDO_MAX = 1.0 - _TRAP_LOSS


def unreached_records(lit: np.ndarray, matrix: tuple) -> np.ndarray:
    """(N,) bool: the records that no chain of the kept rays links to a
    ``lit`` record (one with direct light), where ``matrix`` (row_ptr,
    column, weight) holds, per record, the records its rays read. Light
    reaches a record only along such a chain, so whatever light the lines
    left on an unreached record leaked there through a wall thinner than a
    voxel (``docs/design.md`` §5)."""
    row_ptr, column, _ = matrix
    n = len(row_ptr) - 1
    # an edge from each record read to its reader, and from a source node
    # (n) to every lit record
    reader = np.repeat(np.arange(n, dtype=np.int64), np.diff(row_ptr))
    lit_ids = np.flatnonzero(lit)
    src = np.concatenate([np.asarray(column, np.int64), np.full(len(lit_ids), n)])
    dst = np.concatenate([reader, lit_ids])
    graph = csr_matrix((np.ones(len(src), bool), (src, dst)), shape=(n + 1, n + 1))
    reached = np.zeros(n + 1, bool)
    reached[breadth_first_order(graph, n, directed=True, return_predecessors=False)] = True
    return ~reached[:n]


def trapped_records(rho: np.ndarray, matrix: tuple) -> np.ndarray:
    """The records of the largest set in which every record's kept rays
    return at least ``1 − 2%`` of its reflected light to the set, in some
    channel: ``ρ_i Σ_{j∈S} T̂_ij ≥ 0.98`` (``docs/design.md`` §5).

    The kept operator ``ρ T̂`` loses at every pass only what its sampled
    rays lose. Where surfaces of albedo near 1 face each other (the inside
    of a sofa of albedo 1, lit through its gaps, in Bitterli's living room)
    every kept ray of a record can land on the others; such a set keeps its
    light forever, or nearly, however fast the true light leaves it (the
    living room came out 1.6 times too bright, the sofa glowing). The set is
    found by pruning: start from every record that returns 98% of its light
    to any record, and drop, until none is left to drop, each that no longer
    returns 98% to those kept. Empty: every set of records holds one that
    loses at least 2% a pass. Vectorized over the matrix's entries; a
    pruning that has not settled after 256 rounds counts what is left.
    """
    row_ptr, column, weight = matrix
    n = len(row_ptr) - 1
    rho = np.asarray(rho, np.float64)
    keep_at = 1.0 - _TRAP_LOSS
    if not np.any(rho >= keep_at):
        return np.zeros(n, bool)
    rows = np.repeat(np.arange(n), np.diff(row_ptr))
    trapped = np.zeros(n, bool)
    for c in range(3):
        returned = rho[rows, c] * weight[:, c]
        inside = np.bincount(rows, returned, minlength=n) >= keep_at
        for _ in range(256):
            kept = np.bincount(rows, returned * inside[column], minlength=n) >= keep_at
            kept &= inside
            if np.array_equal(kept, inside):
                break
            inside = kept
        trapped |= inside
    return trapped


def _steady(history: list, lam: np.ndarray, lam_bound: float, size, Btot: float, tol: float):
    """Whether the kept passes' changes fade steadily enough for the tail
    ``d λ / (1 − λ)`` to stand for the rest of the series within ``tol``.

    Through the same rays every pass the change becomes the slowest mode,
    and its tail is then exact but for the error of λ, which ``1 / (1 − λ)``
    magnifies: the ratio's spread over the last :data:`_STEADY_PASSES`
    passes plus its drift from the window before (a slower mode still
    taking over), over ``1 − λ``, bounds that share of what remains.
    """
    if not np.all(lam < lam_bound):
        return False
    w = _STEADY_PASSES
    last, before = np.array(history[-w:]), np.array(history[-2 * w : -w])
    drift = np.abs(last.mean(axis=0) - before.mean(axis=0))
    doubt = (last.max(axis=0) - last.min(axis=0) + drift) / (1 - lam)
    return float(np.sum(size * lam / (1 - lam) * doubt)) / Btot < tol


def keeps_rays(p: Problem) -> tuple[bool, str | None]:
    """Whether the first traced pass's rays are kept for the later passes
    (``traced_cache``, within its memory budget), and why not. Kept rays
    found trapped (:func:`trapped_records`) are dropped after that pass."""
    opt = p.opt
    if opt.traced_cache is False:
        return False, "traced_cache=False"
    need = transport_bytes(p.vox, opt.traced_samples)
    budget = opt.cache_cap
    if budget is None and opt.traced_cache is None:
        budget = available_memory() // 4
    if budget is not None and need > budget:
        return False, (
            f"the first pass's rays need {need / 2**20:.0f} MiB, over the budget of "
            f"{budget / 2**20:.0f} MiB (max_cache_bytes): every pass traced fresh rays"
        )
    return True, None


def lines_stop_early(p: Problem) -> bool:
    """Whether the lines may stop at ``LINES_TOL_FACTOR`` times ``tol``:
    where the rays will be kept and no albedo is above
    :data:`_KEPT_ALBEDO_MAX` (kept rays that may turn out trapped)."""
    rho_max = float(np.max(p.rho)) if np.size(p.rho) else 0.0
    return keeps_rays(p)[0] and rho_max <= _KEPT_ALBEDO_MAX


def traced_bounces(
    p: Problem, Hd: np.ndarray, R: np.ndarray, mode: np.ndarray | None = None
) -> np.ndarray:
    """The reflected radiosity after passes of rays against the exact
    triangles, started from the lines' answer ``R`` (``docs/design.md`` §5).

    The first pass gathers all of ``R``: ``R_1 = ρ (H_d + H_m + T R_0)``,
    ``H_m`` the emitters' light that its rays read beyond where they land,
    through a conductor's lobe or from a stacked sheet
    (:class:`voxgi.traced.TracedGather`), which the direct light's shadow
    rays cannot find. Each later
    pass carries only the last change, ``d_{k+1} = ρ T d_k``, so its noise
    shrinks with the change. The changes fade, after a few passes, by the
    ratio λ of the slowest mode (per channel; :func:`_dominant_ratio`, from
    the lines' last positive update ``mode``, or the larger measured ratio
    of the changes, at most the largest albedo); once, after two passes at
    least, the remaining error of the geometric series ``Σ_c r_c λ_c / (1 − λ_c)``
    is under ``tol``, its tail ``d λ / (1 − λ)`` is added.

    Where they fit (``traced_cache``, :func:`keeps_rays`), the first pass's
    rays are kept as a sparse matrix ``T̂`` and every later pass is
    ``d_{k+1} = ρ T̂ d_k`` with those same rays (up to :data:`_KEPT_PASSES`
    passes); otherwise each later pass traces fresh rays, a quarter as many
    (up to :data:`_TRACED_PASSES`).
    """
    opt = p.opt
    if opt.indirect_light != "traced":
        return R
    why = why_not_traced(p)
    if why is not None:
        p.stats["skipped"]["traced_bounces"] = why + ": the lines alone carried the reflected light"
        return R
    t = time.perf_counter()
    area = p.area[:, None]
    lines_power = (R * area).sum(axis=0)
    R_lines = R
    later = max(16, opt.traced_samples // 4)
    lam_bound = float(min(max(float(p.rho.max()), 0.5), 1 - 1e-6))
    residuals = []
    beyond = None
    n_unreached, leaked = None, None
    keep, why_fresh = keeps_rays(p)
    if why_fresh is not None:
        p.stats["skipped"]["traced_cache"] = why_fresh
    cap = _KEPT_PASSES if keep else _TRACED_PASSES
    matrix = {}
    with TracedGather(
        p.vox.scene, p.vox, threads=opt.threads, response=p.response, go_on=True
    ) as trace:
        sheets = trace.sheets
        if not sheets and (p.vox.scene.lights or p.vox.scene.environment is not None):
            if stacked_records(p.vox).any():
                p.stats["skipped"]["stacked_sheets"] = (
                    "the scene has point lights or an environment, whose light a ray's "
                    "bounce at a stacked sheet cannot find: rays read those records' means"
                )
        seen_albedo = trace(np.asarray(p.rho, np.float64), _ALBEDO_SAMPLES, seed=0)
        lam_mode = np.minimum(_dominant_ratio(p, seen_albedo, mode), lam_bound)
        t_first = time.perf_counter()
        if trace.follows:
            # the emitters that rays find past mirrors and stacked sheets,
            # which no shadow ray of the direct light reaches
            gathered, H_m = trace(R, opt.traced_samples, seed=1, keep=keep, emitted=p.E)
            beyond = (p.rho * H_m * area).sum(axis=0).tolist()
        else:
            gathered, H_m = trace(R, opt.traced_samples, seed=1, keep=keep), 0.0
        R_new = p.rho * (Hd + H_m + gathered)
        if keep and trace.matrix is not None:
            # The lines' light on records no ray chain links to direct light
            # leaked there through thin walls: nothing would remove it but
            # the passes' slow fading among those records.
            lit = np.any(Hd > 0, axis=1) | np.any(np.asarray(H_m) > 0, axis=-1)
            unreached = unreached_records(lit, trace.matrix)
            n_unreached = int(np.count_nonzero(unreached))
            if n_unreached:
                leaked = (np.where(unreached[:, None], R, 0.0) * area).sum(axis=0).tolist()
                R = np.where(unreached[:, None], 0.0, R)
                R_new = p.rho * (Hd + H_m + trace.apply(R))
        t_first = time.perf_counter() - t_first
        if keep and trace.matrix is not None:
            trapped = trapped_records(p.rho, trace.matrix)
            if trapped.any():
                keep = False
                trace.matrix = None
                cap = _TRACED_PASSES
                p.stats["skipped"]["traced_cache"] = (
                    f"{int(trapped.sum())} records of albedo near 1 return over "
                    f"{1 - _TRAP_LOSS:.0%} of their light to each other through the kept rays, "
                    "which would keep it there: every later pass traced fresh rays"
                )
        if keep and trace.matrix is not None:
            matrix = {
                "entries": len(trace.matrix[1]),
                "bytes": int(sum(a.nbytes for a in trace.matrix)),
            }
        t_later = time.perf_counter()
        d = R_new - R
        R = R_new
        Btot = float(np.sum(area * np.abs(p.E + R)))
        lam = lam_mode
        size = None
        done = False
        steady = False
        stalls = 0
        history = []
        while Btot > 0:
            size, previous = np.sum(area * np.abs(d), axis=0), size
            residuals.append(float(size.sum()) / Btot)
            if previous is not None:
                # a mode the lines' update missed shows in the changes' own ratio
                with np.errstate(divide="ignore", invalid="ignore"):
                    measured = np.where(previous > 0, size / previous, 0.0)
                lam = np.clip(np.maximum(lam_mode, measured), 0.0, lam_bound)
                history.append(measured)
            # At least two passes: the first one's change is mostly local (a
            # slit, a junction) and noisy, and its tail would amplify both.
            remaining = float(np.sum(size * lam / (1 - lam))) / Btot
            done = len(residuals) >= 2 and remaining < opt.tol
            if keep and not done and len(history) >= 2 * _STEADY_PASSES:
                steady = _steady(history, lam, lam_bound, size, Btot, opt.tol)
                done = steady
            # Passes that cannot halve what remains before the cap ends them
            # anyway are not run: a mode fading by 0.97 a pass or slower (the
            # light passed round the crevices of a sofa of albedo 1) keeps
            # over half of its change through 20 more. Two passes in a row
            # must say so, as the measured ratio is noisy.
            futile = float(np.max(lam)) ** (cap - len(residuals)) > _FUTILE_SHARE
            stalls = stalls + 1 if futile and len(residuals) >= 3 else 0
            if done or stalls >= 2 or len(residuals) >= cap:
                break
            if keep:
                d = p.rho * trace.apply(d)
            else:
                d = p.rho * trace(d, later, seed=len(residuals) + 1)
            R = R + d
        if len(residuals) >= 2:
            # once steady, the change itself has the slowest mode's shape
            R = R + _tail(p, d, lam, None if steady else mode)
        rays = trace.rays
        t_later = time.perf_counter() - t_later
    if not np.all(np.isfinite(R)):
        warnings.warn(
            "solve: the traced bounces gave a non-finite radiosity; returning the lines' answer",
            RuntimeWarning,
            stacklevel=3,
        )
        p.stats["skipped"]["traced_bounces"] = "their answer was not finite"
        return R_lines
    # The changes carry the first pass's noise with either sign; where they
    # outweigh a dim record's light the sum dips below zero.
    negative = np.any(R < 0, axis=1)
    clamped = (np.minimum(R, 0.0) * area).sum(axis=0)
    R = np.maximum(R, 0.0)
    p.seconds["traced"] = time.perf_counter() - t
    with np.errstate(divide="ignore", invalid="ignore"):
        change = np.where(lines_power > 0, (R * area).sum(axis=0) / lines_power - 1, 0.0)
    p.stats["traced"] = {
        "passes": len(residuals),
        "rays": int(rays),
        # later passes through the first pass's rays (a sparse matrix of
        # "entries" record pairs, "bytes"), or fresh rays
        "kept": bool(keep),
        **matrix,
        "converged": bool(done),
        # stopped before the cap because the passes left could not halve
        # the remaining change (_FUTILE_SHARE)
        "stalled": bool(not done and stalls >= 2),
        "seconds": {"first": t_first, "later": t_later},
        "samples": [opt.traced_samples, 0 if keep else later],
        "residuals": residuals,
        # the ratio of the tail (the largest channel's), per channel, and
        # that of the lines' slowest mode under the traced rays
        "ratio": float(np.max(lam)),
        "ratios": lam.tolist(),
        "mode_ratios": lam_mode.tolist(),
        "reflected_power_change": change.tolist(),
        # records whose sum came out below zero, set to zero, and the power
        # that adds (0.01-0.06% of the reflected power in the built-in interiors)
        "negative_records": int(np.count_nonzero(negative)),
        "negative_power": (-clamped).tolist(),
        # the reflected power, per channel, of the emitters' light that the
        # first pass's rays read beyond where they land, through a
        # conductor's lobe or from a stacked sheet (None: neither is here)
        "emitters_beyond": beyond,
        # records of stacks of sheets finer than a voxel, where a ray that
        # lands bounces once more (docs/design.md §5)
        "stacked_records": sheets,
        # records no chain of the first pass's rays links to direct light,
        # and the lines' reflected power on them (leaked through thin
        # walls), set to zero; None where the first pass's rays were not kept
        "unreached_records": n_unreached,
        "leaked_power": leaked,
    }
    return R
