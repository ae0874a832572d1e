"""The ``sweep:`` section: axes (lists or linspace / logspace / geomspace ranges, values
normalised to the declared type of the parameter or numerics field) and zip groups -> the
grid's :class:`~nematic_solids.sweep.campaign.Dim` tuple."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..campaign import AMB, DEFAULT_MODEL, Axis, Dim
from ..errors import Problem
from ..protocols import PROTOCOL, protocol_axes
from ..settings import setting_names
from .checker import Checker, KeyPath, coerce, is_int, is_number, suggest

SWEEP_KEYS = ("axes", "zip")
RANGE_KINDS = ("linspace", "logspace", "geomspace")
RANGE_KEYS = ("start", "stop", "num")


def _range_values(c: Checker, kind: str, spec: Any, path: KeyPath) -> list[Any] | None:
    usage = "[start, stop, num] or {start: .., stop: .., num: ..}" + (
        " (exponents of 10)" if kind == "logspace" else ""
    )
    if isinstance(spec, Sequence) and not isinstance(spec, str):
        if len(spec) != 3:
            c.bad(path, spec, usage)
            return None
        start, stop, num = spec
    elif isinstance(spec, Mapping):
        keys = c.mapping(path, spec, RANGE_KEYS)
        missing = [k for k in RANGE_KEYS if k not in spec]
        if missing:
            c.add(path, f"missing {', '.join(missing)}; allowed: {usage}")
            return None
        if len(keys) != len(spec):
            return None
        start, stop, num = spec["start"], spec["stop"], spec["num"]
    else:
        c.bad(path, spec, usage)
        return None
    ok = True
    for label, v in (("start", start), ("stop", stop)):
        if not is_number(v) or not math.isfinite(float(v)):
            c.bad((*path, label), v, "a finite number")
            ok = False
    if not is_int(num) or num < 1:
        c.bad((*path, "num"), num, "an integer >= 1 (the number of values)")
        ok = False
    elif num > c.max_runs:
        c.bad((*path, "num"), num, f"at most {c.max_runs} values (limits.max_runs)")
        ok = False
    if ok and kind == "logspace" and max(abs(float(start)), abs(float(stop))) > 300:
        c.bad(path, [start, stop], "exponents from -300 to 300 (the values are 10**start ...)")
        ok = False
    if ok and kind == "linspace" and not math.isfinite(float(stop) - float(start)):
        c.bad(path, [start, stop], "end points whose difference is a finite number")
        ok = False
    if not ok:
        return None
    if kind == "linspace":
        return list(np.linspace(float(start), float(stop), int(num)))
    if kind == "logspace":
        return list(np.logspace(float(start), float(stop), int(num)))
    if float(start) == 0 or float(stop) == 0 or (float(start) > 0) != (float(stop) > 0):
        c.bad(path, [start, stop], "geomspace end points that are non-zero and of one sign")
        return None
    return list(np.geomspace(float(start), float(stop), int(num)))


def _check_axis(
    c: Checker, name: str, raw: Any, path: KeyPath, types: Mapping[str, str]
) -> Axis | None:
    if isinstance(raw, Mapping):
        if len(raw) != 1 or next(iter(raw)) not in RANGE_KINDS:
            keys = list(raw)
            bad = next((k for k in keys if k not in RANGE_KINDS), keys[0] if keys else None)
            if bad is not None and bad not in RANGE_KINDS:
                c.unknown((*path, str(bad)), bad, RANGE_KINDS)
            else:
                c.bad(path, raw, "exactly one of " + ", ".join(RANGE_KINDS))
            return None
        kind = next(iter(raw))
        values = _range_values(c, kind, raw[kind], (*path, kind))
        if values is None:
            return None
        vpaths = [(*path, kind)] * len(values)
    elif isinstance(raw, Sequence) and not isinstance(raw, str):
        values = list(raw)
        vpaths = [(*path, i) for i in range(len(values))]
    else:
        c.bad(
            path,
            raw,
            "a list of values or {linspace|logspace|geomspace: [start, stop, num]} "
            "(a single value belongs under 'parameters:' or 'numerics:')",
        )
        return None
    if not values:
        c.bad(path, raw, "a non-empty list of values (an empty axis would give no runs)")
        return None
    kind_t = types.get(name, "float")  # a protocol's number (nematic_solids.sweep.protocols)
    out: list[Any] = []
    ok = True
    for v, vpath in zip(values, vpaths, strict=True):
        try:
            out.append(coerce(kind_t, v))
        except ValueError as e:
            c.bad(vpath, v, str(e))
            ok = False
    if not ok:
        return None
    seen: set[Any] = set()
    dups = [v for v in out if v in seen or seen.add(v)]  # type: ignore[func-returns-value]
    if dups:
        c.bad(path, dups[0], "distinct values (this one appears twice)")
        return None
    return Axis(name, tuple(out))


def read_sweep(c: Checker, raw: Any, read: Mapping[str, Any]) -> tuple[Dim, ...]:
    """``sweep:`` -> the grid's dims; ``read`` holds the base ``parameters`` and ``numerics``
    (a name may be swept or set, not both)."""
    base = {
        **{k: "parameters" for k in read["parameters"]},
        **{k: "numerics" for k in read["numerics"]},
    }
    sweep = c.mapping(("sweep",), raw, SWEEP_KEYS)
    axes_raw = c.mapping(("sweep", "axes"), sweep.get("axes"), None)
    axes: dict[str, Axis] = {}
    known = setting_names(read.get("model") or DEFAULT_MODEL)
    types = known.axes
    timed = read["protocol"].get(PROTOCOL, {})
    offered = protocol_axes(read["protocol"])
    for name, spec in axes_raw.items():
        path = ("sweep", "axes", name)
        if name not in types and name not in offered:
            c.unknown(
                path,
                name,
                sorted(types) + sorted(offered),
                "" if name not in known.numerics else f" ({name} cannot be swept)",
            )
            continue
        if name in timed or (name == "alpha" and AMB in timed):
            c.add(
                path,
                f"{name!r} is a function of time (protocol.{name if name in timed else AMB}); "
                "sweep the numbers of its function instead (e.g. "
                f"{AMB}_level of a pulse) or drop it from 'protocol:'",
            )
            continue
        if name in base:
            origin = c.origins.get((base[name], name))
            if origin is not None:  # a command-line --set
                c.problems.append(
                    Problem(
                        name,
                        f"{name!r} is a swept axis of this campaign (sweep.axes.{name}); "
                        "--set changes only base values: drop it from the command line, or "
                        "give the campaign a file of its own",
                        f"command line {origin}",
                    )
                )
            else:
                c.add(
                    path,
                    f"{name!r} is both swept and set in "
                    f"'{base[name]}:'; remove it from one of them",
                )
            continue
        axis = _check_axis(c, name, spec, path, types)
        if axis is not None:
            axes[name] = axis
    if AMB in axes_raw and "alpha" in axes_raw:
        c.add(("sweep", "axes", AMB), "sweep either 'alpha' or 'alpha_minus_B', not both")
    for a, b in ((AMB, "alpha"), ("alpha", AMB)):
        if a in axes_raw and base.get(b) == "parameters":
            c.add(
                ("sweep", "axes", a),
                f"conflicts with parameters.{b} (alpha = B + alpha_minus_B): set only one of them",
            )

    groups: list[list[str]] = []
    zip_raw = sweep.get("zip")
    if zip_raw is not None:
        if not isinstance(zip_raw, Sequence) or isinstance(zip_raw, str):
            c.bad(("sweep", "zip"), zip_raw, "a list of groups, each a list of axis names")
            zip_raw = []
        grouped: dict[str, int] = {}
        for gi, group in enumerate(zip_raw):
            gpath: KeyPath = ("sweep", "zip", gi)
            if (
                not isinstance(group, Sequence)
                or isinstance(group, str)
                or len(group) < 2
                or not all(isinstance(n, str) for n in group)
            ):
                c.bad(gpath, group, "a list of two or more axis names")
                continue
            names: list[str] = []
            for ni, n in enumerate(group):
                if n not in axes_raw:
                    c.bad(
                        (*gpath, ni),
                        n,
                        "the name of an axis under sweep.axes"
                        + suggest(n, list(axes_raw))
                        + f" (axes: {', '.join(axes_raw)})",
                    )
                elif n in grouped:
                    c.bad(
                        (*gpath, ni),
                        n,
                        "each axis in at most one zip group (it is already "
                        f"in sweep.zip[{grouped[n]}])",
                    )
                else:
                    grouped[n] = gi
                    names.append(n)
            if len(names) == len(group):
                lengths = {n: len(axes[n].values) for n in names if n in axes}
                if len(lengths) == len(names) and len(set(lengths.values())) > 1:
                    desc = ", ".join(f"{n} has {k}" for n, k in lengths.items())
                    c.bad(gpath, group, f"axes of equal length in a zip group ({desc} values)")
                groups.append(names)

    dims: list[Dim] = []
    placed: set[str] = set()
    for name in axes_raw:
        if name in placed or name not in axes:
            continue
        group = next((g for g in groups if name in g), None)
        if group is None:
            dims.append(Dim(name, (axes[name],)))
            placed.add(name)
        elif all(n in axes for n in group):
            dims.append(Dim(group[0], tuple(axes[n] for n in group)))
            placed.update(group)
    return tuple(dims)
