"""How fast the solve's traced passes find the record a ray lands on.

Per scene: one voxelize with the defaults, then the traced gather of the
solve (:class:`voxgi.traced.TracedGather`, every reflecting record shooting
``--samples`` rays against the exact triangles and looking up the record at
each hit) timed over ``--repeats`` passes, best pass reported, in million
rays per second of wall time and of CPU time (all threads; steadier on a
shared machine); and Embree alone on the same number of rays (the same
origins, cosine-distributed directions; :class:`voxgi.rays.Tracer`), so that
the share of a pass that is the lookup shows. With ``--records-per-voxel``
the distribution of records per voxel.

Usage::

    python benchmarks/record_lookup.py [--samples 16] [--repeats 3] [--threads 2] [scene ...]

A scene is a built-in name (default: cornell-box door-room) or a scene file.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import voxgi
from voxgi.rays import Tracer
from voxgi.traced import TracedGather


def _load(name: str) -> voxgi.Scene:
    return voxgi.Scene.load(name) if Path(name).suffix else voxgi.scenes.get(name)


def _embree_alone(scene, vox, samples: int, threads: int, repeats: int) -> float:
    """Best seconds of Embree tracing ``samples`` cosine rays from each record."""
    rng = np.random.default_rng(0)
    with Tracer(scene, threads) as tr:
        org = np.repeat(np.asarray(vox.centroid, np.float64) - tr.centre, samples, axis=0)
        n = np.repeat(np.asarray(vox.normal, np.float64), samples, axis=0)
        d = rng.normal(size=org.shape)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        d = n + d  # cosine-distributed about n
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        org = org + 1e-4 * float(np.linalg.norm(np.ptp(scene.bounds, axis=0))) * n
        best = np.inf
        for _ in range(repeats):
            t = time.perf_counter()
            tr.first_hit(org, d)
            best = min(best, time.perf_counter() - t)
    return best


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scenes", nargs="*", default=["cornell-box", "door-room"])
    ap.add_argument("--samples", type=int, default=16, help="rays per record a pass")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--no-embree", action="store_true", help="skip Embree alone")
    ap.add_argument("--records-per-voxel", action="store_true")
    args = ap.parse_args()
    for name in args.scenes:
        scene = _load(name)
        vox = voxgi.voxelize(scene, progress=False)
        if args.records_per_voxel:
            _, counts = np.unique(np.asarray(vox.ijk), axis=0, return_counts=True)
            q = np.percentile(counts, [50, 90, 99, 100])
            crowd = np.sum(counts**2) / len(vox)
            print(f"{name}: {len(vox)} records in {len(counts)} voxels; per voxel "
                  f"median {q[0]:.0f} p90 {q[1]:.0f} p99 {q[2]:.0f} max {q[3]:.0f}; "
                  f"a record's voxel holds {crowd:.1f} on average")  # fmt: skip
        rng = np.random.default_rng(1)
        values = rng.uniform(0.0, 1.0, (len(vox), 3))
        with TracedGather(scene, vox, threads=args.threads) as trace:
            best = cpu = np.inf
            for r in range(args.repeats):
                rays0 = trace.rays
                t, c = time.perf_counter(), time.process_time()
                trace(values, args.samples, seed=r)
                best = min(best, time.perf_counter() - t)
                cpu = min(cpu, time.process_time() - c)
                rays = trace.rays - rays0
        line = (f"{name}: {len(vox)} records, {rays / 1e6:.2f} M rays a pass: "
                f"{best:.3f} s, {rays / best / 1e6:.2f} M rays/s; {cpu:.3f} CPU s, "
                f"{rays / cpu / 1e6:.2f} M rays per CPU s")  # fmt: skip
        if not args.no_embree:
            emb = _embree_alone(scene, vox, args.samples, args.threads, args.repeats)
            n = len(vox) * args.samples
            line += f"; Embree alone {n / emb / 1e6:.2f} M rays/s"
        print(line, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
