"""Write docs/performance.md and the README's figure tables from the benchmark JSON.

Run: ``python scripts/make_performance.py`` (``--check`` exits 1 if the
committed page or README.md differs from what the JSON gives, ``--stdout``
prints the page). The README's tables come from ``scripts/readme_figures.py``.
Every table names the command that writes its JSON; re-run that command,
then this script, to refresh the page. The page's last part, from the
``KEPT`` marker on, is written by hand (one-off measurements behind the
rules of ``docs/design.md``): the script keeps it as it is.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
OUT = ROOT / "docs" / "performance.md"
#: The line from which the page is written by hand and kept as it is.
KEPT = "<!-- Written by hand from here on; scripts/make_performance.py keeps it as it is. -->"


def load(name: str) -> dict | None:
    path = RESULTS / name
    return json.loads(path.read_text()) if path.exists() else None


def pct(x: float | None, digits: int = 2) -> str:
    """A fraction as a percentage; tiny values keep two significant digits."""
    if x is None:
        return ""
    v = 100.0 * x
    if v == 0:
        return "0"
    if abs(v) < 0.01:
        return f"{v:.1e}%"
    return f"{v:.{digits}f}%"


def sci(x: float | None) -> str:
    return "" if x is None else f"{x:.2g}" if x == 0 else f"{x:.2e}"


def secs(x: float | None) -> str:
    if x is None:
        return ""
    return f"{x:.3g}" if x < 100 else f"{x:.0f}"


def table(header: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def source(cmd: str, *files: str) -> str:
    names = ", ".join(f"`benchmarks/results/{f}`" for f in files)
    return f"Command: `{cmd}` (writes {names})."


def machine(d: dict) -> str:
    cpu = d.get("cpu") or "x86-64"
    cores = d.get("cores") or d.get("cpu_count")
    return f"{cpu}, {cores} cores" if cores else cpu


# ----------------------------------------------------------------------------- sections


def furnaces() -> list[str]:
    out = [
        "## Furnaces",
        "",
        "Closed enclosures where every surface emits `Le = 1` with albedo ρ: the exact "
        "radiance is `Le / (1 - ρ)` everywhere (`docs/design.md §1`). Error of the front "
        "records against it (mean of |error|, and the largest), iterations, and the lost "
        "fraction δ (`docs/design.md §5`). R 8, shooting R 8.",
        "",
    ]
    names = {
        "sphere": "sphere",
        "sphere+box": "sphere with a closed box inside",
        "box": "box",
        "box+sphere": "box with a closed sphere inside",
    }
    for fname, cmd in (
        ("propagation_furnace.json", "python benchmarks/propagation.py furnace"),
        ("propagation_furnace_res96_R8.json", "python benchmarks/propagation.py furnace --res 96"),
    ):
        d = load(fname)
        if d is None:
            continue
        res = d["rows"][0]["res"]
        rhos = sorted({r["rho"] for r in d["rows"]})
        scenes = list(dict.fromkeys(r["scene"] for r in d["rows"]))
        by = {(r["scene"], r["rho"]): r for r in d["rows"]}
        rows = []
        for s in scenes:
            cells = [names.get(s, s), f"{by[(s, rhos[0])]['records']:,}"]
            for rho in rhos:
                r = by.get((s, rho))
                cells.append(
                    ""
                    if r is None
                    else f"{pct(r['mean_err'])} / {pct(r['max_err'])} ({r['iters']} it)"
                )
            cells.append(sci(max(0.0, by[(s, rhos[0])]["delta"])))
            rows.append(cells)
        out += [
            f"**Resolution {res}**",
            "",
            table(["scene", "records"] + [f"ρ {rho}: mean / max" for rho in rhos] + ["δ"], rows),
            "",
            source(cmd, fname),
            "",
        ]
    return out


def junctions() -> list[str]:
    d = load("propagation_junctions.json")
    if d is None:
        return []
    names = {
        "plain": "no wall",
        "through": "wall meeting floor, ceiling and two walls",
        "end": "wall ending in mid-air",
        "corner": "wall turning a corner",
    }
    rows = []
    for r in d["rows"]:
        solved = "err_mean" in r
        rows.append(
            [
                names.get(r["wall"], r["wall"]),
                r["res"],
                f"{r['records']:,}",
                pct(r["lost_mean"]),
                pct(r["lost_max"]),
                r["lost_over_1%"],
                f"{pct(r['err_mean'])} / {pct(r['err_max'])}" if solved else "",
                r["err_over_2pct"] if solved else "",
            ]
        )
    return [
        "## Thin walls in a furnace",
        "",
        f"A closed unit box (ρ {d['rho']}, every surface emitting) split by a zero-thickness "
        "two-sided wall. In a closed scene every direction of every record ends on a "
        "surface, so the share of a record's hemisphere in which the gathering finds no "
        f"partner (R {d['R']}) measures the propagation's error where surfaces meet "
        "(`docs/design.md` §4); the furnace's radiance error against `Le / (1 - ρ)` "
        "(shot direct light) follows from it, about ρ / (1 - ρ) times larger.",
        "",
        table(
            [
                "scene",
                "res",
                "records",
                "lost: mean",
                "max",
                "records > 1%",
                "radiance error: mean / max",
                "records > 2%",
            ],
            rows,
        ),
        "",
        source("python benchmarks/propagation.py junctions", "propagation_junctions.json"),
        "",
    ]


def thin_walls() -> list[str]:
    d = load("propagation_thin_walls.json")
    if d is None:
        return []
    names = {
        "through": "wall meeting floor, ceiling and two walls",
        "end": "wall ending in mid-air",
        "corner": "wall turning a corner",
    }
    rows = [
        [
            names.get(r["wall"], r["wall"]),
            r["res"],
            f"{r['records']:,}",
            r["bounces"],
            f"{pct(r['err_mean'], 3)} / {pct(r['err_max'])}",
            r["err_over_2pct"],
            r["traced_passes"] or "",
            secs(r["traced_seconds"]) if r["traced_passes"] else "",
            secs(r["seconds"]),
        ]
        for r in d["rows"]
    ]
    return [
        "### The same walls with traced bounces",
        "",
        f"The furnaces above at R {d['R']} (shot direct light, ρ {d['rho']}), solved with the "
        'lines alone and with traced bounces (`SolveTuning(indirect_light="traced")`, '
        "`docs/design.md` §5) of 64 and 256 rays a record in the first pass. What the "
        "traced bounces leave is that first pass's noise on the box's tiny corner records.",
        "",
        table(
            [
                "scene",
                "res",
                "records",
                "bounces",
                "radiance error: mean / max",
                "records > 2%",
                "traced passes",
                "traced",
                "solve",
            ],
            rows,
        ),
        "",
        source("python benchmarks/propagation.py thin_walls", "propagation_thin_walls.json"),
        "",
    ]


def cap_sphere() -> list[str]:
    d = load("propagation_cap.json")
    if d is None:
        return []
    radii = sorted({r["R"] for r in d["rows"]})
    ress = sorted({r["res"] for r in d["rows"]})
    by = {(r["res"], r["R"]): r for r in d["rows"]}
    rows = [
        [res, f"{by[(res, radii[0])]['records']:,}"]
        + [f"{pct(by[(res, R)]['mean_err'])} / {pct(by[(res, R)]['max_err'])}" for R in radii]
        for res in ress
    ]
    return [
        "## Sphere with an emitting cap",
        "",
        f"Inside a sphere every pair of points has the same form factor, so "
        f"`L(x) = Le(x) + ρ L̄e / (1 - ρ)` (`docs/design.md §1`): this checks the "
        f"visibility weights, not only the energy. ρ {d['rho']}, shooting radius equal "
        f"to the gathering radius R; mean / max relative error of the front records.",
        "",
        table(["resolution", "records"] + [f"R {R}" for R in radii], rows),
        "",
        source("python benchmarks/propagation.py cap", "propagation_cap.json"),
        "",
    ]


def direct_light() -> list[str]:
    d = load("direct_light.json")
    if d is None:
        return []
    out = [
        "## Direct light on the records",
        "",
        "Each object's area-weighted direct irradiance (luminance), by the paper's discrete "
        "shooting and by shadow rays to the exact emitters "
        '(`SolveTuning(direct_light="exact")`, 64 sample pairs a record), divided by a '
        "converged shadow-ray integration at the same record points (512 pairs, records "
        "refined to 2% standard error; `docs/design.md §5`).",
        "",
    ]
    for sc in d["scenes"]:
        rows = [
            [r["object"], f"{r['voxel_faces']:.0f}", f"{r['shoot']:.3f}", f"{r['exact']:.3f}"]
            for r in sc["objects"]
        ]
        out += [
            f"**{sc['scene']}**, resolution {sc['resolution']}, {sc['records']:,} records, "
            f"{sc['threads']} threads: shooting {secs(sc['shoot_seconds'])} s, exact "
            f"{secs(sc['exact_seconds'])} s ({sc['exact_rays']:,} rays).",
            "",
            table(
                ["object", "area in voxel faces", "shooting / converged", "exact / converged"], rows
            ),
            "",
        ]
    f = d.get("furnace")
    if f is not None:
        rows = [
            [
                m
                if f[m].get("computed_by", m) == m
                else f"{m} (computed by {f[m]['computed_by']})",
                secs(f[m]["solve_seconds"]),
                secs(f[m]["direct_seconds"]),
                pct(f[m]["mean_error"]),
                pct(f[m]["max_error"]),
            ]
            for m in f.get("runs", ("exact", "shoot"))
        ]
        out += [
            f"**{f['scene']}**, resolution {f['resolution']} ({f['records']:,} records), "
            f"R {f['directions']}, {f['threads']} threads, error against `Le / (1 - rho)`:",
            "",
            table(
                ["direct light", "solve s", "of which direct s", "mean error", "max error"], rows
            ),
            "",
        ]
    out += [source("python benchmarks/direct_light.py", "direct_light.json"), ""]
    return out


def later_bounces() -> list[str]:
    d = load("propagation_later.json")
    if d is None:
        return []
    rows = [
        [
            r["R"],
            r["later_R"] if r["later_R"] is not None else "same",
            r["iters"],
            secs(r["gather_s"]),
            pct(r["mean_err_vs_R22"]),
            pct(r["p99_err_vs_R22"]),
        ]
        for r in d["rows"]
    ]
    return [
        "## Coarser later bounces",
        "",
        f"Cornell box at resolution {d['res']}: gathering radius R for the first two "
        "bounces and a later radius after them "
        "(`SolveTuning.paper(later_radius=...)`, `docs/design.md §5`), "
        "against R 22 throughout (tol 1e-6). 'same' is the plain fixed-point solve.",
        "",
        table(["R", "later R", "iterations", "gathering s", "mean error", "99th percentile"], rows),
        "",
        source("python benchmarks/propagation.py later", "propagation_later.json"),
        "",
    ]


def energy() -> list[str]:
    out = [
        "## Energy balance",
        "",
        "The open Cornell box: `(emitted - absorbed - escaping) / emitted` per channel, the "
        "escaping power counted on the sender side (`docs/design.md §5`). It measures how "
        "well the discretisation conserves energy; it converges with the resolution "
        "(`docs/design.md §10`). Solve tolerance 1e-5, 2 threads.",
        "",
    ]
    for fname in ("propagation_energy_R8.json", "propagation_energy_R22.json"):
        d = load(fname)
        if d is None:
            continue
        r0 = d["rows"][0]
        rows = [
            [
                r["res"],
                f"{r['records']:,}",
                r["iters"],
                " / ".join(pct(r[f"imbalance_{c}"], 3) for c in "rgb"),
                f"{r['escaping/emitted']:.3f}",
                secs(r["seconds"]),
            ]
            for r in d["rows"]
        ]
        res_list = " ".join(str(r["res"]) for r in d["rows"])
        cmd = (
            f"python benchmarks/propagation.py energy --radii {r0['R']} {r0['Rs']} "
            f"--res {res_list} --threads 2"
        )
        out += [
            f"**Gathering R {r0['R']}, shooting R {r0['Rs']}**",
            "",
            table(
                [
                    "resolution",
                    "records",
                    "iterations",
                    "imbalance R / G / B",
                    "escaping / emitted",
                    "solve s",
                ],
                rows,
            ),
            "",
            source(cmd, fname),
            "",
        ]
    d = load("propagation_cornell.json")
    if d is not None:
        rows = [
            [
                r["scene"],
                r["res"],
                f"{r['records']:,}",
                " / ".join(pct(r[f"imbalance_{c}"], 3) for c in "rg"),
                f"{r['absorbed/emitted']:.4f}",
            ]
            for r in d["rows"]
            if r.get("coverage", True) and r.get("silhouettes", True)
        ]
        out += [
            "**Direct light and closed variants** (R 8; 'albedo 0' keeps only the shooting)",
            "",
            table(
                ["Cornell box", "resolution", "records", "imbalance R / G", "absorbed / emitted"],
                rows,
            ),
            "",
            source("python benchmarks/propagation.py cornell", "propagation_cornell.json"),
            "",
        ]
    return out


def linear() -> list[str]:
    d = load("propagation_linear.json")
    if d is None:
        return []
    rows = [
        [
            f"{r['records']:,}",
            r["R"],
            f"{r['families']:,}",
            r["iters"],
            secs(r["seconds"]),
            f"{r['ns_per_ray']:.1f}",
        ]
        for r in d["rows"]
    ]
    return [
        "## Linear cost",
        "",
        "Gathering time for N, 2N and 4N records (the bunny room at three resolutions) "
        "and for more directions, fixed iterations, 1 thread. A gathering ray is one record "
        "meeting one direction family in one iteration (`docs/design.md §7`); a constant "
        "cost per ray is linear time.",
        "",
        table(["records", "R", "families", "iterations", "seconds", "ns per ray"], rows),
        "",
        "![linear cost](../benchmarks/results/linear_cost.png)",
        "",
        source("python benchmarks/propagation.py linear", "propagation_linear.json"),
        "",
    ]


def throughput() -> list[str]:
    out = []
    d = load("propagation_throughput.json")
    if d is not None:
        r0 = d["rows"][0]
        what = {
            "onepass": "walk the lines (one pass)",
            "sort": "walk the lines (sorted)",
            "record": "walk and record the pairs",
            "replay": "replay the recorded pairs",
            "solve4 (record + 3 replays)": "a 4-iteration solve (1 recording, 3 replays)",
        }
        rows = [
            [
                what.get(r["algorithm"], r["algorithm"]),
                r["threads"],
                secs(r["seconds"]),
                f"{r['Mrays_s']:.1f}",
                f"{r['Mrays_s_per_thread']:.1f}",
                f"{r['table_GB']:.2f}" if r["table_GB"] else "",
            ]
            for r in d["rows"]
        ]
        out += [
            "## Gathering throughput",
            "",
            f"The bunny room, {r0['records']:,} records, R {r0['R']} (2,991 families): one "
            "gathering pass in each mode, and what a 4-iteration solve makes of them (one "
            "recording pass, three replays; `docs/design.md §4`).",
            "",
            table(
                ["pass", "threads", "seconds", "M rays/s", "M rays/s per thread", "pair table GB"],
                rows,
            ),
            "",
            source("python benchmarks/propagation.py throughput", "propagation_throughput.json"),
            "",
        ]
    d = load("propagation_paper.json")
    if d is not None:
        r0 = d["rows"][0]
        rows = [
            [
                r["threads"],
                r["pairs"],
                secs(r["shoot_s"]),
                secs(r["gather_s"]),
                f"{r['gather_Mrays_s_per_thread']:.0f}",
                f"{r['shoot_Mrays_s']:.2f}",
            ]
            for r in d["rows"]
        ]
        out += [
            "## The paper's work unit",
            "",
            f"About {r0['records']:,} records ({r0['emitters']} emitters), gathering R 22 "
            f"for 4 iterations, shooting R 35 from a small area light. The paper reports "
            f"{r0['paper_propagate_s']} s of propagation and {r0['paper_shoot_s']} s of "
            "shooting on one 1.86 GHz core.",
            "",
            table(
                [
                    "threads",
                    "pairs",
                    "shooting s",
                    "gathering s",
                    "gathering M rays/s per thread",
                    "shooting M rays/s",
                ],
                rows,
            ),
            "",
            source("python benchmarks/propagation.py paper", "propagation_paper.json"),
            "",
        ]
    return out


def voxelize() -> list[str]:
    d = load("voxelize.json")
    if d is None:
        return []
    rows = [
        [
            r["case"],
            f"{r['triangles']:,}",
            r["resolution"],
            f"{r['records']:,}",
            secs(r["median_s"]),
            f"{r['rss_peak_bytes'] / 2**20:.0f}",
        ]
        for r in d["results"]
    ]
    return [
        "## Voxelization",
        "",
        f"Median of repeated runs, {d['threads']} threads.",
        "",
        table(["mesh", "triangles", "resolution", "records", "seconds", "peak MB"], rows),
        "",
        source("python benchmarks/voxelize.py", "voxelize.json"),
        "",
    ]


def paper_tables() -> list[str]:
    rows = []
    threads = None
    exact_run = load("paper_tables_exact.json")
    exact = {r["scene"]: r for r in exact_run["rows"]} if exact_run else {}
    for fname in ("paper_tables.json", "paper_tables_sponza.json"):
        d = load(fname)
        if d is None:
            continue
        threads = d["threads"]
        for r in d["rows"]:
            p = r["paper"]
            rows.append(
                [
                    r["scene"],
                    f"{r['front_records']:,}",
                    f"{p['voxels']:,}",
                    f"{r['SR']} / {r['LR']}",
                    r["LPL"],
                    f"{secs(r['ST'])} ({p['ST']})",
                    f"{secs(r['LT'])} ({p['LT']})",
                    f"{secs(r['RTT'])} ({p['RTT']})",
                    f"{secs(r['TT'])} ({p['TT']})",
                    secs(exact[r["scene"]]["ST"]) if r["scene"] in exact else "-",
                    secs(exact[r["scene"]]["TT"]) if r["scene"] in exact else "-",
                ]
            )
    if not rows:
        return []
    return [
        "## The paper's tables",
        "",
        "voxgi's procedural look-alikes of the paper's test scenes (the paper does not "
        "publish their geometry, so the comparison is by kind, not exact), at matching record "
        "counts, radii and light path lengths (LPL), 512x512 display. Seconds for shooting "
        "(ST), linear propagation (LT), display (RTT) and in total (TT); the paper's "
        f"figures in parentheses (one 1.86 GHz core; voxgi {threads} threads; the paper's "
        "Sponza display is 1024x768).",
        "",
        table(
            [
                "scene",
                "front records",
                "paper voxels",
                "SR / LR",
                "LPL",
                "ST s",
                "LT s",
                "RTT s",
                "TT s",
                "ST exact s",
                "TT exact s",
            ],
            rows,
        ),
        "",
        "The last two columns replace the discrete shooting by exact direct light on the "
        "records (shadow rays to the emitters, `docs/design.md` §5); '-' where that run "
        "was not made.",
        "",
        "Command: `python benchmarks/paper_tables.py --scenes labyrinth emission shadow "
        "geometric bunny` and `python benchmarks/paper_tables.py --scenes sponza --out "
        "benchmarks/results/paper_tables_sponza.json` (write "
        "`benchmarks/results/paper_tables.json`, `benchmarks/results/paper_tables_sponza.json`); "
        "with exact direct light, `python benchmarks/paper_tables.py --scenes labyrinth "
        "emission shadow geometric bunny --direct-light exact --out "
        "benchmarks/results/paper_tables_exact.json`.",
        "",
    ]


def _mitsuba_time(d: dict, err: float) -> float | None:
    """Mitsuba's time to a relMSE, from its sweep (error falls as 1/spp)."""
    pts = sorted((m["rel_mse"], m["seconds"]) for m in d["mitsuba"])
    best = min(pts, key=lambda p: abs(p[0] - err) / p[0])
    return best[1] * best[0] / err


