"""
The furnace check
=================

Inside a closed enclosure whose every surface emits radiance ``Le`` and
reflects a fraction ``rho``, every point has radiance ``Le / (1 - rho)``:
emission plus an infinite geometric series of bounces. Occluders inside with
the same material must not change that. voxgi's solution and image are
compared with that known answer.

Run: ``python examples/furnace_check.py``
"""

import numpy as np

import voxgi

for rho in (0.5, 0.9):
    scene = voxgi.scenes.furnace_sphere(albedo=rho, emission=1.0, inner=True)
    sol = voxgi.solve(voxgi.voxelize(scene, resolution=48), directions=8, progress=False)
    exact = 1.0 / (1.0 - rho)
    front = ~sol.vox.back
    err = np.abs(sol.radiance[front] / exact - 1.0)
    out = voxgi.render(scene, sol, progress=False)
    img_err = np.abs(out.image / exact - 1.0)
    print(f"rho={rho}: expected {exact:.4f}; records: mean error {err.mean():.2e}, "
          f"max {err.max():.2e}; image: max pixel error {img_err.max():.2e} "
          f"after {sol.bounces} bounces")
