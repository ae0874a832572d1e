"""The report's interactive phase diagram (bokeh): one point per grid point that has runs,
coloured (2-D) or placed (1-D) by the seed mean of the model's classifying observable
(:class:`Shown`; sigma2_S for the paper's model). Hovering a point shows its
parameters and the seed values of the main observables; clicking it shows one of its runs:
its last snapshot (a small PNG, embedded as a data URI) and that observable's series (drawn, and
cached, by :mod:`.run_views`), through a bokeh ``CustomJS`` callback that copies the point's
columns into the run panel.

The x axis is the chain's axis (a ``chain:`` campaign), else the first sweep axis; the y axis
the next (numeric) one; the other dims (a chain's branch among them) are facets, at most
:data:`MAX_FACETS`, as many in a row as fit the page (they stretch to its width). With one
axis besides the facets, the facets are lines in one plot (a chain's two branches: its loop).
An axis whose values are all positive and span a decade or more (:data:`LOG_AXIS_RATIO`: K,
swept as a logspace) is logarithmic. Axes and titles carry the symbols of sweep/names.py."""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from ..analysis.phase import sweep_dims
from ..campaign import BRANCH, DEFAULT_MODEL
from ..models.interface import classifier
from ..models.registry import get_model
from ..names import label, symbol
from .run_views import run_views

log = logging.getLogger(__name__)

#: The observables whose seed values the hover shows: the shown one and the model's next.
HOVERED = 5


@dataclass(frozen=True)
class Shown:
    """What the diagram shows of a campaign's model: ``observable``, whose seed mean is a
    point's colour (2-D) or height (1-D) and whose series the run panel draws (the model's
    classifying observable), and ``hover``, the observables whose seed values the hover
    lists."""

    observable: str
    hover: tuple[str, ...]

    @classmethod
    def of(cls, phase: xr.Dataset) -> Shown:
        """From the model phase.nc names (``model`` attribute; the default model's)."""
        model = get_model(str(phase.attrs.get("model", DEFAULT_MODEL)))
        main = classifier(model).name
        others = [o.name for o in model.observables if o.name != main]
        return cls(main, (main, *others[: HOVERED - 1]))


#: Points whose run (snapshot and series) is embedded; the others show their hover only.
MAX_POINTS_WITH_RUNS = 200
#: Facets of a campaign with more than two sweep dims.
MAX_FACETS = 9
#: Facets side by side at most (they stretch to share the page's width; 4 facets: 2 x 2).
FACETS_PER_ROW = 3
#: The colours of the lines of a plot over one axis, one per facet (a chain's branches).
LINE_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b")
#: A numeric axis is logarithmic when its values are positive and max / min is at least this.
LOG_AXIS_RATIO = 10.0
STATUS_OK, STATUS_FAILED = 1, 2
#: The tools of the phase diagram's plots.
TOOLS = "pan,wheel_zoom,box_zoom,reset,save"
HINT = "<p>Click a point of the phase diagram to show one of its runs here.</p>"

#: The one piece of page code: copy the clicked point's run into the run panel.
ON_TAP = """
const i = source.selected.indices[0];
if (i === undefined) { return; }
const d = source.data;
series.data = {t: d.series_t[i], y: d.series_y[i]};
run_plot.title.text = d.run_title[i];
const img = d.snapshot[i] ? `<img class="snapshot" alt="snapshot of ${d.run_id[i]}" ` +
    `src="${d.snapshot[i]}">` : "<p>no snapshot stored for this run</p>";
panel.text = `<div class="run" data-run="${d.run_id[i]}">${img}` +
    `<p>${d.where[i]}, seed ${d.run_seed[i]}: run ${d.run_id[i]}</p></div>`;
"""


def _label(value: Any) -> str:
    if isinstance(value, (float, np.floating)):
        return f"{float(value):.6g}"
    return str(value)


def _numeric(values: np.ndarray) -> bool:
    return np.issubdtype(np.asarray(values).dtype, np.number)


