"""Progressive rendering: frames into the running mean until the estimated
error meets the tolerance (``docs/design.md`` §6)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..scene import Camera, Scene
from .aovs import AOVMean
from .budget import _reflects_light, light_spread, ray_budget
from .estimate import _MIN_BATCHES, _REL_EPS, _Mean, denoised_estimate
from .executor import FrameExecutor, FrameShaderSpec
from .pixel_filter import _FILTER_REACH
from .seen_emission import skip_reason
from .settings import RenderTuning, _check_executor, _check_render, _check_solution, _RenderSettings
from .vpls import VPLSampler, base_share, continuing_objects, followed_sheets

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
        Per-pixel standard error estimate of ``image`` (radiance units), from
        batch means of the frames with a heavy-tail guard (``docs/design.md``
        §6); None with fewer than two frames. It is the display's noise
        only: the voxel solution's own bias, what the image would keep
        after infinitely many frames, is in neither ``stderr`` nor
        ``stats["est_rel_mse"]`` (``docs/design.md`` §6, "What the estimate
        leaves out").
    stats : dict
        ``seconds`` per phase, ray counts, VPLs used, what was skipped,
        ``mirror_objects`` (the mirrors the camera rays go on through,
        ``docs/design.md`` §6). The phases: ``setup``; ``primary`` (camera rays and their hits);
        ``shadow`` (the VPLs' light: shadow rays and the shading of the VPLs
        they find); ``gather`` (gather rays and the shading of their hits);
        ``lights`` where the scene has lights or an environment (their
        shadow rays and samples); ``filter`` where the indirect light is
        filtered; ``total`` and ``display``
        (the same), plus ``voxelize`` and ``solve`` when :func:`voxgi.render`
        ran them. The error estimate: ``est_rel_mse`` (the image's relMSE,
        what ``tol`` bounds), ``est_max_rel_err`` and ``est_tail_rel_err``
        (per-pixel relative errors), ``flagged_pixels`` (heavy-tailed pixels
        the guard does not believe) and ``edge_pixels`` (pixels whose camera
        rays met more than one surface; None when frames came without their
        surfaces), ``docs/design.md`` §6. With ``RenderTuning(denoise=True)``:
        ``est_rel_mse_denoised``, the denoised image's estimated relMSE (what
        ``tol`` then bounds), and ``denoise_checks``, the checks it took;
        None otherwise. ``stopped``: why the frames ended, ``"tol"`` (the
        estimate met it), ``"max_frames"`` (the cap came first: the image
        is short of ``tol``, or ``tol`` was 0) or ``"interrupted"``.
        ``seen_emission`` (None where not controlled): the pixels whose seen
        emission is replaced by its mean over the pixel,
        their samples and rays, and ``est_rel_mse``, the relMSE those means'
        own error adds, which every frame shares and ``est_rel_mse`` leaves
        out (``docs/design.md`` §6).
    solution : Solution or None
        The voxel solution displayed (computed here when none was given).
    albedo : (H, W, 3) float32 or None
        Diffuse albedo of the surfaces each pixel's camera rays met (where
        a ray went on through a mirror, of the surface it met there: every
        AOV describes the hit the pixel shows), averaged
        over the frames' camera samples with the image's pixel filter (so an
        edge pixel holds the coverage-weighted mean of its surfaces; 0 where
        a ray met nothing). None when the frames came without their AOVs.
    normal : (H, W, 3) float32 or None
        Shading normal (world space, facing the camera) of those hits,
        averaged the same way and not renormalised (shorter than 1 at an
        edge between surfaces; 0 where nothing was met).
    depth : (H, W) float32 or None
        Distance of the hits along the camera's view axis, averaged over the
        samples that met a surface (scene units; inf where none did).
    object_id : (H, W) int32 or None
        Index in ``scene.objects`` of the object the first frame's camera ray
        met in each pixel (-1: nothing, or a one-sided back); not averaged.
    emission : (H, W, 3) float32 or None
        The part of ``image`` that is emitted radiance seen directly (an
        emitter's, or the environment's where a ray leaves the scene),
        averaged the same way; where the emission a pixel sees is
        controlled (``stats["seen_emission"]``), its controlled mean. The
        rest of the image is reflected light, and a denoiser is given only
        that rest (``docs/design.md`` §6).
    undenoised : (H, W, 3) float32 or None
        With ``RenderTuning(denoise=True)``: the image before denoising,
        whose error ``stderr`` and ``stats["est_rel_mse"]`` estimate; ``image``
        is then OIDN's output. None otherwise.
    """

    image: np.ndarray
    frames: int = 0
    stderr: np.ndarray | None = None
    stats: dict = field(default_factory=dict)
    solution: object = None
    albedo: np.ndarray | None = None
    normal: np.ndarray | None = None
    depth: np.ndarray | None = None
    object_id: np.ndarray | None = None
    emission: np.ndarray | None = None
    undenoised: np.ndarray | None = None

    def exr_layers(self) -> dict:
        """The AOVs as EXR channels for :func:`voxgi.io.write_exr`'s
        ``layers``: ``albedo.R/G/B``, ``normal.X/Y/Z``, ``emission.R/G/B``,
        ``depth.Z`` and ``object_id`` (as float32, exact for any object
        count under 2^24), and ``undenoised.R/G/B`` when the image was
        denoised."""
        out = {}
        if self.undenoised is not None:
            out.update({f"undenoised.{c}": self.undenoised[..., i] for i, c in enumerate("RGB")})
        for name, chans in (("albedo", "RGB"), ("normal", "XYZ"), ("emission", "RGB")):
            a = getattr(self, name)
            if a is not None:
                out.update({f"{name}.{c}": a[..., i] for i, c in enumerate(chans)})
        if self.depth is not None:
            out["depth.Z"] = self.depth
        if self.object_id is not None:
            out["object_id"] = self.object_id.astype(np.float32)
        return out


