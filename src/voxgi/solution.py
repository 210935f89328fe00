"""The radiosity of a voxel set and its ``.npz`` file format.

:class:`Solution` holds what :func:`voxgi.solve` found for every record of a
:class:`~voxgi.VoxelSet`; :meth:`Solution.save` and :meth:`Solution.load`
write and read it with its records (the scene stays with its own files).
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from .io import atomic_path, check_solution_records, read_npz
from .voxels import PIECE_FIELDS, VoxelSet

__all__ = ["Solution"]


@dataclass
class Solution:
    """Radiosity of every record of a :class:`VoxelSet`.

    Attributes
    ----------
    vox : VoxelSet
        The records solved for.
    radiosity : (N, 3) float32
        ``B`` per record (W/m² per channel, i.e. ``pi`` times radiance).
    bounces : int
        Gathering iterations run.
    residuals : list of float
        Relative residual after each iteration.
    stats : dict
        ``rays``, ``shoot_rays``, ``gather_rays``, ``seconds`` (phase -> s),
        and what was skipped.
    base_radiosity : (N, 3) float32 or None
        The part of each record's reflected radiosity that a glossy
        material's diffuse base reflects (the rest is its coat's, which the
        display follows in direction; ``docs/design.md`` §14); a record
        without a lobe's whole reflected radiosity. None: no glossy record
        (or a solution that did not split it).
    """

    vox: VoxelSet
    radiosity: np.ndarray
    bounces: int = 0
    residuals: list = field(default_factory=list)
    stats: dict = field(default_factory=dict)
    base_radiosity: np.ndarray | None = None

    @property
    def radiance(self) -> np.ndarray:
        """(N, 3) float32 outgoing radiance ``B / pi``."""
        return (self.radiosity / np.float32(np.pi)).astype(np.float32)

    def save(self, path) -> Path:
        """Save records and radiosity to a ``.npz`` file (see :meth:`load`).

        Parameters
        ----------
        path : str or Path
            Destination; ``.npz`` is appended by numpy when missing.

        Returns
        -------
        Path
            The file written.
        """
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_name(path.name + ".npz")
        arrays = {}
        meta = {
            "bounces": int(self.bounces),
            "residuals": [float(r) for r in self.residuals],
            "stats": self.stats,
            "vox_stats": self.vox.stats,
            # (lets a loaded file's object ids be checked against the scene's count)
            "objects": None if self.vox.scene is None else len(self.vox.scene.objects),
        }
        for f in fields(VoxelSet):
            v = getattr(self.vox, f.name)
            if f.name in _NOT_SAVED:
                continue
            if isinstance(v, np.ndarray):
                arrays["vox_" + f.name] = v
            else:
                meta["vox_" + f.name] = v
        arrays["radiosity"] = self.radiosity
        if self.base_radiosity is not None:
            arrays["base_radiosity"] = np.asarray(self.base_radiosity, np.float32)
        arrays["meta"] = np.frombuffer(
            json.dumps(meta, default=_json_default).encode(), dtype=np.uint8
        )
        # (the temporary name keeps the .npz suffix, so numpy adds none)
        with atomic_path(path) as tmp:
            np.savez_compressed(tmp, **arrays)
        return path

    @classmethod
    def load(cls, path) -> Solution:
        """Load a solution written by :meth:`save`.

        Parameters
        ----------
        path : str or Path
            A ``.npz`` file from :meth:`save`.

        Returns
        -------
        Solution
            With its :class:`VoxelSet`.
        """
        import zlib

        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"solution file not found: {path}")
        if path.is_file() and path.stat().st_size == 0:
            raise ValueError(f"{path}: empty file (0 bytes), not a voxgi solution file")
        try:
            sol = cls._load(path)
        except (
            OSError,
            EOFError,
            ValueError,
            KeyError,
            TypeError,
            zlib.error,
            zipfile.BadZipFile,
        ) as exc:
            # (json and Unicode decoding errors are ValueErrors)
            raise ValueError(
                f"{path}: not a readable voxgi solution file ({type(exc).__name__}: {exc})"
            ) from None
        vox = sol.vox
        ijk = np.asarray(vox.ijk)
        if ijk.ndim != 2:
            raise ValueError(f"{path}: vox_ijk must have shape (N, 3), got {ijk.shape}")
        n = len(ijk)
        # Every per-record array has the record count and the type VoxelSet
        # documents: a short one would otherwise load and fail later in render.
        want = {
            "ijk": ((n, 3), np.int32),
            "normal": ((n, 3), np.float32),
            "area": ((n,), np.float32),
            "albedo": ((n, 3), np.float32),
            "emission": ((n, 3), np.float32),
            "centroid": ((n, 3), np.float64),
            "object_id": ((n,), np.int32),
            "back": ((n,), np.bool_),
            "side": ((n,), np.int8),
            "origin": ((3,), np.float64),
        }
        for name, (shape, dtype) in want.items():
            a = getattr(vox, name)
            if a is None and name == "side":
                continue
            a = np.asarray(a)
            if a.shape != shape or a.dtype != dtype:
                raise ValueError(
                    f"{path}: vox_{name} must be {np.dtype(dtype).name} of shape "
                    f"{shape} for {n} records, got {a.dtype} {a.shape}"
                )
            if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
                raise ValueError(f"{path}: vox_{name} has non-finite values")
        if n and ijk.min() < 0:
            raise ValueError(f"{path}: vox_ijk has negative voxel coordinates")
        if not (np.isfinite(vox.pitch) and vox.pitch > 0) or vox.resolution < 2:
            raise ValueError(f"{path}: bad grid (pitch {vox.pitch}, resolution {vox.resolution})")
        r = np.asarray(sol.radiosity)
        if r.shape != (n, 3) or r.dtype.kind != "f":
            raise ValueError(
                f"{path}: radiosity must be floats of shape ({n}, 3), got {r.dtype} {r.shape}"
            )
        with np.errstate(over="ignore"):
            sol.radiosity = r.astype(np.float32)
        if not np.all(np.isfinite(sol.radiosity)):
            raise ValueError(f"{path}: radiosity has values that are not finite in float32")
        if sol.base_radiosity is not None:
            b = np.asarray(sol.base_radiosity)
            if b.shape != (n, 3) or b.dtype != np.float32:
                raise ValueError(
                    f"{path}: base_radiosity must be float32 of shape ({n}, 3), "
                    f"got {b.dtype} {b.shape}"
                )
            bad = np.flatnonzero(~(np.isfinite(b) & (b >= 0)).all(axis=1))
            if len(bad):
                raise ValueError(
                    f"{path}: base_radiosity of record {bad[0]} is {b[bad[0]].tolist()}, "
                    "expected finite and >= 0"
                )
        check_solution_records(vox, sol.radiosity, str(path), sol.stats.pop("objects", None))
        return sol

    @classmethod
    def _load(cls, path: Path) -> Solution:
        # each array's .npy header is checked against its shape before it is read
        z = read_npz(path, _FILE_ARRAYS)
        meta = json.loads(bytes(z["meta"]).decode())
        kw = {}
        for f in fields(VoxelSet):
            if "vox_" + f.name in z:
                kw[f.name] = z["vox_" + f.name]
            elif "vox_" + f.name in meta:
                kw[f.name] = meta["vox_" + f.name]
        kw["stats"] = meta.get("vox_stats", {})
        kw["pitch"] = float(kw["pitch"])
        kw["resolution"] = int(kw["resolution"])
        vox = VoxelSet(**kw)
        sol = cls(
            vox=vox,
            radiosity=z["radiosity"],
            bounces=meta["bounces"],
            residuals=meta["residuals"],
            stats=meta["stats"],
            base_radiosity=z["base_radiosity"] if "base_radiosity" in z else None,
        )
        sol.stats["objects"] = meta.get("objects")
        return sol


#: Fields of the records a solution file leaves out: the scene stays with its
#: files, and the pieces serve the solve's traced passes alone, which a
#: loaded solution does not run again (a solve of loaded records searches
#: each landing instead).
_NOT_SAVED = ("stats", "scene", *PIECE_FIELDS)

#: The arrays of a solution file: shape ("n": the record count) and dtype.
_FILE_ARRAYS = {
    "vox_ijk": (("n", 3), np.int32),
    "meta": ((-1,), np.uint8),
    "vox_normal": (("n", 3), np.float32),
    "vox_area": (("n",), np.float32),
    "vox_albedo": (("n", 3), np.float32),
    "vox_emission": (("n", 3), np.float32),
    "vox_centroid": (("n", 3), np.float64),
    "vox_object_id": (("n",), np.int32),
    "vox_back": (("n",), np.bool_),
    "vox_side": (("n",), np.int8),
    "vox_origin": ((3,), np.float64),
    "radiosity": (("n", 3), (np.float32, np.float64)),
    "base_radiosity": (("n", 3), np.float32),
}


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"cannot store {type(o).__name__} in Solution stats")
