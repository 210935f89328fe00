"""The memory a local solve needs, estimated before it allocates."""

from __future__ import annotations

import numpy as np

from .. import _core, _validate
from ..directions import direction_set
from ..voxels import VoxelSet, available_memory
from .linesystem import pair_table_bytes
from .tuning import Settings, SolveTuning, gathering_radius, settings

__all__ = ["check_memory", "shoots_direct_light", "solve_memory"]

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


def shoots_direct_light(vox: VoxelSet, opt: Settings) -> bool:
    """Whether a solve of ``vox`` with ``opt`` shoots its direct light (see
    :attr:`Problem.shoots`)."""
    scene = getattr(vox, "scene", None)
    if scene is not None and scene.has_lights:
        return False
    return opt.direct_light == "shoot" or scene is None


def solve_memory(
    vox: VoxelSet,
    *,
    radius: int | None = None,
    threads: int | None = None,
    tuning: SolveTuning | None = None,
) -> dict:
    """Bytes a local :func:`solve` of ``vox`` needs, by part, before it allocates.

    Parameters
    ----------
    vox : VoxelSet
        Records from :func:`voxgi.voxelize`.
    radius : int or None
        Gathering radius, as for :func:`voxgi.solve` (None: the tuning's choice).
    threads : int or None
        Threads (None: all hardware threads); each holds its own walk state.
    tuning : SolveTuning or None
        As for :func:`voxgi.solve` (None: the defaults).

    Returns
    -------
    dict
        ``records`` (line system, arrays, solver state), ``threads`` (each
        thread's walk records, line tables and sums), ``directions`` (the
        direction sets and their ``S(n)``), ``pair_cache`` (the recorded
        pairs the solve would keep, within their budget) and ``total``.

    >>> import voxgi
    >>> vox = voxgi.voxelize(voxgi.scenes.furnace_box(), resolution=8, progress=False)
    >>> est = solve_memory(vox, radius=4, threads=1)
    >>> est["total"] == sum(v for k, v in est.items() if k != "total")
    True
    """
    opt = settings(gathering_radius(radius, tuning, vox), None, 1.0, threads, tuning)
    ijk = _validate.as_c_array(vox.ijk, np.int32, (-1, 3), "vox.ijk")
    n = len(ijk)
    extent = ijk.max(axis=0).astype(np.int64) - ijk.min(axis=0) if n else np.zeros(3, np.int64)
    # the shooting's set only where the direct light is shot (building one of
    # radius 35 takes a quarter of a second)
    radii = {opt.R} | ({opt.Rs} if shoots_direct_light(vox, opt) else set())
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


def check_memory(vox: VoxelSet, opt: Settings, tuning) -> dict:
    """Refuse a local solve whose estimate exceeds the memory available now."""
    est = solve_memory(vox, radius=opt.R, threads=opt.threads, tuning=tuning)
    avail = available_memory()
    if est["total"] > avail:
        parts = ", ".join(f"{k} {v / 2**30:.2f} GiB" for k, v in est.items() if k != "total")
        raise MemoryError(
            f"solve: {len(vox):,} records at radius {opt.R} on {opt.threads} threads need "
            f"about {est['total'] / 2**30:.2f} GiB ({parts}), over the "
            f"{avail / 2**30:.2f} GiB available; use fewer threads, a smaller radius, a coarser "
            "resolution, or SolveTuning(pair_cache=False)"
        )
    return est
