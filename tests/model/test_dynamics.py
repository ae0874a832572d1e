"""Dynamics: reference vs fast rates, explicit cross-check, order of accuracy, invariants,
passive free-energy decay, symmetry, determinism."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from pde import FieldCollection
from pde.solvers import Controller

from nematic_solids.model.errors import SimulationFailure
from nematic_solids.model.fourier import HAVE_FFTW
from nematic_solids.model.initial import band_limited_field, band_limited_modes, initial_fields
from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.model.pde import ActiveNematicPDE, make_state
from nematic_solids.model.simulate import run
from nematic_solids.model.solver import ETDRK2Solver, ETDRK4Solver
from nematic_solids.model.split import SpectralSplit

# a fixed small workload for the numerics' tests (its own constants, so the measured errors and
# orders quoted below do not move with the model's defaults)
SMALL = Parameters(noise_modes=6, K=1e-3, S0=0.2, zeta=1.0, kappa=10.0)


def _final(ds):
    return np.stack([ds[k].values[-1] for k in ("q1", "q2", "A")])


@pytest.mark.parametrize(
    ("mechanics", "incompressible", "compiled", "B_prime"),
    [
        ("linear", False, True, 0.1),
        ("linear", False, True, 0.0),
        ("linear", True, True, 0.1),
        ("linear", False, False, 0.1),
        ("linear", True, False, 0.1),
        ("finite", False, True, 0.1),
        ("finite", False, False, 0.1),
    ],
)
def test_fast_split_rate_equals_numpy_reference(mechanics, incompressible, compiled, B_prime):
    """ETDRK2's L u + N(u) is the PDE's readable ``evolution_rate`` (different code paths):
    both the compiled paths (native FFTW: the whole linear right-hand side,
    nematic_solids.model.compiled.linear_rhs; the finite-strain Krylov solves,
    nematic_solids.model.compiled.finite_krylov) and their numpy references."""
    if compiled and not HAVE_FFTW:
        pytest.skip("native FFTW not available")
    linear = mechanics == "linear"
    p = SMALL.replace(eps=0.03, B_prime=B_prime, alpha_minus_B=1.5 if linear else 1.0)
    num = Numerics(
        resolution=32,
        mechanics=mechanics,
        spin_tol=1e-12,
        newton_tol=1e-12,
        incompressible=incompressible,
        backend="compiled" if compiled else "numpy",
    )
    eq = ActiveNematicPDE(p, num)
    state = make_state(*initial_fields(p, 32, seed=4))
    if linear:
        state.data[:2] = 2.0 * state.data[:2]  # a strong Jaumann feedback: several spin iterations
    state.data[2] = 0.3 * np.cos(2 * np.pi * eq.spectral.x)[:, None]  # nonzero activity
    ref = eq.evolution_rate(state).data
    solver = ETDRK2Solver(ActiveNematicPDE(p, num))
    assert solver.pde.mechanics.compiled == compiled
    fast = solver.full_rate(state.data, 0.0)
    assert solver.pde.mechanics.spin_iterations >= (3 if linear else 1)
    np.testing.assert_allclose(fast, ref, atol=1e-9 * np.abs(ref).max())


@pytest.mark.parametrize(
    ("B_prime", "eps", "incompressible", "norm"),
    [
        (0.0, 0.0, False, "max"),
        (0.1, 0.03, False, "max"),
        (0.1, 0.0, True, "max"),
        (0.1, 0.03, False, "rms"),
    ],
)
def test_compiled_linear_step_is_bitwise_the_python_step(B_prime, eps, incompressible, norm):
    """Linear mechanics' ETDRK4 step as one compiled function
    (nematic_solids.model.compiled.linear_step) gives the bits of the Python step that calls
    the same kernels stage by stage (new state, error estimate, transforms, spin iterations),
    step after step; the max-norm error estimate is formed in the compiled step, the RMS one
    by the caller."""
    if not HAVE_FFTW:
        pytest.skip("native FFTW not available: no compiled right-hand side")
    p = SMALL.replace(alpha_minus_B=1.5, B_prime=B_prime, eps=eps)
    num = Numerics(
        resolution=32, mechanics="linear", incompressible=incompressible, error_norm=norm
    )
    state = make_state(*initial_fields(p, 32, seed=4))
    u = np.ascontiguousarray(state.data, dtype=float)
    u[:2] *= 2.0  # a strong Jaumann feedback: several spin iterations per stage
    u[2] = 0.3 * np.cos(2 * np.pi * (np.arange(32) + 0.5) / 32)[:, None]
    whole, staged = ETDRK4Solver(ActiveNematicPDE(p, num)), ETDRK4Solver(ActiveNematicPDE(p, num))
    assert whole._compiled_split is not None
    staged._compiled_split = None  # the Python step
    a, b, t = u.copy(), u.copy(), 0.0
    for h in (0.05, 0.1, 0.1, 0.025):
        (a, err_a), (b, err_b) = whole.step(a, t, h), staged.step(b, t, h)
        t += h
        assert a.tobytes() == b.tobytes()
        assert err_a == err_b
    for solver in (whole, staged):
        assert solver.stats["rhs"] == 16
    spins = [s.pde.mechanics.spin_iterations for s in (whole, staged)]
    assert spins[0] == spins[1] >= 48
    ffts = [s.pde.spectral.fft.count for s in (whole, staged)]
    assert ffts[0] == ffts[1]
    np.testing.assert_array_equal(whole.pde.mechanics.omega_hat, staged.pde.mechanics.omega_hat)


def test_compiled_linear_step_fails_a_spin_solve_like_the_python_step():
    """A spin solve that does not converge in a stage of the compiled step fails the step
    with spin_diverged, as the Python step does (the step is then retried smaller)."""
    if not HAVE_FFTW:
        pytest.skip("native FFTW not available: no compiled right-hand side")
    p = SMALL.replace(alpha_minus_B=1.5)
    num = Numerics(resolution=32, mechanics="linear", spin_tol=1e-14)
    state = make_state(*initial_fields(p, 32, seed=4))
    u = np.ascontiguousarray(state.data, dtype=float)
    u[:2] *= 2.0
    for compiled in (True, False):
        solver = ETDRK4Solver(ActiveNematicPDE(p, num))
        split = solver._split  # its compiled data hold the iteration cap
        assert isinstance(split, SpectralSplit)
        assert split._rhs_data is not None
        split._rhs_data = split._rhs_data._replace(maxiter=1)
        if compiled:
            solver._compiled_split = split
        else:
            solver._compiled_split = None
        with pytest.raises(SimulationFailure, match="did not converge in 1 iterations"):
            solver.step(u, 0.0, 0.1)


@pytest.mark.parametrize(
    ("mechanics", "scheme"), [("linear", "etdrk4"), ("finite", "etdrk4"), ("finite", "etdrk2")]
)
def test_numpy_backend_runs_the_same_trajectory(mechanics, scheme):
    """A whole adaptive run with ``backend = "numpy"`` (the readable references) takes the
    same steps to the same state as the compiled one (rounding apart)."""
    if not HAVE_FFTW:
        pytest.skip("native FFTW not available: both backends are the numpy path")
    p = SMALL.replace(alpha_minus_B=1.0, eps=0.02)
    num = Numerics(resolution=32, t_final=5.0, save_every=2.5, mechanics=mechanics, scheme=scheme)
    ours, ref = run(p, num, 3), run(p, num.replace(backend="numpy"), 3)
    assert ours.attrs["status"] == ref.attrs["status"] == "ok"
    np.testing.assert_array_equal(ours["steps"].values, ref["steps"].values)
    np.testing.assert_allclose(_final(ours), _final(ref), rtol=0, atol=1e-11)


def test_numpy_backend_runs_no_compiled_code():
    """``backend = "numpy"`` is the readable path all through: a fresh process running both
    mechanics with it calls no numba kernel (none compiled, none loaded from the cache)."""
    code = (
        "import json\n"
        "from nematic_solids.model.parameters import Numerics, Parameters\n"
        "from nematic_solids.model.simulate import run\n"
        "from nematic_solids.model.warmup import compile_counts\n"
        "p = Parameters.from_dict({'noise_modes': 6, 'alpha_minus_B': 1.0, 'eps': 0.02})\n"
        "for mech in ('linear', 'finite'):\n"
        "    ds = run(p, Numerics(resolution=16, t_final=1.0, save_every=0.5, mechanics=mech,\n"
        "                         backend='numpy'), 0)\n"
        "    assert ds.attrs['status'] == 'ok'\n"
        "print(json.dumps(compile_counts()))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=600, check=True
    ).stdout
    assert json.loads(out.strip().splitlines()[-1]) == {"compiled": 0, "loaded": 0}


@pytest.mark.parametrize(
    ("solver", "dt", "atol"),
    [
        (ETDRK2Solver, 0.005, 5e-5),  # global error ~ C dt^2 ~ 1.3e-5 here (5e-5 at dt = 0.01)
        (ETDRK4Solver, 0.05, 5e-6),  # global error ~ C dt^4 (measured 1e-6 at dt = 0.05)
    ],
)
def test_pypde_explicit_solver_runs_the_pde_class_and_agrees(solver, dt, atol):
    """py-pde's own adaptive Runge-Kutta on the same PDE class reaches the same state."""
    p = SMALL
    num = Numerics(resolution=32, mechanics="linear", spin_tol=1e-12)
    eq = ActiveNematicPDE(p, num)
    state = make_state(*initial_fields(p, 32, seed=1))
    theirs = eq.solve(
        state.copy(),
        t_range=1.0,
        dt=1e-3,
        solver="runge-kutta",
        adaptive=True,
        tolerance=1e-7,
        backend="numpy",
        tracker=None,
    )
    ours = eq.solve(state.copy(), t_range=1.0, dt=dt, solver=solver, adaptive=False, tracker=None)
    assert isinstance(ours, FieldCollection)
    np.testing.assert_allclose(ours.data, theirs.data, atol=atol)


