"""FFTW callable from compiled (numba) code: 2-D real transforms with no Python in between.

pyFFTW ships the FFTW library; we load that library once, make the two plans per grid size
ourselves (``fftw_plan_dft_r2c_2d`` / ``c2r_2d``, FFTW_ESTIMATE: chosen from the size alone, so
results are bitwise reproducible across processes) and run them with FFTW's new-array execute
functions, declared to numba as external symbols (``numba.types.ExternalFunction``). So a
whole right-hand side, Krylov loop included, can run as one compiled function
(:mod:`nematic_solids.model.compiled.linear_rhs`), and compiled kernels are still cached on disk
(the symbols are resolved by name when the cache is loaded, not baked in as addresses).

Conventions as :mod:`nematic_solids.model.fourier`: real ``(N, N)`` fields, half spectra ``(N, N//2
+ 1)``, forward unnormalised, inverse divided by N^2.

FFTW's new-array execute needs arrays with the alignment the plan was made with; plans are made
on arrays that FFTW reports as aligned (``fftw_alignment_of == 0``), and :func:`rfft2` /
:func:`irfft2` check every array and go through an aligned scratch copy when needed. The c2r
transform destroys its input, so :func:`irfft2` always transforms a scratch copy.

Plans come from **shipped wisdom** where it applies: ``fftw_wisdom.txt`` (next to this module,
made by ``scripts/fftw_wisdom.py`` with FFTW_PATIENT on the development machine) is imported
once, and :func:`plans` asks FFTW for a plan from wisdom only (FFTW_WISDOM_ONLY: no timing at
run time). The same wisdom gives the same algorithm in every process, so results stay bitwise
reproducible (planning with FFTW_MEASURE at run time would not: it times candidates and may pick
another algorithm in another process). Where the wisdom does not apply (a size it does not
hold, another FFTW build or CPU without the SIMD codelets it names) the plan is FFTW_ESTIMATE's,
chosen from the size alone, equally deterministic; :func:`plan_source` says which. At 128^2 the
wisdom plan (vectorised row transforms) is 20-30 % faster than ESTIMATE's (scalar ``r2cf_128``),
measured side by side.

``AVAILABLE`` is False where the library cannot be found or loaded (then
:mod:`nematic_solids.model.fourier` falls back to scipy.fft and the solver to its numpy path).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import glob
import logging
import os
import threading
from pathlib import Path

import numpy as np
from numba import njit, types

log = logging.getLogger(__name__)

FFTW_ESTIMATE = 1 << 6
FFTW_PATIENT = 1 << 5
FFTW_WISDOM_ONLY = 1 << 21
#: the shipped wisdom (FFTW_PATIENT plans for the common sizes; scripts/fftw_wisdom.py);
#: the environment variable NEMATIC_FFTW_WISDOM names another file ("" for none)
_WISDOM_ENV = os.environ.get("NEMATIC_FFTW_WISDOM")
WISDOM_FILE: Path | None = (
    Path(__file__).with_name("fftw_wisdom.txt")
    if _WISDOM_ENV is None
    else Path(_WISDOM_ENV)
    if _WISDOM_ENV
    else None
)
_ALIGN = 64  # bytes: at least FFTW's SIMD alignment on every platform it supports


def _candidates() -> list[str]:
    """Where FFTW's double-precision library may be: inside the pyFFTW wheel first (Linux
    ``pyfftw.libs``, macOS ``pyfftw/.dylibs``, Windows next to the package), then the system."""
    out: list[str] = []
    try:
        import pyfftw

        here = os.path.dirname(pyfftw.__file__)
        for pattern in (
            "../pyfftw.libs/libfftw3-*.so*",
            ".dylibs/libfftw3.*dylib",
            "libfftw3-3.dll",
            "../pyFFTW.libs/libfftw3-*.so*",
        ):
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
            fn.argtypes = [
                ctypes.c_int,
                ctypes.c_int,
                ctypes.c_void_p,
                ctypes.c_void_p,
                ctypes.c_uint,
            ]
        lib.fftw_alignment_of.restype = ctypes.c_int
        lib.fftw_alignment_of.argtypes = [ctypes.c_void_p]
        lib.fftw_import_wisdom_from_string.restype = ctypes.c_int
        lib.fftw_import_wisdom_from_string.argtypes = [ctypes.c_char_p]
        lib.fftw_export_wisdom_to_string.restype = ctypes.c_void_p
        lib.fftw_export_wisdom_to_string.argtypes = []
        log.debug("native FFTW: %s", path)
        return lib
    return None


def _import_wisdom(lib: ctypes.CDLL | None) -> bool:
    """Import the shipped wisdom (False if absent or rejected by this FFTW build)."""
    if lib is None or WISDOM_FILE is None or not WISDOM_FILE.is_file():
        return False
    ok = bool(lib.fftw_import_wisdom_from_string(WISDOM_FILE.read_bytes()))
    if not ok:
        log.debug("the shipped FFTW wisdom does not fit this FFTW build: ESTIMATE plans")
    return ok


_LIB = _load()
AVAILABLE = _LIB is not None
_LOCK = threading.Lock()  # the FFTW planner is not thread-safe
_PLANS: dict[int, tuple[int, int]] = {}
_SOURCE: dict[int, str] = {}
WISDOM_LOADED = _import_wisdom(_LIB)


def aligned_empty(shape: tuple[int, ...], dtype) -> np.ndarray:
    """An uninitialised C-contiguous array whose data start on a 64-byte boundary."""
    dtype = np.dtype(dtype)
    size = int(np.prod(shape)) * dtype.itemsize
    raw = np.empty(size + _ALIGN, dtype=np.uint8)
    offset = (-raw.ctypes.data) % _ALIGN
    return raw[offset : offset + size].view(dtype).reshape(shape)


def _plan_pair(lib: ctypes.CDLL, n: int, flags: int) -> tuple[int, int]:
    """FFTW's ``(r2c, c2r)`` plans for N x N with ``flags`` (0 where FFTW made none), made on
    64-byte aligned scratch arrays (the alignment every execution then checks for)."""
    real = aligned_empty((n, n), np.float64)
    half = aligned_empty((n, n // 2 + 1), np.complex128)
    assert lib.fftw_alignment_of(real.ctypes.data) == 0
    assert lib.fftw_alignment_of(half.ctypes.data) == 0
    f = lib.fftw_plan_dft_r2c_2d(n, n, real.ctypes.data, half.ctypes.data, flags)
    i = lib.fftw_plan_dft_c2r_2d(n, n, half.ctypes.data, real.ctypes.data, flags)
    return int(f or 0), int(i or 0)


def plans(n: int) -> tuple[int, int]:
    """The ``(r2c, c2r)`` FFTW plans (as integer addresses) for N x N, made once per process
    and never destroyed (plans are read-only and may be executed from several threads): from
    the shipped wisdom where it holds this size, else FFTW_ESTIMATE's (module docstring)."""
    if _LIB is None:
        raise RuntimeError("the native FFTW library is not available")
    with _LOCK:
        got = _PLANS.get(n)
        if got is None:
            got, source = (0, 0), "estimate"
            if WISDOM_LOADED:
                got, source = _plan_pair(_LIB, n, FFTW_PATIENT | FFTW_WISDOM_ONLY), "wisdom"
            if not all(got):
                got, source = _plan_pair(_LIB, n, FFTW_ESTIMATE), "estimate"
            if not all(got):  # pragma: no cover - FFTW plans every size with ESTIMATE
                raise RuntimeError(f"FFTW could not plan a {n} x {n} transform")
            _PLANS[n] = got
            _SOURCE[n] = source
        return got


