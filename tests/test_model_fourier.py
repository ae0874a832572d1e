"""Transforms: the native FFTW path (model.fftw_native) against scipy.fft, on aligned,
misaligned and multi-field arrays, and the compiled-kernel symbols against their reference."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.fft

from model import fftw_native
from model.fourier import FFT, SpectralGrid

pytestmark = pytest.mark.skipif(not fftw_native.AVAILABLE, reason="native FFTW not available")


def _misaligned(shape, dtype):
    """A C-contiguous array whose data start 8 bytes past a 64-byte boundary."""
    dtype = np.dtype(dtype)
    size = int(np.prod(shape)) * dtype.itemsize
    raw = np.empty(size + 128, dtype=np.uint8)
    off = (-raw.ctypes.data) % 64 + 8
    out = raw[off:off + size].view(dtype).reshape(shape)
    assert out.ctypes.data % 16 == 8
    return out


@pytest.mark.parametrize("n", [8, 30, 64])
def test_native_transforms_match_scipy_whatever_the_alignment(n, rng):
    f, i = fftw_native.plans(n)
    a = rng.standard_normal((n, n))
    want = scipy.fft.rfft2(a)
    for src in (a, _misaligned(a.shape, a.dtype)):
        src[...] = a
        for dst in (np.empty(want.shape, complex), _misaligned(want.shape, complex)):
            fftw_native.rfft2(f, src, dst)
            np.testing.assert_allclose(dst, want, rtol=0, atol=1e-12 * np.abs(want).max())
            back = _misaligned(a.shape, float)
            fftw_native.irfft2(i, dst, back)
            np.testing.assert_allclose(back, a, rtol=0, atol=1e-13)
            np.testing.assert_allclose(dst, want, rtol=0, atol=1e-12 * np.abs(want).max())


def test_fft_class_multi_field_and_count(rng):
    n = 16
    native, ref = FFT(n, backend="fftw"), FFT(n, backend="scipy")
    a = rng.standard_normal((2, 2, n, n))
    np.testing.assert_allclose(native.forward(a), ref.forward(a), atol=1e-12)
    ah = ref.forward(a)
    np.testing.assert_allclose(native.inverse(ah), ref.inverse(ah), atol=1e-13)
    assert native.count == 8
    with pytest.raises(ValueError, match="unknown FFT backend"):
        FFT(n, backend="mkl")


def test_linear_response_symbols_match_the_direct_kernel(rng):
    from model import kernels as kern
    from model.mechanics import LinearMechanics
    from model.parameters import Parameters

    n = 16
    g = SpectralGrid(n)
    for incompressible in (False, True):
        mech = LinearMechanics(Parameters(B_prime=0.2, eps=0.01), g, incompressible=incompressible)
        S = mech.response_symbols()
        q = rng.standard_normal((3, n, n))
        qh = g.forward(q)
        dev, tr_e, tr_s = mech.spectral_response(qh[:2], qh[2])
        fast = kern.linear_response_symbols(qh[0], qh[1], -0.2 * qh[2], S, 0.01 * n**2)
        np.testing.assert_allclose(fast, np.stack([dev[0], dev[1], tr_e, tr_s]), atol=1e-10)
