"""Run the whole benchmark suite, in order, and draw the summary plots.

One command for everything the README's performance section quotes::

    python benchmarks/run_all.py            # full size (tens of minutes on 2 cores)
    python benchmarks/run_all.py --quick    # a smoke run of every script

Steps (each a script that also runs on its own; results in benchmarks/results/):

1. ``voxelize.py``       voxelization time and memory (bunny 128-512, 1M triangles);
2. ``propagation.py``    furnace / thin-wall / cap-sphere accuracy, energy
                         balance, linear cost, throughput, the paper's work unit;
3. ``paper_tables.py``   the paper's Tables 1, 2 and 4 on the look-alike scenes;
4. ``reference.py`` + ``time_vs_error.py``   time against error versus Mitsuba 3
                         on the Cornell box, then (full size only) on the
                         ``shadow`` and ``geometric`` look-alikes against their
                         committed references (``results/<scene>_ref_256.exr``;
                         not re-rendered: ``reference.py --scene <scene>`` takes
                         15-30 minutes each on 2 cores); skipped, and said so,
                         when the ``mitsuba`` package is absent
                         (``pip install "voxgi[bench]"``);
5. ``calibration.py``    the display's error estimate against the measured
                         error, five scenes, three seeds; ``furnace_pixels.py``
                         every pixel of the furnace at the defaults;
                         ``display_noise.py``
                         what a frame's noise is made of, and the cost of a
                         unit of error at other ray budgets; ``ray_cost.py``
                         what a ray costs, and the rays' share of the display;
6. the linear-cost log-log plot ``results/linear_cost.png`` from step 2.

Never collected by pytest (``testpaths = ["tests"]``).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"


def run(args: list[str]) -> bool:
    print(f"\n$ python {' '.join(args)}", flush=True)
    t = time.perf_counter()
    rc = subprocess.call([sys.executable, *args], cwd=HERE.parent)
    print(f"  -> exit {rc} after {time.perf_counter() - t:.0f} s", flush=True)
    return rc == 0


def linear_plot() -> None:
    path = RESULTS / "propagation_linear.json"
    if not path.exists():
        print("no propagation_linear.json: linear plot skipped")
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rec = json.loads(path.read_text())
    rows = rec["rows"] if isinstance(rec, dict) and "rows" in rec else rec
    by_r: dict[int, list] = {}
    for r in rows:
        by_r.setdefault(r["R"], []).append(r)
    fig, ax = plt.subplots(figsize=(5, 4))
    for R, rs in sorted(by_r.items()):
        work = [r["records"] * r["families"] * r["iters"] for r in rs]
        ax.loglog(work, [r["seconds"] for r in rs], "o", label=f"R = {R}")
    allw = [r["records"] * r["families"] * r["iters"] for r in rows]
    alls = [r["seconds"] for r in rows]
    k = sum(alls) / sum(allw)
    lo, hi = min(allw) / 1.5, max(allw) * 1.5
    ax.loglog([lo, hi], [k * lo, k * hi], "k--", lw=1, label="slope 1 (linear)")
    ax.set_xlabel("records x direction families x iterations")
    ax.set_ylabel("gathering seconds (1 thread)")
    ax.set_title("Propagation time is linear in the number of rays")
    ax.legend()
    fig.tight_layout()
    fig.savefig(RESULTS / "linear_cost.png", dpi=100)
    print(f"wrote {RESULTS / 'linear_cost.png'}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="small sizes everywhere")
    args = ap.parse_args()
    q = ["--quick"] if args.quick else []
    ok = {}
    ok["voxelize"] = run(["benchmarks/voxelize.py", *q])
    ok["propagation"] = run(["benchmarks/propagation.py", *q])
    ok["paper_tables"] = run(["benchmarks/paper_tables.py", *q])
    ok["direct_light"] = run(["benchmarks/direct_light.py", *q])
    # the display's error estimate against the measured error (--quick: 64x64)
    ok["calibration"] = run(
        [
            "benchmarks/calibration.py",
            *(["--size", "64", "--ref-frames", "64"] if args.quick else []),
        ]
    )
    ok["furnace_pixels"] = run(["benchmarks/furnace_pixels.py"])
    ok["display_noise"] = run(
        [
            "benchmarks/display_noise.py",
            *(["--size", "64", "--frames", "8"] if args.quick else []),
        ]
    )
    ok["ray_cost"] = run(["benchmarks/ray_cost.py", *(["--size", "64"] if args.quick else [])])
    if importlib.util.find_spec("mitsuba") is None:
        print(
            "\nmitsuba not installed: time-vs-error against Mitsuba 3 skipped "
            '(pip install "voxgi[bench]")'
        )
    else:
        sizes = ["256"] if args.quick else ["256", "512"]
        spp = ["1024"] if args.quick else ["4096"]
        # keep committed references (the Cornell ones are 65536-spp GPU renders):
        # render only the missing ones
        missing = [z for z in sizes if not (RESULTS / f"cornell_ref_{z}.exr").exists()]
        if missing:
            ok["reference"] = run(["benchmarks/reference.py", "--size", *missing, "--spp", *spp])
        ok["time_vs_error"] = run(["benchmarks/time_vs_error.py", "--size", *sizes, "--split"])
        if not args.quick:
            for scene in ("shadow", "geometric"):
                ok[f"time_vs_error_{scene}"] = run(
                    ["benchmarks/time_vs_error.py", "--scene", scene, "--size", "256", "--high"]
                )
    linear_plot()
    ok["performance.md"] = run(["scripts/make_performance.py"])
    print("\nsummary:", ", ".join(f"{k}: {'ok' if v else 'FAILED'}" for k, v in ok.items()))
    sys.exit(0 if all(ok.values()) else 1)


if __name__ == "__main__":
    main()
