"""Solve and render on a Dask LocalCluster (processes, loopback only).

What must hold: the distributed solve equals the local solve to 1e-6
relative whatever the number of workers, the distributed render equals the
local image to float rounding with the same seed, a worker killed mid-solve
is survived with the same answer, and the errors (extra missing, not a
Client, not enough worker memory) come before any work.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time

import numpy as np
import pytest
from conftest import paper

import voxgi

# Small on purpose: every test here together must stay well under a minute
# on a 2-core machine (a 20³ Cornell box has ~6k records; R = 5 gives 257
# gathering families, R = 6 for shooting).
RES, R, RS = 20, 5, 6
TUNED = paper(shoot_radius=RS)

# The scheduler's HTTP routes on a free loopback port: with None it still
# binds :8787, and a second cluster (or another process's) then warns,
# which filterwarnings=error turns into a failure.
_HTTP = "127.0.0.1:0"


@pytest.fixture(scope="module")
def cornell_small():
    scene = voxgi.scenes.cornell_box(width=40, height=40)
    return scene, voxgi.voxelize(scene, resolution=RES)


@pytest.fixture(scope="module")
def local_solution(cornell_small):
    _, vox = cornell_small
    return voxgi.solve(vox, radius=R, tuning=TUNED, progress=False, threads=1)


@pytest.fixture(scope="module")
def client():
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=_HTTP
    )
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


@pytest.fixture(scope="module")
def client3():
    """Three thread workers in this process: a different worker count, cheap to start."""
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(
        n_workers=3, threads_per_worker=1, processes=False, dashboard_address=_HTTP
    )
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


def _rel(a, b):
    """Largest relative difference, against the largest value (radiosity >= 0)."""
    return float(np.max(np.abs(np.asarray(a, np.float64) - b)) / np.max(np.abs(b)))


# -- errors ------------------------------------------------------------------------------------


def test_missing_extra_names_it(cornell_small, monkeypatch):
    scene, vox = cornell_small
    # A None entry in sys.modules makes `import distributed` fail as if Dask
    # were not installed (the real import machinery, nothing mocked inside voxgi).
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(ImportError, match=r'pip install "voxgi\[dask\]"'):
        voxgi.solve(vox, radius=R, progress=False, client=object(), tuning=paper())
    sol = voxgi.solve(vox, radius=R, tuning=TUNED, max_bounces=1, progress=False)
    with pytest.raises(ImportError, match=r"voxgi\[dask\]"):
        voxgi.render(scene, sol, max_frames=2, progress=False, client=object())


def test_not_a_client_is_a_type_error(cornell_small):
    pytest.importorskip("distributed")
    scene, vox = cornell_small
    with pytest.raises(TypeError, match="client"):
        voxgi.solve(vox, radius=R, progress=False, client="tcp://127.0.0.1:8786", tuning=paper())
    sol = voxgi.solve(vox, radius=R, tuning=TUNED, max_bounces=1, progress=False)
    with pytest.raises(TypeError, match="client"):
        voxgi.render(scene, sol, max_frames=2, progress=False, client=42)


def test_worker_memory_too_small_is_refused_before_work(cornell_small):
    distributed = pytest.importorskip("distributed")
    _, vox = cornell_small
    from voxgi.distributed import estimate_worker_bytes

    need = estimate_worker_bytes(len(vox))
    # thread workers: the limit is only reported here, no nanny enforces it
    cluster = distributed.LocalCluster(
        n_workers=1,
        threads_per_worker=1,
        processes=False,
        dashboard_address=_HTTP,
        memory_limit=need // 2,
    )
    with distributed.Client(cluster) as c:
        with pytest.raises(MemoryError, match="memory_limit"):
            voxgi.solve(vox, radius=R, tuning=TUNED, progress=False, client=c)
        # refused before anything was scattered or submitted
        assert not c.has_what()[next(iter(c.has_what()))]
    cluster.close()


# -- solve -------------------------------------------------------------------------------------


def test_solve_equals_local(cornell_small, local_solution, client):
    _, vox = cornell_small
    sol = voxgi.solve(vox, radius=R, tuning=TUNED, progress=False, client=client)
    # the partial sums are float64 added in chunk order instead of in one
    # pass: equal to float rounding of the float32 output
    assert _rel(sol.radiosity, local_solution.radiosity) < 1e-6
    assert sol.bounces == local_solution.bounces
    assert sol.stats["gather_rays"] == local_solution.stats["gather_rays"]
    assert sol.stats["shoot_rays"] == local_solution.stats["shoot_rays"]
    d = sol.stats["executor"]
    assert d["workers"] == 2
    # records sent once (36 bytes each), values every call: never the records again
    assert d["bytes_scattered"] == 36 * len(vox)


def test_solve_equals_local_three_workers_and_an_executor(cornell_small, local_solution, client3):
    _, vox = cornell_small
    # an executor object is taken as it is; the stage itself takes one too
    # (a Client is taken by test_solve_equals_local)
    from voxgi.distributed import DaskExecutor

    ex = DaskExecutor(client3)
    a = voxgi.solve(vox, radius=R, tuning=TUNED, progress=False, client=ex)
    assert a.stats["executor"]["workers"] == 3
    assert _rel(a.radiosity, local_solution.radiosity) < 1e-6
    b = voxgi.radiosity.solve(vox, radius=R, tuning=TUNED, progress=False, executor=ex)
    np.testing.assert_array_equal(a.radiosity, b.radiosity)


def test_shoot_and_gather_partial_sums_add_up(cornell_small, client3):
    """The backend against the local LineSystem, call by call (float64 sums)."""
    from voxgi.directions import direction_set
    from voxgi.distributed import DistributedLineSystem
    from voxgi.radiosity import line_records

    _, vox = cornell_small
    records = line_records(vox)
    local = records.build()
    dist = DistributedLineSystem(client3, records)
    ds = direction_set(RS)
    em = np.flatnonzero(np.any(vox.emission > 0, axis=1)).astype(np.int32)
    vals = np.ascontiguousarray(vox.emission * np.pi, dtype=np.float32)
    h0, u0, r0, s0 = local.shoot(em, ds.families, ds.weights, vals, 1)
    h1, u1, r1, s1 = dist.shoot(em, ds.families, ds.weights, vals)
    # the same float64 terms summed in another grouping: ~1e-16 relative,
    # 1e-12 leaves room for a few thousand additions
    np.testing.assert_allclose(h1, h0, rtol=1e-12, atol=1e-12 * np.abs(h0).max())
    np.testing.assert_allclose(u1, u0, rtol=1e-12, atol=1e-12)
    assert (r1, s1) == (r0, s0)
    rng = np.random.default_rng(7)
    v = rng.random((len(vox), 3)).astype(np.float32)
    sel = np.arange(0, len(ds.families), 2)  # a subset of the families
    g0, vis0, l0 = local.gather(ds.families, ds.weights, v, sel, True, 1)
    g1, vis1, l1 = dist.gather(ds.families, ds.weights, v, sel, True)
    np.testing.assert_allclose(g1, g0, rtol=1e-12, atol=1e-12 * np.abs(g0).max())
    np.testing.assert_allclose(vis1, vis0, rtol=1e-12, atol=1e-12)
    assert l1 == l0
    # the stand-in flags (solve's closed-object back records) reach the
    # workers' kernels: here every back record, which changes the sums
    sb = np.ascontiguousarray(vox.back)
    g2, _, _ = local.gather(ds.families, ds.weights, v, sel, False, 1, stand_in=sb)
    g3, _, _ = dist.gather(ds.families, ds.weights, v, sel, False, stand_in=sb)
    assert np.abs(g2 - g0).max() > 1e-3 * np.abs(g0).max()
    np.testing.assert_allclose(g3, g2, rtol=1e-12, atol=1e-12 * np.abs(g2).max())
    h2, u2, _, _ = local.shoot(em, ds.families, ds.weights, vals, 1, stand_in=sb)
    h3, u3, _, _ = dist.shoot(em, ds.families, ds.weights, vals, stand_in=sb)
    assert np.abs(h2 - h0).max() > 1e-3 * np.abs(h0).max()
    np.testing.assert_allclose(h3, h2, rtol=1e-12, atol=1e-12 * np.abs(h2).max())
    np.testing.assert_allclose(u3, u2, rtol=1e-12, atol=1e-12)
    dist.close()


def test_killed_worker_is_survived(cornell_small, local_solution, client):
    """SIGKILL one worker process while gather tasks run: Dask reruns them."""
    _, vox = cornell_small
    pids = client.run(os.getpid)
    killed = {}
    done = threading.Event()

    def killer():
        # wait for the solve's gathering to be under way (not just shooting)
        # (shooting and the normalisation come first: a gather task means mid-solve)
        while not done.is_set():
            for addr, keys in client.processing().items():
                if any(str(k).startswith("voxgi-gather") for k in keys):
                    if addr in pids:
                        os.kill(pids[addr], signal.SIGKILL)
                        killed["addr"] = addr
                        killed["at"] = time.perf_counter()
                        return
            time.sleep(0.005)

    th = threading.Thread(target=killer, daemon=True)
    th.start()
    try:
        sol = voxgi.solve(vox, radius=R, tuning=TUNED, progress=False, client=client)
    finally:
        done.set()
        th.join()
        # the nanny brings a new worker process back; wait so later tests see two
        client.wait_for_workers(2, timeout=60)
    t_end = time.perf_counter()
    assert "addr" in killed, "the solve ended before a worker could be killed"
    assert killed["at"] < t_end
    assert _rel(sol.radiosity, local_solution.radiosity) < 1e-6
    assert sol.bounces == local_solution.bounces
    assert set(client.run(os.getpid).values()) != set(pids.values())


def _lose_last_copy(client, fut):
    """Do what Dask's active memory manager and a killed worker do together:
    reduce a broadcast value to one copy, then SIGKILL the worker holding it."""
    client.amm.run_once()  # ReduceReplicas drops the copies no task waits for
    deadline = time.perf_counter() + 30
    while len(client.who_has([fut]).get(fut.key, ())) != 1:
        assert time.perf_counter() < deadline, "the copies were not reduced to one"
        time.sleep(0.02)
    (holder,) = client.who_has([fut])[fut.key]
    os.kill(client.run(os.getpid)[holder], signal.SIGKILL)
    while fut.status == "finished":
        assert time.perf_counter() < deadline, "the cluster did not lose the value"
        time.sleep(0.02)
    client.wait_for_workers(2, timeout=60)


class _LosingExecutor:
    """A DaskExecutor whose cluster loses the records or the frames' scene
    right after they were sent (and before any task used them)."""

    def __init__(self, client):
        from voxgi.distributed import DaskExecutor

        self.dask = DaskExecutor(client)
        self.client = client

    def line_system(self, records, *, progress=False):
        system = self.dask.line_system(records, progress=progress)
        _lose_last_copy(self.client, system._records)
        return system

    def frames(self, spec, max_frames, *, threads=1):
        frames = self.dask.frames(spec, max_frames, threads=threads)
        _lose_last_copy(self.client, frames._payload)
        return frames


def test_records_lost_with_a_worker_are_sent_again(cornell_small, local_solution, client):
    """The cluster's last copy of the records dies with a worker: sent again."""
    _, vox = cornell_small
    sol = voxgi.solve(vox, radius=R, tuning=TUNED, progress=False, client=_LosingExecutor(client))
    assert _rel(sol.radiosity, local_solution.radiosity) < 1e-6
    assert sol.bounces == local_solution.bounces
    assert sol.stats["executor"]["resent"] >= 1


