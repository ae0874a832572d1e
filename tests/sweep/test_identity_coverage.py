"""Identity covers every input that changes a run's numbers (nematic_solids.sweep.identity).

Every key of ``numerics:`` and ``store:``, enumerated from the code's own tables (a key added
later fails here until it is classified), either changes the run id, or is shown by running a tiny
chain both ways to leave every array of every run unchanged (a successor's numbers included: it
begins from its predecessor's exact end state, whatever the store keeps of the snapshots). A run
of ``initial.from`` that begins from a snapshot instead of the exact end state has another id and
a recorded warning; a parent state that fails its checksum or is missing fails the run with the
reason ``parent_state``, never a fallback to a snapshot."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import netCDF4
import numpy as np
import pytest
import xarray as xr

from nematic_solids.model.checkpoint import InitialState, RunState, read_netcdf
from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.model.simulate import run as simulate
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.identity import (
    ID_LENGTH,
    canonical_json,
    hash_canonical,
    identity_start,
)
from nematic_solids.sweep.models.nematic_identity import EXACT_GUESS, start_guess
from nematic_solids.sweep.run.continuation import STATE_GROUP, file_snapshots
from nematic_solids.sweep.run.task import RunTask, execute_run
from nematic_solids.sweep.settings import setting_names
from nematic_solids.sweep.spec import load_campaign
from nematic_solids.sweep.spec.sections import STORE_KEYS
from nematic_solids.sweep.store import RETRYABLE_REASONS, CampaignStore

CHAIN = """\
name: {name}
parameters: {{noise_modes: 8}}
numerics: {{resolution: 32, t_final: 2, save_every: 1, snapshot_times: [1, 2]{numerics}}}
sweep:
  axes:
    alpha_minus_B: [0.6, 1.2]
