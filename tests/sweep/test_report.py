"""``nematic report``: the page of a real tiny adaptive campaign with failures lists every
failure reason, failed run, refinement round and verification verdict, is self-contained,
and is rewritten by ``nematic report`` from the campaign's name; the pieces (fit tables,
hover texts) from small data. The page in a real browser: tests/sweep/test_report_browser.py."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from sweep_helpers import cli_modules, outside_references
from typer.testing import CliRunner

from nematic_solids.sweep.cli import app
from nematic_solids.sweep.refine.rounds import read_plan
from nematic_solids.sweep.report.content import fit_tables
from nematic_solids.sweep.report.phase_plot import point_columns
from nematic_solids.sweep.store import CampaignStore

#: 3 x 2 grid points, one seed; alpha - B = 20 fails at once (the finite solver loses
#: ellipticity: tests/sweep_helpers.py), and one round refines alpha - B between 0.1 and 0.2.
ADAPTIVE = """\
name: rep
description: a tiny grid whose report must list its failures and rounds
parameters: {noise_modes: 8}
numerics: {resolution: 32, t_final: 2, save_every: 0.5, snapshot_times: [1]}
sweep:
  axes:
    alpha_minus_B: [0.1, 0.2, 20.0]
    K: [1.0e-4, 1.0e-3]
seeds: 1
figures: []
refine:
  axis: alpha_minus_B
  observable: sigma2_S
  criterion: jump
  jump: 1.01
  rounds: 1
  min_spacing: 0.05
verify:
  seeds: 1
  variants:
    - tolerance: /10
execution: {workers: 2}
"""


ROOT = Path(__file__).resolve().parents[2]


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def adaptive(tmp_path_factory):
    folder = tmp_path_factory.mktemp("report")
    path = folder / "rep.yaml"
    path.write_text(ADAPTIVE)
    results = folder / "results"
    result = invoke("run", path, "--results", results, "--no-dashboard")
    return path, results, result


def _records(results: Path) -> list[dict]:
    return [json.loads(p.read_text()) for p in (results / "rep" / "runs").glob("*.json")]


def test_run_writes_a_report_listing_every_failure_and_round(adaptive):
    _, results, result = adaptive
    assert result.exit_code == 1, result.output  # the alpha - B = 20 runs failed
    page = results / "rep" / "report.html"
    assert f"report: {page}" in " ".join(result.output.split())
    html = page.read_text()
    assert "a tiny grid whose report must list its failures and rounds" in html
    failed = [r for r in _records(results) if r["status"] != "ok"]
    assert len(failed) == 2
    reasons = {r["reason"] for r in failed}
    for reason in reasons:
        count = sum(r["reason"] == reason for r in failed)
        assert f'<h3 class="failure-reason">{reason}: {count} run(s)</h3>' in html
    for r in failed:
        assert f"<td>{r['run_id']}</td>" in html
    plan = read_plan(CampaignStore(results, "rep"))
    assert plan is not None
    assert len(plan["rounds"]) == 2  # the grid and one refined round
    for rnd in plan["rounds"]:
        assert f'<h3 class="refine-round">round {rnd["round"]}: {len(rnd["runs"])} run(s)' in html
    assert "boundary: alpha_minus_B 0.1" in html  # why round 1 ran its points
    assert "8: 6 done, 2 failed, 0 pending" in " ".join(html.split())
    # the verification: the grid's 4 corners under one variant, the failed ones missing
    assert '<h2 id="verification">' in html
    assert "of 4 sampled points converged (2 with runs missing)" in html
    assert html.count("<td>tolerance /10</td>") == 4
    assert "<td>missing</td>" in html


def test_the_report_is_self_contained(adaptive):
    _, results, _ = adaptive
    html = (results / "rep" / "report.html").read_text()
    assert not re.search(r"<script[^>]*\ssrc=", html)  # bokeh's JavaScript is inlined
    assert "Bokeh" in html
    markup = re.sub(r"<script[^>]*>.*?</script>", "", html, flags=re.S)  # the page's own tags
    assert not re.search(r"<link[^>]*href=", markup)
    assert not re.search(r"""(src|href)=["']?(https?:|//)""", markup)
    # one snapshot per grid point that has a run to show, and the histogram of run times
    assert html.count("data:image/png;base64,") >= 6
    assert '<img alt="run time histogram" src="data:image/svg+xml;base64,' in html
    assert '<h2 id="refine">' in html
    assert "(seed mean)" in html


