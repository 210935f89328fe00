"""Radiosity on voxels: discrete-line propagation (shooting, then gathering).

The discretised radiosity equation (DESIGN-NOTES §1, eq. 1)

    B(x) = E(x) + ρ(x) Σ_σ B(I(x,σ)) (n_x·σ̂) ΔΩ(σ) / (π S(n_x))

is solved on the records of a :class:`~voxgi.VoxelSet`, ``I(x,σ)`` the first
record seen from ``x`` along the discrete line of direction σ (found for all
records at once in O(N) per direction family, :class:`voxgi._core.LineSystem`)
and ``S(n)`` the raw cos-weighted hemisphere sum of the direction set, so that
every record gathers exactly one hemisphere (DESIGN-NOTES §3).

Bookkeeping (DESIGN-NOTES §5): *shooting* gives every record its direct
irradiance ``H_d`` from the emitters with the finer radius (default 35);
*gathering* (default 22) then propagates only the reflected radiosity
``R = B − E``, so that ``B = E + ρ (H_d + H_gathered)`` and direct light is not
counted twice.

Ray counts (``Solution.stats``): a *gathering ray* is one record meeting one
direction family (both of its directions) in one iteration; a *shooting ray*
is one emitter record and one direction it faces.
"""

from __future__ import annotations

import json
import time
import warnings
import zipfile
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from . import _core, _validate
from .directions import direction_set
from .voxels import VoxelSet, _available_memory

__all__ = ["Solution", "gather_partial", "line_system", "pair_table_bytes", "solve"]


@dataclass
class Solution:
    """Radiosity of every record of a :class:`VoxelSet`.

    Attributes
    ----------
    vox : VoxelSet
        The records solved for.
    radiosity : (N, 3) float32
        ``B`` per record (W/m² per channel, i.e. ``pi`` times radiance).
    bounces : int
        Gathering iterations run.
    residuals : list of float
        Relative residual after each iteration.
    stats : dict
        ``rays``, ``shoot_rays``, ``gather_rays``, ``seconds`` (phase -> s),
        and what was skipped.
    """

    vox: VoxelSet
    radiosity: np.ndarray
    bounces: int = 0
    residuals: list = field(default_factory=list)
    stats: dict = field(default_factory=dict)

    @property
    def radiance(self) -> np.ndarray:
        """(N, 3) float32 outgoing radiance ``B / pi``."""
        return (self.radiosity / np.float32(np.pi)).astype(np.float32)

    def save(self, path) -> Path:
        """Save records and radiosity to a ``.npz`` file (see :meth:`load`).

        Parameters
        ----------
        path : str or Path
            Destination; ``.npz`` is appended by numpy when missing.

        Returns
        -------
        Path
            The file written.
        """
        from .io import atomic_path

        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_name(path.name + ".npz")
        arrays = {}
        meta = {
            "bounces": int(self.bounces),
            "residuals": [float(r) for r in self.residuals],
            "stats": self.stats,
            "vox_stats": self.vox.stats,
        }
        for f in fields(VoxelSet):
            v = getattr(self.vox, f.name)
            if isinstance(v, np.ndarray):
                arrays["vox_" + f.name] = v
            elif f.name not in ("stats",):
                meta["vox_" + f.name] = v
        arrays["radiosity"] = self.radiosity
        arrays["meta"] = np.frombuffer(
            json.dumps(meta, default=_json_default).encode(), dtype=np.uint8
        )
        # (the temporary name keeps the .npz suffix, so numpy adds none)
        with atomic_path(path) as tmp:
            np.savez_compressed(tmp, **arrays)
        return path

    @classmethod
    def load(cls, path) -> Solution:
        """Load a solution written by :meth:`save`.

        Parameters
        ----------
        path : str or Path
            A ``.npz`` file from :meth:`save`.

        Returns
        -------
        Solution
            With its :class:`VoxelSet`.
        """
        import zlib

        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"solution file not found: {path}")
        if path.is_file() and path.stat().st_size == 0:
            raise ValueError(f"{path}: empty file (0 bytes), not a voxgi solution file")
        try:
            sol = cls._load(path)
        except (OSError, EOFError, ValueError, KeyError, TypeError, zlib.error,
                zipfile.BadZipFile) as exc:
            # (json and Unicode decoding errors are ValueErrors)
            raise ValueError(f"{path}: not a readable voxgi solution file "
                             f"({type(exc).__name__}: {exc})") from None
        vox = sol.vox
        ijk = np.asarray(vox.ijk)
        if ijk.ndim != 2:
            raise ValueError(f"{path}: vox_ijk must have shape (N, 3), got {ijk.shape}")
        n = len(ijk)
        # Every per-record array has the record count and the type VoxelSet
        # documents: a short one would otherwise load and fail later in render.
        want = {"ijk": ((n, 3), np.int32), "normal": ((n, 3), np.float32),
                "area": ((n,), np.float32), "albedo": ((n, 3), np.float32),
                "emission": ((n, 3), np.float32), "centroid": ((n, 3), np.float64),
                "object_id": ((n,), np.int32), "back": ((n,), np.bool_),
                "side": ((n,), np.int8), "origin": ((3,), np.float64)}
        for name, (shape, dtype) in want.items():
            a = getattr(vox, name)
            if a is None and name == "side":
                continue
            a = np.asarray(a)
            if a.shape != shape or a.dtype != dtype:
                raise ValueError(f"{path}: vox_{name} must be {np.dtype(dtype).name} of shape "
                                 f"{shape} for {n} records, got {a.dtype} {a.shape}")
            if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
                raise ValueError(f"{path}: vox_{name} has non-finite values")
        if n and ijk.min() < 0:
            raise ValueError(f"{path}: vox_ijk has negative voxel coordinates")
        if not (np.isfinite(vox.pitch) and vox.pitch > 0) or vox.resolution < 2:
            raise ValueError(f"{path}: bad grid (pitch {vox.pitch}, resolution "
                             f"{vox.resolution})")
        r = np.asarray(sol.radiosity)
        if r.shape != (n, 3) or r.dtype.kind != "f":
            raise ValueError(f"{path}: radiosity must be floats of shape ({n}, 3), got "
                             f"{r.dtype} {r.shape}")
        with np.errstate(over="ignore"):
            sol.radiosity = r.astype(np.float32)
        if not np.all(np.isfinite(sol.radiosity)):
            raise ValueError(f"{path}: radiosity has values that are not finite in float32")
        return sol

    @classmethod
    def _load(cls, path: Path) -> Solution:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(bytes(z["meta"]).decode())
            kw = {}
            for f in fields(VoxelSet):
                if "vox_" + f.name in z.files:
                    kw[f.name] = z["vox_" + f.name]
                elif "vox_" + f.name in meta:
                    kw[f.name] = meta["vox_" + f.name]
            kw["stats"] = meta.get("vox_stats", {})
            kw["pitch"] = float(kw["pitch"])
            kw["resolution"] = int(kw["resolution"])
            vox = VoxelSet(**kw)
            return cls(
                vox=vox,
                radiosity=z["radiosity"],
                bounces=meta["bounces"],
                residuals=meta["residuals"],
                stats=meta["stats"],
            )


