"""The stress is the exact derivative of paper Eq. (1); the tangent is its exact derivative."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nematic_solids.model import constitutive as cl
from nematic_solids.model import tensors as T

M = cl.Moduli(kappa=7.0, B=0.5, B_prime=0.3, alpha=1.3)
M_PASSIVE = cl.Moduli(kappa=7.0, B=0.5, B_prime=0.3, alpha=0.0)


def _state(rng, n=6, strain=0.2, q=0.4):
    F = np.eye(2)[:, :, None] + strain * rng.standard_normal((2, 2, n))
    Q = T.nematic(*(q * rng.standard_normal((2, n))))
    return F, Q


def test_passive_stress_is_energy_derivative(rng):
    F, Q = _state(rng)
    P = cl.first_piola(F, Q, M_PASSIVE)
    h = 1e-6
    num = np.zeros_like(P)
    for i in range(2):
        for j in range(2):
            E = np.zeros_like(F)
            E[i, j] = h
            num[i, j] = (
                cl.energy_density(F + E, Q, M_PASSIVE) - cl.energy_density(F - E, Q, M_PASSIVE)
            ) / (2 * h)
    # central differences: error ~ h^2 * W''' ~ 1e-11; roundoff ~ 1e-16 / h ~ 1e-10
    np.testing.assert_allclose(P, num, atol=1e-8)


def test_active_stress_is_alpha_F_Q(rng):
    F, Q = _state(rng)
    dP = cl.first_piola(F, Q, M) - cl.first_piola(F, Q, M_PASSIVE)
    np.testing.assert_allclose(dP, M.alpha * T.matmul(F, Q), atol=1e-13)


def test_tangent_matches_finite_differences_and_is_symmetric(rng):
    F, Q = _state(rng)
    dF = rng.standard_normal(F.shape)
    h = 1e-6
    fd = (cl.first_piola(F + h * dF, Q, M) - cl.first_piola(F - h * dF, Q, M)) / (2 * h)
    np.testing.assert_allclose(cl.first_piola_increment(F, Q, dF, M), fd, atol=1e-7)
    K = cl.tangent(F, Q, M)
    np.testing.assert_allclose(cl.apply_tangent(K, dF), fd, atol=1e-7)
    # major symmetry: P derives from a potential at fixed Q (active term = d/dF of alpha C:Q/2)
    np.testing.assert_allclose(K, K.transpose(2, 3, 0, 1, 4), atol=1e-12)
    # so the packed upper triangle (the backends' layout) determines it
    np.testing.assert_allclose(T.unpack_symmetric(T.pack_symmetric(K)), K, atol=1e-12)


def test_packed_layout_is_the_same_in_both_backends():
    """The compiled kernels' plane table is the numpy packing's (row-by-row upper triangle)."""
    from nematic_solids.model.compiled.constitutive import PACKED

    for c, (a, b) in enumerate(T.PACKED_PAIRS):
        assert PACKED[a, b] == PACKED[b, a] == c
    M4 = np.arange(16.0).reshape(4, 4)
    K = (M4 + M4.T).reshape(2, 2, 2, 2)
    Kp = T.pack_symmetric(K)
    assert Kp.shape == (10,)
    np.testing.assert_array_equal(T.unpack_symmetric(Kp), K)


def test_q_increment_matches_finite_differences(rng):
    F, Q = _state(rng)
    dQ = T.nematic(*rng.standard_normal((2, F.shape[-1])))
    h = 1e-6
    fd = (cl.first_piola(F, Q + h * dQ, M) - cl.first_piola(F, Q - h * dQ, M)) / (2 * h)
    np.testing.assert_allclose(cl.first_piola_q_increment(F, Q, dQ, M), fd, atol=1e-8)


@pytest.mark.parametrize("amp", [1e-3, 1e-4])
def test_small_strain_limit(rng, amp):
    """P(I + grad u) = sigma(grad u) + O(|grad u|^2, |grad u| |Q|, |Q|^2 |grad u|)."""
    G = amp * rng.standard_normal((2, 2, 5))
    Q = T.nematic(*(amp * rng.standard_normal((2, 5))))
    P = cl.first_piola(np.eye(2)[:, :, None] + G, Q, M)
    sigma = cl.small_strain_stress(G, Q, M)
    err = np.abs(P - sigma).max()
    assert err < 50 * amp**2  # second order: the constants are O(kappa) ~ 10


def test_rotation_invariance_of_energy(rng):
    """Frame indifference: W(R F, Q) = W(F, Q); material symmetry: W(F R^T, R Q R^T) = W(F, Q)."""
    F, Q = _state(rng)
    a = 0.7
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])[:, :, None]
    R = np.broadcast_to(R, F.shape)
    W = cl.energy_density(F, Q, M_PASSIVE)
    np.testing.assert_allclose(cl.energy_density(T.matmul(R, F), Q, M_PASSIVE), W, atol=1e-13)
    Qr = T.matmul(T.matmul(R, Q), T.transpose(R))
    Fr = T.matmul(F, T.transpose(R))
    np.testing.assert_allclose(cl.energy_density(Fr, Qr, M_PASSIVE), W, atol=1e-13)


def test_every_compiled_kernel_has_a_numpy_twin_with_its_signature():
    """nematic_solids.model.backend swaps the two kernel modules: both export the members of the
    Kernels interface and nothing else, each with the interface's parameters (the type checker
    compares the numpy twins' types with it; the numba functions it cannot see)."""
    import inspect

    from nematic_solids.model import reference_kernels as twin
    from nematic_solids.model.backend import Kernels, kernels
    from nematic_solids.model.compiled import kernels as kern

    members = sorted(
        n for n, v in vars(Kernels).items() if inspect.isfunction(v) and not n.startswith("_")
    )
    assert len(members) == 25
    assert sorted(kern.__all__) == sorted(twin.__all__) == members
    for name in members:
        wanted = list(inspect.signature(getattr(Kernels, name)).parameters)[1:]  # not self
        compiled = getattr(kern, name)
        params = inspect.signature(getattr(compiled, "py_func", compiled)).parameters
        assert list(params) == wanted, name
        assert list(inspect.signature(getattr(twin, name)).parameters) == wanted, name
    assert kernels("compiled") is kern
    assert kernels("numpy") is twin
    with pytest.raises(ValueError, match="unknown backend"):
        kernels("cuda")


