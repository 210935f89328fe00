"""The shading of one frame: camera hits, the VPLs' light, gather rays, the
lights and environment, the indirect filter (``docs/design.md`` §6).

Every ray workload runs in one compiled kernel that makes its rays, traces
them in the scene's Embree scene as they are made and sums their light pixel
by pixel: ``camera_hits``, ``vpl_light``, ``gather_light`` (the environment
included), ``environment_light`` (the environment's samples) and, for the
delta lights, the tracer's batch queries and ``light_accumulate``.
"""

from __future__ import annotations

import math
import time
from functools import cached_property

import numpy as np

from .. import _core
from ..materials import AshikhminShirley
from ..microfacet import LOBE_WIDTH, Microfacet
from ..rays import Tracer
from ..scene import Camera, Scene
from ..textures import surface_tables
from ..traced import grid_positions, record_grid
from .aovs import EMISSION_COLUMN, frame_aovs
from .environment_guide import environment_guide
from .lighting import _HIT_KEYS, _SceneLights
from .pixel_filter import gaussian_pixel_filter
from .samples import camera_arguments, frame_samples, mirror_points
from .seen_emission import SeenEmission, seen_emission, skip_reason
from .vpls import VPLSampler, base_outgoing, continuing_objects, place_vpls

__all__ = ["frame_surface"]

#: What the VPL kernel reads of each VPL.
_VPL_KEYS = ("pos", "normal", "weight", "area", "pa")
# the record grid's arguments of the walks from the VPLs on stacked sheets
_SHEET_GRID_KEYS = ("rec_sorted_key", "rec_cell_start", "rec_packed", "grid_dims", "grid_lo",
                    "grid_origin", "pitch", "rec_stacked", "piece_first", "piece_key",
                    "piece_record", "piece_side", "piece_plane_first", "piece_plane",
                    "pieces_for_sheets")  # fmt: skip

#: Walks from each VPL on a stacked sheet a frame (:meth:`_FrameShader._walk_vpls`):
#: a VPL lights every pixel of its set, so its walks' noise is shared by
#: them; they cost little beside the pixels' own rays.
SHEET_WALKS = 16


