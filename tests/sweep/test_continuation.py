"""Runs that go on (nematic_solids.sweep.run.continuation): a worker or a driver SIGKILLed at random
points resumes each run from its rolling checkpoint with a result equal, array by array, to the run
that never stopped; a campaign whose t_final grew continues its finished runs from their end states
(recomputing nothing); a corrupt or foreign checkpoint is ignored with a warning;
``store.checkpoint_every`` is read and checked."""

from __future__ import annotations

import json
import os
import pickle
import random
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from sweep_helpers import (
    file_stamps,
    kill_group,
    records,
    start_driver,
    wait_for,
    wait_group_gone,
)
from typer.testing import CliRunner

from nematic_solids.model.checkpoint import RunState, Schedule, load
from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.model.simulate import run as simulate
from nematic_solids.sweep.cli import app
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.run.continuation import STATE_GROUP, checkpoint_path
from nematic_solids.sweep.run.task import RunTask, execute_run
from nematic_solids.sweep.spec import load_campaign
from nematic_solids.sweep.store import CampaignStore

CAMPAIGN = """\
name: {name}
description: continuation test
parameters: {{noise_modes: 8}}
numerics: {{resolution: {n}, t_final: {t_final}, save_every: {save}, mechanics: {mechanics},
           snapshot_times: [{snap}]}}
sweep:
  axes:
    alpha_minus_B: {values}
seeds: {seeds}
store: {{checkpoint_every: {every}}}
execution: {{workers: 2}}
"""


def campaign(folder: Path, name: str, **kw) -> Path:
    values = dict(
        n=32, t_final=300, save=5, mechanics="finite", snap=100, values="[0.3]", seeds=1, every=1
    )
    values.update(kw)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.yaml"
    path.write_text(CAMPAIGN.format(name=name, **values))
    return path


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


def straight(task: RunTask) -> xr.Dataset:
    """The run as one uninterrupted simulation."""
    return simulate(
        Parameters.from_dict(task.parameters), Numerics.from_dict(task.numerics), task.seed
    )


def assert_equal_runs(ref: xr.Dataset, path: Path) -> None:
    """Every array of the run file equal to the straight run's, bit for bit, and its steps."""
    with xr.open_dataset(path) as ds:
        for name in ref.data_vars:
            if name != "wall_time":
                assert np.array_equal(ref[name].values, ds[name].values, equal_nan=True), name
        for key in ("solver_steps", "solver_rejected", "solver_rhs", "solver_newton"):
            assert int(ds.attrs[key]) == int(ref.attrs[key]), key


def tasks_of(path: Path, results: Path) -> tuple[CampaignStore, list[RunTask]]:
    c = load_campaign(path)
    expansion = expand(c)
    store = CampaignStore(results, c.name)
    store.ensure()
    return store, [
        RunTask.from_spec(expansion.run(i), store, c.name, c.store) for i in range(len(expansion))
    ]


#: a worker process that runs one task (what a dask worker does with it)
WORKER = (
    "import pickle, sys\n"
    "from nematic_solids.sweep.run.task import execute_run\n"
    "execute_run(pickle.load(open(sys.argv[1], 'rb')))\n"
)


@pytest.mark.parametrize(
    ("mechanics", "n"), [("finite", 32), ("linear", 64)], ids=["finite", "linear"]
)
def test_a_worker_killed_at_random_points_resumes_exactly(tmp_path, mechanics, n):
    """SIGKILL of the worker process twice, each at a random moment after its run has
    written a checkpoint (mid-step, mid-save or mid-write), then a third worker finishes:
    every array equals the straight run's."""
    rng = random.Random(f"{mechanics}-{os.getpid()}")
    store, (task,) = tasks_of(
        campaign(tmp_path, f"kill-{mechanics}", mechanics=mechanics, n=n), tmp_path / "results"
    )
    pickled = tmp_path / "task.pickle"
    pickled.write_bytes(pickle.dumps(task))
    ckpt = checkpoint_path(store, task.run_id)
    resumed_from = []
    for _ in range(2):
        before = ckpt.stat().st_mtime_ns if ckpt.exists() else None
        proc = subprocess.Popen([sys.executable, "-c", WORKER, str(pickled)])
        try:
            # a new checkpoint of this worker, then a random moment
            wait_for(
                lambda before=before: ckpt.exists() and ckpt.stat().st_mtime_ns != before,
                120,
                "a checkpoint",
                interval=0.01,
            )
            time.sleep(rng.uniform(0.0, 0.25))
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=10)
        finally:
            if proc.poll() is None:
                proc.kill()
        assert not store.nc_path(task.run_id).exists(), "the run finished before the kill"
        resumed_from.append(load(ckpt).t)
    record = execute_run(task)
    assert record["status"] == "ok", record
    lineage = record["lineage"]
    assert lineage
    assert all(e.startswith("checkpoint@") for e in lineage)
    assert float(lineage[-1].split("@")[1]) == resumed_from[-1]
    assert record["started_at"] == resumed_from[-1] > 0
    assert not ckpt.exists()  # folded into the run file as its end state
    assert_equal_runs(straight(task), store.nc_path(task.run_id))


