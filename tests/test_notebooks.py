"""The notebooks run top to bottom and the numbers they compute are right.

Each notebook leaves its key numbers in a dict ``summary``; an extra cell
prints it as JSON, and the checks below hold it to bounds known from the
method (small sizes; VOXGI_FULL=1 runs the full-size studies).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

NOTEBOOKS = sorted((Path(__file__).parent.parent / "notebooks").glob("*.ipynb"))


def check_voxel_resolution(s: dict) -> None:
    # Furnace sphere, rho 0.8: radiance Le / (1 - rho) on every record. At
    # resolution 12-24 and R 4 the lost fraction is a few 1e-3, which
    # rho / (1 - rho) = 4 turns into about 1% (docs/design.md §10).
    assert len(s["furnace"]) >= 3
    for r in s["furnace"]:
        assert r["records"] > 0
        assert r["mean_err"] < 0.012, r
        assert r["max_err"] < 0.05, r
    # The finest setting of the sweep refines the coarser ones.
    assert s["furnace"][-1]["mean_err"] < s["furnace"][0]["mean_err"]
    cornell = s["cornell"]
    assert cornell[-1]["rel_diff"] == 0.0  # the reference itself
    for r in cornell[:-1]:
        assert 0.0 < r["rel_diff"] < 0.1, r


def check_direction_counts(s: dict) -> None:
    # Cap sphere, rho 0.8: L = Le(x) + rho mean(Le) / (1 - rho) exactly.
    cap = s["cap"]
    assert [r["directions"] for r in cap] == sorted(r["directions"] for r in cap)
    for r in cap:
        assert r["mean_err"] < 0.035, r
        assert r["max_err"] < 0.1, r
    # Coarser later bounces: sorted by radius, and close to the full solve
    # (they change only the smooth later light).
    later = s["later"]
    assert [r["later_R"] for r in later] == sorted(r["later_R"] for r in later)
    full = later[-1]["mean_err"]
    for r in later:
        assert abs(r["mean_err"] - full) < 0.005, r
    for r in s["cornell"]:
        assert 0.0 < r["rel_diff"] < 0.15, r


def check_display_error(s: dict) -> None:
    # The render's own estimate of its noise against the error measured
    # against a long render of the same solution. At the notebook's small
    # size (64x64, resolution 16) most pixels lie on edges, whose stratified
    # sub-pixel offsets make the mean converge faster than the spread between
    # batches says: there the estimate errs on the safe side (measured 2.4x
    # over; within 1.5x at 256x256, docs/performance.md). It must never fall
    # well under the measured error, the failure that matters.
    c = s["cornell"]
    assert c["frames"] >= 8  # the stopping rule's floor
    assert 0.67 < c["est"] / c["measured"] < 4.0, c
    assert c["est_worst"] > 0.0


CHECKS = {
    "voxel_resolution": check_voxel_resolution,
    "direction_counts": check_direction_counts,
    "display_error": check_display_error,
}


def run_notebook(path: Path, cwd: Path) -> tuple[nbformat.NotebookNode, dict]:
    nb = nbformat.read(path, as_version=4)
    nb.cells.append(nbformat.v4.new_code_cell("import json\nprint('SUMMARY', json.dumps(summary))"))
    client = nbclient.NotebookClient(
        nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(cwd)}}
    )
    client.execute()
    text = nb.cells[-1].outputs[0]["text"]
    return nb, json.loads(text.split("SUMMARY", 1)[1])


#: run by default; the others run with the long tests (``-m slow``). What they
#: measure is held to closed forms by the default tests too: the cap sphere
#: and the coarser later bounces in tests/test_radiosity.py and
#: tests/test_display.py, the display's error estimate in tests/test_display_error.py
DEFAULT_NOTEBOOK = "voxel_resolution"


@pytest.mark.parametrize(
    "path",
    [
        pytest.param(p, marks=() if p.stem == DEFAULT_NOTEBOOK else pytest.mark.slow)
        for p in NOTEBOOKS
    ],
    ids=[p.stem for p in NOTEBOOKS],
)
def test_notebook(path, tmp_path, monkeypatch):
    monkeypatch.setenv("VOXGI_FULL", os.environ.get("VOXGI_FULL", "0"))
    nb, summary = run_notebook(path, tmp_path)
    CHECKS[path.stem](summary)
    # the plots are inline
    images = [
        o
        for c in nb.cells
        if c.cell_type == "code"
        for o in c.get("outputs", [])
        if "image/png" in o.get("data", {})
    ]
    assert images


def test_every_notebook_is_checked():
    assert {p.stem for p in NOTEBOOKS} == set(CHECKS)
    assert DEFAULT_NOTEBOOK in CHECKS


def test_checks_catch_wrong_numbers():
    # A notebook whose exact answer or solve went wrong (here: a furnace off
    # by 25%, an unsorted later-bounce panel) fails its check.
    furnace = [dict(res=r, records=1000, mean_err=0.25, max_err=0.3) for r in (12, 16, 24)]
    cornell = [dict(res=8, records=10, rel_diff=0.1), dict(res=16, records=20, rel_diff=0.0)]
    with pytest.raises(AssertionError):
        check_voxel_resolution({"furnace": furnace, "cornell": cornell})
    cap = [dict(R=3, directions=100, mean_err=0.01, max_err=0.1)]
    later = [
        dict(later_R=6, seconds=1.0, mean_err=0.01),
        dict(later_R=3, seconds=0.5, mean_err=0.01),
    ]
    with pytest.raises(AssertionError):
        check_direction_counts({"cap": cap, "later": later, "cornell": []})
    # an estimate 3x too small (the spread between frames where frames are correlated)
    with pytest.raises(AssertionError):
        check_display_error({"cornell": dict(frames=16, est=1e-4, measured=3e-4, est_worst=0.1)})
