"""voxgi: voxel-based global illumination.

Linear-complexity discrete-line radiosity on sparse surface voxels
(Malgouyres 2002; Chatelier & Malgouyres 2006; Piwowar & Malgouyres 2008),
displayed without aliasing by progressive VPL ray tracing (Piwowar &
Malgouyres, "Affichage non aliasé pour l'illumination globale par voxels").

>>> import voxgi
>>> scene = voxgi.scenes.cornell_box(width=64, height=64)
>>> vox = voxgi.voxelize(scene, resolution=32)
>>> sol = voxgi.solve(vox, radius=4, progress=False)
>>> out = voxgi.render(scene, sol, max_frames=2, progress=False)
>>> out.image.shape
(64, 64, 3)
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from . import _core, denoise, formats, io, metrics, scenes
from .camera import Camera
from .display import RenderResult, RenderTuning
from .formats import SceneWarning
from .lights import DirectionalLight, Environment, PointLight, SpotLight
from .materials import AshikhminShirley, Material, glass_transmittance
from .microfacet import CONDUCTORS, Microfacet
from .pipeline import render, solve
from .radiosity import Solution, SolveTuning
from .scene import Scene, SceneObject
from .textures import Texture
from .voxels import VoxelSet, voxelize

try:
    __version__ = version("voxgi")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = getattr(_core, "__version__", "0+unknown")

__all__ = [
    "CONDUCTORS",
    "AshikhminShirley",
    "Camera",
    "DirectionalLight",
    "Environment",
    "Material",
    "Microfacet",
    "PointLight",
    "RenderResult",
    "RenderTuning",
    "Scene",
    "SceneObject",
    "SceneWarning",
    "Solution",
    "SolveTuning",
    "SpotLight",
    "Texture",
    "VoxelSet",
    "__version__",
    "denoise",
    "formats",
    "glass_transmittance",
    "io",
    "metrics",
    "render",
    "scenes",
    "solve",
    "voxelize",
]
