"""``results/NAME/verify.nc``: what each variant changes at each sampled point, and the
verdicts.

Per sampled point ``p`` and observable ``X`` (``verify.observables``): ``X_base(p)``, the
seed mean of the base runs (geometric or arithmetic by the observable's declared rule,
:class:`nematic_solids.sweep.models.interface.Observable`: geometric for the nematic model's
sigma2_S; for a pattern measure, over the runs that patterned only); per variant ``v``:
``X(p, v)`` the variant's seed mean, ``X_change(p, v)`` the relative change
``(X - X_base) / |X_base|`` or, for an observable whose change is absolute (the nematic
model's <cos 2 theta>, which lies in [-1, 1] and is near 0 without applied strain), the
absolute change ``X - X_base``, and ``X_verdict(p, v)``:

- 1 converged: ``|change| < verify.threshold``;
- 0 changed;
- -1 not compared: a pattern measure where the base or the variant has no patterned run (the
  class says so), or a value neither has (no peak);
- -2 missing: a run of the pair missing or failed, or the variant not valid there.

The class: ``patterned_base(p)`` and ``patterned(p, v)``, the fraction of the runs whose
sigma2_S is above ``verify.patterned_above``. ``converged(p, v)``: 1 when that fraction is
kept (with the same seeds: every seed keeps its class) and no compared observable changed, 0
otherwise, -2 when runs are missing.

Per fitted transition ``t`` the fit is recomputed on the sampled bracket (its two grid
points) with the base and with each variant's runs: ``transition_location_variant(t, v)``,
its ``transition_shift(t, v)`` from the base and ``transition_within(t, v)`` (1 when the
variant's location lies in the fit's own interval, 0 when it does not or the jump is gone).
The comparison is paired (same seeds unless the variant names others), so it measures the
numerics, not the seed scatter.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from ..analysis.transition import fit_transition
from ..expand import RunSpec
from ..files import atomic_to_netcdf
from ..models.interface import Observable, classifier, observable
from ..models.registry import get_model
from ..outputs.aggregate import coord_attrs
from ..provenance import code_version, git_commit, library_versions_text
from ..store import Record, now_iso
from . import CHANGED, CONVERGED, MISSING, NOT_COMPARED, VERIFY
from .sample import Sample, point_label
from .summary import summary_line

VERDICT_ATTRS = {
    "flag_values": np.array([-2, -1, 0, 1], dtype=np.int8),
    "flag_meanings": "missing not_compared changed converged",
}


def _values(
    runs: Sequence[RunSpec] | None, records: Mapping[str, Record], source: str
) -> tuple[np.ndarray, int]:
    """The runs' values of ``source`` (NaN where missing) and how many runs are ok."""
    if not runs:
        return np.full(0, np.nan), 0
    out = np.full(len(runs), np.nan)
    ok = 0
    for k, r in enumerate(runs):
        rec = records.get(r.run_id)
        if rec is None or rec.get("status") != "ok":
            continue
        ok += 1
        value = (rec.get("scalars") or {}).get(source)
        if value is not None:
            out[k] = float(value)
    return out, ok


