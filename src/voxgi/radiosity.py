"""Radiosity on voxels: discrete-line propagation (shooting, then gathering)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .voxels import VoxelSet

__all__ = ["Solution", "solve"]


@dataclass
class Solution:
    """Radiosity of every record of a :class:`VoxelSet`.

    Attributes
    ----------
    vox : VoxelSet
        The records solved for.
    radiosity : (N, 3) float32
        ``B`` per record (W/m² per channel, i.e. ``pi`` times radiance).
    bounces : int
        Gathering iterations run.
    residuals : list of float
        Relative residual after each iteration.
    stats : dict
        ``rays``, ``shoot_rays``, ``gather_rays``, ``seconds`` (phase -> s),
        and what was skipped.
    """

    vox: VoxelSet
    radiosity: np.ndarray
    bounces: int = 0
    residuals: list = field(default_factory=list)
    stats: dict = field(default_factory=dict)

    @property
    def radiance(self) -> np.ndarray:
        """(N, 3) float32 outgoing radiance ``B / pi``."""
        return (self.radiosity / np.float32(np.pi)).astype(np.float32)

    def save(self, path) -> Path:
        """Save records and radiosity to a ``.npz`` file (see :meth:`load`)."""
        raise NotImplementedError

    @classmethod
    def load(cls, path) -> Solution:
        raise NotImplementedError


def solve(vox: VoxelSet, directions: int = 22, max_bounces: int | None = None, tol: float = 1e-4,
          threads: int | None = None, client=None, **kwargs) -> Solution:
    """Solve the discrete radiosity equation on the records of ``vox``."""
    raise NotImplementedError("solve: not implemented yet")
