"""``voxgi compare``: voxgi against Mitsuba 3 on one scene."""

from __future__ import annotations

from pathlib import Path

from ._console import _say
from ._files import _load_scene, _scene_source, check_writable


def run_compare(args) -> int:
    """``voxgi compare``: voxgi against Mitsuba 3 on one scene; prints the table."""
    from ..compare import compare

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
            voxgi_denoise=args.denoise,
        )
    except ImportError as exc:
        raise SystemExit(f"voxgi compare: error: {exc}") from None
    _say(f"scene {name}")
    _say(res.table())
    _say("wrote " + ", ".join(res.files.values()))
    return 0
