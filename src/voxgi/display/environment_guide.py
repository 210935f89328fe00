"""Where the environment's light reaches the scene: a table that draws each
pixel's environment samples from the directions that are open at its place
(``docs/design.md`` §11).

Inside a room lit through windows most directions of the environment are
blocked by walls, and a sample drawn by the environment's own brightness
is mostly wasted: in a living room lit through two French windows one in
eight passes. The guide learns, from shadow rays traced at the solve's
records, which blocks of the environment's texels bring light to the points
of each cell of a coarse grid that face one way, and the display draws most
samples from those blocks. The density of every sample is exact, so the
balance heuristic with the gather rays stays unbiased however rough the
table is; a rough table only costs variance.
"""

from __future__ import annotations

import time

import numpy as np

from .. import _core
from ..lights import LUMINANCE, Environment
from ..rays import Tracer
from ..voxels import VoxelSet

__all__ = ["EnvironmentGuide", "environment_guide"]

#: Cells across the records' longest extent.
CELLS_ACROSS = 8
#: Most records of one cell and facing that trace the learning rays.
RECORDS_PER_KEY = 256
#: Learning rays of one cell and facing, shared among its records (at
#: least one each): a cell of few records learns as much as a full one.
RAYS_PER_KEY = 16384
#: Most learning rays in all (each key's share shrinks to fit, to no fewer
#: than one per record).
RAYS_IN_ALL = 1 << 22
#: Blocks of texels across and down the environment (fewer where it has
#: fewer texels).
BLOCKS = (32, 16)
#: Share of the samples still drawn by the environment's own density.
ALPHA = 0.1
#: Above this share of the light that reaches the records' hemispheres
#: unblocked, the environment is open (a scene under the sky) and the guide
#: would gain nothing over the environment's own density.
OPEN_SHARE = 0.8


class EnvironmentGuide:
    """The guide's tables and what building them cost.

    Attributes
    ----------
    native : voxgi._core.EnvironmentGuide
        The tables as the shading kernels take them.
    open_share : float
        Share of the environment's light over the records' hemispheres that
        the learning rays found unblocked.
    rays : int
        Learning rays traced.
    seconds : float
    """

    def __init__(self, native, open_share: float, rays: int, seconds: float):
        self.native, self.open_share, self.rays, self.seconds = native, open_share, rays, seconds


def _blocks(env: Environment) -> tuple[int, int, np.ndarray, np.ndarray]:
    """Blocks across and down, each block's share of the environment's own
    density (row-major blocks) and the kernels' ``row_cdf`` (blocks_w, H):
    per column of blocks, the running density of its texels row by row,
    from 0 again at each block's first row. Nothing here grows with the
    texels beyond one (H, blocks_w) table."""
    h, w = env.image.shape[:2]
    bw, bh = min(BLOCKS[0], w), min(BLOCKS[1], h)
    first_col = (np.arange(bw) * w + bw - 1) // bw
    first_row = (np.arange(bh + 1) * h + bh - 1) // bh
    seg = np.add.reduceat(env.tables()["texel_pdf"].reshape(h, w), first_col, axis=1)  # (H, bw)
    run = np.cumsum(seg, axis=0)
    band = (np.arange(h) * bh) // h
    start = first_row[:-1]
    before = np.where((start > 0)[:, None], run[np.maximum(start - 1, 0)], 0.0)  # (bh, bw)
    row_cdf = run - before[band]
    mass = row_cdf[first_row[1:] - 1]  # (bh, bw): each block's last row
    return bw, bh, mass.reshape(-1), np.ascontiguousarray(row_cdf.T)


