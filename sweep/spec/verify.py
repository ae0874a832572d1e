"""The ``verify:`` section of a campaign, its check, and a variant's settings at a point.

::

    verify:
      variants:                 # each one reruns the sample with these settings changed
        - resolution: x2        #   a multiple of the point's own value ("x2", "/10") ...
        - tolerance: /10
        - mechanics: finite     #   ... or a value (any parameter or numerics field)
        - noise_modes: 16
        - seeds: [100, 101]     #   other seeds (a list, or a count after the campaign's)
      points: auto              # default: both sides of each fitted transition; or a list of
                                #   selections ({K: 1e-6}: every grid point with K = 1e-6)
      corners: true             # also the grid's corners (default true)
      seeds: 2                  # the campaign's first seeds run at each sampled point
      threshold: 0.05           # converged: relative change below this ...
      patterned_above: 1.0e-6   #   ... and the same class (patterned: sigma2_S above this)
      observables: [sigma2_S, cos2theta, lambda, lambda_peak, t_peak]
      before: false             # nematic run: verify the sample before the full grid

A resolution variant of a campaign with the per-node texture also fixes the grid the
texture is drawn on (``texture_resolution``: the point's own resolution), so that it starts
from the same physical field (model/initial.py); the band texture is that already.

The checks add their problems to the campaign's checker
(:class:`nematic_solids.sweep.spec.checker.Checker`), so a mistake here is reported with the file,
line, key path and what is allowed, in the same pass as every other problem of the file.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from typing import Any

from ..campaign import (
    AMB,
    DEFAULT_MODEL,
    MAX_SEED,
    Dim,
    Variant,
    VerifySpec,
    normalise_float,
    same_value,
)
from ..models.interface import (
    SettingError,
    classifier,
    resolution_rule,
    setting_error,
    verified,
)
from ..models.registry import get_model
from ..settings import setting_names
from .checker import Checker, coerce, is_int, is_number, suggest

KEYS = (
    "variants",
    "points",
    "corners",
    "seeds",
    "threshold",
    "patterned_above",
    "observables",
    "before",
)
# A verification compares any observable of the campaign's model (its phase.nc names), each
# by its declared rules (nematic_solids.sweep.models.interface.Observable): its seed mean, how
# a change is measured, and whether it measures a pattern (compared only where the base or
# the variant is patterned).
MAX_VARIANTS = 20
MAX_SEEDS = 50
_FACTOR = re.compile(r"^\s*([x*/])\s*([0-9.eE+-]+)\s*$")


def _names(model: str) -> list[str]:
    return sorted(setting_names(model).all)


def _factor(value: Any) -> tuple[str, float] | None:
    """``("x", 2.0)`` for "x2", ``("/", 10.0)`` for "/10", else ``None``."""
    if not isinstance(value, str):
        return None
    m = _FACTOR.match(value)
    if m is None:
        return None
    try:
        f = float(m.group(2))
    except ValueError:
        return None
    return ("/" if m.group(1) == "/" else "x", f) if math.isfinite(f) and f > 0 else None


def variant_name(settings: Mapping[str, Any], seeds: Sequence[int] | None) -> str:
    """A variant's label: ``resolution x2``, ``tolerance /10``, ``mechanics=finite``."""
    parts = []
    for k, v in settings.items():
        f = _factor(v)
        parts.append(f"{k} {v.strip()}" if f is not None else f"{k}={v}")
    if seeds is not None:
        parts.append("seeds=" + ",".join(str(s) for s in seeds))
    return ", ".join(parts)


def resolve(
    variant: Variant, parameters: Any, numerics: Any, model: str = DEFAULT_MODEL
) -> tuple[Any, Any]:
    """The model's objects of ``variant`` at a point whose own are given. Raises the model's
    ``ValueError`` (:class:`~nematic_solids.sweep.models.interface.SettingError`) when the
    result is not a valid run."""
    names = setting_names(model)
    p, n = parameters.to_dict(), numerics.to_dict()
    for key, value in variant.settings.items():
        f = _factor(value)
        if key == AMB:
            base = parameters.alpha - parameters.B
            new = base * f[1] if f and f[0] == "x" else base / f[1] if f else float(value)
            p["alpha"] = p["B"] + normalise_float(new)
            continue
        target = p if key in names.parameters else n
        kind = names.all[key]
        if f is not None:
            old = target[key]
            new = old * f[1] if f[0] == "x" else old / f[1]
            if not math.isfinite(new):
                raise SettingError(key, value, f"a factor that leaves {key} finite")
            target[key] = int(round(new)) if kind == "int" else normalise_float(new)
        else:
            target[key] = coerce(kind, value)
    if (
        "resolution" in n
        and n["resolution"] != numerics.resolution
        and p.get("initial") == "per_node"
        and not p.get("texture_resolution")
        and "texture_resolution" not in variant.settings
    ):
        p["texture_resolution"] = numerics.resolution  # the same physical initial field
    return get_model(model).point(p, n)


