"""Shared fixtures: a seeded rng, floating-point errors raised in model code paths."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20250407)


@pytest.fixture
def raise_fp_errors():
    """``np.seterr(all="raise")`` for the duration of a test (the model must not produce
    overflow/invalid operations on healthy inputs)."""
    old = np.seterr(all="raise")
    yield
    np.seterr(**old)
