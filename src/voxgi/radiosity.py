"""Radiosity on voxels: discrete-line propagation (shooting, then gathering).

The discretised radiosity equation (``docs/design.md`` §1)

    B(x) = E(x) + ρ(x) Σ_σ B(I(x,σ)) (n_x·σ̂) ΔΩ(σ) / (π S(n_x))

is solved on the records of a :class:`~voxgi.VoxelSet`, ``I(x,σ)`` the first
record seen from ``x`` along the discrete line of direction σ (found for all
records at once in O(N) per direction family, :class:`voxgi._core.LineSystem`)
and ``S(n)`` the raw cos-weighted hemisphere sum of the direction set, so that
every record gathers exactly one hemisphere (``docs/design.md`` §3).

Bookkeeping (``docs/design.md`` §5): *shooting* gives every record its direct
irradiance ``H_d`` from the emitters with the finer radius (default 35);
*gathering* (default 22) then propagates only the reflected radiosity
``R = B − E``, so that ``B = E + ρ (H_d + H_gathered)`` and direct light is not
counted twice.

Ray counts (``Solution.stats``): a *gathering ray* is one record meeting one
direction family (both of its directions) in one iteration; a *shooting ray*
is one emitter record and one direction it faces.

Where the passes run is an *executor*'s choice (``docs/design.md`` §8): any
object with a ``line_system(records, *, progress)`` method returning an object
with the :class:`voxgi._core.LineSystem` methods ``size``, ``normalisation``,
``gather`` and ``shoot`` (:class:`LineExecutor`). The default runs them here;
:mod:`voxgi.distributed` runs them on a Dask cluster.
"""

from __future__ import annotations

import itertools
import json
import time
import warnings
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Protocol

import numpy as np

from . import _core, _validate
from .direct import direct_irradiance, light_irradiance
from .directions import DirectionSet, direction_set
from .io import atomic_path
from .traced import TracedGather
from .voxels import VoxelSet, available_memory

__all__ = [
    "LineExecutor",
    "LineRecords",
    "LocalExecutor",
    "Solution",
    "SolveTuning",
    "gather_partial",
    "line_records",
    "line_system",
    "pair_table_bytes",
    "solve",
    "solve_memory",
]


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
            elif f.name not in ("stats", "scene"):  # the scene stays with its files
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
        except (
            OSError,
            EOFError,
            ValueError,
            KeyError,
            TypeError,
            zlib.error,
            zipfile.BadZipFile,
        ) as exc:
            # (json and Unicode decoding errors are ValueErrors)
            raise ValueError(
                f"{path}: not a readable voxgi solution file ({type(exc).__name__}: {exc})"
            ) from None
        vox = sol.vox
        ijk = np.asarray(vox.ijk)
        if ijk.ndim != 2:
            raise ValueError(f"{path}: vox_ijk must have shape (N, 3), got {ijk.shape}")
        n = len(ijk)
        # Every per-record array has the record count and the type VoxelSet
        # documents: a short one would otherwise load and fail later in render.
        want = {
            "ijk": ((n, 3), np.int32),
            "normal": ((n, 3), np.float32),
            "area": ((n,), np.float32),
            "albedo": ((n, 3), np.float32),
            "emission": ((n, 3), np.float32),
            "centroid": ((n, 3), np.float64),
            "object_id": ((n,), np.int32),
            "back": ((n,), np.bool_),
            "side": ((n,), np.int8),
            "origin": ((3,), np.float64),
        }
        for name, (shape, dtype) in want.items():
            a = getattr(vox, name)
            if a is None and name == "side":
                continue
            a = np.asarray(a)
            if a.shape != shape or a.dtype != dtype:
                raise ValueError(
                    f"{path}: vox_{name} must be {np.dtype(dtype).name} of shape "
                    f"{shape} for {n} records, got {a.dtype} {a.shape}"
                )
            if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
                raise ValueError(f"{path}: vox_{name} has non-finite values")
        if n and ijk.min() < 0:
            raise ValueError(f"{path}: vox_ijk has negative voxel coordinates")
        if not (np.isfinite(vox.pitch) and vox.pitch > 0) or vox.resolution < 2:
            raise ValueError(f"{path}: bad grid (pitch {vox.pitch}, resolution {vox.resolution})")
        r = np.asarray(sol.radiosity)
        if r.shape != (n, 3) or r.dtype.kind != "f":
            raise ValueError(
                f"{path}: radiosity must be floats of shape ({n}, 3), got {r.dtype} {r.shape}"
            )
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


# ----------------------------------------------------------------------------- line systems


@dataclass(frozen=True, eq=False)
class LineRecords:
    """What a line system is built from; picklable, so an executor can ship it.

    Attributes
    ----------
    ijk : (N, 3) int32
        Voxel coordinates.
    normal : (N, 3) float32
        Unit normals.
    point : (N, 3) float32
        Surface points in voxel units (voxel ``ijk`` spans ``[ijk, ijk + 1]``).
    epsilon : float
        Facing-rule margin, in voxels (``docs/design.md`` §4).
    history : int
        F records a receiver passes over in its search along a line (1..32;
        a run of them in one plane counts once).
    """

    ijk: np.ndarray
    normal: np.ndarray
    point: np.ndarray
    epsilon: float = 0.02
    history: int = 16

    def __len__(self) -> int:
        return len(self.ijk)

    def build(self) -> _core.LineSystem:
        """The prepared :class:`voxgi._core.LineSystem` (orders, occupancy; O(N))."""
        return _core.LineSystem(
            self.ijk,
            self.normal,
            self.point,
            epsilon=float(self.epsilon),
            history=int(self.history),
        )