def _with_budget(opt: _RenderSettings, sol) -> _RenderSettings:
    """``opt`` with its VPL and gather counts fixed from the solution's light."""
    spread = light_spread(sol)
    filtered = opt.indirect_filter > 0 and _reflects_light(sol)
    # A denoised render's frames are cut down afterwards as a filtered
    # one's are, so it takes the same cheaper frames (docs/design.md §6).
    k, g = ray_budget(spread, opt.K, opt.gather, filtered=filtered or opt.denoise)
    radius = opt.indirect_filter if filtered else 0
    return replace(opt, K=k, gather=g, spread=spread, indirect_filter=radius)


def _shader_spec(scene: Scene, sol, opt: _RenderSettings) -> FrameShaderSpec:
    """The VPL sampler and the shadow-ray offset of this scene and solution."""
    # pixels follow the lobes their gather rays land on (docs/design.md §14)
    share = None
    if opt.gather > 0 and opt.follow_lobes:
        share = base_share(scene, sol, continuing_objects(scene))
    # gather rays walk on through stacked sheets, and the VPLs on them carry
    # the light walked from their own points (docs/design.md §6)
    sheets = followed_sheets(scene, sol) if opt.gather > 0 and opt.follow_sheets else None
    sampler = VPLSampler(
        sol,
        opt.K,
        opt.seed,
        opt.emitter_share,
        mis=opt.gather > 0,
        pdf=opt.vpl_pdf,
        on_surface=opt.vpl_on_surface,
        follow_share=share,
        walked=sheets,
    )
    diag = float(np.linalg.norm(np.ptp(scene.bounds, axis=0)))
    # Shadow-ray offsets: well above float32 rounding of the coordinates
    # (~1e-7 relative) and well below any feature of a sensible scene.
    return FrameShaderSpec(
        scene,
        opt.cam,
        sampler,
        1e-4 * diag,
        opt.gather,
        opt.seed,
        opt.indirect_filter,
        opt.control_emission,
        opt.guide_environment,
        opt.near_reach,
        opt.mirror_alpha,
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
    scene = spec.scene
    emits = any(np.any(np.asarray(o.material.emission) > 0) for o in scene.objects)
    why = (
        skip_reason(spec.camera, emits, scene.environment)
        if spec.control_emission
        else "seen emission: the control variate is switched off"
    )
    if why is not None:
        skipped.append(why)
    if spec.near_reach > 0 and spec.gather_per_frame > 0 and scene.lights:
        skipped.append(
            "near bounce: the scene has point, spot or directional lights, "
            "which a continued gather ray does not sample; near hits read their records"
        )
    return skipped


@dataclass
class _DenoisedRule:
    """The stopping rule of a denoised render: the estimated relMSE of the
    denoised image (:func:`denoised_estimate`) at or under ``tol``, checked
    once the undenoised rule's floor of batches is met and then where the
    last check predicts it (relMSE ∝ 1/frames, a quarter beyond), since each
    check costs two runs of the denoiser (``docs/design.md`` §6)."""

    tol: float
    shape: tuple
    next: int = 0
    est: float = math.nan
    image: np.ndarray | None = None
    frames: int = -1
    #: seconds spent denoising (the checks and the image delivered)
    seconds: float = 0.0
    checks: int = 0

    def check(self, acc: _Mean, aovs: AOVMean) -> None:
        """Denoise the running mean and estimate its error."""
        t0 = time.perf_counter()
        a = aovs.result(*self.shape[:2])
        self.est, self.image = denoised_estimate(
            acc, self.shape, a["albedo"], a["normal"], a["emission"]
        )
        self.frames = acc.frames
        self.checks += 1
        self.seconds += time.perf_counter() - t0

    def done(self, acc: _Mean, aovs: AOVMean) -> bool:
        if self.tol <= 0 or not acc.ready() or acc.frames < self.next:
            return False
        self.check(acc, aovs)
        if self.est <= self.tol:
            return True
        want = 1.25 * acc.frames * self.est / self.tol if np.isfinite(self.est) else 0
        self.next = int(max(min(want, 1 << 30), acc.frames + acc.size))
        return False


def _progressive_mean(
    source, opt: _RenderSettings, progress: bool
) -> tuple[_Mean, AOVMean, bool, _DenoisedRule | None]:
    """Frames 0, 1, ... from ``source`` into the running mean until the
    stopping rule or ``max_frames``; Ctrl-C stops after the current frame.
    Returns the mean, the AOVs' mean, whether it was interrupted and, for a
    denoised render, its stopping rule (with its last check)."""
    from .. import _progress

    cam = opt.cam
    reach = _FILTER_REACH[cam.pixel_filter]
    acc = _Mean.empty(
        cam.height * cam.width,
        opt.pixel_share,
        opt.threads,
        (cam.height, cam.width, reach) if reach else None,
    )
    aovs = AOVMean()
    rule = _DenoisedRule(opt.tol, (cam.height, cam.width, 3)) if opt.denoise else None
    interrupted = False
    # The bar counts frames against the frames the render is predicted to
    # need (the stopping rule's floor, then relMSE ∝ 1/frames), not against
    # the frame cap that is rarely reached.
    floor = _MIN_BATCHES
    need = _progress.frames_needed(0, math.nan, opt.tol, floor, opt.max_frames)
    bar = _progress.bar("display", need, enabled=progress, unit="frame")
    try:
        for f in range(opt.max_frames):
            x = source.frame(f, opt.seed).astype(np.float64)
            surface = getattr(source, "surface", None)
            acc.add(x, surface)
            aovs.add(getattr(source, "aovs", None), None if surface is None else surface[0])
            if rule is not None:
                stop = rule.done(acc, aovs)
                est = worst = rule.est
            else:
                # the estimate is read only once the rule may stop on it
                stop = False
                est = worst = acc.est if opt.tol > 0 and acc.ready() else math.nan
            if rule is None and np.isfinite(est):
                # the per-pixel bound's error falls as 1/sqrt(frames)
                bound = opt.pixel_factor * math.sqrt(opt.tol)
                worst = max(est, opt.tol * (acc.tail / bound) ** 2)
            bar.total = _progress.frames_needed(f + 1, worst, opt.tol, floor, opt.max_frames)
            bar.update(1)
            known = f", est relMSE {est:.2e}" if np.isfinite(est) else ""
            bar.set_postfix_str(f"frame {f + 1}{known}")
            if stop or (rule is None and acc.done(opt)):
                break
    except KeyboardInterrupt:
        interrupted = True
    finally:
        bar.close()
        source.close()
    return acc, aovs, interrupted, rule


def _render_stats(spec, source, acc: _Mean, opt, skipped, interrupted, seconds, rule) -> dict:
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
        "stopped": _why_stopped(acc, opt, interrupted, rule),
        "denoised": bool(opt.denoise and acc.frames > 0),
        "est_rel_mse_denoised": None if rule is None else rule.est,
        "denoise_checks": None if rule is None else rule.checks,
        "threads": opt.threads,
        "seen_emission": _seen_emission_stats(source, acc),
        "mirror_objects": int(
            np.count_nonzero(getattr(source, "mirrors", {}).get("obj_mirror", []))
        ),
        "environment_guide": _guide_stats(source),
    }