def _flat_emitter_coverage(a: dict, vox: VoxelSet, emitters: np.ndarray) -> tuple[np.ndarray, list]:
    """Per record: its area in voxel units if it is a front record of a flat
    emitting object (every front record of the object has one normal and
    lies in one plane, to 1e-3 voxel), else -1 (whole-line rule). Returns
    that and the ids of the flat objects."""
    n = len(a["ijk"])
    cov = np.full(n, -1.0)
    obj = getattr(vox, "object_id", None)
    if obj is None or len(emitters) == 0:
        return cov, []
    obj = np.asarray(obj)
    flat = []
    for o in np.unique(obj[emitters]):
        idx = np.flatnonzero((obj == o) & ~a["back"])
        if len(idx) == 0:
            continue
        nrm = a["normal"][idx].astype(np.float64)
        pts = a["point"][idx].astype(np.float64)
        n0 = nrm[0]
        if np.all(nrm @ n0 > 1 - 1e-6) and np.all(np.abs((pts - pts[0]) @ n0) < 1e-3):
            cov[idx] = a["area"][idx] / a["pitch"] ** 2
            flat.append(int(o))
    return cov, flat


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"cannot store {type(o).__name__} in Solution stats")


# ----------------------------------------------------------------------------- inputs


def _check_vox(vox) -> dict:
    """Validate a VoxelSet and return the C-contiguous arrays the kernels take."""
    if not isinstance(vox, VoxelSet):
        raise TypeError(f"vox: expected a VoxelSet, got {type(vox).__name__}")
    ijk = _validate.as_c_array(vox.ijk, np.int32, (-1, 3), "vox.ijk")
    n = len(ijk)
    if n == 0:
        raise ValueError("vox: no records")
    out = {
        "ijk": ijk,
        "normal": _validate.as_c_array(vox.normal, np.float32, (n, 3), "vox.normal"),
        "area": _validate.as_c_array(vox.area, np.float64, (n,), "vox.area"),
        "albedo": _validate.as_c_array(vox.albedo, np.float32, (n, 3), "vox.albedo"),
        "emission": _validate.as_c_array(vox.emission, np.float32, (n, 3), "vox.emission"),
        "centroid": _validate.as_c_array(vox.centroid, np.float64, (n, 3), "vox.centroid"),
    }
    pitch = _validate.real(vox.pitch, "vox.pitch", low=0.0, low_open=True)
    origin = _validate.vec3(vox.origin, "vox.origin")
    if np.any(out["area"] < 0):
        raise ValueError("vox.area: negative area")
    if np.any(out["emission"] < 0):
        raise ValueError("vox.emission: negative emission")
    a = out["albedo"]
    if np.any(a < 0) or np.any(a >= 1):
        bad = int(np.argwhere((a < 0) | (a >= 1))[0, 0])
        raise ValueError(f"vox.albedo: record {bad} has albedo {a[bad].tolist()} outside [0, 1)")
    ln = np.linalg.norm(out["normal"], axis=1)
    if np.any(np.abs(ln - 1) > 1e-3):
        bad = int(np.argmax(np.abs(ln - 1)))
        raise ValueError(f"vox.normal: record {bad} is not a unit vector (|n| = {ln[bad]:.4g})")
    back = getattr(vox, "back", None)
    out["back"] = (
        np.zeros(n, bool)
        if back is None
        else _validate.as_c_array(back, np.bool_, (n,), "vox.back")
    )
    # surface points in voxel units (voxel ijk spans [ijk, ijk + 1]); float32
    # keeps 1e-3 voxel accuracy up to 16k voxels, far under the facing margin
    out["point"] = np.ascontiguousarray((out["centroid"] - origin) / pitch, dtype=np.float32)
    out["pitch"] = pitch
    return out


