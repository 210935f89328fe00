"""What the display's noise is made of, and what each ray budget buys.

Per scene (the Cornell box, ``shadow``, ``geometric``, the window room, the
furnace sphere at albedo 0.9, the sky-lit atrium) at ``--size`` pixels
square: one voxelize + solve with the defaults of ``voxgi.render(scene)``,
its light's spread (``voxgi.display.light_spread``), then ``--frames`` frames
(``tol=0``, one seed) of each display setting below. For each, the noise of
one frame as a relMSE, ``mean(var / (L² + 0.01))`` over pixels and channels
with ``var`` from the spread between aligned blocks of 4 frames (as the
render's own estimate, ``docs/design.md`` §6) and ``L`` the defaults' image,
and the milliseconds per frame. Their product is the display's cost of a
unit of error: the seconds to reach a relMSE ``tol`` are about
``noise x seconds per frame / tol``, so lower is better.

* the light of the emitting records alone (the solution's other records set
  to zero), and of the other records alone (the emitters set to zero): each
  is displayed with the whole VPL budget on its records;
All without the indirect filter (``RenderTuning(indirect_filter=0)``): the
noise of the estimator itself, before any averaging over pixels.

* the whole light with VPLs per frame and gather rays per pixel of
  (16, 9) (the defaults for concentrated light), (8, 25) (for light spread
  evenly, ``voxgi.display.ray_budget``), (16, 8), (8, 16), (16, 16) and
  (32, 8).

Writes ``results/display_noise.json``.

Usage::

    python benchmarks/display_noise.py [--size 256] [--frames 32]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time

import numpy as np
from calibration import SCENES, make_scene
from time_vs_error import RESULTS, git_commit

import voxgi
import voxgi.display

BUDGETS = ((16, 9), (8, 25), (16, 8), (8, 16), (16, 16), (32, 8))
NOISE_SCENES = (*SCENES, "sponza_atrium")
BLOCK = 4


class _Recorder:
    """A frame executor (:class:`voxgi.display.FrameExecutor`) that keeps a
    copy of every frame it hands out, in ``kept``."""

    def __init__(self):
        self.kept = []

    def frames(self, spec, max_frames, *, threads=1):
        src = spec.build(threads)
        shade = src.frame

        def frame(f, seed):
            x = shade(f, seed)
            self.kept.append(np.asarray(x, dtype=np.float64))
            return x

        src.frame = frame
        return src


def _run(scene, sol, frames: int, vpls: int, gather: int) -> tuple[np.ndarray, float]:
    """(frames, P, 3) frames of one display setting and its seconds per frame."""
    rec = _Recorder()
    t0 = time.perf_counter()
    voxgi.display.render(
        scene,
        sol,
        max_frames=frames,
        tol=0.0,
        seed=5,
        progress=False,
        executor=rec,
        tuning=voxgi.RenderTuning(vpls_per_frame=vpls, gather=gather, indirect_filter=0),
    )
    return np.array(rec.kept), (time.perf_counter() - t0) / frames


def _frame_noise(x: np.ndarray, image: np.ndarray) -> float:
    """One frame's noise as a relMSE: the variance between aligned block means
    times the block size, over ``image² + 0.01``."""
    n = len(x) // BLOCK * BLOCK
    blocks = x[:n].reshape(n // BLOCK, BLOCK, *x.shape[1:]).mean(axis=1)
    var = blocks.var(axis=0, ddof=1) * BLOCK
    return float(np.mean(var / (image * image + 0.01)))


def measure(name: str, size: int, frames: int) -> dict:
    scene = make_scene(name, size)
    vox = voxgi.voxelize(scene)
    sol = voxgi.solve(vox, progress=False)
    emits = np.any(np.asarray(vox.emission) > 0, axis=1)[:, None]
    B = np.asarray(sol.radiosity)
    x, spf = _run(scene, sol, frames, *BUDGETS[0])
    image = x.mean(axis=0)
    rows = []

    def add(label: str, x: np.ndarray, spf: float, vpls: int, gather: int) -> None:
        noise = _frame_noise(x, image)
        rows.append(
            {
                "light": label,
                "vpls": vpls,
                "gather": gather,
                "frame_noise": noise,
                "ms_per_frame": 1e3 * spf,
                "noise_x_seconds": noise * spf,
            }
        )
        print(
            f"{name} {label} ({vpls} VPLs, {gather} gather rays): noise {noise:.2e}, "
            f"{1e3 * spf:.0f} ms a frame, noise x s {noise * spf:.2e}",
            flush=True,
        )

    add("all", x, spf, *BUDGETS[0])
    for label, keep in (("emitting records", emits), ("other records", ~emits)):
        part = dataclasses.replace(sol, radiosity=np.where(keep, B, 0.0))
        if not np.any(part.radiosity > 0):
            continue
        add(label, *_run(scene, part, frames, *BUDGETS[0]), *BUDGETS[0])
    for vpls, gather in BUDGETS[1:]:
        add("all", *_run(scene, sol, frames, vpls, gather), vpls, gather)
    spread = voxgi.display.light_spread(sol)
    return {"scene": name, "records": len(vox), "spread": spread, "rows": rows}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--frames", type=int, default=32)
    ap.add_argument("--scenes", nargs="+", default=list(NOISE_SCENES), choices=NOISE_SCENES)
    args = ap.parse_args(argv)
    res = {
        "size": args.size,
        "frames": args.frames,
        "commit": git_commit(),
        "cores": os.cpu_count(),
        "scenes": [measure(name, args.size, args.frames) for name in args.scenes],
    }
    (RESULTS / "display_noise.json").write_text(json.dumps(res, indent=2, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
