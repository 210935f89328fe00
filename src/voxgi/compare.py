"""Render one scene with voxgi's defaults and with Mitsuba 3, and compare (``voxgi compare``).

This module sits above the pipeline (:mod:`voxgi.pipeline`) and imports
Mitsuba lazily; Mitsuba and OIDN are the optional ``bench`` extra. The
comparison follows ``docs/design.md`` §9: a Mitsuba reference at high spp,
voxgi's relMSE against it, and Mitsuba's own time to reach voxgi's relMSE and
fixed targets, plain and denoised by OIDN with albedo and normal buffers from
Mitsuba's ``aov`` integrator (their time included), from renders at a
series of spp (log-log interpolation between the two that bracket a target).
Every error is also given as SSIM and, with ``flip-evaluator``, FLIP, which
see the detail a denoiser blurs away where relMSE barely does.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import _validate
from .display import RenderTuning, camera_rays
from .metrics import flip, rel_mse, ssim
from .pipeline import render as pipeline_render
from .pipeline import solve
from .radiosity import SolveTuning
from .rays import Tracer
from .resolution import solve_scene
from .scene import Scene
from .voxels import voxelize

__all__ = ["Comparison", "compare"]

#: relMSE targets whose time :func:`compare` reports for each renderer.
TARGETS = (5e-3, 1e-3)
#: Mitsuba's sample counts, in order (the sweep stops once every target is met).
SWEEP_SPP = (4, 16, 64, 256, 1024)

#: Display tolerances looser than the default at which :func:`compare` shows
#: voxgi's solution again, so that its time to each target is measured the
#: way Mitsuba's is (a user who wants 5e-3 sets ``tol``, as one sets ``spp``).
SWEEP_TOL = (1e-2, 3e-3)


@dataclass
class Comparison:
    """Result of :func:`compare`.

    Attributes
    ----------
    rows : list of dict
        voxgi's, each of Mitsuba's sweep renders (``"mitsuba"`` plain,
        ``"mitsuba+oidn"`` denoised) and the reference's: ``method``,
        ``spp`` (Mitsuba), ``seconds``, ``rel_mse`` against the reference,
        ``rel_mse_net`` (less the reference's own noise, floored at 0),
        ``ssim``, ``flip`` (None without ``flip-evaluator``), ``brightness``
        (3,) the ratio of summed radiance to the reference's over the pixels
        whose whole footprint sees surfaces that do not emit. voxgi's row also
        has ``frames`` and ``phases`` (seconds of voxelize, solve, display).
    voxgi, reference : (H, W, 3) float32
        The two images.
    sweep : list of (spp, seconds, rel_mse_net)
        Mitsuba's plain renders.
    sweep_denoised : list of (spp, seconds, rel_mse_net)
        Mitsuba's denoised renders (render with AOVs plus OIDN), empty when
        not asked for.
    sweep_voxgi : list of (tol, seconds, rel_mse_net)
        voxgi's solution displayed at each of the looser tolerances asked
        for and at the default (last); each one's seconds are its display's
        plus the voxelize and solve of the default run.
    sweep_voxgi_denoised : list of (tol, seconds, rel_mse_net)
        The same for the denoised display (``voxgi_denoise``), else empty.
    time_to : dict
        ``{method: {target: seconds or None}}`` for ``"mitsuba"`` and
        ``"mitsuba+oidn"``, targets ``"voxgi"`` (voxgi's own net relMSE; and
        ``"voxgi+oidn"``'s with ``voxgi_denoise``) and each of
        :data:`TARGETS`; None where the sweep did not reach it. ``"voxgi"``
        has each of :data:`TARGETS`, interpolated alike over ``sweep_voxgi``,
        and ``"voxgi+oidn"`` over ``sweep_voxgi_denoised``.
    reference_noise : float
        The reference's own relMSE: a quarter of the relMSE between its two
        halves.
    files : dict
        Paths written (``out_dir``).
    """

    rows: list
    voxgi: np.ndarray
    reference: np.ndarray
    sweep: list
    sweep_denoised: list
    time_to: dict
    reference_noise: float
    sweep_voxgi: list = field(default_factory=list)
    sweep_voxgi_denoised: list = field(default_factory=list)
    files: dict = field(default_factory=dict)

    @property
    def mitsuba_seconds_to_match(self) -> float | None:
        """Plain Mitsuba's time to voxgi's relMSE (None if not reached)."""
        return self.time_to["mitsuba"]["voxgi"]

    def table(self) -> str:
        """The rows as an aligned text table, then the times to each target."""
        head = (
            f"{'method':<13} {'spp/tol':>7} {'seconds':>9} {'relMSE':>10} {'net':>10} "
            f"{'SSIM':>6} {'FLIP':>6}  brightness (R, G, B)"
        )
        lines = [head, "-" * len(head)]
        for r in self.rows:
            spp = f"{r['tol']:.0e}" if r.get("tol") else str(r["spp"] or "")
            b = ", ".join(f"{x:.4f}" for x in r["brightness"])
            fl = "" if r["flip"] is None else f"{r['flip']:.4f}"
            lines.append(
                f"{r['method']:<13} {spp:>7} {r['seconds']:9.2f} {r['rel_mse']:10.3e} "
                f"{r['rel_mse_net']:10.3e} {r['ssim']:6.4f} {fl:>6}  ({b})"
            )
        v = self.rows[0]
        ph = v["phases"]
        lines.append(
            f"voxgi seconds: voxelize {ph['voxelize']:.2f}, solve {ph['solve']:.2f}, "
            f"display {ph['display']:.2f} ({v['frames']} frames)"
        )
        for method, times in self.time_to.items():
            parts = []
            for target, t in times.items():
                what = f"{target}'s relMSE" if isinstance(target, str) else f"relMSE {target:.0e}"
                parts.append(f"{what}: " + ("not reached" if t is None else f"{t:.3g} s"))
            lines.append(f"{method} to " + "; ".join(parts) + " (interpolated)")
        lines.append(
            f"reference noise (estimated relMSE, subtracted as net): {self.reference_noise:.2e}"
        )
        return "\n".join(lines)


#: Sub-pixel points whose rays must all meet a surface that does not emit
#: for a pixel to count in the brightness: its centre and its corners.
_FOOTPRINT = ((0.5, 0.5), (0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0))


def _non_emitter_mask(scene: Scene, cam) -> np.ndarray:
    """(H, W) bool: pixels whose whole footprint sees surfaces that do not emit.

    A pixel at a lamp's edge takes the lamp's radiance, many times the rest,
    in the share of its samples that land on the lamp: a sum over pixels that
    includes such pixels follows that share's noise (up to 1% of the Cornell
    box's sum after 9 frames), not the surfaces' light. A pixel counts when
    the rays through its centre and its four corners all meet a surface that
    does not emit, and with the Gaussian pixel filter, whose samples reach 2
    pixels out, so do its neighbours within 2 pixels.
    """
    obj = scene.triangle_objects()
    emit = np.array([o.material.is_emitter for o in scene.objects])
    ok = np.ones(cam.height * cam.width, bool)
    with Tracer(scene, 1) as tr:
        for offset in _FOOTPRINT:
            org, dirs = camera_rays(cam, offset)
            prim = tr.intersect(
                np.ascontiguousarray(org - tr.centre, np.float32),
                np.ascontiguousarray(dirs, np.float32),
            )
            hit = prim >= 0
            ok &= hit
            ok[hit] &= ~emit[obj[prim[hit]]]
    ok = ok.reshape(cam.height, cam.width)
    if cam.pixel_filter == "gaussian":
        r = 2
        pad = np.pad(ok, r, constant_values=True)
        for dy in range(-r, r + 1):
            for dx in range(-r, r + 1):
                ok = ok & pad[r + dy : r + dy + cam.height, r + dx : r + dx + cam.width]
    return ok


def _brightness(img: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> list[float]:
    a = img[mask].sum(axis=0, dtype=np.float64)
    b = ref[mask].sum(axis=0, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return [float(x) for x in np.where(b > 0, a / b, np.nan)]


def _seconds_to(err: float, sweep: list) -> float | None:
    """Time of the sweep at relMSE ``err``, log-log between the bracketing renders."""
    for (_s0, t0, e0), (_s1, t1, e1) in itertools.pairwise(sweep):
        if e0 >= err >= e1 and e0 > 0 and e1 > 0 and e0 != e1:
            f = math.log(e0 / err) / math.log(e0 / e1)
            return math.exp(math.log(t0) + f * (math.log(t1) - math.log(t0)))
        if e0 >= err and e1 <= 0:
            return t1  # (below the reference's own noise: no slope to follow)
    if sweep and sweep[0][2] <= err:
        # the first render meets it already: the quickest render that does
        # (voxgi's looser tolerances may show the same frames as its default)
        return min(t for _s, t, e in sweep if e <= err)
    return None


def compare(
    scene: Scene,
    *,
    spp: int = 1024,
    reference: tuple[np.ndarray, float] | None = None,
    sweep_spp=SWEEP_SPP,
    denoise: bool = True,
    resolution: int | None = None,
    width: int | None = None,
    height: int | None = None,
    seed: int = 0,
    threads: int | None = None,
    out_dir=None,
    plot: bool = False,
    progress: bool = False,
    variant: str | None = None,
    sweep_tol=SWEEP_TOL,
    voxgi_denoise: bool = False,
) -> Comparison:
    """Render ``scene`` with voxgi's defaults and with Mitsuba 3, and compare.

    Parameters
    ----------
    scene : Scene
        With a camera. Left unchanged.
    spp : int
        Samples per pixel of Mitsuba's reference (>= 2; rendered as two
        halves of different seeds, whose difference estimates its noise).
    reference : (image, noise) or None
        A reference rendered already (of this scene and camera size) and its
        own relMSE, instead of rendering one.
    sweep_spp : sequence of int
        Mitsuba's sample counts, increasing; each of the plain and the
        denoised sweeps stops once it has met voxgi's relMSE and every one
        of :data:`TARGETS`.
    denoise : bool
        Also run the denoised sweep (needs ``mitsuba-oidn``).
    resolution : int or None
        voxgi's voxel resolution (None: the pipeline's default).
    width, height : int or None
        Override the camera's image size.
    seed : int
        voxgi's seed; Mitsuba's sweep and reference use others.
    threads : int or None
        voxgi's threads (Mitsuba uses its own pool).
    out_dir : path or None
        Where to write ``voxgi.exr``, ``reference.exr``, ``difference.png``
        (``|voxgi − reference|``, tone-mapped) and, with ``plot``,
        ``time_vs_error.png``.
    plot : bool
        Also plot relMSE against time (matplotlib): voxgi's ``sweep_voxgi``,
        Mitsuba's sweeps.
    progress : bool
    variant : str or None
        Mitsuba variant (None: ``llvm_ad_rgb`` where it works).
    sweep_tol : sequence of float
        Tolerances, looser than the default, at which voxgi runs again for
        its time to each target, solving anew where the looser tolerance
        asks for a lighter solve (:meth:`voxgi.SolveTuning.for_picture`;
        ``()``: its default run's seconds alone, an upper bound).
    voxgi_denoise : bool
        Also display voxgi's solution denoised (``RenderTuning(denoise=True)``,
        needs ``mitsuba-oidn``): the row ``"voxgi+oidn"``, its seconds those of
        the voxelize, the solve and its own display, beside Mitsuba + OIDN.

    Returns
    -------
    Comparison

    Raises
    ------
    ImportError
        Mitsuba (or, with ``denoise``, OIDN) is not installed
        (``pip install 'voxgi[bench]'``).
    """
    from .mitsuba import to_mitsuba

    spp, counts, cam, mi = _checked(
        scene, spp, sweep_spp, width, height, variant, denoise or voxgi_denoise
    )
    tols = _checked_tols(sweep_tol)
    out, t_voxgi = _render_voxgi(scene, cam, resolution, seed, threads, progress)
    plain = mi.load_dict(to_mitsuba(scene, spp=1, camera=cam))
    ref, ref_noise, ref_seconds = _reference(mi, plain, spp, reference, out.image.shape)
    mask = _non_emitter_mask(scene, cam)
    rows = [_voxgi_row(out, t_voxgi, ref, ref_noise, mask)]
    if voxgi_denoise:
        den, t_den = _voxgi_denoised(scene, out, cam, seed, threads, progress)
        rows.append(_voxgi_denoised_row(den, t_den, rows[0]["phases"], ref, ref_noise, mask))
    goal = min(*(r["rel_mse_net"] for r in rows), *TARGETS)
    solved = {}
    sweeps = {
        "voxgi": _voxgi_sweep(
            scene, out, cam, seed, threads, tols, ref, ref_noise, mask, rows, solved=solved
        )
    }
    if voxgi_denoise:
        sweeps["voxgi+oidn"] = _voxgi_sweep(
            scene, out, cam, seed, threads, tols, ref, ref_noise, mask, rows, rows[1], solved
        )
    sweeps |= _sweeps(mi, plain, scene, cam, counts, denoise, goal, ref, ref_noise, mask, rows)
    rows.append(_reference_row(spp if reference is None else None, ref_seconds, ref_noise))
    result = _comparison(rows, out.image, ref, ref_noise, sweeps)
    if out_dir is not None:
        result.files = _write(result, Path(out_dir), plot)
    return result


def _comparison(rows, img, ref, ref_noise: float, sweeps: dict) -> Comparison:
    """The :class:`Comparison` of the rows and sweeps, with each method's time to each target."""
    # each voxgi method's own error is that of its run at the defaults (its
    # first row; the looser tolerances follow it)
    own = {}
    for r in rows:
        if r["method"].startswith("voxgi"):
            own.setdefault(r["method"], r["rel_mse_net"])
    targets = {**own, **{t: t for t in TARGETS}}
    time_to = {
        m: {k: _seconds_to(e, sw) for k, e in targets.items()}
        for m, sw in sweeps.items()
        if not m.startswith("voxgi")
    }
    for m in ("voxgi", "voxgi+oidn"):
        if m in sweeps:
            time_to[m] = {t: _seconds_to(t, sweeps[m]) for t in TARGETS}
    return Comparison(
        rows,
        img,
        ref,
        sweeps["mitsuba"],
        sweeps.get("mitsuba+oidn", []),
        time_to,
        ref_noise,
        sweep_voxgi=sweeps["voxgi"],
        sweep_voxgi_denoised=sweeps.get("voxgi+oidn", []),
    )


