"""The light of the scene's lights and environment at one frame's hits: a
shadow ray to each delta light and environment samples MIS-combined with the
gather rays (``docs/design.md`` §11)."""

from __future__ import annotations

import math

import numpy as np

from .. import _core
from ..rays import Tracer
from ..scene import Scene

__all__: list[str] = []

#: What the shading kernels read of a pixel's primary hit.
_HIT_KEYS = ("pos", "normal", "ng", "wo", "material")


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
        pdf, solid_angle = self.env.density_tables()
        return {
            "env_radiance": self.env.image,
            "env_to_world": np.ascontiguousarray(self.env.to_world, np.float64),
            "env_texel_pdf": pdf,
            "env_row_solid_angle": solid_angle,
            "env_samples": float(self.n_env),
        }

    def _env_weight(self, dirs: np.ndarray, cos: np.ndarray, gathering: int) -> np.ndarray:
        """(R, 3) environment radiance over the balance heuristic's combined
        density of the environment samples and the gather rays,
        ``n_e p_e(ω) + n_g cos θ / π`` (docs/design.md §11)."""
        dens = self.n_env * self.env.pdf(dirs) + gathering * np.maximum(cos, 0.0) / math.pi
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(dens > 0, 1.0 / dens, 0.0)
        return self.env.eval(dirs) * inv[:, None]

    def _rays(self, h: dict, a: int, b: int, pix: np.ndarray, frame: int, gathering: int):
        """(pixel, direction, length, weight) of each ray of pixels ``pix``
        of [a, b), one part per light and one for the environment."""
        pos = h["pos"][a:b][pix]
        n = h["normal"][a:b][pix].astype(np.float64)
        world = pos + self.tracer.centre
        parts = []
        for light in self.lights:
            w, dist, e = light.incident(world)
            length = np.where(np.isfinite(dist), np.maximum(dist - 2 * self.eps, 0.0), np.inf)
            parts.append((pix, w, length, e))
        if self.env is not None:
            k = self.n_env
            rng = np.random.default_rng([self.seed, frame, a, 0xE4F])
            w, _ = self.env.sample(_stratified(rng, len(pix), k))
            cos = np.einsum("ij,ij->i", w, np.repeat(n, k, axis=0))
            weight = self._env_weight(w, cos, gathering)
            parts.append((np.repeat(pix, k), w, np.full(len(w), np.inf), weight))
        return parts

    def add(self, h: dict, a: int, b: int, out: np.ndarray, frame: int, gathering: int) -> None:
        """Add the light of pixels [a, b) into ``out[a:b]``: one shadow ray
        to each delta light, :attr:`n_env` environment samples weighted
        against ``gathering`` gather rays per pixel."""
        pix = np.flatnonzero(h["material"][a:b] >= 0)
        if len(pix) == 0:
            return
        ng = h["ng"][a:b][pix].astype(np.float64)
        org = h["pos"][a:b][pix] + self.eps * ng
        parts = self._rays(h, a, b, pix, frame, gathering)
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
        if np.any(live):
            occ[live] = self.tracer.occluded(org[at][live], w_all[live], len_all[live])
        self.rays += int(np.count_nonzero(live))
        count = np.bincount(p_all, minlength=b - a).astype(np.int64)
        hh = [h[k][a:b] for k in _HIT_KEYS]
        _core.light_accumulate(
            *hh,
            *self.materials,
            count,
            np.ascontiguousarray(w_all, np.float32),
            np.ascontiguousarray(wt_all, np.float32),
            occ,
            out[a:b],
            self.threads,
        )
