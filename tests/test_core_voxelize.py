"""voxgi._core.voxelize, the binding itself: shapes, dtypes, and errors instead of crashes."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from voxgi import _core


def args(n_tris=4, seed=0):
    """Valid arguments: random triangles in the unit cube, a 10³ grid around it."""
    rng = np.random.default_rng(seed)
    tris = rng.uniform(0.05, 0.95, size=(n_tris, 3, 3))
    return dict(
        triangles=np.ascontiguousarray(tris),
        tri_object=(np.arange(n_tris) % 2).astype(np.int32),
        two_sided=np.array([False, True]),
        albedo=np.array([[0.5, 0.5, 0.5], [0.2, 0.3, 0.4]], np.float32),
        emission=np.array([[0, 0, 0], [1, 2, 3]], np.float32),
        origin=np.zeros(3),
        pitch=0.1,
        dims=np.array([10, 10, 10], np.int32),
    )


def test_shapes_and_dtypes():
    out = _core.voxelize(**args())
    n = len(out["area"])
    assert n > 0
    want = {
        "ijk": (np.int32, (n, 3)),
        "normal": (np.float32, (n, 3)),
        "area": (np.float32, (n,)),
        "albedo": (np.float32, (n, 3)),
        "emission": (np.float32, (n, 3)),
        "centroid": (np.float64, (n, 3)),
        "object_id": (np.int32, (n,)),
        "back": (np.bool_, (n,)),
        "side": (np.int8, (n,)),
    }
    for name, (dtype, shape) in want.items():
        assert out[name].dtype == dtype, name
        assert out[name].shape == shape, name
        assert out[name].flags.c_contiguous
    assert out["stats"]["records"] == n
    assert out["stats"]["triangles"] == 4
    # Object 0 is one-sided (black back records), object 1 two-sided (live).
    back = out["back"]
    assert np.all(out["object_id"][back] == 0)
    np.testing.assert_array_equal(out["albedo"][back], 0)
    two = (out["object_id"] == 1) & (out["side"] == 1)
    np.testing.assert_array_equal(out["emission"][two], np.tile([1, 2, 3], (two.sum(), 1)))


def test_no_triangles_gives_empty_arrays():
    a = args()
    a["triangles"] = np.zeros((0, 3, 3))
    a["tri_object"] = np.zeros(0, np.int32)
    out = _core.voxelize(**a)
    assert out["ijk"].shape == (0, 3)
    assert out["area"].shape == (0,)


@pytest.mark.parametrize(
    ("name", "bad"),
    [
        ("triangles", lambda a: a.astype(np.float32)),
        ("triangles", lambda a: a.tolist()),
        ("triangles", lambda a: np.asfortranarray(a)),
        ("tri_object", lambda a: a.astype(np.int64)),
        ("two_sided", lambda a: a.astype(np.uint8)),
        ("albedo", lambda a: a.astype(np.float64)),
        ("emission", lambda a: a.astype(np.float64)),
        ("origin", lambda a: a.astype(np.float32)),
        ("dims", lambda a: a.astype(np.int64)),
    ],
)
def test_wrong_dtype_or_layout_is_a_type_error(name, bad):
    a = args()
    a[name] = bad(a[name])
    with pytest.raises(TypeError):
        _core.voxelize(**a)


@pytest.mark.parametrize(
    ("name", "bad"),
    [
        ("triangles", lambda a: np.ascontiguousarray(a.reshape(-1, 9))),
        ("triangles", lambda a: np.ascontiguousarray(a[:, :2])),
        ("tri_object", lambda a: a[:-1].copy()),
        ("tri_object", lambda a: a.reshape(-1, 1).copy()),
        ("two_sided", lambda a: a.reshape(1, 2).copy()),
        ("albedo", lambda a: a[:1].copy()),
        ("emission", lambda a: np.ascontiguousarray(a[:, :2])),
        ("origin", lambda a: a[:2].copy()),
        ("dims", lambda a: a[:2].copy()),
    ],
)
def test_wrong_shape_is_a_value_error(name, bad):
    a = args()
    a[name] = bad(a[name])
    with pytest.raises(ValueError, match=name):
        _core.voxelize(**a)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda a: a["tri_object"].__setitem__(0, 2), "tri_object"),
        (lambda a: a["tri_object"].__setitem__(1, -1), "tri_object"),
        (lambda a: a["triangles"].__setitem__((0, 0, 0), np.nan), "non-finite"),
        (lambda a: a["triangles"].__setitem__((1, 2, 1), 1.5), "outside the grid"),
        (lambda a: a["triangles"].__setitem__((1, 2, 1), -0.01), "outside the grid"),
        (lambda a: a.__setitem__("pitch", 0.0), "pitch"),
        (lambda a: a.__setitem__("pitch", float("nan")), "pitch"),
        (lambda a: a["dims"].__setitem__(0, 0), "dims"),
        (lambda a: a["origin"].__setitem__(0, np.inf), "origin"),
        (lambda a: a["albedo"].__setitem__((0, 0), 1.5), "albedo"),
        (lambda a: a["emission"].__setitem__((1, 0), -1.0), "emission"),
        (lambda a: a.__setitem__("cos_cluster", 2.0), "cos_cluster"),
        (lambda a: a.__setitem__("eps", -1.0), "eps"),
        (lambda a: a.__setitem__("threads", -1), "threads"),
    ],
)
def test_bad_values_are_value_errors(change, match):
    a = args()
    change(a)
    with pytest.raises(ValueError, match=match):
        _core.voxelize(**a)


def test_inputs_are_not_modified_and_threads_do_not_matter():
    a = args(n_tris=50, seed=3)
    copies = {k: np.copy(v) for k, v in a.items() if isinstance(v, np.ndarray)}
    one = _core.voxelize(**a, threads=1)
    for k, v in copies.items():
        np.testing.assert_array_equal(a[k], v)
    two = _core.voxelize(**a, threads=2)
    three = _core.voxelize(**a, threads=3)
    for k in ("ijk", "normal", "area", "centroid", "object_id", "back", "side"):
        np.testing.assert_array_equal(one[k], two[k])
        np.testing.assert_array_equal(one[k], three[k])


def test_progress_callable_hears_the_end():
    calls = []
    out = _core.voxelize(**args(n_tris=20), progress=lambda *x: calls.append(x))
    assert len(out["area"]) > 0
    assert calls, "the progress callable was never called"
    assert all(len(c) == 3 and 0 <= c[1] <= c[2] for c in calls)
    _, done, total = calls[-1]
    assert done == total > 0


def test_progress_callable_errors_propagate():
    def fail(*_):
        raise RuntimeError("from progress")

    with pytest.raises(RuntimeError, match="from progress"):
        _core.voxelize(**args(n_tris=20), progress=fail)


def test_area_matches_triangle_area():
    a = args(n_tris=30, seed=9)
    out = _core.voxelize(**a)
    t = a["triangles"]
    want = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum()
    # float32 per-record areas, summed in float64 (measured ~1e-8 relative).
    assert out["area"][out["side"] == 0].sum(dtype=np.float64) == pytest.approx(want, rel=1e-6)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    n=st.integers(0, 6),
    scale=st.sampled_from([1e-6, 1e-3, 1.0]),
    seed=st.integers(0, 2**31 - 1),
    flat=st.booleans(),
    pitch=st.sampled_from([0.05, 0.1, 0.3]),
)
def test_fuzz_never_crashes_or_returns_nan(n, scale, seed, flat, pitch):
    # Tiny, flat (axis-aligned, on voxel faces) and slivered triangles: either
    # a valid result or a ValueError, never a crash, never NaN.
    rng = np.random.default_rng(seed)
    base = rng.uniform(0.1, 0.9, size=(n, 1, 3))
    tris = base + scale * rng.normal(size=(n, 3, 3))
    if flat and n:
        tris[:, :, 2] = np.round(tris[:, :, 2] / pitch) * pitch  # exactly on a grid plane
    tris = np.clip(tris, 0.0, 1.0)
    a = args()
    a.update(
        triangles=np.ascontiguousarray(tris),
        tri_object=np.zeros(n, np.int32),
        pitch=pitch,
        dims=np.full(3, int(np.ceil(1.0 / pitch)) + 1, np.int32),
    )
    out = _core.voxelize(**a)
    for k in ("normal", "area", "centroid"):
        assert np.all(np.isfinite(out[k]))
    f = out["side"] == 0
    np.testing.assert_allclose(np.linalg.norm(out["normal"], axis=1), 1, atol=1e-5)
    want = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    want = want.sum() if out["stats"]["skipped_degenerate"] == 0 else None
    got = out["area"][f].sum(dtype=np.float64)
    if want is not None:
        # Clamping to [0, 1] puts triangles exactly on the grid's boundary planes.
        assert got == pytest.approx(want, rel=1e-5, abs=1e-12)


@pytest.mark.parametrize("x", [0.0, 0.3, 1.0])
def test_triangle_on_a_grid_plane(x):
    # A triangle lying exactly in a voxel-face plane (x = 0, 3 and 10 voxels:
    # the lower boundary, inside, the upper boundary): its area is counted
    # once, and inside the grid the voxels on both sides of the plane touch it.
    a = args()
    a["triangles"] = np.array([[[x, 0.12, 0.13], [x, 0.81, 0.22], [x, 0.33, 0.91]]])
    a["tri_object"] = np.zeros(1, np.int32)
    out = _core.voxelize(**a)
    t = a["triangles"][0]
    want = 0.5 * np.linalg.norm(np.cross(t[1] - t[0], t[2] - t[0]))
    f = out["side"] == 0
    assert out["area"][f].sum(dtype=np.float64) == pytest.approx(want, rel=1e-6)
    layers = np.unique(out["ijk"][:, 0])
    i = round(x / 0.1)
    assert list(layers) == [v for v in (i - 1, i) if 0 <= v < 10]
    np.testing.assert_allclose(out["normal"][f], np.tile([1, 0, 0], (f.sum(), 1)), atol=1e-7)


def _sat_overlap(tri, centres, half):
    """Separating-axis triangle/closed-box test, (B,) bool (Akenine-Möller)."""
    v = tri[None] - centres[:, None, :]
    e = [tri[1] - tri[0], tri[2] - tri[1], tri[0] - tri[2]]
    ok = np.ones(len(centres), bool)
    for ax in [*np.eye(3), np.cross(e[0], e[1]), *[np.cross(a, b) for a in np.eye(3) for b in e]]:
        if not np.any(ax):
            continue
        r = half * np.abs(ax).sum()
        p = v @ ax
        ok &= ~((p.min(axis=1) > r) | (p.max(axis=1) < -r))
    return ok


@pytest.mark.parametrize("seed", range(6))
def test_touching_cubes_are_included_exactly(seed):
    # Vertices on a 1/4-voxel lattice with a power-of-two pitch: vertices,
    # edges and faces lie exactly on voxel faces, edges and corners, and the
    # SAT test with the closed cube is exact in floating point. Every cube
    # that merely touches a triangle must be there (this is where rounding
    # would open gaps between neighbouring triangles); no other cube may be.
    rng = np.random.default_rng(seed)
    pitch = 0.125
    tris = rng.integers(0, 4 * 8 + 1, size=(8, 3, 3)) * (pitch / 4)
    area2 = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    tris = np.ascontiguousarray(tris[area2 > 0])
    a = args()
    a.update(
        triangles=tris,
        tri_object=np.zeros(len(tris), np.int32),
        pitch=pitch,
        dims=np.array([8, 8, 8], np.int32),
    )
    out = _core.voxelize(**a)
    cells = np.stack(np.meshgrid(*[np.arange(8)] * 3, indexing="ij"), -1).reshape(-1, 3)
    centres = (cells + 0.5) * pitch
    closed = np.zeros(len(cells), bool)
    for t in tris:
        closed |= _sat_overlap(t, centres, 0.5 * pitch)
    have = np.zeros((8, 8, 8), bool)
    have[tuple(out["ijk"].T)] = True
    np.testing.assert_array_equal(have.reshape(-1), closed)
    want = (
        0.5
        * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1).sum()
    )
    assert out["area"][out["side"] == 0].sum(dtype=np.float64) == pytest.approx(want, rel=1e-6)
