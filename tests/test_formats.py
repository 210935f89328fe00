"""Scene files of other renderers (voxgi.formats): Mitsuba 3 XML, OBJ + MTL, glTF 2.0.

Expected values are closed forms (Mitsuba's documented shapes, transforms and
field-of-view rules) or Mitsuba 3's own loader, which the tests ask directly
when the ``mitsuba`` package is importable.
"""

# ruff: noqa: E501 (the XML fixtures read best one element to a line)

from __future__ import annotations

import json
import math
import os
import struct
import warnings
import zlib
from pathlib import Path

import numpy as np
import pytest
import trimesh

import voxgi
from voxgi import formats


def _mitsuba():
    """Mitsuba 3 with an RGB variant, or skip."""
    pytest.importorskip("mitsuba")
    from voxgi.mitsuba import mitsuba_module

    return mitsuba_module()


def _xml(tmp_path: Path, body: str, name: str = "scene.xml") -> Path:
    p = tmp_path / name
    p.write_text(f'<scene version="3.0.0">\n{body}\n</scene>\n')
    return p


def _load_quiet(path):
    """Load, returning the scene and the SceneWarning messages."""
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        scene = voxgi.Scene.load(path)
    return scene, [str(w.message) for w in rec if issubclass(w.category, voxgi.SceneWarning)]


RECT = np.array([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])


# -- Mitsuba XML: geometry ---------------------------------------------------


