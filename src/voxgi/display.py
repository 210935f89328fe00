"""Anti-aliased display: progressive VPL ray tracing of a voxel solution.

The camera rays are traced with Embree (embreex); every record of the voxel
solution is a potential virtual point light (VPL); each progressive frame
shades every pixel with a few VPLs, drawn in proportion to power, one
independent set for each of 16 interleaved pixel groups, and with one
sub-pixel offset and one lens sample shared by all pixels (Piwowar &
Malgouyres, section 6; ``docs/design.md`` §6). Only this phase
depends on the camera: a new view of a solved scene costs only the display.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Protocol

import numpy as np

from . import _core, _validate
from ._qmc import sobol
from .lights import LUMINANCE
from .radiosity import Solution
from .rays import Tracer
from .scene import Camera, Scene
from .traced import record_grid
from .voxels import available_memory

__all__ = [
    "FrameExecutor",
    "FrameShaderSpec",
    "LocalFrames",
    "RenderResult",
    "RenderTuning",
    "VPLSampler",
    "camera_rays",
    "frame_samples",
    "frame_surface",
    "gaussian_pixel_filter",
    "light_spread",
    "ray_budget",
    "render",
]

#: What the VPL kernels read of a pixel's primary hit.
_HIT_KEYS = ("pos", "normal", "ng", "wo", "material")
_VPL_KEYS = ("pos", "normal", "weight", "area", "pa")


def _vpl_slice(vpls: dict, a: int, b: int | None) -> dict:
    """VPLs ``a:b`` of one group's frame set (emitters first, then the rest)."""
    return {k: v[a:b] for k, v in vpls.items()}


#: relMSE's epsilon (voxgi.metrics.rel_mse), used by the stopping rule too.
_REL_EPS = 0.01

