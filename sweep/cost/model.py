"""The calibrated cost of one model run: its CPU seconds from its numerics alone (resolution,
mechanics, t_final, save interval, scheme, tolerance), for :mod:`nematic_solids.sweep.cost.estimate`
when a campaign has no finished runs of its own, and to carry measured run times over to runs of
other numerics.

The model, per mechanics, with ``X = N^2 log2 N / (128^2 * 7)`` (1 at 128^2: a step is a
fixed number of FFTs and pointwise passes over the grid, plus a per-step overhead)::

    CPU seconds = steps * (step0 + step1 X) + saves * (save0 + save1 X) + setup0 + setup1 X

``saves = t_final / save_every + 1``; an adaptive run's ``steps`` is read off the step
curve (the median, over Fig. 2's activities alpha - B = 0.1 ... 1.0 at the model's default
parameters, of the accepted steps by time t; extended beyond its last time with its last
slope), scaled by ``(tolerance / 1e-3) ** (-1 / order)`` (the embedded error estimate's
order: 4 for etdrk4, 2 for etdrk2) and never below ``t_final / dt_max``; a fixed-step run
takes ``t_final / dt`` steps. A time protocol forces steps of its own (one per piece between
its switch times, 16 per period of a sine, 8 per ramp piece:
:meth:`nematic_solids.model.protocol.Protocol.forced_steps`): a run takes the larger of the two
counts (measured at 32^2 over t = 30, alpha - B switched 300 and 1000 times: 309 and 1006 steps
against 301 and 1001 forced, 114 without the switches). Numerics other than the calibrated
ones (etdrk2, the RMS error norm, incompressible linear mechanics, finite strain with
``displacement: equilibrium``) multiply the cost by their measured factor.

The constants are measured on this project's 2-core VM by ``benchmarks/bench_cost.py``
(the fit and every row in ``benchmarks/cost_model.json``; ``tests/sweep/test_estimate.py`` checks
that they are the file's). The activity decides the step count (1 to 4 steps per tau), so a
run's cost is known to within :data:`MODEL_SPREAD` only: the 10 % and 90 % quantiles of
measured / model over the calibration's activity runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from nematic_solids.model.parameters import Numerics
    from nematic_solids.model.protocol import Protocol

#: ``X = N^2 log2 N / REFERENCE`` is 1 at the reference resolution 128^2
REFERENCE = 128**2 * 7
#: the tolerance the step curve was measured at (the model's default)
REFERENCE_TOLERANCE = 1e-3
#: the order of each scheme's embedded error estimate: the step size goes as
#: ``tolerance ** (1 / order)``
ORDER = {"etdrk4": 4, "etdrk2": 2}


@dataclass(frozen=True)
class MechanicsCost:
    """The calibrated constants of one mechanics (seconds; see the module docstring)."""

    step: tuple[float, float]
    save: tuple[float, float]
    setup: tuple[float, float]
    #: (t, accepted steps by t): the median over the calibration's activities
    steps_curve: tuple[tuple[float, float], ...]


#: ``benchmarks/cost_model.json`` (``fit``), measured 2026-12-03 on the 2-core VM
COSTS = {
    "linear": MechanicsCost(
        step=(0.0, 0.00581),
        save=(0.00176, 0.00334),
        setup=(0.0452, 0.0315),
        steps_curve=(
            (0, 0),
            (5, 17),
            (10, 24),
            (20, 34),
            (40, 55),
            (60, 104),
            (100, 186),
            (150, 286),
            (200, 386),
            (250, 445),
            (300, 498),
        ),
    ),
    "finite": MechanicsCost(
        step=(0.00248, 0.019),
        save=(0.000994, 0.0),
        setup=(0.0, 0.0),
        steps_curve=(
            (0, 0),
            (5, 24),
            (10, 31),
            (20, 41),
            (40, 61),
            (60, 98),
            (100, 178),
            (150, 278),
            (200, 347),
            (250, 398),
            (300, 448),
        ),
    ),
}
#: measured factors of the CPU time against the calibrated numerics (``variants`` of the
#: JSON: the same run, alpha - B = 0.5, t = 100, 128^2, with one numerics value changed)
VARIANT_FACTORS = {
    ("linear", "scheme", "etdrk2"): 2.13,
    ("finite", "scheme", "etdrk2"): 2.60,
    ("linear", "error_norm", "rms"): 0.71,
    ("linear", "incompressible", True): 1.31,
    ("finite", "displacement", "equilibrium"): 1.51,
}
#: the 10 % and 90 % quantiles of measured / model over the calibration's activity runs
MODEL_SPREAD = (0.66, 1.99)


def scale(resolution: int) -> float:
    """``X``: the cost of a pass over an N x N grid with its FFTs, 1 at 128^2."""
    return resolution * resolution * math.log2(resolution) / REFERENCE


def curve_steps(curve: tuple[tuple[float, float], ...], t: float) -> float:
    """Accepted steps by time ``t`` on a step curve (linear between its points, its last
    slope beyond them)."""
    for (t0, s0), (t1, s1) in zip(curve, curve[1:], strict=False):
        if t <= t1:
            return s0 + (s1 - s0) * (t - t0) / (t1 - t0)
    (t0, s0), (t1, s1) = curve[-2], curve[-1]
    return s1 + (s1 - s0) / (t1 - t0) * (t - t1)


def model_steps(
    numerics: Numerics, t_final: float | None = None, protocol: Protocol | None = None
) -> float:
    """The steps the model expects of a run (to ``t_final``, default the numerics'), at least
    those its ``protocol`` forces."""
    t = numerics.t_final if t_final is None else t_final
    forced = protocol.forced_steps(t) if protocol else 0.0
    if not numerics.adaptive:
        return max(t / numerics.dt, forced)
    cost = COSTS[numerics.mechanics]
    order = ORDER.get(numerics.scheme, 4)
    steps = curve_steps(cost.steps_curve, t) * (numerics.tolerance / REFERENCE_TOLERANCE) ** (
        -1.0 / order
    )
    return max(steps, t / numerics.dt_max, forced)


def variant_factor(numerics: Numerics) -> float:
    """The product of the measured factors of the numerics that are not the calibrated ones
    (1 for the defaults)."""
    factor = 1.0
    for (mech, name, value), f in VARIANT_FACTORS.items():
        if numerics.mechanics == mech and getattr(numerics, name) == value:
            factor *= f
    return factor


def model_seconds(
    numerics: Numerics, t_final: float | None = None, protocol: Protocol | None = None
) -> float:
    """The model's CPU seconds of one run with ``numerics`` (run to ``t_final``: default the
    numerics' own; an early-stopped run's ``t_stopped``) under ``protocol``."""
    t = numerics.t_final if t_final is None else t_final
    cost = COSTS[numerics.mechanics]
    x = scale(numerics.resolution)
    saves = math.floor(t / numerics.save_every) + 1
    seconds = (
        model_steps(numerics, t, protocol) * (cost.step[0] + cost.step[1] * x)
        + saves * (cost.save[0] + cost.save[1] * x)
        + cost.setup[0]
        + cost.setup[1] * x
    )
    return seconds * variant_factor(numerics)


def kind(numerics: Numerics | Any) -> tuple[tuple[object, ...], int]:
    """What makes runs cost alike besides length: mechanics, scheme and the numerics with a
    factor of their own; and the resolution. Another model's runs are all alike: ``((), 0)``."""
    if not has_cost_model(numerics):
        return (), 0
    alike = (
        numerics.mechanics,
        numerics.scheme,
        numerics.error_norm,
        numerics.adaptive,
        numerics.incompressible if numerics.mechanics == "linear" else None,
        numerics.displacement if numerics.mechanics == "finite" else None,
    )
    return alike, numerics.resolution


#: what a run of a model without a cost model is priced at before any is measured (seconds)
UNMEASURED_SECONDS = 1.0


def has_cost_model(numerics: Any) -> bool:
    """Whether a point's runs are priced by this cost model (the nematic model's)."""
    from nematic_solids.model.parameters import Numerics  # (a light module: no py-pde)

    return isinstance(numerics, Numerics)


def point_seconds(parameters: Any, numerics: Any, t_final: float | None = None) -> float:
    """:func:`model_seconds` of one run at a point of the nematic model (its objects). A
    model without a cost model: :data:`UNMEASURED_SECONDS` a run (times the fraction of its
    ``t_final`` it runs), which its measured runs then scale (sweep.cost.estimate)."""
    if has_cost_model(numerics):
        return model_seconds(numerics, t_final, parameters.protocol)
    full = getattr(numerics, "t_final", None)
    return UNMEASURED_SECONDS * (t_final / full if t_final is not None and full else 1.0)
