"""Campaigns on the accelerated backend (``execution: {backend: accelerated, batch: N}``,
:mod:`nematic_solids.sweep.run.batch`): the section's checks, the batches formed, a campaign whose
phase.nc equals the per-seed compiled campaign's, a failing seed that fails alone, a continued
run, and a lost batch result redone. On the CPU, through the code path a GPU runs; skipped where
JAX is not installed."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

pytest.importorskip("jax")

import nematic_solids.model.accelerated.run as accelerated_run
import nematic_solids.sweep.run.driver as driver
import nematic_solids.sweep.run.session as session
from nematic_solids.model.errors import DeviceUnavailable
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.outputs.aggregate import write_phase
from nematic_solids.sweep.run.batch import BatchTask, execute_batch, group_runs
from nematic_solids.sweep.run.task import RunTask
from nematic_solids.sweep.run.todo import plan_runs
from nematic_solids.sweep.spec import load_campaign, parse_campaign
from nematic_solids.sweep.store import CampaignStore

#: two 32^2 small-strain points (relaxing, patterning) x 3 seeds, batches of 2 seeds
CAMPAIGN = """\
name: {name}
parameters: {{noise_modes: 8}}
numerics: {{resolution: 32, t_final: {t_final}, save_every: 5.0, mechanics: {mechanics},
           snapshot_times: [5]}}
sweep:
  axes:
    alpha_minus_B: [0.5, 1.0]
seeds: 3
execution: {{workers: 1{execution}}}
"""
BATCHED = ", backend: accelerated, batch: 2, device: cpu"


def write(
    folder: Path,
    name: str,
    execution: str = BATCHED,
    t_final: float = 10.0,
    mechanics: str = "linear",
) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.yaml"
    text = CAMPAIGN.format(name=name, execution=execution, t_final=t_final, mechanics=mechanics)
    path.write_text(text)
    return path


def campaign_text(execution: str) -> str:
    """The campaign's text as a file named "c" (32^2 small strain to t = 10)."""
    return CAMPAIGN.format(name="c", execution=execution, t_final=10, mechanics="linear")


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
    write_phase(expansion, store)
    return store, summary


def problems(text: str) -> str:
    with pytest.raises(CampaignError) as info:
        parse_campaign(text)
    return " ".join(str(info.value).split())


def test_the_execution_section_checks_backend_batch_and_device():
    good = campaign_text(BATCHED)
    ex = parse_campaign(good).execution
    assert (ex.backend, ex.batch, ex.device) == ("accelerated", 2, "cpu")
    plain = parse_campaign(campaign_text("")).execution
    assert (plain.backend, plain.batch, plain.device) == ("compiled", 1, "auto")
    finite = good.replace("mechanics: linear", "mechanics: finite")
    assert parse_campaign(finite).execution.backend == "accelerated"
    solved = finite.replace("mechanics: finite", "mechanics: finite, displacement: equilibrium")
    assert "the accelerated backend cannot run displacement = 'equilibrium'" in problems(solved)
    assert "execution.backend" in problems(solved)
    text = problems(campaign_text(", batch: 4"))
    assert "'batch' is the accelerated backend's" in text
    text = problems(good.replace("device: cpu", "device: tpu"))
    assert "execution.device" in text
    assert "cpu, gpu, auto" in text
    assert "execution.batch" in problems(good.replace("batch: 2", "batch: 0"))
    assert "execution.backend" in problems(good.replace("accelerated", "cuda"))


def test_the_accelerated_backend_needs_jax_on_a_local_cluster(monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "jax" else real(name, *a)
    )
    text = problems(campaign_text(BATCHED))
    assert "needs JAX, which is not installed here: pip install -e '.[accel]'" in text


