"""The settings of a render: :class:`RenderTuning` and the checks of
:func:`voxgi.display.render`'s arguments."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from .. import _validate
from ..radiosity import Solution
from ..scene import Camera, Scene
from ..voxels import available_memory
from .estimate import PIXEL_FACTOR, PIXEL_SHARE
from .executor import FrameExecutor, LocalFrames

__all__ = ["DEFAULT_TOL", "RenderTuning"]

#: The display's tolerance when none is given: the estimated relMSE of the
#: picture's remaining noise.
DEFAULT_TOL = 1e-3

#: Gather rays that land nearer than this many voxel pitches continue one
#: bounce (:attr:`_Experiment.near_reach`): a record averages its voxel,
#: which a hit that near sees under a wide angle.
NEAR_REACH = 1.0

#: A conductor whose lobe's alpha is at most this is a mirror that camera
#: rays go on through (:attr:`RenderTuning.mirror_alpha`): what it shows is
#: shaded where the reflected ray lands, not read from that surface's records.
MIRROR_ALPHA = 0.05


@dataclass(frozen=True)
class RenderTuning:
    """What a study may choose about :func:`render`'s estimator.

    Attributes
    ----------
    vpls_per_frame : int or None
        VPLs per frame and pixel (1 to 65536; None: from the light's spread,
        :func:`ray_budget`).
    gather : int or None
        Cosine-distributed gather rays per pixel and frame, MIS-combined
        with the VPLs (0 to 4096; 0: VPLs only, the paper's display; None:
        from the light's spread, :func:`ray_budget`).
    emitter_share : float or None
        Share of each frame's VPLs taken from emitters; None splits by power
        (see :class:`VPLSampler`).
    indirect_filter : int or None
        Each frame, the light of the records that do not emit (the indirect
        light) is averaged over the pixels within this many pixels that see
        the same smooth surface: the same material, a normal within about
        25°, near the pixel's tangent plane (``docs/design.md`` §6). 0: off.
        The direct light, from the emitting records and the lights, is
        never filtered. None (the default): 1, or 0 with ``denoise``, which
        needs the per-pixel independent noise that the filter would spread
        over neighbours.
    denoise : bool
        Denoise the finished image with Intel Open Image Denoise, guided by
        the render's own albedo and normal AOVs (:mod:`voxgi.denoise`; needs
        ``pip install "voxgi[denoise]"``). The stopping rule then bounds the
        estimated relMSE of the denoised image, the picture delivered
        (``stats["est_rel_mse_denoised"]``, ``docs/design.md`` §6); the
        result keeps the undenoised image (``undenoised``) with its
        ``stderr`` and ``stats["est_rel_mse"]``. Its frames take the
        filtered render's cheaper ray budget (:func:`ray_budget`).

    >>> RenderTuning(gather=0).indirect_filter is None
    True
    """

    vpls_per_frame: int | None = None
    gather: int | None = None
    emitter_share: float | None = None
    indirect_filter: int | None = None
    denoise: bool = False


@dataclass(frozen=True)
class _Experiment(RenderTuning):
    """:class:`RenderTuning` with the switches of the benchmarks' experiments:
    the paper's choices where the defaults depart from them, and the
    stopping rule's per-pixel bound. Not part of the API.

    Attributes
    ----------
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
    control_emission : bool
        At pixels that see emission over part of their footprint, each
        frame's seen emission is replaced by its mean over the pixel (default;
        :mod:`voxgi.display.seen_emission`); False keeps each frame's own.
    follow_lobes : bool
        A pixel's gather ray that lands on a glossy surface reads the base's
        share of its record and follows that surface's lobe one bounce
        further (default; ``docs/design.md`` §14); False reads the record's
        mean whatever the direction.
    follow_sheets : bool
        A pixel's gather ray that lands on a sheet of a stack finer than a
        voxel (a slat of a blind) walks on through the stack, and the VPLs
        on those records carry the light walked from their own points
        (default; ``docs/design.md`` §6): the light they pass on is right,
        at the price of some noise and time (in Bitterli's Contemporary
        Bathroom a sixth more noise at 64 frames, in the Country Kitchen a
        quarter more time a frame). False reads the records' means, which
        can leave a room lit through blinds a few percent off.
    guide_environment : bool
        Each pixel's environment samples are drawn where the environment's
        light reaches its place (default; :mod:`voxgi.display.environment_guide`);
        False draws them by the environment's brightness alone.
    near_reach : float
        A gather ray that lands on a diffuse surface that does not emit
        nearer than this many voxel pitches continues one bounce there
        instead of reading the record (default 1; ``docs/design.md`` §6);
        0 always reads the record.
    mirror_alpha : float
        A conductor whose lobe's alpha is at most this (a smooth metal, a
        mirror; Mitsuba's ``conductor``) is a mirror: a camera ray that meets
        it goes on in a direction drawn from its lobe, and the pixel shows
        the surface the ray lands on, shaded as if seen directly, times the
        mirror's reflectance (default 0.05; ``docs/design.md`` §6). 0: camera
        rays stop at every surface, and a mirror's pixels read its lobe's
        gather rays (§14).
    """

    vpl_pdf: str = "power"
    vpl_on_surface: bool = True
    pixel_factor: float = PIXEL_FACTOR
    pixel_share: float = PIXEL_SHARE
    control_emission: bool = True
    follow_lobes: bool = True
    follow_sheets: bool = True
    guide_environment: bool = True
    near_reach: float = NEAR_REACH
    mirror_alpha: float = MIRROR_ALPHA


@dataclass(frozen=True)
class _RenderSettings:
    """The validated arguments of one render."""

    cam: Camera
    K: int | None
    max_frames: int
    tol: float
    seed: int
    pixel_factor: float
    pixel_share: float
    emitter_share: float | None
    gather: int | None
    vpl_pdf: str
    vpl_on_surface: bool
    threads: int
    indirect_filter: int = 0
    spread: float = math.nan
    denoise: bool = False
    control_emission: bool = True
    follow_lobes: bool = True
    follow_sheets: bool = True
    guide_environment: bool = True
    near_reach: float = NEAR_REACH
    mirror_alpha: float = MIRROR_ALPHA


def _check_render(scene, sol, camera, max_frames, tol, seed, threads, tuning) -> _RenderSettings:
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
    t = _Experiment() if tuning is None else tuning
    if not isinstance(t, RenderTuning):
        raise TypeError(f"tuning: expected voxgi.RenderTuning or None, got {type(t).__name__}")
    if not isinstance(t, _Experiment):
        t = _Experiment(**{f.name: getattr(t, f.name) for f in fields(RenderTuning)})
    tol = _validate.real(tol, "tol", low=0.0, allow_none=True)
    denoise = _check_denoise(t.denoise)
    radius = _validate.integer(
        t.indirect_filter, "indirect_filter", low=0, high=16, allow_none=True
    )
    return _RenderSettings(
        cam=cam,
        K=_validate.integer(
            t.vpls_per_frame, "vpls_per_frame", low=1, high=1 << 16, allow_none=True
        ),
        max_frames=_validate.integer(max_frames, "max_frames", low=1, allow_none=True) or 256,
        tol=DEFAULT_TOL if tol is None else tol,
        seed=_validate.integer(seed, "seed"),
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
        indirect_filter=(0 if denoise else 1) if radius is None else radius,
        denoise=denoise,
        control_emission=bool(t.control_emission),
        follow_lobes=bool(getattr(t, "follow_lobes", True)),
        follow_sheets=bool(getattr(t, "follow_sheets", True)),
        guide_environment=bool(getattr(t, "guide_environment", True)),
        near_reach=_validate.real(t.near_reach, "near_reach", low=0.0),
        mirror_alpha=_validate.real(t.mirror_alpha, "mirror_alpha", low=0.0),
    )


def _check_denoise(denoise) -> bool:
    """``RenderTuning.denoise`` as a bool; with it, OIDN must import (before
    any frame is spent)."""
    if not isinstance(denoise, (bool, np.bool_)):
        raise TypeError(f"denoise: expected True or False, got {denoise!r}")
    if denoise:
        from .. import denoise as _denoise

        _denoise.load_oidn()  # ImportError naming the extra
    return bool(denoise)


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
