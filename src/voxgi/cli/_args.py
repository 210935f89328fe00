"""The ``voxgi`` argument parser: its subcommands, their options and the usage errors."""

from __future__ import annotations

import argparse

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
    from .. import __version__

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
        "albedo.R/G/B, normal.X/Y/Z, emission.R/G/B (the emitted radiance seen), depth.Z "
        "and object_id. "
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
    from ..radiosity.tuning import TRACED_RADIUS
    from ..voxels import DEFAULT_RESOLUTION

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
        default=None,
        help="voxels along the scene's longest side (default: the coarsest of 16, 32 and "
        f"{DEFAULT_RESOLUTION} whose solution the next one's agrees with at the tolerance, "
        "voxgi.resolution.solve_scene)",
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
    c.add_argument(
        "--denoise",
        action="store_true",
        help="also display voxgi's solution denoised by OIDN (the row voxgi+oidn, beside "
        "Mitsuba + OIDN)",
    )
    c.add_argument("--plot", action="store_true", help="also plot relMSE against seconds")
    c.add_argument("--seed", metavar="S", type=int, default=0, help="voxgi's seed")
    c.add_argument(
        "--threads", metavar="N", type=_at_least(1), default=None, help="voxgi's threads"
    )


def _add_display_arguments(r: argparse.ArgumentParser) -> None:
    """Add the ``render`` options of the display and its image (frames to seed)."""
    from ..io import TONEMAPS

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
        "albedo and normal AOVs (needs pip install 'voxgi[denoise]'), the indirect filter "
        "off; --tol bounds the denoised image's estimated error, and the EXR keeps the "
        "undenoised image in the channels undenoised.R/G/B",
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
