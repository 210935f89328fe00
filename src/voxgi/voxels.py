"""Surface voxelization: triangle meshes -> sparse oriented surface records."""

from __future__ import annotations

import gc
import math
import time
from dataclasses import dataclass, field

import numpy as np

from . import _validate
from ._solids import bury, is_closed, seal
from .textures import surface_tables

__all__ = ["DEFAULT_RESOLUTION", "VoxelSet", "estimate_memory", "voxelize"]


@dataclass
class VoxelSet:
    """Sparse surface records of a voxelized scene.

    One record per voxel, object, orientation cluster, sheet of a stack
    (layer), side of the other surfaces' planes in the voxel, and side of
    the surface; see :func:`voxelize`. The record arrays have length
    ``N = len(vox)``; the ``piece_*`` arrays list where each triangle's
    pieces went.

    Attributes
    ----------
    ijk : (N, 3) int32
        Integer voxel coordinates; voxel ``ijk`` spans
        ``origin + pitch * [ijk, ijk + 1]``.
    normal : (N, 3) float32
        Unit normal, area-weighted over the record's pieces.
    area : (N,) float32
        Surface area represented, scene units²: the exact area of the
        record's triangles clipped to the voxel. The front records
        (``side == 0``) sum to the scene's area; every reverse-side record
        repeats its front record's area, so ``area.sum()`` is twice it. It
        is 0 for a surface that only touches the voxel's closed cube (kept:
        the voxel must still block lines, docs/design.md §2); see
        ``stats["touch_records"]``.
    albedo, emission : (N, 3) float32
        The object's albedo and emitted radiance (0 on black back records).
    centroid : (N, 3) float64
        A point on the surface inside the voxel (where a VPL sits).
    object_id : (N,) int32
        Index of the scene object the record comes from.
    back : (N,) bool
        True for the black back record of a one-sided surface.
    pitch : float
        Voxel edge length.
    origin : (3,) float64
        World position of voxel (0, 0, 0)'s minimum corner.
    resolution : int
        Voxels along the longest side of the bounding box.
    scene_fingerprint : str
        :meth:`voxgi.Scene.fingerprint` of the scene voxelized.
    stats : dict
        Timings and counts (``seconds``, ``triangles``, ``skipped``...).
    side : (N,) int8 or None
        0 for the side the triangles' winding faces, 1 for the reverse side
        (the back record of a one-sided surface, or the second live side of
        a two-sided one). Every side-1 record directly follows its side-0
        record, with the same voxel, area and centroid and the opposite normal.
    scene : Scene or None
        The scene voxelized (set by :func:`voxelize`; None for records loaded
        from a file). The solve traces its exact triangles for direct light.
    piece_triangle : (M,) int32 or None
        For each piece of a triangle in a voxel (with area), once per
        record pair its area went to: the triangle, by its index in
        ``scene.triangles()``.
    piece_record : (M, 2) int32 or None
        That part's records in that voxel: on the side the triangle's
        winding faces, and on the other. A traced pass's ray that lands on
        the triangle there reads them without searching the voxel
        (``docs/design.md`` §5). None for records loaded from a file: a
        solve of them searches every landing.
    piece_plane_first : (M + 1,) int64 or None
    piece_plane : (P, 4) float64 or None
        Entry m's planes, rows ``[piece_plane_first[m],
        piece_plane_first[m + 1])`` of ``piece_plane``: ``(n, off)`` with
        ``n·x = off`` in voxel units (``x = (world - origin) / pitch``),
        the cutting planes that split its piece (none for a piece whole in
        one record pair).
    piece_side : (M,) uint32 or None
        Bit k set where entry m's part lies on the positive side
        (``n·x >= off``) of its k-th plane.
    """

    ijk: np.ndarray
    normal: np.ndarray
    area: np.ndarray
    albedo: np.ndarray
    emission: np.ndarray
    centroid: np.ndarray
    object_id: np.ndarray
    back: np.ndarray
    pitch: float
    origin: np.ndarray
    resolution: int
    scene_fingerprint: str = ""
    stats: dict = field(default_factory=dict)
    side: np.ndarray | None = None
    scene: object = field(default=None, repr=False, compare=False)
    piece_triangle: np.ndarray | None = field(default=None, repr=False)
    piece_record: np.ndarray | None = field(default=None, repr=False)
    piece_plane_first: np.ndarray | None = field(default=None, repr=False)
    piece_plane: np.ndarray | None = field(default=None, repr=False)
    piece_side: np.ndarray | None = field(default=None, repr=False)

    def __len__(self) -> int:
        return int(self.ijk.shape[0])

    def __repr__(self) -> str:
        return (
            f"VoxelSet({len(self)} records, resolution={self.resolution}, "
            f"pitch={self.pitch:.4g}, emitters={int(self.is_emitter.sum())})"
        )

    def positions(self) -> np.ndarray:
        """(N, 3) float64 world-space voxel centres."""
        return self.origin + (self.ijk.astype(np.float64) + 0.5) * self.pitch

    @property
    def is_emitter(self) -> np.ndarray:
        """(N,) bool: records with non-zero emission."""
        return np.any(self.emission > 0, axis=1)