def plan_source(n: int) -> str:
    """Where the N x N plans came from: "wisdom" (the shipped FFTW_PATIENT plans) or
    "estimate" (FFTW_ESTIMATE); makes the plans if needed."""
    plans(n)
    return _SOURCE[n]


def patient_wisdom(sizes: list[int]) -> str:
    """Plan every N x N of ``sizes`` with FFTW_PATIENT (timing candidate algorithms: seconds
    per size) and return FFTW's wisdom for them (what ``scripts/fftw_wisdom.py`` writes to
    :data:`WISDOM_FILE`). It forgets the wisdom imported at start first (so the timings are
    new); plans made earlier in the process stay valid."""
    if _LIB is None:
        raise RuntimeError("the native FFTW library is not available")
    with _LOCK:
        _LIB.fftw_forget_wisdom()
        for n in sizes:
            _plan_pair(_LIB, n, FFTW_PATIENT)
        return ctypes.string_at(_LIB.fftw_export_wisdom_to_string()).decode()


# FFTW's execute functions as external symbols: resolved by name when a compiled function is
# linked (so compiling needs the library loaded: AVAILABLE), not when this module is imported
_r2c = types.ExternalFunction(
    "fftw_execute_dft_r2c", types.void(types.uintp, types.uintp, types.uintp)
)
_c2r = types.ExternalFunction(
    "fftw_execute_dft_c2r", types.void(types.uintp, types.uintp, types.uintp)
)
_alignment_of = types.ExternalFunction("fftw_alignment_of", types.intc(types.uintp))


