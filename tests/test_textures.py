"""UV-mapped bitmap albedo (voxgi.Texture, docs/design.md §12).

Closed forms: a textured plane under a point light, with nothing else in
the scene, shows in each pixel ``albedo(uv) E / pi`` with ``E = I cos / r²``
at the point the pixel's camera ray meets: the texture filtered at that
point's UV, exactly (float32 rounding). Each voxel record's albedo is the
texture's mean over the record's own surface, against a numpy integration
of the same filter. Mitsuba renders the same textured quad (exported by
``to_mitsuba``) alike.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

import voxgi
from voxgi.display.samples import camera_rays, frame_samples


def _random_texture(h=8, w=8, seed=1, **kw) -> voxgi.Texture:
    rng = np.random.default_rng(seed)
    return voxgi.Texture(rng.integers(0, 256, (h, w, 3), dtype=np.uint8), **kw)


def _textured_plane(tex, uv_scale=1.0, flip_v=False) -> voxgi.Scene:
    """A 2 x 2 upward plane at y = 0, UV (0, 0) at corner (-1, -1) (x, z), and
    a camera looking straight down at it."""
    v = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], float)
    uv = (v[:, [0, 2]] + 1) / 2 * uv_scale
    if flip_v:
        uv[:, 1] = 1 - uv[:, 1]
    sc = voxgi.Scene()
    sc.add(
        trimesh.Trimesh(v, [[0, 2, 1], [0, 3, 2]], process=False),
        voxgi.Material(texture=tex),
        name="plane",
        uv=uv,
    )
    sc.camera = voxgi.Camera(
        eye=(0.1, 2.5, 0.05), target=(0.1, 0, 0.05), up=(0, 0, -1), fov=30, width=48, height=40
    )
    return sc


def _expected_pixels(sc: voxgi.Scene, light: voxgi.PointLight, tex: voxgi.Texture, offset):
    """albedo(uv) I cos / (pi r²) at each pixel's ray's hit of y = 0 (0: a
    miss), which pixels hit the plane, and the UVs there."""
    org, d = camera_rays(sc.camera, offset)
    t = -org[:, 1] / d[:, 1]
    x = org + t[:, None] * d
    inside = np.all(np.abs(x[:, [0, 2]]) < 1, axis=1)
    uv = (x[:, [0, 2]] + 1) / 2
    to_light = np.asarray(light.position) - x
    r2 = np.einsum("ij,ij->i", to_light, to_light)
    e = np.asarray(light.intensity)[None, :] * (to_light[:, 1] / r2**1.5)[:, None]
    want = tex.eval(uv) * e / math.pi
    return np.where(inside[:, None], want, 0.0), inside, uv


@pytest.mark.parametrize(
    ("filt", "wrap", "scale"),
    [
        ("bilinear", "repeat", 1.0),
        ("nearest", "repeat", 1.0),
        ("bilinear", "mirror", 2.5),
        ("nearest", "clamp", 1.7),
    ],
)
def test_textured_plane_under_a_point_light_is_exact(filt, wrap, scale):
    tex = _random_texture(filter=filt, wrap=wrap)
    sc = _textured_plane(tex, uv_scale=scale)
    light = sc.add_light(voxgi.PointLight((0.3, 1.5, -0.2), (2.0, 1.5, 1.0)))
    res = voxgi.render(sc, tol=0, max_frames=1, progress=False, threads=1)
    # (the uv scale enters through the mesh's UVs; the reference looks up uv * scale)
    ref_tex = voxgi.Texture(tex.texels, filter=filt, wrap=wrap, to_uv=np.diag([scale, scale, 1]))
    want, inside, uv = _expected_pixels(sc, light, ref_tex, frame_samples(0, 0)[0])
    got = res.image.reshape(-1, 3)
    assert inside.sum() > 1000
    np.testing.assert_allclose(got[inside], want[inside], rtol=2e-5, atol=1e-7)
    # the albedo AOV is the texture at the same points
    albedo = ref_tex.eval(uv)
    np.testing.assert_allclose(res.albedo.reshape(-1, 3)[inside], albedo[inside], rtol=2e-5)


def test_flipped_v_is_seen():
    # the same check fails when the mesh's v runs the other way: the test sees a flip
    tex = _random_texture()
    sc = _textured_plane(tex, flip_v=True)
    light = sc.add_light(voxgi.PointLight((0.3, 1.5, -0.2), 1.0))
    res = voxgi.render(sc, tol=0, max_frames=1, progress=False, threads=1)
    want, inside, _ = _expected_pixels(sc, light, tex, frame_samples(0, 0)[0])
    err = np.abs(res.image.reshape(-1, 3)[inside] - want[inside]).max() / want[inside].max()
    assert err > 0.1


def test_record_albedo_is_the_texture_mean_over_its_own_surface():
    # a plane of two halves, dark and light texels: records on each side see
    # their own half's mean, not the plane's
    texels = np.zeros((4, 4, 3), np.uint8)
    texels[:, :2] = 30
    texels[:, 2:] = 230
    tex = voxgi.Texture(texels, filter="nearest")
    sc = _textured_plane(tex)
    vox = voxgi.voxelize(sc, resolution=8, progress=False)
    up = (vox.normal[:, 1] > 0.5) & (vox.area > 0)
    lin = tex.eval(np.array([[0.1, 0.5], [0.9, 0.5]]))
    x = vox.centroid[up, 0]
    dark, light = x < -0.05, x > 0.05
    assert dark.sum() > 5
    assert light.sum() > 5
    np.testing.assert_allclose(vox.albedo[up][dark], np.tile(lin[0], (dark.sum(), 1)), rtol=1e-6)
    np.testing.assert_allclose(vox.albedo[up][light], np.tile(lin[1], (light.sum(), 1)), rtol=1e-6)
    # the object's own albedo is the whole image's mean
    np.testing.assert_allclose(sc.objects[0].material.albedo, lin.mean(axis=0), rtol=1e-6)


def test_a_glass_sheet_beside_a_textured_plane_keeps_the_records_texture():
    # the sheets are not voxelized: the textures' UVs must follow the
    # triangles that are (a sheet listed first failed the kernel's shape check)
    texels = np.zeros((4, 4, 3), np.uint8)
    texels[:, :2] = 30
    texels[:, 2:] = 230
    tex = voxgi.Texture(texels, filter="nearest")
    plane = _textured_plane(tex)
    sc = voxgi.Scene(plane.camera)
    pane = voxgi.Material(albedo=0.0, transmittance=0.8)
    sc.add(trimesh.Trimesh([[-1, 1, -1], [1, 1, -1], [1, 1, 1]], [[0, 1, 2]]), pane, name="pane")
    o = plane.objects[0]
    sc.add(trimesh.Trimesh(o.vertices, o.faces, process=False), o.material, name="plane", uv=o.uv)
    vox = voxgi.voxelize(sc, resolution=8, progress=False)
    up = (vox.normal[:, 1] > 0.5) & (vox.area > 0)
    lin = tex.eval(np.array([[0.1, 0.5], [0.9, 0.5]]))
    dark = vox.centroid[up, 0] < -0.05
    np.testing.assert_allclose(vox.albedo[up][dark], np.tile(lin[0], (dark.sum(), 1)), rtol=1e-6)


def test_record_albedo_against_numpy_integration():
    # bilinear texture, voxels that cut the triangles into pieces: each
    # record's albedo is the area-weighted mean of the filter over its pieces
    tex = _random_texture(16, 16, seed=4, filter="bilinear")
    sc = _textured_plane(tex)
    vox = voxgi.voxelize(sc, resolution=4, progress=False)
    up = np.flatnonzero((vox.normal[:, 1] > 0.5) & (vox.area > 0))
    pitch = vox.pitch
    origin = np.asarray(vox.origin)
    worst = 0.0
    for r in up:
        lo = origin + vox.ijk[r] * pitch
        # the record's square of the plane, in UV (the plane's uv = (x + 1) / 2, (z + 1) / 2)
        x0, x1 = max(lo[0], -1), min(lo[0] + pitch, 1)
        z0, z1 = max(lo[2], -1), min(lo[2] + pitch, 1)
        u0, u1, v0, v1 = (x0 + 1) / 2, (x1 + 1) / 2, (z0 + 1) / 2, (z1 + 1) / 2
        n = 200
        uu, vv = np.meshgrid(u0 + (u1 - u0) * (np.arange(n) + 0.5) / n,
                             v0 + (v1 - v0) * (np.arange(n) + 0.5) / n)  # fmt: skip
        want = tex.eval(np.stack([uu.ravel(), vv.ravel()], 1)).mean(axis=0)
        worst = max(worst, float(np.abs(vox.albedo[r] - want).max() / want.max()))
    # the kernel's midpoint rule (16 samples a texel) against a 200² grid: a
    # random texture (every texel independent, the worst case for the rule)
    # measured 6.6e-3 here; at 2 samples a texel it was 7.7e-2
    assert worst < 1e-2, worst


def test_texture_validation_names_the_field():
    with pytest.raises(ValueError, match=r"Texture\.texels"):
        voxgi.Texture(np.zeros((4, 4), np.uint8))
    with pytest.raises(ValueError, match=r"Texture\.wrap"):
        voxgi.Texture(np.zeros((4, 4, 3), np.uint8), wrap="tile")
    sc = voxgi.Scene()
    with pytest.raises(ValueError, match="needs UVs"):
        sc.add(trimesh.creation.box(), voxgi.Material(texture=_random_texture()), name="box")


def test_untextured_scene_albedo_aov_is_each_objects_albedo():
    # no texture: the render's albedo AOV is each object's own albedo
    sc = voxgi.scenes.cornell_box(8, 8)
    vox = voxgi.voxelize(sc, resolution=16, progress=False)
    dark = voxgi.Solution(vox=vox, radiosity=np.zeros((len(vox), 3), np.float32))
    res = voxgi.render(sc, dark, tol=0, max_frames=1, progress=False, threads=1)
    albedos = {tuple(np.float32(o.material.albedo)) for o in sc.objects}
    seen = {tuple(a) for a in res.albedo.reshape(-1, 3) if a.any()}
    assert seen
    assert seen <= albedos, seen - albedos


def test_textured_quad_matches_mitsuba():
    # the same export renders the same albedo: a textured quad under a point
    # light has no indirect light, so the two differ by noise only
    pytest.importorskip("mitsuba")
    from voxgi.metrics import rel_mse
    from voxgi.mitsuba import render_mitsuba

    to_uv = np.array([[1.5, 0.2, 0.1], [0.0, 1.2, -0.3], [0, 0, 1]])
    tex = _random_texture(8, 8, seed=7, filter="bilinear", wrap="mirror", to_uv=to_uv)
    sc = _textured_plane(tex)
    sc.camera = sc.camera.replace(width=32, height=32)
    sc.add_light(voxgi.PointLight((0.3, 1.5, -0.2), (2.0, 1.5, 1.0)))
    out = voxgi.render(sc, progress=False, max_frames=64, tol=0, threads=1)
    ref = render_mitsuba(sc, 256)
    err = rel_mse(out.image, ref)
    # (measured 6.8e-6, Mitsuba's own noise at 256 spp 7e-6; against 4096 spp
    # 5.9e-7; the flipped texture below 0.16)
    assert err < 1e-4, err
    # a texture read the other way round in either is far off
    flipped = render_mitsuba(_flipped(sc), 64)
    assert rel_mse(out.image, flipped) > 10 * err


def _flipped(sc: voxgi.Scene) -> voxgi.Scene:
    """``sc`` with its plane's v turned around (a broken input for the check above)."""
    o = sc.objects[0]
    out = voxgi.Scene(camera=sc.camera)
    uv = o.uv.copy()
    uv[:, 1] = 1 - uv[:, 1]
    out.add(trimesh.Trimesh(o.vertices, o.faces, process=False), o.material, uv=uv)
    for light in sc.lights:
        out.add_light(light)
    return out


