"""
Render your own mesh
====================

Load any mesh trimesh reads (OBJ, PLY, STL, GLB), put it in a closed room with
a ceiling light, and render it. Here the Stanford bunny shipped with voxgi
stands in for "your" file: pass a path as the first argument to use another.

Run: ``python examples/own_mesh.py [mesh.obj]``
"""

import sys

import numpy as np
import trimesh

import voxgi

if len(sys.argv) > 1:
    mesh = trimesh.load(sys.argv[1], force="mesh")
else:
    mesh = voxgi.scenes.load_bunny()

# Fit the mesh into a 2-unit cube standing on the floor of a 4 x 3 x 4 room.
lo, hi = mesh.bounds
mesh = mesh.copy()
mesh.apply_translation(-np.array([(lo[0] + hi[0]) / 2, lo[1], (lo[2] + hi[2]) / 2]))
mesh.apply_scale(2.0 / (hi - lo).max())

room = trimesh.creation.box(extents=[4, 3, 4])
room.apply_translation([0, 1.5, 0])
room = trimesh.Trimesh(room.vertices, room.faces[:, ::-1])  # normals point into the room
light = trimesh.Trimesh([[-0.5, 2.99, -0.5], [0.5, 2.99, -0.5], [0.5, 2.99, 0.5],
                         [-0.5, 2.99, 0.5]], [[0, 1, 2], [0, 2, 3]])  # faces down

scene = voxgi.Scene(voxgi.Camera(eye=(0, 1.4, 1.9), target=(0, 0.7, 0), fov=50,
                                 width=256, height=256))
scene.add(room, voxgi.Material(albedo=0.7), name="room")
scene.add(mesh, voxgi.Material(albedo=(0.8, 0.6, 0.4)), name="mesh")
scene.add(light, voxgi.Material(albedo=0.0, emission=12.0), name="light")

out = voxgi.render(scene)  # voxelizes and solves with the defaults first
voxgi.io.write_exr("own_mesh.exr", out.image)
voxgi.io.write_png("own_mesh.png", out.image)
print(f"wrote own_mesh.exr/.png ({out.frames} frames)")
