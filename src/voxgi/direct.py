"""Direct light on the records by shadow rays to the emitters' exact geometry.

The discrete shooting carries direct light along the same voxel lines as the
gathering, so an occluder thinner than a voxel stops whole lines and a lamp's
light lands on the wrong side of thin bars. Direct light has a closed-form
integrand and the exact geometry is at hand, so it is integrated here by
Monte Carlo over the emitters' surfaces (docs/design.md §5):

.. math:: E(x) = \\int_{A_e} L_e(y)\\, \\frac{\\cos\\theta_x \\cos\\theta_y}{|x - y|^2}
          V(x, y)\\, dA(y),

with points y drawn on the emitter triangles in proportion to their power
(area times the luminance of their radiance) and uniformly inside each, from
a scrambled Sobol' sequence shifted per record (Cranley–Patterson), so the
samples of one record are stratified. The cost is records x samples shadow
rays, whatever the number of emitter records.
"""

from __future__ import annotations

import time

import numpy as np

from . import _core, _validate
from ._qmc import sobol
from .incidence import IncidenceResponse
from .lights import LUMINANCE
from .rays import Tracer, ray_scene
from .scene import Scene
from .voxels import VoxelSet

__all__ = ["EmitterSampler", "check_scene_and_records", "direct_irradiance", "light_irradiance"]

#: The pilot's samples per record: a quarter of ``samples``, at least this many.
_PILOT_SAMPLES = 4
#: At most this many times ``samples`` for one record.
_MOST_SAMPLES = 32


