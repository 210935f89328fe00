"""
Render the Cornell box
======================

The classic Cornell box (published dimensions, Mitsuba 3's colours) rendered
with voxgi's whole pipeline: voxelize the surfaces, propagate light along
discrete lines (shooting, then gathering), display by progressive VPL ray
tracing. Writes ``cornell_box.exr`` (linear radiance) and ``cornell_box.png``.

Run: ``python examples/cornell_box.py``
"""

import voxgi

scene = voxgi.scenes.cornell_box(width=256, height=256)
vox = voxgi.voxelize(scene, resolution=96)
print(vox)
sol = voxgi.solve(vox, directions=16)
print(f"solved in {sol.bounces} bounces; seconds per phase: {sol.stats['seconds']}")
out = voxgi.render(scene, sol, seed=0)
print(f"{out.frames} frames; seconds: {out.stats['seconds']}")
voxgi.io.write_exr("cornell_box.exr", out.image)
voxgi.io.write_png("cornell_box.png", out.image)