# -- render ------------------------------------------------------------------------------------


def test_render_equals_local(cornell_small, local_solution, client):
    scene, _ = cornell_small
    kw = dict(max_frames=12, tol=2e-3, seed=3, progress=False)
    ref = voxgi.render(scene, local_solution, threads=1, **kw)
    out = voxgi.render(scene, local_solution, client=client, **kw)
    # the same frames (same VPLs, offsets and gather seeds), accumulated in
    # the same order here: equal to float rounding
    np.testing.assert_allclose(out.image, ref.image, rtol=1e-6, atol=1e-7)
    assert out.frames == ref.frames  # the stopping rule saw the same sequence
    for k in ("shadow_rays", "gather_rays", "vpls"):
        assert out.stats[k] == ref.stats[k], k
    # each worker that shaded frames integrated the seen emission once
    control = ref.stats["seen_emission"]["rays"]
    extra = out.stats["primary_rays"] - (ref.stats["primary_rays"] - control)
    assert control > 0
    assert extra % control == 0
    assert 1 <= extra // control <= 2


def test_scene_lost_with_a_worker_is_sent_again(cornell_small, local_solution, client):
    """The cluster's last copy of the frames' scene dies with a worker: sent again."""
    scene, _ = cornell_small
    kw = dict(max_frames=6, tol=2e-3, seed=3, progress=False)
    ref = voxgi.render(scene, local_solution, threads=1, **kw)
    out = voxgi.render(scene, local_solution, client=_LosingExecutor(client), **kw)
    np.testing.assert_allclose(out.image, ref.image, rtol=1e-6, atol=1e-7)
    assert out.frames == ref.frames


