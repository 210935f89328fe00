"""One solve's records, settings, line system and direction sets."""

from __future__ import annotations

import functools
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from .. import _validate
from ..directions import DirectionSet, direction_set
from ..incidence import incidence_response
from ..solution import Solution
from ..voxels import VoxelSet, available_memory
from .linesystem import Gatherer, LineRecords
from .memory import shoots_direct_light
from .tuning import Settings

__all__ = ["Problem", "build_problem", "gatherer", "normalise", "open_backend", "zero_solution"]


@dataclass
class _Twins:
    """Back records of closed objects and their front twins (``docs/design.md`` §5).

    A back record of a closed object sends its front twin's value along the
    lines (it stays black itself), and two such stand-ins never pair: their
    exchange is the inside of the object, which no front record sees.
    """

    back: np.ndarray
    front: np.ndarray
    stand_in: np.ndarray | None

    def send(self, x) -> np.ndarray:
        """What records send along the lines: float32, stand-ins their twin's value."""
        if len(self.back) == 0:
            return np.ascontiguousarray(x, dtype=np.float32)
        y = np.array(x, dtype=np.float32, copy=True)
        y[self.back] = y[self.front]
        return y


def _closed_twins(vox: VoxelSet, a: dict, closed) -> _Twins:
    """Pair each back record of a closed object with its front twin (the
    voxelizer writes it right before; checked here)."""
    n = len(a["ijk"])
    twin_b = twin_f = np.zeros(0, np.int64)
    if closed is None:
        closed = list(getattr(vox, "stats", {}).get("closed_objects", [])) or False
    if closed is not False:
        obj = _validate.as_c_array(vox.object_id, np.int32, (n,), "vox.object_id")
        if closed is True:
            sel_obj = np.ones(len(a["back"]), bool)
        else:
            ids = _validate.as_c_array(np.atleast_1d(closed), np.int32, (-1,), "closed")
            sel_obj = np.isin(obj, ids)
        b = np.flatnonzero(a["back"] & sel_obj)

        def twin_at(f_):
            f_ = np.clip(f_, 0, n - 1)
            return (
                ~a["back"][f_]
                & np.all(a["ijk"][f_] == a["ijk"][b], axis=1)
                & (obj[f_] == obj[b])
                & (np.einsum("ij,ij->i", a["normal"][f_], a["normal"][b]) < -0.99)
            )

        # the twin precedes a back record, or, where the inner side of a
        # sealed two-sided object is its winding's side, follows it
        before = twin_at(b - 1) & (b > 0)
        after = ~before & twin_at(b + 1) & (b < n - 1)
        ok = before | after
        twin_b, twin_f = b[ok], np.where(before, b - 1, b + 1)[ok]
    stand_in = None
    if len(twin_b):
        stand_in = np.zeros(n, np.bool_)
        stand_in[twin_b] = True
    return _Twins(twin_b, twin_f, stand_in)


@dataclass
class Problem:
    """One solve's records, settings, line system and direction sets."""

    vox: VoxelSet
    a: dict
    opt: Settings
    twins: _Twins
    area: np.ndarray
    rho: np.ndarray
    E: np.ndarray
    stats: dict
    seconds: dict
    sysm: object = None
    gds: DirectionSet | None = None
    sds: DirectionSet | None = None
    lds: DirectionSet | None = None
    S: dict = field(default_factory=dict)
    #: power the records receive from lights other than emitting triangles
    light_power: np.ndarray = field(default_factory=lambda: np.zeros(3))
    #: (N, 3) the direct light weighed by the records' base share
    #: (voxgi.incidence), where exact direct light met glossy records; or None
    direct_base: np.ndarray | None = None

    @property
    def n(self) -> int:
        return len(self.area)

    @property
    def lights(self) -> bool:
        """The records' scene has point, spot or directional lights or an environment."""
        scene = getattr(self.vox, "scene", None)
        return scene is not None and scene.has_lights

    @functools.cached_property
    def response(self):
        """The records' :class:`voxgi.incidence.IncidenceResponse`, or None
        (no glossy record, no scene to read the materials from, or
        switched off by the study tuning's ``incidence``)."""
        scene = getattr(self.vox, "scene", None)
        if scene is None or not self.opt.incidence:
            return None
        return incidence_response(scene, self.vox)

    @property
    def shoots(self) -> bool:
        """Direct light by shooting: asked for, or exact light asked for but
        the records carry no scene to trace. This is the one place that
        decides: lights other than emitting triangles have no records to
        shoot from, so a scene with any is always lit exactly
        (``docs/design.md`` §11)."""
        return shoots_direct_light(self.vox, self.opt)

    @property
    def limit(self) -> int:
        """Iterations allowed: ``max_bounces``, else ``max_iterations``; 0 if all albedos are 0."""
        if not np.any(self.rho > 0):
            return 0
        mb = self.opt.max_bounces
        return self.opt.max_iterations if mb is None else mb


