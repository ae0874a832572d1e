"""A protocol is resolved or refused (nematic_solids.model.protocol, .solver_base, .time_scales):
no step is longer than its fraction of a sine's period or a ramp piece; a resolved sine's response
converges at the scheme's order as that fraction shrinks (and the default is within 2e-5 of the
converged response); a sine faster than the model's floor, a protocol forcing more steps than the
work bound, and values or rates that are not finite anywhere on the time axis are refused, by the
model and by a campaign's validation with file:line."""

from __future__ import annotations

import math

import numpy as np
import pytest

import nematic_solids.model.protocol as protocol_module
from nematic_solids.model.errors import ParameterError
from nematic_solids.model.parameters import MAX_STEPS, Numerics, Parameters, check_compatible
from nematic_solids.model.protocol import protocol_from
from nematic_solids.model.simulate import run
from nematic_solids.model.solver import ETDRK4Solver
from nematic_solids.model.time_scales import PERIOD_FLOOR, relaxation_time
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.spec import load_campaign

EPS0, PERIOD = 1e-3, 10.0
#: the uniform isotropic state driven by a sine of eps: the active response is smooth and the
#: error estimate small, so the protocol's bound, not the tolerance, sets the step
DRIVEN = {
    "S0": 0.0,
    "noise_modes": 4,
    "alpha_minus_B": 0.3,
    "protocol": {"eps": {"sine": {"amplitude": EPS0, "period": PERIOD}}},
}
NUMERICS = Numerics(
    resolution=16, t_final=4 * PERIOD, save_every=PERIOD / 2, mechanics="linear", dt_max=2.0
)


def _steps(monkeypatch) -> list[tuple[float, float]]:
    steps: list[tuple[float, float]] = []
    step = ETDRK4Solver.step

    def spy(self, u, t, h):
        steps.append((t, h))
        return step(self, u, t, h)

    monkeypatch.setattr(ETDRK4Solver, "step", spy)
    return steps


def test_no_step_is_longer_than_its_share_of_a_sine_or_a_ramp(monkeypatch):
    protocol = {
        "eps": {"sine": {"amplitude": 0.001, "period": 4.0, "start": 3.0}},
        "chi": {"ramp": [[0, 10.0], [2.0, 9.0], [12.0, 8.0]]},
    }
    p = Parameters.from_dict({**DRIVEN, "protocol": protocol})
    steps = _steps(monkeypatch)
    ds = run(p, NUMERICS.replace(t_final=16.0, save_every=8.0), 0)
    assert ds.attrs["status"] == "ok"
    for t, h in steps:
        bound = min(
            4.0 / 16 if t >= 3.0 else math.inf,
            2.0 / 8 if t < 2.0 else (10.0 / 8 if t < 12.0 else math.inf),
        )
        assert h <= bound * (1 + 1e-12), (t, h, bound)
    # the bounds are what limits them (dt_max = 2 would allow more): they are reached (on
    # the step ladder dt_max 2^(-j/8), within 2^(-1/8) of them)
    assert max(h for t, h in steps if t >= 3.0) > 0.9 * 4.0 / 16
    assert max(h for t, h in steps if t < 2.0) > 0.9 * 2.0 / 8


def test_a_resolved_sine_converges_as_the_bound_tightens(monkeypatch):
    """The stress of the driven isotropic state with the largest step at T/4 ... T/64 against
    T/128: the error falls at fourth order (ETDRK4) and is below 2e-5 of the active response at
    the default T/16; without the bound (dt_max = T/5 here) it is about 100 times larger."""
    p = Parameters.from_dict(DRIVEN)
    out = {}
    for k in (1e-9, 8, 16, 32, 128):
        monkeypatch.setattr(protocol_module, "SINE_STEP_FRACTION", 1.0 / k)
        out[k] = run(p, NUMERICS, 0)
    assert protocol_module.SINE_STEP_FRACTION != 1.0 / 16  # patched; the default restored after
    ref = out[128].stress_shear.values
    t = out[128].t.values
    response = np.abs(ref - 2 * EPS0 * np.sin(2 * np.pi * t / PERIOD)).max()
    assert response > 1e-4  # the active part of the stress is there to be resolved
    err = {k: np.abs(out[k].stress_shear.values - ref).max() / response for k in out if k != 128}
    assert err[16] < 2e-5
    assert err[8] / err[16] > 8
    assert err[16] / err[32] > 8
    assert err[1e-9] > 50 * err[16]  # measured: 96 times


