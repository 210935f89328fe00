"""Time against error on a built-in scene: voxgi's whole pipeline vs Mitsuba 3.

``--scene`` picks the scene (default ``cornell-box``; any name of
``voxgi.scenes.names()``, e.g. ``shadow``, ``geometric``). For each image
size, in one run on this machine:

- voxgi at several settings: voxelize + solve + display, timed together
  (wall clock, everything included);
- Mitsuba 3 (``path``, ``max_depth = -1``, box filter; fastest CPU variant,
  ``llvm_ad_rgb`` when libLLVM >= 16 is found) at several sample counts,
  timed per render after a warm-up render (JIT compilation and scene
  loading excluded);
- relMSE (``voxgi.metrics.rel_mse``) of each against the reference of
  ``benchmarks/reference.py --scene <scene>`` (run that first); for voxgi
  the mean over ``--seeds`` displays (default 3) of one solution, whose
  mean display time is the one counted;
- the time of a second view with the saved solution (display only; for the
  Cornell box a fixed camera, for the other scenes the scene's camera turned
  25 degrees round the vertical through its target);
- optionally (``--split``) voxgi's error split into voxel discretisation
  (near noise-free renders at rising voxel resolution) and display noise
  (the defaults' render against the noise-free one at the same resolution).

Writes ``benchmarks/results/time_vs_error_<size>.json``, a PNG plot
``time_vs_error_<size>.png``, and ``cornell_diff_<size>.png`` (voxgi
``--main`` setting, reference, relative difference) for the Cornell box;
for another scene ``time_vs_error_<tag>_<size>.{json,png}`` and
``<tag>_diff_<size>.png`` (``<tag>``: the scene name with ``_`` for ``-``,
as ``reference.py`` names the reference). Prints a table and the time each
renderer takes to reach relMSE 5e-3 and 1e-3.

Usage::

    python benchmarks/time_vs_error.py --size 256 512 --split
    python benchmarks/time_vs_error.py --scene shadow --size 256
    python benchmarks/time_vs_error.py --scene geometric --size 256
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import platform
import subprocess
import time
from pathlib import Path

import numpy as np

import voxgi
from voxgi.metrics import rel_mse
from voxgi.resolution import solve_scene

RESULTS = Path(__file__).resolve().parent / "results"

# (label, voxelize resolution, solve directions, render kwargs); None = library default.
_RES, _R = voxgi.voxels.DEFAULT_RESOLUTION, voxgi.radiosity.tuning.TRACED_RADIUS
#: the largest grid voxgi.render(scene) tries, with its other defaults
MAIN = f"res{_RES} R{_R} tol1e-3"
VOXGI_SETTINGS = [
    (f"res32 R{_R} f8", 32, _R, {"max_frames": 8, "tol": 0.0}),
    (f"res48 R{_R} f8", 48, _R, {"max_frames": 8, "tol": 0.0}),
    (f"res64 R{_R} f8", 64, _R, {"max_frames": 8, "tol": 0.0}),
    (f"res48 R{_R} tol1e-3", 48, _R, {}),
    (MAIN, _RES, _R, {}),
    (f"res{_RES} R{_R} tol5e-4", _RES, _R, {"tol": 5e-4}),
    ("res64 R8 tol1e-3", 64, 8, {}),
    (f"res96 R{_R} tol1e-3", 96, _R, {}),
    ("res64 R12 tol1e-3", 64, 12, {}),
]
#: voxelize + solve + render with every default, as voxgi.render(scene):
#: the resolution it chooses (voxgi.resolution.solve_scene).
DEFAULTS = ("defaults", None, None, {})
#: one finer voxelization, run with --high (minutes on 2 cores).
HIGH = (f"res128 R{_R} tol1e-3", 128, _R, {})
MITSUBA_SPP = [4, 16, 64, 256, 1024]
CORNELL = "cornell-box"


def scene_tag(name: str) -> str:
    """File-name stem of a scene's results (as ``reference.py``): ``cornell``
    for the Cornell box, else the name with ``_`` for ``-``."""
    key = name.replace("_", "-").lower()
    return "cornell" if key == CORNELL else key.replace("-", "_")


def make_scene(name: str, size: int) -> voxgi.Scene:
    return voxgi.scenes.get(name, width=size, height=size)


def output_stem(name: str, size: int) -> str:
    """``time_vs_error_<size>`` for the Cornell box (unchanged), else
    ``time_vs_error_<tag>_<size>``."""
    tag = scene_tag(name)
    return f"time_vs_error_{size}" if tag == "cornell" else f"time_vs_error_{tag}_{size}"


def git_commit() -> str:
    try:
        return subprocess.check_output(
            ["git", "rev-parse", "--short", "HEAD"], text=True, cwd=Path(__file__).parent
        ).strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def load_reference(size: int, name: str = CORNELL) -> np.ndarray:
    path = RESULTS / f"{scene_tag(name)}_ref_{size}.exr"
    if not path.exists():
        raise SystemExit(
            f"{path} missing: run python benchmarks/reference.py --scene {name} --size {size}"
        )
    meta = voxgi.io.read_exr_header(path)
    fp = voxgi.scenes.get(name).fingerprint()
    if meta.get("scene_fingerprint") not in (None, fp):
        raise SystemExit(
            f"{path} was rendered from another {name} scene (fingerprint "
            f"{meta.get('scene_fingerprint')} != {fp}): rerun reference.py"
        )
    return voxgi.io.read_exr(path)


def run_voxgi(
    size: int, resolution, directions, render_kw: dict, seed: int = 0, name: str = CORNELL
):
    scene = make_scene(name, size)
    t0 = time.perf_counter()
    if resolution is None:
        # every default: the resolution voxgi.render(scene) chooses
        sol = solve_scene(scene, progress=False, **render_kw)
        t1 = t0 + sol.stats["resolution"]["voxelize_seconds"]
    else:
        vox = voxgi.voxelize(scene, resolution)
        t1 = time.perf_counter()
        # solved as voxgi.render(scene) solves, at the radius asked for
        radius = {} if directions is None else {"radius": directions}
        sol = voxgi.solve(vox, **radius, progress=False)
    t2 = time.perf_counter()
    out = voxgi.render(scene, sol, progress=False, seed=seed, **render_kw)
    t3 = time.perf_counter()
    phases = {"voxelize": t1 - t0, "solve": t2 - t1, "display": t3 - t2}
    return out, sol, t3 - t0, phases


def second_camera(scene: voxgi.Scene, name: str):
    """The second view: a fixed camera in the Cornell box; elsewhere the
    scene's camera turned 25 degrees round the vertical through its target."""
    if scene_tag(name) == "cornell":
        return scene.camera.replace(eye=(0.12, 0.40, -0.55), target=(0.30, 0.22, 0.30))
    eye = np.asarray(scene.camera.eye, float)
    target = np.asarray(scene.camera.target, float)
    a = math.radians(25.0)
    d = eye - target
    rot = np.array(
        [d[0] * math.cos(a) + d[2] * math.sin(a), d[1], -d[0] * math.sin(a) + d[2] * math.cos(a)]
    )
    return scene.camera.replace(eye=tuple(target + rot), target=tuple(target))


