"""The compiled Krylov pieces shared by the fast solvers (nematic_solids.model.compiled.krylov): the
weighted inner product against its numpy definition, the fused update + inner product and the fused
Gram-Schmidt step against their plain, unfused sequence (bitwise), the vectorised sums' independence
of alignment, and the Arnoldi orthogonality they produce."""

from __future__ import annotations

import numpy as np
import pytest

from nematic_solids.model import krylov
from nematic_solids.model.compiled import krylov as ck


def _spectra(rng, shape):
    return rng.standard_normal(shape) + 1j * rng.standard_normal(shape)


@pytest.mark.parametrize("shape", [(16, 9), (2, 16, 9), (2, 30, 16)])
def test_weighted_inner_matches_its_definition(shape, rng):
    w = rng.random(shape[-2:])
    a, b = _spectra(rng, shape), _spectra(rng, shape)
    expected = float(np.sum(np.broadcast_to(w, shape) * (np.conj(a) * b).real))
    got = ck.weighted_inner(a, b, w)
    assert got == pytest.approx(expected, rel=1e-13, abs=1e-13)
    assert ck.weighted_inner(a, b, w) == got  # deterministic
    assert ck.weighted_inner(b, a, w) == got  # symmetric (real part)


@pytest.mark.parametrize("shape", [(16, 9), (2, 30, 16)])
def test_axpy_inner_is_bitwise_the_two_steps(shape, rng):
    w = rng.random(shape[-2:])
    y, x, a = (_spectra(rng, shape) for _ in range(3))
    y_plain = y.copy()
    ck.axpy(y_plain, -0.37, x)
    expected = ck.weighted_inner(a, y_plain, w)
    got = ck.axpy_inner(y, -0.37, x, a, w)
    assert np.array_equal(y, y_plain)
    assert got == expected
    # with a = y itself: the squared norm of the updated vector
    y2 = y_plain.copy()
    ck.axpy(y2, 0.5, x)
    expected2 = ck.weighted_inner(y2, y2, w)
    y3 = y_plain.copy()
    assert ck.axpy_inner(y3, 0.5, x, y3, w) == expected2
    assert np.array_equal(y3, y2)
    assert expected2 > 0


def test_the_vectorised_sums_do_not_depend_on_alignment(rng):
    """The reassociated (SIMD) sums must give the same bits wherever the arrays start:
    otherwise two runs of one simulation could differ with the allocator's addresses."""
    shape = (2, 64, 33)
    w = rng.random(shape[-2:])
    a, b = _spectra(rng, shape), _spectra(rng, shape)
    ref = ck.weighted_inner(a, b, w)
    a_copy = a.copy()
    ref_norm = ck.axpy_inner(a_copy, 0.3, b, a_copy, w)
    n = a.size
    for offset in range(8):  # complex128 views starting 0, 16, ..., 112 bytes into a buffer
        buf = np.empty(2 * n + 16, dtype=complex)
        a2 = buf[offset : offset + n].reshape(shape)
        b2 = buf[n + 8 + offset : n + 8 + offset + n].reshape(shape)
        a2[...], b2[...] = a, b
        assert ck.weighted_inner(a2, b2, w) == ref
        assert ck.axpy_inner(a2, 0.3, b2, a2, w) == ref_norm


@pytest.mark.parametrize("shape", [(16, 9), (2, 30, 16)])
def test_mgs_column_is_modified_gram_schmidt(shape, rng):
    w = rng.random(shape[-2:])
    k = 3
    V = np.empty((k + 2,) + shape, dtype=complex)
    for i in range(k + 1):  # an orthonormal basis, built with the same step
        v = _spectra(rng, shape)
        if i:
            H = np.zeros((k + 2, k + 1))
            ck.mgs_column(V, v, H, i - 1, w)
        ck.scaled(V[i], v, np.sqrt(ck.weighted_inner(v, v, w)))
    gram = np.array(
        [[ck.weighted_inner(V[i], V[j], w) for j in range(k + 1)] for i in range(k + 1)]
    )
    np.testing.assert_allclose(gram, np.eye(k + 1), atol=1e-12)
    wv = _spectra(rng, shape)
    plain, H_plain = wv.copy(), np.zeros((k + 2, k + 1))
    for i in range(k + 1):  # the textbook loop
        H_plain[i, k] = ck.weighted_inner(V[i], plain, w)
        plain -= H_plain[i, k] * V[i]
    H = np.zeros((k + 2, k + 1))
    norm = ck.mgs_column(V, wv, H, k, w)
    np.testing.assert_array_equal(H, H_plain)
    np.testing.assert_array_equal(wv, plain)
    assert norm == np.sqrt(ck.weighted_inner(plain, plain, w))
    # the remainder is orthogonal to the basis
    for i in range(k + 1):
        assert abs(ck.weighted_inner(V[i], wv, w)) < 1e-12 * norm