_XML = """<scene version="3.0.0">
  <bsdf type="diffuse" id="paper">
    <texture type="bitmap" name="reflectance">
      <string name="filename" value="tex.png"/>
      <string name="filter_type" value="nearest"/>
      <string name="wrap_mode" value="clamp"/>
      <transform name="to_uv"><scale x="2" y="3"/></transform>
    </texture>
  </bsdf>
  <shape type="obj">
    <string name="filename" value="quad.obj"/>
    <ref id="paper"/>
  </shape>
</scene>
"""


def _load_xml_quad(tmp_path, obj_text: str):
    """(texture, scene): ``_XML`` loaded over ``obj_text`` as its quad.obj,
    a random 4 x 6 texture as its tex.png; no mean-colour warning."""
    from PIL import Image

    tex = _random_texture(4, 6, seed=3)
    Image.fromarray(tex.texels).save(tmp_path / "tex.png")
    (tmp_path / "quad.obj").write_text(obj_text)
    (tmp_path / "scene.xml").write_text(_XML)
    with _no_mean_warning():
        return tex, voxgi.Scene.load(tmp_path / "scene.xml")


def test_xml_bitmap_loads_as_a_texture_and_saves_with_it(tmp_path):
    # an OBJ's vt has v = 0 at the image's bottom (Mitsuba turns it)
    tex, sc = _load_xml_quad(
        tmp_path,
        "v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
        "f 1/1 3/3 2/2\nf 1/1 4/4 3/3\n",
    )
    t = sc.objects[0].material.texture
    assert t is not None
    assert (t.filter, t.wrap) == ("nearest", "clamp")
    np.testing.assert_array_equal(t.texels, tex.texels)
    np.testing.assert_allclose(t.to_uv, np.diag([2.0, 3.0, 1.0]))
    np.testing.assert_allclose(sc.objects[0].uv[:4], [[0, 1], [1, 1], [1, 0], [0, 0]])
    # Scene.save keeps the texture (its file beside the scene) and the UVs
    sc.save(tmp_path / "out" / "scene.toml")
    back = voxgi.Scene.load(tmp_path / "out" / "scene.toml")
    assert back.fingerprint() == sc.fingerprint()
    assert back.objects[0].material.texture.filter == "nearest"


