"""The propagation kernels called directly (voxgi._core.LineSystem).

Records are built here from analytic surfaces (a sphere and boxes seen from
inside), so these tests do not depend on the voxelizer: areas come from a
deterministic Fibonacci sampling of the sphere or are exact for boxes.
"""

from __future__ import annotations

import numpy as np
import pytest

from voxgi import _core
from voxgi.directions import direction_set

# ----------------------------------------------------------------- records


def sphere_records(res: int, radius: float | None = None, *, back: bool = True,
                   centre=None, samples_per_voxel: int = 200) -> dict:
    """Supercover records of a sphere seen from inside, in voxel units.

    Every voxel whose closed cube meets the sphere gets a record (normal
    pointing to the centre); ``back`` adds a black back record per voxel with
    the opposite normal at the same point, as the voxelizer does for a
    one-sided surface. Areas: a Fibonacci lattice of points on the sphere
    binned into voxels (deterministic).
    """
    c = np.asarray(centre if centre is not None else [res / 2 + 0.13, res / 2 - 0.21, res / 2 + 0.07])
    rs = 0.45 * res if radius is None else radius
    i = np.arange(res)
    g = np.stack(np.meshgrid(i, i, i, indexing="ij"), axis=-1).reshape(-1, 3)
    lo, hi = g.astype(np.float64), g + 1.0
    dmin = np.linalg.norm(np.clip(c, lo, hi) - c, axis=1)
    dmax = np.linalg.norm(np.maximum(np.abs(lo - c), np.abs(hi - c)), axis=1)
    sel = (dmin <= rs) & (rs <= dmax)
    ijk = g[sel].astype(np.int32)
    # Fibonacci lattice on the sphere: equal-area points
    area_total = 4 * np.pi * rs * rs
    m = int(samples_per_voxel * area_total)
    k = np.arange(m) + 0.5
    zc = 1 - 2 * k / m
    phi = np.pi * (1 + 5 ** 0.5) * k
    rxy = np.sqrt(1 - zc * zc)
    pts = c + rs * np.stack([rxy * np.cos(phi), rxy * np.sin(phi), zc], axis=1)
    cell = np.floor(pts).astype(np.int64)
    lin_s = (cell[:, 0] * res + cell[:, 1]) * res + cell[:, 2]
    lin_r = (ijk[:, 0].astype(np.int64) * res + ijk[:, 1]) * res + ijk[:, 2]
    slot = np.searchsorted(lin_r, lin_s)
    ok = (slot < len(lin_r)) & (lin_r[np.minimum(slot, len(lin_r) - 1)] == lin_s)
    assert ok.mean() > 0.999  # the supercover holds (nearly) every sample
    cnt = np.bincount(slot[ok], minlength=len(ijk)).astype(np.float64)
    area = cnt * area_total / m
    cen = np.stack([np.bincount(slot[ok], weights=pts[ok, a], minlength=len(ijk)) for a in range(3)], 1)
    centre_v = ijk + 0.5
    proj = c + rs * (centre_v - c) / np.linalg.norm(centre_v - c, axis=1, keepdims=True)
    cen = np.where(cnt[:, None] > 0, cen / np.maximum(cnt, 1)[:, None], proj)
    normal = c - cen
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    rec = {"ijk": ijk, "normal": normal.astype(np.float32), "point": cen.astype(np.float32),
           "area": area, "back": np.zeros(len(ijk), bool), "centre": c, "radius": rs}
    if back:
        rec = {"ijk": np.concatenate([ijk, ijk]), "normal": np.concatenate([rec["normal"], -rec["normal"]]),
               "point": np.concatenate([rec["point"], rec["point"]]),
               "area": np.concatenate([area, area]),
               "back": np.concatenate([np.zeros(len(ijk), bool), np.ones(len(ijk), bool)]),
               "centre": c, "radius": rs}
    return rec


