"""The emission a pixel sees directly, integrated over its footprint once: a
control variate for the frames' camera samples (``docs/design.md`` §6).

Each frame shoots one camera ray per pixel, at a sub-pixel offset that all
pixels share. A pixel that a lamp's outline crosses sees the lamp in some
frames and the wall beside it in others: its few frames estimate the lamp's
share of the pixel badly (one hit in eight frames where the share is one in
fifty), its error can be a hundred times its level, and every pixel of the
outline errs with the same offsets. The emission seen is a function of the
camera ray alone, so its integral over the pixel can be computed once, with
many rays and no shading: each frame then counts, at those pixels, that
integral in place of the emission its own ray saw,

.. math:: \\hat L_f = L_f - L_e(\\omega_f) + \\bar L_e, \\qquad
          \\bar L_e = \\frac{1}{K} \\sum_k L_e(\\omega_k),

which has the same mean as ``L_f`` (``E[L_e(ω_f)] = ∫ L_e``, up to the K
stratified samples' error in ``\\bar L_e``) and none of the emission's
spread. The pixels are found by one ray through every pixel corner: those
whose corners see different emission, and their neighbours. With the
Gaussian pixel filter a pixel is made of the samples within its reach,
each weighted by the frame's offset: the frame's filtered emission is what
is replaced there, by the mean of the filtered footprint samples.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .. import _core
from .._qmc import sobol
from .pixel_filter import _FILTER_REACH, GAUSSIAN_TAPS, gaussian_norms, gaussian_weights
from .samples import camera_arguments, mirror_points

__all__ = ["SeenEmission", "seen_emission", "skip_reason"]

#: Relative spread of the emission over a pixel's corners beyond which the
#: pixel is controlled (a smooth environment varies by less across a pixel).
_SPREAD = 1e-2
#: Samples per controlled pixel: at most this many, at least
#: :data:`_FEWEST`, fewer where many pixels are controlled (their rays at
#: most :data:`_BUDGET` times the image's pixels, or one batch of rays).
_MOST = 256
_FEWEST = 64
_BUDGET = 8
#: Samples per pixel that sees a mirror: at most this many, their rays at
#: most :data:`_MIRROR_BUDGET` times the image's pixels.
_MIRROR_MOST = 1024
_MIRROR_BUDGET = 256
#: A controlled pixel whose first samples saw emission fewer than this many
#: times (but some) takes :data:`_FEW_MOST` samples: its mean rests on those
#: few, a glint of a bright sky through a gap erring by about its own size,
#: and the frames replace what the pixel sees by it. Their rays are at most
#: :data:`_FEW_BUDGET` times the image's pixels.
_FEW_HITS = 16
_FEW_MOST = 1024
_FEW_BUDGET = 16
#: Camera rays per kernel call (bounds the temporary arrays).
_BATCH = 1 << 18


@dataclass
class SeenEmission:
    """The pixels whose footprint sees emission unevenly, and the emission
    each sees on average.

    Attributes
    ----------
    pixels : (T,) int64
        Row-major indices of the pixels controlled.
    mean : (T, 3) float32
        Their mean seen emission: emitted radiance (times what the sheets
        before it let through; the environment's radiance where a ray leaves
        the scene) over their footprints, through the camera's pixel filter
        (the mean of the filtered frames, which take samples from the pixels
        within its reach).
    sampled : int
        Pixels whose footprints were sampled (``T`` with the box filter).
    samples : int
        Camera rays per controlled pixel.
    rays : int
        Camera rays traced in all (the corners' included).
    seconds : float
    mirrored : int
        Of the pixels sampled, those that see a mirror.
    mirror_samples : int
        Camera rays per pixel that sees a mirror (with the box filter).
    few : int
        Of the pixels sampled, those whose first samples saw emission only
        a few times, and took more (with the box filter).
    variance : (T, 3) float32 or None
        The estimated squared error of each mean: its squared gap to the
        mean of the first half of its samples. That is the error of the
        mean itself where the samples converge as independent ones do (a
        mirror's lobe), and more where their stratification makes them
        converge faster (an outline). Every frame shares the mean's error,
        which the frames' own error estimate cannot see. None with the
        Gaussian filter (not worked out).
    """

    pixels: np.ndarray
    mean: np.ndarray
    sampled: int
    samples: int
    rays: int
    seconds: float
    mirrored: int = 0
    mirror_samples: int = 0
    few: int = 0
    variance: np.ndarray | None = None


def skip_reason(cam, emits: bool, env) -> str | None:
    """Why the control variate does not apply to this camera and scene (None: it does)."""
    if not emits and env is None:
        return "seen emission: no emitter or environment for the camera to see"
    if cam.aperture > 0:
        return "seen emission: a lens aperture spreads it over the lens as well (not controlled)"
    return None


def _seen(ctx: dict, pixels: np.ndarray, samples: np.ndarray) -> np.ndarray:
    """(M, K, 3) float32 emission seen by ``samples`` (K, 4) through ``pixels``
    (``ctx``: the arguments :func:`seen_emission` gathers)."""
    le, wo, prim, through = _core.camera_emission(
        *ctx["camera"],
        pixels,
        samples,
        *ctx["triangles"],
        ctx["scene"],
        threads=ctx["threads"],
        **ctx["mirrors"],
    )
    env = ctx["env"]
    if env is not None:
        miss = np.flatnonzero(prim < 0)
        le[miss] = env.eval(-wo[miss].astype(np.float64))
    if through is not None:
        le *= through
    return le.reshape(len(pixels), len(samples), 3)


def _batches(n: int, per: int):
    step = max(1, _BATCH // per)
    for a in range(0, n, step):
        yield slice(a, min(n, a + step))


def _grow(mask: np.ndarray, r: int) -> np.ndarray:
    """``mask`` (H, W) grown by ``r`` pixels (a square neighbourhood)."""
    for _ in range(r):
        step = mask.copy()
        step[1:] |= mask[:-1]
        step[:-1] |= mask[1:]
        rows = step.copy()
        step[:, 1:] |= rows[:, :-1]
        step[:, :-1] |= rows[:, 1:]
        mask = step
    return mask


def _uneven_pixels(ctx: dict, width: int, height: int) -> np.ndarray:
    """(H, W) bool: pixels whose four corners see different emission, and
    their neighbours (a straight outline that only clips a corner crosses
    the corners of a pixel next to it)."""
    P = width * height
    corner = np.zeros((1, 4))  # every pixel's top-left corner
    v = np.empty(P, np.float32)
    every = np.arange(P, dtype=np.int64)
    for s in _batches(P, 1):
        v[s] = _seen(ctx, every[s], corner)[:, 0].sum(axis=1)
    # the corners past the last row and column: the last ones repeated
    grid = np.pad(v.reshape(height, width), ((0, 1), (0, 1)), mode="edge")
    quad = (grid[:-1, :-1], grid[:-1, 1:], grid[1:, :-1], grid[1:, 1:])
    hi, lo = np.maximum.reduce(quad), np.minimum.reduce(quad)
    return _grow(hi - lo > _SPREAD * hi, 1)


def _mirror_pixels(ctx: dict, width: int, height: int) -> np.ndarray:
    """(H, W) bool: pixels one of whose four corners' rays first meets a mirror."""
    P = width * height
    corner = np.zeros((1, 4))
    obj = ctx["triangles"][3]
    mirror = ctx["mirrors"]["obj_mirror"].astype(bool)
    seen = np.zeros(P, bool)
    every = np.arange(P, dtype=np.int64)
    for s in _batches(P, 1):
        _, _, prim, _ = _core.camera_emission(
            *ctx["camera"],
            every[s],
            corner,
            *ctx["triangles"],
            ctx["scene"],
            threads=ctx["threads"],
        )
        seen[s] = (prim >= 0) & mirror[obj[np.maximum(prim, 0)]]
    grid = np.pad(seen.reshape(height, width), ((0, 1), (0, 1)), mode="edge")
    return grid[:-1, :-1] | grid[:-1, 1:] | grid[1:, :-1] | grid[1:, 1:]


def _footprint_samples(count: int, seed: int, mirrors: bool = False) -> np.ndarray:
    """(count, 4) sub-pixel offsets of a scrambled (0, 2)-sequence (count a
    power of two: one in each cell of every elementary grid of that area),
    the lens at its centre; with ``mirrors`` (count, 6), the numbers of the
    first mirror link following (:func:`~voxgi.display.samples.mirror_points`)."""
    rng = np.random.default_rng([int(seed), 0x5EE1])
    scramble = rng.integers(0, 1 << 32, size=2, dtype=np.uint64).astype(np.uint32)
    out = np.zeros((count, 6 if mirrors else 4))
    out[:, :2] = (sobol(np.arange(count), 2) ^ scramble) / 2.0**32
    if mirrors:
        out[:, 4:] = mirror_points(np.arange(count), seed)
    return out


def seen_emission(
    cam, tracer, triangles: tuple, env, seed: int, threads: int, mirrors: dict | None = None
) -> SeenEmission:
    """The controlled pixels of ``cam``'s image and their mean seen emission.

    Parameters
    ----------
    cam : Camera
    tracer : voxgi.rays.Tracer
        The scene's tracer (its Embree scene and centre).
    triangles : tuple
        The scene tables of :func:`voxgi._core.camera_hits` (``tri_v`` to
        ``obj_emission``), in the tracer's frame.
    env : Environment or None
        Seen where a ray leaves the scene.
    seed : int
        Scrambles the footprint samples.
    threads : int
    mirrors : dict or None
        The mirrors' arguments of :func:`voxgi._core.camera_emission`
        (``obj_mirror``, ``obj_lobe``, ``mirror_seed``, ``eps``): the samples
        go on through smooth mirrors as the frames' camera rays do.
    """
    t0 = time.perf_counter()
    ctx = {
        "camera": camera_arguments(cam, tracer.centre),
        "triangles": triangles,
        "scene": tracer.native,
        "env": env,
        "threads": threads,
        "mirrors": mirrors or {},
    }
    P = cam.width * cam.height
    # Through a filter of reach r a pixel is made of the samples within r of
    # it, each weighted by the frame's offset: the pixels within r of an
    # uneven one are controlled, from the samples within 2r.
    reach = _FILTER_REACH[cam.pixel_filter]
    uneven = _uneven_pixels(ctx, cam.width, cam.height)
    mirrored = np.zeros_like(uneven)
    if mirrors:
        # what a mirror shows is spread by its lobe beyond the pixel's
        # footprint: every pixel that sees a mirror is controlled
        mirrored = _grow(_mirror_pixels(ctx, cam.width, cam.height), 1)
        uneven |= mirrored
    target = np.flatnonzero(_grow(uneven, reach).ravel()).astype(np.int64)
    sampled = np.flatnonzero(_grow(uneven, 2 * reach).ravel()).astype(np.int64)
    M = len(sampled)
    # the mirrored pixels take more samples below; the others share the budget
    plain = M - int(np.count_nonzero(mirrored.ravel()[sampled]))
    per = _MOST
    if M:
        per = 1 << math.floor(math.log2(max(1.0, max(_BUDGET * P, _BATCH) / max(1, plain))))
        per = int(min(_MOST, max(_FEWEST, per)))
    samples = _footprint_samples(per, seed, bool(mirrors))
    rays = P + M * per
    extra = n_few = 0
    variance = None
    if reach:
        mean = _gaussian_mean(ctx, cam, sampled, target, samples)
    else:
        # the mean of each pixel's samples and that of their first half
        moments = (np.zeros((M, 3)), np.zeros((M, 3)))
        hits = np.zeros(M, np.int64)
        for s in _batches(M, per):
            le = _seen(ctx, sampled[s], samples).astype(np.float64)
            moments[0][s] = le.mean(axis=1)
            moments[1][s] = le[:, : per // 2].mean(axis=1)
            hits[s] = np.count_nonzero(le.max(axis=2) > 0, axis=1)
        on_mirror = mirrored.ravel()[sampled]
        if mirrors:
            extra = _mirror_means(ctx, sampled, on_mirror, moments, per, seed)
            rays += extra
        few = (hits > 0) & (hits < _FEW_HITS) & ~on_mirror
        n_few = int(np.count_nonzero(few))
        rays += _refine(ctx, sampled, few, moments, per, seed, _FEW_MOST, _FEW_BUDGET)
        mean, half = moments
        variance = ((half - mean) ** 2).astype(np.float32)
        mean = mean.astype(np.float32)
    n_mirrored = int(np.count_nonzero(mirrored.ravel()[sampled])) if M else 0
    return SeenEmission(
        target,
        mean,
        M,
        per,
        rays,
        time.perf_counter() - t0,
        n_mirrored,
        per + (extra // n_mirrored if n_mirrored and not reach else 0),
        n_few,
        variance,
    )


def _mirror_means(ctx, sampled, mirrored, moments, per: int, seed: int) -> int:
    """Refine ``moments`` (:func:`_refine`) in place at the ``mirrored``
    pixels (bool, one per ``sampled`` pixel) with more samples:
    :data:`_MIRROR_MOST`, fewer (a power of two) where their rays would
    pass :data:`_MIRROR_BUDGET` a pixel of the image. A mirror's lobe
    spreads a window or a lamp over many pixels, in part through its lobe's
    rare wide directions that a few samples miss, and the frames replace
    what each pixel sees by this mean: its error stays in the picture.
    Returns the rays traced."""
    return _refine(ctx, sampled, mirrored, moments, per, seed, _MIRROR_MOST, _MIRROR_BUDGET)


def _refine(ctx, sampled, which, moments, per: int, seed: int, most: int, budget: int) -> int:
    """Refine ``moments`` (the mean of each ``sampled`` pixel's samples and
    of their first half) in place at the pixels ``which`` (bool, one per
    ``sampled`` pixel) to ``most`` footprint samples, fewer (a power of
    two) where their rays would pass ``budget`` a pixel of the image; the
    first ``per`` of them are those already taken. Returns the rays traced."""
    idx = np.flatnonzero(which)
    if len(idx) == 0:
        return 0
    P = ctx["camera"][5] * ctx["camera"][6]
    K = min(most, 1 << math.floor(math.log2(max(1.0, budget * P / len(idx)))))
    if K <= per:
        return 0
    extra = _footprint_samples(K, seed, bool(ctx["mirrors"]))[per:]
    mean, half = moments
    for s in _batches(len(idx), len(extra)):
        q = idx[s]
        le = _seen(ctx, sampled[q], extra).astype(np.float64)
        half[q] = (mean[q] * per + le[:, : K // 2 - per].sum(axis=1)) / (K // 2)
        mean[q] = (mean[q] * per + le.sum(axis=1)) / K
    return len(idx) * len(extra)


def _gaussian_mean(ctx: dict, cam, sampled: np.ndarray, target: np.ndarray, samples):
    """(T, 3) float32: the Gaussian-filtered seen emission of the ``target``
    pixels, averaged over the footprint samples; each frame weights a sample
    at its offset into the pixels around it and divides each pixel by the
    weights it received (:func:`~voxgi.display.pixel_filter.gaussian_pixel_filter`),
    so the mean is taken over filtered frames. ``sampled`` holds every
    pixel within the filter's reach of a target pixel."""
    W, H = cam.width, cam.height
    K = len(samples)
    wx = np.array([gaussian_weights(o) for o in samples[:, 0]])  # (K, taps)
    wy = np.array([gaussian_weights(o) for o in samples[:, 1]])
    nx = np.array([gaussian_norms(o, W) for o in samples[:, 0]])  # (K, W)
    ny = np.array([gaussian_norms(o, H) for o in samples[:, 1]])
    out = np.zeros((H * W, 3))
    for s in _batches(len(sampled), K):
        q = sampled[s]
        le = _seen(ctx, q, samples).astype(np.float64)  # (m, K, 3)
        qi, qj = q // W, q % W
        for a, ty in enumerate(GAUSSIAN_TAPS):
            for b, tx in enumerate(GAUSSIAN_TAPS):
                # the output pixel p = q - t takes the sample of pixel q
                pi, pj = qi - ty, qj - tx
                inside = (pi >= 0) & (pi < H) & (pj >= 0) & (pj < W)
                if not inside.any():
                    continue
                pi, pj = pi[inside], pj[inside]
                coef = (wy[:, a] * wx[:, b])[None, :] / (ny[:, pi].T * nx[:, pj].T)
                np.add.at(out, pi * W + pj, np.einsum("mk,mkc->mc", coef, le[inside]) / K)
    return out[target].astype(np.float32)
