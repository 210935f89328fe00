"""The reflected light finished by passes of rays against the exact
triangles (``docs/design.md`` §5)."""

from __future__ import annotations

import itertools
import time
import warnings

import numpy as np

from ..traced import TracedGather
from .problem import Problem

__all__ = ["traced_bounces"]

#: At most this many traced passes; each shrinks the change by about the
#: albedo, so 32 leave 0.8^32 ≈ 8e-4 of it at ρ = 0.8 before the tail.
_TRACED_PASSES = 32


def _why_not_traced(p: Problem) -> str | None:
    """Why the lines alone carry the reflected light though traced passes were
    asked for (None: the passes run)."""
    if getattr(p.vox, "scene", None) is None:
        return "the records carry no scene (vox.scene is None)"
    if p.opt.max_bounces is not None:
        return f"max_bounces={p.opt.max_bounces} fixes the bounces the lines gather"
    if p.limit == 0:
        return "all albedos are zero"
    return None


def traced_bounces(p: Problem, Hd: np.ndarray, R: np.ndarray) -> np.ndarray:
    """The reflected radiosity after passes of rays against the exact
    triangles, started from the lines' answer ``R`` (``docs/design.md`` §5).

    The first pass gathers all of ``R``: ``R_1 = ρ (H_d + T R)``. Each later
    pass carries only the last change, ``d_{k+1} = ρ T d_k``, so its noise
    shrinks with the change; once, after two passes at least, the remaining
    error of the geometric series, ``r λ / (1 − λ)`` as for the lines, is
    under ``tol``, its tail ``d λ / (1 − λ)`` is added.
    """
    opt = p.opt
    if opt.indirect_light != "traced":
        return R
    why = _why_not_traced(p)
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
    with TracedGather(p.vox.scene, p.vox, threads=opt.threads) as trace:
        R_new = p.rho * (Hd + trace(R, opt.traced_samples, seed=1))
        d = R_new - R
        R = R_new
        Btot = float(np.sum(area * np.abs(p.E + R)))
        lam = lam_bound
        while Btot > 0:
            residuals.append(float(np.sum(area * np.abs(d))) / Btot)
            if len(residuals) >= 2 and min(residuals[-3:-1]) > 0:
                # the larger of the last two ratios: the first pass's noise
                # shrinks faster than the light still on its way
                last = residuals[-3:]
                lam = min(max(b / a for a, b in itertools.pairwise(last)), lam_bound)
            # At least two passes: the first one's change is mostly local (a
            # slit, a junction) and small against the whole, so the rule
            # waits for the ratio it implies to be measured.
            done = len(residuals) >= 2 and residuals[-1] * lam / (1 - lam) < opt.tol
            if done or len(residuals) >= _TRACED_PASSES:
                break
            d = p.rho * trace(d, later, seed=len(residuals) + 1)
            R = R + d
        if len(residuals) >= 2:
            R = R + d * (lam / (1 - lam))
        rays = trace.rays
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
        "samples": [opt.traced_samples, later],
        "residuals": residuals,
        "ratio": lam,
        "reflected_power_change": change.tolist(),
        # records whose sum came out below zero, set to zero, and the power
        # that adds (0.01-0.06% of the reflected power in the built-in interiors)
        "negative_records": int(np.count_nonzero(negative)),
        "negative_power": (-clamped).tolist(),
    }
    return R
