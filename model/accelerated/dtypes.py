r"""The precision of an accelerated run (``Numerics.precision``): which arrays are float32 and
which sums stay float64.

JAX's float64 switch (``jax_enable_x64``) is global and stays on; a float32 run casts its
arrays explicitly. In a float32 run:

* **float32 / complex64**: the fields q1, q2, A and their spectra, the constant Fourier symbols,
  every transform and pointwise pass (the right-hand sides, the stress and its tangent, the
  Krogstad stages and weights, the Krylov bases and iterates, the displacement).
* **float64**: every sum over the grid, through :func:`wide_sum` (a float32 input is widened
  inside the reduction, so no float64 field is stored): the observables (a mean of 512^2
  float32 values summed in float32 loses about 5 digits of the mean; the variance
  ``sigma2_S`` is a small difference of such means), the RMS error norm of the step
  controller, the Krylov inner products and norms (GMRES's Gram-Schmidt coefficients and
  its residual estimate, CG's curvature and residual: tolerances of 1e-2 to 1e-8 relative
  are tested against them), and the Newton residual of the force balance (its tolerance,
  ``newton_tol`` = 1e-6, is a few hundred float32 roundings). The scalars those sums give
  are narrowed back (:func:`narrow`) before they scale a field, so no pass is promoted.
* **float64 always**: the time and the step size of each seed (``t`` advances by ``h`` at
  every step: in float32 a time of 300 would move in steps of 3e-5), and the step
  controller's error and factor. The largest pointwise error (``error_norm = "max"``) is
  exact in either precision.
"""

from __future__ import annotations

from typing import Any, TypeAlias

import jax
import jax.numpy as jnp

Array: TypeAlias = jax.Array

#: the real and complex dtypes of each precision
DTYPES: dict[str, tuple[Any, Any]] = {
    "float64": (jnp.float64, jnp.complex128),
    "float32": (jnp.float32, jnp.complex64),
}


def real_dtype(precision: str) -> Any:
    """The real dtype of a precision ("float64" or "float32")."""
    return DTYPES[precision][0]


def complex_dtype(precision: str) -> Any:
    """The complex dtype of a precision."""
    return DTYPES[precision][1]


def wide_sum(x: Array, axis: Any = None) -> Array:
    """``jnp.sum`` accumulated in float64 (complex128 for a complex ``x``), whatever ``x``'s
    precision."""
    wide = jnp.complex128 if jnp.iscomplexobj(x) else jnp.float64
    return jnp.sum(x, axis=axis, dtype=wide)


def wide_mean(x: Array, axis: Any = None) -> Array:
    """``jnp.mean`` accumulated in float64."""
    wide = jnp.complex128 if jnp.iscomplexobj(x) else jnp.float64
    return jnp.mean(x, axis=axis, dtype=wide)


def narrow(scalar: Array, like: Array) -> Array:
    """``scalar`` (a float64 sum, a step size) in the real precision of the array ``like``,
    so that ``scalar * like`` stays in ``like``'s precision."""
    return jnp.asarray(scalar).astype(jnp.finfo(like.dtype).dtype)