def test_numba_tangent_kernel_matches_numpy_reference(rng):
    from nematic_solids.model.compiled.kernels import tangent_kernel

    F = np.eye(2)[:, :, None, None] + 0.2 * rng.standard_normal((2, 2, 8, 8))
    q = 0.4 * rng.standard_normal((2, 8, 8))
    ref = T.pack_symmetric(cl.tangent(F, T.nematic(*q), M))
    fast = tangent_kernel(F, q[0], q[1], M.kappa, M.B, M.B_prime, M.alpha)
    assert fast.shape == (10, 8, 8)
    np.testing.assert_allclose(fast, ref, rtol=1e-13, atol=1e-13)


def test_numba_apply_tangent_matches_numpy_reference(rng):
    from nematic_solids.model.compiled.kernels import apply_tangent_kernel

    Kp = rng.standard_normal((10, 6, 6))  # packed: the full tangent is its symmetric matrix
    dF = rng.standard_normal((2, 2, 6, 6))
    np.testing.assert_allclose(
        apply_tangent_kernel(Kp, dF),
        cl.apply_tangent(T.unpack_symmetric(Kp), dF),
        rtol=1e-14,
        atol=1e-14,
    )


@pytest.mark.parametrize("incompressible", [False, True])
@pytest.mark.parametrize("B_prime", [0.0, 0.2])
def test_numba_linear_response_matches_numpy_reference(rng, incompressible, B_prime):
    from nematic_solids.model.fourier import SpectralGrid
    from nematic_solids.model.mechanics import LinearMechanics
    from nematic_solids.model.parameters import Parameters

    g = SpectralGrid(16)
    mech = LinearMechanics(
        Parameters(B_prime=B_prime, eps=0.03, alpha=1.3), g, incompressible=incompressible
    )
    q = 0.2 * rng.standard_normal((2, 16, 16))
    q_hat = g.forward(q)
    QQ_hat = g.forward(2 * (q[0] ** 2 + q[1] ** 2)) if B_prime else None
    numpy_twin = LinearMechanics(
        Parameters(B_prime=B_prime, eps=0.03, alpha=1.3),
        g,
        incompressible=incompressible,
        backend="numpy",
    )
    for fast, ref in zip(
        mech.spectral_response(q_hat, QQ_hat),
        numpy_twin.spectral_response(q_hat, QQ_hat),
        strict=True,
    ):
        np.testing.assert_allclose(fast, ref, rtol=0, atol=1e-12 * np.abs(ref).max())