def _checked_tols(sweep_tol) -> tuple[float, ...]:
    """``sweep_tol`` as positive finite floats, loosest first."""
    try:
        tols = [float(t) for t in sweep_tol]
    except (TypeError, ValueError):
        raise TypeError(f"sweep_tol: expected a sequence of numbers, got {sweep_tol!r}") from None
    for t in tols:
        if not (math.isfinite(t) and t > 0):
            raise ValueError(f"sweep_tol: each tolerance must be finite and > 0, got {t!r}")
    return tuple(sorted(set(tols), reverse=True))


def _voxgi_sweep(
    scene, out, cam, seed, threads, tols, ref, ref_noise: float, mask, rows, base=None, solved=None
) -> list:
    """voxgi at each of ``tols`` looser than the default's, then the default
    run itself: ``[(tol, seconds, rel_mse_net), ...]``.

    Each run's seconds count a voxelize and a solve, as a run at that
    tolerance would: where the default run solved the scene itself
    (:func:`voxgi.resolution.solve_scene`) and the looser tolerance asks for
    a lighter solve (:meth:`voxgi.SolveTuning.for_picture`), that solve is
    made and timed (once per tolerance, kept in ``solved`` for the denoised
    sweep); otherwise the default run's solution is shown again after its
    voxelize and solve. Rows are appended to ``rows``. ``base``: the
    default run's row, ``rows[0]`` (voxgi's defaults) unless given; the
    denoised display's row (``"voxgi+oidn"``) sweeps the denoised display.
    """
    v = rows[0] if base is None else base
    method = v["method"]
    tuning = RenderTuning(denoise=True) if method == "voxgi+oidn" else None
    default_tol = float(out.stats["tol"])
    v["tol"] = default_tol
    solved = {} if solved is None else solved
    sweep = []
    for tol in tols:
        if tol <= default_tol:
            continue
        sol, before = _solution_for(scene, out, v, tol, default_tol, threads, solved)
        t = time.perf_counter()
        r = pipeline_render(
            scene, sol, camera=cam, tol=tol, seed=seed, threads=threads, tuning=tuning
        )
        row = _row(method, None, before + time.perf_counter() - t, r.image, ref, ref_noise, mask)
        row["tol"], row["frames"] = tol, r.frames
        rows.append(row)
        sweep.append((tol, row["seconds"], row["rel_mse_net"]))
    return [*sweep, (default_tol, v["seconds"], v["rel_mse_net"])]


