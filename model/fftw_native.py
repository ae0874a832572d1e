"""FFTW callable from compiled (numba) code: 2-D real transforms with no Python in between.

pyFFTW ships the FFTW library; we load that library once, make the two plans per grid size
ourselves (``fftw_plan_dft_r2c_2d`` / ``c2r_2d``, FFTW_ESTIMATE: chosen from the size alone, so
results are bitwise reproducible across processes) and run them with FFTW's new-array execute
functions, declared to numba as external symbols (``numba.types.ExternalFunction``). So a
whole right-hand side, Krylov loop included, can run as one compiled function
(:mod:`model.fast_linear`), and compiled kernels are still cached on disk (the symbols are
resolved by name when the cache is loaded, not baked in as addresses).

Conventions as :mod:`model.fourier`: real ``(N, N)`` fields, half spectra ``(N, N//2 + 1)``,
forward unnormalised, inverse divided by N^2.

FFTW's new-array execute needs arrays with the alignment the plan was made with; plans are made
on arrays that FFTW reports as aligned (``fftw_alignment_of == 0``), and :func:`rfft2` /
:func:`irfft2` check every array and go through an aligned scratch copy when needed. The c2r
transform destroys its input, so :func:`irfft2` always transforms a scratch copy.

``AVAILABLE`` is False where the library cannot be found or loaded (then :mod:`model.fourier`
falls back to scipy.fft and the solver to its numpy path).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import glob
import logging
import os
import threading

import numpy as np

log = logging.getLogger(__name__)

FFTW_ESTIMATE = 1 << 6
_ALIGN = 64  # bytes: at least FFTW's SIMD alignment on every platform it supports


def _candidates() -> list[str]:
    """Where FFTW's double-precision library may be: inside the pyFFTW wheel first (Linux
    ``pyfftw.libs``, macOS ``pyfftw/.dylibs``, Windows next to the package), then the system."""
    out: list[str] = []
    try:
        import pyfftw

        here = os.path.dirname(pyfftw.__file__)
        for pattern in ("../pyfftw.libs/libfftw3-*.so*", ".dylibs/libfftw3.*dylib",
                        "libfftw3-3.dll", "../pyFFTW.libs/libfftw3-*.so*"):
            out += sorted(glob.glob(os.path.join(here, pattern)))
    except ImportError:  # pragma: no cover - pyfftw is a dependency
        pass
    system = ctypes.util.find_library("fftw3")
    if system:
        out.append(system)
    return out


def _load() -> ctypes.CDLL | None:
    try:
        import llvmlite.binding as llvm
    except ImportError:  # pragma: no cover - numba depends on llvmlite
        return None
    for path in _candidates():
        try:
            lib = ctypes.CDLL(path)
            lib.fftw_execute_dft_r2c  # noqa: B018 - the symbols we need must exist
            lib.fftw_execute_dft_c2r  # noqa: B018
            llvm.load_library_permanently(path)  # numba resolves the symbols by name
        except (OSError, AttributeError, RuntimeError):
            continue
        for name in ("fftw_plan_dft_r2c_2d", "fftw_plan_dft_c2r_2d"):
            fn = getattr(lib, name)
            fn.restype = ctypes.c_void_p
            fn.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p,
                           ctypes.c_uint]
        lib.fftw_alignment_of.restype = ctypes.c_int
        lib.fftw_alignment_of.argtypes = [ctypes.c_void_p]
        log.debug("native FFTW: %s", path)
        return lib
    return None


_LIB = _load()
AVAILABLE = _LIB is not None
_LOCK = threading.Lock()  # the FFTW planner is not thread-safe
_PLANS: dict[int, tuple[int, int]] = {}


def aligned_empty(shape: tuple[int, ...], dtype) -> np.ndarray:
    """An uninitialised C-contiguous array whose data start on a 64-byte boundary."""
    dtype = np.dtype(dtype)
    size = int(np.prod(shape)) * dtype.itemsize
    raw = np.empty(size + _ALIGN, dtype=np.uint8)
    offset = (-raw.ctypes.data) % _ALIGN
    return raw[offset:offset + size].view(dtype).reshape(shape)


def plans(n: int) -> tuple[int, int]:
    """The ``(r2c, c2r)`` FFTW plans (as integer addresses) for N x N, made once per process
    and never destroyed (plans are read-only and may be executed from several threads)."""
    if _LIB is None:
        raise RuntimeError("the native FFTW library is not available")
    with _LOCK:
        got = _PLANS.get(n)
        if got is None:
            real = aligned_empty((n, n), np.float64)
            half = aligned_empty((n, n // 2 + 1), np.complex128)
            assert _LIB.fftw_alignment_of(real.ctypes.data) == 0
            assert _LIB.fftw_alignment_of(half.ctypes.data) == 0
            f = _LIB.fftw_plan_dft_r2c_2d(n, n, real.ctypes.data, half.ctypes.data,
                                          FFTW_ESTIMATE)
            i = _LIB.fftw_plan_dft_c2r_2d(n, n, half.ctypes.data, real.ctypes.data,
                                          FFTW_ESTIMATE)
            if not f or not i:  # pragma: no cover - FFTW plans every size with ESTIMATE
                raise RuntimeError(f"FFTW could not plan a {n} x {n} transform")
            got = _PLANS[n] = (int(f), int(i))
        return got


if AVAILABLE:
    from numba import njit, types

    _r2c = types.ExternalFunction(
        "fftw_execute_dft_r2c", types.void(types.uintp, types.uintp, types.uintp))
    _c2r = types.ExternalFunction(
        "fftw_execute_dft_c2r", types.void(types.uintp, types.uintp, types.uintp))
    _alignment_of = types.ExternalFunction("fftw_alignment_of", types.intc(types.uintp))

    @njit(cache=True)
    def _aligned_real(n):  # pragma: no cover - compiled
        raw = np.empty(n * n + 8)
        off = ((-raw.ctypes.data) % 64) // 8
        return raw[off:off + n * n].reshape((n, n))

    @njit(cache=True)
    def _aligned_half(n):  # pragma: no cover - compiled
        m = n // 2 + 1
        raw = np.empty(n * m + 4, dtype=np.complex128)
        off = ((-raw.ctypes.data) % 64) // 16
        return raw[off:off + n * m].reshape((n, m))

    @njit(cache=True)
    def _usable(a):  # pragma: no cover - compiled
        return a.flags.c_contiguous and _alignment_of(a.ctypes.data) == 0

    @njit(cache=True)
    def rfft2(plan, src, dst):  # pragma: no cover - compiled
        """``dst[...] = rfft2(src)`` for one (N, N) field (unnormalised)."""
        if _usable(src) and _usable(dst):
            _r2c(plan, src.ctypes.data, dst.ctypes.data)
            return
        n = src.shape[0]
        a = _aligned_real(n)
        a[:, :] = src
        b = _aligned_half(n)
        _r2c(plan, a.ctypes.data, b.ctypes.data)
        dst[:, :] = b

    @njit(cache=True)
    def irfft2(plan, src, dst):  # pragma: no cover - compiled
        """``dst[...] = irfft2(src)`` for one (N, N // 2 + 1) half spectrum (divides by N^2);
        ``src`` is left intact (FFTW's c2r destroys its input: it works on a copy)."""
        n = dst.shape[0]
        b = _aligned_half(n)
        b[:, :] = src
        scale = 1.0 / (n * n)
        if _usable(dst):
            _c2r(plan, b.ctypes.data, dst.ctypes.data)
            for x in range(n):
                for y in range(n):
                    dst[x, y] *= scale
            return
        a = _aligned_real(n)
        _c2r(plan, b.ctypes.data, a.ctypes.data)
        for x in range(n):
            for y in range(n):
                dst[x, y] = a[x, y] * scale

    @njit(cache=True)
    def rfft2_many(plan, src, dst):  # pragma: no cover - compiled
        """:func:`rfft2` over the leading axis of ``(k, N, N)`` -> ``(k, N, N//2 + 1)``."""
        for j in range(src.shape[0]):
            rfft2(plan, src[j], dst[j])

    @njit(cache=True)
    def irfft2_many(plan, src, dst):  # pragma: no cover - compiled
        """:func:`irfft2` over the leading axis of ``(k, N, N//2 + 1)`` -> ``(k, N, N)``."""
        for j in range(src.shape[0]):
            irfft2(plan, src[j], dst[j])
