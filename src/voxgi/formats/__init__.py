"""Scene files of other renderers: Mitsuba 3 XML, OBJ with MTL, glTF 2.0.

Each loader reads one file into a :class:`SceneData`: plain arrays and
numbers that :meth:`voxgi.Scene.load` turns into a scene (this package never
imports :mod:`voxgi.scene`, so that ``Scene.load`` can dispatch here). What
voxgi cannot represent exactly (glossy BSDFs, textures, point lights, ...) is
approximated or dropped, and listed in one :class:`SceneWarning` per kind;
the conventions are in docs/design.md §12.

Examples
--------
>>> from voxgi import formats
>>> sorted(formats.LOADERS)
['.glb', '.gltf', '.obj', '.xml']
>>> formats.spectrum_to_rgb([400, 700], [0.5, 0.5]).round(3)
array([0.498, 0.5  , 0.497])
"""

from __future__ import annotations

from . import toml
from ._common import MeshData, SceneData, SceneWarning
from ._limits import Limits, RefusedError
from ._paths import FileAccess
from .gltf import load_gltf
from .mitsuba_translate import load_mitsuba
from .obj import load_obj
from .serialized import read_serialized
from .spectra import spectrum_to_rgb

__all__ = [
    "LOADERS",
    "FileAccess",
    "Limits",
    "MeshData",
    "RefusedError",
    "SceneData",
    "SceneWarning",
    "load_gltf",
    "load_mitsuba",
    "load_obj",
    "read_serialized",
    "spectrum_to_rgb",
    "toml",
]

#: Loaders by file suffix (``.toml`` is read by :meth:`voxgi.Scene.load` itself).
LOADERS = {".xml": load_mitsuba, ".obj": load_obj, ".gltf": load_gltf, ".glb": load_gltf}
