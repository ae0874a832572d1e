"""The phase diagram of a campaign: ``results/<name>/phase.nc``.

Dims are the sweep dims (in the campaign's order; a zip group is one dim named after its
first axis, the other axes are coordinates on it) and ``seed`` (CF ``standard_name``
"realization"). For every per-run observable ``X`` (sigma2_S, mean_S, cos2theta, lambda at
t_final; lambda_peak and t_peak at the first peak of sigma2_S(t) by the growth-peak rule and
by the paper's literal rule; lambda_mean; rate_margin_min; plus any other scalar the model
writes) the file holds ``X`` over (dims..., seed), NaN where a run is missing or failed,
and ``X_mean``, ``X_std`` (sample standard deviation, ddof = 1, NaN below two seeds) and
``X_count`` over the seeds that succeeded. ``status`` (0 missing, 1 ok, 2 failed, CF flags),
``reason`` and ``run_id`` (the run file is ``runs/<run_id>.nc``) locate every run;
``run_time`` is each run's wall time in seconds (ok and failed runs).

The values come from the per-run records (the scalars the worker copied from each run file),
so aggregation opens no run file; the records are checked against the files' presence.
Written by the driver (or ``nematic aggregate``) alone, atomically.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from ..campaign import AMB, DEFAULT_MODEL
from ..expand import Expansion
from ..files import atomic_to_netcdf
from ..models.interface import resolution_rule
from ..models.registry import get_model
from ..protocols import AXIS_LONG_NAMES, PROTOCOL
from ..provenance import code_version, git_commit, library_versions_text
from ..store import RETRYABLE_REASONS, CampaignStore, Record, now_iso

if TYPE_CHECKING:
    import xarray as xr

log = logging.getLogger(__name__)

STATUS_MISSING, STATUS_OK, STATUS_FAILED = 0, 1, 2


#: Scalars of the run files that are not observables (they differ between identical runs).
NOT_OBSERVABLES = {"wall_time"}


def _observable_names(records: Mapping[str, Record], model: str) -> dict[str, tuple[str, str]]:
    """phase.nc name -> (run scalar, long name): ``model``'s observables, then every other
    scalar the records hold (``<name>_final`` as ``<name>``), except :data:`NOT_OBSERVABLES`."""
    out = {o.name: (o.scalar, o.long_name) for o in get_model(model).observables}
    known = {src for src, _ in out.values()}
    extra: set[str] = set()
    for rec in records.values():
        extra.update((rec.get("scalars") or {}).keys())
    for src in sorted(extra - known - NOT_OBSERVABLES):
        name = src.removesuffix("_final")
        if name not in out and name not in ("status", "reason", "run_id", "seed"):
            out[name] = (src, f"{src} (run scalar)")
    return out


def _seed_stats(values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean, sample std (ddof = 1) and count over the last axis, ignoring NaN, no warnings."""
    ok = np.isfinite(values)
    count = ok.sum(axis=-1)
    filled = np.where(ok, values, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 0, filled.sum(axis=-1) / np.maximum(count, 1), np.nan)
        dev = np.where(ok, values - mean[..., None], 0.0)
        var = (dev**2).sum(axis=-1) / np.maximum(count - 1, 1)
        std = np.where(count > 1, np.sqrt(var), np.nan)
    return mean, std, count.astype(np.int32)


def coord_attrs(name: str, model: str = DEFAULT_MODEL) -> dict[str, str]:
    """The attributes of a swept coordinate: a parameter's long name and units as its model
    declares them, a number of a protocol's
    (:data:`~nematic_solids.sweep.protocols.AXIS_LONG_NAMES`),
    or a numerics setting's name (its units where it is a number)."""
    setting = {s.name: s for s in get_model(model).settings}.get(name)
    if setting is not None and setting.kind == "parameter":
        return {"long_name": setting.long_name, "units": setting.units}
    if name in AXIS_LONG_NAMES:
        return {"long_name": AXIS_LONG_NAMES[name], "units": "1"}
    attrs = {"long_name": name}
    if setting is not None and setting.type in (int, float):
        attrs["units"] = setting.units
    return attrs


