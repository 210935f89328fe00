"""Where the direct light of the closed black Cornell box goes (issue 3).

The box closed by a fourth wall, albedo 0: every emitted watt must land on
some record. The discrete shooting (receiver-side deposit, as in solve) is
compared per object, and on the floor per voxel, with a Monte Carlo
reference traced by Embree on the exact meshes (cosine-weighted rays from
uniform points of the lamp). Prints the power share of each object, and the
floor's deficit split into voxels near a block's footprint (its shadow
silhouette) and the rest.

    python benchmarks/energy_silhouette.py --res 32 64
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np
import trimesh

import voxgi
from voxgi import _core
from voxgi.directions import direction_set
from voxgi.radiosity import _check_vox, _flat_emitter_coverage


def discrete_direct(vox, Rs=16, eps=0.02, hist=16, sil=False):
    a = _check_vox(vox)
    E = np.pi * a["emission"].astype(np.float64)
    sysm = _core.LineSystem(a["ijk"], a["normal"], a["point"], epsilon=eps, history=hist)
    sds = direction_set(Rs)
    Ss = sysm.normalisation(sds.families, sds.weights, 1)
    emitters = np.flatnonzero(np.any(E > 0, axis=1)).astype(np.int32)
    cov, _ = _flat_emitter_coverage(a, vox, emitters)
    obj = np.ascontiguousarray(vox.object_id, np.int32)
    sil_area = a["area"] / a["pitch"] ** 2
    sil_area[np.isin(obj, np.unique(obj[emitters]))] = -1.0  # as solve: not past emitting objects
    hd, unfound, _, _ = sysm.shoot(emitters, sds.families, sds.weights,
                                   np.ascontiguousarray(E, np.float32), 1, coverage=cov,
                                   **(dict(object=obj, sil_area=sil_area, back=a["back"])
                                      if sil else {}))
    Hd = hd[:, 0] / Ss
    power = Hd * a["area"]
    emitted = float((E[:, 0] * a["area"]).sum())
    escape = float((E[emitters, 0] * a["area"][emitters] * unfound / Ss[emitters]).sum())
    return power, emitted, escape


def mc_reference(scene, vox, n=2_000_000, seed=1):
    """Per object the share of the lamp's power it receives, and per (voxel,
    object) the share (hits binned by voxel)."""
    rng = np.random.default_rng(seed)
    names = [o.name for o in scene.objects]
    li = names.index("light")
    lamp = scene.objects[li]
    v = lamp.vertices
    lo, hi = v.min(axis=0), v.max(axis=0)
    y = v[0, 1]
    meshes, owner = [], []
    for k, o in enumerate(scene.objects):
        if k == li:
            continue
        meshes.append(trimesh.Trimesh(o.vertices, o.faces, process=False))
        owner.append(np.full(len(o.faces), k))
    mesh = trimesh.util.concatenate(meshes)
    owner = np.concatenate(owner)
    ray = trimesh.ray.ray_pyembree.RayMeshIntersector(mesh)
    per_obj = np.zeros(len(names))
    bins = {}
    done = 0
    while done < n:
        m = min(200_000, n - done)
        o = np.empty((m, 3))
        o[:, 0] = rng.uniform(lo[0], hi[0], m)
        o[:, 2] = rng.uniform(lo[2], hi[2], m)
        o[:, 1] = y - 1e-7
        u1, u2 = rng.random(m), rng.random(m)
        r, ph = np.sqrt(u1), 2 * np.pi * u2
        d = np.stack([r * np.cos(ph), -np.sqrt(1 - u1), r * np.sin(ph)], axis=1)
        tri, idx, loc = ray.intersects_id(o, d, multiple_hits=False, return_locations=True)
        obj = owner[tri]
        per_obj += np.bincount(obj, minlength=len(names))
        vk = np.floor((loc - vox.origin) / vox.pitch).astype(np.int64)
        key = obj * 1_000_000_000 + vk[:, 0] * 1_000_000 + vk[:, 1] * 1_000 + vk[:, 2]
        uk, cnt = np.unique(key, return_counts=True)
        for kk, c in zip(uk, cnt):
            bins[int(kk)] = bins.get(int(kk), 0) + int(c)
        done += m
    return names, per_obj / n, {k: c / n for k, c in bins.items()}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--res", type=int, nargs="+", default=[32, 64])
    ap.add_argument("--rays", type=int, default=2_000_000)
    ap.add_argument("--rs", type=int, default=16)
    ap.add_argument("--blocks", type=int, default=1)
    ap.add_argument("--sil", type=int, default=0, help="1: the kernel's silhouette rule")
    args = ap.parse_args()
    scene = voxgi.scenes.cornell_box(width=32, height=32, blocks=bool(args.blocks), closed=True)
    for res in args.res:
        vox = voxgi.voxelize(scene, resolution=res, threads=1)
        vox = dataclasses.replace(vox, albedo=np.zeros_like(vox.albedo))
        power, emitted, escape = discrete_direct(vox, Rs=args.rs, sil=bool(args.sil))
        names, ref, bins = mc_reference(scene, vox, n=args.rays)
        obj = np.asarray(vox.object_id)
        print(f"res {res}: records {len(vox)}, imbalance (direct) "
              f"{(emitted - power.sum() - escape) / emitted:+.5f}, escape {escape / emitted:.5f}")
        print(f"  {'object':12s} {'discrete':>9s} {'MC ref':>9s} {'diff':>9s}  (share of emitted)")
        for k, nm in enumerate(names):
            if nm == "light":
                continue
            dsc = power[obj == k].sum() / emitted
            bk = power[(obj == k) & np.asarray(vox.back)].sum() / emitted
            print(f"  {nm:12s} {dsc:9.5f} {ref[k]:9.5f} {dsc - ref[k]:+9.5f}   (back records {bk:.5f})")
        # per voxel on the floor: deficit near the blocks' footprints vs elsewhere
        fl = names.index("floor")
        ijk = np.asarray(vox.ijk)
        sel = np.flatnonzero(obj == fl)
        dpow = {}
        for r in sel:
            i, j, k = ijk[r]
            key = fl * 1_000_000_000 + i * 1_000_000 + j * 1_000 + k
            dpow[key] = dpow.get(key, 0.0) + power[r] / emitted
        keys = set(dpow) | {k for k in bins if k // 1_000_000_000 == fl}
        diff = np.array([dpow.get(k, 0.0) - bins.get(k, 0.0) for k in keys])
        refv = np.array([bins.get(k, 0.0) for k in keys])
        dscv = np.array([dpow.get(k, 0.0) for k in keys])
        # voxels that the reference lights but the discrete leaves (nearly) dark: a too-wide shadow
        dark = (dscv < 0.1 * refv) & (refv > 0)
        print(f"  floor voxels {len(keys)}: total diff {diff.sum():+.5f}; "
              f"voxels lit in ref but <10% in discrete: {dark.sum()}, their ref power {refv[dark].sum():.5f}")
        print(f"  floor: sum of positive diffs {diff[diff > 0].sum():+.5f}, negative {diff[diff < 0].sum():+.5f}")
        if args.blocks:
            # the reference's visibility of the lamp per floor voxel (with / without blocks)
            _, _, open_bins = mc_reference(voxgi.scenes.cornell_box(width=32, height=32, blocks=False,
                                                                   closed=True), vox, n=args.rays)
            free = np.array([open_bins.get(k, 0.0) for k in keys])
            vis = np.where(free > 0, refv / np.maximum(free, 1e-300), 1.0)
            for nm, m in (("lit (vis > 0.95)", vis > 0.95), ("penumbra", (vis > 0.05) & (vis <= 0.95)),
                          ("umbra (vis <= 0.05)", vis <= 0.05)):
                print(f"    floor {nm:20s}: voxels {m.sum():4d}, ref {refv[m].sum():.5f}, "
                      f"discrete {dscv[m].sum():.5f}, diff {diff[m].sum():+.5f}")


if __name__ == "__main__":
    main()