def versus_mitsuba() -> list[str]:
    out = [
        "## Against a path tracer",
        "",
        "Time to an error against a converged Mitsuba 3 reference (`docs/design.md §9`): "
        "relMSE = mean((x - r)² / (r² + 0.01)); voxgi timed over voxelize + solve + display "
        "(its relMSE the mean of three seeds), Mitsuba 3 (`llvm_ad_rgb`) per render, in the "
        "same run on 2 threads.",
        "",
    ]
    for fname, title, cmd in (
        (
            "time_vs_error_256.json",
            "Cornell box, 256x256",
            "python benchmarks/time_vs_error.py --size 256 --split",
        ),
        (
            "time_vs_error_512.json",
            "Cornell box, 512x512",
            "python benchmarks/time_vs_error.py --size 512",
        ),
        (
            "time_vs_error_shadow_256.json",
            "`shadow`, 256x256",
            "python benchmarks/time_vs_error.py --scene shadow --size 256 --high",
        ),
        (
            "time_vs_error_geometric_256.json",
            "`geometric`, 256x256",
            "python benchmarks/time_vs_error.py --scene geometric --size 256 --high",
        ),
    ):
        d = load(fname)
        if d is None:
            continue
        rows = [
            [f"Mitsuba 3, {m['spp']} spp", secs(m["seconds"]), sci(m["rel_mse"]), ""]
            for m in d["mitsuba"]
        ]
        for v in d["voxgi"]:
            tol = v["render"].get("tol")
            how = (
                f"{v['frames']} frames"
                if tol == 0
                else f"tol {tol or 1e-3:.0e}".replace("e-0", "e-")
            )
            label = f"voxgi res {v['resolution']}, R {v['directions']}, {how}"
            t_m = _mitsuba_time(d, v["rel_mse"])
            rows.append(
                [
                    label,
                    secs(v["seconds"]),
                    sci(v["rel_mse"]),
                    f"{t_m / v['seconds']:.1f}x" if t_m else "",
                ]
            )
        if "second_view" in d:
            rows.append(
                [
                    "voxgi, a second view of the saved solution (display only)",
                    secs(d["second_view"]["seconds"]),
                    "",
                    "",
                ]
            )
        png = fname.replace(".json", ".png")
        out += [
            f"**{title}**",
            "",
            table(
                [
                    "renderer / setting",
                    "seconds",
                    "relMSE",
                    "Mitsuba's time to that error / voxgi's",
                ],
                rows,
            ),
            "",
        ]
        if (RESULTS / png).exists():
            out += [f"![time against error](../benchmarks/results/{png})", ""]
        if "split" in d:
            srows = [
                [r["resolution"], r["frames"], sci(r["rel_mse_vs_ref"])] for r in d["split"]["rows"]
            ]
            out += [
                "The voxels' own error (long renders, so that the display's noise is "
                f"small) against the display's noise at the defaults "
                f"({sci(d['split']['display_noise_rel_mse'])}):",
                "",
                table(["resolution", "frames", "relMSE"], srows),
                "",
            ]
        out += [source(cmd, fname), ""]
    d = load("cornell_defaults.json")
    if d is not None:
        rows = [
            [
                f"{size}x{size}",
                secs(s["whole_pipeline"]),
                secs(s["display"]),
                s["frames"],
                sci(s["rel_mse"]),
                sci(s["est_noise_rel_mse"]),
            ]
            for size, s in d["sizes"].items()
        ]
        out += [
            "**`voxgi.render(scene)` with the defaults** (Cornell box, resolution "
            f"{d['resolution']}, {d['records']:,} records, solve {secs(d['solve'])} s in "
            f"{d['bounces']} bounces)",
            "",
            table(
                [
                    "size",
                    "whole pipeline s",
                    "display s",
                    "frames",
                    "relMSE",
                    "estimated noise relMSE",
                ],
                rows,
            ),
            "",
            source("python benchmarks/cornell_defaults.py", "cornell_defaults.json"),
            "",
        ]
    return out


