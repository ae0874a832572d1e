"""The well-posedness margin of the rate problem: the limit against the computed symbol, the
compiled margin against its numpy reference, and runs that cross the limit fail with its reason."""

from __future__ import annotations

import numpy as np
import pytest

from nematic_solids.model import wellposedness as wp
from nematic_solids.model.compiled.kernels import q_increment_kernel, tangent_kernel
from nematic_solids.model.fourier import SpectralGrid
from nematic_solids.model.mechanics import LinearMechanics
from nematic_solids.model.parameters import Numerics, Parameters
from nematic_solids.model.simulate import run


def _uniform(
    S: float, theta: float, n: int = 4, F: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    q1 = np.full((n, n), S * np.cos(2 * theta))
    q2 = np.full((n, n), S * np.sin(2 * theta))
    if F is None:
        F = np.zeros((2, 2, n, n))
        F[0, 0] = F[1, 1] = 1.0
    return F, q1, q2


def _symbol(F, q1, q2, p: Parameters) -> tuple[np.ndarray, np.ndarray]:
    """The tangent and E exactly as FiniteMechanics.corotational builds them."""
    K = tangent_kernel(F, q1, q2, p.kappa, p.B, p.B_prime, p.alpha)
    E = q_increment_kernel(F, q1, q2, -2.0 * q2, 2.0 * q1, p.B, p.B_prime, p.alpha)
    return K, E


@pytest.mark.parametrize("amb", [0.5, 1.0, 1.2, 2.0])
@pytest.mark.parametrize("theta", [0.0, 0.3, 1.2])
def test_finite_margin_of_the_computed_symbol_is_the_closed_form(amb, theta):
    """Uniform Q at F = I: the minimum over directions of det M of the tangent and E the
    solver uses equals (1 - 2 (alpha - B) S)(1 - (alpha + B) S / (kappa + 1)), attained for k
    perpendicular to the director."""
    p = Parameters.from_dict({"alpha_minus_B": amb})
    for S in (0.1, 0.3, 0.45, 0.6):
        F, q1, q2 = _uniform(S, theta)
        m, _, phi = wp.finite_margin(*_symbol(F, q1, q2, p), p.kappa)
        assert m == pytest.approx(
            wp.uniform_margin(S, p.alpha, p.B, p.kappa, linear=False), abs=1e-5
        )
        gap = abs((phi - theta - np.pi / 2 + np.pi / 2) % np.pi - np.pi / 2)
        assert gap < 1e-3  # k perpendicular to n


@pytest.mark.parametrize("amb", [0.6, 1.0, 1.5])
def test_finite_limit_is_alpha_minus_B_times_S_one_half(amb):
    """The margin of the computed symbol changes sign at (alpha - B) S = 1/2, not 1."""
    p = Parameters.from_dict({"alpha_minus_B": amb})
    S_lim = wp.limit_S(amb, linear=False)
    assert S_lim == pytest.approx(0.5 / amb)
    below = wp.finite_margin(*_symbol(*_uniform(0.98 * S_lim, 0.7), p), p.kappa)[0]
    above = wp.finite_margin(*_symbol(*_uniform(1.02 * S_lim, 0.7), p), p.kappa)[0]
    assert below > 0 > above


def test_compiled_margin_equals_numpy_reference_on_a_deformed_state(rng):
    """A random deformation and Q field: the compiled sampled minimum (refined) agrees with a
    dense numpy scan of det M over directions at every point."""
    n = 8
    p = Parameters.from_dict({"alpha_minus_B": 1.0, "B_prime": 0.3})
    F = np.zeros((2, 2, n, n))
    F[0, 0] = F[1, 1] = 1.0
    F += 0.1 * rng.standard_normal((2, 2, n, n))
    q1, q2 = 0.2 * rng.standard_normal((2, n, n))
    K, E = _symbol(F, q1, q2, p)
    m, idx, phi = wp.finite_margin(K, E, p.kappa)
    phis = np.linspace(0.0, np.pi, 2001)
    dets = np.array([wp.finite_symbol_det(K, E, f) for f in phis]) / (p.kappa + 1)
    assert m == pytest.approx(dets.min(), abs=1e-4)
    assert idx == int(np.argmin(dets.min(axis=0)))
    # det M is even under k -> -k
    assert np.allclose(wp.finite_symbol_det(K, E, 0.3), wp.finite_symbol_det(K, E, 0.3 + np.pi))


def test_compiled_linear_margin_is_the_numpy_margin_bitwise(rng):
    """The compiled small-strain margin gives numpy's values and index exactly: random fields,
    a strided view (py-pde's state), ties (the first index wins), a negative alpha - B (the
    minimum of S) and a NaN (the first NaN is the maximum, as numpy.argmax)."""
    from nematic_solids.model.compiled.kernels import linear_margin_kernel

    q = rng.standard_normal((2, 20, 24))
    cases = [(q[0], q[1], 1.3), (q[0, 2:-2, ::2], q[1, 2:-2, ::2], 0.7), (q[0], q[1], -0.5)]
    tie = np.zeros((8, 8))
    tie[3, 4] = tie[5, 1] = 0.5
    cases.append((tie, np.zeros((8, 8)), 1.0))
    nan = q[0].copy()
    nan[4, 5] = nan[9, 2] = np.nan
    cases.append((nan, q[1], 1.0))
    for q1, q2, amb in cases:
        m, i = linear_margin_kernel(q1, q2, amb)
        m_ref, i_ref = wp.linear_margin(q1, q2, amb)
        assert i == i_ref
        assert m == m_ref or (np.isnan(m) and np.isnan(m_ref))
    assert linear_margin_kernel(tie, np.zeros((8, 8)), 1.0)[1] == 3 * 8 + 4


def test_linear_margin_is_the_spin_amplification_of_the_linear_solver():
    """Small strain: for a uniform Q the compiled/numpy spin solve amplifies the spin of a mode
    at angle phi from the director by 1 / (1 + (alpha - B) S cos 2 phi) (the symbol of
    LinearMechanics' spin problem), so the margin 1 - (alpha - B) S is where it diverges."""
    n, amb, S = 16, 1.0, 0.6
    p = Parameters.from_dict({"alpha_minus_B": amb})
    g = SpectralGrid(n)
    mech = LinearMechanics(p, g, spin_tol=1e-12)
    q1 = np.full((n, n), S)  # director along x
    q2 = np.zeros((n, n))
    assert mech.rate_margin(q1, q2)[0] == pytest.approx(1 - amb * S)
    x = (np.arange(n) + 0.5) / n
    for mode in ((2, 0), (0, 2), (1, 1)):
        kx, ky = 2 * np.pi * np.array(mode)
        R = np.stack([np.cos(kx * x[:, None] + ky * x[None, :]), np.zeros((n, n))])
        qdot_hat = mech.corotational_hat(q1, q2, g.forward(R))
        assert mech.omega_hat is not None  # kept by corotational_hat
        omega = g.inverse(mech.omega_hat)
        # the spin without feedback: omega0 = Omega[R]; with feedback: omega0 / (1 + ...)
        omega0 = g.inverse(mech.spin_multiplier(g.forward(R[0]), g.forward(R[1])))
        c2 = np.cos(2 * np.arctan2(ky, kx))
        assert np.allclose(omega, omega0 / (1 + amb * S * c2), atol=1e-9), mode
        assert np.all(np.isfinite(qdot_hat))


def test_run_crossing_the_limit_fails_with_its_reason_finite():
    """Finite strain, alpha - B = 3: S grows from 0.1 through the limit 1/6 and the run stops
    with rate_problem_ill_posed (value and place named), not ellipticity_lost."""
    ds = run(
        Parameters.from_dict({"alpha_minus_B": 3.0, "noise_modes": 4}),
        Numerics(resolution=16, t_final=20, save_every=1),
        seed=0,
    )
    assert ds.attrs["status"] == "failed"
    assert ds.attrs["reason"] == "rate_problem_ill_posed"
    assert ds.attrs["t_failed"] > 0
    assert "(alpha - B) S" in ds.attrs["detail"]
    margins = ds["rate_margin"].values
    assert margins[0] > 0
    assert np.all(margins[np.isfinite(margins)] > 0)
    assert float(ds["rate_margin_min"]) <= 0


def test_run_crossing_the_limit_fails_with_its_reason_linear():
    """Small strain, alpha - B = 3: the limit is (alpha - B) S = 1."""
    ds = run(
        Parameters.from_dict({"alpha_minus_B": 3.0, "noise_modes": 4, "C": 1.0}),
        Numerics(resolution=16, t_final=20, save_every=1, mechanics="linear"),
        seed=0,
    )
    assert ds.attrs["reason"] == "rate_problem_ill_posed"
    assert ds.attrs["t_failed"] > 0
    # the first state past the limit: (alpha - B) max S just above 1
    amb_S = float(ds.attrs["detail"].split("(alpha - B) S = ")[1].split(",")[0])
    assert 1.0 <= amb_S < 1.2


def test_well_posed_run_records_its_margin():
    """A healthy run: the margin series lies in (0, 1] and its minimum is recorded."""
    ds = run(
        Parameters.from_dict({"alpha_minus_B": 1.0, "noise_modes": 4}),
        Numerics(resolution=16, t_final=5, save_every=1),
        seed=0,
    )
    assert ds.attrs["status"] == "ok"
    m = ds["rate_margin"].values
    assert np.all((m > 0) & (m <= 1))
    assert 0 < float(ds["rate_margin_min"]) <= m.min() + 1e-12
    lin = run(
        Parameters.from_dict({"alpha_minus_B": 1.0, "noise_modes": 4}),
        Numerics(resolution=16, t_final=5, save_every=1, mechanics="linear"),
        seed=0,
    )
    S = np.hypot(lin["q1"].values[-1], lin["q2"].values[-1])
    assert float(lin["rate_margin"][-1]) == pytest.approx(1.0 - S.max())
