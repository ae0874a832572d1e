"""Force balance: analytic solutions, finite vs linear agreement, residual tolerance."""

from __future__ import annotations

import numpy as np
import pytest

from nematic_solids.model.fourier import SpectralGrid
from nematic_solids.model.mechanics import FiniteMechanics, LinearMechanics
from nematic_solids.model.parameters import Parameters

N = 32


@pytest.fixture(scope="module")
def grid():
    return SpectralGrid(N)


def _xy(grid):
    x = grid.x[:, None] + 0 * grid.x[None, :]
    return x, x.T.copy()


@pytest.mark.parametrize("eps", [0.0, 0.05, -0.1])
def test_uniform_load_gives_uniform_deformation(grid, eps):
    p = Parameters(eps=eps, B_prime=0.2)
    zero = np.zeros((N, N))
    for mech in (LinearMechanics(p, grid), FiniteMechanics(p, grid)):
        F = mech.solve(zero, zero).F
        np.testing.assert_allclose(F[0, 0], 1 + eps, atol=1e-12)
        np.testing.assert_allclose(F[1, 1], 1 - eps, atol=1e-12)
        np.testing.assert_allclose(F[0, 1], 0, atol=1e-12)
        np.testing.assert_allclose(F[1, 0], 0, atol=1e-12)


@pytest.mark.parametrize("incompressible", [False, True])
def test_sinusoidal_active_stress_closed_form(grid, incompressible):
    r"""q1 = a cos(2 pi m x), q2 = b cos(2 pi m x): 1-D balance along x gives
    (kappa + 1) du1/dx = -(alpha - B) q1 and du2/dx = -(alpha - B) q2 (mu = 1); incompressible:
    du1/dx = 0 (the pressure takes the normal stress)."""
    p = Parameters(alpha=1.7, B=0.5, kappa=4.0)
    x, _ = _xy(grid)
    a, b, m = 1e-3, 2e-3, 3
    q1 = a * np.cos(2 * np.pi * m * x)
    q2 = b * np.cos(2 * np.pi * m * x)
    mech = LinearMechanics(p, grid, incompressible=incompressible).solve(q1, q2)
    amb = p.alpha - p.B
    expected11 = 0.0 if incompressible else -amb * q1 / (p.kappa + 1)
    np.testing.assert_allclose(mech.F[0, 0] - 1, expected11, atol=1e-14)
    np.testing.assert_allclose(mech.F[1, 0], -amb * q2, atol=1e-14)
    np.testing.assert_allclose(mech.F[0, 1], 0, atol=1e-14)
    # the stress is divergence free and its x-row is uniform (1-D balance)
    assert LinearMechanics(p, grid).residual(mech.P) < 1e-14
    np.testing.assert_allclose(mech.P[0, 0], mech.P[0, 0].mean(), atol=1e-14)


def test_incompressible_projection_is_divergence_free(grid, rng):
    p = Parameters(alpha=1.5)
    q1, q2 = 1e-2 * rng.standard_normal((2, N, N))
    mech = LinearMechanics(p, grid, incompressible=True).solve(q1, q2)
    div_u = mech.F[0, 0] + mech.F[1, 1] - 2.0
    np.testing.assert_allclose(div_u, 0, atol=1e-13)
    # tr sigma = -2 p + tr tau, mean pressure zero
    np.testing.assert_allclose(mech.trP.mean(), 0.0, atol=1e-13)


def _band_limited(grid, rng, amp, modes=4):
    x, y = _xy(grid)
    q = np.zeros((2, N, N))
    for c in range(2):
        for _ in range(6):
            n, m = rng.integers(-modes, modes + 1, 2)
            q[c] += np.cos(2 * np.pi * (n * x + m * y) + rng.uniform(0, 2 * np.pi))
    return amp * q / np.abs(q).max()


def test_finite_and_linear_agree_to_second_order(grid, rng):
    """|F_finite - F_linear| = O(a^2): dividing a by 10 divides the difference by ~100."""
    p = Parameters(alpha=1.5, B_prime=0.2)
    base = _band_limited(grid, rng, 1.0)
    diffs = []
    for amp in (1e-2, 1e-3):
        q1, q2 = amp * base
        lin = LinearMechanics(p, grid).solve(q1, q2)
        fin = FiniteMechanics(p, grid, tol=1e-12).solve(q1, q2)
        diffs.append(np.abs(lin.F - fin.F).max())
    ratio = diffs[0] / diffs[1]
    assert 70 < ratio < 130, (diffs, ratio)


