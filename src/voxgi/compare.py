"""Render one scene with voxgi's defaults and with Mitsuba 3, and compare (``voxgi compare``).

This module sits above the pipeline (:mod:`voxgi.pipeline`) and imports
Mitsuba lazily; Mitsuba is the optional ``bench`` extra. The comparison
follows ``docs/design.md`` §9: a Mitsuba reference at high spp, voxgi's
relMSE against it, and Mitsuba's own time to reach that relMSE, from renders
at doubling spp (interpolated in log-log between the two that bracket it).
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import _validate
from .display import camera_rays
from .metrics import rel_mse
from .pipeline import render as pipeline_render
from .pipeline import solve
from .rays import Tracer
from .scene import Scene
from .voxels import voxelize

__all__ = ["Comparison", "compare"]


@dataclass
class Comparison:
    """Result of :func:`compare`.

    Attributes
    ----------
    rows : list of dict
        One per renderer (``"voxgi"``, ``"mitsuba"`` at the spp that reached
        voxgi's error, ``"reference"``): ``method``, ``spp`` (Mitsuba),
        ``seconds``, ``rel_mse`` against the reference, ``brightness`` (3,)
        the ratio of summed radiance to the reference's over the pixels whose
        whole footprint sees surfaces that do not emit.
    voxgi, reference : (H, W, 3) float32
        The two images.
    sweep : list of (spp, seconds, rel_mse)
        Mitsuba's renders at doubling spp.
    mitsuba_seconds_to_match : float or None
        Mitsuba's time to voxgi's relMSE (interpolated; None if not reached).
    reference_noise : float
        A quarter of the relMSE between the reference's two halves.
    files : dict
        Paths written (``out_dir``).
    """

    rows: list
    voxgi: np.ndarray
    reference: np.ndarray
    sweep: list
    mitsuba_seconds_to_match: float | None
    reference_noise: float
    files: dict = field(default_factory=dict)

    def table(self) -> str:
        """The rows as an aligned text table."""
        head = f"{'method':<10} {'spp':>6} {'seconds':>9} {'relMSE':>10}  brightness (R, G, B)"
        lines = [head, "-" * len(head)]
        for r in self.rows:
            spp = "" if r["spp"] is None else str(r["spp"])
            b = ", ".join(f"{x:.4f}" for x in r["brightness"])
            lines.append(
                f"{r['method']:<10} {spp:>6} {r['seconds']:9.2f} {r['rel_mse']:10.3e}  ({b})"
            )
        t = self.mitsuba_seconds_to_match
        lines.append(
            "mitsuba to voxgi's relMSE: "
            + ("not reached in the sweep" if t is None else f"{t:.2f} s (interpolated)")
        )
        lines.append(f"reference noise (estimated relMSE): {self.reference_noise:.2e}")
        return "\n".join(lines)


#: Sub-pixel points whose rays must all meet a surface that does not emit
#: for a pixel to count in the brightness: its centre and its corners.
_FOOTPRINT = ((0.5, 0.5), (0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0))


def _non_emitter_mask(scene: Scene, cam) -> np.ndarray:
    """(H, W) bool: pixels whose whole footprint sees surfaces that do not emit.

    A pixel at a lamp's edge takes the lamp's radiance, many times the rest,
    in the share of its samples that land on the lamp: a sum over pixels that
    includes such pixels follows that share's noise (up to 1% of the Cornell
    box's sum after 9 frames), not the surfaces' light. A pixel counts when
    the rays through its centre and its four corners all meet a surface that
    does not emit, and with the Gaussian pixel filter, whose samples reach 2
    pixels out, so do its neighbours within 2 pixels.
    """
    obj = scene.triangles()["object"]
    emit = np.array([o.material.is_emitter for o in scene.objects])
    ok = np.ones(cam.height * cam.width, bool)
    with Tracer(scene, 1) as tr:
        for offset in _FOOTPRINT:
            org, dirs = camera_rays(cam, offset)
            prim = tr.intersect(
                np.ascontiguousarray(org - tr.centre, np.float32),
                np.ascontiguousarray(dirs, np.float32),
            )
            hit = prim >= 0
            ok &= hit
            ok[hit] &= ~emit[obj[prim[hit]]]
    ok = ok.reshape(cam.height, cam.width)
    if cam.pixel_filter == "gaussian":
        r = 2
        pad = np.pad(ok, r, constant_values=True)
        for dy in range(-r, r + 1):
            for dx in range(-r, r + 1):
                ok = ok & pad[r + dy : r + dy + cam.height, r + dx : r + dx + cam.width]
    return ok


def _brightness(img: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> list[float]:
    a = img[mask].sum(axis=0, dtype=np.float64)
    b = ref[mask].sum(axis=0, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return [float(x) for x in np.where(b > 0, a / b, np.nan)]


def _seconds_to(err: float, sweep: list) -> float | None:
    """Time of the sweep at relMSE ``err``, log-log between the bracketing renders."""
    for (_s0, t0, e0), (_s1, t1, e1) in itertools.pairwise(sweep):
        if e0 >= err >= e1 and e0 > 0 and e1 > 0 and e0 != e1:
            f = math.log(e0 / err) / math.log(e0 / e1)
            return math.exp(math.log(t0) + f * (math.log(t1) - math.log(t0)))
    if sweep and sweep[0][2] <= err:
        return sweep[0][1]
    return None


def compare(
    scene: Scene,
    *,
    spp: int = 1024,
    max_sweep_spp: int | None = None,
    resolution: int | None = None,
    width: int | None = None,
    height: int | None = None,
    seed: int = 0,
    threads: int | None = None,
    out_dir=None,
    plot: bool = False,
    progress: bool = False,
    variant: str | None = None,
) -> Comparison:
    """Render ``scene`` with voxgi's defaults and with Mitsuba 3, and compare.

    Parameters
    ----------
    scene : Scene
        With a camera. Left unchanged.
    spp : int
        Samples per pixel of Mitsuba's reference (>= 2; rendered as two
        halves of different seeds, whose difference estimates its noise).
    max_sweep_spp : int or None
        Largest spp of Mitsuba's doubling sweep (None: ``spp // 4``); the
        sweep stops once it reaches voxgi's relMSE.
    resolution : int or None
        voxgi's voxel resolution (None: the pipeline's default).
    width, height : int or None
        Override the camera's image size.
    seed : int
        voxgi's seed; Mitsuba's sweep and reference use others.
    threads : int or None
        voxgi's threads (Mitsuba uses its own pool).
    out_dir : path or None
        Where to write ``voxgi.exr``, ``reference.exr``, ``difference.png``
        (``|voxgi − reference|``, tone-mapped) and, with ``plot``,
        ``time_vs_error.png``.
    plot : bool
        Also plot relMSE against time for both (matplotlib); voxgi's curve
        comes from extra renders at looser tolerances of the same solution.
    progress : bool
    variant : str or None
        Mitsuba variant (None: ``llvm_ad_rgb`` where it works).

    Returns
    -------
    Comparison

    Raises
    ------
    ImportError
        Mitsuba is not installed (``pip install 'voxgi[bench]'``).
    """
    from .mitsuba import mitsuba_module, to_mitsuba

    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected voxgi.Scene, got {type(scene).__name__}")
    spp = _validate.integer(spp, "spp", low=2)
    sweep_cap = _validate.integer(max_sweep_spp, "max_sweep_spp", low=1, allow_none=True)
    sweep_cap = max(1, spp // 4) if sweep_cap is None else sweep_cap
    cam = scene.camera
    if cam is None:
        raise ValueError("compare: the scene has no camera")
    changes = {k: v for k, v in (("width", width), ("height", height)) if v is not None}
    if changes:
        cam = cam.replace(**changes)
    mi = mitsuba_module(variant)

    # voxgi with its defaults: voxelize + solve + display
    t0 = time.perf_counter()
    sol, seconds = None, {}
    if resolution is not None:
        vox = voxelize(scene, resolution, threads=threads)
        seconds["voxelize"] = time.perf_counter() - t0
        sol = solve(vox, threads=threads, progress=progress)
        seconds["solve"] = time.perf_counter() - t0 - seconds["voxelize"]
    out = pipeline_render(scene, sol, camera=cam, seed=seed, threads=threads, progress=progress)
    out.stats["seconds"].update(seconds)
    t_voxgi = time.perf_counter() - t0
    img = out.image

    # Mitsuba: one scene, a warm-up render, then the reference and the sweep
    sc = mi.load_dict(to_mitsuba(scene, spp=1, camera=cam))

    def mitsuba(n: int, s: int) -> tuple[np.ndarray, float]:
        t = time.perf_counter()
        im = np.array(mi.render(sc, spp=int(n), seed=int(s)), dtype=np.float32)[..., :3]
        return np.ascontiguousarray(im), time.perf_counter() - t

    mitsuba(1, 7)
    half_a, ta = mitsuba(spp // 2, 1001)
    half_b, tb = mitsuba(spp - spp // 2, 2002)
    ref = 0.5 * (half_a + half_b)
    ref_noise = 0.25 * rel_mse(half_a, half_b)
    err_voxgi = rel_mse(img, ref)
    sweep = []
    n = 1
    while n <= sweep_cap:
        im, t = mitsuba(n, 3003 + n)
        sweep.append((n, t, rel_mse(im, ref)))
        if sweep[-1][2] <= err_voxgi:
            break
        n *= 2
    match = _seconds_to(err_voxgi, sweep)
    mask = _non_emitter_mask(scene, cam)
    last = sweep[-1]
    rows = [
        {
            "method": "voxgi",
            "spp": None,
            "seconds": t_voxgi,
            "rel_mse": err_voxgi,
            "brightness": _brightness(img, ref, mask),
            "frames": out.frames,
        },
        {
            "method": "mitsuba",
            "spp": last[0],
            "seconds": last[1],
            "rel_mse": last[2],
            "brightness": _brightness(im, ref, mask),
        },
        {
            "method": "reference",
            "spp": spp,
            "seconds": ta + tb,
            "rel_mse": ref_noise,
            "brightness": [1.0, 1.0, 1.0],
        },
    ]
    result = Comparison(rows, img, ref, sweep, match, ref_noise)
    if out_dir is not None:
        result.files = _write(result, Path(out_dir), out, plot, scene, cam, seed, threads)
    return result


def _write(result: Comparison, out_dir: Path, out, plot, scene, cam, seed, threads) -> dict:
    """The EXRs, the difference PNG and, with ``plot``, the time-error plot."""
    from .io import write_exr, write_png

    out_dir.mkdir(parents=True, exist_ok=True)
    files = {
        "voxgi": write_exr(out_dir / "voxgi.exr", result.voxgi),
        "reference": write_exr(out_dir / "reference.exr", result.reference),
        "difference": write_png(
            out_dir / "difference.png", np.abs(result.voxgi - result.reference)
        ),
    }
    if plot:
        files["plot"] = _plot(result, out_dir / "time_vs_error.png", out, scene, cam, seed, threads)
    return {k: str(v) for k, v in files.items()}


def _plot(result: Comparison, path: Path, out, scene, cam, seed, threads) -> Path:
    """relMSE against seconds: Mitsuba's sweep, and voxgi's solution displayed
    at a few tolerances (its solve time added to each)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .io import atomic_path
    from .pipeline import render

    secs = out.stats["seconds"]
    solve_t = secs.get("voxelize", 0.0) + secs.get("solve", 0.0)
    pts = []
    for tol in (1e-2, 3e-3, 1e-3, 3e-4):
        t = time.perf_counter()
        r = render(
            scene, out.solution, camera=cam, tol=tol, seed=seed, threads=threads, progress=False
        )
        pts.append((solve_t + time.perf_counter() - t, rel_mse(r.image, result.reference)))
    fig, ax = plt.subplots(figsize=(5, 4))
    ax.loglog(*zip(*pts, strict=True), "o-", label="voxgi (tol 1e-2 .. 3e-4)")
    ax.loglog(
        [s[1] for s in result.sweep], [s[2] for s in result.sweep], "s-", label="Mitsuba (spp x2)"
    )
    ax.set_xlabel("seconds")
    ax.set_ylabel("relMSE against the reference")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)
    return path
