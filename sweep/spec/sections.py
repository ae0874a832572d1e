"""Readers of the campaign's top-level sections (but ``sweep:`` and ``execution:``, which have
modules of their own): each takes the :class:`~nematic_solids.sweep.spec.checker.Checker`, the
section's raw value and the sections read before it, reports every problem and returns what the
:class:`~nematic_solids.sweep.campaign.Campaign` keeps. Also the check of the fits' and figures'
options against their registries and the campaign's axes."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from typing import Any

from ..campaign import (
    AMB,
    DEFAULT_CHECKPOINT_WALL,
    DEFAULT_MODEL,
    DEFAULT_SEEDS,
    MAX_SEED,
    Campaign,
    LimitsSpec,
    Product,
    StoreSpec,
)
from ..limits import DEFAULT_MAX_RUNS, parse_size
from ..settings import setting_names
from .checker import Checker, KeyPath, is_int, suggest

LIMITS_KEYS = ("max_runs", "run_memory")
STORE_KEYS = (
    "snapshot_times",
    "snapshot_fields",
    "snapshot_dtype",
    "checkpoint_every",
    "end_state",
)
#: ``store.checkpoint_every`` as wall time: a number and a unit
WALL_RE = re.compile(
    r"^\s*([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*(s|sec|seconds?|min|minutes?|h|hours?)\s*$"
)
WALL_UNITS = {"s": 1.0, "m": 60.0, "h": 3600.0}
#: Snapshot variables of a run file (nematic_solids.model.simulate.run contract).
SNAPSHOT_FIELDS = ("q1", "q2", "A", "u1", "u2", "I1bar")
SNAPSHOT_DTYPES = ("float64", "float32")
NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$")


def read_limits(c: Checker, raw: Any, read: Mapping[str, Any]) -> LimitsSpec:
    """``limits:``; read first, as the checker's ``max_runs`` bounds the sections after it."""
    lim = c.mapping(("limits",), raw, LIMITS_KEYS)
    max_runs = lim.get("max_runs", DEFAULT_MAX_RUNS)
    if not is_int(max_runs) or max_runs < 1:
        c.bad(
            ("limits", "max_runs"), max_runs, "an integer >= 1 (the most runs a campaign may have)"
        )
        max_runs = DEFAULT_MAX_RUNS
    memory = None
    if lim.get("run_memory") is not None:
        memory = parse_size(lim["run_memory"])
        if memory is None:
            c.bad(
                ("limits", "run_memory"),
                lim["run_memory"],
                "a size such as '8GB' (the most memory one run may need)",
            )
    c.max_runs = int(max_runs)
    return LimitsSpec(max_runs=int(max_runs), run_memory=memory)


def read_name(c: Checker, raw: Any, read: Mapping[str, Any]) -> str:
    """``name:`` (default: the file's stem); the results go to ``results/<name>/``."""
    path: KeyPath = ("name",)
    allowed = (
        "letters, digits, '.', '_' or '-', starting with a letter or digit, at most 100 "
        "characters (the results go to results/<name>/)"
    )
    if raw is None:
        c.add(path, f"missing; allowed: {allowed}")
        return "invalid"
    if not isinstance(raw, str) or not NAME_RE.match(raw) or ".." in raw:
        c.bad(path, raw, allowed)
        return "invalid"
    return raw


def read_description(c: Checker, raw: Any, read: Mapping[str, Any]) -> str:
    """``description:``, free text."""
    description = raw or ""
    if not isinstance(description, str):
        c.bad(("description",), description, "a string")
        description = ""
    return description


def read_parameters(c: Checker, raw: Any, read: Mapping[str, Any]) -> dict[str, Any]:
    """``parameters:``: base values of model parameters (checked at every grid point by the
    model, :func:`nematic_solids.sweep.expand.check_points`)."""
    names = setting_names(read.get("model") or DEFAULT_MODEL)
    return _check_settings(c, raw, "parameters", names.parameters, names.numerics, "numerics")


def read_numerics(c: Checker, raw: Any, read: Mapping[str, Any]) -> dict[str, Any]:
    """``numerics:``: base values of numerics fields. With both base sections read, also
    refuses ``parameters:`` that set both ``alpha`` and ``alpha_minus_B``."""
    names = setting_names(read.get("model") or DEFAULT_MODEL)
    numerics = _check_settings(c, raw, "numerics", names.numerics, names.parameters, "parameters")
    if AMB in read["parameters"] and "alpha" in read["parameters"]:
        c.add(("parameters", AMB), "set either 'alpha' or 'alpha_minus_B', not both")
    return numerics


def _check_settings(
    c: Checker,
    raw: Any,
    section: str,
    types: Mapping[str, str],
    other: Mapping[str, str],
    other_section: str,
) -> dict[str, Any]:
    if raw is None:
        return {}
    if not isinstance(raw, Mapping):
        c.bad((section,), raw, "a mapping of NAME: VALUE")
        return {}
    out: dict[str, Any] = {}
    for key, value in raw.items():
        path = (section, str(key))
        if key in types:
            out[key] = value
        elif key in other:
            c.add(
                path,
                f"{key!r} is a {other_section} setting, not a {section} one; move it "
                f"under '{other_section}:'",
            )
        else:
            c.unknown(path, key, sorted(types))
    return out


