"""Chains (nematic_solids.sweep.chains): an axis walked in order, each run starting from its
predecessor's end state. The section checked at file:line; the ids and parents of both branches; a
chain campaign whose every run begins from its predecessor's fields (equal to the model's run from
them, bit for bit); a chain stopped half-way (runs lost, or the driver killed) resumes where it
stopped and ends with the same results; a run whose predecessor failed fails with the reason
parent_failed and is redone with it."""

from __future__ import annotations

import base64
import os
import random
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from sweep_helpers import kill_group, records, start_driver, wait_for, wait_group_gone
from typer.testing import CliRunner

from nematic_solids.model.checkpoint import RunState, read_netcdf
from nematic_solids.model.simulate import run as simulate
from nematic_solids.sweep.analysis.fits_file import write_fits
from nematic_solids.sweep.cli import app
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.figures.produce import draw
from nematic_solids.sweep.run.continuation import STATE_GROUP, parent_fields
from nematic_solids.sweep.spec import parse_campaign

LOOP = """\
name: {name}
parameters: {{noise_modes: 8}}
numerics: {{resolution: 32, t_final: {t_final}, save_every: 1}}
sweep:
  axes:
    alpha_minus_B: {values}
chain: {{axis: alpha_minus_B{branches}}}
seeds: {seeds}
execution: {{workers: 2}}
"""


def loop(name="loop", values="[0.1, 0.8, 0.4]", branches="", seeds=2, t_final=6) -> str:
    return LOOP.format(name=name, values=values, branches=branches, seeds=seeds, t_final=t_final)


def write(folder: Path, text: str, name: str = "loop") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.yaml"
    path.write_text(text)
    return path


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


def test_each_run_of_a_branch_starts_from_its_predecessor():
    e = expand(parse_campaign(loop()))
    c = e.campaign
    assert [d.name for d in c.dims] == ["branch", "alpha_minus_B"]
    assert c.shape == (2, 3)
    by_coords = {(r.coords["branch"], r.coords["alpha_minus_B"], r.seed): r for r in e}
    for branch, order in (("up", [0.1, 0.4, 0.8]), ("down", [0.8, 0.4, 0.1])):
        for seed in (0, 1):
            chain = [by_coords[(branch, v, seed)] for v in order]
            assert chain[0].start is None  # the first value: from the seeded texture
            for before, after in zip(chain, chain[1:], strict=False):
                assert after.start == {"run": before.run_id, "time": "end", "campaign": "loop"}
    # the first run of a branch is the plain run of that point (a campaign without a chain)
    plain = expand(parse_campaign(loop().replace("chain: {axis: alpha_minus_B}\n", "")))
    firsts = {r.run_id for r in e if r.start is None}
    assert firsts == {r.run_id for r in plain if r.coords["alpha_minus_B"] in (0.1, 0.8)}
    assert len(set(e.run_ids)) == len(e) == 12
    one = expand(parse_campaign(loop(branches=", branches: down")))
    assert one.campaign.shape == (1, 3)
    assert {r.run_id for r in one} == {r.run_id for r in e if r.coords["branch"] == "down"}


ZIPPED = loop().replace(
    "    alpha_minus_B: [0.1, 0.8, 0.4]\n",
    "    alpha_minus_B: [0.1, 0.8]\n    chi: [1, 2]\n  zip: [[alpha_minus_B, chi]]\n",
)


@pytest.mark.parametrize(
    ("text", "says"),
    [
        (loop().replace("axis: alpha_minus_B", "axis: chi"), "a swept axis"),
        (loop(values="[0.4]"), "an axis of two or more numbers"),
        (loop(branches=", branches: [up, sideways]"), "up, down or [up, down]"),
        (loop() + "verify: {variants: [{resolution: x2}]}\n", "a chain has no verify section"),
        (ZIPPED, "an axis of its own (not in a zip group)"),
    ],
)
def test_a_chain_mistake_is_reported_at_its_line(text, says):
    with pytest.raises(CampaignError) as err:
        parse_campaign(text, source="loop.yaml")
    assert says in str(err.value), str(err.value)
    assert "loop.yaml:" in str(err.value)


GRID = (
    loop()
    .replace("alpha_minus_B: [0.1, 0.8, 0.4]", "resolution: [32, 64]")
    .replace("axis: alpha_minus_B", "axis: resolution")
    .replace("resolution: 32, ", "")
)


