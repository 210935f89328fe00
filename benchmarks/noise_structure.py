"""The structure of the display's noise, and what a denoiser makes of it.

Per scene (the Cornell box and the door room at ``--size`` pixels square):
one voxelize + solve with the defaults of ``voxgi.render(scene)``; a
reference render of that same solution with ``--ref-frames`` frames
(``tol=0``, seed 1000, without the indirect filter, so that what is left
of its own noise is white and does not add to the correlation measured);
then, at seeds 0 .. N-1, a render with the defaults
(stopping at ``tol``) and one of ``--frames`` frames, each with the
display's indirect filter as given by ``--indirect-filter``. For each
image:

* relMSE against the reference;
* ``voxgi.metrics.error_autocorrelation`` at lags 1-4 (0: per-pixel
  independent noise, what a denoiser removes);
* with the ``denoise`` extra, the relMSE after OIDN fed with the render's
  own albedo and normal AOVs, and the gain (relMSE before / after).

Writes ``results/noise_structure.json``.

Usage::

    python benchmarks/noise_structure.py [--size 256] [--seeds 3] [--indirect-filter 1]
"""

from __future__ import annotations

import argparse
import json
import time

from time_vs_error import RESULTS, git_commit

import voxgi
from voxgi import metrics

SCENES = {"cornell_box": 16, "door_room": 64}  # scene -> frames of the fixed-length renders


def _row(out, ref, seconds: float) -> dict:
    row = {
        "frames": out.frames,
        "seconds": round(seconds, 3),
        "est_rel_mse": out.stats["est_rel_mse"],
        "rel_mse": metrics.rel_mse(out.image, ref),
        "autocorrelation": metrics.error_autocorrelation(out.image, ref).round(4).tolist(),
    }
    if voxgi.denoise.available():
        t0 = time.perf_counter()
        den = voxgi.denoise.denoise(out)
        row["denoise_seconds"] = round(time.perf_counter() - t0, 3)
        row["rel_mse_denoised"] = metrics.rel_mse(den, ref)
        row["denoise_gain"] = row["rel_mse"] / row["rel_mse_denoised"]
        row["autocorrelation_denoised"] = metrics.error_autocorrelation(den, ref).round(4).tolist()
    return row


def measure(name: str, frames: int, size: int, ref_frames: int, seeds: int, radius: int) -> dict:
    scene = voxgi.scenes.get(name, width=size, height=size)
    sol = voxgi.solve(voxgi.voxelize(scene), progress=False)
    ref = voxgi.render(
        scene,
        sol,
        max_frames=ref_frames,
        tol=0.0,
        seed=1000,
        progress=False,
        tuning=voxgi.RenderTuning(indirect_filter=0),
    )
    tuning = voxgi.RenderTuning(indirect_filter=radius)
    out = {"scene": name, "ref_frames": ref_frames, "defaults": [], "fixed": []}
    for seed in range(seeds):
        for kind, kw in (("defaults", {}), ("fixed", {"tol": 0.0, "max_frames": frames})):
            t0 = time.perf_counter()
            img = voxgi.render(scene, sol, seed=seed, progress=False, tuning=tuning, **kw)
            out[kind].append(_row(img, ref.image, time.perf_counter() - t0))
            print(name, kind, seed, json.dumps(out[kind][-1]), flush=True)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--ref-frames", type=int, default=1024)
    ap.add_argument("--seeds", type=int, default=3, help="seeds 0 .. N-1 per scene")
    ap.add_argument("--indirect-filter", type=int, default=voxgi.RenderTuning().indirect_filter)
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), choices=SCENES)
    args = ap.parse_args()
    rows = [
        measure(n, SCENES[n], args.size, args.ref_frames, args.seeds, args.indirect_filter)
        for n in args.scenes
    ]
    RESULTS.mkdir(exist_ok=True)
    record = {
        "name": "noise_structure",
        "params": vars(args),
        "voxgi": voxgi.__version__,
        "commit": git_commit(),
        "scenes": rows,
    }
    path = RESULTS / "noise_structure.json"
    path.write_text(json.dumps(record, indent=1))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
