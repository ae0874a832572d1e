"""What the API and the dashboard show of a campaign, read from its results folder (the run
records are the source of truth): the seed mean of the shown observable with its 95 % interval
(Student t), a failure with its reason, the rounds (``refine.json``, ``precision.json``), the
marks of the phase diagram (each point's round, decision and verification verdict) and the
verification's summary (``verify.nc``), and one run's time series. Every name that reaches the
disk is checked first (:func:`campaign_store`). :mod:`.campaign_view` puts them together and
keeps them up to date."""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..campaign import DEFAULT_MODEL, Campaign
from ..errors import CampaignError, ParameterError
from ..expand import Expansion
from ..models.interface import Observable, classifier
from ..models.registry import UnknownModel, get_model
from ..store import CampaignStore, Record
from .security import inside, safe_name


def shown(model: str = DEFAULT_MODEL) -> Observable:
    """The observable the phase diagram shows: the one that classifies the model's points
    (the nematic model's sigma2_S, as the report's ``report.phase_plot.Shown``)."""
    return classifier(get_model(model))


#: The confidence of a point's interval.
CONFIDENCE = 0.95
#: Series of a run file the run view sends at most: its model's first observables that the
#: file holds as series over time (the nematic model's sigma2_S, mean_S, cos2theta, lambda).
MAX_SERIES = 4
#: Points of a series sent at most (evenly thinned beyond).
MAX_SERIES_POINTS = 2000


class NotFound(LookupError):
    """A campaign or run the service does not have (or a name refused)."""


def campaign_store(root: Path, name: str) -> CampaignStore:
    """The results folder of campaign ``name`` under ``root``; :class:`NotFound` for a name
    that is not one path component or whose folder (links followed) leaves ``root``."""
    if not safe_name(name):
        raise NotFound(f"no campaign {name!r}")
    store = CampaignStore(root, name)
    if not store.root.is_dir() or not inside(root, store.root):
        raise NotFound(f"no campaign {name!r}")
    return store


def campaign_names(root: Path) -> list[str]:
    """The campaign folders of the root (those with a campaign copy or runs)."""
    try:
        entries = sorted(p for p in root.iterdir() if p.is_dir() and safe_name(p.name))
    except OSError:
        return []
    return [p.name for p in entries if (p / "campaign.yaml").exists() or (p / "runs").is_dir()]


def stored_layout(store: CampaignStore) -> tuple[Campaign, Expansion] | None:
    """The campaign of the folder's copy and its runs (the union grid of its rounds, for a
    campaign with rounds), or ``None`` where the folder has no copy or this code does not
    accept it: its text (:class:`~nematic_solids.sweep.errors.CampaignError`) or a grid
    point the model refuses (:class:`~nematic_solids.model.errors.ParameterError`). The
    points are built once, by the expansion (the copy is read without building them)."""
    from ..outputs.stored import stored_campaign
    from ..refine.rounds import expansion_for

    try:
        campaign = stored_campaign(store, build_points=False)
        return None if campaign is None else (campaign, expansion_for(campaign, store))
    except (CampaignError, ParameterError):
        return None


@functools.cache
def _t_quantile(dof: int) -> float:
    from scipy.stats import t as student

    return float(student.ppf(0.5 + CONFIDENCE / 2, dof))


def interval(values: list[float]) -> tuple[float, float, float]:
    """Mean and the ends of its :data:`CONFIDENCE` Student-t interval (NaN ends below two
    values)."""
    x = np.asarray([v for v in values if math.isfinite(v)], dtype=float)
    if x.size == 0:
        return math.nan, math.nan, math.nan
    mean = float(x.mean())
    if x.size < 2:
        return mean, math.nan, math.nan
    half = _t_quantile(int(x.size - 1)) * float(x.std(ddof=1)) / math.sqrt(x.size)
    return mean, mean - half, mean + half


def _finite(x: Any) -> float | None:
    return float(x) if isinstance(x, (int, float)) and math.isfinite(x) else None