def test_batches_hold_runs_of_one_point_in_queue_order():
    points = {0: "a", 1: "a", 2: "b", 3: "a", 4: "b", 5: "a", 6: "a"}
    objects = {name: object() for name in "ab"}
    out = group_runs(list(points), lambda i: objects[points[i]], 3)
    assert out == [[0, 1, 3], [2, 4], [5, 6]]
    assert group_runs([4, 2], lambda i: objects[points[i]], 1) == [[4], [2]]


@pytest.mark.parametrize("mechanics", ["linear", pytest.param("finite", marks=pytest.mark.slow)])
def test_a_batched_campaign_equals_the_per_seed_campaign(tmp_path, mechanics):
    """Same run ids (the backend is not identity), one file per seed with the batch it ran in,
    and phase.nc equal within the backends' tolerance (1e-10 of each variable's scale), in
    small-strain and finite-strain mechanics (slow: finite strain's batch compiles for two
    batch sizes, about a minute)."""
    acc, summary = run_in_process(write(tmp_path, "acc", mechanics=mechanics), tmp_path / "results")
    assert (summary.ok, len(summary.failed), summary.submitted) == (6, 0, 6)
    cmp_store, _ = run_in_process(
        write(tmp_path, "cmp", execution="", mechanics=mechanics), tmp_path / "results"
    )
    ids = sorted(p.stem for p in acc.runs_dir.glob("*.nc"))
    assert ids == sorted(p.stem for p in cmp_store.runs_dir.glob("*.nc"))
    assert len(ids) == 6
    sizes = []
    for rid in ids:
        with xr.open_dataset(acc.nc_path(rid)) as ds:
            assert ds.attrs["run_backend"] == "accelerated"
            assert ds.attrs["device"].startswith("cpu")
            sizes.append(int(ds.attrs["batch_size"]))
            assert ds.attrs["seed"] in json.loads(ds.attrs["batch_seeds"])
        assert json.loads(acc.record_path(rid).read_text())["status"] == "ok"
    assert sorted(sizes) == [1, 1, 2, 2, 2, 2]  # seeds 0-1 together, seed 2 alone, per point
    with xr.open_dataset(acc.phase_path) as a, xr.open_dataset(cmp_store.phase_path) as b:
        assert set(a.data_vars) == set(b.data_vars)
        compared = 0
        for name in a.data_vars:
            if name == "run_time":  # the runs' wall times
                continue
            x, y = a[name].values, b[name].values
            assert x.shape == y.shape, name
            if x.dtype.kind != "f":
                continue
            assert np.array_equal(np.isfinite(x), np.isfinite(y)), name
            m = np.isfinite(y)
            if m.any():
                scale = max(np.abs(y[m]).max(), 1e-300)
                assert np.abs(x[m] - y[m]).max() <= 1e-10 * scale + 1e-14, name
                compared += 1
        assert compared > 20
        assert float(a["sigma2_S_mean"].sel(alpha_minus_B=1.0)) > 1e-4  # it patterns


def test_a_failing_seed_fails_alone(tmp_path, monkeypatch):
    """Seed 1's texture is made ill posed ((alpha - B) S = 1.5): its record says why, on the
    device, at t = 0; its batch-mate's file equals the one it has in a batch of its own."""
    real = accelerated_run.initial_fields

    def ill_posed_seed_1(params, n, seed):
        q1, q2, A = real(params, n, seed)
        if seed == 1:
            q1, q2 = np.full_like(q1, 1.5), np.zeros_like(q2)
        return q1, q2, A

    path = write(tmp_path, "acc")
    expansion = expand(load_campaign(path))
    store = CampaignStore(tmp_path / "results", "acc")
    store.ensure()
    campaign = expansion.campaign
    point = [i for i in range(len(expansion)) if expansion.run(i).coords["alpha_minus_B"] == 1.0]
    tasks = tuple(
        RunTask.from_spec(expansion.run(i), store, campaign.name, campaign.store)
        for i in point
        if expansion.run(i).seed in (0, 1)
    )
    assert [t.seed for t in tasks] == [0, 1]
    monkeypatch.setattr(accelerated_run, "initial_fields", ill_posed_seed_1)
    good, bad = execute_batch(BatchTask(tasks, "cpu"))
    assert (good["status"], bad["status"]) == ("ok", "failed")
    assert bad["reason"] == "rate_problem_ill_posed"
    assert json.loads(store.record_path(bad["run_id"]).read_text())["status"] == "failed"
    with xr.open_dataset(store.nc_path(tasks[0].run_id)) as ds:
        together = ds["sigma2_S"].values.copy()
    monkeypatch.setattr(accelerated_run, "initial_fields", real)
    (alone,) = execute_batch(BatchTask(tasks[:1], "cpu"))
    assert alone["status"] == "ok"
    with xr.open_dataset(store.nc_path(tasks[0].run_id)) as ds:
        np.testing.assert_allclose(ds["sigma2_S"].values, together, rtol=1e-12, atol=0)


