r"""Time protocols: parameters of Eqs. (2)-(5) that are functions of time.

A :class:`Protocol` makes some of :data:`PROTOCOL_PARAMETERS` (the contractility
:math:`\alpha - B` of Eq. 2, the stress-activity coupling :math:`\chi` of Eq. 5 and the
applied pure shear :math:`\epsilon` of :math:`\bar F`) functions of time; every other constant
stays fixed. A function of time is one of two primitive forms:

* :class:`Piecewise`: through points ``(t_i, v_i)`` with ``t_0 = 0``, either as **steps**
  (piecewise constant, :math:`v(t) = v_i` on :math:`[t_i, t_{i+1})`) or as a **ramp**
  (piecewise linear between the points); the last value holds after the last point.
* :class:`Sine`: :math:`v(t) = m + a \sin(2\pi (t - t_s)/T)` from the start :math:`t_s` on,
  :math:`m` before it (the oscillatory shear of a rheometer).

The input forms of :func:`profile_from` add named shapes whose numbers can be swept:
``pulse`` (``base``, switched to ``level`` at ``start`` for ``duration``) and the named ramp
(``from``, ``to``, ``start``, ``duration``); they are turned into the primitive forms, so one
function has one canonical :meth:`Protocol.to_dict` (and one run identity).

**Switch times.** The times where a function or its derivative jumps (:meth:`Protocol.breaks`)
are landed on exactly by the integrator (:mod:`nematic_solids.model.solver_base`); no step crosses
one. Inside a step from :math:`t_0` every stage uses the piece that holds :math:`t_0`
(:meth:`Protocol.values` with ``after = t_0``): a stage at the end of a step that ends on a switch
time sees the value before the switch. Anywhere else the value is right-continuous: a save at a
switch time (its observables and its force balance) sees the value after it.

**Resolved structure.** No step steps over a function's structure: besides landing on the
switch times, a step is at most :data:`SINE_STEP_FRACTION` of a sine's period (16 steps per
period) and :data:`RAMP_STEP_FRACTION` of a ramp piece's duration (:meth:`Protocol.max_step`).
Every value and every rate of a function is finite at every time, and every step a ramp piece
allows moves the time on (checked when it is read), and
:meth:`Protocol.forced_steps` counts the steps these rules force on a run (the cost estimate's).
The floor on a sine's period relative to the model's own time scales is
:func:`nematic_solids.model.parameters.check_compatible`'s.

A constant function is no protocol (:func:`profile_from` returns its value), so a constant
protocol is the same run as the plain parameter.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from .errors import ParameterError

#: the parameters a protocol may make time dependent
PROTOCOL_PARAMETERS = ("alpha_minus_B", "chi", "eps")
#: the forms of one parameter's function of time (input keys)
FORMS = ("steps", "ramp", "pulse", "sine")
#: most points of one steps or ramp function
MAX_POINTS = 10_000
#: the largest step inside a sine as a fraction of its period, T/16 (measured, the response of
#: a sine at T/8 differs from the T/64 one by 1e-4 of its amplitude, at T/16 by 1e-6;
#: tests/model/test_protocol_resolution.py)
SINE_STEP_FRACTION = 1.0 / 16.0
#: the largest step inside a ramp piece, as a fraction of its duration (a ramp is integrated
#: by the stages exactly in time; the bound keeps the saved response resolved along it)
RAMP_STEP_FRACTION = 1.0 / 8.0
PULSE_KEYS = ("base", "level", "start", "duration")
RAMP_KEYS = ("from", "to", "start", "duration")
SINE_KEYS = ("mean", "amplitude", "period", "start")


def _number(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(name, value, "a real number")
    x = float(value)
    if not math.isfinite(x):
        raise ParameterError(name, value, "a finite real number")
    return x


@dataclass(frozen=True)
class Piecewise:
    """Steps (``linear = False``) or a ramp (``linear = True``) through ``points``."""

    points: tuple[tuple[float, float], ...]
    linear: bool

    def _piece(self, after: float) -> int:
        return max(bisect.bisect_right(self.times, after) - 1, 0)

    @property
    def times(self) -> list[float]:
        return [t for t, _ in self.points]

    def value(self, t: float, after: float) -> float:
        """The value at ``t`` on the piece that holds ``after``."""
        i = self._piece(after)
        t0, v0 = self.points[i]
        if not self.linear or i + 1 == len(self.points):
            return v0
        t1, v1 = self.points[i + 1]
        return v0 + (v1 - v0) * ((t - t0) / (t1 - t0))

    def rate(self, t: float, after: float) -> float:
        """The time derivative on the piece that holds ``after``."""
        i = self._piece(after)
        if not self.linear or i + 1 == len(self.points):
            return 0.0
        (t0, v0), (t1, v1) = self.points[i], self.points[i + 1]
        return (v1 - v0) / (t1 - t0)

    def breaks(self) -> tuple[float, ...]:
        return tuple(t for t, _ in self.points[1:])

    def max_step(self, after: float) -> float:
        """The largest step from ``after``: a fraction of the ramp piece that holds it."""
        i = self._piece(after)
        if not self.linear or i + 1 == len(self.points):
            return math.inf
        return (self.points[i + 1][0] - self.points[i][0]) * RAMP_STEP_FRACTION

    def rate_bound(self) -> float:
        """The largest ``|rate|`` anywhere on the time axis."""
        if not self.linear:
            return 0.0
        pairs = zip(self.points, self.points[1:], strict=False)
        return max((abs((v1 - v0) / (t1 - t0)) for (t0, v0), (t1, v1) in pairs), default=0.0)

    def extremes(self) -> tuple[float, float]:
        values = [v for _, v in self.points]
        return min(values), max(values)

    def constant(self) -> bool:
        return len({v for _, v in self.points}) == 1

    def to_dict(self) -> dict[str, Any]:
        return {"ramp" if self.linear else "steps": [[t, v] for t, v in self.points]}


@dataclass(frozen=True)
class Sine:
    """:math:`m + a \\sin(2\\pi (t - t_s)/T)` for :math:`t \\ge t_s`, ``mean`` before."""

    mean: float
    amplitude: float
    period: float
    start: float = 0.0

    def value(self, t: float, after: float) -> float:
        if after < self.start:
            return self.mean
        return self.mean + self.amplitude * math.sin(2.0 * math.pi * (t - self.start) / self.period)

    def rate(self, t: float, after: float) -> float:
        if after < self.start:
            return 0.0
        w = 2.0 * math.pi / self.period
        return self.amplitude * w * math.cos(w * (t - self.start))

    def breaks(self) -> tuple[float, ...]:
        return (self.start,) if self.start > 0 else ()

    def max_step(self, after: float) -> float:
        """The largest step from ``after``: a fraction of the period once the sine runs."""
        return math.inf if after < self.start else self.period * SINE_STEP_FRACTION

    def rate_bound(self) -> float:
        """The largest ``|rate|``, a 2 pi / T."""
        return abs(self.amplitude) * (2.0 * math.pi / self.period)

    def extremes(self) -> tuple[float, float]:
        a = abs(self.amplitude)
        return self.mean - a, self.mean + a

    def constant(self) -> bool:
        return self.amplitude == 0.0

    def to_dict(self) -> dict[str, Any]:
        return {
            "sine": {
                "mean": self.mean,
                "amplitude": self.amplitude,
                "period": self.period,
                "start": self.start,
            }
        }


Profile = Piecewise | Sine


def _points(name: str, raw: Any) -> tuple[tuple[float, float], ...]:
    usage = "a list of [time, value] pairs, the first at time 0, times increasing"
    if isinstance(raw, (str, bytes)) or not isinstance(raw, Sequence) or not raw:
        raise ParameterError(name, raw, usage)
    if len(raw) > MAX_POINTS:
        raise ParameterError(name, f"{len(raw)} points", f"at most {MAX_POINTS} points")
    points = []
    for i, pair in enumerate(raw):
        if isinstance(pair, (str, bytes)) or not isinstance(pair, Sequence) or len(pair) != 2:
            raise ParameterError(f"{name}[{i}]", pair, "a [time, value] pair")
        t, v = _number(f"{name}[{i}] time", pair[0]), _number(f"{name}[{i}] value", pair[1])
        points.append((t, v))
    if points[0][0] != 0.0:
        raise ParameterError(f"{name}[0] time", points[0][0], "0 (the function starts at t = 0)")
    for i in range(1, len(points)):
        if not points[i][0] > points[i - 1][0]:
            raise ParameterError(
                f"{name}[{i}] time", points[i][0], f"a time > {points[i - 1][0]:g} (increasing)"
            )
    return tuple(points)


def _named(name: str, raw: Any, keys: tuple[str, ...], required: tuple[str, ...]) -> dict:
    if not isinstance(raw, Mapping):
        raise ParameterError(name, raw, "a mapping with " + ", ".join(keys))
    unknown = [k for k in raw if k not in keys]
    if unknown:
        raise ParameterError(f"{name}.{unknown[0]}", raw[unknown[0]], "one of " + ", ".join(keys))
    missing = [k for k in required if k not in raw]
    if missing:
        raise ParameterError(
            name, dict(raw), f"all of {', '.join(required)} (missing: {', '.join(missing)})"
        )
    return {k: _number(f"{name}.{k}", v) for k, v in raw.items()}


def _window(name: str, start: float, duration: float) -> float:
    """The end of a window that begins at ``start`` and lasts ``duration``: a finite time
    after its start (a duration below the rounding of the start would end at the start, and
    ``1e308 + 1e308`` overflows: the switch times written down must increase)."""
    if start < 0:
        raise ParameterError(f"{name}.start", start, "a time >= 0")
    if duration <= 0:
        raise ParameterError(f"{name}.duration", duration, "a duration > 0")
    end = start + duration
    if not (math.isfinite(end) and end > start):
        raise ParameterError(
            f"{name}.duration",
            duration,
            f"a duration that ends after its start ({start:g}) at a finite time "
            f"(start + duration is {end:g})",
        )
    return end


def profile_from(name: str, raw: Any) -> Profile | float:
    """The function of time of the input ``raw`` (see the module docstring): a list of
    points (steps) or a mapping with one of :data:`FORMS`; a constant function is returned as
    its value. ``name`` labels errors (:class:`nematic_solids.model.errors.ParameterError`)."""
    if isinstance(raw, (Piecewise, Sine)):
        return raw.extremes()[0] if raw.constant() else raw
    if not isinstance(raw, Mapping):
        raw = {"steps": raw}
    if len(raw) != 1 or next(iter(raw)) not in FORMS:
        raise ParameterError(name, dict(raw), "exactly one of " + ", ".join(FORMS))
    form, spec = next(iter(raw.items()))
    where = f"{name}.{form}"
    profile: Profile
    if form in ("steps", "ramp") and not isinstance(spec, Mapping):
        profile = Piecewise(_points(where, spec), linear=form == "ramp")
    elif form == "ramp":
        r = _named(where, spec, RAMP_KEYS, RAMP_KEYS)
        end = _window(where, r["start"], r["duration"])
        head = [(0.0, r["from"])] if r["start"] > 0 else []
        profile = Piecewise((*head, (r["start"], r["from"]), (end, r["to"])), linear=True)
    elif form == "pulse":
        r = _named(where, spec, PULSE_KEYS, PULSE_KEYS)
        end = _window(where, r["start"], r["duration"])
        head = [(0.0, r["base"])] if r["start"] > 0 else []
        profile = Piecewise((*head, (r["start"], r["level"]), (end, r["base"])), linear=False)
    elif form == "sine":
        r = _named(where, spec, SINE_KEYS, ("amplitude", "period"))
        if r.get("period", 0.0) <= 0:
            raise ParameterError(f"{where}.period", r.get("period"), "a period > 0")
        if r.get("start", 0.0) < 0:
            raise ParameterError(f"{where}.start", r.get("start"), "a time >= 0")
        profile = Sine(r.get("mean", 0.0), r["amplitude"], r["period"], r.get("start", 0.0))
    else:
        raise ParameterError(where, spec, "a list of [time, value] pairs")
    _check_finite(where, profile)
    _check_resolvable(where, profile)
    return profile.extremes()[0] if profile.constant() else profile


def _check_finite(name: str, profile: Profile) -> None:
    """Every value and rate the function takes, at any time, is finite: its extremes, its
    largest rate and (a ramp) every difference of neighbouring values (which the
    interpolation forms)."""
    # float arithmetic overflows to inf (no exception): the inf is what is checked
    lo, hi = profile.extremes()
    rate, spread = profile.rate_bound(), hi - lo
    for what, x in (("lowest value", lo), ("highest value", hi), ("range of values", spread)):
        if not math.isfinite(x):
            raise ParameterError(name, f"{what} {x}", "finite values at every time")
    if not math.isfinite(rate):
        raise ParameterError(name, f"largest rate {rate}", "a finite rate at every time")


def _check_resolvable(name: str, profile: Profile) -> None:
    """Every step a ramp piece allows (:data:`RAMP_STEP_FRACTION` of it) moves the time on: a
    piece shorter than that many spacings of the floating-point times at its end (a ramp from
    t = 0.1 lasting 2e-17) would hold the integrator at one time forever."""
    if not (isinstance(profile, Piecewise) and profile.linear):
        return
    for (t0, _), (t1, _) in zip(profile.points, profile.points[1:], strict=False):
        if (t1 - t0) * RAMP_STEP_FRACTION < math.ulp(t1):
            raise ParameterError(
                name,
                f"a piece from t = {t0!r} to t = {t1!r}",
                f"ramp pieces at least {1 / RAMP_STEP_FRACTION:g} times the spacing of "
                f"floating-point times at their end ({math.ulp(t1):.3g} there) long",
            )


@dataclass(frozen=True)
class Protocol:
    """The time-dependent parameters of a run: ``profiles``, sorted (name, function) pairs
    (no constant function: see :func:`profile_from`). Empty: every parameter constant."""

    profiles: tuple[tuple[str, Profile], ...] = ()
    _breaks: tuple[float, ...] = field(default=(), init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "profiles", tuple(sorted(self.profiles, key=lambda p: p[0])))
        for name, _ in self.profiles:
            if name not in PROTOCOL_PARAMETERS:
                raise ParameterError(
                    f"protocol.{name}",
                    "a function of time",
                    "one of " + ", ".join(PROTOCOL_PARAMETERS),
                )
        breaks = sorted({b for _, p in self.profiles for b in p.breaks()})
        object.__setattr__(self, "_breaks", tuple(breaks))

    def __bool__(self) -> bool:
        return bool(self.profiles)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.profiles)

    def varies(self, name: str) -> bool:
        return name in self.names

    def values(self, t: float, after: float | None = None) -> dict[str, float]:
        """The parameters' values at ``t`` on the pieces that hold ``after`` (default ``t``:
        right-continuous)."""
        a = t if after is None else after
        return {name: p.value(t, a) for name, p in self.profiles}

    def rates(self, t: float, after: float | None = None) -> dict[str, float]:
        """Their time derivatives at ``t`` (on the pieces that hold ``after``)."""
        a = t if after is None else after
        return {name: p.rate(t, a) for name, p in self.profiles}

    def breaks(self) -> tuple[float, ...]:
        """The switch times (a value or a derivative jumps), increasing."""
        return self._breaks

    def next_break(self, t: float) -> float:
        """The first switch time after ``t`` (beyond rounding), or infinity."""
        i = bisect.bisect_right(self._breaks, t + 1e-12 * max(1.0, abs(t)))
        return self._breaks[i] if i < len(self._breaks) else math.inf

    def extremes(self, name: str) -> tuple[float, float]:
        return dict(self.profiles)[name].extremes()

    def max_step(self, after: float) -> float:
        """The largest step from ``after`` that resolves every function's structure
        (:data:`SINE_STEP_FRACTION`, :data:`RAMP_STEP_FRACTION`); infinity where none bounds
        it. Constant between switch times, on which steps land."""
        return min((p.max_step(after) for _, p in self.profiles), default=math.inf)

    def forced_steps(self, t_final: float) -> float:
        """The fewest steps a run to ``t_final`` takes for the protocol alone: one per piece
        between switch times, and within a piece its length over :meth:`max_step`."""
        edges = [0.0, *(b for b in self._breaks if 0.0 < b < t_final), t_final]
        steps = 0.0
        for a, b in zip(edges, edges[1:], strict=False):
            bound = self.max_step(a)
            steps += 1.0 if math.isinf(bound) else max(math.ceil((b - a) / bound - 1e-9), 1)
        return steps

    def shortest_period(self) -> float:
        """The shortest period of a sine of the protocol (infinity without one)."""
        return min((p.period for _, p in self.profiles if isinstance(p, Sine)), default=math.inf)

    def to_dict(self) -> dict[str, Any]:
        """The canonical form: {name: {"steps" | "ramp": [[t, v], ...]} or {"sine": {...}}}."""
        return {name: p.to_dict() for name, p in self.profiles}


def protocol_from(raw: Any) -> tuple[Protocol, dict[str, float]]:
    """``(protocol, constants)`` from a mapping {parameter: function of time} (or a
    :class:`Protocol`): the functions that are constant come back as plain values."""
    if isinstance(raw, Protocol):
        return raw, {}
    if raw is None:
        return Protocol(), {}
    if not isinstance(raw, Mapping):
        raise ParameterError("protocol", raw, "a mapping {parameter: function of time}")
    profiles, constants = [], {}
    for name, spec in raw.items():
        if name not in PROTOCOL_PARAMETERS:
            raise ParameterError(
                f"protocol.{name}", spec, "one of " + ", ".join(PROTOCOL_PARAMETERS)
            )
        p = profile_from(f"protocol.{name}", spec)
        if isinstance(p, float):
            constants[name] = p
        else:
            profiles.append((name, p))
    return Protocol(tuple(profiles)), constants
