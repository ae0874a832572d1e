"""The py-pde adapter (sweep/models/pypde.py) on py-pde's heat equation and on a PDE of
expressions with a time-dependent diffusivity: decaying Fourier modes against the discrete and
the continuum solutions, settings metadata, determinism per seed, exact continuation, chains
and the errors for bad input."""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass

import numpy as np
import pde
import pytest
import xarray as xr
from pde.fields.base import FieldBase

from nematic_solids.sweep.models.interface import (
    Model,
    Observable,
    RunOutcome,
    RunRequest,
    defaults,
    setting,
)
from nematic_solids.sweep.models.pypde import (
    FunctionMeasure,
    PDEState,
    SolverSettings,
    numerics,
    parameter,
    pde_model,
)

N = 32  # grid points of the periodic interval [0, 2 pi)


@dataclass(frozen=True)
class Heat(SolverSettings):
    diffusivity: float = parameter(0.5, "diffusivity", units="L2 T-1")
    mode: int = numerics(3, "wavenumber of the initial cosine", sweepable=False)
    noise: float = numerics(0.0, "white noise added to the initial cosine")
    t_final: float = numerics(1.0, "final time")
    dt: float = numerics(0.01, "time step")
    save_every: float = numerics(0.25, "time between saves")


def grid(s: Heat) -> pde.CartesianGrid:
    return pde.CartesianGrid([(0.0, 2 * math.pi)], [N], periodic=True)


def cosine(g: pde.GridBase, s: Heat, rng: np.random.Generator) -> pde.ScalarField:
    x = g.axes_coords[0]
    return pde.ScalarField(g, np.cos(s.mode * x) + s.noise * rng.standard_normal(N))


def amplitude(state: FieldBase) -> float:
    """The cosine's amplitude: sqrt(2) times the rms."""
    return float(np.sqrt(2 * np.mean(np.asarray(state.data) ** 2)))


AMPLITUDE = FunctionMeasure(Observable("amplitude", "amplitude_final", "mode amplitude"), amplitude)
HEAT = pde_model("heat", pde.DiffusionPDE, Heat, grid, cosine, [AMPLITUDE])


def request(seed: int = 0, **numerics_values: object) -> RunRequest:
    num = {**defaults(HEAT, "numerics"), **numerics_values}
    return RunRequest(parameters=defaults(HEAT, "parameter"), numerics=num, seed=seed)


def end(outcome: RunOutcome) -> PDEState:
    assert isinstance(outcome.end_state, PDEState)
    return outcome.end_state


def rk4_factor(z: float) -> float:
    return 1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24


def test_the_model_declares_its_settings_from_the_dataclass() -> None:
    assert isinstance(HEAT, Model)
    s = {x.name: x for x in HEAT.settings}
    assert s["diffusivity"].kind == "parameter"
    assert (s["diffusivity"].units, s["diffusivity"].long_name) == ("L2 T-1", "diffusivity")
    assert s["mode"].kind == "numerics"
    assert s["mode"].type is int
    assert not s["mode"].sweepable
    assert s["scheme"].choices == ("runge-kutta", "euler")
    assert HEAT.capabilities.exact_continuation
    assert HEAT.capabilities.start_from_state
    assert not HEAT.capabilities.protocols


def test_a_decaying_mode_of_the_heat_equation() -> None:
    """cos(k x) decays by RK4's factor R(-D kappa^2 dt) per step, kappa^2 the five-point
    Laplacian's (2/dx sin(k dx/2))^2: equal to rounding. The continuum exp(-D k^2 t) differs by
    D (k^2 - kappa^2) t <= D k^4 dx^2 t / 12 in the exponent."""
    out = HEAT.run(request())
    ds = out.dataset
    d, k, dx, dt = 0.5, 3, 2 * math.pi / N, 0.01
    kappa2 = (2 / dx * math.sin(k * dx / 2)) ** 2
    steps = np.rint(ds.time.values / dt)
    discrete = rk4_factor(-d * kappa2 * dt) ** steps
    np.testing.assert_allclose(ds.amplitude.values, discrete, rtol=1e-12)
    continuum = np.exp(-d * k**2 * ds.time.values)
    bound = d * k**4 * dx**2 * ds.time.values / 12
    assert np.all(np.abs(np.log(ds.amplitude.values / continuum)) <= bound + 1e-9)
    assert ds.amplitude.values[-1] < 0.02  # it really decayed: exp(-4.5) = 0.011
    assert float(ds.amplitude_final) == ds.amplitude.values[-1]
    assert list(ds.time.values) == pytest.approx([0, 0.25, 0.5, 0.75, 1.0])
    assert ds.u_final.dims == ("x",)
    assert end(out).t == pytest.approx(1.0)