@pytest.mark.parametrize(
    ("text", "line", "says"),
    [
        (GRID, 7, "would change the grid between a run and the next"),
        (loop() + "store: {snapshot_dtype: float32, end_state: false}\n", 10, "exact end state"),
        (loop() + "store:\n  snapshot_fields: [q1, q2]\n  end_state: false\n", 12, "end_state"),
        (loop().replace("axis: alpha_minus_B", "axis: [alpha_minus_B, K]"), 7, "one swept axis"),
    ],
)
def test_a_chain_that_could_not_feed_its_runs_is_refused_at_its_line(text, line, says):
    """A chain along the grid (the successor's fields would be another shape), or whose store
    keeps no end state (a successor would begin from a snapshot: float32, or without A), is
    refused before anything runs, at the line that makes it so."""
    with pytest.raises(CampaignError) as err:
        parse_campaign(text, source="loop.yaml")
    (problem,) = err.value.problems
    assert problem.location == f"loop.yaml:{line}", str(err.value)
    assert says in problem.message


def _assert_chained_runs(results: Path, text: str) -> dict[str, np.ndarray]:
    """Every chained run's file equals the model's run from its predecessor's end state."""
    e = expand(parse_campaign(text))
    runs = results / "loop" / "runs"
    out = {}
    for spec in e:
        path = next(runs.rglob(f"{spec.run_id}.nc"))
        with xr.open_dataset(path) as ds:
            out[spec.run_id] = ds.sigma2_S.values.copy()
            if spec.start is None:
                assert ds.attrs["initial_from"] == ""
                continue
            assert ds.attrs["initial_from"] == f"loop/{spec.start['run']}@end"
        # the predecessor's end state (its fields, the displacement of its last snapshot)
        source = {**spec.start, "runs_dir": str(runs)}
        initial = parent_fields(source)
        end = RunState.from_dataset(read_netcdf(runs / f"{spec.start['run']}.nc", STATE_GROUP))
        assert np.array_equal(initial.fields, end.fields)
        ref = simulate(spec.point.parameters, spec.point.numerics, spec.seed, initial=initial)
        assert np.array_equal(ref.sigma2_S.values, out[spec.run_id])
    return out


@pytest.mark.slow  # 12-20 s; CI runs it with the slow tests
def test_a_chain_campaign_runs_and_resumes_where_it_stopped(tmp_path):
    text = loop()
    path = write(tmp_path, text)
    results = tmp_path / "results"
    assert invoke("run", path, "--results", results).exit_code == 0
    first = _assert_chained_runs(results, text)
    phase = xr.open_dataset(results / "loop" / "phase.nc")
    assert list(phase.branch.values) == ["up", "down"]
    assert phase.sigma2_S.dims == ("branch", "alpha_minus_B", "seed")
    # half of every chain lost: the campaign goes on from the runs that are there
    e = expand(parse_campaign(text))
    firsts = {"up": 0.1, "down": 0.8}
    lost = [r.run_id for r in e if r.coords["alpha_minus_B"] != firsts[r.coords["branch"]]]
    for rid in lost:
        for f in (results / "loop" / "runs").rglob(f"{rid}.*"):
            f.unlink()
    result = invoke("run", path, "--results", results)
    assert result.exit_code == 0, result.output
    assert f"{len(lost)} to run" in result.output
    again = _assert_chained_runs(results, text)
    assert again.keys() == first.keys()
    assert all(np.array_equal(again[k], first[k]) for k in first)


def test_a_run_whose_predecessor_failed_fails_with_the_reason_and_is_redone(tmp_path):
    text = loop(values="[0.3, 30]", branches=", branches: down", seeds=1)
    path = write(tmp_path, text)
    results = tmp_path / "results"
    invoke("run", path, "--results", results)
    recs = {r["coords"]["alpha_minus_B"]: r for r in records(results / "loop" / "runs").values()}
    assert recs[30.0]["status"] == "failed"
    assert recs[30.0]["reason"] == "ellipticity_lost"
    assert recs[0.3]["status"] == "failed"
    assert recs[0.3]["reason"] == "parent_failed"
    assert "did not end (status failed: ellipticity_lost)" in recs[0.3]["detail"]
    # rerun: the run whose predecessor failed is redone (and fails again: it did not end)
    result = invoke("run", path, "--results", results)
    assert "1 to run" in result.output, result.output


@pytest.mark.slow
def test_a_chain_driver_killed_half_way_resumes(tmp_path):
    text = loop(t_final=30, seeds=1, values="[0.1, 0.4, 0.8]")
    path = write(tmp_path, text)
    results = tmp_path / "results"
    runs = results / "loop" / "runs"
    proc = start_driver(["run", str(path), "--results", str(results)], tmp_path / "driver.log")
    try:
        wait_for(lambda: runs.is_dir() and len(records(runs)) >= 3, 300, "three runs done")
    finally:
        kill_group(proc)
    assert 3 <= len(records(runs)) < 6
    result = invoke("run", path, "--results", results)
    assert result.exit_code == 0, result.output
    _assert_chained_runs(results, text)


