"""Exact continuation (nematic_solids.model.checkpoint, nematic_solids.model.simulate.run's start /
checkpoint / keep_state): a run continued from any saved state, in memory or read back from its
netCDF file, takes the same accepted steps and ends with bitwise the same arrays as the run that
never stopped; a longer run continued from a shorter run's end equals the straight longer run; a
corrupt, truncated or foreign state is refused, naming why."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import xarray as xr

from nematic_solids.model.checkpoint import CheckpointError, InitialState, RunState, Schedule, load
from nematic_solids.model.errors import ParameterError
from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.model.simulate import run

PARAMS = Parameters.from_dict({"noise_modes": 8, "alpha_minus_B": 0.3})
#: the work counters that equal runs share (the wall time differs, and a continued longer
#: run also counts the shorter run's last snapshot: two transforms in fft_saves, fft_count)
SAME_WORK = (
    "solver_steps",
    "solver_rejected",
    "solver_rhs",
    "solver_newton",
    "solver_projections",
    "solver_spin_iterations",
    "solver_cg_iterations",
)


def numerics(**kw) -> Numerics:
    base = dict(resolution=32, t_final=30.0, save_every=2.5, snapshot_times=(10.0,))
    return Numerics(**{**base, **kw})


def assert_same_run(a: xr.Dataset, b: xr.Dataset) -> None:
    """Every array equal bit for bit (NaN where NaN), the same accepted and rejected steps."""
    assert set(a.data_vars) == set(b.data_vars)
    for name in a.data_vars:
        if name == "wall_time":
            continue
        assert np.array_equal(a[name].values, b[name].values, equal_nan=True), name
    for name in ("t", "snapshot_time"):
        assert np.array_equal(a[name].values, b[name].values)
    for key in SAME_WORK:
        assert a.attrs[key] == b.attrs[key], key
    assert a.attrs["status"] == b.attrs["status"] == "ok"


def states_of(num: Numerics, seed: int, tau: float) -> tuple[xr.Dataset, list[RunState]]:
    states: list[RunState] = []
    ds = run(PARAMS, num, seed, checkpoint=states.append, schedule=Schedule(tau=tau))
    return ds, states


@pytest.mark.parametrize(
    "kw",
    [
        {"mechanics": "finite"},
        {"mechanics": "linear"},
        {"mechanics": "finite", "displacement": "equilibrium", "t_final": 15.0},
        {"mechanics": "finite", "scheme": "etdrk2", "t_final": 15.0},
    ],
    ids=["finite", "linear", "finite-equilibrium", "etdrk2"],
)
def test_a_run_continued_from_any_saved_state_equals_the_straight_run(kw):
    num = numerics(**kw)
    straight, states = states_of(num, 3, tau=5.0)
    assert [s.t for s in states] == pytest.approx(np.arange(5.0, num.t_final, 5.0))
    assert all(0 < s.solver.stats["steps"] < straight.attrs["solver_steps"] for s in states)
    for state in states:
        assert not state.complete
        assert_same_run(straight, run(PARAMS, num, 3, start=state))


@pytest.mark.parametrize("mechanics", ["finite", "linear"])
def test_a_state_read_back_from_its_file_continues_exactly(tmp_path, mechanics):
    num = numerics(mechanics=mechanics)
    straight, states = states_of(num, 5, tau=12.0)
    state = states[-1]
    path = tmp_path / "state.nc"
    state.to_dataset().to_netcdf(path)
    back = load(path)
    assert back.t == state.t
    assert back.solver.h == state.solver.h
    assert back.solver.stats == state.solver.stats
    assert back.solver.q_hat is not None
    assert state.solver.q_hat is not None
    assert np.array_equal(back.solver.q_hat, state.solver.q_hat)
    for name, value in state.mechanics.items():
        assert np.array_equal(back.mechanics[name], value)
        assert back.mechanics[name].dtype == value.dtype
    assert_same_run(straight, run(PARAMS, num, 5, start=back))


@pytest.mark.parametrize("mechanics", ["finite", "linear"])
def test_a_longer_run_continues_a_finished_shorter_one(mechanics):
    num = numerics(mechanics=mechanics)
    short = dataclasses.replace(num, t_final=20.0)
    first, end = run(PARAMS, short, 2, keep_state=True)
    assert end is not None
    assert end.complete
    assert end.t == 20.0
    assert [s[0] for s in end.snaps] == [10.0, 20.0]  # the shorter run's end is a snapshot
    longer, end2 = run(PARAMS, num, 2, start=end, keep_state=True)
    assert_same_run(run(PARAMS, num, 2), longer)
    assert list(longer.snapshot_time.values) == [10.0, 30.0]  # not 20: the longer run's own
    # the longer run may add snapshots after the shorter one's end (and at it)
    more = dataclasses.replace(num, snapshot_times=(10.0, 20.0, 25.0))
    assert_same_run(run(PARAMS, more, 2), run(PARAMS, more, 2, start=end))
    # the end state of the finished run continues to nothing more: the same result
    assert end2 is not None
    assert end2.t == 30.0
    assert_same_run(longer, run(PARAMS, num, 2, start=end2))


def test_the_python_api_chains_runs_by_hand():
    """A notebook's chain: 0 -> 10 -> 20 -> 30 by hand, equal to one run to 30."""
    num = numerics()
    state = None
    for t_end in (10.0, 20.0, 30.0):
        ds, state = run(
            PARAMS, dataclasses.replace(num, t_final=t_end), 4, start=state, keep_state=True
        )
    assert state is not None
    assert state.t == 30.0
    straight = run(PARAMS, num, 4)
    for name in ("sigma2_S", "mean_S", "steps", "q1", "u1"):
        assert np.array_equal(straight[name].values, ds[name].values), name