def test_finite_solver_meets_its_residual_tolerance(grid, rng):
    p = Parameters(alpha=1.5, eps=0.05, B_prime=0.1)
    q1, q2 = _band_limited(grid, rng, 0.4)
    for tol in (1e-6, 1e-10):
        fm = FiniteMechanics(p, grid, tol=tol)
        state = fm.solve(q1, q2)
        assert state.residual <= tol
        assert fm.residual(state.P) <= tol  # recomputed independently from P
        assert state.iterations >= 1


def test_finite_warm_start_converges_in_one_newton_step_for_small_change(grid, rng):
    p = Parameters(alpha=1.5)
    q1, q2 = _band_limited(grid, rng, 0.2)
    fm = FiniteMechanics(p, grid, tol=1e-8)
    fm.solve(q1, q2)
    state = fm.solve(q1 * (1 + 1e-4), q2)
    assert state.iterations <= 1


def test_spin_of_linear_and_finite_agree_at_small_amplitude(grid, rng):
    """The Jaumann spin from the displacement-rate solve: finite -> linear as Q -> 0."""
    p = Parameters(alpha=1.5)
    base = _band_limited(grid, rng, 1.0)
    R = _band_limited(grid, np.random.default_rng(5), 1.0)
    diffs = []
    for amp in (1e-2, 1e-3):
        q1, q2 = amp * base
        lin, fin = (
            LinearMechanics(p, grid, spin_tol=1e-12),
            FiniteMechanics(p, grid, tol=1e-12, spin_tol=1e-12),
        )
        _, w_lin = lin.corotational(lin.solve(q1, q2), q1, q2, R)
        _, w_fin = fin.corotational(fin.solve(q1, q2), q1, q2, R)
        diffs.append(np.abs(w_lin - w_fin).max())
        assert np.abs(w_lin).max() > 0.1
    assert 7 < diffs[0] / diffs[1] < 13  # first order in the amplitude of Q


@pytest.mark.parametrize("backend", ["compiled", "numpy"])
def test_rate_solve_returns_the_gradient_of_its_solution(grid, rng, backend):
    """The displacement-rate solve returns the real-space gradient of its solution (the
    integrated scheme carries F with it, and the spin is its skew part), accumulated inside
    the Krylov solve: it equals the transformed gradient of the returned spectrum, from a
    zero start and from a warm start (whose residual application supplies the start's
    gradient), and the spin returned is its skew part."""
    p = Parameters(alpha=1.8)
    q1, q2 = 0.3 * _band_limited(grid, rng, 1.0)
    fm = FiniteMechanics(p, grid, backend=backend)
    mech = fm.solve(q1, q2)
    for seed in (5, 6):  # the second solve is warm-started from the first
        R = _band_limited(grid, np.random.default_rng(seed), 1.0)
        _, omega = fm.corotational(mech, q1, q2, R)
        G = grid.inverse(grid.grad_hat(fm.udot_hat))
        scale = np.abs(G).max()
        assert scale > 1e-3
        np.testing.assert_allclose(fm.udot_grad, G, rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(omega, 0.5 * (G[1, 0] - G[0, 1]), rtol=0, atol=1e-12 * scale)


def test_finite_state_carries_what_the_rate_problem_reuses(grid, rng):
    """A Newton solve leaves its last step's tangent on the state, the rate solve the spin
    coupling E; the margin reuses both: the same as the margin of a state without them whose
    tangent is the one carried (E is recomputed at the same F)."""
    from dataclasses import replace

    from nematic_solids.model import tensors as T
    from nematic_solids.model.constitutive import Moduli, tangent

    p = Parameters(alpha=1.8, eps=0.03, B_prime=0.1)
    q1, q2 = 0.3 * _band_limited(grid, rng, 1.0)
    fm = FiniteMechanics(p, grid)
    mech = fm.solve(q1, q2)
    assert mech.iterations >= 1
    assert mech.tangent is not None
    assert mech.spin_coupling is None
    assert mech.tangent.shape == (10, N, N)  # packed
    fresh = T.pack_symmetric(tangent(mech.F, T.nematic(q1, q2), Moduli.from_params(p)))
    assert not np.allclose(mech.tangent, fresh, rtol=0, atol=1e-12)  # the iterate before
    np.testing.assert_allclose(mech.tangent, fresh, rtol=0, atol=1e-3)
    fm.corotational(mech, q1, q2, _band_limited(grid, np.random.default_rng(5), 1.0))
    assert mech.spin_coupling is not None
    assert mech.spin_coupling.shape == (2, 2, N, N)
    assert fm.rate_margin(q1, q2, mech) == fm.rate_margin(q1, q2, replace(mech, spin_coupling=None))
    assert fm.solve(q1, q2).tangent is None  # converged guess: no Newton step