def environment_guide(
    env: Environment | None, vox: VoxelSet, tracer: Tracer, eps: float, seed: int = 0
) -> tuple[EnvironmentGuide | None, str | None]:
    """Learn where ``env``'s light reaches the records of ``vox``.

    Parameters
    ----------
    env : Environment or None
    vox : VoxelSet
        The solve's records: their front sides trace the learning rays.
    tracer : Tracer
        The scene's tracer (points in its centred frame).
    eps : float
        Offset of the learning rays along the records' normals.
    seed : int
        Seed of the learning rays (the guide is a density: any seed is exact).

    Returns
    -------
    (EnvironmentGuide or None, str or None)
        The guide, or None with the reason it is skipped.
    """
    if env is None:
        return None, "no environment"
    bw, bh, mass, row_cdf = _blocks(env)
    if bw * bh < 2:
        return None, "environment guide: a constant environment has no directions to choose"
    t0 = time.perf_counter()
    area = np.asarray(vox.area)
    keep = area > 0
    if vox.back is not None:
        keep &= ~np.asarray(vox.back, dtype=bool)
    ids = np.flatnonzero(keep)
    if len(ids) == 0:
        return None, "environment guide: no records to learn from"
    pos = np.asarray(vox.centroid, np.float64)[ids] - tracer.centre
    nrm = np.asarray(vox.normal, np.float64)[ids]
    lo = pos.min(axis=0)
    cell = max(float((pos.max(axis=0) - lo).max()) / CELLS_ACROSS, 1e-9)
    dims = np.minimum(np.floor((pos.max(axis=0) - lo) / cell).astype(np.int64) + 1, 4096)
    key = _keys(pos, nrm, lo, cell, dims)
    # up to RECORDS_PER_KEY records of each key, at random, key by key
    rng = np.random.default_rng([seed, 0x5EED])
    order = rng.permutation(len(ids))
    order = order[np.argsort(key[order], kind="stable")]
    sorted_key = key[order]
    first = np.r_[0, np.flatnonzero(np.diff(sorted_key)) + 1]
    rank = np.arange(len(order)) - np.repeat(first, np.diff(np.r_[first, len(order)]))
    learn = order[rank < RECORDS_PER_KEY]
    keys, count = np.unique(key[learn], return_counts=True)
    h, w = env.image.shape[:2]
    hist, possible, rays = _core.learn_environment_guide(
        *env.sampling_arguments(),
        bw,
        bh,
        np.ascontiguousarray(pos[learn]),
        np.ascontiguousarray(nrm[learn], np.float32),
        np.r_[0, np.cumsum(count)].astype(np.int64),
        np.maximum(min(RAYS_PER_KEY, RAYS_IN_ALL // len(keys)) // count, 1).astype(np.int32),
        int(seed) & ((1 << 64) - 1),
        float(eps),
        np.asarray(LUMINANCE, np.float64),
        tracer.native,
        tracer.threads,
    )
    total = float(possible.sum())
    open_share = float(hist.sum()) / total if total > 0 else 0.0
    if open_share >= OPEN_SHARE:
        return None, (
            f"environment guide: the environment is open ({open_share:.0%} of its light "
            "reaches the records unblocked)"
        )
    reached = hist.sum(axis=1)
    if not np.any(reached > 0):
        return None, "environment guide: no learning ray reached the environment"
    keys, hist = keys[reached > 0], hist[reached > 0]
    share = hist / hist.sum(axis=1, keepdims=True)
    factor = ALPHA + (1.0 - ALPHA) * np.divide(
        share, mass[None], out=np.zeros_like(share), where=mass[None] > 0
    )
    block_cdf = np.cumsum(share, axis=1)
    block_cdf /= block_cdf[:, -1:]
    block_cdf[:, -1] = 1.0
    key_row = np.full(int(dims.prod()) * 6, -1, np.int32)
    key_row[keys] = np.arange(len(keys), dtype=np.int32)
    native = _core.EnvironmentGuide(
        lo,
        cell,
        dims.astype(np.int64),
        w,
        h,
        bw,
        bh,
        ALPHA,
        key_row,
        np.ascontiguousarray(factor),
        np.ascontiguousarray(block_cdf),
        row_cdf,
    )
    return EnvironmentGuide(native, open_share, rays, time.perf_counter() - t0), None


def _keys(pos: np.ndarray, nrm: np.ndarray, lo: np.ndarray, cell: float, dims: np.ndarray):
    """Each point's cell and facing, as the kernels number them: cell * 6 +
    2 * axis + (1 where the normal's dominant component is negative)."""
    c = np.clip(np.floor((pos - lo) / cell).astype(np.int64), 0, dims - 1)
    axis = np.abs(nrm).argmax(axis=1)
    neg = nrm[np.arange(len(nrm)), axis] < 0
    return ((c[:, 0] * dims[1] + c[:, 1]) * dims[2] + c[:, 2]) * 6 + 2 * axis + neg
