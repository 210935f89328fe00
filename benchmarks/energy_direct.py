"""The Cornell box's energy imbalance in the direct light alone (the shooting).

All albedos 0, so the solve is the shooting alone (no gathering): the open
box and the box closed by a fourth wall, against the resolution. R 8,
shooting R 16, the default rules; 2 threads.

    python benchmarks/energy_direct.py --res 64 128 256 512
"""

from __future__ import annotations

import argparse
import dataclasses
import time
import warnings

import numpy as np

import voxgi


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, nargs="+", default=[64, 128, 256])
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    for closed in (True, False):
        scene = voxgi.scenes.cornell_box(width=32, height=32, closed=closed)
        for res in args.res:
            vox = voxgi.voxelize(scene, resolution=res)
            vox = dataclasses.replace(vox, albedo=np.zeros_like(vox.albedo))
            t = time.perf_counter()
            sol = voxgi.solve(
                vox,
                radius=8,
                progress=False,
                tol=1e-5,
                threads=args.threads,
                tuning=voxgi.SolveTuning.paper(shoot_radius=16, diagnostics=False),
            )
            e = sol.stats["energy"]
            print(
                f"{'closed' if closed else 'open  '} black res {res:4d} records {len(vox):8d} "
                f"imbalance {e['imbalance'][0]:+.5f}  "
                f"escaping/emitted {e['escaping'][0] / e['emitted'][0]:.4f}  "
                f"{time.perf_counter() - t:.1f}s",
                flush=True,
            )


if __name__ == "__main__":
    main()
