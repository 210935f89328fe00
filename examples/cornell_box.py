"""
Render the Cornell box
======================

The classic Cornell box (its published dimensions, Mitsuba 3's colours)
through voxgi's three stages: voxelize the surfaces into sparse records,
solve their radiosity (direct light by shadow rays to the lamp, the bounces
gathered along discrete lines, then finished by passes of rays against the
triangles), and display the result by progressive ray tracing with virtual
point lights. Writes ``cornell_box.exr`` (linear
radiance) and ``cornell_box.png``.

Run: ``python examples/cornell_box.py`` (about a minute on two cores).
"""

import voxgi

scene = voxgi.scenes.cornell_box(width=256, height=256)

vox = voxgi.voxelize(scene, resolution=96)
print(f"voxelized at resolution 96: {len(vox):,} records (voxel edge {vox.pitch:.4f} scene units)")

sol = voxgi.solve(vox, progress=False)
s = sol.stats
print(
    f"solved: {s['direct_light']['rays']:,} shadow rays, {sol.bounces} bounces along the lines "
    f"({s['gather_rays']:,} gathering rays), then {s['traced']['passes']} traced passes "
    f"({s['traced']['rays']:,} rays) in {s['seconds']['total']:.1f} s"
)

out = voxgi.render(scene, sol, progress=False)
print(
    f"displayed: {out.frames} frames in {out.stats['seconds']['total']:.1f} s, "
    f"estimated noise relMSE {out.stats['est_rel_mse']:.1e}"
)

voxgi.io.write_exr("cornell_box.exr", out.image)
voxgi.io.write_png("cornell_box.png", out.image)
print("wrote cornell_box.exr and cornell_box.png")