@dataclass
class Axis:
    """A plotted sweep dim: positions (numeric values, else indices with tick labels)."""

    name: str
    values: np.ndarray
    log: bool = False
    ticks: dict[int, str] = field(default_factory=dict)

    @classmethod
    def of(cls, phase: xr.Dataset, dim: str) -> Axis:
        values = np.asarray(phase[dim].values)
        if not _numeric(values):
            return cls(
                dim,
                np.arange(len(values), dtype=float),
                ticks={i: str(v) for i, v in enumerate(values)},
            )
        v = values.astype(float)
        finite = v[np.isfinite(v)]
        log = bool(
            finite.size > 1 and finite.min() > 0 and finite.max() / finite.min() >= LOG_AXIS_RATIO
        )
        return cls(dim, v, log=log)


def _seed_text(values: np.ndarray, seeds: np.ndarray, status: np.ndarray) -> str:
    parts = []
    for s, v, st in zip(seeds, values, status, strict=True):
        if st == STATUS_OK and np.isfinite(v):
            parts.append(f"{s}: {v:.3g}")
        elif st == STATUS_FAILED:
            parts.append(f"{s}: failed")
    return ", ".join(parts) or "-"


def plot_dims(phase: xr.Dataset) -> tuple[str, str | None, list[str]]:
    """The dims of the phase diagram: ``(x, y or None, facets)``. x: the chain's axis, else
    the first sweep dim that is not a chain's branch; y: the next such dim; facets: the rest."""
    dims = sweep_dims(phase)
    chain = str(phase.attrs.get("chain_axis", ""))
    axes = [d for d in dims if d != BRANCH]
    x = chain if chain in dims else (axes[0] if axes else dims[0])
    y = next((d for d in axes if d != x), None)
    return x, y, [d for d in dims if d not in (x, y)]


def point_columns(
    phase: xr.Dataset, runs_dir: Path, dims: list[str], facets: list[str] | None = None
) -> dict[str, list[Any]]:
    """The points' columns for bokeh: coordinates, hover texts, the seed mean shown, and one
    run of each point (the first seed that succeeded, else the first with a run file).
    ``facets``: the dims whose values name a point's facet (default: ``dims[2:]``)."""
    facet_dims = dims[2:] if facets is None else facets
    shown_of = Shown.of(phase)
    shape = [phase.sizes[d] for d in dims]
    n_seeds = phase.sizes["seed"]
    seeds = phase["seed"].values

    def per_point(name: str) -> np.ndarray:
        return np.asarray(phase[name].transpose(*dims, "seed").values).reshape(-1, n_seeds)

    status = per_point("status").astype(int)
    run_ids = per_point("run_id")
    observables = {m: per_point(m).astype(float) for m in shown_of.hover if m in phase}
    shown = observables.get(shown_of.observable)
    grids = (
        np.asarray(phase["resolution"].transpose(*dims).values).reshape(-1)
        if "resolution" in phase.data_vars
        else None
    )
    extra = {
        str(c): str(phase[c].dims[0])
        for c in phase.coords
        if phase[c].ndim == 1 and phase[c].dims[0] in dims and str(c) not in dims
    }
    cols = _empty_columns(dims, observables)
    embedded = 0
    for flat, index in enumerate(np.ndindex(*shape)):
        st = status[flat]
        if not (st > 0).any():  # not run (a refined campaign's union grid)
            continue
        _add_place(cols, phase, dict(zip(dims, index, strict=True)), extra, facet_dims)
        grid = f" on {int(grids[flat])}^2" if grids is not None else ""  # resolution: auto
        cols["counts"].append(
            f"{int((st == STATUS_OK).sum())} ok, "
            f"{int((st == STATUS_FAILED).sum())} failed of {len(st)} seeds{grid}"
        )
        for m, values in observables.items():
            cols[f"seeds_{m}"].append(_seed_text(values[flat], seeds, st))
        mean = _seed_mean(st, None if shown is None else shown[flat])
        cols["shown"].append(mean)
        cols["shown_log"].append(math.log10(mean) if mean > 0 else math.nan)
        order = [k for k in range(n_seeds) if st[k] == STATUS_OK] + [
            k for k in range(n_seeds) if st[k] == STATUS_FAILED
        ]
        run = (
            _embedded_run(runs_dir, run_ids[flat], order, shown_of.observable)
            if embedded < MAX_POINTS_WITH_RUNS
            else (None, "", [], [])
        )
        embedded += run[0] is not None
        _add_run(cols, run, order, st, run_ids[flat], seeds, shown_of.observable)
    return cols


