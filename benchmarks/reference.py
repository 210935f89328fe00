"""Reference renders of voxgi's Cornell box with Mitsuba 3's path tracer.

Renders ``voxgi.scenes.cornell_box()`` (exported by :mod:`voxgi.mitsuba`:
same meshes, one-sided area light, camera; box pixel filter; ``path``
integrator with ``max_depth = -1``) at a high sample count, and writes
``benchmarks/results/cornell_ref_<size>.exr`` (+ ``.png`` and ``.json`` with
the variant, spp, seconds, scene fingerprint). The comparison metric is
``voxgi.metrics.rel_mse``; the reference's own error at ``spp`` samples is
about ``rel_mse(64 spp) * 64 / spp`` (DESIGN-NOTES §9: Mitsuba's error falls
as 1/spp), e.g. 8e-5 at 4096 spp.

Usage::

    python benchmarks/reference.py --size 256 --spp 4096
    python benchmarks/reference.py --size 512 --spp 2048

Needs ``pip install mitsuba`` (the ``bench`` extra). ``llvm_ad_rgb`` needs
libLLVM >= 16 (Debian: ``apt-get install libllvm19``; DRJIT_LIBLLVM_PATH is
set automatically when /usr/lib/x86_64-linux-gnu/libLLVM-19.so exists);
otherwise ``scalar_rgb`` is used.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

import voxgi
from voxgi.mitsuba import import_mitsuba, to_mitsuba

RESULTS = Path(__file__).resolve().parent / "results"


def render_reference(size: int, spp: int, variant: str | None = None, seed: int = 1,
                     passes: int = 1) -> tuple[np.ndarray, dict]:
    """Mitsuba render of the Cornell box at ``size``² pixels; ``passes``
    independent renders of ``spp / passes`` samples are averaged (bounds memory)."""
    mi = import_mitsuba(variant)
    scene = voxgi.scenes.cornell_box(width=size, height=size)
    per = max(1, spp // passes)
    sc = mi.load_dict(to_mitsuba(scene, spp=per))
    acc = np.zeros((size, size, 3))
    t0 = time.perf_counter()
    for p in range(passes):
        acc += np.array(mi.render(sc, spp=per, seed=seed + 1000 * p), dtype=np.float64)[..., :3]
    seconds = time.perf_counter() - t0
    info = {"variant": mi.variant(), "spp": per * passes, "size": size, "seconds": seconds,
            "passes": passes, "seed": seed, "scene_fingerprint": scene.fingerprint(),
            "mitsuba": mi.__version__, "cpu": platform.processor() or platform.machine(),
            "filter": "box", "integrator": "path, max_depth=-1"}
    return (acc / passes).astype(np.float32), info


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, nargs="+", default=[256])
    ap.add_argument("--spp", type=int, default=4096)
    ap.add_argument("--passes", type=int, default=8)
    ap.add_argument("--variant", default=None)
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    for size in args.size:
        img, info = render_reference(size, args.spp, args.variant, passes=args.passes)
        base = args.out / f"cornell_ref_{size}"
        voxgi.io.write_exr(base.with_suffix(".exr"), img, metadata=info)
        voxgi.io.write_png(base.with_suffix(".png"), img)
        base.with_suffix(".json").write_text(json.dumps(info, indent=2))
        print(f"{size}x{size}: {info['spp']} spp, {info['variant']}, {info['seconds']:.1f} s "
              f"-> {base.with_suffix('.exr')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
