"""The display kernels called directly: vpl_light, shade_brdf, camera_hits, geometry_filter."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from voxgi import _core, rays


def mats(albedo=((0.5, 0.5, 0.5),), rs=None, nu=None, nv=None, glossy=None):
    a = np.array(albedo, np.float32)
    m = len(a)
    return dict(
        mat_albedo=a,
        mat_rs=np.array(rs if rs is not None else np.zeros((m, 3)), np.float32),
        mat_nu=np.array(nu if nu is not None else np.ones(m), np.float32),
        mat_nv=np.array(nv if nv is not None else np.ones(m), np.float32),
        mat_glossy=np.array(glossy if glossy is not None else np.zeros(m), np.uint8),
    )


def hits(pos, normal, wo=None, material=None):
    pos = np.array(pos, np.float64).reshape(-1, 3)
    n = np.array(normal, np.float32).reshape(-1, 3)
    p = len(pos)
    return dict(
        hit_pos=pos,
        hit_normal=n,
        hit_ng=n.copy(),
        hit_wo=np.array(wo if wo is not None else n, np.float32).reshape(-1, 3),
        hit_material=np.array(material if material is not None else np.zeros(p), np.int32),
    )


def vpls(pos, normal, weight, area, pa=None, n_gather=0.0):
    k = len(np.array(area).reshape(-1))
    return dict(
        vpl_pos=np.array(pos, np.float64).reshape(-1, 3),
        vpl_normal=np.array(normal, np.float32).reshape(-1, 3),
        vpl_weight=np.array(weight, np.float32).reshape(-1, 3),
        vpl_area=np.array(area, np.float32).reshape(-1),
        vpl_pa=np.array(pa if pa is not None else np.zeros(k), np.float32),
        n_gather=n_gather,
    )


#: A scene far from every test's points: nothing occludes.
_FAR = np.array([[[50, 50, 50], [51, 50, 50], [50, 51, 50]]], np.float32)


def scene_of(tris=_FAR):
    return _core.RayScene(rays.embree_library(), np.asarray(tris, np.float32))


def light(h, m, v, eps=1e-4, threads=0, scene=None):
    """(P, 3) light of the VPLs at the hits and the shadow rays traced."""
    return _core.vpl_light(
        **h, **m, **v, eps=eps, scene=scene_of() if scene is None else scene, threads=threads
    )


def test_single_pair_exact_value():
    # x at the origin facing +z, a VPL at height 2 facing down, 45° off axis:
    # contribution = (rho/pi) * W * cos_x cos_y / (r² + dA/pi).
    r = 2.0
    y = np.array([r / math.sqrt(2), 0.0, r / math.sqrt(2)])
    h = hits([0, 0, 0], [0, 0, 1])
    v = vpls(y, [0, 0, -1], [3.0, 2.0, 1.0], [0.01])
    out, n = light(h, mats(), v, eps=1e-5)
    assert n == 1
    c = math.cos(math.pi / 4)
    g = c * c / (r * r + 0.01 / math.pi)
    expect = np.array([3.0, 2.0, 1.0]) * 0.5 / math.pi * g
    np.testing.assert_allclose(out[0], expect, rtol=1e-6)


def test_the_shadow_ray_runs_from_the_hit_to_the_vpl_and_no_further():
    # A small triangle across the segment hides the VPL; the same triangle
    # just beyond the VPL, or just below the hit point's offset origin, does not.
    h = hits([0, 0, 0], [0, 0, 1])
    v = vpls([0, 0, 1], [0, 0, -1], [1, 1, 1], [0.01])

    def tri(z):
        return [[[-0.1, -0.1, z], [0.1, -0.1, z], [0.0, 0.1, z]]]

    lit = light(h, mats(), v)[0][0, 0]
    assert lit > 0
    assert light(h, mats(), v, scene=scene_of(tri(0.5)))[0][0, 0] == 0
    assert light(h, mats(), v, scene=scene_of(tri(1.01)))[0][0, 0] == lit
    assert light(h, mats(), v, scene=scene_of(tri(-0.01)))[0][0, 0] == lit


def test_bounded_geometry_term_at_contact():
    # A VPL right above x (r -> 0) gives at most cos cos / (dA/pi): no spike.
    h = hits([0, 0, 0], [0, 0, 1])
    for r in (1e-1, 1e-3, 1e-6):
        v = vpls([0, 0, r], [0, 0, -1], [1, 1, 1], [0.02])
        out, _ = light(h, mats(albedo=[(1, 1, 1)]), v, eps=0.0)
        g = out[0, 0] * math.pi
        assert g <= math.pi / 0.02 * (1 + 1e-6)
        assert math.isclose(g, 1.0 / (r * r + 0.02 / math.pi), rel_tol=1e-5)


def test_mis_weight_is_bounded_and_matches_formula():
    # An MIS VPL adds f L cos_x cos_y / (r² n_v p + n_g cos_x cos_y / pi): at
    # contact at most pi f L / n_g, far away f L G / (n_v p), the plain estimator.
    h = hits([0, 0, 0], [0, 0, 1])
    m = mats(albedo=[(1, 1, 1)])
    for r in (1e-6, 10.0):
        v = vpls([0, 0, r], [0, 0, -1], [2.0, 2.0, 2.0], [0.02], pa=[4.0], n_gather=4.0)
        out, _ = light(h, m, v, eps=0.0)
        expect = (1 / math.pi) * 2.0 / (r * r * 4.0 + 4.0 / math.pi)
        np.testing.assert_allclose(out[0], expect, rtol=1e-5)
        assert out[0, 0] <= math.pi * (1 / math.pi) * 2.0 / 4.0 * (1 + 1e-6)
    with pytest.raises(ValueError, match="MIS"):
        light(h, m, vpls([0, 0, 1], [0, 0, -1], [1, 1, 1], [0.02], pa=[1.0]))


def test_back_facing_and_below_surface_cost_no_ray():
    h = hits([[0, 0, 0], [0, 0, 0], [0, 0, 0]], [[0, 0, 1]] * 3, material=[0, 0, -1])
    v = vpls(
        [[0, 0, 1], [0, 0, 1], [0, 0, -1]],
        [[0, 0, 1], [0, 0, -1], [0, 0, 1]],  # faces away, faces x, below x
        [[1, 1, 1]] * 3,
        [0.01] * 3,
    )
    out, n = light(h, mats(), v)
    # Pixels 0 and 1: only the VPL facing them from above; pixel 2 is not shaded.
    assert n == 2
    assert np.all(out[:2] > 0)
    assert np.all(out[2] == 0)


def test_vpl_light_independent_of_thread_count():
    rng = np.random.default_rng(1)
    p, k = 3000, 17
    pos = rng.normal(size=(p, 3))
    n = rng.normal(size=(p, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    vn = rng.normal(size=(k, 3))
    vn /= np.linalg.norm(vn, axis=1, keepdims=True)
    h = hits(pos, n, material=rng.integers(-1, 2, p))
    m = mats(
        albedo=[(0.3, 0.5, 0.7), (0.9, 0.1, 0.2)],
        rs=[(0, 0, 0), (0.3, 0.3, 0.3)],
        nu=[1, 50],
        nv=[1, 500],
        glossy=[0, 1],
    )
    v = vpls(rng.normal(size=(k, 3)) * 2, vn, rng.random((k, 3)), rng.random(k) * 0.01)
    # a cloud of small triangles that blocks some of the shadow rays
    c = rng.normal(size=(200, 1, 3))
    blockers = scene_of(c + 0.2 * rng.normal(size=(200, 3, 3)))
    a = light(h, m, v, threads=1, scene=blockers)
    b = light(h, m, v, threads=2, scene=blockers)
    np.testing.assert_array_equal(a[0], b[0])
    assert a[1] == b[1] > 0
    free = light(h, m, v, threads=2)
    assert free[1] == a[1]  # the same rays, some of them blocked
    assert np.all(a[0] <= free[0])
    assert np.any(a[0] < free[0])


def _as_reference(n, k1, k2, rd, rs, nu, nv):
    """Ashikhmin–Shirley 2000 in float64 numpy (independent of the kernel)."""
    u = np.cross(n, [0.0, 1.0, 0.0]) if abs(n[1]) < 0.99 else np.cross(n, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    h = (k1 + k2) / np.linalg.norm(k1 + k2)
    nh, hk = n @ h, h @ k1
    e = (nu * (h @ u) ** 2 + nv * (h @ v) ** 2) / (1 - nh**2)
    fres = rs + (1 - rs) * (1 - hk) ** 5
    spec = (
        math.sqrt((nu + 1) * (nv + 1)) / (8 * math.pi) * nh**e / (hk * max(n @ k1, n @ k2)) * fres
    )
    diff = (
        28
        * rd
        / (23 * math.pi)
        * (1 - rs)
        * (1 - (1 - (n @ k1) / 2) ** 5)
        * (1 - (1 - (n @ k2) / 2) ** 5)
    )
    return spec + diff


def _unit(rng, n, around=None):
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    if around is not None:
        d *= np.sign(d @ around)[:, None]
    return d


def test_brdf_lambert_and_ashikhmin_shirley_match_formulas():
    rng = np.random.default_rng(2)
    rd, rs, nu, nv = np.array([0.6, 0.4, 0.2]), np.array([0.05, 0.3, 0.9]), 20.0, 300.0
    m = mats(
        albedo=[(0.2, 0.4, 0.6), tuple(rd)],
        rs=[(0, 0, 0), tuple(rs)],
        nu=[1, nu],
        nv=[1, nv],
        glossy=[0, 1],
    )
    q = 200
    n = _unit(rng, q)
    k1 = np.array([_unit(rng, 1, a)[0] for a in n])
    k2 = np.array([_unit(rng, 1, a)[0] for a in n])
    args = [np.ascontiguousarray(x, np.float32) for x in (n, k1, k2)]
    lam = _core.shade_brdf(**m, material=np.zeros(q, np.int32), n=args[0], k1=args[1], k2=args[2])
    np.testing.assert_allclose(lam, np.tile([0.2, 0.4, 0.6], (q, 1)) / math.pi, rtol=1e-6)
    f = _core.shade_brdf(**m, material=np.ones(q, np.int32), n=args[0], k1=args[1], k2=args[2])
    ref = np.array(
        [
            _as_reference(*(x.astype(np.float64) for x in (a, b, c)), rd, rs, nu, nv)
            for a, b, c in zip(*args, strict=False)
        ]
    )
    # float32 kernel vs float64 reference; pow(nh, e) with e up to 300
    # amplifies the rounding of nh (measured max rel. error 9e-6).
    np.testing.assert_allclose(f, ref, rtol=1e-4, atol=1e-7)
    # Reciprocity: f(k1, k2) = f(k2, k1).
    g = _core.shade_brdf(**m, material=np.ones(q, np.int32), n=args[0], k1=args[2], k2=args[1])
    np.testing.assert_allclose(f, g, rtol=1e-4, atol=1e-7)


def test_ashikhmin_shirley_conserves_energy():
    # Directional albedo ∫ f cos dω <= 1 for a white, fully specular-at-grazing
    # material (Rd = 1, Rs = 1 and 0.05): Monte Carlo with 200k cosine-weighted
    # directions (std. error ~0.5%; more for the narrow nu = 1000 lobe, which
    # cosine sampling hits rarely). AS 2000 shows the sum stays below 1;
    # measured here 0.56 to 0.97.
    rng = np.random.default_rng(3)
    n = np.array([0.0, 0.0, 1.0], np.float32)
    q = 200_000
    u1, u2 = rng.random(q), rng.random(q)
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    k1 = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - u1)], 1)  # pdf cos/pi
    for rs_, nu in ((1.0, 10.0), (0.05, 10.0), (0.05, 1000.0)):
        m = mats(albedo=[(1.0, 1.0, 1.0)], rs=[(rs_,) * 3], nu=[nu], nv=[nu], glossy=[1])
        for theta in (0.1, 0.8, 1.3):
            k2 = np.tile([math.sin(theta), 0.0, math.cos(theta)], (q, 1))
            f = _core.shade_brdf(
                **m,
                material=np.zeros(q, np.int32),
                n=np.tile(n, (q, 1)),
                k1=np.ascontiguousarray(k1, np.float32),
                k2=np.ascontiguousarray(k2, np.float32),
            )
            albedo = float(np.mean(f[:, 0]) * math.pi)
            assert 0.0 < albedo < 1.03, (rs_, nu, theta, albedo)


def test_bad_arguments_are_errors_not_crashes():
    h = hits([0, 0, 0], [0, 0, 1])
    m = mats()
    v = vpls([0, 0, 1], [0, 0, -1], [1, 1, 1], [0.01])
    with pytest.raises(TypeError):
        light({**h, "hit_pos": h["hit_pos"].astype(np.float32)}, m, v)
    with pytest.raises(TypeError):  # not C-contiguous: refused, never copied silently
        light(h, m, {**v, "vpl_pos": np.zeros((1, 6))[:, ::2]})
    with pytest.raises(ValueError, match="hit_normal"):
        light({**h, "hit_normal": np.zeros((2, 3), np.float32)}, m, v)
    with pytest.raises(ValueError, match="vpl_area"):
        light(h, m, {**v, "vpl_area": np.zeros(2, np.float32)})
    with pytest.raises(ValueError, match="out of range"):
        light({**h, "hit_material": np.array([3], np.int32)}, m, v)
    with pytest.raises(ValueError, match="eps"):
        light(h, m, v, eps=float("nan"))


@settings(max_examples=60, deadline=None)
@given(
    p=st.integers(0, 5),
    k=st.integers(0, 5),
    mat=st.integers(-2, 2),
    dt=st.sampled_from([np.float32, np.float64, np.int32]),
    cols=st.integers(2, 4),
)
def test_fuzz_vpl_light(p, k, mat, dt, cols):
    rng = np.random.default_rng(p * 7 + k)
    h = dict(
        hit_pos=rng.normal(size=(p, 3)),
        hit_normal=np.tile([0, 0, 1], (p, 1)).astype(dt),
        hit_ng=np.tile([0, 0, 1], (p, 1)).astype(np.float32),
        hit_wo=np.tile([0, 0, 1], (p, 1)).astype(np.float32),
        hit_material=np.full(p, mat, np.int32),
    )
    v = vpls(
        rng.normal(size=(k, 3)), np.tile([0, 0, -1], (k, 1)), np.ones((k, 3)), np.full(k, 0.01)
    )
    v["vpl_weight"] = np.ones((k, cols), np.float32)
    try:
        out, n = light(h, mats(), v)
    except (TypeError, ValueError):
        return
    assert dt is np.float32
    assert cols == 3
    assert mat < 1 or p == 0
    assert out.shape == (p, 3)
    assert 0 <= n <= p * k
    assert np.all(np.isfinite(out))
    assert np.all(out >= 0)


def _primary_hits_reference(org, d, prim, v, vn, obj, two_sided, emission):
    """The primary hits written out in numpy, one formula per line."""
    P = len(prim)
    pos = np.zeros((P, 3))
    ns_out = np.zeros((P, 3), np.float32)
    ng_out = np.zeros((P, 3), np.float32)
    mat = np.full(P, -1, np.int32)
    le = np.zeros((P, 3), np.float32)
    for p in np.flatnonzero(prim >= 0):
        t = prim[p]
        v0, v1, v2 = v[t]
        nraw = np.cross(v1 - v0, v2 - v0)
        ng = nraw / np.linalg.norm(nraw)
        dn = d[p] @ ng
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (v0 - org[p]) @ ng / dn
        s = s if np.isfinite(s) else 0.0
        x = org[p] + s * d[p]
        sgn = 1.0 if dn < 0 else -1.0
        n = ng * sgn
        if vn is not None:
            a2 = nraw @ nraw
            b1 = np.cross(x - v0, v2 - v0) @ nraw / a2
            b2 = np.cross(v1 - v0, x - v0) @ nraw / a2
            sm = ((1 - b1 - b2) * vn[t, 0] + b1 * vn[t, 1] + b2 * vn[t, 2]) * sgn
            sm /= max(np.linalg.norm(sm), 1e-300)
            ns = sm if sm @ n > 0 else n
        else:
            ns = n
        pos[p], ns_out[p], ng_out[p] = x, ns, n
        if dn < 0 or two_sided[obj[t]]:
            mat[p] = obj[t]
            le[p] = emission[obj[t]]
    return pos, ns_out, ng_out, mat, le


def _plane_pixels(width, height, step=0.01, depth=1.0):
    """Camera hits on the plane z = depth seen from the origin, one pixel a
    footprint apart (pixel_angle = step / depth): pos, normal, material."""
    rows, cols = np.divmod(np.arange(width * height), width)
    pos = np.column_stack([cols * step, rows * step, np.full(width * height, depth)])
    normal = np.tile(np.float32([0, 0, -1]), (width * height, 1))
    return pos, normal, np.zeros(width * height, np.int32)


def _filter(pos, normal, material, values, width, height, glossy=(0,), radius=1, step=0.01):
    out = np.zeros((width * height, 3), np.float32)
    _core.geometry_filter(
        np.ascontiguousarray(pos, np.float64),
        np.ascontiguousarray(normal, np.float32),
        np.ascontiguousarray(material, np.int32),
        np.asarray(glossy, np.uint8),
        np.zeros(3),
        step,
        width,
        height,
        radius,
        np.ascontiguousarray(values, np.float32),
        out,
    )
    return out


def test_geometry_filter_is_the_symmetric_box_mean_on_one_plane():
    # Every pixel sees the same plane: each gets the plain mean of the
    # largest square around it, up to (2r + 1)², whose rows and columns the
    # image holds on both sides of it (a pixel at the border keeps only the
    # neighbours whose mirror images through it lie inside the image).
    w, h = 7, 5
    pos, normal, mat = _plane_pixels(w, h)
    vals = np.random.default_rng(3).random((w * h, 3)).astype(np.float32)
    for radius in (1, 2):
        got = _filter(pos, normal, mat, vals, w, h, radius=radius).reshape(h, w, 3)
        img = vals.reshape(h, w, 3).astype(np.float64)
        for r in range(h):
            for c in range(w):
                kr, kc = min(radius, r, h - 1 - r), min(radius, c, w - 1 - c)
                box = img[r - kr : r + kr + 1, c - kc : c + kc + 1]
                np.testing.assert_allclose(got[r, c], box.mean(axis=(0, 1)), rtol=1e-6)


def test_geometry_filter_keeps_a_gradient_beside_an_outline():
    # Light that grows linearly across a plane is left as it is by the
    # filter, also on the pixels beside another surface (the right third of
    # the image is another material) and at the image's border, where only
    # part of the square is the plane's: a mean over neighbours on one side
    # would shift those pixels by the gradient times a pixel.
    w, h = 9, 6
    pos, normal, mat = _plane_pixels(w, h)
    rows, cols = np.divmod(np.arange(w * h), w)
    mat = np.where(cols >= 6, 1, 0).astype(np.int32)
    ramp = (1.0 + 0.5 * cols + 0.25 * rows).astype(np.float32)
    vals = np.repeat(ramp[:, None], 3, axis=1)
    for radius in (1, 2):
        got = _filter(pos, normal, mat, vals, w, h, glossy=(0, 0), radius=radius)
        np.testing.assert_allclose(got, vals, rtol=1e-6)


def test_geometry_filter_keeps_other_surfaces_out():
    w, h = 6, 4
    vals = np.random.default_rng(4).random((w * h, 3)).astype(np.float32)
    col = np.arange(w * h) % w
    left = col < 3

    def only_own_side(got, pos, normal, mat, **kw):
        # each half filtered alone must give the same as the whole image
        for side in (left, ~left):
            v = np.where(side[:, None], vals, 0.0)
            alone = _filter(pos, normal, mat, v, w, h, **kw)
            np.testing.assert_allclose(got[side], alone[side], rtol=1e-6)

    pos, normal, mat = _plane_pixels(w, h)
    # another material
    m2 = np.where(left, 0, 1).astype(np.int32)
    only_own_side(
        _filter(pos, normal, m2, vals, w, h, glossy=(0, 0)), pos, normal, m2, glossy=(0, 0)
    )
    # a fold: the right half faces along x
    n2 = normal.copy()
    n2[~left] = (-1, 0, 0)
    only_own_side(_filter(pos, n2, mat, vals, w, h), pos, n2, mat)
    # a step: the right half lies 5 footprints behind, parallel
    p2 = pos.copy()
    p2[~left, 2] += 0.05
    only_own_side(_filter(p2, normal, mat, vals, w, h), p2, normal, mat)
    # a glossy material and pixels with nothing shaded keep their own values
    np.testing.assert_array_equal(_filter(pos, normal, mat, vals, w, h, glossy=(1,)), vals)
    none = np.full(w * h, -1, np.int32)
    np.testing.assert_array_equal(_filter(pos, normal, none, vals, w, h), vals)


def test_geometry_filter_refuses_bad_shapes_and_radii():
    w, h = 3, 2
    pos, normal, mat = _plane_pixels(w, h)
    vals = np.zeros((w * h, 3), np.float32)
    with pytest.raises(ValueError, match="radius"):
        _filter(pos, normal, mat, vals, w, h, radius=-1)
    with pytest.raises(ValueError, match="hit_pos"):
        _filter(pos[:-1], normal, mat, vals, w, h)
    with pytest.raises(ValueError, match="pixel_angle"):
        _filter(pos, normal, mat, vals, w, h, step=0.0)


def _camera_hits_both_ways(scene, cam, offset, lens, corner_normals=False):
    """``_core.camera_hits`` and the same hits written out in numpy from
    ``camera_rays`` and the tracer's first hits, in the tracer's frame."""
    from voxgi.display import camera_rays
    from voxgi.display.shader import _Tracer

    tr = _Tracer(scene, 2)
    n_obj = len(scene.objects)
    vn = None
    if corner_normals:
        # near the winding normal, either way round, some of them behind it
        rng = np.random.default_rng(3)
        F = len(tr.ng)
        vn = tr.ng[:, None, :] * rng.choice([-1.0, 1.0], (F, 1, 1)) + 0.4 * rng.normal(
            size=(F, 3, 3)
        )
        vn /= np.linalg.norm(vn, axis=2, keepdims=True)
    tri_args = (
        np.ascontiguousarray(tr.tris, np.float64),
        np.ascontiguousarray(tr.ng, np.float64),
        vn,
        np.ascontiguousarray(tr.obj, np.int32),
        (np.arange(n_obj) % 2).astype(np.uint8),
        np.arange(3 * n_obj, dtype=np.float32).reshape(n_obj, 3),
    )
    org, dirs = camera_rays(cam, offset, lens)
    org = org - tr.centre
    prim = tr.intersect(org, dirs)
    v, _, vn, obj, two_sided, emission = tri_args
    want = (*_primary_hits_reference(org, dirs, prim, v, vn, obj, two_sided, emission), prim, -dirs)
    right, up, fwd = cam.frame()
    got = _core.camera_hits(
        np.asarray(cam.eye, np.float64) - tr.centre,
        right,
        up,
        fwd,
        math.tan(math.radians(cam.fov) / 2),
        cam.width,
        cam.height,
        cam.aperture,
        cam.focus,
        offset,
        lens,
        *tri_args,
        tr.native,
        threads=2,
    )
    return got, want, tri_args, tr


@pytest.mark.parametrize(("aperture", "corner_normals"), [(0.0, False), (0.04, False), (0.0, True)])
def test_camera_hits_are_the_camera_rays_traced_and_hit(aperture, corner_normals):
    import voxgi

    scene = voxgi.scenes.cornell_box(width=40, height=30)
    cam = scene.camera.replace(aperture=aperture, focus_distance=0.9)
    got, want, _, _ = _camera_hits_both_ways(scene, cam, (0.3, 0.8), (0.6, -0.5), corner_normals)
    pos, normal, ng, wo, material, emission, prim, through, albedo = got
    assert through is None  # no sheets in the scene
    assert albedo is None  # (asked for with obj_albedo only)
    w_pos, w_normal, w_ng, w_material, w_emission, w_prim, w_wo = want
    # the rays are the same arithmetic: the same triangles
    np.testing.assert_array_equal(prim, w_prim)
    assert 0 < np.mean(material >= 0) < 1  # some one-sided backs are black
    np.testing.assert_allclose(pos, w_pos, rtol=0, atol=1e-9)
    np.testing.assert_allclose(normal, w_normal, rtol=0, atol=1e-6)
    np.testing.assert_allclose(ng, w_ng, rtol=0, atol=1e-6)
    np.testing.assert_allclose(wo, w_wo, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(material, w_material)
    np.testing.assert_array_equal(emission, w_emission)
    if corner_normals:
        # the interpolated normals differ from the winding ones somewhere
        assert np.mean(np.abs(normal - ng).max(axis=1) > 1e-3) > 0.1


def test_camera_hits_refuse_a_bad_camera_and_another_scene():
    import voxgi

    scene = voxgi.scenes.cornell_box(width=8, height=6)
    cam = scene.camera
    _, _, tri_args, tr = _camera_hits_both_ways(scene, cam, (0.5, 0.5), (0.0, 0.0))
    right, up, fwd = cam.frame()
    eye = np.asarray(cam.eye, np.float64)
    good = dict(eye=eye, right=right, up=up, forward=fwd, tan_half_fov=0.5, width=8, height=6)
    good.update(aperture=0.0, focus=1.0, offset=(0.5, 0.5), lens=(0.0, 0.0))

    def call(scene=tr.native, **change):
        kw = {**good, **change}
        return _core.camera_hits(
            **kw,
            tri_v=tri_args[0],
            tri_ng=tri_args[1],
            corner_normals=None,
            tri_object=tri_args[3],
            obj_two_sided=tri_args[4],
            obj_emission=tri_args[5],
            scene=scene,
        )

    assert call()[0].shape == (48, 3)
    with pytest.raises(ValueError, match="eye must be finite"):
        call(eye=np.array([0.0, np.nan, 0.0]))
    with pytest.raises(ValueError, match="width and height"):
        call(width=0)
    with pytest.raises(ValueError, match="tan_half_fov"):
        call(tan_half_fov=-1.0)
    with pytest.raises(ValueError, match="focus must be finite"):
        call(aperture=0.1, focus=0.0)
    with pytest.raises(ValueError, match="offset and lens must be finite"):
        call(lens=(math.inf, 0.0))
    other = _core.RayScene(rays.embree_library(), tri_args[0][:3].astype(np.float32))
    with pytest.raises(ValueError, match="scene holds 3 triangles"):
        call(scene=other)


def _boxes_over_a_mirror(mirror, eye, up):
    """Three boxes above the plane z = 0, with ``mirror`` (a conductor's
    (eta, k), or None: none) a mirror of alpha 1e-4 lying in that plane
    facing +z (the last object), and a 40 x 30 camera at ``eye`` looking at
    the origin; the camera hits' tables."""
    import trimesh

    import voxgi
    from voxgi.display.shader import _Tracer

    cam = voxgi.Camera(eye=eye, target=(0.0, 0.0, 0.0), up=up, fov=50.0, width=40, height=30)
    scene = voxgi.Scene(cam)
    for k, (c, e) in enumerate(
        [((0.4, 0.3, 0.6), 0.5), ((-0.6, 0.2, 1.1), 0.4), ((0.1, -0.7, 0.8), 0.3)]
    ):
        box = trimesh.creation.box(extents=(e, 1.5 * e, e))
        box.apply_translation(c)
        scene.add(box, voxgi.Material(0.2 + 0.2 * k), name=f"box{k}")
    if mirror:
        quad = trimesh.Trimesh(
            [[-4, -4, 0], [4, -4, 0], [4, 4, 0], [-4, 4, 0]], [[0, 1, 2], [0, 2, 3]], process=False
        )
        lobe = voxgi.Microfacet("conductor", alpha=1e-4, eta=mirror[0], k=mirror[1])
        scene.add(quad, voxgi.Material(0.5, specular=lobe), name="mirror")
    tr = _Tracer(scene, 2)
    n_obj = len(scene.objects)
    tables = (
        np.ascontiguousarray(tr.tris, np.float64),
        np.ascontiguousarray(tr.ng, np.float64),
        None,
        np.ascontiguousarray(tr.obj, np.int32),
        np.zeros(n_obj, np.uint8),
        np.arange(1, 3 * n_obj + 1, dtype=np.float32).reshape(n_obj, 3),
    )
    return cam, scene, tr, tables


