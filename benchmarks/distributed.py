"""Local against Dask: the bunny-room solve and a 512x512 render.

Run on its own (never collected by pytest)::

    python benchmarks/distributed.py [--resolution 64] [--directions 22] [--frames 16]
                                     [--workers 1 2] [--width 512]

In one run: voxelize the bunny room once; solve it locally (all cores) and on
a LocalCluster of 1 and of 2 worker processes (one thread each, loopback);
render it at 512x512 the same three ways; check each distributed answer
against the local one; and measure the two terms of the cost model of
docs/scaling.md:

- ``c``: seconds of gathering per record and direction family on one core
  (from a local single-thread gather pass);
- ``o``: the fixed cost of one distributed gathering call on N records
  (values out, partial sums back, scheduling), from a distributed call over
  a single family minus the same call locally.

Prints a table and writes ``benchmarks/results/distributed.json``. Timings
on a shared 2-core machine are contended: the JSON records the load.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

# This file is named like the package it benchmarks: drop its folder from the
# path so that `import distributed` finds Dask (worker processes inherit it).
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]

import numpy as np  # noqa: E402

import voxgi  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"


def _meta() -> dict:
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            cwd=Path(__file__).parent,
            check=False,
        ).stdout.strip()
    except OSError:
        commit = ""
    cpu = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import dask

    return {
        "voxgi": voxgi.__version__,
        "dask": dask.__version__,
        "commit": commit,
        "cpu": cpu,
        "cores": os.cpu_count(),
        "load_before": os.getloadavg()[0],
        "python": platform.python_version(),
    }


def _rel(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a, np.float64) - b)) / max(np.max(np.abs(b)), 1e-300))


def _cost_terms(vox, directions: int, client) -> dict:
    """c (s per record x family, one core) and o (s per distributed call)."""
    from voxgi.directions import direction_set
    from voxgi.distributed import DistributedLineSystem
    from voxgi.radiosity import line_records

    records = line_records(vox)
    ds = direction_set(directions)
    n, nf = len(vox), len(ds.families)
    local = records.build()
    vals = np.random.default_rng(0).random((n, 3)).astype(np.float32)
    allf = np.arange(nf, dtype=np.int64)
    one = np.arange(1, dtype=np.int64)
    local.gather(ds.families, ds.weights, vals, one, False, 1)  # warm up
    t = time.perf_counter()
    local.gather(ds.families, ds.weights, vals, allf, False, 1)
    t_full = time.perf_counter() - t
    reps = 5
    t = time.perf_counter()
    for _ in range(reps):
        local.gather(ds.families, ds.weights, vals, one, False, 1)
    t_one_local = (time.perf_counter() - t) / reps
    dist = DistributedLineSystem(client, records)
    dist.gather(ds.families, ds.weights, vals, one)  # the workers build their systems
    t = time.perf_counter()
    for _ in range(reps):
        dist.gather(ds.families, ds.weights, vals, one)
    t_one_dist = (time.perf_counter() - t) / reps
    dist.close()
    return {
        "records": n,
        "families": nf,
        "gather_pass_1core_s": t_full,
        "c_s_per_record_family": t_full / (n * nf),
        "o_s_per_call": max(t_one_dist - t_one_local, 0.0),
        "one_family_local_s": t_one_local,
        "one_family_distributed_s": t_one_dist,
        "bytes_per_call_per_worker": n * (12 + 24),
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--resolution", type=int, default=64)
    p.add_argument("--directions", type=int, default=22)
    p.add_argument("--shoot-directions", type=int, default=35)
    p.add_argument(
        "--max-bounces",
        type=int,
        default=4,
        help="fixed gathering iterations, so every run does the same work",
    )
    p.add_argument("--frames", type=int, default=8, help="frames of the render (tol=0)")
    p.add_argument("--width", type=int, default=512)
    p.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    p.add_argument("--out", default=str(RESULTS / "distributed.json"))
    args = p.parse_args(argv)

    from distributed import Client, LocalCluster

    meta = _meta()
    scene = voxgi.scenes.bunny_room(width=args.width, height=args.width)
    t = time.perf_counter()
    vox = voxgi.voxelize(scene, resolution=args.resolution)
    t_vox = time.perf_counter() - t
    skw = dict(
        radius=args.directions,
        max_bounces=args.max_bounces,
        progress=False,
        tuning=voxgi.SolveTuning.paper(shoot_radius=args.shoot_directions),
    )
    rkw = dict(max_frames=args.frames, tol=0.0, seed=1, progress=False)
    print(
        f"bunny room: {len(vox)} records (resolution {args.resolution}, voxelized in "
        f"{t_vox:.1f} s), R {args.directions}/{args.shoot_directions}, "
        f"{args.max_bounces} iterations; render {args.width}x{args.width}, {args.frames} frames"
    )

    rows = []
    t = time.perf_counter()
    sol = voxgi.solve(vox, **skw)
    t_solve = time.perf_counter() - t
    t = time.perf_counter()
    img = voxgi.render(scene, sol, **rkw)
    t_render = time.perf_counter() - t
    rows.append(
        {
            "where": "local",
            "workers": 0,
            "solve_s": t_solve,
            "render_s": t_render,
            "solve_phases": sol.stats["seconds"],
            "startup_s": 0.0,
        }
    )
    cost = {}
    for w in args.workers:
        t = time.perf_counter()
        cluster = LocalCluster(
            n_workers=w,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address="127.0.0.1:0",
        )
        client = Client(cluster)
        t_start = time.perf_counter() - t
        try:
            t = time.perf_counter()
            dsol = voxgi.solve(vox, client=client, **skw)
            ts = time.perf_counter() - t
            t = time.perf_counter()
            dimg = voxgi.render(scene, sol, client=client, **rkw)
            tr = time.perf_counter() - t
            cost[w] = _cost_terms(vox, args.directions, client)
        finally:
            client.close()
            cluster.close()
        rows.append(
            {
                "where": "dask",
                "workers": w,
                "solve_s": ts,
                "render_s": tr,
                "startup_s": t_start,
                "solve_phases": dsol.stats["seconds"],
                "distributed": dsol.stats["executor"],
                "solve_rel_diff": _rel(dsol.radiosity, sol.radiosity),
                "image_max_abs_diff": float(np.max(np.abs(dimg.image - img.image))),
            }
        )

    loc = rows[0]
    print(
        f"\n{'where':<8} {'workers':>7} {'startup s':>9} {'solve s':>8} {'overhead':>9} "
        f"{'render s':>9} {'overhead':>9} {'solve rel diff':>14} {'image diff':>10}"
    )
    for r in rows:
        so = r["solve_s"] - loc["solve_s"]
        ro = r["render_s"] - loc["render_s"]
        print(
            f"{r['where']:<8} {r['workers']:>7} {r['startup_s']:>9.2f} {r['solve_s']:>8.2f} "
            f"{so:>+9.2f} {r['render_s']:>9.2f} {ro:>+9.2f} "
            f"{r.get('solve_rel_diff', 0.0):>14.1e} {r.get('image_max_abs_diff', 0.0):>10.1e}"
        )
    print(
        "\ncost model (docs/scaling.md): c = s per record x family on one core; "
        "o = s per distributed gathering call"
    )
    for w, c in cost.items():
        print(
            f"  {w} worker(s): N {c['records']}, F {c['families']}, "
            f"c {c['c_s_per_record_family']:.3e} s, o {c['o_s_per_call']:.3f} s, "
            "a full pass on one core "
            f"{c['gather_pass_1core_s']:.2f} s, {c['bytes_per_call_per_worker'] / 1e6:.2f} MB "
            "per call and worker"
        )
    meta["load_after"] = os.getloadavg()[0]
    out = {
        "name": "distributed",
        "params": vars(args),
        "records": len(vox),
        "rows": rows,
        "cost": {str(k): v for k, v in cost.items()},
        "meta": meta,
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1, default=float))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