def _empty_columns(dims: list[str], observables: Mapping[str, Any]) -> dict[str, list[Any]]:
    """The points' columns, empty: their names."""
    names = [
        *("where", "counts", "shown", "shown_log", "run_id", "run_seed", "run_title"),
        *("snapshot", "series_t", "series_y", "facet"),
        *dims,
        *(f"seeds_{m}" for m in observables),
    ]
    return {k: [] for k in names}


def _add_place(
    cols: dict[str, list[Any]],
    phase: xr.Dataset,
    at: dict[str, int],
    extra: Mapping[str, str],
    facet_dims: list[str],
) -> None:
    """Add where a point is (at the indices ``at`` of the dims): its value of each dim, its
    facet, and its coordinates as text (those of ``extra``, coordinate -> its dim, too)."""
    coords = {d: phase[d].values[i] for d, i in at.items()}
    coords.update({c: phase[c].values[at[d]] for c, d in extra.items()})
    for d in at:
        cols[d].append(_label(phase[d].values[at[d]]))
    cols["facet"].append(
        ", ".join(f"{symbol(d)} = {_label(phase[d].values[at[d]])}" for d in facet_dims)
    )
    cols["where"].append(", ".join(f"{symbol(str(k))} = {_label(v)}" for k, v in coords.items()))


def _seed_mean(status: np.ndarray, values: np.ndarray | None) -> float:
    """The mean of a point's ``values`` over its seeds that succeeded with a finite value
    (NaN without any)."""
    if values is None:
        return math.nan
    ok = (status == STATUS_OK) & np.isfinite(values)
    return float(np.mean(values[ok])) if ok.any() else math.nan


#: A point's run as its panel shows it: (the seed's index, or None for none), snapshot, series.
EmbeddedRun = tuple[int | None, str, list[float], list[float]]


def _embedded_run(runs_dir: Path, ids: np.ndarray, order: list[int], series: str) -> EmbeddedRun:
    """The first run of the seeds ``order`` whose file can be read, with its views."""
    for k in order:
        path = runs_dir / f"{ids[k]}.nc"
        if path.is_file():
            try:
                image, t, y = run_views(path, series)
            except (OSError, ValueError, KeyError) as e:
                log.warning("report: cannot read run file %s: %s", path, e)
                continue
            return k, image, t, y
    return None, "", [], []


def _add_run(
    cols: dict[str, list[Any]],
    run: EmbeddedRun,
    order: list[int],
    status: np.ndarray,
    ids: np.ndarray,
    seeds: np.ndarray,
    series: str,
) -> None:
    """Add a point's run: the one embedded, else its first seed in ``order``."""
    chosen, image, t, y = run
    k = chosen if chosen is not None else (order[0] if order else 0)
    state = "ok" if status[k] == STATUS_OK else "failed"
    cols["run_id"].append(str(ids[k]))
    cols["run_seed"].append(int(seeds[k]))
    cols["run_title"].append(
        f"{symbol(series)}(t): seed {int(seeds[k])} ({state})"
        if chosen is not None
        else "run not embedded"
    )
    cols["snapshot"].append(image)
    cols["series_t"].append(t)
    cols["series_y"].append(y)


def _figure(
    x: Axis, y: Axis | None, title: str, tools: str, shown: str, *, stretch: bool = False
) -> Any:
    from bokeh.models import FixedTicker
    from bokeh.plotting import figure

    fig = figure(
        title=title,
        width=520 if y is None else 440,
        height=380 if y is None else 340,
        tools=tools,
        name="phase_diagram",
        x_axis_type="log" if x.log else "linear",
        y_axis_type="log" if y is None or y.log else "linear",
        x_axis_label=label(x.name),
        y_axis_label=f"{label(shown)} (seed mean)" if y is None else label(y.name),
        sizing_mode="stretch_width" if stretch else "fixed",
    )
    for ax, axis in ((fig.xaxis, x), (fig.yaxis, y)):
        if axis is not None and axis.ticks:
            ax.ticker = FixedTicker(ticks=list(axis.ticks))
            ax.major_label_overrides = {k: v for k, v in axis.ticks.items()}
    return fig


