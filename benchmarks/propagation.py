"""Benchmarks and acceptance figures of the discrete-line propagation.

Run on its own (never collected by pytest)::

    python benchmarks/propagation.py [SECTION ...] [--quick] [--threads 1 2]

Sections (all by default):

- ``furnace``    uniform furnaces (sphere, box, each with and without an inner
  object), rho in {0.3, 0.5, 0.9, 0.99}, res 48 (``--res``), R = 8
  (``--radii``): radiance error against Le / (1 - rho), iterations, lost
  fraction δ. Writes ``propagation_furnace.json`` (``_res<N>`` for other
  resolutions).
- ``junctions``  a closed box split by a zero-thickness two-sided wall that
  meets the box, ends in mid-air or turns a corner, rho 0.8, R 22: the share
  of each record's hemisphere without a partner at res 32, 64, 128, and the
  radiance error against Le / (1 - rho) at res 32.
- ``thin_walls`` the same walls in the furnace, rho 0.8, R 8, shot direct
  light, res 32, 64, 128: radiance error of the lines alone and with traced
  bounces (64 and 256 rays a record in the first pass), and seconds.
- ``thin_sheets`` a closed box split off the voxel grid (at 0.4137 of the box,
  turned 3° and 2°) by a zero-thickness two-sided sheet, a one-sided slab
  0.01 thick or the same slab two-sided, res 32, 37, 48, 64: with a lamp in
  one room, the dark room's mean radiance over the lit room's (``voxgi.solve``
  defaults and the lines alone; 0 is right); as a uniform furnace (rho 0.8,
  a small box in the lit room), every record's error against Le / (1 - rho)
  and the solve's seconds, with the defaults and with 64 direct samples a
  record (the defaults' 16 leave their noise in each record).
- ``cap``        emitting-cap sphere: mean / max error vs resolution (32, 64,
  128) and R (8, 16, 22); rho = 0.5.
- ``cornell``    energy balance on the Cornell box vs resolution (32, 64, 128).
- ``later``      coarser directions after the second bounce (2009 paper):
  time and error against the full set (later_R = R: the same bounce-by-bounce
  form without coarsening, to separate the two effects).
- ``linear``     gathering time for N, 2N, 4N records (bunny room at three
  resolutions) and D, 2D directions, fixed iterations, 1 thread.
- ``throughput`` bunny room at about 150k records, R = 22: gathering rays/s
  on 1 and 2 threads (a ray = one record x one family x one iteration).
- ``paper``      the paper's work unit: ~146k records, gathering R = 22 for 4
  iterations, shooting R = 35 from the small area light: seconds per phase
  on 1 and 2 threads (paper: 404 s propagation, 93 s shooting, one 1.86 GHz
  core).

Each section prints a table and writes ``benchmarks/results/propagation_<section>.json``.
Timings taken on a shared machine are noisy: the JSON records the CPU and load.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import time
from pathlib import Path

import numpy as np

import voxgi
from voxgi import SolveTuning
from voxgi.directions import direction_set
from voxgi.radiosity import line_records
from voxgi.scenes.thin_walls import SPLIT_AT, SPLIT_SLAB, split_box, split_normal

RESULTS = Path(__file__).resolve().parent / "results"


def _meta(threads=None) -> dict:
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
    return {
        "voxgi": voxgi.__version__,
        "commit": commit,
        "cpu": cpu,
        "cores": os.cpu_count(),
        "load": os.getloadavg(),
        "python": platform.python_version(),
        "threads": threads,
        "time": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }


def _write(name: str, rows, **extra) -> None:
    RESULTS.mkdir(parents=True, exist_ok=True)
    out = {"name": f"propagation_{name}", **_meta(), **extra, "rows": rows}
    (RESULTS / f"propagation_{name}.json").write_text(json.dumps(out, indent=1, default=float))


def _table(rows, cols) -> None:
    w = [max(len(c), *(len(_fmt(r.get(c))) for r in rows)) for c in cols]
    print("  ".join(c.rjust(x) for c, x in zip(cols, w, strict=True)))
    for r in rows:
        print("  ".join(_fmt(r.get(c)).rjust(x) for c, x in zip(cols, w, strict=True)))


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def _front_err(sol, exact):
    front = ~sol.vox.back
    err = (sol.radiance.astype(np.float64) / exact - 1)[front]
    return float(np.abs(err).mean()), float(np.abs(err).max())


# ----------------------------------------------------------------------------- sections


def furnace(args) -> None:
    rows = []
    res = args.res[0] if args.res else (32 if args.quick else 48)
    R = args.radii[0] if args.radii else 8
    scenes = [
        ("sphere", lambda r: voxgi.scenes.furnace_sphere(albedo=r, emission=1.0)),
        ("sphere+box", lambda r: voxgi.scenes.furnace_sphere(albedo=r, emission=1.0, inner=True)),
        ("box", lambda r: voxgi.scenes.furnace_box(albedo=r, emission=1.0)),
        ("box+sphere", lambda r: voxgi.scenes.furnace_box(albedo=r, emission=1.0, inner=True)),
    ]
    for name, make in scenes:
        for rho in (0.3, 0.5, 0.9, 0.99):
            vox = voxgi.voxelize(make(rho), resolution=res)
            t = time.perf_counter()
            sol = voxgi.solve(
                vox, radius=R, progress=False, tol=1e-6, tuning=SolveTuning.paper(shoot_radius=R)
            )
            dt = time.perf_counter() - t
            mean, mx = _front_err(sol, 1.0 / (1 - rho))
            # slivers: records holding under 5% of a voxel face (edges of the inner object)
            big = ~vox.back & (vox.area >= 0.05 * vox.pitch**2)
            mx_big = float(np.abs(sol.radiance[big] * (1 - rho) - 1).max())
            rows.append(
                {
                    "scene": name,
                    "rho": rho,
                    "res": res,
                    "R": R,
                    "records": len(vox),
                    "iters": sol.bounces,
                    "mean_err": mean,
                    "max_err": mx,
                    "max_err_area>=0.05": mx_big,
                    "delta": sol.stats["lost_fraction"],
                    "seconds": dt,
                    "pass": bool(mean < 0.005 and mx < 0.02),
                }
            )
            print(rows[-1], flush=True)
    _table(
        rows,
        [
            "scene",
            "rho",
            "records",
            "iters",
            "mean_err",
            "max_err",
            "max_err_area>=0.05",
            "delta",
            "seconds",
            "pass",
        ],
    )
    _write("furnace" if res == 48 and R == 8 else f"furnace_res{res}_R{R}", rows)


def _divided_box(kind: str, rho: float):
    """A closed unit box (uniform emission 1, albedo rho) split by a
    zero-thickness two-sided wall at x = 0.1: ``through`` meets the floor, the
    ceiling and two side walls, ``end`` stops in mid-air, ``corner`` turns to
    meet the side wall at x = 0.5."""
    import trimesh

    s = voxgi.scenes.furnace_box(albedo=rho, emission=1.0)
    mat = voxgi.Material(albedo=rho, emission=1.0)
    h = 0.5
    top = {"plain": None, "through": h, "end": 0.05, "corner": 0.15}[kind]
    if top is None:
        return s

    def quad(corners):
        return trimesh.Trimesh(np.array(corners, float), [[0, 1, 2], [0, 2, 3]], process=False)

    s.add(
        quad([(0.1, -h, -h), (0.1, h, -h), (0.1, h, top), (0.1, -h, top)]),
        mat,
        name="wall",
        two_sided=True,
    )
    if kind == "corner":
        s.add(
            quad([(0.1, -h, top), (0.1, h, top), (h, h, top), (h, -h, top)]),
            mat,
            name="wall_top",
            two_sided=True,
        )
    return s


def junctions(args) -> None:
    """Thin two-sided walls meeting a closed box: the share of each record's
    hemisphere the gathering finds a partner in (1 in a closed scene) at
    three resolutions, and the furnace's radiance error at the first."""
    rho, R = 0.8, 22
    ress = args.res or ([24] if args.quick else [32, 64, 128])
    ds = direction_set(R)
    rows = []
    for kind in ("plain", "through", "end", "corner"):
        for res in ress:
            vox = voxgi.voxelize(_divided_box(kind, rho), resolution=res, progress=False)
            front = ~vox.back
            s = line_records(vox).build()
            live = np.repeat(vox.albedo[:, :1] > 0, 3, axis=1).astype(np.float32)
            every = np.arange(len(ds.families), dtype=np.int64)
            sums, _, _ = s.gather(ds.families, ds.weights, live, every, False, 0)
            lost = (1 - sums[:, 0] / s.normalisation(ds.families, ds.weights, 0))[front]
            row = {
                "wall": kind,
                "res": res,
                "records": int(front.sum()),
                "lost_mean": float(lost.mean()),
                "lost_max": float(lost.max()),
                "lost_over_1%": int((lost > 0.01).sum()),
            }
            if res == ress[0]:
                t = time.perf_counter()
                sol = voxgi.solve(
                    vox, radius=R, progress=False, tol=1e-5, tuning=SolveTuning.paper()
                )
                row["seconds"] = time.perf_counter() - t
                err = np.abs(sol.radiance[front, 0] * (1 - rho) - 1)
                row.update(
                    err_mean=float(err.mean()),
                    err_max=float(err.max()),
                    err_over_2pct=int((err > 0.02).sum()),
                )
            rows.append(row)
            print(rows[-1], flush=True)
    cols = [
        "wall",
        "res",
        "records",
        "lost_mean",
        "lost_max",
        "lost_over_1%",
        "err_mean",
        "err_max",
        "err_over_2pct",
        "seconds",
    ]
    _table(rows, cols)
    full = ress == [32, 64, 128]
    _write("junctions" if full else "junctions_res" + "_".join(map(str, ress)), rows, rho=rho, R=R)


