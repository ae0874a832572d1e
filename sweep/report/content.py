"""What the report says, gathered from a campaign's results folder: the summary (question,
grid, seeds, counts), the fits and figures that failed, the figures, the fits as tables, the
failed runs by reason, the refinement rounds, the cost and the provenance. Plain data for
:mod:`.page`; nothing here writes a file."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from html import escape
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import xarray as xr

from ..analysis.fits_file import FITS
from ..figures.common import FIGURES
from ..figures.failed import read_failed
from ..names import symbol, unit
from ..outputs.status import StatusReport

if TYPE_CHECKING:
    from ..outputs.tables import CampaignResults

#: Failed runs listed under each reason (the count is always complete).
MAX_FAILED_LISTED = 50
#: Rows of one fits table (a fit over a long axis is cut, saying so).
MAX_FIT_ROWS = 200
HISTOGRAM_BINS = 20


@dataclass
class Table:
    """A titled table of strings."""

    title: str
    columns: list[str]
    rows: list[list[str]]
    note: str = ""


@dataclass
class Content:
    """Everything the page shows but the interactive phase diagram."""

    name: str
    description: str
    axes: list[tuple[str, str]]
    seeds: str
    counts: dict[str, int]
    #: the line that says which done runs other campaigns made ("" if none)
    reused: str = ""
    figures: list[tuple[str, str]] = field(default_factory=list)
    #: the fits and figures that failed when last produced: (product, why)
    product_failures: list[tuple[str, str]] = field(default_factory=list)
    fits: list[Table] = field(default_factory=list)
    failures: list[dict[str, Any]] = field(default_factory=list)
    refine: dict[str, Any] | None = None
    verification: dict[str, Any] | None = None
    cost: dict[str, Any] = field(default_factory=dict)
    provenance: list[tuple[str, str]] = field(default_factory=list)
    campaign_yaml: str = ""


def fmt(value: Any) -> str:
    """A value for a table cell: numbers to 4 significant digits, NaN as a dash."""
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return "-" if not math.isfinite(value) else f"{float(value):.4g}"
    return str(value)


def _values(values: Any, limit: int = 12) -> str:
    shown = [fmt(v) for v in list(values)[:limit]]
    more = f", ... ({len(values)} values)" if len(values) > limit else ""
    return ", ".join(shown) + more


def summary(opened: CampaignResults, status: StatusReport) -> Content:
    """The page's head: the campaign's question (its description), grid, seeds and counts."""
    c = opened.campaign
    axes = []
    for d in c.dims:
        for a in d.axes:
            zipped = f" (zipped with {symbol(d.name)})" if a.name != d.name else ""
            shown = symbol(a.name)
            named = f"{shown} ({a.name})" if shown != a.name else a.name
            axes.append((f"{named}{zipped}", _values(a.values)))
    return Content(
        name=c.name,
        description=" ".join((c.description or "").split()),
        axes=axes,
        seeds=f"{len(c.seeds)}: {_values(c.seeds)}",
        counts={
            "runs": status.total,
            "done": status.done,
            "failed": status.failed,
            "pending": status.pending,
        },
        reused=_reuse_text(status.reused),
    )


def _reuse_text(counts: dict[str, int]) -> str:
    """``4 of the done runs were made by campaign first (taken in place)``, or ""."""
    if not counts:
        return ""
    parts = ", ".join(f"{n} by {name}" for name, n in sorted(counts.items()))
    return f"{sum(counts.values())} of the done runs were made by other campaigns: {parts}"


def figure_images(root: Path) -> list[tuple[str, str]]:
    """The campaign's figures (``figures/*.png``) as (name, data URI), sorted by name."""
    import base64

    out = []
    for path in sorted((root / FIGURES).glob("*.png")):
        data = base64.b64encode(path.read_bytes()).decode("ascii")
        out.append((path.stem, f"data:image/png;base64,{data}"))
    return out


def _unit(var: xr.DataArray) -> str:
    units = var.attrs.get("units")
    return "" if not units or units == "1" else f" [{units}]"


#: fit variables that are a place on (or a width along) the fit's axis: the axis' units
PLACES = ("_location", "_loop_width")


def units_text(var: xr.DataArray) -> str:
    """A fit variable's units for the fits table: its CF units, or for the model's pure numbers
    (units "1") the scale of the axis it is a place on (sweep/names.py: ``L``, ``τ``), else
    "1 (pure number)"; "" when the variable has no units."""
    units = str(var.attrs.get("units") or "")
    if units != "1":
        return units
    axis = str(var.attrs.get("fit_axis", "")) if str(var.name).endswith(PLACES) else ""
    return (unit(axis) if axis else "") or "1 (pure number)"


