"""Near gather hits read against continued one bounce, on real interiors.

For each scene (as ``benchmarks/bitterli.py`` loads it), the render's own
solve (``voxgi.resolution.solve_scene``) is shown for ``--frames`` frames
with each ``--seeds`` seed, once with every ``--reach`` (the display's
``near_reach`` in voxel pitches; 0: every gather ray reads the record where
it lands), against the scene's cached Mitsuba reference (``bitterli.py
--references-only`` renders it). It prints, per scene, reach and seed, the
relMSE against the reference (its own noise included), the image's mean
brightness over the reference's per channel, the gather phase's seconds and
the gather rays traced (a continued ray and its shadow ray count).

Usage::

    python benchmarks/near_bounce.py kitchen-partial cornell-box --frames 32
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import voxgi
from voxgi.display.settings import _Experiment
from voxgi.metrics import rel_mse

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bitterli import REFS_DIR, load, reference


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--width", type=int, default=256)
    ap.add_argument("--frames", type=int, default=32)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--reach", type=float, nargs="+", default=[0.0, 1.0])
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--refs", type=Path, default=REFS_DIR)
    args = ap.parse_args(argv)
    print("scene reach seed relMSE brightness(R,G,B) gather_s gather_rays")
    for name in args.scenes:
        scene = load(name, args.width)
        ref, _, _ = reference(scene, name, args.ref_spp, refs_dir=args.refs, verbose=False)
        sol = voxgi.resolution.solve_scene(scene, progress=False)
        mean_ref = ref.reshape(-1, 3).mean(axis=0)
        for reach in args.reach:
            for seed in args.seeds:
                out = voxgi.render(
                    scene,
                    sol,
                    progress=False,
                    seed=seed,
                    max_frames=args.frames,
                    tol=0,
                    tuning=_Experiment(near_reach=reach),
                )
                bright = out.image.reshape(-1, 3).mean(axis=0) / mean_ref
                print(
                    f"{name} {reach:g} {seed} {rel_mse(out.image, ref):.3e} "
                    f"({bright[0]:.4f}, {bright[1]:.4f}, {bright[2]:.4f}) "
                    f"{out.stats['seconds']['gather']:.2f} {out.stats['gather_rays']}",
                    flush=True,
                )


if __name__ == "__main__":
    main()