def _conductor_fresnel(c, eta, k):
    """|r|² averaged over both polarisations, from the complex index n = eta + i k."""
    n = eta + 1j * k
    s = np.sqrt(1 - c * c + 0j)
    ct = np.sqrt(1 - (s / n) ** 2)
    rs = (c - n * ct) / (c + n * ct)
    rp = (ct - n * c) / (ct + n * c)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


@pytest.mark.parametrize("metal", ["perfect", "Au"])
def test_camera_hits_go_on_through_a_mirror_to_what_the_unfolded_camera_sees(metal):
    # A camera looking down at a mirror in the plane z = 0 sees, through it,
    # what a camera at its image below the plane (the scene without the
    # mirror) sees, left and right swapped: the same points, normals and
    # objects, the ray's way back the image camera's, and `through` the
    # mirror's f cos / pdf, its Fresnel reflectance at the ray's incidence
    # for a lobe of alpha 1e-4 (1 for a perfect mirror, eta 0 and k 1).
    import voxgi
    from voxgi.display.samples import camera_arguments

    eta, k = ((0.0,) * 3, (1.0,) * 3) if metal == "perfect" else voxgi.CONDUCTORS[metal]
    cam, scene, tr, tables = _boxes_over_a_mirror((eta, k), (0.3, -3.0, 3.0), (0.0, 0.0, 1.0))
    cam2, _, tr2, tables2 = _boxes_over_a_mirror(None, (0.3, -3.0, -3.0), (0.0, 0.0, -1.0))
    n_obj = len(scene.objects)
    lobes = np.zeros((n_obj, len(scene.objects[-1].material.specular.lobe_row())), np.float32)
    lobes[-1] = scene.objects[-1].material.specular.lobe_row()
    mirror = np.zeros(n_obj, np.uint8)
    mirror[-1] = 1
    try:
        plain = _core.camera_hits(
            *camera_arguments(cam, tr.centre), (0.5, 0.5), (0.0, 0.0), *tables, tr.native
        )
        got = _core.camera_hits(
            *camera_arguments(cam, tr.centre),
            (0.5, 0.5),
            (0.0, 0.0),
            *tables,
            tr.native,
            obj_mirror=mirror,
            obj_lobe=lobes,
            mirror_seed=7,
            eps=1e-6,
            mirror_point=(0.3, 0.6),
        )
        want = _core.camera_hits(
            *camera_arguments(cam2, tr2.centre), (0.5, 0.5), (0.0, 0.0), *tables2, tr2.native
        )
    finally:
        tr.close()
        tr2.close()
    W, H = cam.width, cam.height

    def swap(a):  # the image camera's pixels, left and right swapped
        return a.reshape(H, W, *a.shape[1:])[:, ::-1].reshape(a.shape)

    pos, normal, _, wo, material, emission, prim, through, _ = got
    seen = plain[4] == n_obj - 1  # the pixels that see the mirror
    assert 0.3 < seen.mean() < 1.0
    # elsewhere nothing changes
    np.testing.assert_array_equal(pos[~seen], plain[0][~seen])
    np.testing.assert_array_equal(through[~seen], 1.0)
    w_pos, w_normal, _, w_wo, w_material, w_emission, w_prim, _, _ = (
        swap(a) if a is not None else None for a in want
    )
    boxes = seen & (w_material >= 0)
    assert boxes.sum() > 20
    assert (seen & (w_prim < 0)).sum() > 20
    np.testing.assert_array_equal(material[seen], w_material[seen])
    np.testing.assert_array_equal(prim[seen] < 0, w_prim[seen] < 0)
    # the lobe's directions lie within a few alpha of the mirror direction
    # (GGX's tail: a few in a hundred beyond 1e-3)
    off = np.abs(wo[seen] - w_wo[seen]).max(axis=1)
    assert off.max() < 1e-2
    assert np.quantile(off, 0.9) < 1e-3
    far = np.abs(pos[boxes] + tr.centre - (w_pos[boxes] + tr2.centre)).max(axis=1)
    assert far.max() < 5e-2
    assert np.quantile(far, 0.9) < 5e-3
    np.testing.assert_allclose(normal[boxes], w_normal[boxes], rtol=0, atol=1e-6)
    np.testing.assert_array_equal(emission[seen], w_emission[seen])
    # one sample's f cos / pdf: the Fresnel reflectance at the incidence
    cos = np.abs(w_wo[seen][:, 2])
    fresnel = np.stack([_conductor_fresnel(cos, eta[c], k[c]) for c in range(3)], axis=1)
    ratio = through[seen] / fresnel
    assert abs(ratio.mean() - 1.0) < 1e-3
    assert np.abs(ratio - 1.0).max() < 1e-2
    if metal == "Au":
        assert np.ptp(fresnel[:, 2]) > 0.01
        assert fresnel[:, 2].max() < 0.9