def test_the_report_references_nothing_outside_itself(adaptive):
    _, results, _ = adaptive
    html = (results / "rep" / "report.html").read_text()
    assert "Bokeh" in html  # bokeh's code is in the page: its strings are not references
    assert outside_references(html) == []


def test_the_committed_result_pages_reference_nothing_outside_themselves():
    pages = sorted((ROOT / "docs" / "results").glob("*/report.html"))
    assert pages
    for page in pages:
        assert outside_references(page.read_text()) == [], page


def test_the_offline_check_finds_what_a_page_would_fetch():
    from bokeh.embed import file_html
    from bokeh.plotting import figure
    from bokeh.resources import CDN

    fig = figure()
    fig.scatter([1, 2], [3, 4])
    # bokeh's page with its JavaScript from its CDN: the check must see those
    found = outside_references(file_html(fig, CDN))
    assert found
    assert all("cdn.bokeh.org" in f for f in found)
    for snippet in (
        '<link rel="stylesheet" href="https://example.org/a.css">',
        '<script src="http://example.org/a.js"></script>',
        "<img src=//example.org/a.png>",
        '<script>import("https://example.org/m.js")</script>',
        '<script type="module">import {a} from "https://example.org/m.js"</script>',
        '<style>@import "https://example.org/a.css";</style>',
        '<div style="background: url(https://example.org/a.png)"></div>',
        '<meta http-equiv="refresh" content="0; url=https://example.org/">',
    ):
        assert outside_references(snippet), snippet
    local = '<a href="../one/report.html"><img src="figures/fig2.png"></a><img src="data:,">'
    assert outside_references(local) == []


def test_a_tex_label_brings_bokehs_own_mathjax_into_the_page():
    """A label with TeX would need MathJax: bokeh's bundle of it (bokeh-mathjax) is inlined
    with the rest, no CDN (it renders offline: tests/sweep/test_report_browser.py)."""
    from bokeh.plotting import figure

    from nematic_solids.sweep.report.page import inline_resources

    plain, tex = figure(x_axis_label="alpha - B"), figure(x_axis_label=r"$$\alpha - B$$")
    for fig in (plain, tex):
        fig.scatter([1, 2], [3, 4])
    without, with_math = inline_resources(plain), inline_resources(tex)
    assert len(with_math) > len(without) + 10**6  # MathJax's ~1.8 MB
    assert outside_references(f"<html><head>{with_math}</head></html>") == []


def test_nematic_report_from_the_name_and_to_an_output(adaptive, tmp_path):
    _, results, _ = adaptive
    page = results / "rep" / "report.html"
    page.unlink()
    result = invoke("report", "rep", "--results", results)
    assert result.exit_code == 0, result.output
    assert page.is_file()
    out = tmp_path / "elsewhere" / "r.html"
    result = invoke("report", "rep", "--results", results, "--output", out)
    assert result.exit_code == 0, result.output
    assert "round 1:" in out.read_text()
    assert not list(out.parent.glob(".*.tmp"))  # written through a temporary, renamed


