"""voxgi with all its defaults on the Cornell box, against the Mitsuba references.

One voxelize + solve with the defaults of voxgi.render(scene) (timed), then the display at
256x256 and 512x512 from the same solution, each compared with
``results/cornell_ref_<size>.exr`` (relMSE), the difference images
``results/cornell_diff_defaults_<size>.png``, the solution saved and loaded
again, and a second view rendered from the loaded solution (display only).
The whole-pipeline time at a size is voxelize + solve + that display.
Writes ``results/cornell_defaults.json``.

Usage::

    python benchmarks/cornell_defaults.py
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

from time_vs_error import RESULTS, diff_png, git_commit, load_reference

import voxgi
from voxgi.metrics import rel_mse


def main() -> int:
    scene = voxgi.scenes.cornell_box(width=256, height=256)
    t0 = time.perf_counter()
    vox = voxgi.voxelize(scene)
    t1 = time.perf_counter()
    # exactly what voxgi.render(scene) and `voxgi render` run without a solution
    sol = voxgi.solve(vox, progress=False)
    t2 = time.perf_counter()
    res = {
        "records": len(vox),
        "resolution": vox.resolution,
        "voxelize": t1 - t0,
        "solve": t2 - t1,
        "solve_stats_seconds": sol.stats.get("seconds"),
        "bounces": sol.bounces,
        "commit": git_commit(),
        "sizes": {},
    }
    print(
        f"voxelize {t1 - t0:.2f} s ({len(vox)} records), solve {t2 - t1:.2f} s "
        f"({sol.bounces} bounces)",
        flush=True,
    )
    for size in (256, 512):
        ref = load_reference(size)
        sc = voxgi.scenes.cornell_box(width=size, height=size)
        t = time.perf_counter()
        out = voxgi.render(sc, sol, progress=False)
        secs = time.perf_counter() - t
        e = rel_mse(out.image, ref)
        row = {
            "display": secs,
            "frames": out.frames,
            "rel_mse": e,
            "est_noise_rel_mse": out.stats["est_rel_mse"],
            "whole_pipeline": res["voxelize"] + res["solve"] + secs,
            "phases": out.stats["seconds"],
        }
        res["sizes"][size] = row
        diff_png(
            out.image,
            ref,
            RESULTS / f"cornell_diff_defaults_{size}.png",
            f"defaults ({row['whole_pipeline']:.0f} s, relMSE {e:.2e})",
        )
        voxgi.io.write_png(RESULTS / f"cornell_voxgi_defaults_{size}.png", out.image)
        print(
            f"{size}x{size}: display {secs:.2f} s ({out.frames} frames), relMSE {e:.2e} "
            f"(noise estimate {out.stats['est_rel_mse']:.1e}), whole pipeline "
            f"{row['whole_pipeline']:.1f} s",
            flush=True,
        )
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        sol.save(Path(tmp) / "cornell.npz")
        sol2 = voxgi.Solution.load(Path(tmp) / "cornell.npz")
        res["save_load"] = time.perf_counter() - t
    cam = scene.camera.replace(eye=(0.12, 0.40, -0.55), target=(0.30, 0.22, 0.30))
    t = time.perf_counter()
    out = voxgi.render(scene, sol2, camera=cam, progress=False)
    res["second_view"] = {"seconds": time.perf_counter() - t, "frames": out.frames}
    voxgi.io.write_png(RESULTS / "cornell_second_view_256.png", out.image)
    print(
        f"saved + loaded the solution in {res['save_load']:.2f} s; second view (256x256, "
        f"display only) {res['second_view']['seconds']:.2f} s ({out.frames} frames)"
    )
    (RESULTS / "cornell_defaults.json").write_text(json.dumps(res, indent=2, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