def test_camera_kernels_refuse_bad_mirrors():
    import voxgi
    from voxgi.display.samples import camera_arguments

    perfect = ((0.0,) * 3, (1.0,) * 3)
    cam, scene, tr, tables = _boxes_over_a_mirror(perfect, (0.3, -3.0, 3.0), (0.0, 0.0, 1.0))
    n_obj = len(scene.objects)
    lobes = np.zeros((n_obj, len(scene.objects[-1].material.specular.lobe_row())), np.float32)
    lobes[-1] = scene.objects[-1].material.specular.lobe_row()
    mirror = np.zeros(n_obj, np.uint8)
    mirror[-1] = 1
    good = dict(obj_mirror=mirror, obj_lobe=lobes, mirror_seed=1, eps=1e-6)
    args = (*camera_arguments(cam, tr.centre), (0.5, 0.5), (0.0, 0.0), *tables, tr.native)
    plastic = lobes.copy()
    plastic[-1] = voxgi.Microfacet("plastic", alpha=0.02).lobe_row()
    try:
        for change, word in [
            ({"obj_mirror": mirror[:-1]}, "obj_mirror"),
            ({"obj_lobe": None}, "obj_mirror needs obj_lobe"),
            ({"obj_lobe": lobes[:, :-1].copy()}, "obj_lobe"),
            ({"obj_lobe": plastic}, "not a conductor's lobe"),
            ({"eps": 0.0}, "eps"),
            ({"mirror_point": (1.0, 0.5)}, "mirror_point"),
        ]:
            with pytest.raises(ValueError, match=word):
                _core.camera_hits(*args, **{**good, **change})
        # no mirror at all: the same hits as without the arguments, no `through`
        none = _core.camera_hits(*args, **{**good, "obj_mirror": np.zeros(n_obj, np.uint8)})
        assert none[7] is None
        samples = np.array([[0.5, 0.5, 0.0, 0.0, 1.2, 0.1]])
        with pytest.raises(ValueError, match="mirror numbers 0 outside"):
            _core.camera_emission(
                *camera_arguments(cam, tr.centre)[:9],
                np.array([0], np.int64),
                samples,
                *tables,
                tr.native,
                **good,
            )
    finally:
        tr.close()