# Bytes per (voxel, triangle) pair and per record in the C++ kernel
# (csrc/voxelize.h: Pair is 16 bytes, VoxelRecord 88), per record in the
# numpy arrays returned (ijk 12, normal 12, area 4, albedo 12, emission 12,
# centroid 24, object_id 4, back 1, side 1), and per triangle on the Python
# side: the concatenated corners and object ids (76), the estimate's own
# temporaries (about 100), and trimesh's watertight and winding checks of
# each object (about 300; 284 measured on a 940,544-triangle bunny).
_PAIR_BYTES = 16
_KERNEL_RECORD_BYTES = 88
_ARRAY_RECORD_BYTES = 82
_TRIANGLE_BYTES = 76
_ESTIMATE_TRIANGLE_BYTES = 100
_CLOSED_CHECK_TRIANGLE_BYTES = 300
#: Margin on the estimate for what the model leaves out (cut records,
#: allocator slack): the estimate sits above the measured peak, within 2x.
_MARGIN = 1.25


def estimate_memory(triangles: np.ndarray, pitch: float) -> dict:
    """Peak memory of the voxelization, estimated from the triangles before any allocation.

    Parameters
    ----------
    triangles : (F, 3, 3) float64
        Triangle corners, scene units.
    pitch : float
        Voxel edge, scene units.

    Returns
    -------
    dict
        ``bytes`` (estimated peak bytes the call adds, with a 25% margin),
        ``expected_pairs`` and ``expected_records`` (the counts it rests
        on), ``pairs`` and ``records`` (upper bounds of those counts).

    Notes
    -----
    The voxels whose closed cube meets a triangle T have their minimum
    corners in T ⊕ [-1, 0]³ (voxel units). Under a random shift of the grid
    their expected number is the volume of T ⊕ [0, 1]³, by the mixed-volume
    formula for a sum with segments (vol(K + s) = vol(K) + |s| area(K
    projected along s)) ``A ||n||_1 + Δx + Δy + Δz + 1``, with A the area,
    n the unit normal and Δ the bounding-box extents in voxel units (the
    ``‖n‖₁ A/h²`` of docs/design.md §2 plus edge and corner terms); on the
    bunny it matches the kernel's count to 0.1%. The same formula with a
    cube of edge 2, ``2 A ||n||_1 + 4 (Δx + Δy + Δz) + 8``, bounds it.

    Records are per voxel, not per pair: the voxels a surface meets number
    about ``Σ A ||n||_1`` (without the edge terms, which adjacent triangles
    share; within 0.3% of the kernel's count on the bunny from 3,674 to
    3,762,176 triangles), each with a front and a reverse record. Small
    triangles thus give many pairs but few records.

    The peak is the largest of the phases' live buffers: the pairs and their
    radix-sort buffer; the pairs, voxel starts and kernel records; the
    kernel records and the numpy arrays made from them; the arrays and the
    closed-mesh check; all with the concatenated triangles. Against the peak
    RSS growth measured in a fresh process, the estimate (margin included)
    is 1.17-1.33 times it on the bunny (3,674 triangles at resolution
    128-512, 940,544 at 128 and 512, 3,762,176 at 128) and the Cornell box
    at 896 (10.4 million records).
    """
    t = np.asarray(triangles, dtype=np.float64)
    n_tri = len(t)
    a, b, c = t[:, 0], t[:, 1], t[:, 2]
    # A ||n||_1 = ||cross||_1 / 2, in voxel units².
    an1 = (0.5 / pitch**2) * np.abs(np.cross(b - a, c - a)).sum(axis=1)
    # (Elementwise max/min of the corners: much faster than reducing axis 1.)
    ext = (np.maximum(np.maximum(a, b), c) - np.minimum(np.minimum(a, b), c)).sum(axis=1) / pitch
    bound_pairs = float(np.sum(2.0 * an1 + 4.0 * ext + 8.0))
    pairs = float(np.sum(an1 + ext + 1.0))
    cells = min(pairs, float(an1.sum()) + 1.0)
    records = 2.0 * cells
    tri_bytes = _TRIANGLE_BYTES * n_tri
    nbytes = tri_bytes + max(
        _ESTIMATE_TRIANGLE_BYTES * n_tri,  # this estimate
        2 * _PAIR_BYTES * pairs,  # pairs + radix buffer
        _PAIR_BYTES * pairs + 8 * cells + _KERNEL_RECORD_BYTES * records,  # pairs -> records
        (_KERNEL_RECORD_BYTES + _ARRAY_RECORD_BYTES) * records,  # records -> numpy
        _ARRAY_RECORD_BYTES * records + _CLOSED_CHECK_TRIANGLE_BYTES * n_tri,
    )  # closed check
    return {
        "bytes": math.ceil(_MARGIN * nbytes),
        "expected_pairs": math.ceil(pairs),
        "expected_records": math.ceil(records),
        "pairs": math.ceil(bound_pairs),
        "records": math.ceil(2.0 * bound_pairs),
    }