def test_numba_pointwise_stepper_kernels_match_numpy(rng):
    from nematic_solids.model.compiled import kernels as kern
    from nematic_solids.model.reference_kernels import phi_functions

    q1, q2, A, tr = 0.3 * rng.standard_normal((4, 8, 8))
    A[0, 0] = 0.0  # the small-|z| branch
    zeta, s, tau, C, Bp, chi, h = 1.0, 10.0, 1.0, 3.0, 0.2, 10.0, 0.3
    L, p1, p2 = kern.activity_exponential(A, h, zeta, s, tau)
    L_ref = -(zeta + 3 * s * A**2) / tau
    _, p1_ref, p2_ref = phi_functions(L_ref * h)
    for fast, ref in ((L, L_ref), (p1, p1_ref), (p2, p2_ref)):
        np.testing.assert_allclose(fast, ref, rtol=1e-14)
    bulk = A + C * 2 * (q1**2 + q2**2) - 2 * Bp * tr
    np.testing.assert_allclose(
        kern.bulk_terms(q1, q2, A, tr, C, 2 * Bp), np.stack([-bulk * q1, -bulk * q2]), rtol=1e-14
    )
    np.testing.assert_allclose(
        kern.activity_rate(A, tr, zeta, chi, s, tau),
        (-zeta * A - chi * tr - s * A**3) / tau,
        rtol=1e-14,
        atol=1e-15,
    )
    np.testing.assert_allclose(
        kern.jaumann_products(tr, q1, q2), np.stack([-2 * tr * q2, 2 * tr * q1]), rtol=1e-15
    )
    R, grad = rng.standard_normal((2, 8, 8)), rng.standard_normal((2, 2, 8, 8))
    qdot, omega = kern.corotational_rate(R, grad, q1, q2)
    w = 0.5 * (grad[1, 0] - grad[0, 1])
    np.testing.assert_allclose(omega, w, rtol=1e-15)
    np.testing.assert_allclose(
        qdot, R + np.stack([-2 * w * q2, 2 * w * q1]), rtol=1e-14, atol=1e-15
    )
    E0, E1, lap1, lap2 = rng.standard_normal((4, 8, 8))
    A0, B, K = -0.3, 1.2, 1e-3
    H = kern.molecular_field_kernel(
        q1, q2, A, tr, np.stack([E0, E1]), np.stack([lap1, lap2]), A0, C, 2 * Bp, B, K
    )
    bulk0 = bulk + A0
    np.testing.assert_allclose(
        H,
        np.stack([-bulk0 * q1 + B * E0 + K * lap1, -bulk0 * q2 + B * E1 + K * lap2]),
        rtol=1e-13,
        atol=1e-15,
    )
    a, b = rng.standard_normal((2, 8, 5)) + 1j * rng.standard_normal((2, 8, 5))
    m1, m2 = rng.standard_normal((2, 8, 5))
    np.testing.assert_allclose(
        kern.symbol_combination(a, m1, m2, a, b), a - (m1 * a + m2 * b), rtol=1e-14
    )


@pytest.mark.parametrize("complex_", [False, True])
def test_runge_kutta_stage_kernels_are_the_numpy_expressions(rng, complex_):
    """The integrated displacement's stage and update kernels give numpy's values exactly
    (spectra and real-space gradients alike)."""
    from nematic_solids.model import reference_kernels as ref
    from nematic_solids.model.compiled import kernels as kern

    shape = (2, 8, 5) if complex_ else (2, 2, 8, 8)
    x0, v0, v1, v2, v3 = (
        rng.standard_normal(shape) + (1j * rng.standard_normal(shape) if complex_ else 0.0)
        for _ in range(5)
    )
    h = 0.37
    np.testing.assert_array_equal(kern.rk_stage(x0, 0.5 * h, v0), x0 + 0.5 * h * v0)
    np.testing.assert_array_equal(
        kern.rk4_update(x0, h / 6.0, v0, v1, v2, v3),
        x0 + (h / 6.0) * (v0 + 2.0 * v1 + 2.0 * v2 + v3),
    )
    np.testing.assert_array_equal(
        ref.rk4_update(x0, h / 6.0, v0, v1, v2, v3), kern.rk4_update(x0, h / 6.0, v0, v1, v2, v3)
    )


