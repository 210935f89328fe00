"""``voxgi render``: voxelize, solve and display a scene, then write EXR + PNG."""

from __future__ import annotations

import time

from ._args import EXIT_INTERRUPTED, UsageError
from ._console import _interrupted, _note, _say
from ._files import _load_scene, _scene_source, check_writable, output_paths


def _prepare_render(args):
    """Resolve the scene and outputs (checked writable), load the scene and size its
    camera; returns ``(scene, name, exr, png)``."""

    src, name = _scene_source(args.scene)
    exr, png = output_paths(args.output if args.output else f"{name}.exr")
    check_writable((exr, png))
    if args.denoise:
        from ..denoise import load_oidn

        try:
            load_oidn()
        except ImportError as exc:  # before any work, as the outputs are checked
            raise UsageError(f"--denoise: {exc}") from None
    scene = _load_scene(args, src, name)
    changes = {k: v for k, v in (("width", args.width), ("height", args.height)) if v is not None}
    if changes:
        scene.camera = scene.camera.replace(**changes)
    return scene, name, exr, png


def _run_voxelize(args, scene):
    """Voxelize the scene and report it; returns ``(vox, seconds)``."""
    from ..voxels import voxelize

    t0 = time.perf_counter()
    vox = voxelize(scene, resolution=args.resolution, threads=args.threads, progress=not args.quiet)
    t_vox = time.perf_counter() - t0
    _say(f"voxelize: {len(vox)} records (resolution {vox.resolution}) in {t_vox:.2f} s")
    for key in ("skipped_degenerate", "polygon_overflows", "cut_limit_hits"):
        if vox.stats.get(key):
            _note(args, f"voxelize {key}: {vox.stats[key]}")
    return vox, t_vox


def _run_solve(args, vox):
    """Solve the radiosity for the display and report it; returns ``(sol, seconds)``."""
    from ..pipeline import solve

    t0 = time.perf_counter()
    sol = solve(vox, radius=args.radius, threads=args.threads, progress=not args.quiet)
    t_sol = time.perf_counter() - t0
    traced = sol.stats.get("traced")
    then = (
        ""
        if traced is None
        else f", then {traced['passes']} traced passes of {traced['rays']:.3g} rays"
    )
    _say(
        f"solve: {sol.bounces} bounces, {sol.stats.get('rays', 0):.3g} rays{then} in {t_sol:.2f} s"
    )
    for what, why in sol.stats.get("skipped", {}).items():
        _note(args, f"solve skipped {what}: {why}")
    return sol, t_sol


def _run_solve_scene(args, scene):
    """Solve at the coarsest resolution the picture needs and report each one
    tried; returns ``(sol, voxelize seconds, solve seconds)``."""
    from ..display.settings import DEFAULT_TOL
    from ..resolution import solve_scene

    t0 = time.perf_counter()
    sol = solve_scene(
        scene,
        tol=args.tol if args.tol > 0 else DEFAULT_TOL,
        radius=args.radius,
        threads=args.threads,
        progress=not args.quiet,
    )
    r = sol.stats["resolution"]
    for level in r["levels"]:
        agree = (
            f", differs from the last by relMSE {level['difference']:.2e}"
            if "difference" in level
            else ""
        )
        _say(
            f"resolution {level['resolution']}: {level['records']} records, solved in "
            f"{level['solve_seconds']:.2f} s{agree}"
        )
    _say(f"kept {r['reason']}")
    for what, why in sol.stats.get("skipped", {}).items():
        _note(args, f"solve skipped {what}: {why}")
    t_vox = r["voxelize_seconds"]
    return sol, t_vox, time.perf_counter() - t0 - t_vox


def _run_display(args, scene, sol):
    """Render the image by progressive display frames."""
    from ..display import RenderTuning, render

    return render(
        scene,
        sol,
        max_frames=args.frames,
        tol=args.tol,
        seed=args.seed,
        progress=not args.quiet,
        threads=args.threads,
        tuning=RenderTuning(denoise=True) if args.denoise else None,
    )


