"""Transforms: the native FFTW path (nematic_solids.model.compiled.fftw) against scipy.fft, on
aligned, misaligned and multi-field arrays, and the compiled-kernel symbols against their
reference."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.fft

from nematic_solids.model.compiled import fftw as fftw_native
from nematic_solids.model.fourier import FFT, SpectralGrid

pytestmark = pytest.mark.skipif(not fftw_native.AVAILABLE, reason="native FFTW not available")


def _misaligned(shape, dtype):
    """A C-contiguous array whose data start 8 bytes past a 64-byte boundary."""
    dtype = np.dtype(dtype)
    size = int(np.prod(shape)) * dtype.itemsize
    raw = np.empty(size + 128, dtype=np.uint8)
    off = (-raw.ctypes.data) % 64 + 8
    out = raw[off : off + size].view(dtype).reshape(shape)
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
    from nematic_solids.model.mechanics import LinearMechanics
    from nematic_solids.model.parameters import Parameters

    n = 16
    g = SpectralGrid(n)
    for incompressible in (False, True):
        mech = LinearMechanics(Parameters(B_prime=0.2, eps=0.01), g, incompressible=incompressible)
        S = mech.response_symbols()
        q = rng.standard_normal((3, n, n))
        qh = g.forward(q)
        dev, tr_e, tr_s = mech.spectral_response(qh[:2], qh[2])
        fast = np.einsum("rcij,cij->rij", S, np.stack([qh[0], qh[1], -0.2 * qh[2]]))
        fast[0, 0, 0] += 0.01 * n**2  # the applied mean strain
        np.testing.assert_allclose(fast, np.stack([dev[0], dev[1], tr_e, tr_s]), atol=1e-10)


def test_irfft_through_a_scratch_even_the_input_itself(rng):
    n = 32
    f, i = fftw_native.plans(n)
    a = rng.standard_normal((n, n))
    spec = scipy.fft.rfft2(a)
    for scratch in (
        fftw_native.aligned_empty(spec.shape, complex),
        _misaligned(spec.shape, complex),
        "self",
    ):
        src = spec.copy()
        out = np.empty((n, n))
        fftw_native.irfft2_via(i, src, out, src if isinstance(scratch, str) else scratch)
        np.testing.assert_allclose(out, a, rtol=0, atol=1e-13)
        if not isinstance(scratch, str):
            np.testing.assert_array_equal(src, spec)  # a separate scratch leaves src intact


def _run(code: str, env: dict[str, str]) -> str:
    import os
    import subprocess
    import sys

    return subprocess.run(
        [sys.executable, "-c", code],
        env={**os.environ, **env},
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()


_TRANSFORM = """
import hashlib, numpy as np
from nematic_solids.model.compiled import fftw as fx
n = {n}
f, i = fx.plans(n)
a = np.random.default_rng(1).standard_normal((n, n))
out = np.empty((n, n // 2 + 1), complex)
fx.rfft2(f, a, out)
print(fx.WISDOM_LOADED, fx.plan_source(n), hashlib.sha256(out.tobytes()).hexdigest())
"""


def test_shipped_wisdom_plans_are_the_same_in_every_process(tmp_path):
    """Wisdom made once (FFTW_PATIENT, timing) is imported by later processes, which plan from
    it without timing: their transforms are bitwise identical; a size the wisdom does not hold
    gets FFTW_ESTIMATE's plan (also deterministic)."""
    wisdom = tmp_path / "wisdom.txt"
    _run(
        f"from nematic_solids.model.compiled import fftw as fx; open({str(wisdom)!r}, 'w').write("
        "fx.patient_wisdom([16]))",
        {"NEMATIC_FFTW_WISDOM": ""},
    )
    env = {"NEMATIC_FFTW_WISDOM": str(wisdom)}
    one, two = (_run(_TRANSFORM.format(n=16), env) for _ in range(2))
    assert one == two
    assert one.split()[:2] == ["True", "wisdom"]
    assert _run(_TRANSFORM.format(n=18), env).split()[:2] == ["True", "estimate"]
    off = _run(_TRANSFORM.format(n=16), {"NEMATIC_FFTW_WISDOM": ""})
    assert off.split()[:2] == ["False", "estimate"]


def test_the_shipped_wisdom_holds_the_campaign_sizes():
    """The wisdom file in the package covers the resolutions the campaigns use (when this FFTW
    build accepts it: elsewhere plans fall back to FFTW_ESTIMATE, see
    nematic_solids.model.compiled.fftw)."""
    assert fftw_native.WISDOM_FILE is not None
    text = fftw_native.WISDOM_FILE.read_text()
    assert text.startswith("(fftw-3")
    if not fftw_native.WISDOM_LOADED:
        pytest.skip("this FFTW build does not accept the shipped wisdom")
    for n in (32, 64, 128, 256):
        assert fftw_native.plan_source(n) == "wisdom"
