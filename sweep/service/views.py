"""What the API and the dashboard show of a campaign, read from its results folder (the run
records are the source of truth): its points with the seed mean of the shown observable and
its 95 % interval (Student t), its failures with their reasons, its cost so far, its rounds
(``refine.json``, ``precision.json``) and verification verdicts (``verify.nc``), and one run's
time series. Every name that reaches the disk is checked first (:func:`campaign_store`)."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..campaign import DEFAULT_MODEL, Campaign
from ..errors import CampaignError
from ..expand import Expansion
from ..models.interface import Observable, classifier
from ..models.registry import get_model
from ..store import CampaignStore, Record
from .security import inside, safe_name


def shown(model: str = DEFAULT_MODEL) -> Observable:
    """The observable the phase diagram shows: the one that classifies the model's points
    (the nematic model's sigma2_S, as the report's ``report.phase_plot.SHOWN``)."""
    return classifier(get_model(model))


#: The confidence of a point's interval.
CONFIDENCE = 0.95
#: Series of a run file the run view sends (those present).
SERIES = ("sigma2_S", "mean_S", "cos2theta", "lambda")
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


def load_stored(store: CampaignStore) -> Campaign | None:
    from ..outputs.stored import stored_campaign

    try:
        return stored_campaign(store)
    except CampaignError:
        return None


def expansion_of(campaign: Campaign, store: CampaignStore) -> Expansion:
    from ..refine.rounds import expansion_for

    return expansion_for(campaign, store)


def _interval(values: list[float]) -> tuple[float, float, float]:
    """Mean and the ends of its :data:`CONFIDENCE` Student-t interval (NaN ends below two
    values)."""
    from scipy.stats import t as student

    x = np.asarray([v for v in values if math.isfinite(v)], dtype=float)
    if x.size == 0:
        return math.nan, math.nan, math.nan
    mean = float(x.mean())
    if x.size < 2:
        return mean, math.nan, math.nan
    half = float(student.ppf(0.5 + CONFIDENCE / 2, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size))
    return mean, mean - half, mean + half


def _finite(x: Any) -> float | None:
    return float(x) if isinstance(x, (int, float)) and math.isfinite(x) else None


def _plain(value: Any) -> Any:
    if isinstance(value, (np.floating, float)):
        return _finite(float(value))
    if isinstance(value, np.integer):
        return int(value)
    return value if isinstance(value, (int, str, bool)) or value is None else str(value)


def points(expansion: Expansion, records: Mapping[str, Record]) -> list[dict[str, Any]]:
    """One entry per grid point: its swept values, its runs (id, seed, status, value), the
    seed mean of the :func:`shown` observable and its interval, counts by status."""
    scalar = shown(expansion.campaign.model).scalar
    by_point: dict[tuple[int, ...], dict[str, Any]] = {}
    for run in expansion:
        entry = by_point.setdefault(
            run.point.index,
            {
                "coords": {k: _plain(v) for k, v in run.point.coords.items()},
                "runs": [],
                "ok": 0,
                "failed": 0,
                "pending": 0,
            },
        )
        rec = records.get(run.run_id)
        status = "pending" if rec is None else str(rec.get("status"))
        value = None if rec is None else _finite((rec.get("scalars") or {}).get(scalar))
        entry["runs"].append(
            {"run_id": run.run_id, "seed": run.seed, "status": status, "value": value}
        )
        entry[status if status in ("ok", "failed") else "pending"] += 1
    out = []
    for entry in by_point.values():
        values = [
            r["value"] for r in entry["runs"] if r["status"] == "ok" and r["value"] is not None
        ]
        mean, low, high = _interval(values)
        entry.update(mean=_finite(mean), low=_finite(low), high=_finite(high), n=len(values))
        out.append(entry)
    return out


def failures(expansion: Expansion, records: Mapping[str, Record]) -> list[dict[str, Any]]:
    out = []
    for run in expansion:
        rec = records.get(run.run_id)
        if rec is None or rec.get("status") == "ok":
            continue
        detail = str(rec.get("detail") or "").strip().splitlines()
        out.append(
            {
                "run_id": run.run_id,
                "coords": {k: _plain(v) for k, v in run.coords.items()},
                "reason": str(rec.get("reason") or "unknown"),
                "t_failed": _finite(rec.get("t_failed")),
                "detail": detail[-1] if detail else "",
            }
        )
    return out


def cost_so_far(expansion: Expansion, records: Mapping[str, Record]) -> dict[str, Any]:
    times = [
        float(t)
        for run in expansion
        if (rec := records.get(run.run_id)) is not None
        and (t := _finite(rec.get("wall_time"))) is not None
    ]
    return {"runs": len(times), "cpu_seconds": float(sum(times))}


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


def campaign_detail(store: CampaignStore) -> dict[str, Any]:
    """Everything the campaign's page shows but the queue's view of it."""
    campaign = load_stored(store)
    if campaign is None:
        return not_started(store.root.name)
    records = store.scan(save=False)
    expansion = expansion_of(campaign, store)
    pts = points(expansion, records)
    counts = {s: sum(p[s] for p in pts) for s in ("ok", "failed", "pending")}
    return {
        "name": campaign.name,
        "readable": True,
        "description": campaign.description,
        "dims": [d.name for d in campaign.dims],
        "shown": shown(campaign.model).name,
        "confidence": CONFIDENCE,
        "total": len(expansion),
        "counts": counts,
        "points": pts,
        "failures": failures(expansion, records),
        "cost": cost_so_far(expansion, records),
        "rounds": rounds(store),
        "verification": verification(store),
    }


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
            for name in SERIES:
                if name in ds and ds[name].ndim == 1 and ds[name].size == time.size:
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
