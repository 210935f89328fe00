"""Glossy lobes against Mitsuba 3 with the same BSDFs: a rough plastic floor
and a rough copper panel under an area light, beside a white wall.

    python benchmarks/glossy.py [--spp 1024] [--width 128] [--out DIR]

Prints ``voxgi compare``'s table (relMSE net of the reference's own noise)
and the relMSE per object. Needs the ``bench`` extra (Mitsuba 3).
"""

from __future__ import annotations

import argparse

import numpy as np
import trimesh

from voxgi import CONDUCTORS, Camera, Material, Microfacet, Scene


def quad(corners, toward) -> trimesh.Trimesh:
    c = np.asarray(corners, dtype=np.float64)
    if np.dot(np.cross(c[1] - c[0], c[2] - c[0]), np.asarray(toward) - c.mean(axis=0)) < 0:
        c = c[::-1]
    return trimesh.Trimesh(c, [[0, 1, 2], [0, 2, 3]], process=False)


def glossy_plane(width: int = 128, *, floor_alpha: float = 0.1, metal_alpha: float = 0.2) -> Scene:
    """A rough plastic floor (GGX), a rough copper panel and a white wall
    under a square area light, seen from where the floor mirrors the light."""
    cam = Camera(eye=(0.0, 1.2, 3.2), target=(0.0, 0.35, 0.0), fov=45.0, width=width, height=width)
    sc = Scene(cam)
    floor = Microfacet("plastic", alpha=floor_alpha, ior=1.5)
    sc.add(
        quad([[-2, 0, -2], [2, 0, -2], [2, 0, 2], [-2, 0, 2]], (0, 1, 0)),
        Material(albedo=(0.35, 0.3, 0.25), specular=floor),
        name="floor",
    )
    sc.add(
        quad([[-2, 0, -1.5], [2, 0, -1.5], [2, 2, -1.5], [-2, 2, -1.5]], (0, 1, 0)),
        Material(albedo=(0.7, 0.7, 0.7)),
        name="wall",
    )
    eta, k = CONDUCTORS["Cu"]
    sc.add(
        quad([[0.3, 0.0, -0.8], [1.3, 0.0, -0.3], [1.3, 0.9, -0.3], [0.3, 0.9, -0.8]], (0, 0.5, 3)),
        Material(specular=Microfacet("conductor", alpha=metal_alpha, eta=eta, k=k)),
        name="copper",
    )
    sc.add(
        quad(
            [[-0.4, 1.9, -0.9], [0.4, 1.9, -0.9], [0.4, 1.9, -0.1], [-0.4, 1.9, -0.1]], (0, 0, -0.5)
        ),
        Material(albedo=0.0, emission=(12.0, 12.0, 12.0)),
        name="light",
    )
    return sc


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--width", type=int, default=128)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    from voxgi.compare import compare

    sc = glossy_plane(a.width)
    r = compare(sc, spp=a.spp, sweep_spp=(16,), denoise=False, threads=a.threads, out_dir=a.out)
    print(r.table())


if __name__ == "__main__":
    main()