def test_the_runs_views_are_cached_by_run_file(adaptive, monkeypatch):
    from nematic_solids.sweep.report import run_views as views

    _, results, _ = adaptive
    cache = results / "rep" / views.CACHE
    cached = sorted(cache.glob("*.json"), key=lambda p: "data:image" not in p.read_text())
    assert len(cached) >= 6  # written with the report at the end of the run
    path = results / "rep" / "runs" / f"{cached[0].stem}.nc"
    kept = cached[0].read_text()
    first = views.run_views(path, "sigma2_S")
    assert first[0].startswith("data:image/png;base64,")

    def no_drawing(path, series):
        raise AssertionError(f"{path} drawn again")

    monkeypatch.setattr(views, "draw_run_views", no_drawing)
    assert views.run_views(path, "sigma2_S") == first  # from the cache
    drawn = []

    def drawing(path, series):
        drawn.append(path)
        return "", [1.0], [2.0]

    monkeypatch.setattr(views, "draw_run_views", drawing)
    cached[0].write_text("{not json")
    assert views.run_views(path, "sigma2_S") == (
        "",
        [1.0],
        [2.0],
    )  # an unreadable cache file: redrawn
    data = json.loads(cached[0].read_text())
    data["stamp"][-1] += 1  # another file (an older mtime): redrawn
    cached[0].write_text(json.dumps(data))
    views.run_views(path, "sigma2_S")
    assert views.run_views(path, "mean_S")[1:] == ([1.0], [2.0])  # another series: drawn
    assert drawn == [path, path, path]
    cached[0].write_text(kept)


def test_report_and_status_import_only_what_they_need(adaptive, tmp_path):
    """Once the run's views are cached (the run wrote its report), ``nematic report``
    imports neither numba, the model's compiled code, dask's arrays and cluster, nor
    matplotlib; ``status`` reads no netCDF: no xarray, no pandas (benchmarks/report_time.py
    measures the times)."""
    path, results, _ = adaptive
    modules, out = cli_modules(
        "report", "rep", "--results", results, "--output", tmp_path / "r.html"
    )
    assert "wrote" in out, out
    for heavy in (
        "numba",
        "nematic_solids.model.compiled",
        "distributed",
        "dask.array",
        "matplotlib",
    ):
        assert heavy not in modules, heavy
    modules, out = cli_modules("status", path, "--results", results)
    assert "6 done" in out, out
    for heavy in ("xarray", "pandas", "numba", "distributed", "matplotlib", "bokeh"):
        assert heavy not in modules, heavy


def test_nematic_report_of_an_unknown_campaign_is_one_error_line(tmp_path):
    result = invoke("report", "nothing", "--results", tmp_path)
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("error: no results of a campaign named 'nothing'")


def test_fit_tables_put_intervals_with_their_values_and_label_units():
    fits = xr.Dataset(
        {
            "transition_location": (
                (),
                0.35,
                {"long_name": "transition location", "fit": "transition"},
            ),
            "transition_location_lower": ((), 0.3, {"fit": "transition"}),
            "transition_location_upper": ((), 0.4, {"fit": "transition"}),
            "alpha_cr": (
                ("K",),
                [0.1, np.nan],
                {"long_name": "critical activity", "units": "1", "fit": "alpha_cr"},
            ),
            "alpha_cr_lower": (("K",), [0.05, np.nan], {"fit": "alpha_cr"}),
            "alpha_cr_upper": (("K",), [0.2, np.nan], {"fit": "alpha_cr"}),
            "wall": (("K",), [3.0, 4.0], {"units": "s", "fit": "alpha_cr"}),
        },
        coords={"K": ("K", [1e-4, 1e-3], {"units": "1"})},
    )
    tables = {t.title: t for t in fit_tables(fits)}
    scalar = tables["transition"]
    assert scalar.columns == ["variable", "value [interval]", "units", "meaning"]
    assert scalar.rows == [["transition_location", "0.35 [0.3, 0.4]", "", "transition location"]]
    over_k = tables["alpha_cr over K"]
    assert over_k.columns == ["K", "alpha_cr", "wall [s]"]
    assert over_k.rows == [["0.0001", "0.1 [0.05, 0.2]", "3"], ["0.001", "-", "4"]]
    assert "alpha_cr: critical activity" in over_k.note


