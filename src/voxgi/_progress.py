"""Progress bars of the long stages: drawn on a terminal, silent elsewhere.

A bar is drawn in place only where someone watches it: stderr a terminal,
or a notebook. Redirected to a file or a pipe, stderr gets nothing from the
bars, so a log holds no carriage returns (the command line prints its own
summary lines on stdout).

A bar counts towards the work it expects, not towards a cap that is rarely
reached: the display counts frames against the frames it predicts it needs
(:func:`frames_needed`); the solve measures its stopping quantity against
the tolerance on a log scale (:func:`log_share`), since that quantity
falls geometrically with the iterations.
"""

from __future__ import annotations

import math
import sys

#: tqdm ``bar_format`` of a bar whose total is 100 (a share of the way, in percent).
PERCENT = "{desc}: {percentage:3.0f}%|{bar}| {elapsed}<{remaining}{postfix}"


def interactive(stream=None) -> bool:
    """True when ``stream`` (default ``sys.stderr``) is watched: a terminal or
    a notebook's output."""
    stream = sys.stderr if stream is None else stream
    if type(stream).__module__.startswith("ipykernel"):
        return True
    isatty = getattr(stream, "isatty", None)
    try:
        return bool(isatty and isatty())
    except ValueError:  # a closed stream
        return False


def bar(desc: str, total: float | None, *, enabled: bool = True, stream=None, **kwargs):
    """A tqdm bar on ``stream`` (default ``sys.stderr``), disabled unless
    ``enabled`` and :func:`interactive`; it is cleared when closed.

    A disabled bar takes the same calls (``update``, ``set_postfix_str``,
    ``close``, assigning ``total``) and writes nothing.
    """
    stream = sys.stderr if stream is None else stream
    if type(stream).__module__.startswith("ipykernel"):
        from tqdm.auto import tqdm
    else:
        from tqdm import tqdm
    return tqdm(
        total=total,
        desc=desc,
        file=stream,
        leave=False,
        disable=not (enabled and interactive(stream)),
        **kwargs,
    )


def frames_needed(frames: int, est: float, tol: float, floor: int, cap: int) -> int:
    """Frames a progressive render is predicted to need in all.

    The relMSE of a mean of ``n`` independent frames falls as ``1/n``, so
    an estimate ``est`` after ``frames`` frames reaches ``tol`` after about
    ``frames * est / tol``. Without an estimate yet (``est`` NaN, or no
    ``tol``) the render needs at least ``floor`` frames, the stopping rule's
    minimum. The prediction is never below ``frames``, nor above ``cap``.
    """
    if tol > 0 and math.isfinite(est) and est >= 0:
        need = math.ceil(frames * est / tol) if est > tol else frames
    else:
        need = floor if tol > 0 else cap
    return int(min(cap, max(need, floor if tol > 0 else 1, frames)))


def log_share(first: float, now: float, target: float) -> float:
    """The share of the way from ``first`` down to ``target`` that ``now``
    has gone, on a log scale, in [0, 1]; 1 once ``now <= target``."""
    if not (math.isfinite(now) and now > 0) or now <= target:
        return 1.0 if math.isfinite(now) and now <= target else 0.0
    if not (math.isfinite(first) and first > target > 0):
        return 0.0
    return min(1.0, max(0.0, math.log(first / now) / math.log(first / target)))
