"""Spectra to linear sRGB, as Mitsuba 3's RGB variants read them (docs/design.md §12)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["CIE_MAX", "CIE_MIN", "spectrum_to_rgb"]

_CIE: np.ndarray | None = None
# CIE XYZ to linear sRGB (D65 white), the matrix Mitsuba 3's xyz_to_srgb uses.
_XYZ_TO_SRGB = np.array(
    [
        [3.240479, -1.537150, -0.498535],
        [-0.969256, 1.875991, 0.041556],
        [0.055648, -0.204043, 1.057311],
    ]
)
CIE_MIN, CIE_MAX = 360.0, 830.0
# 1 / integral of y over [360, 830] nm (Mitsuba 3's MI_CIE_Y_NORMALIZATION);
# the D65 table is scaled so that y * D65 has the same integral.
_CIE_Y_NORM = 0.009367658735689113


def _cie_table() -> np.ndarray:
    """(95, 5) wavelength, x, y, z, D65 at 5 nm (src/voxgi/data/cie1931_d65.csv)."""
    global _CIE
    if _CIE is None:
        _CIE = np.loadtxt(
            Path(__file__).parent.parent / "data" / "cie1931_d65.csv", delimiter=",", skiprows=5
        )
    return _CIE


def spectrum_to_rgb(wavelengths, values, *, emitter: bool = False) -> np.ndarray:
    """Linear sRGB of a piecewise-linear spectrum, as Mitsuba 3's RGB variants read it.

    Parameters
    ----------
    wavelengths : (N,) float
        Increasing wavelengths in nm (N >= 2).
    values : (N,) float
        The spectrum at those wavelengths; zero outside them.
    emitter : bool
        A radiance (integrated against the CIE matching functions, unclamped)
        instead of a reflectance (weighted by the D65 illuminant so that a flat
        spectrum stays grey, clamped to [0, 1]).

    Returns
    -------
    (3,) float64

    Notes
    -----
    docs/design.md §12: 1000 samples between 360 and 830 nm, the CIE 1931
    2-degree observer, normalised by the integral of ``y`` (``y * D65`` for a
    reflectance), then XYZ to linear sRGB.
    """
    w = np.asarray(wavelengths, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    if w.ndim != 1 or w.shape != v.shape or len(w) < 2 or np.any(np.diff(w) <= 0):
        raise ValueError(
            f"spectrum: need >= 2 increasing wavelengths with one value each, got {w.tolist()}"
        )
    t = _cie_table()
    x = CIE_MIN + np.arange(1000) / 999.0 * (CIE_MAX - CIE_MIN)
    x = x[(x >= w[0]) & (x <= w[-1])]
    y = np.interp(x, w, v)
    xyz = np.stack([np.interp(x, t[:, 0], t[:, k]) for k in (1, 2, 3)], axis=1)
    if not emitter:
        xyz *= np.interp(x, t[:, 0], t[:, 4])[:, None]
    # (the sum is a Riemann sum of step (830 - 360) / 1000 nm)
    norm = (CIE_MAX - CIE_MIN) / 1000 * _CIE_Y_NORM
    rgb = _XYZ_TO_SRGB @ ((xyz * y[:, None]).sum(axis=0) * norm)
    return rgb if emitter else np.clip(rgb, 0.0, 1.0)
