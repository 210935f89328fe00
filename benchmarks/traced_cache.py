"""The solve's later traced passes through the first pass's kept rays, against fresh rays.

Two parts, each side by side in one process:

``bias`` (per scene): one default solve captures what its traced passes
start from (the lines' answer, the direct light, the lines' mode); from
that one start, with the same first pass (64 rays a record, seed 1), the
passes are finished

* ``kept``: every later pass through the first pass's rays (a sparse
  matrix), the default;
* ``fresh A`` and ``fresh B``: every later pass with fresh rays (16 a
  record), two seeds for the later passes.

It prints the records' relative difference of kept against fresh A next to
that of fresh B against fresh A (the later passes' own noise), both
area-weighted mean, 99th percentile and largest over the lit reflecting
records, and the change of the total reflected power; and, for the furnaces,
each answer's error against the exact radiance ``Le / (1 - rho)``.

``timing`` (per scene): voxelize at resolution 64 (``voxgi.render``'s
default), then solve with fresh later passes (``traced_cache=False``), with
the kept rays (the default), and with the kept rays after lines stopped at a
looser tolerance (``--lines-tol``); seconds of the solve, of the lines and of
the traced passes, line iterations, traced passes, and with ``--render`` the
relMSE of ``voxgi.render`` (seed 0) of each solution against the Mitsuba
reference that ``bitterli.py`` caches (rendered there if missing).

Writes ``results/traced_cache.json``.

Usage::

    python benchmarks/traced_cache.py bias cornell-box window-room door-room split-box
    python benchmarks/traced_cache.py timing cornell-box staircase2 --render
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time
from pathlib import Path

import numpy as np
from time_vs_error import RESULTS, git_commit

import voxgi
from voxgi.radiosity import solver, traced_passes
from voxgi.radiosity.tuning import _StudyTuning
from voxgi.traced import TracedGather

#: Samples per pixel of the Mitsuba references (bitterli.py's cache holds
#: these; more would be rendered here, minutes a pass); others take 4096.
REFERENCE_SPP = {"cornell-box": 1024, "staircase2": 1280}


def load(name: str, width: int = 256) -> voxgi.Scene:
    """A built-in scene, the furnace ``split-box`` or an extracted interior."""
    if name == "split-box":
        return voxgi.scenes.split_box(furnace=True)
    from bitterli import load as load_scene

    return load_scene(name, width)


def _capture(vox, threads):
    """A default solve, and what its traced passes started from."""
    seen = {}
    original = solver.traced_bounces

    def spy(p, Hd, R, mode=None):
        seen.update(p=p, Hd=Hd, R=R.copy(), mode=mode)
        return original(p, Hd, R, mode)

    solver.traced_bounces = spy
    try:
        sol = voxgi.solve(vox, progress=False, threads=threads)
    finally:
        solver.traced_bounces = original
    return sol, seen


def _finish(seen, keep: bool, later_seed: int = 0, first_seed: int = 1):
    """The traced passes from the captured start: kept rays, or fresh ones
    whose later passes are seeded ``later_seed`` on (the first pass's seed,
    1 in the solve, is ``first_seed``)."""
    p = seen["p"]
    p.stats["skipped"].pop("traced_cache", None)
    p.opt = dataclasses.replace(p.opt, traced_cache=keep)
    call = TracedGather.__call__

    def seeded(self, values, samples, seed, keep=False):
        seed = {0: 0, 1: first_seed}.get(seed, seed + later_seed)
        return call(self, values, samples, seed, keep=keep)

    TracedGather.__call__ = seeded
    try:
        t = time.perf_counter()
        R = traced_passes.traced_bounces(p, seen["Hd"], seen["R"].copy(), seen["mode"])
        seconds = time.perf_counter() - t
    finally:
        TracedGather.__call__ = call
    return p.E + R, dict(p.stats["traced"]), seconds


def _difference(p, B, ref, lit):
    rel = np.abs(B - ref).sum(axis=1)[lit] / ref.sum(axis=1)[lit]
    w = p.area[lit]
    return {
        "mean": float((rel * w).sum() / w.sum()),
        "p99": float(np.percentile(rel, 99)),
        "max": float(rel.max()),
    }


def bias(name: str, threads: int, seeds: int) -> dict:
    scene = load(name)
    vox = voxgi.voxelize(scene, 64, progress=False)
    _, seen = _capture(vox, threads)
    p = seen["p"]
    runs = {
        "kept": _finish(seen, True),
        "fresh A": _finish(seen, False, 0),
        "fresh B": _finish(seen, False, 1000),
    }
    area = p.area[:, None]
    # the reflected power, kept against fresh, over first passes of other seeds
    ratio = []
    for j in range(seeds):
        first = 1 + 7919 * (j + 1)
        kept = (area * (_finish(seen, True, 0, first)[0] - p.E)).sum(0)
        fresh = (area * (_finish(seen, False, 0, first)[0] - p.E)).sum(0)
        ratio.append(kept / fresh - 1)
    ref = runs["fresh A"][0]
    lit = (p.area > 0) & (p.rho.max(axis=1) > 0) & (ref.sum(axis=1) > 1e-3 * np.median(ref.sum(1)))
    power = {k: (p.area[:, None] * (B - p.E)).sum(axis=0) for k, (B, _, _) in runs.items()}
    out = {"records": len(vox), "runs": {}}
    if seeds:
        r = np.array(ratio)
        out["power_kept_vs_fresh_over_seeds"] = {
            "seeds": seeds,
            "mean": r.mean(0).tolist(),
            "std_of_mean": (r.std(0, ddof=1) / np.sqrt(seeds)).tolist() if seeds > 1 else None,
        }
    for k, (B, st, sec) in runs.items():
        row = {
            "passes": st["passes"],
            "converged": st["converged"],
            "seconds": sec,
            "reflected_power_vs_fresh_A": (power[k] / power["fresh A"] - 1).tolist(),
        }
        if k != "fresh A":
            row["vs_fresh_A"] = _difference(p, B, ref, lit)
        if name in ("split-box", "furnace-box"):
            exact = np.full_like(B, 1.0 / (1 - 0.8)) * np.pi  # radiosity of radiance 1/(1-rho)
            front = lit & ~np.asarray(vox.back)
            e = B[front] / exact[front] - 1
            row["vs_exact"] = {
                "mean": float(np.abs(e).mean()),
                "max": float(np.abs(e).max()),
                "signed_mean": float(e.mean()),
            }
        out["runs"][k] = row
    return out


def timing(
    name: str,
    threads: int,
    lines_tol: list[float],
    render: bool,
    fresh: bool = True,
    kept: bool = True,
) -> dict:
    scene = load(name)
    t = time.perf_counter()
    vox = voxgi.voxelize(scene, 64, progress=False)
    out = {"records": len(vox), "voxelize_seconds": time.perf_counter() - t, "runs": {}}
    configs = {
        "fresh": voxgi.SolveTuning(traced_cache=False),
        "kept": voxgi.SolveTuning(),
        **{f"kept, lines_tol {t:g}": _StudyTuning(lines_tol=t) for t in lines_tol},
    }
    if not fresh:
        del configs["fresh"]
    if not kept:
        del configs["kept"]
    ref = None
    if render:
        from bitterli import reference

        ref, noise, info = reference(scene, name, REFERENCE_SPP.get(name, 4096), verbose=False)
        out["reference"] = {"spp": info["spp"], "noise": noise}
    sols = {}
    for k, tuning in configs.items():
        t = time.perf_counter()
        sol = voxgi.solve(vox, progress=False, threads=threads, tuning=tuning)
        sec = time.perf_counter() - t
        st = sol.stats["traced"]
        row = {
            "solve_seconds": sec,
            "lines_seconds": sol.stats["seconds"].get("gather"),
            "traced_seconds": sol.stats["seconds"].get("traced"),
            "iterations": sol.bounces,
            "passes": st["passes"],
            "kept": st["kept"],
            "converged": st["converged"],
            "traced_split": st["seconds"],
            "matrix_bytes": st.get("bytes"),
        }
        sols[k] = sol
        if ref is not None:
            t = time.perf_counter()
            img = voxgi.render(scene, sol, seed=0, threads=threads, progress=False).image
            row["render_seconds"] = time.perf_counter() - t
            row["relmse"] = float(voxgi.metrics.rel_mse(img, ref))
        out["runs"][k] = row
        print(f"  {k}: {row}", flush=True)
    base = next(iter(sols.values())).radiosity.astype(np.float64)
    area = np.asarray(vox.area)[:, None]
    for k, sol in sols.items():
        B = sol.radiosity.astype(np.float64)
        out["runs"][k]["power"] = (area * B).sum(0).tolist()
        out["runs"][k]["power_vs_first"] = ((area * B).sum(0) / (area * base).sum(0) - 1).tolist()
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("part", choices=["bias", "timing"])
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--lines-tol", type=float, nargs="+", default=[1e-2])
    ap.add_argument("--render", action="store_true")
    ap.add_argument(
        "--seeds", type=int, default=0, help="bias: first passes of more seeds, kept and fresh"
    )
    ap.add_argument("--no-fresh", action="store_true", help="timing: skip the fresh-ray solve")
    ap.add_argument(
        "--no-kept", action="store_true", help="timing: skip the kept-ray solve at the lines' tol"
    )
    ap.add_argument("--json", type=Path, default=RESULTS / "traced_cache.json")
    args = ap.parse_args()
    results = {"commit": git_commit(), "load": os.getloadavg(), "part": args.part, "scenes": {}}
    for name in args.scenes:
        print(name, flush=True)
        if args.part == "bias":
            res = bias(name, args.threads, args.seeds)
            for k, row in res["runs"].items():
                print(f"  {k}: {row}", flush=True)
            if args.seeds:
                print(f"  over seeds: {res['power_kept_vs_fresh_over_seeds']}", flush=True)
        else:
            res = timing(
                name, args.threads, args.lines_tol, args.render, not args.no_fresh, not args.no_kept
            )
        results["scenes"][name] = res
    results["load_after"] = os.getloadavg()
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(results, indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
