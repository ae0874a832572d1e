"""Reuse across campaigns: a second campaign of the same results root takes the runs the first
finished in place (links, no copy, nothing recomputed) and its results equal a fresh
computation; a longer run continues another campaign's shorter run of its trajectory; the
dry-run says where runs come from; a reused file that goes away is run again."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
import xarray as xr
from sweep_helpers import file_stamps, run_ids, write_campaign
from typer.testing import CliRunner

from nematic_solids.sweep.catalogue import location, open_catalogue
from nematic_solids.sweep.cli import app


@pytest.fixture(autouse=True)
def no_env(monkeypatch):
    monkeypatch.delenv(location.ENV, raising=False)


def nematic(*args: str) -> str:
    result = CliRunner().invoke(app, [str(a) for a in args])
    assert result.exit_code in (0, 1), result.output
    return result.output


def phase(results: Path, name: str) -> xr.Dataset:
    with xr.open_dataset(results / name / "phase.nc") as ds:
        return ds.load()


@pytest.fixture(scope="module")
def two(tmp_path_factory):
    """Campaign ``first`` (2 values x 2 seeds), then ``second`` (3 values x 3 seeds) in the
    same root; ``fresh``: ``second`` alone in another root."""
    folder = tmp_path_factory.mktemp("reuse")
    results = folder / "results"
    first = write_campaign(folder, "first", values="[0.1, 0.2]", seeds=2, t_final=1.0)
    second = write_campaign(folder, "second", values="[0.1, 0.2, 0.3]", seeds=3, t_final=1.0)
    nematic("run", first, "--results", results)
    before = file_stamps(results / "first" / "runs")
    dry = nematic("run", second, "--results", results, "--dry-run")
    out = nematic("run", second, "--results", results)
    fresh = folder / "fresh"
    nematic("run", second, "--results", fresh)
    return folder, results, first, second, before, dry, out, fresh


def test_the_second_campaign_recomputes_nothing_the_first_has(two):
    _, results, first, second, before, dry, out, _ = two
    shared = set(run_ids(first)) & set(run_ids(second))
    assert len(shared) == 4  # alpha - B 0.1 and 0.2, seeds 0 and 1
    runs = results / "second" / "runs"
    for rid in shared:
        link = runs / f"{rid}.nc"
        assert link.is_symlink()  # in place: no copy of the file
        assert link.resolve() == (results / "first" / "runs" / f"{rid}.nc").resolve()
        assert not os.path.isabs(os.readlink(link))  # relative: the root can move
        assert json.loads((runs / f"{rid}.json").read_text())["reused_from"] == "first"
    assert file_stamps(results / "first" / "runs") == before  # the first's files untouched
    made = {p.stem for p in runs.glob("*.nc") if not p.is_symlink()}
    assert made == set(run_ids(second)) - shared  # only the others ran
    assert "reused 4 finished run(s): 4 from first" in dry
    assert "4 to do" not in dry
    assert "5 to do" in dry
    assert "4 from first" in out


def test_status_and_the_report_say_where_runs_came_from(two):
    _, results, _, second, *_ = two
    status = nematic("status", second, "--results", results)
    assert "4 done run(s) made by other campaigns, taken in place: 4 from first" in status
    nematic("report", second, "--results", results)
    page = (results / "second" / "report.html").read_text()
    assert "4 of the done runs were made by other campaigns: 4 by first" in page


def test_reused_results_equal_a_fresh_computation(two):
    _, results, _, _, _, _, _, fresh = two
    got, want = phase(results, "second"), phase(fresh, "second")
    for name in ("sigma2_S", "run_id", "status"):
        xr.testing.assert_equal(got[name], want[name])


def test_the_catalogue_says_who_made_and_who_reused(two):
    _, results, first, second, *_ = two
    cat = open_catalogue(results)
    camps = cat.campaigns().set_index("name")
    assert camps.loc["first", "made"] == 4
    assert camps.loc["second", "reused"] == 4
    assert camps.loc["second", "made"] == 5
    rid = sorted(set(run_ids(first)) & set(run_ids(second)))[0]
    one = cat.run(rid)
    assert one is not None
    held = {m["campaign"]: m["origin"] for m in one["campaigns"]}
    assert held == {"first": "made", "second": "reused"}
    assert one["path"] == f"first/runs/{rid}.nc"
    cat.close()


@pytest.mark.slow
def test_a_reused_file_that_went_away_is_run_again(two, tmp_path):
    import shutil

    folder, results, first, second, *_ = two
    root = tmp_path / "results"
    shutil.copytree(results, root, symlinks=True)
    rid = sorted(set(run_ids(first)) & set(run_ids(second)))[0]
    (root / "first" / "runs" / f"{rid}.nc").unlink()
    (root / "first" / "runs" / f"{rid}.json").unlink()
    out = nematic("run", second, "--results", root)
    assert "1 to run" in out
    made = root / "second" / "runs" / f"{rid}.nc"
    assert made.exists()
    assert not made.is_symlink()
    assert "reused_from" not in json.loads(made.with_suffix(".json").read_text())


@pytest.mark.slow
def test_a_longer_run_continues_another_campaigns_run(two, tmp_path):
    """``longer`` is ``first`` to t = 2: each run continues first's run of its trajectory
    from t = 1 and equals a straight run to t = 2."""
    folder, results, *_ = two
    import shutil

    root = tmp_path / "results"
    shutil.copytree(results, root, symlinks=True)
    longer = write_campaign(tmp_path, "longer", values="[0.1]", seeds=1, t_final=2.0)
    nematic("run", longer, "--results", root)
    rid = run_ids(longer)[0]
    record = json.loads((root / "longer" / "runs" / f"{rid}.json").read_text())
    assert record["started_at"] == pytest.approx(1.0)
    first_id = record["continued_from"]
    assert (root / "first" / "runs" / f"{first_id}.nc").exists()
    straight = tmp_path / "straight"
    nematic("run", longer, "--results", straight)
    want = json.loads((straight / "longer" / "runs" / f"{rid}.json").read_text())
    assert want["started_at"] == 0.0
    assert record["scalars"]["sigma2_S_final"] == want["scalars"]["sigma2_S_final"]
    cat = open_catalogue(root)
    assert (first_id, "continued") in cat.lineage(rid)
    cat.close()


def test_a_run_begun_from_a_snapshot_looks_for_its_own_trajectory():
    """The catalogue looks for the trajectory the run task records: a run begun from another
    run's snapshot (``state: snapshot``) is not taken for one begun from its exact end state."""
    from types import SimpleNamespace

    from nematic_solids.model.parameters import Numerics, Parameters
    from nematic_solids.sweep.catalogue.reuse import trajectories
    from nematic_solids.sweep.identity import identity_start, trajectory_id

    parameters, numerics = Parameters(), Numerics(resolution=16, t_final=1.0)
    starts = [
        {"run": "a" * 16, "time": "end"},
        {"run": "a" * 16, "time": "end", "state": "snapshot"},
    ]
    runs = [
        SimpleNamespace(
            point=SimpleNamespace(parameters=parameters, numerics=numerics), seed=0, start=s
        )
        for s in starts
    ]
    expansion = SimpleNamespace(run=runs.__getitem__, campaign=SimpleNamespace(model="nematic"))
    found = trajectories(expansion, [0, 1])  # type: ignore[arg-type]
    recorded = [
        trajectory_id(parameters.to_dict(), numerics.to_dict(), 0, identity_start(s))
        for s in starts
    ]
    assert [found[0], found[1]] == recorded
    assert found[0] != found[1]
