"""Short runs of the compiled backend grouped into one dask task (``execution.runs_per_task``,
:mod:`nematic_solids.sweep.run.group`): the section's check, the groups formed, a grouped
campaign whose run files and records equal the one-run-per-task campaign's bit for bit, a
group given again that takes the records its earlier try wrote, a worker killed in a group,
and every run of a campaign of runs finishing every few milliseconds in the catalogue."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import nematic_solids.sweep.run.driver as driver
import nematic_solids.sweep.run.session as session
from nematic_solids.sweep.catalogue.opening import open_catalogue
from nematic_solids.sweep.catalogue.recorder import known_runs
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.files import dumps
from nematic_solids.sweep.run.group import (
    RunGroup,
    execute_group,
    group_by_cost,
    group_size,
    planned_stamp,
    record_stamp,
    tasks_of,
)
from nematic_solids.sweep.run.task import RunTask, execute_run
from nematic_solids.sweep.run.todo import plan_runs
from nematic_solids.sweep.spec import load_campaign, parse_campaign
from nematic_solids.sweep.store import CampaignStore

#: 16^2 small strain to t = 0.5: runs of tens of milliseconds; a patterned point and a
#: decaying one, so the numbers differ between runs
CAMPAIGN = """\
name: {name}
parameters: {{noise_modes: 4}}
numerics: {{resolution: 16, t_final: {t_final}, mechanics: linear, save_every: 0.25}}
sweep:
  axes:
    alpha_minus_B: {values}
