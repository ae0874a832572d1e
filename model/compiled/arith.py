"""Real-times-complex products for compiled code (numba would promote the real factor to
complex and multiply as complex numbers: twice the work in the hot loops; the values are the
same). numpy twin: the plain products ``c * z`` and ``1j * c * z``."""

from __future__ import annotations

from numba import types
from numba.extending import overload


def rmul(c, z):
    """``c * z`` for a real ``c``; compiled, a complex ``z`` is scaled component by component
    (numba would promote ``c`` to complex and multiply as complex numbers: twice the work, and
    in the hot loops below that work, not memory, was the limit; the values are the same)."""
    return c * z


@overload(rmul)
def _rmul_compiled(c, z):  # pragma: no cover - compiled
    if isinstance(z, types.Complex):
        return lambda c, z: complex(c * z.real, c * z.imag)
    return lambda c, z: c * z


def imul(c, z):
    """``1j * c * z`` for a real ``c`` and a complex ``z``, compiled as
    ``complex(-c z.imag, c z.real)`` (see :func:`rmul`)."""
    return 1j * c * z


@overload(imul)
def _imul_compiled(c, z):  # pragma: no cover - compiled
    return lambda c, z: complex(-c * z.imag, c * z.real)
