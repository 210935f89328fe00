"""
Several views of one solution
=============================

Only the display depends on the camera: solve once, save the solution, and
render new views from it (in this run or a later one) without solving again.

Run: ``python examples/several_views.py``
"""

import time

import voxgi

scene = voxgi.scenes.cornell_box(width=192, height=192)
sol = voxgi.solve(voxgi.voxelize(scene, resolution=96), directions=16)
sol.save("cornell_solution.npz")

sol = voxgi.Solution.load("cornell_solution.npz")  # e.g. in a later session
views = {
    "front": scene.camera,
    "left": scene.camera.replace(eye=(0.45, 0.3, -0.5), target=(0.2, 0.25, 0.3)),
    "low": scene.camera.replace(eye=(0.278, 0.05, -0.4), target=(0.278, 0.3, 0.3)),
}
for name, cam in views.items():
    scene.camera = cam
    t0 = time.perf_counter()
    out = voxgi.render(scene, sol, progress=False)
    print(f"{name}: {time.perf_counter() - t0:.2f} s, {out.frames} frames")
    voxgi.io.write_png(f"view_{name}.png", out.image)