def calibration() -> list[str]:
    d = load("calibration.json")
    if d is None:
        return []
    rows, phases, spread = [], [], []
    for r in d["rows"]:
        ratios = [s["ratio"] for s in r["seeds"]]
        outside = [s for s in r["seeds"] if not 0.5 <= s["ratio"] <= 2.0]
        spread.append(
            [
                r["scene"],
                len(ratios),
                f"{sum(ratios) / len(ratios):.2f}",
                f"{min(ratios):.2f}",
                f"{max(ratios):.2f}",
                ", ".join(f"seed {s['seed']}: {s['ratio']:.2f}" for s in outside) or "none",
                " ".join(str(s["frames"]) for s in r["seeds"]),
            ]
        )
        width, height = r["pixels"]
        for s in r["seeds"][:3]:
            first = s["seed"] == r["seeds"][0]["seed"]
            rows.append(
                [
                    r["scene"] if first else "",
                    f"{width}x{height}" if first else "",
                    s["seed"],
                    s["frames"],
                    sci(s["est_rel_mse"]),
                    sci(s["rel_mse"]),
                    f"{s['ratio']:.2f}",
                    pct(s["est_max_rel_err"], 1),
                    pct(s["max_rel_err"], 1),
                ]
            )
        ref = r["reference"]
        total = sum(ref["phases"][k] for k in ("primary", "shadow", "gather"))
        phases.append(
            [
                r["scene"],
                ref["frames"],
                secs(total / ref["frames"] * 1000),
                *(
                    f"{pct(ref['phases'][k] / total, 0)} ({ref['rays'][k] / (width * height):.1f})"
                    for k in ("primary", "shadow", "gather")
                ),
            ]
        )
    return [
        "## How well the display knows its error",
        "",
        "Each scene solved once with the defaults of `voxgi.render(scene)`, then displayed "
        f"with the defaults (tol {d['tol']:.0e}, pixel_factor {d['pixel_factor']:g}) at seeds 0 "
        f"to {d['seeds'] - 1} (the first table shows seeds 0-2). The measured relMSE is "
        "against a long render of the same solution (its frames in the last table), less "
        "that reference's own estimated noise: the estimate is of the display's noise, not "
        "of the voxel solution's bias. Ratio: estimated over measured (1: calibrated). Worst "
        "pixel: the largest relative error `|x - r| / sqrt(r² + 0.01)`, estimated and "
        "measured (`docs/design.md` §6, which discusses the seeds outside [0.5, 2]). "
        "Bitterli's wooden staircase (`staircase`) is a scene the estimate was not tuned on.",
        "",
        table(
            [
                "scene",
                "pixels",
                "seed",
                "frames",
                "estimated relMSE",
                "measured relMSE",
                "ratio",
                "worst pixel, estimated",
                "worst pixel, measured",
            ],
            rows,
        ),
        "",
        "Over all the seeds: estimated over measured relMSE, its average and range, the "
        "seeds outside [0.5, 2], and the frames at which each render stopped.",
        "",
        table(
            ["scene", "seeds", "mean ratio", "lowest", "highest", "outside [0.5, 2]", "frames"],
            spread,
        ),
        "",
        f"Where the display's time goes (the reference render on {d['threads']} "
        "threads, on a machine shared with other jobs: the milliseconds are not for "
        "comparison): the share of each phase, with rays per pixel and frame in "
        "parentheses. The compiled kernels shade each ray's hit as it is traced, so a "
        "phase's time includes the shading of its rays (`docs/design.md` §6).",
        "",
        table(
            [
                "scene",
                "reference frames",
                "ms per frame",
                "primary rays",
                "shadow rays",
                "gather rays",
            ],
            phases,
        ),
        "",
        source(
            f"python benchmarks/calibration.py --seeds {d['seeds']} --threads {d['threads']}",
            "calibration.json",
        ),
        "",
        *_calibration_at("calibration_tol5e-3.json"),
    ]


