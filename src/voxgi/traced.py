"""Reflected light gathered at the records by rays against the exact triangles.

The propagation carries light along discrete lines whose blockers are voxels
(``docs/design.md`` §4), so a gap narrower than a voxel closes for it, and
where a thin wall meets another surface the records of both rooms can share
a line. The traced gather asks the scene's own triangles instead: from each
record's surface point, cosine-distributed rays find the first triangle, and
the record standing for the hit point (the lookup the display's gather rays
use, §6) gives the radiosity seen there. With ``values`` the records'
radiosity ``B`` and n rays per record,

.. math:: H(x) \\approx \\frac{1}{n} \\sum_{k=1}^{n} B(y_k),

the irradiance of a Lambertian record at x (the rays' density
``cos θ / π`` cancels the integrand's ``cos θ`` and ``1/π``). The cost is
records × rays per pass, whatever the geometry's detail.
"""

from __future__ import annotations

import time

import numpy as np

from . import _core, _validate
from .direct import check_scene_and_records
from .incidence import IncidenceResponse
from .microfacet import LOBE_WIDTH
from .rays import Tracer
from .scene import Scene
from .voxels import VoxelSet

__all__ = [
    "DENSE_TABLE_CELLS",
    "TracedGather",
    "conductor_lobes",
    "grid_positions",
    "record_grid",
    "stacked_records",
    "traced_irradiance",
    "transport_bytes",
]


#: Columns of a row of ``rec_packed``, float32, 64 bytes: the layout of
#: ``PackedRecord`` in ``csrc/vpl_shade.h`` (the object id as an int32's bits).
_CENTROID, _NORMAL, _OBJECT, _PA, _RADIANCE, _ALBEDO, _ROW = (
    slice(0, 3), slice(3, 6), 6, 7, slice(8, 11), slice(11, 14), 16
)  # fmt: skip


