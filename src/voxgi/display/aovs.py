"""The pixel AOVs: albedo, shading normal, depth, object and seen emission of
each pixel's first hits, from the camera hits the frames trace anyway (no
extra rays), averaged over the frames' camera samples with the image's pixel
filter (``docs/design.md`` §6)."""

from __future__ import annotations

import numpy as np

__all__ = ["AOV_CHANNELS", "EMISSION_COLUMN", "AOVMean", "frame_aovs"]

#: Columns of :func:`frame_aovs`: albedo RGB, shading normal XYZ, view depth
#: times the hit indicator, the hit indicator (the share of the pixel's
#: filtered samples that met a surface), and the emitted radiance RGB the
#: pixel sees (an emitter's or the environment's, as the image counts it).
AOV_CHANNELS = (
    *("albedo.R", "albedo.G", "albedo.B"),
    *("normal.X", "normal.Y", "normal.Z"),
    *("zhit", "hit"),
    *("emission.R", "emission.G", "emission.B"),
)

#: Where the seen emission's columns start in :data:`AOV_CHANNELS`.
EMISSION_COLUMN = 8


def frame_aovs(
    hits: dict,
    albedo: np.ndarray,
    eye: np.ndarray,
    forward: np.ndarray,
    *,
    per_hit: bool = False,
    emission: np.ndarray | None = None,
) -> np.ndarray:
    """One frame's AOV samples, a row per pixel (:data:`AOV_CHANNELS`).

    Parameters
    ----------
    hits : dict
        The frame's camera hits (``_FrameShader.camera_hits``): ``pos``
        (P, 3), ``normal`` (P, 3) facing the viewer, ``material`` (P,)
        (-1: nothing, or a one-sided back, which shows black).
    albedo : (objects, 3) or (P, 3) float32
        Each object's diffuse albedo, or with ``per_hit`` each hit's own
        (a texture's; 0 where nothing is met).
    eye, forward : (3,) float
        The camera's centre, in the hits' frame, and its unit view axis.
    emission : (P, 3) float, optional
        The emitted radiance each camera ray sees, as the frame's image
        counts it (0 without).

    Returns
    -------
    (P, 11) float32
        A pixel that met nothing has albedo, normal and depth 0 and hit 0.
    """
    mat = hits["material"]
    hit = mat >= 0
    out = np.empty((len(mat), len(AOV_CHANNELS)), np.float32)
    if per_hit:
        np.multiply(albedo, hit[:, None], out=out[:, 0:3])
    else:
        # one zero row past the objects' for index -1 (nothing met)
        table = np.zeros((len(albedo) + 1, 3), np.float32)
        table[:-1] = albedo
        out[:, 0:3] = table[mat]
    np.multiply(hits["normal"], hit[:, None], out=out[:, 3:6])
    with np.errstate(invalid="ignore", over="ignore"):  # a miss's point is never read
        depth = (hits["pos"] - np.asarray(eye)) @ np.asarray(forward)
    out[:, 6] = np.where(hit, depth, 0.0)
    out[:, 7] = hit
    out[:, EMISSION_COLUMN : EMISSION_COLUMN + 3] = 0.0 if emission is None else emission
    return out


class AOVMean:
    """The running mean of the frames' AOV samples, and the first frame's objects."""

    def __init__(self) -> None:
        self.sum: np.ndarray | None = None
        self.frames = 0
        self.object_id: np.ndarray | None = None

    def add(self, aovs: np.ndarray | None, objects: np.ndarray | None) -> None:
        """Add a frame's (P, 11) AOV samples; keep the first frame's objects."""
        if aovs is None:
            return
        if self.sum is None:
            self.sum = np.zeros(aovs.shape, np.float64)
            self.object_id = None if objects is None else np.asarray(objects, np.int32).copy()
        self.sum += aovs
        self.frames += 1

    def result(self, height: int, width: int) -> dict:
        """``albedo``, ``normal`` and ``emission`` (H, W, 3), ``depth`` and
        ``object_id`` (H, W) of :class:`RenderResult`; all None without any
        frame's AOVs."""
        keys = ("albedo", "normal", "depth", "object_id", "emission")
        if self.sum is None or self.frames == 0:
            return dict.fromkeys(keys)
        m = (self.sum / self.frames).reshape(height, width, -1)
        hit = m[..., 7]
        with np.errstate(divide="ignore", invalid="ignore"):
            depth = np.where(hit > 0, m[..., 6] / hit, np.inf)
        obj = None if self.object_id is None else self.object_id.reshape(height, width)
        return {
            "albedo": m[..., 0:3].astype(np.float32),
            "normal": m[..., 3:6].astype(np.float32),
            "depth": depth.astype(np.float32),
            "object_id": obj,
            "emission": m[..., EMISSION_COLUMN : EMISSION_COLUMN + 3].astype(np.float32),
        }
