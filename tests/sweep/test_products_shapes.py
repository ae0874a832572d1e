"""Every registered figure and fit against every shape of campaign the validator accepts: one,
two and three axes, chains (over one axis and over two), protocols (an oscillatory shear, a
switch-off), a zip, an adaptive grid, seeds by precision. On each shape each product either is
produced without a failure, or the validator refuses the campaign that asks for it, at the
file:line of its ``figures:`` or ``fits:`` entry. The results are real (the model at 16^2, t/tau
up to 2, built once per shape, through the campaign manager's Python API and, for the adaptive
and the precision campaigns, `nematic run`)."""

from __future__ import annotations

import re
from html.parser import HTMLParser
from pathlib import Path
from types import SimpleNamespace

import pytest
from typer.testing import CliRunner

from nematic_solids.sweep.analysis.registry import REGISTRY as FITS
from nematic_solids.sweep.chains import in_chain_order
from nematic_solids.sweep.cli import app
from nematic_solids.sweep.errors import CampaignError
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.figures import produce as produce_module
from nematic_solids.sweep.figures.produce import produce
from nematic_solids.sweep.figures.registry import REGISTRY as FIGURES
from nematic_solids.sweep.outputs.aggregate import write_phase
from nematic_solids.sweep.run.task import RunTask, execute_run
from nematic_solids.sweep.spec import parse_campaign
from nematic_solids.sweep.store import CampaignStore

HEAD = """\
name: {name}
parameters: {{noise_modes: 7}}
numerics: {{resolution: 16, t_final: {t_final}, save_every: 0.25}}
seeds: 2
"""

#: name -> (the campaign's shape, t_final, whether it is run by `nematic run`)
SHAPES: dict[str, tuple[str, float, bool]] = {
    "one_axis": ("sweep: {axes: {alpha_minus_B: [0.1, 1.0]}}\n", 1.0, False),
    "two_axes": ("sweep: {axes: {K: [1.0e-4, 1.0e-3], alpha_minus_B: [0.1, 1.0]}}\n", 1.0, False),
    "three_axes": (
        "sweep: {axes: {chi: [2.0, 10.0], K: [1.0e-4, 1.0e-3], eps: [0.0, 0.05]}}\n",
        1.0,
        False,
    ),
    "chain": (
        "sweep: {axes: {alpha_minus_B: [0.1, 0.5, 1.0]}}\nchain: {axis: alpha_minus_B}\n",
        1.0,
        False,
    ),
    "chain_two_axes": (
        "sweep: {axes: {K: [5.0e-5, 2.0e-4], alpha_minus_B: [0.0, 0.4, 1.0]}}\n"
        "chain: {axis: alpha_minus_B, branches: [up, down]}\n",
        1.0,
        False,
    ),
    "oscillatory": (
        "protocol: {eps: {sine: {start: 0.5}}}\n"
        "sweep: {axes: {alpha_minus_B: [0.1, 1.0], eps_amplitude: [0.01], eps_period: [2.0]}}\n",
        5.0,
        False,
    ),
    "switch_off": (
        "protocol: {alpha_minus_B: {pulse: {base: 1.0, start: 0.5}}}\n"
        "sweep: {axes: {alpha_minus_B_level: [0.0, 0.4], alpha_minus_B_duration: [0.5, 1.0]}}\n",
        2.0,
        False,
    ),
    "zip": (
        "sweep: {axes: {alpha_minus_B: [0.1, 1.0], chi: [5.0, 10.0]}, "
        "zip: [[alpha_minus_B, chi]]}\n",
        1.0,
        False,
    ),
    "adaptive": (
        "sweep: {axes: {alpha_minus_B: [0.1, 0.5, 1.0]}}\n"
        "refine: {axis: alpha_minus_B, observable: sigma2_S, criterion: jump, jump: 1.01, "
        "rounds: 1, min_spacing: 0.05}\n"
        "execution: {workers: 1}\n",
        1.0,
        True,
    ),
    "precision": (
        "sweep: {axes: {alpha_minus_B: [0.1, 1.0]}}\n"
        "precision: {observable: sigma2_S, width: 0.01, initial: 2, add: 1}\n"
        "execution: {workers: 1}\n",
        1.0,
        True,
    ),
}


