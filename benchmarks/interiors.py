"""Interiors against a path tracer: voxgi's defaults and Mitsuba 3, side by side.

For each scene (``--scenes``; by default the Cornell box and the built-in
interiors that show what thin geometry does to discrete lines: the room lit
through a barred window, the room lit through a door left ajar, and the
Sponza-like atrium under its sky panel), in one run on this machine,
``voxgi.compare.compare`` renders:

- voxgi's defaults, ``voxgi.render(scene)``: voxelize, solve and display
  timed together;
- Mitsuba 3's path tracer (``path``, ``max_depth = -1``, box filter) at
  ``--ref-spp`` samples as the reference, in two halves whose difference
  estimates its own noise;
- Mitsuba at 1, 2, 4, ... spp (up to 4096) until its relMSE is under
  voxgi's, and the time at which it reaches voxgi's relMSE (log-log
  interpolation).

A relMSE against a reference with noise of its own is that noise plus the
image's own error. Where the reference's noise is not small against voxgi's
error (the door room, lit through a slit, takes a path tracer many samples),
no affordable sweep gets under voxgi's relMSE; then both errors are also
given less the reference's noise, and Mitsuba's time at voxgi's error so
measured is extrapolated from its last sweep render by the Monte Carlo law
(error proportional to 1/spp), and marked so. The door room's reference
takes 32,768 samples (``REFERENCE_SPP``).

It records relMSE (``voxgi.metrics.rel_mse``) and the brightness ratio, per
channel, of the pixels whose whole footprint sees surfaces that do not emit,
and writes ``benchmarks/results/interiors_<size>.json`` and each scene's
voxgi image as ``<tag>_voxgi_<size>.png``. Needs ``pip install mitsuba``
(the ``bench`` extra).

Usage::

    python benchmarks/interiors.py --size 128
    python benchmarks/interiors.py --scenes window-room door-room --size 256 --ref-spp 16384
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from pathlib import Path

import voxgi
from voxgi.compare import compare

sys.path.insert(0, str(Path(__file__).resolve().parent))
from time_vs_error import git_commit

RESULTS = Path(__file__).resolve().parent / "results"
SCENES = ["cornell-box", "window-room", "door-room", "sponza-atrium"]
#: Reference samples per pixel where ``--ref-spp`` would leave noise
#: comparable with voxgi's error (at 8192 the door room's is 9e-3).
REFERENCE_SPP = {"door-room": 32768}
#: The largest render of Mitsuba's sweep.
SWEEP_SPP = 4096


def _beyond_the_sweep(c, err: float) -> float | None:
    """Mitsuba's seconds at its own error ``err`` (the reference's noise
    taken off), extrapolated from the last sweep render by error ∝ 1/spp."""
    _, seconds, e = c.sweep[-1]
    own = e - c.reference_noise
    if own <= 0 or err <= 0:
        return None
    return seconds * own / err


def run_scene(name: str, size: int, ref_spp: int) -> dict:
    scene = voxgi.scenes.get(name, width=size, height=size)
    ref_spp = max(ref_spp, REFERENCE_SPP.get(name, 0))
    c = compare(scene, spp=ref_spp, max_sweep_spp=min(ref_spp // 2, SWEEP_SPP))
    vox_row = c.rows[0]
    own = vox_row["rel_mse"] - c.reference_noise
    extrapolated = c.mitsuba_seconds_to_match is None
    tag = name.replace("-", "_")
    voxgi.io.write_png(RESULTS / f"{tag}_voxgi_{size}.png", c.voxgi)
    return {
        "scene": name,
        "triangles": scene.n_triangles,
        "reference_spp": ref_spp,
        "reference_noise_rel_mse": c.reference_noise,
        "voxgi_seconds": vox_row["seconds"],
        "voxgi_rel_mse": vox_row["rel_mse"],
        "voxgi_brightness": vox_row["brightness"],
        "voxgi_frames": vox_row["frames"],
        "mitsuba": [{"spp": s, "seconds": t, "rel_mse": e} for s, t, e in c.sweep],
        "mitsuba_seconds_at_voxgi_error": (
            _beyond_the_sweep(c, own) if extrapolated else c.mitsuba_seconds_to_match
        ),
        "mitsuba_seconds_extrapolated": extrapolated,
        "voxgi_rel_mse_less_reference_noise": own,
    }


def print_row(r: dict) -> None:
    b = "/".join(f"{x:.3f}" for x in r["voxgi_brightness"])
    tm = r["mitsuba_seconds_at_voxgi_error"]
    ratio = "" if tm is None else f"{tm / r['voxgi_seconds']:5.2f}x"
    if r["mitsuba_seconds_extrapolated"] and tm is not None:
        own = r["voxgi_rel_mse_less_reference_noise"]
        ratio += f" (extrapolated, at the error less the reference noise, {own:.1e})"
    print(
        f"{r['scene']:14s} voxgi {r['voxgi_seconds']:6.2f} s  relMSE {r['voxgi_rel_mse']:.2e}  "
        f"brightness {b}  | Mitsuba at that relMSE {'-' if tm is None else f'{tm:6.2f} s'} "
        f"{ratio}  (reference noise {r['reference_noise_rel_mse']:.1e})",
        flush=True,
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", nargs="+", default=SCENES, choices=voxgi.scenes.names())
    ap.add_argument("--size", type=int, default=128, help="image width and height")
    ap.add_argument("--ref-spp", type=int, default=8192, help="reference samples per pixel")
    args = ap.parse_args(argv)
    rows = []
    for name in args.scenes:
        rows.append(run_scene(name, args.size, args.ref_spp))
        print_row(rows[-1])
    out = {
        "size": args.size,
        "commit": git_commit(),
        "machine": {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count()},
        "load_avg": os.getloadavg(),
        "scenes": rows,
    }
    path = RESULTS / f"interiors_{args.size}.json"
    path.write_text(json.dumps(out, indent=2))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
