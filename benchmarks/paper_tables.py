"""The paper's Tables 1, 2 and 4 on voxgi's look-alikes of its test scenes.

Piwowar & Malgouyres report, per scene: voxels, light path length (LPL),
shooting / linear-method sphere radii (SR, LR), image size and total time
(Table 1); shooting, propagation and ray-tracing seconds with the discrete
shooting, discrete linear-method and continuous ray counts (Table 2); and
rays per second of each kind (Table 4), on one 1.86 GHz Core 2 core.

Here the same settings run on voxgi's procedural look-alikes (the paper's
geometry was never published: the comparison is by kind, not exact). Each
scene's resolution is chosen so its front-facing records approach the
paper's voxel count. Ray counts follow voxgi's definitions (a gathering ray is
one record x one direction family x one iteration; a shooting ray one emitter
record x one direction; continuous rays are primary + shadow + final-gather
rays cast by Embree), which differ from the paper's; the ray rates are
comparable in kind.

Run on its own (never collected by pytest)::

    python benchmarks/paper_tables.py [--quick] [--threads N] [--scenes labyrinth ...]

Prints the three tables next to the paper's and writes
``benchmarks/results/paper_tables.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

import voxgi

RESULTS = Path(__file__).resolve().parent / "results"

# name: (voxgi scene, paper voxels, LPL, SR, LR, paper size, paper TT, ST, LT, RTT,
#        SRays, LRays, CRays, DSR/s, DLR/s, CR/s)   -- Tables 1, 2, 4 of the paper
PAPER = {
    "labyrinth": (
        "labyrinth",
        11803,
        9,
        35,
        22,
        "512x512",
        207,
        12,
        68,
        124,
        22e6,
        183e6,
        48.5e6,
        1_833_333,
        2_691_176,
        391_373,
    ),
    "emission": (
        "emission",
        36062,
        4,
        8,
        22,
        "512x512",
        112,
        5,
        50,
        56,
        3.7e6,
        284e6,
        8.7e6,
        670_556,
        5_636_372,
        154_896,
    ),
    "shadow": (
        "shadow",
        26547,
        4,
        22,
        18,
        "512x512",
        147,
        4,
        23,
        119,
        3.2e6,
        141e6,
        29.3e6,
        703_332,
        5_886_649,
        246_006,
    ),
    "geometric": (
        "geometric",
        21074,
        4,
        28,
        18,
        "512x512",
        208,
        11,
        20,
        176,
        8.1e6,
        109e6,
        43.5e6,
        740_149,
        5_453_033,
        247_269,
    ),
    "bunny": (
        "bunny-room",
        146355,
        5,
        35,
        22,
        "1024x768",
        558,
        93,
        404,
        52,
        70.5e6,
        807.6e6,
        9.45e6,
        758_064,
        1_999_010,
        150_105,
    ),
    "sponza": (
        "sponza-atrium",
        236754,
        7,
        35,
        26,
        "1024x768",
        29185,
        274,
        960,
        27755,
        211.4e6,
        1181e6,
        2030e6,
        771_533,
        1_230_208,
        73_129,
    ),
}


def _resolution_for(scene, target: int) -> tuple[int, voxgi.VoxelSet]:
    """Resolution whose front records come closest to ``target`` (records ~ res²)."""
    res = 48
    for _ in range(3):
        vox = voxgi.voxelize(scene, res)
        n = int((~vox.back).sum())
        new = round(res * np.sqrt(target / max(n, 1)))
        if abs(new - res) <= 1:
            break
        res = max(8, min(new, 1024))
    vox = voxgi.voxelize(scene, res)
    return res, vox


def run_scene(key: str, args) -> dict:
    (
        scene_name,
        vox_p,
        lpl,
        sr,
        lr,
        size_p,
        tt_p,
        st_p,
        lt_p,
        rtt_p,
        sr_p,
        lr_p,
        cr_p,
        dsr_p,
        dlr_p,
        cr_s_p,
    ) = PAPER[key]
    w, h = (128, 128) if args.quick else (512, 512)
    scene = voxgi.scenes.get(scene_name, width=w, height=h)
    target = vox_p // 8 if args.quick else vox_p
    t0 = time.perf_counter()
    res, vox = _resolution_for(scene, target)
    t_vox = vox.stats["seconds"]
    if args.quick:
        sr, lr = min(sr, 8), min(lr, 6)
    bounces = lpl - 1  # light path length = reflections + 1; the first is the shooting
    sol = voxgi.solve(
        vox,
        radius=lr,
        max_bounces=bounces - 1,
        tol=1e-12,
        threads=args.threads,
        progress=False,
        tuning=voxgi.SolveTuning.paper(shoot_radius=sr, direct_light=args.direct_light),
    )
    out = voxgi.render(
        scene, sol, threads=args.threads, progress=False, max_frames=8 if args.quick else None
    )
    wall = time.perf_counter() - t0
    s = sol.stats
    # ST: the first bounce's time, the shooting or the exact direct light
    st = s["seconds"].get("shoot", s["seconds"].get("direct", 0.0))
    lt = s["seconds"].get("gather", 0.0)
    rtt = out.stats["seconds"]["display"]
    crays = out.stats["primary_rays"] + out.stats["shadow_rays"] + out.stats.get("gather_rays", 0)
    row = {
        "scene": key,
        "voxgi_scene": scene_name,
        "resolution": res,
        "records": len(vox),
        "front_records": int((~vox.back).sum()),
        "LPL": lpl,
        "SR": sr,
        "LR": lr,
        "size": f"{w}x{h}",
        "bounces": sol.bounces,
        "voxelize_s": t_vox,
        "ST": st,
        "LT": lt,
        "RTT": rtt,
        "TT": t_vox + s["seconds"]["total"] + rtt,
        "wall_s": wall,
        "direct_light": args.direct_light,
        "SRays": s["shoot_rays"] if args.direct_light == "shoot" else s["direct_light"]["rays"],
        "LRays": s["gather_rays"],
        "CRays": crays,
        "frames": out.frames,
        "DSR": (s["shoot_rays"] if args.direct_light == "shoot" else s["direct_light"]["rays"]) / st
        if st > 0
        else float("nan"),
        "DLR": s["gather_rays"] / lt if lt > 0 else float("nan"),
        "CR": crays / rtt if rtt > 0 else float("nan"),
        "paper": {
            "voxels": vox_p,
            "size": size_p,
            "TT": tt_p,
            "ST": st_p,
            "LT": lt_p,
            "RTT": rtt_p,
            "SRays": sr_p,
            "LRays": lr_p,
            "CRays": cr_p,
            "DSR": dsr_p,
            "DLR": dlr_p,
            "CR": cr_s_p,
        },
    }
    return row


def _e(v) -> str:
    return f"{v:.3g}" if isinstance(v, float) else str(v)


def print_tables(rows, threads) -> None:
    print("\nTable 1 (scene statistics)  -- voxgi | paper")
    print(
        f"{'Scene':<10} {'records':>9} {'front':>8} {'paper vox':>9} {'LPL':>3} {'SR':>3} "
        f"{'LR':>3} {'size':>8} {'TT s':>8} {'paper TT':>8}"
    )
    for r in rows:
        p = r["paper"]
        print(
            f"{r['scene']:<10} {r['records']:9,d} {r['front_records']:8,d} {p['voxels']:9,d} "
            f"{r['LPL']:3d} {r['SR']:3d} {r['LR']:3d} {r['size']:>8} {r['TT']:8.2f} "
            f"{p['TT']:8d}"
        )
    print("\nTable 2 (seconds and rays per kind)  -- voxgi (paper)")
    print(
        f"{'Scene':<10} {'ST':>14} {'LT':>14} {'RTT':>16} {'SRays':>18} {'LRays':>20} {'CRays':>20}"
    )
    for r in rows:
        p = r["paper"]
        print(
            f"{r['scene']:<10} {r['ST']:6.2f} ({p['ST']:5d}) {r['LT']:6.2f} ({p['LT']:5d}) "
            f"{r['RTT']:7.2f} ({p['RTT']:5d}) {r['SRays']:8.3g} ({p['SRays']:7.3g}) "
            f"{r['LRays']:9.3g} ({p['LRays']:8.3g}) {r['CRays']:9.3g} ({p['CRays']:8.3g})"
        )
    print(f"\nTable 4 (rays per second; voxgi on {threads} thread(s), paper on one 1.86 GHz core)")
    print(
        f"{'Scene':<10} {'DSR':>10} {'paper':>9} {'x':>6} {'DLR':>10} {'paper':>9} {'x':>6} "
        f"{'CR':>9} {'paper':>8} {'x':>5} {'CR/DSR':>7} {'CR/DLR':>7}"
    )
    for r in rows:
        p = r["paper"]
        print(
            f"{r['scene']:<10} {r['DSR']:10.3g} {p['DSR']:9.3g} {r['DSR'] / p['DSR']:6.0f} "
            f"{r['DLR']:10.3g} {p['DLR']:9.3g} {r['DLR'] / p['DLR']:6.0f} {r['CR']:9.3g} "
            f"{p['CR']:8.3g} {r['CR'] / p['CR']:5.1f} {100 * r['CR'] / r['DSR']:6.2f}% "
            f"{100 * r['CR'] / r['DLR']:6.2f}%"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (a smoke run)")
    ap.add_argument("--threads", type=int, default=None, help="threads (default: all)")
    ap.add_argument("--scenes", nargs="+", default=list(PAPER), choices=list(PAPER))
    ap.add_argument(
        "--direct-light",
        choices=["shoot", "exact"],
        default="shoot",
        help="the first bounce: the paper's shooting (default) or exact direct light "
        "(SRays then counts its shadow and hemisphere rays)",
    )
    ap.add_argument(
        "--out",
        type=Path,
        default=None,
        help="JSON file (default results/paper_tables.json, or "
        "paper_tables_quick.json with --quick)",
    )
    args = ap.parse_args()
    rows = []
    for key in args.scenes:
        print(f"running {key} ...", flush=True)
        rows.append(run_scene(key, args))
    threads = args.threads or os.cpu_count()
    print_tables(rows, threads)
    RESULTS.mkdir(parents=True, exist_ok=True)
    rec = {
        "name": "paper_tables",
        "voxgi": voxgi.__version__,
        "quick": args.quick,
        "threads": threads,
        "cpu": platform.processor() or platform.machine(),
        "load_avg": os.getloadavg(),
        "rows": rows,
    }
    name = "paper_tables_quick.json" if args.quick else "paper_tables.json"
    out = args.out or RESULTS / name
    out.write_text(json.dumps(rec, indent=1, default=float))
    print(f"\nwrote {out}")


if __name__ == "__main__":
    main()