def test_a_longer_batched_campaign_continues_its_runs_end_states(tmp_path):
    """t_final grows 5 -> 10: each batch continues its seeds from the end states their runs to
    5 keep, on the device, and ends bitwise as the batched campaign run to 10 at once (the
    same batches); from the compiled runs' end states, within the backends' tolerance."""
    run_in_process(write(tmp_path, "grow", t_final=5.0), tmp_path / "results")
    store, summary = run_in_process(write(tmp_path, "grow"), tmp_path / "results")
    assert summary.ok == 6
    whole, _ = run_in_process(write(tmp_path, "whole"), tmp_path / "results")
    ids = [p.stem for p in whole.runs_dir.glob("*.nc")]
    assert len(ids) == 6
    for rid in ids:  # the runs to 10 (the folder also holds the runs to 5 they continue)
        with xr.open_dataset(store.nc_path(rid)) as ds, xr.open_dataset(whole.nc_path(rid)) as ref:
            assert ds.attrs["run_backend"] == "accelerated"
            assert ds.attrs["continued_from"] != ""
            assert ds.attrs["started_at"] == 5.0
            for name in ("sigma2_S", "lambda", "mean_S", "q1"):
                np.testing.assert_array_equal(ds[name].values, ref[name].values)
    run_in_process(write(tmp_path, "mixed", execution="", t_final=5.0), tmp_path / "results")
    mixed, _ = run_in_process(write(tmp_path, "mixed"), tmp_path / "results")
    for rid in ids:  # from the compiled path's end states
        with xr.open_dataset(mixed.nc_path(rid)) as ds, xr.open_dataset(whole.nc_path(rid)) as ref:
            assert ds.attrs["run_backend"] == "accelerated"
            assert ds.attrs["started_at"] == 5.0
            want, have = ref["sigma2_S"].values, ds["sigma2_S"].values
            assert np.abs(have - want).max() <= 1e-10 * np.abs(want).max()


