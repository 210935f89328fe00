"""EXR and PNG files."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import fails_to_write

from voxgi import io


def test_exr_round_trip_is_exact_with_metadata(tmp_path, rng):
    img = (rng.random((7, 11, 3)) * 100).astype(np.float32)
    p = io.write_exr(tmp_path / "a.exr", img, metadata={"seconds": {"solve": 1.5}, "scene": "x"})
    back = io.read_exr(p)
    assert back.dtype == np.float32
    assert back.shape == (7, 11, 3)
    np.testing.assert_array_equal(back, img)
    assert io.read_exr_header(p) == {"seconds": {"solve": 1.5}, "scene": "x"}


def test_png_tone_mapping(tmp_path):
    img = np.zeros((2, 2, 3), np.float32)
    img[0, 0] = 1.0
    img[1, 1] = 0.5
    srgb = io.to_srgb8(img)
    assert srgb[0, 0, 0] == 255
    assert srgb[0, 1, 0] == 0
    assert srgb[1, 1, 0] == 188  # sRGB(0.5) = 0.7354 -> 188
    assert io.to_srgb8(img, exposure=1.0)[1, 1, 0] == 255
    from skimage.io import imread

    p = io.write_png(tmp_path / "a.png", img, exposure=0.0, tonemap="clip")
    np.testing.assert_array_equal(imread(p), srgb)


def test_bad_images(tmp_path):
    with pytest.raises(ValueError, match="shape"):
        io.write_exr(tmp_path / "x.exr", np.zeros((2, 2, 4)))
    with pytest.raises(TypeError, match="numeric"):
        io.write_png(tmp_path / "x.png", np.array([["a"]]))
    with pytest.raises(FileNotFoundError):
        io.read_exr(tmp_path / "missing.exr")


# A write that fails part-way (here: the file-size limit RLIMIT_FSIZE of a
# forked child, with SIGXFSZ ignored so the write returns EFBIG instead of
# killing the process)
# must leave the earlier file whole and no temporary file behind.
@pytest.mark.parametrize("kind", ["exr", "png"])
def test_failed_write_keeps_the_earlier_file(tmp_path, kind):
    path = tmp_path / f"a.{kind}"
    small = np.full((4, 5, 3), 0.25, np.float32)
    write = getattr(io, f"write_{kind}")
    write(path, small)
    before = path.read_bytes()
    big = np.random.default_rng(0).random((256, 256, 3)).astype(np.float32)  # incompressible
    assert "refused:" in fails_to_write(write, path, big, fsize=20000)
    assert path.read_bytes() == before
    if kind == "exr":
        np.testing.assert_array_equal(io.read_exr(path), small)
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]


def test_atomic_path_removes_the_temporary_file_on_error(tmp_path):
    target = tmp_path / "keep.txt"
    target.write_text("old")
    target.chmod(0o640)
    seen = []

    def interrupted_write():
        with io.atomic_path(target) as tmp:
            seen.append(tmp)
            tmp.write_text("half")
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        interrupted_write()
    assert seen[0].parent == tmp_path
    assert seen[0].suffix == ".txt"
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["keep.txt"]
    with io.atomic_path(target) as tmp:
        tmp.write_text("new")
    assert target.read_text() == "new"
    assert [p.name for p in tmp_path.iterdir()] == ["keep.txt"]
    assert target.stat().st_mode & 0o777 == 0o640  # the replaced file's permissions


def test_write_into_a_folder_name_is_refused(tmp_path):
    with pytest.raises(IsADirectoryError, match="folder"):
        io.write_exr(tmp_path, np.zeros((2, 2, 3)))


def test_a_symbolic_link_is_kept_and_its_target_replaced(tmp_path):
    real = io.write_exr(tmp_path / "real.exr", np.zeros((2, 2, 3)))
    link = tmp_path / "link.exr"
    link.symlink_to(real)
    io.write_exr(link, np.ones((2, 2, 3)))
    assert link.is_symlink()
    np.testing.assert_array_equal(io.read_exr(real), np.ones((2, 2, 3), np.float32))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.exr", "real.exr"]


def test_atomic_path_refuses_a_read_only_file_and_flushes_before_chmod(tmp_path):
    target = tmp_path / "kept.txt"
    target.write_text("old")
    target.chmod(0o444)
    with pytest.raises(PermissionError, match="read-only"), io.atomic_path(target) as tmp:
        tmp.write_text("new")  # (never reached)
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.txt"]
    # a mode without the owner's write bit on a writable file is still copied
    target.chmod(0o640)
    with io.atomic_path(target) as tmp:
        tmp.write_text("new")
    assert target.read_text() == "new"
    assert target.stat().st_mode & 0o777 == 0o640


def test_read_npz_checks_headers_before_data(tmp_path):
    path = tmp_path / "a.npz"
    np.savez(path, ijk=np.zeros((5, 3), np.int32), v=np.zeros(5, np.float32))
    want = {"ijk": (("n", 3), np.int32), "v": (("n",), np.float32)}
    got = io.read_npz(path, want)
    assert got["ijk"].shape == (5, 3)
    assert got["v"].dtype == np.float32
    with pytest.raises(ValueError, match=r"a\.npz: v must be float64 of shape \(5,\) for 5"):
        io.read_npz(path, {**want, "v": (("n",), np.float64)})
    np.savez(path, ijk=np.zeros((5, 3), np.int32), v=np.zeros(4, np.float32))
    with pytest.raises(ValueError, match=r"v must be float32 of shape \(5,\) for 5 records, got"):
        io.read_npz(path, want)
    (tmp_path / "b.npz").write_text("no zip")
    with pytest.raises(ValueError, match=r"not a \.npz file"):
        io.read_npz(tmp_path / "b.npz", want)