def _calibration_at(name: str) -> list[str]:
    """The same calibration at another tolerance: its spread per scene."""
    d = load(name)
    if d is None:
        return []
    spread = []
    for r in d["rows"]:
        ratios = [s["ratio"] for s in r["seeds"]]
        measured = [s["rel_mse"] for s in r["seeds"]]
        frames = sorted({s["frames"] for s in r["seeds"]})
        spread.append(
            [
                r["scene"],
                r.get("resolution", ""),
                len(ratios),
                f"{min(ratios):.2f}-{max(ratios):.2f}",
                f"{sci(min(measured))}-{sci(max(measured))}",
                f"{frames[0]}-{frames[-1]}" if len(frames) > 1 else str(frames[0]),
            ]
        )
    return [
        f"At tol {d['tol']:.0e}, where a render may stop at the floor of 4 frames:",
        "",
        table(["scene", "resolution", "seeds", "ratio", "measured relMSE", "frames"], spread),
        "",
        source(
            f"python benchmarks/calibration.py --seeds {d['seeds']} --threads {d['threads']} "
            f"--tol {d['tol']:g} --json benchmarks/results/{name}",
            name,
        ),
        "",
    ]


def display_noise() -> list[str]:
    d = load("display_noise.json")
    if d is None:
        return []
    rows = []
    for sc in d["scenes"]:
        base = sc["rows"][0]["noise_x_seconds"]
        for i, r in enumerate(sc["rows"]):
            rows.append(
                [
                    f"{sc['scene']} ({sc['spread']:.3f})" if i == 0 else "",
                    r["light"],
                    f"{r['vpls']} / {r['gather']}",
                    sci(r["frame_noise"]),
                    secs(r["ms_per_frame"]),
                    f"{r['noise_x_seconds'] / base:.2f}" if r["light"] == "all" else "",
                ]
            )
    return [
        "## What the display's noise is made of",
        "",
        f"Each scene at {d['size']}x{d['size']}, solved with the defaults of "
        f"`voxgi.render(scene)`, displayed without the indirect filter for {d['frames']} "
        "frames (one seed) per setting. "
        "Frame noise: the relMSE of a single frame, `mean(var / (L² + 0.01))`, from the spread "
        "between aligned blocks of 4 frames (`docs/design.md §6`). The light of the emitting "
        "records and of the other records is each displayed alone, with the whole VPL budget. "
        "Cost of error: frame noise times seconds per frame, relative to 16 VPLs and 9 gather "
        "rays (the time to a given relMSE scales with it; under 1 is cheaper). In brackets, "
        "the light's spread (`voxgi.display.light_spread`): from 0.8 on the defaults are 8 "
        "VPLs and 25 gather rays, under it 16 and 9 without the filter and 8 and 4 with it "
        "(`docs/design.md §6`).",
        "",
        table(
            [
                "scene",
                "light",
                "VPLs / gather rays",
                "frame noise",
                "ms per frame",
                "cost of error",
            ],
            rows,
        ),
        "",
        source(f"python benchmarks/display_noise.py --size {d['size']}", "display_noise.json"),
        "",
    ]


