"""The documents say what the code does: docs/performance.md and the README's figures are
what scripts/make_performance.py makes of the benchmark JSON, and the README's command
line, defaults and picture are those of the code."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def test_performance_page_and_readme_figures_match_the_json():
    # Both are generated: an edit by hand, or a JSON re-run without
    # regenerating them, makes them differ from the script's output.
    res = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "make_performance.py"), "--check"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert res.returncode == 0, res.stdout + res.stderr


def test_design_sections_are_the_ones_the_code_cites():
    text = (ROOT / "docs" / "design.md").read_text()
    found = [int(n) for n in re.findall(r"^## §(\d+) ", text, flags=re.MULTILINE)]
    assert found == list(range(1, 16))


def test_readme_starts_with_the_two_commands():
    blocks = re.findall(r"```bash\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.DOTALL)
    assert [b.strip() for b in blocks[:2]] == [
        "python -m pip install . && voxgi render cornell-box -o cornell-box.exr",
        'python -m pip install ".[test]" && python -m pytest -q',
    ]


def _readme() -> str:
    return (ROOT / "README.md").read_text()


def test_readme_is_short():
    assert len(_readme().splitlines()) < 200


def _render_parser():
    from voxgi.cli import build_parser

    sub = next(a for a in build_parser()._actions if a.dest == "command")
    return sub.choices["render"]


def test_readme_command_line_defaults_are_the_parsers():
    # Each "`--option` (default X)" of the README's command-line paragraph is
    # the render parser's own default for that option.
    found = re.findall(r"`(--[a-z-]+)` \(default ([^)]+)\)", _readme())
    assert len(found) >= 3
    options = {o: a for a in _render_parser()._actions for o in a.option_strings}
    for option, text in found:
        default = options[option].default
        assert float(text) == pytest.approx(default, rel=0), (option, text, default)


def test_readme_usage_names_real_options():
    usage = re.search(r"```\n(voxgi render .*?)```", _readme(), flags=re.DOTALL).group(1)
    first = usage.split("voxgi compare")[0]
    options = {o for a in _render_parser()._actions for o in a.option_strings}
    named = set(re.findall(r"(--?[a-z][a-z-]*)", first))
    assert named <= options, named - options


def test_hero_picture_is_what_the_render_command_writes():
    # The picture above the render command is its output: the built-in Cornell
    # box's camera size, as the caption says.
    import voxgi

    alt = re.search(r"!\[([^\]]*)\]\(docs/cornell_box\.png\)", _readme()).group(1)
    assert "`voxgi render cornell-box`" in alt
    w, h = (int(v) for v in re.search(r"(\d+)x(\d+)", alt).groups())
    cam = voxgi.scenes.cornell_box().camera
    assert (w, h) == (cam.width, cam.height)
    assert _png_size(ROOT / "docs" / "cornell_box.png") == (h, w)


def _png_size(path: Path) -> tuple[int, int]:
    """(height, width) from a PNG's IHDR chunk."""
    head = path.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n"
    return int.from_bytes(head[20:24], "big"), int.from_bytes(head[16:20], "big")


def _documented_parameters(doc: str) -> set[str]:
    """Names in a numpydoc Parameters section (``a, b : int`` names two)."""
    part = re.search(
        r"\n\s*Parameters\n\s*-+\n(.*?)(?:\n\s*\n\s*[A-Z][a-z]+\n\s*-+\n|\Z)", doc, re.S
    )
    if part is None:
        return set()
    names = set()
    for line in part.group(1).splitlines():
        if line.strip() and not line[0].isspace():  # a name line, not a description
            head = line.split(" : ")[0].strip()
            names |= {n.strip() for n in head.split(",")}
    return names


@pytest.mark.parametrize("module", ["voxgi", "voxgi.scenes", "voxgi.metrics"])
def test_public_functions_document_every_parameter(module):
    # help() on a public function explains each of its arguments (numpydoc).
    import importlib
    import inspect

    mod = importlib.import_module(module)
    for name in mod.__all__:
        fn = getattr(mod, name)
        if not inspect.isfunction(fn):
            continue
        params = {
            ("**" if p.kind is p.VAR_KEYWORD else "") + p.name
            for p in inspect.signature(fn).parameters.values()
        }
        assert params <= _documented_parameters(inspect.getdoc(fn) or ""), (name, params)


@pytest.mark.parametrize("name", ["voxelize", "solve", "render"])
def test_readme_api_rows_are_the_signatures(name):
    # The README's API table writes each stage's signature out in full.
    import inspect

    import voxgi

    parts, starred = [], False
    for p in inspect.signature(getattr(voxgi, name)).parameters.values():
        if p.kind is p.KEYWORD_ONLY and not starred:
            parts.append("*")
            starred = True
        parts.append(p.name if p.default is p.empty else f"{p.name}={p.default!r}")
    assert f"`voxgi.{name}({', '.join(parts)})`" in _readme()


def test_ci_runs_the_readme_test_command():
    # CI runs exactly what the README tells a newcomer to run, in a fresh venv.
    blocks = re.findall(r"```bash\n(.*?)```", _readme(), flags=re.DOTALL)
    ci = (ROOT / ".ci" / "run").read_text().splitlines()
    assert blocks[1].strip() in ci
    assert any(line.startswith("python3 -m venv") for line in ci)