def thin_walls(args) -> None:
    """Thin walls in the uniform furnace: every record's radiance error
    against Le / (1 - rho), the lines alone and with traced bounces."""
    rho, R = 0.8, 8
    ress = args.res or ([24] if args.quick else [32, 64, 128])
    configs = [("lines", 64), ("traced", 64), ("traced", 256)]
    rows = []
    for kind in ("through", "end", "corner"):
        for res in ress:
            vox = voxgi.voxelize(_divided_box(kind, rho), resolution=res, progress=False)
            front = ~vox.back & (vox.area > 0)
            for how, samples in configs:
                tuning = SolveTuning.paper(
                    shoot_radius=R,
                    diagnostics=False,
                    indirect_light=how,
                    traced_samples=samples,
                )
                t = time.perf_counter()
                sol = voxgi.solve(vox, radius=R, progress=False, tuning=tuning)
                err = sol.radiance[front, 0] * (1 - rho) - 1
                rows.append(
                    {
                        "wall": kind,
                        "res": res,
                        "records": int(front.sum()),
                        "bounces": how if how == "lines" else f"traced {samples}",
                        "err_mean": float(err.mean()),
                        "err_max": float(np.abs(err).max()),
                        "err_over_2pct": int((np.abs(err) > 0.02).sum()),
                        "traced_passes": sol.stats.get("traced", {}).get("passes", 0),
                        "traced_seconds": sol.stats["seconds"].get("traced", 0.0),
                        "seconds": time.perf_counter() - t,
                    }
                )
                print(rows[-1], flush=True)
    cols = ["wall", "res", "records", "bounces", "err_mean", "err_max", "err_over_2pct"]
    _table(rows, [*cols, "traced_passes", "traced_seconds", "seconds"])
    full = ress == [32, 64, 128]
    _write(
        "thin_walls" if full else "thin_walls_res" + "_".join(map(str, ress)), rows, rho=rho, R=R
    )