seeds: {seeds}
execution: {{workers: 1{execution}}}
"""


def write(
    folder: Path,
    name: str,
    execution: str = "",
    values: str = "[0.3, 1.0]",
    seeds: int = 3,
    t_final: float = 0.5,
) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.yaml"
    text = CAMPAIGN.format(
        name=name, execution=execution, values=values, seeds=seeds, t_final=t_final
    )
    path.write_text(text)
    return path


def run_in_process(path: Path, results: Path) -> tuple[CampaignStore, driver.RunSummary]:
    """The campaign run by the driver on an in-process dask cluster (one worker thread)."""
    from distributed import Client, LocalCluster

    expansion = expand(load_campaign(path))
    store = CampaignStore(results, expansion.campaign.name)
    store.ensure()
    plan = plan_runs(expansion, store)
    with (
        LocalCluster(
            n_workers=1, processes=False, threads_per_worker=1, dashboard_address=None
        ) as cluster,
        Client(cluster) as client,
    ):
        summary = driver.run_campaign(expansion, store, client, plan)
    return store, summary


def count_groups(monkeypatch: pytest.MonkeyPatch, log: Path) -> None:
    """Make the driver's group tasks append their sizes to ``log`` (a file: dask may copy
    the function and its closure)."""
    real = session.execute_group

    def counted(group: RunGroup):
        with open(log, "a") as f:
            f.write(f"{len(group.tasks)}\n")
        return real(group)

    monkeypatch.setattr(session, "execute_group", counted)


def problems(text: str) -> str:
    with pytest.raises(CampaignError) as info:
        parse_campaign(text)
    return " ".join(str(info.value).split())


def test_the_execution_section_checks_runs_per_task():
    def text(execution: str) -> str:
        return CAMPAIGN.format(name="c", execution=execution, values="[0.3]", seeds=1, t_final=0.5)

    def given(execution: str) -> int | None:
        return parse_campaign(text(execution)).execution.runs_per_task

    assert given("") is None
    assert given(", runs_per_task: auto") is None
    assert given(", runs_per_task: 7") == 7
    for bad in ("0", "-1", "2.5", "many", "100001"):
        said = problems(text(f", runs_per_task: {bad}"))
        assert "execution.runs_per_task" in said, said
        assert "'auto' or an integer" in said, said


def test_the_accelerated_backend_groups_by_batch_not_runs_per_task():
    pytest.importorskip("jax")
    text = CAMPAIGN.format(
        name="c",
        execution=", backend: accelerated, runs_per_task: 4",
        values="[0.3]",
        seeds=1,
        t_final=0.5,
    )
    assert "groups the seeds of a point by 'batch'" in problems(text)


def test_group_sizes_from_the_predicted_time_and_the_workers():
    # 10 ms runs: 50 make half a second, but 200 runs on 2 threads keep 8 tasks (25 each)
    assert group_size(0.01, 200, 2, None) == 25
    assert group_size(0.01, 2000, 2, None) == 50
    assert group_size(0.05, 200, 2, None) == 10
    assert group_size(0.6, 200, 2, None) == 1  # a long run is a task of its own
    assert group_size(0.01, 3, 2, None) == 1  # too few runs to share out
    assert group_size(0.01, 200, 2, 3) == 3  # the campaign's choice
    assert group_size(float("nan"), 200, 2, None) == 1
    # consecutive runs; a group never holds more than the smallest size of its runs
    sizes = {0: 2, 1: 2, 2: 2, 3: 2, 4: 2}
    assert group_by_cost(range(5), sizes.__getitem__) == [[0, 1], [2, 3], [4]]
    mixed = {0: 3, 1: 3, 2: 1, 3: 3, 4: 3, 5: 3, 6: 3}
    assert group_by_cost(range(7), mixed.__getitem__) == [[0, 1], [2], [3, 4, 5], [6]]


def test_the_driver_groups_short_runs_and_keeps_long_ones_alone(tmp_path):
    short = expand(load_campaign(write(tmp_path, "short", values="[0.3, 0.5, 1.0]", seeds=20)))
    tasks = tasks_of(short, list(range(len(short))), False, 2)
    assert sorted(i for t in tasks for i in t) == list(range(60))  # every run once, in order
    assert [i for t in tasks for i in t] == list(range(60))
    assert len(tasks[0]) > 1
    assert len(tasks) >= 8
    assert tasks_of(short, list(range(60)), True, 2) == [[i] for i in range(60)]  # a chain
    long = expand(load_campaign(write(tmp_path, "long", seeds=20, t_final=300.0)))
    assert tasks_of(long, list(range(40)), False, 2) == [[i] for i in range(40)]


def run_files(store: CampaignStore) -> dict[str, tuple[xr.Dataset, xr.Dataset]]:
    out = {}
    for path in sorted(store.runs_dir.glob("*.nc")):
        with xr.open_dataset(path) as ds, xr.open_dataset(path, group="state") as state:
            out[path.stem] = (ds.load(), state.load())
    return out


def test_a_grouped_campaign_equals_the_one_run_per_task_campaign(tmp_path, monkeypatch):
    log = tmp_path / "groups"
    count_groups(monkeypatch, log)
    alone, summary1 = run_in_process(
        write(tmp_path / "a", "c", ", runs_per_task: 1"), tmp_path / "a" / "results"
    )
    assert not log.exists()  # one run per task: no group
    grouped, summary4 = run_in_process(
        write(tmp_path / "b", "c", ", runs_per_task: 4"), tmp_path / "b" / "results"
    )
    assert sorted(log.read_text().split()) == ["2", "4"]  # 6 runs: a group of 4, one of 2
    assert (summary1.ok, summary4.ok, len(summary4.failed)) == (6, 6, 0)
    a, b = run_files(alone), run_files(grouped)
    assert sorted(a) == sorted(b)
    assert len(a) == 6
    for rid, (ds1, state1) in a.items():
        ds2, state2 = b[rid]
        for name in ds1.data_vars:
            if "wall" in str(name):  # the run's own time
                continue
            assert np.array_equal(ds1[name].values, ds2[name].values, equal_nan=True), name
        xr.testing.assert_equal(state1, state2)  # the end state, bit for bit
        clock = {"wall", "sha256"}  # the run's wall time, and the state's hash including it
        assert {k: repr(v) for k, v in state1.attrs.items() if k not in clock} == {
            k: repr(v) for k, v in state2.attrs.items() if k not in clock
        }  # (repr: NaN equals NaN)
        r1, r2 = alone.read_record(rid), grouped.read_record(rid)
        assert r1 is not None
        assert r2 is not None
        assert r2["status"] == "ok"
        scalars = {k for k in r1["scalars"] if "wall" not in k}
        for k in scalars:
            assert np.array_equal(r1["scalars"][k], r2["scalars"][k], equal_nan=True), k
        assert r1["trajectory"] == r2["trajectory"]


def test_a_group_given_again_takes_the_records_its_earlier_try_wrote(tmp_path):
    path = write(tmp_path, "again")
    campaign = load_campaign(path)
    expansion = expand(campaign)
    store = CampaignStore(tmp_path / "results", campaign.name)
    store.ensure()
    tasks = [
        RunTask.from_spec(expansion.run(i), store, campaign.name, campaign.store) for i in range(3)
    ]
    # run 1 failed in an earlier session (its record is the planned one: it is redone)
    old = execute_run(tasks[1])
    stale = dict(old, status="failed", reason="exception", detail="earlier session")
    store.write_record(stale)
    before = (None, record_stamp(store, tasks[1].run_id), None)
    plan = plan_runs(expansion, store, retry_failed=True)
    assert planned_stamp(plan.records, tasks[1].run_id) == before[1]
    # the first try of the group wrote run 0's record, then its worker was lost
    execute_run(tasks[0])
    first = dumps(store.read_record(tasks[0].run_id))
    stamp0 = record_stamp(store, tasks[0].run_id)
    nc0 = store.nc_path(tasks[0].run_id).stat().st_mtime_ns
    records = execute_group(RunGroup(tuple(tasks), before))
    assert dumps(records[0]) == first  # taken, not run again (dumps: NaN equals NaN)
    assert record_stamp(store, tasks[0].run_id) == stamp0
    assert store.nc_path(tasks[0].run_id).stat().st_mtime_ns == nc0
    assert [r["status"] for r in records] == ["ok", "ok", "ok"]  # run 1 redone
    for task, record in zip(tasks, records, strict=True):
        assert dumps(store.read_record(task.run_id)) == dumps(record)
        assert not store.checkpoint_path(task.run_id).exists()


def die_once_in_a_group(group: RunGroup) -> list:
    """The first try of a group: its first run is stored, then its worker dies (SIGKILL's
    effect, as the process exits at once); later tries run the group."""
    from nematic_solids.sweep.run.group import execute_group as real

    marker = Path(group.tasks[0].runs_dir).parent / "died"
    if not marker.exists():
        real(RunGroup(group.tasks[:1], group.before[:1]))
        marker.write_text(str(os.getpid()))
        os._exit(1)
    return real(group)


def test_a_worker_killed_in_a_group_loses_only_the_group_s_runs_without_records(
    tmp_path, monkeypatch
):
    import cloudpickle

    from nematic_solids.sweep.campaign import ExecutionSpec
    from nematic_solids.sweep.run.clusters import open_cluster

    path = write(tmp_path, "killed", ", runs_per_task: 3", seeds=3)
    expansion = expand(load_campaign(path))
    store = CampaignStore(tmp_path / "results", expansion.campaign.name)
    store.ensure()
    plan = plan_runs(expansion, store)
    monkeypatch.setattr(session, "execute_group", die_once_in_a_group)
    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the workers lack tests/
    try:
        with open_cluster(ExecutionSpec(workers=1)) as link:
            summary = driver.run_campaign(expansion, store, link, plan, record=False)
    finally:
        cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
    assert (summary.ok, len(summary.failed), summary.worker_lost) == (6, 0, [])
    killed = int((store.root / "died").read_text())
    pids = {rid: store.read_record(rid)["pid"] for rid in expansion.run_ids}  # type: ignore[index]
    lost = [rid for rid, pid in pids.items() if pid == killed]
    assert len(lost) == 1  # the run stored before the kill is taken, not run again
    assert len(set(pids.values()) - {killed}) == 1  # the rest ran on the new worker


def test_runs_finishing_every_few_milliseconds_are_all_recorded(tmp_path, monkeypatch):
    """60 runs of 16^2 to t = 0.05 (a few ms each) in groups of 20: every record reaches the
    catalogue, and what it holds is what the run files say."""
    path = write(
        tmp_path, "fast", ", runs_per_task: 20", values="[0.3, 0.5, 1.0]", seeds=20, t_final=0.05
    )
    store, summary = run_in_process(path, tmp_path / "results")
    assert (summary.ok, len(summary.failed)) == (60, 0)
    catalogue = open_catalogue(store.results_root)
    try:
        known = known_runs(catalogue, "fast")
    finally:
        catalogue.close()
    on_disk = store.scan(save=False)
    assert len(known) == len(on_disk) == 60
    assert known == {rid: (rec["status"], rec["finished"]) for rid, rec in on_disk.items()}