@pytest.mark.parametrize(
    ("scheme", "dts", "order"),
    [
        ("etdrk2", (0.08, 0.04, 0.02), 1.8),
        # measured 4.06, 3.86 (linear), 4.19, 4.14 (finite, integrated), 3.83, 3.89 (equilibrium)
        ("etdrk4", (0.1, 0.05, 0.025), 3.5),
    ],
)
@pytest.mark.parametrize(
    ("mechanics", "displacement"),
    [
        ("linear", "integrated"),
        pytest.param("finite", "integrated", marks=pytest.mark.slow),
        pytest.param("finite", "equilibrium", marks=pytest.mark.slow),
    ],
)
def test_time_step_convergence_order(mechanics, displacement, scheme, dts, order):
    """The orders of both schemes, for finite strain with the displacement integrated with
    the state (projected once per step) and with force balance solved at every stage."""
    num = Numerics(
        resolution=32,
        t_final=4,
        adaptive=False,
        mechanics=mechanics,
        scheme=scheme,
        save_every=4,
        spin_tol=1e-12,
        newton_tol=1e-12,
        displacement=displacement,
    )
    ref = _final(run(SMALL, num.replace(dt=0.005), 2))
    errs = [np.abs(_final(run(SMALL, num.replace(dt=dt), 2)) - ref).max() for dt in dts]
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(orders > order), (errs, orders)


