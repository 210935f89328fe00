"""
Render your own mesh
====================

Load any mesh trimesh reads (OBJ, PLY, STL, GLB), stand it on the floor of a
closed room lit by a ceiling panel, aim the camera so the whole mesh is in
view, and render it. The Stanford bunny shipped with voxgi stands in for
"your" file: pass a path as the first argument to use another. Writes
``own_mesh.exr`` and ``own_mesh.png``.

Run: ``python examples/own_mesh.py [mesh.obj]``
"""

import math
import sys

import numpy as np
import trimesh

import voxgi

if len(sys.argv) > 1:
    mesh = trimesh.load(sys.argv[1], force="mesh")
else:
    mesh = voxgi.scenes.load_bunny()

# Scale the mesh to 1.2 units along its longest side and stand it on the
# floor (y = 0), centred on the room's vertical axis.
mesh = mesh.copy()
mesh.apply_scale(1.2 / (mesh.bounds[1] - mesh.bounds[0]).max())
lo, hi = mesh.bounds
mesh.apply_translation([-(lo[0] + hi[0]) / 2, -lo[1], -(lo[2] + hi[2]) / 2])
lo, hi = mesh.bounds
print(f"mesh: {len(mesh.faces):,} triangles, {hi - lo} units after scaling")

# A 6 x 3.5 x 6 room around it, normals pointing in, and a light panel facing down.
room = trimesh.creation.box(extents=[6, 3.5, 6])
room.apply_translation([0, 1.75, 0])
room = trimesh.Trimesh(room.vertices, room.faces[:, ::-1])
light = trimesh.Trimesh(
    [[-0.6, 3.49, -0.6], [0.6, 3.49, -0.6], [0.6, 3.49, 0.6], [-0.6, 3.49, 0.6]],
    [[0, 1, 2], [0, 2, 3]],
)

# Frame the mesh: its bounding sphere fills the field of view, seen from the
# front and a little above.
fov = 50.0
centre = (lo + hi) / 2
radius = float(np.linalg.norm(hi - lo)) / 2
distance = 1.05 * radius / math.sin(math.radians(fov / 2))
view = np.array([0.35, 0.45, 1.0]) / np.linalg.norm([0.35, 0.45, 1.0])
eye = centre + distance * view  # inside the room for a mesh of this size
camera = voxgi.Camera(eye=tuple(eye), target=tuple(centre), fov=fov, width=256, height=256)
print(f"camera at {np.round(eye, 2)}, {distance:.2f} units from the mesh's centre")

scene = voxgi.Scene(camera)
scene.add(room, voxgi.Material(albedo=0.7), name="room")
scene.add(mesh, voxgi.Material(albedo=(0.8, 0.6, 0.4)), name="mesh")
scene.add(light, voxgi.Material(albedo=0.0, emission=10.0), name="light")

out = voxgi.render(scene, progress=False)  # voxelizes and solves with the defaults first
sec = out.stats["seconds"]
print(
    f"voxelized in {sec['voxelize']:.1f} s, solved in {sec['solve']:.1f} s "
    f"({out.solution.bounces} bounces), displayed {out.frames} frames in "
    f"{sec['display']:.1f} s"
)
voxgi.io.write_exr("own_mesh.exr", out.image)
voxgi.io.write_png("own_mesh.png", out.image)
print("wrote own_mesh.exr and own_mesh.png")
