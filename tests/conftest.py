"""Shared fixtures: a seeded RNG and small scenes built once per run."""

from __future__ import annotations

import numpy as np
import pytest

import voxgi


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def cornell():
    return voxgi.scenes.cornell_box(width=64, height=64)