def _guide_stats(source) -> dict | None:
    """The environment guide's open share, learning rays and seconds, where
    the frames were shaded here and it applied."""
    guide = getattr(getattr(source, "lights", None), "guide", None)
    if guide is None:
        return None
    return {"open_share": guide.open_share, "rays": guide.rays, "seconds": guide.seconds}


def _why_stopped(acc: _Mean, opt, interrupted: bool, rule) -> str:
    """Why the frames ended: ``"tol"`` (the estimate met it), ``"max_frames"``
    (the cap came first, or ``tol`` 0 asked for it) or ``"interrupted"``."""
    if interrupted:
        return "interrupted"
    if opt.tol > 0 and acc.frames > 0:
        met = rule.est <= opt.tol if rule is not None else acc.done(opt)
        if met:
            return "tol"
    return "max_frames"


def _seen_emission_stats(source, acc: _Mean) -> dict | None:
    """The emission control's pixels, samples, rays and seconds, where the
    frames were shaded here and it applied, and ``est_rel_mse``: the relMSE
    its means' own error adds to the image, shared by every frame (None
    with the Gaussian filter, or before any frame)."""
    ctl = getattr(source, "emission_control", None)
    if ctl is None:
        return None
    est = None
    if ctl.variance is not None and acc.frames > 0:
        image = acc.mean
        level = image[ctl.pixels]
        est = float((ctl.variance / (level * level + _REL_EPS)).sum() / image.size)
    return {
        "pixels": len(ctl.pixels),
        "sampled": ctl.sampled,
        "samples": ctl.samples,
        "rays": ctl.rays,
        "seconds": ctl.seconds,
        "mirrored": ctl.mirrored,
        "mirror_samples": ctl.mirror_samples,
        "few": ctl.few,
        "est_rel_mse": est,
    }