@pytest.mark.slow  # 12-20 s; CI runs it with the slow tests
def test_sigkill_of_the_driver_and_its_workers_then_resume(tmp_path):
    path = campaign(tmp_path, "driver", values="[0.2, 0.3]", seeds=1)
    results = tmp_path / "results"
    store, tasks = tasks_of(path, results)
    checkpoints = store.root / "checkpoints"
    proc = start_driver(
        ["run", str(path), "--results", str(results), "--no-figures"], tmp_path / "log"
    )
    try:
        wait_for(
            lambda: (
                (checkpoints.exists() and any(checkpoints.glob("*.nc"))) or proc.poll() is not None
            ),
            120,
            "a checkpoint",
            interval=0.01,
        )
        assert proc.poll() is None, (tmp_path / "log").read_text()
        time.sleep(0.3)
    finally:
        kill_group(proc)  # SIGKILL: the driver and its local workers at once
    # a killed process ends the system call it is in (a checkpoint's rename): read after
    wait_group_gone(proc.pid)
    in_progress = {p.stem: load(p).t for p in checkpoints.glob("*.nc")}
    assert in_progress
    status = json.loads(invoke("status", path, "--results", results, "--json").output)
    assert status["done"] + status["pending"] == 2
    shown = {r["run_id"]: r for r in status["in_progress"]}
    assert set(shown) == set(in_progress)
    for rid, t in in_progress.items():
        assert shown[rid]["t"] == t
        assert shown[rid]["t_final"] == 300
        assert shown[rid]["checkpoint"] == str(store.checkpoint_path(rid))
    text = " ".join(invoke("status", path, "--results", results).output.split())
    assert "pending run(s) with a checkpoint" in text
    assert f"t = {next(iter(in_progress.values())):.6g} of 300" in text
    result = invoke("run", path, "--results", results, "--no-figures")
    assert result.exit_code == 0, result.output
    recs = records(store.runs_dir)
    for task in tasks:
        rec = recs[task.run_id]
        if task.run_id in in_progress:
            assert rec["lineage"][-1] == f"checkpoint@{in_progress[task.run_id]:.12g}"
        assert_equal_runs(straight(task), store.nc_path(task.run_id))
    assert not list(checkpoints.glob("*"))


@pytest.mark.slow  # 12-20 s; CI runs it with the slow tests
def test_a_campaign_whose_t_final_grew_continues_its_runs(tmp_path):
    kw = dict(n=32, t_final=5, save=0.5, snap=1, values="[0.1, 0.2]", seeds=2)
    path = campaign(tmp_path, "grow", **kw)
    results = tmp_path / "results"
    assert invoke("run", path, "--results", results, "--no-figures").exit_code == 0
    runs = results / "grow" / "runs"
    short = records(runs)
    assert len(short) == 4
    assert all(r["end_state"] == 5.0 for r in short.values())
    stamps = file_stamps(runs)
    path.write_text(path.read_text().replace("t_final: 5,", "t_final: 10,"))
    dry = " ".join(invoke("run", path, "--results", results, "--dry-run").output.split())
    assert "4 new (4 continue a finished shorter run from its end state)" in dry, dry
    assert "the rest of a run from t = 5" in dry, dry
    result = invoke("run", path, "--results", results, "--no-figures")
    assert result.exit_code == 0, result.output
    after = records(runs)
    longer = {rid: r for rid, r in after.items() if rid not in short}
    assert len(longer) == 4
    by_trajectory = {r["trajectory"]: rid for rid, r in short.items()}
    for rec in longer.values():
        parent = by_trajectory[rec["trajectory"]]
        assert rec["continued_from"] == parent
        assert rec["started_at"] == 5.0
        assert rec["lineage"] == [f"{parent}@5"]
        assert rec["end_state"] == 10.0
    assert {k: v for k, v in file_stamps(runs).items() if k in short} == stamps  # untouched
    # the same runs straight to 10, in another results folder: equal array by array
    other = tmp_path / "straight"
    assert invoke("run", path, "--results", other, "--no-figures").exit_code == 0
    for rid in longer:
        with xr.open_dataset(other / "grow" / "runs" / f"{rid}.nc") as ref:
            assert_equal_runs(ref.load(), runs / f"{rid}.nc")
    # the aggregate reads each run at the campaign's t_final
    with xr.open_dataset(results / "grow" / "phase.nc") as phase:
        assert float(phase.attrs.get("num_t_final", 10.0)) == 10.0


