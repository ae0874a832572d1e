"""One exception hierarchy for the model (signac-style): every message names the bad value,
what was expected and, where there is one, the fix."""

from __future__ import annotations


class NematicError(Exception):
    """Base class of every error raised on purpose by this project."""


class ParameterError(NematicError, ValueError):
    """A parameter or numerics value is unknown, of the wrong type or out of range."""

    def __init__(self, name: str, value: object, allowed: str):
        self.name, self.value, self.allowed = name, value, allowed
        super().__init__(f"invalid value for '{name}': {value!r} (allowed: {allowed})")


class SimulationFailure(NematicError, RuntimeError):
    """A run ended early for a physical or numerical reason (J <= 0, no convergence, NaN).

    ``reason`` is a short machine-readable tag, ``t`` the simulation time at which it happened.
    """

    def __init__(self, reason: str, detail: str, t: float | None = None):
        self.reason, self.detail, self.t = reason, detail, t
        when = "" if t is None else f" at t = {t:.6g}"
        super().__init__(f"{reason}{when}: {detail}")


class IllPosed(SimulationFailure):
    """The rate problem of an accepted state lost well-posedness (``rate_problem_ill_posed``):
    the failure of the state, not of a step, so a shorter step is not tried."""

    def __init__(self, detail: str, t: float | None = None):
        super().__init__("rate_problem_ill_posed", detail, t)


class DeviceUnavailable(NematicError):
    """The accelerated backend (:mod:`nematic_solids.model.accelerated`) cannot run where it was
    asked to: its library (JAX) is not installed, or the device named (a GPU) is not there. The
    message names what was asked, what is available and the fix."""
