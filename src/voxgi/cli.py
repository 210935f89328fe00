"""Command line: ``voxgi render SCENE -o out.exr``."""

from __future__ import annotations

import argparse
import sys


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


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="voxgi", description="Voxel-based global illumination")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="voxelize, solve and render a scene to EXR + PNG")
    r.add_argument("scene", help="scene TOML file or built-in name (cornell-box, furnace-sphere, ...)")
    r.add_argument("-o", "--output", default=None, help="output EXR path (PNG written beside it)")
    r.add_argument("--resolution", type=_at_least(2), default=None, help="voxels along the longest side")
    r.add_argument("--directions", type=_at_least(1), default=None, help="gathering direction radius R")
    r.add_argument("--frames", "--spp", dest="frames", type=_at_least(1), default=None,
                   help="maximum progressive frames")
    r.add_argument("--width", type=int, default=None)
    r.add_argument("--height", type=int, default=None)
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--threads", type=_at_least(1), default=None)
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.command == "render":
        from .display import run_cli  # type: ignore[attr-defined]

        try:
            return run_cli(args)
        except (ValueError, TypeError, FileNotFoundError) as exc:
            # bad scene files and arguments: a message, not a traceback
            raise SystemExit(f"voxgi render: {exc}") from None
    return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