def plain(value: Any) -> Any:
    if isinstance(value, (np.floating, float)):
        return _finite(float(value))
    if isinstance(value, np.integer):
        return int(value)
    return value if isinstance(value, (int, str, bool)) or value is None else str(value)


def failure_entry(run_id: str, coords: Mapping[str, Any], record: Record) -> dict[str, Any]:
    """A failed run as the page lists it: where, the reason, when, the detail's last line."""
    detail = str(record.get("detail") or "").strip().splitlines()
    return {
        "run_id": run_id,
        "coords": {k: plain(v) for k, v in coords.items()},
        "reason": str(record.get("reason") or "unknown"),
        "t_failed": _finite(record.get("t_failed")),
        "detail": detail[-1] if detail else "",
    }


def _plan_file(store: CampaignStore, name: str) -> dict[str, Any] | None:
    try:
        data = json.loads((store.root / name).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def rounds(store: CampaignStore) -> dict[str, Any] | None:
    """The rounds of an adaptive campaign or of seeds by precision, as decided so far: per
    round its runs and new points, the points' seed decisions, whether it finished and why."""
    plan = _plan_file(store, "refine.json") or _plan_file(store, "precision.json")
    if plan is None:
        return None
    return {
        "finished": bool(plan.get("finished")),
        "stop": plan.get("stop") or "",
        "rounds": [
            {k: r.get(k) for k in ("round", "n_runs", "new_points", "seeded_points")}
            for r in plan.get("rounds") or []
            if isinstance(r, dict)
        ],
        "decisions": [
            {k: p.get(k) for k in ("coords", "seeds_run", "decision", "why")}
            for p in plan.get("points") or []
            if isinstance(p, dict)
        ],
    }


def point_key(coords: Mapping[str, Any]) -> str:
    """A point's swept values as one text, numbers to 12 significant digits (the same point
    read from the expansion, a plan file or verify.nc gives the same key)."""
    parts = []
    for k in sorted(coords):
        v = coords[k]
        number = isinstance(v, (int, float, np.number)) and not isinstance(v, bool)
        parts.append(f"{k}={float(v):.12g}" if number else f"{k}={v}")
    return ",".join(parts)


def point_marks(store: CampaignStore) -> dict[str, dict[str, Any]]:
    """What the phase diagram marks on each point, by :func:`point_key`: ``round``, the round
    that added it (``refine.json``: adaptive refinement) or that last ran seeds at it
    (``precision.json``: seeds by precision); ``decision``, its seeds'
    decision under a precision; ``verdict``, its verification verdict (``verify.nc``:
    "CHANGED" where a variant changed it, "converged" where every variant agreed, else "not
    compared") with ``verdicts``, one text per variant."""
    out: dict[str, dict[str, Any]] = {}
    refine = _plan_file(store, "refine.json")
    plan = refine or _plan_file(store, "precision.json")
    which = min if refine is not None else max  # the round that added it, or seeded it last
    for rnd in (plan or {}).get("rounds") or []:
        if not isinstance(rnd, dict) or not isinstance(rnd.get("round"), int):
            continue
        for run in rnd.get("runs") or []:
            if isinstance(run, dict) and isinstance(run.get("coords"), dict):
                mark = out.setdefault(point_key(run["coords"]), {})
                mark["round"] = which(mark.get("round", rnd["round"]), rnd["round"])
    for p in (plan or {}).get("points") or []:
        if isinstance(p, dict) and isinstance(p.get("coords"), dict) and p.get("decision"):
            out.setdefault(point_key(p["coords"]), {})["decision"] = str(p["decision"])
    _verdict_marks(store, out)
    return out


def _verdict_marks(store: CampaignStore, out: dict[str, dict[str, Any]]) -> None:
    from ..verify.summary import CHANGED, CONVERGED, VERDICT_TEXT, read_verify

    try:
        ds = read_verify(store.root)
    except (OSError, ValueError):
        return
    if ds is None or "converged" not in ds or "point" not in ds.dims:
        return
    axes = [str(c) for c in ds.coords if ds[c].dims == ("point",) and str(c) != "point"]
    axes = [a for a in axes if np.issubdtype(ds[a].dtype, np.number)]
    names = [str(v) for v in ds["variant_name"].values]
    for p in range(ds.sizes["point"]):
        codes = [int(c) for c in np.asarray(ds["converged"].values[p])]
        verdict = (
            "CHANGED"
            if CHANGED in codes
            else "converged"
            if codes and all(c == CONVERGED for c in codes)
            else "not compared"
        )
        key = point_key({a: float(ds[a].values[p]) for a in axes})
        out.setdefault(key, {}).update(
            verdict=verdict,
            verdicts=[
                f"{n}: {VERDICT_TEXT.get(c, '?')}" for n, c in zip(names, codes, strict=True)
            ],
        )


def verification(store: CampaignStore) -> dict[str, Any] | None:
    """The verification's summary and verdicts (``verify.nc``), or ``None``."""
    from ..verify.summary import read_verify, summary_line, verdict_rows

    try:
        ds = read_verify(store.root)
    except (OSError, ValueError) as e:
        return {"summary": f"verify.nc cannot be read: {e}", "rows": []}
    if ds is None:
        return None
    return {"summary": summary_line(ds), "rows": verdict_rows(ds)}


def not_started(name: str) -> dict[str, Any]:
    """The page of a queued campaign that has no results folder yet."""
    return {
        "name": name,
        "readable": False,
        "dims": [],
        "shown": shown().name,
        "confidence": CONFIDENCE,
        "total": 0,
        "counts": {"ok": 0, "failed": 0, "pending": 0},
        "points": [],
        "failures": [],
        "cost": {"runs": 0, "cpu_seconds": 0.0},
        "rounds": None,
        "verification": None,
    }


def _series_names(ds: Any, size: int) -> list[str]:
    """The series the run view sends of the run file ``ds``: the first :data:`MAX_SERIES`
    observables of its model (the file's ``model`` attribute; the default model's) that it
    holds over its time; any of its series over time where the model is not registered here."""
    try:
        names = [o.name for o in get_model(str(ds.attrs.get("model", DEFAULT_MODEL))).observables]
    except UnknownModel:  # a model named by its module: every series it holds
        names = [str(k) for k in ds.data_vars]
    found = [n for n in names if n in ds and ds[n].ndim == 1 and ds[n].size == size]
    return found[:MAX_SERIES]


def run_detail(store: CampaignStore, run_id: str) -> dict[str, Any]:
    """One run: its record and its time series (thinned to :data:`MAX_SERIES_POINTS`)."""
    import xarray as xr

    from ..files import series_time

    if not safe_name(run_id):
        raise NotFound(f"no run {run_id!r}")
    record = store.read_record(run_id)
    if record is None:
        raise NotFound(f"no run {run_id!r} in campaign {store.root.name}")
    path = store.nc_path(run_id)
    series: dict[str, list[float | None]] = {}
    t: list[float | None] = []
    if path.exists() and inside(store.results_root, path):
        with xr.open_dataset(path) as ds:
            time = np.asarray(series_time(ds).values, dtype=float)
            step = max(1, math.ceil(time.size / MAX_SERIES_POINTS))
            t = [_finite(v) for v in time[::step]]
            for name in _series_names(ds, time.size):
                series[name] = [_finite(v) for v in np.asarray(ds[name].values)[::step]]
    keep = (
        "run_id",
        "status",
        "reason",
        "detail",
        "t_failed",
        "seed",
        "wall_time",
        "scalars",
        "finished",
        "coords",
        "continued_from",
        "lineage",
    )
    return {
        "campaign": store.root.name,
        "record": {k: record.get(k) for k in keep if k in record},
        "t": t,
        "series": series,
    }