chain: {{axis: alpha_minus_B, branches: up}}
seeds: [0]
{store}"""

#: a value other than the campaign's for every numerics key that changes the id
CHANGES_ID = {
    "resolution": 64,
    "t_final": 3,
    "dt": 0.01,
    "scheme": "etdrk2",
    "adaptive": False,
    "tolerance": 1e-4,
    "error_norm": "rms",
    "dt_max": 0.5,
    "save_every": 0.5,
    "snapshot_times": [2],
    "mechanics": "linear",
    "incompressible": True,
    "displacement": "equilibrium",
    "newton_tol": 1e-8,
    "max_newton": 10,
    "spin_tol": 1e-3,
    "steady_tol": 1e-3,
}
#: the keys that do not enter the id, with a value to run both ways (in ``numerics:`` or
#: ``store:``) and what is shown: "same" (every array bit for bit) or "rounding" (the numpy
#: backend agrees with the compiled one to rounding: nematic_solids.model.parameters.BACKENDS)
SAME_ARRAYS = {
    ("numerics", "backend"): ("numpy", "rounding"),
    ("numerics", "steady_window"): (1.5, "same"),  # without early stop (steady_tol = 0)
    ("store", "snapshot_fields"): ("[q1, q2, A]", "same"),
    ("store", "snapshot_dtype"): ("float32", "same"),
    ("store", "checkpoint_every"): ("0.5", "same"),
}


#: keys that change the id, checked in another file because this file's chain campaign cannot
#: take them: float32 runs on the accelerated backend only, outside chains
#: (tests/sweep/test_float32.py: float32 changes the id, float64 keeps every shipped id)
CHANGES_ID_ELSEWHERE = {"precision": "float32"}


#: the run file's variables that measure the execution, not the model (its seconds)
MEASURED = ("wall_time",)


def test_every_numerics_and_store_key_is_classified():
    numerics = set(setting_names().numerics)
    store = set(STORE_KEYS) - {"snapshot_times"}  # store.snapshot_times is numerics' key
    assert "snapshot_times" in numerics
    classified_numerics = (
        set(CHANGES_ID) | set(CHANGES_ID_ELSEWHERE) | {k for s, k in SAME_ARRAYS if s == "numerics"}
    )
    # end_state: true is what a chain needs (false is refused: tests/sweep/test_chains.py)
    classified_store = {k for s, k in SAME_ARRAYS if s == "store"} | {"end_state"}
    assert numerics == classified_numerics, numerics ^ classified_numerics
    assert store == classified_store, store ^ classified_store


def _text(name: str = "c", numerics: str = "", store: str = "") -> str:
    return CHAIN.format(name=name, numerics=numerics, store=store)


def _ids(tmp_path: Path, text: str) -> list[str]:
    path = tmp_path / "c.yaml"
    path.write_text(text)
    return expand(load_campaign(path)).run_ids


#: where a key's change needs another base (a setting it only matters with)
BASE_FOR = {"steady_tol": ", steady_window: 1", "incompressible": ", mechanics: linear"}


@pytest.mark.parametrize(("key", "value"), sorted(CHANGES_ID.items()))
def test_a_numerics_key_changes_every_run_id(tmp_path, key, value):
    base_extra = BASE_FOR.get(key, "")
    base = _ids(tmp_path, _text(numerics=base_extra))
    if key == "resolution":
        changed = _text().replace("resolution: 32", f"resolution: {value}")
    elif key in ("t_final", "save_every", "snapshot_times"):
        old = {"t_final": "t_final: 2", "save_every": "save_every: 1"}.get(
            key, "snapshot_times: [1, 2]"
        )
        changed = _text().replace(old, f"{key}: {json.dumps(value)}")
    else:
        changed = _text(numerics=f"{base_extra}, {key}: {json.dumps(value)}")
    other = _ids(tmp_path, changed)
    assert len(other) == len(base) == 2
    assert not set(other) & set(base), key


def _run_chain(folder: Path, text: str) -> dict[tuple[float, str], xr.Dataset]:
    """Every run of the chain campaign ``text``, in chain order, in this process (the driver's
    tasks: each successor from its predecessor's end state in the run file)."""
    path = folder / "c.yaml"
    folder.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    campaign = load_campaign(path)
    store = CampaignStore(folder / "results", campaign.name)
    store.runs_dir.mkdir(parents=True, exist_ok=True)
    expansion = expand(campaign)
    out = {}
    for i in sorted(range(len(expansion)), key=lambda i: expansion.run(i).start is not None):
        run = expansion.run(i)
        task = RunTask.from_spec(run, store, campaign.name, campaign.store)
        record = execute_run(task)
        assert record["status"] == "ok", record
        with xr.open_dataset(store.runs_dir / f"{run.run_id}.nc") as ds:
            out[(run.point.coords["alpha_minus_B"], run.run_id)] = ds.load()
    return out


def test_keys_outside_the_identity_leave_every_array_unchanged(tmp_path):
    """A chain of two runs (the successor from its predecessor's end state) with each key
    changed: the same run ids, and every array of every run the same (bit for bit; the numpy
    backend to rounding); snapshots kept at float32 are the float64 ones rounded, and a
    successor's numbers do not depend on what its predecessor's file keeps of snapshots."""
    base = _run_chain(tmp_path / "base", _text())
    assert len(base) == 2
    for (section, key), (value, shown) in SAME_ARRAYS.items():
        if section == "numerics":
            text = _text(numerics=f", {key}: {value}")
        else:
            text = _text(store=f"store: {{{key}: {value}}}\n")
        got = _run_chain(tmp_path / key, text)
        assert got.keys() == base.keys(), key  # the same run ids
        for run, ds in got.items():
            ref = base[run]
            for name, var in ds.data_vars.items():
                if name in MEASURED:
                    continue
                want = ref[name].values
                if var.dtype == np.float32:
                    want = want.astype(np.float32)  # the kept precision of the same numbers
                if shown == "same":
                    assert np.array_equal(var.values, want, equal_nan=True), (key, name)
                else:
                    np.testing.assert_allclose(var.values, want, rtol=1e-9, atol=1e-12)
            if key == "snapshot_fields":
                assert "u1" not in ds.data_vars


PARENT = """\
name: parent
parameters: {{noise_modes: 8}}
numerics: {{resolution: 32, t_final: 2, save_every: 1, snapshot_times: [2]}}
seeds: [0]
{store}"""
CHILD = """\
name: child
parameters: {noise_modes: 8, zeta: 0.0}
numerics: {resolution: 32, t_final: 1, save_every: 1}
seeds: [0]
initial:
  from: {campaign: parent.yaml, time: end}
"""


def _parent_and_child(folder: Path, store: str):
    """The parent campaign run with ``store``, and the child campaign (from its end)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "parent.yaml").write_text(PARENT.format(store=store))
    (folder / "child.yaml").write_text(CHILD)
    parent = load_campaign(folder / "parent.yaml")
    pstore = CampaignStore(folder / "results", "parent")
    pstore.runs_dir.mkdir(parents=True, exist_ok=True)
    (run,) = list(expand(parent))
    assert execute_run(RunTask.from_spec(run, pstore, "parent", parent.store))["status"] == "ok"
    child = load_campaign(folder / "child.yaml")
    cstore = CampaignStore(folder / "results", "child")
    cstore.runs_dir.mkdir(parents=True, exist_ok=True)
    (crun,) = list(expand(child))
    return pstore.runs_dir / f"{run.run_id}.nc", crun, cstore, child


def test_a_child_begun_from_a_snapshot_has_another_id_and_a_warning(tmp_path):
    _, exact, store, child = _parent_and_child(tmp_path / "a", "")
    _, snap, snap_store, snap_child = _parent_and_child(
        tmp_path / "b", "store: {snapshot_dtype: float32, end_state: false}\n"
    )
    assert exact.start is not None
    assert "state" not in exact.start
    assert snap.start is not None
    assert snap.start["state"] == "snapshot (float32, all fields)"
    assert exact.run_id != snap.run_id  # another state to begin from: another run
    records = []
    for run, st, c in ((exact, store, child), (snap, snap_store, snap_child)):
        rec = execute_run(RunTask.from_spec(run, st, "child", c.store))
        assert rec["status"] == "ok", rec
        records.append(json.loads((st.runs_dir / f"{run.run_id}.json").read_text()))
    assert not records[0].get("start_warning")
    assert "begins from the snapshot (float32, all fields)" in records[1]["start_warning"]
    assert "not its exact end state" in records[1]["start_warning"]
    with (
        xr.open_dataset(store.runs_dir / f"{exact.run_id}.nc") as a,
        xr.open_dataset(snap_store.runs_dir / f"{snap.run_id}.nc") as b,
    ):
        assert a.attrs["initial_from"] == f"parent/{exact.start['run']}@end"
        assert not np.array_equal(a.sigma2_S.values, b.sigma2_S.values)  # other numbers


def _corrupt_state(path: Path) -> None:
    """Change one value of the end state group, leaving its checksum as it was."""
    with netCDF4.Dataset(path, "a") as ds:
        group = ds.groups[STATE_GROUP]
        name = next(n for n, v in group.variables.items() if v.ndim >= 2)
        data = group.variables[name][:]
        data.flat[0] += 1e-3
        group.variables[name][:] = data


def _drop_state(path: Path) -> None:
    """The run file without its end state group (as store.end_state: false writes it)."""
    with xr.open_dataset(path) as ds:
        main = ds.load()
    path.unlink()
    main.to_netcdf(path)


@pytest.mark.parametrize(
    ("damage", "says"),
    [(_corrupt_state, "checksum"), (_drop_state, "keeps no end state")],
)
def test_a_parent_state_that_cannot_be_used_fails_the_run_with_its_reason(tmp_path, damage, says):
    parent_file, run, store, child = _parent_and_child(tmp_path, "")
    damage(parent_file)
    rec = execute_run(RunTask.from_spec(run, store, "child", child.store))
    assert rec["status"] == "failed"
    assert rec["reason"] == "parent_state"
    assert says in rec["detail"]
    assert str(parent_file) in rec["detail"]
    assert not (store.runs_dir / f"{run.run_id}.nc").exists()  # nothing from a fallback
    assert "parent_state" in RETRYABLE_REASONS  # redone once the parent is whole again


def _without_guess(text: str) -> str:
    """The run id a canonical text had before the exact guess entered it."""
    payload = json.loads(text)
    payload.pop("start_guess", None)
    compact = json.dumps(payload, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return hashlib.sha256(compact.encode("ascii")).hexdigest()[:ID_LENGTH]


def test_a_finite_strain_successor_names_its_exact_guess_in_its_id(tmp_path):
    """A finite-strain run begun from an exact end state solves its force balance at t = 0
    from the end state's displacement spectrum (runs made before: from the end snapshot's
    displacement), so its id names that guess; the first runs of a chain, linear strain and
    a start from a snapshot keep the ids they had."""
    for mechanics, marked in (("finite", True), ("linear", False)):
        path = tmp_path / f"{mechanics}.yaml"
        path.write_text(_text(numerics=f", mechanics: {mechanics}"))
        for run in expand(load_campaign(path)):
            p, n = run.point.parameters.to_dict(), run.point.numerics.to_dict()
            start = identity_start(run.start)
            text = canonical_json(p, n, run.seed, start)
            assert run.run_id == hash_canonical(p, n, run.seed, start)
            if start is None or not marked:
                assert "start_guess" not in json.loads(text)
                assert run.run_id == _without_guess(text)  # as before
            else:
                assert json.loads(text)["start_guess"] == EXACT_GUESS
                assert run.run_id != _without_guess(text)  # another id than before
    finite = Numerics().to_dict()
    p = Parameters().to_dict()
    assert start_guess(finite, {"run": "a", "time": "end"}) == EXACT_GUESS  # initial.from
    assert start_guess(finite, {"run": "a", "time": "1"}) is None  # a snapshot's displacement
    assert start_guess(finite, {"run": "a", "time": "end", "state": "snapshot (float32)"}) is None
    assert "start_guess" not in canonical_json(p, finite, 0)  # the seeded texture


def test_a_successor_from_the_guess_runs_were_made_with_has_other_numbers(tmp_path):
    """Why the guess enters the id: the chain's successor run again from its predecessor's
    end state with the first guess that runs made before took (the displacement of the end
    snapshot in real space, the state's own fields) gives other arrays than the exact
    spectrum (here apart by rounding; Newton's stop bounds them by its tolerance), while the
    exact guess reproduces the run's file bit for bit."""
    runs = _run_chain(tmp_path, _text())
    campaign = load_campaign(tmp_path / "c.yaml")
    successor = next(r for r in expand(campaign) if r.start is not None)
    assert successor.start is not None
    before = tmp_path / "results" / "c" / "runs" / f"{successor.start['run']}.nc"
    state = RunState.from_dataset(read_netcdf(before, STATE_GROUP))
    with xr.open_dataset(before) as main:
        state.snaps = file_snapshots(main.load())
    params, numerics = successor.point.parameters, successor.point.numerics
    exact = simulate(params, numerics, successor.seed, initial=InitialState.exact(state))
    older = simulate(params, numerics, successor.seed, initial=InitialState.at(state))
    stored = runs[(successor.coords["alpha_minus_B"], successor.run_id)]
    for name in ("q1", "q2", "A", "sigma2_S", "mean_S"):
        np.testing.assert_array_equal(exact[name].values, stored[name].values)
    assert any(
        not np.array_equal(exact[name].values, older[name].values) for name in ("q1", "q2", "A")
    )
    np.testing.assert_allclose(older["q1"].values, exact["q1"].values, rtol=0, atol=1e-9)


def test_the_shipped_chain_keeps_its_first_runs_and_not_its_successors(tmp_path):
    """docs/results/fig2_loop was run before the exact guess: the first run of each branch
    (from the seeded texture) keeps its id, every successor has a new one, so its stored
    numbers are never taken for a run from the exact guess."""
    results = Path(__file__).resolve().parents[2] / "docs" / "results" / "fig2_loop"
    with xr.open_dataset(results / "phase.nc") as phase:
        ids = phase["run_id"].transpose("branch", "alpha_minus_B", "seed").values
        path = tmp_path / "fig2_loop.yaml"
        path.write_text(phase.attrs["campaign_yaml"])
        assert phase.attrs.get("campaign_overrides", "") == ""
        first = {"up": 0, "down": len(phase["alpha_minus_B"]) - 1}  # each branch's first value
        branches = [str(b) for b in phase["branch"].values]
    planned = set(expand(load_campaign(path)).run_ids)
    firsts = {str(r) for b, i in first.items() for r in ids[branches.index(b), i]}
    successors = {str(r) for r in ids.ravel()} - firsts
    assert len(firsts) == 20
    assert len(successors) == 2 * 12 * 10
    assert firsts <= planned
    assert not successors & planned
