"""The report in a real browser (headless Chromium driven by selenium through the system
chromedriver: Debian's ``chromium`` and ``chromium-driver``, which .ci/run installs), on
the quickstart's own page (campaigns/quickstart.yaml scaled down) with the network blocked:
no request leaves the file (Chrome's log of every request it sent; a page that does fetch
is seen to), the phase diagram and the figures render without a severe console error, the
labels are the plain text intended, and clicking a point shows that point's run (its
snapshot image and sigma2_S(t)); a TeX label renders offline with bokeh's own MathJax
(:func:`nematic_solids.sweep.report.page.inline_resources`). Saves a screenshot of the page in the
test's temporary folder; with ``NEMATIC_UPDATE_SCREENSHOT=1`` in the environment it replaces
docs/figures/report_screenshot.png (a report with a point clicked) instead, so a plain test run
leaves the checkout unchanged.

Marked ``browser`` (run with ``pytest -m browser``; CI does); skipped, with the reason, where
Chromium, its driver or selenium is missing."""

from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml
from typer.testing import CliRunner

from nematic_solids.sweep.cli import app

pytestmark = pytest.mark.browser

ROOT = Path(__file__).resolve().parents[2]
SCREENSHOT = ROOT / "docs" / "figures" / "report_screenshot.png"
#: ``NEMATIC_UPDATE_SCREENSHOT=1``: the test's screenshot replaces :data:`SCREENSHOT`.
UPDATE_SCREENSHOT = "NEMATIC_UPDATE_SCREENSHOT"
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")

#: The quickstart (campaigns/quickstart.yaml) scaled down, its figures, axes and seeds kept:
#: 4 x 2 linear runs across the Fig. 2 transition at 32^2 to t = 4 (seconds, not minutes).
QUICKSTART = ROOT / "campaigns" / "quickstart.yaml"
SCALED = {"resolution": 32, "t_final": 4, "save_every": 0.5, "mechanics": "linear"}


def scaled_quickstart() -> str:
    spec = yaml.safe_load(QUICKSTART.read_text())
    spec["numerics"] = {**spec.get("numerics", {}), **SCALED}
    spec["parameters"] = {**spec.get("parameters", {}), "noise_modes": 8}
    return yaml.safe_dump(spec, sort_keys=False)


#: Finds a model's view by walking down from the document's root views (bokeh's own view
#: index holds only the roots); returns the clicked figure's points in page coordinates.
FIND = """
const doc = Bokeh.documents[0];
const named = (name) => [...doc.all_models].filter(m => m.name === name);
let roots = Bokeh.index.roots;
if (typeof roots === "function") { roots = roots.call(Bokeh.index); }
const find = (model) => {
  const queue = [...roots];
  while (queue.length) {
    const v = queue.shift();
    if (v.model === model) { return v; }
    for (const c of (v.child_views ?? [])) { queue.push(c); }
  }
  return null;
};
"""
POINTS = (
    FIND
    + """
const plot = find(named("phase_diagram")[0]);
const glyph = plot.renderer_views.get(named("phase_points")[0]).glyph;
const canvas = plot.canvas_view.el.getBoundingClientRect();
return {left: canvas.left, top: canvas.top, width: canvas.width, height: canvas.height,
        sx: Array.from(glyph.sx), sy: Array.from(glyph.sy),
        run_ids: named("points")[0].data.run_id};
"""
)
SHOWN = (
    FIND
    + """
const panel = find(named("run_panel")[0]);
const root = panel.shadow_el ?? panel.el.shadowRoot ?? panel.el;
const img = root.querySelector("img.snapshot");
const run = root.querySelector("div.run");
return {selected: named("points")[0].selected.indices,
        run: run ? run.dataset.run : null,
        image_width: img && img.complete ? img.naturalWidth : 0,
        series: named("series")[0].data.t.length};
"""
)
REQUESTS = """
return performance.getEntriesByType("resource").map(e => e.name)
  .filter(n => !n.startsWith("data:") && !n.startsWith("file:") && !n.startsWith("blob:"));
"""
#: The page's figures (PNG data URIs: the math of their labels is drawn by matplotlib).
FIGURES = """
return [...document.querySelectorAll(".figure img")]
  .map(i => [i.alt, i.complete ? i.naturalWidth : 0]);
"""
#: The axis labels of every plot of the page, and for a TeX one whether MathJax drew it.
LABELS = (
    FIND
    + """
const out = [];
const queue = [...roots];
while (queue.length) {
  const v = queue.shift();
  for (const c of (v.child_views ?? [])) { queue.push(c); }
  for (const r of (v.renderer_views?.values() ?? [])) { queue.push(r); }  // a plot's axes
  if (v.model.axis_label === undefined) { continue; }
  const label = v.model.axis_label;
  const shown = v._axis_label_view;
  out.push({text: String(label?.text ?? label), tex: shown?.provider !== undefined,
            mathjax: shown?.provider?.status ?? null, drawn: shown?.svg_image != null});
}
return out;
"""
)
#: What the browser is told to block: every request of a network scheme.
BLOCKED = ["http://*", "https://*", "ws://*", "wss://*", "ftp://*"]


