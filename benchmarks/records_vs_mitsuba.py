"""voxgi's records against Mitsuba's path tracer at the same points.

For each scene (as ``benchmarks/bitterli.py`` loads it), voxelize and solve
with the defaults, then ask Mitsuba 3's path tracer for the irradiance at
every record's point (:func:`voxgi.mitsuba.record_reference`) and print, per
object, the diffuse records' reflected power over the path tracer's (each
record's reflected radiosity times its area), the objects ranked by their
share of the scene's gap, and the whole scene's ratio. A record stands for
its part of the surface in its voxel and the reference is taken at its
point, so one record may differ from it by more than the noise; an
object's sum over its records shows the solve's bias. Glossy records are
left out (their solve weighs light by the incidence response,
``docs/design.md`` §14).

Usage::

    python benchmarks/records_vs_mitsuba.py bathroom-partial --spp 64
    python benchmarks/records_vs_mitsuba.py cornell-box kitchen --resolution 96

Needs the ``bench`` extra (Mitsuba 3) and the extracted scenes
(``scripts/extract_bitterli.py``) for Bitterli's.
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np
from bitterli import load

import voxgi
from voxgi.mitsuba import record_reference


def compare_records(scene: voxgi.Scene, resolution: int, spp: int, top: int) -> dict:
    """Solve ``scene`` with the defaults at ``resolution`` and print its
    diffuse records' reflected power against Mitsuba's, per object."""
    t = time.perf_counter()
    vox = voxgi.voxelize(scene, resolution)
    sol = voxgi.solve(vox, progress=False)
    t_voxgi = time.perf_counter() - t
    t = time.perf_counter()
    E = record_reference(scene, vox, spp=spp)
    t_ref = time.perf_counter() - t
    diffuse = np.array([o.material.specular is None for o in scene.objects])
    oid = np.asarray(vox.object_id)
    area = np.asarray(vox.area, np.float64)
    albedo = np.asarray(vox.albedo, np.float64)
    live = diffuse[oid] & (area > 0) & (albedo.max(axis=1) > 0)
    mine = (np.asarray(sol.radiosity, np.float64) - np.pi * np.asarray(vox.emission)).mean(axis=1)
    ref = (albedo * E).mean(axis=1)
    p_mine, p_ref = mine * area, ref * area
    total = float(p_ref[live].sum())
    rows = []
    for i in np.unique(oid[live]):
        m = live & (oid == i)
        a, b = float(p_mine[m].sum()), float(p_ref[m].sum())
        rows.append((abs(a - b) / total, a / b if b > 0 else float("nan"), int(m.sum()), i))
    rows.sort(reverse=True)
    ratio = float(p_mine[live].sum()) / total
    print(
        f"{len(vox):,} records ({int(live.sum()):,} diffuse), voxgi {t_voxgi:.1f} s, "
        f"Mitsuba {spp} rays a record {t_ref:.1f} s; reflected power voxgi / Mitsuba {ratio:.4f}"
    )
    print(f"{'object':<24} {'records':>8} {'voxgi / Mitsuba':>16} {'share of the gap':>17}")
    for gap, r, count, i in rows[:top]:
        print(f"{scene.objects[i].name:<24} {count:>8} {r:>16.3f} {gap:>17.4f}")
    return {"ratio": ratio, "objects": rows}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--resolution", type=int, default=64)
    ap.add_argument("--spp", type=int, default=64, help="Mitsuba's rays per record")
    ap.add_argument("--top", type=int, default=12, help="objects listed per scene")
    args = ap.parse_args()
    warnings.simplefilter("ignore", RuntimeWarning)
    for name in args.scenes:
        print(f"== {name}")
        compare_records(load(name, 64), args.resolution, args.spp, args.top)


if __name__ == "__main__":
    main()
