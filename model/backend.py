r"""The kernels a run executes: ``Numerics.backend`` "compiled" (numba,
:mod:`nematic_solids.model.compiled.kernels`) or "numpy" (their readable twins,
:mod:`nematic_solids.model.reference_kernels`).

:class:`Kernels` is the kernel set's interface: every pointwise and spectral kernel the
mechanics, the PDE, the split right-hand side and the solver call (through ``self.k`` or
``mechanics.k``), with its signature. Both modules satisfy it: :func:`kernels` returns either
as a :class:`Kernels`, so the type checker compares the numpy twins' signatures with it (the
numba dispatchers are untyped to it; ``tests/model/test_constitutive.py`` checks that the
compiled functions take the same parameters). The FFTs and Krylov solves follow the same
choice (:mod:`nematic_solids.model.fourier`, :class:`nematic_solids.model.mechanics.Mechanics`).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from . import reference_kernels
from .compiled import kernels as compiled_kernels

Array = np.ndarray


class Kernels(Protocol):
    """The kernel set of a backend (the numpy twins' docstrings hold the formulas)."""

    # --- finite-strain stress (paper Eqs. 1-2) -------------------------------------------
    def tangent_kernel(
        self, F: Array, q1: Array, q2: Array, kappa: float, B: float, Bp: float, alpha: float
    ) -> Array:
        """The tangent :math:`\\partial P / \\partial F`, packed (10 components)."""

    def apply_tangent_kernel(self, K: Array, dF: Array) -> Array:
        """:math:`\\mathbb K : dF` of the packed tangent ``K``."""

    def apply_tangent_spin_kernel(self, K: Array, G: Array, E: Array) -> Array:
        """:math:`\\mathbb K : G + E\\, \\omega(G)` (the displacement-rate operator)."""

    def first_piola_kernel(
        self, F: Array, q1: Array, q2: Array, kappa: float, B: float, Bp: float, alpha: float
    ) -> Array:
        """The first Piola stress P (the derivative of Eq. 1)."""

    def q_increment_kernel(
        self,
        F: Array,
        q1: Array,
        q2: Array,
        d1: Array,
        d2: Array,
        B: float,
        Bp: float,
        alpha: float,
    ) -> Array:
        """:math:`\\partial_Q P : dQ`, dQ of components (d1, d2)."""

    def strain_measures_kernel(self, F: Array, P: Array) -> tuple[Array, Array, Array]:
        """(dev :math:`\\bar E` as two components, J - 1, tr P)."""

    # --- spectral operators ----------------------------------------------------------------
    def grad_hat_kernel(self, v: Array, kx: Array, ky: Array) -> Array:
        """:math:`i k_j \\hat v_i`."""

    def div_hat_kernel(self, T: Array, kx: Array, ky: Array) -> Array:
        """:math:`i k_j \\hat T_{ij}`."""

    def balance_residual_kernel(
        self, P: Array, P_hat: Array, khx: Array, khy: Array, weights: Array
    ) -> float:
        """The force-balance residual
        (:meth:`nematic_solids.model.mechanics.Mechanics.residual`)."""

    def neg_div_hat_kernel(self, T: Array, kx: Array, ky: Array) -> Array:
        """:math:`-i k_j \\hat T_{ij}`."""

    def green_kernel(self, b: Array, khx: Array, khy: Array, inv_k2: Array, a: float) -> Array:
        """:math:`(I - a \\hat k \\hat k)\\, \\hat b / k^2`."""

    def symbol_combination(self, x: Array, m1: Array, m2: Array, a: Array, b: Array) -> Array:
        """:math:`x - (m_1 a + m_2 b)`."""

    def linear_response(
        self,
        q1h: Array,
        q2h: Array,
        isoh: Array,
        kx: Array,
        ky: Array,
        khx: Array,
        khy: Array,
        inv_k2: Array,
        amb: float,
        a: float,
        kappa: float,
        incompressible: bool,
        mean_dev: float,
    ) -> tuple[Array, Array, Array]:
        """The small-strain spectra (dev e, tr e, tr sigma) of the eigenstress."""

    # --- rates of Eqs. (4)-(5) -------------------------------------------------------------
    def bulk_terms(
        self, q1: Array, q2: Array, A: Array, tr_e: Array, C: float, two_Bp: float
    ) -> Array:
        """The bulk part of the molecular field H of Eq. (4)."""

    def molecular_field_kernel(
        self,
        q1: Array,
        q2: Array,
        A: Array,
        Jm1: Array,
        Ebar_dev: Array,
        lap: Array,
        A0: float,
        C: float,
        two_Bp: float,
        B: float,
        K: float,
    ) -> Array:
        """The molecular field H of Eq. (4)."""

    def activity_rate(
        self, A: Array, trP: Array, zeta: float, chi: float, s: float, tau: float
    ) -> Array:
        """:math:`\\dot A` of Eq. (5)."""

    def corotational_rate(
        self, R: Array, grad_v: Array, q1: Array, q2: Array
    ) -> tuple[Array, Array]:
        """``(R + 2 omega J q, omega)`` from the gradient of the velocity (Eq. 4)."""

    def jaumann_products(self, omega: Array, q1: Array, q2: Array) -> Array:
        """:math:`2 \\omega J q`."""

    # --- the exponential integrators' pointwise pieces ----------------------------------------
    def activity_exponential(
        self, A: Array, h: float, zeta: float, s: float, tau: float
    ) -> tuple[Array, Array, Array]:
        """``(L_A, phi1(h L_A), phi2(h L_A))`` of the activity's linear part."""

    def activity_krogstad(
        self, A: Array, h: float, zeta: float, s: float, tau: float
    ) -> tuple[Array, Array]:
        """``(L_A, W)``, Krogstad's ten pointwise weights."""

    def etd_combination(
        self, E: Array, x: Array, h: float, coef: tuple[Array, ...], terms: tuple[Array, ...]
    ) -> Array:
        """:math:`E x + h \\sum_k c_k N_k`."""

    def rk_stage(self, x0: Array, c: float, v: Array) -> Array:
        """:math:`x_0 + c\\, v`."""

    def rk4_update(self, x0: Array, c: float, v0: Array, v1: Array, v2: Array, v3: Array) -> Array:
        """:math:`x_0 + c\\, (v_0 + 2 v_1 + 2 v_2 + v_3)`."""

    # --- well-posedness ------------------------------------------------------------------
    def finite_margin_kernel(
        self, K: Array, E: Array, cos_t: Array, sin_t: Array, scale: float
    ) -> tuple[float, int, int]:
        """The sampled minimum of the rate problem's symbol determinant / ``scale``, its flat
        point index and angle index
        (:func:`nematic_solids.model.wellposedness.finite_margin_samples`)."""

    def linear_margin_kernel(self, q1: Array, q2: Array, alpha_minus_B: float) -> tuple[float, int]:
        """The small-strain margin and the flat index of its minimum
        (:func:`nematic_solids.model.wellposedness.linear_margin`)."""


def kernels(backend: str) -> Kernels:
    """The kernel module of ``backend`` ("compiled" or "numpy")."""
    if backend == "compiled":
        return compiled_kernels
    if backend == "numpy":
        return reference_kernels
    raise ValueError(f"unknown backend {backend!r} (compiled, numpy)")
