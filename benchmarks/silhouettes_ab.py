"""Render error with and without the shooting's silhouette rule (issue 3).

For each scene: one voxelize, then ``solve`` with ``shoot_silhouettes``
False and True (the render pipeline's radius and tolerance), each displayed
at 256x256 with two seeds and a fixed number of frames, and compared with the
committed Mitsuba reference ``results/<scene>_ref_256.exr`` (relMSE). Also
prints the solve's energy imbalance. Two seeds show how much of a difference
is noise.

Usage::

    python benchmarks/silhouettes_ab.py [--scenes cornell-box geometric shadow]
                                        [--res 64] [--frames 64]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from time_vs_error import load_reference, make_scene

import voxgi
from voxgi.metrics import rel_mse


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["cornell-box", "geometric", "shadow"])
    ap.add_argument("--res", type=int, nargs="+", default=[64])
    ap.add_argument("--frames", type=int, default=64)
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    args = ap.parse_args()
    size = 256
    for name in args.scenes:
        ref = load_reference(size, name)
        scene = make_scene(name, size)
        for res in args.res:
            vox = voxgi.voxelize(scene, resolution=res)
            for sil in (False, True):
                t = time.perf_counter()
                sol = voxgi.solve(vox, directions=voxgi.pipeline.RENDER_DIRECTIONS,
                                  tol=voxgi.pipeline.RENDER_SOLVE_TOL, diagnostics=False,
                                  progress=False, shoot_silhouettes=sil)
                dt = time.perf_counter() - t
                errs = []
                for seed in args.seeds:
                    img = voxgi.render(scene, sol, progress=False, seed=seed,
                                       max_frames=args.frames, tol=1e-9)
                    errs.append(rel_mse(np.asarray(img.image), ref))
                imb = sol.stats["energy"]["imbalance"][0]
                print(f"{name:12s} res {res:3d} silhouettes {sil!s:5s} imbalance {imb:+.4f} "
                      f"solve {dt:5.1f} s relMSE " + " ".join(f"{e:.3e}" for e in errs),
                      flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