#: each fit variable -> the variables of its interval (``None``: it has none)
Ends = dict[str, tuple[str, str] | None]


def _interval_ends(name: str, names: list[str]) -> tuple[str, str] | None:
    """The variables that hold ``name``'s interval: ``X_lower`` and ``X_upper``, or for a
    ``P_location`` the ``P_lower`` and ``P_upper`` of its fit."""
    for base in (name, name.removesuffix("_location") if name.endswith("_location") else None):
        if base and f"{base}_lower" in names and f"{base}_upper" in names:
            return f"{base}_lower", f"{base}_upper"
    return None


def _value(fits: xr.Dataset, name: str, ends: tuple[str, str] | None, at: Any = None) -> str:
    """A value with its interval (``0.25 [0.1, 0.4]``) at ``at`` (an isel, or a scalar)."""

    def get(n: str) -> Any:
        var = fits[n] if at is None else fits[n].isel(at)
        return var.values.item()

    text = fmt(get(name))
    if ends is not None and text != "-":
        text += f" [{fmt(get(ends[0]))}, {fmt(get(ends[1]))}]"
    return text


def _fit_groups(fits: xr.Dataset) -> dict[tuple[str, tuple[str, ...]], list[str]]:
    """The variables of ``fits.nc`` by (fit, dims): the variables of one table."""
    groups: dict[tuple[str, tuple[str, ...]], list[str]] = {}
    for name, var in fits.data_vars.items():
        fit = str(var.attrs.get("fit", str(name).split("_")[0]))
        groups.setdefault((fit, tuple(str(d) for d in var.dims)), []).append(str(name))
    return groups


def _scalar_fit_table(fits: xr.Dataset, fit: str, shown: list[str], pairs: Ends) -> Table:
    """A scalar fit's table: one row per variable (its value and interval, or why it has
    none; its units and long name)."""
    rows = []
    for n in shown:
        value = _value(fits, n, pairs[n])
        why = str(fits[n].attrs.get("nan_reason") or "")
        rows.append(
            [
                n,
                f"no value: {why}" if value == "-" and why else value,
                units_text(fits[n]),
                str(fits[n].attrs.get("long_name") or ""),
            ]
        )
    return Table(title=fit, rows=rows, columns=["variable", "value [interval]", "units", "meaning"])


def _swept_fit_table(
    fits: xr.Dataset, fit: str, dims: tuple[str, ...], shown: list[str], pairs: Ends
) -> Table:
    """A fit over sweep values' table: one row per coordinate value (the first
    :data:`MAX_FIT_ROWS`), a column per variable; the long names and the reasons of NaN
    values in its note."""
    headers = [f"{symbol(d)}{_unit(fits[d])}" if d in fits.coords else d for d in dims]
    headers += [f"{n}{_unit(fits[n])}" for n in shown]
    rows = []
    size = int(np.prod([fits.sizes[d] for d in dims]))
    for index in list(np.ndindex(*[fits.sizes[d] for d in dims]))[:MAX_FIT_ROWS]:
        at = dict(zip(dims, index, strict=True))
        row = [fmt(fits[d].values[i]) if d in fits.coords else str(i) for d, i in at.items()]
        row += [_value(fits, n, pairs[n], at) for n in shown]
        rows.append(row)
    meanings = "; ".join(
        f"{n}: {fits[n].attrs['long_name']}" for n in shown if fits[n].attrs.get("long_name")
    )
    reasons = list(
        dict.fromkeys(
            str(fits[n].attrs["nan_reason"]) for n in shown if fits[n].attrs.get("nan_reason")
        )
    )
    why = f" No value ('-') where: {'; '.join(reasons)}." if reasons else ""
    cut = f"the first {MAX_FIT_ROWS} of {size} rows. " if size > MAX_FIT_ROWS else ""
    return Table(
        title=f"{fit} over {', '.join(symbol(d) for d in dims)}",
        columns=headers,
        rows=rows,
        note=cut + meanings + why,
    )


def fit_tables(fits: xr.Dataset) -> list[Table]:
    """``fits.nc`` as tables: one per fit and set of dims. A scalar fit is one row per
    variable (its value, interval, units and long name; a NaN value gives the fit's reason,
    its ``nan_reason``); a fit over sweep values is one row per coordinate value, a column per
    variable (its name and units; the long names, and where a value is NaN why, in the table's
    note). An interval (``X_lower``, ``X_upper``; for ``P_location``, ``P_lower`` and
    ``P_upper``) stands with its value: ``0.25 [0.1, 0.4]``."""
    tables = []
    for (fit, dims), names in _fit_groups(fits).items():
        pairs = {n: _interval_ends(n, names) for n in names}
        ends = {e for pair in pairs.values() if pair for e in pair}
        shown = [n for n in names if n not in ends]
        if dims:
            tables.append(_swept_fit_table(fits, fit, dims, shown, pairs))
        else:
            tables.append(_scalar_fit_table(fits, fit, shown, pairs))
    return tables