def test_a_mesh_with_an_unused_vertex_keeps_its_uvs(tmp_path):
    # Bitterli's OBJ files hold vertices no face uses among the used ones;
    # trimesh's order-keeping OBJ reader then drops every UV of the mesh.
    # The texture must stay a texture, through Scene.save and back, with each
    # used vertex's own UV.
    _, sc = _load_xml_quad(
        tmp_path,
        "v 0 0 0\nv 1 0 0\nv 9 9 9\nv 1 0 1\nv 0 0 1\n"
        "vt 0 0\nvt 1 0\nvt 0.5 0.5\nvt 1 1\nvt 0 1\n"
        "f 1/1 4/4 2/2\nf 1/1 5/5 4/4\n",
    )
    obj = sc.objects[0]
    assert obj.material.texture is not None
    # each face corner keeps the UV its vertex had in the file (v turned to
    # the image's top, as Mitsuba reads an OBJ)
    want = {(0, 0, 0): (0, 1), (1, 0, 0): (1, 1), (1, 0, 1): (1, 0), (0, 0, 1): (0, 0)}
    for f in obj.faces:
        for i in f:
            np.testing.assert_allclose(obj.uv[i], want[tuple(obj.vertices[i].round(6))])
    sc.save(tmp_path / "out" / "scene.toml")
    with _no_mean_warning():
        back = voxgi.Scene.load(tmp_path / "out" / "scene.toml")
    assert back.objects[0].material.texture is not None
    assert back.fingerprint() == sc.fingerprint()