def headless_chromium(window: str, bypass: str, blocked: list[str] | None = None):
    """Headless Chromium driven by selenium, with no network: a proxy that is not there for
    any host but ``bypass``, the requests in the performance log (Chrome's DevTools events),
    and ``blocked`` URL patterns refused. Skips where Chromium, its driver or selenium is
    missing. A generator for a fixture to yield from."""
    if CHROMIUM is None or CHROMEDRIVER is None:
        pytest.skip(
            "needs Chromium and its driver (Debian: apt-get install chromium "
            "chromium-driver; .ci/run installs them)"
        )
    webdriver = pytest.importorskip(
        "selenium.webdriver", reason="needs selenium (a test dependency: pip install selenium)"
    )
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        f"--window-size={window}",
        "--proxy-server=http://127.0.0.1:9",
        f"--proxy-bypass-list={bypass}",
    ):
        options.add_argument(arg)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL", "performance": "ALL"})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    try:
        driver.execute_cdp_cmd("Network.enable", {})
        if blocked:
            driver.execute_cdp_cmd("Network.setBlockedURLs", {"urls": blocked})
        yield driver
    finally:
        driver.quit()


@pytest.fixture(scope="module")
def browser():
    # no network but this machine, every request of a network scheme blocked
    yield from headless_chromium("1300,1050", "<-loopback>", BLOCKED)


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("browser")
    path = folder / "quickstart.yaml"
    path.write_text(scaled_quickstart())
    result = CliRunner().invoke(
        app, ["run", str(path), "--results", str(folder / "results"), "--no-dashboard"]
    )
    assert result.exit_code == 0, result.output
    page = folder / "results" / "quickstart" / "report.html"
    assert page.is_file(), result.output
    return page


def sent_requests(driver) -> list[str]:
    """The URLs of every request the browser sent since the last call (blocked or not)."""
    urls = []
    for entry in driver.get_log("performance"):
        message = json.loads(entry["message"])["message"]
        if message["method"] == "Network.requestWillBeSent":
            urls.append(message["params"]["request"]["url"])
    return urls


def outside(urls: list[str]) -> list[str]:
    return [u for u in urls if not u.startswith(("file:", "data:", "blob:"))]


def _wait(driver, script: str, ready, timeout: float = 30.0):
    """Poll ``script`` until ``ready(value)``; return the last value."""
    deadline = time.monotonic() + timeout
    value = None
    while time.monotonic() < deadline:
        try:
            value = driver.execute_script(script)
        except Exception:  # noqa: BLE001 - bokeh not loaded or not rendered yet
            value = None
        if value is not None and ready(value):
            return value
        time.sleep(0.2)
    return value


def screenshot_path(tmp_path: Path) -> Path:
    """docs/figures/report_screenshot.png when asked for (:data:`UPDATE_SCREENSHOT`), else a
    file in the test's temporary folder."""
    if os.environ.get(UPDATE_SCREENSHOT) == "1":
        return SCREENSHOT
    return tmp_path / SCREENSHOT.name


def test_the_screenshot_goes_to_the_docs_only_when_asked(tmp_path, monkeypatch):
    monkeypatch.delenv(UPDATE_SCREENSHOT, raising=False)
    assert screenshot_path(tmp_path) == tmp_path / "report_screenshot.png"
    monkeypatch.setenv(UPDATE_SCREENSHOT, "1")
    assert screenshot_path(tmp_path) == SCREENSHOT