def _split_rooms(vox, wall: str):
    """(dark, lit): records with area in front of the wall's two sides (by a
    point a thousandth of a voxel in front of the centroid), a slab's inside
    in neither."""
    half = 0.0 if wall == "sheet" else SPLIT_SLAB / 2
    p = np.asarray(vox.centroid, np.float64) + 1e-3 * vox.pitch * vox.normal
    s = p @ split_normal() - (-0.5 + SPLIT_AT)
    live = np.asarray(vox.area) > 0
    return live & (s < -half), live & (s > half)


def thin_sheets(args) -> None:
    """No light through a wall thinner than a voxel, off the grid."""
    ress = args.res or ([32] if args.quick else [32, 37, 48, 64])
    rows = []
    for wall in ("sheet", "slab", "two-sided slab"):
        for res in ress:
            row = {"wall": wall, "res": res}
            vox = voxgi.voxelize(split_box(wall, False), resolution=res, progress=False)
            dark, lit = _split_rooms(vox, wall)
            w = np.asarray(vox.area, np.float64)
            for name, tuning in (
                ("defaults", None),
                ("lines", SolveTuning(indirect_light="lines")),
            ):
                L = voxgi.solve(vox, progress=False, tuning=tuning).radiance.mean(axis=1) * w
                row[f"dark/lit {name}"] = float(
                    (L[dark].sum() / w[dark].sum()) / (L[lit].sum() / w[lit].sum())
                )
            vox = voxgi.voxelize(split_box(wall, True), resolution=res, progress=False)
            dark, lit = _split_rooms(vox, wall)
            front = (dark | lit) & ~vox.back
            for name, tuning in (
                ("defaults", None),
                ("ds64", SolveTuning(direct_samples=64)),
            ):
                t0 = time.perf_counter()
                sol = voxgi.solve(vox, progress=False, tuning=tuning)
                row[f"furnace {name} s"] = time.perf_counter() - t0
                err = sol.radiance[front, 0] * (1 - 0.8) - 1
                row[f"furnace {name} mean"] = float(err.mean())
                row[f"furnace {name} max"] = float(np.abs(err).max())
                row[f"furnace {name} >2%"] = int((np.abs(err) > 0.02).sum())
            row["records"] = int(front.sum())
            rows.append(row)
            print(rows[-1], flush=True)
    _table(rows, list(rows[0]))
    full = ress == [32, 37, 48, 64]
    _write("thin_sheets" if full else "thin_sheets_res" + "_".join(map(str, ress)), rows)