def second_view(
    size: int, sol, render_kw: dict, tmp: Path, name: str = CORNELL, out_dir: Path = RESULTS
) -> dict:
    """Time a new camera on a saved and reloaded solution (display only)."""
    scene = make_scene(name, size)
    cam = second_camera(scene, name)
    info = {"eye": list(map(float, cam.eye)), "target": list(map(float, cam.target))}
    try:
        t0 = time.perf_counter()
        sol.save(tmp / "solution.npz")
        sol2 = voxgi.Solution.load(tmp / "solution.npz")
        info["save_load_seconds"] = time.perf_counter() - t0
    except NotImplementedError:
        sol2 = sol
        info["save_load_seconds"] = None
    t0 = time.perf_counter()
    out = voxgi.render(scene, sol2, camera=cam, progress=False, **render_kw)
    info["seconds"] = time.perf_counter() - t0
    info["frames"] = out.frames
    info["display_phases"] = out.stats["seconds"]
    voxgi.io.write_png(out_dir / f"{scene_tag(name)}_second_view_{size}.png", out.image)
    return info


def run_mitsuba(size: int, spps, variant=None, name: str = CORNELL) -> list[dict]:
    from voxgi.mitsuba import mitsuba_module, to_mitsuba

    mi = mitsuba_module(variant)
    scene = make_scene(name, size)
    sc = mi.load_dict(to_mitsuba(scene, spp=max(spps)))
    np.array(mi.render(sc, spp=1, seed=999))  # warm-up: JIT compilation
    rows = []
    for spp in spps:
        t0 = time.perf_counter()
        img = np.array(mi.render(sc, spp=spp, seed=spp), dtype=np.float32)[..., :3]
        rows.append(
            {"spp": spp, "seconds": time.perf_counter() - t0, "image": img, "variant": mi.variant()}
        )
    return rows


def time_to_error(rows: list[dict], target: float) -> float | None:
    """Interpolated (log-log) time at which a method's relMSE reaches ``target``."""
    pts = sorted((r["seconds"], r["rel_mse"]) for r in rows)
    for (t0, e0), (t1, e1) in itertools.pairwise(pts):
        if e0 >= target >= e1 and e0 > e1:
            a = math.log(e0 / target) / math.log(e0 / e1)
            return math.exp(math.log(t0) + a * math.log(t1 / t0))
    for t, e in pts:
        if e <= target:
            return t
    return None