def test_a_batch_goes_on_from_its_seeds_rolling_checkpoints(tmp_path):
    """A batch lost after its checkpoints at t = 5 (their files are left, no run file, no
    record) goes on from them when it runs again: the seeds' files are bitwise those of the
    batch that never stopped, and say so (started_at, lineage); the checkpoints are removed."""
    from nematic_solids.model.accelerated.datasets import batch_datasets
    from nematic_solids.model.checkpoint import Schedule
    from nematic_solids.model.parameters import Numerics, Parameters
    from nematic_solids.sweep.run.continuation import Checkpointer, checkpoint_path

    path = write(tmp_path, "ck")
    expansion = expand(load_campaign(path))
    campaign = expansion.campaign
    store = CampaignStore(tmp_path / "results", "ck")
    store.ensure()
    runs = [expansion.run(i) for i in range(len(expansion))]
    held = [r for r in runs if r.coords["alpha_minus_B"] == 1.0 and r.seed in (0, 1)]
    tasks = tuple(RunTask.from_spec(r, store, campaign.name, campaign.store) for r in held)
    (ref, _), (ref1, _) = execute_batch_reference(tasks)
    writers = [Checkpointer(store, t.run_id) for t in tasks]
    batch_datasets(  # the lost batch: its checkpoints at t = 5 written, then it is gone
        Parameters.from_dict(tasks[0].parameters),
        Numerics.from_dict(tasks[0].numerics),
        [t.seed for t in tasks],
        device="cpu",
        checkpoint=lambda b, state: writers[b](state) if state.t == 5.0 else None,
        schedule=Schedule(tau=5.0),
    )
    assert all(checkpoint_path(store, t.run_id).exists() for t in tasks)
    records = execute_batch(BatchTask(tasks, "cpu"))
    assert [r["status"] for r in records] == ["ok", "ok"]
    for task, want in zip(tasks, (ref, ref1), strict=True):
        assert not checkpoint_path(store, task.run_id).exists()
        with xr.open_dataset(store.nc_path(task.run_id)) as ds:
            assert ds.attrs["started_at"] == 5.0
            assert "checkpoint@5" in str(ds.attrs["lineage"])
            for name in ("sigma2_S", "lambda", "A"):
                np.testing.assert_array_equal(ds[name].values, want[name].values)


def execute_batch_reference(tasks: tuple[RunTask, ...]):
    """The batch of ``tasks`` run whole, without a campaign (the reference Datasets)."""
    from nematic_solids.model.accelerated.datasets import batch_datasets
    from nematic_solids.model.parameters import Numerics, Parameters

    return batch_datasets(
        Parameters.from_dict(tasks[0].parameters),
        Numerics.from_dict(tasks[0].numerics),
        [t.seed for t in tasks],
        device="cpu",
        keep_state=True,
    )


def test_a_batch_task_that_raises_records_its_seeds_failed(tmp_path, monkeypatch):
    """A batch task that raises on its worker (an OSError while it is set up: a folder it
    cannot open) is its seeds' failure, each recorded with the reason and where it failed,
    not a result lost with a worker (tests/sweep/test_lost_workers.py: a lost result)."""
    real = session.execute_batch
    marker = tmp_path / "raised-once"  # a file: dask may copy the function and its closure

    def raises_once(batch: BatchTask):
        if not marker.exists():
            marker.write_text(str(len(batch.tasks)))
            raise OSError("the batch's folder cannot be opened")
        return real(batch)

    monkeypatch.setattr(session, "execute_batch", raises_once)
    path = write(tmp_path, "raised")
    store, summary = run_in_process(path, tmp_path / "results")
    n = int(marker.read_text())
    assert (summary.ok, len(summary.failed)) == (6 - n, n)
    assert summary.submitted == 6
    failed = [rec for _, rec in summary.failed]
    assert all("failed while its task was set up" in r["detail"] for r in failed)
    assert all("the batch's folder cannot be opened" in r["detail"] for r in failed)
    assert len(list(store.runs_dir.glob("*.json"))) == 6


def test_asking_for_a_missing_gpu_is_one_message_and_exit_2(tmp_path):
    from typer.testing import CliRunner

    from nematic_solids.model.accelerated.device import _devices
    from nematic_solids.sweep.cli import app

    if _devices("gpu"):
        pytest.skip("this machine has a GPU")
    path = write(tmp_path, "gpu", execution=BATCHED.replace("cpu", "gpu"))
    result = CliRunner().invoke(app, ["run", str(path), "--results", str(tmp_path / "r")])
    assert result.exit_code == 2, result.output
    text = " ".join(result.output.split())
    assert "a GPU was asked for, but JAX" in text
    assert "sees none" in text
    assert "Traceback" not in result.output
    assert not list((tmp_path / "r").rglob("*.nc"))
    with pytest.raises(DeviceUnavailable):
        driver.check_device("gpu")