def line_system(vox: VoxelSet, *, epsilon: float = 0.02, history: int = 16) -> _core.LineSystem:
    """The prepared line system of a VoxelSet (orders, occupancy; O(N) once).

    Parameters
    ----------
    vox : VoxelSet
        Records.
    epsilon : float
        Facing-rule margin, in voxels (DESIGN-NOTES §4).
    history : int
        F records remembered per line (1..32).
    """
    a = _check_vox(vox)
    return _core.LineSystem(
        a["ijk"], a["normal"], a["point"], epsilon=float(epsilon), history=int(history)
    )


def gather_partial(
    vox: VoxelSet,
    radiosity,
    family_indices,
    directions: int = 22,
    *,
    threads: int | None = None,
    epsilon: float = 0.02,
    history: int = 16,
    system: _core.LineSystem | None = None,
) -> np.ndarray:
    """One Jacobi gathering pass over a subset of the direction families.

    The unit of work a distributed solver hands to a worker: partial sums
    over disjoint subsets of families add up to the full pass.

    Parameters
    ----------
    vox : VoxelSet
        Records.
    radiosity : (N, 3) array_like
        Values to propagate (for the solver, the reflected radiosity ``B - E``).
    family_indices : (K,) array_like of int
        Indices into ``direction_set(directions).families``.
    directions : int
        Radius of the direction sphere.
    threads : int or None
        Threads (None: all).
    system : LineSystem, optional
        A prepared :func:`line_system` of ``vox`` to reuse.

    Returns
    -------
    sums : (N, 3) float64
        ``Σ radiosity[partner] · cos · ΔΩ/π`` over the selected families (both
        signs), not yet divided by the records' ``S(n)``.
    """
    ds = direction_set(directions)
    s = system if system is not None else line_system(vox, epsilon=epsilon, history=history)
    vals = _validate.as_c_array(radiosity, np.float32, (s.size, 3), "radiosity")
    idx = _validate.as_c_array(family_indices, np.int64, (-1,), "family_indices")
    if idx.size and (idx.min() < 0 or idx.max() >= len(ds.families)):
        raise ValueError(f"family_indices: must lie in [0, {len(ds.families)})")
    sums, _, _ = s.gather(ds.families, ds.weights, vals, idx, False, _validate.threads(threads))
    return sums


# ----------------------------------------------------------------------------- solve


