"""voxgi compare: voxgi against Mitsuba 3 on one scene (voxgi.compare, docs/design.md §11)."""

from __future__ import annotations

import re
import sys

import numpy as np
import pytest

import voxgi
from voxgi import cli
from voxgi.compare import _seconds_to, compare


def test_seconds_to_an_error_interpolates_in_log_log():
    # errors 1e-2 at 1 s and 1e-3 at 10 s: 1/t scaling, so 1e-2.5 at 10^0.5 s
    sweep = [(1, 1.0, 1e-2), (2, 10.0, 1e-3)]
    assert _seconds_to(10**-2.5, sweep) == pytest.approx(10**0.5)
    assert _seconds_to(1e-4, sweep) is None  # never reached
    assert _seconds_to(0.1, sweep) == 1.0  # reached by the first render


def test_without_mitsuba_the_error_says_how_to_install(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "mitsuba", None)  # import mitsuba -> ImportError
    with pytest.raises(ImportError, match=r"voxgi\[bench\]"):
        compare(voxgi.scenes.sky_objects(8, 8), spp=4)
    with pytest.raises(SystemExit, match=r"voxgi compare: error: .*voxgi\[bench\]"):
        cli.main(["compare", "sky-objects", "--width", "8", "--height", "8", "-o", str(tmp_path)])


def test_compare_writes_both_images_and_prints_the_table(tmp_path, capsys):
    pytest.importorskip("mitsuba")
    code = cli.main(
        [
            *("compare", "sky-objects", "--width", "16", "--height", "16", "--spp", "64"),
            *("--resolution", "16", "-o", str(tmp_path)),
        ]
    )
    assert code == 0
    out = capsys.readouterr().out
    assert re.search(r"^voxgi\s+[\d.]+\s+[\d.e+-]+\s+\(", out, flags=re.MULTILINE), out
    assert "mitsuba to voxgi's relMSE" in out
    for name in ("voxgi.exr", "reference.exr", "difference.png"):
        assert (tmp_path / name).is_file()
    ref = voxgi.io.read_exr(tmp_path / "reference.exr")
    # the sky (radiance 1) fills the top rows of the picture in both renders
    np.testing.assert_allclose(ref[0], 1.0, rtol=1e-5)
    np.testing.assert_allclose(voxgi.io.read_exr(tmp_path / "voxgi.exr")[0], 1.0, rtol=1e-5)
