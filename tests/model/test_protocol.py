"""Time protocols (nematic_solids.model.protocol): the forms and their canonical text, validation, a
constant protocol being the plain parameter; the integrator landing on every switch time and the
stages using the value at their time on the step's piece; the displacement rate under a changing
alpha or eps being the time derivative of the force balance (both mechanics); the compiled and numpy
paths agreeing; a protocol run continued exactly from its saved states."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nematic_solids.model.checkpoint import RunState, Schedule
from nematic_solids.model.errors import ParameterError
from nematic_solids.model.fourier import SpectralGrid
from nematic_solids.model.mechanics import make_mechanics
from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.model.protocol import Piecewise, Protocol, protocol_from
from nematic_solids.model.simulate import run
from nematic_solids.model.solver import ETDRK4Solver
from nematic_solids.model.solver_base import ETDSolver

SWITCH_OFF = {"alpha_minus_B": [[0, 1.0], [7.3, 0.05], [13.1, 1.0]]}


def params(protocol, **kw) -> Parameters:
    return Parameters.from_dict(
        {"noise_modes": 8, "alpha_minus_B": 1.0, **kw, "protocol": protocol}
    )


def test_forms_their_values_and_one_canonical_text():
    p, _ = protocol_from(
        {
            "alpha_minus_B": {"pulse": {"base": 1.0, "level": 0.1, "start": 5, "duration": 3}},
            "chi": {"ramp": {"from": 10, "to": 4, "start": 2, "duration": 6}},
            "eps": {"sine": {"amplitude": 0.02, "period": 4, "start": 1}},
        }
    )
    assert p.breaks() == (1.0, 2.0, 5.0, 8.0)
    v = p.values
    assert v(4.9)["alpha_minus_B"] == 1.0
    assert v(5.0)["alpha_minus_B"] == 0.1
    assert v(8.0, after=7.5)["alpha_minus_B"] == 0.1  # the step's piece: before the switch
    assert v(8.0)["alpha_minus_B"] == 1.0  # right-continuous
    assert v(5.0)["chi"] == pytest.approx(10 - 6 * 3 / 6)
    assert p.rates(3.0)["chi"] == pytest.approx(-1.0)
    assert p.rates(9.0)["chi"] == 0.0
    assert v(0.5)["eps"] == 0.0
    assert v(2.0)["eps"] == pytest.approx(0.02)
    assert p.rates(1.0)["eps"] == pytest.approx(0.02 * 2 * np.pi / 4)
    # the named forms become points: the same function written as points is the same protocol
    q, _ = protocol_from(
        {
            "alpha_minus_B": [[0, 1.0], [5, 0.1], [8, 1.0]],
            "chi": {"ramp": [[0, 10], [2, 10], [8, 4]]},
            "eps": {"sine": {"mean": 0, "amplitude": 0.02, "period": 4, "start": 1}},
        }
    )
    assert p == q
    assert p.to_dict() == q.to_dict()
    assert protocol_from(p.to_dict())[0] == p


def test_a_constant_protocol_is_the_plain_parameter():
    plain = Parameters.from_dict({"alpha_minus_B": 0.7, "chi": 3.0})
    for chi in (
        [[0, 3.0]],
        [[0, 3.0], [10, 3.0]],
        {"sine": {"mean": 3.0, "amplitude": 0, "period": 1}},
    ):
        p = Parameters.from_dict({"protocol": {"alpha_minus_B": [[0, 0.7]], "chi": chi}})
        assert p == plain
        assert p.to_dict() == plain.to_dict()
        assert not p.protocol
    varying = Parameters.from_dict({"protocol": {"chi": [[0, 3.0], [4, 2.0]]}})
    assert varying.chi == 3.0
    assert varying.at(5.0).chi == 2.0
    assert not varying.at(5.0).protocol


@pytest.mark.parametrize(
    ("protocol", "where"),
    [
        ({"eps": {"sine": {"amplitude": 0.6, "period": 3}}}, "protocol.eps"),
        ({"chi": [[0, 1.0], [3, -1.0]]}, "protocol.chi"),
        ({"chi": [[1, 1.0], [3, 2.0]]}, "protocol.chi.steps[0] time"),
        ({"chi": [[0, 1.0], [3, 2.0], [3, 1.0]]}, "protocol.chi.steps[2] time"),
        ({"kappa": [[0, 1.0], [3, 2.0]]}, "protocol.kappa"),
        ({"chi": {"pulse": {"base": 1, "level": 0, "start": 2}}}, "protocol.chi.pulse"),
        ({"chi": {"pulse": {"base": 1, "level": 0, "start": 2, "duration": 0}}}, "duration"),
        # an end the sum cannot hold: at the start (rounded away) or past the largest float
        (
            {"chi": {"pulse": {"base": 1, "level": 0, "start": 0.1, "duration": 1e-300}}},
            "'protocol.chi.pulse.duration': 1e-300 (allowed: a duration that ends after its start",
        ),
        (
            {"chi": {"ramp": {"from": 0, "to": 1, "start": 1e308, "duration": 1e308}}},
            "protocol.chi.ramp.duration",
        ),
        (
            {"eps": {"pulse": {"base": 0, "level": 0.1, "start": 1e308, "duration": 1e308}}},
            "start + duration is inf",
        ),
        # a ramp piece too short for its steps (1/8 of it) to move the time on
        (
            {"chi": {"ramp": {"from": 0, "to": 0.4, "start": 0.1, "duration": 2e-17}}},
            "'protocol.chi.ramp': 'a piece from t = 0.1 to t = 0.10000000000000002' (allowed: "
            "ramp pieces at least 8 times the spacing of floating-point times at their end "
            "(1.39e-17 there) long)",
        ),
        ({"chi": {"ramp": [[0, 0.0], [1e6, 0.1], [1e6 + 5e-10, 0.2]]}}, "protocol.chi.ramp"),
        ({"eps": {"sine": {"amplitude": 0.1, "period": 0}}}, "protocol.eps.sine.period"),
        ({"chi": {"ramp": [[0, 1], [2, "x"]]}}, "protocol.chi.ramp[1] value"),
        ({"chi": {"steps": [[0, 1]], "ramp": [[0, 1]]}}, "exactly one of"),
    ],
)
def test_a_bad_protocol_names_its_place(protocol, where):
    with pytest.raises(ParameterError, match=None) as err:
        Parameters.from_dict({"protocol": protocol})
    assert where in str(err.value)


def test_a_step_that_would_not_move_the_time_on_ends_the_run(monkeypatch):
    """A ramp piece shorter than 8 float spacings of its time, built past the reader's check,
    ends the run (``time_unresolved``) instead of holding it at one time forever."""
    piece = Piecewise(((0.0, 0.0), (0.1, 0.0), (math.nextafter(0.1, 1.0), 0.4)), linear=True)
    p = Parameters.from_dict({"noise_modes": 8, "protocol": Protocol((("chi", piece),))})
    steps = []
    step = ETDRK4Solver.step

    def counted(self, u, t, h):
        steps.append(t)
        assert len(steps) < 100_000, f"the run stalls at t = {t!r}"
        return step(self, u, t, h)

    monkeypatch.setattr(ETDRK4Solver, "step", counted)
    ds = run(p, Numerics(resolution=32, t_final=0.2, save_every=0.1), 0)
    assert ds.attrs["status"] == "failed"
    assert ds.attrs["reason"] == "time_unresolved", ds.attrs
    assert ds.attrs["t_failed"] == 0.1


def _spy_steps(monkeypatch):
    """Record every attempted step (t, h) and every right-hand side's (time, step start,
    constants the PDE and the mechanics hold)."""
    steps, stages = [], []
    step, split = ETDRK4Solver.step, ETDSolver.split

    def spy_step(self, u, t, h):
        steps.append((t, h))
        return step(self, u, t, h)

    def spy_split(self, u, q_hat, t, disp=None, F=None):
        out = split(self, u, q_hat, t, disp, F)
        m = self.pde.mechanics
        stages.append(
            (
                t,
                self._after,
                self.pde.params,
                m.moduli.alpha,
                m.Fbar.copy(),
                m.alpha_rate,
                m.eps_rate,
            )
        )
        return out

    monkeypatch.setattr(ETDRK4Solver, "step", spy_step)
    monkeypatch.setattr(ETDSolver, "split", spy_split)
    return steps, stages


@pytest.mark.parametrize("mechanics", ["finite", "linear"])
def test_steps_land_on_every_switch_and_stages_use_their_piece(monkeypatch, mechanics):
    protocol = {
        "alpha_minus_B": [[0, 1.0], [2.3, 0.4], [4.1, 0.9]],
        "chi": {"ramp": [[0, 10.0], [3.7, 6.0]]},
        "eps": {"sine": {"amplitude": 0.01, "period": 2.5, "start": 1.05}},
    }
    p = params(protocol)
    steps, stages = _spy_steps(monkeypatch)
    ds = run(p, Numerics(resolution=32, t_final=6.0, save_every=1.0, mechanics=mechanics), 0)
    assert ds.attrs["status"] == "ok"
    breaks = p.protocol.breaks()
    assert breaks == (1.05, 2.3, 3.7, 4.1)
    for t, h in steps:  # no step crosses a switch
        assert not any(t < b < t + h - 1e-12 for b in breaks), (t, h)
    starts = {t for t, _ in steps}
    assert all(b in starts for b in breaks)  # a step begins exactly at each switch time
    inside = 0
    for t, after, current, alpha, Fbar, alpha_rate, eps_rate in stages:
        if after is None:  # a save or a projection: right-continuous
            after = t
        else:
            inside += 1
        want = p.at(t, after)
        rates = p.protocol.rates(t, after)
        assert current == want
        assert alpha == want.alpha
        assert np.array_equal(Fbar, np.diag([1 + want.eps, 1 - want.eps]))
        assert alpha_rate == rates["alpha_minus_B"] == 0.0
        assert eps_rate == rates["eps"]
    assert inside > 4 * len(steps) - 10  # every stage of every step was checked
    # a stage at the end of a step ending on a switch used the value before it
    for b in (2.3, 4.1):  # the jumps of alpha - B
        ends = [s for s in stages if s[1] is not None and s[1] < b and abs(s[0] - b) < 1e-9]
        assert ends
        assert all(s[2] == p.at(b, s[1]) != p.at(b) for s in ends)


def _state(n: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """A smooth order field with S of about 0.2 (well inside the well-posed range)."""
    x = np.arange(n) / n
    X, Y = np.meshgrid(x, x, indexing="ij")
    theta = np.pi * (np.sin(2 * np.pi * X) * np.cos(4 * np.pi * Y) + 0.3 * rng.standard_normal())
    S = 0.15 + 0.05 * np.cos(2 * np.pi * (X + 2 * Y))
    return S * np.cos(2 * theta), S * np.sin(2 * theta)


@pytest.mark.parametrize("mechanics", ["finite", "linear"])
def test_the_displacement_rate_is_the_time_derivative_of_force_balance(mechanics, rng):
    """Along Q(t) = Q + t Qdot, alpha(t) = alpha + t alpha', eps(t) = eps + t eps', the rate
    solve's displacement rate (finite) or spin (linear) equals the central difference of the
    force-balance solutions: the rates of alpha and eps drive it
    (nematic_solids.model.mechanics)."""
    n = 32
    num = Numerics(
        resolution=n, mechanics=mechanics, newton_tol=1e-12, spin_tol=1e-12, backend="numpy"
    )
    base = Parameters(alpha=1.3, eps=0.02, kappa=5.0)
    rates = {"alpha_minus_B": 0.7, "eps": -0.05}
    grid = SpectralGrid(n, fft_backend="scipy")

    def mech_at(dt: float):
        p = base.replace(
            alpha=base.alpha + dt * rates["alpha_minus_B"], eps=base.eps + dt * rates["eps"]
        )
        m = make_mechanics(p, num, grid)
        m.set_parameters(p, rates)
        return m

    q1, q2 = _state(n, rng)
    m0 = mech_at(0.0)
    state = m0.solve(q1, q2)
    R = 0.1 * np.stack(_state(n, rng))
    qdot, omega = m0.corotational(state, q1, q2, R)
    d = 1e-5
    ends = []
    for sign in (1.0, -1.0):
        m = mech_at(sign * d)
        ends.append(m.solve(q1 + sign * d * qdot[0], q2 + sign * d * qdot[1]).u_hat)
    fd_hat = (ends[0] - ends[1]) / (2 * d)
    if mechanics == "finite":
        scale = np.abs(fd_hat).max()
        assert np.abs(m0.udot_hat - fd_hat).max() < 1e-6 * scale
        # without the protocol's rates the rate solve misses a part of it
        m0.set_parameters(base, {})
        m0.corotational(m0.solve(q1, q2), q1, q2, R)
        assert np.abs(m0.udot_hat - fd_hat).max() > 1e-2 * scale
    else:
        grad = grid.inverse(grid.grad_hat(fd_hat))
        fd_omega = 0.5 * (grad[1, 0] - grad[0, 1])
        assert np.abs(omega - fd_omega).max() < 1e-6 * np.abs(fd_omega).max()


def test_compiled_and_numpy_paths_agree_under_a_protocol():
    protocol = {"alpha_minus_B": {"ramp": [[0, 1.0], [4, 0.6]]}, "chi": [[0, 10.0], [2.2, 5.0]]}
    for mechanics in ("linear", "finite"):
        num = Numerics(resolution=32, t_final=5.0, save_every=1.0, mechanics=mechanics)
        a = run(params(protocol), num, 1)
        b = run(params(protocol), num.replace(backend="numpy"), 1)
        for name in ("sigma2_S", "mean_S", "mean_A"):
            assert np.allclose(a[name], b[name], rtol=1e-9, atol=1e-14), (mechanics, name)


@pytest.mark.parametrize("mechanics", ["finite", "linear"])
def test_a_protocol_run_continues_exactly_across_its_switches(mechanics):
    p = params(SWITCH_OFF)
    num = Numerics(resolution=32, t_final=16.0, save_every=1.0, mechanics=mechanics)
    states: list[RunState] = []
    straight = run(p, num, 2, checkpoint=states.append, schedule=Schedule(tau=3.0))
    assert [s.t for s in states] == [3.0, 6.0, 9.0, 12.0, 15.0]
    for state in states[1:3]:  # before and between the switches
        again = run(p, num, 2, start=state)
        for name in straight.data_vars:
            if name != "wall_time":
                assert np.array_equal(straight[name], again[name], equal_nan=True), name
    # the pattern fades while activity is off and grows back after (the run's physics)
    s2 = straight.sigma2_S.sel(t=[7.0, 13.0, 16.0]).values
    assert s2[1] < 0.5 * s2[0]
    assert s2[2] > 2 * s2[1]
    assert straight.attrs["param_protocol"]
    assert "steps" in straight.attrs["param_protocol"]


def test_the_empty_protocol_changes_nothing():
    assert not Protocol()
    assert Protocol().next_break(3.0) == np.inf
    assert "protocol" not in Parameters().to_dict()
