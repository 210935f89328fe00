"""What every scene-file reader shares: the data a loader returns, the warning
that lists what it approximated or left out, and the albedo bound."""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


class SceneWarning(UserWarning):
    """A scene file held something voxgi approximated or left out."""


@dataclass
class MeshData:
    """One mesh of a loaded scene, in world space.

    ``vertices`` (V, 3) float64, ``faces`` (F, 3) int64 (counter-clockwise
    around the front normal), ``albedo`` and ``emission`` (3,) float64 linear
    RGB (emission is radiance), ``two_sided`` as :meth:`voxgi.Scene.add`;
    a sheet's ``transmittance`` makes it a transmitting sheet (its albedo
    and emission unused); ``texture`` and ``uv`` as :class:`voxgi.Material`
    and ``Scene.add`` take them (the texture's mean in ``albedo``).
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    albedo: np.ndarray
    emission: np.ndarray
    two_sided: bool = False
    source: str | None = None
    #: (3,) float64 straight-through transmittance of a sheet (glass,
    #: ``docs/design.md`` §13), or None: opaque
    transmittance: np.ndarray | None = None
    #: a voxgi.Texture of the albedo (its factor included), or None
    texture: object = None
    #: (V, 2) float64 texture coordinates (v = 0 the image's top row), or None
    uv: np.ndarray | None = None
    #: a voxgi.Microfacet lobe (its diffuse base in ``albedo``), or None
    specular: object = None


@dataclass
class SceneData:
    """What a loader read: meshes, the keyword arguments of a Camera (or None),
    and the lights in the tables of a TOML scene."""

    meshes: list[MeshData] = field(default_factory=list)
    camera: dict | None = None
    #: ``[[light]]`` tables of a TOML scene (``type`` and the light's fields)
    lights: list[dict] = field(default_factory=list)
    #: the ``[environment]`` table of a TOML scene, or None
    environment: dict | None = None


#: Largest albedo a Material holds (below 1 in float32, docs/design.md §12).
ALBEDO_MAX = float(np.nextafter(np.float32(1.0), np.float32(0.0)))


class Notes:
    """What a loader approximated or dropped, for one warning per kind."""

    def __init__(self, path: Path):
        self.path = path
        self.approximated: list[str] = []
        self.unsupported: list[str] = []

    def approx(self, what: str) -> None:
        if what not in self.approximated:
            self.approximated.append(what)

    def drop(self, what: str) -> None:
        if what not in self.unsupported:
            self.unsupported.append(what)

    def emit(self) -> None:
        # stacklevel 4: the warning points at the caller of Scene.load
        if self.approximated:
            warnings.warn(
                SceneWarning(f"{self.path}: approximated: " + "; ".join(self.approximated)),
                stacklevel=4,
            )
        if self.unsupported:
            warnings.warn(
                SceneWarning(
                    f"{self.path}: not supported, left out: " + "; ".join(self.unsupported)
                ),
                stacklevel=4,
            )


def clamp_albedo(albedo, what: str, notes: Notes) -> np.ndarray:
    a = np.asarray(albedo, dtype=np.float64)
    if np.any(a > ALBEDO_MAX):
        notes.approx(f"{what}: albedo {a.tolist()} clamped below 1")
        a = np.minimum(a, ALBEDO_MAX)
    return a


#: An OBJ face that names texture coordinates (``f 1/1 ...``).
_OBJ_FACE_WITH_VT = re.compile(rb"^f[ \t]+[^ \t/]+/[^ \t/]", re.MULTILINE)


def load_trimesh(data: bytes, file_type: str, **kwargs):
    """``trimesh.load`` of a mesh file's bytes, keeping the file's vertex order
    and its UVs.

    With ``maintain_order=True`` trimesh drops the UVs of an OBJ whose faces
    name texture coordinates when a vertex no face uses lies among the used
    ones (Bitterli's meshes hold such vertices), and the texture would be lost
    without a word. Such a file is read again without keeping the order:
    trimesh then drops the unused vertices and keeps each used one's UV.
    """
    import trimesh

    def load(maintain_order: bool):
        with warnings.catch_warnings():
            # trimesh's numpy warnings on such a file's texture coordinates
            # (an all-NaN median) say nothing about the geometry read
            warnings.simplefilter("ignore", RuntimeWarning)
            return trimesh.load(
                trimesh.util.wrap_as_stream(data),
                file_type=file_type,
                process=False,
                maintain_order=maintain_order,
                **kwargs,
            )

    mesh = load(True)
    if file_type == "obj" and _OBJ_FACE_WITH_VT.search(data) and _lost_uv(mesh):
        mesh = load(False)
    return mesh


def _lost_uv(loaded) -> bool:
    """Whether any mesh of ``loaded`` (a mesh or a scene) came without UVs."""
    meshes = loaded.geometry.values() if hasattr(loaded, "geometry") else [loaded]
    return any(getattr(getattr(m, "visual", None), "uv", None) is None for m in meshes)