def _err_vs(sol, ref, vox) -> np.ndarray:
    """Relative error of ``sol`` against a reference solution on the lit front records."""
    front = ~vox.back & (ref.radiosity.max(axis=1) > 0)
    return np.abs(sol.radiosity[front] / ref.radiosity[front] - 1)


def _cap_exact(vox, rho):
    front = ~vox.back
    Le = vox.emission.astype(np.float64)
    A = vox.area.astype(np.float64)
    Lm = (Le * A[:, None])[front].sum(axis=0) / A[front].sum()
    return Le + rho * Lm / (1 - rho)


def cap(args) -> None:
    rho = 0.5
    ress = args.res or ((32, 64) if args.quick else (32, 64, 128))
    radii = args.radii or (8, 16, 22)
    # keep the rows of earlier runs (the big cases take long on a shared machine)
    old = RESULTS / "propagation_cap.json"
    rows = json.loads(old.read_text())["rows"] if old.exists() and not args.fresh else []
    done = {(r["res"], r["R"]) for r in rows}
    voxs = {
        res: voxgi.voxelize(voxgi.scenes.cap_sphere(albedo=rho, emission=1.0), resolution=res)
        for res in ress
    }
    for R in radii:
        for res in ress:
            if (res, R) in done:
                continue
            vox = voxs[res]
            t = time.perf_counter()
            sol = voxgi.solve(
                vox, radius=R, progress=False, tol=1e-5, tuning=SolveTuning.paper(shoot_radius=R)
            )
            dt = time.perf_counter() - t
            mean, mx = _front_err(sol, _cap_exact(vox, rho))
            rows.append(
                {
                    "res": res,
                    "R": R,
                    "records": len(vox),
                    "iters": sol.bounces,
                    "mean_err": mean,
                    "max_err": mx,
                    "delta": sol.stats["lost_fraction"],
                    "seconds": dt,
                }
            )
            print(rows[-1], flush=True)
            rows.sort(key=lambda r: (r["res"], r["R"]))
            _write(
                "cap", rows, rho=rho, note="shoot_directions = directions = R"
            )  # partial results
    _table(rows, ["res", "R", "records", "iters", "mean_err", "max_err", "delta", "seconds"])


