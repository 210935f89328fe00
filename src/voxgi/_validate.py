"""Shared argument checks: every public entry point validates through here.

Each check names the offending argument (``what``) in its message so that a
user sees which mesh, field or value was wrong.
"""

from __future__ import annotations

import numbers
from collections.abc import Sequence

import numpy as np


def as_c_array(value, dtype, shape: Sequence[int], what: str, *, finite: bool = True) -> np.ndarray:
    """Return ``value`` as a C-contiguous array of ``dtype`` and ``shape``.

    ``-1`` in ``shape`` accepts any length on that axis. Always returns a copy
    or a fresh conversion when needed; the caller's array is never modified.
    """
    try:
        arr = np.asarray(value)
    except Exception as exc:  # ragged lists and the like
        raise TypeError(f"{what}: cannot be read as an array ({exc})") from None
    if arr.dtype == object or not (
        np.issubdtype(arr.dtype, np.number) or np.issubdtype(arr.dtype, np.bool_)
    ):
        raise TypeError(f"{what}: expected a numeric array, got dtype {arr.dtype}")
    # (zip is strict: the ndim test before it guarantees equal lengths)
    if arr.ndim != len(shape) or any(
        s not in (-1, a) for s, a in zip(shape, arr.shape, strict=True)
    ):
        want = "(" + ", ".join("N" if s == -1 else str(s) for s in shape) + ")"
        raise ValueError(f"{what}: expected shape {want}, got {arr.shape}")
    if np.issubdtype(np.dtype(dtype), np.integer) and not np.issubdtype(arr.dtype, np.integer):
        if (arr.size and not np.all(np.isfinite(arr))) or np.any(arr != np.round(arr)):
            raise ValueError(f"{what}: expected integers")
    out = np.ascontiguousarray(arr, dtype=dtype)
    if finite and np.issubdtype(out.dtype, np.floating) and not np.all(np.isfinite(out)):
        bad = np.argwhere(~np.isfinite(out))[0]
        where = tuple(int(i) for i in bad)
        raise ValueError(f"{what}: non-finite value {arr[tuple(bad)]} at index {where}")
    return out


_F32_MAX = float(np.finfo(np.float32).max)


def rgb(
    value,
    what: str,
    *,
    low: float = 0.0,
    high: float | None = None,
    high_inclusive: bool = True,
    float32: bool = False,
) -> tuple[float, float, float]:
    """Colour argument: a scalar or 3 finite numbers within [low, high].

    With ``float32``, each value must also fit in float32 (the kernels'
    type), and an exclusive ``high`` must hold after rounding to float32
    (``1 - 1e-12`` is 1 there).
    """
    if isinstance(value, bool) or value is None or isinstance(value, (str, bytes)):
        raise TypeError(f"{what}: expected a number or 3 numbers, got {value!r}")
    if isinstance(value, numbers.Real):
        vals = (float(value),) * 3
    else:
        try:
            arr = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise TypeError(f"{what}: expected a number or 3 numbers, got {value!r}") from None
        if arr.shape != (3,):
            raise ValueError(f"{what}: expected a scalar or 3 values, got shape {arr.shape}")
        vals = tuple(float(v) for v in arr)
    for v in vals:
        if not np.isfinite(v):
            raise ValueError(f"{what}: non-finite value {v}")
        if v < low:
            raise ValueError(f"{what}: value {v} is below {low}")
        if high is not None and (v > high or (v == high and not high_inclusive)):
            rng = f"[{low}, {high}]" if high_inclusive else f"[{low}, {high})"
            raise ValueError(f"{what}: value {v} is outside {rng}")
        if float32:
            if abs(v) > _F32_MAX:
                raise ValueError(
                    f"{what}: value {v} does not fit in float32 (largest {_F32_MAX:.4g})"
                )
            if high is not None and not high_inclusive and float(np.float32(v)) >= high:
                raise ValueError(
                    f"{what}: value {v!r} rounds to {high} in float32; use at "
                    f"most {float(np.nextafter(np.float32(high), np.float32(0)))!r}"
                )
    return vals  # type: ignore[return-value]


def vec3(value, what: str) -> np.ndarray:
    """A finite 3-vector as float64."""
    if isinstance(value, (str, bytes)):
        raise TypeError(f"{what}: expected 3 numbers, got {value!r}")
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{what}: expected 3 numbers, got {value!r}") from None
    if arr.shape != (3,):
        raise ValueError(f"{what}: expected 3 values, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what}: non-finite value in {arr.tolist()}")
    return arr


def integer(
    value, what: str, *, low: int | None = None, high: int | None = None, allow_none: bool = False
) -> int | None:
    """An int (numpy integers accepted, bools and floats refused)."""
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{what}: expected an integer, got {type(value).__name__} {value!r}")
    v = int(value)
    if low is not None and v < low:
        raise ValueError(f"{what}: must be >= {low}, got {v}")
    if high is not None and v > high:
        raise ValueError(f"{what}: must be <= {high}, got {v}")
    return v


def real(
    value,
    what: str,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
    allow_none: bool = False,
) -> float | None:
    """A finite real number within optional (open or closed) bounds."""
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{what}: expected a number, got {type(value).__name__} {value!r}")
    v = float(value)
    if not np.isfinite(v):
        raise ValueError(f"{what}: must be finite, got {v}")
    if low is not None and (v < low or (low_open and v == low)):
        raise ValueError(f"{what}: must be {'>' if low_open else '>='} {low}, got {v}")
    if high is not None and (v > high or (high_open and v == high)):
        raise ValueError(f"{what}: must be {'<' if high_open else '<='} {high}, got {v}")
    return v


def threads(value, what: str = "threads") -> int:
    """Thread count: None means all hardware threads."""
    from . import _core

    if value is None:
        return int(_core.hardware_threads())
    return integer(value, what, low=1, high=1024)  # type: ignore[return-value]


def nondegenerate(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) bool: the faces with an area, relative to each triangle's own size.

    Zero area, a repeated vertex or collinear corners (to 1e-12 of the
    longest edge squared) make a face degenerate; the test is relative so that
    a scene far from the origin or at any scale keeps its faces.
    """
    t = vertices[faces]
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    dbl_area = np.linalg.norm(np.cross(e1, e2), axis=1)
    edge2 = np.max([np.einsum("ij,ij->i", e, e) for e in (e1, e2, e2 - e1)], axis=0)
    return dbl_area > 1e-12 * edge2


def all_degenerate(vertices, faces) -> bool:
    """Whether a mesh of finite vertices and valid faces has faces and every one
    is degenerate (a mesh with other faults is for :meth:`voxgi.Scene.add` to name)."""
    v, f = np.asarray(vertices, np.float64), np.asarray(faces)
    if v.ndim != 2 or v.shape[1:] != (3,) or f.ndim != 2 or f.shape[1:] != (3,) or len(f) == 0:
        return False
    if not np.all(np.isfinite(v)) or f.min() < 0 or f.max() >= len(v):
        return False
    return not nondegenerate(v, f).any()
