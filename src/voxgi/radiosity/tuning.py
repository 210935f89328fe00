"""The settings of a solve: :class:`SolveTuning`, the paper's method, and their validation.

:class:`SolveTuning` holds what a researcher chooses: how the direct and the
reflected light reach the records and with how many samples, the radii, the
tolerance and the pair cache's budget. Its defaults are the accurate
pipeline that :func:`voxgi.render` uses; :meth:`SolveTuning.paper` is the
method of Piwowar & Malgouyres. The switches that only experiments turn
(the facing margin, the search history, coarser later bounces, the
iteration bound, which objects count as closed, the diagnostic passes) are
fields of :class:`_StudyTuning`, a private subclass for the benchmarks.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from .. import _validate

__all__ = [
    "LINES_RADIUS",
    "LOOSEST_SOLVE_TOL",
    "TRACED_RADIUS",
    "Settings",
    "SolveTuning",
    "gathering_radius",
    "settings",
]

#: Gathering radius when traced passes finish the reflected light: they carry
#: it against the exact triangles, and the lines only give them a start, which
#: a coarse direction set gives as well as a fine one for less
#: (``docs/design.md`` §5).
TRACED_RADIUS = 4
#: Gathering radius when the lines alone carry the reflected light.
LINES_RADIUS = 8

#: The loosest tolerance of the traced passes that
#: :meth:`SolveTuning.for_picture` gives a loose picture: a remaining error
#: of 1% of the records' light, under 1e-4 of the picture's relMSE.
LOOSEST_SOLVE_TOL = 1e-2


@dataclass(frozen=True)
class SolveTuning:
    """What a solve computes and how: the choices of :func:`voxgi.solve`.

    The defaults are the accurate pipeline, the one :func:`voxgi.render`
    solves with: exact direct light by shadow rays, the reflected light
    along the discrete lines and then finished by traced passes, radius 4,
    tolerance 1e-3. :meth:`paper` is the paper's method.

    Attributes
    ----------
    radius : int or None
        Radius R >= 1 of the gathering direction set (R 4: 210 directions,
        R 8: 762, R 22: 5982); ``voxgi.solve(radius=...)`` overrides it.
        None: :data:`TRACED_RADIUS` (4) where traced passes finish the
        reflected light, else :data:`LINES_RADIUS` (8).
    tol : float
        Bound on the estimated remaining relative error of the traced passes
        (and of the gathering along the lines; where traced passes keep
        their rays, ``traced_cache``, the lines stop at 100 times it);
        ``voxgi.solve(tol=...)`` overrides it.
    direct_light : {"exact", "shoot"}
        How the records get their direct light (``docs/design.md`` §5):
        ``"exact"`` traces shadow rays from every record to points on the
        emitting triangles (:func:`voxgi.direct.direct_irradiance`; cost
        records x samples; needs ``vox.scene``, else the solve shoots and
        ``stats["skipped"]`` says why); ``"shoot"`` marches discrete rays
        from every emitter record (the paper's method; cost emitter records
        x directions x path length; where it would give the same answer for
        more, one gathering pass over the emitters stands in, and
        ``stats["skipped"]`` says so). Point, spot and directional lights
        and environments are always lit exactly.
    direct_samples : int
        Emitter points per record for exact direct light (records whose
        estimate stays noisy get more).
    shoot_radius : int
        Radius of the shooting's direction set (35: 15194 directions).
    indirect_light : {"traced", "lines"}
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
    pair_cache : bool or None
        Record the pairs of the first gathering pass over a direction set and
        replay them in later passes over it (3 bytes per record and family;
        :func:`voxgi.radiosity.pair_table_bytes`). None: when they fit in
        ``max_cache_bytes``; True: the same with no default budget; False:
        walk every pass (least memory).
    traced_cache : bool or None
        Keep the first traced pass's rays (the record each one read and the
        factor it read it by, summed per record pair: a sparse matrix of at
        most ``traced_samples`` entries a record) and make every later pass a
        product with that matrix instead of fresh rays (``docs/design.md``
        §5). None: when they fit in ``max_cache_bytes``
        (:func:`voxgi.traced.transport_bytes`); True: the same with no
        default budget; False: fresh rays every pass.
    max_cache_bytes : int or None
        Budget for the recorded pairs, and for the kept traced rays; None: a
        quarter of the memory available when the solve starts, or when the
        traced passes start (``pair_cache=None``, ``traced_cache=None``), no
        limit (True).

    >>> SolveTuning().direct_light, SolveTuning.paper().radius
    ('exact', 22)
    """

    radius: int | None = None
    tol: float = 1e-3
    direct_light: str = "exact"
    direct_samples: int = 16
    shoot_radius: int = 35
    indirect_light: str = "traced"
    traced_samples: int = 64
    pair_cache: bool | None = None
    traced_cache: bool | None = None
    max_cache_bytes: int | None = None

    @staticmethod
    def for_picture(tol: float) -> SolveTuning:
        """The defaults, with the effort a picture of relMSE ``tol`` needs.

        At the defaults' tolerance (1e-3) and under it, the defaults. Looser
        pictures stop the traced passes at ``tol`` (at most
        :data:`LOOSEST_SOLVE_TOL`) and start them with ``64 · 1e-3 / tol``
        rays a record, rounded down to a square, at least 16: a remaining
        relative error ``ε`` of the records adds about ``ε²`` to the
        picture's relMSE, and their noise shrinks as the rays grow, so that
        both stay a small share of the looser tolerance
        (``docs/design.md`` §5, "The solve a picture needs").
        :func:`voxgi.resolution.solve_scene`, and so :func:`voxgi.render`
        without a solution, solve with it.

        Parameters
        ----------
        tol : float
            The picture's tolerance (relMSE), > 0.

        Returns
        -------
        SolveTuning

        >>> SolveTuning.for_picture(1e-3) == SolveTuning()
        True
        >>> t = SolveTuning.for_picture(5e-3); t.tol, t.traced_samples
        (0.005, 16)
        """
        tol = _validate.real(tol, "tol", low=0.0, low_open=True)
        base = SolveTuning()
        if tol <= base.tol:
            return base
        rays = base.traced_samples * base.tol / tol
        square = max(int(np.floor(np.sqrt(rays) + 1e-9)), 4) ** 2
        return replace(base, tol=min(tol, LOOSEST_SOLVE_TOL), traced_samples=square)

    @staticmethod
    def paper(**changes) -> SolveTuning:
        """The method of Piwowar & Malgouyres (2008), for the paper's tables and studies.

        Direct light shot along the discrete lines (radius 35), the
        reflected light gathered along them alone (radius 22) to a tolerance
        of 1e-4, and the diagnostic passes behind ``stats["back_fraction"]``
        and the energy balance of every record. Slower than the defaults
        and blind to occluders thinner than a voxel (``docs/design.md`` §5).

        Parameters
        ----------
        **changes
            Fields to change, e.g. ``shoot_radius=8``; studies may also set
            the experiment switches of the benchmarks' private tuning
            (``later_radius``, ``epsilon``, ``history``, ``closed``, ...).

        Returns
        -------
        SolveTuning
            For ``voxgi.solve(vox, tuning=SolveTuning.paper())``.

        >>> SolveTuning.paper(shoot_radius=8).shoot_radius
        8
        """
        paper = _StudyTuning(
            radius=22,
            tol=1e-4,
            direct_light="shoot",
            direct_samples=64,
            indirect_light="lines",
            diagnostics=True,
        )
        return replace(paper, **changes)


@dataclass(frozen=True)
class _StudyTuning(SolveTuning):
    """:class:`SolveTuning` with the switches that only experiments turn
    (the benchmarks' and tests'; ``tuning=`` takes it as a SolveTuning).

    Attributes
    ----------
    later_radius : int or None
        Radius for the bounces after the first ``later_after`` ones (later
        bounces are smooth; Piwowar & Malgouyres 2009). The solver then
        propagates each bounce's increment and ends with the geometric-tail
        term once the ratio of successive bounces is steady. None: every
        bounce with ``radius``.
    later_after : int
        Bounces gathered with ``radius`` before ``later_radius``.
    epsilon : float
        Facing-rule margin in voxels (``docs/design.md`` §4).
    history : int
        F records a receiver passes over in its search along a line (1..32;
        a run of them in one plane counts once).
    max_iterations : int
        Bound on the iterations when ``max_bounces`` is None.
    lines_tol : float or None
        The lines' own tolerance where traced passes follow them; the passes
        still run to ``tol``. None: 100 times ``tol`` where the passes keep
        their rays (``traced_cache`` not False, within its budget), else ``tol``
        (:func:`voxgi.radiosity.iteration.lines_tol`).
    closed : bool, sequence of int or None
        Objects (ids into ``vox.object_id``; True: all; False: none) whose
        meshes are closed: their back records send their front twin's
        radiosity instead of black (``docs/design.md`` §5). None: the objects
        :func:`voxgi.voxelize` found watertight (``vox.stats["closed_objects"]``).
    diagnostics : bool
        Run the extra gathering pass behind ``stats["back_fraction"]`` and
        light the black records too, for the energy balance.
    incidence : bool
        Weigh the light a glossy record gathers by its material's
        directional albedo over its mean (:mod:`voxgi.incidence`); False:
        every record reflects its light by its mean albedo.

    >>> _StudyTuning(later_radius=8).later_after
    2
    """

    later_radius: int | None = None
    later_after: int = 2
    epsilon: float = 0.02
    history: int = 16
    max_iterations: int = 10000
    lines_tol: float | None = None
    closed: bool | Sequence[int] | None = None
    diagnostics: bool = False
    incidence: bool = True


_NO_STUDY = _StudyTuning()


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
    direct_light: str = "exact"
    direct_samples: int = 16
    indirect_light: str = "traced"
    traced_samples: int = 64
    traced_cache: bool | None = None
    lines_tol: float | None = None
    incidence: bool = True


def _checked_tuning(tuning) -> SolveTuning:
    t = SolveTuning() if tuning is None else tuning
    if not isinstance(t, SolveTuning):
        raise TypeError(f"tuning: expected voxgi.SolveTuning or None, got {type(t).__name__}")
    return t


def gathering_radius(radius, tuning, vox, max_bounces=None) -> int:
    """The gathering radius of a solve: ``radius``, else the tuning's, else
    :data:`TRACED_RADIUS` where traced passes finish the reflected light
    (``indirect_light="traced"``, the records carry their scene, and
    ``max_bounces`` is None), else :data:`LINES_RADIUS`."""
    t = _checked_tuning(tuning)
    if radius is None:
        radius = t.radius
    if radius is None:
        traced = (
            t.indirect_light == "traced"
            and getattr(vox, "scene", None) is not None
            and max_bounces is None
        )
        radius = TRACED_RADIUS if traced else LINES_RADIUS
    return _validate.integer(radius, "radius", low=1, high=256)


def settings(radius, max_bounces, tol, threads, tuning) -> Settings:
    """Check the arguments and the tuning (``tol`` None: the tuning's);
    raise TypeError/ValueError naming the bad one."""
    t = _checked_tuning(tuning)
    s = t if isinstance(t, _StudyTuning) else _NO_STUDY
    for name in ("pair_cache", "traced_cache"):
        value = getattr(t, name)
        if value is not None and not isinstance(value, (bool, np.bool_)):
            raise TypeError(f"{name}: expected True, False or None, got {value!r}")
    if t.direct_light not in ("shoot", "exact"):
        raise ValueError(f"direct_light: expected 'shoot' or 'exact', got {t.direct_light!r}")
    if t.indirect_light not in ("lines", "traced"):
        raise ValueError(f"indirect_light: expected 'lines' or 'traced', got {t.indirect_light!r}")
    return Settings(
        R=_validate.integer(radius, "radius", low=1, high=256),
        Rs=_validate.integer(t.shoot_radius, "shoot_radius", low=1, high=256),
        Rl=_validate.integer(s.later_radius, "later_radius", low=1, high=256, allow_none=True),
        later_after=_validate.integer(s.later_after, "later_after", low=1),
        max_bounces=_validate.integer(max_bounces, "max_bounces", low=0, allow_none=True),
        max_iterations=_validate.integer(s.max_iterations, "max_iterations", low=1),
        tol=_validate.real(t.tol if tol is None else tol, "tol", low=0.0, low_open=True),
        threads=_validate.threads(threads),
        epsilon=_validate.real(s.epsilon, "epsilon", low=0.0),
        history=_validate.integer(s.history, "history", low=1, high=32),
        closed=s.closed,
        diagnostics=bool(s.diagnostics),
        incidence=bool(s.incidence),
        pair_cache=t.pair_cache,
        cache_cap=_validate.integer(t.max_cache_bytes, "max_cache_bytes", low=0, allow_none=True),
        direct_light=t.direct_light,
        direct_samples=_validate.integer(t.direct_samples, "direct_samples", low=1, high=1 << 16),
        indirect_light=t.indirect_light,
        traced_samples=_validate.integer(t.traced_samples, "traced_samples", low=1, high=4096),
        traced_cache=t.traced_cache,
        lines_tol=_validate.real(s.lines_tol, "lines_tol", low=0.0, low_open=True, allow_none=True),
    )