def _position(axis: Axis, labels: list[str], phase: xr.Dataset) -> list[float]:
    lookup = {_label(v): axis.values[i] for i, v in enumerate(phase[axis.name].values)}
    return [float(lookup[s]) for s in labels]


def phase_layout(phase: xr.Dataset, runs_dir: Path) -> tuple[Any, int, list[str]]:
    """The interactive phase diagram of ``phase``: ``(bokeh layout or None, points with an
    embedded run, notes)``."""
    from bokeh.layouts import column, gridplot, row
    from bokeh.models import ColumnDataSource, CustomJS, HoverTool, TapTool

    if not sweep_dims(phase):
        return None, 0, ["no sweep axis: nothing to plot"]
    x_dim, y_dim, facet_dims = plot_dims(phase)
    dims = [x_dim, *([y_dim] if y_dim else []), *facet_dims]
    notes: list[str] = []
    cols = point_columns(phase, runs_dir, dims, facet_dims)
    if not cols["where"]:
        return None, 0, ["no run has finished yet"]
    embedded = sum(1 for s, t in zip(cols["snapshot"], cols["series_t"], strict=True) if s or t)
    if embedded < len(cols["where"]):
        notes.append(
            f"{embedded} of {len(cols['where'])} points show a run when clicked "
            f"(at most {MAX_POINTS_WITH_RUNS}; a run that failed at once may leave "
            "nothing to show)"
        )
    x_axis = Axis.of(phase, x_dim)
    y_axis = Axis.of(phase, y_dim) if y_dim else None
    cols["x"] = _position(x_axis, cols[x_dim], phase)
    cols["y"] = _position(y_axis, cols[y_dim], phase) if y_axis and y_dim else cols["shown"]
    source = ColumnDataSource(cols, name="points")
    shown_of = Shown.of(phase)
    tooltips = _tooltips(cols, dims, shown_of)
    facets = list(dict.fromkeys(cols["facet"]))
    if len(facets) > MAX_FACETS:
        notes.append(
            f"{len(facets)} combinations of {', '.join(symbol(d) for d in facet_dims)}: the "
            f"first {MAX_FACETS} are shown"
        )
        facets = facets[:MAX_FACETS]
    if y_axis is None:  # one plot, a line per facet (a chain's branches)
        plots, renderers = _line_plot(x_axis, facets, bool(facet_dims), cols, source, shown_of)
        notes.append("Click a point for one of its runs.")
    else:
        plots, renderers = _colour_plots(x_axis, y_axis, facets, cols, source, shown_of)
        notes.append(
            f"Colour: log10 of the seed mean of {symbol(shown_of.observable)} at t_final; red: no "
            "successful run. Click a point for one of its runs."
        )
    series, run_plot, panel = _run_panel(shown_of)
    for fig in plots:
        mine = [r for r in renderers if r in fig.renderers]
        fig.add_tools(HoverTool(renderers=mine, tooltips=tooltips), TapTool(renderers=mine))
    source.selected.js_on_change(
        "indices",
        CustomJS(
            args={"source": source, "series": series, "panel": panel, "run_plot": run_plot},
            code=ON_TAP,
        ),
    )
    if len(plots) == 1:
        diagram = plots[0]
    else:
        diagram = gridplot(
            plots,
            ncols=min(FACETS_PER_ROW, math.ceil(math.sqrt(len(plots)))),
            sizing_mode="stretch_width",
            merge_tools=False,
        )
    return column(diagram, row(panel, run_plot), sizing_mode="stretch_width"), embedded, notes