def _solution_for(scene, out, row, tol: float, default_tol: float, threads, solved: dict):
    """The solution a run at ``tol`` shows and the seconds of its voxelize and
    solve: the default run's where it fits, else a solve for ``tol`` (kept in
    ``solved``)."""
    own = "resolution" in out.solution.stats
    if not own or SolveTuning.for_picture(tol) == SolveTuning.for_picture(default_tol):
        return out.solution, row["phases"]["voxelize"] + row["phases"]["solve"]
    if tol not in solved:
        t = time.perf_counter()
        sol = solve_scene(scene, tol=tol, threads=threads, progress=False)
        solved[tol] = (sol, time.perf_counter() - t)
    return solved[tol]


def _checked(scene, spp, sweep_spp, width, height, variant, denoise):
    """:func:`compare`'s arguments checked and Mitsuba (and OIDN) found.

    Returns (spp, sweep counts, the camera at the asked size, the Mitsuba module).
    """
    from .mitsuba import mitsuba_module

    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected voxgi.Scene, got {type(scene).__name__}")
    spp = _validate.integer(spp, "spp", low=2)
    counts = [_validate.integer(n, "sweep_spp", low=1) for n in sweep_spp]
    if not counts or counts != sorted(set(counts)):
        raise ValueError(f"sweep_spp: expected increasing sample counts, got {list(sweep_spp)}")
    cam = scene.camera
    if cam is None:
        raise ValueError("compare: the scene has no camera")
    changes = {k: v for k, v in (("width", width), ("height", height)) if v is not None}
    if changes:
        cam = cam.replace(**changes)
    mi = mitsuba_module(variant)
    if denoise:
        _require_oidn()  # before the renders, not after them
    return spp, counts, cam, mi