class _no_mean_warning:
    """No warning that a bitmap was reduced to its mean colour."""

    def __enter__(self):
        import warnings

        self._cm = warnings.catch_warnings(record=True)
        self._w = self._cm.__enter__()
        warnings.simplefilter("always")

    def __exit__(self, *exc):
        self._cm.__exit__(*exc)
        assert not any("mean colour" in str(w.message) for w in self._w)


def _visual_quad(texels):
    """A quad with trimesh's texture visual (its uv with v = 0 at the image's bottom)."""
    from PIL import Image

    v = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]], float)
    uv = np.array([[0.1, 0.2], [0.9, 0.2], [0.9, 0.7], [0.1, 0.7]])
    mat = trimesh.visual.material.PBRMaterial(
        name="paper", baseColorTexture=Image.fromarray(texels)
    )
    mesh = trimesh.Trimesh(v, [[0, 2, 1], [0, 3, 2]], process=False)
    mesh.visual = trimesh.visual.TextureVisuals(uv=uv, material=mat)
    return mesh, uv


@pytest.mark.parametrize("suffix", [".obj", ".glb"])
def test_obj_map_kd_and_gltf_base_color_texture_load_as_textures(tmp_path, suffix):
    from PIL import Image

    texels = _random_texture(4, 4, seed=9).texels
    mesh, uv = _visual_quad(texels)
    if suffix == ".obj":
        Image.fromarray(texels).save(tmp_path / "paper.png")
        (tmp_path / "s.mtl").write_text("newmtl paper\nKd 1 1 1\nmap_Kd paper.png\n")
        lines = ["mtllib s.mtl", "usemtl paper"]
        lines += [f"v {a} {b} {c}" for a, b, c in mesh.vertices]
        lines += [f"vt {a} {b}" for a, b in uv]
        lines += ["f 1/1 3/3 2/2", "f 1/1 4/4 3/3"]
        (tmp_path / "s.obj").write_text("\n".join(lines) + "\n")
    else:
        mesh.export(tmp_path / "s.glb")
    with _no_mean_warning():
        sc = voxgi.Scene.load(tmp_path / f"s{suffix}")
    o = sc.objects[0]
    assert o.material.texture is not None
    np.testing.assert_array_equal(o.material.texture.texels, texels)
    # the same visual gives the same UVs from either format: v = 0 the image's top
    order = [int(np.argmin(np.linalg.norm(o.vertices - p, axis=1))) for p in mesh.vertices]
    np.testing.assert_allclose(o.uv[order], np.c_[uv[:, 0], 1 - uv[:, 1]], atol=1e-6)


