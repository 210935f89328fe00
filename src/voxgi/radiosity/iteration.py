"""The gathering iteration of the reflected radiosity (``docs/design.md`` §5)."""

from __future__ import annotations

import itertools
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from .. import _progress
from .linesystem import Gatherer
from .problem import Problem
from .traced_passes import lines_stop_early, why_not_traced

#: Where traced passes through kept rays follow the lines, the lines stop
#: at this many times ``tol``: the passes, milliseconds each, carry the
#: slowest mode from there, and their answer does not depend on where the
#: lines stopped (``docs/design.md`` §5). 100 rather than 10: the same passes'
#: answers within 2e-4 of the power, for a quarter of the living room's solve
#: (docs/performance.md, "The lines' tolerance under kept passes").
LINES_TOL_FACTOR = 100.0

#: Where traced passes with fresh rays follow the lines, the lines stop at
#: ``tol`` but never above this: the passes' stopping rule reads the slowest
#: mode's ratio from the lines' last updates, which a looser stop leaves low,
#: and the passes, each as costly as the first, then run on before they
#: call themselves futile (Bitterli's kitchen, ``tol`` 1e-2: ratio 0.974
#: against 0.982, 8 passes and 17.7 s against 4 and 12.6 s).
FRESH_LINES_TOL = 1e-3


def passes_follow(p: Problem) -> bool:
    """Whether traced passes finish the reflected light after the lines
    (``indirect_light="traced"``, a scene to trace, no ``max_bounces``)."""
    return p.opt.indirect_light == "traced" and why_not_traced(p) is None


def lines_tol(p: Problem) -> float:
    """The tolerance the lines stop at: ``tol``, or where traced passes follow
    (``indirect_light="traced"``, a scene to trace, no ``max_bounces``), the
    study tuning's ``lines_tol``, by default, where the passes will keep
    their rays and no albedo is near 1 (:func:`lines_stop_early`),
    :data:`LINES_TOL_FACTOR` times ``tol``, and otherwise ``tol`` but at
    most :data:`FRESH_LINES_TOL`."""
    opt = p.opt
    if not passes_follow(p):
        return opt.tol
    if opt.lines_tol is not None:
        return opt.lines_tol
    if lines_stop_early(p):
        return LINES_TOL_FACTOR * opt.tol
    return min(opt.tol, FRESH_LINES_TOL)


__all__ = ["State", "iterate"]


#: The float32 values sent along the lines round every record's radiosity
#: to about 6e-8: a residual under this that makes no new low for
#: :data:`_FLOOR_ITERATIONS` iterations is their rounding, not the iteration's.
_FLOOR_RESIDUAL = 1e-6
_FLOOR_ITERATIONS = 10
#: The two-iteration ratios of the residuals the lines' stopping rule takes
#: the largest of.
_RATIO_WINDOW = 4
#: Iterations without a new lowest residual after which the iteration has
#: stalled for good.
_STALL_ITERATIONS = 50


class _Extrapolator:
    """Geometric-tail extrapolation of a linear fixed-point iteration.

    Once successive updates ``d_k = R_{k+1} − R_k`` shrink by a steady ratio
    λ (per channel, from ``<d_k, d_{k-1}> / <d_{k-1}, d_{k-1}>``), the rest of
    the series is ``d_k λ / (1 − λ)`` (the ambient term of progressive
    radiosity; Aitken's Δ²), added at once (``docs/design.md`` §5).
    """

    def __init__(self, weights: np.ndarray, rel_tol: float = 0.02):
        self.w = weights[:, None]
        self.prev = None
        self.lam_prev = None
        self.rel_tol = rel_tol
        self.count = 0
        self.factor = None

    def __call__(self, d: np.ndarray) -> np.ndarray | None:
        """Given the latest update d (N, 3), return the tail to add, or None."""
        prev, self.prev = self.prev, d
        if prev is None:
            return None
        den = np.sum(self.w * prev * prev, axis=0)
        num = np.sum(self.w * d * prev, axis=0)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            lam = np.where(den > 0, num / den, 0.0)
        lam_prev, self.lam_prev = self.lam_prev, lam
        if lam_prev is None:
            return None
        ok = (lam > 0) & (lam < 1) & (np.abs(lam - lam_prev) <= self.rel_tol * (1 - lam))
        active = den > 0
        if not np.all(ok | ~active) or not np.any(active):
            return None
        # after a jump the next differences start a new geometric run
        self.prev = None
        self.lam_prev = None
        with np.errstate(over="ignore", invalid="ignore"):
            factor = np.where(active, lam / (1 - lam), 0.0)
            tail = d * factor
        if not np.all(np.isfinite(tail)):
            return None  # a ratio too close to 1 for the float range: no jump
        self.count += 1
        self.factor = factor
        return tail