def read_store(c: Checker, raw: Any, read: Mapping[str, Any]) -> StoreSpec:
    """``store:``; its ``snapshot_times`` joins the base ``numerics`` read before it."""
    numerics = read["numerics"]
    store = c.mapping(("store",), raw, STORE_KEYS)
    if "snapshot_times" in store:
        if "snapshot_times" in numerics:
            c.add(("store", "snapshot_times"), "set in both 'store:' and 'numerics:'; keep one")
        else:
            numerics["snapshot_times"] = store["snapshot_times"]
    fields: tuple[str, ...] | None = None
    if "snapshot_fields" in store:
        raw_fields = store["snapshot_fields"]
        if not isinstance(raw_fields, Sequence) or isinstance(raw_fields, str):
            c.bad(
                ("store", "snapshot_fields"),
                raw_fields,
                "a list of field names from " + ", ".join(SNAPSHOT_FIELDS),
            )
        else:
            for i, f in enumerate(raw_fields):
                if f not in SNAPSHOT_FIELDS:
                    c.bad(
                        ("store", "snapshot_fields", i),
                        f,
                        "one of " + ", ".join(SNAPSHOT_FIELDS) + suggest(str(f), SNAPSHOT_FIELDS),
                    )
            fields = tuple(f for f in SNAPSHOT_FIELDS if f in raw_fields)
    dtype = store.get("snapshot_dtype", "float64")
    if dtype not in SNAPSHOT_DTYPES:
        c.bad(("store", "snapshot_dtype"), dtype, " or ".join(SNAPSHOT_DTYPES))
        dtype = "float64"
    tau, wall = math.inf, DEFAULT_CHECKPOINT_WALL
    if "checkpoint_every" in store:
        tau, wall = _checkpoint_every(c, store["checkpoint_every"])
    end_state = store.get("end_state", True)
    if not isinstance(end_state, bool):
        c.bad(("store", "end_state"), end_state, "true or false")
        end_state = True
    return StoreSpec(
        snapshot_fields=fields,
        snapshot_dtype=dtype,
        checkpoint_tau=tau,
        checkpoint_wall=wall,
        end_state=end_state,
    )


def _checkpoint_every(c: Checker, raw: Any) -> tuple[float, float]:
    """``store.checkpoint_every`` -> (tau, wall seconds): a number is simulated time, a text
    such as "10 min" (s, min, h) wall time, ``false`` none."""
    allowed = (
        "a time in tau (a number > 0), a wall time such as '10 min', '30 s' or '2 h', "
        "or false (no checkpoints)"
    )
    if raw is False:
        return math.inf, math.inf
    if isinstance(raw, (int, float)) and not isinstance(raw, bool):
        if raw > 0 and math.isfinite(raw):
            return float(raw), math.inf
    elif isinstance(raw, str) and (m := WALL_RE.match(raw)):
        seconds = float(m.group(1)) * WALL_UNITS[m.group(2)[0]]
        if seconds > 0:
            return math.inf, seconds
    c.bad(("store", "checkpoint_every"), raw, allowed)
    return math.inf, DEFAULT_CHECKPOINT_WALL


def read_seeds(c: Checker, raw: Any, read: Mapping[str, Any]) -> tuple[int, ...]:
    """``seeds:``: a count, a list, or ``{count: N, start: S}`` (default 50 seeds from 0)."""
    path: KeyPath = ("seeds",)
    if raw is None:
        return tuple(range(DEFAULT_SEEDS))
    if is_int(raw):
        if raw < 1:
            c.bad(path, raw, "a count >= 1, a list of seeds, or {count: N, start: S}")
            return ()
        if raw > c.max_runs:
            c.bad(path, raw, f"at most {c.max_runs} seeds (limits.max_runs)")
            return ()
        return tuple(range(int(raw)))
    if isinstance(raw, Mapping):
        m = c.mapping(path, raw, ("count", "start"))
        count, start = m.get("count", DEFAULT_SEEDS), m.get("start", 0)
        if not is_int(count) or count < 1 or count > c.max_runs:
            c.bad((*path, "count"), count, f"an integer from 1 to {c.max_runs} (limits.max_runs)")
            return ()
        if not is_int(start) or start < 0 or start + count > MAX_SEED:
            c.bad((*path, "start"), start, "an integer >= 0")
            return ()
        return tuple(range(int(start), int(start) + int(count)))
    if isinstance(raw, Sequence) and not isinstance(raw, str):
        if not raw:
            c.bad(path, raw, "a non-empty list of seeds")
            return ()
        out = []
        for i, s in enumerate(raw):
            if not is_int(s) or not 0 <= s <= MAX_SEED:
                c.bad((*path, i), s, "an integer seed >= 0")
            elif int(s) in out:
                c.bad((*path, i), s, "distinct seeds (this one appears twice)")
            else:
                out.append(int(s))
        return tuple(out)
    c.bad(path, raw, "a count >= 1, a list of seeds, or {count: N, start: S}")
    return ()