class _FailsAboveStep(ETDRK4Solver):
    """A stage that cannot be evaluated for steps above ``h_bad`` (as a stage thrown out of
    the well-posed range by a too-large step)."""

    h_bad = 0.1

    def step(self, u, t, h):
        if h > self.h_bad:
            raise SimulationFailure("spin_diverged", "stage out of range (test)", t)
        return super().step(u, t, h)


def test_stage_failure_is_retried_with_a_smaller_step_but_a_persistent_one_fails():
    num = Numerics(resolution=32, t_final=1.0, dt=0.8, mechanics="linear")
    eq = ActiveNematicPDE(SMALL, num)
    state = make_state(*initial_fields(SMALL, 32, seed=1))
    solver = _FailsAboveStep(eq)
    Controller(solver, t_range=1.0, tracker=None).run(state.copy(), 0.8)
    assert solver.stats["rejected"] >= 2
    assert solver.stats["steps"] >= 10
    solver = _FailsAboveStep(ActiveNematicPDE(SMALL, num))
    solver.h_bad = 0.0  # fails at every step size: the original failure is the run's
    with pytest.raises(SimulationFailure, match="spin_diverged"):
        Controller(solver, t_range=1.0, tracker=None).run(state.copy(), 0.8)


def test_adaptive_error_control_tracks_the_tolerance():
    """Tightening the tolerance 10x reduces the error of sigma2_S (to a fine reference)."""
    num = Numerics(resolution=32, t_final=10, save_every=10, mechanics="linear")
    ref = run(SMALL, num.replace(adaptive=False, dt=0.005), 1)["sigma2_S"].values[-1]
    errors = [
        abs(run(SMALL, num.replace(tolerance=tol), 1)["sigma2_S"].values[-1] - ref)
        for tol in (1e-2, 1e-3, 1e-4)
    ]
    assert errors[2] < errors[1] < errors[0]
    assert errors[2] < 1e-3 * ref