def test_the_phase_diagram_renders_and_a_click_shows_the_points_run(browser, report, tmp_path):
    from selenium.webdriver.common.actions.action_builder import ActionBuilder

    browser.get(report.as_uri())
    points = _wait(browser, POINTS, lambda v: len(v["sx"]) == 4)
    assert points is not None, "the phase diagram did not render"
    assert len(points["sx"]) == 4  # one point per alpha - B value
    assert points["width"] > 100
    assert points["height"] > 100
    for sx, sy in zip(points["sx"], points["sy"], strict=True):
        assert 0 <= sx <= points["width"]
        assert 0 <= sy <= points["height"]
    before = browser.execute_script(SHOWN)
    assert before["run"] is None
    assert before["series"] == 0

    i = 2  # alpha - B = 0.5
    action = ActionBuilder(browser)
    action.pointer_action.move_to_location(
        int(points["left"] + points["sx"][i]), int(points["top"] + points["sy"][i])
    ).click()
    action.perform()
    shown = _wait(browser, SHOWN, lambda v: v["image_width"] > 0 and v["series"] > 0)
    assert shown["selected"] == [i]
    assert shown["run"] == points["run_ids"][i]
    assert shown["image_width"] > 50  # the snapshot PNG decoded
    assert shown["series"] > 2  # sigma2_S(t) of that run is drawn
    severe = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert severe == []
    assert browser.execute_script(REQUESTS) == []  # nothing came from the network
    target = screenshot_path(tmp_path)
    target.parent.mkdir(parents=True, exist_ok=True)
    assert browser.save_screenshot(str(target))


def test_the_quickstart_page_works_offline(browser, report):
    """The quickstart's own page with the network blocked: it renders, sends no request
    outside its file, its figures (whose math matplotlib drew) decode, and its plots' axis
    labels are the plain text intended (no TeX: nothing that needs MathJax)."""
    sent_requests(browser)  # the log so far, dropped
    browser.get(report.as_uri())
    points = _wait(browser, POINTS, lambda v: len(v["sx"]) == 4)
    assert points is not None, "the phase diagram did not render"
    figures = _wait(browser, FIGURES, lambda v: bool(v) and all(w > 0 for _, w in v))
    assert [name for name, _ in figures] == ["fig2"]
    assert all(width > 100 for _, width in figures)
    labels = browser.execute_script(LABELS)
    texts = {label["text"] for label in labels}
    assert {"α − B", "σ²_S (seed mean)", "t [τ]", "σ²_S"} <= texts  # sweep/names.py
    assert not any(label["tex"] for label in labels)
    urls = sent_requests(browser)
    assert report.as_uri() in urls  # the log sees the page's requests
    assert outside(urls) == []
    severe = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert severe == []


def test_a_request_to_the_network_would_be_seen(browser, tmp_path):
    """The check above can fail: a page that fetches from the network shows its requests
    (blocked) in the log."""
    page = tmp_path / "online.html"
    page.write_text(
        '<!DOCTYPE html><html><head><script src="https://example.org/a.js"></script></head>'
        '<body><img src="http://example.org/a.png" alt="a"></body></html>'
    )
    sent_requests(browser)
    browser.get(page.as_uri())
    _wait(browser, "return document.readyState", lambda v: v == "complete")
    wanted = {"https://example.org/a.js", "http://example.org/a.png"}
    seen: set[str] = set()
    deadline = time.monotonic() + 10
    while not wanted <= seen and time.monotonic() < deadline:
        seen |= set(outside(sent_requests(browser)))
        time.sleep(0.2)
    assert wanted <= seen
    browser.get_log("browser")  # its console errors (the blocked requests) are not ours