def cornell(args) -> None:
    # The open Cornell box as it is, then (albedo 0: direct light alone) the
    # box closed by a fourth wall with and without its blocks: where the
    # remaining imbalance comes from.
    import dataclasses

    def closed(blocks: bool) -> voxgi.Scene:
        return voxgi.scenes.cornell_box(width=32, height=32, blocks=blocks, closed=True)

    rows = []
    cases = [
        ("open", voxgi.scenes.cornell_box(width=32, height=32), False),
        ("closed, albedo 0", closed(True), True),
        ("closed, no blocks, albedo 0", closed(False), True),
    ]
    ress = (32, 64) if args.quick else (32, 64, 128)
    for name, scene, black in cases:
        for res in ress:
            vox = voxgi.voxelize(scene, resolution=res)
            if black:
                vox = dataclasses.replace(vox, albedo=np.zeros_like(vox.albedo))
            if res == 128 and name != "open":
                continue  # the trend is clear from 32 and 64
            t = time.perf_counter()
            sol = voxgi.solve(
                vox, radius=8, progress=False, tol=1e-5, tuning=SolveTuning.paper(shoot_radius=16)
            )
            dt = time.perf_counter() - t
            e = sol.stats["energy"]
            em = np.array(e["emitted"])
            rows.append(
                {
                    "scene": name,
                    "res": res,
                    "records": len(vox),
                    "iters": sol.bounces,
                    "imbalance_r": e["imbalance"][0],
                    "imbalance_g": e["imbalance"][1],
                    "absorbed/emitted": float(e["absorbed"][0] / em[0]),
                    "escaping/emitted": float(e["escaping"][0] / em[0]),
                    "seconds": dt,
                }
            )
            print(rows[-1], flush=True)
    _table(
        rows,
        [
            "scene",
            "res",
            "records",
            "iters",
            "imbalance_r",
            "imbalance_g",
            "absorbed/emitted",
            "escaping/emitted",
            "seconds",
        ],
    )
    _write(
        "cornell",
        rows,
        note="imbalance = (emitted - absorbed - escaping) / emitted; "
        "escaping counted on the sender side",
    )


def later(args) -> None:
    rows = []
    res = 48 if args.quick else 64
    vox = voxgi.voxelize(voxgi.scenes.cornell_box(width=32, height=32), resolution=res)
    ref = voxgi.solve(
        vox, radius=22, progress=False, tol=1e-6, tuning=SolveTuning.paper(shoot_radius=22)
    )
    for R, Rl in ((22, None), (22, 22), (22, 11), (22, 8), (16, None), (11, None), (8, None)):
        t = time.perf_counter()
        sol = voxgi.solve(
            vox,
            radius=R,
            progress=False,
            tol=1e-6,
            tuning=SolveTuning.paper(shoot_radius=22, later_radius=Rl, later_after=2),
        )
        dt = time.perf_counter() - t
        err = _err_vs(sol, ref, vox)
        rows.append(
            {
                "R": R,
                "later_R": Rl,
                "iters": sol.bounces,
                "gather_s": sol.stats["seconds"]["gather"],
                "mean_err_vs_R22": float(err.mean()),
                "p99_err_vs_R22": float(np.quantile(err, 0.99)),
                "seconds": dt,
            }
        )
        print(rows[-1], flush=True)
    _table(
        rows, ["R", "later_R", "iters", "gather_s", "mean_err_vs_R22", "p99_err_vs_R22", "seconds"]
    )
    _write("later", rows, res=res, note="Cornell box; reference R = 22 everywhere, tol 1e-6")


def _bunny(res):
    return voxgi.voxelize(voxgi.scenes.bunny_room(width=32, height=32), resolution=res)


def _gather_time(vox, R, threads, iters=2, repeats=1):
    s = voxgi.radiosity.line_system(vox)
    ds = direction_set(R)
    vals = np.random.default_rng(0).random((len(vox), 3)).astype(np.float32)
    fam = np.arange(len(ds.families), dtype=np.int64)
    s.gather(ds.families[:8].copy(), ds.weights[:8].copy(), vals, fam[:8], False, threads)  # warm
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(iters):
            s.gather(ds.families, ds.weights, vals, fam, False, threads)
        best = min(best, time.perf_counter() - t)
    rays = len(vox) * len(ds.families) * iters
    return best, rays