def verify_dataset(
    sample: Sample, base_records: Mapping[str, Record], variant_records: Mapping[str, Record]
) -> xr.Dataset:
    """The verify.nc Dataset of ``sample`` from the records of the campaign (base runs) and
    of its verify folder (variant runs)."""
    spec = sample.spec
    model = get_model(sample.campaign.model)
    n_p, n_v = len(sample.points), len(sample.variants)
    level = spec.patterned_above
    sig_src = classifier(model).scalar
    base_sig = [_values(runs, base_records, sig_src) for runs in sample.base]
    base_frac = np.array([_fraction(v, ok, level) for v, ok in base_sig])
    var_sig: list[list[np.ndarray]] = [[np.full(0, np.nan)] * n_v for _ in range(n_p)]
    var_frac = np.full((n_p, n_v), np.nan)
    complete = np.zeros((n_p, n_v), dtype=bool)
    for v in range(n_v):
        for p in range(n_p):
            runs = sample.variant_runs[v][p]
            vals, ok = _values(runs, variant_records, sig_src)
            var_sig[p][v] = vals
            var_frac[p, v] = _fraction(vals, ok, level)
            complete[p, v] = (
                runs is not None and ok == len(runs) and base_sig[p][1] == len(sample.base[p])
            )
    data: dict[str, xr.Variable] = {}
    worst = np.ones((n_p, n_v), dtype=bool)
    for name in spec.observables:
        obs = observable(model, name)
        source, pattern = obs.scalar, obs.pattern

        def mean(vals: np.ndarray, sig: np.ndarray, obs: Observable = obs) -> float:
            # a pattern measure is the mean over the patterned runs only: a relaxed run's
            # sigma2_S (1e-13, at the solver's floor) or lambda (the texture's) is no pattern's
            return obs.mean(vals[sig > level] if obs.pattern else vals)

        base = np.array(
            [
                mean(_values(runs, base_records, source)[0], base_sig[p][0])
                for p, runs in enumerate(sample.base)
            ]
        )
        value = np.full((n_p, n_v), np.nan)
        change = np.full((n_p, n_v), np.nan)
        verdict = np.full((n_p, n_v), MISSING, dtype=np.int8)
        for v in range(n_v):
            for p in range(n_p):
                value[p, v] = mean(
                    _values(sample.variant_runs[v][p], variant_records, source)[0], var_sig[p][v]
                )
                change[p, v] = obs.difference(base[p], value[p, v])
                if not complete[p, v]:
                    continue
                if not (math.isfinite(base[p]) and math.isfinite(value[p, v])):
                    # no patterned run on a side (the class says it), or no peak in either
                    verdict[p, v] = NOT_COMPARED
                elif abs(change[p, v]) < spec.threshold:
                    verdict[p, v] = CONVERGED
                else:
                    verdict[p, v] = CHANGED
        worst &= verdict != CHANGED
        long = obs.long_name
        over = " over the patterned runs" if pattern else ""
        data[f"{name}_base"] = xr.Variable(
            ("point",),
            base,
            {"long_name": f"base runs' seed mean{over} of {name}: {long}", "units": "1"},
        )
        data[name] = xr.Variable(
            ("point", "variant"),
            value,
            {"long_name": f"variant runs' seed mean{over} of {name}", "units": "1"},
        )
        data[f"{name}_change"] = xr.Variable(
            ("point", "variant"),
            change,
            {
                "long_name": f"absolute change of {name}: variant - base"
                if obs.change == "absolute"
                else f"relative change of {name}: (variant - base) / |base|",
                "units": "1",
            },
        )
        data[f"{name}_verdict"] = xr.Variable(
            ("point", "variant"), verdict, {"long_name": f"verdict on {name}", **VERDICT_ATTRS}
        )
    kept = var_frac == base_frac[:, None]
    converged = np.where(~complete, MISSING, np.where(kept & worst, CONVERGED, CHANGED))
    data["patterned_base"] = xr.Variable(
        ("point",),
        base_frac,
        {
            "long_name": "fraction of the base runs that patterned (sigma2_S above "
            "patterned_above)",
            "units": "1",
        },
    )
    data["patterned"] = xr.Variable(
        ("point", "variant"),
        var_frac,
        {"long_name": "fraction of the variant runs that patterned", "units": "1"},
    )
    data["converged"] = xr.Variable(
        ("point", "variant"),
        converged.astype(np.int8),
        {
            "long_name": "verdict at the point: the patterned fraction kept and no compared "
            "observable changed by more than the threshold",
            **VERDICT_ATTRS,
        },
    )
    coords: dict[str, Any] = {
        "point": xr.Variable(
            ("point",), np.arange(n_p), {"long_name": "sampled point", "units": "1"}
        ),
        "variant": xr.Variable(
            ("variant",), np.arange(n_v), {"long_name": "variant", "units": "1"}
        ),
        "variant_name": xr.Variable(
            ("variant",),
            np.array([v.name for v in sample.variants]),
            {"long_name": "variant: the settings changed"},
        ),
        "label": xr.Variable(
            ("point",),
            np.array([point_label(p) for p in sample.points]),
            {"long_name": "the point's swept values"},
        ),
        "why": xr.Variable(
            ("point",), np.array(sample.why), {"long_name": "why the point is sampled"}
        ),
    }
    for axis in sample.campaign.axes:
        coords[axis.name] = xr.Variable(
            ("point",),
            np.array([p.coords[axis.name] for p in sample.points]),
            coord_attrs(axis.name, sample.campaign.model),
        )
    ds = xr.Dataset(data, coords=coords)
    if sample.transitions:
        _transitions(ds, sample, base_records, variant_records)
    ds.attrs.update(
        {
            "Conventions": "CF-1.11",
            "title": f"verification of campaign {sample.campaign.name}",
            "campaign": sample.campaign.name,
            "source": "active-nematic-solids campaign manager (nematic verify)",
            "code_version": code_version(),
            "git_commit": git_commit(),
            "library_versions": library_versions_text(),
            "created": now_iso(),
            "history": f"{now_iso()}: {n_p} points x {n_v} variants compared",
            "verify_spec": json.dumps(spec.to_dict()),
            "variant_settings": json.dumps({v.name: v.to_dict() for v in sample.variants}),
            "seeds": ", ".join(str(s) for s in sample.seeds),
            "threshold": spec.threshold,
            "patterned_above": spec.patterned_above,
            "problems": "; ".join(sample.problems),
            "summary": summary_line(ds),
        }
    )
    return ds


