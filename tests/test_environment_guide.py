"""The environment guide (voxgi.display.environment_guide): a room lit only
through a skylight reads the closed form with the guide and without it, the
guide's samples are the less noisy, an open scene skips it, and bad tables
are refused by name."""

import math

import numpy as np
import pytest
import trimesh

import voxgi
from voxgi import _core
from voxgi.display.settings import _Experiment

#: the room [0, 2]^3, its floor white, the rest black, a square skylight of
#: side 2 HOLE centred over (1, 1) in the ceiling
HOLE = 0.3
ROOM = 2.0
RHO = 0.5
SKY = 2.0


def _quad(x0, x1, z0, z1, y, up):
    """A horizontal rectangle at height y facing +y (up) or -y."""
    v = np.array([[x0, y, z0], [x1, y, z0], [x1, y, z1], [x0, y, z1]], float)
    f = np.array([[0, 2, 1], [0, 3, 2]]) if up else np.array([[0, 1, 2], [0, 2, 3]])
    return trimesh.Trimesh(v, f, process=False)


def _skylight_room(sky: voxgi.Environment) -> voxgi.Scene:
    c0, c1 = ROOM / 2 - HOLE, ROOM / 2 + HOLE
    walls = trimesh.creation.box(bounds=[[0, 0, 0], [ROOM, ROOM, ROOM]])
    keep = np.abs(walls.face_normals[:, 1]) < 0.5  # the four sides, not floor or ceiling
    sides = trimesh.Trimesh(walls.vertices, walls.faces[keep][:, ::-1], process=False)
    ceiling = [
        _quad(0, ROOM, 0, c0, ROOM, up=False),
        _quad(0, ROOM, c1, ROOM, ROOM, up=False),
        _quad(0, c0, c0, c1, ROOM, up=False),
        _quad(c1, ROOM, c0, c1, ROOM, up=False),
    ]
    sc = voxgi.Scene()
    sc.add(_quad(0, ROOM, 0, ROOM, 0.0, up=True), voxgi.Material(RHO), name="floor")
    sc.add(sides, voxgi.Material(0.0), name="walls", two_sided=True)
    sc.add(trimesh.util.concatenate(ceiling), voxgi.Material(0.0), name="ceiling", two_sided=True)
    sc.environment = sky
    # straight down at the floor under the skylight, a footprint 4 cm wide
    sc.camera = voxgi.Camera(
        eye=(1.0, 1.0, 1.0), target=(1.0, 0.0, 1.0), up=(0, 0, 1), fov=2.3, width=16, height=16
    )
    return sc


def _corner(a: float, b: float, c: float) -> float:
    """Form factor from a point to a parallel rectangle a x b at distance c
    with a corner straight above it, signed by the sides' directions."""
    x, y = abs(a) / c, abs(b) / c
    f = (
        x / math.sqrt(1 + x * x) * math.atan(y / math.sqrt(1 + x * x))
        + y / math.sqrt(1 + y * y) * math.atan(x / math.sqrt(1 + y * y))
    ) / (2 * math.pi)
    return math.copysign(1.0, a) * math.copysign(1.0, b) * f


def _skylight_radiance(px: float, pz: float) -> float:
    """The floor's radiance at (px, pz): rho L F to the opening."""
    c0, c1 = ROOM / 2 - HOLE, ROOM / 2 + HOLE
    f = (
        _corner(c1 - px, c1 - pz, ROOM)
        - _corner(c0 - px, c1 - pz, ROOM)
        - _corner(c1 - px, c0 - pz, ROOM)
        + _corner(c0 - px, c0 - pz, ROOM)
    )
    return RHO * SKY * f


@pytest.fixture(scope="module")
def skylight():
    # a uniform sky as an image: the guide needs texels to choose between
    sc = _skylight_room(voxgi.Environment(np.full((16, 32, 3), SKY)))
    sol = voxgi.solve(voxgi.voxelize(sc, 32, progress=False), progress=False, threads=2)
    return sc, sol