def ray_cost() -> list[str]:
    d = load("ray_cost.json")
    if d is None:
        return []
    rows = []
    for r in d["scenes"]:
        rd = r["render"]
        one, two = r["ns_per_ray_1"], r["ns_per_ray_2"]
        rows.append(
            [
                r["scene"],
                f"{r['triangles']:,}",
                *(f"{one[k]:.0f} / {two[k]:.0f}" for k in ("primary", "shadow", "gather")),
                str(rd["frames"]),
                *(
                    f"{rd['rays_per_pixel_frame'][k]:.1f}, {pct(rd['rays_alone'][k], 0)}"
                    for k in ("primary", "shadow", "gather")
                ),
            ]
        )
    return [
        "## What a ray costs",
        "",
        f"Each scene at {d['size']}x{d['size']}, solved and displayed with the defaults of "
        "`voxgi.render(scene)`. The camera, shadow and gather rays of two of its frames, "
        "traced alone through the compiled core's Embree scene (`voxgi.rays.Tracer`): "
        "nanoseconds per ray on 1 / 2 threads (best of "
        f"{d['repeats']}). Then, per phase of the default render, the rays per pixel and "
        "frame and the share of the phase's time that its rays alone take at the 2-thread "
        "cost; the rest is making the rays, finding the hit's record and shading. A share "
        "over 100%: the phase's kernel, which traces each pixel's rays among that other "
        "work, got more from the second thread than the bare rays did "
        "(`docs/design.md` §7).",
        "",
        table(
            [
                "scene",
                "triangles",
                "camera ray, ns",
                "shadow ray, ns",
                "gather ray, ns",
                "frames",
                "camera rays: per pixel, share",
                "shadow rays",
                "gather rays",
            ],
            rows,
        ),
        "",
        source(f"python benchmarks/ray_cost.py --size {d['size']}", "ray_cost.json"),
        "",
    ]


