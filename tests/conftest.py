"""Shared fixtures: a seeded RNG and small scenes built once per run; the
paper's solve settings with changes (:func:`paper`)."""

from __future__ import annotations

import dataclasses
import math
import signal

import numpy as np
import pytest
import trimesh

import voxgi

#: The tests this run will execute, once selection (``-k``, ``-m``) is done:
#: for fixtures that prepare only what the chosen tests need.
SELECTED = pytest.StashKey[list]()


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config, items):
    # the list itself: the deselection that runs before this hook has
    # already narrowed it in place
    config.stash[SELECTED] = items


@pytest.fixture(autouse=True, scope="session")
def _python_handles_sigint():
    """The Ctrl-C tests send SIGINT as a terminal would; that needs Python's
    own handler. A shell starts a background job with SIGINT ignored, and
    Python then installs no handler: the signal would vanish and an
    interrupted render would run to its frame cap. The child processes of the
    command-line tests get the default disposition back through exec."""
    before = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def cornell():
    return voxgi.scenes.cornell_box(width=64, height=64)


def paper(**changes) -> voxgi.SolveTuning:
    """``voxgi.SolveTuning.paper()`` with ``changes``: shooting along the lines,
    the lines alone, radius 22, tol 1e-4, diagnostics; ``changes`` may set the
    experiment switches too (``later_radius``, ``epsilon``, ``closed``, ...)."""
    return dataclasses.replace(voxgi.SolveTuning.paper(), **changes)


def fails_to_write(write, *args, fsize: int, timeout: float = 60.0) -> str:
    """Call ``write(*args)`` in a forked child whose files may not grow past
    ``fsize`` bytes (``RLIMIT_FSIZE``, ``SIGXFSZ`` ignored, so a write past
    it fails with ``EFBIG``). The child starts from this process as it is (no
    fresh interpreter to import voxgi into): call ``write`` once here first,
    so that the child imports nothing. Returns the ``OSError``'s text; fails
    the test where the call succeeds, raises anything else or runs past
    ``timeout`` seconds."""
    import os
    import resource
    import time
    import traceback
    import warnings

    r, w = os.pipe()
    with warnings.catch_warnings():
        # Python 3.12 warns of fork in a process with threads (a Dask test's
        # leftovers): the child takes no lock that they may hold
        warnings.simplefilter("ignore", DeprecationWarning)
        pid = os.fork()
    if pid == 0:  # the child: report through the pipe, never return into pytest
        code = 1
        try:
            os.close(r)
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))
            try:
                write(*args)
                text = "the write succeeded"
            except OSError as exc:
                text, code = f"refused: {exc}", 3
            except BaseException:
                text = traceback.format_exc()
            os.write(w, text.encode())
        finally:
            os._exit(code)
    os.close(w)
    t0, status = time.monotonic(), None
    while status is None and time.monotonic() - t0 < timeout:
        done, st = os.waitpid(pid, os.WNOHANG)
        if done:
            status = st
        else:
            time.sleep(0.01)
    if status is None:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    chunks = []
    while chunk := os.read(r, 1 << 16):
        chunks.append(chunk)
    os.close(r)
    assert status is not None, f"the write ran past {timeout} s"
    text = b"".join(chunks).decode()
    assert os.waitstatus_to_exitcode(status) == 3, text
    return text


def closed_slabs(count, width, thickness, spacing, tilt_degrees, first_centre):
    """A stack of ``count`` closed boxes ``width`` x ``thickness`` x 0.6 (one
    trimesh), turned ``tilt_degrees`` about z, the first centred at
    ``first_centre`` and each next one ``spacing`` further along y: slats
    modelled as slabs, as interiors model blinds."""
    t = np.radians(tilt_degrees)
    frame = np.eye(4)
    frame[:3, 0] = [np.cos(t), np.sin(t), 0.0]
    frame[:3, 1] = [-np.sin(t), np.cos(t), 0.0]
    slabs = []
    for i in range(count):
        b = trimesh.creation.box(extents=[width, thickness, 0.6])
        b.apply_transform(frame)
        b.apply_translation(np.asarray(first_centre, float) + np.array([0.0, spacing * i, 0.0]))
        slabs.append(b)
    return trimesh.util.concatenate(slabs)


def quad(corners) -> trimesh.Trimesh:
    """The quad with these four corners, two triangles wound 0-1-2, 0-2-3."""
    return trimesh.Trimesh(np.asarray(corners, float), [[0, 1, 2], [0, 2, 3]], process=False)


def irradiance_from_quad(x, n, corners) -> float:
    """Irradiance at point x (unit normal n) from a quad of unit radiance
    wholly in front of it: Lambert's polygon formula, ½ Σ β_i (γ_i · n)."""
    v = [np.asarray(c, float) - x for c in corners]
    v = [a / np.linalg.norm(a) for a in v]
    total = 0.0
    for a, b in zip(v, v[1:] + v[:1], strict=True):
        g = np.cross(a, b)
        total += math.acos(np.clip(np.dot(a, b), -1.0, 1.0)) * np.dot(g / np.linalg.norm(g), n)
    return 0.5 * abs(total)
