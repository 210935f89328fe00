"""
The furnace check
=================

Inside a closed enclosure whose every surface emits radiance ``Le`` and
reflects a fraction ``rho``, every point has radiance ``Le / (1 - rho)``: the
emission plus the geometric series of its bounces. A box inside with the same
material must not change that. This script solves a furnace sphere with a box
inside, renders it, and compares both with the known answer:

* the solve's error on its surface records, which comes from the voxel
  discretisation (``docs/design.md §10``);
* the image's error, which adds the display's noise, against the render's
  own estimate of it (``out.stderr``; ``docs/design.md`` §6). With the
  defaults the render stops once the estimated relMSE is under 1e-3 and 999
  pixels in 1000 have an estimated relative error under 10·sqrt(1e-3) =
  0.32: the worst pixel, near the box's corners, keeps one to a few
  percent. ``tol=1e-4`` lowers both bounds (the per-pixel one to
  10·sqrt(1e-4) = 0.1), at the price of more frames. Both are printed,
  each worst pixel beside its estimate. The furnace's light is spread
  evenly, so the display takes 8 VPLs and 25 gather rays a frame
  (``voxgi.display.ray_budget``).

Every surface emits and the furnace's light is uniform, so the shooting
radius 8 (``SolveTuning.paper(shoot_radius=8)``, the paper's method) serves as
well as its 35; with the gathering's radius, the solve gets the shot direct light by one
gathering pass over the emitters (``sol.stats["skipped"]["shooting"]``).

Run: ``python examples/furnace_check.py`` (up to half a minute per albedo).
"""

import numpy as np

import voxgi

LE = 1.0
for rho in (0.5, 0.9):
    exact = LE / (1.0 - rho)
    print(f"rho = {rho}: every point should have radiance Le / (1 - rho) = {exact:.4f}")
    scene = voxgi.scenes.furnace_sphere(albedo=rho, emission=LE, inner=True, width=48, height=48)
    vox = voxgi.voxelize(scene, resolution=32)
    print(f"  voxelized at resolution 32: {len(vox):,} records")
    sol = voxgi.solve(vox, radius=8, progress=False, tuning=voxgi.SolveTuning.paper(shoot_radius=8))
    front = ~vox.back
    rec_err = sol.radiance[front] / exact - 1.0
    print(
        f"  solved in {sol.bounces} bounces: records' radiance {sol.radiance[front].mean():.4f} "
        f"on average; error {np.abs(rec_err).mean():.2%} mean, {np.abs(rec_err).max():.2%} max; "
        f"lost fraction {sol.stats['lost_fraction']:.1e}"
    )
    for label, tol in (("defaults", None), ("tol 1e-4", 1e-4)):
        out = voxgi.render(scene, sol, progress=False, tol=tol)
        pix_err = np.abs(out.image / exact - 1.0)
        print(
            f"  rendered ({label}) {out.frames} frames: image mean {out.image.mean():.4f} "
            f"({out.image.mean() / exact - 1.0:+.2%}); worst pixel {pix_err.max():.2%} off, "
            f"estimated {out.stats['est_max_rel_err']:.2%}; every pixel's error "
            f"{np.sqrt(np.mean(pix_err**2)):.2%} RMS, estimated "
            f"{np.sqrt(np.mean((out.stderr / exact) ** 2)):.2%} RMS"
        )