def available_memory() -> int:
    """Bytes of memory available to new allocations now (psutil's ``available``);
    the stages check their estimates against it before allocating."""
    import psutil

    return int(psutil.virtual_memory().available)


def _progress_bar(enabled: bool):
    """A callable(phase, done, total) driving a progress bar, and a closer."""
    if not enabled:
        return None, lambda: None
    from . import _progress

    names = {1: "voxelize: triangles", 2: "voxelize: sorting", 3: "voxelize: voxels"}
    state = {"phase": 0, "bar": None}

    def update(phase: int, done: int, total: int) -> None:
        if phase != state["phase"]:
            if state["bar"] is not None:
                state["bar"].close()
            state["bar"] = _progress.bar(names.get(phase, "voxelize"), max(int(total), 1))
            state["phase"] = phase
        bar = state["bar"]
        bar.update(max(0, int(done) - bar.n))

    def close() -> None:
        if state["bar"] is not None:
            state["bar"].close()

    return update, close


def _check_arguments(scene, resolution, max_memory, threads, progress, cut):
    """Validate :func:`voxelize`'s arguments; returns ``(resolution, max_memory, threads)``."""
    from .scene import Scene

    if not isinstance(scene, Scene):
        raise TypeError(f"voxelize: expected a voxgi.Scene, got {type(scene).__name__}")
    resolution = _validate.integer(resolution, "voxelize: resolution", low=2, high=1 << 20)
    if max_memory is not None:
        max_memory = _validate.integer(max_memory, "voxelize: max_memory", low=1)
    nthreads = _validate.threads(threads, "voxelize: threads")
    if not isinstance(progress, (bool, np.bool_)):
        raise TypeError(f"voxelize: progress must be a bool, got {progress!r}")
    if not isinstance(cut, (bool, np.bool_)):
        raise TypeError(f"voxelize: cut must be a bool, got {cut!r}")
    scene.check_nonempty()
    return resolution, max_memory, nthreads


