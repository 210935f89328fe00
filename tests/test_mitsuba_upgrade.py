"""Mitsuba 0.5/0.6 XML read as Mitsuba 3 reads it: its upgrade of older files.

Mitsuba 3 upgrades a file whose ``<scene version>`` is below 2.0.0 by
renaming every property of every object from camelCase to underscore_case
(``toWorld`` to ``to_world``, ``intIOR`` to ``int_ior``) and a ``diffuse``
BSDF's ``diffuseReflectance`` to ``reflectance``. The scenes below are small
procedural files in the old spelling; the expected values are closed forms
and, where the ``mitsuba`` package is importable, Mitsuba 3's own loader.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

import voxgi
from voxgi.formats import mitsuba_xml


def _load(path):
    """Load, returning the scene and the SceneWarning messages."""
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        scene = voxgi.Scene.load(path)
    return scene, [str(w.message) for w in rec if issubclass(w.category, voxgi.SceneWarning)]


def _write(folder: Path, body: str, version: str = "0.5.0", name: str = "scene.xml") -> Path:
    p = folder / name
    p.write_text(f'<?xml version="1.0"?>\n<scene version="{version}">\n{body}\n</scene>\n')
    return p


#: A 64x32 lookat camera with a vertical field of view, old spelling.
SENSOR = """
<sensor type="perspective">
    <float name="fov" value="40"/>
    <string name="fovAxis" value="y"/>
    <transform name="toWorld">
        <lookat origin="1, 2, 3" target="1, 2, 0" up="0, 1, 0"/>
    </transform>
    <film type="hdrfilm">
        <integer name="width" value="64"/>
        <integer name="height" value="32"/>
        <rfilter name="rfilter" type="box"/>
    </film>
</sensor>
"""

#: A 2 x 2 rectangle moved 5 along z by its toWorld.
FLOOR = """
<shape type="rectangle">
    <transform name="toWorld"><translate x="0" y="0" z="-5"/></transform>
    <bsdf type="roughplastic">
        <string name="distribution" value="ggx"/>
        <float name="intIOR" value="1.5"/>
        <float name="extIOR" value="1"/>
        <rgb name="diffuseReflectance" value="0.2, 0.4, 0.6"/>
    </bsdf>
