"""Every pixel of the furnace sphere at the render's defaults.

Inside the uniform furnace sphere (every surface emits ``Le = 1`` and
reflects ``rho``) every pixel's exact radiance is ``Le / (1 - rho)``. Per
albedo (0.5, 0.9): one voxelize + solve with the defaults of
``voxgi.render(scene)``, then ``voxgi.render`` with its defaults (the ray
budget from the light's spread, ``tol`` 1e-3) from two cameras (the scene's,
at the centre, and one off-centre looking at the wall) at seeds 0, 1 and 2,
64x48 pixels. Per render: the frames, the seconds, the VPLs and gather rays
of a frame, and the worst and the RMS relative error over the pixels. The
same with 16 VPLs and 8 gather rays for comparison (``--budgets``).

Writes ``results/furnace_pixels.json``.

Usage::

    python benchmarks/furnace_pixels.py [--budgets default 16,8]
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np
from time_vs_error import RESULTS, git_commit

import voxgi

ALBEDOS = (0.5, 0.9)
SEEDS = (0, 1, 2)
WIDTH, HEIGHT = 64, 48


def cameras(scene: voxgi.Scene) -> dict[str, voxgi.Camera]:
    off = voxgi.Camera(
        eye=(0.3, -0.2, 0.4),
        target=(-0.5, 0.4, -0.6),
        up=(0, 0, 1),
        fov=60,
        width=WIDTH,
        height=HEIGHT,
    )
    return {"centre": scene.camera, "off-centre": off}


def measure(rho: float, budgets: list[str]) -> list[dict]:
    scene = voxgi.scenes.furnace_sphere(albedo=rho, width=WIDTH, height=HEIGHT)
    vox = voxgi.voxelize(scene)
    sol = voxgi.solve(vox, progress=False)
    exact = 1.0 / (1.0 - rho)
    rows = []
    for budget in budgets:
        vpls, gather = (None, None) if budget == "default" else map(int, budget.split(","))
        for cam_name, cam in cameras(scene).items():
            for seed in SEEDS:
                t0 = time.perf_counter()
                out = voxgi.display.render(
                    scene,
                    sol,
                    seed=seed,
                    progress=False,
                    camera=cam,
                    tuning=voxgi.RenderTuning(vpls_per_frame=vpls, gather=gather),
                )
                secs = time.perf_counter() - t0
                err = np.abs(out.image / exact - 1.0).max(axis=2)
                row = {
                    "albedo": rho,
                    "budget": budget,
                    "camera": cam_name,
                    "seed": seed,
                    "vpls": out.stats["vpls_per_frame"],
                    "gather": out.stats["gather_per_frame"],
                    "spread": out.stats["light_spread"],
                    "frames": out.frames,
                    "seconds": secs,
                    "worst": float(err.max()),
                    "rms": float(np.sqrt(np.mean(err**2))),
                }
                rows.append(row)
                print(
                    f"albedo {rho} {budget} ({row['vpls']} VPLs, {row['gather']} gather rays) "
                    f"{cam_name} seed {seed}: {out.frames} frames {secs:.2f} s, worst pixel "
                    f"{row['worst']:.2%}, RMS {row['rms']:.3%}",
                    flush=True,
                )
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budgets", nargs="+", default=["default", "16,8"])
    args = ap.parse_args(argv)
    res = {
        "size": [WIDTH, HEIGHT],
        "commit": git_commit(),
        "cores": os.cpu_count(),
        "rows": [r for rho in ALBEDOS for r in measure(rho, args.budgets)],
    }
    (RESULTS / "furnace_pixels.json").write_text(json.dumps(res, indent=2, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
