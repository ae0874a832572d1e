"""Shared fixtures: a seeded rng, floating-point errors raised in model code paths, the
small real campaign run once per session (campaign-manager tests)."""

from __future__ import annotations

import shutil
from pathlib import Path
from types import SimpleNamespace

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


@pytest.fixture(scope="session")
def small(tmp_path_factory):
    """The small campaign (3 alpha - B values x 2 seeds, one value failing), run once."""
    from sweep_helpers import run_ids, write_campaign
    from typer.testing import CliRunner

    from sweep.cli import app

    folder = tmp_path_factory.mktemp("small")
    path = write_campaign(folder)
    result = CliRunner().invoke(app, ["run", str(path), "--results", str(folder / "results")])
    return SimpleNamespace(path=path, results=folder / "results", result=result,
                           runs=folder / "results" / "small" / "runs", ids=run_ids(path))


@pytest.fixture
def copy_of_small(small, tmp_path):
    """A private copy of the small campaign's results (for tests that change them)."""
    shutil.copytree(small.results, tmp_path / "results", symlinks=True)
    path = shutil.copy(small.path, tmp_path / "small.yaml")
    return SimpleNamespace(path=Path(path), results=tmp_path / "results",
                           runs=tmp_path / "results" / "small" / "runs", ids=small.ids,
                           phase=tmp_path / "results" / "small" / "phase.nc")
