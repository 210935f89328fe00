"""Command line: ``voxgi render SCENE -o out.exr``, ``voxgi compare SCENE`` and ``voxgi scenes``.

Exit codes: 0 done; 1 a scene file or value that cannot be used; 2 a bad
command line or an output that cannot be written (both checked before any
work; missing output folders are created); 130 interrupted (Ctrl-C).
Errors are one line on stderr, never a traceback.
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
import time
import warnings
from pathlib import Path

#: What ``-o`` may end with; both files are always written.
OUTPUT_EXTENSIONS = (".exr", ".png")
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as shells report a Ctrl-C


class UsageError(Exception):
    """A bad argument or output path: reported in one line, exit code 2 (as
    argparse reports its own errors)."""


def _at_least(low: int):
    """argparse type: an integer >= ``low`` (checked before any work starts)."""

    def conv(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if v < low:
            raise argparse.ArgumentTypeError(f"must be >= {low}, got {v}")
        return v

    conv.__name__ = f"integer >= {low}"
    return conv


def _finite(low: float | None = None):
    """argparse type: a finite float (>= ``low`` when given)."""

    def conv(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if v != v or v in (float("inf"), float("-inf")):
            raise argparse.ArgumentTypeError(f"must be finite, got {text}")
        if low is not None and v < low:
            raise argparse.ArgumentTypeError(f"must be >= {low:g}, got {v:g}")
        return v

    conv.__name__ = "number" if low is None else f"number >= {low:g}"
    return conv


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows ``(default: X)`` after every option whose default is a value; the
    help of an option without one (None) says what happens instead."""

    def _get_help_string(self, action):
        if action.default is None or action.default is False:
            return action.help
        return super()._get_help_string(action)


def _version() -> str:
    from . import __version__

    return __version__


def build_parser() -> argparse.ArgumentParser:
    """The ``voxgi`` argument parser with its ``render``, ``compare`` and ``scenes`` subcommands."""
    p = argparse.ArgumentParser(
        prog="voxgi",
        formatter_class=_HelpFormatter,
        description="Voxel-based global illumination: voxelize a scene, solve its radiosity "
        "on the voxels and display it by progressive VPL ray tracing.",
    )
    p.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    r = sub.add_parser(
        "render",
        formatter_class=_HelpFormatter,
        help="voxelize, solve and render a scene to EXR + PNG",
        description="Render a scene to a linear EXR and a tone-mapped PNG preview beside it. "
        "The EXR also holds each pixel's estimated standard error in the channels "
        "stderr.R, stderr.G, stderr.B, and the pixel AOVs of the camera hits: "
        "albedo.R/G/B, normal.X/Y/Z, depth.Z and object_id. "
        "Exit codes: 0 done, 1 a scene or value that cannot be used, 2 a bad "
        "command line or an output that cannot be written (a read-only file, a folder "
        "that cannot be written; checked before any work, and missing folders are "
        "created), 130 interrupted by Ctrl-C (a partial image is written only if a "
        "frame finished; its EXR header says so).",
    )
    _add_render_arguments(r)
    c = sub.add_parser(
        "compare",
        formatter_class=_HelpFormatter,
        help="render a scene with voxgi and with Mitsuba 3 and compare them",
        description="Render a scene with voxgi's defaults and with Mitsuba 3 (a reference "
        "at --spp, and Mitsuba's time to voxgi's relMSE at doubling spp); print relMSE, "
        "brightness ratios of non-emitter pixels and seconds; write both EXRs and a "
        "difference PNG. Needs Mitsuba (pip install 'voxgi[bench]').",
    )
    _add_compare_arguments(c)
    sub.add_parser(
        "scenes",
        formatter_class=_HelpFormatter,
        help="list the built-in scenes",
        description="List the built-in scenes that 'voxgi render NAME' accepts.",
    )
    return p


