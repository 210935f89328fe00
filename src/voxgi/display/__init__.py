"""Anti-aliased display: progressive VPL ray tracing of a voxel solution.

The camera rays are traced with Embree; every record of the voxel solution is
a potential virtual point light (VPL); each progressive frame shades every
pixel with a few VPLs, drawn in proportion to power, from one of up to 256
independent sets dealt to the pixels at random each frame, and with one sub-pixel offset and one
lens sample shared by all pixels (Piwowar & Malgouyres, section 6;
``docs/design.md`` §6). Only this phase depends on the camera: a new view of
a solved scene costs only the display.

One module per concept: :mod:`~voxgi.display.samples` (each frame's
sub-pixel offset and lens point), :mod:`~voxgi.display.pixel_filter`,
:mod:`~voxgi.display.vpls` (the VPL sampler), :mod:`~voxgi.display.shader`
(one frame's shading), :mod:`~voxgi.display.executor` (where frames run),
:mod:`~voxgi.display.budget` (rays per frame), :mod:`~voxgi.display.estimate`
(the error estimate and stopping rule), :mod:`~voxgi.display.settings`
(:class:`RenderTuning`) and :mod:`~voxgi.display.progressive`
(:func:`render`).
"""

from __future__ import annotations

from .budget import FILTERED_BUDGET, RAY_BUDGETS, SPREAD_EVEN, light_spread, ray_budget
from .estimate import PIXEL_FACTOR, PIXEL_SHARE
from .executor import FrameExecutor, FrameShaderSpec, LocalFrames
from .pixel_filter import gaussian_pixel_filter
from .progressive import RenderResult, render
from .samples import camera_rays, frame_samples
from .settings import RenderTuning
from .shader import frame_surface
from .vpls import VPLSampler

__all__ = [
    "FILTERED_BUDGET",
    "PIXEL_FACTOR",
    "PIXEL_SHARE",
    "RAY_BUDGETS",
    "SPREAD_EVEN",
    "FrameExecutor",
    "FrameShaderSpec",
    "LocalFrames",
    "RenderResult",
    "RenderTuning",
    "VPLSampler",
    "camera_rays",
    "frame_samples",
    "frame_surface",
    "gaussian_pixel_filter",
    "light_spread",
    "ray_budget",
    "render",
]
