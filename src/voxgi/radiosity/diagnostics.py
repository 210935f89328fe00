"""What a solve reports about itself: the lost and back fractions and the
energy balance (``docs/design.md`` §5, §10)."""

from __future__ import annotations

import time

import numpy as np

from .iteration import State
from .linesystem import Gatherer
from .problem import Problem

__all__ = ["back_fraction", "energy_balance", "lost_fraction"]


def lost_fraction(p: Problem, gather: Gatherer, vis) -> tuple:
    """Per record the found share of its hemisphere, and the lost fraction δ
    (area-weighted over front records; ``docs/design.md`` §5, §10)."""
    if vis is None:  # no gathering ran (or only a recording pass): one visibility pass
        t = time.perf_counter()
        all_fams = np.arange(len(p.gds.families), dtype=np.int64)
        _, vis, _ = gather(p.gds, np.zeros((p.n, 3), np.float32), all_fams, True, defer_vis=False)
        p.seconds["visibility"] = time.perf_counter() - t
    found = vis / p.S["gather"]
    front = ~p.a["back"]
    wa = p.area * front
    delta = float(1 - np.sum(wa * found) / np.sum(wa)) if np.sum(wa) > 0 else 0.0
    p.stats["lost_fraction"] = delta
    p.stats["lost_fraction_max"] = float(np.max(np.where(front, 1 - found, 0.0)))
    return found


def back_fraction(p: Problem, gather: Gatherer) -> None:
    """Share of the front records' cos-weighted hemisphere that ends on black
    back records (no albedo, no emission): in a closed scene, light lost
    through occluders, which the lost fraction does not see."""
    front = ~p.a["back"]
    wa = p.area * front
    dark = p.a["back"] & ~np.any(p.rho > 0, axis=1) & ~np.any(p.E > 0, axis=1)
    dark[p.twins.back] = False  # stand-ins for their front twins: not a loss
    bf = bf_max = 0.0
    if not p.opt.diagnostics:
        p.stats["skipped"]["back_fraction"] = "diagnostics=False"
    elif np.any(dark) and np.sum(wa) > 0:
        t = time.perf_counter()
        ind = np.zeros((p.n, 3), np.float32)
        ind[dark] = 1.0
        all_fams = np.arange(len(p.gds.families), dtype=np.int64)
        gb, _, _ = gather(p.gds, ind, all_fams, False)
        p.seconds["back_fraction"] = time.perf_counter() - t
        share = gb[:, 0] / p.S["gather"]
        bf = float(np.sum(wa * share) / np.sum(wa))
        bf_max = float(np.max(np.where(front, share, 0.0)))
    else:
        p.stats["skipped"]["back_fraction"] = "no black back records"
    p.stats["back_fraction"] = bf
    p.stats["back_fraction_max"] = bf_max


def energy_balance(p: Problem, Hd, s: State, found, shoot_escape) -> dict:
    """Emitted, absorbed and escaping power per channel and their imbalance
    (escaping counted on the sender side; ``docs/design.md`` §5)."""
    area = p.area
    emitted = (p.E * area[:, None]).sum(axis=0) + p.light_power
    absorbed = ((1 - p.rho) * (Hd + s.Hg) * area[:, None]).sum(axis=0)
    gather_escape = (s.R * (area * (1 - found))[:, None]).sum(axis=0)
    escaping = shoot_escape + gather_escape
    with np.errstate(divide="ignore", invalid="ignore"):
        imbalance = np.where(emitted > 0, (emitted - absorbed - escaping) / emitted, 0.0)
    return {
        "emitted": emitted.tolist(),
        "absorbed": absorbed.tolist(),
        "escaping": escaping.tolist(),
        "escaping_shoot": shoot_escape.tolist(),
        "imbalance": imbalance.tolist(),
    }