def _render(sc, sol, guide: bool, seed: int = 0, frames: int = 16):
    return voxgi.render(
        sc,
        sol,
        seed=seed,
        tol=0,
        max_frames=frames,
        progress=False,
        threads=2,
        tuning=_Experiment(guide_environment=guide),
    )


def test_a_skylit_floor_reads_the_closed_form_with_and_without_the_guide(skylight):
    sc, sol = skylight
    want = _skylight_radiance(1.0, 1.0)
    # the footprint is small enough for the form factor to stay put across it
    assert abs(_skylight_radiance(1.02, 1.02) / want - 1) < 2e-3
    for guide in (True, False):
        out = _render(sc, sol, guide, frames=256)
        mean = float(out.image.mean())
        se = float(np.sqrt(np.mean(out.stderr**2) / out.image[..., 0].size))
        # 4 standard errors of the mean over the pixels, and 0.5% for the footprint
        assert abs(mean - want) < 4 * se + 0.005 * want, (guide, mean, want, se)
        assert se < 0.008 * want  # the check can see a 4% error
        used = out.stats["environment_guide"] is not None
        assert used == guide, out.stats["skipped"]


def test_the_guide_draws_the_skylight_with_less_noise(skylight):
    sc, sol = skylight
    noise = {}
    for guide in (True, False):
        a, b = (_render(sc, sol, guide, seed=s).image for s in (0, 1))
        noise[guide] = float(np.mean((a - b) ** 2) / 2)
    # the opening is 3% of the floor's projected hemisphere: the environment's own
    # density sends 1 sample in 70 through it, the guide most of them
    assert noise[True] < 0.25 * noise[False], noise


def test_an_open_scene_skips_the_guide():
    sc = voxgi.Scene()
    sc.add(_quad(-1, 1, -1, 1, 0.0, up=True), voxgi.Material(0.5))
    sc.environment = voxgi.Environment(np.full((16, 32, 3), 1.0))
    sc.camera = voxgi.Camera(eye=(0, 1, 0), target=(0, 0, 0), up=(0, 0, 1), width=8, height=8)
    sol = voxgi.solve(voxgi.voxelize(sc, 16, progress=False), progress=False, threads=1)
    out = voxgi.render(sc, sol, tol=0, max_frames=2, progress=False, threads=1)
    assert out.stats["environment_guide"] is None
    assert any("environment is open" in s for s in out.stats["skipped"]), out.stats["skipped"]


def _tables(width=4, height=2, bw=2, bh=2):
    """A valid guide's arguments: one cell, its six facings on row 0, an
    environment of equal texels (each block's rows run up by one row's
    share of the block's columns)."""
    rows_per, cols_per = height // bh, width // bw
    step = cols_per / (width * height)
    return dict(
        origin=np.zeros(3),
        cell=1.0,
        dims=np.ones(3, np.int64),
        width=width,
        height=height,
        blocks_w=bw,
        blocks_h=bh,
        alpha=0.1,
        key_row=np.zeros(6, np.int32),
        factor=np.ones((1, bw * bh)),
        block_cdf=np.cumsum(np.full((1, bw * bh), 1.0 / (bw * bh)), axis=1),
        row_cdf=np.tile(step * (np.arange(height) % rows_per + 1.0), (bw, 1)),
    )


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (dict(key_row=np.full(6, 3, np.int32)), "key_row: a row out of range"),
        (dict(block_cdf=np.full((1, 4), 0.5)), "block_cdf: each row must end at 1"),
        (dict(row_cdf=np.full((2, 2), -1.0)), r"row_cdf: block \(0, 0\) must ascend"),
        (dict(factor=np.full((1, 4), np.nan)), "factor must be finite"),
        (dict(alpha=0.0), "alpha must be in"),
    ],
)
def test_bad_guide_tables_are_refused_by_name(change, message):
    _core.EnvironmentGuide(**_tables())  # the unchanged tables pass
    with pytest.raises(ValueError, match=message):
        _core.EnvironmentGuide(**{**_tables(), **change})
