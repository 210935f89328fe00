"""Shared fixtures: a seeded RNG and small scenes built once per run; the
paper's solve settings with changes (:func:`paper`)."""

from __future__ import annotations

import dataclasses
import signal

import numpy as np
import pytest

import voxgi


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