def _add_render_arguments(r: argparse.ArgumentParser) -> None:
    """Add the ``render`` subcommand's arguments to its parser ``r``."""
    from .radiosity.tuning import TRACED_RADIUS
    from .voxels import DEFAULT_RESOLUTION

    r.add_argument(
        "scene",
        help="scene file (TOML, Mitsuba 3 XML, OBJ, glTF), "
        "or a built-in scene name (see 'voxgi scenes')",
    )
    r.add_argument(
        "-o",
        "--output",
        metavar="PATH",
        default=None,
        help="output file ending in .exr or .png; the other of the two is written "
        "beside it with the same name (default: SCENE.exr in the current "
        "folder)",
    )
    r.add_argument(
        "--resolution",
        metavar="N",
        type=_at_least(2),
        default=DEFAULT_RESOLUTION,
        help="voxels along the scene's longest side",
    )
    r.add_argument(
        "--radius",
        metavar="R",
        type=_at_least(1),
        default=TRACED_RADIUS,
        help="radius R of the solve's gathering direction set, whose answer its traced "
        "passes finish",
    )
    # the option's former name, kept working
    r.add_argument("--directions", dest="radius", type=_at_least(1), help=argparse.SUPPRESS)
    _add_display_arguments(r)
    _add_path_arguments(r)
    r.add_argument(
        "--threads",
        metavar="N",
        type=_at_least(1),
        default=None,
        help="worker threads (default: all hardware threads)",
    )
    talk = r.add_mutually_exclusive_group()
    talk.add_argument(
        "-q", "--quiet", action="store_true", help="no progress bars (the summary lines stay)"
    )
    talk.add_argument(
        "-v",
        "--verbose",
        action="store_true",
        help="also print diagnostics: what each stage skipped and why",
    )


def _add_compare_arguments(c: argparse.ArgumentParser) -> None:
    """Add the ``compare`` subcommand's arguments to its parser ``c``."""
    c.add_argument("scene", help="scene TOML file, or a built-in scene name (see 'voxgi scenes')")
    _add_path_arguments(c)
    c.add_argument(
        "--spp", metavar="N", type=_at_least(2), default=1024, help="spp of Mitsuba's reference"
    )
    c.add_argument(
        "--resolution",
        metavar="N",
        type=_at_least(2),
        default=None,
        help="voxgi's voxel resolution (default: the pipeline's)",
    )
    c.add_argument("--width", metavar="PX", type=_at_least(1), default=None, help="image width")
    c.add_argument("--height", metavar="PX", type=_at_least(1), default=None, help="image height")
    c.add_argument(
        "-o",
        "--out-dir",
        metavar="DIR",
        default=None,
        help="folder for voxgi.exr, reference.exr, difference.png (default: compare_SCENE)",
    )
    c.add_argument(
        "--no-denoise",
        action="store_true",
        help="leave out Mitsuba + OIDN (the denoised sweep; it needs mitsuba-oidn)",
    )
    c.add_argument("--plot", action="store_true", help="also plot relMSE against seconds")
    c.add_argument("--seed", metavar="S", type=int, default=0, help="voxgi's seed")
    c.add_argument(
        "--threads", metavar="N", type=_at_least(1), default=None, help="voxgi's threads"
    )


def _add_display_arguments(r: argparse.ArgumentParser) -> None:
    """Add the ``render`` options of the display and its image (frames to seed)."""
    from .io import TONEMAPS

    r.add_argument(
        "--frames",
        "--spp",
        dest="frames",
        metavar="N",
        type=_at_least(1),
        default=256,
        help="most progressive display frames",
    )
    r.add_argument(
        "--tol",
        metavar="T",
        type=_finite(0.0),
        default=1e-3,
        help="stop the display once the estimated relMSE of the image's noise is "
        "under this (0: run all --frames)",
    )
    r.add_argument(
        "--exposure",
        metavar="EV",
        type=_finite(),
        default=None,
        help="exposure of the PNG preview in stops (the EXR stays linear) (default: the "
        "exposure that maps the image's log-average luminance to middle grey, 0.18)",
    )
    r.add_argument(
        "--denoise",
        action="store_true",
        help="denoise the image with Intel Open Image Denoise guided by the render's "
        "albedo and normal AOVs (needs pip install 'voxgi[denoise]'); --tol still bounds "
        "the undenoised image's estimated error, and the EXR keeps that image in the "
        "channels undenoised.R/G/B",
    )
    r.add_argument(
        "--tonemap",
        choices=TONEMAPS,
        default="reinhard",
        help="tone curve of the PNG preview: 'reinhard' compresses the highlights so "
        "that only the brightest 0.1%% of pixels reach white, 'clip' clips at 1",
    )
    r.add_argument(
        "--width",
        metavar="PX",
        type=_at_least(1),
        default=None,
        help="image width in pixels (default: the scene camera's)",
    )
    r.add_argument(
        "--height",
        metavar="PX",
        type=_at_least(1),
        default=None,
        help="image height in pixels (default: the scene camera's)",
    )
    r.add_argument(
        "--seed", metavar="S", type=int, default=0, help="seed of the display's sample sequences"
    )


