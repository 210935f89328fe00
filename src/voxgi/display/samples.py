"""Camera sampling: each frame's sub-pixel offset and lens point, and the
camera rays through them (``docs/design.md`` §6)."""

from __future__ import annotations

import math

import numpy as np

from .. import _core
from .._qmc import sobol
from ..scene import Camera

__all__ = ["camera_arguments", "camera_rays", "frame_samples", "mirror_points"]


def _radical_inverse(i: int, base: int) -> float:
    f, r = 1.0, 0.0
    while i > 0:
        f /= base
        r += f * (i % base)
        i //= base
    return r


def _concentric_disc(u: float, v: float) -> tuple[float, float]:
    """Shirley–Chiu map of the unit square onto the unit disc (area preserving)."""
    a, b = 2.0 * u - 1.0, 2.0 * v - 1.0
    if a == 0.0 and b == 0.0:
        return 0.0, 0.0
    if abs(a) > abs(b):
        r, phi = a, (math.pi / 4) * (b / a)
    else:
        r, phi = b, math.pi / 2 - (math.pi / 4) * (a / b)
    return r * math.cos(phi), r * math.sin(phi)


def frame_samples(frame: int, seed: int = 0) -> tuple[tuple[float, float], tuple[float, float]]:
    """Sub-pixel offset in [0, 1)² and lens point in the unit disc for a frame.

    One sample per frame, shared by all pixels (the paper, section 6). The
    offsets follow the (0, 2)-sequence in base 2 (van der Corput and Sobol'
    dimension 2) with a random digit scramble (XOR) drawn from ``seed``, which
    keeps its stratification: any first 4^k frames put exactly one offset in
    each cell of a 2^k x 2^k grid of the pixel. The lens points follow Halton
    bases 3 and 5 (Cranley–Patterson rotated), mapped to the disc by the
    area-preserving concentric map.
    """
    rng = np.random.default_rng([int(seed), 0x5EED])
    s1, s2 = (int(x) for x in rng.integers(0, 1 << 32, size=2, dtype=np.uint64))
    rot = rng.random(2)
    i = int(frame)
    u1, u2 = (int(x) for x in sobol([i], 2)[0])
    off = ((u1 ^ s1) / 2.0**32, (u2 ^ s2) / 2.0**32)
    lu = (_radical_inverse(i + 1, 3) + rot[0]) % 1.0
    lv = (_radical_inverse(i + 1, 5) + rot[1]) % 1.0
    return off, _concentric_disc(lu, lv)


def mirror_points(index, seed: int = 0) -> np.ndarray:
    """(n, 2) numbers in [0, 1)² of the first mirror link of samples
    ``index`` (n,): Sobol' dimensions 3 and 4 with a random digit scramble
    drawn from ``seed``, so that with the sub-pixel offsets (dimensions 1
    and 2, :func:`frame_samples`) the samples stay evenly spread in all four
    (the compiled kernels rotate them by each pixel's own offset)."""
    rng = np.random.default_rng([int(seed), 0x3C1])
    scramble = rng.integers(0, 1 << 32, size=2, dtype=np.uint64).astype(np.uint32)
    return (sobol(index, 4)[:, 2:] ^ scramble) / 2.0**32


def camera_arguments(cam: Camera, centre=(0.0, 0.0, 0.0)) -> tuple:
    """The camera arguments of the compiled camera kernels (``camera_rays``,
    ``camera_hits``, ``camera_emission``), before the sample: the eye moved
    by ``-centre`` (into a tracer's scene-centred frame), the unit frame,
    ``tan(fov / 2)``, the image size, the aperture and the focus distance."""
    right, up, fwd = cam.frame()
    return (
        np.asarray(cam.eye, dtype=np.float64) - np.asarray(centre, dtype=np.float64),
        np.asarray(right, dtype=np.float64),
        np.asarray(up, dtype=np.float64),
        np.asarray(fwd, dtype=np.float64),
        math.tan(math.radians(cam.fov) / 2.0),
        cam.width,
        cam.height,
        float(cam.aperture),
        float(cam.focus),
    )


def camera_rays(cam: Camera, offset=(0.5, 0.5), lens=(0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Primary rays of every pixel, row-major from the top-left pixel.

    The rays the display traces (:func:`voxgi._core.camera_rays`, the
    arithmetic of its camera kernel), in world coordinates.

    Parameters
    ----------
    cam : Camera
    offset : (2,) float
        Sub-pixel position in [0, 1)² (x right, y down) used by every pixel.
    lens : (2,) float
        Point on the unit disc scaled by ``cam.aperture`` (thin lens).

    Returns
    -------
    org, dirs : (H*W, 3) float64
        Origins (on the lens) and unit directions. Pixel ``(i, j)`` (row,
        column) sees ``right = forward x up`` to its right; the rays of all
        lens points through one pixel meet on the plane in focus.
    """
    return _core.camera_rays(
        *camera_arguments(cam),
        (float(offset[0]), float(offset[1])),
        (float(lens[0]), float(lens[1])),
    )
