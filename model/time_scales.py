"""A time protocol's time scales against the model's own and against the work they force (the
time-scale rule of a campaign's ``protocol:``).

* A sine's period is at least :data:`PERIOD_FLOOR` times the model's fastest relaxation time
  (:func:`relaxation_time`: the shorter of Q's gamma / |A0| and A's tau / zeta).
* The steps the protocol forces on a run
  (:meth:`nematic_solids.model.protocol.Protocol.forced_steps`: 16 per period of a sine, 8 per
  ramp piece, one per switch) are at most :data:`nematic_solids.model.parameters.MAX_STEPS`.

Both are checked by :func:`nematic_solids.model.parameters.check_compatible`, so a campaign's
validation reports them at the key path (file:line) of the number that breaks them.
"""

from __future__ import annotations

import math

from .errors import ParameterError
from .parameters import MAX_STEPS, Numerics, Parameters
from .protocol import Protocol

#: the shortest period a sine of a protocol may have, as a fraction of the model's fastest
#: relaxation time (:func:`relaxation_time`): below it the state answers a sine of amplitude a
#: by at most a T / (2 pi t_r) < 0.2 % of a, i.e. the run computes the time average at the cost
#: of 16 steps per period (docs: "Time protocols", the time-scale rule)
PERIOD_FLOOR = 0.01


def relaxation_time(params: Parameters) -> float:
    """The model's fastest relaxation time: the shorter of the linear relaxation times at
    k = 0 of Q (Eq. 4: gamma / |A0|) and of the activity A (Eq. 5: tau / zeta); infinity
    when both rates are 0."""
    times = [params.gamma / abs(params.A0)] if params.A0 != 0 else []
    if params.zeta > 0:
        times.append(params.tau / params.zeta)
    return min(times, default=math.inf)


def check_time_scales(params: Parameters, numerics: Numerics) -> None:
    """A protocol's time scales against the model's and the work they force: every sine's
    period at least :data:`PERIOD_FLOOR` times :func:`relaxation_time`, and the steps the
    protocol forces (:meth:`nematic_solids.model.protocol.Protocol.forced_steps`) at most
    :data:`~nematic_solids.model.parameters.MAX_STEPS`."""
    protocol = params.protocol
    floor = PERIOD_FLOOR * relaxation_time(params)
    for name, profile in protocol.profiles:
        period = getattr(profile, "period", None)
        if period is not None and period < floor:
            raise ParameterError(
                f"protocol.{name}.sine.period",
                period,
                f"a period >= {floor:.3g} ({PERIOD_FLOOR:g} of the model's fastest relaxation "
                f"time {relaxation_time(params):.3g} = min(gamma / |A0|, tau / zeta); a faster "
                "sine is averaged out by the model)",
            )
    steps = protocol.forced_steps(numerics.t_final)
    if steps > MAX_STEPS:
        worst = max(
            protocol.names,
            key=lambda n: Protocol(((n, dict(protocol.profiles)[n]),)).forced_steps(
                numerics.t_final
            ),
        )
        raise ParameterError(
            f"protocol.{worst}",
            f"{steps:.3g} steps forced to t_final = {numerics.t_final:g}",
            f"at most {MAX_STEPS:.0e} steps (16 per period of a sine, 8 per ramp piece, one "
            "per switch)",
        )
