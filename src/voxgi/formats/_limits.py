"""The budgets a scene file is read within: bytes, elements, includes, pixels.

Every limit is checked before the work it bounds (a file's size before it is
read, a mesh's decompressed size from its header's counts before it is
inflated, a texture's pixel count from its header before it is decoded), so
that a few hostile bytes cannot take the memory or the time of the machine.
Each limit is raised for one call with ``Scene.load(..., limits=Limits(...))``
or for a process (the command line included) with an environment variable
``VOXGI_MAX_<NAME>`` (docs/scene-files.md).
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass

__all__ = ["Limits", "RefusedError"]

_GIB = 1 << 30


class RefusedError(ValueError):
    """A file refused by a limit or by the path policy (not a broken file)."""


@dataclass(frozen=True)
class Limits:
    """How much a scene file may make voxgi read, inflate, parse and decode.

    Parameters
    ----------
    file_bytes : int
        Size of any one file a scene reads (the scene file, its includes,
        meshes, material libraries, buffers, textures, spectra).
    mesh_bytes : int
        Decompressed size of one compressed mesh (a Mitsuba ``serialized``
        shape), as its header's vertex and triangle counts give it.
    elements : int
        XML elements of a scene, counted across all its included files.
    includes : int
        Files a scene includes, counted over the whole scene (not only in
        depth).
    texture_pixels : int
        Pixels of one texture (width times height, from its header).

    Notes
    -----
    The defaults read the environment variables ``VOXGI_MAX_FILE_BYTES``,
    ``VOXGI_MAX_MESH_BYTES``, ``VOXGI_MAX_ELEMENTS``, ``VOXGI_MAX_INCLUDES``,
    and ``VOXGI_MAX_TEXTURE_PIXELS`` when they are set (:meth:`from_env`).

    Examples
    --------
    >>> from voxgi.formats import Limits
    >>> Limits().texture_pixels
    178956970
    >>> Limits(file_bytes=8 << 30).file_bytes
    8589934592
    """

    file_bytes: int = _GIB
    mesh_bytes: int = 2 * _GIB
    elements: int = 1_000_000
    includes: int = 10_000
    texture_pixels: int = 178_956_970  # Pillow's own default bound

    def __post_init__(self):
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"Limits.{f.name}: expected an integer >= 1, got {v!r}")

    @classmethod
    def from_env(cls) -> Limits:
        """The defaults, each replaced by its ``VOXGI_MAX_<NAME>`` variable when set."""
        kw = {}
        for f in dataclasses.fields(cls):
            var = f"VOXGI_MAX_{f.name.upper()}"
            text = os.environ.get(var)
            if text is None:
                continue
            try:
                kw[f.name] = int(text.replace("_", ""))
            except ValueError:
                raise ValueError(f"{var}={text!r}: expected an integer") from None
        return cls(**kw)

    def check(self, name: str, value: int, what: str) -> None:
        """Raise a ValueError naming ``what`` if ``value`` exceeds the limit ``name``."""
        limit = getattr(self, name)
        if value > limit:
            raise RefusedError(
                f"{what}: {value:,} {_UNITS[name]}, above the limit of {limit:,} "
                f"(raise it with Scene.load(..., limits=voxgi.formats.Limits({name}=...)) "
                f"or the environment variable VOXGI_MAX_{name.upper()})"
            )


_UNITS = {
    "file_bytes": "bytes",
    "mesh_bytes": "bytes once decompressed",
    "elements": "XML elements",
    "includes": "included files",
    "texture_pixels": "pixels",
}
