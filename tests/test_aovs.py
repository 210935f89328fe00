"""The pixel AOVs (albedo, normal, depth, object, seen emission) against the
camera rays' own hits computed in closed form."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

import voxgi
from voxgi.display.pixel_filter import gaussian_pixel_filter
from voxgi.display.samples import camera_rays, frame_samples

W, H, FOV = 8, 6, 60.0
NEAR_ALBEDO = np.array([0.1, 0.3, 0.9])
FAR_ALBEDO = np.array([0.8, 0.2, 0.1])
FAR_POINT = np.array([0.0, 0.0, -3.0])
FAR_NORMAL = np.array([0.0, 0.4, 1.0]) / np.linalg.norm([0.0, 0.4, 1.0])
# The near quad is flat (geometric normal +z) but carries vertex normals
# tilted to this: its shading normal.
NEAR_SHADING = np.array([0.3, 0.0, 1.0]) / np.linalg.norm([0.3, 0.0, 1.0])
CAM = voxgi.Camera(eye=(0, 0, 0), target=(0, 0, -1), up=(0, 1, 0), fov=FOV, width=W, height=H)
# The pinhole's ray through (column + ox) meets the plane z = -1 at
# x = (2 (column + ox) / W - 1) tan(fov/2) W/H: the near quad's edge at the
# centre of column 3 covers half of that column.
EDGE_X = (2 * 3.5 / W - 1) * np.tan(np.radians(FOV) / 2) * W / H


def _scene(pixel_filter: str = "box") -> voxgi.Scene:
    s = voxgi.Scene(dataclasses.replace(CAM, pixel_filter=pixel_filter))
    near = [[-10, -10, -1], [EDGE_X, -10, -1], [EDGE_X, 10, -1], [-10, 10, -1]]
    mesh = trimesh.Trimesh(
        near, [[0, 1, 2], [0, 2, 3]], vertex_normals=np.tile(NEAR_SHADING, (4, 1)), process=False
    )
    s.add(mesh, voxgi.Material(albedo=tuple(NEAR_ALBEDO)), name="near")
    u = np.array([1.0, 0.0, 0.0])
    v = np.cross(FAR_NORMAL, u)
    far = [FAR_POINT + 20 * (a * u + b * v) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    s.add(
        trimesh.Trimesh(far, [[0, 1, 2], [0, 2, 3]], process=False),
        voxgi.Material(albedo=tuple(FAR_ALBEDO), emission=1.0),
        name="far",
    )
    return s


def _exact_frame(offset) -> np.ndarray:
    """(P, 8): albedo, normal, depth, object of each camera ray's first hit,
    intersected with the two planes in closed form."""
    org, d = camera_rays(CAM, offset)
    t_near = -1.0 / d[:, 2]  # the plane z = -1
    x = t_near * d[:, 0]
    near = x <= EDGE_X
    t_far = ((FAR_POINT - org) @ FAR_NORMAL) / (d @ FAR_NORMAL)
    t = np.where(near, t_near, t_far)
    out = np.zeros((len(d), 8))
    out[:, 0:3] = np.where(near[:, None], NEAR_ALBEDO, FAR_ALBEDO)
    out[:, 3:6] = np.where(near[:, None], NEAR_SHADING, FAR_NORMAL)
    out[:, 6] = t * -d[:, 2]  # along the view axis (0, 0, -1)
    out[:, 7] = np.where(near, 0, 1)
    return out


def _render(pixel_filter: str, frames: int, seed: int):
    scene = _scene(pixel_filter)
    sol = voxgi.solve(voxgi.voxelize(scene, 8), progress=False)
    return voxgi.render(scene, sol, tol=0, max_frames=frames, seed=seed, progress=False)


@pytest.mark.parametrize("seed", [0, 3])
def test_aovs_are_the_camera_hits_averaged_over_the_frames(seed):
    frames = 16
    out = _render("box", frames, seed)
    assert out.frames == frames
    samples = [_exact_frame(frame_samples(f, seed)[0]) for f in range(frames)]
    want = np.mean(samples, axis=0).reshape(H, W, 8)
    np.testing.assert_allclose(out.albedo, want[..., 0:3], atol=1e-6)
    np.testing.assert_allclose(out.normal, want[..., 3:6], atol=1e-6)
    np.testing.assert_allclose(out.depth, want[..., 6], rtol=1e-5)
    np.testing.assert_array_equal(out.object_id, samples[0][:, 7].reshape(H, W))
    # Column 3 is half covered by the near quad: its albedo is the two
    # albedos mixed by the share of the 16 stratified offsets left of the
    # pixel's centre, 8 of 16 to within one stratum.
    cover = (out.albedo[:, 3, 2] - FAR_ALBEDO[2]) / (NEAR_ALBEDO[2] - FAR_ALBEDO[2])
    np.testing.assert_allclose(cover, 0.5, atol=1 / 16 + 1e-6)
    np.testing.assert_allclose(
        out.albedo[:, :3], np.broadcast_to(NEAR_ALBEDO, (H, 3, 3)), atol=1e-6
    )
    np.testing.assert_allclose(out.albedo[:, 4:], np.broadcast_to(FAR_ALBEDO, (H, 4, 3)), atol=1e-6)


def test_emission_aov_is_the_emitters_radiance_each_pixel_sees():
    """The far plane emits radiance 1 and the near quad nothing: the emission
    AOV is 1 right of the near quad's edge and 0 left of it; column 3, half
    covered, is controlled (``stats["seen_emission"]``) and holds its
    controlled mean, a half. The rest of the image is reflected light."""
    out = _render("box", 16, 0)
    np.testing.assert_array_equal(out.emission[:, :3], 0.0)
    np.testing.assert_array_equal(out.emission[:, 4:], 1.0)
    np.testing.assert_allclose(out.emission[:, 3], 0.5, atol=0.02)
    assert out.stats["seen_emission"]["pixels"] >= H
    assert np.all(out.image - out.emission >= -1e-6)
    # where the far plane fills the pixel, it reflects nothing back (the near
    # quad faces away from it): the image there is its emission exactly
    np.testing.assert_array_equal(out.image[:, 4:], out.emission[:, 4:])


def test_aovs_take_the_images_gaussian_pixel_filter():
    frames, seed = 8, 1
    out = _render("gaussian", frames, seed)
    acc = np.zeros((H * W, 8))
    for f in range(frames):
        offset = frame_samples(f, seed)[0]
        s = _exact_frame(offset)
        # the hit indicator weights the depth, as the renderer's frames do
        x = np.concatenate([s[:, 0:6], s[:, 6:7], np.ones((H * W, 1))], axis=1)
        acc += gaussian_pixel_filter(x, W, H, offset)
    want = (acc / frames).reshape(H, W, 8)
    np.testing.assert_allclose(out.albedo, want[..., 0:3], atol=1e-5)
    np.testing.assert_allclose(out.normal, want[..., 3:6], atol=1e-5)
    np.testing.assert_allclose(out.depth, want[..., 6], rtol=1e-5)
    # the filter blurs the edge over column 3's neighbours too
    assert np.all(out.albedo[:, 2, 2] < NEAR_ALBEDO[2] - 0.01)


def test_exr_layers_round_trip(tmp_path):
    out = _render("box", 4, 0)
    p = voxgi.io.write_exr(
        tmp_path / "a.exr", out.image, stderr=out.stderr, layers=out.exr_layers()
    )
    np.testing.assert_array_equal(voxgi.io.read_exr(p, layer="albedo"), out.albedo)
    np.testing.assert_array_equal(voxgi.io.read_exr(p, layer="normal"), out.normal)
    np.testing.assert_array_equal(voxgi.io.read_exr(p, layer="emission"), out.emission)
    ch = voxgi.io.read_exr_channels(p)
    np.testing.assert_array_equal(ch["depth.Z"], out.depth)
    np.testing.assert_array_equal(ch["object_id"], out.object_id)
    np.testing.assert_array_equal(voxgi.io.read_exr(p), out.image)


def test_cli_writes_the_aov_layers(tmp_path):
    from voxgi import cli

    out = tmp_path / "c.exr"
    small = ["--resolution", "8", "--frames", "2", "--width", "8", "--height", "6", "-q"]
    assert cli.main(["render", "cornell-box", "-o", str(out), *small]) == 0
    ch = voxgi.io.read_exr_channels(out)
    want = {"albedo.R", "albedo.G", "albedo.B", "normal.X", "normal.Y", "normal.Z"}
    want |= {"emission.R", "emission.G", "emission.B"}
    assert want | {"depth.Z", "object_id", "stderr.R"} <= set(ch)
    albedo = voxgi.io.read_exr(out, layer="albedo")
    assert np.all((albedo >= 0) & (albedo <= 1))
    n = np.linalg.norm(voxgi.io.read_exr(out, layer="normal"), axis=-1)
    assert np.all(n <= 1 + 1e-5)
    assert n.max() > 0.99  # a pixel inside a wall: a unit normal


def test_bad_layers(tmp_path):
    img = np.zeros((2, 3, 3))
    with pytest.raises(ValueError, match=r"layers\['depth.Z'\]: expected shape \(2, 3\)"):
        voxgi.io.write_exr(tmp_path / "a.exr", img, layers={"depth.Z": np.zeros((3, 2))})
    with pytest.raises(TypeError, match=r"layers\['x'\]: expected a numeric"):
        voxgi.io.write_exr(tmp_path / "a.exr", img, layers={"x": np.full((2, 3), "a")})
    with pytest.raises(ValueError, match="repeated channel name 'R'"):
        voxgi.io.write_exr(tmp_path / "a.exr", img, layers={"R": np.zeros((2, 3))})
    assert not (tmp_path / "a.exr").exists()