def failure_groups(status: StatusReport, phase: xr.Dataset) -> list[dict[str, Any]]:
    """The failures by reason, most frequent first: the count, the first run (status's
    failure group: where its record and traceback are) and the failed runs, each with its
    swept values and seed."""
    from ..outputs.tables import runs_table

    table = runs_table(phase)
    failed = table[table["status"] == "failed"]
    axes = [
        c
        for c in table.columns
        if c not in ("seed", "run_id", "status", "reason") and c in phase.coords
    ]
    out = []
    for group in status.failure_groups:
        rows = failed[failed["reason"] == group["reason"]]
        runs = [
            (", ".join(f"{a}={fmt(r[a])}" for a in axes), int(r["seed"]), str(r["run_id"]))
            for _, r in rows.head(MAX_FAILED_LISTED).iterrows()
        ]
        detail = str(group.get("detail") or "").strip().splitlines()
        out.append(
            {
                "reason": group["reason"],
                "count": group["count"],
                "detail": detail[-1] if detail else "",
                "record": group["record"],
                "t_failed": fmt(group.get("t_failed")),
                "runs": runs,
                "more": max(0, len(rows) - MAX_FAILED_LISTED),
            }
        )
    return out


def refine_rounds(plan: Mapping[str, Any] | None) -> dict[str, Any] | None:
    """An adaptive campaign's rounds from ``refine.json``: per round its runs, new points and
    why each point was run."""
    if not plan or not isinstance(plan.get("rounds"), list):
        return None
    rounds: list[dict[str, Any]] = []
    for rnd in plan["rounds"]:
        runs = rnd.get("runs") or []
        points: dict[str, dict[str, Any]] = {}
        for r in runs:
            where = ", ".join(f"{k}={fmt(v)}" for k, v in (r.get("coords") or {}).items())
            entry = points.setdefault(
                where, {"where": where, "seeds": [], "why": r.get("why"), "states": []}
            )
            entry["seeds"].append(str(r.get("seed")))
            entry["states"].append(str(r.get("state")))
        rounds.append(
            {
                "number": rnd.get("round", len(rounds)),
                "n_runs": len(runs),
                "points": list(points.values()),
            }
        )
    return {
        "rounds": rounds,
        "finished": bool(plan.get("finished")),
        "stop": plan.get("stop") or "",
        "run_bound": plan.get("run_bound"),
    }


def verification(root: Path) -> dict[str, Any] | None:
    """The verification's summary, verdicts and transitions from ``verify.nc`` (``None``
    without one; a note when it cannot be read)."""
    from ..verify.summary import read_verify, summary_line, transition_rows, verdict_rows

    try:
        ds = read_verify(root)
    except (OSError, ValueError) as e:
        return {
            "summary": f"verify.nc cannot be read: {e}",
            "rows": [],
            "transitions": [],
            "seeds": "",
            "threshold": math.nan,
        }
    if ds is None:
        return None
    return {
        "summary": summary_line(ds),
        "rows": verdict_rows(ds),
        "transitions": transition_rows(ds),
        "seeds": str(ds.attrs.get("seeds", "")),
        "threshold": float(ds.attrs.get("threshold", math.nan)),
    }


def cost(records: Mapping[str, Mapping[str, Any]], run_ids: set[str]) -> dict[str, Any]:
    """CPU time: the sum of the campaign's runs' wall times (one core each), their median,
    and a small histogram of them (an SVG data URI)."""
    times = np.array(
        [
            float(r["wall_time"])
            for rid, r in records.items()
            if rid in run_ids
            and isinstance(r.get("wall_time"), (int, float))
            and math.isfinite(r["wall_time"])
        ]
    )
    if not times.size:
        return {"n": 0}
    return {
        "n": int(times.size),
        "cpu_hours": float(times.sum() / 3600),
        "total_seconds": float(times.sum()),
        "median": float(np.median(times)),
        "min": float(times.min()),
        "max": float(times.max()),
        "histogram": histogram_svg(
            times, min(HISTOGRAM_BINS, max(1, times.size)), "wall time of a run [s]"
        ),
    }