def _fraction(sigma2: np.ndarray, ok: int, level: float) -> float:
    """The fraction of the runs whose sigma2_S is above ``level`` (NaN without runs)."""
    finite = sigma2[np.isfinite(sigma2)]
    if ok == 0 or finite.size == 0:
        return math.nan
    return float(np.mean(finite > level))


def _transitions(
    ds: xr.Dataset,
    sample: Sample,
    base_records: Mapping[str, Record],
    variant_records: Mapping[str, Record],
) -> None:
    n_t, n_v = len(sample.transitions), len(sample.variants)
    loc_v = np.full((n_t, n_v), np.nan)
    loc_b = np.full(n_t, np.nan)
    for t, tr in enumerate(sample.transitions):
        known = {o.name: o.scalar for o in get_model(sample.campaign.model).observables}
        source = known.get(tr.observable, tr.observable)
        x = [sample.points[tr.below].coords[tr.axis], sample.points[tr.above].coords[tr.axis]]

        def location(
            runs: Sequence[Sequence[RunSpec] | None],
            records: Mapping[str, Record],
            tr: Any = tr,
            x: Any = x,
            source: str = source,
        ) -> float:
            if any(r is None for r in runs):
                return math.nan
            vals = [_values(r, records, source)[0] for r in runs]
            width = max(v.size for v in vals)
            table = np.full((2, width), np.nan)
            for k, v in enumerate(vals):
                table[k, : v.size] = v
            fit = fit_transition(x, table, log=tr.log, min_jump=tr.min_jump, mean=tr.mean, n_boot=1)
            return fit.location

        loc_b[t] = location([sample.base[tr.below], sample.base[tr.above]], base_records)
        for v in range(n_v):
            loc_v[t, v] = location(
                [sample.variant_runs[v][tr.below], sample.variant_runs[v][tr.above]],
                variant_records,
            )
    lower = np.array([tr.lower for tr in sample.transitions])
    upper = np.array([tr.upper for tr in sample.transitions])
    within = ((loc_v >= lower[:, None]) & (loc_v <= upper[:, None])).astype(np.int8)
    ds.coords["transition"] = xr.Variable(
        ("transition",), np.arange(n_t), {"long_name": "fitted transition sampled", "units": "1"}
    )
    ds["transition_fit"] = xr.Variable(
        ("transition",),
        np.array(
            [
                f"{tr.prefix} along {tr.axis}"
                + "".join(f", {k} = {v:g}" for k, v in tr.where.items())
                for tr in sample.transitions
            ]
        ),
        {"long_name": "the fitted transition"},
    )
    ds["transition_location"] = xr.Variable(
        ("transition",),
        np.array([tr.location for tr in sample.transitions]),
        {"long_name": "the fit's location", "units": "1"},
    )
    ds["transition_lower"] = xr.Variable(
        ("transition",), lower, {"long_name": "the fit's interval, lower end", "units": "1"}
    )
    ds["transition_upper"] = xr.Variable(
        ("transition",), upper, {"long_name": "the fit's interval, upper end", "units": "1"}
    )
    ds["transition_location_base"] = xr.Variable(
        ("transition",),
        loc_b,
        {
            "long_name": "location recomputed on the sampled bracket with the base runs",
            "units": "1",
        },
    )
    ds["transition_location_variant"] = xr.Variable(
        ("transition", "variant"),
        loc_v,
        {
            "long_name": "location recomputed on the sampled bracket with the variant's runs "
            "(NaN: no jump between the bracket's points)",
            "units": "1",
        },
    )
    ds["transition_shift"] = xr.Variable(
        ("transition", "variant"),
        loc_v - loc_b[:, None],
        {"long_name": "shift of the recomputed location, variant - base", "units": "1"},
    )
    ds["transition_within"] = xr.Variable(
        ("transition", "variant"),
        within,
        {
            "long_name": "1 when the variant's location lies in the fit's own interval",
            "flag_values": np.array([0, 1], dtype=np.int8),
            "flag_meanings": "outside within",
        },
    )


def write_verify(root: Path, ds: xr.Dataset) -> Path:
    path = root / VERIFY
    text = {
        name: {"dtype": "S1"}
        for name in ("variant_name", "label", "why", "transition_fit")
        if name in ds.variables
    }
    atomic_to_netcdf(ds, path, text)
    return path