def linear(args) -> None:
    rows = []
    base = 48 if args.quick else 64
    for res, R in ((base, 11), (round(base * 2**0.5), 11), (2 * base, 11), (base, 16)):
        vox = _bunny(res)
        dt, rays = _gather_time(vox, R, 1)
        rows.append(
            {
                "res": res,
                "records": len(vox),
                "R": R,
                "families": len(direction_set(R).families),
                "iters": 2,
                "seconds": dt,
                "ns_per_ray": 1e9 * dt / rays,
                "Mrays_s": rays / dt / 1e6,
            }
        )
        print(rows[-1], flush=True)
    _table(rows, ["res", "records", "R", "families", "iters", "seconds", "ns_per_ray", "Mrays_s"])
    _write("linear", rows, note="gathering only, 1 thread; ray = record x family x iteration")


def throughput(args) -> None:
    # One gathering iteration over all 2991 families of R 22, three ways:
    # the one-pass walk (every iteration without recorded pairs), the same
    # walk recording its pairs (a solve's first pass over a set), and the
    # replay of the recorded pairs (its later passes); the counting-sort
    # walk for reference.
    rows = []
    res = 64 if args.quick else 113
    vox = _bunny(res)
    ds = direction_set(22)
    vals = np.random.default_rng(0).random((len(vox), 3)).astype(np.float32)
    fam = np.arange(len(ds.families), dtype=np.int64)
    rays = len(vox) * len(fam)
    for th in args.threads:
        s = voxgi.radiosity.line_system(vox)
        tab = s.make_pair_table(ds.families, ds.weights, False)
        args_ = (ds.families, ds.weights, vals, fam, False, th)
        runs = {
            "onepass": (s.gather, args_, {}),
            "sort": (voxgi._core.testing.gather_sorted, (s, *args_), {}),
            "record": (s.gather, args_, {"record": tab}),
            "replay": (s.gather_recorded, (tab, vals, fam, False, th), {}),
        }
        took = {}
        for algo, (fn, a, kw) in runs.items():
            t = time.perf_counter()
            fn(*a, **kw)
            took[algo] = dt = time.perf_counter() - t
            rows.append(
                {
                    "records": len(vox),
                    "R": 22,
                    "threads": th,
                    "algorithm": algo,
                    "seconds": dt,
                    "Mrays_s": rays / dt / 1e6,
                    "Mrays_s_per_thread": rays / dt / 1e6 / th,
                    "table_GB": tab.nbytes / 1e9 if algo in ("record", "replay") else 0.0,
                }
            )
            print(rows[-1], flush=True)
        # What a solve's gathering does with these passes (4 iterations, the
        # paper's work unit): the first walks and records, the other three
        # replay; a ray per record, family and iteration, as sol.stats counts.
        t4 = took["record"] + 3 * took["replay"]
        rows.append(
            {
                "records": len(vox),
                "R": 22,
                "threads": th,
                "algorithm": "solve4 (record + 3 replays)",
                "seconds": t4,
                "Mrays_s": 4 * rays / t4 / 1e6,
                "Mrays_s_per_thread": 4 * rays / t4 / 1e6 / th,
                "table_GB": tab.nbytes / 1e9,
            }
        )
        print(rows[-1], flush=True)
        del tab
    _table(
        rows,
        ["records", "threads", "algorithm", "seconds", "Mrays_s", "Mrays_s_per_thread", "table_GB"],
    )
    _write(
        "throughput",
        rows,
        res=res,
        note="one gathering iteration over all 2991 families (solve4: the record row plus "
        "three times the replay row, over 4 iterations); a ray is one record meeting one "
        "direction family in one iteration",
    )


