"""Surface voxelization: triangle meshes -> sparse oriented surface records."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["VoxelSet", "voxelize"]


@dataclass
class VoxelSet:
    """Sparse surface records of a voxelized scene.

    One record per voxel, surface orientation (side) and material; see
    :func:`voxelize`. All arrays have length ``N = len(vox)``.

    Attributes
    ----------
    ijk : (N, 3) int32
        Integer voxel coordinates; voxel ``ijk`` spans
        ``origin + pitch * [ijk, ijk + 1]``.
    normal : (N, 3) float32
        Unit normal, area-weighted over the record's pieces.
    area : (N,) float32
        Surface area represented, scene units².
    albedo, emission : (N, 3) float32
        Area-weighted albedo and emitted radiance.
    centroid : (N, 3) float64
        A point on the surface inside the voxel (where a VPL sits).
    object_id : (N,) int32
        Index of the scene object the record comes from.
    back : (N,) bool
        True for the black back record of a one-sided surface.
    pitch : float
        Voxel edge length.
    origin : (3,) float64
        World position of voxel (0, 0, 0)'s minimum corner.
    resolution : int
        Voxels along the longest side of the bounding box.
    scene_fingerprint : str
        :meth:`voxgi.Scene.fingerprint` of the scene voxelized.
    stats : dict
        Timings and counts (``seconds``, ``triangles``, ``skipped``...).
    """

    ijk: np.ndarray
    normal: np.ndarray
    area: np.ndarray
    albedo: np.ndarray
    emission: np.ndarray
    centroid: np.ndarray
    object_id: np.ndarray
    back: np.ndarray
    pitch: float
    origin: np.ndarray
    resolution: int
    scene_fingerprint: str = ""
    stats: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.ijk.shape[0])

    def __repr__(self) -> str:
        return (f"VoxelSet({len(self)} records, resolution={self.resolution}, "
                f"pitch={self.pitch:.4g}, emitters={int(self.is_emitter.sum())})")

    def positions(self) -> np.ndarray:
        """(N, 3) float64 world-space voxel centres."""
        return self.origin + (self.ijk.astype(np.float64) + 0.5) * self.pitch

    @property
    def is_emitter(self) -> np.ndarray:
        """(N,) bool: records with non-zero emission."""
        return np.any(self.emission > 0, axis=1)


def voxelize(scene, resolution: int = 128, *, max_memory: int | None = None) -> VoxelSet:
    """Convert the surfaces of a scene into oriented surface voxels."""
    raise NotImplementedError("voxelize: not implemented yet")
