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
  ``X_n = R_n`` + the tail the solve adds (the power of ``d_n`` times
  ``λ / (1 − λ)`` in the shape of the slowest mode, at most twice
  ``|d_n|`` times it at each record): area-weighted
  mean, 99th percentile and largest over the lit reflecting records;
* the solve's stopping estimate ``Σ_c r_c λ_c / (1 − λ_c)`` (λ per channel:
  the ratio of the lines' slowest mode, or the changes' own if larger);
* the records whose ``X_n`` is below zero.

Then the solve's answer against ``--passes`` passes of many more rays
(``--reference-samples`` in the first pass, a quarter in the later ones)
from the same start: the stopping error and the rays' noise together.

Writes ``results/traced_passes.json``.

Usage::

    python benchmarks/traced_passes.py [--passes 24] [--reference-samples 256] [scene ...]

A scene is a built-in name (default: cornell-box window-room door-room
furnace-box) or a scene file.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from time_vs_error import RESULTS, git_commit

import voxgi
from voxgi.radiosity import solver, traced_passes
from voxgi.traced import TracedGather


def _solve_capturing_passes_input(vox):
    """The default solve, and what its traced passes started from."""
    seen = {}
    traced_bounces = solver.traced_bounces

    def spy(p, Hd, R, mode=None):
        seen.update(p=p, Hd=Hd, R=R.copy(), mode=mode)
        seen["answer"] = traced_bounces(p, Hd, R, mode)
        return seen["answer"]

    solver.traced_bounces = spy
    try:
        t = time.perf_counter()
        sol = voxgi.solve(vox, progress=False)
        seconds = time.perf_counter() - t
    finally:
        solver.traced_bounces = traced_bounces
    return sol, seconds, seen