def read_fits(c: Checker, raw: Any, read: Mapping[str, Any]) -> tuple[Product, ...]:
    """``fits:``: names of registered fits, or ``{name: {options}}``."""
    return _check_products(c, raw, "fits")


def read_figures(c: Checker, raw: Any, read: Mapping[str, Any]) -> tuple[Product, ...] | None:
    """``figures:``; absent (or null): ``None``, every figure that applies; ``[]``: none."""
    return None if raw is None else _check_products(c, raw, "figures")


def _check_products(c: Checker, raw: Any, kind: str) -> tuple[Product, ...]:
    path: KeyPath = (kind,)
    if raw is None:
        return ()
    if not isinstance(raw, Sequence) or isinstance(raw, str):
        c.bad(path, raw, "a list of names or {name: {options}}")
        return ()
    if not raw:  # "figures: []": no registry to import (it brings xarray)
        return ()
    known = sorted(registry(kind))
    out = []
    for i, item in enumerate(raw):
        options: dict[str, Any]
        if isinstance(item, str):
            name, options = item, {}
        elif (
            isinstance(item, Mapping)
            and len(item) == 1
            and isinstance(next(iter(item)), str)
            and isinstance(next(iter(item.values())), (Mapping, type(None)))
        ):
            name, raw_options = next(iter(item.items()))
            options = dict(raw_options or {})
        else:
            c.bad((*path, i), item, "a name or {name: {options}}")
            continue
        if name not in known:
            c.bad((*path, i), name, f"one of {', '.join(known)}{suggest(name, known)}")
            continue
        out.append(Product(name, options))
    return tuple(out)


#: Options of fits and figures that name a sweep axis, and those that map axes to values.
AXIS_OPTIONS = ("axis", "activity", "strain")
SELECT_OPTIONS = ("select", "snapshot")


def check_product_options(c: Checker, campaign: Campaign) -> None:
    """Fits' and figures' options against the registries (unknown options, bad values) and
    against the campaign's axes (an option that names an axis must name one of them)."""
    names = [a.name for a in campaign.axes]
    if AMB in names:
        names.append("alpha")
    shape = None
    for kind, products in (("fits", campaign.fits), ("figures", campaign.figures or ())):
        for i, product in enumerate(products):
            path: KeyPath = (kind, i, product.name)
            problems = _registry_problems(kind, product)
            if not problems:  # options fine: can this campaign have it at all?
                shape = shape or _shape(campaign)
                problems = _shape_problems(kind, product, shape, campaign)
            for problem in problems:
                c.add(path, problem)
            options = product.options
            for key in AXIS_OPTIONS:
                value = options.get(key)
                if value is not None and value not in names:
                    c.bad(
                        (*path, key),
                        value,
                        "a sweep axis of this campaign ("
                        + (", ".join(names) or "none")
                        + ")"
                        + (suggest(value, names) if isinstance(value, str) else ""),
                    )
            chosen = [options.get(k) for k in SELECT_OPTIONS]
            snaps = options.get("snapshots")
            if isinstance(snaps, Sequence) and not isinstance(snaps, str):
                chosen.extend(snaps)
            for mapping in chosen:
                if not isinstance(mapping, Mapping):
                    continue
                for axis in mapping:
                    if axis not in names:
                        c.bad(
                            (*path,),
                            axis,
                            "sweep axes of this campaign in select / "
                            "snapshot options (" + (", ".join(names) or "none") + ")",
                        )


def registry(kind: str) -> Mapping[str, Any]:
    """The registered fits (``kind`` = "fits") or figures, by name. Imported when a campaign
    names some: they bring xarray, which ``nematic --help`` and ``simulate`` do without."""
    if kind == "fits":
        from ..analysis.registry import REGISTRY as FITS

        return FITS
    from ..figures.registry import REGISTRY as FIGURES

    return FIGURES


def _shape(campaign: Campaign) -> Any:
    from ..analysis.shape import Shape

    return Shape.of_campaign(campaign)


def _shape_problems(kind: str, product: Product, shape: Any, campaign: Campaign) -> list[str]:
    """Why ``product`` cannot be produced for a campaign of ``shape`` (the registries'
    ``needs``), so that it is refused here rather than failing after the runs."""
    if kind == "figures":
        from ..figures.registry import shape_problems

        fits = {p.name: p.options for p in campaign.fits}
        return shape_problems(product.name, product.options, shape, fits)
    from ..analysis.registry import fit_shape_problems

    return fit_shape_problems(product.name, product.options, shape)


def _registry_problems(kind: str, product: Product) -> list[str]:
    if kind == "figures":
        from ..figures.registry import option_problems as figure_problems

        return figure_problems(product.name, product.options)
    from ..analysis.registry import option_problems as fit_problems

    return (
        [] if product.name not in registry("fits") else fit_problems(product.name, product.options)
    )
