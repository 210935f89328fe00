"""``voxgi render`` and ``voxgi scenes``: outputs decided and checked before any work,
EXR + PNG with settings and timings, clear errors with exit code 2."""

from __future__ import annotations

import re

import numpy as np
import pytest

import voxgi
from voxgi import cli

EXR_MAGIC = b"\x76\x2f\x31\x01"
PNG_MAGIC = b"\x89PNG"
SMALL = [
    "--resolution",
    "12",
    "--radius",
    "4",
    "--frames",
    "2",
    "--width",
    "8",
    "--height",
    "8",
    "-q",
]


def test_render_builtin_scene_writes_exr_png_and_metadata(tmp_path, capsys):
    out = tmp_path / "f.exr"
    rc = cli.main(
        [
            "render",
            "furnace-sphere",
            "-o",
            str(out),
            "--resolution",
            "16",
            "--radius",
            "6",
            "--frames",
            "6",
            "--width",
            "12",
            "--height",
            "10",
            "-q",
        ]
    )
    assert rc == 0
    img = voxgi.io.read_exr(out)
    assert img.shape == (10, 12, 3)
    # furnace_sphere(): rho 0.5, Le 1 -> L = 2 everywhere; coarse voxels and 6
    # frames: within 5%.
    assert np.all(np.abs(img / 2.0 - 1.0) < 0.05)
    assert out.with_suffix(".png").read_bytes()[:4] == PNG_MAGIC
    meta = voxgi.io.read_exr_header(out)
    assert meta["scene"] == "furnace-sphere"
    assert meta["frames"] <= 6
    assert meta["interrupted"] is False
    assert meta["max_frames"] == 6
    assert {"voxelize", "solve", "total"} <= set(meta["seconds"])
    # the furnace's light is even: the budget of spread light, said and recorded
    assert (meta["vpls_per_frame"], meta["gather_per_frame"]) == (8, 25)
    assert meta["light_spread"] > 0.99
    text = capsys.readouterr().out
    for word in ("voxelize", "solve", "display", "wrote", "seconds"):
        assert word in text
    assert "traced passes of" in text  # the render pipeline's solve finishes with them
    assert "8 VPLs and 25 gather rays a pixel (light spread 1.00)" in text


def test_default_output_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["render", "furnace-box", *SMALL]) == 0
    assert (tmp_path / "furnace-box.exr").exists()
    assert (tmp_path / "furnace-box.png").exists()


def test_png_output_writes_the_exr_beside_it(tmp_path, capsys):
    out = tmp_path / "pic.png"
    assert cli.main(["render", "furnace-box", "-o", str(out), *SMALL]) == 0
    assert out.read_bytes()[:4] == PNG_MAGIC
    assert (tmp_path / "pic.exr").read_bytes()[:4] == EXR_MAGIC
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pic.exr", "pic.png"]
    assert f"wrote {tmp_path / 'pic.exr'} and {out}" in capsys.readouterr().out


def test_exposure_and_tol(tmp_path):
    a, b = tmp_path / "a.exr", tmp_path / "b.exr"
    assert cli.main(["render", "furnace-box", "-o", str(a), "--exposure", "0", *SMALL]) == 0
    assert (
        cli.main(
            ["render", "furnace-box", "-o", str(b), "--exposure", "-2", "--tol", "0.5", *SMALL]
        )
        == 0
    )
    np.testing.assert_array_equal(voxgi.io.read_exr(a), voxgi.io.read_exr(b))
    from skimage.io import imread

    assert imread(b.with_suffix(".png")).mean() < imread(a.with_suffix(".png")).mean()
    meta = voxgi.io.read_exr_header(b)
    assert meta["exposure"] == -2
    assert meta["tol"] == 0.5