@pytest.mark.parametrize("mechanics", ["linear", "finite"])
def test_passive_free_energy_never_increases(mechanics):
    """alpha = 0, chi = 0 (A stays 0): Eq. (4) is a gradient flow of Eq. (1)."""
    p = Parameters(
        alpha=0.0, chi=0.0, A0=-0.2, K=1e-3, S0=0.3, B=0.5, B_prime=0.1, eps=0.02, noise_modes=4
    )
    ds = run(p, Numerics(resolution=32, t_final=20, save_every=0.5, mechanics=mechanics), 3)
    assert ds.attrs["status"] == "ok"
    E = ds["free_energy"].values
    assert np.all(np.diff(E) <= 1e-10 * np.abs(E).max())
    assert E[-1] < E[0] - 0.01  # and it does decrease (the test can fail)
    np.testing.assert_allclose(ds["mean_A"].values, 0.0, atol=1e-14)


@pytest.mark.parametrize("mechanics", ["linear", "finite"])
def test_rotating_the_initial_state_rotates_the_result(mechanics):
    """X -> R X with R the 90-degree rotation: Q -> R Q R^T (q -> -q), eps -> -eps."""
    p = SMALL.replace(eps=0.03)
    num = Numerics(
        resolution=32,
        t_final=3,
        save_every=3,
        dt=0.05,
        adaptive=False,
        mechanics=mechanics,
        spin_tol=1e-12,
        newton_tol=1e-12,
    )
    q1, q2, A = initial_fields(p, 32, seed=7)
    rot = [-np.rot90(q1), -np.rot90(q2), np.rot90(A)]
    eq_a = ActiveNematicPDE(p, num)
    eq_b = ActiveNematicPDE(p.replace(eps=-0.03), num)
    a = eq_a.solve(
        make_state(q1, q2, A), t_range=3, dt=0.05, solver=ETDRK2Solver, adaptive=False, tracker=None
    )
    b = eq_b.solve(
        make_state(*rot), t_range=3, dt=0.05, solver=ETDRK2Solver, adaptive=False, tracker=None
    )
    expected = np.stack([-np.rot90(a.data[0]), -np.rot90(a.data[1]), np.rot90(a.data[2])])
    assert np.abs(a.data).max() > 0.1  # something happened
    np.testing.assert_allclose(b.data, expected, atol=1e-9)


def test_same_seed_bitwise_identical_different_seed_differs():
    num = Numerics(resolution=32, t_final=5, save_every=1, mechanics="finite")
    a, b = run(SMALL, num, 11), run(SMALL, num, 11)
    c = run(SMALL, num, 12)
    for name in ("q1", "q2", "A", "u1", "sigma2_S", "free_energy"):
        assert np.array_equal(a[name].values, b[name].values), name
    assert not np.array_equal(a["q1"].values, c["q1"].values)


