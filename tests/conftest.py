"""Shared fixtures: a seeded rng, floating-point errors raised in every test, the small real
campaign run once per session (campaign-manager tests)."""

from __future__ import annotations

import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20250407)


@pytest.fixture(autouse=True)
def raise_fp_errors(request):
    """Floating-point errors raise in every test: division by zero, overflow and invalid
    operations are ``FloatingPointError`` (underflow to zero is not an error). Code that
    expects them says so locally with ``np.errstate``; a test that feeds non-finite or
    degenerate data on purpose opts out with ``@pytest.mark.allow_fp_errors("why")``."""
    marker = request.node.get_closest_marker("allow_fp_errors")
    if marker is not None:
        if not (marker.args and str(marker.args[0]).strip()):
            pytest.fail("@pytest.mark.allow_fp_errors needs a reason")
        yield
        return
    with np.errstate(divide="raise", over="raise", invalid="raise", under="ignore"):
        yield


@pytest.fixture(scope="session")
def small(tmp_path_factory):
    """The small campaign (3 alpha - B values x 2 seeds, one value failing), run once."""
    from sweep_helpers import run_ids, write_campaign
    from typer.testing import CliRunner

    from nematic_solids.sweep.cli import app

    folder = tmp_path_factory.mktemp("small")
    path = write_campaign(folder)
    result = CliRunner().invoke(app, ["run", str(path), "--results", str(folder / "results")])
    return SimpleNamespace(
        path=path,
        results=folder / "results",
        result=result,
        runs=folder / "results" / "small" / "runs",
        ids=run_ids(path),
    )


@pytest.fixture
def copy_of_small(small, tmp_path):
    """A private copy of the small campaign's results (for tests that change them)."""
    shutil.copytree(small.results, tmp_path / "results", symlinks=True)
    path = shutil.copy(small.path, tmp_path / "small.yaml")
    return SimpleNamespace(
        path=Path(path),
        results=tmp_path / "results",
        runs=tmp_path / "results" / "small" / "runs",
        ids=small.ids,
        phase=tmp_path / "results" / "small" / "phase.nc",
    )
