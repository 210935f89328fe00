"""The error estimate of the progressive mean and the stopping rule
(``docs/design.md`` §6)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import _core

__all__ = ["PIXEL_FACTOR", "PIXEL_SHARE"]

#: relMSE's epsilon (voxgi.metrics.rel_mse), used by the stopping rule too.
_REL_EPS = 0.01

#: The stopping rule's per-pixel bound: a pixel's estimated relative error
#: may reach this many times ``sqrt(tol)`` (``docs/design.md`` §6).
PIXEL_FACTOR = 10.0
#: The share of pixels that may exceed that bound: a single pixel (a sliver
#: of a bright light at a pixel's edge, a rare spike) cannot hold a large
#: image back, a region of them can.
PIXEL_SHARE = 1e-3


#: Batch means kept per pixel: between half this and this many once there
#: are that many frames (pairs merge when the store is full, doubling the
#: batch size), so the error estimate always rests on at least 16 batches.
_BATCH_SLOTS = 32

#: Batches before the stopping rule is trusted: one block of
#: :data:`_STRATUM_FRAMES` frames, so that every pixel's offsets have
#: visited each quarter of it, and the heavy-tail test's least number of
#: batches. Each pixel's variance is then known only to a relative standard
#: deviation of sqrt(2 / 3) = 0.82 (normal batches), but the relMSE is the
#: mean over the pixels; before two blocks an edge pixel's error comes from
#: the single frames, which overstates it (``docs/design.md`` §6).
_MIN_BATCHES = 4

#: Frames per block of the mean relMSE's estimate. The sub-pixel offsets
#: follow a (0, 2)-sequence, so any 4 frames from a multiple of 4 put one
#: offset in each quarter of the pixel and their errors at edges partly
#: cancel: consecutive frames are negatively correlated. The spread between
#: single frames misses that and overstates the error of the mean (1.3-1.6x
#: in the window room); the spread between such blocks sees it.
_STRATUM_FRAMES = 4

#: Largest angle between the geometric normals a pixel's camera rays meet on
#: one object for the pixel to count as inside a surface rather than at an
#: edge (more than a coarse tessellation's crease, less than a box's corner).
_EDGE_ANGLE_DEG = 25.0
_EDGE_COS = math.cos(math.radians(_EDGE_ANGLE_DEG))

#: The least factor on an edge pixel's block spread: the offsets' part of its
#: error falls as frames^-3/2, the light samples' part as frames^-1.
_EDGE_SHRINK_MIN = 0.5

#: Significance of the heavy-tail test over a pixel's batches (Bonferroni over
#: the batches, two-sided): a normal pixel is flagged with this probability.
_OUTLIER_ALPHA = 1e-3


#: Student's t quantiles ``t.ppf(1 - _OUTLIER_ALPHA / (2k), k - 2)`` for k = 4
#: to :data:`_BATCH_SLOTS` batches, to 6 digits (the tests check them against
#: scipy): a table, because importing ``scipy.stats`` takes half a second.
_OUTLIER_CRIT = (
    63.2337, 22.2037, 13.6531, 10.3808, 8.7294, 7.75503, 7.12, 6.67681, 6.35172, 6.1041,
    5.90987, 5.75387, 5.62614, 5.51987, 5.43025, 5.35379, 5.28791, 5.23064, 5.18048, 5.13625,
    5.09702, 5.06202, 5.03066, 5.00243, 4.97693, 4.95379, 4.93274, 4.91353, 4.89594,
)  # fmt: skip


def _outlier_threshold(k: int) -> float:
    """Critical externally studentized residual for ``4 <= k <= 32`` batch
    means: under normal batches each residual follows Student's t with
    ``k - 2`` degrees of freedom; Bonferroni over the ``k`` batches,
    two-sided."""
    return _OUTLIER_CRIT[k - 4]


def _batch_statistics(batches: np.ndarray, size: int, frames: int, threads: int = 0):
    """Per-pixel error of the running mean from ``k`` batch means.

    Parameters
    ----------
    batches : (k, P, 3) float32
        Means of ``size`` consecutive frames each, ``k >= 2`` (the
        heavy-tail test needs ``k >= 4``).
    size, frames : int
        Frames per batch; frames in the running mean.
    threads : int
        Threads of the compiled kernel (0: all).

    Returns
    -------
    stderr : (P, 3) float64
        ``sqrt(s_b² · size / frames)``, ``s_b²`` the variance between batch
        means, raised for a flagged pixel to the largest single-batch jump
        ``max_j |m_j - M| · size / frames``.
    flagged : (P,) bool
        Pixels one of whose batches lies beyond what the others' spread
        allows (``docs/design.md`` §6).
    """
    k = len(batches)
    crit = _outlier_threshold(k) if k >= 4 else math.inf
    se, tail = _core.batch_error(
        np.ascontiguousarray(batches, dtype=np.float32), size, frames, crit, threads
    )
    return se, tail.any(axis=1)


def _dilate(mask: np.ndarray, r: int) -> np.ndarray:
    """(H, W) bool: ``mask`` grown by ``r`` pixels in each direction (a
    (2r + 1)² square), by shifted ORs along rows, then columns."""
    out = mask
    for axis in (0, 1):
        grown = out.copy()
        n = out.shape[axis]
        for t in range(1, r + 1):
            lo = [slice(None)] * 2
            hi = [slice(None)] * 2
            lo[axis], hi[axis] = slice(0, n - t), slice(t, n)
            grown[tuple(lo)] |= out[tuple(hi)]
            grown[tuple(hi)] |= out[tuple(lo)]
        out = grown
    return out


class _Estimated:
    """A statistic of :class:`_Mean`'s error estimate, worked out when read:
    reading ``acc.est`` returns ``acc._est`` once ``acc`` has brought its
    estimate up to date."""

    def __init__(self, doc: str):
        self.__doc__ = doc

    def __set_name__(self, owner, name: str) -> None:
        self.field = "_" + name

    def __get__(self, acc, owner=None):
        if acc is None:
            return self
        acc._refresh()
        return getattr(acc, self.field)


@dataclass
class _Mean:
    """The progressive mean of the frames, its error by batch means, and
    the stopping rule (``docs/design.md`` §6).

    Frames go into batches of ``size`` consecutive frames; the variance
    between batch means estimates the variance of the mean even where frames
    are correlated. When the store of :data:`_BATCH_SLOTS` batches is full,
    neighbouring batches merge and ``size`` doubles. ``se`` (per pixel),
    ``worst``, the largest per-pixel relative error ``se / sqrt(L² + 0.01)``
    (largest over a pixel's channels), and ``tail``, the one that all but
    ``share`` of the pixels stay within, come from these batches. ``est``,
    the estimated relMSE ``mean(se² / (L² + 0.01))`` over pixels and
    channels, depends on where a pixel lies. Inside a surface (every frame's
    camera ray met the same object, at normals within
    :data:`_EDGE_ANGLE_DEG`) frames are independent and ``se`` is the
    batches'. At an edge the sub-pixel offsets make them negatively
    correlated: ``se`` comes from the spread between aligned blocks of
    :data:`_STRATUM_FRAMES` frames, kept as running sums, times ``1/sqrt(k)``
    over ``k`` blocks (at least :data:`_EDGE_SHRINK_MIN`). A flagged pixel
    keeps the larger of the batches' and the blocks' spread; before two
    blocks, all take the batches'. Frames that come without their surfaces
    (:func:`frame_surface`) leave every pixel to the blocks.

    These are worked out when first read after a batch completes, not at
    every batch: a render reads them only once its stopping rule can apply,
    and a fixed number of frames only at the end.
    """

    total: np.ndarray
    batches: np.ndarray
    current: np.ndarray
    frames: int = 0
    size: int = 1
    count: int = 0
    share: float = PIXEL_SHARE
    threads: int = 0
    block_sum: np.ndarray | None = None
    block_sq: np.ndarray | None = None
    #: (P,) bool: pixels whose own camera rays met an edge so far; None once
    #: a frame came without its surface
    edge: np.ndarray | None = None
    #: (height, width, pixels): how far a pixel filter spreads a sample
    #: (:meth:`edges`); None for a box filter
    reach: tuple[int, int, int] | None = None
    _first_surface: tuple | None = None
    _est: float = float("inf")
    _worst: float = float("inf")
    _tail: float = float("inf")
    _flagged: int = 0
    _se: np.ndarray | None = None
    _stale: bool = False

    @classmethod
    def empty(cls, pixels: int, share: float = PIXEL_SHARE, threads: int = 0, reach=None) -> _Mean:
        """No frames yet for ``pixels`` pixels; ``share`` as
        :data:`PIXEL_SHARE`; ``threads`` for the error's kernel;
        ``reach`` as :attr:`reach`."""
        return cls(
            np.zeros((pixels, 3)),
            np.zeros((_BATCH_SLOTS, pixels, 3), np.float32),
            np.zeros((pixels, 3)),
            share=share,
            threads=threads,
            block_sum=np.zeros((pixels, 3)),
            block_sq=np.zeros((pixels, 3)),
            reach=reach,
        )

    def edges(self) -> np.ndarray | None:
        """(P,) bool: the pixels the estimate treats as at an edge. With a
        pixel filter a frame's pixel mixes the samples of its neighbours, so
        an edge within the filter's reach counts too."""
        if self.edge is None or self.reach is None:
            return self.edge
        h, w, r = self.reach
        return _dilate(self.edge.reshape(h, w), r).reshape(-1)

    @property
    def mean(self) -> np.ndarray:
        """(P, 3) float64 mean of the frames so far."""
        return self.total / max(self.frames, 1)

    est = _Estimated("estimated relMSE of the mean (inf before two batches)")
    worst = _Estimated("largest per-pixel relative error")
    tail = _Estimated("per-pixel relative error all but ``share`` of the pixels stay within")
    flagged = _Estimated("pixels the heavy-tail test flagged")
    se = _Estimated("(P, 3) per-pixel standard error (None before two batches)")

    def _refresh(self) -> None:
        if self._stale:
            self._estimate()
            self._stale = False

    def add(self, x: np.ndarray, surface: tuple | None = None) -> None:
        """Fold one frame in, with what its camera rays met
        (:func:`frame_surface`); on completing a batch, mark the estimate
        for an update."""
        if self._stale and self.frames + 1 - self.count * self.size < self.size:
            # this frame opens a batch and changes the sums the last complete
            # batch's estimate is made of: make it while they are as they were
            self._refresh()
        self._add_surface(surface)
        self.frames += 1
        self.total += x
        self.current += x
        if self.frames % _STRATUM_FRAMES == 0:
            # the block just completed: all frames less the blocks before it
            block = (self.total - _STRATUM_FRAMES * self.block_sum) / _STRATUM_FRAMES
            self.block_sum += block
            self.block_sq += block * block
        if self.frames - self.count * self.size < self.size:
            return
        self.batches[self.count] = self.current / self.size
        self.current[:] = 0.0
        self.count += 1
        if self.count == _BATCH_SLOTS:
            half = _BATCH_SLOTS // 2
            self.batches[:half] = 0.5 * (self.batches[0::2] + self.batches[1::2])
            self.count, self.size = half, 2 * self.size
        self._stale = self.count >= 2

    def _add_surface(self, surface: tuple | None) -> None:
        if surface is None:
            self.edge = None
            self._first_surface = None
            return
        obj, ng = surface
        if self.frames == 0:
            self._first_surface = (np.array(obj, np.int32), np.array(ng, np.float32))
            self.edge = np.zeros(len(obj), bool)
        elif self.edge is not None:
            obj0, ng0 = self._first_surface
            cos = np.abs(np.einsum("ij,ij->i", ng, ng0, dtype=np.float32))
            self.edge |= (obj != obj0) | ((obj >= 0) & (cos < _EDGE_COS))

    def _estimate(self) -> None:
        done = self.count * self.size
        # The estimate speaks for the mean of the complete batches; the open
        # batch's frames only add to the image.
        mean = self.total - self.current
        mean /= done
        se, flagged = _batch_statistics(self.batches[: self.count], self.size, done, self.threads)
        denom = mean * mean + _REL_EPS
        rel = se * se / denom
        pixel = rel.max(axis=1)
        self._se = se
        k = self.frames // _STRATUM_FRAMES
        if k >= 2:
            spread = np.maximum(self.block_sq - self.block_sum**2 / k, 0.0) / (k - 1)
            rel_blocks = spread * (_STRATUM_FRAMES / done) / denom
            edge = self.edges()
            if edge is None:
                kept = rel_blocks
            else:
                shrink = max(1.0 / math.sqrt(k), _EDGE_SHRINK_MIN)
                kept = np.where(edge[:, None], shrink * rel_blocks, rel)
            self._est = float(
                np.mean(np.where(flagged[:, None], np.maximum(rel, rel_blocks), kept))
            )
        else:
            self._est = float(np.mean(rel))
        self._worst = float(np.sqrt(np.max(pixel)))
        self._tail = float(np.sqrt(np.quantile(pixel, 1.0 - self.share, method="higher")))
        self._flagged = int(np.count_nonzero(flagged))

    def done(self, opt) -> bool:
        """:data:`_MIN_BATCHES` batches, the estimated relMSE at or under
        ``opt.tol`` and at most a share ``pixel_share`` of the pixels with a
        relative error over ``opt.pixel_factor · sqrt(opt.tol)``."""
        return (
            self.ready()
            and self.est <= opt.tol
            and self.tail <= opt.pixel_factor * math.sqrt(opt.tol)
        )

    def ready(self) -> bool:
        """Whether the stopping rule may apply: :data:`_MIN_BATCHES` batches."""
        return self.count >= _MIN_BATCHES

    def stderr(self, shape) -> np.ndarray | None:
        """Per-pixel standard error (None before two batches)."""
        if self.se is None:
            return None
        return self.se.reshape(shape).astype(np.float32)


#: The denoised image's relMSE over the spread between the denoised first
#: half of the frames and the denoised whole: the spread sees only the
#: denoiser's residual noise, not the detail it blurs away, which grows with
#: the noise it is given; measured on the Cornell box and the door room at
#: 256 x 256 (``docs/design.md`` §6).
DENOISED_FACTOR = 2.0


def denoised_estimate(acc: _Mean, shape, albedo, normal, emission=None) -> tuple[float, np.ndarray]:
    """The estimated relMSE of the denoised running mean, and that image.

    With ``h`` of the ``n`` frames in the first half of the complete batches,
    the denoised half ``D_h`` and the denoised whole ``D_n`` differ by the
    denoiser's response to the noise of the frames the half lacks: where
    the response is about linear, ``E|D_h - D_n|² = Var(D_n) (n - h) / h``
    pixel by pixel, so ``Var(D_n)`` is that spread times ``h / (n - h)``.
    The relMSE is its mean over ``L² + 0.01``, times
    :data:`DENOISED_FACTOR` for what the denoiser blurs.

    Parameters
    ----------
    acc : _Mean
        At least two complete batches.
    shape : (H, W, 3)
    albedo, normal : (H, W, 3) float32 or None
        The denoiser's guides.
    emission : (H, W, 3) float32 or None
        The seen emission, kept out of the denoiser
        (:func:`voxgi.denoise.denoise`).

    Returns
    -------
    est : float
    denoised : (H, W, 3) float32
        The denoised running mean of all the frames.
    """
    from ..denoise import denoise

    half = acc.count // 2
    h, n = half * acc.size, acc.frames
    full = acc.mean.reshape(shape).astype(np.float32)
    d_n = denoise(full, albedo, normal, emission=emission)
    if half == 0 or h >= n:
        return math.inf, d_n
    first = acc.batches[:half].mean(axis=0, dtype=np.float64).reshape(shape)
    d_h = denoise(first.astype(np.float32), albedo, normal, emission=emission)
    spread = (d_h.astype(np.float64) - d_n) ** 2 / (full.astype(np.float64) ** 2 + _REL_EPS)
    return DENOISED_FACTOR * float(np.mean(spread)) * h / (n - h), d_n
