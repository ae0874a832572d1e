"""The kernels a run executes: ``Numerics.backend`` "compiled" (numba,
:mod:`model.compiled.kernels`) or "numpy" (their readable twins,
:mod:`model.reference_kernels`). Both modules export the same names with the same signatures;
the mechanics and the solver call every pointwise and spectral kernel through the module this
returns, and the FFTs and Krylov solves follow the same choice (:mod:`model.fourier`,
:class:`model.mechanics.Mechanics`)."""

from __future__ import annotations

from types import ModuleType

from . import reference_kernels
from .compiled import kernels as compiled_kernels


def kernels(backend: str) -> ModuleType:
    """The kernel module of ``backend`` ("compiled" or "numpy")."""
    if backend == "compiled":
        return compiled_kernels
    if backend == "numpy":
        return reference_kernels
    raise ValueError(f"unknown backend {backend!r} (compiled, numpy)")