def output_paths(output: str | Path) -> tuple[Path, Path]:
    """The ``(EXR, PNG)`` pair that ``-o output`` names.

    ``out.exr`` gives ``out.exr`` and the preview ``out.png``; ``out.png``
    gives ``out.png`` and the data ``out.exr``. Any other extension is a
    :class:`UsageError` naming the supported ones.
    """
    out = Path(output)
    ext = out.suffix.lower()
    if ext == ".exr":
        return out, out.with_suffix(".png")
    if ext == ".png":
        return out.with_suffix(".exr"), out
    raise UsageError(
        f"-o {out}: unsupported extension {ext or '(none)'!r}; use .exr or .png "
        "(voxgi writes both: the linear EXR and a tone-mapped PNG beside it)"
    )


def check_writable(paths) -> None:
    """Fail now, before any work, if a file cannot be written at each of ``paths``.

    Creates missing folders, then a temporary file in each folder (removed
    at once): the same steps the final writes take. A read-only file
    (:func:`voxgi.io.is_read_only`) is refused, as the final write would.
    """
    from .io import is_read_only

    for path in paths:
        path = Path(path)
        if path.is_dir():
            raise UsageError(f"cannot write {path}: it is a folder")
        if is_read_only(path):
            raise UsageError(f"cannot write {path}: the file is read-only")
        blocker = next((p for p in path.parents if p.exists() and not p.is_dir()), None)
        if blocker is not None:
            raise UsageError(f"cannot write {path}: {blocker} is a file, not a folder")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(
                dir=path.parent, prefix=f".{path.stem}.", suffix=".probe"
            ):
                pass
        except OSError as exc:
            raise UsageError(f"cannot write {path}: {exc.strerror or exc}") from None


def _scene_source(spec: str) -> tuple[Path | None, str]:
    """``(scene file or None for a built-in scene, name)``, checked without loading."""
    from . import formats, scenes

    src = Path(spec)
    if src.suffix.lower() in {".toml", *formats.LOADERS} or src.exists():
        if not src.is_file():
            raise UsageError(f"scene file not found: {src}")
        return src, src.stem
    if spec.replace("_", "-").lower() not in scenes.names():
        raise UsageError(
            f"unknown built-in scene {spec!r}; known: {', '.join(scenes.names())} "
            "(or give a scene file: .toml, .xml, .obj, .gltf, .glb)"
        )
    return None, spec


def _say(text: str) -> None:
    """Print one line of progress on stdout at once."""
    print(text, flush=True)


def _note(args, text: str) -> None:
    """Print an indented diagnostic line, only with ``--verbose``."""
    if args.verbose:
        _say(f"  {text}")


def _interrupted(text: str) -> int:
    """Report an interrupted render on stderr; returns its exit code."""
    print(f"voxgi render: {text}", file=sys.stderr, flush=True)
    return EXIT_INTERRUPTED


def _load_scene(args, src: Path | None, name: str):
    """The scene of a file (through the path policy the options widen) or a
    built-in name; a scene without a camera is a ValueError (exit 1)."""
    from . import scenes
    from .scene import Scene

    if src is None:
        return scenes.get(name)
    scene = Scene.load(src, search_paths=args.search_path or (), allow_outside=args.allow_outside)
    if scene.camera is None:
        raise ValueError(
            f"scene file {src}: has no camera to render from (an OBJ holds none); "
            "name the file in a TOML scene with a [camera] table (docs/scene-files.md)"
        )
    return scene


def _add_path_arguments(r: argparse.ArgumentParser) -> None:
    """The options that widen what a scene file may read (docs/scene-files.md)."""
    r.add_argument(
        "--search-path",
        metavar="DIR",
        action="append",
        default=None,
        help="a folder besides the scene file's own that its meshes, includes and "
        "textures may lie in (repeatable)",
    )
    r.add_argument(
        "--allow-outside",
        action="store_true",
        help="let the scene file read any path it names",
    )