def _tooltips(cols: dict[str, list[Any]], dims: list[str], shown_of: Shown) -> list[Any]:
    """The hover of a point: its value of each dim (or its coordinates, when it has more),
    its runs and the seed values of the hovered observables."""
    tooltips = [(symbol(d), f"@{{{d}}}") for d in dims]
    if len(cols["where"][0].split(", ")) > len(dims):
        tooltips = [("point", "@where")]
    tooltips.append(("runs", "@counts"))
    tooltips += [
        (f"{symbol(m)} by seed", f"@{{seeds_{m}}}") for m in shown_of.hover if f"seeds_{m}" in cols
    ]
    return tooltips


def _line_plot(
    x_axis: Axis, facets: list[str], legend: bool, cols: Any, source: Any, shown_of: Shown
) -> tuple[list[Any], list[Any]]:
    """One plot over the x axis, a line per facet: ``([the plot], the points' renderers)``."""
    from bokeh.models import CDSView, GroupFilter

    title = f"{symbol(shown_of.observable)} at t_final over {symbol(x_axis.name)}"
    fig = _figure(x_axis, None, title, TOOLS, shown_of.observable, stretch=True)
    renderers = []
    for k, facet in enumerate(facets):
        colour = LINE_COLOURS[k % len(LINE_COLOURS)]
        rows = [i for i, f in enumerate(cols["facet"]) if f == facet]
        rows.sort(key=lambda i: cols["x"][i])
        fig.line(
            [cols["x"][i] for i in rows],
            [cols["y"][i] for i in rows],
            line_width=2,
            color=colour,
            **({"legend_label": facet} if facet else {}),
        )
        view = CDSView(filter=GroupFilter(column_name="facet", group=facet))
        renderers.append(
            fig.scatter(
                "x", "y", source=source, view=view, size=11, color=colour, name="phase_points"
            )
        )
    if legend:
        fig.legend.location = "top_left"
    return [fig], renderers


def _colour_plots(
    x_axis: Axis, y_axis: Axis, facets: list[str], cols: Any, source: Any, shown_of: Shown
) -> tuple[list[Any], list[Any]]:
    """A plot over the x and y axes per facet, its points coloured by the log10 of their
    seed mean (red: none): ``(the plots, the points' renderers)``."""
    from bokeh.models import CDSView, GroupFilter, LinearColorMapper
    from bokeh.models.annotations.legends import ColorBar

    finite = [v for v in cols["shown_log"] if math.isfinite(v)]
    low, high = (min(finite), max(finite)) if finite else (0.0, 1.0)
    mapper = LinearColorMapper(
        palette="Viridis256", low=low, high=high if high > low else low + 1, nan_color="#d62728"
    )
    plots, renderers = [], []
    for facet in facets:
        title = facet or f"log10 {symbol(shown_of.observable)} (seed mean)"
        fig = _figure(x_axis, y_axis, title, TOOLS, shown_of.observable, stretch=len(facets) > 1)
        view = CDSView(filter=GroupFilter(column_name="facet", group=facet))
        renderers.append(
            fig.scatter(
                "x",
                "y",
                source=source,
                view=view,
                size=16,
                line_color="black",
                fill_color={"field": "shown_log", "transform": mapper},
                name="phase_points",
            )
        )
        fig.add_layout(ColorBar(color_mapper=mapper, width=10), "right")
        plots.append(fig)
    return plots, renderers


def _run_panel(shown_of: Shown) -> tuple[Any, Any, Any]:
    """Where the clicked point's run shows: ``(the source of its series, the plot of the
    series, the panel of its snapshot)``."""
    from bokeh.models import ColumnDataSource
    from bokeh.models.widgets.markups import Div
    from bokeh.plotting import figure

    series = ColumnDataSource({"t": [], "y": []}, name="series")
    run_plot = figure(
        title=f"{symbol(shown_of.observable)}(t) of the clicked point's run",
        width=420,
        height=260,
        y_axis_type="log",
        x_axis_label=label("t"),
        y_axis_label=symbol(shown_of.observable),
        tools="pan,wheel_zoom,reset,save",
        name="run_plot",
    )
    run_plot.line("t", "y", source=series, line_width=2, color="#d62728")
    return series, run_plot, Div(text=HINT, width=420, name="run_panel")