def diff_png(img: np.ndarray, ref: np.ndarray, path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rel = (img - ref).mean(axis=2) / (ref.mean(axis=2) + 0.1)
    fig, ax = plt.subplots(1, 3, figsize=(12, 4.2))
    ax[0].imshow(voxgi.io.to_srgb8(img))
    ax[0].set_title("voxgi " + title)
    ax[1].imshow(voxgi.io.to_srgb8(ref))
    ax[1].set_title("Mitsuba 3 reference")
    lim = max(0.05, float(np.percentile(np.abs(rel), 99)))
    im = ax[2].imshow(rel, cmap="RdBu_r", vmin=-lim, vmax=lim)
    ax[2].set_title("(voxgi - ref) / (ref + 0.1), mean RGB")
    fig.colorbar(im, ax=ax[2], fraction=0.046)
    for a in ax:
        a.set_axis_off()
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot(
    size: int, vrows: list[dict], mrows: list[dict], path: Path, title: str = "Cornell box"
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    ax.loglog(
        [r["seconds"] for r in mrows],
        [r["rel_mse"] for r in mrows],
        "o-",
        label=f"Mitsuba 3 path ({mrows[0]['variant']})",
    )
    for r in mrows:
        ax.annotate(f"{r['spp']} spp", (r["seconds"], r["rel_mse"]), fontsize=7)
    ax.loglog(
        [r["seconds"] for r in vrows],
        [r["rel_mse"] for r in vrows],
        "s",
        label="voxgi (voxelize + solve + display)",
    )
    for r in vrows:
        ax.annotate(r["label"], (r["seconds"], r["rel_mse"]), fontsize=7)
    ax.axhline(5e-3, color="grey", lw=0.8, ls="--")
    ax.axhline(1e-3, color="grey", lw=0.8, ls=":")
    ax.set_xlabel("seconds (wall clock, this machine)")
    ax.set_ylabel("relMSE vs reference")
    ax.set_title(f"{title} {size}x{size}")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def split_error(
    size: int,
    default_img: np.ndarray,
    ref: np.ndarray,
    resolutions,
    frames: int,
    directions=None,
    name: str = CORNELL,
) -> list[dict]:
    """Near noise-free voxgi renders at rising resolution: the discretisation error."""
    rows = []
    for res in resolutions:
        out, _, secs, _ = run_voxgi(
            size, res, directions, {"max_frames": frames, "tol": 0.0}, seed=7, name=name
        )
        rows.append(
            {
                "resolution": res,
                "frames": frames,
                "seconds": secs,
                "rel_mse_vs_ref": rel_mse(out.image, ref),
                "est_noise_rel_mse": out.stats["est_rel_mse"],
                "image": out.image,
            }
        )
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--scene",
        default=CORNELL,
        help="built-in scene name (voxgi.scenes.names()); default cornell-box",
    )
    ap.add_argument("--size", type=int, nargs="+", default=[256])
    ap.add_argument("--spp", type=int, nargs="+", default=MITSUBA_SPP)
    ap.add_argument("--variant", default=None)
    ap.add_argument("--split", action="store_true", help="also split voxgi's error")
    ap.add_argument(
        "--high", action="store_true", help=f"also run voxgi at resolution 128, R {_R}, tol 1e-3"
    )
    ap.add_argument(
        "--main",
        default=MAIN,
        help="setting used for the difference image, second view and split",
    )
    ap.add_argument("--split-frames", type=int, default=128)
    ap.add_argument(
        "--seeds",
        type=int,
        default=3,
        help="voxgi displays per setting (seeds 0..N-1): relMSE and display time are their means",
    )
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    name, tag = args.scene, scene_tag(args.scene)
    title = "Cornell box" if tag == "cornell" else f"{name} (voxgi.scenes)"
    for size in args.size:
        ref = load_reference(size, name)
        load_start = os.getloadavg()
        vrows = []
        default = None
        settings = VOXGI_SETTINGS + ([HIGH] if args.high else []) + [DEFAULTS]
        scene_s = make_scene(name, size)  # the extra seeds' displays
        for label, res, dirs, kw in settings:
            out, sol, secs, phases = run_voxgi(size, res, dirs, kw, name=name)
            # A display's error at a few frames varies by +-40% with the seed
            # (a frame's VPLs are shared by every pixel, so its noise is
            # correlated across the image): average over seeds, each a
            # display of the same solution, and time the mean display.
            errs, disp = [rel_mse(out.image, ref)], [phases["display"]]
            for seed in range(1, args.seeds):
                t0 = time.perf_counter()
                o2 = voxgi.render(scene_s, sol, progress=False, seed=seed, **kw)
                disp.append(time.perf_counter() - t0)
                errs.append(rel_mse(o2.image, ref))
            secs = phases["voxelize"] + phases["solve"] + float(np.mean(disp))
            phases = {**phases, "display": float(np.mean(disp))}
            row = {
                "label": label,
                "resolution": sol.vox.resolution,
                "records": len(sol.vox),
                "directions": dirs,
                "render": kw,
                "frames": out.frames,
                "seconds": secs,
                "phases": phases,
                "rel_mse": float(np.mean(errs)),
                "rel_mse_seeds": errs,
                "est_noise_rel_mse": out.stats["est_rel_mse"],
                "shadow_rays": out.stats["shadow_rays"],
                "vpl_split": out.stats["vpl_split"],
            }
            vrows.append(row)
            print(
                f"voxgi   {label:>20s}: {secs:7.2f} s  relMSE {row['rel_mse']:.2e} "
                f"(seeds {' '.join(f'{e:.1e}' for e in errs)})  "
                f"({out.frames} frames; vox {phases['voxelize']:.2f} solve "
                f"{phases['solve']:.2f} display {phases['display']:.2f})",
                flush=True,
            )
            if label == args.main:
                default = (out, sol, row)
        mrows = run_mitsuba(size, args.spp, args.variant, name=name)
        for r in mrows:
            r["rel_mse"] = rel_mse(r.pop("image"), ref)
            print(
                f"mitsuba {r['spp']:>16d} spp: {r['seconds']:7.2f} s  relMSE {r['rel_mse']:.2e}",
                flush=True,
            )
        result = {
            "scene": name,
            "size": size,
            "voxgi": vrows,
            "mitsuba": mrows,
            "commit": git_commit(),
            "voxgi_version": voxgi.__version__,
            "cpu": platform.processor(),
            "threads": voxgi._core.hardware_threads(),
            # 1/5/15-minute load averages before the voxgi runs and after
            # Mitsuba's: tells a quiet run from a contended one.
            "loadavg": {"start": load_start, "after_mitsuba": os.getloadavg()},
        }
        if default is not None:
            out, sol, row = default
            diff_png(
                out.image,
                ref,
                args.out / f"{tag}_diff_{size}.png",
                f"{row['label']} ({row['seconds']:.1f} s, relMSE {row['rel_mse']:.2e})",
            )
            voxgi.io.write_png(args.out / f"{tag}_voxgi_{size}.png", out.image)
            import tempfile

            with tempfile.TemporaryDirectory() as tmp:
                result["second_view"] = second_view(
                    size, sol, row["render"], Path(tmp), name=name, out_dir=args.out
                )
            print(
                f"second view (saved solution, display only): "
                f"{result['second_view']['seconds']:.2f} s",
                flush=True,
            )
            if args.split:
                rows = split_error(
                    size,
                    out.image,
                    ref,
                    sorted({32, 48, sol.vox.resolution, 96}),
                    args.split_frames,
                    directions=row["directions"],
                    name=name,
                )
                same = [r for r in rows if r["resolution"] == sol.vox.resolution][-1]
                noise = rel_mse(out.image, same["image"])
                for r in rows:
                    r.pop("image")
                    print(
                        f"split: res {r['resolution']:4d}, {r['frames']} frames: relMSE vs "
                        f"ref {r['rel_mse_vs_ref']:.2e} (noise est {r['est_noise_rel_mse']:.1e})"
                    )
                print(
                    f"split: {row['label']} vs {same['frames']}-frame render at the same "
                    "resolution "
                    f"(display noise) {noise:.2e}"
                )
                result["split"] = {
                    "rows": rows,
                    "display_noise_rel_mse": noise,
                    "defaults_rel_mse": row["rel_mse"],
                }
        for target in (5e-3, 1e-3):
            tv = min((r["seconds"] for r in vrows if r["rel_mse"] <= target), default=None)
            tm = time_to_error(mrows, target)
            result[f"time_to_{target:.0e}"] = {"voxgi_best": tv, "mitsuba": tm}
            print(
                f"time to relMSE {target:.0e}: voxgi (fastest setting) "
                f"{'-' if tv is None else f'{tv:.2f} s'}, Mitsuba "
                f"{'-' if tm is None else f'{tm:.2f} s'}"
            )
        print("\n| method | setting | seconds | relMSE |\n|---|---|---|---|")
        for r in vrows:
            print(
                f"| voxgi | {r['label']} ({r['records']} records, {r['frames']} frames) | "
                f"{r['seconds']:.2f} | {r['rel_mse']:.2e} |"
            )
        for r in mrows:
            print(
                f"| Mitsuba {r['variant']} | {r['spp']} spp | {r['seconds']:.2f} | "
                f"{r['rel_mse']:.2e} |"
            )
        stem = output_stem(name, size)
        (args.out / f"{stem}.json").write_text(json.dumps(result, indent=2, default=float))
        plot(size, vrows, mrows, args.out / f"{stem}.png", title=title)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