def test_a_failed_run_has_no_end_state():
    num = numerics(t_final=5.0, snapshot_times=())
    ds, end = run(
        Parameters.from_dict({"noise_modes": 8, "alpha_minus_B": 20.0}), num, 0, keep_state=True
    )
    assert ds.attrs["status"] == "failed"
    assert end is None


def test_a_foreign_state_is_refused_with_the_reason():
    num = numerics(t_final=10.0)
    _, states = states_of(num, 1, tau=5.0)
    state = states[0]
    with pytest.raises(CheckpointError, match="computed by model version 0.0.1, this is"):
        run(PARAMS, num, 1, start=dataclasses.replace(state, code_version="0.0.1"))
    with pytest.raises(CheckpointError, match="seed 1's state, not seed 2's"):
        run(PARAMS, num, 2, start=state)
    with pytest.raises(CheckpointError, match="parameters differ.*alpha"):
        run(Parameters.from_dict({"noise_modes": 8, "alpha_minus_B": 0.4}), num, 1, start=state)
    with pytest.raises(CheckpointError, match="numerics differ.*tolerance"):
        run(PARAMS, dataclasses.replace(num, tolerance=1e-4), 1, start=state)
    with pytest.raises(CheckpointError, match="past this run's t_final"):
        run(PARAMS, dataclasses.replace(num, t_final=2.5, snapshot_times=()), 1, start=state)
    with pytest.raises(CheckpointError, match="save times up to t = 5 are not"):
        run(PARAMS, dataclasses.replace(num, snapshot_times=(4.0,)), 1, start=state)
    with pytest.raises(CheckpointError, match="numerics differ.*save_every"):
        run(PARAMS, dataclasses.replace(num, save_every=1.25), 1, start=state)
    with pytest.raises(CheckpointError, match="no snapshot at t = 2.5"):
        run(PARAMS, dataclasses.replace(num, snapshot_times=(2.5,)), 1, start=state)


def test_a_corrupt_or_truncated_state_file_is_refused(tmp_path):
    _, states = states_of(numerics(t_final=10.0), 1, tau=5.0)
    path = tmp_path / "state.nc"
    states[0].to_dataset().to_netcdf(path)
    # an altered value that still reads: the checksum says so
    ds = xr.load_dataset(path)
    ds["fields"].values[0, 3, 4] += 1e-12
    altered = tmp_path / "altered.nc"
    ds.to_netcdf(altered)
    with pytest.raises(CheckpointError, match="checksum does not match"):
        load(altered)
    truncated = tmp_path / "truncated.nc"
    truncated.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(CheckpointError, match="not a readable netCDF"):
        load(truncated)
    other = tmp_path / "other.nc"
    xr.Dataset({"a": ("x", np.zeros(3))}).to_netcdf(other)
    with pytest.raises(CheckpointError, match="not a run state"):
        load(other)
    with pytest.raises(CheckpointError, match="does not exist"):
        load(tmp_path / "missing.nc")


def test_the_schedule_counts_simulated_and_wall_time():
    assert not Schedule().due(1e9, 1e9)
    assert Schedule(tau=5.0).due(5.0, 0.0)
    assert not Schedule(tau=5.0).due(4.9, 1e9)
    assert Schedule(wall=60.0).due(0.0, 60.0)
    assert not Schedule(wall=60.0).due(1e9, 59.0)
    # a wall-clock schedule at 0 s hands out the state after every save but the last
    num = numerics(t_final=10.0)
    states: list[RunState] = []
    run(PARAMS, num, 1, checkpoint=states.append, schedule=Schedule(wall=0.0))
    assert [s.t for s in states] == [0.0, 2.5, 5.0, 7.5]


@pytest.mark.parametrize("mechanics", ["finite", "linear"])
def test_a_new_run_from_another_runs_end_follows_its_trajectory(mechanics):
    """A run begun from another run's end fields (InitialState, same parameters) is a new
    run at t = 0 on the same trajectory: its fields at t = 0 are the parent's, bit for bit,
    and 10 tau later it agrees with the parent run straight on to the step tolerance (the
    step sizes and the last step's spectra are not carried over: not bitwise)."""
    num = numerics(mechanics=mechanics, snapshot_times=(0.0,))
    _, end = run(PARAMS, dataclasses.replace(num, t_final=20.0), 6, keep_state=True)
    assert end is not None
    child = run(PARAMS, dataclasses.replace(num, t_final=10.0), 99, initial=InitialState.at(end))
    for i, name in enumerate(("q1", "q2", "A")):
        assert np.array_equal(child[name].values[0], end.fields[i]), name
    straight = run(PARAMS, num, 6)
    for name in ("sigma2_S", "mean_S"):
        a = float(straight[name].sel(t=30.0))
        b = float(child[name].sel(t=10.0))
        assert abs(a - b) <= 1e-3 * abs(a), (name, a, b)


def test_initial_fields_of_the_wrong_shape_are_refused():
    num = numerics(t_final=5.0, snapshot_times=())
    with pytest.raises(ParameterError, match=r"fields of shape \(3, 32, 32\)"):
        run(PARAMS, num, 0, initial=InitialState(np.zeros((3, 16, 16))))
