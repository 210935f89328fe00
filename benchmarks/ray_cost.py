"""What a ray costs, and how much of the display's time is Embree's.

Per scene (the Cornell box, ``shadow``, ``geometric``, the window room) at
``--size`` pixels square:

* one voxelize + solve and one ``voxgi.render`` with the defaults: its
  frames, rays per pixel and frame, and seconds per phase;
* the camera, shadow and gather rays of the first two frames of that
  display, kept as arrays (from a render through embreex's batches, whose
  rays are the same) and traced alone through :class:`voxgi.rays.Tracer`
  (Embree called from the compiled core), on 1 and on 2 threads:
  nanoseconds per ray, best of ``--repeats``;
* for each phase of the default render, the share of its time that its rays
  alone take at that cost; the rest is making the rays, shading their hits
  and, for the gather rays, finding the record each one lands on.

Writes ``results/ray_cost.json``.

Usage::

    python benchmarks/ray_cost.py [--size 256] [--repeats 3]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import time

import numpy as np
from time_vs_error import RESULTS, git_commit

import voxgi
from voxgi.rays import Tracer

SCENES = ("cornell_box", "shadow", "geometric", "window_room")
GATHER, SHADOW = 9, 16


@contextlib.contextmanager
def _recorded_rays(pixels: int):
    """Within it, renders trace through embreex in batches (the two-pass
    path, whose rays are arrays), and every batch is kept: first-hit
    batches of one ray a pixel are the camera rays, the others the gather
    rays; occlusion batches are the shadow rays."""
    kept = {"primary": [], "gather": [], "shadow": []}
    saved = (voxgi.rays.embree_library, Tracer.intersect, Tracer.occluded)

    def intersect(tr, org, dirs):
        kind = "primary" if len(org) == pixels else "gather"
        kept[kind].append((np.array(org, np.float32), np.array(dirs, np.float32)))
        return saved[1](tr, org, dirs)

    def occluded(tr, org, dirs, length):
        kept["shadow"].append(tuple(np.array(a, np.float32) for a in (org, dirs, length)))
        return saved[2](tr, org, dirs, length)

    voxgi.rays.embree_library = lambda: None
    Tracer.intersect, Tracer.occluded = intersect, occluded
    try:
        yield kept
    finally:
        voxgi.rays.embree_library, Tracer.intersect, Tracer.occluded = saved


def display_rays(scene: voxgi.Scene, sol, frames: int) -> dict:
    """The camera, shadow and gather rays of the first ``frames`` frames of
    the default display, as arrays."""
    with _recorded_rays(scene.camera.width * scene.camera.height) as kept:
        voxgi.render(scene, sol, max_frames=frames, tol=0.0, progress=False)
    return {k: [np.concatenate(p) for p in zip(*v, strict=True)] for k, v in kept.items()}


def time_rays(tracer: Tracer, rays: dict, repeats: int) -> dict:
    """Best nanoseconds per ray of each kind, traced alone (no shading)."""
    best = {}
    for kind, arrays in rays.items():
        call = tracer.occluded if kind == "shadow" else tracer.intersect
        for _ in range(repeats):
            t = time.perf_counter()
            call(*arrays)
            ns = (time.perf_counter() - t) / len(arrays[0]) * 1e9
            best[kind] = min(best.get(kind, np.inf), ns)
    return best


def measure(name: str, size: int, repeats: int) -> dict:
    scene = voxgi.scenes.get(name, width=size, height=size)
    vox = voxgi.voxelize(scene)
    sol = voxgi.solve(vox, progress=False)
    out = voxgi.render(scene, sol, progress=False)
    st, sec = out.stats, out.stats["seconds"]
    pixel_frames = size * size * out.frames
    rays = display_rays(scene, sol, frames=2)
    row = {
        "scene": name,
        "triangles": int(sum(o.n_triangles for o in scene.objects)),
        "rays_timed": {k: len(v[0]) for k, v in rays.items()},
    }
    for threads in (1, 2):
        with Tracer(scene, threads) as tr:
            row["library"] = "compiled" if tr.native is not None else "embreex"
            row[f"ns_per_ray_{threads}"] = time_rays(tr, rays, repeats)
    ns = row[f"ns_per_ray_{min(2, st['threads'])}"]
    row["render"] = {
        "frames": out.frames,
        "threads": st["threads"],
        "seconds": {k: sec[k] for k in ("primary", "shadow", "gather", "total")},
        "rays_per_pixel_frame": {
            k: st[f"{k}_rays"] / pixel_frames for k in ("primary", "shadow", "gather")
        },
        # the time the phase's rays alone take, as a share of the phase
        "rays_alone": {
            k: st[f"{k}_rays"] * ns[k] * 1e-9 / sec[k] for k in ("primary", "shadow", "gather")
        },
    }
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--scenes", nargs="+", default=list(SCENES))
    args = ap.parse_args()
    rows = []
    for name in args.scenes:
        row = measure(name, args.size, args.repeats)
        r, t1, t2 = row["render"], row["ns_per_ray_1"], row["ns_per_ray_2"]
        print(
            f"{name}: {row['triangles']} triangles; ns per ray on 1 / 2 threads: "
            + ", ".join(f"{k} {t1[k]:.0f} / {t2[k]:.0f}" for k in t1)
            + f"; the default render ({r['frames']} frames): rays alone "
            + ", ".join(f"{100 * v:.0f}% of {k}" for k, v in r["rays_alone"].items()),
            flush=True,
        )
        rows.append(row)
    out = {
        "size": args.size,
        "repeats": args.repeats,
        "cpus": os.cpu_count(),
        "commit": git_commit(),
        "scenes": rows,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "ray_cost.json").write_text(json.dumps(out, indent=2, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