def text_of(shape: str) -> str:
    body, t_final, _ = SHAPES[shape]
    return HEAD.format(name=shape, t_final=t_final) + body


def build(folder: Path, shape: str) -> SimpleNamespace:
    """The shape's campaign run for real and aggregated, without fits or figures."""
    folder.mkdir(parents=True, exist_ok=True)
    text = text_of(shape) + "figures: []\n"
    path = folder / f"{shape}.yaml"
    path.write_text(text)
    results = folder / "results"
    if SHAPES[shape][2]:
        r = CliRunner().invoke(app, ["run", str(path), "--results", str(results), "--quiet"])
        assert r.exit_code == 0, r.output
    else:
        campaign = parse_campaign(text, source=str(path))
        store = CampaignStore(results, campaign.name)
        store.ensure()
        e = expand(campaign)
        for i in in_chain_order(range(len(e)), e.chain_parents):
            execute_run(RunTask.from_spec(e.run(i), store, campaign.name, campaign.store))
        write_phase(e, store)
    return SimpleNamespace(folder=folder, results=results)


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    cache: dict[str, SimpleNamespace] = {}

    def get(shape: str) -> SimpleNamespace:
        if shape not in cache:
            cache[shape] = build(tmp_path_factory.mktemp(shape), shape)
        return cache[shape]

    return get


def produced_or_refused(built, shape: str, kind: str, name: str, monkeypatch) -> str:
    """``"refused"`` (the validator's error names the product's file:line) or ``"produced"``
    (no failure); anything else fails the test."""
    text = text_of(shape) + (
        f"figures: [{name}]\nfits: []\n" if kind == "figures" else f"fits: [{name}]\nfigures: []\n"
    )
    line = (
        text.splitlines().index(f"figures: [{name}]" if kind == "figures" else f"fits: [{name}]")
        + 1
    )
    try:
        campaign = parse_campaign(text, source="shape.yaml")
    except CampaignError as e:
        refusal = str(e)
    else:
        refusal = ""
    if refusal:
        assert re.search(rf"shape\.yaml:{line}\b", refusal), refusal
        return "refused"
    b = built(shape)
    # drawn whole, saved small: a PNG at 40 dpi (the formats are test_figures.py's)
    monkeypatch.setattr(produce_module, "FORMATS", ("png",))
    monkeypatch.setattr(produce_module, "PNG_DPI", 40)
    out = produce(campaign, b.results)
    assert not out.failures, out.failures
    if kind == "figures":
        assert [p.name for p in out.paths] == [f"{name}.png"]
    else:
        assert out.fits_path is not None
    return "produced"


#: the shapes run by `nematic run` (a dask cluster per campaign: tens of seconds)
SLOW = {"adaptive", "precision"}


@pytest.mark.parametrize(
    "shape", [pytest.param(s, marks=pytest.mark.slow) if s in SLOW else s for s in SHAPES]
)
def test_every_product_is_produced_or_refused_at_its_line(built, shape, monkeypatch):
    outcome = {
        f"{kind} {name}": produced_or_refused(built, shape, kind, name, monkeypatch)
        for kind, registry in (("figures", FIGURES), ("fits", FITS))
        for name in registry
    }
    assert "produced" in outcome.values()


