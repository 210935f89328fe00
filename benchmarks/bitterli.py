"""voxgi's defaults against Mitsuba 3, plain and denoised, on real interiors.

The scenes: every whole scene of Bitterli's Mitsuba interiors as
``scripts/extract_bitterli.py`` extracts them (``<scenes>/<name>/diffuse/scene.toml``,
the scene as voxgi loads it, textures and glossy lobes included); for a
scene that is not whole, its partial variant where one was written
(``<name>-partial``: the shapes whose meshes the snapshot lacks left out,
missing textures grey; ``extract_bitterli.py --partial``); and the built-in
Cornell box, window room and door room. Each is rendered at
``--width`` pixels wide (the height keeps the camera's aspect) by

- voxgi's defaults (``voxgi.render(scene)``: voxelize, solve, display),
- Mitsuba 3 ``llvm_ad_rgb`` (``voxgi.mitsuba.to_mitsuba`` of the same loaded
  scene) at 4, 16, 64, 256, ... spp, plain and denoised by OIDN with albedo
  and normal buffers from Mitsuba's ``aov`` integrator (AOV time included),

in one run on one machine, all against a Mitsuba reference at high spp of
the same scene (``--ref-spp``; cached under ``--refs``, rendered in passes
split into two halves whose relMSE against each other, divided by 4,
estimates the reference's own noise). It prints, per scene, voxgi's relMSE,
SSIM, brightness off the lamps per channel and seconds (voxelize / solve /
display), and Mitsuba's seconds to voxgi's relMSE and to relMSE 5e-3 and
1e-3, plain and +OIDN (log-log interpolation over the sweep), with SSIM at
each sweep point; ``--voxgi-denoise`` adds voxgi's solution displayed
denoised (``RenderTuning(denoise=True)``) and Mitsuba + OIDN's time to its
relMSE; ``--json`` writes everything.

Usage::

    python scripts/extract_bitterli.py                         # the scenes, once
    nice python benchmarks/bitterli.py --references-only       # the references, once
    python benchmarks/bitterli.py                              # the comparison
    python benchmarks/bitterli.py living-room cornell-box --json out.json

Needs the ``bench`` extra (``pip install 'voxgi[bench]'``: Mitsuba 3 and
``mitsuba-oidn``); ``llvm_ad_rgb`` needs libLLVM >= 16 (see CONTRIBUTING.md
for ``DRJIT_LIBLLVM_PATH``).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import time
from pathlib import Path

import numpy as np

import voxgi
from voxgi.compare import SWEEP_TOL, compare
from voxgi.metrics import rel_mse

SCENES_DIR = Path("/work/scenes")
REFS_DIR = Path("/work/refs")
BITTERLI = ("bathroom", "bathroom2", "dining-room", "kitchen", "living-room", "staircase",
            "staircase2")  # fmt: skip
BUILT_IN = ("cornell-box", "window-room", "door-room")


def _extracted(scenes_dir: Path) -> list[str]:
    """Each of Bitterli's scenes extracted whole, or else its partial variant."""
    names = []
    for n in BITTERLI:
        for variant in (n, f"{n}-partial"):
            if (scenes_dir / variant / "diffuse" / "scene.toml").exists():
                names.append(variant)
                break
    return names


def load(name: str, width: int, scenes_dir: Path = SCENES_DIR) -> voxgi.Scene:
    """A built-in scene or an extracted interior, its camera ``width`` pixels wide."""
    if name in BUILT_IN:
        scene = voxgi.scenes.get(name)
    else:
        scene = voxgi.Scene.load(scenes_dir / name / "diffuse" / "scene.toml")
    cam = scene.camera
    height = max(1, round(width * cam.height / cam.width))
    scene.camera = cam.replace(width=width, height=height)
    return scene


