"""Direct light on the records: the discrete shooting against shadow rays to the exact emitters.

For each scene, every object's area-weighted direct irradiance (luminance)
from both methods is divided by a converged shadow-ray integration at the
same record points (512 samples, records refined to 2% standard error),
beside each method's seconds. Then the all-emitting furnace sphere: its
direct light and whole solve by each method, and the solve's error against
``Le / (1 - rho)``.

    python benchmarks/direct_light.py [--resolution 64] [--threads 2]

Writes ``results/direct_light.json``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import voxgi
from voxgi.direct import direct_irradiance

RESULTS = Path(__file__).parent / "results"
LUM = np.array([0.2126, 0.7152, 0.0722])


def _direct_by_shooting(vox, threads):
    """H_d of the paper's shooting: a solve with no gathering, B = E + rho H_d."""
    t = time.perf_counter()
    sol = voxgi.solve(
        vox,
        max_bounces=0,
        threads=threads,
        progress=False,
        tuning=voxgi.SolveTuning.paper(diagnostics=False),
    )
    rho = vox.albedo.astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        hd = np.where(rho > 0, (sol.radiosity - np.pi * vox.emission) / rho, 0.0)
    return hd, sol.stats["seconds"]["shoot"], time.perf_counter() - t


def per_object(name: str, resolution: int, threads: int) -> dict:
    scene = voxgi.scenes.get(name)
    vox = voxgi.voxelize(scene, resolution=resolution, progress=False)
    print(
        f"{name} at resolution {resolution}: {len(vox):,} records; converged reference ...",
        flush=True,
    )
    ref, _ = direct_irradiance(scene, vox, samples=512, seed=7, rel_error=0.02, threads=threads)
    shot, shoot_s, _ = _direct_by_shooting(vox, threads)
    t = time.perf_counter()
    exact, st = direct_irradiance(scene, vox, threads=threads)
    exact_s = time.perf_counter() - t
    rows = []
    area = vox.area.astype(np.float64)
    for i, obj in enumerate(scene.objects):
        m = (vox.object_id == i) & ~vox.back & (area > 0) & np.any(vox.albedo > 0, axis=1)
        r = float(np.sum(area[m] * (ref[m] @ LUM)))
        if not m.any() or r <= 0:
            continue
        rows.append(
            {
                "object": obj.name,
                "area": float(area[m].sum()),
                "voxel_faces": float(area[m].sum() / vox.pitch**2),
                "shoot": float(np.sum(area[m] * (shot[m] @ LUM)) / r),
                "exact": float(np.sum(area[m] * (exact[m] @ LUM)) / r),
            }
        )
        print(f"  {obj.name:12s} shooting {rows[-1]['shoot']:.4f}  exact {rows[-1]['exact']:.4f}")
    print(f"  seconds: shooting {shoot_s:.2f}, exact {exact_s:.2f} ({st['rays']:,} rays)")
    return {
        "scene": name,
        "resolution": resolution,
        "records": len(vox),
        "threads": threads,
        "shoot_seconds": shoot_s,
        "exact_seconds": exact_s,
        "exact_rays": st["rays"],
        "objects": rows,
    }


def furnace(resolution: int, threads: int, directions: int = 8) -> dict:
    rho, le = 0.5, 1.0
    scene = voxgi.scenes.furnace_sphere(albedo=rho, emission=le)
    vox = voxgi.voxelize(scene, resolution=resolution, progress=False)
    out = {
        "scene": "furnace-sphere (every record emits)",
        "resolution": resolution,
        "directions": directions,
        "records": len(vox),
        "threads": threads,
    }
    front = ~vox.back & (vox.area > 0)
    # the paper's shooting at its own radius (35), and at the gathering's,
    # where one gathering pass stands in for it with the same answer
    runs = {
        "exact": voxgi.SolveTuning.paper(direct_light="exact", diagnostics=False),
        "shoot": voxgi.SolveTuning.paper(direct_light="shoot", diagnostics=False),
        f"shoot at R {directions}": voxgi.SolveTuning.paper(
            direct_light="shoot", shoot_radius=directions, diagnostics=False
        ),
        # and with the reflected light finished by traced bounces
        f"shoot at R {directions}, traced bounces": voxgi.SolveTuning.paper(
            direct_light="shoot",
            shoot_radius=directions,
            diagnostics=False,
            indirect_light="traced",
        ),
    }
    out["runs"] = list(runs)
    for method, tuning in runs.items():
        t = time.perf_counter()
        sol = voxgi.solve(vox, radius=directions, threads=threads, progress=False, tuning=tuning)
        total = time.perf_counter() - t
        err = np.abs(sol.radiance[front, 0] * (1 - rho) / le - 1)
        sec = sol.stats["seconds"]
        out[method] = {
            "solve_seconds": total,
            "direct_seconds": sec.get("direct", sec.get("shoot", 0.0)),
            "computed_by": sol.stats["direct_light"]["method"],
            "mean_error": float(np.average(err, weights=vox.area[front])),
            "max_error": float(err.max()),
        }
        print(
            f"furnace {method} ({out[method]['computed_by']}): solve {total:.2f} s "
            f"(direct {out[method]['direct_seconds']:.2f} s),"
            f" error mean {out[method]['mean_error']:.2e} max {out[method]['max_error']:.2e}",
            flush=True,
        )
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=64)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--no-furnace", action="store_true", help="skip the furnace's shooting")
    ap.add_argument("--quick", action="store_true", help="resolution 24, no furnace")
    args = ap.parse_args()
    if args.quick:
        args.resolution, args.no_furnace = 24, True
    res = {
        "version": voxgi.__version__,
        "scenes": [
            per_object(n, args.resolution, args.threads) for n in ("window-room", "cornell-box")
        ],
    }
    if not args.no_furnace:
        res["furnace"] = furnace(args.resolution, args.threads)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "direct_light.json").write_text(json.dumps(res, indent=1))
    print(f"wrote {RESULTS / 'direct_light.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
