"""The settings of a solve: :class:`SolveTuning` and their validation."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .. import _validate

__all__ = ["Settings", "SolveTuning", "settings"]


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
class Settings:
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


def settings(directions, max_bounces, tol, threads, tuning) -> Settings:
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
    return Settings(
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
