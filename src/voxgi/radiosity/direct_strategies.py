"""Direct light on the records, three ways (``docs/design.md`` §5).

Shadow rays to the exact emitters (:func:`voxgi.direct.direct_irradiance`),
the paper's shooting along the discrete lines, or, where it gives the
shooting's answer for less, one gathering pass over the emitters.
"""

from __future__ import annotations

import time

import numpy as np

from .. import _validate
from ..direct import direct_irradiance, light_irradiance
from .problem import Problem, gatherer
from .records import flat_emitter_coverage

__all__ = ["direct_light", "gathering_is_cheaper"]


def direct_light(p: Problem):
    """Direct irradiance H_d from the emitters, the power that escapes on the
    way and the rays it took: by shadow rays to the exact emitters where the
    tuning asks for it and the records know their scene, else by shooting."""
    if not p.shoots:
        if p.lights and p.opt.direct_light == "shoot":
            p.stats["skipped"]["shooting"] = (
                "the scene has point, spot or directional lights or an environment, "
                "which shooting cannot represent: exact direct light instead"
            )
        return _exact_direct_light(p)
    if p.opt.direct_light == "exact":
        p.stats["skipped"]["exact_direct_light"] = (
            "the records carry no scene (vox.scene is None): shot along the lines instead"
        )
    why = gathering_is_cheaper(p)
    if why is not None:
        p.stats["skipped"]["shooting"] = why
        return _gathered_direct_light(p)
    return _shot_direct_light(p)


def gathering_is_cheaper(p: Problem) -> str | None:
    """Why one gathering pass over the emitters' radiosity gives the shot
    direct light for less (``docs/design.md`` §5), or None where it does not.

    Shooting and gathering pair the same records on the same lines, so with
    one direction set for both they exchange the same light; only the
    coverage of flat emitters and the silhouettes of objects that do not
    emit are the shooting's own, so the pass stands in where every object
    emits and none is flat (furnaces, glowing solids). A shot ray marches
    about half the grid's extent, a gathering pass visits every record once
    per direction: with more emitter records x path than records, the pass
    is cheaper. The cheap tests come first: a scene with a lamp leaves before
    the flat test, which the shooting then makes itself."""
    if p.opt.Rs != p.opt.R:
        return None
    es = np.flatnonzero(np.any(p.twins.send(p.E) > 0, axis=1))
    if len(es) == 0:
        return None
    obj = getattr(p.vox, "object_id", None)
    if obj is not None and not np.all(np.isin(obj, obj[es])):
        return None  # a silhouette of an object that does not emit may pass light
    ijk = p.a["ijk"]
    path = 0.5 * float(np.mean(ijk.max(axis=0) - ijk.min(axis=0) + 1))
    if len(es) * path <= p.n or flat_emitter_coverage(p.a, p.vox, es)[1]:
        return None
    return (
        f"{len(es)} emitter records x ~{path:.0f} voxels of path outweigh {p.n} records: "
        "the same light gathered in one pass over the shooting's direction set"
    )


def _gathered_direct_light(p: Problem):
    """The shot direct light by one gathering pass of the emitters'
    radiosity (``gathering_is_cheaper``); what the records do not receive of
    the emitted power escapes."""
    p.stats["direct_light"] = {"method": "gather"}
    t = time.perf_counter()
    # the shooting's direction set is the gathering's: its pass may record
    # the pairs that the bounces then replay
    fams = np.arange(len(p.gds.families), dtype=np.int64)
    sums, _, _ = gatherer(p)(p.gds, p.twins.send(p.E), fams, False, defer_vis=False)
    Hd = sums / p.S["gather"][:, None]
    p.seconds["direct"] = time.perf_counter() - t
    escape = (p.E * p.area[:, None]).sum(axis=0) - (Hd * p.area[:, None]).sum(axis=0)
    return Hd, escape, p.n * len(fams)