def reference(
    scene: voxgi.Scene,
    tag: str,
    spp: int,
    *,
    refs_dir: Path = REFS_DIR,
    pass_spp: int = 128,
    verbose: bool = True,
) -> tuple[np.ndarray, float, dict]:
    """Mitsuba's reference of ``scene``: (image, estimated own relMSE, info).

    Rendered in passes of ``pass_spp`` samples alternating between two
    halves; progress is saved after each pass under ``refs_dir``, so an
    interrupted render resumes and a finished one is read back. One process
    at a time renders a given reference; another asking for it waits.
    """
    cam = scene.camera
    fp = scene.fingerprint()
    base = refs_dir / f"{tag}_{cam.width}x{cam.height}_{fp}"
    refs_dir.mkdir(parents=True, exist_ok=True)
    with _lock(base.with_suffix(".lock")):
        sums, info = _render_passes(scene, tag, spp, base, pass_spp, verbose)
    n = int(info["passes_done"])
    half_a = (sums[0] / (n - n // 2)).astype(np.float32)
    half_b = (sums[1] / (n // 2)).astype(np.float32)
    noise = 0.25 * rel_mse(half_a, half_b)
    info["noise_rel_mse_est"] = noise
    return ((sums[0] + sums[1]) / n).astype(np.float32), noise, info


@contextlib.contextmanager
def _lock(path: Path):
    """Hold ``path`` as a lock; a lock left by a process that died is taken over."""
    while True:
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            os.write(fd, str(os.getpid()).encode())
            os.close(fd)
            break
        except FileExistsError:
            try:
                os.kill(int(path.read_text() or "0"), 0)
            except (ProcessLookupError, ValueError, FileNotFoundError):
                path.unlink(missing_ok=True)
                continue
            time.sleep(10)
    try:
        yield
    finally:
        path.unlink(missing_ok=True)


def _render_passes(scene, tag: str, spp: int, base: Path, pass_spp: int, verbose: bool):
    """The two halves' sums and the record, rendering the passes still missing."""
    from voxgi.mitsuba import mitsuba_module, to_mitsuba

    cam = scene.camera
    meta_path, arr_path = base.with_suffix(".json"), base.with_suffix(".npz")
    info = json.loads(meta_path.read_text()) if meta_path.exists() else {}
    passes = max(2, spp // pass_spp)
    if arr_path.exists():
        with np.load(arr_path) as z:
            sums = [z["a"], z["b"]]
    else:
        sums = [np.zeros((cam.height, cam.width, 3)), np.zeros((cam.height, cam.width, 3))]
    done = int(info.get("passes_done", 0))
    if done >= passes:
        return sums, info
    mi = mitsuba_module()
    sc = mi.load_dict(to_mitsuba(scene, spp=pass_spp))
    t0 = time.perf_counter() - float(info.get("seconds", 0.0))
    for p in range(done, passes):
        img = mi.render(sc, spp=pass_spp, seed=10_000 + p)
        sums[p % 2] += np.array(img, dtype=np.float64)[..., :3]
        info.update(
            tag=tag,
            variant=mi.variant(),
            mitsuba=mi.__version__,
            pass_spp=pass_spp,
            passes_done=p + 1,
            spp=pass_spp * (p + 1),
            seconds=time.perf_counter() - t0,
            scene_fingerprint=scene.fingerprint(),
        )
        part = Path(str(arr_path) + ".part.npz")
        np.savez(part, a=sums[0], b=sums[1])
        part.replace(arr_path)
        meta_path.write_text(json.dumps(info, indent=2))
        if verbose and (p + 1) % 4 == 0:
            print(f"  {tag}: {info['spp']} spp, {info['seconds']:.0f} s", flush=True)
    return sums, info


def original_render(xml: Path, width: int, spp: int) -> np.ndarray:
    """Mitsuba's render of the scene file ``xml`` as written (its own BSDFs,
    textures and glass), ``width`` pixels wide: the camera check."""
    import re

    from voxgi.mitsuba import mitsuba_module

    mi = mitsuba_module()
    folder = xml.parent
    text = xml.read_text(encoding="utf-8")
    w = int(re.search(r'name="width" value="(\d+)"', text).group(1))
    h = int(re.search(r'name="height" value="(\d+)"', text).group(1))
    text = re.sub(r'(name="width" value=")\d+', rf"\g<1>{width}", text, count=1)
    text = re.sub(r'(name="height" value=")\d+', rf"\g<1>{round(width * h / w)}", text, count=1)
    mi.file_resolver().prepend(str(folder))
    sc = mi.load_string(text)
    return np.ascontiguousarray(np.array(mi.render(sc, spp=spp), np.float32)[..., :3])


def side_by_side(path: Path, images: list[np.ndarray]) -> Path:
    """The images in a row, 4 pixels apart, one exposure chosen from the first."""
    from PIL import Image

    from voxgi.io import to_srgb8

    lum = images[0].mean(axis=2)
    exposure = float(np.log2(0.18 / max(float(np.exp(np.log(lum + 1e-4).mean())), 1e-8)))
    h = max(im.shape[0] for im in images)
    gap = np.full((h, 4, 3), 255, np.uint8)
    row = []
    for im in images:
        tile = np.zeros((h, im.shape[1], 3), np.uint8)
        tile[: im.shape[0]] = to_srgb8(im, exposure)
        row += [tile, gap]
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.concatenate(row[:-1], axis=1)).save(path)
    return path


def summary(name: str, scene: voxgi.Scene, res) -> dict:
    """The figures of one scene: voxgi's row and Mitsuba's times to each target."""
    v = res.rows[0]
    den = next((r for r in res.rows if r["method"] == "voxgi+oidn"), None)

    def best(method, target):
        t = res.time_to.get(method, {}).get(target)
        return None if t is None else round(t, 3)

    return {
        "scene": name,
        "triangles": int(sum(len(o.faces) for o in scene.objects)),
        "size": [scene.camera.width, scene.camera.height],
        "voxgi_rel_mse": v["rel_mse"],
        "voxgi_rel_mse_net": v["rel_mse_net"],
        "voxgi_ssim": v["ssim"],
        "voxgi_flip": v["flip"],
        "brightness": v["brightness"],
        "voxgi_seconds": v["seconds"],
        "voxgi_phases": v["phases"],
        "frames": v["frames"],
        "voxgi_oidn": None
        if den is None
        else {k: den[k] for k in ("rel_mse", "rel_mse_net", "ssim", "flip", "seconds", "frames")},
        "reference_noise": res.reference_noise,
        "time_to": {m: {str(k): best(m, k) for k in t} for m, t in res.time_to.items()},
        "sweep_voxgi": res.sweep_voxgi,
        "rows": res.rows,
    }


def _fmt(t) -> str:
    return "-" if t is None else f"{t:.3g}"


def print_table(rows: list[dict]) -> None:
    print(
        "| scene | tris | voxgi relMSE (net) | SSIM | brightness R/G/B"
        " | voxgi s (vox/solve/display)"
        " | Mitsuba s to voxgi's relMSE: plain / +OIDN"
        " | s to 5e-3: voxgi / Mitsuba / +OIDN | s to 1e-3: voxgi / Mitsuba / +OIDN"
        " | ref noise |"
        + (
            " voxgi+OIDN net relMSE, SSIM, s; Mitsuba+OIDN s to it | voxgi+OIDN s to 5e-3 / 1e-3 |"
            if any(r.get("voxgi_oidn") for r in rows)
            else ""
        )
    )
    print("|" + "---|" * (12 if any(r.get("voxgi_oidn") for r in rows) else 10))
    for r in rows:
        ph, t = r["voxgi_phases"], r["time_to"]
        b = " / ".join(f"{x:.3f}" for x in r["brightness"])
        cells = [
            r["scene"],
            str(r["triangles"]),
            f"{r['voxgi_rel_mse']:.2e} ({r['voxgi_rel_mse_net']:.2e})",
            f"{r['voxgi_ssim']:.4f}",
            b,
            f"{r['voxgi_seconds']:.1f} ({ph['voxelize']:.1f} / {ph['solve']:.1f} / "
            f"{ph['display']:.1f})",
        ]
        for key in ("voxgi", str(5e-3), str(1e-3)):
            plain = t.get("mitsuba", {}).get(key)
            den = t.get("mitsuba+oidn", {}).get(key)
            own = "" if key == "voxgi" else f"{_fmt(t.get('voxgi', {}).get(key))} / "
            cells.append(f"{own}{_fmt(plain)} / {_fmt(den)}")
        cells.append(f"{r['reference_noise']:.1e}")
        den = r.get("voxgi_oidn")
        if den is not None:
            to = t.get("mitsuba+oidn", {}).get("voxgi+oidn")
            cells.append(
                f"{den['rel_mse_net']:.2e}, SSIM {den['ssim']:.4f}, {den['seconds']:.1f} s; "
                f"Mitsuba+OIDN {_fmt(to)} s"
            )
            own = t.get("voxgi+oidn", {})
            cells.append(f"{_fmt(own.get(str(5e-3)))} / {_fmt(own.get(str(1e-3)))}")
        print("| " + " | ".join(cells) + " |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="*", help="scene names (default: the whole ones and built-ins)")
    ap.add_argument("--width", type=int, default=256)
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--sweep", type=int, nargs="+", default=[4, 16, 64, 256, 1024])
    ap.add_argument("--scenes-dir", type=Path, default=SCENES_DIR)
    ap.add_argument("--refs", type=Path, default=REFS_DIR)
    ap.add_argument("--references-only", action="store_true")
    ap.add_argument("--no-denoise", action="store_true")
    ap.add_argument(
        "--voxgi-denoise",
        action="store_true",
        help="also voxgi's solution displayed with RenderTuning(denoise=True)",
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--sweep-tol",
        type=float,
        nargs="*",
        default=list(SWEEP_TOL),
        help="tolerances, looser than the default, at which voxgi runs again for its time "
        "to each target (solving anew where SolveTuning.for_picture asks for a lighter solve)",
    )
    ap.add_argument(
        "--pictures",
        type=Path,
        default=None,
        help="folder for side-by-side PNGs: voxgi | reference | Mitsuba's render of the file",
    )
    ap.add_argument("--original-spp", type=int, default=64)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    names = args.scenes or [*_extracted(args.scenes_dir), *BUILT_IN]
    rows = []
    for name in names:
        scene = load(name, args.width, args.scenes_dir)
        ref, noise, info = reference(scene, name, args.ref_spp, refs_dir=args.refs)
        print(f"{name}: reference {info['spp']} spp, {info['seconds']:.0f} s, noise {noise:.1e}")
        if args.references_only:
            continue
        res = compare(
            scene,
            reference=(ref, noise),
            sweep_spp=args.sweep,
            denoise=not args.no_denoise,
            seed=args.seed,
            voxgi_denoise=args.voxgi_denoise,
            sweep_tol=args.sweep_tol,
        )
        print(res.table(), flush=True)
        rows.append(summary(name, scene, res) | {"reference_spp": info["spp"]})
        if args.pictures is not None:
            pics = [res.voxgi, res.reference]
            if name not in BUILT_IN:
                xml = args.scenes_dir / name / "scene.xml"
                if name.endswith("-partial"):
                    xml = args.scenes_dir / name.removesuffix("-partial") / "scene.partial.xml"
                pics.append(original_render(xml, args.width, args.original_spp))
            print("  wrote", side_by_side(args.pictures / f"{name}_{args.width}.png", pics))
    if rows:
        print_table(rows)
    if args.json is not None:
        args.json.write_text(json.dumps({"scenes": rows}, indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