def _replay(p, Hd, R, mode, passes, samples=None, later=None):
    """Per pass: (R_n, d_n, λ_n, the rule's estimate), as the solve computes
    them (``samples`` and ``later`` rays: the solve's by default)."""
    area, opt = p.area[:, None], p.opt
    samples = samples or opt.traced_samples
    later = later or max(16, opt.traced_samples // 4)
    lam_max = float(min(max(float(p.rho.max()), 0.5), 1 - 1e-6))
    out, size = [], None
    with TracedGather(p.vox.scene, p.vox, threads=opt.threads) as trace:
        seen_albedo = trace(np.asarray(p.rho, np.float64), traced_passes._ALBEDO_SAMPLES, seed=0)
        lam_mode = np.minimum(traced_passes._dominant_ratio(p, seen_albedo, mode), lam_max)
        lam = lam_mode
        Rn = p.rho * (Hd + trace(R, samples, seed=1))
        d = Rn - R
        Btot = float(np.sum(area * np.abs(p.E + Rn)))
        for n in range(1, passes + 1):
            size, previous = np.sum(area * np.abs(d), axis=0), size
            if previous is not None:
                measured = np.where(previous > 0, size / np.maximum(previous, 1e-300), 0.0)
                lam = np.clip(np.maximum(lam_mode, measured), 0.0, lam_max)
            out.append((Rn.copy(), d.copy(), lam, float(np.sum(size * lam / (1 - lam))) / Btot))
            d = p.rho * trace(d, later, seed=n + 1)
            Rn = Rn + d
    return out, lam_mode


def _errors(p, X, B_ref, lit):
    """Relative error of the records' radiosity ``E + X``: mean (area-weighted),
    p99, max, and that of their power (``bias``, with its sign)."""
    signed = p.E + np.maximum(X, 0.0) - B_ref
    e = np.abs(signed)
    rel = e.sum(axis=1)[lit] / B_ref.sum(axis=1)[lit]
    power = (p.area[:, None] * B_ref)[lit].sum()
    mean = float((p.area[:, None] * e)[lit].sum() / power)
    bias = float((p.area[:, None] * signed)[lit].sum() / power)
    return {"mean": mean, "p99": float(np.percentile(rel, 99)), "max": float(rel.max()),
            "bias": bias}  # fmt: skip


def _converged(p, history, mode):
    """The sum after the last pass and its tail."""
    R_last, d_last, lam_last, _ = history[-1]
    return R_last + traced_passes._tail(p, d_last, lam_last, mode)


def measure(scene: voxgi.Scene, passes: int, reference_samples: int) -> dict:
    vox = voxgi.voxelize(scene, progress=False)
    sol, seconds, seen = _solve_capturing_passes_input(vox)
    p = seen["p"]
    history, lam_mode = _replay(p, seen["Hd"], seen["R"], seen["mode"], passes + 1)
    B_ref = p.E + _converged(p, history, seen["mode"])
    history.pop()
    total = B_ref.sum(axis=1)
    lit = (p.area > 0) & (p.rho.max(axis=1) > 0) & (total > 1e-3 * np.median(total))
    lit &= np.all(B_ref > 0, axis=1)
    rows = []
    for n, (Rn, d, lam, estimate) in enumerate(history, 1):
        X = Rn + traced_passes._tail(p, d, lam, seen["mode"])
        rows.append(
            {
                "passes": n,
                "ratio": lam.tolist(),
                "rule_estimate": estimate,
                "no_tail": _errors(p, Rn, B_ref, lit),
                "tail": _errors(p, X, B_ref, lit),
                "negative_records": int(np.count_nonzero(np.any(X < 0, axis=1))),
            }
        )
    st = sol.stats["traced"]
    res = {
        "records": len(vox),
        "solve_seconds": seconds,
        "traced_seconds": sol.stats["seconds"]["traced"],
        "default_passes": st["passes"],
        "default_ratio": st["ratios"],
        "mode_ratio": lam_mode.tolist(),
        "largest_albedo": float(p.rho.max()),
        "per_pass": rows,
    }
    if reference_samples:
        # the solve's answer against many passes of many rays from the same start
        t = time.perf_counter()
        ref, _ = _replay(p, seen["Hd"], seen["R"], seen["mode"], passes + 1,
                         reference_samples, reference_samples // 4)  # fmt: skip
        B_many = p.E + _converged(p, ref, seen["mode"])
        res["many_rays"] = {
            "samples": [reference_samples, reference_samples // 4],
            "passes": passes + 1,
            "seconds": time.perf_counter() - t,
            "settled_ratio": ref[-1][2].tolist(),
            "solve": _errors(p, seen["answer"], B_many, lit),
        }
    return res


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scenes", nargs="*", default=["cornell-box", "window-room", "door-room",
                                                  "furnace-box"])  # fmt: skip
    ap.add_argument("--passes", type=int, default=24)
    ap.add_argument("--reference-samples", type=int, default=256,
                    help="first-pass rays of the many-ray reference (0: none)")  # fmt: skip
    args = ap.parse_args()
    results = {"commit": git_commit(), "scenes": {}}
    for name in args.scenes:
        scene = voxgi.Scene.load(name) if Path(name).suffix else voxgi.scenes.get(name)
        res = measure(scene, args.passes, args.reference_samples)
        results["scenes"][name] = res
        print(
            f"{name}: {res['records']} records, the solve's {res['default_passes']} passes "
            f"(ratio {max(res['default_ratio']):.3f}, the lines' mode "
            f"{max(res['mode_ratio']):.3f}, traced {res['traced_seconds']:.2f} s)"
        )
        if "many_rays" in res:
            m = res["many_rays"]
            print(
                f"  the solve against {m['passes']} passes of {m['samples']} rays "
                f"(settled ratio {max(m['settled_ratio']):.3f}): mean {m['solve']['mean']:.2e} "
                f"p99 {m['solve']['p99']:.2e} max {m['solve']['max']:.2e} "
                f"power {m['solve']['bias']:+.2e}"
            )
        print("  n  ratio  rule_est | no tail: mean     p99     max | tail: mean"
              "     p99     max  negative")  # fmt: skip
        for row in res["per_pass"]:
            a, b = row["no_tail"], row["tail"]
            print(
                f" {row['passes']:2d}  {max(row['ratio']):.3f}  {row['rule_estimate']:.2e} | "
                f"{a['mean']:.2e} {a['p99']:.2e} {a['max']:.2e} | "
                f"{b['mean']:.2e} {b['p99']:.2e} {b['max']:.2e} {row['negative_records']:4d}",
                flush=True,
            )
    out = RESULTS / "traced_passes.json"
    out.write_text(json.dumps(results, indent=1))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
