"""The PNG preview's exposure and tone curve (voxgi.io)."""

from __future__ import annotations

import numpy as np
import pytest
from skimage.io import imread

from voxgi import io


def _srgb8(x: float) -> int:
    """The sRGB transfer curve (IEC 61966-2-1) of a value in [0, 1], in 8 bits."""
    s = 12.92 * x if x <= 0.0031308 else 1.055 * x ** (1 / 2.4) - 0.055
    return round(255 * s)


def test_auto_exposure_maps_the_log_average_to_middle_grey():
    # Two halves of luminance 0.5 and 8 (grey): log-average sqrt(0.5 * 8) = 2.
    img = np.full((4, 4, 3), 0.5, np.float32)
    img[:, 2:] = 8.0
    assert io.auto_exposure(img) == pytest.approx(np.log2(0.18 / 2.0), abs=1e-5)
    # A uniform image lands on 0.18 exactly, whatever its level.
    for level in (1e-3, 1.0, 50.0):
        ev = io.auto_exposure(np.full((3, 3), level))
        assert level * 2**ev == pytest.approx(0.18, rel=1e-3)
    assert io.auto_exposure(np.zeros((2, 2, 3))) == 0.0
    assert np.isfinite(io.auto_exposure(np.full((2, 2, 3), np.nan)))


def test_reinhard_is_the_identity_when_nothing_exceeds_white():
    img = np.linspace(0.0, 1.0, 48, dtype=np.float32).reshape(4, 4, 3)
    np.testing.assert_array_equal(io.to_srgb8(img, 0.0, "reinhard"), io.to_srgb8(img, 0.0, "clip"))


def test_reinhard_keeps_highlights_apart_and_only_the_top_reaches_white():
    # A window of radiance 6 crossed by bars of 3, over a room of 0.25: the
    # curve x (1 + x / w²) / (1 + x) with w = 6 (the 99.9th percentile).
    img = np.full((40, 40, 3), 0.25, np.float32)
    img[:10, :10] = 6.0
    img[:10, 5] = 3.0
    out = io.to_srgb8(img, 0.0, "reinhard")
    w = 6.0
    for x, px in [(6.0, out[0, 0, 0]), (3.0, out[0, 5, 0]), (0.25, out[30, 30, 0])]:
        assert px == _srgb8(x * (1 + x / w**2) / (1 + x))
    assert out[0, 0, 0] == 255
    assert out[0, 5, 0] < 240  # the bars stay visible against the window
    clipped = io.to_srgb8(img, 0.0, "clip")
    assert clipped[0, 5, 0] == clipped[0, 0, 0] == 255


def test_write_png_default_is_auto_exposure_and_reinhard(tmp_path):
    # Log-average 3 (4/3)^(1/64); exposed, nothing reaches 1, so the curve
    # is the identity and the background lands just under 0.18.
    img = np.full((8, 8, 3), 3.0, np.float32)
    img[0, 0] = 4.0
    p = io.write_png(tmp_path / "a.png", img)
    want = io.to_srgb8(img, io.auto_exposure(img), "reinhard")
    np.testing.assert_array_equal(imread(p), want)
    assert imread(p)[4, 4, 0] == _srgb8(0.18 / (4.0 / 3.0) ** (1 / 64))


def test_bad_tonemap_and_infinite_pixels():
    with pytest.raises(ValueError, match="tonemap"):
        io.to_srgb8(np.zeros((2, 2, 3)), 0.0, "filmic")
    img = np.zeros((2, 2, 3), np.float32)
    img[0, 0] = np.inf
    img[1, 1] = np.nan
    for curve in io.TONEMAPS:
        out = io.to_srgb8(img, 3.0, curve)
        assert out[0, 0].tolist() == [255, 255, 255]
        assert out[1, 1].tolist() == [0, 0, 0]


def test_cli_states_the_chosen_exposure_and_curve(tmp_path):
    from voxgi import cli

    small = ["--resolution", "8", "--frames", "2", "--width", "8", "--height", "6", "-q"]
    a, b = tmp_path / "a.exr", tmp_path / "b.exr"
    assert cli.main(["render", "furnace-box", "-o", str(a), *small]) == 0
    img = io.read_exr(a)
    meta = io.read_exr_header(a)
    assert meta["exposure"] == pytest.approx(io.auto_exposure(img), abs=1e-12)
    assert (meta["exposure_auto"], meta["tonemap"]) == (True, "reinhard")
    want = io.to_srgb8(img, meta["exposure"], "reinhard")
    np.testing.assert_array_equal(imread(a.with_suffix(".png")), want)
    argv = ["render", "furnace-box", "-o", str(b), "--exposure", "1.5", "--tonemap", "clip"]
    assert cli.main([*argv, *small]) == 0
    meta = io.read_exr_header(b)
    assert (meta["exposure"], meta["exposure_auto"], meta["tonemap"]) == (1.5, False, "clip")
    np.testing.assert_array_equal(
        imread(b.with_suffix(".png")), io.to_srgb8(io.read_exr(b), 1.5, "clip")
    )
