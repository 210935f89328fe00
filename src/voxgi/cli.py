"""Command line: ``voxgi render SCENE -o out.exr``."""

from __future__ import annotations

import argparse
import sys


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="voxgi", description="Voxel-based global illumination")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="voxelize, solve and render a scene to EXR + PNG")
    r.add_argument("scene", help="scene TOML file or built-in name (cornell-box, furnace-sphere, ...)")
    r.add_argument("-o", "--output", default=None, help="output EXR path (PNG written beside it)")
    r.add_argument("--resolution", type=int, default=None, help="voxels along the longest side")
    r.add_argument("--directions", type=int, default=None, help="gathering direction radius R")
    r.add_argument("--frames", "--spp", dest="frames", type=int, default=None,
                   help="maximum progressive frames")
    r.add_argument("--width", type=int, default=None)
    r.add_argument("--height", type=int, default=None)
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--threads", type=int, default=None)
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.command == "render":
        from .display import run_cli  # type: ignore[attr-defined]

        return run_cli(args)
    return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