@dataclass
class State:
    """The iterate and what the iteration has gathered so far."""

    R: np.ndarray  # reflected radiosity B - E
    Hg: np.ndarray  # gathered irradiance
    dk: np.ndarray  # the last update R_k - R_{k-1}
    vis: np.ndarray | None = None
    it: int = 0
    gather_rays: int = 0
    lines_walked: int = 0
    seconds: float = 0.0
    residuals: list = field(default_factory=list)
    stopped: str | None = None
    stalled: bool = False  # stopped because the residual made no new low
    # The last update before the first tail: from the nonnegative direct
    # light, a nonnegative vector turning into the slowest-fading mode, whose
    # ratio the traced passes measure (traced_passes._dominant_ratio).
    mode: np.ndarray | None = None


class _Iteration:
    """Gathering of the reflected radiosity ``R = B − E`` (``docs/design.md`` §5).

    Jacobi, ``R_{k+1} = ρ (H_d + M R_k / S)``, with the geometric tail added
    once the updates shrink steadily (:class:`_Extrapolator`). The same
    iteration in correction form, ``ΔR_{k+1} = ρ M ΔR_k / S``, propagates
    only the last update, which float32 rounds relative to its own size: it
    is used with coarser later bounces (a fixed-point iteration would
    converge to the coarse operator's answer) and once the Jacobi residual
    sits at the rounding of the values sent (albedos near 1). In correction
    form the tail, once added, stands for every bounce left.
    """

    def __init__(self, p: Problem, gather: Gatherer, Hd: np.ndarray):
        self.p, self.gather, self.Hd = p, gather, Hd
        R = p.rho * Hd
        self.s = State(R=R, Hg=np.zeros((p.n, 3)), dk=R.copy(), mode=R)
        self.corrections = p.lds is not None
        self.extrap = _Extrapolator(p.area)
        rmax = float(p.rho.max())
        self.lam_bound = float(min(max(rmax, 0.5), 1 - 1e-6))
        self.best = (float("inf"), 0)  # lowest residual and its iteration
        # ratios res_k / res_{k-1} of the residuals (None after a tail jump,
        # whose next update is no step of the series)
        self.ratios: list = []
        self.tol = lines_tol(p)
        if self.tol != p.opt.tol:
            p.stats["lines_tol"] = self.tol

    def step(self) -> tuple:
        """One gathering pass: (R_new, Hg_new, update, residual, h_inc, use_later), not kept."""
        p, s = self.p, self.s
        use_later = p.lds is not None and s.it >= p.opt.later_after
        ds = p.lds if use_later else p.gds
        S = p.S["later"] if use_later else p.S["gather"]
        fams = np.arange(len(ds.families), dtype=np.int64)
        t = time.perf_counter()
        want_vis = s.vis is None and not use_later
        sums, v, nl = self.gather(
            ds, p.twins.send(s.dk if self.corrections else s.R), fams, want_vis
        )
        s.lines_walked += nl
        if want_vis:
            s.vis = v
        with np.errstate(over="ignore", invalid="ignore"):  # run() checks finiteness
            if self.corrections:
                h_inc = sums / S[:, None]
                Hg = s.Hg + h_inc
                R_new = s.R + p.rho * h_inc
            else:
                h_inc = None
                Hg = sums / S[:, None]
                R_new = p.rho * (self.Hd + Hg)
            s.seconds += time.perf_counter() - t
            s.gather_rays += p.n * len(ds.families)
            d = R_new - s.R
            Btot = np.sum(p.area[:, None] * np.abs(p.E + R_new))
            res = float(np.sum(p.area[:, None] * np.abs(d)) / Btot) if Btot > 0 else 0.0
        return R_new, Hg, d, res, h_inc, use_later

    def run(self, bar) -> State:
        """Iterate until the stopping rule, the iteration limit, a stall or a
        non-finite iterate; return the last finite state."""
        s = self.s
        first = None  # the stopping quantity after the first iteration
        jumps = self.extrap.count
        while s.it < self.p.limit:
            R_new, Hg, d, res, h_inc, use_later = self.step()
            if not (np.all(np.isfinite(R_new)) and np.isfinite(res)):
                s.stopped = f"iteration {s.it + 1} was not finite"
                break
            s.R, s.Hg, s.dk = R_new, Hg, (self.p.rho * h_inc if self.corrections else d)
            if self.extrap.count == 0:
                s.mode = s.dk
            s.it += 1
            if s.residuals:
                after_jump = self.extrap.count != jumps
                last = s.residuals[-1]
                self.ratios.append(None if after_jump or last <= 0 else res / last)
            jumps = self.extrap.count
            s.residuals.append(res)
            if bar is not None:  # the way to tol on a log scale: the quantity falls geometrically
                lam = self.ratio()
                q = res * lam / (1 - lam)
                first = q if first is None else first
                bar.update(round(100 * _progress.log_share(first, q, self.tol)) - bar.n)
                bar.set_postfix_str(f"iteration {s.it}, residual {res:.2e}")
            if self.converged(res):
                break
            if self.at_floor(res):
                continue
            if self.stalled(res) or self.jump(d, h_inc, use_later):
                break
        return s

    def ratio(self) -> float:
        """The ratio λ by which the updates shrink an iteration: once steady,
        the largest of the last :data:`_RATIO_WINDOW` two-iteration ratios
        ``sqrt(res_k / res_{k−2})``; until then the largest albedo
        (``docs/design.md`` §5).

        Two iterations, because facing surfaces of high albedo make the
        residual alternate (ratios 0.92, 1.01, 0.92, ... in Bitterli's living
        room) about a steady decay. Steady: the last two within 2% of
        ``1 − λ``. The largest albedo bounds λ but can sit far above it: one
        white object (albedo 1, a sofa) among darker surfaces made it
        ``1 − 1e-6``, and the lines then ran until their float32 rounding
        stalled them (3740 iterations, 272 s, in the living room).
        """
        r = self.ratios[-(_RATIO_WINDOW + 1) :]
        if len(r) <= _RATIO_WINDOW or any(x is None or x <= 0 for x in r):
            return self.lam_bound
        q = [float(np.sqrt(a * b)) for a, b in itertools.pairwise(r)]
        if not (q[-1] < 1 and abs(q[-1] - q[-2]) <= 0.02 * (1 - q[-1])):
            return self.lam_bound
        return min(self.lam_bound, max(q))

    def converged(self, res: float) -> bool:
        """The estimated remaining error of the geometric tail, ``res λ / (1 − λ)``
        with λ the updates' measured ratio (:meth:`ratio`), is under the
        lines' tolerance (:func:`lines_tol`)."""
        lam = self.ratio()
        return res * lam / (1 - lam) < self.tol

    def at_floor(self, res: float) -> bool:
        """Switch Jacobi to the correction form when its residual sits at the
        rounding of the values sent (True: switched, no jump this iteration)."""
        if res < self.best[0]:
            self.best = (res, self.s.it)
            return False
        if (
            self.corrections
            or self.best[0] >= _FLOOR_RESIDUAL
            or self.s.it - self.best[1] < _FLOOR_ITERATIONS
        ):
            return False
        self.corrections = True
        self.best = (float("inf"), self.s.it)
        self.extrap.prev = self.extrap.lam_prev = None
        self.p.stats["correction_form_after"] = self.s.it
        return True

    def stalled(self, res: float) -> bool:
        """No new lowest residual for :data:`_STALL_ITERATIONS` iterations."""
        if self.s.it - self.best[1] >= _STALL_ITERATIONS:
            self.s.stalled = True
            self.s.stopped = (
                f"the residual stalled at {self.best[0]:.3g} (its lowest, "
                f"iteration {self.best[1]}) for {_STALL_ITERATIONS} iterations"
            )
            return True
        return False

    def jump(self, d: np.ndarray, h_inc: np.ndarray | None, use_later: bool) -> bool:
        """Add the geometric tail when the updates shrink steadily; True when
        that ends the correction form (the tail stands for every bounce left)."""
        if self.p.lds is not None and not use_later:
            return False
        tail = self.extrap(d)
        if tail is None:
            return False
        R = self.s.R + tail
        if not np.all(np.isfinite(R)):
            return False
        self.s.R = R
        if self.corrections:
            self.s.Hg = self.s.Hg + h_inc * self.extrap.factor
            return True
        return False