def build_phase(
    expansion: Expansion, records: Mapping[str, Record], store: CampaignStore | None = None
) -> xr.Dataset:
    """The phase-diagram Dataset of a campaign from its run records (see module doc)."""
    import xarray as xr  # here: the campaign's reader needs this module, not xarray

    campaign = expansion.campaign
    dims = [d.name for d in campaign.dims] + ["seed"]
    shape = (*campaign.shape, len(campaign.seeds))
    n = len(expansion)
    status = np.zeros(n, dtype=np.int8)
    reason = np.full(n, "", dtype=object)
    observables = _observable_names(records, campaign.model)
    data = {name: np.full(n, np.nan) for name in observables}
    run_time = np.full(n, np.nan)
    versions: set[str] = set()
    commits: set[str] = set()
    for i, rid in enumerate(expansion.run_ids):
        rec = records.get(rid)
        if rec is None or (store is not None and not store.is_complete(rid, rec)):
            continue  # missing (or unreadable: the driver redoes it)
        if rec.get("status") != "ok" and rec.get("reason") in RETRYABLE_REASONS:
            continue  # not stored: missing, not failed
        wall = rec.get("wall_time")
        if isinstance(wall, (int, float)) and not isinstance(wall, bool):
            run_time[i] = float(wall)
        if rec.get("status") != "ok":
            status[i] = STATUS_FAILED
            reason[i] = str(rec.get("reason") or "unknown")
            continue
        status[i] = STATUS_OK
        scalars = rec.get("scalars") or {}
        for name, (src, _) in observables.items():
            value = scalars.get(src)
            if value is not None:
                data[name][i] = float(value)
        if rec.get("code_version"):
            versions.add(str(rec["code_version"]))
        if rec.get("git_commit"):
            commits.add(str(rec["git_commit"]))

    coords: dict[str, Any] = {}
    for d in campaign.dims:
        for axis in d.axes:
            coords[axis.name] = xr.Variable(
                (d.name,), np.asarray(axis.values), coord_attrs(axis.name, campaign.model)
            )
    coords["seed"] = xr.Variable(
        ("seed",),
        np.asarray(campaign.seeds, dtype=np.int64),
        {
            "standard_name": "realization",
            "long_name": "random seed of the initial director field",
            "units": "1",
        },
    )

    # the seed statistics (X_mean, X_std) pool the seeds: their cell_methods name this scalar
    # coordinate variable (CF 7.3: "realization: mean")
    coords["realization"] = xr.Variable(
        (),
        np.int64(len(campaign.seeds)),
        {
            "long_name": "number of seeds pooled by the seed statistics (X_mean, X_std); the "
            "seeds are the seed coordinate",
            "units": "1",
        },
    )
    ds = xr.Dataset(coords=coords)
    ds["status"] = xr.Variable(
        dims,
        status.reshape(shape),
        {
            "long_name": "run status",
            "flag_values": np.array([0, 1, 2], dtype=np.int8),
            "flag_meanings": "missing ok failed",
        },
    )
    ds["reason"] = xr.Variable(
        dims,
        reason.reshape(shape).astype(str),
        {"long_name": "why the run failed (empty when it did not)"},
    )
    ds["run_id"] = xr.Variable(
        dims,
        np.asarray(expansion.run_ids, dtype=str).reshape(shape),
        {"long_name": "run identifier: the run's file is runs/<run_id>.nc"},
    )
    ds["run_time"] = xr.Variable(
        dims,
        run_time.reshape(shape),
        {
            "long_name": "wall time of the run on its worker (an accelerated batch's time "
            "divided by its seeds); what a prior: of this campaign prices later rounds with",
            "units": "s",
        },
    )
    for name, (src, long_name) in observables.items():
        values = data[name].reshape(shape)
        ds[name] = xr.Variable(
            dims, values, {"long_name": long_name, "units": "1", "source_variable": src}
        )
        mean, std, count = _seed_stats(values)
        sd = dims[:-1]
        # CF cell_methods name the collapsed seed axis by the scalar coordinate "realization"
        ds[f"{name}_mean"] = xr.Variable(
            sd,
            mean,
            {
                "long_name": f"seed mean of {name}",
                "units": "1",
                "cell_methods": "realization: mean",
            },
        )
        ds[f"{name}_std"] = xr.Variable(
            sd,
            std,
            {
                "long_name": f"seed standard deviation (ddof = 1) of {name}",
                "units": "1",
                "cell_methods": "realization: standard_deviation",
            },
        )
        ds[f"{name}_count"] = xr.Variable(
            sd, count, {"long_name": f"number of seeds with a value of {name}", "units": "1"}
        )

    by_rule = resolution_rule(get_model(campaign.model), campaign.numerics.get("resolution"))
    if by_rule and "resolution" not in {a.name for a in campaign.axes}:
        ds["resolution"] = xr.Variable(  # resolution: auto, each point's own grid
            dims[:-1],
            np.asarray([p.numerics.resolution for p in expansion.points]).reshape(shape[:-1]),
            {
                "long_name": "grid points per side of the point's runs, chosen by the rule "
                + by_rule,
                "units": "1",
            },
        )
    for var in ds.data_vars.values():  # the per-seed values do not pool seeds
        if "seed" in var.dims:
            var.encoding["coordinates"] = None

    swept = {a.name for a in campaign.axes}
    first = expansion.points[0]
    params = first.parameters.to_dict()
    fixed_params = {
        k: v
        for k, v in params.items()
        if k not in swept and not (k == "alpha" and (AMB in swept or "B" in swept))
    }
    amb = getattr(first.parameters, AMB, None)  # the nematic model's alpha - B
    if amb is not None and AMB not in swept and "alpha" not in swept and "B" not in swept:
        fixed_params[AMB] = amb
    if PROTOCOL in campaign.parameters:  # as written (its swept numbers are axes)
        fixed_params[PROTOCOL] = json.dumps(campaign.parameters[PROTOCOL], sort_keys=True)
        for name in campaign.parameters[PROTOCOL]:  # not constants: no value of their own
            for key in (name, "alpha") if name == AMB else (name,):
                fixed_params.pop(key, None)
    fixed_numerics = {k: v for k, v in first.numerics.to_dict().items() if k not in swept}
    if by_rule:  # the rule, not the first point's grid (the variable resolution has each)
        fixed_numerics["resolution"] = by_rule
    n_ok = int((status == STATUS_OK).sum())
    n_failed = int((status == STATUS_FAILED).sum())
    ds.attrs.update(
        {
            "Conventions": "CF-1.11",
            "title": f"phase diagram of campaign {campaign.name}",
            "campaign": campaign.name,
            "model": campaign.model,
            "description": campaign.description,
            "source": "active-nematic-solids campaign manager (nematic aggregate)",
            "code_version": code_version(),
            "git_commit": git_commit(),
            "library_versions": library_versions_text(),
            "run_code_versions": ", ".join(sorted(versions)),
            "run_git_commits": ", ".join(sorted(commits)),
            "created": now_iso(),
            "history": f"{now_iso()}: aggregated {n_ok} ok and {n_failed} failed of {n} runs",
            "campaign_yaml": campaign.text,
            "campaign_overrides": "; ".join(campaign.overrides),
            "sweep_dims": ", ".join(d.name for d in campaign.dims),
            "zip_groups": "; ".join(
                ", ".join(a.name for a in d.axes) for d in campaign.dims if len(d.axes) > 1
            ),
            **(
                {
                    "chain_axis": campaign.chain.axis,
                    "chain_branches": ", ".join(campaign.chain.branches),
                    "chain_up": campaign.chain.up,
                }
                if campaign.chain is not None
                else {}
            ),
            "n_runs": n,
            "n_ok": n_ok,
            "n_failed": n_failed,
            "n_missing": n - n_ok - n_failed,
            **{f"param_{k}": v for k, v in fixed_params.items()},
            **{f"num_{k}": v for k, v in fixed_numerics.items()},
        }
    )
    return ds