def furnace_pixels() -> list[str]:
    d = load("furnace_pixels.json")
    if d is None:
        return []
    groups: dict[tuple, list[dict]] = {}
    for r in d["rows"]:
        groups.setdefault((r["albedo"], r["budget"], r["camera"]), []).append(r)
    rows = []
    for (rho, budget, cam), rs in groups.items():
        rows.append(
            [
                f"{rho}",
                f"{rs[0]['vpls']} / {rs[0]['gather']}"
                + (" (defaults)" if budget == "default" else ""),
                cam,
                " / ".join(str(r["frames"]) for r in rs),
                " / ".join(f"{100 * r['worst']:.2f}%" for r in rs),
                " / ".join(f"{100 * r['rms']:.3f}%" for r in rs),
            ]
        )
    w, h = d["size"]
    return [
        "## Every pixel of the furnace",
        "",
        f"The uniform furnace sphere at {w}x{h} pixels, solved with the defaults of "
        "`voxgi.render(scene)` and displayed with its defaults (`tol` 1e-3) at seeds 0, 1 "
        "and 2 from the scene's camera at the centre and from an off-centre one looking at "
        "the wall; every pixel's exact radiance is `Le / (1 - ρ)`. The light is spread "
        "evenly (spread 1), so the defaults take 8 VPLs and 25 gather rays a frame "
        "(`docs/design.md §6`); 16 and 8 for comparison. Per seed: frames, the worst "
        "pixel's relative error, the RMS relative error over the pixels.",
        "",
        table(
            ["albedo", "VPLs / gather rays", "camera", "frames", "worst pixel", "RMS"],
            rows,
        ),
        "",
        source("python benchmarks/furnace_pixels.py", "furnace_pixels.json"),
        "",
    ]


