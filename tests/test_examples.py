"""The examples are gallery scripts that say what they compute, and say it right."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = sorted((Path(__file__).resolve().parent.parent / "examples").glob("*.py"))


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_is_a_gallery_script(path):
    tree = ast.parse(path.read_text())
    doc = ast.get_docstring(tree)
    assert doc, "a docstring with a title"
    title, underline = doc.splitlines()[:2]
    assert title
    assert set(underline) == {"="}
    assert f"python examples/{path.name}" in doc  # how to run it
    # it prints what it computes
    assert any(
        isinstance(n, ast.Call) and getattr(n.func, "id", "") == "print" for n in ast.walk(tree)
    )


@pytest.mark.slow
def test_furnace_check_prints_the_furnace_answer(tmp_path):
    # Every record of a furnace has radiance Le / (1 - rho) (docs/design.md §1);
    # the example prints its records' errors, which at resolution 32 and R 8
    # stay within 1% mean and 3% max (docs/performance.md, furnaces).
    res = subprocess.run(
        [sys.executable, str(EXAMPLES[0].parent / "furnace_check.py")],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        check=True,
    )
    found = re.findall(r"error ([\d.]+)% mean, ([\d.]+)% max", res.stdout)
    assert len(found) == 2, res.stdout
    for mean, worst in found:
        assert float(mean) < 1.0
        assert float(worst) < 3.0
