"""Benchmark voxgi.voxelize: the bunny at resolution 128, 256, 512 and a
subdivided bunny of about 1M triangles at 512.

Run on its own (never collected by pytest)::

    python benchmarks/voxelize.py [--repeats 5] [--threads N] [--quick]

Each case runs in a fresh subprocess so that its peak resident memory is its
own: the table gives the process's peak RSS growth during voxelization over
the RSS once the scene is built (Linux ``VmHWM``, reset through
``/proc/self/clear_refs``), and the kernel's own accounting of its large
buffers (``stats["peak_bytes"]``). Times are the
median (and minimum) of ``--repeats`` runs after one warm-up. Prints a table
and writes ``benchmarks/results/voxelize.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

CASES = [("bunny", 128), ("bunny", 256), ("bunny", 512), ("bunny_1m", 512)]
TARGETS = {("bunny", 256): 1.0, ("bunny_1m", 512): 20.0}  # seconds


def build_scene(name: str):
    import trimesh

    import voxgi

    mesh = voxgi.scenes.load_bunny()
    if name == "bunny_1m":
        # Four midpoint subdivisions: 3674 * 4**4 = 940,544 triangles.
        v, f = mesh.vertices, mesh.faces
        for _ in range(4):
            v, f = trimesh.remesh.subdivide(v, f)
        mesh = trimesh.Trimesh(v, f, process=False)
    s = voxgi.Scene()
    s.add(mesh, voxgi.Material(albedo=0.7), name=name)
    return s


def _status_bytes(field: str) -> int | None:
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def _reset_peak() -> bool:
    """Reset the kernel's peak-RSS mark (Linux: write 5 to clear_refs)."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
        return True
    except OSError:
        return False


def run_one(name: str, resolution: int, repeats: int, threads: int | None) -> dict:
    import gc

    import voxgi

    scene = build_scene(name)
    gc.collect()
    # Peak RSS growth over the RSS once the scene is built: Linux's VmHWM reset
    # through clear_refs, else ru_maxrss (which then cannot see below the
    # peak of building the scene).
    if _reset_peak() and _status_bytes("VmRSS") is not None:
        rss0, peak = _status_bytes("VmRSS"), lambda: _status_bytes("VmHWM")
    else:  # pragma: no cover - not Linux
        rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
        peak = lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # noqa: E731
    vox = voxgi.voxelize(scene, resolution, threads=threads)  # warm-up
    times = []
    for _ in range(repeats):
        vox = None  # free the previous result: the RSS growth is one run's
        t = time.perf_counter()
        vox = voxgi.voxelize(scene, resolution, threads=threads)
        times.append(time.perf_counter() - t)
    rss1 = peak()
    st = vox.stats
    return {
        "case": name,
        "resolution": resolution,
        "triangles": st["triangles"],
        "records": len(vox),
        "cells": st["cells"],
        "pairs": st["pairs"],
        "back_records": st["back_records"],
        "cut_records": st["cut_records"],
        "median_s": statistics.median(times),
        "min_s": min(times),
        "repeats": repeats,
        "phase_seconds": st["phase_seconds"],
        "threads": st["threads"],
        "kernel_peak_bytes": st["peak_bytes"],
        "estimate_bytes": st["estimate_bytes"],
        "rss_growth_bytes": max(0, rss1 - rss0),
        "rss_peak_bytes": rss1,
    }


def git_commit() -> str:
    try:
        return subprocess.run(
            ["git", "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            cwd=Path(__file__).parent,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--quick", action="store_true", help="bunny cases only")
    ap.add_argument("--one", nargs=2, metavar=("CASE", "RES"), help=argparse.SUPPRESS)
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "voxelize.json"))
    a = ap.parse_args()
    if a.one:
        print(json.dumps(run_one(a.one[0], int(a.one[1]), a.repeats, a.threads)))
        return

    import voxgi

    rows = []
    for name, res in CASES:
        if a.quick and name != "bunny":
            continue
        reps = a.repeats if name == "bunny" else max(1, min(a.repeats, 3))
        cmd = [sys.executable, __file__, "--one", name, str(res), "--repeats", str(reps)]
        if a.threads:
            cmd += ["--threads", str(a.threads)]
        out = subprocess.run(cmd, capture_output=True, text=True, check=True)
        rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
        r = rows[-1]
        target = TARGETS.get((name, res))
        r["target_s"] = target
        r["meets_target"] = None if target is None else r["median_s"] <= target

    hdr = (
        f"{'case':<10} {'res':>4} {'triangles':>10} {'records':>10} {'cells':>9} "
        f"{'median s':>9} {'min s':>8} {'kernel MB':>10} {'RSS+ MB':>8} {'target':>7}"
    )
    print(hdr)
    print("-" * len(hdr))
    for r in rows:
        tgt = "" if r["target_s"] is None else f"<={r['target_s']:g}s"
        print(
            f"{r['case']:<10} {r['resolution']:>4} {r['triangles']:>10,} {r['records']:>10,} "
            f"{r['cells']:>9,} {r['median_s']:>9.3f} {r['min_s']:>8.3f} "
            f"{r['kernel_peak_bytes'] / 2**20:>10.1f} {r['rss_growth_bytes'] / 2**20:>8.1f} "
            f"{tgt:>7}"
        )
    meta = {
        "benchmark": "voxelize",
        "voxgi_version": voxgi.__version__,
        "git_commit": git_commit(),
        "cpu": cpu_name(),
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "threads": rows[0]["threads"] if rows else None,
        "time": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    path = Path(a.out)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({**meta, "results": rows}, indent=2) + "\n")
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()