def paper(args) -> None:
    rows = []
    res = 64 if args.quick else 112
    vox = _bunny(res)
    for th, cache in [(th, c) for c in (False, None) for th in args.threads]:
        t = time.perf_counter()
        sol = voxgi.solve(
            vox,
            radius=22,
            max_bounces=4,
            threads=th,
            progress=False,
            tuning=SolveTuning.paper(shoot_radius=35, pair_cache=cache),
        )
        dt = time.perf_counter() - t
        sec = sol.stats["seconds"]
        rows.append(
            {
                "records": len(vox),
                "emitters": sol.stats["emitters"],
                "threads": th,
                "pairs": "replayed" if sol.stats["pair_cache"].get("replayed_passes") else "walked",
                "shoot_s": sec["shoot"],
                "gather_s": sec["gather"],
                "total_s": dt,
                "shoot_rays": sol.stats["shoot_rays"],
                "gather_rays": sol.stats["gather_rays"],
                "shoot_Mrays_s": sol.stats["shoot_rays"] / sec["shoot"] / 1e6,
                "gather_Mrays_s": sol.stats["gather_rays"] / sec["gather"] / 1e6,
                "gather_Mrays_s_per_thread": sol.stats["gather_rays"] / sec["gather"] / 1e6 / th,
                "paper_shoot_s": 93,
                "paper_propagate_s": 404,
            }
        )
        print(rows[-1], flush=True)
    _table(
        rows,
        [
            "records",
            "emitters",
            "threads",
            "pairs",
            "shoot_s",
            "gather_s",
            "total_s",
            "shoot_rays",
            "gather_rays",
            "gather_Mrays_s",
            "gather_Mrays_s_per_thread",
            "paper_shoot_s",
            "paper_propagate_s",
        ],
    )
    _write("paper", rows, res=res)


def dump(args) -> None:
    """Write the paper work unit's records for benchmarks/propagate_bench.cpp."""
    res = 64 if args.quick else 112
    vox = _bunny(res)
    rec = line_records(vox)
    emit = np.flatnonzero(vox.is_emitter).astype(np.int32)
    vals = (np.pi * vox.emission.astype(np.float32) + 0.5 * vox.albedo).astype(np.float32)
    path = RESULTS / f"bunny_room_{res}.bin"
    with open(path, "wb") as f:
        f.write(np.int64(len(vox)).tobytes())
        for arr in (rec.ijk, rec.normal, rec.point, vals):
            f.write(np.ascontiguousarray(arr).tobytes())
        f.write(np.int64(len(emit)).tobytes())
        f.write(emit.tobytes())
        for R in (22, 35):
            ds = direction_set(R)
            f.write(np.int64(len(ds.families)).tobytes())
            f.write(ds.families.tobytes())
            f.write(ds.weights.tobytes())
    print(f"wrote {path} ({len(vox)} records, {len(emit)} emitters)")


def _send_ratio(vox, R: int, threads: int) -> dict:
    """Per object: the power its records deliver through the gathering
    operator per unit radiosity (the transposed pass of area / S) over the
    power they send into the directions in which they found a partner
    (area x found share). 1 everywhere would make the gathering conserve
    energy; where it is not 1 is where the imbalance comes from."""
    s = line_records(vox).build()
    a = {"area": vox.area.astype(np.float64), "back": np.asarray(vox.back, bool)}
    n = len(vox)
    ds = direction_set(R)
    fam = np.arange(len(ds.families), dtype=np.int64)
    S = s.normalisation(ds.families, ds.weights, threads)
    w = np.repeat((a["area"] / S)[:, None], 3, axis=1).astype(np.float32)
    _, vis, _ = s.gather(ds.families, ds.weights, np.zeros((n, 3), np.float32), fam, True, threads)
    col, _, _ = voxgi._core.testing.gather_sorted(
        s, ds.families, ds.weights, w, fam, False, threads, transpose=True
    )
    target = a["area"] * vis / S
    out = {}
    for o in np.unique(vox.object_id):
        m = (vox.object_id == o) & ~a["back"]
        out[str(int(o))] = float(col[m, 0].sum() / target[m].sum()) if target[m].sum() > 0 else 0.0
    return out