def variant_grid(variant: Variant, resolution: int, mechanics: str) -> tuple[int, str]:
    """The resolution and mechanics of ``variant``'s run at a point whose own are given (what
    its memory is estimated from, :func:`nematic_solids.sweep.limits.run_memory_bytes`)."""
    value = variant.settings.get("resolution", resolution)
    f = _factor(value)
    if f is not None:
        value = resolution * f[1] if f[0] == "x" else resolution / f[1]
    finite = is_number(value) and math.isfinite(float(value))
    grid = int(round(float(value))) if finite else resolution
    return grid, str(variant.settings.get("mechanics", mechanics))


def read_verify(c: Checker, raw: Any, read: Mapping[str, Any]) -> VerifySpec | None:
    """The reader of the ``verify:`` section (a row of :data:`nematic_solids.sweep.spec.SECTIONS`):
    needs the ``parameters``, ``numerics``, ``sweep`` and ``seeds`` sections read before it."""
    return check_verify(
        c,
        raw,
        read.get("sweep") or (),
        read.get("seeds") or (),
        read.get("parameters") or {},
        read.get("numerics") or {},
        read.get("model") or DEFAULT_MODEL,
    )


def _variant(
    c: Checker,
    path: tuple[str | int, ...],
    raw: Any,
    seeds: Sequence[int],
    parameters: Any,
    numerics: Any,
    model: str,
) -> Variant | None:
    names = _names(model)
    if not isinstance(raw, Mapping) or not raw:
        c.bad(
            path,
            raw,
            "a mapping of the settings changed (e.g. resolution: x2, "
            "tolerance: /10, mechanics: finite, seeds: [100, 101])",
        )
        return None
    before = len(c.problems)
    settings: dict[str, Any] = {}
    other: tuple[int, ...] | None = None
    for key, value in raw.items():
        if key == "seeds":
            if is_int(value) and 1 <= value <= MAX_SEEDS:
                start = max(seeds, default=-1) + 1
                other = tuple(range(start, start + int(value)))
            elif (
                isinstance(value, Sequence)
                and not isinstance(value, str)
                and value
                and len(value) <= MAX_SEEDS
                and all(is_int(s) and 0 <= s <= MAX_SEED for s in value)
            ):
                other = tuple(int(s) for s in value)
            else:
                c.bad(
                    (*path, "seeds"),
                    value,
                    f"a list of seeds, or a count from 1 to "
                    f"{MAX_SEEDS} (the seeds after the campaign's)",
                )
            continue
        if not isinstance(key, str) or key not in names:
            c.unknown((*path, str(key)), key, [*names, "seeds"])
            continue
        kind = setting_names(model).all[key]
        f = _factor(value)
        if isinstance(value, str) and value.strip()[:1] in "x*/" and kind in ("int", "float"):
            if f is None:
                c.bad(
                    (*path, key),
                    value,
                    "a value, or a factor of the point's own value: "
                    "'x2', '/10' (a positive number after x or /)",
                )
            settings[key] = value
            continue
        try:
            settings[key] = coerce(kind, value)
        except ValueError as e:
            c.bad((*path, key), value, str(e))
    if len(c.problems) > before:
        return None
    variant = Variant(variant_name(settings, other), settings, other)
    if parameters is not None and numerics is not None and settings:
        try:
            resolve(variant, parameters, numerics, model)
        except ValueError as exc:
            why = setting_error(exc)
            c.add(
                path,
                f"at the campaign's base values: {why.name} = {why.value!r}; allowed: "
                f"{why.allowed}",
            )
            return None
    return variant


