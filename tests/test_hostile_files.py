"""Hostile and broken scene files, each read in a child process under limits.

Every probe (``tests/hostile_probes_*.py``) writes a small file (or a few) at test time and reads it
in a forked child of a server process that runs under a 2 GiB address-space
limit (``RLIMIT_AS``); the parent kills a child still running after 30 s.
Each probe must end in a ``ValueError`` or ``TypeError`` whose message names
the file and the element (the probe's pattern), or load where the file is
valid. None may be killed (by the limit, a signal or the timeout), and none
may raise its peak resident memory by more than twice what the scene
legitimately needs plus 64 MiB: the floor covers a Python exception, the
readers' lazily imported modules and numpy's temporaries.

The probes that take seconds (``slow=True``) run with the long tests (``-m slow``).
``python -m pytest -s tests/test_hostile_files.py`` prints the table.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import hostile_probes_other  # noqa: F401  (registers its probes)
import hostile_probes_scenes  # noqa: F401
import pytest
from conftest import SELECTED
from hostile_common import LOADS, PROBES, SLOW

if not sys.platform.startswith("linux"):  # RLIMIT_AS, fork and /proc/self/status
    pytest.skip("the probes' limits and memory figures need Linux", allow_module_level=True)

LIMIT_AS = 2 << 30
TIMEOUT_S = 30
FLOOR_MB = 64


# -- the child ------------------------------------------------------------------------

SERVER = (
    textwrap.dedent(
        r"""
    import contextlib, io, json, os, resource, signal, sys, time, traceback, warnings
    resource.setrlimit(resource.RLIMIT_AS, (__LIMIT__, __LIMIT__))
    import numpy as np
    import voxgi, voxgi.cli, voxgi.formats, trimesh
    import trimesh.exchange.gltf, trimesh.exchange.obj, trimesh.exchange.ply
    from PIL import Image
    Image.init()

    def status(key):
        for line in open("/proc/self/status"):
            if line.startswith(key):
                return int(line.split()[1]) / 1024

    def run(call, path, kw):
        if call == "load":
            kw = dict(kw)
            if "limits" in kw:
                kw["limits"] = voxgi.formats.Limits(**kw["limits"])
            voxgi.Scene.load(path, **kw)
        elif call == "load_relative":
            os.chdir(path)
            voxgi.Scene.load(kw["path"])
        elif call == "solution":
            voxgi.Solution.load(path)
        else:
            os.chdir(path)
            err = io.StringIO()
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                try:
                    code = voxgi.cli.main(kw["argv"])
                except SystemExit as exc:
                    code = exc.code if isinstance(exc.code, int) else 1
                    if not isinstance(exc.code, int):
                        print(exc.code, file=err)
            raise ValueError(f"{err.getvalue().strip()} (exit {code})")

    for spec in json.loads(sys.stdin.read()):
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:
            os.close(r)
            try:
                with open("/proc/self/clear_refs", "w") as fh:
                    fh.write("5")  # the peak resident size starts again from here
            except OSError:
                pass
            base = status("VmRSS")
            out = {"name": spec["name"]}
            with warnings.catch_warnings(record=True):
                warnings.simplefilter("always")
                try:
                    run(spec["call"], spec["path"], spec["kw"])
                    out["outcome"] = "loads"
                except BaseException as exc:
                    out["outcome"] = type(exc).__name__
                    out["kind"] = next(
                        (k.__name__ for k in (ValueError, TypeError) if isinstance(exc, k)), None
                    )
                    out["message"] = str(exc)
            out["extra_mb"] = status("VmHWM") - base
            os.write(w, json.dumps(out).encode())
            os._exit(0)
        os.close(w)
        t0, res = time.monotonic(), None
        while time.monotonic() - t0 < __TIMEOUT__:
            done, st = os.waitpid(pid, os.WNOHANG)
            if done:
                res = st
                break
            time.sleep(0.02)
        data = b""
        if res is None:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            out = {"name": spec["name"], "outcome": "killed (timeout)"}
        else:
            while chunk := os.read(r, 1 << 16):
                data += chunk
            out = json.loads(data) if data else {"name": spec["name"], "outcome": f"killed ({res})"}
        os.close(r)
        out["seconds"] = time.monotonic() - t0
        print(json.dumps(out), flush=True)
    """
    )
    .replace("__LIMIT__", str(LIMIT_AS))
    .replace("__TIMEOUT__", str(TIMEOUT_S))
)


def _start_servers(chunks: int = 2) -> list:
    """Start ``chunks`` servers; they import voxgi while the files are written."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    return [
        subprocess.Popen(
            [sys.executable, "-c", SERVER],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        for _ in range(chunks)
    ]


