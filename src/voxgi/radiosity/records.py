"""The records as the radiosity kernels take them: validated, C-contiguous."""

from __future__ import annotations

import numpy as np

from .. import _validate
from ..voxels import VoxelSet

__all__ = ["check_vox", "flat_emitter_coverage"]


def check_vox(vox) -> dict:
    """Validate a VoxelSet and return the C-contiguous arrays the kernels take."""
    if not isinstance(vox, VoxelSet):
        raise TypeError(f"vox: expected a VoxelSet, got {type(vox).__name__}")
    ijk = _validate.as_c_array(vox.ijk, np.int32, (-1, 3), "vox.ijk")
    n = len(ijk)
    if n == 0:
        raise ValueError("vox: no records")
    out = {
        "ijk": ijk,
        "normal": _validate.as_c_array(vox.normal, np.float32, (n, 3), "vox.normal"),
        "area": _validate.as_c_array(vox.area, np.float64, (n,), "vox.area"),
        "albedo": _validate.as_c_array(vox.albedo, np.float32, (n, 3), "vox.albedo"),
        "emission": _validate.as_c_array(vox.emission, np.float32, (n, 3), "vox.emission"),
        "centroid": _validate.as_c_array(vox.centroid, np.float64, (n, 3), "vox.centroid"),
    }
    pitch = _validate.real(vox.pitch, "vox.pitch", low=0.0, low_open=True)
    origin = _validate.vec3(vox.origin, "vox.origin")
    if np.any(out["area"] < 0):
        raise ValueError("vox.area: negative area")
    if np.any(out["emission"] < 0):
        raise ValueError("vox.emission: negative emission")
    a = out["albedo"]
    if np.any(a < 0) or np.any(a >= 1):
        bad = int(np.argwhere((a < 0) | (a >= 1))[0, 0])
        raise ValueError(f"vox.albedo: record {bad} has albedo {a[bad].tolist()} outside [0, 1)")
    ln = np.linalg.norm(out["normal"], axis=1)
    if np.any(np.abs(ln - 1) > 1e-3):
        bad = int(np.argmax(np.abs(ln - 1)))
        raise ValueError(f"vox.normal: record {bad} is not a unit vector (|n| = {ln[bad]:.4g})")
    back = getattr(vox, "back", None)
    out["back"] = (
        np.zeros(n, bool)
        if back is None
        else _validate.as_c_array(back, np.bool_, (n,), "vox.back")
    )
    # surface points in voxel units (voxel ijk spans [ijk, ijk + 1]); float32
    # keeps 1e-3 voxel accuracy up to 16k voxels, far under the facing margin
    out["point"] = np.ascontiguousarray((out["centroid"] - origin) / pitch, dtype=np.float32)
    out["pitch"] = pitch
    return out


def flat_emitter_coverage(a: dict, vox: VoxelSet, emitters: np.ndarray) -> tuple[np.ndarray, list]:
    """Per record: its area in voxel units if it is a front record of a flat
    emitting object (every front record of the object has one normal and
    lies in one plane, to 1e-3 voxel), else -1 (whole-line rule). Returns
    that and the ids of the flat objects."""
    n = len(a["ijk"])
    cov = np.full(n, -1.0)
    obj = getattr(vox, "object_id", None)
    if obj is None or len(emitters) == 0:
        return cov, []
    obj = np.asarray(obj)
    flat = []
    for o in np.unique(obj[emitters]):
        idx = np.flatnonzero((obj == o) & ~a["back"])
        if len(idx) == 0:
            continue
        nrm = a["normal"][idx].astype(np.float64)
        pts = a["point"][idx].astype(np.float64)
        n0 = nrm[0]
        if np.all(nrm @ n0 > 1 - 1e-6) and np.all(np.abs((pts - pts[0]) @ n0) < 1e-3):
            cov[idx] = a["area"][idx] / a["pitch"] ** 2
            flat.append(int(o))
    return cov, flat