def test_a_corrupt_or_foreign_checkpoint_is_ignored_with_a_warning(tmp_path):
    path = campaign(
        tmp_path, "bad", t_final=10, save=2.5, snap=5, values="[0.2, 0.3]", every="false"
    )
    results = tmp_path / "results"
    store, (a, b) = tasks_of(path, results)
    # a checkpoint of run a, planted as run b's; garbage as run a's
    states: list[RunState] = []
    simulate(
        Parameters.from_dict(a.parameters),
        Numerics.from_dict(a.numerics),
        a.seed,
        checkpoint=states.append,
        schedule=Schedule(tau=5.0),
    )
    checkpoint_path(store, b.run_id).parent.mkdir(parents=True)
    states[0].to_dataset().to_netcdf(checkpoint_path(store, b.run_id))
    checkpoint_path(store, a.run_id).write_bytes(b"CDF\x01 not really a checkpoint")
    result = invoke("run", path, "--results", results, "--no-figures")
    assert result.exit_code == 0, result.output
    recs = records(store.runs_dir)
    assert "not a readable netCDF" in recs[a.run_id]["start_warning"]
    assert "not this run's state" in recs[b.run_id]["start_warning"]
    for task in (a, b):
        assert recs[task.run_id]["started_at"] == 0.0
        assert not checkpoint_path(store, task.run_id).exists()
        assert_equal_runs(straight(task), store.nc_path(task.run_id))
        with xr.open_dataset(store.nc_path(task.run_id), group=STATE_GROUP) as state:
            assert float(state.attrs["t"]) == 10.0


def test_store_checkpoint_every_is_read_and_checked(tmp_path):
    def store_of(text: str):
        p = tmp_path / "c.yaml"
        p.write_text(textwrap.dedent(f"name: c\nnumerics: {{resolution: 128}}\n{text}"))
        return load_campaign(p).store

    default = store_of("")
    assert (default.checkpoint_tau, default.checkpoint_wall, default.end_state) == (
        np.inf,
        600.0,
        True,
    )
    assert store_of("store: {checkpoint_every: 25}\n").checkpoint_tau == 25.0
    assert store_of("store: {checkpoint_every: 2 min}\n").checkpoint_wall == 120.0
    assert store_of("store: {checkpoint_every: 30 s}\n").checkpoint_wall == 30.0
    off = store_of("store: {checkpoint_every: false, end_state: false}\n")
    assert (off.checkpoint_tau, off.checkpoint_wall, off.end_state) == (np.inf, np.inf, False)
    for bad in ("0", "-3", "ten minutes", "5 weeks", "true"):
        p = tmp_path / "bad.yaml"
        p.write_text(f"name: c\nnumerics: {{resolution: 128}}\nstore:\n  checkpoint_every: {bad}\n")
        with pytest.raises(CampaignError, match=f"{p}:4: store.checkpoint_every"):
            load_campaign(p)


# ------------------------------------------------------------- runs from another campaign's
PARENT = """\
name: parent
parameters: {noise_modes: 8}
numerics: {resolution: 32, t_final: 5, save_every: 0.5, snapshot_times: [2.5]}
sweep:
  axes:
    alpha_minus_B: [0.2, 0.3]
seeds: 2
execution: {workers: 2}
"""
CHILD = """\
name: {name}
parameters: {{noise_modes: 8, zeta: 0.0}}
numerics: {{resolution: 32, t_final: 2, save_every: 0.5, snapshot_times: [0]}}
sweep:
  axes:
    alpha_minus_B: [0.2, 0.3]
seeds: 2
execution: {{workers: 2}}
initial:
  from:
    campaign: parent.yaml
    seed: same
    time: {time}
"""