def test_gmres_from_zero_needs_no_operator_application_for_its_residual(rng):
    """A zero start takes b as its residual: one operator application per iteration and none
    more (a warm start pays one for its residual); both reach the tolerance, and the auxiliary
    output L x is the same linear map of the solution."""
    n = 24
    A = np.eye(n) + 0.3 * rng.standard_normal((n, n)) / np.sqrt(n)
    L = rng.standard_normal((2, n))
    b = rng.standard_normal(n)
    calls = []

    def op(v):
        calls.append(1)
        return A @ v, L @ v

    solution = np.linalg.solve(A, b)
    for x0 in (np.zeros(n), solution + 0.1 * rng.standard_normal(n)):
        calls.clear()
        x, it, status, Lx = krylov.gmres_aux(
            op, b, x0, lambda r: r, np.dot, rtol=1e-10, maxiter=100
        )
        assert status == "ok"
        np.testing.assert_allclose(x, solution, atol=1e-8)
        np.testing.assert_allclose(Lx, L @ x, atol=1e-8)
        assert len(calls) == it + (0 if not np.any(x0) else 1)
    calls.clear()
    x, it, status, Lx = krylov.gmres_aux(
        op, np.zeros(n), np.zeros(n), lambda r: r, np.dot, rtol=1e-10, maxiter=100
    )
    assert (it, status) == (0, "ok")
    assert not np.any(x)
    assert Lx.shape == (2,)
    assert not np.any(Lx)


def test_compiled_spin_gmres_from_zero_meets_its_tolerance(rng):
    from nematic_solids.model.compiled import fftw as fftw_native
    from nematic_solids.model.compiled import linear_rhs as fast_linear
    from nematic_solids.model.fourier import SpectralGrid
    from nematic_solids.model.mechanics import LinearMechanics
    from nematic_solids.model.parameters import Parameters

    if not fftw_native.AVAILABLE:
        pytest.skip("native FFTW not available")
    n = 32
    g = SpectralGrid(n)
    mech = LinearMechanics(Parameters.from_dict({"alpha_minus_B": 1.0}), g)
    m1, m2 = mech.spin_symbols
    q1, q2 = 0.3 * rng.standard_normal((2, n, n))
    b = g.forward(rng.standard_normal((n, n)))
    w = g.weights / n**2
    V, LZ = fast_linear.workspace(n)
    # (numba's Dispatcher type does not carry the compiled function's signature)
    x, j, its, ok, nop = fast_linear.spin_gmres(  # type: ignore[call-arg, misc]
        b, np.zeros_like(b), q1, q2, m1, m2, w, *g.fft.plans, 1e-6, 100, V, LZ
    )
    assert ok
    assert its > 2
    assert nop == its  # no application for the zero start's residual
    Ax, jx = np.empty_like(b), np.empty((2,) + b.shape, complex)
    fast_linear._spin_operator(  # type: ignore[call-arg, misc]
        x,
        q1,
        q2,
        m1,
        m2,
        *g.fft.plans,
        np.empty((n, n)),
        np.empty((2, n, n)),
        fftw_native.aligned_empty(b.shape, complex),
        Ax,
        jx,
    )
    r = b - Ax
    assert np.sqrt(ck.weighted_inner(r, r, w)) <= 1.01e-6 * np.sqrt(ck.weighted_inner(b, b, w))
    np.testing.assert_allclose(j, jx, atol=1e-10 * np.abs(jx).max())  # accumulated = direct