</shape>
"""


@pytest.mark.parametrize(
    ("old", "new"),
    [
        ("toWorld", "to_world"),
        ("intIOR", "int_ior"),
        ("diffuseReflectance", "diffuse_reflectance"),
        ("fovAxis", "fov_axis"),
        ("sampleCount", "sample_count"),
        ("sigmaS", "sigma_s"),
        ("IOR", "IOR"),  # no lower-case letter before the capitals
        ("to_world", "to_world"),
        ("fooBARbaz", "foo_barbaz"),
    ],
)
def test_names_are_upgraded_by_mitsubas_rule(old, new):
    assert mitsuba_xml._underscore_case(old) == new


def test_camera_of_a_05_file_follows_its_to_world_and_fov_axis(tmp_path):
    scene, _ = _load(_write(tmp_path, SENSOR + FLOOR))
    cam = scene.camera
    np.testing.assert_allclose(cam.eye, [1, 2, 3])
    np.testing.assert_allclose(np.subtract(cam.target, cam.eye), [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(cam.up, [0, 1, 0], atol=1e-12)
    # fovAxis y: the 40 degrees are the vertical field as given (along x,
    # Mitsuba's default, the vertical field would be 2 atan(tan 20 / 2))
    assert cam.fov == pytest.approx(40.0, abs=1e-12)
    assert (cam.width, cam.height) == (64, 32)
    assert cam.pixel_filter == "box"  # the named rfilter, not Mitsuba's default Gaussian


def test_fov_along_x_is_mitsubas_default_in_05_files_too(tmp_path):
    sensor = SENSOR.replace('<string name="fovAxis" value="y"/>', "")
    scene, _ = _load(_write(tmp_path, sensor + FLOOR))
    expect = math.degrees(2 * math.atan(math.tan(math.radians(20)) * 32 / 64))
    assert scene.camera.fov == pytest.approx(expect, rel=1e-12)


def test_shape_to_world_and_roughplastic_diffuse_reflectance(tmp_path):
    scene, warned = _load(_write(tmp_path, SENSOR + FLOOR))
    (floor,) = scene.objects
    np.testing.assert_allclose(floor.vertices[:, 2], -5.0)
    np.testing.assert_allclose(floor.material.albedo, [0.2, 0.4, 0.6], rtol=1e-6)
    assert not any("read as Mitsuba 3" in w for w in warned), warned


def test_diffuse_reflectance_of_an_old_diffuse_bsdf_is_its_reflectance(tmp_path):
    body = FLOOR.replace('type="roughplastic"', 'type="diffuse"')
    scene, _ = _load(_write(tmp_path, SENSOR + body))
    np.testing.assert_allclose(scene.objects[0].material.albedo, [0.2, 0.4, 0.6], rtol=1e-6)


def test_named_references_and_area_emitters_in_old_spelling(tmp_path):
    body = """
    <bsdf type="twosided" id="paint">
        <bsdf type="roughplastic"><rgb name="diffuseReflectance" value="0.3"/></bsdf>
    </bsdf>
    <shape type="rectangle">
        <transform name="toWorld"><scale value="2"/></transform>
        <ref name="bsdf" id="paint"/>
    </shape>
    <shape type="rectangle">
        <transform name="toWorld"><translate z="1"/></transform>
        <emitter type="area"><rgb name="radiance" value="4, 5, 6"/></emitter>
    </shape>
    """
    scene, _ = _load(_write(tmp_path, SENSOR + body))
    wall, lamp = scene.objects
    np.testing.assert_allclose(np.abs(wall.vertices[:, :2]), 2.0)
    np.testing.assert_allclose(wall.material.albedo, 0.3, rtol=1e-6)
    assert wall.two_sided
    np.testing.assert_allclose(lamp.material.emission, [4, 5, 6])


def test_only_files_below_version_2_are_upgraded(tmp_path):
    # A Mitsuba 3 file keeps its names as written: there toWorld is unknown,
    # as Mitsuba 3 has it (it would reject the file), so the shape stays put.
    scene, _ = _load(_write(tmp_path, FLOOR, version="3.0.0"))
    np.testing.assert_allclose(scene.objects[0].vertices[:, 2], 0.0)
    np.testing.assert_allclose(scene.objects[0].material.albedo, 0.5)


def test_an_included_05_file_is_upgraded_inside_a_3_file(tmp_path):
    _write(tmp_path, FLOOR, version="0.5.0", name="floor.xml")
    path = _write(tmp_path, '<include filename="floor.xml"/>', version="3.0.0")
    scene, _ = _load(path)
    np.testing.assert_allclose(scene.objects[0].vertices[:, 2], -5.0)


def test_a_bad_version_names_the_file_and_value(tmp_path):
    path = _write(tmp_path, FLOOR, version="zero.five")
    with pytest.raises(ValueError, match=r"scene\.xml: line 2: <scene version='zero\.five'>"):
        voxgi.Scene.load(path)


def test_glass_is_listed_plainly_in_the_warning(tmp_path):
    body = FLOOR.replace('<bsdf type="roughplastic">', '<bsdf type="dielectric" id="WindowGlass">')
    scene, warned = _load(_write(tmp_path, SENSOR + body))
    (line,) = [w for w in warned if "approximated" in w]
    assert "glass bsdf 'dielectric' (id 'WindowGlass')" in line
    assert "each crossing of its surface a transmitting sheet" in line
    (pane,) = scene.objects
    assert pane.material.is_sheet
    assert pane.two_sided
    # one interface of index 1.5 (intIOR 1.5 over extIOR 1), hemispherical mean
    np.testing.assert_allclose(pane.material.transmittance, 0.908222, atol=1e-6)


def test_thin_glass_is_a_slab_and_both_kinds_are_listed(tmp_path):
    thin = FLOOR.replace('<bsdf type="roughplastic">', '<bsdf type="thindielectric" id="Pane">')
    thick = FLOOR.replace('<bsdf type="roughplastic">', '<bsdf type="dielectric" id="Lens">')
    thick = thick.replace('z="-5"', 'z="-6"')
    scene, warned = _load(_write(tmp_path, SENSOR + thin + thick))
    (line,) = [w for w in warned if "approximated" in w]
    assert "glass bsdf 'thindielectric' (id 'Pane'): a transmitting sheet, 0.845" in line
    assert "glass bsdf 'dielectric' (id 'Lens'): each crossing" in line
    np.testing.assert_allclose(scene.objects[0].material.transmittance, 0.844556, atol=1e-6)


def test_a_mesh_of_zero_area_is_left_out_and_listed(tmp_path):
    (tmp_path / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    body = '<shape type="obj" id="sliver"><string name="filename" value="flat.obj"/></shape>'
    scene, warned = _load(_write(tmp_path, SENSOR + FLOOR + body))
    assert [o.name for o in scene.objects] == ["rectangle0"]
    assert any("'sliver': every face has zero area" in w for w in warned), warned


def test_relative_paths_load_from_another_folder(tmp_path, monkeypatch):
    folder = tmp_path / "room"
    (folder / "models").mkdir(parents=True)
    (folder / "models" / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    body = '<shape type="obj"><string name="filename" value="models/tri.obj"/></shape>'
    _write(folder, SENSOR + body)
    monkeypatch.chdir(tmp_path)
    scene, _ = _load(Path("room") / "scene.xml")
    np.testing.assert_allclose(scene.objects[0].vertices[1], [1, 0, 0])


def test_camera_matches_mitsubas_own_upgrade(tmp_path):
    pytest.importorskip("mitsuba")
    from voxgi.mitsuba import mitsuba_module

    mi = mitsuba_module()
    # a tilted, off-axis camera so that every component of the frame counts
    sensor = SENSOR.replace(
        'origin="1, 2, 3" target="1, 2, 0" up="0, 1, 0"',
        'origin="1, 2, 3" target="-0.5, 1.2, -1" up="0.1, 1, 0.2"',
    ).replace('value="y"', 'value="x"')
    path = _write(tmp_path, sensor + FLOOR)
    ours = _load(path)[0].camera
    sc = mi.load_file(str(path))
    m = np.array(sc.sensors()[0].world_transform().matrix, np.float64).reshape(4, 4)
    np.testing.assert_allclose(ours.eye, m[:3, 3], atol=1e-6)
    fwd = np.subtract(ours.target, ours.eye)
    np.testing.assert_allclose(fwd / np.linalg.norm(fwd), m[:3, 2], atol=1e-6)
    np.testing.assert_allclose(ours.up / np.linalg.norm(ours.up), m[:3, 1], atol=1e-6)
    x_fov = float(mi.traverse(sc.sensors()[0])["x_fov"][0])
    expect = math.degrees(2 * math.atan(math.tan(math.radians(x_fov) / 2) * 32 / 64))
    assert ours.fov == pytest.approx(expect, rel=1e-5)