def test_balance_residual_kernel_matches_numpy_twin(rng):
    """The force-balance residual (H^-1 norm of Div P over the floored RMS stress): compiled
    and numpy agree, for stresses below and above the floor of 1."""
    from nematic_solids.model import reference_kernels as twin
    from nematic_solids.model.compiled import kernels as kern
    from nematic_solids.model.fourier import SpectralGrid

    g = SpectralGrid(16)
    for amp in (0.1, 10.0):
        P = amp * rng.standard_normal((2, 2, 16, 16))
        P_hat = g.forward(P)
        args = (P, P_hat, g.khat[0], g.khat[1], g.weights)
        ref = twin.balance_residual_kernel(*args)
        assert ref > 0
        np.testing.assert_allclose(kern.balance_residual_kernel(*args), ref, rtol=1e-13)


def test_numba_finite_strain_kernels_match_numpy_references(rng):
    from nematic_solids.model.compiled import kernels as kern

    M = cl.Moduli(kappa=10.0, B=0.5, B_prime=0.2, alpha=1.5)
    F = np.eye(2)[:, :, None, None] + 0.2 * rng.standard_normal((2, 2, 6, 6))
    q = 0.3 * rng.standard_normal((2, 6, 6))
    d = rng.standard_normal((2, 6, 6))
    Q, dQ = T.nematic(q[0], q[1]), T.nematic(d[0], d[1])
    np.testing.assert_allclose(
        kern.first_piola_kernel(F, q[0], q[1], M.kappa, M.B, M.B_prime, M.alpha),
        cl.first_piola(F, Q, M),
        rtol=1e-12,
        atol=1e-13,
    )
    np.testing.assert_allclose(
        kern.q_increment_kernel(F, q[0], q[1], d[0], d[1], M.B, M.B_prime, M.alpha),
        cl.first_piola_q_increment(F, Q, dQ, M),
        rtol=1e-12,
        atol=1e-13,
    )
    K = cl.tangent(F, Q, M)
    E = cl.first_piola_q_increment(F, Q, d[0] * np.eye(2)[:, :, None, None], M)
    G = rng.standard_normal((2, 2, 6, 6))
    omega = 0.5 * (G[1, 0] - G[0, 1])
    np.testing.assert_allclose(
        kern.apply_tangent_spin_kernel(T.pack_symmetric(K), G, E),
        cl.apply_tangent(K, G) + E * omega,
        rtol=1e-12,
        atol=1e-13,
    )


def test_numba_spectral_kernels_match_numpy_references(rng):
    from nematic_solids.model import reference_kernels as twin
    from nematic_solids.model.compiled import kernels as kern
    from nematic_solids.model.fourier import SpectralGrid

    g = SpectralGrid(16)
    v = g.forward(rng.standard_normal((2, 16, 16)))
    Th = g.forward(rng.standard_normal((2, 2, 16, 16)))
    np.testing.assert_allclose(kern.grad_hat_kernel(v, g.kx, g.ky), g.grad_hat(v), rtol=1e-15)
    np.testing.assert_allclose(
        kern.neg_div_hat_kernel(Th, g.kx, g.ky), -g.div_hat(Th), rtol=1e-14, atol=1e-12
    )
    kh, inv_k2 = g.khat, np.where(g.active, 1.0 / np.where(g.active, g.kd2, 1.0), 0.0)
    np.testing.assert_allclose(
        kern.green_kernel(v, kh[0], kh[1], inv_k2, 0.7),
        twin.green_kernel(v, kh[0], kh[1], inv_k2, 0.7),
        rtol=1e-14,
        atol=1e-16,
    )
    for name in ("grad_hat_kernel", "neg_div_hat_kernel", "div_hat_kernel"):
        arg = v if name == "grad_hat_kernel" else Th
        np.testing.assert_allclose(
            getattr(twin, name)(arg, g.kx, g.ky),
            getattr(kern, name)(arg, g.kx, g.ky),
            rtol=1e-14,
            atol=1e-12,
        )


def test_phi_functions_match_their_integral_definition():
    """phi_k(z) = int_0^1 e^{(1 - s) z} s^(k-1) / (k-1)! ds on both branches (|z| < 1 Taylor,
    recursion beyond), in numpy and in the numba scalar kernel."""
    import math

    from scipy.integrate import quad

    from nematic_solids.model.compiled import etd
    from nematic_solids.model.reference_kernels import phi_functions

    z = np.array([-60.0, -7.3, -1.0001, -0.9999, -0.3, -1e-9, 0.0, 0.4])
    numpy_phis = phi_functions(z, 3)
    for i, zi in enumerate(z):
        exact = [math.exp(zi)] + [
            quad(
                lambda s, k=k, zi=zi: math.exp((1 - s) * zi) * s ** (k - 1) / math.factorial(k - 1),
                0,
                1,
                epsabs=0,
                epsrel=1e-13,
                limit=200,
            )[0]
            for k in (1, 2, 3)
        ]
        np.testing.assert_allclose([p[i] for p in numpy_phis], exact, rtol=1e-11)
        np.testing.assert_allclose(etd._phi0123(zi), exact, rtol=1e-11)