def _render_voxgi(scene, cam, resolution, seed, threads, progress):
    """voxgi with its defaults (voxelize + solve + display): (RenderResult, seconds)."""
    t0 = time.perf_counter()
    sol, seconds = None, {}
    if resolution is not None:
        vox = voxelize(scene, resolution, threads=threads)
        seconds["voxelize"] = time.perf_counter() - t0
        sol = solve(vox, threads=threads, progress=progress)
        seconds["solve"] = time.perf_counter() - t0 - seconds["voxelize"]
    out = pipeline_render(scene, sol, camera=cam, seed=seed, threads=threads, progress=progress)
    out.stats["seconds"].update(seconds)
    return out, time.perf_counter() - t0


def _reference(mi, plain, spp: int, reference, shape) -> tuple[np.ndarray, float, float | None]:
    """Mitsuba's reference as two halves, or the one given: (image, noise, seconds or None)."""
    if reference is None:
        half_a, ta = _mitsuba(mi, plain, spp // 2, 1001)
        half_b, tb = _mitsuba(mi, plain, spp - spp // 2, 2002)
        return 0.5 * (half_a + half_b), 0.25 * rel_mse(half_a, half_b), ta + tb
    ref, ref_noise = np.asarray(reference[0], np.float32), float(reference[1])
    if ref.shape != shape:
        raise ValueError(f"reference: shape {ref.shape}, the camera's image is {shape}")
    return ref, ref_noise, None


def _voxgi_row(out, t_voxgi: float, ref, ref_noise: float, mask) -> dict:
    """voxgi's row: its errors, frames and the seconds of each phase."""
    row = _row("voxgi", None, t_voxgi, out.image, ref, ref_noise, mask)
    row["frames"] = out.frames
    secs = out.stats["seconds"]
    vs = float(secs.get("voxelize", 0.0)), float(secs.get("solve", 0.0))
    row["phases"] = {"voxelize": vs[0], "solve": vs[1], "display": t_voxgi - sum(vs)}
    return row


def _voxgi_denoised(scene, out, cam, seed, threads, progress):
    """voxgi's solution of ``out`` displayed with ``RenderTuning(denoise=True)``:
    (RenderResult, display seconds)."""
    t0 = time.perf_counter()
    den = pipeline_render(
        scene,
        out.solution,
        camera=cam,
        seed=seed,
        threads=threads,
        progress=progress,
        tuning=RenderTuning(denoise=True),
    )
    return den, time.perf_counter() - t0


def _voxgi_denoised_row(den, t_display: float, phases: dict, ref, ref_noise: float, mask) -> dict:
    """The row of :func:`_voxgi_denoised`'s render, after the solve of ``phases``."""
    vs = phases["voxelize"], phases["solve"]
    row = _row("voxgi+oidn", None, sum(vs) + t_display, den.image, ref, ref_noise, mask)
    row["frames"] = den.frames
    row["phases"] = {"voxelize": vs[0], "solve": vs[1], "display": t_display}
    return row


def _sweeps(mi, plain, scene, cam, counts, denoise, goal, ref, ref_noise, mask, rows) -> dict:
    """Mitsuba's plain and (with ``denoise``) denoised sweeps, each stopping at ``goal``.

    Appends each render's row to ``rows``; returns ``{method: [(spp, seconds,
    rel_mse_net), ...]}``.
    """
    from .mitsuba import to_mitsuba, with_aovs

    sweeps = {"mitsuba": []}
    _mitsuba(mi, plain, 1, 7)  # warm-up: the JIT's first kernels
    for n in counts:
        im, t = _mitsuba(mi, plain, n, 3003 + n)
        rows.append(_row("mitsuba", n, t, im, ref, ref_noise, mask))
        sweeps["mitsuba"].append((n, t, rows[-1]["rel_mse_net"]))
        if rows[-1]["rel_mse_net"] <= goal:
            break
    if denoise:
        from .mitsuba import denoise_oidn

        sweeps["mitsuba+oidn"] = []
        aov = mi.load_dict(with_aovs(to_mitsuba(scene, spp=1, camera=cam)))
        denoise_oidn(_mitsuba(mi, aov, 1, 7, channels=9)[0], cam)  # warm-up
        for n in counts:
            t = time.perf_counter()
            im = denoise_oidn(_mitsuba(mi, aov, n, 5005 + n, channels=9)[0], cam)[0]
            t = time.perf_counter() - t
            rows.append(_row("mitsuba+oidn", n, t, im, ref, ref_noise, mask))
            sweeps["mitsuba+oidn"].append((n, t, rows[-1]["rel_mse_net"]))
            if rows[-1]["rel_mse_net"] <= goal:
                break
    return sweeps


def _reference_row(spp, ref_seconds, ref_noise: float) -> dict:
    """The reference's row: its own noise as its relMSE."""
    return {
        "method": "reference",
        "spp": spp,
        "seconds": float("nan") if ref_seconds is None else ref_seconds,
        "rel_mse": ref_noise,
        "rel_mse_net": 0.0,
        "ssim": 1.0,
        "flip": 0.0,
        "brightness": [1.0, 1.0, 1.0],
    }


def _require_oidn() -> None:
    try:
        import mitsuba_oidn  # noqa: F401
    except ImportError as exc:
        raise ImportError(
            "OIDN is needed for the denoised comparison: pip install 'voxgi[bench]' "
            "(or pip install mitsuba-oidn), or pass denoise=False (--no-denoise)"
        ) from exc


def _mitsuba(mi, sc, n: int, seed: int, channels: int = 3) -> tuple[np.ndarray, float]:
    """One Mitsuba render of ``n`` spp: (image, seconds to the finished array)."""
    t = time.perf_counter()
    im = np.array(mi.render(sc, spp=int(n), seed=int(seed)), dtype=np.float32)[..., :channels]
    return np.ascontiguousarray(im), time.perf_counter() - t


def _row(method: str, spp, seconds: float, img, ref, ref_noise: float, mask) -> dict:
    """One row of the table: errors against the reference, its noise taken off."""
    err = rel_mse(img, ref)
    return {
        "method": method,
        "spp": spp,
        "seconds": float(seconds),
        "rel_mse": err,
        "rel_mse_net": max(err - ref_noise, 0.0),
        "ssim": ssim(img, ref),
        "flip": flip(img, ref),
        "brightness": _brightness(img, ref, mask),
    }


def _write(result: Comparison, out_dir: Path, plot: bool) -> dict:
    """The EXRs, the difference PNG and, with ``plot``, the time-error plot."""
    from .io import write_exr, write_png

    out_dir.mkdir(parents=True, exist_ok=True)
    files = {
        "voxgi": write_exr(out_dir / "voxgi.exr", result.voxgi),
        "reference": write_exr(out_dir / "reference.exr", result.reference),
        "difference": write_png(
            out_dir / "difference.png", np.abs(result.voxgi - result.reference)
        ),
    }
    if plot:
        files["plot"] = _plot(result, out_dir / "time_vs_error.png")
    return {k: str(v) for k, v in files.items()}


def _plot(result: Comparison, path: Path) -> Path:
    """relMSE against seconds: voxgi's tolerances and Mitsuba's sweeps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .io import atomic_path

    fig, ax = plt.subplots(figsize=(5, 4))
    for sweep, label, mark in (
        (result.sweep_voxgi, "voxgi (display tolerances)", "o-"),
        (result.sweep, "Mitsuba", "s-"),
        (result.sweep_denoised, "Mitsuba + OIDN", "s-"),
    ):
        if sweep:
            ax.loglog([s[1] for s in sweep], [max(s[2], 1e-12) for s in sweep], mark, label=label)
    ax.set_xlabel("seconds")
    ax.set_ylabel("relMSE against the reference")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)
    return path