def test_the_fits_table_gives_the_loop_width_its_interval_units_and_why_it_is_nan():
    """A chain's transition fit (tests/sweep/test_fits.py's two branches, the up one without a
    jump): per branch the location with its interval (transition_lower/upper), the NaN one's
    reason in the note; the loop width a row saying why it is NaN; with both jumps, its value
    and interval, and the units of alpha - B (a pure number)."""
    from nematic_solids.sweep.analysis.transition import transition

    x = np.array([0.0, 1.0, 2.0])
    values = np.array(
        [
            [[1e-14, 1e-14], [1e-14, 1e-3], [1e-14, 1e-2]],
            [[1e-14, 1e-14], [1e-3, 1e-3], [1e-2, 1e-2]],
        ]
    )
    n = values.shape
    phase = xr.Dataset(
        {"sigma2_S": (("branch", "alpha_minus_B", "seed"), values)},
        coords={"branch": ["up", "down"], "alpha_minus_B": x, "seed": [0, 1]},
    )
    phase["status"] = (("branch", "alpha_minus_B", "seed"), np.ones(n, dtype=int))
    fits = transition(phase, {"axis": "alpha_minus_B", "crossing": 1e-6, "n_boot": 50})
    for v in fits.data_vars.values():
        v.attrs["fit"] = "transition"
    tables = {t.title: t for t in fit_tables(fits)}
    per_branch = tables["transition over branch"]
    assert per_branch.columns[:2] == ["branch", "transition_location"]
    assert per_branch.rows[0][:2] == ["up", "-"]
    assert per_branch.rows[1][:2] == ["down", "0.5 [0, 1]"]
    assert "No value ('-') where: branch = up: the geometric seed mean" in per_branch.note
    (width,) = [r for r in tables["transition"].rows if r[0] == "transition_loop_width"]
    assert width[1].startswith("no value: no transition on a branch: branch = up:")
    assert width[2] == "1 (pure number)"
    both = transition(phase, {"axis": "alpha_minus_B", "mean": "arithmetic", "n_boot": 50})
    for v in both.data_vars.values():
        v.attrs["fit"] = "transition"
    (width,) = [r for r in fit_tables(both)[-1].rows if r[0] == "transition_loop_width"]
    w = float(both.transition_loop_width)
    lo, hi = float(both.transition_loop_width_lower), float(both.transition_loop_width_upper)
    assert width[1] == f"{w:.4g} [{lo:.4g}, {hi:.4g}]"


def test_hover_texts_give_each_seed_and_skip_points_not_run(tmp_path):
    phase = xr.Dataset(
        {
            "status": (("eps", "seed"), [[1, 2], [0, 0]]),
            "run_id": (("eps", "seed"), [["a", "b"], ["c", "d"]]),
            "sigma2_S": (("eps", "seed"), [[1e-3, np.nan], [np.nan, np.nan]]),
        },
        coords={"eps": [0.1, 0.2], "seed": [3, 7]},
    )
    cols = point_columns(phase, tmp_path, ["eps"])  # no run files: hover only
    assert cols["eps"] == ["0.1"]  # eps = 0.2 has no run
    assert cols["seeds_sigma2_S"] == ["3: 0.001, 7: failed"]
    assert cols["counts"] == ["1 ok, 1 failed of 2 seeds"]
    assert cols["shown"] == [pytest.approx(1e-3)]
    assert cols["snapshot"] == [""]
    assert cols["run_id"] == ["a"]


def test_axes_spanning_a_decade_of_positive_values_are_logarithmic():
    from nematic_solids.sweep.report.phase_plot import Axis

    phase = xr.Dataset(
        coords={
            "K": [1e-4, 1e-3],
            "chi": [0.0, 5.0, 10.0],
            "amb": [0.1, 0.3, 0.7],
            "S0": [1.0, 10.0, 100.0],
        }
    )
    assert Axis.of(phase, "K").log  # a decade (K logspaced)
    assert Axis.of(phase, "S0").log
    assert not Axis.of(phase, "chi").log  # zero
    assert not Axis.of(phase, "amb").log  # less than a decade


def _phase(shape: dict[str, list], seeds: int = 1) -> xr.Dataset:
    dims = [*shape, "seed"]
    size = [len(v) for v in shape.values()] + [seeds]
    n = int(np.prod(size))
    return xr.Dataset(
        {
            "status": (dims, np.ones(size, dtype=int)),
            "run_id": (dims, np.array([f"r{i}" for i in range(n)]).reshape(size)),
            "sigma2_S": (dims, np.linspace(1e-4, 1e-2, n).reshape(size)),
        },
        coords={**shape, "seed": list(range(seeds))},
    )