@pytest.mark.slow
def test_a_chain_driver_killed_at_random_moments_ends_as_an_uninterrupted_one(tmp_path):
    """SIGKILL of the driver and its workers twice, each at a random moment (after a random
    number of runs is done, then a random delay: mid-run, mid-checkpoint, mid-write), then a
    run to the end: every array of every run (the successors begun from their predecessors' end
    states, some continued from checkpoints) is bit-identical to an uninterrupted campaign's."""
    rng = random.Random(f"chain-kill-{os.getpid()}")
    text = loop(t_final=20, seeds=1, values="[0.1, 0.4, 0.8]") + "store: {checkpoint_every: 2}\n"
    reference = tmp_path / "reference"
    assert invoke("run", write(reference, text), "--results", reference / "results").exit_code == 0
    killed = tmp_path / "killed"
    path = write(killed, text)
    results = killed / "results"
    runs = results / "loop" / "runs"
    for attempt in range(2):
        done = len(records(runs)) if runs.is_dir() else 0
        wanted = done + rng.randint(0, 2)
        log = killed / f"driver{attempt}.log"
        proc = start_driver(["run", str(path), "--results", str(results), "--no-figures"], log)
        try:
            wait_for(
                lambda wanted=wanted, proc=proc: (
                    (runs.is_dir() and len(records(runs)) >= wanted) or proc.poll() is not None
                ),
                300,
                f"{wanted} runs done",
                interval=0.05,
            )
            time.sleep(rng.uniform(0.0, 1.5))
        finally:
            kill_group(proc)
        wait_group_gone(proc.pid)
        if attempt == 0:  # at most two runs and 1.5 s in: the chains are not through
            assert len(records(runs)) < 6 if runs.is_dir() else True
    result = invoke("run", path, "--results", results, "--no-figures")
    assert result.exit_code == 0, result.output
    _assert_chained_runs(results, text)
    want_runs = reference / "results" / "loop" / "runs"
    assert {p.name for p in runs.glob("*.nc")} == {p.name for p in want_runs.glob("*.nc")}
    for got in runs.glob("*.nc"):
        with xr.open_dataset(got) as a, xr.open_dataset(want_runs / got.name) as b:
            for name in a.data_vars:
                if name != "wall_time":
                    assert np.array_equal(a[name].values, b[name].values, equal_nan=True), name


def test_the_loop_figure_and_the_loop_width(tmp_path):
    text = loop(values="[0.1, 0.4, 0.8]", t_final=20)
    text += "fits: [{transition: {axis: alpha_minus_B, min_jump: 0.5}}]\n"
    path = write(tmp_path, text)
    results = tmp_path / "results"
    assert invoke("run", path, "--results", results).exit_code == 0
    root = results / "loop"
    assert (root / "figures" / "loop.png").stat().st_size > 10_000
    assert not (root / "figures" / "fig2.png").exists()  # fig2 is a plain sweep's figure
    page = (root / "report.html").read_text()
    assert "<th>chain</th><td>along alpha_minus_B on the branches up, down" in page
    png = base64.b64encode((root / "figures" / "loop.png").read_bytes()).decode("ascii")
    assert png in page  # the figure is on the page
    fits = xr.open_dataset(root / "fits.nc")
    up, down = (fits.sel(branch=b) for b in ("up", "down"))
    width = float(fits["transition_loop_width"])
    assert width > 0  # at 32^2 already: the down branch keeps its pattern below the up's jump
    assert width == pytest.approx(float(up.transition_location - down.transition_location))
    assert float(fits["transition_loop_width_lower"]) == pytest.approx(
        float(up.transition_lower - down.transition_upper)
    )
    phase = xr.open_dataset(root / "phase.nc")
    assert phase.attrs["chain_axis"] == "alpha_minus_B"
    assert phase.attrs["chain_branches"] == "up, down"
    # compared with a plain sweep's jump (here the up branch as a campaign of its own)
    plain = results / "plain"
    plain.mkdir()
    phase.sel(branch="up", drop=True).to_netcdf(plain / "phase.nc")
    write_fits(plain, [("transition", {"min_jump": 0.5})])
    jump = xr.open_dataset(plain / "fits.nc")
    assert float(jump.transition_location) == float(up.transition_location)
    paths = draw("loop", root, {"compare": "plain"})
    assert paths[0].stat().st_size > 10_000
