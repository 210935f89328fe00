"""The ray budget: VPLs per frame and gather rays per pixel from how evenly
the light is spread (``docs/design.md`` §6)."""

from __future__ import annotations

import numpy as np

from ..lights import LUMINANCE

__all__ = ["FILTERED_BUDGET", "RAY_BUDGETS", "SPREAD_EVEN", "light_spread", "ray_budget"]

#: (VPLs per frame, gather rays per pixel and frame) of :func:`ray_budget`
#: for concentrated light and for light spread evenly. Concentrated light is
#: found by VPLs drawn by power, even light by cosine gather rays, whose MIS
#: weight then barely depends on where they land. Both gather counts are
#: squares, so the rays are stratified in both angles (3 x 3 and 5 x 5 cells),
#: where any other count is stratified in one (``docs/design.md`` §6).
RAY_BUDGETS = ((16, 9), (8, 25))

#: The budget for concentrated light where the indirect light is filtered
#: (:attr:`RenderTuning.indirect_filter`) or the image denoised
#: (:attr:`RenderTuning.denoise`): the filter or the denoiser takes most of
#: the noise, and what is left needs fewer rays; where the stopping rule's
#: floor of frames ends a render, cheaper frames are what saves time
#: (``docs/design.md`` §6; the measurements in ``docs/performance.md``).
FILTERED_BUDGET = (8, 4)

#: :func:`light_spread` from which the light counts as spread evenly. The
#: spread alone does not rank the two budgets between about 0.4 and 0.6, so
#: the threshold sits above that range and below a uniform sky (about 0.95)
#: and a furnace (1), where the gather rays' budget wins clearly
#: (``docs/design.md`` §6).
SPREAD_EVEN = 0.8


def light_spread(sol) -> float:
    """How evenly the light of a solution covers the scene's surfaces.

    ``(Σ ΔA·B)² / (Σ ΔA · Σ ΔA·B²)`` over the front records, with ``B`` the
    luminance of their radiosity: 1 when every surface is equally bright (a
    furnace), about the share of the area that carries the light when a few
    surfaces do (0.025 in the Cornell box, 0.18 in a room lit through a
    window), 0 with no light.

    Parameters
    ----------
    sol : Solution

    Returns
    -------
    float in [0, 1]
    """
    vox = sol.vox
    area = np.asarray(vox.area, dtype=np.float64)
    lum = np.asarray(sol.radiosity, dtype=np.float64) @ LUMINANCE
    front = area > 0
    if vox.back is not None:
        front &= ~np.asarray(vox.back, dtype=bool)
    a, b = area[front], np.maximum(lum[front], 0.0)
    second = float(np.sum(a * b * b)) * float(np.sum(a))
    return float(np.sum(a * b)) ** 2 / second if second > 0 else 0.0


def ray_budget(
    spread: float, vpls: int | None = None, gather: int | None = None, *, filtered: bool = False
):
    """VPLs per frame and gather rays per pixel for light of this spread.

    VPLs drawn by power go where the light comes from, gather rays where a
    pixel looks: light from a few bright surfaces needs the first, light that
    comes evenly from everywhere the second (``docs/design.md`` §6). Under a
    spread of :data:`SPREAD_EVEN` the budget is the first of
    :data:`RAY_BUDGETS`, or :data:`FILTERED_BUDGET` where the indirect light
    is filtered or the image denoised; from it on the second. A number given is kept.

    Parameters
    ----------
    spread : float
        :func:`light_spread` of the solution.
    vpls, gather : int or None
        Chosen counts (None: from the spread).
    filtered : bool
        The render filters the indirect light (:attr:`RenderTuning.indirect_filter`)
        or denoises the image (:attr:`RenderTuning.denoise`).

    Returns
    -------
    (int, int)
        VPLs per frame, gather rays per pixel and frame.

    >>> ray_budget(0.025), ray_budget(0.025, filtered=True), ray_budget(1.0, gather=0)
    ((16, 9), (8, 4), (8, 0))
    """
    even = spread >= SPREAD_EVEN
    k, g = FILTERED_BUDGET if filtered and not even else RAY_BUDGETS[even]
    return (k if vpls is None else int(vpls)), (g if gather is None else int(gather))


def _reflects_light(sol) -> bool:
    """Whether any record that does not emit carries light (what the
    indirect filter would filter)."""
    vox = sol.vox
    keep = ~np.any(np.asarray(vox.emission) > 0, axis=1) & (np.asarray(vox.area) > 0)
    if vox.back is not None:
        keep &= ~np.asarray(vox.back, dtype=bool)
    return bool(np.any(np.asarray(sol.radiosity)[keep] > 0))
