"""The repository's style checks: ruff (lint and format) over the Python,
clang-format over the C++. They run with the tests so that a change that
breaks them fails CI; each skips where its tool is not installed."""

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run(tool: str, *args: str) -> None:
    exe = shutil.which(tool)
    if exe is None:
        pytest.skip(f"{tool} is not installed (pip install '.[test]')")
    r = subprocess.run([exe, *args], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, f"{tool} {' '.join(args)}:\n{r.stdout}{r.stderr}"


def test_ruff_lint():
    _run("ruff", "check", ".")


def test_ruff_format():
    _run("ruff", "format", "--check", ".")


def test_clang_format():
    sources = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "csrc").rglob("*.[ch]*"))
    _run("clang-format", "--dry-run", "--Werror", *sources)
