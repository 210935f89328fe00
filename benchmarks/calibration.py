"""How well the display knows its own error: estimated against measured noise.

Per scene (by default the Cornell box with its box filter, ``window_room`` and
``door_room`` at ``--size`` pixels square, and Bitterli's wooden staircase,
which the estimate was not tuned on, ``--small-width`` pixels wide, when
``--scenes-dir`` holds it; ``shadow``, ``geometric`` and the furnace sphere at
albedo 0.9 on request): one voxelize + solve as ``voxgi.render(scene)`` does
(``voxgi.resolution.solve_scene``); a reference render of that same solution with
``--ref-frames`` frames (``tol=0``, seed 1000; twice as many for the door
room, whose light arrives through a gap and is the noisiest, four times for
the staircase, whose renders run longest); then
``voxgi.render`` with its defaults (``--tol``: another tolerance) at seeds
0 .. N-1. The estimate is of the
display's noise only, so the reference is the long render of the same
solution, not a path-traced image (whose difference would add the voxel
solution's bias):

* measured relMSE: ``rel_mse(image, reference)`` less the reference's own
  estimated relMSE (its noise adds to the difference);
* estimated relMSE: ``stats["est_rel_mse"]`` at the stopping point, and
  their ratio (1 is a calibrated estimate);
* the worst pixel: the estimated largest relative error
  (``stats["est_max_rel_err"]``) and the measured largest
  ``|image - reference| / sqrt(reference² + 0.01)``;
* the display's seconds per phase (primary rays, shadow rays, gather rays,
  shading) of the reference render.

The summary per scene: the least and largest ratio over the seeds, and
whether every one lies within [0.5, 2]. Writes ``results/calibration.json``
(``--json``: elsewhere).

Usage::

    python benchmarks/calibration.py [--size 256] [--ref-frames 256] [--seeds 16]
        [--scenes cornell_box window_room door_room staircase] [--scenes-dir /work/scenes]
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np
from time_vs_error import RESULTS, git_commit

import voxgi
from voxgi.metrics import rel_mse
from voxgi.resolution import solve_scene

SCENES = ("cornell_box", "window_room", "door_room", "staircase")
OTHER = ("shadow", "geometric", "furnace_sphere")
#: Extracted interiors (``scripts``' extraction of Bitterli's set), by folder.
INTERIORS = ("staircase",)
#: Reference frames over ``--ref-frames`` per scene: the reference's own
#: noise is subtracted as estimated, so it must stay well under the renders'
#: error. The door room's light arrives through a gap and is the noisiest;
#: the staircase's renders run to 100 frames, and against 1024 frames its
#: 256-frame reference measures 8.6e-5 where it estimates 2.1e-4 (its
#: estimate runs high), which would take a third off the measured error.
REF_SCALE = {"door_room": 2, "staircase": 4}


def make_scene(name: str, size: int, small_width: int, scenes_dir: Path) -> voxgi.Scene:
    if name == "furnace_sphere":
        return voxgi.scenes.furnace_sphere(albedo=0.9, width=size, height=size)
    if name in INTERIORS:
        scene = voxgi.Scene.load(scenes_dir / name / "diffuse" / "scene.toml")
        cam = scene.camera
        h = max(1, round(small_width * cam.height / cam.width))
        scene.camera = cam.replace(width=small_width, height=h)
        return scene
    return voxgi.scenes.get(name, width=size, height=size)


def measure(
    scene: voxgi.Scene, name: str, ref_frames: int, seeds: int, threads: int, tol: float = 1e-3
) -> dict:
    t0 = time.perf_counter()
    sol = solve_scene(scene, tol=tol, progress=False, threads=threads)
    vox = sol.vox
    solve_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    ref = voxgi.render(
        scene, sol, max_frames=ref_frames, tol=0.0, seed=1000, progress=False, threads=threads
    )
    row = {
        "scene": name,
        "pixels": [scene.camera.width, scene.camera.height],
        "records": len(vox),
        "resolution": vox.resolution,
        "solve_s": solve_s,
        "reference": {
            "frames": ref.frames,
            "seconds": time.perf_counter() - t0,
            "est_rel_mse": ref.stats["est_rel_mse"],
            "phases": {k: ref.stats["seconds"][k] for k in ("primary", "shadow", "gather")},
            "rays": {
                k: ref.stats[f"{k}_rays"] / ref.frames for k in ("primary", "shadow", "gather")
            },
        },
        "seeds": [],
    }
    r = ref.image.astype(np.float64)
    for seed in range(seeds):
        t0 = time.perf_counter()
        out = voxgi.render(scene, sol, tol=tol, seed=seed, progress=False, threads=threads)
        secs = time.perf_counter() - t0
        measured = rel_mse(out.image, ref.image) - ref.stats["est_rel_mse"]
        worst = float(np.max(np.abs(out.image - r) / np.sqrt(r * r + 0.01)))
        row["seeds"].append(
            {
                "seed": seed,
                "frames": out.frames,
                "seconds": secs,
                "est_rel_mse": out.stats["est_rel_mse"],
                "rel_mse": measured,
                "ratio": out.stats["est_rel_mse"] / measured,
                "est_max_rel_err": out.stats["est_max_rel_err"],
                "max_rel_err": worst,
                "flagged_pixels": out.stats["flagged_pixels"],
                "edge_pixels": out.stats["edge_pixels"],
            }
        )
        if name == "furnace_sphere":
            exact = 1.0 / (1.0 - 0.9)
            row["seeds"][-1]["max_err_vs_exact"] = float(np.max(np.abs(out.image / exact - 1)))
        s = row["seeds"][-1]
        print(
            f"{name} seed {seed}: {s['frames']} frames {secs:.2f} s, relMSE est "
            f"{s['est_rel_mse']:.2e} measured {s['rel_mse']:.2e} (ratio {s['ratio']:.2f}); "
            f"worst pixel est {s['est_max_rel_err']:.3f} measured {s['max_rel_err']:.3f}",
            flush=True,
        )
    ratios = [s["ratio"] for s in row["seeds"]]
    row["ratio_range"] = [min(ratios), max(ratios)]
    row["all_within_half_to_two"] = bool(all(0.5 <= r <= 2.0 for r in ratios))
    print(
        f"{name}: ratio {min(ratios):.2f} .. {max(ratios):.2f} over {len(ratios)} seeds", flush=True
    )
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--ref-frames", type=int, default=256)
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), choices=SCENES + OTHER)
    ap.add_argument("--seeds", type=int, default=16, help="seeds 0 .. N-1 per scene")
    ap.add_argument("--small-width", type=int, default=96, help="width of the interiors")
    ap.add_argument("--scenes-dir", type=Path, default=Path("/work/scenes"))
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--tol", type=float, default=1e-3, help="the renders' tolerance")
    ap.add_argument("--json", type=Path, default=RESULTS / "calibration.json")
    args = ap.parse_args(argv)
    names = [
        n for n in args.scenes if n not in INTERIORS or (args.scenes_dir / n / "diffuse").is_dir()
    ]
    rows = []
    for name in names:
        scene = make_scene(name, args.size, args.small_width, args.scenes_dir)
        frames = args.ref_frames * REF_SCALE.get(name, 1)
        rows.append(measure(scene, name, frames, args.seeds, args.threads, args.tol))
    res = {
        "size": args.size,
        "ref_frames": args.ref_frames,
        "tol": args.tol,
        "pixel_factor": voxgi.display.PIXEL_FACTOR,
        "commit": git_commit(),
        "cores": os.cpu_count(),
        "threads": args.threads,
        "seeds": args.seeds,
        "small_width": args.small_width,
        "rows": rows,
    }
    args.json.write_text(json.dumps(res, indent=2, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