def test_progress_bar_counts_finished_tasks(cornell_small, client, monkeypatch):
    """With progress=True the tasks of each distributed call feed a progress bar."""
    _, vox = cornell_small
    # bars are drawn only where someone watches: count capsys's stderr as a terminal
    monkeypatch.setattr("voxgi._progress.interactive", lambda stream=None: True)
    made, bar = [], voxgi._progress.bar
    monkeypatch.setattr(
        "voxgi._progress.bar", lambda *a, **kw: made.append(bar(*a, **kw)) or made[-1]
    )
    voxgi.solve(vox, radius=R, tuning=TUNED, max_bounces=2, progress=True, client=client)
    # one task per worker (2) per call: each gather call's bar reaches 2 of 2
    tasks = [b for b in made if b.desc == "gather tasks"]
    assert tasks
    assert all(b.n == b.total == 2 for b in tasks)


def _slow_square(x):
    time.sleep(0.2)
    return x * x


def test_a_task_the_scheduler_forgot_runs_again(client):
    # A worker killed while another fetches a result from it can leave a
    # task's future cancelled ("already forgotten"); its inputs are on every
    # worker, so the farm submits it again and the results stay in order.
    from voxgi.distributed.farm import _Farm

    farm = _Farm(client, progress=False, desc="test")
    submit = client.submit
    cancelled = []

    def submit_then_forget(*args, **kwargs):
        fut = submit(*args, **kwargs)
        if not cancelled:
            client.cancel(fut)
            cancelled.append(fut.key)
        return fut

    client.submit = submit_then_forget
    try:
        out = farm._map(_slow_square, [(i,) for i in range(6)], key_prefix="voxgi-test")
    finally:
        client.submit = submit
    assert cancelled
    assert out == [i * i for i in range(6)]
