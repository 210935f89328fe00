"""Furnace accuracy with and without a closed inner object.

Uniform furnaces (every surface Le = 1, albedo rho): the exact radiance is
Le / (1 - rho) everywhere. Prints the mean and max relative error of the
front records of each object, and the solve's loss statistics, for
furnace_sphere / furnace_box, inner False/True, rho 0.5/0.9/0.99.
Writes benchmarks/results/furnace_inner.json. Usage:

    python benchmarks/furnace_inner.py [--res 48] [--R 8] [--rho 0.5 0.9 0.99] [--out FILE]

The lost fraction δ falls fast with the resolution (sphere: 2.45e-4 at 48,
3.3e-5 at 96): the rho = 0.99 sphere needs res 96 to reach 0.5% mean.
"""

import argparse
import json
import time
from pathlib import Path

import numpy as np

import voxgi


def run(kind, inner, rho, res, R, closed=None):
    s = getattr(voxgi.scenes, kind)(albedo=rho, inner=inner)
    v = voxgi.voxelize(s, res)
    t = time.perf_counter()
    sol = voxgi.solve(
        v, radius=R, progress=False, tuning=voxgi.SolveTuning.paper(shoot_radius=R, closed=closed)
    )
    dt = time.perf_counter() - t
    e = sol.radiance[:, 0] * (1 - rho) - 1
    f = ~v.back
    rows = []
    for k, obj in enumerate(s.objects):
        m = f & (v.object_id == k)
        rows.append(
            dict(
                scene=kind,
                inner=inner,
                rho=rho,
                object=obj.name,
                n=int(m.sum()),
                mean=float(e[m].mean()),
                abs_mean=float(np.abs(e[m]).mean()),
                iters=sol.bounces,
                max=float(np.abs(e[m]).max()),
                lost=sol.stats.get("lost_fraction"),
                back=sol.stats.get("back_fraction"),
                back_max=sol.stats.get("back_fraction_max"),
                seconds=dt,
            )
        )
    return rows


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--res", type=int, default=48)
    ap.add_argument("--R", type=int, default=8)
    ap.add_argument("--rho", type=float, nargs="+", default=[0.5, 0.9, 0.99])
    ap.add_argument("--scenes", nargs="+", default=["furnace_sphere", "furnace_box"])
    ap.add_argument("--closed", action="store_true", help="solve(closed=True)")
    ap.add_argument(
        "--out", default=str(Path(__file__).resolve().parent / "results" / "furnace_inner.json")
    )
    a = ap.parse_args()
    out = []
    print(f"res {a.res} R {a.R} closed={a.closed}")
    print(
        f"{'scene':15s} {'inner':5s} {'rho':>5s} {'object':8s} {'mean err':>9s} "
        f"{'|err| mean':>10s} {'max err':>8s} "
        f"{'lost':>8s} {'back':>8s} {'back max':>8s} {'iters':>5s} {'s':>5s}"
    )
    for kind in a.scenes:
        for inner in (False, True):
            for rho in a.rho:
                for r in run(kind, inner, rho, a.res, a.R, True if a.closed else None):
                    out.append(r)
                    fmt = lambda x: f"{x:8.2e}" if x is not None else f"{'-':>8s}"  # noqa: E731
                    print(
                        f"{r['scene']:15s} {r['inner']!s:5s} {r['rho']:5.2f} {r['object']:8s} "
                        f"{r['mean']:+9.4%} {r['abs_mean']:10.4%} {r['max']:8.3%} "
                        f"{fmt(r['lost'])} {fmt(r['back'])} "
                        f"{fmt(r['back_max'])} {r['iters']:5d} {r['seconds']:5.1f}",
                        flush=True,
                    )
    with open(a.out, "w") as fh:
        json.dump(dict(res=a.res, R=a.R, closed=a.closed, rows=out), fh, indent=1)


if __name__ == "__main__":
    main()