class EmitterSampler:
    """The emitting triangles of a scene, drawn in proportion to their power.

    Parameters
    ----------
    scene : Scene
        Any scene; objects whose material has non-zero emission are emitters.

    Attributes
    ----------
    triangles : (E, 3, 3) float64
        Corner positions of the emitting triangles.
    normal : (E, 3) float64
        Unit winding normals (the side a one-sided emitter lights).
    two_sided : (E,) bool
        Emits on both sides.
    radiance : (E, 3) float64
        Emitted radiance of each triangle.
    area : (E,) float64
    probability : (E,) float64
        Chance of drawing each triangle (power share).
    """

    def __init__(self, scene: Scene):
        tris, rad, two, owner = [], [], [], []
        first = 0  # the object's first triangle in the scene's order
        for o in scene.objects:
            le = np.asarray(o.material.emission, np.float64)
            first += len(o.faces)
            if not np.any(le > 0):
                continue
            owner.append(np.arange(first - len(o.faces), first))
            t = o.vertices[o.faces].astype(np.float64)
            tris.append(t)
            rad.append(np.broadcast_to(le, (len(t), 3)))
            two.append(np.full(len(t), bool(o.two_sided)))
        #: (T,) int32: the emitter index of each scene triangle (in the
        #: order of :meth:`Scene.triangles`), -1 for those that do not emit
        self.emitter_of = np.full(first, -1, np.int32)
        if tris:
            self.emitter_of[np.concatenate(owner)] = np.arange(sum(map(len, owner)), dtype=np.int32)
            self.triangles = np.concatenate(tris)
            self.radiance = np.concatenate(rad).astype(np.float64)
            self.two_sided = np.concatenate(two)
        else:
            self.triangles = np.zeros((0, 3, 3))
            self.radiance = np.zeros((0, 3))
            self.two_sided = np.zeros(0, bool)
        t = self.triangles
        cross = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        twice = np.linalg.norm(cross, axis=1)
        self.area = 0.5 * twice
        self.normal = cross / np.maximum(twice, np.finfo(np.float64).tiny)[:, None]
        # a two-sided triangle sends its radiance into both hemispheres
        power = self.area * (self.radiance @ LUMINANCE) * np.where(self.two_sided, 2.0, 1.0)
        total = float(power.sum())
        self.probability = power / total if total > 0 else power
        self._cdf = np.cumsum(self.probability)
        if len(self._cdf):
            self._cdf[-1] = 1.0
        density = self.probability / np.maximum(self.area, np.finfo(np.float64).tiny)
        #: the arguments of the compiled kernels, in their order
        self.arrays = (
            np.ascontiguousarray(self.triangles),
            np.ascontiguousarray(self.normal),
            self.two_sided.astype(np.uint8),
            np.ascontiguousarray(self.radiance),
            np.ascontiguousarray(self._cdf),
            density,
        )

    def __len__(self) -> int:
        return len(self.triangles)

    def sample(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Map points of the unit cube to emitter points.

        Parameters
        ----------
        u : (..., 3) float64 in [0, 1)
            ``u[..., 0]`` picks the triangle (by power), the other two the
            point inside it (uniform in area).

        Returns
        -------
        idx : (...,) int64
            Triangle drawn.
        y : (..., 3) float64
            Point on it; its area density is ``probability[idx] / area[idx]``.
        """
        idx = np.minimum(np.searchsorted(self._cdf, u[..., 0], side="right"), len(self._cdf) - 1)
        s = np.sqrt(u[..., 1])
        b0 = 1.0 - s
        b1 = u[..., 2] * s
        t = self.triangles[idx]
        y = (
            b0[..., None] * t[..., 0, :]
            + b1[..., None] * t[..., 1, :]
            + ((1.0 - b0 - b1)[..., None] * t[..., 2, :])
        )
        return idx, y


def _sequence(samples: int, seed: int) -> np.ndarray:
    """(samples, 5) Sobol' points in [0, 1), digitally shifted by ``seed``:
    one record's stratified samples (three dimensions pick the light point,
    two the hemisphere direction). The digital shift keeps the sequence's
    stratification; each record adds its own rotation on top."""
    m = max(0, int(np.ceil(np.log2(samples))))
    shift = np.random.default_rng(seed).integers(0, 1 << 32, size=5, dtype=np.uint64)
    pts = sobol(np.arange(1 << m)) ^ shift.astype(np.uint32)
    return (pts[:samples] / 2.0**32).astype(np.float64)


def direct_irradiance(
    scene: Scene,
    vox: VoxelSet,
    *,
    samples: int = 64,
    seed: int = 0,
    threads: int | None = None,
    offset: float | None = None,
    rel_error: float = 0.1,
    receivers: str = "reflecting",
    max_rays: int = 1 << 21,
    response: IncidenceResponse | None = None,
    base_out: np.ndarray | None = None,
) -> tuple[np.ndarray, dict]:
    """Irradiance from the emitters at every record's surface point, by shadow rays.

    Parameters
    ----------
    scene : Scene
        The scene ``vox`` was voxelized from (its exact triangles occlude).
    vox : VoxelSet
        Records; each receives at ``vox.centroid`` on the side of ``vox.normal``.
    samples : int, optional
        Emitter points per record (>= 1), stratified per record.
    seed : int, optional
        Seeds the sequence and its per-record shifts.
    threads : int or None, optional
        Worker threads for the shadow rays (None: all cores).
    offset : float or None, optional
        Shadow-ray offset from both ends, scene units (None: 1e-4 of the
        scene's diagonal).
    rel_error : float, optional
        Records whose standard error, by a pilot of a quarter of ``samples``
        (at least 4), would exceed this share of their irradiance (those next
        to an emitter) get more samples, up to 32 times ``samples``; the
        pilot only chooses the counts, so the estimate stays unbiased.
    receivers : {"reflecting", "all"}, optional
        The records to light: those that reflect (albedo > 0), which is all
        the light transport needs, or every record with area (black ones
        too), which an energy balance needs.
    max_rays : int, optional
        Rays traced per batch (bounds the temporary memory).
    response : IncidenceResponse or None, optional
        Each sample's light weighed by its record's R(μ) / A at the
        sample's cosine (:mod:`voxgi.incidence`): the irradiance times what
        the record reflects of it over its mean albedo. None: plain irradiance.
    base_out : (N, 3) float64 array or None, optional
        With ``response``: filled with the same samples weighed by the
        response of the records' diffuse base (``response.base``), the
        part of the light their base reflects.

    Returns
    -------
    irradiance : (N, 3) float64
        Direct irradiance of every record (radiance units times π); 0 for
        records with no area and, unless ``receivers="all"``, for records
        that reflect nothing (albedo 0).
    stats : dict
        ``rays``, ``samples``, ``emitter_triangles``, ``records_lit``,
        ``refined_records`` (given more samples), ``max_samples``,
        ``seconds``.

    Notes
    -----
    The estimator of a record at x with normal n, for a point y drawn on
    emitter triangle k with area density ``p_k / A_k``, is
    ``L_e max(0, n·w) |n_k·w| / r² · A_k / p_k`` (w the unit direction from
    x to y, ``|n_k·w|`` replaced by 0 on the back of a one-sided emitter),
    averaged over the samples; it is unbiased, and exact for a record
    inside a closed emitting enclosure (every direction sees ``L_e``:
    ``E = π L_e``).
    """
    samples, seed, nthreads = _check(scene, vox, samples, seed, threads, receivers)
    t0 = time.perf_counter()
    est = _Estimate(len(vox))
    emit = EmitterSampler(scene)
    lit = _receiving(vox, receivers)
    stats = {"rays": 0, "samples": samples, "emitter_triangles": len(emit), "records_lit": len(lit)}
    if len(emit) and len(lit):
        if offset is None:
            offset = 1e-4 * float(np.linalg.norm(np.ptp(scene.bounds, axis=0)))
        with _Rays(scene, vox, emit, float(offset), nthreads, response) as rays:
            rng = np.random.default_rng([seed, 1])
            # A pilot decides how many samples each record takes; the
            # estimate is made of fresh samples alone, so that a record's
            # count does not depend on them: refining records because their
            # own first samples look noisy would keep the lucky ones and
            # redraw the unlucky, a bias of +0.3% in a furnace.
            pilot = _Estimate(len(vox))
            per = max(_PILOT_SAMPLES, samples // 4)
            stats["rays"] += rays.estimate(pilot, lit, per, rng, max_rays)
            scale = _hemisphere_scale(pilot, lit, np.asarray(vox.object_id))
            for todo, per in _sample_counts(pilot, lit, rel_error, samples):
                stats["rays"] += rays.estimate(est, todo, per, rng, max_rays, scale)
    if base_out is not None:
        base_out[...] = est.base
    stats["refined_records"] = int(np.count_nonzero(est.counts > samples))
    stats["max_samples"] = int(est.counts.max(initial=0))
    stats["seconds"] = time.perf_counter() - t0
    return est.irradiance, stats


def check_scene_and_records(scene, vox) -> None:
    """Raise TypeError or ValueError unless ``scene`` is a :class:`Scene` and
    ``vox`` a :class:`VoxelSet` voxelized from it (where it records which)."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected voxgi.Scene, got {type(scene).__name__}")
    if not isinstance(vox, VoxelSet):
        raise TypeError(f"vox: expected voxgi.VoxelSet, got {type(vox).__name__}")
    if vox.scene_fingerprint and vox.scene_fingerprint != scene.fingerprint():
        raise ValueError(
            "vox: these records were voxelized from another scene "
            f"(fingerprint {vox.scene_fingerprint!r}, the scene's is "
            f"{scene.fingerprint()!r})"
        )


