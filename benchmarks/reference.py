"""Reference renders of voxgi's built-in scenes with Mitsuba 3's path tracer.

Renders a built-in scene (``--scene``, default ``cornell-box``; any name of
``voxgi.scenes.names()``), exported by :mod:`voxgi.mitsuba` (same meshes,
one-sided area lights, camera; box pixel filter; ``path`` integrator with
``max_depth = -1``), at a high sample count, and writes
``benchmarks/results/<tag>_ref_<size>.exr`` (+ ``.png`` and ``.json`` with
the variant, spp, seconds, scene fingerprint), where ``<tag>`` is ``cornell``
for the Cornell box and the scene name with ``_`` for ``-`` otherwise
(``shadow_ref_256.exr``). The comparison metric is ``voxgi.metrics.rel_mse``.

The sample count is split into ``--passes`` independent renders (bounds
memory); the even and the odd passes make two independent half-spp images,
and their relMSE against each other is recorded: ``rel_mse(half1, half2)``
is about twice the error of one half-spp image, so the full reference's own
error (its noise, which adds to every relMSE measured against it) is about
``rel_mse(half1, half2) / 4`` (docs/design.md §9: Mitsuba's error falls as
1/spp). The ``.json`` holds both ``half_vs_half_rel_mse`` and
``noise_rel_mse_est`` (= / 4).

Usage::

    python benchmarks/reference.py --size 256 --spp 4096
    python benchmarks/reference.py --size 512 --spp 2048
    python benchmarks/reference.py --scene shadow --size 256 --spp 8192 --passes 16

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
from voxgi.metrics import rel_mse
from voxgi.mitsuba import mitsuba_module, to_mitsuba

RESULTS = Path(__file__).resolve().parent / "results"


def scene_tag(name: str) -> str:
    """File-name stem of a built-in scene's results: ``cornell`` for the
    Cornell box (the historical name), else the name with ``_`` for ``-``."""
    key = name.replace("_", "-").lower()
    return "cornell" if key == "cornell-box" else key.replace("-", "_")


def render_reference(
    size: int,
    spp: int,
    variant: str | None = None,
    seed: int = 1,
    passes: int = 1,
    scene_name: str = "cornell-box",
    verbose: bool = False,
) -> tuple[np.ndarray, dict]:
    """Mitsuba render of a built-in scene at ``size``² pixels; ``passes``
    independent renders of ``spp / passes`` samples are averaged (bounds memory).
    With two passes or more, the even and odd passes' means are compared
    (``info["half_vs_half_rel_mse"]``, ``info["noise_rel_mse_est"]``)."""
    mi = mitsuba_module(variant)
    scene = voxgi.scenes.get(scene_name, width=size, height=size)
    per = max(1, spp // passes)
    sc = mi.load_dict(to_mitsuba(scene, spp=per))
    halves = [np.zeros((size, size, 3)), np.zeros((size, size, 3))]
    t0 = time.perf_counter()
    for p in range(passes):
        halves[p % 2] += np.array(mi.render(sc, spp=per, seed=seed + 1000 * p), dtype=np.float64)[
            ..., :3
        ]
        if verbose:
            print(f"  pass {p + 1}/{passes}: {time.perf_counter() - t0:.0f} s", flush=True)
    seconds = time.perf_counter() - t0
    info = {
        "scene": scene_name,
        "variant": mi.variant(),
        "spp": per * passes,
        "size": size,
        "seconds": seconds,
        "passes": passes,
        "seed": seed,
        "scene_fingerprint": scene.fingerprint(),
        "mitsuba": mi.__version__,
        "cpu": platform.processor() or platform.machine(),
        "filter": "box",
        "integrator": "path, max_depth=-1",
    }
    if passes >= 2:
        n1, n0 = passes // 2, passes - passes // 2
        hh = rel_mse((halves[0] / n0).astype(np.float32), (halves[1] / n1).astype(np.float32))
        info["half_vs_half_rel_mse"] = hh
        info["noise_rel_mse_est"] = hh / 4
    return ((halves[0] + halves[1]) / passes).astype(np.float32), info


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--scene", default="cornell-box", help="built-in scene name (voxgi.scenes.names())"
    )
    ap.add_argument("--size", type=int, nargs="+", default=[256])
    ap.add_argument("--spp", type=int, default=4096)
    ap.add_argument("--passes", type=int, default=8)
    ap.add_argument("--variant", default=None)
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    for size in args.size:
        img, info = render_reference(
            size, args.spp, args.variant, passes=args.passes, scene_name=args.scene, verbose=True
        )
        base = args.out / f"{scene_tag(args.scene)}_ref_{size}"
        voxgi.io.write_exr(base.with_suffix(".exr"), img, metadata=info)
        voxgi.io.write_png(base.with_suffix(".png"), img)
        base.with_suffix(".json").write_text(json.dumps(info, indent=2))
        noise = ""
        if "noise_rel_mse_est" in info:
            noise = (
                f"; half vs half relMSE {info['half_vs_half_rel_mse']:.2e} -> "
                f"reference noise ~{info['noise_rel_mse_est']:.1e}"
            )
        print(
            f"{args.scene} {size}x{size}: {info['spp']} spp, {info['variant']}, "
            f"{info['seconds']:.1f} s{noise} -> {base.with_suffix('.exr')}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