def _run_servers(procs: list, specs: list) -> dict:
    """Run the probes in the servers ``procs`` at once (every len(procs)-th
    to each); returns the outcome of each by name."""
    from concurrent.futures import ThreadPoolExecutor

    def talk(k):
        payload = json.dumps(specs[k :: len(procs)])
        return procs[k].communicate(payload, timeout=TIMEOUT_S * max(1, len(specs)))

    with ThreadPoolExecutor(len(procs)) as pool:
        talks = list(pool.map(talk, range(len(procs))))
    results, failed = {}, []
    for p, (out, err) in zip(procs, talks, strict=True):
        if p.returncode != 0:
            failed.append(err[-2000:])
        for line in out.splitlines():
            if not line.startswith('{"name"'):
                continue  # (a reader that printed on stdout: its probe is judged as usual)
            r = json.loads(line)
            results[r["name"]] = r
    assert not failed, failed
    return results


@pytest.fixture(scope="module")
def outcomes(request, tmp_path_factory):
    # the probes of the tests selected (the slow ones take seconds each)
    chosen = {
        item.callspec.params["name"]
        for item in request.config.stash[SELECTED]
        if item.originalname == "test_probe" and item.module is sys.modules[__name__]
    }
    procs = _start_servers()
    specs = []
    for k, (name, (build, _, _)) in enumerate(PROBES.items()):
        if name not in chosen:
            continue
        folder = tmp_path_factory.mktemp(f"probe{k:03d}")
        call, path, kw = build(folder)
        if "limits" in kw:
            kw["limits"] = {f: getattr(kw["limits"], f) for f in kw["limits"].__dataclass_fields__}
        if "search_paths" in kw:
            kw["search_paths"] = [str(p) for p in kw["search_paths"]]
        specs.append({"name": name, "call": call, "path": path, "kw": kw})
    results = _run_servers(procs, specs)
    print()
    print(f"{'probe':<58} {'outcome':<12} {'MiB':>6} {'s':>5}  message")
    for name in (n for n in PROBES if n in chosen):
        r = results.get(name, {"outcome": "missing"})
        msg = r.get("message", "").replace(str(Path.home()), "~")
        msg = msg if len(msg) < 150 else msg[:147] + "..."
        print(
            f"{name:<58} {r['outcome']:<12} {r.get('extra_mb', 0):6.0f} "
            f"{r.get('seconds', 0):5.2f}  {msg}"
        )
    return results


def test_there_are_at_least_60_probes():
    assert len(PROBES) >= 60
    assert SLOW <= set(PROBES)


@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=pytest.mark.slow) if n in SLOW else n for n in PROBES]
)
def test_probe(outcomes, name):
    _, pattern, need_mb = PROBES[name]
    r = outcomes[name]
    assert not r["outcome"].startswith("killed"), r
    if pattern is LOADS:
        assert r["outcome"] == "loads", r
    else:
        assert r.get("kind") in ("ValueError", "TypeError"), r
        import re

        assert re.search(pattern, r["message"]), (pattern, r["message"])
    assert r["extra_mb"] <= 2 * need_mb + FLOOR_MB, r
