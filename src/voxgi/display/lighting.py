"""The light of the scene's lights and environment at one frame's hits: a
shadow ray to each delta light, and environment samples MIS-combined with the
gather rays (``docs/design.md`` §11), each kind in one compiled kernel."""

from __future__ import annotations

import numpy as np

from .. import _core
from ..rays import Tracer
from ..scene import Scene

__all__: list[str] = []

#: What the shading kernels read of a pixel's primary hit.
_HIT_KEYS = ("pos", "normal", "ng", "wo", "material")


class _SceneLights:
    """The delta lights and the environment of a scene, as one frame's
    pixels receive them.

    Parameters
    ----------
    scene : Scene
    tracer : Tracer
        The scene's tracer; points are in its centred frame.
    materials : tuple
        The shading kernels' material tables (albedo, rs, nu, nv, glossy).
    eps : float
        Shadow-ray offset (scene units).
    seed : int
    n_env : int
        Environment samples per pixel and frame.
    threads : int
    """

    def __init__(
        self,
        scene: Scene,
        tracer: Tracer,
        materials: tuple,
        eps: float,
        seed: int,
        n_env: int,
        threads: int,
    ):
        self.lights = list(scene.lights)
        self.env = scene.environment
        self.tracer, self.materials = tracer, materials
        self.eps, self.seed, self.n_env, self.threads = eps, seed, n_env, threads
        #: shadow rays traced to the lights and the environment
        self.rays = 0
        #: the materials' microfacet lobes (csrc/microfacet.h), or None
        self.lobe = None
        #: where the environment's light reaches (environment_guide), or None
        self.guide = None

    @property
    def any(self) -> bool:
        """Whether the scene has a light or an environment."""
        return bool(self.lights) or self.env is not None

    def environment_tables(self) -> dict:
        """The environment's arguments of :func:`voxgi._core.gather_light`
        (empty without one): a gather ray that escapes sees the environment,
        MIS-combined with its :attr:`n_env` samples."""
        if self.env is None:
            return {}
        t = self.env.tables()
        return {
            "env_radiance": self.env.image,
            "env_to_world": np.ascontiguousarray(self.env.to_world, np.float64),
            "env_texel_pdf": t["texel_pdf"],
            "env_row_solid_angle": t["row_solid_angle"],
            "env_samples": float(self.n_env),
            "env_guide": None if self.guide is None else self.guide.native,
        }

    def add(self, h: dict, out: np.ndarray, frame: int, gathering: int, tile: int) -> None:
        """Add the light of every pixel into ``out``: one shadow ray to each
        delta light (pixels in tiles of ``tile``), :attr:`n_env` environment
        samples weighted against ``gathering`` gather rays per pixel."""
        P = len(h["material"])
        if self.lights:
            for a in range(0, P, tile):
                self._add_delta(h, a, min(P, a + tile), out)
        if self.env is not None and self.n_env > 0:
            self.rays += _core.environment_light(
                *(h[k] for k in _HIT_KEYS),
                *self.materials,
                *self.env.sampling_arguments(),
                self.n_env,
                float(gathering),
                self.seed,
                frame,
                self.eps,
                self.tracer.native,
                out,
                self.threads,
                hit_albedo=h.get("albedo"),
                mat_lobe=self.lobe,
                env_guide=None if self.guide is None else self.guide.native,
            )

    def _add_delta(self, h: dict, a: int, b: int, out: np.ndarray) -> None:
        """Add the delta lights' light of pixels [a, b) into ``out[a:b]``."""
        pix = np.flatnonzero(h["material"][a:b] >= 0)
        if len(pix) == 0:
            return
        ng = h["ng"][a:b][pix].astype(np.float64)
        org = h["pos"][a:b][pix] + self.eps * ng
        world = h["pos"][a:b][pix] + self.tracer.centre
        parts = []  # (pixel, direction, length, irradiance) per light
        for light in self.lights:
            w, dist, e = light.incident(world)
            length = np.where(np.isfinite(dist), np.maximum(dist - 2 * self.eps, 0.0), np.inf)
            parts.append((pix, w, length, e))
        p_all = np.concatenate([q[0] for q in parts])
        order = np.argsort(p_all, kind="stable")  # pixel-major, as the kernel takes them
        w_all = np.concatenate([q[1] for q in parts])[order]
        len_all = np.concatenate([q[2] for q in parts])[order]
        wt_all = np.concatenate([q[3] for q in parts])[order]
        at = np.searchsorted(pix, p_all[order])
        # only rays that can add light are traced
        cos_g = np.einsum("ij,ij->i", w_all, ng[at])
        live = (cos_g > 0) & np.any(wt_all > 0, axis=1)
        occ = np.ones(len(w_all), np.uint8)
        if np.any(live) and self.tracer.has_sheets:
            through = self.tracer.transmittance(org[at][live], w_all[live], len_all[live])
            wt_all[live] *= through
            occ[live] = ~np.any(through > 0, axis=1)
        elif np.any(live):
            occ[live] = self.tracer.occluded(org[at][live], w_all[live], len_all[live])
        self.rays += int(np.count_nonzero(live))
        count = np.bincount(p_all, minlength=b - a).astype(np.int64)
        _core.light_accumulate(
            *(h[k][a:b] for k in _HIT_KEYS),
            *self.materials,
            count,
            np.ascontiguousarray(w_all, np.float32),
            np.ascontiguousarray(wt_all, np.float32),
            occ,
            out[a:b],
            self.threads,
            hit_albedo=None if h.get("albedo") is None else h["albedo"][a:b],
            mat_lobe=self.lobe,
        )