def _prepare_render(args):
    """Resolve the scene and outputs (checked writable), load the scene and size its
    camera; returns ``(scene, name, exr, png)``."""

    src, name = _scene_source(args.scene)
    exr, png = output_paths(args.output if args.output else f"{name}.exr")
    check_writable((exr, png))
    if args.denoise:
        from .denoise import load_oidn

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
    from .voxels import voxelize

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
    from .pipeline import solve

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


def _run_display(args, scene, sol):
    """Render the image by progressive display frames."""
    from .display import RenderTuning, render

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
    from . import io

    scene, name, exr, png = _prepare_render(args)
    cam = scene.camera
    _say(
        f"scene {name}: {len(scene.objects)} objects, {scene.n_triangles} triangles, "
        f"{cam.width}x{cam.height} pixels"
    )
    phase = "voxelize"
    try:
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


def run_compare(args) -> int:
    """``voxgi compare``: voxgi against Mitsuba 3 on one scene; prints the table."""
    from .compare import compare

    src, name = _scene_source(args.scene)
    out_dir = Path(args.out_dir if args.out_dir else f"compare_{name}")
    check_writable([out_dir / "voxgi.exr"])
    scene = _load_scene(args, src, name)
    try:
        res = compare(
            scene,
            spp=args.spp,
            resolution=args.resolution,
            width=args.width,
            height=args.height,
            seed=args.seed,
            threads=args.threads,
            out_dir=out_dir,
            plot=args.plot,
            denoise=not args.no_denoise,
        )
    except ImportError as exc:
        raise SystemExit(f"voxgi compare: error: {exc}") from None
    _say(f"scene {name}")
    _say(res.table())
    _say("wrote " + ", ".join(res.files.values()))
    return 0


def plain_text(doc: str) -> str:
    """A docstring line without its Sphinx roles: ``:func:`window_room``` becomes
    ``window-room`` when it names a built-in scene (as ``voxgi render`` takes
    it), else ``window_room``; double backquotes are dropped."""
    from . import scenes

    names = set(scenes.names())

    def name(m: re.Match) -> str:
        target = m.group(1).lstrip("~").rsplit(".", 1)[-1]
        dashed = target.replace("_", "-")
        return dashed if dashed in names else target

    doc = re.sub(r":[a-z:]+:`([^`]+)`", name, doc)
    return doc.replace("``", "")


def run_scenes(args) -> int:
    """``voxgi scenes``: each built-in scene's name and the first line of its description."""
    from . import scenes

    names = scenes.names()
    width = max(len(n) for n in names)
    for n in names:
        fn = getattr(scenes, n.replace("-", "_"), None)
        doc = (getattr(fn, "__doc__", None) or "").strip().splitlines()
        print(f"{n:<{width}}  {plain_text(doc[0].strip()) if doc else ''}")
    return 0


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Print a warning as ``warning: <message>`` on stderr: a command-line user
    needs what it says, not the source line that raised it."""
    print(f"warning: {message}", file=sys.stderr if file is None else file, flush=True)


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code, or raises ``SystemExit``
    on an error (code 2 for the command line and outputs, as argparse does,
    else the one-line message, which exits with 1)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    run = {"render": run_render, "compare": run_compare, "scenes": run_scenes}[args.command]
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _show_warning
            return run(args)
    except UsageError as exc:
        print(f"voxgi {args.command}: error: {exc}", file=sys.stderr)
        raise SystemExit(EXIT_USAGE) from None
    except (ValueError, TypeError, OSError) as exc:
        # bad or unreadable scene files and values: a message, not a traceback
        raise SystemExit(f"voxgi {args.command}: error: {exc}") from None
    except MemoryError:
        raise SystemExit(
            f"voxgi {args.command}: error: out of memory (a lower --resolution or a smaller "
            "image needs less)"
        ) from None
    except RecursionError:
        raise SystemExit(f"voxgi {args.command}: error: input nested too deeply") from None
    except KeyboardInterrupt:
        print(f"voxgi {args.command}: interrupted; nothing written", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