def box_records(lo, hi, *, inward: bool = True, back: bool = False) -> dict:
    """Records of an axis-aligned box [lo, hi] (voxel units, non-integer
    faces), one record per face piece per voxel, exact clipped areas."""
    lo = np.asarray(lo, np.float64)
    hi = np.asarray(hi, np.float64)
    out = {"ijk": [], "normal": [], "point": [], "area": [], "back": []}
    for a in range(3):
        b, c = [x for x in range(3) if x != a]
        for side, plane in ((0, lo[a]), (1, hi[a])):
            n = np.zeros(3)
            n[a] = (1.0 if side == 0 else -1.0) * (1 if inward else -1)
            jb = np.arange(int(np.floor(lo[b])), int(np.ceil(hi[b])))
            jc = np.arange(int(np.floor(lo[c])), int(np.ceil(hi[c])))
            JB, JC = np.meshgrid(jb, jc, indexing="ij")
            JB, JC = JB.ravel(), JC.ravel()
            b0, b1 = np.maximum(JB, lo[b]), np.minimum(JB + 1, hi[b])
            c0, c1 = np.maximum(JC, lo[c]), np.minimum(JC + 1, hi[c])
            ijk = np.zeros((len(JB), 3), np.int32)
            ijk[:, a] = int(np.floor(plane))
            ijk[:, b], ijk[:, c] = JB, JC
            pt = np.zeros((len(JB), 3))
            pt[:, a] = plane
            pt[:, b], pt[:, c] = (b0 + b1) / 2, (c0 + c1) / 2
            for flip, isback in ((1, False), (-1, True)) if back else ((1, False),):
                out["ijk"].append(ijk)
                out["normal"].append(np.tile(n * flip, (len(JB), 1)))
                out["point"].append(pt)
                out["area"].append((b1 - b0) * (c1 - c0))
                out["back"].append(np.full(len(JB), isback))
    rec = {k: np.concatenate(v) for k, v in out.items()}
    rec["ijk"] = rec["ijk"].astype(np.int32)
    rec["normal"] = rec["normal"].astype(np.float32)
    rec["point"] = rec["point"].astype(np.float32)
    return rec


def merge(*recs) -> dict:
    return {k: np.concatenate([r[k] for r in recs]) for k in ("ijk", "normal", "point", "area", "back")}


def system(rec, **kw) -> _core.LineSystem:
    return _core.LineSystem(np.ascontiguousarray(rec["ijk"], np.int32),
                            np.ascontiguousarray(rec["normal"], np.float32),
                            np.ascontiguousarray(rec["point"], np.float32), **kw)


def gathered_share(rec, radius, **kw):
    """Share of each record's hemisphere (cos-weighted, normalised) that finds a partner."""
    ds = direction_set(radius)
    s = system(rec, **kw)
    S = s.normalisation(ds.families, ds.weights)
    ones = np.ones((len(rec["ijk"]), 3), np.float32)
    sums, vis, _ = s.gather(ds.families, ds.weights, ones, np.arange(len(ds.families)), True)
    return sums[:, 0] / S, vis / S, S


def voxelset(rec, *, albedo=0.5, emission=1.0, pitch=0.1, emit_mask=None):
    """A VoxelSet from synthetic records (voxel units -> world with `pitch`)."""
    from voxgi.voxels import VoxelSet

    n = len(rec["ijk"])
    back = rec["back"]
    alb = np.broadcast_to(np.asarray(albedo, np.float32), (n, 3)).copy()
    em = np.broadcast_to(np.asarray(emission, np.float32), (n, 3)).copy()
    if emit_mask is not None:
        em[~emit_mask] = 0
    alb[back] = 0
    em[back] = 0
    origin = np.array([-1.0, 0.5, 2.0])
    return VoxelSet(ijk=rec["ijk"].astype(np.int32), normal=rec["normal"].astype(np.float32),
                    area=(rec["area"] * pitch * pitch).astype(np.float32), albedo=alb, emission=em,
                    centroid=origin + rec["point"].astype(np.float64) * pitch,
                    object_id=np.zeros(n, np.int32), back=back.copy(), pitch=pitch, origin=origin,
                    resolution=int(rec["ijk"].max()) + 1)