@njit(cache=True)
def aligned_real(n):  # pragma: no cover - compiled
    """An uninitialised 64-byte aligned (N, N) real array (in compiled code)."""
    raw = np.empty(n * n + 8)
    off = ((-raw.ctypes.data) % 64) // 8
    return raw[off : off + n * n].reshape((n, n))


@njit(cache=True)
def aligned_half(n):  # pragma: no cover - compiled
    """An uninitialised 64-byte aligned (N, N // 2 + 1) half spectrum (in compiled code)."""
    m = n // 2 + 1
    raw = np.empty(n * m + 4, dtype=np.complex128)
    off = ((-raw.ctypes.data) % 64) // 16
    return raw[off : off + n * m].reshape((n, m))


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
    a = aligned_real(n)
    a[:, :] = src
    b = aligned_half(n)
    _r2c(plan, a.ctypes.data, b.ctypes.data)
    dst[:, :] = b


@njit(cache=True)
def irfft2(plan, src, dst):  # pragma: no cover - compiled
    """``dst[...] = irfft2(src)`` for one (N, N // 2 + 1) half spectrum (divides by N^2);
    ``src`` is left intact (FFTW's c2r destroys its input: it works on a copy)."""
    irfft2_via(plan, src, dst, aligned_half(dst.shape[0]))


@njit(cache=True)
def irfft2_via(plan, src, dst, scratch):  # pragma: no cover - compiled
    """:func:`irfft2` through the caller's scratch half spectrum (overwritten; it may be
    ``src`` itself, which is then destroyed): a hot loop then allocates nothing (a fresh
    133 kB scratch per 128^2 transform costs ~15 % of its time, measured)."""
    n = dst.shape[0]
    scale = 1.0 / (n * n)
    unscaled_irfft2_into(plan, src, dst, scratch)
    for x in range(n):
        for y in range(n):
            dst[x, y] *= scale


@njit(cache=True)
def unscaled_irfft2_into(plan, src, dst, scratch):  # pragma: no cover - compiled
    """:func:`unscaled_irfft2_via` into any ``dst``: directly where it is aligned for the
    plan, else through an aligned copy."""
    if not unscaled_irfft2_via(plan, src, dst, scratch):
        a = aligned_real(dst.shape[0])
        unscaled_irfft2_via(plan, src, a, scratch)
        dst[:, :] = a


@njit(cache=True)
def unscaled_irfft2_via(plan, src, dst, scratch):  # pragma: no cover - compiled
    """FFTW's c2r of ``src`` into ``dst`` through ``scratch`` (as :func:`irfft2_via`),
    *not* divided by N^2: for a caller that folds 1/N^2 (a power of two for the even N
    used, so exactly) into its next pass over the result. Returns False, doing nothing,
    if ``dst`` is not aligned for the plan."""
    if not _usable(dst):
        return False
    b = scratch if _usable(scratch) else aligned_half(dst.shape[0])
    if b.ctypes.data != src.ctypes.data:
        b[:, :] = src
    _c2r(plan, b.ctypes.data, dst.ctypes.data)
    return True


@njit(cache=True)
def rfft2_many(plan, src, dst):  # pragma: no cover - compiled
    """:func:`rfft2` over the leading axis of ``(k, N, N)`` -> ``(k, N, N//2 + 1)``."""
    for j in range(src.shape[0]):
        rfft2(plan, src[j], dst[j])


@njit(cache=True)
def irfft2_many(plan, src, dst):  # pragma: no cover - compiled
    """:func:`irfft2` over the leading axis of ``(k, N, N//2 + 1)`` -> ``(k, N, N)``."""
    scratch = aligned_half(dst.shape[1])
    for j in range(src.shape[0]):
        irfft2_via(plan, src[j], dst[j], scratch)
