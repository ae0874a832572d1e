"""The compiled kernels a ``Numerics.backend = "compiled"`` run uses, under the names of their
numpy twins in :mod:`nematic_solids.model.reference_kernels`
(:func:`nematic_solids.model.backend.kernels` picks one of the two modules)."""

from __future__ import annotations

from .constitutive import (
    apply_tangent_kernel,
    apply_tangent_spin_kernel,
    first_piola_kernel,
    q_increment_kernel,
    strain_measures_kernel,
    tangent_kernel,
)
from .etd import (
    activity_exponential,
    activity_krogstad,
    etd_combination,
    rk4_update,
    rk_stage,
)
from .rates import (
    activity_rate,
    bulk_terms,
    corotational_rate,
    jaumann_products,
    molecular_field_kernel,
)
from .spectral import (
    balance_residual_kernel,
    div_hat_kernel,
    grad_hat_kernel,
    green_kernel,
    linear_response,
    neg_div_hat_kernel,
    symbol_combination,
)
from .wellposedness import finite_margin_kernel, linear_margin_kernel

__all__ = [
    "activity_exponential",
    "activity_krogstad",
    "activity_rate",
    "apply_tangent_kernel",
    "apply_tangent_spin_kernel",
    "balance_residual_kernel",
    "bulk_terms",
    "corotational_rate",
    "div_hat_kernel",
    "etd_combination",
    "finite_margin_kernel",
    "first_piola_kernel",
    "grad_hat_kernel",
    "green_kernel",
    "jaumann_products",
    "linear_margin_kernel",
    "linear_response",
    "molecular_field_kernel",
    "neg_div_hat_kernel",
    "q_increment_kernel",
    "rk4_update",
    "rk_stage",
    "strain_measures_kernel",
    "symbol_combination",
    "tangent_kernel",
]