def test_etdrk4_activity_weights_match_numpy(rng):
    from nematic_solids.model import reference_kernels as twin
    from nematic_solids.model.compiled import kernels as kern
    from nematic_solids.model.reference_kernels import phi_functions
    from nematic_solids.model.solver import ETDRK4Solver

    A = 0.5 * rng.standard_normal((8, 8))
    A[0, 0] = 0.0
    A[0, 1] = 0.04  # |z| < 1: the Taylor branch, for both h and h/2
    zeta, s, tau, h = 1.0, 10.0, 1.0, 0.7
    L, W = kern.activity_krogstad(A, h, zeta, s, tau)
    L_ref = -(zeta + 3 * s * A**2) / tau
    np.testing.assert_allclose(L, L_ref, rtol=1e-15)
    E, f1, f2, f3 = phi_functions(L_ref * h, 3)
    E2, g1, g2 = phi_functions(L_ref * h / 2, 2)
    w = ETDRK4Solver._weights_from(f1, f2, f3, g1, g2)
    ref = [E, E2, *w["a"], *w["b"], *w["c"], w["new"][0], w["new"][1], w["new"][3]]
    np.testing.assert_allclose(W, np.stack(ref), rtol=1e-12, atol=1e-15)
    L2, W2 = twin.activity_krogstad(A, h, zeta, s, tau)
    np.testing.assert_allclose(W2, W, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(L2, L, rtol=1e-15)


def test_numba_strain_measures_and_divergence_match_numpy_references(rng):
    from nematic_solids.model.compiled.kernels import div_hat_kernel, strain_measures_kernel
    from nematic_solids.model.fourier import SpectralGrid
    from nematic_solids.model.reference_kernels import (
        strain_measures_kernel as strain_measures_twin,
    )

    F = np.eye(2)[:, :, None, None] + 0.2 * rng.standard_normal((2, 2, 8, 8))
    P = rng.standard_normal((2, 2, 8, 8))
    for fast, ref in zip(strain_measures_kernel(F, P), strain_measures_twin(F, P), strict=True):
        np.testing.assert_allclose(fast, ref, rtol=1e-13, atol=1e-14)
    g = SpectralGrid(8)
    T_hat = g.forward(P)
    np.testing.assert_allclose(
        div_hat_kernel(T_hat, g.kx, g.ky), g.div_hat(T_hat), rtol=1e-14, atol=1e-14
    )


def test_etdrk4_activity_weights_row_by_row_equal_point_by_point(rng):
    """The compiled weights (the Taylor series a row at a time) are bitwise those of
    evaluating the phi functions point by point (nematic_solids.model.compiled.etd._phi123_from)."""
    from nematic_solids.model.compiled import etd

    A = rng.uniform(-0.6, 0.6, (6, 16))
    zeta, s, tau, h = 1.0, 10.0, 1.0, 0.3  # z from -0.3 to -3.5: both branches, for h and h/2
    L, W = etd.activity_krogstad(A, h, zeta, s, tau)
    for x in range(A.shape[0]):
        for y in range(A.shape[1]):
            a = A[x, y]
            lam = -(zeta + 3.0 * s * a * a) / tau
            z = lam * h
            # libm's exp and expm1, as compiled code calls them (numpy's own may differ)
            e_half = math.exp(0.5 * z) if z < -1.0 else 1.0 + math.expm1(0.5 * z)
            em1_half = e_half - 1.0 if z < -1.0 else math.expm1(0.5 * z)
            f1, f2, f3 = etd._phi123_from(z, em1_half * (e_half + 1.0))
            g1, g2, _ = etd._phi123_from(0.5 * z, em1_half)
            assert L[x, y] == lam
            assert W[0, x, y] == e_half * e_half
            assert W[1, x, y] == e_half
            assert W[2, x, y] == 0.5 * g1
            assert W[4, x, y] == g2
            assert W[3, x, y] == 0.5 * g1 - g2
            assert W[5, x, y] == f1 - 2.0 * f2
            assert W[6, x, y] == 2.0 * f2
            assert W[7, x, y] == f1 - 3.0 * f2 + 4.0 * f3
            assert W[8, x, y] == 2.0 * f2 - 4.0 * f3
            assert W[9, x, y] == 4.0 * f3 - f2