@pytest.mark.parametrize(
    ("argv", "msg"),
    [
        (["render", "no-such-scene"], "unknown built-in scene 'no-such-scene'; known: bunny-room"),
        (["render", "missing.toml"], "scene file not found: missing.toml"),
        (
            ["render", "cornell-box", "-o", "out.jpg"],
            r"unsupported extension '.jpg'; use .exr or .png",
        ),
        (["render", "cornell-box", "-o", "out"], r"unsupported extension '\(none\)'"),
    ],
)
def test_errors_are_one_line_with_exit_code_2(argv, msg, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        cli.main(argv)
    assert exc.value.code == 2
    cap = capsys.readouterr()
    assert cap.out == ""  # no work started
    assert cap.err.count("\n") == 1
    assert "Traceback" not in cap.err
    assert re.search(msg, cap.err), cap.err
    assert list(tmp_path.iterdir()) == []


def test_bad_scene_file_is_one_line_with_exit_code_1(tmp_path, capsys):
    p = tmp_path / "s.toml"
    p.write_text("[[object]]\nmesh = 5\n")
    with pytest.raises(SystemExit) as exc:
        cli.main(["render", str(p), "-o", str(tmp_path / "o.exr")])
    assert re.fullmatch(
        r"voxgi render: error: .*s\.toml: object #0: 'mesh' must be a string.*", str(exc.value.code)
    )
    assert capsys.readouterr().out == ""
    assert sorted(x.name for x in tmp_path.iterdir()) == ["s.toml"]


@pytest.mark.parametrize(
    ("argv", "msg"),
    [
        (["render", "cornell-box", "--width", "0"], "--width: must be >= 1"),
        (["render", "cornell-box", "--height", "-2"], "--height: must be >= 1"),
        (["render", "cornell-box", "--tol", "nan"], "--tol: must be finite"),
        (["render", "cornell-box", "--exposure", "x"], "--exposure: expected a number"),
        (["render", "cornell-box", "-q", "-v"], "not allowed with argument"),
    ],
)
def test_bad_arguments_exit_2(argv, msg, capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(argv)
    assert exc.value.code == 2
    assert msg in capsys.readouterr().err


def test_unwritable_output_is_refused_before_any_work(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(SystemExit) as exc:
        cli.main(["render", "cornell-box", "-o", str(blocker / "out.exr"), *SMALL])
    assert exc.value.code == 2
    cap = capsys.readouterr()
    assert "cannot write" in cap.err
    assert str(blocker) in cap.err
    assert "Traceback" not in cap.err
    assert cap.out == ""
    (tmp_path / "dir.exr").mkdir()
    with pytest.raises(SystemExit) as exc:
        cli.main(["render", "cornell-box", "-o", str(tmp_path / "dir.exr"), *SMALL])
    assert exc.value.code == 2
    assert "is a folder" in capsys.readouterr().err


def test_unwritable_folder_exit_code_from_the_command(tmp_path):
    import os
    import subprocess
    import sys

    targets = [tmp_path / "file" / "out.exr"]
    (tmp_path / "file").write_text("not a folder")
    if os.geteuid() != 0:  # root writes into read-only folders
        ro = tmp_path / "ro"
        ro.mkdir(mode=0o500)
        targets.append(ro / "out.png")
    for out in targets:
        r = subprocess.run(
            [sys.executable, "-m", "voxgi.cli", "render", "cornell-box", "-o", str(out)],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert r.returncode == 2, r.stderr
        assert r.stdout == ""
        assert r.stderr.startswith(f"voxgi render: error: cannot write {out.with_suffix('.exr')}")
        assert r.stderr.count("\n") == 1


def test_diagnostics_only_with_verbose(tmp_path, capsys):
    out = str(tmp_path / "v.exr")
    assert cli.main(["render", "furnace-box", "-o", out, *SMALL]) == 0
    assert "skipped" not in capsys.readouterr().out
    assert cli.main(["render", "furnace-box", "-o", out, *SMALL[:-1], "-v"]) == 0
    assert "solve skipped" in capsys.readouterr().out


def test_version_and_scenes(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"voxgi {voxgi.__version__}"
    assert cli.main(["scenes"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split()[0] for ln in lines] == voxgi.scenes.names()
    assert all(len(ln.split(None, 1)) == 2 for ln in lines)  # each has a description
    assert any(ln.startswith("cornell-box") and "Cornell box" in ln for ln in lines)


def test_help_shows_the_defaults(capsys):
    with pytest.raises(SystemExit):
        cli.main(["render", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    from voxgi.radiosity.tuning import TRACED_RADIUS
    from voxgi.voxels import DEFAULT_RESOLUTION

    for want in (
        f"(default: the coarsest of 16, 32 and {DEFAULT_RESOLUTION} whose solution",
        f"(default: {TRACED_RADIUS})",
        "(default: 256)",
        "(default: 0.001)",
        "(default: the exposure that maps the image's log-average luminance",
        "(default: the scene camera's)",
        "(default: all hardware threads)",
        "(default: SCENE.exr in the current folder)",
    ):
        assert want in text, want
    assert "(default: None)" not in text


def test_read_only_output_exits_2_before_any_work(tmp_path, capsys):
    out = tmp_path / "out.exr"
    out.write_bytes(b"kept")
    out.chmod(0o444)
    with pytest.raises(SystemExit) as exc:
        cli.main(["render", "cornell-box", "-o", str(out), *SMALL])
    assert exc.value.code == 2
    cap = capsys.readouterr()
    assert cap.out == ""  # nothing voxelized or solved
    assert cap.err == f"voxgi render: error: cannot write {out}: the file is read-only\n"
    assert out.read_bytes() == b"kept"


def test_missing_output_folders_are_created(tmp_path, capsys):
    out = tmp_path / "new" / "deeper" / "img.png"
    assert cli.main(["render", "cornell-box", "-o", str(out), *SMALL]) == 0
    assert out.is_file()
    assert out.with_suffix(".exr").is_file()


def test_scene_without_camera_exits_1_with_how_to_give_one(tmp_path, capsys):
    (tmp_path / "mesh.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(SystemExit) as exc:
        cli.main(["render", str(tmp_path / "mesh.obj"), "-o", str(tmp_path / "o.exr")])
    assert re.fullmatch(
        r"voxgi render: error: scene file .*mesh\.obj: has no camera to render from .*"
        r"\[camera\] table .*",
        str(exc.value.code),
    )
    assert capsys.readouterr().out == ""


def test_search_path_and_allow_outside_widen_what_a_scene_reads(tmp_path, capsys):
    (tmp_path / "shared").mkdir()
    (tmp_path / "room").mkdir()
    (tmp_path / "shared" / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    scene = tmp_path / "room" / "scene.toml"
    scene.write_text(
        "[camera]\neye = [0.3, 0.3, 2]\ntarget = [0.3, 0.3, 0]\nwidth = 8\nheight = 8\n"
        '[[object]]\nmesh = "../shared/tri.obj"\nemission = 1.0\n'
    )
    argv = ["render", str(scene), "-o", str(tmp_path / "o.exr"), *SMALL]
    with pytest.raises(SystemExit) as exc:
        cli.main(argv)
    assert "outside the folders this scene may read" in str(exc.value.code)
    assert cli.main([*argv, "--search-path", str(tmp_path / "shared")]) == 0
    assert cli.main([*argv, "--allow-outside"]) == 0