def build_problem(vox, a, opt) -> Problem:
    """Records, closed-object twins and the statistics every solve reports."""
    twins = _closed_twins(vox, a, opt.closed)
    E = np.pi * a["emission"].astype(np.float64)  # emitted radiosity
    stats: dict = {
        "records": len(a["ijk"]),
        "emitters": int(np.count_nonzero(np.any(a["emission"] > 0, axis=1))),
        "threads": opt.threads,
        "skipped": {},
        "closed_back_records": len(twins.back),
    }
    vstats = getattr(vox, "stats", None) or {}
    if vstats.get("inner_records"):
        stats["skipped"]["inner_records"] = (
            f"{vstats['inner_records']} records on the inner side of the closed two-sided "
            f"objects {vstats.get('sealed_objects')}, which no light reaches, are black"
        )
    return Problem(
        vox=vox,
        a=a,
        opt=opt,
        twins=twins,
        area=a["area"],
        rho=a["albedo"].astype(np.float64),
        E=E,
        stats=stats,
        seconds={},
    )


def zero_solution(p: Problem) -> Solution:
    """The zero solution of a scene without emitters, with a warning."""
    warnings.warn(
        "solve: the scene has no emitter; the solution is zero", RuntimeWarning, stacklevel=3
    )
    p.stats.update(
        rays=0, shoot_rays=0, gather_rays=0, seconds={"total": 0.0}, skipped={"all": "no emitter"}
    )
    return Solution(vox=p.vox, radiosity=np.zeros((p.n, 3), np.float32), stats=p.stats)


def open_backend(p: Problem, executor, progress: bool) -> None:
    """The line system (the executor's) and the direction sets."""
    t = time.perf_counter()
    opt, a = p.opt, p.a
    records = LineRecords(a["ijk"], a["normal"], a["point"], opt.epsilon, opt.history)
    p.sysm = executor.line_system(records, progress=progress)
    if hasattr(p.sysm, "stats"):
        p.stats["executor"] = p.sysm.stats
    p.gds = direction_set(opt.R)
    p.sds = direction_set(opt.Rs) if p.shoots else None
    p.lds = direction_set(opt.Rl) if opt.Rl is not None else None
    p.seconds["setup"] = time.perf_counter() - t


def normalise(p: Problem) -> None:
    """Per-record normalisation S(n) of every direction set (``docs/design.md`` §3)."""
    t = time.perf_counter()
    opt, nt = p.opt, p.opt.threads
    Sg = p.sysm.normalisation(p.gds.families, p.gds.weights, nt)
    # exact direct light shoots nothing: the shooting set needs no S(n)
    Ss = (
        Sg
        if opt.Rs == opt.R or not p.shoots
        else p.sysm.normalisation(p.sds.families, p.sds.weights, nt)
    )
    Sl = None
    if p.lds is not None:
        if opt.Rl == opt.R:
            Sl = Sg
        elif opt.Rl == opt.Rs and p.shoots:
            Sl = Ss
        else:
            Sl = p.sysm.normalisation(p.lds.families, p.lds.weights, nt)
    p.S = {"gather": Sg, "shoot": Ss, "later": Sl}
    p.seconds["normalisation"] = time.perf_counter() - t
    d = {}
    for name, ds in (("gather", p.gds), ("shoot", p.sds)):
        if ds is None:
            continue
        d[name] = {
            "radius": int(ds.radius),
            "count": len(ds),
            "families": len(ds.families),
            "non_primitive": ds.non_primitive,
        }
    if p.lds is not None:
        d["later"] = {"radius": opt.Rl, "count": len(p.lds), "after": opt.later_after}
    p.stats["directions"] = d
    p.stats["S_spread"] = {"gather": [float(Sg.min()), float(Sg.max())]}
    if p.sds is not None:
        p.stats["S_spread"]["shoot"] = [float(Ss.min()), float(Ss.max())]


def gatherer(p: Problem) -> Gatherer:
    """The gathering passes, with the pair cache's budget and expected passes."""
    opt = p.opt
    if not hasattr(p.sysm, "make_pair_table") or opt.pair_cache is False:
        budget = None
        why = "pair_cache=False" if opt.pair_cache is False else "the executor walks the lines"
        p.stats["pair_cache"] = {"recorded": False, "reason": why}
    elif opt.cache_cap is not None:
        budget = opt.cache_cap
    else:
        budget = available_memory() // 4 if opt.pair_cache is None else 1 << 62
    limit, la = p.limit, opt.later_after
    extra = 1 if opt.diagnostics else 0
    passes = {id(p.gds): (min(limit, la) if p.lds is not None else limit) + extra}
    if p.lds is not None:  # (the same object as gds when later_radius == radius)
        passes[id(p.lds)] = passes.get(id(p.lds), 0) + max(0, limit - la)
    return Gatherer(p.sysm, opt.threads, p.twins.stand_in, budget, passes)
