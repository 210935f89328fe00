"""Command line: ``voxgi render SCENE -o out.exr``."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


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


def run_render(args) -> int:
    """``voxgi render``: load or build the scene, voxelize, solve, display,
    write EXR + PNG, print what was done and the seconds of each phase."""
    from . import io, scenes
    from .display import render
    from .pipeline import RENDER_RESOLUTION, solve_for_display
    from .scene import Scene
    from .voxels import voxelize

    say = print
    src = Path(args.scene)
    if src.suffix.lower() == ".toml" or src.exists():
        if not src.exists():
            raise SystemExit(f"voxgi render: scene file not found: {src}")
        scene = Scene.load(src)
        name = src.stem
    else:
        try:
            scene = scenes.get(args.scene)
        except ValueError as exc:
            raise SystemExit(f"voxgi render: {exc}") from None
        name = args.scene
    if scene.camera is None:
        raise SystemExit(f"voxgi render: scene {name!r} has no camera")
    try:
        changes = {k: v for k, v in (("width", args.width), ("height", args.height)) if v is not None}
        if changes:
            scene.camera = scene.camera.replace(**changes)
    except (TypeError, ValueError) as exc:
        raise SystemExit(f"voxgi render: {exc}") from None
    out = Path(args.output) if args.output else Path(f"{name}.exr")
    cam = scene.camera
    say(f"scene {name}: {len(scene.objects)} objects, {scene.n_triangles} triangles, "
        f"{cam.width}x{cam.height} pixels")
    t0 = time.perf_counter()
    vox = voxelize(scene, resolution=args.resolution or RENDER_RESOLUTION)
    t_vox = time.perf_counter() - t0
    say(f"voxelize: {len(vox)} records (resolution {vox.resolution}) in {t_vox:.2f} s")
    t0 = time.perf_counter()
    sol = solve_for_display(vox, directions=args.directions, threads=args.threads,
                            progress=not args.quiet)
    t_sol = time.perf_counter() - t0
    say(f"solve: {sol.bounces} bounces, {sol.stats.get('rays', 0):.3g} rays in {t_sol:.2f} s")
    for what, why in sol.stats.get("skipped", {}).items():
        say(f"  solve skipped {what}: {why}")
    res = render(scene, sol, max_frames=args.frames, seed=args.seed, progress=not args.quiet,
                 threads=args.threads)
    s = res.stats
    sec = s["seconds"]
    say(f"display: {res.frames} frames, {s['vpls']} VPLs/pixel, {s['primary_rays']:.3g} primary "
        f"+ {s['shadow_rays']:.3g} shadow + {s['gather_rays']:.3g} gather rays in "
        f"{sec['display']:.2f} s "
        f"(estimated relMSE of the noise {s['est_rel_mse']:.2e})")
    timings = {"voxelize": t_vox, "solve": t_sol, **{k: v for k, v in sec.items()
                                                      if k not in ("voxelize", "solve", "total")}}
    timings["total"] = t_vox + t_sol + sec["display"]
    meta = {
        "scene": name, "width": cam.width, "height": cam.height, "resolution": vox.resolution,
        "records": len(vox), "directions": args.directions, "frames": res.frames,
        "vpls_per_pixel": s["vpls"], "seed": args.seed, "seconds": timings,
        "skipped": s["skipped"],
    }
    io.write_exr(out, res.image, metadata=meta)
    png = out.with_suffix(".png")
    io.write_png(png, res.image)
    say(f"wrote {out} and {png}")
    say("seconds: " + ", ".join(f"{k} {v:.2f}" for k, v in timings.items()))
    return 0


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.command == "render":
        try:
            return run_render(args)
        except (ValueError, TypeError, FileNotFoundError) as exc:
            # bad scene files and arguments: a message, not a traceback
            raise SystemExit(f"voxgi render: {exc}") from None
    return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