def render(
    scene,
    sol,
    *,
    tol: float | None = None,
    max_frames: int | None = None,
    camera: Camera | None = None,
    seed: int = 0,
    threads: int | None = None,
    progress: bool = True,
    executor: FrameExecutor | None = None,
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
    tol : float or None
        Bound on the estimated relMSE of the remaining noise (default 1e-3; 0:
        run ``max_frames``).
    max_frames : int or None
        At most this many frames (default 256).
    camera : Camera, optional
        Overrides ``scene.camera``.
    seed : int
        Seeds the VPL, sub-pixel and lens sequences.
    threads : int or None
        Worker threads (None: all cores); the image does not depend on it.
    progress : bool
        A progress bar on a terminal or in a notebook.
    executor : FrameExecutor or None
        Where the frames are computed (None: here); the image is the local one.
    tuning : RenderTuning or None
        The estimator's choices (:class:`RenderTuning`: VPLs and gather rays
        per frame, the emitters' share, the indirect filter).

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
    opt = _check_render(scene, sol, camera, max_frames, tol, seed, threads, tuning)
    executor = _check_executor(executor)
    _check_solution(scene, sol, opt.cam)
    opt = _with_budget(opt, sol)
    t0 = time.perf_counter()
    spec = _shader_spec(scene, sol, opt)
    source = executor.frames(spec, opt.max_frames, threads=opt.threads)
    seconds = {"setup": time.perf_counter() - t0}
    skipped = _skipped(spec)
    if getattr(source, "env_guide_skipped", None):
        skipped.append(source.env_guide_skipped)
    acc, aovs, interrupted, rule = _progressive_mean(source, opt, progress)
    image = acc.mean.reshape(opt.cam.height, opt.cam.width, 3).astype(np.float32)
    aov = aovs.result(opt.cam.height, opt.cam.width)
    seconds.update(source.seconds)
    undenoised = None
    if rule is not None and acc.frames > 0:
        if rule.frames != acc.frames:  # the last frames came after the last check
            rule.check(acc, aovs)
        undenoised, image = image, rule.image
        seconds["denoise"] = rule.seconds
    seconds["total"] = time.perf_counter() - t_start
    seconds["display"] = seconds["total"]
    stats = _render_stats(spec, source, acc, opt, skipped, interrupted, seconds, rule)
    return RenderResult(
        image=image,
        frames=acc.frames,
        stderr=acc.stderr(image.shape),
        stats=stats,
        solution=sol,
        undenoised=undenoised,
        **aov,
    )
