"""The virtual point lights: which records light a frame, and with what
weight (``docs/design.md`` §6)."""

from __future__ import annotations

import math

import numpy as np

from .. import _validate
from ..incidence import NODES
from ..lights import LUMINANCE
from ..microfacet import Microfacet

__all__ = ["VPLSampler", "continuing_objects", "followed_sheets", "place_vpls"]


def continuing_objects(scene):
    """(O,) uint8: 1 for the objects with a microfacet lobe and no emission,
    where the display's gather rays follow the lobe one bounce further
    (docs/design.md §14); or None where there is none."""
    flag = np.array(
        [
            isinstance(o.material.specular, Microfacet) and not o.material.is_emitter
            for o in scene.objects
        ],
        np.uint8,
    )
    return flag if flag.any() else None


def followed_sheets(scene, sol) -> np.ndarray | None:
    """(N,) bool: the records of stacked sheets (:func:`voxgi.traced.stacked_records`)
    that do not emit, where the display's gather rays bounce on
    rather than read the record's mean, and whose VPLs carry the light
    leaving their own point, walked alike (``docs/design.md`` §6); None
    where there are none, or where the scene has point lights or an
    environment, whose light that bounce cannot find."""
    from ..traced import sheet_codes, stacked_records

    if scene.lights or scene.environment is not None:
        return None
    vox = sol.vox
    # the sheets a walk goes on through (code 1): a ray reads an emitter's
    # light where it lands, the light it sends and the light it reflects,
    # which MIS shares with its VPLs; a black back record sends none either way
    sheets = sheet_codes(vox, stacked_records(vox)) == 1
    if vox.back is not None:
        sheets &= ~np.asarray(vox.back, bool)
    return sheets if sheets.any() else None


def base_outgoing(scene) -> np.ndarray:
    """(O, NODES, 3) float32: per object, the radiance its diffuse base sends
    out at cosine μ = i / (NODES - 1) over its mean, ``b(μ) / (2 ∫ b(μ) μ dμ)``
    with ``b`` the base's directional albedo (by reciprocity the base sends
    out light as it takes it in); 1 for objects without a microfacet lobe or
    without a base (a conductor). A plastic's base lies under a coat whose
    Fresnel reflection grows towards grazing angles, so it sends little
    there (``docs/design.md`` §14)."""
    mu = np.linspace(0.0, 1.0, NODES)
    fine = np.linspace(0.0, 1.0, 513)
    out = np.ones((len(scene.objects), NODES, 3), np.float32)
    rows: dict = {}
    for i, o in enumerate(scene.objects):
        m = o.material
        if not isinstance(m.specular, Microfacet):
            continue
        key = (m.specular, tuple(float(x) for x in m.albedo))
        if key not in rows:
            base = np.asarray(m.albedo, np.float64)
            b = np.asarray(m.specular.base_albedo(base, fine), np.float64)  # (513, 3)
            y = b * fine[:, None]
            mean = 2.0 * np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(fine)[:, None], axis=0)
            at = np.asarray(m.specular.base_albedo(base, mu), np.float64)
            with np.errstate(divide="ignore", invalid="ignore"):
                rows[key] = np.where(mean > 0, at / mean, 1.0)
        out[i] = rows[key]
    return out


def base_share(scene, sol, flag) -> np.ndarray | None:
    """(N, 3) the share of each record's light that a pixel whose gather
    rays follow the lobes reads as the record's mean: 1, or for the records
    of an object the rays follow (``flag``) its diffuse base's. From the
    solve's split (``sol.base_radiosity``) where it made one, else the split
    under uniform light, 1 - S / A for a plastic (S its coat's hemispherical
    reflectance, A the record's albedo) and 0 for a conductor."""
    if flag is None:
        return None
    vox = sol.vox
    share = np.ones((len(vox), 3))
    oid = np.asarray(vox.object_id)
    albedo = np.asarray(vox.albedo, np.float64)
    B = np.asarray(sol.radiosity, np.float64)
    split = getattr(sol, "base_radiosity", None)
    for i in np.flatnonzero(flag):
        sel = oid == i
        lobe = scene.objects[i].material.specular
        if split is not None:
            b = np.asarray(split, np.float64)[sel]
            with np.errstate(divide="ignore", invalid="ignore"):
                share[sel] = np.where(B[sel] > 0, np.clip(b / B[sel], 0.0, 1.0), 0.0)
        elif lobe.kind == "conductor":
            share[sel] = 0.0
        else:
            s, _ = lobe._plastic_albedo_terms()
            s32 = np.asarray(s, np.float32).astype(np.float64)
            a = albedo[sel]
            with np.errstate(divide="ignore", invalid="ignore"):
                share[sel] = np.where(a > 0, np.maximum(0.0, 1.0 - s32 / a), 0.0)
    return share