def interiors() -> list[str]:
    out = []
    for path in sorted(RESULTS.glob("interiors_*.json")):
        d = json.loads(path.read_text())
        rows = []
        for r in d["scenes"]:
            tm = r["mitsuba_seconds_at_voxgi_error"]
            rows.append(
                [
                    r["scene"],
                    f"{r['triangles']:,}",
                    secs(r["voxgi_seconds"]),
                    r["voxgi_frames"],
                    sci(r["voxgi_rel_mse"]),
                    " / ".join(f"{b:.3f}" for b in r["voxgi_brightness"]),
                    secs(tm) + (" *" if r.get("mitsuba_seconds_extrapolated") and tm else ""),
                    "" if tm is None else f"{tm / r['voxgi_seconds']:.1f}x",
                    sci(r["reference_noise_rel_mse"]),
                ]
            )
        size = d["size"]
        out += [
            f"## Interiors against a path tracer ({size}x{size})",
            "",
            "`voxgi.render(scene)` with every default (voxelize, solve and display timed "
            "together) against Mitsuba 3's path tracer on the same exported scene: relMSE "
            "against a high-spp Mitsuba reference (its own noise in the last column), the "
            "brightness ratio per channel (R / G / B) of the pixels whose whole footprint "
            "(centre and corners) sees surfaces that do not emit, and the seconds Mitsuba "
            "needs to reach voxgi's relMSE "
            "(doubling spp, log-log interpolation), in the same run. * : no sweep render "
            "reached voxgi's relMSE against a reference whose own noise is not small; the "
            "seconds are extrapolated from the last one by error ∝ 1/spp, both errors less "
            "the reference's noise.",
            "",
            table(
                [
                    "scene",
                    "triangles",
                    "voxgi s",
                    "frames",
                    "voxgi relMSE",
                    "brightness",
                    "Mitsuba s at that relMSE",
                    "Mitsuba / voxgi",
                    "reference noise",
                ],
                rows,
            ),
            "",
            source(f"python benchmarks/interiors.py --size {size}", path.name),
            "",
        ]
    return out


