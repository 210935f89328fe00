"""Scene model: materials, camera, meshes, TOML files, built-in scenes."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh
from conftest import fails_to_write

import voxgi
from voxgi.scene import Scene


def test_material_scalar_and_rgb():
    m = voxgi.Material(albedo=0.5, emission=(1, 2, 3))
    assert m.albedo == (0.5, 0.5, 0.5)
    assert m.emission == (1.0, 2.0, 3.0)
    assert m.is_emitter


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"albedo": 1.0}, r"Material.albedo.*\[0.0, 1.0\)"),
        ({"albedo": -0.1}, "Material.albedo"),
        ({"albedo": float("nan")}, "Material.albedo: non-finite"),
        ({"emission": -1.0}, "Material.emission"),
        ({"emission": (1, 2)}, "Material.emission.*shape"),
        # the kernels hold these in float32
        ({"albedo": 1 - 1e-12}, r"Material.albedo.*rounds to 1.0 in float32"),
        ({"albedo": (0.5, 0.5, 0.99999999)}, r"Material.albedo.*rounds to 1.0 in float32"),
        ({"emission": 1e39}, r"Material.emission.*1e\+39 does not fit in float32"),
    ],
)
def test_material_bad_values(kw, match):
    with pytest.raises(ValueError, match=match):
        voxgi.Material(**kw)


def test_material_bad_types():
    with pytest.raises(TypeError, match=r"Material\.albedo"):
        voxgi.Material(albedo="red")
    with pytest.raises(TypeError, match=r"Material\.specular"):
        voxgi.Material(specular=0.5)


def test_camera_frame_is_right_handed_as_documented():
    cam = voxgi.Camera(eye=(0, 0, 0), target=(0, 0, -1), up=(0, 1, 0))
    right, up, fwd = cam.frame()
    np.testing.assert_allclose(fwd, [0, 0, -1])
    np.testing.assert_allclose(up, [0, 1, 0])
    np.testing.assert_allclose(right, np.cross(fwd, up))
    np.testing.assert_allclose(right, [1, 0, 0])
    assert cam.focus == pytest.approx(1.0)


@pytest.mark.parametrize(
    ("kw", "exc", "match"),
    [
        ({"width": 0}, ValueError, "Camera.width"),
        ({"height": -3}, ValueError, "Camera.height"),
        ({"width": 2.5}, TypeError, "Camera.width"),
        ({"fov": 0.0}, ValueError, "Camera.fov"),
        ({"fov": 180.0}, ValueError, "Camera.fov"),
        ({"eye": (0, 0, 0), "target": (0, 0, 0)}, ValueError, "coincide"),
        ({"up": (0, 0, 1), "eye": (0, 0, 0), "target": (0, 0, -1)}, ValueError, "parallel"),
        ({"eye": (0, np.inf, 0)}, ValueError, "Camera.eye"),
        ({"aperture": -1.0}, ValueError, "Camera.aperture"),
    ],
)
def test_camera_bad_input(kw, exc, match):
    with pytest.raises(exc, match=match):
        voxgi.Camera(**kw)


def test_add_copies_the_mesh():
    mesh = trimesh.creation.box()
    before = mesh.vertices.copy()
    s = Scene()
    obj = s.add(mesh, voxgi.Material(), name="box")
    obj.vertices[:] = 0.0
    np.testing.assert_array_equal(mesh.vertices, before)


def test_add_bad_meshes():
    s = Scene()
    with pytest.raises(TypeError, match=r"mesh 'x'.*trimesh\.Trimesh"):
        s.add(np.zeros((3, 3)), name="x")
    bad = trimesh.creation.box()
    v = bad.vertices.copy()
    v[3, 1] = np.nan
    with pytest.raises(ValueError, match="mesh 'nanbox': vertex 3 is not finite"):
        s.add(trimesh.Trimesh(v, bad.faces, process=False), name="nanbox")
    with pytest.raises(TypeError, match="material"):
        s.add(trimesh.creation.box(), material="white")


def test_degenerate_faces_are_skipped_with_a_warning():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0]], float)
    f = np.array([[0, 1, 2], [0, 1, 3], [1, 1, 2]])  # 2nd collinear, 3rd repeats a vertex
    s = Scene()
    with pytest.warns(UserWarning, match="skipped 2 degenerate"):
        obj = s.add(trimesh.Trimesh(v, f, process=False), name="tri")
    assert obj.n_triangles == 1


@pytest.mark.parametrize(
    ("shift", "scale"), [(1e12, 1.0), (1e7, 1.0), (0.0, 1e-9), (0.0, 1e12), (-3e9, 1e-3)]
)
def test_degenerate_test_is_relative_to_each_triangle(shift, scale):
    box = trimesh.creation.box()
    box.apply_scale(scale)
    box.apply_translation([shift, -shift, 0.5 * shift])
    s = Scene()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        obj = s.add(box, name="box")
    assert obj.n_triangles == 12
    # a sliver whose corners are collinear to 1e-14 of its size is still degenerate
    v = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1e-14, 0], [0, 1, 0]]) * scale + shift
    with pytest.warns(UserWarning, match="skipped 1 degenerate"):
        obj = s.add(trimesh.Trimesh(v, [[0, 1, 2], [0, 1, 3]], process=False), name="sliver")
    assert obj.n_triangles == 1


def test_empty_scene_is_an_error():
    with pytest.raises(ValueError, match="scene is empty"):
        Scene().bounds  # noqa: B018


def test_toml_round_trip(tmp_path):
    s = voxgi.scenes.cornell_box(width=32, height=24)
    s.objects[0].material = voxgi.Material(
        albedo=0.3, specular=voxgi.AshikhminShirley(rs=0.2, nu=10, nv=1000)
    )
    path = s.save(tmp_path / "cbox.toml")
    t = Scene.load(path)
    assert t.camera == s.camera
    assert [o.name for o in t.objects] == [o.name for o in s.objects]
    for a, b in zip(s.objects, t.objects, strict=False):
        assert a.material == b.material
        np.testing.assert_allclose(a.vertices[a.faces], b.vertices[b.faces], rtol=1e-12)
    assert t.fingerprint() == s.fingerprint()


def test_toml_round_trip_of_awkward_names(tmp_path):
    s = Scene(camera=voxgi.Camera(focus_distance=2.5, aperture=0.01))
    names = ['line\nbreak "quoted" \\ tab\t del\x7f', "ünïcødé 😀", ""]
    for name in names:
        s.add(trimesh.creation.box(), voxgi.Material(albedo=1e-300), name=name)
    t = Scene.load(s.save(tmp_path / "odd.toml"))
    assert [o.name for o in t.objects] == names
    assert t.camera == s.camera
    assert t.fingerprint() == s.fingerprint()


def test_toml_transforms_and_named_materials(tmp_path):
    trimesh.creation.box().export(tmp_path / "box.obj")
    (tmp_path / "s.toml").write_text(
        "[materials.grey]\nalbedo = 0.5\n\n"
        '[[object]]\nmesh = "box.obj"\nmaterial = "grey"\nscale = 2.0\n'
        "rotate = [90, 0, 0, 1]\ntranslate = [10, 0, 0]\n"
    )
    s = Scene.load(tmp_path / "s.toml")
    np.testing.assert_allclose(s.bounds, [[9, -1, -1], [11, 1, 1]], atol=1e-12)
    assert s.objects[0].material.albedo == (0.5, 0.5, 0.5)
    assert s.area() == pytest.approx(24.0)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[camera\n", r"malformed TOML.*line 1"),
        ("[[object]]\nmesh = 'nope.ply'\n", "object #0.*mesh file not found"),
        ("[[object]]\nname='a'\nmesh = 'box.obj'\nalbedo = 2.0\n", r"object #0 \('a'\).*albedo"),
        ("[[object]]\nmesh = 'box.obj'\ncolour = 1\n", r"unknown key\(s\) \['colour'\]"),
        ("[[object]]\nmesh = 'box.obj'\nmaterial = 'x'\n", "unknown material 'x'"),
        ("[camera]\nfov = 200\n", r"\[camera\].*Camera.fov"),
        ("[camera]\nzoom = 2\n", r"\[camera\]"),
        ("lights = 3\n", "unknown top-level"),
        ("[[object]]\nmesh = 5\n", r"object #0.*'mesh' must be a string, got int 5"),
        (
            "[[object]]\nmesh = 'box.obj'\nmaterial = [1]\n",
            r"object #0.*'material' must be a string, got list \[1\]",
        ),
        ("[[object]]\nmesh = 'box.obj'\nname = 3\n", r"'name' must be a string"),
        ("x = " + "[" * 5000 + "]" * 5000 + "\n", "nested too deeply"),
        ("x = " + "{a = " * 5000 + "1" + "}" * 5000 + "\n", "nested too deeply"),
    ],
)
def test_toml_errors_name_where(tmp_path, text, match):
    trimesh.creation.box().export(tmp_path / "box.obj")
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises(ValueError, match=match):
        Scene.load(p)


@pytest.mark.parametrize("name", ["junk.obj", "junk.off"])
def test_random_bytes_as_a_text_mesh(tmp_path, name):
    (tmp_path / name).write_bytes(np.random.default_rng(1).bytes(3000))
    p = tmp_path / "s.toml"
    p.write_text(f"[[object]]\nmesh = '{name}'\n")
    with pytest.raises(ValueError, match=rf"object #0.*{name} is not UTF-8 text"):
        Scene.load(p)


def test_failed_save_keeps_the_earlier_files(tmp_path):
    small = voxgi.scenes.furnace_box()
    path = small.save(tmp_path / "s.toml")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    s = voxgi.Scene()
    s.add(trimesh.creation.icosphere(subdivisions=6), voxgi.Material(albedo=0.5), name="big")
    assert "refused:" in fails_to_write(s.save, path, fsize=50000)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    assert Scene.load(path).fingerprint() == small.fingerprint()


def test_missing_scene_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="scene file not found"):
        Scene.load(tmp_path / "none.toml")


def test_cornell_box_dimensions(cornell):
    # Published Cornell data: 556 x 548.8 x 559.2 mm, light 130 x 105 mm.
    np.testing.assert_allclose(cornell.bounds, [[0, 0, 0], [0.556, 0.5488, 0.5592]], atol=1e-9)
    light = next(o for o in cornell.objects if o.name == "light")
    assert light.area() == pytest.approx(0.130 * 0.105, rel=1e-9)
    centre = np.array([0.278, 0.2744, 0.2796])
    for o in cornell.objects:
        t = o.vertices[o.faces]
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        to_centre = centre - t.mean(axis=1)
        if o.name in ("floor", "ceiling", "back", "red", "green", "light"):
            assert np.all(np.einsum("ij,ij->i", n, to_centre) > 0), o.name  # face the room
        else:
            assert np.all(np.einsum("ij,ij->i", n, t.mean(axis=1) - t.mean(axis=(0, 1))) > 0)


def test_cornell_box_closed_without_blocks():
    s = voxgi.scenes.cornell_box(width=32, height=32, blocks=False, closed=True)
    names = [o.name for o in s.objects]
    assert "short_block" not in names
    assert "tall_block" not in names
    front = s.objects[names.index("front")]
    t = front.vertices[front.faces]
    assert np.allclose(t[..., 2], 0.0)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    assert np.all(n[:, 2] > 0)  # faces into the room (+z)
    assert front.area() == pytest.approx(0.5544 * 0.5488, rel=1e-2)


@pytest.mark.parametrize("make", [voxgi.scenes.furnace_sphere, voxgi.scenes.furnace_box])
def test_furnace_normals_point_inward(make):
    s = make(inner=True)
    enclosure = s.objects[0]
    t = enclosure.vertices[enclosure.faces]
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    assert np.all(np.einsum("ij,ij->i", n, -t.mean(axis=1)) > 0)
    inner = s.objects[1].to_trimesh()
    assert inner.is_watertight
    assert inner.volume > 0


def test_bunny_room_is_closed_and_lit():
    s = voxgi.scenes.bunny_room()
    room, bunny, light = s.objects
    assert bunny.to_trimesh().is_watertight
    assert light.material.is_emitter
    assert not room.material.is_emitter


def test_scene_registry():
    assert "cornell-box" in voxgi.scenes.names()
    with pytest.raises(ValueError, match="unknown built-in scene 'nope'"):
        voxgi.scenes.get("nope")


@pytest.mark.parametrize(
    "name",
    ["labyrinth", "emission", "shadow", "geometric", "sponza-atrium", "bunny-room", "cornell-box"],
)
def test_paper_scenes_are_lit_and_inside_their_enclosure(name):
    s = voxgi.scenes.get(name, width=16, height=16)
    assert any(o.material.is_emitter for o in s.objects)
    lo, hi = s.bounds
    assert np.all(hi > lo)
    # the camera sits inside the scene's bounding box (these are interiors)
    eye = np.asarray(s.camera.eye)
    if name != "cornell-box":  # the Cornell camera stands in front of the open side
        assert np.all(eye > lo)
        assert np.all(eye < hi)
    # objects other than the enclosure and the one-sided light quads are closed solids
    for o in s.objects:
        m = o.to_trimesh()
        if (
            o.name not in ("room", "hall", "light", "small_light", "panel_light", "sky")
            and name != "cornell-box"
        ):
            assert m.is_watertight, o.name


def test_sponza_atrium_has_many_triangles():
    assert voxgi.scenes.sponza_atrium().n_triangles > 4000


def _glossy_lit_scene() -> Scene:
    """A mirror-like conductor, a glossy plastic and a point light: the
    materials and lights whose values a fingerprint writes out."""
    from voxgi.microfacet import Microfacet

    sc = Scene()
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    copper = Microfacet("conductor", alpha=0.1, eta=(0.27105, 0.67693, 1.31640), k=(3.6, 2.6, 2.3))
    sc.add(box, voxgi.Material(specular=copper), name="copper")
    shiny = Microfacet("plastic", alpha=0.05)
    sc.add(box.copy().apply_translation((2, 0, 0)), voxgi.Material(0.123456789, specular=shiny))
    sc.lights.append(voxgi.PointLight(position=(0.0, 3.0, 0.0), intensity=(1.0, 2.0, 3.0)))
    return sc


def test_the_fingerprint_does_not_follow_numpy_print_options():
    """A solution still belongs to its scene after ``np.set_printoptions``
    (a conductor's albedo, worked out from its lobe, once printed short)."""
    sc = _glossy_lit_scene()
    assert all(type(v) is float for v in sc.objects[0].material.albedo)
    fp = sc.fingerprint()
    with np.printoptions(precision=2, floatmode="fixed"):
        assert sc.fingerprint() == fp


def test_the_fingerprint_writes_plain_values_as_repr_does():
    """Scenes of plain Python values keep the fingerprints they had: their
    canonical text is their repr."""
    from voxgi.scene import _stable_repr

    sc = _glossy_lit_scene()
    for v in (
        (0.1, 0.2, 0.30000000000000004),
        (0.5,),
        ("sheet", (0.9, 0.9, 0.9)),
        ("lobe", sc.objects[1].material.specular),
        sc.lights[0],
        [1, True, None, "x"],
    ):
        assert _stable_repr(v) == repr(v)
    # numpy values read as the Python numbers they hold, in full
    assert _stable_repr(np.array([0.52994119123, 0.5])) == repr((0.52994119123, 0.5))
    assert _stable_repr((np.float32(0.5), np.int64(3))) == repr((0.5, 3))


def test_the_triangles_objects_come_without_their_corners():
    # The shading kernels need each triangle's object only; it is the same
    # array as triangles()'s, in the same order.
    s = voxgi.scenes.cornell_box()
    obj = s.triangle_objects()
    assert obj.dtype == np.int32
    np.testing.assert_array_equal(obj, s.triangles()["object"])
    assert obj[-1] == len(s.objects) - 1
    assert np.all(np.diff(obj) >= 0)
    with pytest.raises(ValueError, match="scene is empty"):
        voxgi.Scene().triangle_objects()
