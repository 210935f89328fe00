"""A glossy record reflects the light it gathers by its directional albedo
(voxgi.incidence, docs/design.md §14).

Closed forms: the directional albedo R(μ) averages, under uniform light, to
the albedo the solve's records carry; a glossy floor under a low sun
reflects R(μ) E, not its mean albedo times E; and each estimate of a
record's light (shadow rays to emitters, traced passes) weighs its samples
by R(μ) / A at their own cosine, which a small light far away makes a
single cosine.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import voxgi
from voxgi._core import direct_light_traced
from voxgi.direct import direct_irradiance
from voxgi.incidence import NODES, IncidenceResponse, incidence_response
from voxgi.radiosity.tuning import _StudyTuning
from voxgi.rays import ray_scene
from voxgi.traced import TracedGather

PLASTIC = voxgi.Microfacet(alpha=0.1)
LOBES = [
    PLASTIC,
    voxgi.Microfacet(alpha=0.01, nonlinear=True),
    voxgi.Microfacet(alpha=0.3, distribution="beckmann"),
    voxgi.Microfacet(kind="conductor", alpha=0.1, eta=(0.2, 0.9, 1.1), k=(3.9, 2.4, 2.1)),
]
BASE = (0.8, 0.5, 0.1)


@pytest.mark.parametrize("lobe", LOBES, ids=["plastic", "nonlinear", "beckmann", "conductor"])
def test_directional_albedo_averages_to_the_solve_albedo(lobe):
    x, w = np.polynomial.legendre.leggauss(64)
    mu, w = 0.5 * (x + 1.0), 0.5 * w
    mean = (2.0 * w * mu) @ lobe.directional_albedo(BASE, mu)
    np.testing.assert_allclose(mean, lobe.solve_albedo(np.array(BASE)), rtol=1e-4)


def test_a_plastic_reflects_more_at_grazing_incidence():
    # the coat reflects 4% at normal incidence and nearly all at grazing
    r = PLASTIC.directional_albedo(BASE, [1.0, 0.5, 0.05])
    assert np.all(r[0] < r[1])
    assert np.all(r[1] < r[2])
    a = PLASTIC.solve_albedo(np.array(BASE))
    assert np.all(r[0] < a)
    assert np.all(r[2] > a)


def _floor(material: voxgi.Material, half: float = 4.0) -> voxgi.Scene:
    sc = voxgi.Scene()
    v = [[-half, 0, -half], [half, 0, -half], [half, 0, half], [-half, 0, half]]
    sc.add(trimesh.Trimesh(v, [[0, 2, 1], [0, 3, 2]], process=False), material, name="floor")
    return sc


def _response(sc, vox, mu):
    """(3,) the floor's tabulated R / A at mu."""
    resp = incidence_response(sc, vox)
    up = np.flatnonzero(resp.row >= 0)
    return resp.at(up[:1], np.array([mu]))[0]


@pytest.mark.parametrize("incidence", [True, False])
def test_a_glossy_floor_under_a_low_sun_reflects_its_directional_albedo(incidence):
    # sun at cos θ = 1/4 (a node of the table): E = cos θ, and the floor's
    # radiosity is R(1/4) E; the diffuse reading A E is 30% short
    mu = 0.25
    sc = _floor(voxgi.Material(BASE, specular=PLASTIC))
    sc.add_light(voxgi.DirectionalLight((np.sqrt(1 - mu * mu), -mu, 0.0), 1.0))
    vox = voxgi.voxelize(sc, 16, progress=False)
    sol = voxgi.solve(vox, progress=False, threads=1, tuning=_StudyTuning(incidence=incidence))
    up = vox.normal[:, 1] > 0.5
    want = PLASTIC.directional_albedo(BASE, [mu])[0] * mu
    got = np.asarray(sol.radiosity, np.float64)[up]
    if incidence:
        np.testing.assert_allclose(got, np.broadcast_to(want, got.shape), rtol=2e-3)
        # and the part its base reflects, which the display reads as the
        # record's mean (the coat's it follows in direction): base(1/4) E
        base = PLASTIC.base_albedo(BASE, [mu])[0] * mu
        split = np.asarray(sol.base_radiosity, np.float64)[up]
        np.testing.assert_allclose(split, np.broadcast_to(base, split.shape), rtol=2e-3)
        # the table's linear interpolation between nodes stays within 1%
        i = int(mu * (NODES - 1))
        between = PLASTIC.directional_albedo(BASE, [(i + 0.5) / (NODES - 1)])[0]
        mid = 0.5 * (
            _response(sc, vox, i / (NODES - 1)) + _response(sc, vox, (i + 1) / (NODES - 1))
        )
        np.testing.assert_allclose(mid * PLASTIC.solve_albedo(np.array(BASE)), between, rtol=1e-2)
    else:
        # the mean albedo: 2% short in red (a strong base), 40% in blue (a weak one)
        assert np.all(got[:, 2] / want[2] < 0.7)