def test_bitwise_identical_across_processes():
    """Two fresh processes give the same bits (campaigns run on different workers)."""
    import subprocess
    import sys

    code = (
        "import hashlib; from nematic_solids.model.parameters import Parameters, Numerics; "
        "from nematic_solids.model.simulate import run; "
        "ds = run(Parameters(noise_modes=6, K=1e-3, S0=0.2), Numerics(resolution=32, "
        "t_final=3, save_every=3), 5); "
        "print(hashlib.sha256(ds['q1'].values.tobytes() + ds['A'].values.tobytes())"
        ".hexdigest())"
    )
    digests = {
        subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, check=True
        ).stdout.strip()
        for _ in range(2)
    }
    assert len(digests) == 1


def test_initial_field_is_resolution_independent():
    """The same seed gives the same physical field at any resolution (DESIGN.md)."""
    n, m, c = band_limited_modes(5, 6)
    for N in (16, 40, 64):
        x = (np.arange(N) + 0.5) / N
        X, Y = np.meshgrid(x, x, indexing="ij")
        direct = sum(
            ck * np.exp(2j * np.pi * (nk * X + mk * Y)) for nk, mk, ck in zip(n, m, c, strict=True)
        )
        np.testing.assert_allclose(band_limited_field(5, 6, N), direct, atol=1e-12)
    q1, q2, A = initial_fields(Parameters(S0=0.1, noise_modes=6), 64, 5)
    np.testing.assert_allclose(np.hypot(q1, q2), 0.1, rtol=1e-12)  # homogeneous S0
    assert np.all(A == 0)
    with pytest.raises(ValueError, match="resolution"):
        band_limited_field(5, 16, 32)


def test_jaumann_rotation_preserves_S_and_order_parameter_stays_traceless():
    """The corotational part of Qdot is a rotation: it does not change S^2 = q1^2 + q2^2."""
    p = SMALL
    eq = ActiveNematicPDE(p, Numerics(resolution=32, mechanics="linear", spin_tol=1e-12))
    q1, q2, A = initial_fields(p, 32, seed=3)
    mech = eq.mechanics.solve(q1, q2)
    H = eq.molecular_field(q1, q2, A, mech)
    qdot, omega = eq.corotational_rates(q1, q2, H, mech)
    assert np.abs(omega).max() > 1e-3
    jaumann = qdot - H / p.gamma
    np.testing.assert_allclose(q1 * jaumann[0] + q2 * jaumann[1], 0, atol=1e-14)


def test_the_pde_takes_its_grid_from_the_state():
    """``ActiveNematicPDE()`` (no numerics) follows the state's grid; with explicit numerics a
    state of another size is a clear error, not a reshape failure deep inside."""
    p = Parameters(noise_modes=4)
    state = make_state(*initial_fields(p, 48, seed=1))
    eq = ActiveNematicPDE(p)
    rate = eq.evolution_rate(state)
    assert rate.data.shape == (3, 48, 48)
    assert eq.numerics.resolution == 48
    assert eq.spectral.n == 48
    eq.evolution_rate(make_state(*initial_fields(p, 32, seed=1)))  # and follows a new size
    assert eq.spectral.n == 32
    fixed = ActiveNematicPDE(p, Numerics(resolution=64))
    with pytest.raises(ValueError, match="48x48 grid .* resolution 64"):
        fixed.evolution_rate(state)


def test_symbol_cache_keeps_the_step_sizes_used_most_recently():
    """The solver's cache of phi functions and weights (solver_base._cached) holds CACHE_SIZE
    step sizes; a new one pushes out the one unused the longest, so a step size in use (the
    ladder's) survives any number of one-off sizes (steps shortened onto save times)."""
    from nematic_solids.model.solver_base import CACHE_SIZE, _cached

    cache: dict = {}
    made: list[float] = []

    def get(h: float) -> float:
        def make() -> float:
            made.append(h)
            return 2.0 * h

        return _cached(cache, h, make)

    assert get(0.5) == 1.0
    for i in range(3 * CACHE_SIZE):
        get(1e-3 * (i + 1))  # one-off sizes
        assert get(0.5) == 1.0  # the size in use, made once
    assert made.count(0.5) == 1
    assert len(cache) == CACHE_SIZE
    assert 1e-3 not in cache
    assert 1e-3 * (3 * CACHE_SIZE) in cache