def histogram_svg(values: np.ndarray, bins: int, label: str) -> str:
    """A small histogram of ``values`` as an SVG data URI: bars, the count axis (0 and the
    largest count) and the value axis (its two ends and middle) under ``label``. Written
    out here: matplotlib is not imported for it."""
    import base64

    counts, edges = np.histogram(values, bins=bins)
    width, height, left, right, top, bottom = 360, 200, 42, 12, 10, 40
    plot_w, plot_h = width - left - right, height - top - bottom
    most = max(int(counts.max()), 1)
    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
        'font-family="sans-serif" font-size="10">',
        f'<rect x="{left}" y="{top}" width="{plot_w}" height="{plot_h}" fill="none" '
        'stroke="#888"/>',
    ]
    step = plot_w / len(counts)
    for i, count in enumerate(counts):
        h = plot_h * int(count) / most
        parts.append(
            f'<rect x="{left + i * step + 0.5:.1f}" y="{top + plot_h - h:.1f}" '
            f'width="{max(step - 1.0, 0.5):.1f}" height="{h:.1f}" fill="#1f77b4"/>'
        )
    base = top + plot_h
    for x, value in (
        (left, edges[0]),
        (left + plot_w / 2, (edges[0] + edges[-1]) / 2),
        (left + plot_w, edges[-1]),
    ):
        parts.append(
            f'<text x="{x:.1f}" y="{base + 13}" text-anchor="middle">{float(value):.3g}</text>'
        )
    parts += [
        f'<text x="{left - 4}" y="{base + 3}" text-anchor="end">0</text>',
        f'<text x="{left - 4}" y="{top + 8}" text-anchor="end">{most}</text>',
        f'<text x="{left + plot_w / 2:.1f}" y="{height - 6}" text-anchor="middle">'
        f"{escape(label)}</text>",
        f'<text x="12" y="{top + plot_h / 2:.1f}" text-anchor="middle" '
        f'transform="rotate(-90 12 {top + plot_h / 2:.1f})">runs</text>',
        "</svg>",
    ]
    data = base64.b64encode("".join(parts).encode("utf-8")).decode("ascii")
    return f"data:image/svg+xml;base64,{data}"


def provenance(phase: xr.Dataset, root: Path) -> tuple[list[tuple[str, str]], str]:
    """(label, value) rows of where the results came from (the aggregating code and the
    runs' code, library versions), and the campaign copy ``campaign.yaml`` as text."""
    from ..provenance import code_version, git_commit, library_versions_text

    a = phase.attrs
    rows = [
        ("runs made by code version(s)", str(a.get("run_code_versions") or "-")),
        ("runs made at git commit(s)", str(a.get("run_git_commits") or "-")),
        ("report made by code version", code_version()),
        ("report made at git commit", str(git_commit() or "-")),
        ("library versions", library_versions_text()),
    ]
    fixed = [
        f"{k[len('param_') :]}={fmt(v)}"
        for k, v in a.items()
        if k.startswith("param_") and k != "param_protocol"
    ]
    numerics = [f"{k[len('num_') :]}={fmt(v)}" for k, v in a.items() if k.startswith("num_")]
    rows += [
        ("fixed parameters", ", ".join(fixed) or "-"),
        ("fixed numerics", ", ".join(numerics) or "-"),
    ]
    if a.get("param_protocol"):  # the functions of time (nematic_solids.model.protocol), as written
        rows.append(("time protocol", str(a["param_protocol"])))
    if a.get("chain_axis"):
        rows.append(
            (
                "chain",
                f"along {a['chain_axis']} on the branches {a.get('chain_branches', '')}: each "
                "point's runs begin from the previous point's end state (same seed)",
            )
        )
    if a.get("campaign_overrides"):
        rows.append(("command-line overrides", str(a["campaign_overrides"])))
    copy = root / "campaign.yaml"
    text = copy.read_text(encoding="utf-8") if copy.is_file() else str(a.get("campaign_yaml") or "")
    return rows, text


def gather(
    opened: CampaignResults,
    phase: xr.Dataset,
    status: StatusReport,
    records: Mapping[str, Mapping[str, Any]],
) -> Content:
    """Every section of the page but the phase diagram."""
    from ..analysis.fits_file import load_fits
    from ..refine.rounds import read_plan

    root = opened.store.root
    content = summary(opened, status)
    content.figures = figure_images(root)
    content.product_failures = list(read_failed(root).items())
    fits = load_fits(root) if (root / FITS).is_file() else xr.Dataset()
    content.fits = fit_tables(fits)
    content.failures = failure_groups(status, phase)
    if opened.campaign.refine is not None:
        content.refine = refine_rounds(read_plan(opened.store))
    content.verification = verification(root)
    ids = {str(r) for r in np.asarray(phase["run_id"].values).ravel() if r}
    content.cost = cost(records, ids)
    content.provenance, content.campaign_yaml = provenance(phase, root)
    return content