def test_axpy_sum_is_bitwise_the_axpys(rng):
    shape = (2, 30, 16)
    B = _spectra(rng, (5,) + shape)
    y = rng.standard_normal(5)
    x0 = _spectra(rng, shape)
    plain = x0.copy()
    for i in range(4):
        ck.axpy(plain, y[i], B[i])
    fused = x0.copy()
    ck.axpy_sum(fused, y, B, 4)  # the first m = 4 of the 5 basis vectors
    assert np.array_equal(fused, plain)


def test_gmres_warm_start_with_known_aux_takes_its_residual_from_it(rng):
    """A warm start whose L x0 is given takes its residual from ``op_given_aux`` (no full
    operator application for it) and reaches the same solution and L x."""
    n = 24
    A = np.eye(n) + 0.3 * rng.standard_normal((n, n)) / np.sqrt(n)
    L = rng.standard_normal((2, n))
    b = rng.standard_normal(n)
    calls, given = [], []

    def op(v):
        calls.append(1)
        return A @ v, L @ v

    def op_given_aux(v, Lv):
        given.append(1)
        return A @ v

    x0 = np.linalg.solve(A, b) + 0.1 * rng.standard_normal(n)
    x_ref, it_ref, _, Lx_ref = krylov.gmres_aux(
        op, b, x0, lambda r: r, np.dot, rtol=1e-10, maxiter=100
    )
    calls.clear()
    x, it, status, Lx = krylov.gmres_aux(
        op,
        b,
        x0,
        lambda r: r,
        np.dot,
        rtol=1e-10,
        maxiter=100,
        Lx0=L @ x0,
        op_given_aux=op_given_aux,
    )
    assert status == "ok"
    assert it == it_ref
    assert (len(calls), len(given)) == (it, 1)
    np.testing.assert_allclose(x, x_ref, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(Lx, Lx_ref, rtol=1e-10, atol=1e-10)


def test_compiled_rate_gmres_from_a_known_gradient_matches_numpy(rng):
    """The finite-strain rate solve warm-started with the start's gradient known: compiled
    (nematic_solids.model.compiled.finite_krylov.gmres, the start's residual from the gradient: 4
    transforms fewer) and numpy (nematic_solids.model.krylov.gmres_aux) agree, and agree with the
    solve that transforms the start."""
    from nematic_solids.model.compiled import fftw as fftw_native
    from nematic_solids.model.fourier import SpectralGrid
    from nematic_solids.model.mechanics import FiniteMechanics
    from nematic_solids.model.parameters import Parameters

    if not fftw_native.AVAILABLE:
        pytest.skip("native FFTW not available")
    n = 32
    p = Parameters.from_dict({"alpha_minus_B": 1.0, "kappa": 10.0})
    q1, q2 = 0.2 * rng.standard_normal((2, n, n))
    out: dict[str, tuple[np.ndarray, np.ndarray, int]] = {}
    R = 0.1 * rng.standard_normal((2, n, n))
    for backend, fft in (("compiled", "auto"), ("numpy", "scipy")):
        g = SpectralGrid(n, fft_backend=fft)
        mech = FiniteMechanics(p, g, backend=backend, spin_tol=1e-12)
        state = mech.solve(q1, q2)
        mech.corotational(state, q1, q2, R)  # a first rate: the warm start and its gradient
        x0, g0 = mech.udot_hat, mech.udot_grad
        np.testing.assert_allclose(
            g0, mech.deformation(x0) - mech.Fbar[:, :, None, None], atol=1e-10
        )
        R2 = 1.1 * R
        count = g.fft.count
        mech.corotational(state, q1, q2, R2)
        out[backend] = (mech.udot_hat, mech.udot_grad, g.fft.count - count)
        if backend == "compiled":  # the same solve transforming the start
            mech.udot_hat, mech.udot_grad = x0, np.empty((0, 0, 0, 0))
            mech.corotational(state, q1, q2, R2)
            np.testing.assert_allclose(mech.udot_hat, out[backend][0], atol=1e-12)
    np.testing.assert_allclose(out["compiled"][0], out["numpy"][0], atol=1e-10)
    np.testing.assert_allclose(out["compiled"][1], out["numpy"][1], atol=1e-10)
    assert out["compiled"][2] == out["numpy"][2]  # the same transforms counted