def _vpl_part(vpls: dict, lo: int, hi: int | None) -> dict:
    """VPLs ``lo:hi`` of every set of one frame's VPLs (:meth:`VPLSampler.frame`:
    sets of equal size, each its emitters first, then the rest)."""
    sets = len(vpls["start"]) - 1
    out = {
        k: np.ascontiguousarray(
            v.reshape(sets, -1, *v.shape[1:])[:, lo:hi].reshape(-1, *v.shape[1:])
        )
        for k, v in vpls.items()
        if k != "start"
    }
    out["start"] = np.arange(sets + 1, dtype=np.int64) * (len(out["index"]) // max(sets, 1))
    return out


class _Tracer(Tracer):
    """The scene's tracer with the per-triangle data shading needs: object,
    winding normal and corner normals, in float64 (scene-centred frame)."""

    def __init__(self, scene: Scene, threads: int):
        super().__init__(scene, threads)
        self.obj = scene.triangle_objects()  # (F,) int32
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


class _FrameShader:
    """Everything a frame needs that does not change between frames."""

    #: Most VPL sets per frame. Each frame every pixel takes its VPLs from
    #: one of :meth:`vpl_sets` sets, drawn for it at random (each set lights
    #: an equal share of the pixels, scattered over the image). A set's VPLs
    #: light all of its pixels alike, too bright or too dark together, so the
    #: error that a whole frame shares is a set's divided by the square root
    #: of their number: with 256 sets it is a sixteenth of one set's, and two
    #: neighbouring pixels share a set once in 256 frames, so that no pattern
    #: ties their errors (``docs/design.md`` §6).
    VPL_SETS = 256
    #: Fewest pixels per set: a small image takes fewer sets, so that placing
    #: the sets' VPLs costs little beside its pixels' rays.
    SET_PIXELS = 16

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
        control_emission: bool = True,
        guide_environment: bool = True,
        near_reach: float = 0.0,
        mirror_alpha: float = 0.0,
    ):
        self.scene, self.cam, self.tracer, self.sampler = scene, cam, tracer, sampler
        # the filter needs the two kinds of light apart; without any light of
        # non-emitting records there is nothing to filter
        self.indirect_filter = int(indirect_filter) if sampler.counts[1] > 0 else 0
        self.eps, self.threads = float(eps), int(threads)
        self.gather = int(gather) if sampler.mis else 0
        self.seed = int(seed)
        self._material_tables(scene)
        self._mirror_tables(float(mirror_alpha))
        self.env = scene.environment
        emits = bool(np.any(self.mat_emission > 0))
        #: why the seen emission is not controlled (None: it is)
        self.emission_skipped = (
            skip_reason(cam, emits, self.env)
            if control_emission
            else "seen emission: the control variate is switched off"
        )
        #: why the environment's samples are not guided (None: they are)
        self.env_guide_skipped: str | None = None
        guide = None
        if self.env is not None and not guide_environment:
            self.env_guide_skipped = "environment guide: switched off"
        elif self.env is not None:
            guide, self.env_guide_skipped = environment_guide(
                self.env, sampler.vox, tracer, self.eps
            )
        # environment samples per pixel and frame: as many as the gather rays
        # they are MIS-combined with, twice as many where the guide draws
        # them from the directions open at each place, where each is worth
        # more than a gather ray (docs/design.md §11)
        n_env = (2 if guide is not None else 1) * max(1, self.gather) if self.env is not None else 0
        self.lights = _SceneLights(
            scene, tracer, self._materials(), self.eps, self.seed, n_env, self.threads
        )
        self.lights.lobe = self.mat_lobe
        self.lights.guide = guide
        self.tile = 1 << 16
        self._groups = self._pixel_groups(cam, self.vpl_sets(cam))
        self.primary_rays = 0
        #: :func:`frame_surface` of the last frame
        self.surface: tuple[np.ndarray, np.ndarray] | None = None
        #: :func:`frame_aovs` of the last frame, pixel-filtered as its image
        self.aovs: np.ndarray | None = None
        self.shadow_rays = 0
        self.gather_rays = 0
        # the VPLs' and gather rays' shading is timed with their rays
        self.seconds = {"primary": 0.0, "shadow": 0.0, "gather": 0.0}
        # the frame's emitter VPLs, for the gather rays that continue (shade)
        self._near: dict = {}
        if self.gather:
            self._grid = record_grid(
                sampler.vox,
                tracer.centre,
                sampler.B / math.pi,
                sampler.record_pa,
                share=sampler.share if self.mat_continue is not None else None,
                stacked=sampler.walked,
                pieces="sheets" if sampler.walked is not None else False,
            )
            # the rows of the VPLs' records in the grid, for their walks
            if sampler.walked is not None:
                self._grid_row = grid_positions(sampler.vox)
            self._tri = {
                "tri_v": tracer.tris,
                "tri_object": tracer.obj,
                "obj_two_sided": self.two_sided.astype(np.uint8),
            }
            # A near hit continues with the emitters' light sampled at it; a
            # delta light it could not sample (docs/design.md §6). A walk
            # through stacked sheets samples them at every bounce.
            near = near_reach > 0 and not scene.lights
            if near or sampler.walked is not None:
                self._tri["obj_emits"] = (self.mat_emission.max(axis=1) > 0).astype(np.uint8)
            if near:
                self._tri["reach"] = float(near_reach) * float(sampler.vox.pitch)
            self._env = self.lights.environment_tables()

    def _material_tables(self, scene: Scene) -> None:
        """Per object: albedo, emission, sidedness and the specular layer's
        parameters, as the shading kernels take them."""
        objs = scene.objects
        self.mat_albedo = np.array([o.material.albedo for o in objs], np.float32)
        self.mat_emission = np.array([o.material.emission for o in objs], np.float32)
        self.two_sided = np.array([o.two_sided for o in objs], bool)
        spec = [o.material.specular for o in objs]
        self.mat_glossy = np.array([s is not None for s in spec], np.uint8)
        ash = [s if isinstance(s, AshikhminShirley) else None for s in spec]
        self.mat_rs = np.array([s.rs if s else (0.0, 0.0, 0.0) for s in ash], np.float32)
        self.mat_nu = np.array([s.nu if s else 1.0 for s in ash], np.float32)
        self.mat_nv = np.array([s.nv if s else 1.0 for s in ash], np.float32)
        # the microfacet lobes' rows, or None: no pixel pays for lobes
        self.mat_lobe = None
        self.mat_continue = None
        self.mat_base_out = None
        if any(isinstance(s, Microfacet) for s in spec):
            self.mat_lobe = np.zeros((len(objs), LOBE_WIDTH), np.float32)
            for i, s in enumerate(spec):
                if isinstance(s, Microfacet):
                    self.mat_lobe[i] = s.lobe_row()
            if self.sampler.share is not None:
                self.mat_continue = continuing_objects(scene)
                self.mat_base_out = base_outgoing(scene)

    def _mirror_tables(self, alpha: float) -> None:
        """``mirrors``: the mirrors' arguments of the camera kernels, the
        conductors whose lobe's alpha is at most ``alpha`` that do not emit
        ({} where none is: camera rays stop at every surface)."""
        self.mirrors: dict = {}
        if self.mat_lobe is None or not alpha > 0:
            return
        spec = [o.material.specular for o in self.scene.objects]
        mirror = np.array(
            [isinstance(s, Microfacet) and s.kind == "conductor" and s.alpha <= alpha for s in spec]
        ) & ~(self.mat_emission.max(axis=1) > 0)
        if mirror.any():
            self.mirrors = {
                "obj_mirror": mirror.astype(np.uint8),
                "obj_lobe": self.mat_lobe,
                "eps": self.eps,
            }

    def _mirror_arguments(self, stream: int, **extra) -> dict:
        """The mirrors' arguments with the random stream ``stream`` and
        ``extra`` (none without mirrors)."""
        if not self.mirrors:
            return {}
        return {**self.mirrors, "mirror_seed": int(stream) & 0xFFFFFFFFFFFFFFFF, **extra}

    @property
    def light_rays(self) -> int:
        """Shadow rays traced to the lights and the environment."""
        return self.lights.rays

    def camera_hits(self, offset, lens) -> dict:
        """Primary hits of the camera rays through sub-pixel ``offset`` and
        lens point ``lens`` (:func:`~voxgi.display.camera_rays`), made,
        traced and hit in one kernel: points in float64 on the hit
        triangle's plane, normals facing the viewer, material index (-1:
        miss or a one-sided back), the emission seen (the environment's
        radiance for a ray that leaves the scene), and ``through``: what the
        sheets before the hit let through (None in a scene without)."""
        tr = self.tracer
        pos, n_out, ng_out, wo, mat, le, prim, through, albedo = _core.camera_hits(
            *camera_arguments(self.cam, tr.centre),
            (float(offset[0]), float(offset[1])),
            (float(lens[0]), float(lens[1])),
            *self._primary_scene,
            tr.native,
            threads=self.threads,
            **self._textures,
            **self._mirror_arguments(
                hash((self.seed, self._frame, 0x3C1)),
                mirror_point=tuple(mirror_points([self._frame], self.seed)[0]),
            ),
        )
        self.primary_rays += len(prim)
        if self.env is not None:
            miss = np.flatnonzero(prim < 0)
            le[miss] = self.env.eval(-wo[miss].astype(np.float64))
        hits = {"pos": pos, "normal": n_out, "ng": ng_out, "wo": wo, "material": mat}
        # what the sheets (glass) before each hit let through, None without any
        # and each hit's albedo only where a texture makes it differ from its object's
        return {**hits, "emission": le, "through": through, "albedo": albedo}

    @cached_property
    def emission_control(self) -> SeenEmission | None:
        """The pixels whose footprint sees emission unevenly and the mean
        each sees (:mod:`voxgi.display.seen_emission`), computed at the first
        frame; None where :attr:`emission_skipped` says why not."""
        if self.emission_skipped is not None:
            return None
        out = seen_emission(
            self.cam,
            self.tracer,
            self._primary_scene,
            self.env,
            self.seed,
            self.threads,
            self._mirror_arguments(hash((self.seed, 0x3C2))),
        )
        self.primary_rays += out.rays
        self.seconds["primary"] += out.seconds
        return out

    def _seen_emission(self, h: dict) -> np.ndarray:
        """The emission this frame's rays saw, as the frame counts it
        (through the sheets before it)."""
        seen = h["emission"]
        if h["through"] is not None:
            seen = seen * h["through"]
        return seen

    @cached_property
    def _gather_textures(self) -> dict:
        """The textures' arguments of :func:`_core.gather_light`: a gather ray
        that lands on a textured object sees the texture's detail there (not
        on an emitter, whose record's light holds its emission)."""
        if not self._textures:
            return {}
        keys = ("tex_texels", "tex_info", "obj_texture", "corner_uv")
        out = {k: self._textures[k] for k in keys}
        out["obj_texture"] = np.where(
            self.mat_emission.max(axis=1) > 0, -1, out["obj_texture"]
        ).astype(np.int32)
        return out

    @cached_property
    def _textures(self) -> dict:
        """The textures' arguments of :func:`_core.camera_hits` (none without
        a textured object): each hit's albedo is then the texture's there."""
        tables = surface_tables(self.scene)
        if tables is None:
            return {}
        return {"obj_albedo": self.mat_albedo, **tables}

    @cached_property
    def _primary_scene(self) -> tuple:
        """The triangle and object arrays of :func:`_core.camera_hits`."""
        tr = self.tracer
        return (
            np.ascontiguousarray(tr.tris, dtype=np.float64),
            np.ascontiguousarray(tr.ng, dtype=np.float64),
            None if tr.vn is None else np.ascontiguousarray(tr.vn, dtype=np.float64),
            np.ascontiguousarray(tr.obj, dtype=np.int32),
            self.two_sided.astype(np.uint8),
            np.ascontiguousarray(self.mat_emission, dtype=np.float32),
        )

    def shade(self, h: dict, vpls: dict | None) -> np.ndarray:
        """(P, 3) float32 radiance: emission seen + VPL estimate of the reflected
        light, the VPLs of set g (:meth:`VPLSampler.frame`) lighting the
        pixels of set g."""
        P = len(h["material"])
        out = h["emission"].astype(np.float32, copy=True)
        # the gather rays run only with VPLs to combine with
        has_vpls = vpls is not None and len(vpls["index"]) > 0
        if self.lights.any:
            t0 = time.perf_counter()
            gathering = self.gather if has_vpls else 0
            self.lights.add(h, out, self._frame, gathering, self.tile)
            self.seconds["lights"] = self.seconds.get("lights", 0.0) + time.perf_counter() - t0
        if not has_vpls:
            return out
        # With the filter, the light of the non-emitting records' VPLs and of
        # all the gather rays is kept apart, filtered and then added. A gather
        # ray finds an emitter or another record, never both, so the two
        # kinds of its light err in opposite directions: they are filtered
        # together, or the cancellation between them is lost. The emitters'
        # VPLs, which carry the sharp shadows, are never filtered.
        reflected = np.zeros_like(out) if self.indirect_filter else None
        if self.gather:
            self._near = self._near_emitters(vpls)
        if self.sampler.walked is not None:
            self._walk_vpls(vpls)
        nd = self.sampler.counts[0]
        parts = [(vpls, out)]
        if reflected is not None:
            parts = [(_vpl_part(vpls, 0, nd), out), (_vpl_part(vpls, nd, None), reflected)]
        for part, into in parts:
            if len(part["index"]) > 0:
                into += self._vpl_light(h, part)
        if self.gather:
            for a in range(0, P, self.tile):
                b = min(P, a + self.tile)
                self._gather(h, a, b, out if reflected is None else reflected)
        if reflected is not None:
            self._filter(h, reflected, out)
        return out

    def _walk_vpls(self, vpls: dict) -> None:
        """Give the frame's VPLs on stacked sheets (:attr:`VPLSampler.walked`)
        the light leaving their own points, walked through their stacks
        (:data:`SHEET_WALKS` walks each, the emitters sampled at every
        bounce) as the gather rays that land there read it, in place of
        their record's mean ``B/π`` (``docs/design.md`` §6)."""
        on = np.flatnonzero(self.sampler.walked[vpls["index"]])
        if len(on) == 0:
            return
        t0 = time.perf_counter()
        grid = {k: v for k, v in self._grid.items() if k in _SHEET_GRID_KEYS}
        near = {k: v for k, v in self._near.items() if k.startswith("emitter_")}
        vpls["weight"][on] = _core.sheet_radiance(
            np.ascontiguousarray(vpls["pos"][on]),
            np.ascontiguousarray(vpls["normal"][on]),
            self._grid_row[vpls["index"][on]],
            SHEET_WALKS,
            self.seed,
            self._frame,
            self.eps,
            self._tri["tri_v"],
            self._tri["tri_object"],
            self._tri["obj_two_sided"],
            self._tri["obj_emits"],
            **grid,
            scene=self.tracer.native,
            threads=self.threads,
            **near,
        )
        self.seconds["sheets"] = self.seconds.get("sheets", 0.0) + time.perf_counter() - t0

    def _near_emitters(self, vpls: dict) -> dict:
        """The kernels' arguments for the emitters' light where a near
        gather ray continues or a walk bounces through stacked sheets
        (:meth:`_walk_vpls`): this frame's emitter VPLs (every set's),
        each drawn with its record's density per unit area in the emitters'
        table, so that one picked uniformly among them is a sample of that
        density (empty: no ray continues, or no emitter to sample)."""
        nd = self.sampler.counts[0]
        continues = self._tri.get("reach", 0.0) > 0 or self.sampler.walked is not None
        if not continues or nd == 0 or not self.sampler.mis:
            return {}
        e = _vpl_part(vpls, 0, nd)
        density = self.sampler.sets[0][3]
        return {
            "emitter_pos": e["pos"],
            "emitter_normal": e["normal"],
            "emitter_radiance": np.ascontiguousarray(
                self.sampler.B[e["index"]] / math.pi, dtype=np.float32
            ),
            "emitter_density": np.ascontiguousarray(density[e["index"]], dtype=np.float32),
            "emitter_per_set": float(nd),
        }

    def _filter(self, h: dict, reflected: np.ndarray, out: np.ndarray) -> None:
        """Add the non-emitting records' light, filtered over the pixels that
        see the same smooth surface (``docs/design.md`` §6)."""
        t0 = time.perf_counter()
        cam = self.cam
        albedo = h.get("albedo")
        if albedo is not None:
            # A texture's detail is the hit's own: the light is filtered
            # divided by each hit's albedo, and multiplied back after
            # (where a channel's albedo is 0, its light passes unfiltered).
            keep = albedo > 1e-4
            target, out = out, np.zeros_like(out)
            target += np.where(keep, 0.0, reflected)
            reflected = np.where(keep, reflected / np.where(keep, albedo, 1.0), 0.0).astype(
                np.float32
            )
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
        if albedo is not None:
            target += out * albedo
        self.seconds["filter"] = self.seconds.get("filter", 0.0) + time.perf_counter() - t0

    def _vpl_share(self, vpls: dict) -> dict:
        """The kernels' arguments for pixels whose gather rays follow the
        lobes they land on: which materials, and each VPL's share."""
        if self.mat_continue is None or vpls.get("share") is None:
            return {}
        return {
            "mat_continue": self.mat_continue,
            "vpl_share": vpls["share"],
            "mat_base_out": self.mat_base_out,
            "vpl_object": vpls["object"],
        }

    def _vpl_light(self, h: dict, vpls: dict) -> np.ndarray:
        """(P, 3) float32: the VPLs' light at the hits ``h``, each pixel lit by
        its VPL set's VPLs, its shadow rays traced as they are made."""
        t0 = time.perf_counter()
        cat = [vpls[k] for k in _VPL_KEYS]
        start = vpls["start"]
        sets = len(start) > 2
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
            hit_albedo=h.get("albedo"),
            mat_lobe=self.mat_lobe,
            **self._vpl_share(vpls),
        )
        self.shadow_rays += rays
        self.seconds["shadow"] += time.perf_counter() - t0
        return out

    @cached_property
    def _pixel_set(self) -> np.ndarray:
        """(P,) int32 VPL set of each pixel, in row-major order."""
        perm, cuts = self._groups
        out = np.empty(len(perm), np.int32)
        out[perm] = np.repeat(np.arange(len(cuts) - 1, dtype=np.int32), np.diff(cuts))
        return out

    def _materials(self) -> tuple:
        return self.mat_albedo, self.mat_rs, self.mat_nu, self.mat_nv, self.mat_glossy

    def _gather(self, h: dict, a: int, b: int, out: np.ndarray) -> None:
        """Add the gather rays' MIS-weighted share of the light into
        ``out[a:b]``: the records' light where a ray lands, the
        environment's where it leaves the scene."""
        t0 = time.perf_counter()
        self.gather_rays += _core.gather_light(
            *(h[k][a:b] for k in _HIT_KEYS),
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
            **self._env,
            hit_albedo=None if h.get("albedo") is None else h["albedo"][a:b],
            **self._gather_textures,
            mat_lobe=self.mat_lobe,
            mat_continue=self.mat_continue,
            mat_base_out=self.mat_base_out if self.mat_continue is not None else None,
            **self._near,
        )
        self.seconds["gather"] += time.perf_counter() - t0

    def frame(self, f: int, seed: int) -> np.ndarray:
        """(H*W, 3) radiance estimate of frame ``f``."""
        self._frame = int(f)
        offset, lens = frame_samples(f, seed)
        t0 = time.perf_counter()
        h = self.camera_hits(offset, lens)
        self.seconds["primary"] += time.perf_counter() - t0
        self.surface = frame_surface(h)
        rng = np.random.default_rng([self.seed, self._frame, 0x6B0])
        self._groups = self._pixel_groups(self.cam, self.vpl_sets(self.cam), rng)
        self.__dict__.pop("_pixel_set", None)  # the cached view of the groups
        per_hit = h.get("albedo") is not None
        self.aovs = frame_aovs(
            h,
            h["albedo"] if per_hit else self.mat_albedo,
            np.asarray(self.cam.eye) - self.tracer.centre,
            self.cam.frame()[2],
            per_hit=per_hit,
            emission=self._seen_emission(h),
        )
        vpls = None
        if not self.sampler.empty:
            vpls = self.sampler.frame(f, len(self._groups[1]) - 1)
            # into the tracer's scene-centred frame; every set's VPLs placed at once
            pos = vpls["pos"] - self.tracer.centre
            if self.sampler.on_surface:
                pos = place_vpls(
                    self.sampler, self.tracer, vpls["index"], pos, f, self.seed, self.eps
                )
            vpls["pos"] = np.ascontiguousarray(pos)
        img = self.shade(h, vpls)
        if h["through"] is not None:
            img *= h["through"]  # the pixel sees its hit through the sheets
        ctl = self.emission_control
        if ctl is not None and len(ctl.pixels) == 0:
            ctl = None
        e = EMISSION_COLUMN
        if self.cam.pixel_filter == "gaussian":
            # the AOVs, the seen emission among them, through the same filter
            # as the image, in the same pass
            both = gaussian_pixel_filter(
                np.concatenate([img, self.aovs], axis=1), self.cam.width, self.cam.height, offset
            )
            img = np.ascontiguousarray(both[:, :3])
            self.aovs = np.ascontiguousarray(both[:, 3:])
        if ctl:
            # the frame's seen emission at the controlled pixels, for its
            # mean; the emission AOV alike, so that it stays the part of the
            # image that is emission
            img[ctl.pixels] += ctl.mean - self.aovs[ctl.pixels, e : e + 3]
            self.aovs[ctl.pixels, e : e + 3] = ctl.mean
        return img

    @classmethod
    def vpl_sets(cls, cam: Camera) -> int:
        """VPL sets per frame for this camera's image: :attr:`VPL_SETS`, or
        one per :attr:`SET_PIXELS` pixels of a smaller image (at least 1)."""
        return int(max(1, min(cls.VPL_SETS, cam.width * cam.height // cls.SET_PIXELS)))

    @staticmethod
    def _pixel_groups(cam: Camera, n: int, rng=None) -> tuple[np.ndarray, np.ndarray]:
        """The row-major pixel indices sorted by VPL set, and where each of
        the ``n`` sets starts in them (one more entry, the end). With ``rng``
        the pixels are dealt to the sets in a random order, each set an
        equal share (to one pixel); without it in row-major order."""
        P = cam.height * cam.width
        perm = np.arange(P) if rng is None else rng.permutation(P)
        n = max(1, min(int(n), P))
        cuts = (np.arange(n + 1) * P) // n
        return perm, cuts

    def close(self) -> None:
        """Release the tracer."""
        self.tracer.close()