def _grid(triangles: np.ndarray, resolution: int) -> tuple[float, np.ndarray, np.ndarray]:
    """The voxel grid ``(pitch, origin, dims)`` around the triangles' bounding box."""
    lo = triangles.reshape(-1, 3).min(axis=0)
    hi = triangles.reshape(-1, 3).max(axis=0)
    longest = float(np.max(hi - lo))
    if not longest > 0:
        raise ValueError("voxelize: the scene's bounding box has zero size")
    pitch = longest / resolution
    # Areas and normals are float32 (API): a voxel face must be representable
    # with room to spare (normal float32 range ~1e-38 .. 3e38).
    if not 1e-30 <= pitch * pitch <= 1e30:
        raise ValueError(
            f"voxelize: voxel pitch {pitch:.3g} (scene size {longest:.3g} over "
            f"resolution {resolution}) gives voxel areas outside float32's range; "
            "rescale the scene"
        )
    origin = lo - 0.5 * pitch
    dims = (np.floor((hi - origin) / pitch) + 1).astype(np.int32)
    return pitch, origin, dims


def _check_memory(triangles: np.ndarray, pitch: float, resolution: int, max_memory) -> dict:
    """Estimate the peak memory and raise if it is over the budget; returns the estimate."""
    est = estimate_memory(triangles, pitch)
    budget = max_memory if max_memory is not None else available_memory() // 2
    if est["bytes"] > budget:
        raise ValueError(
            f"voxelize: resolution {resolution} needs up to {est['bytes']:,} bytes "
            f"(estimated with a 25% margin from {est['expected_pairs']:,} voxel-triangle pairs, "
            f"{est['expected_records']:,} records for {len(triangles):,} triangles), over the "
            f"budget of {budget:,} bytes "
            f"({'max_memory' if max_memory is not None else 'half the available memory'}); "
            "lower the resolution or raise max_memory"
        )
    return est


def _run_kernel(
    tri: dict, origin, pitch: float, dims, *, cut, threads: int, progress, textures=None
) -> dict:
    """Run the C++ voxelization kernel on the scene's triangles, with a progress bar."""
    from . import _core

    callback, close = _progress_bar(bool(progress))
    try:
        return _core.voxelize(
            tri["triangles"],
            tri["object"],
            tri["two_sided"],
            tri["albedo"],
            tri["emission"],
            np.ascontiguousarray(origin, dtype=np.float64),
            float(pitch),
            dims,
            cut=bool(cut),
            threads=threads,
            progress=callback,
            **(textures or {}),
        )
    finally:
        close()


def _voxelize_stats(
    st: dict, triangles: np.ndarray, est: dict, scene, *, cut, seconds: float
) -> dict:
    """:attr:`VoxelSet.stats` from the kernel's counters and the memory estimate."""
    return {
        "triangles": int(st["triangles"]),
        "records": int(st["records"]),
        "back_records": int(st["back_records"]),
        "two_sided_records": int(st["two_sided_records"]),
        "cells": int(st["cells"]),
        "pairs": int(st["pairs"]),
        "skipped_degenerate": int(st["skipped_degenerate"]),
        "touch_records": int(st["touch_records"]),
        "clusters": int(st["clusters"]),
        "cut_clusters": int(st["cut_clusters"]),
        "cut_records": int(st["cut_records"]),
        "cut_limit_hits": int(st["cut_limit_hits"]),
        "cut_small_planes": int(st["cut_small_planes"]),
        "layer_records": int(st["layer_records"]),
        "polygon_overflows": int(st["polygon_overflows"]),
        "peak_bytes": int(st["peak_bytes"] + triangles.nbytes),
        "estimate_bytes": est["bytes"],
        "estimate_pairs": est["pairs"],
        "expected_pairs": est["expected_pairs"],
        "expected_records": est["expected_records"],
        "threads": int(st["threads"]),
        "cut": bool(cut),
        # Objects whose mesh is closed (watertight, consistently wound): their
        # inside can never be seen, which voxgi.solve uses (closed=None).
        "closed_objects": [
            i for i, o in enumerate(scene.objects) if not o.material.is_sheet and is_closed(o)
        ],
        "seconds": seconds,
        "phase_seconds": {
            "pairs": st["seconds_pairs"],
            "sort": st["seconds_sort"],
            "records": st["seconds_records"],
        },
    }


