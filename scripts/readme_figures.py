"""The README's two figure tables, "How accurate" and "How fast", from the
benchmark JSON in benchmarks/results/.

``scripts/make_performance.py`` writes them into README.md between the
``<!-- BEGIN name ... -->`` and ``<!-- END name -->`` markers, together with
docs/performance.md, and its ``--check`` fails when either file differs from
what the JSON gives. Each row names the command that writes its JSON.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
README = ROOT / "README.md"


def _load(name: str) -> dict:
    return json.loads((RESULTS / name).read_text())


def pc(x: float) -> str:
    """A fraction as a percentage with two significant digits."""
    v = 100.0 * abs(x)
    return f"{v:.2g}%" if v < 10 else f"{v:.0f}%"


def pcr(values) -> str:
    """A range of fractions as percentages: ``0.25-0.36%``."""
    lo, hi = pc(min(values)), pc(max(values))
    return lo if lo == hi else f"{lo[:-1]}-{hi}"


def sci(x: float) -> str:
    return f"{x:.1e}".replace("e-0", "e-")


def s(x: float) -> str:
    return f"{x:.2g} s" if x < 10 else f"{x:.0f} s"


def _table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])


# ----------------------------------------------------------------------------- accuracy


def _furnace() -> list[list[str]]:
    rows = {(r["scene"], r["rho"]): r for r in _load("propagation_furnace.json")["rows"]}
    fine = {(r["scene"], r["rho"]): r for r in _load("propagation_furnace_res96_R8.json")["rows"]}
    a, b = rows["sphere", 0.5], rows["sphere", 0.9]
    c, c48 = fine["sphere", 0.99], rows["sphere", 0.99]
    return [
        [
            f"furnace sphere, `L = Le/(1-ρ)`, res {a['res']}, R {a['R']}",
            f"ρ 0.5: {pc(a['mean_err'])} mean / {pc(a['max_err'])} max; "
            f"ρ 0.9: {pc(b['mean_err'])} / {pc(b['max_err'])}",
            "`python benchmarks/propagation.py furnace`",
        ],
        [
            f"furnace sphere, ρ 0.99, res {c['res']}",
            f"{pc(c['mean_err'])} / {pc(c['max_err'])} ({pc(c48['mean_err'])} / "
            f"{pc(c48['max_err'])} at res {c48['res']})",
            f"`python benchmarks/propagation.py furnace --res {c['res']}`",
        ],
    ]


def _cap() -> list[str]:
    r = max(_load("propagation_cap.json")["rows"], key=lambda r: (r["res"], r["R"]))
    return [
        f"emitting-cap sphere, res {r['res']}, R {r['R']}",
        f"{pc(r['mean_err'])} mean / {pc(r['max_err'])} max",
        "`python benchmarks/propagation.py cap`",
    ]


def _energy() -> list[str]:
    rows = _load("propagation_energy_R8.json")["rows"]
    worst = {r["res"]: max(abs(r[f"imbalance_{c}"]) for c in "rgb") for r in rows}
    fine = max(v for k, v in worst.items() if k >= 256)
    ress = " ".join(str(k) for k in sorted(worst))
    return [
        "energy balance, open Cornell box, R 8",
        f"within {pc(fine)} from res 256 on; {pc(worst[64])} at res 64",
        f"`python benchmarks/propagation.py energy --radii 8 16 --res {ress} --threads 2`",
    ]


def _cornell_image() -> list[str]:
    r = _load("cornell_defaults.json")["sizes"]["256"]
    return [
        "Cornell box image, defaults, 256x256, against a converged Mitsuba 3 render",
        f"relMSE {sci(r['rel_mse'])} after {r['frames']} frames (the tolerance: 1e-3)",
        "`python benchmarks/cornell_defaults.py`",
    ]


def _furnace_pixels() -> list[str]:
    d = _load("furnace_pixels.json")
    rows = [r for r in d["rows"] if r["budget"] == "default"]
    seeds = len({r["seed"] for r in rows})
    cams = len({r["camera"] for r in rows})
    w, h = d["size"]
    by = {a: [r["worst"] for r in rows if r["albedo"] == a] for a in (0.5, 0.9)}
    return [
        f"furnace sphere image, defaults, {w}x{h}, {seeds} seeds x {cams} cameras",
        f"worst pixel {pcr(by[0.5])} (ρ 0.5), {pcr(by[0.9])} (ρ 0.9)",
        "`python benchmarks/furnace_pixels.py`",
    ]


def _calibration() -> list[str]:
    d = _load("calibration.json")
    ratios = [x["ratio"] for r in d["rows"] for x in r["seeds"]]
    outside = sum(not 0.5 <= x <= 2.0 for x in ratios)
    sizes = ", ".join(f"{r['scene']} {r['pixels'][0]}x{r['pixels'][1]}" for r in d["rows"])
    return [
        f"the display's own error estimate where it stops, {len(d['rows'])} scenes x "
        f"{d['seeds']} seeds ({sizes})",
        f"estimated over measured relMSE {min(ratios):.2f}-{max(ratios):.2f}, "
        f"{outside} of {len(ratios)} outside 0.5-2",
        f"`python benchmarks/calibration.py --seeds {d['seeds']} --threads {d['threads']}`",
    ]


def _interiors() -> list[str]:
    d = _load("interiors_128.json")
    sc = {r["scene"]: r for r in d["scenes"]}
    names = ("window-room", "sponza-atrium", "door-room")
    door = sc["door-room"]

    def bright(r) -> str:
        b = r["voxgi_brightness"]
        lo, hi = f"{min(b):.3f}", f"{max(b):.3f}"
        return lo if lo == hi else f"{lo}-{hi}"

    return [
        f"interiors at {d['size']}x{d['size']} against Mitsuba 3: barred window / "
        "Sponza-like atrium / door ajar",
        "relMSE "
        + " / ".join(sci(sc[n]["voxgi_rel_mse"]) for n in names)
        + f" (the door room, lit through a slit narrower than a voxel, against "
        f"{door['reference_spp']:,} samples a pixel whose own noise is "
        f"{sci(door['reference_noise_rel_mse'])} of that); brightness of the pixels off the "
        "lamps "
        + " / ".join(bright(sc[n]) for n in names)
        + f" (the Cornell box: {bright(sc['cornell-box'])})",
        "`python benchmarks/interiors.py`",
    ]


def _junctions() -> list[str]:
    rows = [r for r in _load("propagation_junctions.json")["rows"] if r["wall"] != "plain"]
    ress = sorted({r["res"] for r in rows})
    return [
        f"a closed box split by a zero-thickness wall, res {ress[0]}-{ress[-1]}, R 22",
        "the gathering finds a partner in all but "
        f"{pcr([r['lost_mean'] for r in rows])} of each record's hemisphere on average; up "
        f"to {pc(max(r['lost_max'] for r in rows))} missing where three surfaces meet in "
        "one voxel",
        "`python benchmarks/propagation.py junctions`",
    ]


def _thin_walls() -> list[str]:
    d = _load("propagation_thin_walls.json")
    traced = [r for r in d["rows"] if r["bounces"] == "traced 64"]
    lines = [r for r in d["rows"] if r["bounces"] == "lines"]
    ress = sorted({r["res"] for r in traced})
    off = [r["err_over_2pct"] for r in lines]
    return [
        f"the same box in the furnace (ρ {d['rho']}, R {d['R']}), res {ress[0]}-{ress[-1]}, "
        "with the traced bounces of `voxgi.render`'s solve",
        f"every record within {pc(max(r['err_max'] for r in traced))} of `Le/(1-ρ)`, mean "
        f"within {pc(max(abs(r['err_mean']) for r in traced))} (the lines alone: "
        f"{min(off)}-{max(off)} records more than 2% off, up to "
        f"{pc(max(r['err_max'] for r in lines))})",
        "`python benchmarks/propagation.py thin_walls`",
    ]


def _direct_light() -> list[str]:
    sc = next(r for r in _load("direct_light.json")["scenes"] if r["scene"] == "window-room")
    exact = max(abs(o["exact"] - 1) for o in sc["objects"])
    short = [1 - o["shoot"] for o in sc["objects"]]
    return [
        f"direct light per object, barred-window room, res {sc['resolution']}",
        f"within {pc(exact)} of a converged integration (the paper's shooting: {pcr(short)} short)",
        "`python benchmarks/direct_light.py`",
    ]


def accuracy() -> str:
    rows = [
        *_furnace(),
        _cap(),
        _energy(),
        _cornell_image(),
        _furnace_pixels(),
        _calibration(),
        _interiors(),
        _junctions(),
        _thin_walls(),
        _direct_light(),
    ]
    return _table(["check", "result", "command"], rows)


# ----------------------------------------------------------------------------- speed


def _time_vs_error(size: int) -> list[str]:
    d = _load(f"time_vs_error_{size}.json")
    best = min(d["voxgi"], key=lambda r: r["seconds"] if r["rel_mse"] < 1e-3 else 1e9)
    default = next(r for r in d["voxgi"] if r["label"] == "defaults")
    t = d["time_to_1e-03"]
    return [
        f"Cornell box {size}x{size} to relMSE 1e-3",
        f"{s(default['seconds'])} (`voxgi.render(scene)`: resolution {default['resolution']}, "
        f"{default['frames']} frames, to {sci(default['rel_mse'])}; the fastest setting: "
        f"{s(best['seconds'])})",
        f"Mitsuba 3 `{d['mitsuba'][0]['variant']}`: {s(t['mitsuba'])}, same run",
        f"`python benchmarks/time_vs_error.py --size {size}`",
    ]


def _second_view() -> list[str]:
    a, b = (_load(f"time_vs_error_{n}.json")["second_view"] for n in (256, 512))
    return [
        "a second view of a saved solution, 256x256 / 512x512",
        f"{s(a['seconds'])} / {s(b['seconds'])}",
        "",
        "`python benchmarks/time_vs_error.py --size 256 512`",
    ]


def _rooms() -> list[list[str]]:
    d = _load("interiors_128.json")
    sc = {r["scene"]: r for r in d["scenes"]}
    w, door = sc["window-room"], sc["door-room"]
    size = f"{d['size']}x{d['size']}"
    approx = " (extrapolated by 1/spp)" if door["mitsuba_seconds_extrapolated"] else ", same run"
    return [
        [
            f"the room lit through a barred window, {size}, to voxgi's relMSE "
            f"({sci(w['voxgi_rel_mse'])})",
            s(w["voxgi_seconds"]),
            f"Mitsuba: {s(w['mitsuba_seconds_at_voxgi_error'])}, same run",
            "`python benchmarks/interiors.py`",
        ],
        [
            f"the room lit through a door ajar, {size}, to voxgi's error "
            f"({sci(door['voxgi_rel_mse_less_reference_noise'])} less the reference's noise)",
            s(door["voxgi_seconds"]),
            f"Mitsuba: about {s(door['mitsuba_seconds_at_voxgi_error'])}{approx}",
            "`python benchmarks/interiors.py`",
        ],
    ]


def _furnace_direct() -> list[str]:
    f = _load("direct_light.json")["furnace"]
    ex, sh, tr, paper = (
        f[k] for k in ("exact", "shoot at R 8", "shoot at R 8, traced bounces", "shoot")
    )
    return [
        f"direct light of a furnace sphere whose {f['records'] / 1000:.0f}k records all emit, "
        f"res {f['resolution']}, R {f['directions']}",
        f"exact: {s(ex['direct_seconds'])} (solve {s(ex['solve_seconds'])}); the shot light, "
        f"by one gathering pass: {s(sh['direct_seconds'])} (solve {s(sh['solve_seconds'])}; "
        f"with traced bounces {s(tr['solve_seconds'])}, radiance error {pc(tr['mean_error'])} "
        f"mean / {pc(tr['max_error'])} max)",
        f"the paper's shooting at R 35: {s(paper['solve_seconds'])} "
        f"({pc(paper['mean_error'])} / {pc(paper['max_error'])})",
        "`python benchmarks/direct_light.py`",
    ]


def _paper() -> list[list[str]]:
    rows = _load("propagation_paper.json")["rows"]
    r = next(r for r in rows if r["threads"] == 2 and r["pairs"] == "replayed")
    return [
        [
            f"the paper's bunny: {r['records'] / 1000:.0f}k records, gathering R 22 x 4 iterations",
            f"{s(r['gather_s'])} ({r['threads']} threads)",
            f"paper: {r['paper_propagate_s']} s on one 1.86 GHz core",
            "`python benchmarks/propagation.py paper`",
        ],
        [
            "its shooting, R 35",
            f"{s(r['shoot_s'])} ({r['threads']} threads)",
            f"paper: {r['paper_shoot_s']} s",
            "same",
        ],
    ]


def _voxelize() -> list[str]:
    r = max(_load("voxelize.json")["results"], key=lambda r: r["triangles"])
    return [
        f"voxelize {r['triangles'] / 1000:.0f}k triangles at resolution {r['resolution']}",
        s(r["median_s"]),
        "",
        "`python benchmarks/voxelize.py`",
    ]


def speed() -> str:
    meta = _load("propagation_furnace.json")
    rows = [
        _time_vs_error(256),
        _time_vs_error(512),
        _second_view(),
        *_rooms(),
        _furnace_direct(),
        *_paper(),
        _voxelize(),
    ]
    cpu = (meta.get("cpu") or "x86-64 CPU").replace("(R)", "")
    head = f"On {meta.get('cores', 2)} cores of an {cpu}, no GPU:\n\n"
    return head + _table(["work", "voxgi", "for comparison", "command"], rows)


def tables() -> dict[str, str]:
    """The generated blocks of the README, by marker name."""
    return {"accuracy": accuracy(), "speed": speed()}


def render(text: str) -> str:
    """``text`` (the README) with every generated block rewritten."""
    for name, body in tables().items():
        pat = re.compile(
            rf"(<!-- BEGIN {name}: [^\n]*-->\n).*?(<!-- END {name} -->)", flags=re.DOTALL
        )
        if not pat.search(text):
            raise SystemExit(f"README.md has no <!-- BEGIN {name}: ... --> block")
        text = pat.sub(lambda m, body=body: m.group(1) + body + "\n" + m.group(2), text)
    return text