def test_transformed_rectangle_lands_where_mitsuba_puts_it(tmp_path):
    # Mitsuba applies the elements of <transform> in order: scale, then
    # rotate, then translate here, so world = T @ R @ S @ v.
    path = _xml(
        tmp_path,
        """<shape type="rectangle" id="r">
             <transform name="to_world">
               <scale x="2" y="0.5"/>
               <rotate y="1" angle="30"/>
               <translate x="1" y="2" z="3"/>
             </transform>
           </shape>
           <shape type="rectangle" id="flipped">
             <boolean name="flip_normals" value="true"/>
             <transform name="to_world">
               <matrix value="0 0 1 5  1 0 0 0  0 1 0 0  0 0 0 1"/>
             </transform>
           </shape>""",
    )
    scene = voxgi.Scene.load(path)
    r, flipped = scene.objects
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    rot = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    want = RECT * [2, 0.5, 1] @ rot.T + [1, 2, 3]
    np.testing.assert_allclose(r.vertices, want, atol=1e-12)
    # the front normal of the rectangle is R @ +z
    t = r.vertices[r.faces[0]]
    n = np.cross(t[1] - t[0], t[2] - t[0])
    np.testing.assert_allclose(n / np.linalg.norm(n), rot @ [0, 0, 1], atol=1e-12)
    # the matrix maps local z to world x; flip_normals turns the normal to -x
    t = flipped.vertices[flipped.faces[0]]
    n = np.cross(t[1] - t[0], t[2] - t[0])
    np.testing.assert_allclose(n / np.linalg.norm(n), [-1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(flipped.vertices.mean(axis=0), [5, 0, 0], atol=1e-12)

    mi = _mitsuba()
    shapes = {sh.id(): sh for sh in mi.load_file(str(path)).shapes()}
    uv = np.array([[0.5, 0.5], [0.1, 0.2], [0.9, 0.7]])
    for obj in (r, flipped):
        # Mitsuba's rectangle is analytic: its points at (u, v) are the
        # canonical (2u - 1, 2v - 1, 0) carried by to_world, its normal
        # flipped by flip_normals
        ps = shapes[obj.name].sample_position(0.0, mi.Point2f(uv[:, 0], uv[:, 1]))
        p, n = np.array(ps.p).T, np.array(ps.n).T
        v = obj.vertices
        want = v[0] + uv[:, :1] * (v[1] - v[0]) + uv[:, 1:] * (v[3] - v[0])
        np.testing.assert_allclose(p, want, atol=1e-5)
        t = v[obj.faces[0]]
        ours = np.cross(t[1] - t[0], t[2] - t[0])
        np.testing.assert_allclose(
            np.broadcast_to(n, (3, 3)), np.tile(ours / np.linalg.norm(ours), (3, 1)), atol=1e-6
        )


def test_mirrored_shapes_face_as_in_mitsuba(tmp_path):
    # A mesh's front follows the winding of its transformed vertices: the
    # mirror x -> -x turns the triangle's +z normal to -z. The analytic
    # rectangle transforms its normal as a normal: diag(-1, 1, 1) keeps +z.
    (tmp_path / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    mirror = '<transform name="to_world"><scale x="-1"/></transform>'
    path = _xml(
        tmp_path,
        f"""<shape type="obj" id="tri"><string name="filename" value="tri.obj"/>{mirror}</shape>
            <shape type="rectangle" id="rect">{mirror}</shape>""",
    )
    normals = {}
    for o in voxgi.Scene.load(path).objects:
        t = o.vertices[o.faces[0]]
        n = np.cross(t[1] - t[0], t[2] - t[0])
        normals[o.name] = n / np.linalg.norm(n)
    np.testing.assert_allclose(normals["tri"], [0, 0, -1])
    np.testing.assert_allclose(normals["rect"], [0, 0, 1])

    mi = _mitsuba()
    for sh in mi.load_file(str(path)).shapes():
        ps = sh.sample_position(0.0, mi.Point2f(0.3, 0.3))
        np.testing.assert_allclose(np.array(ps.n).ravel(), normals[sh.id()], atol=1e-6)


def test_canonical_shapes(tmp_path):
    path = _xml(
        tmp_path,
        """<shape type="cube" id="cube"/>
           <shape type="disk" id="disk"><transform name="to_world"><scale value="2"/></transform></shape>
           <shape type="sphere" id="sphere">
             <point name="center" x="1" y="0" z="0"/><float name="radius" value="0.5"/>
           </shape>""",
    )
    cube, disk, sphere = voxgi.Scene.load(path).objects
    np.testing.assert_allclose(cube.vertices.min(axis=0), -1)
    np.testing.assert_allclose(cube.vertices.max(axis=0), 1)
    assert cube.area() == pytest.approx(24.0)
    # a 128-gon inscribed in the radius-2 circle: area (n/2) r^2 sin(2 pi / n)
    assert disk.area() == pytest.approx(64 * 4 * math.sin(2 * math.pi / 128))
    np.testing.assert_allclose(np.linalg.norm(sphere.vertices - [1, 0, 0], axis=1), 0.5)
    # outward normals: every face's normal points away from the centre
    t = sphere.vertices[sphere.faces]
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    assert np.all(np.einsum("ij,ij->i", n, t.mean(axis=1) - [1, 0, 0]) > 0)


def _serialized(meshes) -> bytes:
    """A version-4 Mitsuba .serialized file of float32 (vertices, faces) meshes."""
    out, offsets = b"", []
    for name, v, f in meshes:
        payload = struct.pack("<I", 0x1000) + name.encode() + b"\0"
        payload += struct.pack("<QQ", len(v), len(f))
        payload += np.asarray(v, "<f4").tobytes() + np.asarray(f, "<u4").tobytes()
        offsets.append(len(out))
        out += struct.pack("<HH", 0x041C, 4) + zlib.compress(payload)
    return out + struct.pack(f"<{len(offsets)}Q", *offsets) + struct.pack("<I", len(offsets))


def test_serialized_meshes(tmp_path):
    tri = np.array([[0, 1, 2]])
    box = trimesh.creation.box()
    (tmp_path / "m.serialized").write_bytes(
        _serialized([("a", RECT[:3], tri), ("b", box.vertices + 3, box.faces)])
    )
    path = _xml(
        tmp_path,
        """<shape type="serialized" id="b">
             <string name="filename" value="m.serialized"/><integer name="shape_index" value="1"/>
           </shape>""",
    )
    (obj,) = voxgi.Scene.load(path).objects
    np.testing.assert_allclose(obj.vertices, np.float32(box.vertices + 3))
    np.testing.assert_array_equal(obj.faces, box.faces)
    with pytest.raises(ValueError, match=r"shape_index 2 out of range: the file holds 2"):
        formats.read_serialized(tmp_path / "m.serialized", 2)

    mi = _mitsuba()
    params = mi.traverse(mi.load_file(str(path)).shapes()[0])
    mv = np.array(params["vertex_positions"]).reshape(-1, 3)
    mf = np.array(params["faces"]).reshape(-1, 3)
    np.testing.assert_allclose(obj.vertices[obj.faces], mv[mf], atol=1e-6)


# -- Mitsuba XML: camera -----------------------------------------------------


@pytest.mark.parametrize("axis", ["x", "y", "diagonal", "smaller", "larger"])
def test_fov_axis_becomes_vertical_fov(tmp_path, axis):
    w, h, fov = 300, 200, 50.0
    path = _xml(
        tmp_path,
        f"""<sensor type="perspective">
              <float name="fov" value="{fov}"/><string name="fov_axis" value="{axis}"/>
              <film type="hdrfilm"><integer name="width" value="{w}"/><integer name="height" value="{h}"/><rfilter type="box"/></film>
            </sensor>
            <shape type="rectangle"/>""",
    )
    cam = voxgi.Scene.load(path).camera
    # the image plane at distance 1 is 2 tan(fov/2) wide along the fov's axis
    half = math.tan(math.radians(fov) / 2)
    along = {"x": w, "y": h, "diagonal": math.hypot(w, h), "smaller": h, "larger": w}[axis]
    assert math.tan(math.radians(cam.fov) / 2) == pytest.approx(half * h / along, rel=1e-12)
    assert (cam.width, cam.height) == (w, h)

    mi = _mitsuba()
    x_fov = float(mi.traverse(mi.load_file(str(path)).sensors()[0])["x_fov"][0])
    y_from_x = math.degrees(2 * math.atan(math.tan(math.radians(x_fov) / 2) * h / w))
    assert cam.fov == pytest.approx(y_from_x, rel=1e-5)


def test_camera_frame_and_handedness(tmp_path):
    path = _xml(
        tmp_path,
        """<sensor type="thinlens">
             <float name="fov" value="40"/><string name="fov_axis" value="y"/>
             <float name="aperture_radius" value="0.1"/><float name="focus_distance" value="7"/>
             <transform name="to_world"><lookat origin="1, 2, 3" target="1, 2, 13" up="0, 1, 0"/></transform>
             <film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="32"/><rfilter type="box"/></film>
           </sensor>
           <shape type="rectangle"/>""",
    )
    cam = voxgi.Scene.load(path).camera
    right, up, fwd = cam.frame()
    np.testing.assert_allclose(cam.eye, [1, 2, 3])
    np.testing.assert_allclose(fwd, [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(up, [0, 1, 0], atol=1e-12)
    # Mitsuba's camera x axis points to the image's left: look_at's "left" is up x forward
    np.testing.assert_allclose(right, -np.cross([0, 1, 0], [0, 0, 1]), atol=1e-12)
    assert (cam.fov, cam.aperture, cam.focus_distance) == (40.0, 0.1, 7.0)

    mi = _mitsuba()
    sensor = mi.load_file(str(path)).sensors()[0]
    # a ray through the right half of the image, at the lens centre
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(0.9, 0.5), mi.Point2f(0.5, 0.5))
    d = np.array(ray.d).ravel()
    assert np.dot(d, right) > 0.1
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(0.5, 0.1), mi.Point2f(0.5, 0.5))
    assert np.dot(np.array(ray.d).ravel(), up) > 0.1  # image row 0 is the top


# -- Mitsuba XML: materials and emitters --------------------------------------

# Mitsuba 3.9.1's loader (llvm_ad_rgb) reads scenes/cbox/cbox.xml's spectra as
# these RGB values (printed by mi.traverse on the loaded scene).
CBOX_WHITE = "400:0.343, 404:0.445, 408:0.551, 412:0.624, 416:0.665, 420:0.687, 424:0.708, 428:0.723, 432:0.715, 436:0.71, 440:0.745, 444:0.758, 448:0.739, 452:0.767, 456:0.777, 460:0.765, 464:0.751, 468:0.745, 472:0.748, 476:0.729, 480:0.745, 484:0.757, 488:0.753, 492:0.75, 496:0.746, 500:0.747, 504:0.735, 508:0.732, 512:0.739, 516:0.734, 520:0.725, 524:0.721, 528:0.733, 532:0.725, 536:0.732, 540:0.743, 544:0.744, 548:0.748, 552:0.728, 556:0.716, 560:0.733, 564:0.726, 568:0.713, 572:0.74, 576:0.754, 580:0.764, 584:0.752, 588:0.736, 592:0.734, 596:0.741, 600:0.74, 604:0.732, 608:0.745, 612:0.755, 616:0.751, 620:0.744, 624:0.731, 628:0.733, 632:0.744, 636:0.731, 640:0.712, 644:0.708, 648:0.729, 652:0.73, 656:0.727, 660:0.707, 664:0.703, 668:0.729, 672:0.75, 676:0.76, 680:0.751, 684:0.739, 688:0.724, 692:0.73, 696:0.74, 700:0.737"


def test_spectra_become_mitsubas_rgb(tmp_path):
    path = _xml(
        tmp_path,
        f"""<shape type="rectangle" id="lamp">
              <bsdf type="diffuse"><spectrum name="reflectance" value="400:0.78, 700:0.78"/></bsdf>
              <emitter type="area"><spectrum name="radiance" value="400:0, 500:8, 600:15.6, 700:18.4"/></emitter>
            </shape>
            <shape type="rectangle" id="white">
              <bsdf type="diffuse"><spectrum name="reflectance" value="{CBOX_WHITE}"/></bsdf>
            </shape>
            <shape type="rectangle" id="grey">
              <bsdf type="diffuse"><spectrum name="reflectance" value="0.3"/></bsdf>
              <emitter type="area"><rgb name="radiance" value="5, 4, 3"/></emitter>
            </shape>""",
    )
    lamp, white, grey = voxgi.Scene.load(path).objects
    np.testing.assert_allclose(lamp.material.emission, [20.7108, 10.8546, 2.77115], rtol=2e-5)
    np.testing.assert_allclose(lamp.material.albedo, [0.776367, 0.77981, 0.776029], rtol=2e-5)
    np.testing.assert_allclose(white.material.albedo, [0.735013, 0.735625, 0.736264], rtol=2e-5)
    assert grey.material.albedo == (0.3, 0.3, 0.3)
    assert grey.material.emission == (5.0, 4.0, 3.0)

    mi = _mitsuba()
    rng = np.random.default_rng(1)
    for _ in range(5):
        w = np.sort(rng.uniform(380, 780, 6))
        v = rng.uniform(0, 1, 6)
        for emitter in (False, True):
            want = mi.spectrum_list_to_srgb(list(w), list(v), not emitter, not emitter)
            got = formats.spectrum_to_rgb(w, v, emitter=emitter)
            np.testing.assert_allclose(got, np.array(want).ravel(), rtol=1e-4, atol=1e-6)


def test_two_sided_and_emitter_sides(tmp_path):
    path = _xml(
        tmp_path,
        """<bsdf type="twosided" id="w"><bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.4, 0.6"/></bsdf></bsdf>
           <shape type="rectangle" id="wall"><ref id="w"/></shape>
           <shape type="rectangle" id="panel">
             <ref id="w"/><emitter type="area"><rgb name="radiance" value="1, 2, 3"/></emitter>
           </shape>
           <shape type="rectangle" id="bare"><emitter type="area"><float name="radiance" value="2"/></emitter></shape>
           <shape type="rectangle" id="plain"/>""",
    )
    objs = {o.name: o for o in voxgi.Scene.load(path).objects}
    assert objs["wall"].two_sided
    assert objs["wall"].material.albedo == (0.2, 0.4, 0.6)
    # A two-sided BSDF does not make Mitsuba's area emitter two-sided: the
    # panel emits from its front only and reflects on both sides.
    front, back = objs["panel"], objs["panel_back"]
    assert not front.two_sided
    assert not back.two_sided
    assert front.material.emission == (1.0, 2.0, 3.0)
    assert back.material.emission == (0, 0, 0)
    assert back.material.albedo == (0.2, 0.4, 0.6)
    np.testing.assert_array_equal(back.faces, front.faces[:, ::-1])
    # Mitsuba's default BSDF: black under an emitter, diffuse 0.5 otherwise
    assert objs["bare"].material.albedo == (0, 0, 0)
    assert objs["bare"].material.emission == (2.0, 2.0, 2.0)
    assert objs["plain"].material.albedo == (0.5, 0.5, 0.5)


def test_one_warning_lists_approximated_bsdfs_another_what_is_left_out(tmp_path):
    path = _xml(
        tmp_path,
        """<bsdf type="roughplastic" id="plastic"><rgb name="diffuse_reflectance" value="0.1, 0.2, 0.3"/></bsdf>
           <bsdf type="principled" id="pbr"><rgb name="base_color" value="0.7, 0.6, 0.5"/></bsdf>
           <shape type="rectangle" id="a"><ref id="plastic"/></shape>
           <shape type="rectangle" id="b"><ref id="pbr"/></shape>
           <shape type="rectangle" id="c"><bsdf type="conductor" id="metal"/></shape>
           <emitter type="projector" id="beamer"/>
           <emitter type="directionalarea"/>""",
    )
    with pytest.warns(voxgi.SceneWarning) as rec:
        scene = voxgi.Scene.load(path)
    msgs = [str(w.message) for w in rec]
    assert len(msgs) == 2, msgs
    approx, dropped = msgs
    for label in ("'principled' (id 'pbr')", "'conductor' (id 'metal')"):
        assert label in approx
    # a rough plastic is read as it is: only what still differs is listed
    assert "roughplastic" not in approx
    assert "mirror reflection as a GGX lobe of alpha 0.02" in approx
    assert "emitter 'projector' (id 'beamer')" in dropped
    assert "emitter 'directionalarea'" in dropped
    a, b, c = scene.objects
    assert a.material.albedo == (0.1, 0.2, 0.3)
    assert a.material.specular == voxgi.Microfacet(
        "plastic", alpha=0.1, distribution="beckmann", ior=1.49 / 1.000277
    )
    assert b.material.albedo == (0.7, 0.6, 0.5)
    # Mitsuba's default conductor: a perfect mirror (eta 0, k 1)
    assert c.material.specular.kind == "conductor"
    assert c.material.specular.eta == (0.0, 0.0, 0.0)
    assert min(c.material.albedo) > 0.99


def test_scene_emitters_become_lights(tmp_path):
    # Mitsuba's point, spot, directional and constant emitters in their own
    # units: a spot shines along its local +z (here the lookat's target), a
    # spot's beam_width defaults to 3/4 of its cutoff angle.
    path = _xml(
        tmp_path,
        """<shape type="rectangle"/>
           <emitter type="point"><point name="position" value="0, 1, 0"/><rgb name="intensity" value="2, 3, 4"/></emitter>
           <emitter type="spot">
             <transform name="to_world"><lookat origin="0, 2, 0" target="0, 0, 0" up="0, 0, 1"/></transform>
             <rgb name="intensity" value="5"/><float name="cutoff_angle" value="40"/>
           </emitter>
           <emitter type="directional"><vector name="direction" value="0, -2, 0"/><rgb name="irradiance" value="7"/></emitter>
           <emitter type="constant"><rgb name="radiance" value="0.5, 0.25, 1"/></emitter>""",
    )
    scene, msgs = _load_quiet(path)
    assert msgs == []
    point, spot, sun = scene.lights
    assert isinstance(point, voxgi.PointLight)
    np.testing.assert_allclose(point.position, (0, 1, 0))
    np.testing.assert_allclose(point.intensity, (2, 3, 4))
    assert isinstance(spot, voxgi.SpotLight)
    np.testing.assert_allclose(spot.position, (0, 2, 0))
    np.testing.assert_allclose(spot.direction, (0, -1, 0), atol=1e-12)
    assert (spot.cutoff_angle, spot.beam_width) == (40.0, 30.0)
    assert isinstance(sun, voxgi.DirectionalLight)
    np.testing.assert_allclose(sun.direction, (0, -1, 0))
    np.testing.assert_allclose(sun.irradiance, (7, 7, 7))
    assert scene.environment is not None
    np.testing.assert_allclose(scene.environment.constant, (0.5, 0.25, 1))


def test_defaults_variables_includes_and_refs(tmp_path):
    (tmp_path / "frag.xml").write_text(
        '<scene version="3.0.0"><bsdf type="diffuse" id="red">'
        '<rgb name="reflectance" value="$r, 0, 0"/></bsdf></scene>'
    )
    path = _xml(
        tmp_path,
        """<default name="r" value="0.25"/><default name="res" value="40"/>
           <include filename="frag.xml"/>
           <sensor type="perspective">
             <film type="hdrfilm"><integer name="width" value="$res"/><integer name="height" value="$res"/><rfilter type="box"/></film>
           </sensor>
           <shape type="rectangle"><ref id="red"/></shape>""",
    )
    scene = voxgi.Scene.load(path)
    assert scene.objects[0].material.albedo == (0.25, 0.0, 0.0)
    assert (scene.camera.width, scene.camera.height) == (40, 40)
    # default focal length 50 mm on a 36 mm wide frame, fov_axis x, square image
    assert scene.camera.fov == pytest.approx(math.degrees(2 * math.atan(18 / 50)))


# -- OBJ + MTL -------------------------------------------------------------

# the wall's face counts back from the vertices before it (OBJ's relative
# indices), the lamp's from the start of the file
OBJ = """mtllib m.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
usemtl wall
f -4 -3 -2 -1
v 0 0 1
v 1 0 1
usemtl lamp
f 1 5 6
"""


def test_obj_kd_ke_and_texture_mean(tmp_path):
    from PIL import Image

    # a 2x1 sRGB texture, 255 and 0 in red: linear mean 0.5
    Image.fromarray(np.array([[[255, 0, 0], [0, 0, 0]]], np.uint8)).save(tmp_path / "t.png")
    (tmp_path / "m.obj").write_text(OBJ)
    (tmp_path / "m.mtl").write_text(
        "newmtl wall\nKd 0.7 0.1 0.05\nmap_Kd t.png\nnewmtl lamp\nKd 0 0 0\nKe 10 9 8\n"
    )
    with pytest.warns(
        voxgi.SceneWarning, match=r"material 'wall': texture t.png reduced to its mean"
    ):
        scene = voxgi.Scene.load(tmp_path / "m.obj")
    objs = {o.name: o for o in scene.objects}
    np.testing.assert_allclose(objs["wall"].material.albedo, [0.35, 0, 0], atol=1e-12)
    assert objs["lamp"].material.emission == (10.0, 9.0, 8.0)
    assert objs["wall"].area() == pytest.approx(1.0)
    assert objs["lamp"].area() == pytest.approx(0.5)


def test_obj_without_mtl_is_grey(tmp_path):
    (tmp_path / "m.obj").write_text(OBJ)
    with pytest.warns(voxgi.SceneWarning, match=r"material library m.mtl not found: grey 0.5"):
        scene = voxgi.Scene.load(tmp_path / "m.obj")
    assert all(o.material.albedo == (0.5, 0.5, 0.5) for o in scene.objects)


# -- glTF ------------------------------------------------------------------


def _gltf(tmp_path: Path) -> Path:
    """A box (node translated and scaled) with a double-sided emissive material, and a camera."""
    box = trimesh.creation.box()
    box.visual = trimesh.visual.TextureVisuals(
        material=trimesh.visual.material.PBRMaterial(
            name="glow", baseColorFactor=[0.5, 0.5, 0.5, 1]
        )
    )
    sc = trimesh.Scene()
    sc.add_geometry(box, node_name="boxnode", geom_name="box")
    files = sc.export(file_type="gltf")
    doc = json.loads(files["model.gltf"])
    for k, v in files.items():
        if k != "model.gltf":
            (tmp_path / k).write_bytes(v)
    doc["materials"] = [
        {
            "name": "glow",
            "pbrMetallicRoughness": {"baseColorFactor": [0.73, 0.2, 0.1, 1.0], "metallicFactor": 0},
            "emissiveFactor": [1.0, 0.5, 0.25],
            "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4.0}},
            "doubleSided": True,
        }
    ]
    box_node = next(i for i, n in enumerate(doc["nodes"]) if n.get("name") == "boxnode")
    doc["nodes"][box_node].update(translation=[1, 2, 3], scale=[2, 2, 2])
    doc["nodes"][box_node].pop("matrix", None)
    # a camera at (0, 0, 10), rotated 90 degrees about +y: it looks down -x
    s = math.sqrt(0.5)
    doc["cameras"] = [
        {"type": "perspective", "perspective": {"yfov": 0.5, "aspectRatio": 1.5, "znear": 0.1}}
    ]
    doc["nodes"].append({"camera": 0, "translation": [0, 0, 10], "rotation": [0, s, 0, s]})
    doc["scenes"][0]["nodes"].append(len(doc["nodes"]) - 1)
    path = tmp_path / "model.gltf"
    path.write_text(json.dumps(doc))
    return path


def test_gltf_material_transform_camera(tmp_path):
    # a dielectric: glTF's lobe, stated as a rough plastic coat
    with pytest.warns(voxgi.SceneWarning, match="a dielectric as a GGX plastic coat"):
        scene = voxgi.Scene.load(_gltf(tmp_path))
    (obj,) = scene.objects
    np.testing.assert_allclose(obj.vertices.min(axis=0), [0, 1, 2], atol=1e-6)
    np.testing.assert_allclose(obj.vertices.max(axis=0), [2, 3, 4], atol=1e-6)
    assert obj.material.albedo == (0.73, 0.2, 0.1)  # exact, not 8-bit
    assert obj.material.emission == (4.0, 2.0, 1.0)
    assert obj.two_sided
    cam = scene.camera
    right, up, fwd = cam.frame()
    np.testing.assert_allclose(cam.eye, [0, 0, 10], atol=1e-12)
    np.testing.assert_allclose(fwd, [-1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(up, [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(right, [0, 0, -1], atol=1e-12)  # glTF: +x is right
    assert cam.fov == pytest.approx(math.degrees(0.5))
    assert (cam.width, cam.height) == (768, 512)


def test_gltf_metals_and_lights_are_listed(tmp_path):
    path = _gltf(tmp_path)
    doc = json.loads(path.read_text())
    doc["materials"][0]["pbrMetallicRoughness"]["metallicFactor"] = 0.5
    doc["materials"][0]["extensions"]["KHR_materials_transmission"] = {"transmissionFactor": 1}
    doc["extensions"] = {"KHR_lights_punctual": {"lights": [{"type": "point"}, {"type": "spot"}]}}
    path.write_text(json.dumps(doc))
    with pytest.warns(voxgi.SceneWarning) as rec:
        voxgi.Scene.load(path)
    approx, dropped = (str(w.message) for w in rec)
    assert "material 'glow': metallic 0.5 as a GGX conductor of alpha roughness²" in approx
    assert "material 'glow': KHR_materials_transmission left out" in approx
    assert "KHR_lights_punctual light 0 (point); KHR_lights_punctual light 1 (spot)" in dropped


# -- round trip --------------------------------------------------------------


@pytest.mark.parametrize("kind", ["xml", "obj", "gltf"])
def test_save_and_load_keeps_the_fingerprint(tmp_path, kind):
    if kind == "xml":
        path = _xml(
            tmp_path,
            f"""<shape type="sphere"><float name="radius" value="0.7"/>
                  <bsdf type="diffuse"><spectrum name="reflectance" value="{CBOX_WHITE}"/></bsdf></shape>
                <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="33"/></transform>
                  <emitter type="area"><rgb name="radiance" value="3, 2, 1"/></emitter></shape>""",
        )
    elif kind == "obj":
        (tmp_path / "m.obj").write_text(OBJ)
        (tmp_path / "m.mtl").write_text("newmtl wall\nKd 0.3 0.2 0.1\nnewmtl lamp\nKe 1 1 1\n")
        path = tmp_path / "m.obj"
    else:
        path = _gltf(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", voxgi.SceneWarning)  # (glTF's lobe, stated)
        scene = voxgi.Scene.load(path)
    saved = scene.save(tmp_path / "out" / "s.toml")
    again = voxgi.Scene.load(saved)
    assert again.fingerprint() == scene.fingerprint()
    assert again.camera == scene.camera


# -- bad files ---------------------------------------------------------------

BAD_XML = [
    ("<shape type='rectangle'>", r"scene\.xml: malformed XML: mismatched tag \(line 3"),
    ("<shape/>", r"line 2: <shape>: missing attribute 'type'"),
    ("<widget type='x'/>", r"line 2: <widget type=\"x\">: unknown top-level element"),
    (
        "<shape type='rectangle'><bsdf type='difuse'/></shape>",
        r"line 2: <bsdf type=\"difuse\">: unknown bsdf plugin 'difuse'",
    ),
    (
        "<shape type='rectangle'><ref id='nope'/></shape>",
        r"line 2: <ref id=\"nope\">: unknown id 'nope'",
    ),
    (
        "<shape type='obj' id='m'><string name='filename' value='gone.obj'/></shape>",
        r"line 2: <shape type=\"obj\" id=\"m\">: mesh file not found: .*gone\.obj",
    ),
    (
        "<shape type='rectangle'><bsdf type='diffuse'><float name='reflectance' value='abc'/></bsdf></shape>",
        r"line 2: <float name=\"reflectance\">: value='abc' is not a number",
    ),
    (
        "<shape type='rectangle'><bsdf type='diffuse'><rgb name='reflectance' value='$col'/></bsdf></shape>",
        r"undefined parameter \$col",
    ),
    (
        "<shape type='rectangle'><transform name='to_world'><scale value='0'/></transform></shape>",
        r"<transform name=\"to_world\">: transform is singular",
    ),
    (
        "<shape type='rectangle'><bsdf type='diffuse'><rgb name='reflectance' value='1.5, 0, 0'/></bsdf></shape>",
        None,
    ),
    (
        "<sensor type='perspective'><string name='fov_axis' value='z'/></sensor><shape type='cube'/>",
        r"fov_axis='z'",
    ),
    (
        "<shape type='rectangle'><foo name='x' value='1'/></shape>",
        r"<foo name=\"x\">: unknown element <foo>",
    ),
    ("<emitter type='point'/>", r"no shape voxgi can read"),
]


@pytest.mark.parametrize(("body", "message"), BAD_XML)
def test_bad_xml_names_file_line_and_element(tmp_path, body, message):
    path = _xml(tmp_path, body)
    if message is None:
        # an albedo of 1 or more is clamped below 1, with the shape named
        with pytest.warns(
            voxgi.SceneWarning, match=r"shape 'rectangle': albedo .* clamped below 1"
        ):
            (obj,) = voxgi.Scene.load(path).objects
        assert obj.material.albedo[0] < 1.0
        return
    with pytest.raises(ValueError, match=message) as exc:
        voxgi.Scene.load(path)
    assert str(path) in str(exc.value)


def test_bad_files_of_each_kind(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"scene file not found: .*nothing\.xml"):
        voxgi.Scene.load(tmp_path / "nothing.xml")
    with pytest.raises(FileNotFoundError, match=r"scene file not found: .*nothing\.glb"):
        voxgi.Scene.load(tmp_path / "nothing.glb")
    (tmp_path / "bad.gltf").write_text('{"asset": {"version": "2.0"}, "meshes": [')
    with pytest.raises(ValueError, match=r"bad\.gltf: malformed glTF JSON"):
        voxgi.Scene.load(tmp_path / "bad.gltf")
    (tmp_path / "refs.gltf").write_text(
        '{"asset": {"version": "2.0"}, "meshes": [{"primitives": [{"attributes": {"POSITION": 5}}]}]}'
    )
    with pytest.raises(
        ValueError,
        match=r"refs\.gltf: /meshes/0/primitives/0/attributes/POSITION: accessor 5",
    ):
        voxgi.Scene.load(tmp_path / "refs.gltf")
    (tmp_path / "broken.glb").write_bytes(b"glTF\x02\x00\x00\x00")
    with pytest.raises(ValueError, match=r"broken\.glb: truncated GLB header"):
        voxgi.Scene.load(tmp_path / "broken.glb")
    (tmp_path / "m.obj").write_text(OBJ)
    (tmp_path / "m.mtl").write_text("newmtl wall\nKd 0.5 x 0.5\n")
    with pytest.raises(ValueError, match=r"m\.mtl: line 2: Kd: not numbers"):
        voxgi.Scene.load(tmp_path / "m.obj")
    (tmp_path / "n.serialized").write_bytes(b"\x1c\x04\x04\x00garbage" + struct.pack("<QI", 0, 1))
    with pytest.raises(ValueError, match=r"n\.serialized: mesh 0: corrupt zlib stream"):
        formats.read_serialized(tmp_path / "n.serialized")


def test_cli_takes_scene_files_of_other_renderers(tmp_path, monkeypatch, capsys):
    from voxgi import cli

    monkeypatch.chdir(tmp_path)
    for name in ("missing.xml", "missing.obj", "missing.glb"):
        with pytest.raises(SystemExit) as exc:
            cli.main(["render", name])
        assert exc.value.code == 2
        assert f"scene file not found: {name}" in capsys.readouterr().err
    # a broken file is one line naming it, no traceback
    (tmp_path / "bad.xml").write_text("<scene><shape type='rectangle'></scene>")
    with pytest.raises(SystemExit) as exc:
        cli.main(["render", "bad.xml", "-q"])
    # (exits as a TOML file that cannot be loaded does: with the message)
    assert str(exc.value.code) == (
        "voxgi render: error: scene file bad.xml: malformed XML: mismatched tag (line 1, column 34)"
    )


# -- acceptance: Mitsuba's Cornell box -----------------------------------------


@pytest.mark.slow
def test_cbox_xml_matches_mitsuba(tmp_path):
    # VOXGI_MITSUBA_DATA: a checkout of mitsuba-renderer/mitsuba-data
    data = os.environ.get("VOXGI_MITSUBA_DATA")
    if not data or not (Path(data) / "scenes/cbox/cbox.xml").exists():
        pytest.skip("set VOXGI_MITSUBA_DATA to a mitsuba-data checkout")
    mi = _mitsuba()
    xml = Path(data) / "scenes/cbox/cbox.xml"
    with pytest.warns(voxgi.SceneWarning, match=r"max_depth 6"):
        scene = voxgi.Scene.load(xml)
    assert scene.camera.pixel_filter == "gaussian"  # the film's, as Mitsuba reads it
    out = voxgi.render(scene, progress=False)
    # The same XML, with every bounce (voxgi computes them all).
    spp = 4096
    ref = mi.render(mi.load_file(str(xml), max_depth=-1, spp=spp), spp=spp, seed=1)
    # voxgi's defaults reach 1e-3 against a converged reference (README); the
    # reference's own noise at 4096 spp is about 5e-5 (two seeds compared)
    assert voxgi.metrics.rel_mse(out.image, np.array(ref)[..., :3]) < 1e-3


# -- what a scene file may read (docs/scene-files.md) --------------------------

TRI = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"


def _outside(tmp_path: Path) -> tuple[Path, Path]:
    """A ``room`` folder for the scene and a ``shared`` folder beside it."""
    (tmp_path / "room").mkdir()
    (tmp_path / "shared").mkdir()
    (tmp_path / "shared" / "tri.obj").write_text(TRI)
    return tmp_path / "room", tmp_path / "shared"


def _policy(path: Path, shared: Path, link: Path | None = None):
    """The rule, tried three ways: refused by default (the message naming the file
    and the way to widen it), read with ``search_paths``, read with ``allow_outside``."""
    with pytest.raises(ValueError, match=r"outside the folders this scene may read .*search_paths"):
        _load_quiet(path)
    assert len(_load_quiet_kw(path, search_paths=[shared]).objects) >= 1
    assert len(_load_quiet_kw(path, allow_outside=True).objects) >= 1


def _load_quiet_kw(path, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", voxgi.SceneWarning)
        return voxgi.Scene.load(path, **kw)


def test_policy_xml(tmp_path):
    room, shared = _outside(tmp_path)
    body = '<shape type="obj"><string name="filename" value="../shared/tri.obj"/></shape>'
    _policy(_xml(room, body), shared)
    # a symbolic link inside the folder that leaves it is outside too
    (room / "link.obj").symlink_to(shared / "tri.obj")
    body = '<shape type="obj"><string name="filename" value="link.obj"/></shape>'
    _policy(_xml(room, body, "linked.xml"), shared)


def test_policy_obj_mtl(tmp_path):
    room, shared = _outside(tmp_path)
    (shared / "m.mtl").write_text("newmtl red\nKd 0.5 0 0\n")
    (room / "mesh.obj").write_text("mtllib ../shared/m.mtl\nusemtl red\n" + TRI)
    _policy(room / "mesh.obj", shared)
    (obj,) = _load_quiet_kw(room / "mesh.obj", search_paths=[shared]).objects
    assert obj.material.albedo == (0.5, 0.0, 0.0)


def test_policy_gltf(tmp_path):
    room, shared = _outside(tmp_path)
    blob = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "<f4").tobytes()
    (shared / "b.bin").write_bytes(blob)
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": 36, "uri": "../shared/b.bin"}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}],
    }
    (room / "scene.gltf").write_text(json.dumps(doc))
    _policy(room / "scene.gltf", shared)


def test_policy_toml(tmp_path):
    room, shared = _outside(tmp_path)
    (room / "scene.toml").write_text('[[object]]\nmesh = "../shared/tri.obj"\n')
    _policy(room / "scene.toml", shared)
    with pytest.raises(ValueError, match=r"outside the folders"):
        voxgi.Scene.from_dict({"object": [{"mesh": "../shared/tri.obj"}]}, base_dir=room)
    scene = voxgi.Scene.from_dict(
        {"object": [{"mesh": "../shared/tri.obj"}]}, base_dir=room, search_paths=[shared]
    )
    assert len(scene.objects) == 1


def test_limits_are_raised_per_call_and_by_environment(tmp_path, monkeypatch):
    path = _xml(tmp_path, '<shape type="rectangle"/>' * 3)
    with pytest.raises(ValueError, match=r"4 XML elements, above the limit of 3 .*VOXGI_MAX"):
        voxgi.Scene.load(path, limits=formats.Limits(elements=3))
    assert len(voxgi.Scene.load(path, limits=formats.Limits(elements=4)).objects) == 3
    monkeypatch.setenv("VOXGI_MAX_ELEMENTS", "3")
    assert formats.Limits.from_env().elements == 3
    with pytest.raises(ValueError, match=r"above the limit of 3"):
        voxgi.Scene.load(path)
    monkeypatch.setenv("VOXGI_MAX_ELEMENTS", "many")
    with pytest.raises(ValueError, match=r"VOXGI_MAX_ELEMENTS='many': expected an integer"):
        voxgi.Scene.load(path)
    with pytest.raises(ValueError, match=r"Limits.file_bytes: expected an integer >= 1"):
        formats.Limits(file_bytes=0)


def test_serialized_stream_is_read_to_its_header_counts_only(tmp_path):
    # the header says one triangle; the stream holds 64 MiB more
    payload = struct.pack("<I", 0x1000) + b"m\0" + struct.pack("<QQ", 3, 1)
    payload += np.asarray(RECT[:3], "<f4").tobytes() + np.array([[0, 1, 2]], "<u4").tobytes()
    data = struct.pack("<HH", 0x041C, 4) + zlib.compress(payload + bytes(64 << 20))
    (tmp_path / "m.serialized").write_bytes(data)
    with pytest.raises(ValueError, match=r"mesh 0: the stream holds more data than its header"):
        formats.read_serialized(tmp_path / "m.serialized")
    with pytest.raises(ValueError, match=r"mesh 0 \(3 vertices, 1 triangles\): .*mesh_bytes"):
        formats.read_serialized(tmp_path / "m.serialized", limits=formats.Limits(mesh_bytes=40))


def test_texture_mean_is_exact_from_the_histogram(rng):
    from PIL import Image

    from voxgi.formats.textures import image_mean

    a = rng.integers(0, 256, (37, 53, 3), dtype=np.uint8)
    # the mean of the linear values (sRGB decoded), computed in float64
    c = a / 255.0
    want = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).reshape(-1, 3)
    for mode in ("RGB", "RGBA"):
        np.testing.assert_allclose(image_mean(Image.fromarray(a).convert(mode)), want.mean(0))
    np.testing.assert_allclose(image_mean(a, raw=True), c.reshape(-1, 3).mean(0))
    grey = Image.fromarray(a[:, :, 0])
    np.testing.assert_allclose(image_mean(grey), want[:, 0].mean() * np.ones(3))


def test_relative_scene_path_does_not_double_its_folder(tmp_path, monkeypatch):
    (tmp_path / "room" / "models").mkdir(parents=True)
    (tmp_path / "room" / "models" / "m.obj").write_text(TRI)
    body = '<shape type="obj"><string name="filename" value="models/m.obj"/></shape>'
    _xml(tmp_path / "room", body)
    monkeypatch.chdir(tmp_path)
    (obj,) = voxgi.Scene.load("room/scene.xml").objects
    assert obj.source == "room/models/m.obj"


def test_a_mesh_of_degenerate_faces_is_left_out_by_name(tmp_path):
    (tmp_path / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    (tmp_path / "tri.obj").write_text(TRI)
    (tmp_path / "scene.toml").write_text(
        '[[object]]\nmesh = "tri.obj"\n[[object]]\nmesh = "flat.obj"\nname = "flat"\n'
    )
    with pytest.warns(
        voxgi.SceneWarning, match=r"object #1 \('flat'\): .*every face is degenerate"
    ):
        scene = voxgi.Scene.load(tmp_path / "scene.toml")
    assert [o.name for o in scene.objects] == ["tri"]


def test_emission_beyond_float32_radiosity_is_refused_naming_the_object(tmp_path):
    (tmp_path / "tri.obj").write_text(TRI)
    (tmp_path / "s.toml").write_text(
        '[[object]]\nmesh = "tri.obj"\nname = "lamp"\nemission = 3e37\nalbedo = 0.0\n'
        '[[object]]\nmesh = "tri.obj"\nname = "wall"\nalbedo = 0.9\n'
    )
    # pi * 3e37 / (1 - 0.9) = 9.4e38 > 3.4e38; at albedo 0.5, 1.9e38 fits
    with pytest.raises(ValueError, match=r"s\.toml: mesh 'lamp': emission .*radiosity up to 9\.42"):
        voxgi.Scene.load(tmp_path / "s.toml")
    (tmp_path / "s.toml").write_text(
        '[[object]]\nmesh = "tri.obj"\nname = "lamp"\nemission = 3e37\nalbedo = 0.0\n'
        '[[object]]\nmesh = "tri.obj"\nname = "wall"\nalbedo = 0.5\n'
    )
    assert len(voxgi.Scene.load(tmp_path / "s.toml").objects) == 2