def test_runs_are_deterministic_per_seed() -> None:
    a, b, c = (HEAT.run(request(seed, noise=0.1)).dataset for seed in (4, 4, 5))
    xr.testing.assert_identical(a, b)
    assert not np.array_equal(a.u_final.values, c.u_final.values)


def test_continuation_with_a_fixed_step_is_exact() -> None:
    whole = HEAT.run(request(t_final=1.0))
    half = HEAT.run(request(t_final=0.5))
    rest = HEAT.run(dataclasses.replace(request(t_final=1.0), start=half.end_state))
    np.testing.assert_array_equal(rest.dataset.u_final.values, whole.dataset.u_final.values)
    np.testing.assert_array_equal(rest.dataset.amplitude.values, whole.dataset.amplitude.values)
    np.testing.assert_array_equal(rest.dataset.time.values, whole.dataset.time.values)
    assert end(rest).t == end(whole).t
    assert rest.dataset.attrs["continuation"] == "exact"
    assert not rest.warnings


def test_continuation_with_adaptive_steps_says_it_is_not_exact() -> None:
    half = HEAT.run(request(t_final=0.5, adaptive=True))
    rest = HEAT.run(dataclasses.replace(request(t_final=1.0, adaptive=True), start=half.end_state))
    assert rest.dataset.attrs["continuation"].startswith("not exact")
    assert any("not equal" in w for w in rest.warnings)
    whole = HEAT.run(request(t_final=1.0, adaptive=True))
    np.testing.assert_allclose(
        rest.dataset.amplitude.values, whole.dataset.amplitude.values, rtol=1e-3
    )


def test_a_chain_starts_from_the_end_state_at_t_zero() -> None:
    first = HEAT.run(request(t_final=0.5))
    second = HEAT.run(dataclasses.replace(request(t_final=0.5), initial=first.end_state))
    whole = HEAT.run(request(t_final=1.0))
    assert second.dataset.time.values[0] == 0.0
    np.testing.assert_allclose(
        second.dataset.u_final.values, whole.dataset.u_final.values, rtol=1e-12, atol=1e-15
    )


def test_an_end_state_round_trips_through_a_dataset(tmp_path) -> None:
    state = end(HEAT.run(request()))
    state.to_dataset().to_netcdf(tmp_path / "end.nc")
    with xr.open_dataset(tmp_path / "end.nc") as ds:
        back = PDEState.from_dataset(ds.load())
    np.testing.assert_array_equal(back.data, state.data)
    assert (back.t, back.times, dict(back.series)) == (state.t, state.times, dict(state.series))


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"numerics": {"dt": 0.03}}, "a whole number of steps"),
        ({"numerics": {"t_final": 0.3}}, "a whole number of save_every"),
        ({"numerics": {"scheme": "leapfrog"}}, "one of ['runge-kutta', 'euler']"),
        ({"parameters": {"diffusivity": "fast"}}, "is not float"),
        ({"parameters": {"viscosity": 1.0}}, "unknown settings ['viscosity']"),
        ({"initial": PDEState(np.zeros(7), 0.0)}, "PDEState of shape (32,)"),
    ],
)
def test_bad_input_is_refused_with_the_reason(change: dict, message: str) -> None:
    base = request()
    req = dataclasses.replace(
        base,
        parameters={**base.parameters, **change.get("parameters", {})},
        numerics={**base.numerics, **change.get("numerics", {})},
        initial=change.get("initial"),
    )
    with pytest.raises(ValueError, match=re.escape(message)):
        HEAT.run(req)


# a PDE of expressions whose diffusivity is a function of time (a protocol)
@dataclass(frozen=True)
class Ramp(Heat):
    diffusivity: float = parameter(0.5, "diffusivity", protocol=True)


def ramp_pde(s: Ramp) -> pde.PDE:
    d = s.diffusivity if callable(s.diffusivity) else (lambda t, c=s.diffusivity: c)
    return pde.PDE({"u": "D(t) * laplace(u)"}, user_funcs={"D": d})


class Linear:
    """D(t) = a + b t, as a protocol object."""

    def __init__(self, a: float, b: float) -> None:
        self.a, self.b = a, b

    def __call__(self, t: float) -> float:
        return self.a + self.b * t