class _Extrapolator:
    """Geometric-tail extrapolation of a linear fixed-point iteration.

    Once successive updates ``d_k = R_{k+1} − R_k`` shrink by a steady ratio
    λ (per channel, from ``<d_k, d_{k-1}> / <d_{k-1}, d_{k-1}>``), the rest of
    the series is ``d_k λ / (1 − λ)`` (the ambient term of progressive
    radiosity; Aitken's Δ²), added at once. DESIGN-NOTES §5.
    """

    def __init__(self, weights: np.ndarray, rel_tol: float = 0.02):
        self.w = weights[:, None]
        self.prev = None
        self.lam_prev = None
        self.rel_tol = rel_tol
        self.count = 0

    def __call__(self, d: np.ndarray) -> np.ndarray | None:
        """Given the latest update d (N, 3), return the tail to add, or None."""
        prev, self.prev = self.prev, d
        if prev is None:
            return None
        den = np.sum(self.w * prev * prev, axis=0)
        num = np.sum(self.w * d * prev, axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = np.where(den > 0, num / den, 0.0)
        lam_prev, self.lam_prev = self.lam_prev, lam
        if lam_prev is None:
            return None
        ok = (lam > 0) & (lam < 1) & (np.abs(lam - lam_prev) <= self.rel_tol * (1 - lam))
        active = den > 0
        if not np.all(ok | ~active) or not np.any(active):
            return None
        # after a jump the next differences start a new geometric run
        self.prev = None
        self.lam_prev = None
        self.count += 1
        self.factor = np.where(active, lam / (1 - lam), 0.0)
        return d * self.factor


def pair_table_bytes(n: int, families: np.ndarray) -> int:
    """Bytes of the recorded pairs of ``n`` records over ``families``: 3 per
    record and family, each main axis's families padded to tiles of 16."""
    fam = np.asarray(families)
    if len(fam) == 0:
        return 0
    m = np.argmax(np.abs(fam), axis=1)
    tile = _core.PairTable.TILE
    cols = sum(-(-int(np.sum(m == a)) // tile) * tile for a in range(3))
    return _core.PairTable.ENTRY_BYTES * int(n) * cols


class _Gatherer:
    """The gathering passes of one solve. The first pass over a direction
    set walks the lines and, where the budget allows, records the pairs it
    finds (:class:`voxgi._core.PairTable`); later passes over recorded
    families replay them: visibility does not change between iterations,
    so only the first pass pays for it."""

    def __init__(self, sysm, nthreads: int, stand_in, budget: int | None, passes: dict):
        self.sysm = sysm
        self.nthreads = nthreads
        self.stand_in = stand_in
        self.budget = budget  # None: never record
        self.passes = passes  # id(ds) -> expected passes over that set
        self.tables: dict = {}
        self.used = 0
        self.info: dict = {"bytes": 0, "sets": []}
        self.replayed = 0

    def _table(self, ds):
        key = id(ds)
        if key in self.tables:
            return self.tables[key]
        tab = None
        need = pair_table_bytes(self.sysm.size, ds.families)
        entry = {"radius": int(ds.radius), "bytes": need}
        if self.budget is None:
            entry["recorded"] = False
        elif self.sysm.size > _core.PairTable.MAX_RECORDS:
            entry["recorded"] = False
            entry["reason"] = f"more than {_core.PairTable.MAX_RECORDS} records"
        elif self.passes.get(key, 0) < 2:
            entry["recorded"] = False
            entry["reason"] = "one pass only"
        elif self.used + need > self.budget:
            entry["recorded"] = False
            entry["reason"] = f"needs {need / 2**30:.2f} GiB, budget {self.budget / 2**30:.2f} GiB"
        else:
            tab = self.sysm.make_pair_table(ds.families, ds.weights, self.stand_in is not None)
            self.used += need
            entry["recorded"] = True
            self.info["bytes"] = self.used
        self.info["sets"].append(entry)
        self.tables[key] = tab
        return tab

    def __call__(self, ds, values, sel, want_vis, defer_vis=True):
        """(sums, vis, lines walked) of one pass over ``ds.families[sel]``.

        With ``defer_vis``, a pass that records leaves ``vis`` (None) to the
        next pass, which replays and sums it at no cost (the walk pays about
        10% for it)."""
        tab = self._table(ds)
        if tab is not None and np.all(tab.recorded_mask[sel]):
            sums, vis = self.sysm.gather_recorded(tab, values, sel, want_vis, self.nthreads)
            self.replayed += 1
            return sums, vis, 0
        if tab is not None and defer_vis:
            want_vis = False
        return self.sysm.gather(ds.families, ds.weights, values, sel, want_vis, self.nthreads,
                                stand_in=self.stand_in,
                                **({"record": tab} if tab is not None else {}))


def solve(
    vox: VoxelSet,
    directions: int = 22,
    max_bounces: int | None = None,
    tol: float = 1e-4,
    threads: int | None = None,
    client=None,
    *,
    shoot_directions: int = 35,
    method: str = "jacobi",
    progress: bool = True,
    accelerate: bool = True,
    later_directions: int | None = None,
    later_after: int = 2,
    epsilon: float = 0.02,
    history: int = 16,
    gs_blocks: int = 8,
    max_iterations: int = 10000,
    closed=None,
    shoot_coverage: bool = True,
    shoot_silhouettes: bool = True,
    diagnostics: bool = True,
    pair_cache: bool | None = None,
    max_cache_bytes: int | None = None,
) -> Solution:
    """Solve the discrete radiosity equation on the records of ``vox``.

    Shooting from the emitter records first (direct light, radius
    ``shoot_directions``), then Jacobi or Gauss–Seidel gathering of the
    reflected light (radius ``directions``) until the relative residual falls
    under ``tol`` or ``max_bounces`` iterations ran.

    Parameters
    ----------
    vox : VoxelSet
        Records from :func:`voxgi.voxelize`; left unchanged.
    directions : int
        Radius R >= 1 of the gathering direction sphere (22: 5982 directions).
    max_bounces : int or None
        At most this many gathering iterations (None: until converged, at
        most ``max_iterations``). 0 gives direct light only.
    tol : float
        Stop when the estimated remaining relative error of the iteration,
        ``r λ / (1 − λ)`` with ``r = Σ area·|R_{k+1} − R_k| / Σ area·|B_{k+1}|``
        (all channels; one entry of ``residuals`` per iteration) and ``λ`` the
        largest albedo (at least 0.5), falls under it (> 0). For albedos up
        to 0.5 this is ``r < tol``; at 0.99 it asks ``r < tol / 99``.
    threads : int or None
        Threads (None: all hardware threads). Results do not depend on it
        beyond float rounding.
    client : dask.distributed.Client or None
        Run the shooting and every gathering pass on the client's workers
        (:mod:`voxgi.distributed`; ``pip install "voxgi[dask]"``): the records
        are sent once, the direction families split over the workers and the
        partial sums added in a fixed order, so the result equals the local
        one to float rounding.
    shoot_directions : int
        Radius of the shooting direction sphere (35: 15194 directions).
    method : {"jacobi", "gauss-seidel"}
        Jacobi: every iteration gathers from the previous one. Gauss–Seidel:
        the families are split into ``gs_blocks`` blocks and the radiosity is
        updated in place after each block.
    progress : bool
        Show a tqdm progress bar over iterations.
    accelerate : bool
        Geometric-tail extrapolation once the updates shrink steadily
        (DESIGN-NOTES §5); ρ = 0.99 then converges in tens of iterations.
    later_directions : int or None
        Radius for the bounces after the first ``later_after`` ones
        (Piwowar & Malgouyres 2009: later bounces are smooth). The solver then
        propagates each bounce's increment (ΔR_{k+1} = ρ M_k ΔR_k, Jacobi
        only) and ends with the geometric-tail term once the ratio of
        successive bounces is steady. None: every bounce with ``directions``.
    epsilon : float
        Facing-rule margin in voxels (DESIGN-NOTES §4).
    history : int
        F records remembered per line (1..32).
    gs_blocks : int
        Blocks of families for ``method="gauss-seidel"``.
    max_iterations : int
        Bound on the iterations when ``max_bounces`` is None.
    closed : bool or sequence of int, optional
        Objects (ids into ``vox.object_id``; True: all; False: none) whose
        meshes are closed. None (default): the objects :func:`voxgi.voxelize`
        found watertight and consistently wound
        (``vox.stats["closed_objects"]``). A naive line that clips a closed object's band in a voxel
        holding only its near side reaches a black back record: in reality
        it either hit the object's surface or missed it, never its inside
        (measured: the furnace sphere with a closed inner box lost 2.6% at
        rho = 0.9, 22% at 0.99). For these objects a back record sends its
        front twin's radiosity and emission instead of black (it stays black
        itself). The back of an open one-sided surface (a lamp quad) stays
        black either way: its back can be seen.
    shoot_coverage : bool
        Direct light from flat emitters (lamp quads, discs: every record of
        the object in one plane with one normal) by partial coverage
        (default): a shooting ray of emitter record e stands for the share
        ``ΔA_e |n_e·d| / |d_m|`` (voxel units) of its discrete line's
        cross-section, and the rest of e's own plane does not occlude it.
        Curved or closed emitters, and False, keep the paper's rule (each
        ray covers its whole line): a thin lamp seen edge-on then sends as
        if it were a voxel thick (measured on the Cornell box: 37% too much
        power at resolution 32, 15% at 64).
    shoot_silhouettes : bool
        Shooting lines that graze an object's silhouette (default): where a
        line's receivers on one object include a record at a convex edge
        whose other face the line leaves (F along it), and the line then
        leaves the object, the share of the line that those receivers do
        not cover (``1 - Σ ΔA_r |n_r·d| / |d_m|``, voxel units, clamped at
        0) goes on past that object (its F records and its back records) to
        the receivers behind. Without it a line that clips a block's rim is
        stopped whole by the block's far side: shadows a voxel too wide, and
        that light lost (measured on the closed black Cornell box: direct
        light imbalance +3.5% at resolution 32, +2.0% at 64; with it +0.3%,
        +0.4%; ``benchmarks/energy_silhouette.py``). Walls, concave corners
        and edges between two lit faces stay opaque.
    diagnostics : bool
        Run the extra gathering pass behind ``stats["back_fraction"]``
        (default). False skips it (one pass of the ``directions`` set; the
        statistics then say it was skipped); the energy balance and the lost
        fraction come from passes the solve runs anyway.
    pair_cache : bool or None
        Record the pairs the first gathering pass over a direction set finds
        (3 bytes per record and family, at most 16,777,214 records) and
        replay them in the later passes over that set (visibility does not
        change between iterations; the same sums to float rounding, about 4x
        faster per pass; measured on 150k records at R 22, 1 thread: 270-300
        M rays/s replayed, 72-77 M walked, 50 M while recording, which then
        leaves the visibility sums to the first replay). Only for a set
        gathered at least twice (iterations plus the diagnostics pass).
        None (default): when the pairs fit in ``max_cache_bytes``; True: the
        same with no default budget; False: walk the lines every pass. Never
        with ``client`` (the workers walk). ``stats["pair_cache"]`` gives the
        bytes, the sets recorded (or why not) and the passes replayed.
    max_cache_bytes : int or None
        Budget for the recorded pairs of all direction sets; None: a quarter
        of the memory available when the solve starts (``pair_cache=None``),
        no limit (``pair_cache=True``).

    Returns
    -------
    Solution
        ``radiosity`` (N, 3) float32; ``stats`` with ``rays``, ``shoot_rays``,
        ``gather_rays``, ``seconds`` (phase -> s), ``directions``,
        ``S_spread``, ``lost_fraction`` (δ), ``back_fraction`` (area-weighted
        mean share of the front records' cos-weighted hemisphere that ends on
        black back records: in a closed scene, light lost through occluders)
        and ``back_fraction_max``, ``energy`` (emitted, absorbed,
        escaping power per channel; escaping counted on the sender side) and
        ``skipped``.

    Raises
    ------
    TypeError, ValueError
        On a malformed VoxelSet or bad arguments.
    ImportError
        If ``client`` is given and dask.distributed is not installed.
    MemoryError
        If a worker's memory_limit cannot hold the records (checked first).
    """
    t_all = time.perf_counter()
    a = _check_vox(vox)
    R = _validate.integer(directions, "directions", low=1, high=256)
    Rs = _validate.integer(shoot_directions, "shoot_directions", low=1, high=256)
    Rl = _validate.integer(later_directions, "later_directions", low=1, high=256, allow_none=True)
    la = _validate.integer(later_after, "later_after", low=1)
    mb = _validate.integer(max_bounces, "max_bounces", low=0, allow_none=True)
    mi = _validate.integer(max_iterations, "max_iterations", low=1)
    tol = _validate.real(tol, "tol", low=0.0, low_open=True)
    nthreads = _validate.threads(threads)
    eps = _validate.real(epsilon, "epsilon", low=0.0)
    hist = _validate.integer(history, "history", low=1, high=32)
    gsb = _validate.integer(gs_blocks, "gs_blocks", low=1)
    if pair_cache is not None and not isinstance(pair_cache, (bool, np.bool_)):
        raise TypeError(f"pair_cache: expected True, False or None, got {pair_cache!r}")
    cache_cap = _validate.integer(max_cache_bytes, "max_cache_bytes", low=0, allow_none=True)
    if not isinstance(method, str) or method.lower().replace("_", "-") not in (
        "jacobi",
        "gauss-seidel",
    ):
        raise ValueError(f"method: expected 'jacobi' or 'gauss-seidel', got {method!r}")
    method = method.lower().replace("_", "-")
    if later_directions is not None and method != "jacobi":
        raise ValueError("later_directions: only with method='jacobi'")
    if client is not None:  # fail early: the extra missing (ImportError) or not a Client
        from .distributed import check_client

        check_client(client)

    n = len(a["ijk"])
    area = a["area"]
    rho = a["albedo"].astype(np.float64)
    E = np.pi * a["emission"].astype(np.float64)  # emitted radiosity
    # back records of closed objects and their front twins (the voxelizer
    # writes each back record right after its front record; checked here)
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
        b = b[b > 0]
        f_ = b - 1
        ok = (
            ~a["back"][f_]
            & np.all(a["ijk"][f_] == a["ijk"][b], axis=1)
            & (obj[f_] == obj[b])
            & (np.einsum("ij,ij->i", a["normal"][f_], a["normal"][b]) < -0.99)
        )
        twin_b, twin_f = b[ok], f_[ok]
    # the kernels' stand-in flags: two such back records never pair along a
    # line (their exchange is the inside of a closed object, which no front
    # record sees, and it would occlude the front records' own exchanges)
    stand_in = None
    if len(twin_b):
        stand_in = np.zeros(n, np.bool_)
        stand_in[twin_b] = True

    def _send(x):
        # what records send along the lines: back records of closed objects
        # send their front twin's value
        if len(twin_b) == 0:
            return np.ascontiguousarray(x, dtype=np.float32)
        y = np.array(x, dtype=np.float32, copy=True)
        y[twin_b] = y[twin_f]
        return y

    E_send = _send(E)
    emitters = np.flatnonzero(np.any(a["emission"] > 0, axis=1)).astype(np.int32)
    emitters_send = np.flatnonzero(np.any(E_send > 0, axis=1)).astype(np.int32)
    seconds: dict[str, float] = {}
    stats: dict = {
        "records": n,
        "emitters": len(emitters),
        "method": method,
        "threads": nthreads,
        "skipped": {},
        "closed_back_records": len(twin_b),
    }
    if len(emitters) == 0:
        warnings.warn(
            "solve: the scene has no emitter; the solution is zero", RuntimeWarning, stacklevel=2
        )
        stats.update(
            rays=0,
            shoot_rays=0,
            gather_rays=0,
            seconds={"total": 0.0},
            skipped={"all": "no emitter"},
        )
        return Solution(vox=vox, radiosity=np.zeros((n, 3), np.float32), stats=stats)

    t = time.perf_counter()
    if client is None:
        sysm = _core.LineSystem(a["ijk"], a["normal"], a["point"], epsilon=float(eps), history=hist)
    else:  # the same loop below, its gather/shoot calls split over Dask workers
        from .distributed import DistributedLineSystem

        sysm = DistributedLineSystem(client, a["ijk"], a["normal"], a["point"],
                                     epsilon=float(eps), history=hist, progress=progress)
        stats["distributed"] = sysm.stats
    gds = direction_set(R)
    sds = direction_set(Rs)
    lds = direction_set(Rl) if Rl is not None else None
    seconds["setup"] = time.perf_counter() - t

    # per-record normalisation S(n) of every direction set (DESIGN-NOTES §3)
    t = time.perf_counter()
    Sg = sysm.normalisation(gds.families, gds.weights, nthreads)
    Ss = Sg if Rs == R else sysm.normalisation(sds.families, sds.weights, nthreads)
    Sl = None
    if lds is not None:
        Sl = (
            Sg
            if Rl == R
            else (Ss if Rl == Rs else sysm.normalisation(lds.families, lds.weights, nthreads))
        )
    seconds["normalisation"] = time.perf_counter() - t
    stats["directions"] = {
        "gather": {
            "radius": R,
            "count": len(gds),
            "families": len(gds.families),
            "non_primitive": gds.non_primitive,
        },
        "shoot": {
            "radius": Rs,
            "count": len(sds),
            "families": len(sds.families),
            "non_primitive": sds.non_primitive,
        },
    }
    if lds is not None:
        stats["directions"]["later"] = {"radius": Rl, "count": len(lds), "after": la}
    stats["S_spread"] = {
        "gather": [float(Sg.min()), float(Sg.max())],
        "shoot": [float(Ss.min()), float(Ss.max())],
    }

    # --- shooting: direct irradiance H_d from the emitters
    t = time.perf_counter()
    # receiver-side deposit: the exact transpose of gathering (see the
    # kernel's `send_scale` for the sender-side alternative and its aliasing)
    cov = None
    if shoot_coverage:
        cov, flat = _flat_emitter_coverage(a, vox, emitters_send)
        stats["flat_emitter_objects"] = flat
    sil = {}
    if shoot_silhouettes and getattr(vox, "object_id", None) is not None:
        obj_id = _validate.as_c_array(vox.object_id, np.int32, (n,), "vox.object_id")
        sil_area = np.ascontiguousarray(area / a["pitch"] ** 2, dtype=np.float64)
        # Only objects that send nothing in this pass: an emitting object's
        # exit face shoots its whole line to the receivers behind it, and a
        # carried remainder would count that part of the line twice
        # (measured: furnace sphere with an inner box, rho 0.9, res 32: box
        # mean error -0.3% -> +0.8%, sphere -0.3% -> +1.7%).
        sil_area[np.isin(obj_id, np.unique(obj_id[emitters_send]))] = -1.0
        sil = dict(object=obj_id, sil_area=sil_area,
                   back=np.ascontiguousarray(a["back"], dtype=np.bool_))
    stats["shoot_silhouettes"] = bool(sil)
    hd_raw, unfound, shoot_rays, steps = sysm.shoot(
        emitters_send, sds.families, sds.weights, E_send, nthreads, coverage=cov,
        stand_in=stand_in, **sil,
    )
    Hd = hd_raw / Ss[:, None]
    seconds["shoot"] = time.perf_counter() - t
    # sender side: the share of each emitter's rays that met nobody
    # (stand-in back emitters have E = 0: they add nothing to the escape)
    es = emitters_send
    shoot_escape = (E[es] * (area[es] * unfound / Ss[es])[:, None]).sum(axis=0)
    stats["shoot_steps"] = int(steps)

    # --- gathering of the reflected radiosity R = B - E
    Rk = rho * Hd
    residuals: list[float] = []
    gather_rays = 0
    vis = None
    Hg = np.zeros((n, 3))
    t_gather = 0.0
    all_fams = np.arange(len(gds.families), dtype=np.int64)
    parts, parts_ds = None, None  # Gauss-Seidel: the latest sums of every block
    extrap = _Extrapolator(area) if accelerate else None
    limit = mi if mb is None else mb
    if not np.any(rho > 0):
        stats["skipped"]["gathering"] = "all albedos are zero"
        limit = 0
    # recorded pairs (pair_cache): expected passes over each direction set
    if client is not None or pair_cache is False:
        budget = None
        why = "distributed" if client is not None else "pair_cache=False"
        stats["pair_cache"] = {"recorded": False, "reason": why}
    else:
        budget = cache_cap if cache_cap is not None else (
            _available_memory() // 4 if pair_cache is None else 1 << 62)
    extra = 1 if diagnostics else 0
    passes = {id(gds): (min(limit, la) if lds is not None else limit) + extra}
    if lds is not None:  # (the same object as gds when later_directions == directions)
        passes[id(lds)] = passes.get(id(lds), 0) + max(0, limit - la)
    gather = _Gatherer(sysm, nthreads, stand_in, budget, passes)
    bar = None
    if progress and limit > 0:
        from tqdm.auto import tqdm

        bar = tqdm(total=mb, desc="gather", unit="it", leave=False)
    lines_walked = 0
    it = 0
    # coarser later bounces need the bounce-by-bounce (progressive) form: a
    # fixed-point iteration would converge to the coarse operator's answer
    progressive = lds is not None
    dk = Rk.copy()
    Hg_acc = np.zeros((n, 3))
    lam_bound = float(min(max(rho.max(), 0.5), 1 - 1e-6))
    vis_S = Sg
    try:
        while it < limit:
            use_later = lds is not None and it >= la
            ds_it, S_it = (lds, Sl) if use_later else (gds, Sg)
            fams = np.arange(len(ds_it.families), dtype=np.int64)
            blk = np.array_split(fams, min(gsb, len(fams))) if method == "gauss-seidel" else [fams]
            t = time.perf_counter()
            want_vis = vis is None and not use_later
            R_old = Rk
            if progressive:
                # propagate only the last bounce (its increment), with this
                # bounce's directions: B = E + Σ_k ΔR_k, ΔR_{k+1} = ρ M_k ΔR_k
                sums, v, nl = gather(ds_it, _send(dk), fams, want_vis)
                lines_walked += nl
                h_inc = sums / S_it[:, None]
                Hg_acc += h_inc
                dk = rho * h_inc
                R_new = Rk + dk
                if want_vis:
                    vis = v
            elif method == "jacobi":
                sums, v, nl = gather(ds_it, _send(Rk), blk[0], want_vis)
                lines_walked += nl
                Hg = sums / S_it[:, None]
                R_new = rho * (Hd + Hg)
                if want_vis:
                    vis = v
            else:
                # in place: block b gathers from the radiosity updated by blocks < b
                if parts_ds is not ds_it:  # first sweep with this set: blocks not yet run count 0
                    parts, parts_ds = [np.zeros((n, 3)) for _ in blk], ds_it
                cur = Rk.copy()
                vacc = np.zeros(n) if want_vis else None
                for bi, sel in enumerate(blk):
                    sums, v, nl = gather(ds_it, _send(cur), sel, want_vis)
                    lines_walked += nl
                    parts[bi] = sums
                    if vacc is not None:
                        # (None: a recording pass left it to the next sweep)
                        vacc = vacc + v if v is not None else None
                    Hg = sum(parts) / S_it[:, None]
                    cur = rho * (Hd + Hg)
                R_new = cur
                if want_vis:
                    vis = vacc
            t_gather += time.perf_counter() - t
            gather_rays += n * len(ds_it.families)
            d = R_new - R_old
            Btot = np.sum(area[:, None] * np.abs(E + R_new))
            res = float(np.sum(area[:, None] * np.abs(d)) / Btot) if Btot > 0 else 0.0
            Rk = R_new
            it += 1
            residuals.append(res)
            if bar is not None:
                bar.update(1)
                bar.set_postfix(residual=f"{res:.2e}")
            # stop on the estimated remaining error of the geometric tail,
            # res * lam / (1 - lam), lam <= max albedo (every record gathers at
            # most one hemisphere): at rho 0.99 a residual of tol would still
            # leave ~99 tol of error
            if res * lam_bound / (1 - lam_bound) < tol:
                break
            if extrap is not None and (not progressive or use_later):
                tail = extrap(d)
                if tail is not None:
                    Rk = Rk + tail
                    if progressive:
                        # the ambient term stands for all the remaining bounces: done
                        Hg_acc += h_inc * extrap.factor
                        break
    finally:
        if bar is not None:
            bar.close()
    seconds["gather"] = t_gather
    if limit > 0 and it == limit and (not residuals or residuals[-1] >= tol) and mb is None:
        warnings.warn(
            f"solve: not converged after {it} iterations (residual {residuals[-1]:.3g})",
            RuntimeWarning,
            stacklevel=2,
        )

    if progressive:
        Hg = Hg_acc
    B = E + Rk
    # --- diagnostics: lost fraction δ, energy balance (DESIGN-NOTES §5, §10)
    if vis is None:  # no gathering ran (or only a recording pass): one visibility pass
        t = time.perf_counter()
        _, vis, _ = gather(gds, np.zeros((n, 3), np.float32), all_fams, True, defer_vis=False)
        seconds["visibility"] = time.perf_counter() - t
    found = vis / vis_S
    front = ~a["back"]
    wa = area * front
    delta = float(1 - np.sum(wa * found) / np.sum(wa)) if np.sum(wa) > 0 else 0.0
    # Share of the front records' cos-weighted hemisphere that ends on black
    # back records (no albedo, no emission). In a closed scene no front
    # record should see one: this is light lost through occluders (a line
    # passing a closed object's near side), which lost_fraction does not see.
    dark = a["back"] & ~np.any(rho > 0, axis=1) & ~np.any(E > 0, axis=1)
    dark[twin_b] = False  # stand-ins for their front twins: not a loss
    back_fraction = back_fraction_max = 0.0
    if not diagnostics:
        stats["skipped"]["back_fraction"] = "diagnostics=False"
    elif np.any(dark) and np.sum(wa) > 0:
        t = time.perf_counter()
        ind = np.zeros((n, 3), np.float32)
        ind[dark] = 1.0
        gb, _, _ = gather(gds, ind, all_fams, False)
        seconds["back_fraction"] = time.perf_counter() - t
        share = gb[:, 0] / vis_S
        back_fraction = float(np.sum(wa * share) / np.sum(wa))
        back_fraction_max = float(np.max(np.where(front, share, 0.0)))
    else:
        stats["skipped"]["back_fraction"] = "no black back records"
    H_tot = Hd + Hg
    emitted = (E * area[:, None]).sum(axis=0)
    absorbed = ((1 - rho) * H_tot * area[:, None]).sum(axis=0)
    gather_escape = (Rk * (area * (1 - found))[:, None]).sum(axis=0)
    escaping = shoot_escape + gather_escape
    with np.errstate(divide="ignore", invalid="ignore"):
        imbalance = np.where(emitted > 0, (emitted - absorbed - escaping) / emitted, 0.0)

    seconds["total"] = time.perf_counter() - t_all
    stats.update(
        rays=int(shoot_rays + gather_rays),
        shoot_rays=int(shoot_rays),
        gather_rays=int(gather_rays),
        seconds=seconds,
        bounces=it,
        lines_walked=int(lines_walked),
        lost_fraction=delta,
        lost_fraction_max=float(np.max(np.where(front, 1 - found, 0.0))),
        back_fraction=back_fraction,
        back_fraction_max=back_fraction_max,
        energy={
            "emitted": emitted.tolist(),
            "absorbed": absorbed.tolist(),
            "escaping": escaping.tolist(),
            "escaping_shoot": shoot_escape.tolist(),
            "imbalance": imbalance.tolist(),
        },
        extrapolations=extrap.count if extrap is not None else 0,
        pair_cache=stats.get("pair_cache", {**gather.info, "replayed_passes": gather.replayed}),
        epsilon=eps,
        history=hist,
    )
    if it and lds is not None:
        stats["skipped"]["finer_directions_after"] = la
    if gather.replayed:
        stats["skipped"]["line_walks"] = (
            f"{gather.replayed} gathering passes replayed the recorded pairs")
    return Solution(
        vox=vox, radiosity=B.astype(np.float32), bounces=it, residuals=residuals, stats=stats
    )