def line_records(vox: VoxelSet, *, epsilon: float = 0.02, history: int = 16) -> LineRecords:
    """The :class:`LineRecords` of a VoxelSet (validated, C-contiguous).

    >>> import voxgi
    >>> vox = voxgi.voxelize(voxgi.scenes.furnace_box(), resolution=8, progress=False)
    >>> len(line_records(vox)) == len(vox)
    True
    """
    a = _check_vox(vox)
    eps = _validate.real(epsilon, "epsilon", low=0.0)
    hist = _validate.integer(history, "history", low=1, high=32)
    return LineRecords(a["ijk"], a["normal"], a["point"], eps, hist)


def line_system(vox: VoxelSet, *, epsilon: float = 0.02, history: int = 16) -> _core.LineSystem:
    """The prepared line system of a VoxelSet (orders, occupancy; O(N) once).

    Parameters
    ----------
    vox : VoxelSet
        Records.
    epsilon : float
        Facing-rule margin, in voxels (``docs/design.md`` §4).
    history : int
        F records a receiver passes over in its search along a line (1..32;
        a run of them in one plane counts once).
    """
    return line_records(vox, epsilon=epsilon, history=history).build()


class LineExecutor(Protocol):
    """Where a solve's passes run (``docs/design.md`` §8).

    ``line_system(records, progress=...)`` returns an object with the
    :class:`voxgi._core.LineSystem` interface that :func:`solve` uses:
    ``size``, ``normalisation``, ``gather`` and ``shoot`` (and, to record
    and replay the pairs of a direction set, ``make_pair_table`` and
    ``gather_recorded``). Results must be the local ones to float rounding.
    """

    def line_system(self, records: LineRecords, *, progress: bool = False): ...


class LocalExecutor:
    """The default executor: every pass in this process, on ``threads`` threads.

    >>> LocalExecutor().line_system  # doctest: +ELLIPSIS
    <bound method LocalExecutor.line_system of <...LocalExecutor object at ...>>
    """

    def line_system(self, records: LineRecords, *, progress: bool = False) -> _core.LineSystem:
        """Build the line system here (``progress`` has no bar to drive)."""
        return records.build()


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

    Partial sums over disjoint subsets of families add up to the full pass.

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


# ----------------------------------------------------------------------------- settings


@dataclass(frozen=True)
class SolveTuning:
    """Expert settings of :func:`solve`, for studies and benchmarks.

    Attributes
    ----------
    shoot_directions : int
        Radius of the shooting direction sphere (35: 15194 directions).
    later_directions : int or None
        Radius for the bounces after the first ``later_after`` ones (later
        bounces are smooth; Piwowar & Malgouyres 2009). The solver then
        propagates each bounce's increment and ends with the geometric-tail
        term once the ratio of successive bounces is steady. None: every
        bounce with ``directions``.
    later_after : int
        Bounces gathered with ``directions`` before ``later_directions``.
    epsilon : float
        Facing-rule margin in voxels (``docs/design.md`` §4).
    history : int
        F records a receiver passes over in its search along a line (1..32;
        a run of them in one plane counts once).
    max_iterations : int
        Bound on the iterations when ``max_bounces`` is None.
    closed : bool, sequence of int or None
        Objects (ids into ``vox.object_id``; True: all; False: none) whose
        meshes are closed: their back records send their front twin's
        radiosity instead of black (``docs/design.md`` §5). None: the objects
        :func:`voxgi.voxelize` found watertight (``vox.stats["closed_objects"]``).
    diagnostics : bool
        Run the extra gathering pass behind ``stats["back_fraction"]``.
    pair_cache : bool or None
        Record the pairs of the first gathering pass over a direction set and
        replay them in later passes over it (3 bytes per record and family;
        :func:`pair_table_bytes`). None: when they fit in ``max_cache_bytes``;
        True: the same with no default budget; False: walk every pass.
    max_cache_bytes : int or None
        Budget for the recorded pairs; None: a quarter of the memory available
        when the solve starts (``pair_cache=None``), no limit (True).
    direct_light : {"shoot", "exact"}
        How the records get their direct light (``docs/design.md`` §5):
        ``"shoot"`` marches discrete rays from every emitter record (the
        paper's method; cost emitter records x directions x path length;
        where it would give the same answer for more, one gathering pass
        over the emitters stands in, and ``stats["skipped"]`` says so);
        ``"exact"`` traces shadow rays from every record to points on the
        emitting triangles (:func:`voxgi.direct.direct_irradiance`; cost
        records x samples; needs ``vox.scene``, else the solve shoots and
        ``stats["skipped"]`` says why).
    direct_samples : int
        Emitter points per record for ``direct_light="exact"`` (records whose
        estimate stays noisy get more).
    indirect_light : {"lines", "traced"}
        How the reflected light travels between records (``docs/design.md``
        §5): ``"lines"`` along the discrete lines only (the paper's method);
        ``"traced"`` then, once the lines have converged, in passes of rays
        against the exact triangles (:mod:`voxgi.traced`) until their update
        is under ``tol``, so that gaps and occluders thinner than a voxel and
        thin walls meeting other surfaces act as they are. Needs
        ``vox.scene`` and ``max_bounces=None``; otherwise ``stats["skipped"]``
        says why the lines alone carried it.
    traced_samples : int
        Rays per record in the first traced pass (1 to 4096; a square number
        is stratified in both angles); the later passes, which carry only
        the previous pass's change, take a quarter (at least 16).

    >>> SolveTuning(shoot_directions=8).later_after
    2
    """

    shoot_directions: int = 35
    later_directions: int | None = None
    later_after: int = 2
    epsilon: float = 0.02
    history: int = 16
    max_iterations: int = 10000
    closed: bool | Sequence[int] | None = None
    diagnostics: bool = True
    pair_cache: bool | None = None
    max_cache_bytes: int | None = None
    direct_light: str = "shoot"
    direct_samples: int = 64
    indirect_light: str = "lines"
    traced_samples: int = 64


