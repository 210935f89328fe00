"""Interiors against a path tracer: voxgi's defaults and Mitsuba 3, side by side.

For each scene (``--scenes``; by default the Cornell box and the built-in
interiors that show what thin geometry does to discrete lines: the room lit
through a barred window, the room lit through a door left ajar, and the
Sponza-like atrium under its sky panel), in one run on this machine:

- the reference: Mitsuba 3's path tracer (``path``, ``max_depth = -1``, box
  filter) at ``--ref-spp`` samples, cached as
  ``benchmarks/results/<tag>_ref_<size>.exr`` by ``reference.py`` (its noise,
  estimated from two independent halves, is printed beside it);
- voxgi's defaults, ``voxgi.render(scene)``: voxelize, solve and display
  timed together; relMSE against the reference (``voxgi.metrics.rel_mse``)
  and the brightness ratio, per channel, of the pixels whose primary ray
  hits a surface that does not emit (the mean over those pixels against the
  reference's);
- Mitsuba at 4, 8, 16, ... spp (timed per render, after a warm-up render
  that compiles its kernels) until its relMSE is under voxgi's, and the
  time at which it reaches voxgi's relMSE (log-log interpolation).

Writes ``benchmarks/results/interiors_<size>.json``. Needs ``pip install
mitsuba`` (the ``bench`` extra).

Usage::

    python benchmarks/interiors.py --size 128
    python benchmarks/interiors.py --scenes window-room door-room --size 256 --ref-spp 16384
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

import voxgi
from voxgi.display import camera_rays
from voxgi.metrics import rel_mse
from voxgi.rays import Tracer

sys.path.insert(0, str(Path(__file__).resolve().parent))
from reference import render_reference, scene_tag
from time_vs_error import git_commit, time_to_error

RESULTS = Path(__file__).resolve().parent / "results"
SCENES = ["cornell-box", "window-room", "door-room", "sponza-atrium"]


def reference(name: str, size: int, spp: int) -> tuple[np.ndarray, dict]:
    """The cached reference of ``name`` at ``size``², rendered when missing
    or rendered from another version of the scene."""
    path = RESULTS / f"{scene_tag(name)}_ref_{size}.exr"
    fp = voxgi.scenes.get(name, width=size, height=size).fingerprint()
    if path.exists():
        meta = voxgi.io.read_exr_header(path)
        if meta.get("scene_fingerprint") == fp:
            info = json.loads(path.with_suffix(".json").read_text())
            return voxgi.io.read_exr(path), info
    print(f"  rendering the reference of {name} at {spp} spp ...", flush=True)
    img, info = render_reference(size, spp, passes=8, scene_name=name)
    voxgi.io.write_exr(path, img, metadata=info)
    voxgi.io.write_png(path.with_suffix(".png"), img)
    path.with_suffix(".json").write_text(json.dumps(info, indent=2))
    return img, info


def non_emitter_pixels(scene: voxgi.Scene) -> np.ndarray:
    """(H, W) bool: the pixel centre's primary ray hits a non-emitting surface."""
    cam = scene.camera
    org, dirs = camera_rays(cam)
    tri = scene.triangles()
    emits = np.any(tri["emission"] > 0, axis=1)[tri["object"]]
    with Tracer(scene, 1) as tr:
        prim = tr.intersect((org - tr.centre).astype(np.float32), dirs.astype(np.float32))
    hit = prim >= 0
    mask = np.zeros(len(prim), bool)
    mask[hit] = ~emits[prim[hit]]
    return mask.reshape(cam.height, cam.width)


def brightness(img: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> list[float]:
    """Per channel: mean of ``img`` over ``mask`` against the reference's."""
    return [float(img[..., c][mask].mean() / ref[..., c][mask].mean()) for c in range(3)]


def run_voxgi(scene: voxgi.Scene) -> tuple[np.ndarray, float, dict]:
    """``voxgi.render(scene)`` with every default, timed from the scene."""
    t0 = time.perf_counter()
    out = voxgi.render(scene, progress=False)
    seconds = time.perf_counter() - t0
    return out.image, seconds, {"frames": out.frames, "phases": out.stats["seconds"]}


def run_mitsuba(scene: voxgi.Scene, ref: np.ndarray, target: float) -> list[dict]:
    """Mitsuba at doubling spp until its relMSE is under ``target`` (or 65,536 spp)."""
    from voxgi.mitsuba import mitsuba_module, to_mitsuba

    mi = mitsuba_module()
    sc = mi.load_dict(to_mitsuba(scene, spp=4))
    np.array(mi.render(sc, spp=1, seed=999))  # warm-up: JIT compilation
    rows, spp = [], 4
    while spp <= 65536:
        t0 = time.perf_counter()
        img = np.array(mi.render(sc, spp=spp, seed=spp), dtype=np.float32)[..., :3]
        rows.append({"spp": spp, "seconds": time.perf_counter() - t0, "rel_mse": rel_mse(img, ref)})
        if rows[-1]["rel_mse"] <= target and len(rows) >= 2:
            break
        spp *= 2
    return rows


def run_scene(name: str, size: int, ref_spp: int) -> dict:
    scene = voxgi.scenes.get(name, width=size, height=size)
    ref, ref_info = reference(name, size, ref_spp)
    mask = non_emitter_pixels(scene)
    img, seconds, info = run_voxgi(scene)
    err = rel_mse(img, ref)
    mts = run_mitsuba(scene, ref, err)
    row = {
        "scene": name,
        "triangles": scene.n_triangles,
        "reference_spp": ref_info.get("spp"),
        "reference_noise_rel_mse": ref_info.get("noise_rel_mse_est"),
        "voxgi_seconds": seconds,
        "voxgi_rel_mse": err,
        "voxgi_brightness": brightness(img, ref, mask),
        "voxgi_frames": info["frames"],
        "voxgi_phases": info["phases"],
        "mitsuba": mts,
        "mitsuba_seconds_at_voxgi_error": time_to_error(mts, err),
    }
    voxgi.io.write_png(RESULTS / f"{scene_tag(name)}_voxgi_{size}.png", img)
    return row


def print_row(r: dict) -> None:
    b = "/".join(f"{x:.3f}" for x in r["voxgi_brightness"])
    tm = r["mitsuba_seconds_at_voxgi_error"]
    ratio = "" if tm is None else f"{tm / r['voxgi_seconds']:5.2f}x"
    noise = r["reference_noise_rel_mse"]
    print(
        f"{r['scene']:14s} voxgi {r['voxgi_seconds']:6.2f} s  relMSE {r['voxgi_rel_mse']:.2e}  "
        f"brightness {b}  | Mitsuba at that relMSE {'-' if tm is None else f'{tm:6.2f} s'} "
        f"{ratio}  (reference noise {'-' if noise is None else f'{noise:.1e}'})",
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
        "scenes": rows,
    }
    path = RESULTS / f"interiors_{args.size}.json"
    path.write_text(json.dumps(out, indent=2, default=lambda x: None if math.isnan(x) else x))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