def energy(args) -> None:
    # The open Cornell box's energy balance against the resolution (the
    # convergence study docs/design.md §10 asks the tolerance to come from):
    # R 8, shooting 16, tol 1e-5, the default rules; escaping counted on the
    # sender side. One thread (--threads: the first value) and the recorded
    # pairs (pair_cache=True: res 512 needs about 6 GB for them).
    radii = args.radii or [8, 16]
    R, Rs = radii[0], radii[1] if len(radii) > 1 else 2 * radii[0]
    ress = args.res or ([32, 64] if args.quick else [32, 64, 128, 256])
    th = args.threads[0]
    scene = voxgi.scenes.cornell_box(width=32, height=32)
    names = [o.name for o in scene.objects]
    rows = []
    for res in ress:
        vox = voxgi.voxelize(scene, resolution=res)
        ratio = _send_ratio(vox, R, th) if res <= 128 else {}
        ratio = {names[int(k)]: v for k, v in ratio.items()}
        t = time.perf_counter()
        sol = voxgi.solve(
            vox,
            radius=R,
            progress=False,
            tol=1e-5,
            threads=th,
            tuning=SolveTuning.paper(shoot_radius=Rs, pair_cache=True),
        )
        dt = time.perf_counter() - t
        e = sol.stats["energy"]
        em = np.array(e["emitted"])
        rows.append(
            {
                "res": res,
                "records": len(vox),
                "R": R,
                "Rs": Rs,
                "iters": sol.bounces,
                "imbalance_r": e["imbalance"][0],
                "imbalance_g": e["imbalance"][1],
                "imbalance_b": e["imbalance"][2],
                "absorbed/emitted": float(e["absorbed"][0] / em[0]),
                "escaping/emitted": float(e["escaping"][0] / em[0]),
                "seconds": dt,
                "send_ratio": ratio,
            }
        )
        print(rows[-1], flush=True)
    _table(
        rows,
        [
            "res",
            "records",
            "R",
            "Rs",
            "iters",
            "imbalance_r",
            "imbalance_g",
            "imbalance_b",
            "absorbed/emitted",
            "escaping/emitted",
            "seconds",
        ],
    )
    print("send ratio of the gathering (delivered / sent per unit radiosity; front records):")
    for r in rows:
        if r["send_ratio"]:
            ratios = "  ".join(f"{k} {v:.4f}" for k, v in r["send_ratio"].items())
            print(f"  res {r['res']:4d}: {ratios}")
    # keep the rows of other resolutions from earlier runs (a 768 run takes
    # a while on its own); each row says its threads and seconds
    for r in rows:
        r["threads"] = th
    old = RESULTS / f"propagation_energy_R{R}.json"
    if old.exists() and not args.fresh:
        done = {r["res"] for r in rows}
        rows = sorted(
            [r for r in json.loads(old.read_text())["rows"] if r["res"] not in done] + rows,
            key=lambda r: r["res"],
        )
    _write(
        f"energy_R{R}",
        rows,
        threads=th,
        note="open Cornell box; imbalance = (emitted - absorbed - escaping) / emitted, "
        "escaping counted on the sender side",
    )


SECTIONS = {
    "furnace": furnace,
    "junctions": junctions,
    "thin_walls": thin_walls,
    "thin_sheets": thin_sheets,
    "cap": cap,
    "cornell": cornell,
    "energy": energy,
    "later": later,
    "linear": linear,
    "throughput": throughput,
    "paper": paper,
}
EXTRA = {"dump": dump}  # not run by default


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sections", nargs="*", default=[], help=", ".join(SECTIONS))
    ap.add_argument("--quick", action="store_true", help="smaller cases")
    ap.add_argument(
        "--fresh",
        action="store_true",
        help="cap, energy: run every cell (default: keep the cells of earlier runs)",
    )
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument(
        "--res",
        type=int,
        nargs="+",
        help="cap, energy, junctions, thin_walls, thin_sheets: resolutions; furnace: the first one",
    )
    ap.add_argument(
        "--radii",
        type=int,
        nargs="+",
        help="cap: direction radii; furnace: the first one; energy: R and Rs",
    )
    args = ap.parse_args()
    bad = [s for s in args.sections if s not in SECTIONS and s not in EXTRA]
    if bad:
        ap.error(f"unknown section(s) {bad}; known: {', '.join(SECTIONS)}")
    for name in args.sections or list(SECTIONS):
        print(f"== {name}", flush=True)
        {**SECTIONS, **EXTRA}[name](args)


if __name__ == "__main__":
    main()
