"""``Solution.save`` / ``Solution.load``: atomic writes and clear errors for bad files."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest
from conftest import fails_to_write

import voxgi
from voxgi import Solution


@pytest.fixture(scope="module")
def sol():
    vox = voxgi.voxelize(voxgi.scenes.furnace_box(), resolution=6)
    b = np.linspace(0.5, 2.0, 3 * len(vox), dtype=np.float32).reshape(-1, 3)
    return Solution(vox=vox, radiosity=b, bounces=3, residuals=[0.1, 0.01, 0.001])


def test_round_trip(tmp_path, sol):
    p = sol.save(tmp_path / "s.npz")
    back = Solution.load(p)
    np.testing.assert_array_equal(back.radiosity, sol.radiosity)
    np.testing.assert_array_equal(back.vox.centroid, sol.vox.centroid)
    assert back.bounces == 3
    assert [p.name for p in tmp_path.iterdir()] == ["s.npz"]


def test_the_base_split_round_trips_and_is_checked(tmp_path, sol):
    split = Solution(vox=sol.vox, radiosity=sol.radiosity, base_radiosity=0.5 * sol.radiosity)
    p = split.save(tmp_path / "split.npz")
    np.testing.assert_array_equal(Solution.load(p).base_radiosity, split.base_radiosity)
    assert Solution.load(sol.save(tmp_path / "plain.npz")).base_radiosity is None
    bad = split.base_radiosity.copy()
    bad[3, 1] = -1.0
    _rewrite(p, tmp_path / "bad.npz", base_radiosity=bad)
    with pytest.raises(ValueError, match=r"base_radiosity of record 3 is \[.*-1\.0.*expected"):
        Solution.load(tmp_path / "bad.npz")
    _rewrite(p, tmp_path / "short.npz", base_radiosity=bad[:-1])
    with pytest.raises(ValueError, match="base_radiosity"):
        Solution.load(tmp_path / "short.npz")


def test_empty_file(tmp_path):
    p = tmp_path / "empty.npz"
    p.write_bytes(b"")
    with pytest.raises(ValueError, match=r"empty\.npz.*empty file"):
        Solution.load(p)


def test_flipped_bytes_give_a_value_error(tmp_path, sol):
    good = sol.save(tmp_path / "s.npz").read_bytes()
    # every member's compressed data, flipped in its middle (a CRC or deflate error)
    with zipfile.ZipFile(tmp_path / "s.npz") as z:
        infos = z.infolist()
    bad = tmp_path / "bad.npz"
    for info in infos:
        data = bytearray(good)
        start = info.header_offset + 30 + len(info.filename.encode()) + 4
        at = start + info.compress_size // 2
        data[at] ^= 0x5A
        bad.write_bytes(bytes(data))
        with pytest.raises(ValueError, match="not a readable voxgi solution file"):
            Solution.load(bad)


def _rewrite(src, dst, **changes):
    with np.load(src) as z:
        arrays = {k: z[k] for k in z.files}
    arrays.update(changes)
    np.savez_compressed(dst, **arrays)


@pytest.mark.parametrize(
    ("key", "fix", "match"),
    [
        ("vox_centroid", lambda a: a[:-1], "vox_centroid must be float64 of shape"),
        ("vox_normal", lambda a: a[:-2], "vox_normal must be float32 of shape"),
        ("vox_area", lambda a: a.astype(np.float64), "vox_area must be float32"),
        ("vox_ijk", lambda a: a.astype(np.float32), "vox_ijk must be int32"),
        ("vox_back", lambda a: a[:, None], "vox_back must be bool"),
        ("vox_origin", lambda a: a[:2], "vox_origin"),
        ("radiosity", lambda a: a[:-1], "radiosity must be floats of shape"),
        ("radiosity", lambda a: a * np.inf, "not finite"),
        ("vox_normal", lambda a: a * np.nan, "non-finite"),
    ],
)
def test_arrays_are_checked_against_the_record_count(tmp_path, sol, key, fix, match):
    good = sol.save(tmp_path / "s.npz")
    with np.load(good) as z:
        arr = z[key]
    _rewrite(good, tmp_path / "bad.npz", **{key: fix(arr)})
    with pytest.raises(ValueError, match=match):
        Solution.load(tmp_path / "bad.npz")


def test_failed_save_keeps_the_earlier_file(tmp_path, sol):
    path = sol.save(tmp_path / "s.npz")
    before = path.read_bytes()
    vox = voxgi.voxelize(voxgi.scenes.furnace_box(), resolution=40)
    rad = np.random.default_rng(0).random((len(vox), 3)).astype(np.float32)
    big = voxgi.Solution(vox=vox, radiosity=rad)
    assert "refused:" in fails_to_write(big.save, path, fsize=len(before) + 100)
    assert path.read_bytes() == before
    np.testing.assert_array_equal(Solution.load(path).radiosity, sol.radiosity)
    assert [p.name for p in tmp_path.iterdir()] == ["s.npz"]