def iterate(p: Problem, gather: Gatherer, Hd: np.ndarray, progress: bool) -> State:
    """Run :class:`_Iteration` with its progress bar; warn where it stopped short."""
    limit = p.limit
    if limit == 0 and not np.any(p.rho > 0):
        p.stats["skipped"]["gathering"] = "all albedos are zero"
    bar = None
    if progress and limit > 0:
        bar = _progress.bar("gather", 100, bar_format=_progress.PERCENT)
    it = _Iteration(p, gather, Hd)
    try:
        s = it.run(bar)
    finally:
        if bar is not None:
            bar.close()
    p.seconds["gather"] = s.seconds
    p.stats["extrapolations"] = it.extrap.count
    if s.stalled and passes_follow(p):
        # The traced passes sum the rest of the series from any start, so
        # where the lines stopped changes how many passes run, not the
        # answer (docs/design.md §5): a stall is no failure of the solve.
        p.stats["lines_stopped"] = s.stopped
    elif s.stopped is not None:
        p.stats["stopped"] = s.stopped
        warnings.warn(
            f"solve: {s.stopped}; returning the last finite iterate (iteration {s.it})",
            RuntimeWarning,
            stacklevel=3,
        )
    elif (
        limit > 0
        and s.it == limit
        and (not s.residuals or s.residuals[-1] >= p.opt.tol)
        and p.opt.max_bounces is None
    ):
        warnings.warn(
            f"solve: not converged after {s.it} iterations (residual {s.residuals[-1]:.3g})",
            RuntimeWarning,
            stacklevel=3,
        )
    return s