class _FailedProducts(HTMLParser):
    """The report's "Products that failed" section: whether its heading is there, and the
    cells of its table's rows."""

    def __init__(self) -> None:
        super().__init__()
        self.heading = False
        self.rows: list[list[str]] = []
        self._in_table = self._in_cell = False

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.heading |= a.get("id") == "product-failures"
        if tag == "table":
            self._in_table = a.get("class") == "product-failures"
        elif self._in_table and tag == "tr":
            self.rows.append([])
        elif self._in_table and tag == "td":
            self._in_cell = True
            self.rows[-1].append("")

    def handle_endtag(self, tag):
        self._in_cell &= tag != "td"
        self._in_table &= tag != "table"

    def handle_data(self, data):
        if self._in_cell:
            self.rows[-1][-1] += data


def failed_products_in(report: Path) -> list[tuple[str, str]]:
    """The rows of the report's "Products that failed" table (none: the section is absent)."""
    parser = _FailedProducts()
    parser.feed(report.read_text(encoding="utf-8"))
    rows = [(r[0], " ".join(r[1].split())) for r in parser.rows if r]
    assert parser.heading == bool(rows)
    return rows


def test_a_product_that_fails_fails_the_run_and_figures_in_one_line(tmp_path):
    """Every run succeeds, but the figures cannot be written (a file where their folder goes):
    `nematic run` and `nematic figures` name the figure in one line each and exit 4, not 0,
    and the report names it with the same reason; once it is drawn (`nematic figures` rewrites
    the report), the report names none."""
    path = tmp_path / "one.yaml"
    path.write_text(text_of("one_axis") + "figures: [fig2]\nexecution: {workers: 1}\n")
    results = tmp_path / "results"
    root = results / "one_axis"
    root.mkdir(parents=True)
    (root / "figures").write_text("not a folder")
    runner = CliRunner()
    r = runner.invoke(app, ["run", str(path), "--results", str(results)])
    assert r.exit_code == 4, r.output
    lines = [ln for ln in r.output.splitlines() if ln.startswith("failed: figure fig2: ")]
    assert len(lines) == 1, r.output
    assert "Traceback" not in r.output
    assert "every run succeeded, but 1 fit(s) or figure(s) failed" in " ".join(r.output.split())
    assert (root / "phase.nc").is_file()  # the runs are kept
    why = lines[0].removeprefix("failed: figure fig2: ")
    assert failed_products_in(root / "report.html") == [("figure fig2", why)]
    r = runner.invoke(app, ["figures", str(path), "--results", str(results)])
    assert r.exit_code == 4, r.output
    assert len([ln for ln in r.output.splitlines() if ln.startswith("failed: figure fig2: ")]) == 1
    (root / "figures").unlink()
    r = runner.invoke(app, ["figures", str(path), "--results", str(results)])
    assert r.exit_code == 0, r.output
    assert not (root / "failed_products.json").exists()
    assert failed_products_in(root / "report.html") == []  # nematic figures rewrote it
    assert '<img alt="fig2"' in (root / "report.html").read_text(encoding="utf-8")


def test_the_failed_products_record_keeps_what_was_not_produced_again(tmp_path):
    """failed_products.json after each products step: what was produced again is replaced (all
    the fits when fits.nc is rewritten; the figures drawn), the rest kept; none left, no file."""
    from nematic_solids.sweep.figures.failed import FAILED_PRODUCTS, read_failed, record_failed

    record_failed(
        tmp_path, {"fit transition": "a", "loop": "b", "fig2": "c"}, fits=True, figures=None
    )
    assert read_failed(tmp_path) == {
        "figure fig2": "c",
        "figure loop": "b",
        "fit transition": "a",
    }
    record_failed(tmp_path, {}, fits=False, figures=["loop"])  # --only loop, --no-fits
    assert read_failed(tmp_path) == {"figure fig2": "c", "fit transition": "a"}
    record_failed(tmp_path, {"fig3": "d"}, fits=True, figures=[])  # the fits alone
    assert read_failed(tmp_path) == {"figure fig2": "c", "figure fig3": "d"}
    record_failed(tmp_path, {}, fits=True, figures=None)
    assert read_failed(tmp_path) == {}
    assert not (tmp_path / FAILED_PRODUCTS).exists()