def check_verify(
    c: Checker,
    raw: Any,
    dims: Sequence[Dim],
    seeds: Sequence[int],
    parameters: Mapping[str, Any],
    numerics: Mapping[str, Any],
    model: str = DEFAULT_MODEL,
) -> VerifySpec | None:
    """The ``verify:`` section as a :class:`VerifySpec`, or ``None`` when there is none (or it
    has problems, which are added to ``c``); its observables are ``model``'s."""
    if raw is None:
        return None
    path: tuple[str | int, ...] = ("verify",)
    if not isinstance(raw, Mapping):
        c.bad(path, raw, "a mapping with keys " + ", ".join(KEYS))
        return None
    sec = c.mapping(path, raw, KEYS)
    before = len(c.problems)
    try:
        m = get_model(model)
        base_p, base_n = m.point(
            parameters,
            {
                k: v
                for k, v in numerics.items()
                if not (k == "resolution" and resolution_rule(m, v) is not None)
            },
        )  # a resolution rule: the checks below need no grid
    except (ValueError, TypeError):
        base_p = base_n = None  # reported by their own sections

    raw_variants = sec.get("variants")
    variants: list[Variant] = []
    if (
        not isinstance(raw_variants, Sequence)
        or isinstance(raw_variants, str)
        or not 1 <= len(raw_variants) <= MAX_VARIANTS
    ):
        c.bad(
            (*path, "variants"),
            raw_variants,
            f"a list of 1 to {MAX_VARIANTS} mappings, "
            "each the settings one variant changes (e.g. - resolution: x2)",
        )
    else:
        for i, item in enumerate(raw_variants):
            v = _variant(c, (*path, "variants", i), item, seeds, base_p, base_n, model)
            if v is not None:
                variants.append(v)
        labels = [v.name for v in variants]
        for label in {x for x in labels if labels.count(x) > 1}:
            c.add((*path, "variants"), f"the variant {label!r} is given twice")

    axes = {a.name: a.values for d in dims for a in d.axes}
    points = sec.get("points", "auto")
    selections: tuple[Mapping[str, Any], ...] | None = None
    if points != "auto":
        if not isinstance(points, Sequence) or isinstance(points, str) or not points:
            c.bad(
                (*path, "points"),
                points,
                "auto, or a list of selections ({AXIS: VALUE, "
                "...}: every grid point with these values)",
            )
        else:
            chosen = []
            for i, sel in enumerate(points):
                p_path = (*path, "points", i)
                if not isinstance(sel, Mapping) or not sel:
                    c.bad(p_path, sel, "a mapping {AXIS: VALUE, ...} of sweep axes")
                    continue
                out = {}
                for axis, value in sel.items():
                    if axis not in axes:
                        c.unknown((*p_path, str(axis)), axis, list(axes))
                        continue
                    match = [v for v in axes[axis] if same_value(v, value)]
                    if not match:
                        c.bad(
                            (*p_path, axis),
                            value,
                            "a value of the axis: "
                            + ", ".join(f"{v:g}" if is_number(v) else str(v) for v in axes[axis]),
                        )
                        continue
                    out[axis] = match[0]
                chosen.append(out)
            selections = tuple(chosen)

    corners = sec.get("corners", True)
    if not isinstance(corners, bool):
        c.bad((*path, "corners"), corners, "true or false")
        corners = True
    n = sec.get("seeds", 2)
    if not is_int(n) or not 1 <= n <= max(len(seeds), 1):
        c.bad(
            (*path, "seeds"),
            n,
            f"an integer from 1 to {len(seeds)} (the campaign's first "
            "seeds run at each sampled point)",
        )
        n = 1
    threshold = sec.get("threshold", 0.05)
    if not is_number(threshold) or not 0 < threshold < 10:
        c.bad((*path, "threshold"), threshold, "a relative change in (0, 10), e.g. 0.05")
        threshold = 0.05
    patterned = sec.get("patterned_above", 1e-6)
    if not is_number(patterned) or not 0 < patterned < 1:
        c.bad((*path, "patterned_above"), patterned, "a sigma2_S level in (0, 1)")
        patterned = 1e-6
    known = [o.name for o in get_model(model).observables]
    observables = sec.get("observables", list(verified(get_model(model))))
    if (
        not isinstance(observables, Sequence)
        or isinstance(observables, str)
        or not observables
        or any(o not in known for o in observables)
    ):
        bad = [o for o in observables if o not in known] if isinstance(observables, list) else []
        c.bad(
            (*path, "observables"),
            observables,
            "a list of " + ", ".join(known) + (suggest(str(bad[0]), known) if bad else ""),
        )
        observables = [classifier(get_model(model)).name]
    before_flag = sec.get("before", False)
    if not isinstance(before_flag, bool):
        c.bad((*path, "before"), before_flag, "true or false")
        before_flag = False
    if len(c.problems) > before:
        return None
    return VerifySpec(
        variants=tuple(variants),
        points=selections,
        corners=corners,
        seeds=int(n),
        threshold=float(threshold),
        patterned_above=float(patterned),
        observables=tuple(dict.fromkeys(str(o) for o in observables)),
        before=before_flag,
    )