@dataclass(frozen=True)
class _Settings:
    """The validated arguments of one solve."""

    R: int
    Rs: int
    Rl: int | None
    later_after: int
    max_bounces: int | None
    max_iterations: int
    tol: float
    threads: int
    epsilon: float
    history: int
    closed: object
    diagnostics: bool
    pair_cache: bool | None
    cache_cap: int | None
    direct_light: str = "shoot"
    direct_samples: int = 64
    indirect_light: str = "lines"
    traced_samples: int = 64


def _settings(directions, max_bounces, tol, threads, tuning) -> _Settings:
    """Check the arguments and the tuning; raise TypeError/ValueError naming the bad one."""
    t = SolveTuning() if tuning is None else tuning
    if not isinstance(t, SolveTuning):
        raise TypeError(f"tuning: expected voxgi.SolveTuning or None, got {type(t).__name__}")
    if t.pair_cache is not None and not isinstance(t.pair_cache, (bool, np.bool_)):
        raise TypeError(f"pair_cache: expected True, False or None, got {t.pair_cache!r}")
    if t.direct_light not in ("shoot", "exact"):
        raise ValueError(f"direct_light: expected 'shoot' or 'exact', got {t.direct_light!r}")
    if t.indirect_light not in ("lines", "traced"):
        raise ValueError(f"indirect_light: expected 'lines' or 'traced', got {t.indirect_light!r}")
    return _Settings(
        R=_validate.integer(directions, "directions", low=1, high=256),
        Rs=_validate.integer(t.shoot_directions, "shoot_directions", low=1, high=256),
        Rl=_validate.integer(
            t.later_directions, "later_directions", low=1, high=256, allow_none=True
        ),
        later_after=_validate.integer(t.later_after, "later_after", low=1),
        max_bounces=_validate.integer(max_bounces, "max_bounces", low=0, allow_none=True),
        max_iterations=_validate.integer(t.max_iterations, "max_iterations", low=1),
        tol=_validate.real(tol, "tol", low=0.0, low_open=True),
        threads=_validate.threads(threads),
        epsilon=_validate.real(t.epsilon, "epsilon", low=0.0),
        history=_validate.integer(t.history, "history", low=1, high=32),
        closed=t.closed,
        diagnostics=bool(t.diagnostics),
        pair_cache=t.pair_cache,
        cache_cap=_validate.integer(t.max_cache_bytes, "max_cache_bytes", low=0, allow_none=True),
        direct_light=t.direct_light,
        direct_samples=_validate.integer(t.direct_samples, "direct_samples", low=1, high=1 << 16),
        indirect_light=t.indirect_light,
        traced_samples=_validate.integer(t.traced_samples, "traced_samples", low=1, high=4096),
    )


def _check_executor(executor, vox: VoxelSet, opt: _Settings, tuning) -> LineExecutor:
    """The executor given, or the local one for None (whose memory estimate
    is checked here, before anything is allocated)."""
    if executor is None:
        executor = LocalExecutor()
    if isinstance(executor, LocalExecutor):
        _check_memory(vox, opt, tuning)
        return executor
    if not callable(getattr(executor, "line_system", None)):
        raise TypeError(
            f"executor: expected an object with a line_system(records, progress=...) method "
            f"(voxgi.radiosity.LineExecutor) or None, got {type(executor).__name__}; "
            "voxgi.solve also takes a dask.distributed.Client as client="
        )
    return executor


# ----------------------------------------------------------------------------- memory

#: Bytes per record held once by a local solve: the line system's three axis
#: orders (213), the records' arrays as the kernels take them (73) and the
#: solver's float64 (N, 3) arrays (E, ρ, H_d, H_g, R, the update and its
#: temporaries: 14 of 24 bytes).
_RECORD_BYTES = 213 + 73 + 14 * 24
#: Bytes per record and thread of a pass: the gathering walk's 64-byte
#: records, queued B records (12), line links (4), float64 sums of the axes
#: left (24) and the shooting's float64 sums (24).
_THREAD_RECORD_BYTES = 64 + 12 + 4 + 24 + 24
#: Bytes per line key and thread: the walk's line table (stamp, last F).
_LINE_KEY_BYTES = 8