def distributed() -> list[str]:
    d = load("distributed.json")
    if d is None:
        return []
    rows = [
        [
            r["where"],
            r["workers"] or "",
            secs(r["startup_s"]) if r["workers"] else "",
            secs(r["solve_s"]),
            secs(r["render_s"]),
            sci(r.get("solve_rel_diff")) if r["workers"] else "",
            sci(r.get("image_max_abs_diff")) if r["workers"] else "",
        ]
        for r in d["rows"]
    ]
    c1 = d["cost"]["1"]
    p = d["params"]
    return [
        "## Distribution",
        "",
        f"The bunny room at resolution {p['resolution']} ({d['records']:,} records), "
        f"R {p['directions']} / shooting {p['shoot_directions']}, {p['max_bounces']} "
        f"iterations; render {p['width']}x{p['width']}, {p['frames']} frames. 'local' uses "
        "both cores; each Dask worker one thread, on the same two cores, so this shows the "
        "overhead and that the answers are equal, not a speed-up (`docs/design.md §8`).",
        "",
        table(
            [
                "where",
                "workers",
                "cluster start s",
                "solve s",
                "render s",
                "solve rel. diff",
                "image diff",
            ],
            rows,
        ),
        "",
        f"Cost-model terms: c = {c1['c_s_per_record_family']:.2g} s per record and family "
        f"on one core, o = {c1['o_s_per_call']:.2g} s per distributed call with one worker "
        f"({c1['bytes_per_call_per_worker']:,} bytes per call and worker).",
        "",
        source("python benchmarks/distributed.py", "distributed.json"),
        "",
    ]


def build() -> str:
    meta = load("propagation_furnace.json") or {}
    lines = [
        "# Performance and accuracy",
        "",
        "<!-- Generated by scripts/make_performance.py from benchmarks/results/*.json; "
        "do not edit by hand. -->",
        "",
        "Figures of the benchmark scripts in `benchmarks/`, each of which writes the JSON "
        "named under its table (`python benchmarks/run_all.py` runs them all; then "
        "`python scripts/make_performance.py` rewrites this page). Measured on "
        f"{machine(meta)}, no GPU; timings on a shared machine vary by up to a third "
        "between runs, errors do not. The method behind each figure is in "
        "[design.md](design.md).",
        "",
        "Contents: furnaces, thin walls in a furnace, the emitting-cap sphere, direct light "
        "on the records, coarser later bounces, energy balance, linear cost, throughput, "
        "the paper's work unit, voxelization, the paper's tables, time against error "
        "versus Mitsuba 3, interiors, the display's error estimate, every pixel of the "
        "furnace, what the display's noise is made of, what a ray costs, distribution; "
        "then, written by hand, the measurements behind the design's rules.",
        "",
    ]
    for part in (
        furnaces,
        junctions,
        thin_walls,
        cap_sphere,
        direct_light,
        later_bounces,
        energy,
        linear,
        throughput,
        voxelize,
        paper_tables,
        versus_mitsuba,
        interiors,
        calibration,
        furnace_pixels,
        display_noise,
        ray_cost,
        distributed,
    ):
        lines += part()
    return "\n".join(lines).rstrip() + "\n\n" + kept_part()


def kept_part() -> str:
    """The hand-written end of the current page, from the :data:`KEPT` marker on."""
    text = OUT.read_text() if OUT.exists() else ""
    at = text.find(KEPT)
    return text[at:] if at >= 0 else KEPT + "\n"


def main(argv: list[str] | None = None) -> int:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import readme_figures

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--check",
        action="store_true",
        help="exit 1 if docs/performance.md or the README's figures are not what the JSON gives",
    )
    ap.add_argument("--stdout", action="store_true", help="print instead of writing")
    args = ap.parse_args(argv)
    pages = {
        OUT: build(),
        readme_figures.README: readme_figures.render(readme_figures.README.read_text()),
    }
    if args.stdout:
        sys.stdout.write(pages[OUT])
        return 0
    if args.check:
        stale = [p for p, text in pages.items() if not p.exists() or p.read_text() != text]
        for p in stale:
            print(f"{p.relative_to(ROOT)} is out of date: run python scripts/make_performance.py")
        return 1 if stale else 0
    for p, text in pages.items():
        p.write_text(text)
        print(f"wrote {p.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
