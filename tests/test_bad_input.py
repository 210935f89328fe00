"""Bad input at every public entry point: a clear ValueError/TypeError naming
what was wrong, never a crash, never a silently wrong answer.

Each test feeds one kind of bad argument and checks the exception type and a
word of the message (which field, which mesh, which line). The C++ bindings
are also called directly with wrong dtypes, shapes, non-contiguous arrays and
out-of-range indices: they must raise, not read out of bounds.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from conftest import paper

import voxgi
from voxgi import _core
from voxgi.display.settings import _Experiment

NAN, INF = float("nan"), float("inf")


@pytest.fixture(scope="module")
def small():
    """A furnace box (albedo 0.5, Le 1) voxelized and solved cheaply."""
    s = voxgi.scenes.furnace_box(albedo=0.5, emission=1.0)
    s.camera = s.camera.replace(width=8, height=8)
    vox = voxgi.voxelize(s, resolution=8, progress=False)
    sol = voxgi.solve(vox, radius=4, tuning=paper(shoot_radius=4), progress=False)
    return s, vox, sol


# ----------------------------------------------------------------- Material
@pytest.mark.parametrize(
    ("kw", "exc", "word"),
    [
        ({"albedo": NAN}, ValueError, "albedo"),
        ({"albedo": (0.5, INF, 0.5)}, ValueError, "albedo"),
        ({"albedo": 1.0}, ValueError, "albedo"),  # albedo must be < 1
        ({"albedo": -0.1}, ValueError, "albedo"),
        ({"albedo": (0.5, 0.5)}, ValueError, "albedo"),
        ({"albedo": "red"}, TypeError, "albedo"),
        ({"albedo": True}, TypeError, "albedo"),
        ({"albedo": None}, TypeError, "albedo"),
        ({"emission": -1.0}, ValueError, "emission"),
        ({"emission": (1, 1, NAN)}, ValueError, "emission"),
        ({"emission": [[1, 1, 1]]}, ValueError, "emission"),
        ({"specular": 0.5}, TypeError, "specular"),
    ],
)
def test_material_bad(kw, exc, word):
    with pytest.raises(exc, match=word):
        voxgi.Material(**kw)


@pytest.mark.parametrize(
    ("kw", "exc", "word"),
    [
        ({"rs": 1.5}, ValueError, "rs"),
        ({"rs": (NAN, 0, 0)}, ValueError, "rs"),
        ({"nu": 0.0}, ValueError, "nu"),
        ({"nu": INF}, ValueError, "nu"),
        ({"nv": -3.0}, ValueError, "nv"),
        ({"nv": "10"}, TypeError, "nv"),
    ],
)
def test_ashikhmin_shirley_bad(kw, exc, word):
    with pytest.raises(exc, match=word):
        voxgi.AshikhminShirley(**kw)


# ----------------------------------------------------------------- Camera
@pytest.mark.parametrize(
    ("kw", "exc", "word"),
    [
        ({"eye": (0, 0, NAN)}, ValueError, "eye"),
        ({"target": (INF, 0, 0)}, ValueError, "target"),
        ({"up": (0, NAN, 0)}, ValueError, "up"),
        ({"eye": (0, 0)}, ValueError, "eye"),
        ({"eye": "origin"}, TypeError, "eye"),
        ({"eye": (0, 0, 0), "target": (0, 0, 0)}, ValueError, "coincide"),
        ({"up": (0, 0, 1)}, ValueError, "up"),  # parallel to the view direction
        ({"up": (0, 0, 0)}, ValueError, "up"),
        ({"fov": 0.0}, ValueError, "fov"),
        ({"fov": 180.0}, ValueError, "fov"),
        ({"fov": NAN}, ValueError, "fov"),
        ({"width": 0}, ValueError, "width"),
        ({"width": 64.0}, TypeError, "width"),
        ({"height": 1 << 20}, ValueError, "height"),
        ({"aperture": -1.0}, ValueError, "aperture"),
        ({"aperture": INF}, ValueError, "aperture"),
        ({"focus_distance": 0.0}, ValueError, "focus_distance"),
    ],
)
def test_camera_bad(kw, exc, word):
    with pytest.raises(exc, match=word):
        voxgi.Camera(**kw)


# ----------------------------------------------------------------- Scene.add
def _tri(v, f=((0, 1, 2),)):
    return trimesh.Trimesh(np.asarray(v, float), np.asarray(f), process=False)


def test_scene_add_nan_vertex_names_mesh_and_vertex():
    with pytest.raises(ValueError, match=r"'bad'.*vertex 1"):
        voxgi.Scene().add(_tri([(0, 0, 0), (1, NAN, 0), (0, 1, 0)]), name="bad")


def test_scene_add_inf_vertex():
    with pytest.raises(ValueError, match="not finite"):
        voxgi.Scene().add(_tri([(0, 0, 0), (INF, 0, 0), (0, 1, 0)]))


@pytest.mark.parametrize(
    ("mesh", "exc", "word"),
    [
        ("box.obj", TypeError, "trimesh"),
        (np.zeros((3, 3)), TypeError, "trimesh"),
        (None, TypeError, "trimesh"),
    ],
)
def test_scene_add_not_a_mesh(mesh, exc, word):
    with pytest.raises(exc, match=word):
        voxgi.Scene().add(mesh)


def test_scene_add_face_index_out_of_range():
    m = _tri([(0, 0, 0), (1, 0, 0), (0, 1, 0)])
    m.faces = np.array([[0, 1, 7]])  # trimesh keeps it when process=False
    with pytest.raises(ValueError, match="out of range"):
        voxgi.Scene().add(m, name="oob")


def test_scene_add_all_degenerate():
    with (
        pytest.raises(ValueError, match="degenerate"),
        pytest.warns(UserWarning, match="degenerate"),
    ):
        voxgi.Scene().add(_tri([(0, 0, 0), (1, 0, 0), (2, 0, 0)]))


@pytest.mark.parametrize(
    ("kw", "exc", "word"),
    [
        ({"material": "white"}, TypeError, "material"),
        ({"name": 3}, TypeError, "name"),
        ({"two_sided": "yes"}, TypeError, "two_sided"),
    ],
)
def test_scene_add_bad_args(kw, exc, word):
    with pytest.raises(exc, match=word):
        voxgi.Scene().add(trimesh.creation.box(), **kw)


def test_scene_camera_wrong_type():
    with pytest.raises(TypeError, match="Camera"):
        voxgi.Scene(camera=(0, 0, 1))


def test_scene_add_does_not_modify_mesh():
    m = trimesh.creation.box()
    v0, f0 = m.vertices.copy(), m.faces.copy()
    voxgi.Scene().add(m)
    assert np.array_equal(m.vertices, v0)
    assert np.array_equal(m.faces, f0)


# ----------------------------------------------------------------- Scene.load
def _write(tmp_path, text, name="s.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.fixture
def box_obj(tmp_path):
    p = tmp_path / "box.obj"
    p.write_text(trimesh.creation.box().export(file_type="obj"))
    return p


def test_load_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="not found"):
        voxgi.Scene.load(tmp_path / "nope.toml")


def test_load_malformed_toml_gives_line(tmp_path):
    p = _write(tmp_path, "[camera]\neye = [0, 0, 1]\nfov = = 3\n")
    with pytest.raises(ValueError, match=r"line 3"):
        voxgi.Scene.load(p)


def test_load_binary_file(tmp_path):
    p = tmp_path / "s.toml"
    p.write_bytes(b"\xff\xfe\x00garbage\x80")
    with pytest.raises(ValueError, match=r"s\.toml"):
        voxgi.Scene.load(p)


def test_load_directory(tmp_path):
    with pytest.raises((ValueError, IsADirectoryError)):
        voxgi.Scene.load(tmp_path)


@pytest.mark.parametrize(
    ("body", "words"),
    [
        ('[[object]]\nmesh = "box.obj"\nalbedo = 1.5\n', ["object #0", "albedo"]),
        ('[[object]]\nmesh = "box.obj"\nalbedo = "nan"\n', ["object #0", "albedo"]),
        ('[[object]]\nmesh = "box.obj"\nemission = -1\n', ["object #0", "emission"]),
        ('[[object]]\nmesh = "box.obj"\ncolour = 1\n', ["object #0", "colour"]),
        ('[[object]]\nname = "x"\n', ["object #0", "mesh"]),
        ('[[object]]\nmesh = "missing.obj"\n', ["object #0", "missing.obj"]),
        ('[[object]]\nmesh = "box.obj"\nmaterial = "gold"\n', ["object #0", "gold"]),
        ('[[object]]\nmesh = "box.obj"\nscale = 0\n', ["object #0", "scale"]),
        ('[[object]]\nmesh = "box.obj"\nrotate = [90, 0, 0, 0]\n', ["object #0", "rotate"]),
        ('[[object]]\nmesh = "box.obj"\nmatrix = [[1, 0], [0, 1]]\n', ["object #0", "matrix"]),
        ('[[object]]\nmesh = "box.obj"\ntranslate = [0, 0]\n', ["object #0", "translate"]),
        ('[[object]]\nmesh = "box.obj"\ntwo_sided = "no"\n', ["object #0", "two_sided"]),
        ("[camera]\nfov = 200\n", ["camera", "fov"]),
        ("[camera]\neye = [0, 0, 0]\ntarget = [0, 0, 0]\n", ["camera", "coincide"]),
        ("[camera]\nlens = 3\n", ["camera", "lens"]),
        ("[materials.w]\nalbedo = [0.5, 0.5]\n", ["materials.w", "albedo"]),
        ("[materials.w]\nshiny = 1\n", ["materials.w", "shiny"]),
        ("[materials.w]\nspecular = { rs = 0.1, nu = -1, nv = 10 }\n", ["materials.w", "nu"]),
        ("lights = 3\n", ["lights"]),
        ("object = 3\n", ["object"]),
        ("camera = 3\n", ["camera"]),
    ],
)
def test_load_bad_value_names_key(tmp_path, box_obj, body, words):
    p = _write(tmp_path, body)
    with pytest.raises(ValueError, match=r"s\.toml") as ei:
        voxgi.Scene.load(p)
    for w in words:
        assert w in str(ei.value), (w, str(ei.value))
    assert "s.toml" in str(ei.value)


def test_load_bad_value_gives_line(tmp_path, box_obj):
    """A bad value deep in the file is reported with its line number."""
    p = _write(
        tmp_path,
        '[camera]\nwidth = 8\n\n[[object]]\nmesh = "box.obj"\n\n'
        '[[object]]\nmesh = "box.obj"\nalbedo = 2.0\n',
    )
    with pytest.raises(ValueError, match=r"line 9.*albedo|albedo.*line 9"):
        voxgi.Scene.load(p)


def test_load_unreadable_mesh(tmp_path):
    (tmp_path / "junk.obj").write_bytes(b"v 1 2\nf 1 2 3 4 5\nthis is not an obj\n")
    p = _write(tmp_path, '[[object]]\nmesh = "junk.obj"\n')
    with pytest.raises(ValueError, match=r"junk\.obj"):
        voxgi.Scene.load(p)


def test_load_mesh_with_nan_vertex(tmp_path):
    (tmp_path / "nan.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n")
    p = _write(tmp_path, '[[object]]\nmesh = "nan.obj"\n')
    with pytest.raises(ValueError, match="not finite"):
        voxgi.Scene.load(p)


# ----------------------------------------------------------------- voxelize
def test_voxelize_bad(small):
    s, _, _ = small
    with pytest.raises(TypeError, match="Scene"):
        voxgi.voxelize("cornell-box")
    with pytest.raises(ValueError, match="empty"):
        voxgi.voxelize(voxgi.Scene())
    for res, exc in [
        (1, ValueError),
        (0, ValueError),
        (-5, ValueError),
        (16.0, TypeError),
        ("16", TypeError),
        (None, TypeError),
        (True, TypeError),
    ]:
        with pytest.raises(exc, match="resolution"):
            voxgi.voxelize(s, resolution=res, progress=False)
    with pytest.raises(TypeError, match="threads"):
        voxgi.voxelize(s, resolution=8, threads="2", progress=False)
    with pytest.raises(ValueError, match="threads"):
        voxgi.voxelize(s, resolution=8, threads=0, progress=False)
    with pytest.raises(TypeError, match="progress"):
        voxgi.voxelize(s, resolution=8, progress="no")


def test_voxelize_memory_limit_refused_before_allocating(small):
    """A request over max_memory is refused, and the message gives the estimate."""
    s, _, _ = small
    with pytest.raises(ValueError, match=r"needs up to [\d,]+ bytes.*max_memory") as ei:
        voxgi.voxelize(s, resolution=4096, max_memory=10_000_000, progress=False)
    assert "records" in str(ei.value)
    # the default budget (half the available memory) refuses an absurd resolution too
    with pytest.raises(ValueError, match="bytes"):
        voxgi.voxelize(s, resolution=1 << 20, progress=False)


def test_voxelize_tiny_pitch_refused():
    s = voxgi.Scene()
    s.add(trimesh.creation.box(extents=(1e-17, 1e-17, 1e-17)))
    with pytest.raises(ValueError, match="pitch"):
        voxgi.voxelize(s, resolution=64, progress=False)


# ----------------------------------------------------------------- solve
def test_solve_bad_args(small):
    _, vox, _ = small
    with pytest.raises(TypeError, match="VoxelSet"):
        voxgi.solve(np.zeros((3, 3)), tuning=paper())
    for kw, exc, word in [
        ({"radius": 0}, ValueError, "radius"),
        ({"radius": 2.5}, TypeError, "radius"),
        ({"max_bounces": -1}, ValueError, "max_bounces"),
        ({"tol": 0.0}, ValueError, "tol"),
        ({"tol": NAN}, ValueError, "tol"),
        ({"tol": "1e-3"}, TypeError, "tol"),
        ({"threads": 0}, ValueError, "threads"),
        ({"tuning": paper(epsilon=-1.0)}, ValueError, "epsilon"),
        ({"tuning": paper(history=0)}, ValueError, "history"),
        ({"tuning": "fast"}, TypeError, "tuning"),
    ]:
        with pytest.raises(exc, match=word):
            voxgi.solve(vox, progress=False, **kw)


def _corrupt(vox, **changes):
    import dataclasses

    return dataclasses.replace(vox, **changes)


def test_solve_corrupt_voxelset(small):
    """Arrays swapped for wrong shapes, dtypes or NaN are caught before the kernels."""
    _, vox, _ = small
    n = len(vox)
    bad_normal = vox.normal.copy()
    bad_normal[3] = np.nan
    cases = [
        ({"normal": bad_normal}, ValueError, "vox.normal"),
        ({"normal": vox.normal[:, :2]}, ValueError, "vox.normal"),
        ({"normal": vox.normal * 2}, ValueError, "unit"),
        ({"area": -vox.area}, ValueError, "vox.area"),
        ({"area": vox.area[: n - 1]}, ValueError, "vox.area"),
        ({"albedo": np.ones_like(vox.albedo)}, ValueError, "vox.albedo"),
        ({"emission": np.full_like(vox.emission, np.inf)}, ValueError, "vox.emission"),
        ({"ijk": vox.ijk.astype(np.float64) + 0.5}, ValueError, "vox.ijk"),
        ({"ijk": vox.ijk.astype(str)}, TypeError, "vox.ijk"),
        ({"centroid": vox.centroid[:, :1]}, ValueError, "vox.centroid"),
        ({"pitch": 0.0}, ValueError, "pitch"),
        ({"pitch": NAN}, ValueError, "pitch"),
        ({"origin": (0, 0)}, ValueError, "origin"),
    ]
    for changes, exc, word in cases:
        with pytest.raises(exc, match=word):
            voxgi.solve(
                _corrupt(vox, **changes),
                radius=4,
                progress=False,
                tuning=paper(shoot_radius=4),
            )
    # the user's arrays are untouched by a failed and a successful call
    a0 = vox.area.copy()
    voxgi.solve(vox, radius=4, tuning=paper(shoot_radius=4), progress=False)
    assert np.array_equal(vox.area, a0)


def test_solve_empty_voxelset(small):
    _, vox, _ = small
    empty = _corrupt(
        vox,
        ijk=vox.ijk[:0],
        normal=vox.normal[:0],
        area=vox.area[:0],
        albedo=vox.albedo[:0],
        emission=vox.emission[:0],
        centroid=vox.centroid[:0],
    )
    with pytest.raises(ValueError, match="no records"):
        voxgi.solve(empty, progress=False, tuning=paper())


# ----------------------------------------------------------------- render
def test_render_bad_args(small):
    s, vox, sol = small
    with pytest.raises(TypeError, match="Scene"):
        voxgi.render(sol)
    with pytest.raises(TypeError, match="sol"):
        voxgi.render(s, sol=vox, progress=False)
    with pytest.raises(ValueError, match="camera"):
        voxgi.render(
            voxgi.scenes.furnace_box().__class__(), progress=False
        ) if False else voxgi.render(_no_camera(s), sol, progress=False)
    with pytest.raises(TypeError, match="camera"):
        voxgi.render(s, sol, camera=(0, 0, 1), progress=False)
    for kw, exc, word in [
        ({"tuning": voxgi.RenderTuning(vpls_per_frame=0)}, ValueError, "vpls_per_frame"),
        ({"tuning": voxgi.RenderTuning(vpls_per_frame=1.5)}, TypeError, "vpls_per_frame"),
        ({"max_frames": 0}, ValueError, "max_frames"),
        ({"tol": -1.0}, ValueError, "tol"),
        ({"tol": NAN}, ValueError, "tol"),
        ({"seed": 1.5}, TypeError, "seed"),
        ({"seed": "x"}, TypeError, "seed"),
        ({"threads": -1}, ValueError, "threads"),
        ({"tuning": {"gather": 4}}, TypeError, "tuning"),
        ({"tuning": voxgi.RenderTuning(emitter_share=2.0)}, ValueError, "emitter_share"),
        ({"tuning": _Experiment(vpl_pdf="uniform")}, ValueError, "pdf"),
        ({"tuning": _Experiment(mirror_alpha=-0.1)}, ValueError, "mirror_alpha"),
        ({"tuning": _Experiment(mirror_alpha=NAN)}, ValueError, "mirror_alpha"),
        ({"client": 42}, TypeError, "client"),
    ]:
        with pytest.raises(exc, match=word):
            voxgi.render(s, sol, progress=False, **kw)
    with pytest.raises(TypeError, match="executor"):
        voxgi.display.render(s, sol, progress=False, executor=object())


def _no_camera(s):
    c = voxgi.Scene()
    c.objects = list(s.objects)
    return c


def test_render_solution_of_other_scene(small):
    _, _, sol = small
    other = voxgi.scenes.furnace_sphere(subdivisions=1)
    other.camera = other.camera.replace(width=8, height=8)
    with pytest.raises(ValueError, match="another scene"):
        voxgi.render(other, sol, progress=False)


def test_render_corrupt_solution(small):
    import dataclasses

    s, _, sol = small
    bad = sol.radiosity.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        voxgi.render(s, dataclasses.replace(sol, radiosity=bad), progress=False, max_frames=2)
    with pytest.raises(ValueError, match="radiosity"):
        voxgi.render(
            s,
            dataclasses.replace(sol, radiosity=sol.radiosity[:, :2]),
            progress=False,
            max_frames=2,
        )
    with pytest.raises(ValueError, match=">= 0"):
        voxgi.render(
            s, dataclasses.replace(sol, radiosity=-sol.radiosity), progress=False, max_frames=2
        )


# ----------------------------------------------------------------- Solution.load
def test_solution_load_bad_files(tmp_path, small):
    _, _, sol = small
    with pytest.raises(FileNotFoundError):
        voxgi.Solution.load(tmp_path / "none.npz")
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip file at all")
    with pytest.raises(ValueError, match=r"junk\.npz"):
        voxgi.Solution.load(junk)
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(ValueError, match=r"other\.npz"):
        voxgi.Solution.load(tmp_path / "other.npz")
    # a file whose arrays were tampered with is caught on load, not in a kernel
    p = sol.save(tmp_path / "sol.npz")
    with np.load(p) as z:
        d = dict(z)
    d["radiosity"] = d["radiosity"][:-1]
    np.savez(tmp_path / "bad.npz", **d)
    with pytest.raises(ValueError, match="radiosity"):
        voxgi.Solution.load(tmp_path / "bad.npz")


# ----------------------------------------------------------------- io
def test_io_bad(tmp_path):
    from voxgi import io

    for img, exc in [
        (np.zeros((4, 4, 4)), ValueError),
        (np.zeros((0, 4, 3)), ValueError),
        (np.zeros(5), ValueError),
        ([["a"]], TypeError),
        (np.zeros((2, 2, 3), dtype=object), TypeError),
    ]:
        with pytest.raises(exc, match="image"):
            io.write_exr(tmp_path / "a.exr", img)
        with pytest.raises(exc, match="image"):
            io.write_png(tmp_path / "a.png", img)
    with pytest.raises(FileNotFoundError):
        io.read_exr(tmp_path / "missing.exr")
    (tmp_path / "junk.exr").write_bytes(b"definitely not an exr")
    with pytest.raises((ValueError, OSError), match=r"junk\.exr"):
        io.read_exr(tmp_path / "junk.exr")
    with pytest.raises((TypeError, ValueError), match="exposure"):
        io.write_png(tmp_path / "b.png", np.zeros((2, 2, 3)), exposure="bright")
    with pytest.raises(ValueError, match="exposure"):
        io.write_png(tmp_path / "b.png", np.zeros((2, 2, 3)), exposure=NAN)


def test_io_nan_pixels_written_not_crash(tmp_path):
    """NaN in an image is data, not an error, for EXR (it round-trips); PNG maps it to 0."""
    from voxgi import io

    img = np.zeros((2, 2, 3), np.float32)
    img[0, 0] = np.nan
    back = io.read_exr(io.write_exr(tmp_path / "n.exr", img))
    assert np.isnan(back[0, 0]).all()
    assert np.all(back[1] == 0)
    assert io.to_srgb8(img)[0, 0].tolist() == [0, 0, 0]


# ----------------------------------------------------------------- metrics
@pytest.mark.parametrize("fn", ["rel_mse", "rmse", "psnr", "ssim"])
def test_metrics_bad(fn):
    f = getattr(voxgi.metrics, fn)
    a = np.ones((8, 8, 3))
    with pytest.raises(ValueError, match="shape"):
        f(a, np.ones((8, 7, 3)))
    with pytest.raises(ValueError, match="empty"):
        f(np.ones((0, 8, 3)), np.ones((0, 8, 3)))
    b = a.copy()
    b[1, 1, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        f(b, a)
    with pytest.raises(ValueError, match="NaN"):
        f(a, b * INF)
    with pytest.raises((TypeError, ValueError)):
        f("image", a)


# ----------------------------------------------------------------- cli
@pytest.mark.parametrize(
    ("argv", "word"),
    [
        (["render", "no-such-scene"], "no-such-scene"),
        (["render", "cornell-box", "--resolution", "1"], "resolution"),
        (["render", "cornell-box", "--resolution", "abc"], "resolution"),
        (["render", "cornell-box", "--width", "0"], "width"),
        (["render", "cornell-box", "--frames", "-1"], "frames"),
        (["frobnicate"], "frobnicate"),
        ([], ""),
    ],
)
def test_cli_bad(argv, word, tmp_path, capsys):
    from voxgi.cli import main

    with pytest.raises(SystemExit) as ei:
        main([*argv, "-o", str(tmp_path / "o.exr"), "-q"] if argv[:1] == ["render"] else argv)
    assert ei.value.code not in (0, None)
    msg = str(ei.value.code) + capsys.readouterr().err
    assert word in msg


def test_cli_malformed_scene_file(tmp_path, capsys):
    from voxgi.cli import main

    p = _write(tmp_path, "[camera\n")
    with pytest.raises(SystemExit) as ei:
        main(["render", str(p), "-o", str(tmp_path / "o.exr"), "-q"])
    assert "line 1" in str(ei.value.code)


# ----------------------------------------------------------------- C++ core, called directly
def _ls_arrays(n=4):
    ijk = np.array([[i, 0, 0] for i in range(n)], np.int32)
    normal = np.tile(np.array([0, 1, 0], np.float32), (n, 1))
    point = (ijk + 0.5).astype(np.float32)
    return ijk, normal, point


def test_core_linesystem_bad_arrays():
    ijk, normal, point = _ls_arrays()
    bad = [
        (ijk.astype(np.int64), normal, point),  # dtype
        (ijk.astype(np.float32), normal, point),
        (ijk[:, :2].copy(), normal, point),  # shape
        (ijk, normal[:3].copy(), point),  # length mismatch
        (np.asfortranarray(np.repeat(ijk, 2, 0))[::2], normal, point),  # not contiguous
        (ijk, normal, point.astype(np.float64)),
        (ijk.ravel(), normal, point),
    ]
    for args in bad:
        with pytest.raises((TypeError, ValueError)):
            _core.LineSystem(*args)


def _misaligned(a: np.ndarray) -> np.ndarray:
    """``a``'s values in a C-contiguous array one byte off its type's alignment
    (as Dask and pickle protocol 5 can deliver them to a worker)."""
    buf = np.zeros(a.nbytes + a.itemsize + 1, np.uint8)
    out = np.frombuffer(buf.data, a.dtype, a.size, offset=1).reshape(a.shape)
    out[...] = a
    return out


def test_core_takes_misaligned_arrays_as_aligned_copies():
    arrays = [
        np.arange(12, dtype=t).reshape(4, 3) for t in (np.int32, np.int64, np.float32, np.float64)
    ]
    off = [_misaligned(a) for a in arrays]
    assert not any(a.flags.aligned for a in off)
    assert all(a.flags.c_contiguous for a in off)
    assert _core.testing.input_alignment(*off) == (True, True, True, True)
    # and a kernel given them answers as it does for aligned arrays
    ijk, normal, point = _ls_arrays()
    from voxgi.directions import direction_set

    ds = direction_set(2)
    vals = np.linspace(0.5, 1.5, 12, dtype=np.float32).reshape(4, 3)
    sel = np.arange(len(ds.families), dtype=np.int64)
    want = _core.LineSystem(ijk, normal, point).gather(ds.families, ds.weights, vals, sel)[0]
    ls = _core.LineSystem(_misaligned(ijk), _misaligned(normal), _misaligned(point))
    got = ls.gather(
        _misaligned(ds.families), _misaligned(ds.weights), _misaligned(vals), _misaligned(sel)
    )
    np.testing.assert_array_equal(got[0], want)


def _light_accumulate_args(P=4):
    """Arguments of _core.light_accumulate: P pixels facing +z, one ray each
    straight up, weight 1, none occluded, and the output (P, 3)."""
    up = np.tile(np.array([0, 0, 1], np.float32), (P, 1))
    hits = (np.zeros((P, 3)), up, up, up, np.zeros(P, np.int32))
    mats = (
        np.full((1, 3), 0.5, np.float32),
        np.zeros((1, 3), np.float32),
        np.ones(1, np.float32),
        np.ones(1, np.float32),
        np.zeros(1, np.uint8),
    )
    rays = (np.ones(P, np.int64), up.copy(), np.ones((P, 3), np.float32), np.zeros(P, np.uint8))
    return hits, mats, rays, np.zeros((P, 3), np.float32)


def test_core_refuses_misaligned_arrays_it_writes_into():
    # a copy would take the answer with it: in-place outputs are never converted
    hits, mats, rays, out = _light_accumulate_args()
    _core.light_accumulate(*hits, *mats, *rays, out)
    np.testing.assert_allclose(out, 0.5 / np.pi)  # (rho / pi) cos 0 x 1, written in place
    with pytest.raises(ValueError, match="out must be aligned"):
        _core.light_accumulate(*hits, *mats, *rays, _misaligned(out))
    ro = out.copy()
    ro.flags.writeable = False
    with pytest.raises(ValueError, match="out must be writeable"):
        _core.light_accumulate(*hits, *mats, *rays, ro)


def test_core_linesystem_out_of_range_indices():
    ijk, normal, point = _ls_arrays()
    ls = _core.LineSystem(ijk, normal, point)
    from voxgi.directions import direction_set

    ds = direction_set(2)
    fam, w = ds.families, ds.weights
    vals = np.ones((4, 3), np.float32)
    with pytest.raises((ValueError, IndexError)):
        ls.shoot(np.array([7], np.int32), fam, w, vals, 1)
    with pytest.raises((ValueError, IndexError)):
        ls.shoot(np.array([-1], np.int32), fam, w, vals, 1)
    with pytest.raises((ValueError, TypeError)):
        ls.shoot(np.array([0], np.int32), fam, w, vals[:2].copy(), 1)
    with pytest.raises((ValueError, IndexError)):
        ls.gather(fam, w, vals, np.array([len(fam) + 5], np.int64))
    with pytest.raises((ValueError, IndexError)):
        ls.gather(fam, w, vals, np.array([-1], np.int64))
    with pytest.raises((ValueError, TypeError)):
        ls.gather(fam, w[:-1].copy(), vals, np.array([0], np.int64))
    with pytest.raises((ValueError, TypeError)):
        ls.normalisation(fam.astype(np.int64), w)


def test_core_voxelize_bad_arrays():
    tri = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], np.float64)
    good = dict(
        triangles=tri,
        tri_object=np.zeros(1, np.int32),
        two_sided=np.zeros(1, bool),
        albedo=np.full((1, 3), 0.5, np.float32),
        emission=np.zeros((1, 3), np.float32),
        origin=np.array([-0.1, -0.1, -0.1]),
        pitch=0.25,
        dims=np.array([6, 6, 2], np.int32),
    )
    res = _core.voxelize(**good)  # sanity: the good call works
    assert res is not None
    bad = [
        {"triangles": tri.astype(np.float32)},
        {"triangles": tri[:, :2].copy()},
        {"tri_object": np.array([3], np.int32)},  # object index out of range
        {"tri_object": np.array([-1], np.int32)},
        {"tri_object": np.zeros(2, np.int32)},
        {"albedo": np.full((1, 2), 0.5, np.float32)},
        {"origin": np.zeros(2)},
        {"dims": np.array([6, 6], np.int32)},
        {"dims": np.array([0, 6, 2], np.int32)},
        {"dims": np.array([-6, 6, 2], np.int32)},
        {"pitch": 0.0},
        {"pitch": float("nan")},
        {"pitch": -1.0},
        {"triangles": np.full_like(tri, np.nan)},
        {"two_sided": np.zeros(3, bool)},
    ]
    for change in bad:
        with pytest.raises((TypeError, ValueError)):
            _core.voxelize(**{**good, **change})


def test_core_display_bad_arrays():
    m = np.zeros(4, np.int32)
    alb = np.full((1, 3), 0.5, np.float32)
    rs = np.zeros((1, 3), np.float32)
    nu = np.ones(1, np.float32)
    glossy = np.zeros(1, np.uint8)
    n = np.tile(np.array([0, 0, 1], np.float32), (4, 1))
    k = n.copy()
    out = _core.shade_brdf(alb, rs, nu, nu, glossy, m, n, k, k)
    assert out.shape == (4, 3)
    for args in [
        (alb, rs, nu, nu, glossy, m + 5, n, k, k),  # material index out of range
        (alb, rs, nu, nu, glossy, m - 1, n, k, k),
        (alb, rs, nu, nu, glossy, m, n[:3].copy(), k, k),  # length mismatch
        (alb, rs, nu, nu, glossy, m, n.astype(np.float64), k, k),
        (alb[:, :2].copy(), rs, nu, nu, glossy, m, n, k, k),
        (alb, rs, nu[:0], nu, glossy, m, n, k, k),
    ]:
        with pytest.raises((TypeError, ValueError)):
            _core.shade_brdf(*args)
    hits, mats, (cnt, dirs, weight, occ), out = _light_accumulate_args()
    for rays in [
        (np.array([2, 3, 0, 0], np.int64), dirs, weight, occ),  # counts exceed the rays
        (np.array([-1, 5, 0, 0], np.int64), dirs, weight, occ),
        (cnt, dirs, weight, occ[:3].copy()),
        (cnt.astype(np.int32), dirs, weight, occ),
        (cnt, dirs, weight[:3].copy(), occ),
    ]:
        with pytest.raises((TypeError, ValueError)):
            _core.light_accumulate(*hits, *mats, *rays, out)


def test_core_gather_families_bad_indices():
    ijk, normal, point = _ls_arrays()
    from voxgi.directions import direction_set

    ds = direction_set(2)
    vals = np.ones((4, 3), np.float32)
    ok = _core.gather_families(
        ijk, normal, point, ds.families, ds.weights, vals, np.array([0], np.int64)
    )
    assert np.all(np.isfinite(ok))
    for fi in (np.array([len(ds.families)], np.int64), np.array([-3], np.int64)):
        with pytest.raises((ValueError, IndexError)):
            _core.gather_families(ijk, normal, point, ds.families, ds.weights, vals, fi)
    with pytest.raises((ValueError, TypeError)):
        _core.gather_families(
            ijk, normal, point, ds.families, ds.weights, vals[:1].copy(), np.array([0], np.int64)
        )


def test_render_memory_limit_refused_before_allocating(small):
    """A 32768 x 32768 image (~1 TB of buffers) is refused up front, with the estimate."""
    s, _, sol = small
    cam = s.camera.replace(width=1 << 15, height=1 << 15)
    with pytest.raises(ValueError, match=r"needs about [\d,]+ bytes"):
        voxgi.render(s, sol, camera=cam, progress=False)


def test_read_exr_header_bad(tmp_path):
    from voxgi import io

    with pytest.raises(FileNotFoundError):
        io.read_exr_header(tmp_path / "missing.exr")
    (tmp_path / "junk.exr").write_bytes(b"not an exr")
    with pytest.raises(ValueError, match=r"junk\.exr"):
        io.read_exr_header(tmp_path / "junk.exr")


@pytest.mark.parametrize(
    ("call", "word"),
    [
        (lambda: voxgi.scenes.furnace_box(albedo=1.5), "albedo"),
        (lambda: voxgi.scenes.furnace_sphere(emission=-1.0), "emission"),
        (lambda: voxgi.scenes.furnace_sphere(subdivisions=-1), "subdivisions"),
        (lambda: voxgi.scenes.furnace_sphere(radius=NAN), "radius"),
        (lambda: voxgi.scenes.cornell_box(width=0), "width"),
        (lambda: voxgi.scenes.labyrinth(cells=0), "cells"),
        (lambda: voxgi.scenes.get("nope"), "nope"),
    ],
)
def test_builtin_scenes_bad(call, word):
    with pytest.raises((ValueError, TypeError), match=word):
        call()