def _max_line_keys(families: np.ndarray, extent: np.ndarray) -> int:
    """The most lines (``nu · nw`` keys) of one family over the records' box
    (the line frame of ``docs/design.md`` §4, as the kernels compute it)."""
    v = np.abs(np.asarray(families, dtype=np.int64))
    if len(v) == 0:
        return 0
    i = np.arange(len(v))
    m = np.argmax(v, axis=1)
    o1 = np.where(m == 0, 1, 0)
    o2 = np.where(m == 2, 1, 2)
    A, B, C = v[i, m], v[i, o1], v[i, o2]
    ext = np.asarray(extent, dtype=np.int64)
    xma = -(-ext[m] // A) * A
    nu = (A * ext[o1] + B * xma + A // 2) // A + 1
    nw = (A * ext[o2] + C * xma + A // 2) // A + 1
    return int(np.max(nu * nw))


def _shoots(vox: VoxelSet, opt: _Settings) -> bool:
    """Whether a solve of ``vox`` with ``opt`` shoots its direct light (see
    :attr:`_Problem.shoots`)."""
    scene = getattr(vox, "scene", None)
    if scene is not None and scene.has_lights:
        return False
    return opt.direct_light == "shoot" or scene is None


def solve_memory(
    vox: VoxelSet,
    directions: int = 22,
    threads: int | None = None,
    *,
    tuning: SolveTuning | None = None,
) -> dict:
    """Bytes a local :func:`solve` of ``vox`` needs, by part, before it allocates.

    Parameters
    ----------
    vox : VoxelSet
    directions, threads, tuning
        As for :func:`solve`.

    Returns
    -------
    dict
        ``records`` (line system, arrays, solver state), ``threads`` (each
        thread's walk records, line tables and sums), ``directions`` (the
        direction sets and their ``S(n)``), ``pair_cache`` (the recorded
        pairs the solve would keep, within their budget) and ``total``.

    >>> import voxgi
    >>> vox = voxgi.voxelize(voxgi.scenes.furnace_box(), resolution=8, progress=False)
    >>> est = solve_memory(vox, directions=4, threads=1)
    >>> est["total"] == sum(v for k, v in est.items() if k != "total")
    True
    """
    opt = _settings(directions, None, 1.0, threads, tuning)
    ijk = _validate.as_c_array(vox.ijk, np.int32, (-1, 3), "vox.ijk")
    n = len(ijk)
    extent = ijk.max(axis=0).astype(np.int64) - ijk.min(axis=0) if n else np.zeros(3, np.int64)
    # the shooting's set only where the direct light is shot (building one of
    # radius 35 takes a quarter of a second)
    radii = {opt.R} | ({opt.Rs} if _shoots(vox, opt) else set())
    radii |= {opt.Rl} if opt.Rl is not None else set()
    sets = [direction_set(r) for r in sorted(radii)]
    keys = max(_max_line_keys(ds.families, extent) for ds in sets)
    per_thread = n * _THREAD_RECORD_BYTES + keys * _LINE_KEY_BYTES
    cells = int(np.prod(extent + 1))
    pairs = 0
    if opt.pair_cache is not False and n <= _core.PairTable.MAX_RECORDS:
        want = sum(pair_table_bytes(n, direction_set(r).families) for r in {opt.R, opt.Rl} - {None})
        cap = opt.cache_cap
        if cap is None and opt.pair_cache is None:
            cap = available_memory() // 4
        pairs = want if cap is None else min(want, cap)
        # recording: each thread fills one tile of 16 columns of 4 bytes
        per_thread += 16 * 4 * n
    out = {
        "records": n * _RECORD_BYTES + cells // 8,
        "threads": opt.threads * per_thread,
        "directions": sum(ds.families.nbytes * 4 + 8 * n for ds in sets),
        "pair_cache": int(pairs),
    }
    out["total"] = int(sum(out.values()))
    return out


def _check_memory(vox: VoxelSet, opt: _Settings, tuning) -> dict:
    """Refuse a local solve whose estimate exceeds the memory available now."""
    est = solve_memory(vox, opt.R, opt.threads, tuning=tuning)
    avail = available_memory()
    if est["total"] > avail:
        parts = ", ".join(f"{k} {v / 2**30:.2f} GiB" for k, v in est.items() if k != "total")
        raise MemoryError(
            f"solve: {len(vox):,} records at directions={opt.R} on {opt.threads} threads need "
            f"about {est['total'] / 2**30:.2f} GiB ({parts}), over the "
            f"{avail / 2**30:.2f} GiB available; use fewer threads or directions, a coarser "
            "resolution, or SolveTuning(pair_cache=False)"
        )
    return est


# ----------------------------------------------------------------------------- solve


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
        b = b[b > 0]
        f_ = b - 1
        ok = (
            ~a["back"][f_]
            & np.all(a["ijk"][f_] == a["ijk"][b], axis=1)
            & (obj[f_] == obj[b])
            & (np.einsum("ij,ij->i", a["normal"][f_], a["normal"][b]) < -0.99)
        )
        twin_b, twin_f = b[ok], f_[ok]
    stand_in = None
    if len(twin_b):
        stand_in = np.zeros(n, np.bool_)
        stand_in[twin_b] = True
    return _Twins(twin_b, twin_f, stand_in)


class _Extrapolator:
    """Geometric-tail extrapolation of a linear fixed-point iteration.

    Once successive updates ``d_k = R_{k+1} − R_k`` shrink by a steady ratio
    λ (per channel, from ``<d_k, d_{k-1}> / <d_{k-1}, d_{k-1}>``), the rest of
    the series is ``d_k λ / (1 − λ)`` (the ambient term of progressive
    radiosity; Aitken's Δ²), added at once (``docs/design.md`` §5).
    """

    def __init__(self, weights: np.ndarray, rel_tol: float = 0.02):
        self.w = weights[:, None]
        self.prev = None
        self.lam_prev = None
        self.rel_tol = rel_tol
        self.count = 0
        self.factor = None

    def __call__(self, d: np.ndarray) -> np.ndarray | None:
        """Given the latest update d (N, 3), return the tail to add, or None."""
        prev, self.prev = self.prev, d
        if prev is None:
            return None
        den = np.sum(self.w * prev * prev, axis=0)
        num = np.sum(self.w * d * prev, axis=0)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
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
        with np.errstate(over="ignore", invalid="ignore"):
            factor = np.where(active, lam / (1 - lam), 0.0)
            tail = d * factor
        if not np.all(np.isfinite(tail)):
            return None  # a ratio too close to 1 for the float range: no jump
        self.count += 1
        self.factor = factor
        return tail


def pair_table_bytes(n: int, families: np.ndarray) -> int:
    """Bytes of the recorded pairs of ``n`` records over ``families``: 3 per
    record and family, each main axis's families padded to tiles of 16.

    >>> from voxgi.directions import direction_set
    >>> pair_table_bytes(1000, direction_set(4).families)
    384000
    """
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

    def _why_not(self, ds, need: int) -> str | None:
        """Why the pairs of ``ds`` are not recorded (None: they are)."""
        if self.sysm.size > _core.PairTable.MAX_RECORDS:
            return f"more than {_core.PairTable.MAX_RECORDS} records"
        if self.passes.get(id(ds), 0) < 2:
            return "one pass only"
        if self.used + need > self.budget:
            return f"needs {need / 2**30:.2f} GiB, budget {self.budget / 2**30:.2f} GiB"
        return None

    def _table(self, ds):
        key = id(ds)
        if key in self.tables:
            return self.tables[key]
        tab = None
        need = pair_table_bytes(self.sysm.size, ds.families)
        entry = {"radius": int(ds.radius), "bytes": need}
        why = None if self.budget is None else self._why_not(ds, need)
        if self.budget is None:
            entry["recorded"] = False
        elif why is not None:
            entry["recorded"] = False
            entry["reason"] = why
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
        next pass, which replays and sums it at no cost."""
        tab = self._table(ds)
        if tab is not None and np.all(tab.recorded_mask[sel]):
            sums, vis = self.sysm.gather_recorded(tab, values, sel, want_vis, self.nthreads)
            self.replayed += 1
            return sums, vis, 0
        if tab is not None and defer_vis:
            want_vis = False
        return self.sysm.gather(
            ds.families,
            ds.weights,
            values,
            sel,
            want_vis,
            self.nthreads,
            stand_in=self.stand_in,
            **({"record": tab} if tab is not None else {}),
        )


@dataclass
class _Problem:
    """One solve's records, settings, line system and direction sets."""

    vox: VoxelSet
    a: dict
    opt: _Settings
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

    @property
    def n(self) -> int:
        return len(self.area)

    @property
    def lights(self) -> bool:
        """The records' scene has point, spot or directional lights or an environment."""
        scene = getattr(self.vox, "scene", None)
        return scene is not None and scene.has_lights

    @property
    def shoots(self) -> bool:
        """Direct light by shooting: asked for, or exact light asked for but
        the records carry no scene to trace. This is the one place that
        decides: lights other than emitting triangles have no records to
        shoot from, so a scene with any is always lit exactly
        (``docs/design.md`` §11)."""
        return _shoots(self.vox, self.opt)

    @property
    def limit(self) -> int:
        """Iterations allowed: ``max_bounces``, else ``max_iterations``; 0 if all albedos are 0."""
        if not np.any(self.rho > 0):
            return 0
        mb = self.opt.max_bounces
        return self.opt.max_iterations if mb is None else mb


def _problem(vox, a, opt) -> _Problem:
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
    return _Problem(
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


def _no_emitter(p: _Problem) -> Solution:
    """The zero solution of a scene without emitters, with a warning."""
    warnings.warn(
        "solve: the scene has no emitter; the solution is zero", RuntimeWarning, stacklevel=3
    )
    p.stats.update(
        rays=0, shoot_rays=0, gather_rays=0, seconds={"total": 0.0}, skipped={"all": "no emitter"}
    )
    return Solution(vox=p.vox, radiosity=np.zeros((p.n, 3), np.float32), stats=p.stats)


def _open_backend(p: _Problem, executor, progress: bool) -> None:
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


def _normalise(p: _Problem) -> None:
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


def _silhouettes(p: _Problem, emitters_send: np.ndarray) -> dict:
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


def _direct_light(p: _Problem):
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
    why = _gathering_is_cheaper(p)
    if why is not None:
        p.stats["skipped"]["shooting"] = why
        return _gathered_direct_light(p)
    return _shot_direct_light(p)


def _gathering_is_cheaper(p: _Problem) -> str | None:
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
    if len(es) * path <= p.n or _flat_emitter_coverage(p.a, p.vox, es)[1]:
        return None
    return (
        f"{len(es)} emitter records x ~{path:.0f} voxels of path outweigh {p.n} records: "
        "the same light gathered in one pass over the shooting's direction set"
    )


def _gathered_direct_light(p: _Problem):
    """The shot direct light by one gathering pass of the emitters'
    radiosity (``_gathering_is_cheaper``); what the records do not receive of
    the emitted power escapes."""
    p.stats["direct_light"] = {"method": "gather"}
    t = time.perf_counter()
    # the shooting's direction set is the gathering's: its pass may record
    # the pairs that the bounces then replay
    fams = np.arange(len(p.gds.families), dtype=np.int64)
    sums, _, _ = _gatherer(p)(p.gds, p.twins.send(p.E), fams, False, defer_vis=False)
    Hd = sums / p.S["gather"][:, None]
    p.seconds["direct"] = time.perf_counter() - t
    escape = (p.E * p.area[:, None]).sum(axis=0) - (Hd * p.area[:, None]).sum(axis=0)
    return Hd, escape, p.n * len(fams)


def _exact_direct_light(p: _Problem):
    """Direct irradiance by shadow rays (``docs/design.md`` §5); what the
    records do not receive of the emitted power escapes. The black records
    (albedo 0) reflect nothing, so they are lit only for the energy balance
    of a solve with diagnostics."""
    t = time.perf_counter()
    receivers = "all" if p.opt.diagnostics else "reflecting"
    kw = dict(samples=p.opt.direct_samples, threads=p.opt.threads, receivers=receivers)
    Hd, st = direct_irradiance(p.vox.scene, p.vox, **kw)
    p.stats["direct_light"] = {"method": "exact", "receivers": receivers, **st}
    # what the records receive of the emitting triangles' power (the rest escapes)
    received = (Hd * p.area[:, None]).sum(axis=0)
    if p.lights:
        # the lights' power is what the records receive: it counts as emitted
        # in the energy balance, and none of it escapes on the way
        H_lights, st_l = light_irradiance(p.vox.scene, p.vox, **kw)
        Hd = Hd + H_lights
        p.light_power = (H_lights * p.area[:, None]).sum(axis=0)
        p.stats["direct_light"]["lights"] = st_l
        p.stats["direct_light"]["rays"] += st_l["rays"]
    p.seconds["direct"] = time.perf_counter() - t
    if receivers == "reflecting":
        p.stats["skipped"]["direct_light_on_black_records"] = (
            "diagnostics=False: what they absorb counts as escaping in stats['energy']"
        )
    escape = (p.E * p.area[:, None]).sum(axis=0) - received
    return Hd, escape, 0


def _shot_direct_light(p: _Problem):
    """Shooting: direct irradiance H_d from the emitters, the power that
    escapes on the way (sender side) and the shooting rays."""
    p.stats["direct_light"] = {"method": "shoot"}
    t = time.perf_counter()
    E_send = p.twins.send(p.E)
    es = np.flatnonzero(np.any(E_send > 0, axis=1)).astype(np.int32)
    cov, flat = _flat_emitter_coverage(p.a, p.vox, es)
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


def _gatherer(p: _Problem) -> _Gatherer:
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
    if p.lds is not None:  # (the same object as gds when later_directions == directions)
        passes[id(p.lds)] = passes.get(id(p.lds), 0) + max(0, limit - la)
    return _Gatherer(p.sysm, opt.threads, p.twins.stand_in, budget, passes)


#: The float32 values sent along the lines round every record's radiosity
#: to about 6e-8: a residual under this that makes no new low for
#: :data:`_FLOOR_ITERATIONS` iterations is their rounding, not the iteration's.
_FLOOR_RESIDUAL = 1e-6
_FLOOR_ITERATIONS = 10
#: Iterations without a new lowest residual after which the iteration has
#: stalled for good.
_STALL_ITERATIONS = 50
#: At most this many traced passes; each shrinks the change by about the
#: albedo, so 32 leave 0.8^32 ≈ 8e-4 of it at ρ = 0.8 before the tail.
_TRACED_PASSES = 32


@dataclass
class _State:
    """The iterate and what the iteration has gathered so far."""

    R: np.ndarray  # reflected radiosity B - E
    Hg: np.ndarray  # gathered irradiance
    dk: np.ndarray  # the last update R_k - R_{k-1}
    vis: np.ndarray | None = None
    it: int = 0
    gather_rays: int = 0
    lines_walked: int = 0
    seconds: float = 0.0
    residuals: list = field(default_factory=list)
    stopped: str | None = None


class _Iteration:
    """Gathering of the reflected radiosity ``R = B − E`` (``docs/design.md`` §5).

    Jacobi, ``R_{k+1} = ρ (H_d + M R_k / S)``, with the geometric tail added
    once the updates shrink steadily (:class:`_Extrapolator`). The same
    iteration in correction form, ``ΔR_{k+1} = ρ M ΔR_k / S``, propagates
    only the last update, which float32 rounds relative to its own size: it
    is used with coarser later bounces (a fixed-point iteration would
    converge to the coarse operator's answer) and once the Jacobi residual
    sits at the rounding of the values sent (albedos near 1). In correction
    form the tail, once added, stands for every bounce left.
    """

    def __init__(self, p: _Problem, gather: _Gatherer, Hd: np.ndarray):
        self.p, self.gather, self.Hd = p, gather, Hd
        R = p.rho * Hd
        self.s = _State(R=R, Hg=np.zeros((p.n, 3)), dk=R.copy())
        self.corrections = p.lds is not None
        self.extrap = _Extrapolator(p.area)
        rmax = float(p.rho.max())
        self.lam_bound = float(min(max(rmax, 0.5), 1 - 1e-6))
        self.best = (float("inf"), 0)  # lowest residual and its iteration

    def step(self) -> tuple:
        """One gathering pass: (R_new, Hg_new, update, residual, h_inc, use_later), not kept."""
        p, s = self.p, self.s
        use_later = p.lds is not None and s.it >= p.opt.later_after
        ds = p.lds if use_later else p.gds
        S = p.S["later"] if use_later else p.S["gather"]
        fams = np.arange(len(ds.families), dtype=np.int64)
        t = time.perf_counter()
        want_vis = s.vis is None and not use_later
        sums, v, nl = self.gather(
            ds, p.twins.send(s.dk if self.corrections else s.R), fams, want_vis
        )
        s.lines_walked += nl
        if want_vis:
            s.vis = v
        with np.errstate(over="ignore", invalid="ignore"):  # run() checks finiteness
            if self.corrections:
                h_inc = sums / S[:, None]
                Hg = s.Hg + h_inc
                R_new = s.R + p.rho * h_inc
            else:
                h_inc = None
                Hg = sums / S[:, None]
                R_new = p.rho * (self.Hd + Hg)
            s.seconds += time.perf_counter() - t
            s.gather_rays += p.n * len(ds.families)
            d = R_new - s.R
            Btot = np.sum(p.area[:, None] * np.abs(p.E + R_new))
            res = float(np.sum(p.area[:, None] * np.abs(d)) / Btot) if Btot > 0 else 0.0
        return R_new, Hg, d, res, h_inc, use_later

    def run(self, bar) -> _State:
        """Iterate until the stopping rule, the iteration limit, a stall or a
        non-finite iterate; return the last finite state."""
        s = self.s
        while s.it < self.p.limit:
            R_new, Hg, d, res, h_inc, use_later = self.step()
            if not (np.all(np.isfinite(R_new)) and np.isfinite(res)):
                s.stopped = f"iteration {s.it + 1} was not finite"
                break
            s.R, s.Hg, s.dk = R_new, Hg, (self.p.rho * h_inc if self.corrections else d)
            s.it += 1
            s.residuals.append(res)
            if bar is not None:
                bar.update(1)
                bar.set_postfix(residual=f"{res:.2e}")
            if self.converged(res):
                break
            if self.at_floor(res):
                continue
            if self.stalled(res) or self.jump(d, h_inc, use_later):
                break
        return s

    def converged(self, res: float) -> bool:
        """The estimated remaining error of the geometric tail, ``res λ / (1 − λ)``
        with λ bounded by the largest albedo, is under ``tol``."""
        return res * self.lam_bound / (1 - self.lam_bound) < self.p.opt.tol

    def at_floor(self, res: float) -> bool:
        """Switch Jacobi to the correction form when its residual sits at the
        rounding of the values sent (True: switched, no jump this iteration)."""
        if res < self.best[0]:
            self.best = (res, self.s.it)
            return False
        if (
            self.corrections
            or self.best[0] >= _FLOOR_RESIDUAL
            or self.s.it - self.best[1] < _FLOOR_ITERATIONS
        ):
            return False
        self.corrections = True
        self.best = (float("inf"), self.s.it)
        self.extrap.prev = self.extrap.lam_prev = None
        self.p.stats["correction_form_after"] = self.s.it
        return True

    def stalled(self, res: float) -> bool:
        """No new lowest residual for :data:`_STALL_ITERATIONS` iterations."""
        if self.s.it - self.best[1] >= _STALL_ITERATIONS:
            self.s.stopped = (
                f"the residual stalled at {self.best[0]:.3g} (its lowest, "
                f"iteration {self.best[1]}) for {_STALL_ITERATIONS} iterations"
            )
            return True
        return False

    def jump(self, d: np.ndarray, h_inc: np.ndarray | None, use_later: bool) -> bool:
        """Add the geometric tail when the updates shrink steadily; True when
        that ends the correction form (the tail stands for every bounce left)."""
        if self.p.lds is not None and not use_later:
            return False
        tail = self.extrap(d)
        if tail is None:
            return False
        R = self.s.R + tail
        if not np.all(np.isfinite(R)):
            return False
        self.s.R = R
        if self.corrections:
            self.s.Hg = self.s.Hg + h_inc * self.extrap.factor
            return True
        return False


def _iterate(p: _Problem, gather: _Gatherer, Hd: np.ndarray, progress: bool) -> _State:
    """Run :class:`_Iteration` with its progress bar; warn where it stopped short."""
    limit = p.limit
    if limit == 0 and not np.any(p.rho > 0):
        p.stats["skipped"]["gathering"] = "all albedos are zero"
    bar = None
    if progress and limit > 0:
        from tqdm.auto import tqdm

        bar = tqdm(total=p.opt.max_bounces, desc="gather", unit="it", leave=False)
    it = _Iteration(p, gather, Hd)
    try:
        s = it.run(bar)
    finally:
        if bar is not None:
            bar.close()
    p.seconds["gather"] = s.seconds
    p.stats["extrapolations"] = it.extrap.count
    if s.stopped is not None:
        p.stats["stopped"] = s.stopped
        warnings.warn(
            f"solve: {s.stopped}; returning the last finite iterate (iteration {s.it})",
            RuntimeWarning,
            stacklevel=3,
        )
    elif (
        limit > 0
        and s.it == limit
        and (not s.residuals or s.residuals[-1] >= p.opt.tol)
        and p.opt.max_bounces is None
    ):
        warnings.warn(
            f"solve: not converged after {s.it} iterations (residual {s.residuals[-1]:.3g})",
            RuntimeWarning,
            stacklevel=3,
        )
    return s


def _lost_fraction(p: _Problem, gather: _Gatherer, vis) -> tuple:
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


def _back_fraction(p: _Problem, gather: _Gatherer) -> None:
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


def _energy(p: _Problem, Hd, s: _State, found, shoot_escape) -> dict:
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


def _traced_bounces(p: _Problem, Hd: np.ndarray, R: np.ndarray) -> np.ndarray:
    """The reflected radiosity after passes of rays against the exact
    triangles, started from the lines' answer ``R`` (``docs/design.md`` §5).

    The first pass gathers all of ``R``: ``R_1 = ρ (H_d + T R)``. Each later
    pass carries only the last change, ``d_{k+1} = ρ T d_k``, so its noise
    shrinks with the change; once, after two passes at least, the remaining
    error of the geometric series, ``r λ / (1 − λ)`` as for the lines, is
    under ``tol``, its tail ``d λ / (1 − λ)`` is added.
    """
    opt = p.opt
    if opt.indirect_light != "traced":
        return R
    why = None
    if getattr(p.vox, "scene", None) is None:
        why = "the records carry no scene (vox.scene is None)"
    elif opt.max_bounces is not None:
        why = f"max_bounces={opt.max_bounces} fixes the bounces the lines gather"
    elif p.limit == 0:
        why = "all albedos are zero"
    if why is not None:
        p.stats["skipped"]["traced_bounces"] = why + ": the lines alone carried the reflected light"
        return R
    t = time.perf_counter()
    area = p.area[:, None]
    lines_power = (R * area).sum(axis=0)
    R_lines = R
    later = max(16, opt.traced_samples // 4)
    lam_bound = float(min(max(float(p.rho.max()), 0.5), 1 - 1e-6))
    residuals = []
    with TracedGather(p.vox.scene, p.vox, threads=opt.threads) as trace:
        R_new = p.rho * (Hd + trace(R, opt.traced_samples, seed=1))
        d = R_new - R
        R = R_new
        Btot = float(np.sum(area * np.abs(p.E + R)))
        lam = lam_bound
        while Btot > 0:
            residuals.append(float(np.sum(area * np.abs(d))) / Btot)
            if len(residuals) >= 2 and min(residuals[-3:-1]) > 0:
                # the larger of the last two ratios: the first pass's noise
                # shrinks faster than the light still on its way
                last = residuals[-3:]
                lam = min(max(b / a for a, b in itertools.pairwise(last)), lam_bound)
            # At least two passes: the first one's change is mostly local (a
            # slit, a junction) and small against the whole, so the rule
            # waits for the ratio it implies to be measured.
            done = len(residuals) >= 2 and residuals[-1] * lam / (1 - lam) < opt.tol
            if done or len(residuals) >= _TRACED_PASSES:
                break
            d = p.rho * trace(d, later, seed=len(residuals) + 1)
            R = R + d
        if len(residuals) >= 2:
            R = R + d * (lam / (1 - lam))
        rays = trace.rays
    if not np.all(np.isfinite(R)):
        warnings.warn(
            "solve: the traced bounces gave a non-finite radiosity; returning the lines' answer",
            RuntimeWarning,
            stacklevel=3,
        )
        p.stats["skipped"]["traced_bounces"] = "their answer was not finite"
        return R_lines
    # The changes carry the first pass's noise with either sign; where they
    # outweigh a dim record's light the sum dips below zero.
    negative = np.any(R < 0, axis=1)
    clamped = (np.minimum(R, 0.0) * area).sum(axis=0)
    R = np.maximum(R, 0.0)
    p.seconds["traced"] = time.perf_counter() - t
    with np.errstate(divide="ignore", invalid="ignore"):
        change = np.where(lines_power > 0, (R * area).sum(axis=0) / lines_power - 1, 0.0)
    p.stats["traced"] = {
        "passes": len(residuals),
        "rays": int(rays),
        "samples": [opt.traced_samples, later],
        "residuals": residuals,
        "ratio": lam,
        "reflected_power_change": change.tolist(),
        # records whose sum came out below zero, set to zero, and the power
        # that adds (0.01-0.06% of the reflected power in the built-in interiors)
        "negative_records": int(np.count_nonzero(negative)),
        "negative_power": (-clamped).tolist(),
    }
    return R


def _statistics(p: _Problem, gather: _Gatherer, s: _State, shoot_rays: int) -> None:
    """Ray counts, phases, pair cache and what was skipped, into ``p.stats``."""
    p.stats.update(
        rays=int(shoot_rays + s.gather_rays),
        shoot_rays=int(shoot_rays),
        gather_rays=int(s.gather_rays),
        seconds=p.seconds,
        bounces=s.it,
        lines_walked=int(s.lines_walked),
        pair_cache=p.stats.get("pair_cache", {**gather.info, "replayed_passes": gather.replayed}),
        epsilon=p.opt.epsilon,
        history=p.opt.history,
    )
    if s.it and p.lds is not None:
        p.stats["skipped"]["finer_directions_after"] = p.opt.later_after
    if gather.replayed:
        p.stats["skipped"]["line_walks"] = (
            f"{gather.replayed} gathering passes replayed the recorded pairs"
        )


def solve(
    vox: VoxelSet,
    directions: int = 22,
    max_bounces: int | None = None,
    tol: float = 1e-4,
    threads: int | None = None,
    executor: LineExecutor | None = None,
    *,
    progress: bool = True,
    tuning: SolveTuning | None = None,
) -> Solution:
    """Solve the discrete radiosity equation on the records of ``vox``.

    Shooting from the emitter records first (direct light, radius
    ``tuning.shoot_directions``), then Jacobi gathering of the reflected
    light (radius ``directions``) with geometric-tail extrapolation, until
    the estimated remaining error falls under ``tol`` (``docs/design.md`` §5).

    Parameters
    ----------
    vox : VoxelSet
        Records from :func:`voxgi.voxelize`; left unchanged.
    directions : int
        Radius R >= 1 of the gathering direction sphere (22: 5982 directions).
    max_bounces : int or None
        At most this many gathering iterations (None: until converged; 0: direct light).
    tol : float
        Bound on the estimated remaining relative error ``r λ / (1 − λ)``, ``r``
        the area-weighted residual (``residuals``), ``λ`` the largest albedo.
    threads : int or None
        Threads (None: all hardware threads). Results do not depend on it.
    executor : LineExecutor or None
        Where the passes run (None: here; ``voxgi.solve`` also takes a Client).
    progress : bool
        Show a tqdm progress bar over iterations.
    tuning : SolveTuning or None
        Expert settings (:class:`SolveTuning`).

    Returns
    -------
    Solution
        ``radiosity`` (N, 3) float32, always finite; ``stats`` with ray counts,
        ``seconds``, ``lost_fraction``, ``energy`` (of the lines), ``skipped``,
        ``stopped`` and, after traced bounces, ``traced`` (passes, rays,
        residuals, the change of the reflected power against the lines, and
        the records whose sum came out negative and were set to zero).

    Raises
    ------
    TypeError, ValueError, MemoryError
        Bad arguments; an estimate (:func:`solve_memory`) over the memory available.

    Warns
    -----
    RuntimeWarning
        No emitter; not converged; stalled or non-finite (the last finite
        iterate is returned).
    """
    t_start = time.perf_counter()
    a = _check_vox(vox)
    opt = _settings(directions, max_bounces, tol, threads, tuning)
    executor = _check_executor(executor, vox, opt, tuning)
    p = _problem(vox, a, opt)
    if p.stats["emitters"] == 0 and not p.lights:
        return _no_emitter(p)
    _open_backend(p, executor, progress)
    try:
        _normalise(p)
        Hd, shoot_escape, shoot_rays = _direct_light(p)
        gather = _gatherer(p)
        s = _iterate(p, gather, Hd, progress)
        p.stats["energy"] = _energy(p, Hd, s, _lost_fraction(p, gather, s.vis), shoot_escape)
        _back_fraction(p, gather)
        s.R = _traced_bounces(p, Hd, s.R)
    finally:
        if hasattr(p.sysm, "close"):
            p.sysm.close()
    p.seconds["total"] = time.perf_counter() - t_start
    _statistics(p, gather, s, shoot_rays)
    B = (p.E + s.R).astype(np.float32)
    return Solution(vox=vox, radiosity=B, bounces=s.it, residuals=s.residuals, stats=p.stats)
