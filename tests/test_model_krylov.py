"""The compiled Krylov pieces shared by the fast solvers (model.krylov): the weighted inner
product against its numpy definition, the fused update + inner product and the fused
Gram-Schmidt step against their plain, unfused sequence (bitwise), and the Arnoldi
orthogonality they produce."""

from __future__ import annotations

import numpy as np
import pytest

from model import krylov


def _spectra(rng, shape):
    return rng.standard_normal(shape) + 1j * rng.standard_normal(shape)


@pytest.mark.parametrize("shape", [(16, 9), (2, 16, 9), (2, 30, 16)])
def test_weighted_inner_matches_its_definition(shape, rng):
    w = rng.random(shape[-2:])
    a, b = _spectra(rng, shape), _spectra(rng, shape)
    expected = float(np.sum(np.broadcast_to(w, shape) * (np.conj(a) * b).real))
    got = krylov.weighted_inner(a, b, w)
    assert got == pytest.approx(expected, rel=1e-13, abs=1e-13)
    assert krylov.weighted_inner(a, b, w) == got  # deterministic
    assert krylov.weighted_inner(b, a, w) == got  # symmetric (real part)


@pytest.mark.parametrize("shape", [(16, 9), (2, 30, 16)])
def test_axpy_inner_is_bitwise_the_two_steps(shape, rng):
    w = rng.random(shape[-2:])
    y, x, a = (_spectra(rng, shape) for _ in range(3))
    y_plain = y.copy()
    krylov.axpy(y_plain, -0.37, x)
    expected = krylov.weighted_inner(a, y_plain, w)
    got = krylov.axpy_inner(y, -0.37, x, a, w)
    assert np.array_equal(y, y_plain)
    assert got == expected
    # with a = y itself: the squared norm of the updated vector
    y2 = _spectra(rng, shape)
    y2_plain = y2.copy()
    krylov.axpy(y2_plain, 0.5, x)
    assert krylov.axpy_inner(y2, 0.5, x, y2, w) == krylov.weighted_inner(y2_plain, y2_plain, w)


@pytest.mark.parametrize("shape", [(16, 9), (2, 30, 16)])
def test_mgs_column_is_modified_gram_schmidt(shape, rng):
    w = rng.random(shape[-2:])
    k = 3
    V = np.empty((k + 2,) + shape, dtype=complex)
    for i in range(k + 1):  # an orthonormal basis, built with the same step
        v = _spectra(rng, shape)
        if i:
            H = np.zeros((k + 2, k + 1))
            krylov.mgs_column(V, v, H, i - 1, w)
        krylov.scaled(V[i], v, np.sqrt(krylov.weighted_inner(v, v, w)))
    gram = np.array([[krylov.weighted_inner(V[i], V[j], w) for j in range(k + 1)]
                     for i in range(k + 1)])
    np.testing.assert_allclose(gram, np.eye(k + 1), atol=1e-12)
    wv = _spectra(rng, shape)
    plain, H_plain = wv.copy(), np.zeros((k + 2, k + 1))
    for i in range(k + 1):  # the textbook loop
        H_plain[i, k] = krylov.weighted_inner(V[i], plain, w)
        plain -= H_plain[i, k] * V[i]
    H = np.zeros((k + 2, k + 1))
    norm = krylov.mgs_column(V, wv, H, k, w)
    np.testing.assert_array_equal(H, H_plain)
    np.testing.assert_array_equal(wv, plain)
    assert norm == np.sqrt(krylov.weighted_inner(plain, plain, w))
    # the remainder is orthogonal to the basis
    for i in range(k + 1):
        assert abs(krylov.weighted_inner(V[i], wv, w)) < 1e-12 * norm