def phase_dataset(
    expansion: Expansion, store: CampaignStore, records: Mapping[str, Record]
) -> xr.Dataset:
    """The phase-diagram Dataset of ``expansion`` (a grid, or an adaptive campaign's union
    grid, whose expansion builds its own:
    :class:`nematic_solids.sweep.refine.rounds.RefinedExpansion`)."""
    own = getattr(expansion, "build_phase", None)
    return own(records, store) if own is not None else build_phase(expansion, records, store)


def write_phase(
    expansion: Expansion, store: CampaignStore, records: Mapping[str, Record] | None = None
) -> xr.Dataset:
    """Build and atomically write ``results/<name>/phase.nc``; return the Dataset."""
    if records is None:
        records = store.scan()
    ds = phase_dataset(expansion, store, records)
    store.root.mkdir(parents=True, exist_ok=True)
    # text variables as classic char arrays (read back as str), not netCDF-4 vlen strings,
    # which older CF checkers (cfchecks, CF <= 1.8) reject
    text = {name: {"dtype": "S1"} for name in ("reason", "run_id")}
    atomic_to_netcdf(ds, store.phase_path, text)
    log.info(
        "wrote %s (%d ok, %d failed, %d missing)",
        store.phase_path,
        ds.attrs["n_ok"],
        ds.attrs["n_failed"],
        ds.attrs["n_missing"],
    )
    return ds