def _check(scene, vox, samples, seed, threads, receivers) -> tuple[int, int, int]:
    """Validate the arguments of :func:`direct_irradiance`; the checked numbers."""
    check_scene_and_records(scene, vox)
    if receivers not in ("reflecting", "all"):
        raise ValueError(f"receivers: expected 'reflecting' or 'all', got {receivers!r}")
    return (
        _validate.integer(samples, "samples", low=1, high=1 << 16),
        _validate.integer(seed, "seed"),
        _validate.threads(threads),
    )


def _receiving(vox: VoxelSet, receivers: str) -> np.ndarray:
    """Indices of the records to light: those with area, and unless
    ``receivers="all"`` only those that reflect."""
    lit = np.flatnonzero(np.asarray(vox.area) > 0)
    if receivers == "reflecting":
        lit = lit[np.any(np.asarray(vox.albedo)[lit] > 0, axis=1)]
    return lit


class _Estimate:
    """Per record: the running mean irradiance, the mean square of the
    luminance of its samples, and how many samples it took."""

    def __init__(self, n: int):
        self.irradiance = np.zeros((n, 3))
        self.mean_sq = np.zeros(n)
        self.counts = np.zeros(n, np.int64)
        #: (N, 2): the variance of the light and of the hemisphere samples'
        #: own estimates (the pilot's, :func:`_hemisphere_scale`)
        self.strategy_var = np.zeros((n, 2))
        #: (N, 3): the same samples weighed by the base's incidence response
        self.base = np.zeros((n, 3))

    def add(
        self, rec: np.ndarray, mean: np.ndarray, sq: np.ndarray, per: int, var=None, base=None
    ) -> None:
        """Fold the means of ``per`` more samples of records ``rec`` in."""
        w_old = self.counts[rec] / (self.counts[rec] + per)
        self.irradiance[rec] = w_old[:, None] * self.irradiance[rec] + (1 - w_old)[:, None] * mean
        if base is not None:
            self.base[rec] = w_old[:, None] * self.base[rec] + (1 - w_old)[:, None] * base
        self.mean_sq[rec] = w_old * self.mean_sq[rec] + (1 - w_old) * sq
        if var is not None:
            self.strategy_var[rec] = (
                w_old[:, None] * self.strategy_var[rec] + (1 - w_old)[:, None] * var
            )
        self.counts[rec] += per