@pytest.mark.slow  # about a minute on 2 loaded cores: py-pde's numpy path, 400 evaluations
def test_a_time_dependent_setting_follows_its_protocol() -> None:
    """With D(t) = 0.5 + 0.5 t the mode decays as exp(-kappa^2 (0.5 t + 0.25 t^2)). RK4's
    error in the exponent is at most z^5/120 per step, z = kappa^2 D dt <= 0.089: 4.7e-6 over
    the 100 steps to t = 1."""
    model = pde_model("ramp", ramp_pde, Ramp, grid, cosine, [AMPLITUDE])
    assert not model.capabilities.protocols  # a campaign's protocol: section: not wired
    assert setting(model, "diffusivity").protocol  # a function of time in a RunRequest
    req = RunRequest(
        parameters={"diffusivity": Linear(0.5, 0.5)},
        numerics={**defaults(model, "numerics"), "backend": "numpy"},
        seed=0,
    )
    ds = model.run(req).dataset
    dx, t = 2 * math.pi / N, ds.time.values
    kappa2 = (2 / dx * math.sin(3 * dx / 2)) ** 2
    np.testing.assert_allclose(
        ds.amplitude.values, np.exp(-kappa2 * (0.5 * t + 0.25 * t**2)), rtol=5e-6
    )


class Checkpoints:
    """Collects the states a run hands to its checkpoint callback and the progress times."""

    def __init__(self) -> None:
        self.states: list[PDEState] = []
        self.times: list[float] = []

    def checkpoint(self, state: object) -> None:
        assert isinstance(state, PDEState)
        self.states.append(state)

    def progress(self, t: float) -> None:
        self.times.append(t)


def test_checkpoints_are_end_states_that_continue_exactly() -> None:
    seen = Checkpoints()
    req = dataclasses.replace(
        request(t_final=1.0),
        checkpoint=seen.checkpoint,
        checkpoint_every=0.5,
        progress=seen.progress,
    )
    whole = HEAT.run(req)
    assert [s.t for s in seen.states] == pytest.approx([0.5, 1.0])
    assert seen.times == pytest.approx([0, 0.25, 0.5, 0.75, 1.0])
    rest = HEAT.run(dataclasses.replace(request(t_final=1.0), start=seen.states[0]))
    np.testing.assert_array_equal(rest.dataset.u_final.values, whole.dataset.u_final.values)
    np.testing.assert_array_equal(rest.dataset.amplitude.values, whole.dataset.amplitude.values)


def test_a_finished_run_continued_to_its_own_end_is_unchanged() -> None:
    whole = HEAT.run(request(t_final=1.0))
    again = HEAT.run(dataclasses.replace(request(t_final=1.0), start=end(whole)))
    xr.testing.assert_identical(again.dataset.drop_attrs(), whole.dataset.drop_attrs())
    with pytest.raises(ValueError, match="shorter t_final"):
        HEAT.run(dataclasses.replace(request(t_final=0.5), start=end(whole)))


# two fields (a FieldCollection): u_t = -v, v_t = u from u = 1, v = 0 is a rotation
@dataclass(frozen=True)
class Rotation(SolverSettings):
    rate: float = parameter(1.0, "angular frequency")
    t_final: float = numerics(1.0, "final time")
    dt: float = numerics(0.01, "time step")
    save_every: float = numerics(0.5, "time between saves")


def rotation_pde(s: Rotation) -> pde.PDE:
    return pde.PDE({"u": f"-{s.rate} * v", "v": f"{s.rate} * u"})


def rotation_start(g: pde.GridBase, s: Rotation, rng: np.random.Generator) -> pde.FieldCollection:
    return pde.FieldCollection(
        [pde.ScalarField(g, 1.0, label="u"), pde.ScalarField(g, 0.0, label="v")]
    )


def four_points(s: Rotation) -> pde.CartesianGrid:
    return pde.CartesianGrid([(0.0, 1.0)], [4], periodic=True)


def mean_u(state: FieldBase) -> float:
    assert isinstance(state, pde.FieldCollection)
    return float(np.mean(state[0].data))


def test_a_pde_of_two_fields() -> None:
    """u = cos(t), v = sin(t); RK4's phase error is t dt^4/120 = 1e-10 at t = 1."""
    model = pde_model(
        "rotation",
        rotation_pde,
        Rotation,
        four_points,
        rotation_start,
        [FunctionMeasure(Observable("u", "u_final", "mean of u"), mean_u)],
    )
    req = RunRequest(
        parameters=defaults(model, "parameter"), numerics=defaults(model, "numerics"), seed=0
    )
    out = model.run(req)
    ds = out.dataset
    np.testing.assert_allclose(ds.u.values, np.cos(ds.time.values), rtol=1e-9)
    np.testing.assert_allclose(ds.v_final.values, math.sin(1.0), rtol=1e-9)
    assert end(out).data.shape == (2, 4)
