"""EXR and PNG files."""

from __future__ import annotations

import numpy as np
import pytest

from voxgi import io


def test_exr_round_trip_is_exact_with_metadata(tmp_path, rng):
    img = (rng.random((7, 11, 3)) * 100).astype(np.float32)
    p = io.write_exr(tmp_path / "a.exr", img, metadata={"seconds": {"solve": 1.5}, "scene": "x"})
    back = io.read_exr(p)
    assert back.dtype == np.float32 and back.shape == (7, 11, 3)
    np.testing.assert_array_equal(back, img)
    assert io.read_exr_header(p) == {"seconds": {"solve": 1.5}, "scene": "x"}


def test_png_tone_mapping(tmp_path):
    img = np.zeros((2, 2, 3), np.float32)
    img[0, 0] = 1.0
    img[1, 1] = 0.5
    srgb = io.to_srgb8(img)
    assert srgb[0, 0, 0] == 255 and srgb[0, 1, 0] == 0
    assert srgb[1, 1, 0] == 188  # sRGB(0.5) = 0.7354 -> 188
    assert io.to_srgb8(img, exposure=1.0)[1, 1, 0] == 255
    from skimage.io import imread

    p = io.write_png(tmp_path / "a.png", img)
    np.testing.assert_array_equal(imread(p), srgb)


def test_bad_images(tmp_path):
    with pytest.raises(ValueError, match="shape"):
        io.write_exr(tmp_path / "x.exr", np.zeros((2, 2, 4)))
    with pytest.raises(TypeError, match="numeric"):
        io.write_png(tmp_path / "x.png", np.array([["a"]]))
    with pytest.raises(FileNotFoundError):
        io.read_exr(tmp_path / "missing.exr")
