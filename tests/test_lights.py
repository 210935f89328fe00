"""Point, spot and directional lights and the environment (voxgi.lights, docs/design.md §11).

Closed forms: a point light over a plane gives ``I cos θ / r²``, a sun
``E cos θ``; a constant environment of radiance L over an unoccluded plane
gives ``π L``, and nothing inside a closed sphere; a diffuse plane under it
shows ``ρ L``. The Mitsuba comparisons render the same tiny scene with
``to_mitsuba``'s translation.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from conftest import paper

import voxgi
from voxgi.direct import ENVIRONMENT_SAMPLES, light_irradiance
from voxgi.incidence import incidence_response
from voxgi.lights import spot_falloff


def _plane(half: float = 50.0, albedo: float = 0.5, camera=None) -> voxgi.Scene:
    """An upward one-sided square plane at y = 0."""
    sc = voxgi.Scene(camera=camera)
    v = [[-half, 0, -half], [half, 0, -half], [half, 0, half], [-half, 0, half]]
    sc.add(trimesh.Trimesh(v, [[0, 2, 1], [0, 3, 2]], process=False), voxgi.Material(albedo))
    return sc


def _up_records(sc: voxgi.Scene, resolution: int = 48):
    vox = voxgi.voxelize(sc, resolution=resolution, progress=False)
    up = vox.normal[:, 1] > 0.5
    assert up.sum() > 100
    return vox, up


def _solved(sc: voxgi.Scene, resolution: int) -> voxgi.Solution:
    """The solution ``voxgi.render(sc)`` would display, at ``resolution``."""
    return voxgi.solve(voxgi.voxelize(sc, resolution), progress=False, threads=1)


def test_point_light_over_plane_is_exact():
    # E = I cos θ / r², cos θ = h / r for a light at height h over the plane
    sc = _plane()
    pos, inten = np.array([3.0, 2.0, -1.0]), np.array([2.0, 1.0, 0.5])
    sc.add_light(voxgi.PointLight(pos, inten))
    vox, up = _up_records(sc)
    e, st = light_irradiance(sc, vox, threads=1)
    d = pos - vox.centroid[up]
    r2 = np.einsum("ij,ij->i", d, d)
    want = inten[None, :] * (pos[1] - vox.centroid[up, 1] + 0 * r2)[:, None] / r2[:, None] ** 1.5
    np.testing.assert_allclose(e[up], want, rtol=1e-9)
    assert st["rays"] == int(up.sum())
    # the black back side of the one-sided plane reflects nothing: not lit
    assert np.all(e[~up] == 0)


def test_sun_on_plane_is_exact():
    # E cos θ with cos θ = -direction·n
    sc = _plane()
    d = np.array([1.0, -2.0, 0.5])
    sc.add_light(voxgi.DirectionalLight(d, (3.0, 2.0, 1.0)))
    vox, up = _up_records(sc)
    e, _ = light_irradiance(sc, vox, threads=1)
    cos = 2.0 / np.linalg.norm(d)
    np.testing.assert_allclose(e[up], np.tile([3.0 * cos, 2.0 * cos, cos], (up.sum(), 1)), 1e-12)


def test_sun_is_blocked_by_an_occluder():
    # a slab above part of the plane shadows exactly the records under it
    sc = _plane(half=5.0)
    sc.add(trimesh.creation.box((2.0, 0.1, 2.0)).apply_translation((0, 1, 0)), voxgi.Material())
    sc.add_light(voxgi.DirectionalLight((0, -1, 0), 1.0))
    vox, _ = _up_records(sc, 64)
    e, _ = light_irradiance(sc, vox, threads=1)
    floor = (np.abs(vox.centroid[:, 1]) < 1e-9) & (vox.normal[:, 1] > 0.5)
    under = floor & np.all(np.abs(vox.centroid[:, [0, 2]]) < 0.95, axis=1)
    outside = floor & np.any(np.abs(vox.centroid[:, [0, 2]]) > 1.05, axis=1)
    assert np.all(e[under] == 0)
    assert np.all(e[outside, 0] == 1.0)


def test_constant_environment_over_plane_gives_pi_l():
    # ∫ L cos θ dω over the upper hemisphere = π L; the estimate is unbiased,
    # so the mean over N records is within 4 standard errors of it
    sc = _plane()
    L = np.array([1.0, 0.5, 2.0])
    sc.environment = voxgi.Environment(L)
    vox, up = _up_records(sc)
    e, st = light_irradiance(sc, vox, samples=16, seed=3, threads=1)
    vals = e[up] / (math.pi * L)
    se = vals.std(axis=0) / math.sqrt(len(vals))
    assert np.all(np.abs(vals.mean(axis=0) - 1.0) < 4 * se + 1e-12), (vals.mean(axis=0), se)
    assert se.max() < 0.01  # the check can see a 4% error
    assert st["environment_samples"] == ENVIRONMENT_SAMPLES * 16


def test_a_plastic_planes_records_weigh_a_low_sky_by_their_incidence_response():
    # A sky that shines only below 45° of elevation: a record of a plastic
    # plane gathers 2π ∫ L (R(μ) / A) μ dμ over μ < cos 45°, more than the
    # π L / 2 a diffuse record would (a plastic reflects grazing light
    # better), and its base's part with base(μ) in place of R(μ) / A.
    sc = voxgi.Scene()
    v = [[-50, 0, -50], [50, 0, -50], [50, 0, 50], [-50, 0, 50]]
    lobe = voxgi.Microfacet("plastic", alpha=0.1)
    plane = trimesh.Trimesh(v, [[0, 2, 1], [0, 3, 2]], process=False)
    sc.add(plane, voxgi.Material(0.5, specular=lobe))
    sky = np.zeros((8, 16, 3))
    sky[2:4] = 1.0  # rows 2 and 3: θ from 45° to 90°
    sc.environment = voxgi.Environment(sky)
    vox, up = _up_records(sc)
    resp = incidence_response(sc, vox)
    base = np.zeros((len(vox), 3))
    e, _ = light_irradiance(sc, vox, samples=16, seed=5, threads=2, response=resp, base_out=base)
    mu = np.linspace(0.0, math.sqrt(0.5), 4001)
    rec = np.full(len(mu), np.flatnonzero(up)[0])
    for got, weight in ((e, resp.at(rec, mu)), (base, resp.at(rec, mu, base=True))):
        want = 2 * math.pi * np.trapezoid(weight[:, 0] * mu, mu)
        vals = got[up, 0]
        se = vals.std() / math.sqrt(len(vals))
        assert abs(vals.mean() - want) < 4 * se, (vals.mean(), want, se)
        assert se < 0.005 * want  # the check can see a 2% error
    # the response matters here: the diffuse answer π / 2 is 3% (8 se) off
    want = 2 * math.pi * np.trapezoid(resp.at(rec, mu)[:, 0] * mu, mu)
    assert want - math.pi / 2 > 8 * e[up, 0].std() / math.sqrt(up.sum())


def test_closed_sphere_gets_no_environment_light():
    # every ray from inside meets the sphere: no record sees the sky
    sph = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    sph.invert()  # lit side inward
    sc = voxgi.Scene()
    sc.add(sph, voxgi.Material(0.5))
    sc.environment = voxgi.Environment(3.0)
    vox = voxgi.voxelize(sc, resolution=24, progress=False)
    e, _ = light_irradiance(sc, vox, samples=8, threads=1, receivers="all")
    inside = np.einsum("ij,ij->i", vox.normal, vox.centroid) < 0
    assert inside.sum() > 100
    assert np.all(e[inside] == 0)
    # the black outer side (lit here with receivers="all") sees the sky: from a face of a
    # convex mesh the whole outward hemisphere, so E = pi L on every record
    out = e[~inside, 0] / (math.pi * 3.0)
    se = out.std() / math.sqrt(len(out))
    assert abs(out.mean() - 1.0) < 4 * se, (out.mean(), se)
    assert se < 0.005  # the check can see a 2% error


def test_environment_sampling_density_matches_its_pdf():
    # sample() and pdf() agree, and the density integrates to 1 over the sphere
    rng = np.random.default_rng(0)
    env = voxgi.Environment(rng.random((8, 16, 3)) ** 3, to_world=np.diag([1.0, -1.0, -1.0]))
    d, p = env.sample(rng.random((2000, 3)))
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, rtol=1e-12)
    np.testing.assert_allclose(env.pdf(d), p, rtol=1e-12)
    # uniform directions: E[pdf / (1/4π)] = 1
    u = rng.normal(size=(200000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    assert abs(env.pdf(u).mean() * 4 * math.pi - 1.0) < 0.02


def test_environment_orientation_follows_mitsuba():
    # lat-long, y up: the top row is +y, u = atan2(x, -z) / 2π picks the column
    img = np.zeros((2, 4, 3))
    img[0, 1] = 1.0  # θ < 90°, φ in [90°, 180°): direction (+x, +y, ...)
    env = voxgi.Environment(img)
    d = np.array([[math.sin(math.radians(135)), 0.5, -math.cos(math.radians(135))]])
    assert env.eval(d)[0, 0] == 1.0
    assert env.eval(d * [1, -1, 1])[0, 0] == 0.0
    rot = voxgi.Environment(
        img, to_world=trimesh.transformations.rotation_matrix(math.pi, [1, 0, 0])
    )
    assert rot.eval(d * [1, -1, -1])[0, 0] == 1.0


def _mitsuba_spot_falloff(cos_theta, cutoff_deg, beam_deg):
    """Mitsuba 3's spot.cpp falloff_curve, written out: 1 inside the beam,
    (cutoff − θ) / (cutoff − beam) in the transition, 0 outside the cutoff."""
    cutoff, beam = math.radians(cutoff_deg), math.radians(beam_deg)
    inv_transition = 1.0 / (cutoff - beam)
    out = []
    for c in cos_theta:
        beam_res = 1.0 if c >= math.cos(beam) else (cutoff - math.acos(c)) * inv_transition
        out.append(beam_res if c > math.cos(cutoff) else 0.0)
    return np.array(out)


def test_spot_falloff_is_mitsubas():
    c = np.cos(np.radians(np.linspace(0, 40, 401)))
    np.testing.assert_allclose(spot_falloff(c, 30.0, 12.0), _mitsuba_spot_falloff(c, 30.0, 12.0))
    spot = voxgi.SpotLight((0, 2, 0), (0, -1, 0), 4.0, cutoff_angle=30.0, beam_width=12.0)
    x = np.stack([2 * np.tan(np.radians([0, 10, 20, 29.9, 31])), np.zeros(5), np.zeros(5)], 1)
    _w, r, e = spot.incident(x)
    want = 4.0 * _mitsuba_spot_falloff(np.cos(np.radians([0, 10, 20, 29.9, 31])), 30, 12) / r**2
    np.testing.assert_allclose(e[:, 0], want, rtol=1e-9)


def test_display_of_plane_under_constant_environment_is_rho_l():
    # a single plane: no indirect light, so L = ρ L_env (ρ/π · π L_env)
    cam = voxgi.Camera(eye=(0, 3, 0.01), target=(0, 0, 0), fov=40, width=16, height=16)
    sc = _plane(half=5.0, albedo=0.6, camera=cam)
    sc.environment = voxgi.Environment((1.0, 2.0, 0.5))
    out = voxgi.render(sc, _solved(sc, 16), progress=False, max_frames=16, tol=0, threads=1)
    want = 0.6 * np.array([1.0, 2.0, 0.5])
    mean = out.image.reshape(-1, 3).mean(axis=0)
    se = np.sqrt((out.stderr.reshape(-1, 3) ** 2).mean(axis=0) / out.image[..., 0].size)
    assert np.all(np.abs(mean - want) < 4 * se + 1e-6), (mean, want, se)
    assert np.all(se < 0.005 * want)


def test_display_of_plane_under_sun_is_exact():
    # L = ρ/π · E cos θ at every pixel; the camera sees only the plane
    cam = voxgi.Camera(eye=(0, 3, 0.01), target=(0, 0, 0), fov=40, width=12, height=12)
    sc = _plane(half=5.0, albedo=0.6, camera=cam)
    sc.add_light(voxgi.DirectionalLight((0.0, -1.0, 1.0), 2.0))
    out = voxgi.render(sc, _solved(sc, 16), progress=False, max_frames=2, tol=0, threads=1)
    np.testing.assert_allclose(out.image, 0.6 / math.pi * 2.0 / math.sqrt(2), rtol=1e-5)


def test_camera_rays_that_escape_see_the_environment():
    cam = voxgi.Camera(eye=(0, 1, 0), target=(0, 2, 0), up=(0, 0, 1), fov=30, width=8, height=8)
    sc = _plane(half=1.0, camera=cam)
    sc.environment = voxgi.Environment((0.25, 0.5, 1.0))
    out = voxgi.render(sc, _solved(sc, 8), progress=False, max_frames=2, tol=0, threads=1)
    np.testing.assert_allclose(out.image, np.broadcast_to([0.25, 0.5, 1.0], out.image.shape))


def test_solve_with_lights_uses_exact_direct_light_and_says_so():
    sc = _plane(half=2.0)
    sc.add_light(voxgi.PointLight((0, 1, 0), 1.0))
    vox = voxgi.voxelize(sc, resolution=16, progress=False)
    sol = voxgi.solve(vox, radius=2, progress=False, threads=1, tuning=paper())
    assert sol.stats["direct_light"]["method"] == "exact"
    assert "shooting" in sol.stats["skipped"]
    assert sol.stats["direct_light"]["lights"]["lights"] == 1
    assert np.all(np.isfinite(sol.radiosity))
    assert sol.radiosity.max() > 0


def test_lights_change_the_fingerprint():
    a = _plane()
    fp = a.fingerprint()
    a.add_light(voxgi.PointLight((0, 1, 0), 1.0))
    fp1 = a.fingerprint()
    a.environment = voxgi.Environment(1.0)
    assert len({fp, fp1, a.fingerprint()}) == 3


def test_toml_round_trip(tmp_path):
    sc = _plane(half=2.0)
    sc.add_light(voxgi.PointLight((0, 1, 0), (1.0, 2.0, 3.0)))
    sc.add_light(voxgi.SpotLight((0, 2, 0), (0, -1, 0.1), 5.0, cutoff_angle=40, beam_width=20))
    sc.add_light(voxgi.DirectionalLight((0.1, -1, 0), 2.5))
    rot = trimesh.transformations.rotation_matrix(0.5, [0, 1, 0])
    img = np.random.default_rng(0).random((4, 8, 3))  # float64: kept as float32 values
    sc.environment = voxgi.Environment(img, to_world=rot)
    back = voxgi.Scene.load(sc.save(tmp_path / "lit.toml"))
    assert back.lights == sc.lights
    assert back.environment == sc.environment
    assert back.fingerprint() == sc.fingerprint()
    sc.environment = voxgi.Environment((0.5, 1.0, 2.0))
    back = voxgi.Scene.load(sc.save(tmp_path / "lit2.toml"))
    assert back.environment == sc.environment
    assert back.fingerprint() == sc.fingerprint()


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: voxgi.PointLight((0, 1), 1.0), "PointLight.position"),
        (lambda: voxgi.PointLight((0, 1, 0), -1.0), "PointLight.intensity"),
        (lambda: voxgi.SpotLight((0, 1, 0), (0, 0, 0), 1.0), "SpotLight.direction"),
        (lambda: voxgi.SpotLight((0, 1, 0), (0, -1, 0), 1.0, 100.0), "SpotLight.cutoff_angle"),
        (lambda: voxgi.SpotLight((0, 1, 0), (0, -1, 0), 1.0, 20, 30), "SpotLight.beam_width"),
        (lambda: voxgi.DirectionalLight((0, 0, 0), 1.0), "DirectionalLight.direction"),
        (lambda: voxgi.Environment(-1.0), "Environment.radiance"),
        (lambda: voxgi.Environment(np.full((2, 4, 3), np.nan)), "Environment.radiance"),
        (lambda: voxgi.Environment(1.0, to_world=np.diag([1, 2, 1.0])), "rotation"),
        (lambda: voxgi.Environment("missing_sky.exr"), "not found"),
    ],
)
def test_bad_lights_name_the_value(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_bad_light_tables(tmp_path):
    sc = voxgi.Scene()
    with pytest.raises(TypeError, match="add_light"):
        sc.add_light(voxgi.Environment(1.0))
    with pytest.raises(TypeError, match=r"Scene\.environment"):
        sc.environment = 1.0
    with pytest.raises(ValueError, match=r"light #0.*'type'"):
        voxgi.Scene.from_dict({"light": [{"type": "area"}]})
    with pytest.raises(ValueError, match=r"light #0 \(point\): unknown key"):
        voxgi.Scene.from_dict({"light": [{"type": "point", "position": [0, 1, 0], "power": 3}]})
    with pytest.raises(ValueError, match=r"\[environment\]: give exactly one"):
        voxgi.Scene.from_dict({"environment": {"radiance": 1.0, "image": "a.exr"}})


# --------------------------------------------------------------------------
# Against Mitsuba 3: to_mitsuba's translation of each light
# --------------------------------------------------------------------------
def _mitsuba_cases():
    rng = np.random.default_rng(1)
    # an image with a bright patch off the axes: a wrong orientation moves the light
    img = 0.2 + np.repeat(np.repeat(rng.random((4, 8, 3)), 8, 0), 8, 1)
    img[4:10, 20:28] += 6.0
    rot = trimesh.transformations.rotation_matrix(0.7, [1, 0.3, 0])
    return {
        "point": lambda s: s.add_light(voxgi.PointLight((0.3, 1, 0.2), (2, 1, 0.5))),
        "spot": lambda s: s.add_light(voxgi.SpotLight((0, 1, 0), (0.3, -1, 0), 3.0, 30, 15)),
        "sun": lambda s: s.add_light(voxgi.DirectionalLight((0.3, -1, 0.2), (1, 2, 3))),
        "constant": lambda s: setattr(s, "environment", voxgi.Environment((1, 0.5, 0.25))),
        "envmap": lambda s: setattr(s, "environment", voxgi.Environment(img, to_world=rot)),
    }


@pytest.mark.parametrize("kind", ["point", "spot", "sun", "constant", "envmap"])
def test_to_mitsuba_lights_match_mitsuba(kind):
    pytest.importorskip("mitsuba")
    from voxgi.metrics import rel_mse
    from voxgi.mitsuba import render_mitsuba

    cam = voxgi.Camera(eye=(0, 3, 0.01), target=(0, 0, 0), fov=50, width=16, height=16)
    sc = _plane(half=5.0, camera=cam)
    _mitsuba_cases()[kind](sc)
    out = voxgi.render(sc, _solved(sc, 16), progress=False, max_frames=64, tol=2e-4, threads=1)
    ref = render_mitsuba(sc, 1024)
    # a single plane has no indirect light: the two differ by noise only
    # (measured relMSE: delta lights <= 6e-5, environments <= 1.2e-3 with a
    # reference noise ~3e-4 and Mitsuba's texel interpolation)
    err = rel_mse(out.image, ref)
    assert err < (2e-4 if kind in ("point", "spot", "sun") else 3e-3), err
    ratio = out.image.mean(axis=(0, 1)) / ref.mean(axis=(0, 1))
    np.testing.assert_allclose(ratio, 1.0, atol=0.02)


def _hdr_header(h: int, w: int) -> bytes:
    return b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y %d +X %d\n" % (h, w)


def test_environment_reads_radiance_hdr_files(tmp_path):
    # value = mantissa * 2^(exponent - 136) (Ward's RGBE, as stb_image reads it)
    g = np.arange(8, dtype=np.uint8) * 16
    b = np.array([64, 64, 64, 64, 1, 2, 3, 4], np.uint8)
    row = [2, 2, 0, 8, 136, 128, 8, *g, 132, 64, 4, 1, 2, 3, 4, 136, 129]  # run-length encoded
    flat = [255, 0, 0, 130] * 8  # row 2: flat RGBE, 255 * 2^-6 in red
    (tmp_path / "sky.hdr").write_bytes(_hdr_header(2, 8) + bytes(row) + bytes(flat))
    env = voxgi.Environment(tmp_path / "sky.hdr")
    want = np.zeros((2, 8, 3))
    want[0, :, 0], want[0, :, 1], want[0, :, 2] = 1.0, g / 128.0, b / 128.0
    want[1, :, 0] = 255 / 64
    np.testing.assert_array_equal(env.image, want)
    (tmp_path / "bad.hdr").write_bytes(b"P6\n")
    with pytest.raises(ValueError, match="not a Radiance HDR"):
        voxgi.Environment(tmp_path / "bad.hdr")


def test_closed_box_receives_all_of_a_point_lights_power():
    # Gauss: the surfaces around a point light receive its whole power 4π I;
    # the records' centroid quadrature of I cos θ / r² (measured within 2e-4
    # at resolution 32) counts it as emitted, and nothing escapes directly
    sc = voxgi.scenes.cornell_box(8, 8, closed=True, area_light=False)
    sc.add_light(voxgi.PointLight((0.278, 0.4, 0.2795), 0.25))
    vox = voxgi.voxelize(sc, resolution=32, progress=False)
    tuning = paper(direct_light="exact")
    sol = voxgi.solve(vox, radius=4, progress=False, threads=1, tuning=tuning)
    e = sol.stats["energy"]
    np.testing.assert_allclose(e["emitted"], math.pi, rtol=1e-3)
    np.testing.assert_allclose(e["escaping_shoot"], 0.0, atol=1e-12)
    # the gathering's imbalance at this resolution (docs/design.md §10): ~1.5%
    assert max(abs(x) for x in e["imbalance"]) < 0.03


def test_unit_directions_survive_a_reload_bit_for_bit():
    # a saved direction is already unit: loading it must not move its last
    # bits, or the reloaded scene's fingerprint no longer matches its solution
    rng = np.random.default_rng(0)
    for d in rng.normal(size=(300, 3)):
        sun = voxgi.DirectionalLight(d, 1.0)
        assert voxgi.DirectionalLight(sun.direction, 1.0) == sun
        spot = voxgi.SpotLight((0, 0, 0), d, 1.0)
        assert voxgi.SpotLight((0, 0, 0), spot.direction, 1.0) == spot


def test_bad_light_in_a_file_names_its_line(tmp_path):
    text = '[[object]]\nmesh = "m.obj"\n\n[[light]]\ntype = "point"\nposition = [0, 1, 0]\n'
    text += '\n[[light]]\ntype = "spot"\nposition = [0, 2, 0]\ndirection = [0, -1, 0]\n'
    text += "cutoff_angle = 120\n\n[environment]\nradiance = 1\n"
    (tmp_path / "m.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 0 1\nf 1 3 2\n")
    (tmp_path / "s.toml").write_text(text)
    with pytest.raises(
        ValueError, match=r"light #1 \(spot\): SpotLight\.cutoff_angle.*\(line 12\)"
    ):
        voxgi.Scene.load(tmp_path / "s.toml")
    (tmp_path / "s.toml").write_text(
        text.replace("120", "30").replace("radiance = 1", "scale = -2")
    )
    with pytest.raises(ValueError, match=r"\[environment\]: give exactly one.*\(line 14\)"):
        voxgi.Scene.load(tmp_path / "s.toml")
