"""Sobol' points: the display's sub-pixel offsets (its first two dimensions,
a (0, 2)-sequence) and the exact direct light's record samples (five)."""

from __future__ import annotations

from functools import lru_cache

import numpy as np

#: Direction numbers of dimensions 2-5 (Joe and Kuo 2008): degree s,
#: coefficients a and initial m_1..m_s of each primitive polynomial.
_POLYNOMIALS = ((1, 0, (1,)), (2, 1, (1, 3)), (3, 1, (1, 3, 1)), (3, 2, (1, 1, 1)))
_BITS = 32
DIMENSIONS = 1 + len(_POLYNOMIALS)


@lru_cache(maxsize=1)
def _directions() -> np.ndarray:
    """(DIMENSIONS, 32) uint64: the direction numbers as 32-bit fractions."""
    v = np.zeros((DIMENSIONS, _BITS), np.uint64)
    v[0] = [1 << (_BITS - 1 - j) for j in range(_BITS)]  # van der Corput
    for d, (deg, a, init) in enumerate(_POLYNOMIALS, start=1):
        m = list(init)
        for j in range(deg, _BITS):
            x = m[j - deg] ^ (m[j - deg] << deg)
            for k in range(1, deg):
                if (a >> (deg - 1 - k)) & 1:
                    x ^= m[j - k] << k
            m.append(x)
        v[d] = [m[j] << (_BITS - 1 - j) for j in range(_BITS)]
    return v


def sobol(index, dims: int = DIMENSIONS) -> np.ndarray:
    """(n, dims) uint32: points ``index`` (n,) (below 2**32) of the Sobol'
    sequence as 32-bit fractions, each the XOR of the direction numbers of
    its index's set bits (natural order, unscrambled)."""
    i = np.asarray(index, dtype=np.uint64).reshape(-1)
    v = _directions()[:dims]
    out = np.zeros((len(i), dims), np.uint64)
    for j in range(_BITS):
        out ^= ((i >> np.uint64(j)) & np.uint64(1))[:, None] * v[:, j][None, :]
    return out.astype(np.uint32)
