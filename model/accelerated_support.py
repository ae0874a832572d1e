"""What the accelerated backend (:mod:`nematic_solids.model.accelerated`) runs, checked without
importing JAX: a campaign validates its points with it on a machine where JAX may be absent (the
driver of a cluster whose workers have it), and
:func:`nematic_solids.model.accelerated.run.run_batch`
refuses the rest with the same errors."""

from __future__ import annotations

import importlib.util

from .errors import ParameterError
from .parameters import Numerics, Parameters

#: the devices a run may ask for
#: (:func:`nematic_solids.model.accelerated.device.select_device`): the CPU, the first GPU JAX
#: sees, or a GPU if there is one and else the CPU
DEVICES = ("cpu", "gpu", "auto")
#: how to install the backend's library
INSTALL = "pip install -e '.[accel]' (and 'jax[cuda12]' for an NVIDIA GPU)"


def jax_installed() -> bool:
    """Whether JAX can be imported here (found, not imported)."""
    return importlib.util.find_spec("jax") is not None


#: the smallest force-balance tolerance a float32 finite-strain run accepts: its Newton solve
#: stalls near a residual of 9e-7 (benchmarks/float32_newton_floor.json, docs/guide/precision.md)
FLOAT32_NEWTON_TOL = 1e-6


def check_precision(numerics: Numerics) -> None:
    """Refuse with :class:`nematic_solids.model.errors.ParameterError` what float32 cannot do:
    finite strain's ``newton_tol`` below :data:`FLOAT32_NEWTON_TOL`."""
    if (
        numerics.precision == "float32"
        and numerics.mechanics == "finite"
        and numerics.newton_tol < FLOAT32_NEWTON_TOL
    ):
        raise ParameterError(
            "newton_tol",
            numerics.newton_tol,
            f"at least {FLOAT32_NEWTON_TOL:g} with precision float32 (its Newton solve stalls "
            "near a residual of 9e-7, measured: docs/guide/precision.md)",
        )


def check_supported(params: Parameters, numerics: Numerics) -> None:
    """Refuse with :class:`nematic_solids.model.errors.ParameterError` what the accelerated path
    does not do yet: ETDRK2, finite strain with its displacement solved at every stage
    (``displacement: equilibrium``), time protocols, the early stop."""
    if numerics.mechanics == "finite" and numerics.displacement != "integrated":
        raise ParameterError(
            "displacement", numerics.displacement, "integrated in the accelerated backend"
        )
    if numerics.scheme != "etdrk4":
        raise ParameterError("scheme", numerics.scheme, "etdrk4 in the accelerated backend")
    if params.protocol:
        raise ParameterError(
            "protocol", params.protocol.to_dict(), "none in the accelerated backend"
        )
    if numerics.steady_tol > 0:
        raise ParameterError("steady_tol", numerics.steady_tol, "0 in the accelerated backend")
    check_precision(numerics)