def _solve_albedo(scene, albedo: np.ndarray, object_id: np.ndarray, back: np.ndarray):
    """The records' albedo as the diffuse solve reflects: a plastic's whole
    hemispherical reflectance (its coat's specular light and its base's light
    through the coat) from the base albedo the kernel gave each record
    (``docs/design.md`` §14); a conductor's is its material's already."""
    from .microfacet import Microfacet

    out = albedo
    for i, o in enumerate(scene.objects):
        lobe = o.material.specular
        if not (isinstance(lobe, Microfacet) and lobe.kind == "plastic"):
            continue
        sel = (object_id == i) & ~back
        if out is albedo:
            out = albedo.copy()
        below_one = np.nextafter(np.float32(1.0), np.float32(0.0))
        out[sel] = np.minimum(lobe.solve_albedo(albedo[sel]), below_one)
    return out


def _voxel_set(res: dict, pitch: float, origin, resolution: int, scene, stats: dict) -> VoxelSet:
    """The :class:`VoxelSet` of the kernel's record arrays on the grid."""
    return VoxelSet(
        ijk=res["ijk"],
        normal=res["normal"],
        area=res["area"],
        albedo=_solve_albedo(scene, res["albedo"], res["object_id"], res["back"]),
        emission=res["emission"],
        centroid=res["centroid"],
        object_id=res["object_id"],
        back=res["back"],
        pitch=float(pitch),
        origin=np.asarray(origin, dtype=np.float64),
        resolution=resolution,
        scene_fingerprint=scene.fingerprint(),
        stats=stats,
        side=res["side"],
        scene=scene,
        **{k: res[k] for k in PIECE_FIELDS},
    )


#: The fields of a :class:`VoxelSet` that list where each triangle's pieces
#: went (all None, or all set).
PIECE_FIELDS = ("piece_triangle", "piece_record", "piece_plane_first", "piece_plane", "piece_side")


#: Voxels along the scene's longest side when :func:`voxelize` is not told:
#: on the Cornell box at 256x256 against a converged path-traced reference,
#: past 64 the display's noise at its default tolerance, not the voxels,
#: sets the picture's error (``docs/design.md`` §5).
DEFAULT_RESOLUTION = 64


def voxelize(
    scene,
    resolution: int = DEFAULT_RESOLUTION,
    *,
    threads: int | None = None,
    progress: bool = False,
    max_memory: int | None = None,
) -> VoxelSet:
    """Convert the surfaces of a scene into oriented surface voxel records.

    Every voxel whose closed cube meets a triangle (the supercover, which no
    26-connected naive discrete line can cross; docs/design.md §2) holds one
    record per object, orientation and side of the other surfaces' planes,
    each followed by its reverse side.

    Parameters
    ----------
    scene : Scene
        Scene to voxelize; left unchanged.
    resolution : int, optional
        Voxels along the longest side of the scene's bounding box (>= 2;
        :data:`DEFAULT_RESOLUTION`, 64, the resolution :func:`voxgi.render`
        voxelizes at).
    threads : int or None, optional
        Worker threads; None uses every hardware thread. The result does not
        depend on it.
    progress : bool, optional
        Show a progress bar (on a terminal or in a notebook).
    max_memory : int or None, optional
        Memory budget in bytes; None means half of the memory available now.
        The peak memory is estimated from the triangles before anything is
        allocated (see :func:`estimate_memory`).

    Returns
    -------
    vox : VoxelSet
        ``ijk`` (N, 3) int32, ``normal`` (N, 3) float32 unit vectors,
        ``area`` (N,) float32 in scene units² (exact: the area of the
        triangles clipped to the cube; ``area.sum()`` is the scene's area),
        ``albedo`` and ``emission`` (N, 3) float32, ``centroid`` (N, 3)
        float64 (a point of the surface inside the voxel), ``object_id``
        (N,) int32, ``back`` (N,) bool, ``side`` (N,) int8. Records are
        sorted by ``(i, j, k)``; inside a voxel by object, orientation
        cluster and side of the cutting planes, each front record followed by
        its reverse side. ``stats`` holds ``triangles``, ``records``,
        ``back_records``, ``cells``, ``skipped_degenerate``, ``peak_bytes``,
        ``estimate_bytes``, ``seconds`` (total) and ``phase_seconds``.

    Raises
    ------
    TypeError
        If ``scene`` is not a :class:`voxgi.Scene` or ``resolution`` is not
        an integer.
    ValueError
        If the scene is empty, ``resolution < 2``, the memory estimate exceeds
        ``max_memory`` (the message gives the estimate), or the voxel size
        is so large or small that float32 areas would overflow (pitch² outside
        [1e-30, 1e30] scene units²).

    Notes
    -----
    ``pitch`` is the longest side of the bounding box over ``resolution``;
    the grid starts half a voxel below the box, so that every index is >= 0
    and axis-aligned faces of the box lie mid-voxel along its longest side.
    The reverse side of a one-sided surface is a black record (``back``
    True: albedo and emission 0) that keeps it opaque from behind; a
    two-sided object's reverse side has its albedo and emission. Triangles
    whose normal underflows at the voxel scale are skipped and counted in
    ``stats["skipped_degenerate"]`` (the scene already drops zero-area faces).

    Examples
    --------
    >>> import voxgi
    >>> vox = voxgi.voxelize(voxgi.scenes.cornell_box(), resolution=32)
    >>> vox.ijk.dtype, vox.area.dtype
    (dtype('int32'), dtype('float32'))
    """
    return _voxelize(
        scene, resolution, threads=threads, progress=progress, max_memory=max_memory, cut=True
    )


