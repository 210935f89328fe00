"""docs/performance.md is what scripts/make_performance.py makes of the benchmark JSON."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_performance_page_matches_the_json():
    # The page is generated: an edit by hand, or a JSON re-run without
    # regenerating the page, makes it differ from the script's output.
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
    assert found == list(range(1, 14))


def test_readme_starts_with_the_two_commands():
    blocks = re.findall(r"```bash\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.DOTALL)
    assert [b.strip() for b in blocks[:2]] == [
        "python -m pip install . && voxgi render cornell-box -o cornell-box.exr",
        'python -m pip install ".[test]" && python -m pytest -q',
    ]
