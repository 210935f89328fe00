"""How the solve's traced passes converge, pass by pass, with and without the tail.

Per scene: one voxelize + solve with the defaults of ``voxgi.render(scene)``
(its traced passes, ratio and time as the solve reports them), then the
passes replayed from the same starting point with the same rays (the
recurrence of ``voxgi.radiosity.traced_passes``: ``R_1 = ρ (H_d + T R_0)``,
``d_{k+1} = ρ T d_k`` with the same seeds and ray counts) for ``--passes``
passes. For each pass count n, against the sum after the last pass plus its
tail, one pass beyond the last reported (the converged answer of those same
rays, so that the figures are the stopping error alone, not the rays' noise):

* the records' relative error of ``R_n`` (no tail) and of
  ``X_n = R_n + d_n λ / (1 − λ)`` (the tail the solve adds): area-weighted
  mean, 99th percentile and largest over the lit reflecting records;
* the solve's stopping estimate ``r_n λ / (1 − λ)`` and the change of the
  extrapolated sum times ``λ_max / (1 − λ_max)`` (an estimate of the error
  of ``X_n``: for a part of the changes shrinking by μ a pass, the error of
  ``X_n`` is ``μ / (1 − μ)`` times its part of ``X_n − X_{n−1}``);
* the records whose ``X_n`` is below zero.

Writes ``results/traced_passes.json``.

Usage::

    python benchmarks/traced_passes.py [--passes 24] [scene ...]

A scene is a built-in name (default: cornell-box window-room door-room
furnace-box) or a scene file.
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from pathlib import Path

import numpy as np
from time_vs_error import RESULTS, git_commit

import voxgi
from voxgi.radiosity import solver
from voxgi.traced import TracedGather


def _solve_capturing_passes_input(vox):
    """The default solve, and what its traced passes started from."""
    seen = {}
    traced_bounces = solver.traced_bounces

    def spy(p, Hd, R):
        seen.update(p=p, Hd=Hd, R=R.copy())
        return traced_bounces(p, Hd, R)

    solver.traced_bounces = spy
    try:
        t = time.perf_counter()
        sol = voxgi.solve(vox, progress=False)
        seconds = time.perf_counter() - t
    finally:
        solver.traced_bounces = traced_bounces
    return sol, seconds, seen


def _replay(p, Hd, R, passes):
    """Per pass: (R_n, d_n, λ_n, r_n), as the solve computes them; and ``Σ ΔA |B|``."""
    area, opt = p.area[:, None], p.opt
    later = max(16, opt.traced_samples // 4)
    lam_max = float(min(max(float(p.rho.max()), 0.5), 1 - 1e-6))
    out, residuals, lam = [], [], lam_max
    with TracedGather(p.vox.scene, p.vox, threads=opt.threads) as trace:
        Rn = p.rho * (Hd + trace(R, opt.traced_samples, seed=1))
        d = Rn - R
        Btot = float(np.sum(area * np.abs(p.E + Rn)))
        for n in range(1, passes + 1):
            residuals.append(float(np.sum(area * np.abs(d))) / Btot)
            if n >= 2 and min(residuals[-3:-1]) > 0:
                last = residuals[-3:]
                lam = min(max(b / a for a, b in itertools.pairwise(last)), lam_max)
            out.append((Rn.copy(), d.copy(), lam, residuals[-1]))
            d = p.rho * trace(d, later, seed=n + 1)
            Rn = Rn + d
    return out, Btot, lam_max


def _errors(p, X, B_ref, lit):
    """Relative error of the records' radiosity ``E + X``: mean (area-weighted), p99, max."""
    e = np.abs(p.E + np.maximum(X, 0.0) - B_ref)
    rel = e.sum(axis=1)[lit] / B_ref.sum(axis=1)[lit]
    mean = float((p.area[:, None] * e)[lit].sum() / (p.area[:, None] * B_ref)[lit].sum())
    return {"mean": mean, "p99": float(np.percentile(rel, 99)), "max": float(rel.max())}


def measure(scene: voxgi.Scene, passes: int) -> dict:
    vox = voxgi.voxelize(scene, progress=False)
    sol, seconds, seen = _solve_capturing_passes_input(vox)
    p = seen["p"]
    history, Btot, lam_max = _replay(p, seen["Hd"], seen["R"], passes + 1)
    R_last, d_last, lam_last, _ = history.pop()
    B_ref = p.E + R_last + d_last * (lam_last / (1 - lam_last))
    total = B_ref.sum(axis=1)
    lit = (p.area > 0) & (p.rho.max(axis=1) > 0) & (total > 1e-3 * np.median(total))
    area = p.area[:, None]
    rows, previous = [], None
    for n, (Rn, d, lam, r) in enumerate(history, 1):
        X = Rn + d * (lam / (1 - lam))
        change = None
        if previous is not None:
            step = float(np.sum(area * np.abs(d - lam * previous))) / ((1 - lam) * Btot)
            change = step * lam_max / (1 - lam_max)
        previous = d
        rows.append(
            {
                "passes": n,
                "ratio": lam,
                "rule_estimate": r * lam / (1 - lam),
                "extrapolation_estimate": change,
                "no_tail": _errors(p, Rn, B_ref, lit),
                "tail": _errors(p, X, B_ref, lit),
                "negative_records": int(np.count_nonzero(np.any(X < 0, axis=1))),
            }
        )
    st = sol.stats["traced"]
    return {
        "records": len(vox),
        "solve_seconds": seconds,
        "traced_seconds": sol.stats["seconds"]["traced"],
        "default_passes": st["passes"],
        "default_ratio": st["ratio"],
        "largest_albedo": lam_max,
        "per_pass": rows,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scenes", nargs="*", default=["cornell-box", "window-room", "door-room",
                                                  "furnace-box"])  # fmt: skip
    ap.add_argument("--passes", type=int, default=24)
    args = ap.parse_args()
    results = {"commit": git_commit(), "scenes": {}}
    for name in args.scenes:
        scene = voxgi.Scene.load(name) if Path(name).suffix else voxgi.scenes.get(name)
        res = measure(scene, args.passes)
        results["scenes"][name] = res
        print(
            f"{name}: {res['records']} records, the solve's {res['default_passes']} passes "
            f"(ratio {res['default_ratio']:.3f}, traced {res['traced_seconds']:.2f} s)"
        )
        print("  n  ratio  rule_est  extr_est | no tail: mean     p99     max | tail: mean"
              "     p99     max  negative")  # fmt: skip
        for row in res["per_pass"]:
            a, b = row["no_tail"], row["tail"]
            x = row["extrapolation_estimate"]
            print(
                f" {row['passes']:2d}  {row['ratio']:.3f}  {row['rule_estimate']:.2e}  "
                f"{x if x is not None else float('nan'):.2e} | {a['mean']:.2e} {a['p99']:.2e} "
                f"{a['max']:.2e} | {b['mean']:.2e} {b['p99']:.2e} {b['max']:.2e} "
                f"{row['negative_records']:4d}",
                flush=True,
            )
    out = RESULTS / "traced_passes.json"
    out.write_text(json.dumps(results, indent=1))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