def _morton(ijk: np.ndarray) -> np.ndarray:
    """30-bit interleaved (Morton) keys of voxel coordinates (10 bits each)."""

    def spread(v):
        v = (v.astype(np.int64) - v.min()) & 0x3FF
        v = (v | (v << 16)) & 0x030000FF
        v = (v | (v << 8)) & 0x0300F00F
        v = (v | (v << 4)) & 0x030C30C3
        v = (v | (v << 2)) & 0x09249249
        return v

    return spread(ijk[:, 0]) | (spread(ijk[:, 1]) << 1) | (spread(ijk[:, 2]) << 2)


class VPLSampler:
    """The fixed VPL sequence of a solution: two sets, emitters and the rest.

    As in the paper, records are drawn from a cumulative table by binary
    search, with replacement, in two sets (emitters and non-emitters), each
    set with its own count per frame. Records with zero radiosity (black back
    records above all) can send no light and are left out of the table; that
    changes no expectation.

    ``pdf="power"`` (the default) draws a record with probability
    proportional to its power ``ΔA · B`` (luminance) instead of its area
    (``pdf="area"``, the paper's choice): the estimator weight is then
    ``B / (π n p(y))`` with the area density ``p(y) = lum(B_y) / Σ ΔA lum(B)``,
    so every VPL carries the same power. With area sampling a few bright
    records (on the Cornell box, those on top of the tall block, B ≈ 11× the
    mean) are drawn in one frame of several and then light a wall alone: a
    heavy-tailed error that the between-frame spread underestimates.

    Each frame draws its ``n_d`` emitter and ``n_i`` other VPLs stratified
    along the cumulative table, whose records are in Morton (Z-curve) order:
    every draw still has its probability, but a frame's VPLs are spread over
    the surfaces instead of clumped. Frames draw their VPLs independently;
    the render estimates the error of their mean from batch means of frames
    (``docs/design.md`` §6).

    The split: ``n_d / K = Φ_d / (Φ_d + Φ_i)`` with Φ the power
    ``Σ ΔA · B`` (luminance) of each set, at least one VPL for a set with
    power; with equal relative spread per VPL this is the Neyman allocation
    (samples ∝ each set's standard deviation, which scales with its power).
    ``emitter_share`` overrides it.

    Parameters
    ----------
    sol : Solution
    vpls_per_frame : int
    seed : int
    emitter_share : float in [0, 1] or None
    mis : bool
        The VPLs of both sets are combined with gather rays (their weight is
        then ``B/π`` and ``pa`` carries ``n p(y)`` of their set).
    pdf : {"power", "area"}
    on_surface : bool
        Each VPL of a frame sits at a point drawn uniformly on its record's
        own surface (``docs/design.md`` §6) instead of at the
        record's fixed centroid.
    follow_share : (N, 3) or None
        The share of each record's light its VPLs bring a pixel whose
        gather rays follow the lobes (:func:`base_share`).
    walked : (N,) bool or None
        With MIS only: the records of stacked sheets whose VPLs carry, each
        frame, the light leaving their own point (walked through the stack
        by the shader, :func:`followed_sheets`) rather than their record's
        mean ``B/π``; they keep their place in the tables.
    """

    def __init__(
        self,
        sol,
        vpls_per_frame: int = 16,
        seed: int = 0,
        emitter_share: float | None = None,
        mis: bool = False,
        pdf: str = "power",
        on_surface: bool = True,
        follow_share: np.ndarray | None = None,
        walked: np.ndarray | None = None,
    ):
        if pdf not in ("power", "area"):
            raise ValueError(f"pdf: expected 'power' or 'area', got {pdf!r}")
        vox = sol.vox
        n = len(vox)
        B = _validate.as_c_array(sol.radiosity, np.float64, (n, 3), "sol.radiosity")
        area = _validate.as_c_array(vox.area, np.float64, (n,), "vox.area")
        if np.any(B < 0) or np.any(area < 0):
            raise ValueError("sol.radiosity and vox.area must be >= 0")
        back = np.asarray(vox.back, dtype=bool) if vox.back is not None else np.zeros(n, bool)
        emit = np.any(np.asarray(vox.emission) > 0, axis=1) & ~back
        useful = ~back & (area > 0) & np.any(B > 0, axis=1)
        #: (N,) bool or None: the records whose VPLs' light is walked each
        #: frame (followed_sheets; with MIS only)
        self.walked = None
        if walked is not None and mis:
            self.walked = _validate.as_c_array(walked, bool, (n,), "walked")
        self.skipped_records = int(n - useful.sum())
        order = np.argsort(_morton(np.asarray(vox.ijk)), kind="stable")
        lum = B @ LUMINANCE
        self.pdf = pdf
        self.sets = []
        for sel in (useful & emit, useful & ~emit):
            idx = order[sel[order]]
            w = area[idx] * lum[idx] if pdf == "power" else area[idx]
            cum = np.cumsum(w)
            power = float(np.sum(area[idx] * lum[idx]))
            # Density per unit area of each record of the set: p(y) = w_y / (ΔA_y W).
            dens = np.zeros(n)
            if len(idx):
                dens[idx] = (lum[idx] if pdf == "power" else 1.0) / cum[-1]
            self.sets.append((idx, cum, power, dens))
        self.K = int(vpls_per_frame)
        (_, cum_d, pd, dens_d), (_, cum_i, pi, dens_i) = self.sets
        has_d, has_i = len(cum_d) > 0 and pd > 0, len(cum_i) > 0 and pi > 0
        if emitter_share is None:
            share = pd / (pd + pi) if (pd + pi) > 0 else 0.0
        else:
            share = float(emitter_share)
        if has_d and has_i and self.K >= 2:
            nd = int(np.clip(round(self.K * share), 1, self.K - 1))
        elif has_d:
            nd = self.K
        else:
            nd = 0
        if not has_i:
            nd = self.K if has_d else 0
        self.counts = (nd, self.K - nd if has_i else 0)
        self.seed = int(seed)
        self.mis = bool(mis) and sum(self.counts) > 0
        #: (N,) float32 n p(y) of every record in an MIS set (n its set's VPLs
        #: per frame, 0 elsewhere): the VPL side of the MIS weights, for VPLs
        #: and gather hits alike.
        pa = self.counts[0] * dens_d + self.counts[1] * dens_i if self.mis else np.zeros(n)
        self.record_pa = pa.astype(np.float32)
        self.pos = np.ascontiguousarray(vox.centroid, dtype=np.float64)
        self.normal = np.ascontiguousarray(vox.normal, dtype=np.float32)
        self.area32 = area.astype(np.float32)
        self.B = B
        #: (N, 3) float32 or None: the share of each record's light its VPLs
        #: bring a pixel whose gather rays follow the lobes (base_share)
        self.share = None if follow_share is None else np.asarray(follow_share, np.float32)
        self.vox = vox
        self.on_surface = bool(on_surface)

    @property
    def empty(self) -> bool:
        return sum(self.counts) == 0

    def frame(self, f: int, sets: int = 1) -> dict:
        """The VPLs of frame ``f`` in ``sets`` independent sets, set after set
        (each its emitters' VPLs first, then the rest's), every set drawn
        stratified along the tables; ``start`` (sets + 1,) says where each
        set begins. They depend on the seed, the frame and ``sets`` only:
        every view of that many sets sees the same."""
        rng = np.random.default_rng([self.seed, int(f), 0x1B1, int(sets)])
        idx_all, w_all, pa_all = [], [], []
        for (idx, cum, _, dens), k in zip(self.sets, self.counts, strict=True):
            if k == 0:
                continue
            # stratified along the table, each set with its own jitter
            u = (np.arange(k) + rng.random((sets, k))) / k * float(cum[-1])
            pick = idx[np.minimum(np.searchsorted(cum, u, side="right"), len(idx) - 1)]
            idx_all.append(pick)
            if self.mis:
                # An MIS VPL carries B/π; the kernel divides by n p(y) + the gather pdf.
                w_all.append(np.ones((sets, k)))
                pa_all.append(self.record_pa[pick])
            else:
                # E ≈ (1/n) Σ (B/π) G V / p(y): the estimator weight times the radiance.
                w_all.append(1.0 / (k * dens[pick]))
                pa_all.append(np.zeros((sets, k), np.float32))
        idx = np.concatenate(idx_all, axis=1).reshape(-1)
        w = np.concatenate(w_all, axis=1).reshape(-1)
        out = {
            "pa": np.ascontiguousarray(np.concatenate(pa_all, axis=1).reshape(-1), np.float32),
            "index": idx,
            "pos": np.ascontiguousarray(self.pos[idx]),
            "normal": np.ascontiguousarray(self.normal[idx]),
            "weight": np.ascontiguousarray((w[:, None] * self.B[idx] / math.pi).astype(np.float32)),
            "area": np.ascontiguousarray(self.area32[idx]),
            "start": np.arange(sets + 1, dtype=np.int64) * sum(self.counts),
        }
        if self.share is not None:
            out["share"] = np.ascontiguousarray(self.share[idx])
            out["object"] = np.ascontiguousarray(np.asarray(self.vox.object_id)[idx], np.int32)
        return out