def _voxel_order(vox: VoxelSet) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The records' voxel keys on their bounding grid: (lo, dims, key, order),
    ``order`` the records sorted by key (stable)."""
    ijk = np.asarray(vox.ijk, dtype=np.int64)
    lo = ijk.min(axis=0)
    dims = ijk.max(axis=0) - lo + 1
    rel = ijk - lo
    key = (rel[:, 0] * dims[1] + rel[:, 1]) * dims[2] + rel[:, 2]
    return lo, dims, key, np.argsort(key, kind="stable")


def grid_positions(vox: VoxelSet) -> np.ndarray:
    """(N,) int64: each record's row in :func:`record_grid`'s tables (the
    kernels' ``point_record`` and ``transport_record`` index these rows)."""
    return _rows(_voxel_order(vox)[3])


def _rows(order: np.ndarray) -> np.ndarray:
    """(N,) int64: the inverse of the permutation ``order``, each record's row."""
    position = np.empty(len(order), np.int64)
    position[order] = np.arange(len(order))
    return position


#: Cells of the records' bounding grid up to which a lookup reads a dense
#: table of each voxel's first record (4 bytes a cell, 64 MB at most) instead
#: of a binary search over the sorted keys.
DENSE_TABLE_CELLS = 1 << 24


def record_grid(
    vox: VoxelSet,
    centre: np.ndarray,
    radiance: np.ndarray,
    pa: np.ndarray | None = None,
    *,
    dense_cells: int = DENSE_TABLE_CELLS,
    share: np.ndarray | None = None,
    stacked: np.ndarray | None = None,
    pieces: bool | str = False,
) -> dict:
    """The records sorted by voxel, as the compiled gather kernels look them up.

    Parameters
    ----------
    vox : VoxelSet
        The records.
    centre : (3,) float64
        Origin of the tracer's frame (:attr:`voxgi.rays.Tracer.centre`).
    radiance : (N, 3)
        What a ray that lands on each record reads.
    pa : (N,) float32 or None
        Each record's VPL density for the display's MIS (None: zeros, no MIS).
    dense_cells : int
        Largest bounding grid, in cells, given the dense table of each
        voxel's first record; a larger one is searched by voxel key (the same
        answers).
    share : (N, 3) or None
        The base's share of each record's light, which a gather ray that
        follows a glossy record's lobe reads (``docs/design.md`` §14): then
        also ``rec_share`` in the records' key order.
    stacked : (N,) bool or None
        The records where a gather ray bounces once more rather than read
        the record (:func:`stacked_records`): then also ``rec_stacked`` in
        the records' key order.
    pieces : bool or "sheets"
        Also the table of each triangle's pieces (``piece_*``), by which a
        ray reads the record of the piece it lands on, where ``vox`` holds
        its pieces (:attr:`VoxelSet.piece_record`); ``"sheets"``: only to
        tell the ``stacked`` records a ray lands on and to walk them, every
        other lookup searching (``pieces_for_sheets``, the display's).

    Returns
    -------
    dict
        The kernels' ``rec_*``, ``grid_*`` and ``pitch`` keyword arguments.
        ``rec_packed`` holds one 64-byte row a record in key order (centroid,
        normal, object, ``pa``, radiance, albedo), aligned to 64 bytes: a gather ray's
        lookup then reads a cache line or two, where separate arrays cost one
        each.
    """
    order = _voxel_order(vox)
    out = _record_grid(vox, centre, radiance, pa, order, dense_cells)
    if share is not None:
        out["rec_share"] = np.ascontiguousarray(np.asarray(share, np.float32)[order[3]])
    if stacked is not None:
        out["rec_stacked"] = sheet_codes(vox, stacked)[order[3]]
    if pieces:
        table = _piece_table(vox, order[2], order[3])
        out.update(table)
        if pieces == "sheets" and table and stacked is not None:
            out["pieces_for_sheets"] = True
    return out


def sheet_codes(vox: VoxelSet, stacked: np.ndarray) -> np.ndarray:
    """(N,) uint8, the kernels' ``rec_stacked``: 0 where a ray reads the
    record; 1 for a stacked sheet (:func:`stacked_records`), where a ray
    bounces on; 2 for one that emits, where a ray that lands first bounces
    on but one bounced there from another sheet stops and reads it, its
    emitted light with it (``docs/design.md`` §5)."""
    emits = np.any(np.asarray(vox.emission) > 0, axis=1)
    return np.ascontiguousarray(np.asarray(stacked, bool) * (1 + emits), np.uint8)


def _record_grid(vox, centre, radiance, pa, voxel_order, dense_cells=DENSE_TABLE_CELLS) -> dict:
    """:func:`record_grid` from the records' :func:`_voxel_order`."""
    lo, dims, key, order = voxel_order
    sorted_key = np.ascontiguousarray(key[order])
    cells = int(np.prod(dims))
    if cells <= dense_cells:
        start = np.zeros(cells + 1, np.int32)
        np.cumsum(np.bincount(sorted_key, minlength=cells), out=start[1:])
    else:
        start = np.zeros(0, np.int32)
    n = len(vox)
    buf = np.zeros(n * _ROW + _ROW, np.float32)
    skip = (-buf.ctypes.data % 64) // buf.itemsize
    packed = buf[skip : skip + n * _ROW].reshape(n, _ROW)
    packed[:, _CENTROID] = np.asarray(vox.centroid, np.float64)[order] - centre
    packed[:, _NORMAL] = np.asarray(vox.normal, np.float32)[order]
    packed.view(np.int32)[:, _OBJECT] = np.asarray(vox.object_id, np.int32)[order]
    if pa is not None:
        packed[:, _PA] = np.asarray(pa, np.float32)[order]
    packed[:, _RADIANCE] = np.asarray(radiance, np.float32)[order]
    packed[:, _ALBEDO] = np.asarray(vox.albedo, np.float32)[order]
    return {
        "rec_sorted_key": sorted_key,
        "rec_cell_start": start,
        "rec_packed": packed,
        "grid_dims": dims.astype(np.int64),
        "grid_lo": lo.astype(np.int64),
        "grid_origin": np.asarray(vox.origin, dtype=np.float64).reshape(3) - centre,
        "pitch": float(vox.pitch),
    }


def _piece_table(vox: VoxelSet, key: np.ndarray, order: np.ndarray) -> dict:
    """The records of each triangle's pieces (:attr:`VoxelSet.piece_record`
    and their planes) by triangle, as the lookup reads them:
    ``piece_first`` (T + 1,) int64, triangle t's entries at
    ``[piece_first[t], piece_first[t + 1])``; ``piece_key`` (M,) int64, each
    entry's voxel key; ``piece_record`` (M, 2) int32, its records' positions
    in the grid's order; ``piece_side``, ``piece_plane_first`` and
    ``piece_plane`` in the same order. Empty without pieces."""
    if vox.piece_triangle is None or len(vox.piece_triangle) == 0:
        return {}
    tri = np.asarray(vox.piece_triangle, np.int64)
    rec = np.asarray(vox.piece_record, np.int64)
    position = _rows(order)
    by_tri = np.argsort(tri, kind="stable")
    first = np.zeros(int(tri.max()) + 2, np.int64)
    np.cumsum(np.bincount(tri, minlength=len(first) - 1), out=first[1:])
    plane_first = np.asarray(vox.piece_plane_first, np.int64)
    count = np.diff(plane_first)[by_tri]
    new_first = np.zeros(len(tri) + 1, np.int64)
    np.cumsum(count, out=new_first[1:])
    rows = np.repeat(plane_first[:-1][by_tri] - new_first[:-1], count) + np.arange(new_first[-1])
    return {
        "piece_first": first,
        "piece_key": np.ascontiguousarray(key[rec[by_tri, 0]]),
        "piece_record": np.ascontiguousarray(position[rec[by_tri]], dtype=np.int32),
        "piece_side": np.ascontiguousarray(np.asarray(vox.piece_side, np.uint32)[by_tri]),
        "piece_plane_first": new_first,
        "piece_plane": np.ascontiguousarray(np.asarray(vox.piece_plane, np.float64)[rows]),
    }


def conductor_lobes(scene: Scene) -> dict:
    """The gather kernel's arguments by which a record's ray that lands on a
    conductor that does not emit follows its lobe one bounce further
    (``docs/design.md`` §14, "Rays through mirrors in the solve"):
    ``obj_lobe`` (O, LOBE_WIDTH) float32 and ``mat_continue`` (O,) uint8;
    {} where the scene has no such conductor."""
    follow = np.array(
        [o.material.is_conductor and not o.material.is_emitter for o in scene.objects], bool
    )
    if not follow.any():
        return {}
    lobes = np.zeros((len(follow), LOBE_WIDTH), np.float32)
    for i in np.flatnonzero(follow):
        lobes[i] = scene.objects[i].material.specular.lobe_row()
    return {"obj_lobe": lobes, "mat_continue": follow.astype(np.uint8)}


def stacked_records(vox: VoxelSet) -> np.ndarray:
    """(N,) bool: the records that share their voxel with another record of
    the same object facing the same way (normals within about 18°) on
    another plane (a tenth of a voxel or more apart along the normal): the
    sheets of a stack finer than a voxel (a blind's slats, ``docs/design.md``
    §2), whose light the record's mean does not hold. Records of one sheet
    that other surfaces' planes split are not a stack."""
    n = len(vox)
    out = np.zeros(n, bool)
    if n < 2:
        return out
    _, _, key, _ = _voxel_order(vox)
    obj = np.asarray(vox.object_id, np.int64)
    order = np.lexsort((obj, key))
    k, o = key[order], obj[order]
    nrm = np.asarray(vox.normal, np.float32)[order]
    pt = np.asarray(vox.centroid, np.float64)[order]
    apart = 0.1 * float(vox.pitch)
    same = (k[1:] == k[:-1]) & (o[1:] == o[:-1])
    # group sizes are small: compare each record with the next ones of its group
    run = same.copy()
    step = 1
    while run.any():
        a = np.flatnonzero(run)
        gap = np.abs(np.einsum("ij,ij->i", nrm[a], pt[a + step] - pt[a]))
        facing = (np.einsum("ij,ij->i", nrm[a], nrm[a + step]) > 0.95) & (gap > apart)
        out[order[a[facing]]] = True
        out[order[a[facing] + step]] = True
        step += 1
        if step >= n:
            break
        run = run[:-1] & same[step - 1 :]
    return out


class TracedGather:
    """Gather the records' radiosity at every reflecting record, by rays.

    Builds the ray scene once; each call is one pass. Use as a context
    manager, or call :meth:`close`.

    Parameters
    ----------
    scene : Scene
        The scene ``vox`` was voxelized from (its triangles are traced).
    vox : VoxelSet
        The records; rays leave each reflecting record (albedo > 0, area > 0)
        from ``vox.centroid`` on the side of ``vox.normal``.
    threads : int or None
        Worker threads (None: all cores); the result does not depend on it.
    offset : float or None
        Ray offset from the surface, scene units (None: 1e-4 of the scene's
        diagonal).
    source : VoxelSet or None
        The records the rays read where they land (None: ``vox``'s own):
        another voxelization of the same scene, so that two solutions are
        gathered with the same rays (:mod:`voxgi.resolution`). Each pass's
        ``values`` are then per record of ``source``.
    response : IncidenceResponse or None
        Weighs each ray by its record's R(μ) / A at the ray's cosine
        (:mod:`voxgi.incidence`), so that a pass gives what a glossy record
        reflects over its mean albedo. None: the plain mean.
    go_on : bool
        Let rays go on past conductors and stacked sheets (below), as the
        solve's passes do, where ``values`` are the records' reflected light
        and the emitters' comes by ``emitted``. False (the default): every
        ray reads the record where it lands, and a pass is the mean of
        ``values`` under the rays.

    Notes
    -----
    With ``go_on``, a ray that lands on a conductor does not read the
    conductor's record, which stands for its light leaving alike in every
    direction: it follows
    the conductor's lobe one bounce and reads the record where that ray
    lands, as the display's gather rays do (:func:`conductor_lobes`). One
    that lands on a sheet of a stack finer than a voxel
    (:func:`stacked_records`) reads the sheet's albedo times the record
    where one cosine-distributed ray from its landing point lands: the
    light of the sheet where it is met, not its record's mean (in scenes
    without point lights or an environment, whose light that bounce
    cannot find).
    """

    def __init__(
        self,
        scene: Scene,
        vox: VoxelSet,
        *,
        threads: int | None = None,
        offset: float | None = None,
        source: VoxelSet | None = None,
        response: IncidenceResponse | None = None,
        go_on: bool = False,
    ):
        check_scene_and_records(scene, vox)
        if source is None:
            source = vox
        else:
            check_scene_and_records(scene, source)
        self.threads = _validate.threads(threads)
        if offset is None:
            offset = 1e-4 * float(np.linalg.norm(np.ptp(scene.bounds, axis=0)))
        self.offset = float(offset)
        self.vox = vox
        self.tracer = Tracer(scene, self.threads)
        c = self.tracer.centre
        normal = np.ascontiguousarray(vox.normal, np.float32)
        reflecting = (np.asarray(vox.area) > 0) & np.any(np.asarray(vox.albedo) > 0, axis=1)
        # Each record is a "pixel" of the display's gather kernels with a
        # white Lambertian material: index 0, or 1 + its row of the incidence
        # response, which weighs each ray by R(μ) / A; -1: no rays.
        material = np.zeros(len(vox), np.int32)
        m = 1
        self._response = {}
        if response is not None:
            material = response.row + 1
            m += len(response.table)
            ones = np.ones((1, *response.table.shape[1:]), np.float32)
            self._response = {
                "mat_response": np.ascontiguousarray(np.concatenate([ones, response.table]))
            }
        self._hits = (
            np.ascontiguousarray(np.asarray(vox.centroid, np.float64) - c),
            normal,
            normal,
            normal,
            np.where(reflecting, material, -1).astype(np.int32),
        )
        self._materials = (
            np.ones((m, 3), np.float32),
            np.zeros((m, 3), np.float32),
            np.ones(m, np.float32),
            np.ones(m, np.float32),
            np.zeros(m, np.uint8),
        )
        self._tri = {
            "tri_v": self.tracer.tris,
            "tri_object": scene.triangle_objects(),
            "obj_two_sided": np.array([o.two_sided for o in scene.objects], np.uint8),
        }
        self.source = source
        voxel_order = _voxel_order(source)
        self._order = voxel_order[3]  # puts each pass's values in the grid's order
        self._grid = _record_grid(
            source, c, np.zeros((len(source), 3), np.float32), None, voxel_order
        )
        # A ray reads the record the voxelization put its landing point's
        # part of the triangle in (docs/design.md §5), not the display's
        # search: the voxelization's own answer, at a fraction of the cost.
        self._grid.update(_piece_table(source, voxel_order[2], voxel_order[3]))
        self._lobes = conductor_lobes(scene) if go_on else {}
        if self._lobes:
            # a conductor has no base: its records' whole light is the lobe's
            self._lobes["rec_share"] = np.zeros((len(source), 3), np.float32)
        # A ray's bounce at a stacked sheet reads the light the sheet's point
        # takes from records and emitters, not from point lights or the sky.
        self.sheets = 0
        if go_on and not scene.lights and scene.environment is None:
            stacked = stacked_records(source)
            self.sheets = int(np.count_nonzero(stacked))
            if self.sheets:
                self._lobes["rec_stacked"] = sheet_codes(source, stacked)[voxel_order[3]]
        #: Whether some rays go on past where they land (a conductor's lobe, a
        #: stacked sheet); then a pass can also give the emitters' light those
        #: rays find (``emitted``).
        self.follows = bool(self._lobes)
        self.rays = 0
        #: The rays of the pass called with ``keep=True``, as a sparse matrix
        #: (``row_ptr``, ``column``, ``weight``; :meth:`apply`), or None.
        self.matrix: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def close(self) -> None:
        """Release the tracer's threads."""
        self.tracer.close()

    def __enter__(self) -> TracedGather:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __call__(
        self,
        values: np.ndarray,
        samples: int,
        seed: int,
        *,
        keep: bool = False,
        emitted: np.ndarray | None = None,
    ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """One pass: (N, 3) float64 mean of ``values`` under ``samples`` rays
        per reflecting record (0 elsewhere), stratified in cos²θ and hashed
        from ``seed`` and the record (the same for any thread count).

        With ``keep``, the pass's rays are also kept as :attr:`matrix`: per
        record, the records its rays read and the sum of the factors they
        read them by (:func:`transport_bytes` of memory while it is made),
        so that :meth:`apply` gives the same pass for other values without
        tracing the rays again.

        With ``emitted`` ((M, 3), each record's emitted radiosity), returns
        the pass and, from the same rays, the (N, 3) float64 mean of the
        emitted light that the rays going on past a conductor or a stacked
        sheet read where they land: the emitters seen in mirrors or from a
        slat's point, which the records' direct light (shadow rays to the
        emitters from the records' own points) does not give.
        """
        n, m = len(self.vox), len(self.source)
        values = np.asarray(values)
        if values.shape != (m, 3):
            raise ValueError(f"values: expected shape ({m}, 3), got {values.shape}")
        self._grid["rec_packed"][:, _RADIANCE] = values[self._order]
        out = np.zeros((n, 3), np.float32)
        kept = {}
        if keep:
            kept = {
                "transport_record": np.full(n * samples, -1, np.int32),
                "transport_weight": np.zeros((n * samples, 3), np.float32),
            }
        seen = {}
        if emitted is not None:
            emitted = np.asarray(emitted)
            if emitted.shape != (m, 3):
                raise ValueError(f"emitted: expected shape ({m}, 3), got {emitted.shape}")
            if self.follows:
                seen = {
                    "rec_emitted": np.ascontiguousarray(emitted[self._order], np.float32),
                    "emitted_out": np.zeros((n, 3), np.float32),
                }
        self.rays += _core.gather_light(
            *self._hits,
            *self._materials,
            samples,
            seed,
            0,
            self.offset,
            **self._tri,
            **self._grid,
            scene=self.tracer.native,
            out=out,
            threads=self.threads,
            **kept,
            **self._response,
            **self._lobes,
            **seen,
        )
        if keep:
            record, weight = kept["transport_record"], kept["transport_weight"]
            row_ptr = np.empty(n + 1, np.int64)
            nnz = _core.transport_compact(
                samples, self._order.astype(np.int32), record, weight, row_ptr, self.threads
            )
            del kept
            self.matrix = (row_ptr, record[:nnz].copy(), weight[:nnz].copy())
        if emitted is None:
            return out.astype(np.float64)
        lobe_light = seen["emitted_out"] if seen else np.zeros((n, 3), np.float32)
        return out.astype(np.float64), lobe_light.astype(np.float64)

    def apply(self, values: np.ndarray) -> np.ndarray:
        """The pass kept by ``keep=True``, applied to ``values`` (one row per
        record of ``source``): the (N, 3) float64 mean of ``values`` under the
        same rays, to rounding, without tracing them."""
        if self.matrix is None:
            raise RuntimeError("no pass was kept: call with keep=True first")
        n, m = len(self.vox), len(self.source)
        values = np.ascontiguousarray(values, np.float64)
        if values.shape != (m, 3):
            raise ValueError(f"values: expected shape ({m}, 3), got {values.shape}")
        out = np.empty((n, 3), np.float64)
        _core.transport_apply(*self.matrix, values, out, self.threads)
        return out


def transport_bytes(vox: VoxelSet, samples: int) -> int:
    """Bytes that keeping a traced pass of ``samples`` rays per record takes
    at most (``TracedGather(..., keep=True)``): the rays' records and factors
    (16 bytes a ray) while they are summed per record pair, then at most as
    much again for the kept matrix, and its row pointers."""
    return 2 * 16 * len(vox) * int(samples) + 8 * (len(vox) + 1)


def traced_irradiance(
    scene: Scene,
    vox: VoxelSet,
    radiosity: np.ndarray,
    *,
    samples: int = 64,
    seed: int = 0,
    threads: int | None = None,
) -> tuple[np.ndarray, dict]:
    """Irradiance at every reflecting record from the records' radiosity, by rays.

    Parameters
    ----------
    scene : Scene
        The scene ``vox`` was voxelized from.
    vox : VoxelSet
        The records.
    radiosity : (N, 3)
        Each record's radiosity (radiance times π), as a ray landing on it
        reads it; for the indirect light, the reflected part ``B − E``.
    samples : int, optional
        Cosine-distributed rays per record, 1 to 4096 (a square number is
        stratified in both angles).
    seed : int, optional
        Seeds the rays.
    threads : int or None, optional
        Worker threads (None: all cores).

    Returns
    -------
    irradiance : (N, 3) float64
        0 for records that reflect nothing or have no area.
    stats : dict
        ``rays`` and ``seconds``.

    Examples
    --------
    Inside a closed box whose every record has radiosity π, each record
    receives π (every ray lands on the box):

    >>> import numpy as np, voxgi
    >>> scene = voxgi.scenes.furnace_box()
    >>> vox = voxgi.voxelize(scene, 8, progress=False)
    >>> H, _ = voxgi.traced.traced_irradiance(scene, vox, np.full((len(vox), 3), np.pi))
    >>> bool(np.allclose(H[vox.albedo[:, 0] > 0], np.pi, rtol=1e-5))
    True
    """
    samples = _validate.integer(samples, "samples", low=1, high=4096)
    seed = _validate.integer(seed, "seed")
    t0 = time.perf_counter()
    with TracedGather(scene, vox, threads=threads) as g:
        H = g(radiosity, samples, seed)
        rays = g.rays
    return H, {"rays": rays, "seconds": time.perf_counter() - t0}
