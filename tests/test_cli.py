"""``voxgi render``: writes EXR + PNG with settings and timings, clear errors."""

from __future__ import annotations

import numpy as np
import pytest

import voxgi
from voxgi import cli


def _run(argv):
    return cli.main(argv)


def test_render_builtin_scene_writes_exr_png_and_metadata(tmp_path, capsys):
    out = tmp_path / "f.exr"
    rc = _run(["render", "furnace-sphere", "-o", str(out), "--resolution", "16",
                       "--directions", "6", "--frames", "6", "--width", "12", "--height", "10",
                       "-q"])
    assert rc == 0
    img = voxgi.io.read_exr(out)
    assert img.shape == (10, 12, 3)
    # furnace_sphere(): rho 0.5, Le 1 -> L = 2 everywhere; coarse voxels and 6
    # frames: within 5%.
    assert np.all(np.abs(img / 2.0 - 1.0) < 0.05)
    assert out.with_suffix(".png").exists()
    meta = voxgi.io.read_exr_header(out)
    assert meta["scene"] == "furnace-sphere" and meta["frames"] <= 6
    assert {"voxelize", "solve", "total"} <= set(meta["seconds"])
    text = capsys.readouterr().out
    for word in ("voxelize", "solve", "display", "wrote", "seconds"):
        assert word in text


def test_default_output_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _run(["render", "furnace-box", "--resolution", "12", "--directions", "4",
                  "--frames", "2", "--width", "8", "--height", "8", "-q"])
    assert (tmp_path / "furnace-box.exr").exists() and (tmp_path / "furnace-box.png").exists()


@pytest.mark.parametrize(("argv", "msg"), [
    (["render", "no-such-scene"], "unknown built-in scene"),
    (["render", "cornell-box", "--width", "0"], "Camera.width"),
    (["render", "cornell-box", "--height", "-2"], "Camera.height"),
    (["render", "missing.toml"], "not found"),
])
def test_cli_errors_are_clear(argv, msg, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit, match=msg):
        cli.main(argv)