def test_tex_in_a_label_renders_offline_with_bokehs_own_mathjax(browser, tmp_path):
    """Were a label of the page TeX (``$$...$$``),
    :func:`nematic_solids.sweep.report.page.inline_resources` inlines bokeh's MathJax bundle, and
    the math is drawn without a network."""
    from bokeh.embed import components
    from bokeh.plotting import figure

    from nematic_solids.sweep.report.page import inline_resources

    fig = figure(x_axis_label=r"$$\alpha - B$$", y_axis_label="sigma2_S", width=400, height=300)
    fig.scatter([0.1, 0.3, 0.5], [1e-8, 1e-6, 1e-2])
    script, div = components(fig)
    page = tmp_path / "tex.html"
    page.write_text(
        f"<!DOCTYPE html><html><head>{inline_resources(fig)}</head>"
        f"<body>{div}{script}</body></html>"
    )
    sent_requests(browser)
    browser.get(page.as_uri())
    labels = _wait(browser, LABELS, lambda v: any(label["drawn"] for label in v), timeout=60)
    tex = [label for label in labels if label["tex"]]
    assert [label["text"] for label in tex] == [r"$$\alpha - B$$"]
    assert tex[0]["mathjax"] == "loaded"
    assert tex[0]["drawn"]  # MathJax's SVG of the label
    assert outside(sent_requests(browser)) == []
    severe = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert severe == []


#: A chain over three axes (K x chi x alpha - B, the chain along alpha - B, its up branch from
#: fresh textures): 48 grid positions, 40 runs at 32^2 to t/tau = 20.
CHAIN3 = """\
name: chain3
parameters: {noise_modes: 8}
numerics: {resolution: 32, t_final: 20, save_every: 1}
sweep:
  axes:
    K: [1.0e-5, 2.0e-4]
    chi: [5.0, 10.0]
    alpha_minus_B: [0.1, 0.4, 0.8]
chain: {axis: alpha_minus_B, up: fresh}
seeds: 2
fits: [{transition: {axis: alpha_minus_B, min_jump: 0.5}}]
execution: {workers: 2}
"""
#: Every phase-diagram plot's title: its text, the width it takes in the title's font, and
#: the width of the plot's frame it is drawn over.
TITLES = (
    FIND
    + """
const ctx = document.createElement("canvas").getContext("2d");
return named("phase_diagram").map(m => {
  const v = find(m);
  const t = m.title;
  ctx.font = `${t.text_font_style} ${t.text_font_size} ${t.text_font}`;
  return {text: t.text, needed: ctx.measureText(t.text).width,
          width: v ? v.frame.bbox.width : 0, x_label: String(m.below[0].axis_label)};
});
"""
)
SCROLL = "return [document.documentElement.scrollWidth, document.documentElement.clientWidth];"


@pytest.fixture(scope="module")
def chain_report(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("chain3")
    path = folder / "chain3.yaml"
    path.write_text(CHAIN3)
    result = CliRunner().invoke(
        app, ["run", str(path), "--results", str(folder / "results"), "--no-dashboard"]
    )
    assert result.exit_code == 0, result.output
    return folder / "results" / "chain3" / "report.html"


def test_a_three_axis_chain_report_fits_the_page(browser, chain_report, tmp_path):
    """The chain's axis (alpha - B) on every plot's x, K on y, one facet per branch and chi;
    the page does not scroll sideways at 1300 px, every facet's title fits over its plot, and
    the fits give the loop width per (K, chi) with its interval."""
    browser.get(chain_report.as_uri())
    titles = _wait(browser, TITLES, lambda v: len(v) == 4 and all(t["width"] > 0 for t in v))
    assert titles is not None, "the phase diagram did not render"
    assert {t["x_label"] for t in titles} == {"α − B"}
    assert sorted(t["text"] for t in titles) == sorted(
        f"branch = {b}, χ = {c}" for b in ("up", "down") for c in ("5", "10")
    )
    for t in titles:
        assert t["needed"] < t["width"], t
    scroll, client = browser.execute_script(SCROLL)
    assert scroll <= client
    tables = browser.execute_script(
        "return [...document.querySelectorAll('#fits ~ h3')].map(h => h.textContent);"
    )
    assert "transition over K, χ" in tables
    page = chain_report.read_text()
    assert "transition_loop_width" in page
    fits = xr.open_dataset(chain_report.parent / "fits.nc")
    assert fits.transition_loop_width.dims == ("K", "chi")
    assert np.isfinite(fits.transition_loop_width.values).any()
    severe = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert severe == []
    assert browser.save_screenshot(str(tmp_path / "chain3.png"))
