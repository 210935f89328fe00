"""What a ray costs, and how much of the display's time is Embree's.

Per scene (the Cornell box, ``shadow``, ``geometric``, the window room) at
``--size`` pixels square:

* one voxelize + solve and one ``voxgi.render`` with the defaults: its
  frames, rays per pixel and frame, and seconds per phase;
* rays of the three kinds of that display, as arrays, traced alone through
  :class:`voxgi.rays.Tracer` (Embree called from the compiled core), on 1
  and on 2 threads: nanoseconds per ray, best of ``--repeats``. The camera
  rays are the display's (:func:`voxgi.display.camera_rays`); the shadow
  rays run from the camera hits to 16 random records each, the gather rays
  leave them in 9 cosine-distributed directions each: rays of the same
  kinds and lengths as the display's, not the same rays;
* for each phase of the default render, the share of its time that its rays
  alone take at that cost; the rest is making the rays, shading their hits
  and, for the gather rays, finding the record each one lands on.

Writes ``results/ray_cost.json``.

Usage::

    python benchmarks/ray_cost.py [--size 256] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np
from time_vs_error import RESULTS, git_commit

import voxgi
from voxgi.rays import Tracer

SCENES = ("cornell_box", "shadow", "geometric", "window_room")
GATHER, SHADOW = 9, 16


def display_rays(scene: voxgi.Scene, sol) -> dict:
    """Camera, shadow and gather rays of one frame of the display, as
    (origins, directions[, lengths]) arrays in the tracer's frame."""
    rng = np.random.default_rng(0)
    org, dirs = voxgi.display.camera_rays(scene.camera)
    with Tracer(scene, 2) as tr:
        org = org - tr.centre
        prim, u, v = tr.first_hit(org, dirs)
        t = tr.tris[np.maximum(prim, 0)]
        x = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
        x = x[prim >= 0]
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])[prim >= 0]
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        n *= -np.sign(np.einsum("ij,ij->i", n, dirs[prim >= 0]))[:, None]
        x = x + 1e-4 * n
        y = np.asarray(sol.vox.centroid, np.float64)[
            rng.integers(0, len(sol.vox), (len(x), SHADOW))
        ]
        seg = y - tr.centre - x[:, None]
        length = np.linalg.norm(seg, axis=2)
        shadow = (
            np.repeat(x, SHADOW, axis=0),
            (seg / length[..., None]).reshape(-1, 3),
            (0.999 * length).reshape(-1),
        )
        w = rng.normal(size=(len(x), GATHER, 3))
        w /= np.linalg.norm(w, axis=2, keepdims=True)
        w = w + n[:, None]  # a unit sphere moved onto the normal: cosine-distributed
        w /= np.linalg.norm(w, axis=2, keepdims=True)
        gather = (np.repeat(x, GATHER, axis=0), w.reshape(-1, 3))
    f32 = [np.ascontiguousarray(a, np.float32) for a in (org, dirs)]
    return {
        "primary": f32,
        "shadow": [np.ascontiguousarray(a, np.float32) for a in shadow],
        "gather": [np.ascontiguousarray(a, np.float32) for a in gather],
    }


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
    rays = display_rays(scene, sol)
    row = {
        "scene": name,
        "triangles": int(sum(o.n_triangles for o in scene.objects)),
        "rays_timed": {k: len(v[0]) for k, v in rays.items()},
    }
    for threads in (1, 2):
        with Tracer(scene, threads) as tr:
            row["library"] = f"Embree {tr.native.embree_version}"
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