def test_the_default_bound_is_the_stated_one():
    p = Parameters.from_dict(DRIVEN)
    assert protocol_module.SINE_STEP_FRACTION == 1.0 / 16
    assert p.protocol.max_step(0.0) == PERIOD / 16
    ramp, _ = protocol_from({"chi": {"ramp": [[0, 1.0], [4.0, 2.0]]}})
    assert ramp.max_step(1.0) == 0.5
    assert ramp.max_step(5.0) == math.inf


@pytest.mark.parametrize("period", [1.0e-9, 1.0e-12])
def test_a_sine_faster_than_the_floor_is_refused(period):
    p = Parameters.from_dict({"protocol": {"eps": {"sine": {"amplitude": 0.01, "period": period}}}})
    floor = PERIOD_FLOOR * relaxation_time(p)
    assert floor == pytest.approx(0.02)  # defaults: min(gamma / A0 = 10, tau / zeta = 2) / 100
    with pytest.raises(ParameterError) as err:
        check_compatible(p, Numerics(t_final=300.0))
    assert err.value.name == "protocol.eps.sine.period"
    # at the floor it runs (and forces its 16 steps per period)
    ok = Parameters.from_dict({"protocol": {"eps": {"sine": {"amplitude": 0.01, "period": floor}}}})
    check_compatible(ok, Numerics(t_final=300.0))
    assert ok.protocol.forced_steps(300.0) == pytest.approx(300.0 / floor * 16)


def test_a_protocol_forcing_more_steps_than_the_bound_is_refused():
    p = Parameters.from_dict({"protocol": {"eps": {"sine": {"amplitude": 0.01, "period": 0.05}}}})
    t_final = MAX_STEPS * 0.05 / 16 * 1.01
    with pytest.raises(ParameterError, match="steps forced"):
        check_compatible(p, Numerics(t_final=t_final, save_every=t_final / 10, dt_max=t_final))


@pytest.mark.parametrize(
    "raw",
    [
        {"alpha_minus_B": {"ramp": [[0, -1.7e308], [1, 1.7e308]]}},
        {"chi": {"ramp": {"from": 0.0, "to": 1.0e308, "start": 0.0, "duration": 1.0e-10}}},
        {"eps": {"sine": {"mean": 1.0e308, "amplitude": 1.0e308, "period": 1.0}}},
        {"alpha_minus_B": {"sine": {"amplitude": 1.0e308, "period": 1.0}}},
    ],
)
def test_values_and_rates_not_finite_anywhere_are_refused(raw):
    with pytest.raises(ParameterError, match="finite"):
        protocol_from(raw)


CAMPAIGN = """name: fast
parameters: {{noise_modes: 4}}
numerics: {{resolution: 16, t_final: 1.0, save_every: 0.5}}
protocol:
  eps: {{sine: {{amplitude: 0.01, period: 1.0}}}}
sweep:
  axes:
    eps_period: [{periods}]
{fits}"""


def _problems(tmp_path, periods: str, fits: str = "") -> list:
    f = tmp_path / "c.yaml"
    f.write_text(CAMPAIGN.format(periods=periods, fits=fits))
    with pytest.raises(CampaignError) as err:
        load_campaign(f)
    return err.value.problems


def test_validation_refuses_a_fast_sine_and_unresolved_moduli_with_file_and_line(tmp_path):
    (problem,) = _problems(tmp_path, "1.0, 1.0e-9")
    assert problem.path == "sweep.axes.eps_period"
    assert problem.location.endswith("c.yaml:8")
    assert "eps_period=1e-09" in problem.message
    assert "period >= 0.02" in problem.message
    (problem,) = _problems(tmp_path, "1.0, 2.0", "fits: [moduli]")
    assert problem.path == "sweep.axes.eps_period"
    assert "save_every <= T/8" in problem.message