@pytest.mark.slow  # 12-20 s; CI runs it with the slow tests
def test_a_campaign_begins_from_another_campaigns_runs(tmp_path):
    """Activity switched off (zeta = 0) from the parent's end states and from its snapshots
    at t = 2.5: each child run begins with its parent run's fields, bit for bit, under its
    own parameters; its id names the parent run and the time; a child whose parents are not
    done is refused before it runs, naming the file and line."""
    (tmp_path / "parent.yaml").write_text(PARENT)
    end = tmp_path / "child.yaml"
    end.write_text(CHILD.format(name="child", time="end"))
    mid = tmp_path / "mid.yaml"
    mid.write_text(CHILD.format(name="mid", time="2.5"))
    results = tmp_path / "results"
    dry = invoke("run", end, "--results", results, "--dry-run")
    assert dry.exit_code == 0, dry.output
    assert "waiting: 4 run(s) of campaign parent" in " ".join(dry.output.split())
    early = invoke("run", end, "--results", results, "--no-figures")
    assert early.exit_code == 2, early.output
    said = " ".join(early.output.split())
    assert f"{end}:11: initial.from" in said
    assert "4 run(s) of campaign parent" in said
    assert "nematic run" in said
    assert not list((results / "child" / "runs").glob("*.nc"))  # nothing ran
    assert (
        invoke("run", tmp_path / "parent.yaml", "--results", results, "--no-figures").exit_code == 0
    )
    for path, time_text in ((end, "end"), (mid, "2.5")):
        result = invoke("run", path, "--results", results, "--no-figures")
        assert result.exit_code == 0, result.output
        child = load_campaign(path)
        expansion = expand(child)
        parent_runs = results / "parent" / "runs"
        for i, rid in enumerate(expansion.run_ids):
            run = expansion.run(i)
            assert run.start is not None
            assert run.start["time"] == time_text
            rec = json.loads((results / child.name / "runs" / f"{rid}.json").read_text())
            assert rec["status"] == "ok", rec
            assert rec["initial_from"] == f"parent/{run.start['run']}@{time_text}"
            with (
                xr.open_dataset(parent_runs / f"{run.start['run']}.nc") as parent,
                xr.open_dataset(results / child.name / "runs" / f"{rid}.nc") as ds,
            ):
                assert parent.attrs["seed"] == ds.attrs["seed"] == run.seed
                assert parent.attrs["param_alpha"] == ds.attrs["param_alpha"]
                at = -1 if time_text == "end" else 0  # the parent's end, or its t = 2.5
                for name in ("q1", "q2", "A"):
                    assert np.array_equal(parent[name].values[at], ds[name].values[0]), name
                assert float(ds.attrs["param_zeta"]) == 0.0
    ends, mids = expand(load_campaign(end)).run_ids, expand(load_campaign(mid)).run_ids
    plain = expand(load_campaign(_without_initial(tmp_path, end))).run_ids
    assert len(set(ends) | set(mids) | set(plain)) == 12  # parent and time are the identity


def _without_initial(folder: Path, path: Path) -> Path:
    out = folder / "plain.yaml"
    out.write_text(path.read_text().split("initial:")[0])
    return out


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        ("    campaign: parent.yaml", "initial.from.campaign: there is no campaign file"),
        ("    point: {chi: 1}", "initial.from.point.chi: campaign parent sweeps no 'chi'"),
        ("    point: {alpha_minus_B: 0.25}", "allowed: one of campaign parent's values"),
        ("    time: 3", "initial.from.time: got 3; allowed: 'end' (t = 5) or one of"),
        ("    seed: 7", "initial.from.seed: got 7; allowed: 'same' or one of"),
    ],
)
def test_a_missing_parent_is_refused_with_file_and_line(tmp_path, change, expected):
    (tmp_path / "parent.yaml").write_text(PARENT)
    text = CHILD.format(name="child", time="end")
    if "campaign:" in change:
        (tmp_path / "parent.yaml").unlink()
    else:
        text += change + "\n"
    path = tmp_path / "child.yaml"
    path.write_text(text)
    result = invoke("validate", path)
    assert result.exit_code == 2, result.output
    said = " ".join(result.output.split())
    assert f"{path}:" in said, said
    assert expected in said, said
