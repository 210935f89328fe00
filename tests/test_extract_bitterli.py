"""scripts/extract_bitterli.py: a mesh the snapshot lacks, filled in from a
second mirror's PLY only where that mirror's copy of a mesh the scene has
is identical to it."""

import importlib.util
import subprocess
from pathlib import Path

import numpy as np
import pytest
import trimesh

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "extract_bitterli.py"


@pytest.fixture(scope="module")
def extract():
    spec = importlib.util.spec_from_file_location("extract_bitterli", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _mesh(shift: float) -> trimesh.Trimesh:
    m = trimesh.creation.icosphere(subdivisions=1)
    m.apply_translation((shift, 0.0, 0.0))
    uv = np.random.default_rng(int(shift * 10)).random((len(m.vertices), 2))
    m.visual = trimesh.visual.TextureVisuals(uv=uv)
    return m


def _mirror(root: Path, files: dict) -> Path:
    repo = root / "mirrors" / "gonsolo+bitterli" / "repo"
    repo.mkdir(parents=True)
    for path, mesh in files.items():
        (repo / path).parent.mkdir(parents=True, exist_ok=True)
        (repo / path).write_bytes(trimesh.exchange.ply.export_ply(mesh, encoding="binary"))
    git = ["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run([*git, "init", "-q"], check=True)
    subprocess.run([*git, "add", "."], check=True)
    subprocess.run([*git, "commit", "-qm", "meshes"], check=True)
    return root / "mirrors"


def test_a_missing_mesh_is_written_vertex_for_vertex_from_a_matching_source(extract, tmp_path):
    own, lacking = _mesh(0.0), _mesh(2.0)
    models = "room/pbrt/models"
    mirrors = _mirror(tmp_path, {f"{models}/Mesh001.ply": own, f"{models}/Mesh002.ply": lacking})
    scene = tmp_path / "room"
    (scene / "models").mkdir(parents=True)
    extract._write_obj(
        extract._read_ply(
            (mirrors / "gonsolo+bitterli/repo" / models / "Mesh001.ply").read_bytes()
        ),
        scene / "models/Mesh001.obj",
    )
    notes = extract.fill_meshes(scene, ["models/Mesh002.obj"], mirrors)
    assert any("1 meshes" in n for n in notes), notes
    v, uv, n, f = extract._read_obj(scene / "models/Mesh002.obj")
    assert np.allclose(v, lacking.vertices, atol=1e-6)
    assert np.array_equal(f, lacking.faces)
    assert np.allclose(uv, lacking.visual.uv, atol=1e-6)
    assert np.allclose(n, lacking.vertex_normals, atol=1e-6)


def test_a_source_whose_copy_of_a_present_mesh_differs_is_not_used(extract, tmp_path):
    models = "room/pbrt/models"
    mirrors = _mirror(
        tmp_path, {f"{models}/Mesh001.ply": _mesh(0.0), f"{models}/Mesh002.ply": _mesh(2.0)}
    )
    scene = tmp_path / "room"
    (scene / "models").mkdir(parents=True)
    moved = _mesh(0.0)
    moved.apply_translation((0.0, 0.01, 0.0))  # the scene's own mesh is not the source's
    extract._write_obj(
        extract._read_ply(trimesh.exchange.ply.export_ply(moved, encoding="binary")),
        scene / "models/Mesh001.obj",
    )
    notes = extract.fill_meshes(scene, ["models/Mesh002.obj"], mirrors)
    assert any("not used, it differs on models/Mesh001.obj" in n for n in notes), notes
    assert not (scene / "models/Mesh002.obj").exists()


def test_vertices_no_triangle_uses_do_not_make_two_meshes_differ(extract):
    # Bitterli's OBJs keep a few vertices that no triangle uses, which the
    # PLY export drops: the triangles are the same
    m = _mesh(0.0)
    ply = extract._read_ply(trimesh.exchange.ply.export_ply(m, encoding="binary"))
    v, uv, n, f = ply
    padded = (np.vstack([v, [[9.0, 9.0, 9.0]]]), np.vstack([uv, [[0.5, 0.5]]]), n, f)
    assert extract._same_mesh(padded, ply)
    moved = (v + np.array([0.0, 1e-3, 0.0]), uv, n, f)
    assert not extract._same_mesh(moved, ply)
