"""Anti-aliased display: progressive VPL ray tracing of a voxel solution."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["RenderResult", "render"]


@dataclass
class RenderResult:
    """Output of :func:`voxgi.render`.

    Attributes
    ----------
    image : (H, W, 3) float32
        Linear radiance; ``image[0, 0]`` is the top-left pixel.
    frames : int
        Progressive frames accumulated.
    stderr : (H, W, 3) float32 or None
        Per-pixel standard error estimate of ``image``.
    stats : dict
        ``seconds`` per phase and ray counts.
    """

    image: np.ndarray
    frames: int = 0
    stderr: np.ndarray | None = None
    stats: dict = field(default_factory=dict)
    solution: object = None


def render(scene, sol=None, vpls_per_frame: int = 16, max_frames: int | None = None,
           tol: float | None = None, seed: int = 0, progress: bool = True,
           threads: int | None = None, client=None, **kwargs) -> RenderResult:
    """Render ``scene`` from its camera using the voxel solution ``sol``."""
    raise NotImplementedError("render: not implemented yet")