def _voxelize(scene, resolution, *, threads, progress, max_memory, cut) -> VoxelSet:
    """:func:`voxelize`; ``cut=False`` keeps each surface's pieces uncut by the
    planes of the other surfaces in their voxel (``docs/design.md`` §4), for
    comparisons only: a floor piece straddling a thin wall then belongs to
    both rooms."""
    t_start = time.perf_counter()
    resolution, max_memory, nthreads = _check_arguments(
        scene, resolution, max_memory, threads, progress, cut
    )
    tri = scene.triangles()
    # The grid spans the whole scene; the sheets (glass) have no records
    # (docs/design.md §13): light crosses them on the rays, not on the lines.
    pitch, origin, dims = _grid(tri["triangles"], resolution)
    sheet = np.array([o.material.is_sheet for o in scene.objects])
    textures = surface_tables(scene)
    kept = None
    if sheet.any():
        keep = ~sheet[tri["object"]]
        if not keep.any():
            raise ValueError("voxelize: every object is a transmitting sheet; nothing to voxelize")
        kept = np.flatnonzero(keep).astype(np.int32)
        tri = {**tri, "triangles": tri["triangles"][keep], "object": tri["object"][keep]}
        if textures is not None:  # (one UV triple per triangle voxelized)
            textures = {**textures, "corner_uv": textures["corner_uv"][keep]}
    triangles = tri["triangles"]
    est = _check_memory(triangles, pitch, resolution, max_memory)
    res = _run_kernel(
        tri,
        origin,
        pitch,
        dims,
        cut=cut,
        threads=nthreads,
        progress=progress,
        textures=textures,
    )
    if kept is not None:  # the pieces' triangles by their index in the whole scene
        res["piece_triangle"] = kept[res["piece_triangle"]]
    stats = _voxelize_stats(dict(res["stats"]), triangles, est, scene, cut=cut, seconds=0.0)
    sealed, inner = seal(res, scene, pitch)
    stats["buried_records"] = bury(res, scene, stats["closed_objects"], pitch, sealed)
    stats["closed_objects"] = sorted(set(stats["closed_objects"]) | set(sealed))
    stats["sealed_objects"] = sorted(sealed)
    # Every mesh the parity tests traced holds an Embree device of embreex's
    # in a reference cycle (the mesh and its ray intersector), which only the
    # cycle collector frees: thousands of them left to it made the next
    # voxelization of a cluttered scene crash inside embreex.
    del sealed
    gc.collect()
    stats["inner_records"] = inner
    stats["seconds"] = time.perf_counter() - t_start
    return _voxel_set(res, pitch, origin, resolution, scene, stats)