class _Rays:
    """The records' points and the emitters in the tracer's frame, centred
    on the scene (:mod:`voxgi.rays`), and the tracer."""

    def __init__(
        self,
        scene: Scene,
        vox: VoxelSet,
        emit: EmitterSampler,
        offset: float,
        threads: int,
        response: IncidenceResponse | None = None,
    ):
        self.response = response
        self.tracer = Tracer(scene, threads)
        centre = self.tracer.centre
        self.emitters = (emit.arrays[0] - centre, *emit.arrays[1:])
        self.emitter_of = emit.emitter_of
        # The emitters alone, which the compiled kernel traces a hemisphere
        # ray against before the whole scene: worth it where most rays meet
        # no emitter. Where most triangles emit (a furnace), a ray's nearest
        # emitter costs about its first hit, and the scene's ray would come
        # on top.
        self.emitter_scene = None
        if 0 < len(emit) <= len(self.tracer.tris) // 2:
            self.emitter_scene = ray_scene(np.ascontiguousarray(self.emitters[0], np.float32))
        self.point = np.asarray(vox.centroid, np.float64) - centre
        self.normal = np.asarray(vox.normal, np.float64)
        self.offset, self.threads = offset, threads

    def __enter__(self) -> _Rays:
        return self

    def __exit__(self, *exc) -> None:
        self.tracer.close()

    def estimate(
        self, est: _Estimate, todo: np.ndarray, per: int, rng, max_rays: int, scale=None
    ) -> int:
        """``per`` more samples for each record of ``todo``, in batches of at
        most ``max_rays`` rays; returns the sample pairs taken. With
        ``scale`` (one per record of the scene) each record's hemisphere
        samples weigh that much more in its power heuristic; without, each
        strategy's own variance is measured."""
        base = _sequence(per, int(rng.integers(1 << 31)))
        shifts = rng.random((len(todo), 5))
        step = max(1, max_rays // per)
        for a in range(0, len(todo), step):
            rec = todo[a : a + step]
            args = (
                self.emitters,
                self.point[rec],
                self.normal[rec],
                shifts[a : a + step],
                base,
                self.offset,
            )
            hs = None if scale is None else np.ascontiguousarray(scale[rec])
            out = _batch(args, self, hs, rec)
            est.add(
                rec,
                out[0],
                out[1],
                per,
                out[2] if len(out) > 2 else None,
                out[3] if len(out) > 3 else None,
            )
        return len(todo) * per


def _sample_counts(
    pilot: _Estimate, lit: np.ndarray, rel_error: float, samples: int
) -> list[tuple[np.ndarray, int]]:
    """The records grouped by the samples each takes: enough for the standard
    error the pilot's variance implies to be ``rel_error`` of its estimate,
    at least ``samples``, at most :data:`_MOST_SAMPLES` times it.

    The counts are rounded up to powers of two, so that records next to an
    emitter, where the 1/r² term varies most, get the samples they need in
    a few batches and the rest of the scene keeps ``samples``.
    """
    lum = pilot.irradiance[lit] @ LUMINANCE
    counts = np.maximum(pilot.counts[lit], 1)
    # the sample variance, with Bessel's correction (the pilot is small)
    var = np.maximum(pilot.mean_sq[lit] - lum * lum, 0.0) * counts / np.maximum(counts - 1, 1)
    need = var / np.maximum((rel_error * lum) ** 2, np.finfo(np.float64).tiny)
    need = np.where(lum > 0, need, 0.0)
    size = np.clip(need, samples, _MOST_SAMPLES * samples)
    size = np.minimum(2 ** np.ceil(np.log2(size)).astype(np.int64), _MOST_SAMPLES * samples)
    size = np.maximum(size, samples)
    return [(lit[size == k], int(k)) for k in np.unique(size)]


def _batch(args: tuple, rays: _Rays, scale=None, rec=None) -> tuple:
    """Trace one batch: ``args`` are the kernels' (emitters, points, normals,
    shifts, sequence, offset) for R records and S samples; ``scale`` (R,)
    the hemisphere samples' weights, or None for the default heuristic and
    each strategy's variance; ``rec`` (R,) the records (for their incidence
    response, if ``rays`` has one).

    Returns the mean RGB irradiance (R, 3) and the mean square of its
    luminance (R,), from which the caller judges each record's noise, and
    without ``scale`` the two strategies' variances (R, 2).
    """
    tracer, nthreads, emitter_of = rays.tracer, rays.threads, rays.emitter_of
    resp = {}
    if rays.response is not None:
        resp = {
            "response": rays.response.table,
            "response_row": np.ascontiguousarray(rays.response.row[rec]),
            "response_base": rays.response.base,
        }
    return _core.direct_light_traced(
        *args,
        emitter_of,
        tracer.native,
        rays.emitter_scene,
        threads=nthreads,
        hemisphere_scale=scale,
        strategies=scale is None,
        **resp,
    )


#: The hemisphere samples' weight, relative to the light samples', stays
#: within these bounds (any positive weight keeps the estimate unbiased).
_SCALE_RANGE = (1e-2, 1e2)


def _hemisphere_scale(pilot: _Estimate, lit: np.ndarray, object_id: np.ndarray) -> np.ndarray:
    """(N,) each record's weight on its hemisphere samples, relative to its
    light samples, in the power heuristic: the ratio of the light samples'
    to the hemisphere samples' variance (Grittmann et al. 2019), each
    relative to the record's irradiance, pooled over the records of an
    object (a pilot of a few samples per record cannot tell a hemisphere
    that never met the lamp from one that always sees the same light)."""
    scale = np.ones(len(pilot.counts))
    lum = pilot.irradiance[lit] @ LUMINANCE
    ok = lum > 0
    rec = lit[ok]
    rel = pilot.strategy_var[rec] / (lum[ok] ** 2)[:, None]
    obj = object_id[rec]
    n_obj = int(object_id.max(initial=-1)) + 1
    light = np.bincount(obj, weights=rel[:, 0], minlength=n_obj)
    hemi = np.bincount(obj, weights=rel[:, 1], minlength=n_obj)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(hemi > 0, light / hemi, _SCALE_RANGE[1])
    ratio = np.where(light > 0, ratio, 1.0)
    scale[rec] = np.clip(ratio, *_SCALE_RANGE)[obj]
    return scale


def light_irradiance(
    scene: Scene,
    vox: VoxelSet,
    *,
    samples: int = 64,
    seed: int = 0,
    threads: int | None = None,
    offset: float | None = None,
    receivers: str = "reflecting",
    max_rays: int = 1 << 21,
    response: IncidenceResponse | None = None,
    base_out: np.ndarray | None = None,
) -> tuple[np.ndarray, dict]:
    """Irradiance from the scene's lights and environment at every record's surface point.

    Parameters
    ----------
    scene : Scene
        Its ``lights`` and ``environment`` light; its triangles occlude.
    vox : VoxelSet
        Records; each receives at ``vox.centroid`` on the side of ``vox.normal``.
    samples : int, optional
        :data:`ENVIRONMENT_SAMPLES` times this many environment samples per
        record, and as many cosine-distributed rays; the delta lights take
        one shadow ray each.
    seed : int, optional
    threads, offset, receivers, max_rays, response, base_out
        As for :func:`direct_irradiance`.

    Returns
    -------
    irradiance : (N, 3) float64
    stats : dict
        ``rays``, ``lights``, ``environment_samples``, ``records_lit``, ``seconds``.

    Notes
    -----
    A delta light's irradiance is exact: ``I cos θ / r²`` (times the spot
    falloff) or the sun's ``E cos θ`` where the shadow ray is free; the
    sun's ray runs to infinity (nothing lies outside the scene's bounds).
    The environment's ``∫ L(ω) cos θ dω`` over the directions whose ray
    leaves the scene is estimated in one compiled kernel from directions
    drawn from the environment (luminance × solid angle) and as many drawn
    in proportion to cos θ, combined by the balance heuristic
    (``docs/design.md`` §11).
    """
    samples, seed, nthreads = _check(scene, vox, samples, seed, threads, receivers)
    t0 = time.perf_counter()
    n = len(vox)
    out = np.zeros((n, 3))
    lit = _receiving(vox, receivers)
    env = scene.environment
    stats = {
        "rays": 0,
        "lights": len(scene.lights),
        "environment_samples": ENVIRONMENT_SAMPLES * samples if env is not None else 0,
        "records_lit": len(lit),
    }
    if len(lit) and scene.has_lights:
        if offset is None:
            offset = 1e-4 * float(np.linalg.norm(np.ptp(scene.bounds, axis=0)))
        with Tracer(scene, nthreads) as tracer:
            x = np.asarray(vox.centroid, np.float64)
            nrm = np.asarray(vox.normal, np.float64)
            if scene.lights:
                step = max(1, max_rays // len(scene.lights))
                for a in range(0, len(lit), step):
                    rec = lit[a : a + step]
                    e, rays, eb = _delta_lights(
                        scene, tracer, x[rec], nrm[rec], offset, response, rec
                    )
                    if base_out is not None and eb is not None:
                        base_out[rec] += eb
                    out[rec] += e
                    stats["rays"] += rays
            if env is not None:
                e, eb, rays = _environment(
                    env, tracer, x[lit], nrm[lit], samples, seed, offset, response, lit
                )
                out[lit] += e
                if base_out is not None and eb is not None:
                    base_out[lit] += eb
                stats["rays"] += rays
    stats["seconds"] = time.perf_counter() - t0
    return out, stats


def _through(tracer: Tracer, org: np.ndarray, dirs: np.ndarray, length: np.ndarray) -> np.ndarray:
    """(R, 3): the light that passes the segments (scene-centred origins): 0
    where something opaque lies on them, else the sheets' transmittance."""
    if len(org) == 0:
        return np.zeros((0, 3))
    return tracer.transmittance(org, dirs, length).astype(np.float64)


def _delta_lights(
    scene, tracer, x, nrm, offset, response=None, rec=None
) -> tuple[np.ndarray, int, np.ndarray | None]:
    """Irradiance (R, 3) at points ``x`` with normals ``nrm`` from the delta
    lights (each weighed by ``response`` of records ``rec``, if given), the
    rays traced, and with ``response`` the same weighed by its base's rows
    (else None)."""
    r = len(x)
    e = np.zeros((r, 3))
    eb = None if response is None else np.zeros((r, 3))
    rays = 0
    org = x + offset * nrm - tracer.centre
    for light in scene.lights:
        w, dist, eperp = light.incident(x)
        cos = np.einsum("ij,ij->i", w, nrm)
        live = np.flatnonzero((cos > 0) & np.any(eperp > 0, axis=1))
        length = np.where(np.isfinite(dist[live]), np.maximum(dist[live] - 2 * offset, 0.0), np.inf)
        through = _through(tracer, org[live], w[live], length)
        light_in = eperp[live] * cos[live, None] * through
        if response is None:
            e[live] += light_in
        else:
            e[live] += light_in * response.at(rec[live], cos[live])
            eb[live] += light_in * response.at(rec[live], cos[live], base=True)
        rays += len(live)
    return e, rays, eb


#: Environment samples and cosine-distributed rays per record, each, as a
#: multiple of ``samples``: the sky a record sees through a window is the
#: light most of a room reflects, and the error of its estimate stays in
#: the records the display reads (``docs/design.md`` §11).
ENVIRONMENT_SAMPLES = 4


def _environment(env, tracer, x, nrm, samples, seed, offset, response, rec):
    """The environment's irradiance (R, 3) at records ``rec`` (points ``x``,
    normals ``nrm``), with the base's part where ``response`` is given (else
    None), and the rays traced."""
    n = ENVIRONMENT_SAMPLES * samples
    kw = {}
    if response is not None:
        kw = {
            "response": response.table,
            "response_base": response.base,
            "response_row": np.ascontiguousarray(response.row[rec]),
        }
    e, eb, rays = _core.environment_irradiance(
        *env.sampling_arguments(),
        np.ascontiguousarray(x - tracer.centre, np.float64),
        np.ascontiguousarray(nrm, np.float32),
        n,
        n,
        int(seed) & ((1 << 64) - 1),
        float(offset),
        tracer.native,
        tracer.threads,
        **kw,
    )
    return e, eb, rays
