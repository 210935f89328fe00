"""Glossy lobes against Mitsuba 3 with the same BSDFs.

    python benchmarks/glossy.py [--scene sphere-plastic] [--spp 1024] [--width 128] [--out DIR]

Scenes: ``sphere-plastic`` and ``sphere-conductor`` (a glossy sphere on a
diffuse floor under a square area light, nothing else: the acceptance scene),
``plane`` (a rough plastic floor and a rough copper panel beside a white wall
under an area light) and ``plane-diffuse`` (the same with the floor diffuse,
its albedo the plastic's hemispherical reflectance, in both renderers).
Prints ``voxgi compare``'s table (relMSE net of the reference's own noise)
and, per object, the relMSE and the brightness against Mitsuba. Needs the
``bench`` extra (Mitsuba 3).
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


def glossy_plane(
    width: int = 128, *, floor_alpha: float = 0.1, metal_alpha: float = 0.2, diffuse_floor=False
) -> Scene:
    """A rough plastic floor (GGX), a rough copper panel and a white wall
    under a square area light, seen from where the floor mirrors the light.
    With ``diffuse_floor`` the floor is diffuse, of the plastic's
    hemispherical reflectance (what its records carry)."""
    cam = Camera(eye=(0.0, 1.2, 3.2), target=(0.0, 0.35, 0.0), fov=45.0, width=width, height=width)
    sc = Scene(cam)
    floor = Microfacet("plastic", alpha=floor_alpha, ior=1.5)
    base = (0.35, 0.3, 0.25)
    if diffuse_floor:
        mat = Material(albedo=tuple(float(x) for x in floor.solve_albedo(base)))
    else:
        mat = Material(albedo=base, specular=floor)
    sc.add(quad([[-2, 0, -2], [2, 0, -2], [2, 0, 2], [-2, 0, 2]], (0, 1, 0)), mat, name="floor")
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


def glossy_sphere(width: int = 128, *, kind: str = "plastic", alpha: float = 0.1) -> Scene:
    """A glossy sphere (rough GGX plastic, or rough gold) on a diffuse floor
    under a square area light, in the open (nothing else, no environment).

    Open, so that what the sphere mirrors is the light, the black sky and a
    diffuse floor, whose records are exact in direction: the comparison
    then measures the lobe and its sampling, not the diffuse records'
    stand-in for other glossy surfaces (``plane`` shows that). The sphere
    is flat-shaded (5,120 triangles, as Mitsuba gets it)."""
    cam = Camera(eye=(0.0, 1.1, 3.0), target=(0.0, 0.45, 0.0), fov=40.0, width=width, height=width)
    sc = Scene(cam)
    sc.add(
        quad([[-3, 0, -3], [3, 0, -3], [3, 0, 3], [-3, 0, 3]], (0, 1, 0)),
        Material(albedo=(0.5, 0.5, 0.5)),
        name="floor",
    )
    ico = trimesh.creation.icosphere(subdivisions=4, radius=0.5)
    ball = trimesh.Trimesh(
        np.asarray(ico.vertices) + np.array([0.0, 0.5, 0.0]), ico.faces, process=False
    )
    if kind == "plastic":
        mat = Material(
            albedo=(0.6, 0.15, 0.1), specular=Microfacet("plastic", alpha=alpha, ior=1.5)
        )
    elif kind == "conductor":
        eta, k = CONDUCTORS["Au"]
        mat = Material(specular=Microfacet("conductor", alpha=alpha, eta=eta, k=k))
    else:
        raise ValueError(f"kind: 'plastic' or 'conductor', got {kind!r}")
    sc.add(ball, mat, name="sphere")
    sc.add(
        quad(
            [[-0.5, 2.2, -1.0], [0.5, 2.2, -1.0], [0.5, 2.2, 0.0], [-0.5, 2.2, 0.0]], (0, 0, -0.5)
        ),
        Material(albedo=0.0, emission=(10.0, 10.0, 10.0)),
        name="light",
    )
    return sc


SCENES = {
    "sphere-plastic": lambda w: glossy_sphere(w, kind="plastic", alpha=0.1),
    "sphere-conductor": lambda w: glossy_sphere(w, kind="conductor", alpha=0.2),
    "plane": lambda w: glossy_plane(w),
    "plane-diffuse": lambda w: glossy_plane(w, diffuse_floor=True),
}


def object_masks(scene: Scene) -> dict:
    """{name: (H, W) bool}: the pixels whose centre and corners all see that
    object, and whose neighbours within 2 pixels do too (the reach of the
    Gaussian pixel filter), as the brightness mask of ``voxgi.compare``."""
    from voxgi.display import camera_rays
    from voxgi.rays import Tracer

    cam = scene.camera
    obj = scene.triangles()["object"]
    ids = None
    with Tracer(scene, 1) as tr:
        for offset in ((0.5, 0.5), (0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)):
            org, dirs = camera_rays(cam, offset)
            prim = tr.intersect(
                np.ascontiguousarray(org - tr.centre, np.float32),
                np.ascontiguousarray(dirs, np.float32),
            )
            o = np.where(prim >= 0, obj[np.maximum(prim, 0)], -1)
            ids = o if ids is None else np.where(ids == o, ids, -2)
    ids = ids.reshape(cam.height, cam.width)
    r = 2
    pad = np.pad(ids, r, constant_values=-2)
    same = np.ones_like(ids, bool)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            same &= pad[r + dy : r + dy + cam.height, r + dx : r + dx + cam.width] == ids
    return {o.name: same & (ids == i) for i, o in enumerate(scene.objects)}


def per_object(scene: Scene, img: np.ndarray, ref: np.ndarray) -> list:
    """[(name, pixels, relMSE, brightness (3,))] of each object not emitting."""
    from voxgi.metrics import rel_mse

    rows = []
    for o, (name, m) in zip(scene.objects, object_masks(scene).items(), strict=True):
        if o.material.is_emitter or not m.any():
            continue
        a, b = img[m].astype(np.float64), ref[m].astype(np.float64)
        rows.append((name, int(m.sum()), rel_mse(a, b), a.sum(axis=0) / b.sum(axis=0)))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", choices=sorted(SCENES), default="sphere-plastic")
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--width", type=int, default=128)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    from voxgi.compare import compare

    sc = SCENES[a.scene](a.width)
    r = compare(sc, spp=a.spp, sweep_spp=(16,), denoise=False, threads=a.threads, out_dir=a.out)
    print(r.table())
    for name, n, e, b in per_object(sc, r.voxgi, r.reference):
        print(
            f"{name:<8} {n:6d} px  relMSE {e:.3e}  brightness " + ", ".join(f"{x:.4f}" for x in b)
        )


if __name__ == "__main__":
    main()