#: Candidate points per VPL and frame; each lands on the record's surface
#: with probability about 1/3 for a flat record (its polygon against the
#: square of side √3 pitch the candidates are drawn from).
_PLACE_TRIES = 12


def place_vpls(
    sampler: VPLSampler,
    tracer,
    index: np.ndarray,
    centroid: np.ndarray,
    f: int,
    seed: int,
    eps: float,
) -> np.ndarray:
    """(K, 3) points drawn uniformly on each VPL's record surface (centred frame).

    A VPL fixed at its record's centroid makes the image converge to the
    lighting of a finite set of point lights: each casts a sharp shadow of
    every thin occluder, and the shadows line up into streaks. A point
    drawn anew each frame on the record's own surface converges to the
    area integral of the piecewise-constant radiosity instead
    (``docs/design.md`` §6). Candidates are drawn in a square of the
    record's tangent plane around the voxel, projected onto the scene's
    triangles along the normal, and kept when the hit is the record's own
    object, facing within 60° of its normal (the voxelization's clustering),
    inside its voxel, and in sight of the centroid (a record cut at a thin
    wall keeps to its own side). A record none of whose candidates lands
    keeps its centroid. ``tracer`` is the scene's (:class:`voxgi.rays.Tracer`
    with ``obj``, ``ng`` per triangle), ``eps`` the shadow-ray offset.
    """
    tr, T = tracer, _PLACE_TRIES
    vox, K = sampler.vox, len(index)
    rng = np.random.default_rng([seed, int(f), 0x5EA])
    h = float(vox.pitch)
    n = sampler.normal[index].astype(np.float64)
    lo = np.asarray(vox.origin, np.float64) + np.asarray(vox.ijk, np.float64)[index] * h
    lo -= tr.centre
    mid = lo + 0.5 * h
    # The voxel centre projected onto the record's plane: the polygon lies
    # within √3/2 pitch of it.
    mid -= np.einsum("ij,ij->i", mid - centroid, n)[:, None] * n
    a = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(n, a)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    uv = (rng.random((T, K, 2)) - 0.5) * (math.sqrt(3.0) * h)
    cand = mid + uv[..., :1] * t1 + uv[..., 1:] * t2 + h * n  # (T, K, 3)
    org = cand.reshape(-1, 3)
    dirs = np.broadcast_to(-n, (T, K, 3)).reshape(-1, 3)
    prim = tr.intersect(org.astype(np.float32), dirs.astype(np.float32))
    ok = prim >= 0
    tri = np.where(ok, prim, 0)
    ng = tr.ng[tri]
    dn = np.einsum("ij,ij->i", dirs, ng)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.einsum("ij,ij->i", tr.tris[tri, 0] - org, ng) / dn
    q = org + np.where(np.isfinite(t), t, 0.0)[:, None] * dirs
    obj = np.broadcast_to(np.asarray(vox.object_id)[index], (T, K)).reshape(-1)
    slack = 1e-6 * h
    inside = np.all((q >= np.repeat(lo[None], T, 0).reshape(-1, 3) - slack), axis=1) & np.all(
        (q <= np.repeat(lo[None], T, 0).reshape(-1, 3) + h + slack), axis=1
    )
    ok &= (tr.obj[tri] == obj) & (np.abs(dn) > 0.5) & inside
    # In sight of the centroid, both lifted by the shadow-ray offset.
    c = np.broadcast_to(centroid, (T, K, 3)).reshape(-1, 3) + eps * -dirs
    seg = q + eps * -dirs - c
    dist = np.linalg.norm(seg, axis=1)
    check = np.flatnonzero(ok & (dist > eps))
    if len(check):
        d = seg[check] / dist[check, None]
        blocked = tr.occluded(
            c[check].astype(np.float32), d.astype(np.float32), dist[check].astype(np.float32)
        )
        ok[check[blocked != 0]] = False
    ok = ok.reshape(T, K)
    first = np.argmax(ok, axis=0)
    found = ok[first, np.arange(K)]
    out = centroid.copy()
    out[found] = q.reshape(T, K, 3)[first[found], np.flatnonzero(found)]
    return out
