"""The shading of one frame: camera hits, the VPLs' light, gather rays,
lights and environment, the indirect filter (``docs/design.md`` §6)."""

from __future__ import annotations

import math
import time
from functools import cached_property

import numpy as np

from .. import _core
from ..rays import Tracer
from ..scene import Camera, Scene
from ..traced import record_grid
from .pixel_filter import gaussian_pixel_filter
from .samples import camera_rays, frame_samples
from .vpls import VPLSampler

__all__ = ["frame_surface"]

#: What the VPL kernels read of a pixel's primary hit.
_HIT_KEYS = ("pos", "normal", "ng", "wo", "material")
_VPL_KEYS = ("pos", "normal", "weight", "area", "pa")


def _vpl_slice(vpls: dict, a: int, b: int | None) -> dict:
    """VPLs ``a:b`` of one group's frame set (emitters first, then the rest)."""
    return {k: v[a:b] for k, v in vpls.items()}


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
            ray_org=org_buf[:n],
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