def _plots(layout) -> list:
    from bokeh.models import Plot

    return [m for m in layout.select({"type": Plot}) if m.name == "phase_diagram"]


def test_one_two_and_more_dims_give_a_line_a_scatter_and_facets(tmp_path):
    from nematic_solids.sweep.report.phase_plot import MAX_FACETS, phase_layout

    layout, embedded, notes = phase_layout(_phase({"alpha_minus_B": [0.1, 0.3, 0.5]}), tmp_path)
    (plot,) = _plots(layout)
    assert plot.xaxis[0].axis_label == "α − B"  # symbols: sweep/names.py
    assert plot.yaxis[0].axis_label == "σ²_S (seed mean)"
    assert embedded == 0  # no run files here
    assert notes[0] == (
        "0 of 3 points show a run when clicked (at most 200; a run that failed "
        "at once may leave nothing to show)"
    )
    # 2-D with a text axis: its values become tick labels at 0, 1
    layout, _, _ = phase_layout(
        _phase({"alpha_minus_B": [0.1, 0.3], "mechanics": ["linear", "finite"]}), tmp_path
    )
    (plot,) = _plots(layout)
    assert plot.yaxis[0].major_label_overrides == {0: "linear", 1: "finite"}
    source = layout.select_one({"name": "points"})
    assert sorted(zip(source.data["x"], source.data["y"], strict=True)) == [
        (0.1, 0.0),
        (0.1, 1.0),
        (0.3, 0.0),
        (0.3, 1.0),
    ]
    # 4-D: the first two dims, one facet per combination of the others, at most MAX_FACETS
    layout, _, notes = phase_layout(
        _phase(
            {
                "alpha_minus_B": [0.1, 0.3],
                "K": [1e-4, 1e-3],
                "eps": [0.0, 0.1, 0.2],
                "chi": [1.0, 2.0, 3.0, 4.0],
            }
        ),
        tmp_path,
    )
    plots = _plots(layout)
    assert len(plots) == MAX_FACETS < 12
    shown = {p.title.text for p in plots}
    assert shown == {f"ε = {e}, χ = {c}" for e in ("0", "0.1") for c in (1, 2, 3, 4)} | {
        "ε = 0.2, χ = 1"
    }  # in the grid's order, chi varying fastest
    assert f"12 combinations of ε, χ: the first {MAX_FACETS} are shown" in notes


def test_a_chain_has_its_axis_on_x_and_its_branches_as_lines_or_facets(tmp_path):
    """A chain's phase diagram (dims branch, K, alpha - B in phase.nc): the chain's axis on x;
    over one axis the branches are two lines of one plot; over two, K is the y axis (log: it
    spans a decade) and the branches are facets titled with the branch."""
    from nematic_solids.sweep.report.phase_plot import phase_layout, plot_dims

    one = _phase({"branch": ["up", "down"], "alpha_minus_B": [0.1, 0.5, 1.0]})
    one.attrs["chain_axis"] = "alpha_minus_B"
    assert plot_dims(one) == ("alpha_minus_B", None, ["branch"])
    layout, _, _ = phase_layout(one, tmp_path)
    (plot,) = _plots(layout)
    assert plot.xaxis[0].axis_label == "α − B"
    assert [item.label["value"] for item in plot.legend[0].items] == [
        "branch = up",
        "branch = down",
    ]
    two = _phase({"branch": ["up", "down"], "K": [1e-4, 1e-3], "alpha_minus_B": [0.1, 0.5, 1.0]})
    two.attrs["chain_axis"] = "alpha_minus_B"
    assert plot_dims(two) == ("alpha_minus_B", "K", ["branch"])
    layout, _, _ = phase_layout(two, tmp_path)
    plots = _plots(layout)
    assert sorted(p.title.text for p in plots) == ["branch = down", "branch = up"]
    assert {p.xaxis[0].axis_label for p in plots} == {"α − B"}
    assert {p.yaxis[0].axis_label for p in plots} == {"K"}
    assert all(p.y_scale.__class__.__name__ == "LogScale" for p in plots)