def _report_display(args, res, interrupted: bool) -> None:
    """Print the display's summary line and, with ``--verbose``, what it skipped."""
    s = res.stats
    _say(
        f"display: {res.frames} frames{' (interrupted)' if interrupted else ''} of "
        f"{s['vpls_per_frame']} VPLs and {s['gather_per_frame']} gather rays a pixel (light "
        f"spread {s['light_spread']:.2f}), {s['primary_rays']:.3g} primary + "
        f"{s['shadow_rays']:.3g} shadow + {s['gather_rays']:.3g} gather rays in "
        f"{s['seconds']['display']:.2f} s "
        f"(estimated relMSE of the noise {s['est_rel_mse']:.2e}, worst pixel "
        f"{s['est_max_rel_err']:.1%})"
    )
    seen = (s.get("seen_emission") or {}).get("est_rel_mse")
    if seen is not None and seen > 0.25 * s.get("tol", 0):
        # every frame shares it, so the estimate above does not count it
        _say(
            f"display: the mean emission seen across pixels adds an estimated relMSE "
            f"{seen:.2e}, shared by every frame and not in the estimate above"
        )
    if s.get("stopped") == "max_frames" and s.get("tol", 0) > 0:
        est = s["est_rel_mse_denoised"] if s.get("denoised") else s["est_rel_mse"]
        _say(
            f"display: stopped at the frame cap ({res.frames}) with estimated relMSE "
            f"{est:.2e} over --tol {s['tol']:.2e}; raise --frames or --tol"
        )
    for why in s.get("skipped", []):
        _note(args, f"display skipped {why}")


def _timings(t_vox: float, t_sol: float, sec: dict) -> dict:
    """Seconds of each phase, the display's own phases, and the total."""
    timings = {
        "voxelize": t_vox,
        "solve": t_sol,
        **{k: v for k, v in sec.items() if k not in ("voxelize", "solve", "total")},
    }
    timings["total"] = t_vox + t_sol + sec["display"]
    return timings


def _render_metadata(args, name: str, cam, vox, res, timings: dict, exposure: float) -> dict:
    """The EXR header's record of the render: its settings, sizes and timings."""
    s = res.stats
    return {
        "scene": name,
        "width": cam.width,
        "height": cam.height,
        "resolution": vox.resolution,
        "records": len(vox),
        "radius": res.solution.stats["directions"]["gather"]["radius"],
        "frames": res.frames,
        "max_frames": args.frames,
        "tol": args.tol,
        "est_rel_mse": s["est_rel_mse"],
        "est_max_rel_err": s["est_max_rel_err"],
        "vpls_per_pixel": s["vpls"],
        "vpls_per_frame": s["vpls_per_frame"],
        "gather_per_frame": s["gather_per_frame"],
        "light_spread": s["light_spread"],
        "seed": args.seed,
        "exposure": exposure,
        "exposure_auto": args.exposure is None,
        "tonemap": args.tonemap,
        "denoised": bool(res.stats.get("denoised")),
        "interrupted": bool(s.get("interrupted")),
        "seconds": timings,
        "skipped": s["skipped"],
    }


def run_render(args) -> int:
    """``voxgi render``: decide and check the outputs, load the scene, voxelize,
    solve, display, write EXR + PNG; print what was done and each phase's seconds."""
    from .. import io

    scene, name, exr, png = _prepare_render(args)
    cam = scene.camera
    _say(
        f"scene {name}: {len(scene.objects)} objects, {scene.n_triangles} triangles, "
        f"{cam.width}x{cam.height} pixels"
    )
    phase = "voxelize"
    try:
        if args.resolution is None:
            phase = "voxelize and solve"
            sol, t_vox, t_sol = _run_solve_scene(args, scene)
            vox = sol.vox
        else:
            vox, t_vox = _run_voxelize(args, scene)
            phase = "solve"
            sol, t_sol = _run_solve(args, vox)
        phase = "display"
        res = _run_display(args, scene, sol)
    except KeyboardInterrupt:
        return _interrupted(f"interrupted during {phase}; nothing written")

    interrupted = bool(res.stats.get("interrupted"))
    if interrupted and res.frames == 0:
        return _interrupted("interrupted before the first display frame finished; nothing written")
    _report_display(args, res, interrupted)
    timings = _timings(t_vox, t_sol, res.stats["seconds"])
    exposure = io.auto_exposure(res.image) if args.exposure is None else args.exposure
    meta = _render_metadata(args, name, cam, vox, res, timings, exposure)
    # Each write is atomic (voxgi.io.atomic_path): a Ctrl-C here leaves every
    # file either as it was or complete.
    try:
        io.write_exr(exr, res.image, metadata=meta, stderr=res.stderr, layers=res.exr_layers())
        io.write_png(png, res.image, exposure=exposure, tonemap=args.tonemap)
    except KeyboardInterrupt:
        return _interrupted("interrupted while writing; the outputs are whole (old or new)")
    if interrupted:
        _say(f"interrupted: wrote a partial image ({res.frames} frames) to {exr} and {png}")
    else:
        _say(f"wrote {exr} and {png}")
    _say("seconds: " + ", ".join(f"{k} {v:.2f}" for k, v in timings.items()))
    return EXIT_INTERRUPTED if interrupted else 0
