"""What the command line and the progress bars write: plain text, one line per
warning, and no bar where nobody watches (voxgi._progress)."""

from __future__ import annotations

import io
import math
import re

import pytest

from voxgi import _progress
from voxgi.cli import main

# A Mitsuba 3 scene with a BSDF that voxgi approximates (one SceneWarning),
# small enough to render in a fraction of a second.
_XML = """<scene version="3.0.0">
  <sensor type="perspective">
    <float name="fov" value="60"/>
    <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
  </sensor>
  <shape type="rectangle"><bsdf type="conductor"/></shape>
  <shape type="rectangle">
    <transform name="to_world"><translate value="0,0,2"/><rotate x="1" angle="180"/></transform>
    <emitter type="area"><rgb name="radiance" value="1,1,1"/></emitter>
  </shape>
</scene>
"""


class _Terminal(io.StringIO):
    """A stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


def test_scenes_are_listed_in_plain_text(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    for markup in ("`", ":func:", ":class:"):
        assert markup not in out
    # a scene named in another's description is named as `voxgi render` takes it
    (sun,) = [line for line in out.splitlines() if line.startswith("sun-room ")]
    assert "window-room" in sun


@pytest.mark.filterwarnings("default")
def test_a_warning_is_one_line_without_source(tmp_path, capsys):
    scene = tmp_path / "s.xml"
    scene.write_text(_XML)
    argv = ["render", str(scene), "-o", str(tmp_path / "o.exr"), "--resolution", "8"]
    assert main([*argv, "--frames", "2"]) == 0
    err = capsys.readouterr().err
    warned = [line for line in err.splitlines() if line.startswith("warning:")]
    assert warned == [
        f"warning: {scene}: approximated: bsdf 'conductor': its mirror reflection as a GGX lobe "
        "of alpha 0.02 (the display's reflections of other surfaces read their records)"
    ]
    for source in (".py:", "SceneWarning", "return cls"):
        assert source not in err


def test_a_bar_draws_on_a_terminal_and_not_elsewhere():
    tty, log = _Terminal(), io.StringIO()
    for stream in (tty, log):
        b = _progress.bar("work", 4, stream=stream)
        b.update(2)
        b.close()
    assert "work" in tty.getvalue()
    assert "\r" in tty.getvalue()
    assert log.getvalue() == ""
    off = _Terminal()
    b = _progress.bar("work", 4, stream=off, enabled=False)
    b.update(1)
    b.close()
    assert off.getvalue() == ""
    assert _progress.interactive(tty)
    assert not _progress.interactive(log)


def test_frames_needed_follows_one_over_n():
    # relMSE of a mean of n independent frames is sigma^2 / n: 8 frames at
    # 4 tol reach tol after 8 * 4 = 32 frames.
    assert _progress.frames_needed(8, 4e-3, 1e-3, floor=8, cap=256) == 32
    assert _progress.frames_needed(10, 1.5e-3, 1e-3, floor=8, cap=256) == 15
    # below tol: the frames done; capped; no estimate yet: the rule's floor
    assert _progress.frames_needed(9, 5e-4, 1e-3, floor=8, cap=256) == 9
    assert _progress.frames_needed(8, 1.0, 1e-3, floor=8, cap=256) == 256
    assert _progress.frames_needed(3, math.nan, 1e-3, floor=8, cap=256) == 8
    # without a tolerance every frame up to the cap runs
    assert _progress.frames_needed(3, math.nan, 0.0, floor=8, cap=64) == 64


def test_log_share_is_the_way_down_on_a_log_scale():
    # from 1e-1 to a target of 1e-4, 1e-2 is a third of the way
    assert _progress.log_share(1e-1, 1e-2, 1e-4) == pytest.approx(1 / 3)
    assert _progress.log_share(1e-1, 1e-1, 1e-4) == 0.0
    assert _progress.log_share(1e-1, 1e-5, 1e-4) == 1.0
    assert _progress.log_share(1e-1, math.nan, 1e-4) == 0.0


def test_no_bars_when_stderr_is_not_a_terminal(tmp_path, capsys):
    # capsys's stderr is not a terminal, as a file or a pipe is not: the
    # bars of the voxelization, the solve and the display write nothing.
    argv = ["render", "cornell-box", "-o", str(tmp_path / "c.exr"), "--resolution", "8"]
    assert main([*argv, "--frames", "2", "--width", "16", "--height", "16"]) == 0
    err = capsys.readouterr().err
    assert err == ""


def test_the_display_bar_counts_towards_the_frames_it_needs(monkeypatch):
    # On a terminal the display's bar shows "frames done/frames predicted";
    # the render stops at the rule's floor of 8 frames here (a coarse
    # Cornell box well under its tolerance), so the bar counts to 8 of 8
    # and never towards the cap of 256 frames.
    import voxgi

    tty = _Terminal()
    monkeypatch.setattr("sys.stderr", tty)
    scene = voxgi.scenes.cornell_box(width=32, height=32)
    vox = voxgi.voxelize(scene, resolution=16, progress=False)
    sol = voxgi.solve(vox, progress=False)
    res = voxgi.display.render(scene, sol, tol=0.5, max_frames=256, progress=True)
    drawn = [(int(n), int(m)) for n, m in re.findall(r"(\d+)/(\d+) \[", tty.getvalue())]
    assert drawn, tty.getvalue()
    assert drawn[-1] == (res.frames, res.frames)
    assert max(m for _, m in drawn) < 256