def _floor_and_far_lamp(mu: float):
    """A glossy floor and a small emitting cube ten times its half width
    away, seen from the floor's middle at cos θ = mu; and the lamp's centre."""
    sc = _floor(voxgi.Material(BASE, specular=PLASTIC), half=1.0)
    centre = np.array([np.sqrt(1 - mu * mu), mu, 0.0]) * 10.0
    sc.add(
        trimesh.creation.box((0.2, 0.2, 0.2)).apply_translation(centre),
        voxgi.Material(0.0, emission=50.0),
        name="lamp",
    )
    return sc, centre


def _cosines(vox, records, centre):
    """(R,) the cosine at which each record sees the point ``centre``."""
    d = centre - vox.centroid[records]
    return d[:, 1] / np.linalg.norm(d, axis=1)


def test_shadow_rays_to_a_far_lamp_weigh_each_sample_by_its_response():
    sc, centre = _floor_and_far_lamp(0.15)
    vox = voxgi.voxelize(sc, 96, progress=False)
    resp = incidence_response(sc, vox)
    floor = np.flatnonzero(resp.row >= 0)
    plain, _ = direct_irradiance(sc, vox, threads=1, seed=3)
    weighed, _ = direct_irradiance(sc, vox, threads=1, seed=3, response=resp)
    lit = floor[plain[floor, 1] > 0]
    assert len(lit) > 20
    ratio = weighed[lit] / plain[lit]
    # the lamp spans about 1.6° from every floor record: one cosine
    want = resp.at(lit, _cosines(vox, lit, centre))
    np.testing.assert_allclose(ratio, want, rtol=1e-2)
    assert want.max() > 1.3  # where the mean albedo would be 30% short
    # records without a lobe (the lamp's) are left alone
    other = np.flatnonzero((resp.row < 0) & (plain[:, 1] > 0))
    np.testing.assert_array_equal(weighed[other], plain[other])


def test_a_traced_pass_weighs_each_ray_by_the_response_at_its_cosine():
    sc, centre = _floor_and_far_lamp(0.3)
    sc.objects[1].material = voxgi.Material(0.5)  # a reflecting cube to read
    vox = voxgi.voxelize(sc, 96, progress=False)
    resp = incidence_response(sc, vox)
    floor = np.flatnonzero(resp.row >= 0)
    values = np.where((vox.object_id == 1)[:, None], 1.0, 0.0) * np.ones((1, 3))
    with TracedGather(sc, vox, threads=1) as g:
        plain = g(values, 4096, seed=5)
    with TracedGather(sc, vox, threads=1, response=resp) as g:
        weighed = g(values, 4096, seed=5)
    seen = floor[plain[floor, 1] > 0]
    assert len(seen) > 20
    ratio = weighed[seen] / plain[seen]
    # the few rays that meet the cube meet it within its angular size
    # (±0.01 in cos θ): the ratio lies within the response over that range
    mu = _cosines(vox, seen, centre)
    lo = np.minimum(resp.at(seen, mu - 0.015), resp.at(seen, mu + 0.015))
    hi = np.maximum(resp.at(seen, mu - 0.015), resp.at(seen, mu + 0.015))
    assert np.all((ratio > lo * (1 - 1e-5)) & (ratio < hi * (1 + 1e-5)))
    assert ratio[:, 2].min() > 1.4


def test_a_bad_response_is_named():
    sc, _ = _floor_and_far_lamp(0.5)
    vox = voxgi.voxelize(sc, 8, progress=False)
    resp = incidence_response(sc, vox)
    bad = resp.row.copy()
    bad[3] = 7
    with pytest.raises(ValueError, match="record 3 names row 7 of a table of 1"):
        IncidenceResponse(table=resp.table, row=bad)
    nan = resp.table.copy()
    nan[0, 5, 1] = np.nan
    with pytest.raises(ValueError, match="row 0 holds a value that is not finite"):
        IncidenceResponse(table=nan, row=resp.row)
    # the kernel checks its own inputs too, naming the batch's record
    tri = np.array([[[0.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 1.0]]])
    emitters = (
        tri,
        np.array([[0.0, -1.0, 0.0]]),
        np.zeros(1, np.uint8),
        np.ones((1, 3)),
        np.ones(1),
        np.full(1, 2.0),
    )
    point = (np.zeros((1, 3)), np.array([[0.0, 1.0, 0.0]]), np.zeros((1, 5)), np.zeros((1, 5)))
    with pytest.raises(ValueError, match="response_row: record 0 names row 7 of 1"):
        direct_light_traced(
            emitters,
            *point,
            1e-4,
            np.zeros(1, np.int32),
            ray_scene(tri.astype(np.float32)),
            response=resp.table,
            response_row=np.array([7], np.int32),
        )


def test_a_scene_without_lobes_has_no_response():
    sc = _floor(voxgi.Material(0.5))
    vox = voxgi.voxelize(sc, 8, progress=False)
    assert incidence_response(sc, vox) is None