@pytest.mark.parametrize(
    ("filt", "wrap", "uv", "want"),
    [
        # raw codes 0, 255 / 51, 102 (linear 0, 1 / 0.2, 0.4), row 0 at v = 0
        ("bilinear", "repeat", (0.25, 0.25), 0.0),  # a texel centre
        ("bilinear", "repeat", (0.5, 0.25), 0.5),  # midway between two centres
        ("bilinear", "repeat", (0.5, 0.5), (0 + 1 + 0.2 + 0.4) / 4),  # the four
        ("bilinear", "repeat", (-0.25, 0.25), 1.0),  # column -1 is column 1
        ("bilinear", "mirror", (-0.25, 0.25), 0.0),  # column -1 is column 0
        ("bilinear", "clamp", (1.5, 0.75), 0.4),  # past the edge: the edge texel
        ("bilinear", "repeat", (0.0, 0.25), 0.5),  # the seam blends columns 1 and 0
        ("bilinear", "clamp", (0.0, 0.25), 0.0),
        ("nearest", "repeat", (0.49, 0.51), 0.2),
        ("nearest", "repeat", (1.76, -0.2), 0.4),  # column 3, row -1: texel (1, 1)
        ("nearest", "mirror", (1.26, 0.1), 1.0),  # column 2 mirrors to column 1
    ],
)
def test_texture_lookup_by_hand(filt, wrap, uv, want):
    codes = np.array([[0, 255], [51, 102]], np.uint8)
    tex = voxgi.Texture(np.repeat(codes[..., None], 3, axis=2), filter=filt, wrap=wrap, raw=True)
    # the decode table is float32
    np.testing.assert_allclose(tex.eval(np.array([uv])), [[want] * 3], rtol=1e-7, atol=1e-9)


def test_texture_srgb_decoding_by_hand():
    # IEC 61966-2-1: code 128 is ((128/255 + 0.055) / 1.055)^2.4 = 0.2158605;
    # 10 is on the linear toe, 10 / 255 / 12.92 = 0.0030353
    tex = voxgi.Texture(np.array([[[128, 10, 255]]], np.uint8), filter="nearest")
    np.testing.assert_allclose(tex.eval([[0.5, 0.5]]), [[0.2158605, 0.0030353, 1.0]], rtol=1e-5)
    np.testing.assert_allclose(tex.mean(), [0.2158605, 0.0030353, 1.0], rtol=1e-5)


def test_the_surface_tables_are_built_once_for_a_scene_as_it_stands():
    # The voxelization and the display read the same tables; a texture or a
    # mesh changed in place gives new ones.
    from voxgi.textures import surface_tables

    sc = _textured_plane(_random_texture())
    first = surface_tables(sc)
    assert surface_tables(sc) is first
    assert not first["corner_uv"].flags.writeable
    sc.objects[0].material = voxgi.Material(texture=_random_texture(seed=2))
    second = surface_tables(sc)
    assert second is not first
    assert not np.array_equal(second["tex_texels"][0], first["tex_texels"][0])
