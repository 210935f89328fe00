"""Fuzz tests (hypothesis) over scene files and API arguments.

Whatever the input, the library answers with a result or a ValueError /
TypeError / FileNotFoundError: never another exception, never a crash of the
process (a crash in the C++ core would take pytest down with it). The example
counts are bounded and derandomized (the same examples every run, no
database) so CI time is fixed (500 scene files and 500 argument sets take
seconds); each test prints how many examples it ran.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import trimesh
from conftest import paper

import voxgi

hyp = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

OK_ERRORS = (ValueError, TypeError, FileNotFoundError)
SETTINGS = dict(
    deadline=None, derandomize=True, database=None, suppress_health_check=list(HealthCheck)
)

# ------------------------------------------------------------------ TOML writer
scalars = st.one_of(
    st.integers(-3, 5000),
    st.floats(allow_nan=True, allow_infinity=True, width=32),
    st.sampled_from([0.0, 0.5, 0.999, 1.0, -0.0, 1e308, -1e-308, 39.3, 180.0]),
    st.booleans(),
    st.text(max_size=6),
    st.just("box.obj"),
    st.just("missing.obj"),
    st.just("junk.obj"),
)
values = st.one_of(
    scalars,
    st.lists(scalars, max_size=5),
    st.lists(st.lists(st.floats(-2, 2), min_size=0, max_size=4), max_size=4),
)


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return '"' + v.encode("unicode_escape").decode("ascii").replace('"', '\\"') + '"'
    return "[" + ", ".join(_toml_value(x) for x in v) + "]"


camera_keys = st.sampled_from(
    ["eye", "target", "up", "fov", "width", "height", "aperture", "focus_distance", "zoom"]
)
object_keys = st.sampled_from(
    [
        "mesh",
        "material",
        "name",
        "two_sided",
        "translate",
        "rotate",
        "scale",
        "matrix",
        "albedo",
        "emission",
        "glow",
    ]
)
material_keys = st.sampled_from(["albedo", "emission", "shine"])


@st.composite
def scene_texts(draw):
    lines = []
    if draw(st.booleans()):
        lines.append("[camera]")
        cam = {"eye": [0.0, 0.0, 3.0], "target": [0.0, 0.0, 0.0], "width": 4, "height": 4}
        cam.update(draw(st.dictionaries(camera_keys, values, max_size=3)))
        lines += [f"{k} = {_toml_value(v)}" for k, v in cam.items()]
    for mname in draw(st.lists(st.sampled_from(["a", "b"]), max_size=2, unique=True)):
        lines.append(f"[materials.{mname}]")
        m = draw(st.dictionaries(material_keys, values, max_size=2))
        lines += [f"{k} = {_toml_value(v)}" for k, v in m.items()]
    for _ in range(draw(st.integers(0, 2))):
        lines.append("[[object]]")
        o = {"mesh": "box.obj"}
        o.update(draw(st.dictionaries(object_keys, values, max_size=3)))
        lines += [f"{k} = {_toml_value(v)}" for k, v in o.items()]
    text = "\n".join(lines) + "\n"
    if draw(st.integers(0, 9)) == 0:  # sometimes: a corrupted file
        cut = draw(st.integers(0, len(text)))
        text = text[:cut] + draw(st.text(max_size=8)) + text[cut:]
    return text


@pytest.fixture(scope="module")
def fuzz_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("fuzz")
    (d / "box.obj").write_text(trimesh.creation.box().export(file_type="obj"))
    (d / "junk.obj").write_bytes(b"v 1 nan\nf 1 2 9\n\x00\xff")
    return d


@pytest.mark.parametrize("examples", [150, pytest.param(500, marks=pytest.mark.slow)])
def test_fuzz_scene_files(fuzz_dir, examples):
    count = {"n": 0, "loaded": 0, "voxelized": 0}

    @settings(max_examples=examples, **SETTINGS)
    @given(text=scene_texts())
    def run(text):
        count["n"] += 1
        p = fuzz_dir / "s.toml"
        p.write_text(text, encoding="utf-8", errors="surrogatepass")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                scene = voxgi.Scene.load(p)
            except OK_ERRORS:
                return
            count["loaded"] += 1
            if scene.objects:
                try:
                    vox = voxgi.voxelize(scene, resolution=4, progress=False)
                except OK_ERRORS:
                    return
                count["voxelized"] += 1
                assert np.all(np.isfinite(vox.area))
                assert np.all(np.isfinite(vox.normal))

    run()
    print(
        f"fuzz scene files: {count['n']} examples, {count['loaded']} loaded, "
        f"{count['voxelized']} voxelized"
    )
    assert count["n"] >= 100


# ------------------------------------------------------------------ API arguments
junk = st.sampled_from(
    [
        None,
        "x",
        b"b",
        -1,
        0,
        1,
        2,
        3,
        1.5,
        float("nan"),
        float("inf"),
        -0.5,
        True,
        [1, 2],
        (0.5, 0.5, 0.5),
        np.int64(2),
        np.float32(0.5),
        1 << 40,
        np.zeros(3),
        object(),
    ]
)


@pytest.fixture(scope="module")
def solved():
    s = voxgi.scenes.furnace_box(albedo=0.5, emission=1.0)
    s.camera = s.camera.replace(width=4, height=4)
    vox = voxgi.voxelize(s, resolution=4, progress=False)
    sol = voxgi.solve(vox, radius=2, tuning=paper(shoot_radius=2), progress=False)
    return s, vox, sol


def test_fuzz_api_arguments(solved):
    s, vox, sol = solved
    count = {"n": 0, "ok": 0}

    @settings(max_examples=500, **SETTINGS)
    @given(which=st.integers(0, 5), a=junk, b=junk, c=junk)
    def run(which, a, b, c):
        count["n"] += 1
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                if which == 0:
                    voxgi.Material(
                        albedo=a,
                        emission=b,
                        specular=None if c is None else voxgi.AshikhminShirley(rs=c),
                    )
                elif which == 1:
                    voxgi.Camera(eye=a, target=b, fov=c, width=4, height=4)
                elif which == 2:
                    # resolution capped so that a valid draw stays fast
                    res = a if not isinstance(a, int) or a < 64 else 4
                    voxgi.voxelize(s, resolution=res, threads=b, max_memory=c, progress=False)
                elif which == 3:
                    mb = b if not isinstance(b, int) or b < 10 else 2
                    voxgi.solve(
                        vox,
                        radius=a if not isinstance(a, int) or a < 4 else 2,
                        tuning=paper(shoot_radius=2),
                        max_bounces=mb,
                        tol=c,
                        progress=False,
                    )
                elif which == 4:
                    k = a if not isinstance(a, int) or a < 64 else 4
                    f = b if not isinstance(b, int) or b < 4 else 2
                    out = voxgi.display.render(
                        s,
                        sol,
                        max_frames=f,
                        seed=c,
                        progress=False,
                        tuning=voxgi.RenderTuning(vpls_per_frame=k),
                    )
                    assert np.all(np.isfinite(out.image))
                else:
                    img = np.full((2, 2, 3), 0.5) if a is None else a
                    voxgi.metrics.rel_mse(img, np.full((2, 2, 3), 0.5))
                    voxgi.io.to_srgb8(img, exposure=0.0 if b is None else b)
                count["ok"] += 1
            except OK_ERRORS:
                pass

    run()
    print(f"fuzz API arguments: {count['n']} examples, {count['ok']} accepted")
    assert count["n"] >= 100