#: Default :attr:`RenderTuning.pixel_factor` (``docs/design.md`` §6).
PIXEL_FACTOR = 10.0
#: Default :attr:`RenderTuning.pixel_share`: a single pixel (a sliver of a
#: bright light at a pixel's edge, a rare spike) cannot hold a large image
#: back, a region of them can.
PIXEL_SHARE = 1e-3


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
        Per-pixel standard error estimate of ``image`` (radiance units), from
        batch means of the frames with a heavy-tail guard (``docs/design.md``
        §6); None with fewer than two frames.
    stats : dict
        ``seconds`` per phase, ray counts, VPLs used, what was skipped. The
        phases: ``setup``; ``primary`` (camera rays and their hits);
        ``shadow`` (the VPLs' light: shadow rays and the shading of the VPLs
        they find); ``gather`` (gather rays and the shading of their hits);
        ``shade`` only where the VPLs are shaded apart from their shadow rays
        (the embreex path, ``docs/design.md`` §6); ``filter`` where the
        indirect light is filtered; ``total`` and ``display``
        (the same), plus ``voxelize`` and ``solve`` when :func:`voxgi.render`
        ran them. The error estimate: ``est_rel_mse`` (the image's relMSE,
        what ``tol`` bounds), ``est_max_rel_err`` and ``est_tail_rel_err``
        (per-pixel relative errors), ``flagged_pixels`` (heavy-tailed pixels
        the guard does not believe) and ``edge_pixels`` (pixels whose camera
        rays met more than one surface; None when frames came without their
        surfaces), ``docs/design.md`` §6.
    solution : Solution or None
        The voxel solution displayed (computed here when none was given).
    """

    image: np.ndarray
    frames: int = 0
    stderr: np.ndarray | None = None
    stats: dict = field(default_factory=dict)
    solution: object = None


# --------------------------------------------------------------------------
# Ray tracing with Embree (embreex)
# --------------------------------------------------------------------------
class _Tracer(Tracer):
    """The scene's tracer with the per-triangle data shading needs: object,
    winding normal and corner normals, in float64 (scene-centred frame)."""

    def __init__(self, scene: Scene, threads: int):
        super().__init__(scene, threads)
        self.obj = scene.triangles()["object"]  # (F,) int32
        e1 = self.tris[:, 1] - self.tris[:, 0]
        e2 = self.tris[:, 2] - self.tris[:, 0]
        n = np.cross(e1, e2)
        # winding normals (docs/design.md §2)
        self.ng = n / np.linalg.norm(n, axis=1, keepdims=True)
        # Per-corner shading normals where an object's mesh carried them.
        self.vn = None
        if any(o.vertex_normals is not None for o in scene.objects):
            parts = []
            for o in scene.objects:
                if o.vertex_normals is not None:
                    vn = o.vertex_normals[o.faces]
                    vn = vn / np.maximum(np.linalg.norm(vn, axis=2, keepdims=True), 1e-300)
                else:
                    t = o.vertices[o.faces]
                    g = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
                    g /= np.linalg.norm(g, axis=1, keepdims=True)
                    vn = np.repeat(g[:, None, :], 3, axis=1)
                parts.append(vn)
            self.vn = np.concatenate(parts)

    def occluded(self, org: np.ndarray, dirs: np.ndarray, length: np.ndarray) -> np.ndarray:
        """(R,) uint8: 1 where something lies on the segment [org, org + length·dir)."""
        if self.native is not None:
            return self.native.occluded(org, dirs, length, self.threads)
        return (super().occluded(org, dirs, length) != -1).astype(np.uint8)


# --------------------------------------------------------------------------
# Camera
# --------------------------------------------------------------------------
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


def frame_surface(hits: dict) -> tuple[np.ndarray, np.ndarray]:
    """What each pixel's camera ray met in one frame: the object (-1: nothing,
    or a one-sided back) and its geometric normal, all the error estimate's
    edge test needs (``docs/design.md`` §6). The hits' own arrays, not
    copies; a distributed frame sends the normals in half precision.

    Returns
    -------
    object : (P,) int32
    normal : (P, 3) float32 or float16
    """
    return hits["material"], hits["ng"]


def camera_rays(cam: Camera, offset=(0.5, 0.5), lens=(0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Primary rays of every pixel, row-major from the top-left pixel.

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
    right, up, fwd = cam.frame()
    eye = np.asarray(cam.eye, dtype=np.float64)
    th = math.tan(math.radians(cam.fov) / 2.0)
    aspect = cam.width / cam.height
    sx = (2.0 * (np.arange(cam.width) + offset[0]) / cam.width - 1.0) * th * aspect
    sy = (1.0 - 2.0 * (np.arange(cam.height) + offset[1]) / cam.height) * th
    d = (
        fwd[None, None, :]
        + sx[None, :, None] * right[None, None, :]
        + sy[:, None, None] * up[None, None, :]
    ).reshape(-1, 3)
    if cam.aperture > 0.0:
        lo = eye + cam.aperture * (lens[0] * right + lens[1] * up)
        d = eye + cam.focus * d - lo  # d·fwd = 1, so eye + focus·d lies on the focal plane
        org = np.broadcast_to(lo, d.shape)
    else:
        org = np.broadcast_to(eye, d.shape)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.ascontiguousarray(org), d


# --------------------------------------------------------------------------
# VPLs
# --------------------------------------------------------------------------
#: Pixels from a sample's own to the farthest pixel a reconstruction filter
#: weights it into (``Camera.pixel_filter``).
_FILTER_REACH = {"box": 0, "gaussian": 2}


def gaussian_pixel_filter(frame: np.ndarray, width: int, height: int, offset) -> np.ndarray:
    """One frame's samples, taken at ``offset`` in every pixel, weighted into
    the pixels around them by Mitsuba 3's Gaussian reconstruction filter.

    The filter is separable, ``w(x) = max(0, exp(-x²/2σ²) - exp(-r²/2σ²))``
    with σ = 0.5 pixel and r = 4σ, ``x`` the distance from the sample to a
    pixel's centre; each pixel is normalised by the weights it received, so
    the image edge needs no samples outside it (``docs/design.md`` §6).

    Parameters
    ----------
    frame : (H*W, C) array
        The frame, row-major pixels.
    width, height : int
    offset : (2,) float
        The frame's sub-pixel sample position (x right, y down) in [0, 1)².

    Returns
    -------
    (H*W, C) float32
    """
    sigma = 0.5
    radius = 4 * sigma
    reach = _FILTER_REACH["gaussian"]
    taps = np.arange(-reach, reach + 1)  # sample pixel minus output pixel, within the radius

    def weights(o: float) -> np.ndarray:
        x = taps + o - 0.5
        w = np.exp(-(x * x) / (2 * sigma**2)) - math.exp(-(radius**2) / (2 * sigma**2))
        return np.where(np.abs(x) < radius, np.maximum(w, 0.0), 0.0)

    def along(img: np.ndarray, w: np.ndarray, axis: int) -> np.ndarray:
        n = img.shape[axis]
        out = np.zeros_like(img)
        for t, wt in zip(taps, w, strict=True):
            if wt == 0.0:
                continue
            # the output pixel i takes the sample of pixel i + t
            dst = [slice(None)] * img.ndim
            src = [slice(None)] * img.ndim
            dst[axis] = slice(max(0, -t), min(n, n - t))
            src[axis] = slice(max(0, t), min(n, n + t))
            out[tuple(dst)] += wt * img[tuple(src)]
        return out

    c = frame.shape[1]
    img = np.concatenate(
        [frame.reshape(height, width, c).astype(np.float64), np.ones((height, width, 1))], axis=2
    )
    wx, wy = weights(float(offset[0])), weights(float(offset[1]))
    img = along(along(img, wx, 1), wy, 0)
    return (img[..., :c] / img[..., c:]).reshape(-1, c).astype(np.float32)


def _morton(ijk: np.ndarray) -> np.ndarray:
    """30-bit interleaved (Morton) keys of voxel coordinates (10 bits each)."""

    def spread(v):
        v = (v.astype(np.int64) - v.min()) & 0x3FF
        v = (v | (v << 16)) & 0x030000FF
        v = (v | (v << 8)) & 0x0300F00F
        v = (v | (v << 4)) & 0x030C30C3
        v = (v | (v << 2)) & 0x09249249
        return v

    return spread(ijk[:, 0]) | (spread(ijk[:, 1]) << 1) | (spread(ijk[:, 2]) << 2)


class VPLSampler:
    """The fixed VPL sequence of a solution: two sets, emitters and the rest.

    As in the paper, records are drawn from a cumulative table by binary
    search, with replacement, in two sets (emitters and non-emitters), each
    set with its own count per frame. Records with zero radiosity (black back
    records above all) can send no light and are left out of the table; that
    changes no expectation.

    ``pdf="power"`` (the default) draws a record with probability
    proportional to its power ``ΔA · B`` (luminance) instead of its area
    (``pdf="area"``, the paper's choice): the estimator weight is then
    ``B / (π n p(y))`` with the area density ``p(y) = lum(B_y) / Σ ΔA lum(B)``,
    so every VPL carries the same power. With area sampling a few bright
    records (on the Cornell box, those on top of the tall block, B ≈ 11× the
    mean) are drawn in one frame of several and then light a wall alone: a
    heavy-tailed error that the between-frame spread underestimates.

    Each frame draws its ``n_d`` emitter and ``n_i`` other VPLs stratified
    along the cumulative table, whose records are in Morton (Z-curve) order:
    every draw still has its probability, but a frame's VPLs are spread over
    the surfaces instead of clumped. Frames draw their VPLs independently;
    the render estimates the error of their mean from batch means of frames
    (``docs/design.md`` §6).

    The split: ``n_d / K = Φ_d / (Φ_d + Φ_i)`` with Φ the power
    ``Σ ΔA · B`` (luminance) of each set, at least one VPL for a set with
    power; with equal relative spread per VPL this is the Neyman allocation
    (samples ∝ each set's standard deviation, which scales with its power).
    ``emitter_share`` overrides it.

    Parameters
    ----------
    sol : Solution
    vpls_per_frame : int
    seed : int
    emitter_share : float in [0, 1] or None
    mis : bool
        The VPLs of both sets are combined with gather rays (their weight is
        then ``B/π`` and ``pa`` carries ``n p(y)`` of their set).
    pdf : {"power", "area"}
    on_surface : bool
        Each VPL of a frame sits at a point drawn uniformly on its record's
        own surface (``docs/design.md`` §6) instead of at the
        record's fixed centroid.
    """

    def __init__(
        self,
        sol,
        vpls_per_frame: int = 16,
        seed: int = 0,
        emitter_share: float | None = None,
        mis: bool = False,
        pdf: str = "power",
        on_surface: bool = True,
    ):
        if pdf not in ("power", "area"):
            raise ValueError(f"pdf: expected 'power' or 'area', got {pdf!r}")
        vox = sol.vox
        n = len(vox)
        B = _validate.as_c_array(sol.radiosity, np.float64, (n, 3), "sol.radiosity")
        area = _validate.as_c_array(vox.area, np.float64, (n,), "vox.area")
        if np.any(B < 0) or np.any(area < 0):
            raise ValueError("sol.radiosity and vox.area must be >= 0")
        back = np.asarray(vox.back, dtype=bool) if vox.back is not None else np.zeros(n, bool)
        emit = np.any(np.asarray(vox.emission) > 0, axis=1) & ~back
        useful = ~back & (area > 0) & np.any(B > 0, axis=1)
        self.skipped_records = int(n - useful.sum())
        order = np.argsort(_morton(np.asarray(vox.ijk)), kind="stable")
        lum = B @ LUMINANCE
        self.pdf = pdf
        self.sets = []
        for sel in (useful & emit, useful & ~emit):
            idx = order[sel[order]]
            w = area[idx] * lum[idx] if pdf == "power" else area[idx]
            cum = np.cumsum(w)
            power = float(np.sum(area[idx] * lum[idx]))
            # Density per unit area of each record of the set: p(y) = w_y / (ΔA_y W).
            dens = np.zeros(n)
            if len(idx):
                dens[idx] = (lum[idx] if pdf == "power" else 1.0) / cum[-1]
            self.sets.append((idx, cum, power, dens))
        self.K = int(vpls_per_frame)
        (_, cum_d, pd, dens_d), (_, cum_i, pi, dens_i) = self.sets
        has_d, has_i = len(cum_d) > 0 and pd > 0, len(cum_i) > 0 and pi > 0
        if emitter_share is None:
            share = pd / (pd + pi) if (pd + pi) > 0 else 0.0
        else:
            share = float(emitter_share)
        if has_d and has_i and self.K >= 2:
            nd = int(np.clip(round(self.K * share), 1, self.K - 1))
        elif has_d:
            nd = self.K
        else:
            nd = 0
        if not has_i:
            nd = self.K if has_d else 0
        self.counts = (nd, self.K - nd if has_i else 0)
        self.seed = int(seed)
        self.mis = bool(mis) and sum(self.counts) > 0
        #: (N,) float32 n p(y) of every record in an MIS set (n its set's VPLs
        #: per frame, 0 elsewhere): the VPL side of the MIS weights, for VPLs
        #: and gather hits alike.
        pa = self.counts[0] * dens_d + self.counts[1] * dens_i if self.mis else np.zeros(n)
        self.record_pa = pa.astype(np.float32)
        self.pos = np.ascontiguousarray(vox.centroid, dtype=np.float64)
        self.normal = np.ascontiguousarray(vox.normal, dtype=np.float32)
        self.area32 = area.astype(np.float32)
        self.B = B
        self.vox = vox
        self.on_surface = bool(on_surface)

    @property
    def empty(self) -> bool:
        return sum(self.counts) == 0

    def frame(self, f: int, group: int = 0) -> dict:
        """The VPLs of frame ``f`` for the pixels of interleaving group
        ``group``: the same for every view."""
        rng = np.random.default_rng([self.seed, int(f), 0x1B1, *([int(group)] if group else [])])
        idx_all, w_all, pa_all = [], [], []
        for (idx, cum, _, dens), k in zip(self.sets, self.counts, strict=True):
            if k == 0:
                continue
            u = (np.arange(k) + rng.random(k)) / k * float(cum[-1])  # stratified along the table
            pick = idx[np.minimum(np.searchsorted(cum, u, side="right"), len(idx) - 1)]
            idx_all.append(pick)
            if self.mis:
                # An MIS VPL carries B/π; the kernel divides by n p(y) + the gather pdf.
                w_all.append(np.ones(k))
                pa_all.append(self.record_pa[pick])
            else:
                # E ≈ (1/n) Σ (B/π) G V / p(y): the estimator weight times the radiance.
                w_all.append(1.0 / (k * dens[pick]))
                pa_all.append(np.zeros(k, np.float32))
        idx = np.concatenate(idx_all)
        w = np.concatenate(w_all)
        return {
            "pa": np.ascontiguousarray(np.concatenate(pa_all), dtype=np.float32),
            "index": idx,
            "pos": np.ascontiguousarray(self.pos[idx]),
            "normal": np.ascontiguousarray(self.normal[idx]),
            "weight": np.ascontiguousarray((w[:, None] * self.B[idx] / math.pi).astype(np.float32)),
            "area": np.ascontiguousarray(self.area32[idx]),
        }


# --------------------------------------------------------------------------
# Shading of one frame
# --------------------------------------------------------------------------
def _stratified(rng, n: int, k: int) -> np.ndarray:
    """(n * k, 3) points of [0, 1)³, k per pixel and jittered in strata: the
    first coordinate (the environment's texel) in k strata, the other two
    (the direction inside it) in a √k x √k grid when k is a square. The first
    coordinate's strata are shuffled per pixel (Latin-hypercube pairing), so
    each point is uniform in the cube and the mean stays unbiased for any
    integrand, not only for one separable in the two groups."""
    u = rng.random((n, k, 3))
    i = np.arange(k)
    shuffled = np.argsort(rng.random((n, k)), axis=1)
    u[..., 0] = (shuffled + u[..., 0]) / k
    s = math.isqrt(k)
    if s * s == k and k > 1:
        u[..., 1] = (i % s + u[..., 1]) / s
        u[..., 2] = (i // s + u[..., 2]) / s
    return u.reshape(-1, 3)


class _FrameShader:
    """Everything a frame needs that does not change between frames."""

    def __init__(
        self,
        scene: Scene,
        cam: Camera,
        tracer: _Tracer,
        sampler: VPLSampler,
        eps: float,
        threads: int,
        gather: int = 0,
        seed: int = 0,
        indirect_filter: int = 0,
    ):
        self.scene, self.cam, self.tracer, self.sampler = scene, cam, tracer, sampler
        # the filter needs the two kinds of light apart; without any light of
        # non-emitting records there is nothing to filter
        self.indirect_filter = int(indirect_filter) if sampler.counts[1] > 0 else 0
        self.eps, self.threads = float(eps), int(threads)
        self.gather = int(gather) if sampler.mis else 0
        self.seed = int(seed)
        objs = scene.objects
        self.mat_albedo = np.array([o.material.albedo for o in objs], np.float32)
        self.mat_emission = np.array([o.material.emission for o in objs], np.float32)
        self.two_sided = np.array([o.two_sided for o in objs], bool)
        spec = [o.material.specular for o in objs]
        self.mat_glossy = np.array([s is not None for s in spec], np.uint8)
        self.mat_rs = np.array([s.rs if s else (0.0, 0.0, 0.0) for s in spec], np.float32)
        self.mat_nu = np.array([s.nu if s else 1.0 for s in spec], np.float32)
        self.mat_nv = np.array([s.nv if s else 1.0 for s in spec], np.float32)
        self.lights = list(scene.lights)
        self.env = scene.environment
        # environment samples per pixel and frame: as many as the gather rays
        # they are MIS-combined with (docs/design.md §11)
        self.n_env = max(1, self.gather) if self.env is not None else 0
        self.light_rays = 0
        self.tile = 1 << 16
        self._groups = self._pixel_groups(cam, self.INTERLEAVE)
        self._buffers = None
        self._gbuffers = None
        self.primary_rays = 0
        #: :func:`frame_surface` of the last frame
        self.surface: tuple[np.ndarray, np.ndarray] | None = None
        self.shadow_rays = 0
        self.gather_rays = 0
        # the VPLs' and gather rays' shading is timed with their rays; only
        # the embreex path, which shades apart from tracing, adds "shade"
        self.seconds = {"primary": 0.0, "shadow": 0.0, "gather": 0.0}
        if self.gather:
            self._grid = record_grid(
                sampler.vox, tracer.centre, sampler.B / math.pi, sampler.record_pa
            )
            self._tri = {
                "tri_v": tracer.tris,
                "tri_object": tracer.obj,
                "obj_two_sided": self.two_sided.astype(np.uint8),
            }

    def camera_hits(self, offset, lens) -> dict:
        """Primary hits of the camera rays through sub-pixel ``offset`` and
        lens point ``lens`` (:func:`camera_rays`): points in float64 on the
        hit triangle's plane, normals facing the viewer, material index (-1:
        miss or a one-sided back). The compiled tracer makes, traces and hits
        the rays in one kernel, without ray arrays; embreex's calls trace
        :func:`camera_rays`."""
        tr = self.tracer
        dirs = None
        if tr.native is None:
            org, dirs = camera_rays(self.cam, offset, lens)
            org = org - tr.centre
            prim = tr.intersect(org.astype(np.float32), dirs.astype(np.float32))
            pos, n_out, ng_out, mat, le = _core.primary_hits(
                org, dirs, prim, *self._primary_scene, threads=self.threads
            )
            wo = np.ascontiguousarray(-dirs, dtype=np.float32)
        else:
            cam = self.cam
            right, up, fwd = cam.frame()
            pos, n_out, ng_out, wo, mat, le, prim = _core.camera_hits(
                np.asarray(cam.eye, dtype=np.float64) - tr.centre,
                right,
                up,
                fwd,
                math.tan(math.radians(cam.fov) / 2.0),
                cam.width,
                cam.height,
                float(cam.aperture),
                float(cam.focus),
                (float(offset[0]), float(offset[1])),
                (float(lens[0]), float(lens[1])),
                *self._primary_scene,
                tr.native,
                threads=self.threads,
            )
        self.primary_rays += len(prim)
        if self.env is not None:
            # camera rays that leave the scene see the environment
            miss = np.flatnonzero(prim < 0)
            le[miss] = self.env.eval(-wo[miss].astype(np.float64) if dirs is None else dirs[miss])
        return {
            "pos": pos,
            "normal": n_out,
            "ng": ng_out,
            "wo": wo,
            "material": mat,
            "emission": le,
        }

    @cached_property
    def _primary_scene(self) -> tuple:
        """The triangle and object arrays of :func:`_core.primary_hits` and
        :func:`_core.camera_hits`."""
        tr = self.tracer
        return (
            np.ascontiguousarray(tr.tris, dtype=np.float64),
            np.ascontiguousarray(tr.ng, dtype=np.float64),
            None if tr.vn is None else np.ascontiguousarray(tr.vn, dtype=np.float64),
            np.ascontiguousarray(tr.obj, dtype=np.int32),
            self.two_sided.astype(np.uint8),
            np.ascontiguousarray(self.mat_emission, dtype=np.float32),
        )

    def shade(self, h: dict, vpls: list | None) -> np.ndarray:
        """(P, 3) float32 radiance: emission seen + VPL estimate of the reflected
        light, ``vpls[g]`` lighting the pixels of interleaving group g."""
        P = len(h["material"])
        out = h["emission"].astype(np.float32, copy=True)
        # the gather rays run only with VPLs to combine with
        has_vpls = vpls is not None and len(vpls[0]["index"]) > 0
        self._gathering = self.gather if has_vpls else 0
        if self.lights or self.env is not None:
            for a in range(0, P, self.tile):
                self._direct_lights(h, a, min(P, a + self.tile), out)
        if not has_vpls:
            return out
        # With the filter, the light of the non-emitting records' VPLs and of
        # all the gather rays is kept apart, filtered and then added. A gather
        # ray finds an emitter or another record, never both, so the two
        # kinds of its light err in opposite directions: they are filtered
        # together, or the cancellation between them is lost. The emitters'
        # VPLs, which carry the sharp shadows, are never filtered.
        reflected = np.zeros_like(out) if self.indirect_filter else None
        nd = self.sampler.counts[0]
        parts = [(vpls, out)]
        if reflected is not None:
            parts = [
                ([_vpl_slice(v, 0, nd) for v in vpls], out),
                ([_vpl_slice(v, nd, None) for v in vpls], reflected),
            ]
        for part, into in parts:
            if len(part[0]["index"]) == 0:
                continue
            if self.tracer.native is not None:
                into += self._vpl_light_traced(h, part)
            elif len(part) == 1:
                into += self._vpl_light(h, part, self._groups[1])
            else:  # the hits sorted by group, so that each group is a slice
                perm, cuts = self._groups
                into[perm] += self._vpl_light({k: h[k][perm] for k in _HIT_KEYS}, part, cuts)
        if self.gather:
            for a in range(0, P, self.tile):
                b = min(P, a + self.tile)
                self._gather(h, a, b, out if reflected is None else reflected)
        if reflected is not None:
            self._filter(h, reflected, out)
        return out

    def _filter(self, h: dict, reflected: np.ndarray, out: np.ndarray) -> None:
        """Add the non-emitting records' light, filtered over the pixels that
        see the same smooth surface (``docs/design.md`` §6)."""
        t0 = time.perf_counter()
        cam = self.cam
        _core.geometry_filter(
            h["pos"],
            h["normal"],
            h["material"],
            self.mat_glossy,
            np.asarray(cam.eye, np.float64) - self.tracer.centre,
            2.0 * math.tan(math.radians(cam.fov) / 2.0) / cam.height,
            cam.width,
            cam.height,
            self.indirect_filter,
            reflected,
            out,
            threads=self.threads,
        )
        self.seconds["filter"] = self.seconds.get("filter", 0.0) + time.perf_counter() - t0

    def _vpl_light(self, h: dict, vpls: list, cuts: np.ndarray) -> np.ndarray:
        """(P, 3) float32: the VPLs' light at the hits ``h``, ``vpls[g]``
        lighting the hits ``cuts[g]:cuts[g + 1]``. Each tile of hits makes
        its shadow rays group by group and traces them in one batch: Embree's
        worker threads spin for a while after a batch, and a kernel started
        in that time runs on a shared core."""
        P = len(h["material"])
        out = np.zeros((P, 3), np.float32)
        K = max(len(v["index"]) for v in vpls)
        cap = min(P, self.tile) * K
        if self._buffers is None or len(self._buffers[1]) < cap:
            # Reused by every frame: fresh pages for ~40 bytes x P x K rays
            # each frame cost as much as the shading itself.
            self._buffers = (
                np.zeros(self.tile, np.int64),
                np.zeros((cap, 3), np.float32),
                np.zeros((cap, 3), np.float32),
                np.zeros(cap, np.float32),
                np.zeros((cap, 3), np.float32),
            )
        cnt_buf, org_buf, dir_buf, len_buf, con_buf = self._buffers
        for a in range(0, P, self.tile):
            b = min(P, a + self.tile)
            t0 = time.perf_counter()
            n = 0
            for g, vpl in enumerate(vpls):
                lo, hi = max(a, int(cuts[g])), min(b, int(cuts[g + 1]))
                if lo >= hi:
                    continue
                n += _core.vpl_prepare(
                    h["pos"][lo:hi],
                    h["normal"][lo:hi],
                    h["ng"][lo:hi],
                    h["wo"][lo:hi],
                    h["material"][lo:hi],
                    self.mat_albedo,
                    self.mat_rs,
                    self.mat_nu,
                    self.mat_nv,
                    self.mat_glossy,
                    vpl["pos"],
                    vpl["normal"],
                    vpl["weight"],
                    vpl["area"],
                    vpl["pa"],
                    float(self.gather),
                    self.eps,
                    cnt_buf[lo - a : hi - a],
                    org_buf[n:],
                    dir_buf[n:],
                    len_buf[n:],
                    con_buf[n:],
                    self.threads,
                )
            org, dirs, length, contrib = org_buf[:n], dir_buf[:n], len_buf[:n], con_buf[:n]
            t1 = time.perf_counter()
            occ = self.tracer.occluded(org, dirs, length)
            t2 = time.perf_counter()
            out[a:b] += _core.vpl_accumulate(cnt_buf[: b - a], contrib, occ, self.threads)
            t3 = time.perf_counter()
            self.shadow_rays += len(occ)
            self.seconds["shade"] = self.seconds.get("shade", 0.0) + (t1 - t0) + (t3 - t2)
            self.seconds["shadow"] += t2 - t1
        return out

    def _vpl_light_traced(self, h: dict, vpls: list) -> np.ndarray:
        """:meth:`_vpl_light` in one compiled call, each pixel lit by its
        group's VPLs and its shadow rays traced as they are made: the same
        sums."""
        t0 = time.perf_counter()
        cat = [np.concatenate([v[k] for v in vpls]) for k in _VPL_KEYS]
        start = np.cumsum([0] + [len(v["index"]) for v in vpls]).astype(np.int64)
        sets = len(vpls) > 1
        out, rays = _core.vpl_light(
            *(h[k] for k in _HIT_KEYS),
            *self._materials(),
            *cat,
            float(self.gather),
            self.eps,
            self.tracer.native,
            self._pixel_set if sets else None,
            start if sets else None,
            self.threads,
        )
        self.shadow_rays += rays
        self.seconds["shadow"] += time.perf_counter() - t0
        return out

    @cached_property
    def _pixel_set(self) -> np.ndarray:
        """(P,) int32 interleaving group of each pixel, in row-major order."""
        perm, cuts = self._groups
        return np.repeat(np.arange(len(cuts) - 1, dtype=np.int32), np.diff(cuts))[np.argsort(perm)]

    def _light_sum(self, hh, count, dirs, weight, occluded, out) -> None:
        """Add into ``out`` each pixel's light rays: BRDF x cos x ``weight``
        along ``dirs`` (pixel-major, ``count`` a pixel), but the occluded."""
        _core.light_accumulate(
            hh["pos"],
            hh["normal"],
            hh["ng"],
            hh["wo"],
            hh["material"],
            *self._materials(),
            count,
            np.ascontiguousarray(dirs, np.float32),
            np.ascontiguousarray(weight, np.float32),
            occluded,
            out,
            self.threads,
        )

    def _materials(self) -> tuple:
        return self.mat_albedo, self.mat_rs, self.mat_nu, self.mat_nv, self.mat_glossy

    def _env_weight(self, dirs: np.ndarray, cos: np.ndarray) -> np.ndarray:
        """(R, 3) environment radiance over the balance heuristic's combined
        density of the environment samples and the gather rays,
        ``n_e p_e(ω) + n_g cos θ / π`` (docs/design.md §11)."""
        dens = self.n_env * self.env.pdf(dirs) + self._gathering * np.maximum(cos, 0.0) / math.pi
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(dens > 0, 1.0 / dens, 0.0)
        return self.env.eval(dirs) * inv[:, None]

    def _direct_lights(self, h: dict, a: int, b: int, out: np.ndarray) -> None:
        """Add the delta lights (one shadow ray each) and the environment
        samples of pixels [a, b) (docs/design.md §11)."""
        t0 = time.perf_counter()
        mat = h["material"][a:b]
        pix = np.flatnonzero(mat >= 0)
        if len(pix) == 0:
            return
        pos = h["pos"][a:b][pix]
        ng = h["ng"][a:b][pix].astype(np.float64)
        n = h["normal"][a:b][pix].astype(np.float64)
        org = pos + self.eps * ng
        world = pos + self.tracer.centre
        parts = []  # (pixel, direction, length, weight) per kind of ray
        for light in self.lights:
            w, dist, e = light.incident(world)
            length = np.where(np.isfinite(dist), np.maximum(dist - 2 * self.eps, 0.0), np.inf)
            parts.append((pix, w, length, e))
        if self.env is not None:
            k = self.n_env
            rng = np.random.default_rng([self.seed, self._frame, a, 0xE4F])
            w, _ = self.env.sample(_stratified(rng, len(pix), k))
            cos = np.einsum("ij,ij->i", w, np.repeat(n, k, axis=0))
            parts.append((np.repeat(pix, k), w, np.full(len(w), np.inf), self._env_weight(w, cos)))
        p_all = np.concatenate([q[0] for q in parts])
        order = np.argsort(p_all, kind="stable")  # pixel-major, as the kernel takes them
        w_all = np.concatenate([q[1] for q in parts])[order]
        len_all = np.concatenate([q[2] for q in parts])[order]
        wt_all = np.concatenate([q[3] for q in parts])[order]
        o_all = org[np.searchsorted(pix, p_all[order])]
        # only rays that can add light are traced
        cos_g = np.einsum("ij,ij->i", w_all, ng[np.searchsorted(pix, p_all[order])])
        live = (cos_g > 0) & np.any(wt_all > 0, axis=1)
        occ = np.ones(len(w_all), np.uint8)
        if np.any(live):
            occ[live] = self.tracer.occluded(
                np.ascontiguousarray(o_all[live], np.float32),
                np.ascontiguousarray(w_all[live], np.float32),
                np.ascontiguousarray(len_all[live], np.float32),
            )
        self.light_rays += int(np.count_nonzero(live))
        count = np.bincount(p_all, minlength=b - a).astype(np.int64)
        hh = {k: h[k][a:b] for k in _HIT_KEYS}
        self._light_sum(hh, count, w_all, wt_all, occ, out[a:b])
        self.seconds["lights"] = self.seconds.get("lights", 0.0) + time.perf_counter() - t0

    def _gather(self, h: dict, a: int, b: int, out: np.ndarray) -> None:
        """Add the gather rays' MIS-weighted share of the light into ``out[a:b]``."""
        t0 = time.perf_counter()
        if self.tracer.native is not None and self.env is None:
            # made, traced and shaded pixel by pixel (the escaping rays would
            # need the environment's MIS below)
            hh = [h[k][a:b] for k in _HIT_KEYS]
            self.gather_rays += _core.gather_light(
                *hh,
                *self._materials(),
                self.gather,
                self.seed,
                self._frame,
                self.eps,
                **self._tri,
                **self._grid,
                scene=self.tracer.native,
                out=out[a:b],
                threads=self.threads,
            )
            self.seconds["gather"] += time.perf_counter() - t0
            return
        cap = self.tile * self.gather
        if self._gbuffers is None:
            self._gbuffers = (
                np.zeros(self.tile, np.int64),
                np.zeros((cap, 3), np.float32),
                np.zeros((cap, 3), np.float32),
            )
        cnt_buf, org_buf, dir_buf = self._gbuffers
        count = cnt_buf[: b - a]
        hh = {k: h[k][a:b] for k in _HIT_KEYS}
        n = _core.gather_rays(
            hh["pos"],
            hh["normal"],
            hh["ng"],
            hh["wo"],
            hh["material"],
            self.gather,
            self.seed,
            self._frame,
            self.eps,
            count,
            org_buf,
            dir_buf,
            self.threads,
        )
        prim = self.tracer.intersect(org_buf[:n], dir_buf[:n])
        self.gather_rays += n
        _core.gather_shade(
            hh["pos"],
            hh["normal"],
            hh["ng"],
            hh["wo"],
            hh["material"],
            self.mat_albedo,
            self.mat_rs,
            self.mat_nu,
            self.mat_nv,
            self.mat_glossy,
            float(self.gather),
            **self._tri,
            **self._grid,
            ray_count=count,
            ray_dir=dir_buf[:n],
            prim=prim,
            out=out[a:b],
            threads=self.threads,
        )
        if self.env is not None:
            # gather rays that leave the scene see the environment, MIS-combined
            # with its samples (docs/design.md §11)
            pix = np.repeat(np.arange(b - a), count)
            esc = np.flatnonzero(prim < 0)
            w = dir_buf[:n][esc].astype(np.float64)
            cos = np.einsum("ij,ij->i", w, hh["normal"][pix[esc]].astype(np.float64))
            count = np.bincount(pix[esc], minlength=b - a).astype(np.int64)
            self._light_sum(hh, count, w, self._env_weight(w, cos), np.zeros(0, np.uint8), out[a:b])
        self.seconds["gather"] += time.perf_counter() - t0

    def frame(self, f: int, seed: int) -> np.ndarray:
        """(H*W, 3) radiance estimate of frame ``f``."""
        self._frame = int(f)
        offset, lens = frame_samples(f, seed)
        t0 = time.perf_counter()
        h = self.camera_hits(offset, lens)
        self.seconds["primary"] += time.perf_counter() - t0
        self.surface = frame_surface(h)
        vpls = None
        if not self.sampler.empty:
            vpls = [self.sampler.frame(f, g) for g in range(len(self._groups[1]) - 1)]
            # into the tracer's scene-centred frame; every group's VPLs placed at once
            pos = np.concatenate([v["pos"] for v in vpls]) - self.tracer.centre
            if self.sampler.on_surface:
                pos = self.place_vpls(np.concatenate([v["index"] for v in vpls]), pos, f)
            cuts = np.cumsum([0] + [len(v["index"]) for v in vpls])
            vpls = [
                {**v, "pos": np.ascontiguousarray(pos[a:b])}
                for v, a, b in zip(vpls, cuts[:-1], cuts[1:], strict=True)
            ]
        img = self.shade(h, vpls)
        if self.cam.pixel_filter == "gaussian":
            img = gaussian_pixel_filter(img, self.cam.width, self.cam.height, offset)
        return img

    #: Pixels take their VPLs from one of INTERLEAVE² sets per frame, by the
    #: pixel's row and column modulo INTERLEAVE (interleaved sampling).
    INTERLEAVE = 4

    @staticmethod
    def _pixel_groups(cam: Camera, n: int) -> tuple[np.ndarray, np.ndarray]:
        """The row-major pixel indices sorted by interleaving group, and where
        each group starts in them (one more entry, the end)."""
        rows, cols = np.divmod(np.arange(cam.height * cam.width), cam.width)
        key = (rows % n) * n + cols % n
        perm = np.argsort(key, kind="stable")
        cuts = np.searchsorted(key[perm], np.arange(n * n + 1))
        keep = np.concatenate([[True], np.diff(cuts) > 0])  # groups an image too small lacks
        return perm, cuts[keep]

    #: Candidate points per VPL and frame; each lands on the record's surface
    #: with probability about 1/3 for a flat record (its polygon against the
    #: square of side √3 pitch the candidates are drawn from).
    _PLACE_TRIES = 12

    def place_vpls(self, index: np.ndarray, centroid: np.ndarray, f: int) -> np.ndarray:
        """(K, 3) points drawn uniformly on each VPL's record surface (centred frame).

        A VPL fixed at its record's centroid makes the image converge to the
        lighting of a finite set of point lights: each casts a sharp shadow of
        every thin occluder, and the shadows line up into streaks. A point
        drawn anew each frame on the record's own surface converges to the
        area integral of the piecewise-constant radiosity instead
        (``docs/design.md`` §6). Candidates are drawn in a square of the
        record's tangent plane around the voxel, projected onto the scene's
        triangles along the normal, and kept when the hit is the record's own
        object, facing within 60° of its normal (the voxelization's clustering),
        inside its voxel, and in sight of the centroid (a record cut at a thin
        wall keeps to its own side). A record none of whose candidates lands
        keeps its centroid.
        """
        sampler, tr, T = self.sampler, self.tracer, self._PLACE_TRIES
        vox, K = sampler.vox, len(index)
        rng = np.random.default_rng([self.seed, int(f), 0x5EA])
        h = float(vox.pitch)
        n = sampler.normal[index].astype(np.float64)
        lo = np.asarray(vox.origin, np.float64) + np.asarray(vox.ijk, np.float64)[index] * h
        lo -= tr.centre
        mid = lo + 0.5 * h
        # The voxel centre projected onto the record's plane: the polygon lies
        # within √3/2 pitch of it.
        mid -= np.einsum("ij,ij->i", mid - centroid, n)[:, None] * n
        a = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        t1 = np.cross(n, a)
        t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
        t2 = np.cross(n, t1)
        uv = (rng.random((T, K, 2)) - 0.5) * (math.sqrt(3.0) * h)
        cand = mid + uv[..., :1] * t1 + uv[..., 1:] * t2 + h * n  # (T, K, 3)
        org = cand.reshape(-1, 3)
        dirs = np.broadcast_to(-n, (T, K, 3)).reshape(-1, 3)
        prim = tr.intersect(org.astype(np.float32), dirs.astype(np.float32))
        ok = prim >= 0
        tri = np.where(ok, prim, 0)
        ng = tr.ng[tri]
        dn = np.einsum("ij,ij->i", dirs, ng)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.einsum("ij,ij->i", tr.tris[tri, 0] - org, ng) / dn
        q = org + np.where(np.isfinite(t), t, 0.0)[:, None] * dirs
        obj = np.broadcast_to(np.asarray(vox.object_id)[index], (T, K)).reshape(-1)
        slack = 1e-6 * h
        inside = np.all((q >= np.repeat(lo[None], T, 0).reshape(-1, 3) - slack), axis=1) & np.all(
            (q <= np.repeat(lo[None], T, 0).reshape(-1, 3) + h + slack), axis=1
        )
        ok &= (tr.obj[tri] == obj) & (np.abs(dn) > 0.5) & inside
        # In sight of the centroid, both lifted by the shadow-ray offset.
        c = np.broadcast_to(centroid, (T, K, 3)).reshape(-1, 3) + self.eps * -dirs
        seg = q + self.eps * -dirs - c
        dist = np.linalg.norm(seg, axis=1)
        check = np.flatnonzero(ok & (dist > self.eps))
        if len(check):
            d = seg[check] / dist[check, None]
            blocked = tr.occluded(
                c[check].astype(np.float32), d.astype(np.float32), dist[check].astype(np.float32)
            )
            ok[check[blocked != 0]] = False
        ok = ok.reshape(T, K)
        first = np.argmax(ok, axis=0)
        found = ok[first, np.arange(K)]
        out = centroid.copy()
        out[found] = q.reshape(T, K, 3)[first[found], np.flatnonzero(found)]
        return out

    def close(self) -> None:
        """Release the tracer's threads."""
        self.tracer.close()


# --------------------------------------------------------------------------
# Frame sources: the spec of a frame shader and where it runs
# --------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class FrameShaderSpec:
    """What a frame shader is built from; picklable, so an executor can ship it.

    Frames are independent (each has its own VPLs, sub-pixel offset and
    gather-ray seed), so a shader built from the same spec anywhere returns
    the same frame ``f``.

    Attributes
    ----------
    scene : Scene
    camera : Camera
    sampler : VPLSampler
    eps : float
        Shadow-ray offset (scene units).
    gather : int
        Gather rays per pixel and frame for the non-emitter light (0: VPLs only).
    seed : int
    indirect_filter : int
        Radius in pixels of the geometry-aware filter of the non-emitting
        records' light (0: none; :attr:`RenderTuning.indirect_filter`).
    """

    scene: Scene
    camera: Camera
    sampler: VPLSampler
    eps: float
    gather: int
    seed: int
    indirect_filter: int = 0

    @property
    def gather_per_frame(self) -> int:
        """Gather rays per pixel and frame the shader will trace."""
        return int(self.gather) if self.sampler.mis else 0

    @property
    def glossy(self) -> bool:
        """Whether any material has a specular layer."""
        return any(o.material.specular is not None for o in self.scene.objects)

    def build(self, threads: int = 1) -> _FrameShader:
        """The shader (Embree scene, material tables, buffers) on ``threads`` threads.

        It has ``frame(f, seed)`` -> (H*W, 3) float32, the counters
        ``primary_rays``, ``shadow_rays``, ``gather_rays``, ``seconds``, and
        ``close()``."""
        tracer = _Tracer(self.scene, threads)
        return _FrameShader(
            self.scene,
            self.camera,
            tracer,
            self.sampler,
            self.eps,
            threads,
            self.gather,
            self.seed,
            self.indirect_filter,
        )


class FrameExecutor(Protocol):
    """Where a render's frames are computed (``docs/design.md`` §8).

    ``frames(spec, max_frames, threads=...)`` returns a frame source with
    the interface of :meth:`FrameShaderSpec.build`'s shader: ``frame(f,
    seed)`` must return frame ``f`` as the local shader would, whatever
    the order of computation; the render loop asks for frames 0, 1, ... and
    stops after at most ``max_frames``. After each frame, the source's
    ``surface`` attribute, where it has one, is that frame's
    :func:`frame_surface`; without it the relMSE estimate rests on the
    blocks of frames alone (``docs/design.md`` §6).
    """

    def frames(self, spec: FrameShaderSpec, max_frames: int, *, threads: int = 1): ...


class LocalFrames:
    """The default frame executor: every frame in this process."""

    def frames(self, spec: FrameShaderSpec, max_frames: int, *, threads: int = 1):
        """The shader built here."""
        return spec.build(threads)


# --------------------------------------------------------------------------
# render
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class RenderTuning:
    """Expert settings of :func:`render`, for studies and benchmarks.

    Attributes
    ----------
    min_frames : int
        Frames before the stopping rule is trusted (>= 2; the rule also
        waits for 8 batches, ``docs/design.md`` §6).
    emitter_share : float or None
        Share of each frame's VPLs taken from emitters; None splits by power
        (see :class:`VPLSampler`).
    gather : int or None
        Cosine-distributed gather rays per pixel and frame, MIS-combined
        with the VPLs (0: VPLs only, the paper's display; None: from the
        light's spread, see :func:`ray_budget`).
    vpl_pdf : {"power", "area"}
        VPLs drawn in proportion to power ``ΔA·B`` (default) or to area (the
        paper); see :class:`VPLSampler`.
    vpl_on_surface : bool
        Each frame places every VPL at a fresh point of its record's surface
        (default); False keeps it at the record's centroid (the paper).
    pixel_factor, pixel_share : float
        The stopping rule's per-pixel bound: at most a share ``pixel_share``
        (one in 1000) of the pixels with an estimated relative error
        ``se / sqrt(L² + 0.01)`` over ``pixel_factor · sqrt(tol)`` (10;
        ``inf``: the mean relMSE alone decides; ``pixel_share=0``: every
        pixel).
    indirect_filter : int
        Each frame, the light of the records that do not emit (the indirect
        light) is averaged over the pixels within this many pixels that see
        the same smooth surface: the same material, a normal within about
        25°, near the pixel's tangent plane (``docs/design.md`` §6). 0: off.
        The direct light, from the emitting records and the lights, is
        never filtered.

    >>> RenderTuning(gather=0).min_frames
    4
    """

    min_frames: int = 4
    emitter_share: float | None = None
    gather: int | None = None
    vpl_pdf: str = "power"
    vpl_on_surface: bool = True
    pixel_factor: float = PIXEL_FACTOR
    pixel_share: float = PIXEL_SHARE
    indirect_filter: int = 1


@dataclass(frozen=True)
class _RenderSettings:
    """The validated arguments of one render."""

    cam: Camera
    K: int | None
    max_frames: int
    tol: float
    seed: int
    min_frames: int
    pixel_factor: float
    pixel_share: float
    emitter_share: float | None
    gather: int | None
    vpl_pdf: str
    vpl_on_surface: bool
    threads: int
    indirect_filter: int = 0
    spread: float = math.nan


def _check_render(
    scene, sol, camera, vpls_per_frame, max_frames, tol, seed, threads, tuning
) -> _RenderSettings:
    """Image checks: scene, solution, camera and numbers; TypeError/ValueError naming them."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected voxgi.Scene, got {type(scene).__name__}")
    scene.check_nonempty()
    if sol is None:
        raise TypeError(
            "sol: expected a voxgi.Solution (voxgi.render, the pipeline's "
            "render, solves the scene first when given none)"
        )
    cam = camera if camera is not None else scene.camera
    if cam is None:
        raise ValueError("render: the scene has no camera (set scene.camera or pass camera=)")
    if not isinstance(cam, Camera):
        raise TypeError(f"camera: expected voxgi.Camera, got {type(cam).__name__}")
    t = RenderTuning() if tuning is None else tuning
    if not isinstance(t, RenderTuning):
        raise TypeError(f"tuning: expected voxgi.RenderTuning or None, got {type(t).__name__}")
    tol = _validate.real(tol, "tol", low=0.0, allow_none=True)
    return _RenderSettings(
        cam=cam,
        K=_validate.integer(vpls_per_frame, "vpls_per_frame", low=1, high=1 << 16, allow_none=True),
        max_frames=_validate.integer(max_frames, "max_frames", low=1, allow_none=True) or 256,
        tol=1e-3 if tol is None else tol,
        seed=_validate.integer(seed, "seed"),
        min_frames=_validate.integer(t.min_frames, "min_frames", low=2),
        pixel_factor=(
            math.inf
            if t.pixel_factor == math.inf
            else _validate.real(t.pixel_factor, "pixel_factor", low=0.0, low_open=True)
        ),
        pixel_share=_validate.real(t.pixel_share, "pixel_share", low=0.0, high=1.0, high_open=True),
        emitter_share=_validate.real(
            t.emitter_share, "emitter_share", low=0.0, high=1.0, allow_none=True
        ),
        gather=_validate.integer(t.gather, "gather", low=0, high=4096, allow_none=True),
        vpl_pdf=t.vpl_pdf,
        vpl_on_surface=bool(t.vpl_on_surface),
        threads=_validate.threads(threads),
        indirect_filter=_validate.integer(t.indirect_filter, "indirect_filter", low=0, high=16),
    )


def _check_image_memory(cam: Camera) -> None:
    """Refuse an image that cannot fit before allocating anything: a render
    holds about 1400 bytes per pixel (the running sums, 32 batch means,
    hit records, frame buffers) plus about 30 MB of tile buffers and 50 MB
    for the batch statistics."""
    need = 1500 * cam.width * cam.height + (80 << 20)
    budget = available_memory() // 2
    if need > budget:
        raise ValueError(
            f"render: a {cam.width}x{cam.height} image needs about {need:,} bytes "
            f"(~1500 bytes per pixel), over the budget of {budget:,} bytes (half "
            "the available memory); lower Camera.width/height"
        )


def _check_solution(scene: Scene, sol, cam: Camera) -> None:
    """The image fits in memory; the solution is a :class:`Solution` of this
    scene, one radiosity per record."""
    _check_image_memory(cam)
    if not isinstance(sol, Solution):
        raise TypeError(f"sol: expected voxgi.Solution or None, got {type(sol).__name__}")
    fp = getattr(sol.vox, "scene_fingerprint", "")
    if fp != scene.fingerprint():
        raise ValueError(
            f"sol: this solution was computed for another scene (fingerprint {fp!r}, this "
            f"scene's is {scene.fingerprint()!r}); solve this scene or pass sol=None"
        )
    n = len(sol.vox)
    r = np.asarray(sol.radiosity)
    if r.shape != (n, 3):
        raise ValueError(f"sol.radiosity: expected shape ({n}, 3), got {r.shape}")


def _check_executor(executor) -> FrameExecutor:
    """The executor given, or the local one for None."""
    if executor is None:
        return LocalFrames()
    if not callable(getattr(executor, "frames", None)):
        raise TypeError(
            f"executor: expected an object with a frames(spec, max_frames, threads=...) method "
            f"(voxgi.display.FrameExecutor) or None, got {type(executor).__name__}; "
            "voxgi.render also takes a dask.distributed.Client as client="
        )
    return executor


#: (VPLs per frame, gather rays per pixel and frame) of :func:`ray_budget`
#: for concentrated light and for light spread evenly. Both gather counts are
#: squares, so the rays are stratified in both angles (3 x 3 and 5 x 5
#: cells): 9 such rays leave 0.80 times the noise of 8 stratified in one angle
#: in the Cornell box (``docs/design.md`` §6).
RAY_BUDGETS = ((16, 9), (8, 25))

#: The budget for concentrated light where the indirect light is filtered
#: (:attr:`RenderTuning.indirect_filter`): the filter takes most of the
#: indirect light's noise, and what is left, the direct light's, needs fewer
#: rays. Over nine scenes (spread 0.025-0.57, 256x256, two seeds), the time
#: to the default tolerance was 0.58-0.87 of that with :data:`RAY_BUDGETS`'
#: first budget, the filter on in both, but 1.47 times in a sky-lit atrium
#: (``docs/design.md`` §6).
FILTERED_BUDGET = (8, 4)

#: :func:`light_spread` from which the light counts as spread evenly. Cost of
#: a unit of error of the second budget against the first (``docs/design.md``
#: §6): 1.3-3.7 times on the Cornell box, ``shadow``, ``geometric`` (spread
#: 0.025-0.07), rooms lit through a window or by a sun (0.18-0.29), a box lit
#: by a point light (0.42) and a sphere lit by an emitting cap (0.57); about 1
#: in a sky-lit atrium (0.55); 0.7 for objects under a uniform sky (0.95) and
#: 0.16-0.21 in a furnace (1).
SPREAD_EVEN = 0.8


def light_spread(sol) -> float:
    """How evenly the light of a solution covers the scene's surfaces.

    ``(Σ ΔA·B)² / (Σ ΔA · Σ ΔA·B²)`` over the front records, with ``B`` the
    luminance of their radiosity: 1 when every surface is equally bright (a
    furnace), about the share of the area that carries the light when a few
    surfaces do (0.025 in the Cornell box, 0.18 in a room lit through a
    window), 0 with no light.

    Parameters
    ----------
    sol : Solution

    Returns
    -------
    float in [0, 1]
    """
    vox = sol.vox
    area = np.asarray(vox.area, dtype=np.float64)
    lum = np.asarray(sol.radiosity, dtype=np.float64) @ LUMINANCE
    front = area > 0
    if vox.back is not None:
        front &= ~np.asarray(vox.back, dtype=bool)
    a, b = area[front], np.maximum(lum[front], 0.0)
    second = float(np.sum(a * b * b)) * float(np.sum(a))
    return float(np.sum(a * b)) ** 2 / second if second > 0 else 0.0


def ray_budget(
    spread: float, vpls: int | None = None, gather: int | None = None, *, filtered: bool = False
):
    """VPLs per frame and gather rays per pixel for light of this spread.

    VPLs drawn by power go where the light comes from, gather rays where a
    pixel looks: light from a few bright surfaces needs the first, light that
    comes evenly from everywhere the second (``docs/design.md`` §6). Under a
    spread of :data:`SPREAD_EVEN` the budget is the first of
    :data:`RAY_BUDGETS`, or :data:`FILTERED_BUDGET` where the indirect light
    is filtered; from it on the second. A number given is kept.

    Parameters
    ----------
    spread : float
        :func:`light_spread` of the solution.
    vpls, gather : int or None
        Chosen counts (None: from the spread).
    filtered : bool
        The render filters the indirect light (:attr:`RenderTuning.indirect_filter`).

    Returns
    -------
    (int, int)
        VPLs per frame, gather rays per pixel and frame.

    >>> ray_budget(0.025), ray_budget(0.025, filtered=True), ray_budget(1.0, gather=0)
    ((16, 9), (8, 4), (8, 0))
    """
    even = spread >= SPREAD_EVEN
    k, g = FILTERED_BUDGET if filtered and not even else RAY_BUDGETS[even]
    return (k if vpls is None else int(vpls)), (g if gather is None else int(gather))


def _reflects_light(sol) -> bool:
    """Whether any record that does not emit carries light (what the
    indirect filter would filter)."""
    vox = sol.vox
    keep = ~np.any(np.asarray(vox.emission) > 0, axis=1) & (np.asarray(vox.area) > 0)
    if vox.back is not None:
        keep &= ~np.asarray(vox.back, dtype=bool)
    return bool(np.any(np.asarray(sol.radiosity)[keep] > 0))


def _with_budget(opt: _RenderSettings, sol) -> _RenderSettings:
    """``opt`` with its VPL and gather counts fixed from the solution's light."""
    spread = light_spread(sol)
    filtered = opt.indirect_filter > 0 and _reflects_light(sol)
    k, g = ray_budget(spread, opt.K, opt.gather, filtered=filtered)
    radius = opt.indirect_filter if filtered else 0
    return replace(opt, K=k, gather=g, spread=spread, indirect_filter=radius)


def _shader_spec(scene: Scene, sol, opt: _RenderSettings) -> FrameShaderSpec:
    """The VPL sampler and the shadow-ray offset of this scene and solution."""
    sampler = VPLSampler(
        sol,
        opt.K,
        opt.seed,
        opt.emitter_share,
        mis=opt.gather > 0,
        pdf=opt.vpl_pdf,
        on_surface=opt.vpl_on_surface,
    )
    diag = float(np.linalg.norm(np.ptp(scene.bounds, axis=0)))
    # Shadow-ray offsets: well above float32 rounding of the coordinates
    # (~1e-7 relative) and well below any feature of a sensible scene.
    return FrameShaderSpec(
        scene, opt.cam, sampler, 1e-4 * diag, opt.gather, opt.seed, opt.indirect_filter
    )


def _skipped(spec: FrameShaderSpec) -> list[str]:
    """What this render leaves out, and why."""
    sampler, skipped = spec.sampler, []
    if not spec.glossy:
        skipped.append("glossy: no material has a specular layer")
    if sampler.counts[0] == 0:
        skipped.append("emitter VPLs: no emitting record with power")
    if sampler.counts[1] == 0:
        skipped.append("non-emitter VPLs: no reflecting record with power")
    if sampler.skipped_records:
        skipped.append(
            f"{sampler.skipped_records} records with zero radiosity or area "
            "(back records) are never VPLs"
        )
    return skipped


#: Batch means kept per pixel: between half this and this many once there
#: are that many frames (pairs merge when the store is full, doubling the
#: batch size), so the error estimate always rests on at least 16 batches.
_BATCH_SLOTS = 32

#: Batches before the stopping rule is trusted: two blocks of
#: :data:`_STRATUM_FRAMES` frames for the relMSE estimate, and a per-pixel
#: variance known to a relative standard deviation of sqrt(2 / (k - 1)) =
#: 0.53 (normal batches). A ninth frame, which opens a third block, measured
#: no lower error than eight (``docs/design.md`` §6).
_MIN_BATCHES = 8

#: Frames per block of the mean relMSE's estimate. The sub-pixel offsets
#: follow a (0, 2)-sequence, so any 4 frames from a multiple of 4 put one
#: offset in each quarter of the pixel and their errors at edges partly
#: cancel: consecutive frames are negatively correlated. The spread between
#: single frames misses that and overstates the error of the mean (1.3-1.6x
#: in the window room); the spread between such blocks sees it.
_STRATUM_FRAMES = 4

#: Largest angle between the geometric normals a pixel's camera rays meet on
#: one object for the pixel to count as inside a surface rather than at an
#: edge (more than a coarse tessellation's crease, less than a box's corner).
_EDGE_ANGLE_DEG = 25.0
_EDGE_COS = math.cos(math.radians(_EDGE_ANGLE_DEG))

#: The least factor on an edge pixel's block spread: the offsets' part of its
#: error falls as frames^-3/2, the light samples' part as frames^-1.
_EDGE_SHRINK_MIN = 0.5

#: Significance of the heavy-tail test over a pixel's batches (Bonferroni over
#: the batches, two-sided): a normal pixel is flagged with this probability.
_OUTLIER_ALPHA = 1e-3


#: Student's t quantiles ``t.ppf(1 - _OUTLIER_ALPHA / (2k), k - 2)`` for k = 4
#: to :data:`_BATCH_SLOTS` batches, to 6 digits (the tests check them against
#: scipy): a table, because importing ``scipy.stats`` takes half a second.
_OUTLIER_CRIT = (
    63.2337, 22.2037, 13.6531, 10.3808, 8.7294, 7.75503, 7.12, 6.67681, 6.35172, 6.1041,
    5.90987, 5.75387, 5.62614, 5.51987, 5.43025, 5.35379, 5.28791, 5.23064, 5.18048, 5.13625,
    5.09702, 5.06202, 5.03066, 5.00243, 4.97693, 4.95379, 4.93274, 4.91353, 4.89594,
)  # fmt: skip


def _outlier_threshold(k: int) -> float:
    """Critical externally studentized residual for ``4 <= k <= 32`` batch
    means: under normal batches each residual follows Student's t with
    ``k - 2`` degrees of freedom; Bonferroni over the ``k`` batches,
    two-sided."""
    return _OUTLIER_CRIT[k - 4]


def _batch_statistics(batches: np.ndarray, size: int, frames: int, threads: int = 0):
    """Per-pixel error of the running mean from ``k`` batch means.

    Parameters
    ----------
    batches : (k, P, 3) float32
        Means of ``size`` consecutive frames each, ``k >= 2`` (the
        heavy-tail test needs ``k >= 4``).
    size, frames : int
        Frames per batch; frames in the running mean.
    threads : int
        Threads of the compiled kernel (0: all).

    Returns
    -------
    stderr : (P, 3) float64
        ``sqrt(s_b² · size / frames)``, ``s_b²`` the variance between batch
        means, raised for a flagged pixel to the largest single-batch jump
        ``max_j |m_j - M| · size / frames``.
    flagged : (P,) bool
        Pixels one of whose batches lies beyond what the others' spread
        allows (``docs/design.md`` §6).
    """
    k = len(batches)
    crit = _outlier_threshold(k) if k >= 4 else math.inf
    se, tail = _core.batch_error(
        np.ascontiguousarray(batches, dtype=np.float32), size, frames, crit, threads
    )
    return se, tail.any(axis=1)


def _dilate(mask: np.ndarray, r: int) -> np.ndarray:
    """(H, W) bool: ``mask`` grown by ``r`` pixels in each direction (a
    (2r + 1)² square), by shifted ORs along rows, then columns."""
    out = mask
    for axis in (0, 1):
        grown = out.copy()
        n = out.shape[axis]
        for t in range(1, r + 1):
            lo = [slice(None)] * 2
            hi = [slice(None)] * 2
            lo[axis], hi[axis] = slice(0, n - t), slice(t, n)
            grown[tuple(lo)] |= out[tuple(hi)]
            grown[tuple(hi)] |= out[tuple(lo)]
        out = grown
    return out


class _Estimated:
    """A statistic of :class:`_Mean`'s error estimate, worked out when read:
    reading ``acc.est`` returns ``acc._est`` once ``acc`` has brought its
    estimate up to date."""

    def __init__(self, doc: str):
        self.__doc__ = doc

    def __set_name__(self, owner, name: str) -> None:
        self.field = "_" + name

    def __get__(self, acc, owner=None):
        if acc is None:
            return self
        acc._refresh()
        return getattr(acc, self.field)


@dataclass
class _Mean:
    """The progressive mean of the frames, its error by batch means, and
    the stopping rule (``docs/design.md`` §6).

    Frames go into batches of ``size`` consecutive frames; the variance
    between batch means estimates the variance of the mean even where frames
    are correlated. When the store of :data:`_BATCH_SLOTS` batches is full,
    neighbouring batches merge and ``size`` doubles. ``se`` (per pixel),
    ``worst``, the largest per-pixel relative error ``se / sqrt(L² + 0.01)``
    (largest over a pixel's channels), and ``tail``, the one that all but
    ``share`` of the pixels stay within, come from these batches. ``est``,
    the estimated relMSE ``mean(se² / (L² + 0.01))`` over pixels and
    channels, depends on where a pixel lies. Inside a surface (every frame's
    camera ray met the same object, at normals within
    :data:`_EDGE_ANGLE_DEG`) frames are independent and ``se`` is the
    batches'. At an edge the sub-pixel offsets make them negatively
    correlated: ``se`` comes from the spread between aligned blocks of
    :data:`_STRATUM_FRAMES` frames, kept as running sums, times ``1/sqrt(k)``
    over ``k`` blocks (at least :data:`_EDGE_SHRINK_MIN`). A flagged pixel
    keeps the larger of the batches' and the blocks' spread; before two
    blocks, all take the batches'. Frames that come without their surfaces
    (:func:`frame_surface`) leave every pixel to the blocks.

    These are worked out when first read after a batch completes, not at
    every batch: a render reads them only once its stopping rule can apply,
    and a fixed number of frames only at the end.
    """

    total: np.ndarray
    batches: np.ndarray
    current: np.ndarray
    frames: int = 0
    size: int = 1
    count: int = 0
    share: float = PIXEL_SHARE
    threads: int = 0
    block_sum: np.ndarray | None = None
    block_sq: np.ndarray | None = None
    #: (P,) bool: pixels whose own camera rays met an edge so far; None once
    #: a frame came without its surface
    edge: np.ndarray | None = None
    #: (height, width, pixels): how far a pixel filter spreads a sample
    #: (:meth:`edges`); None for a box filter
    reach: tuple[int, int, int] | None = None
    _first_surface: tuple | None = None
    _est: float = float("inf")
    _worst: float = float("inf")
    _tail: float = float("inf")
    _flagged: int = 0
    _se: np.ndarray | None = None
    _stale: bool = False

    @classmethod
    def empty(cls, pixels: int, share: float = PIXEL_SHARE, threads: int = 0, reach=None) -> _Mean:
        """No frames yet for ``pixels`` pixels; ``share`` as
        :attr:`RenderTuning.pixel_share`; ``threads`` for the error's kernel;
        ``reach`` as :attr:`reach`."""
        return cls(
            np.zeros((pixels, 3)),
            np.zeros((_BATCH_SLOTS, pixels, 3), np.float32),
            np.zeros((pixels, 3)),
            share=share,
            threads=threads,
            block_sum=np.zeros((pixels, 3)),
            block_sq=np.zeros((pixels, 3)),
            reach=reach,
        )

    def edges(self) -> np.ndarray | None:
        """(P,) bool: the pixels the estimate treats as at an edge. With a
        pixel filter a frame's pixel mixes the samples of its neighbours, so
        an edge within the filter's reach counts too."""
        if self.edge is None or self.reach is None:
            return self.edge
        h, w, r = self.reach
        return _dilate(self.edge.reshape(h, w), r).reshape(-1)

    @property
    def mean(self) -> np.ndarray:
        """(P, 3) float64 mean of the frames so far."""
        return self.total / max(self.frames, 1)

    est = _Estimated("estimated relMSE of the mean (inf before two batches)")
    worst = _Estimated("largest per-pixel relative error")
    tail = _Estimated("per-pixel relative error all but ``share`` of the pixels stay within")
    flagged = _Estimated("pixels the heavy-tail test flagged")
    se = _Estimated("(P, 3) per-pixel standard error (None before two batches)")

    def _refresh(self) -> None:
        if self._stale:
            self._estimate()
            self._stale = False

    def add(self, x: np.ndarray, surface: tuple | None = None) -> None:
        """Fold one frame in, with what its camera rays met
        (:func:`frame_surface`); on completing a batch, mark the estimate
        for an update."""
        if self._stale and self.frames + 1 - self.count * self.size < self.size:
            # this frame opens a batch and changes the sums the last complete
            # batch's estimate is made of: make it while they are as they were
            self._refresh()
        self._add_surface(surface)
        self.frames += 1
        self.total += x
        self.current += x
        if self.frames % _STRATUM_FRAMES == 0:
            # the block just completed: all frames less the blocks before it
            block = (self.total - _STRATUM_FRAMES * self.block_sum) / _STRATUM_FRAMES
            self.block_sum += block
            self.block_sq += block * block
        if self.frames - self.count * self.size < self.size:
            return
        self.batches[self.count] = self.current / self.size
        self.current[:] = 0.0
        self.count += 1
        if self.count == _BATCH_SLOTS:
            half = _BATCH_SLOTS // 2
            self.batches[:half] = 0.5 * (self.batches[0::2] + self.batches[1::2])
            self.count, self.size = half, 2 * self.size
        self._stale = self.count >= 2

    def _add_surface(self, surface: tuple | None) -> None:
        if surface is None:
            self.edge = None
            self._first_surface = None
            return
        obj, ng = surface
        if self.frames == 0:
            self._first_surface = (np.array(obj, np.int32), np.array(ng, np.float32))
            self.edge = np.zeros(len(obj), bool)
        elif self.edge is not None:
            obj0, ng0 = self._first_surface
            cos = np.abs(np.einsum("ij,ij->i", ng, ng0, dtype=np.float32))
            self.edge |= (obj != obj0) | ((obj >= 0) & (cos < _EDGE_COS))

    def _estimate(self) -> None:
        done = self.count * self.size
        # The estimate speaks for the mean of the complete batches; the open
        # batch's frames only add to the image.
        mean = self.total - self.current
        mean /= done
        se, flagged = _batch_statistics(self.batches[: self.count], self.size, done, self.threads)
        denom = mean * mean + _REL_EPS
        rel = se * se / denom
        pixel = rel.max(axis=1)
        self._se = se
        k = self.frames // _STRATUM_FRAMES
        if k >= 2:
            spread = np.maximum(self.block_sq - self.block_sum**2 / k, 0.0) / (k - 1)
            rel_blocks = spread * (_STRATUM_FRAMES / done) / denom
            edge = self.edges()
            if edge is None:
                kept = rel_blocks
            else:
                shrink = max(1.0 / math.sqrt(k), _EDGE_SHRINK_MIN)
                kept = np.where(edge[:, None], shrink * rel_blocks, rel)
            self._est = float(
                np.mean(np.where(flagged[:, None], np.maximum(rel, rel_blocks), kept))
            )
        else:
            self._est = float(np.mean(rel))
        self._worst = float(np.sqrt(np.max(pixel)))
        self._tail = float(np.sqrt(np.quantile(pixel, 1.0 - self.share, method="higher")))
        self._flagged = int(np.count_nonzero(flagged))

    def done(self, opt: _RenderSettings) -> bool:
        """At least ``min_frames`` frames and :data:`_MIN_BATCHES` batches, the
        estimated relMSE at or under ``tol`` and at most a share
        ``pixel_share`` of the pixels with a relative error over
        ``pixel_factor · sqrt(tol)``."""
        return (
            self.ready(opt)
            and self.est <= opt.tol
            and self.tail <= opt.pixel_factor * math.sqrt(opt.tol)
        )

    def ready(self, opt: _RenderSettings) -> bool:
        """Whether the stopping rule may apply: ``min_frames`` frames and
        :data:`_MIN_BATCHES` batches."""
        return self.frames >= opt.min_frames and self.count >= _MIN_BATCHES

    def stderr(self, shape) -> np.ndarray | None:
        """Per-pixel standard error (None before two batches)."""
        if self.se is None:
            return None
        return self.se.reshape(shape).astype(np.float32)


def _progressive_mean(source, opt: _RenderSettings, progress: bool) -> tuple[_Mean, bool]:
    """Frames 0, 1, ... from ``source`` into the running mean until the
    stopping rule or ``max_frames``; Ctrl-C stops after the current frame.
    Returns the mean and whether it was interrupted."""
    from tqdm.auto import tqdm

    cam = opt.cam
    reach = _FILTER_REACH[cam.pixel_filter]
    acc = _Mean.empty(
        cam.height * cam.width,
        opt.pixel_share,
        opt.threads,
        (cam.height, cam.width, reach) if reach else None,
    )
    interrupted = False
    # With a tolerance the bar follows the error, not the frame cap that is
    # rarely reached: the share of the way, in log scale, from the first
    # estimate to tol (or the share of the frames, whichever is further).
    bar = tqdm(
        total=100,
        disable=not progress,
        desc="display",
        unit="%",
        leave=False,
        bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed}<{remaining}{postfix}",
    )
    first = None
    try:
        for f in range(opt.max_frames):
            x = source.frame(f, opt.seed).astype(np.float64)
            acc.add(x, getattr(source, "surface", None))
            share = (f + 1) / opt.max_frames
            # the estimate is read only once the rule may stop on it
            est = acc.est if opt.tol > 0 and acc.ready(opt) else math.nan
            if np.isfinite(est) and est > 0:
                first = est if first is None else first
                if first > opt.tol:
                    share = max(share, math.log(first / est) / math.log(first / opt.tol))
            bar.update(int(100 * min(share, 1.0)) - bar.n)
            known = f", est relMSE {est:.2e}" if np.isfinite(est) else ""
            bar.set_postfix_str(f"frame {f + 1}{known}")
            if acc.done(opt):
                break
    except KeyboardInterrupt:
        interrupted = True
    finally:
        bar.close()
        source.close()
    return acc, interrupted


def _render_stats(spec, source, acc: _Mean, opt, skipped, interrupted, seconds) -> dict:
    """Ray counts, VPLs, frames, the estimate and what was skipped."""
    return {
        "seconds": seconds,
        "primary_rays": int(source.primary_rays),
        "shadow_rays": int(source.shadow_rays),
        "light_rays": int(getattr(source, "light_rays", 0)),
        "gather_rays": int(source.gather_rays),
        "gather_per_frame": spec.gather_per_frame,
        "indirect_filter": int(spec.indirect_filter),
        "vpls_per_frame": int(sum(spec.sampler.counts)),
        "light_spread": opt.spread,
        "vpls": int(acc.frames * sum(spec.sampler.counts)),
        "vpl_split": [int(c) for c in spec.sampler.counts],
        "vpl_pdf": spec.sampler.pdf,
        "frames": int(acc.frames),
        "est_rel_mse": acc.est,
        "est_max_rel_err": acc.worst,
        "est_tail_rel_err": acc.tail,
        "flagged_pixels": acc.flagged,
        "edge_pixels": None if acc.edge is None else int(np.count_nonzero(acc.edges())),
        "batches": acc.count,
        "batch_frames": acc.size,
        "tol": opt.tol,
        "eps": spec.eps,
        "skipped": skipped,
        "interrupted": interrupted,
        "threads": opt.threads,
    }


def render(
    scene,
    sol,
    vpls_per_frame: int | None = None,
    max_frames: int | None = None,
    tol: float | None = None,
    seed: int = 0,
    progress: bool = True,
    threads: int | None = None,
    executor: FrameExecutor | None = None,
    *,
    camera: Camera | None = None,
    tuning: RenderTuning | None = None,
) -> RenderResult:
    r"""Render ``scene`` from its camera using the voxel solution ``sol``.

    Each pixel's primary ray (Embree) hits a point x; its radiance is
    ``Le(x)`` plus the light reflected from the records of ``sol``, each a
    virtual point light of radiance ``B/π`` (``docs/design.md`` §6):

    .. math:: L(x) = L_e(x) + \int f(x, \omega_i, \omega_o)\, \frac{B(y)}{\pi}\,
              \frac{\cos\theta_x \cos\theta_y}{r^2 + \Delta A(y)/\pi} V(x, y)\, dA(y),

    estimated with a few VPLs per frame and gather rays MIS-combined with
    them, frames averaged until the estimated noise falls under ``tol``.

    Parameters
    ----------
    scene : Scene
        With a camera (``scene.camera``, or ``camera=``).
    sol : Solution
        The voxel solution of ``scene`` (``voxgi.render`` also takes None).
    vpls_per_frame : int or None
        VPLs per frame and pixel (>= 1; None: from the light's spread,
        :func:`ray_budget`).
    max_frames : int or None
        At most this many frames (default 256).
    tol : float or None
        Bound on the estimated relMSE of the remaining noise (default 1e-3; 0:
        run ``max_frames``).
    seed : int
        Seeds the VPL, sub-pixel and lens sequences.
    progress, threads
        A tqdm progress bar; worker threads (None: all cores).
    executor : FrameExecutor or None
        Where the frames are computed (None: here); the image is the local one.
    camera : Camera, optional
        Overrides ``scene.camera``.
    tuning : RenderTuning or None
        Expert settings (:class:`RenderTuning`).

    Returns
    -------
    RenderResult
        ``image`` (H, W, 3) float32 linear radiance, ``image[0, 0]`` top-left;
        ``stderr``; ``frames``; ``stats`` (seconds, ray counts, ``est_rel_mse``,
        ``skipped``, ``interrupted``: Ctrl-C stops after the current frame).

    Raises
    ------
    ValueError, TypeError
        No camera, a solution of another scene, bad arguments, too large an image.
    """
    t_start = time.perf_counter()
    opt = _check_render(scene, sol, camera, vpls_per_frame, max_frames, tol, seed, threads, tuning)
    executor = _check_executor(executor)
    _check_solution(scene, sol, opt.cam)
    opt = _with_budget(opt, sol)
    t0 = time.perf_counter()
    spec = _shader_spec(scene, sol, opt)
    source = executor.frames(spec, opt.max_frames, threads=opt.threads)
    seconds = {"setup": time.perf_counter() - t0}
    skipped = _skipped(spec)
    tracer = getattr(source, "tracer", None)
    if tracer is not None and tracer.why_not_native is not None:
        skipped.append(
            f"compiled ray tracing: {tracer.why_not_native}; the rays go through embreex's "
            "Python calls in batches (the same image, slower)"
        )
    acc, interrupted = _progressive_mean(source, opt, progress)
    image = acc.mean.reshape(opt.cam.height, opt.cam.width, 3).astype(np.float32)
    seconds.update(source.seconds)
    seconds["total"] = time.perf_counter() - t_start
    seconds["display"] = seconds["total"]
    stats = _render_stats(spec, source, acc, opt, skipped, interrupted, seconds)
    return RenderResult(
        image=image, frames=acc.frames, stderr=acc.stderr(image.shape), stats=stats, solution=sol
    )
