"""
Several views of one solution
=============================

Only the display depends on the camera: solve the Cornell box once, save the
solution, and render three views from it (in this run or a later one)
without solving again. Each view costs only its display. Writes
``view_front.png``, ``view_left.png`` and ``view_right.png``.

Run: ``python examples/several_views.py``
"""

import time

import voxgi

scene = voxgi.scenes.cornell_box(width=192, height=192)
t0 = time.perf_counter()
sol = voxgi.solve(voxgi.voxelize(scene), progress=False)
print(f"voxelized and solved once in {time.perf_counter() - t0:.1f} s")
sol.save("cornell_solution.npz")

sol = voxgi.Solution.load("cornell_solution.npz")  # e.g. in a later run
views = {  # the default view, and one from each front corner of the open side
    "front": scene.camera,
    "left": scene.camera.replace(eye=(0.0, 0.35, -0.65), target=(0.33, 0.22, 0.3)),
    "right": scene.camera.replace(eye=(0.556, 0.35, -0.65), target=(0.22, 0.22, 0.3)),
}
for name, cam in views.items():
    scene.camera = cam
    t0 = time.perf_counter()
    out = voxgi.render(scene, sol, progress=False)
    voxgi.io.write_png(f"view_{name}.png", out.image)
    print(
        f"view {name!r}: displayed in {time.perf_counter() - t0:.1f} s ({out.frames} frames), "
        f"wrote view_{name}.png"
    )
