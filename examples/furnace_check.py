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
* the image's error, which adds the display's noise: the render stops at a
  relMSE of about 1e-3, so single pixels are off by a few percent, about as
  much as the render's own estimate of that noise (``out.stderr``), printed
  beside it. A smaller ``tol`` in ``voxgi.render`` brings the pixels closer,
  at the price of more frames.

Every surface emits, so every record shoots; the furnace's light is uniform,
and the shooting radius 8 (``SolveTuning(shoot_directions=8)``) serves as well
as the default 35 in a fraction of the time.

Run: ``python examples/furnace_check.py`` (a few seconds per albedo).
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
    sol = voxgi.solve(
        vox, directions=8, progress=False, tuning=voxgi.SolveTuning(shoot_directions=8)
    )
    front = ~vox.back
    rec_err = sol.radiance[front] / exact - 1.0
    print(
        f"  solved in {sol.bounces} bounces: records' radiance {sol.radiance[front].mean():.4f} "
        f"on average; error {np.abs(rec_err).mean():.2%} mean, {np.abs(rec_err).max():.2%} max; "
        f"lost fraction {sol.stats['lost_fraction']:.1e}"
    )
    out = voxgi.render(scene, sol, progress=False)
    pix_err = out.image / exact - 1.0
    noise = out.stderr / exact
    print(
        f"  rendered {out.frames} frames: image mean {out.image.mean():.4f} "
        f"({out.image.mean() / exact - 1.0:+.2%}); per pixel {np.abs(pix_err).mean():.2%} mean, "
        f"{np.abs(pix_err).max():.2%} max, against an estimated noise of "
        f"{np.sqrt(np.mean(noise**2)):.2%} RMS"
    )