def _exact_direct_light(p: Problem):
    """Direct irradiance by shadow rays (``docs/design.md`` §5); what the
    records do not receive of the emitted power escapes. The black records
    (albedo 0) reflect nothing, so they are lit only for the energy balance
    of a solve with diagnostics."""
    t = time.perf_counter()
    receivers = "all" if p.opt.diagnostics else "reflecting"
    kw = dict(
        samples=p.opt.direct_samples,
        threads=p.opt.threads,
        receivers=receivers,
        response=p.response,
    )
    base = np.zeros((p.n, 3)) if p.response is not None else None
    Hd, st = direct_irradiance(p.vox.scene, p.vox, base_out=base, **kw)
    p.stats["direct_light"] = {"method": "exact", "receivers": receivers, **st}
    # what the records receive of the emitting triangles' power (the rest escapes)
    received = (Hd * p.area[:, None]).sum(axis=0)
    if p.lights:
        # the lights' power is what the records receive: it counts as emitted
        # in the energy balance, and none of it escapes on the way
        base_lights = np.zeros((p.n, 3)) if base is not None else None
        H_lights, st_l = light_irradiance(p.vox.scene, p.vox, base_out=base_lights, **kw)
        Hd = Hd + H_lights
        if base is not None:
            base = base + base_lights
        p.light_power = (H_lights * p.area[:, None]).sum(axis=0)
        p.stats["direct_light"]["lights"] = st_l
        p.stats["direct_light"]["rays"] += st_l["rays"]
    p.seconds["direct"] = time.perf_counter() - t
    if receivers == "reflecting":
        p.stats["skipped"]["direct_light_on_black_records"] = (
            "diagnostics=False: what they absorb counts as escaping in stats['energy']"
        )
    escape = (p.E * p.area[:, None]).sum(axis=0) - received
    p.direct_base = base
    return Hd, escape, 0


def _shot_direct_light(p: Problem):
    """Shooting: direct irradiance H_d from the emitters, the power that
    escapes on the way (sender side) and the shooting rays."""
    p.stats["direct_light"] = {"method": "shoot"}
    t = time.perf_counter()
    E_send = p.twins.send(p.E)
    es = np.flatnonzero(np.any(E_send > 0, axis=1)).astype(np.int32)
    cov, flat = flat_emitter_coverage(p.a, p.vox, es)
    p.stats["flat_emitter_objects"] = flat
    sil = _silhouettes(p, es)
    p.stats["silhouettes"] = bool(sil)
    sds, Ss = p.sds, p.S["shoot"]
    hd_raw, unfound, shoot_rays, steps = p.sysm.shoot(
        es,
        sds.families,
        sds.weights,
        E_send,
        p.opt.threads,
        coverage=cov,
        stand_in=p.twins.stand_in,
        **sil,
    )
    Hd = hd_raw / Ss[:, None]
    p.seconds["shoot"] = time.perf_counter() - t
    # stand-in back emitters have E = 0: they add nothing to the escape
    shoot_escape = (p.E[es] * (p.area[es] * unfound / Ss[es])[:, None]).sum(axis=0)
    p.stats["shoot_steps"] = int(steps)
    return Hd, shoot_escape, int(shoot_rays)


def _silhouettes(p: Problem, emitters_send: np.ndarray) -> dict:
    """The shooting's silhouette inputs (``docs/design.md`` §5): records'
    objects, areas in voxel units (-1 for objects that send in this pass)
    and back flags; empty without object ids."""
    if getattr(p.vox, "object_id", None) is None:
        return {}
    obj_id = _validate.as_c_array(p.vox.object_id, np.int32, (p.n,), "vox.object_id")
    sil_area = np.ascontiguousarray(p.area / p.a["pitch"] ** 2, dtype=np.float64)
    # An emitting object's exit face shoots its whole line to the receivers
    # behind it: a carried remainder would count that part of the line twice.
    sil_area[np.isin(obj_id, np.unique(obj_id[emitters_send]))] = -1.0
    return dict(
        object=obj_id, sil_area=sil_area, back=np.ascontiguousarray(p.a["back"], dtype=np.bool_)
    )
