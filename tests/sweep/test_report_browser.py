"""The report in a real browser (headless Chromium driven by selenium through the system
chromedriver: Debian's ``chromium`` and ``chromium-driver``, which .ci/run installs): the
phase diagram renders its points without a severe console error and without loading
anything from the network, and clicking a point shows that point's run (its snapshot image
and sigma2_S(t)). Saves a screenshot of the page in the test's temporary folder; with
``NEMATIC_UPDATE_SCREENSHOT=1`` in the environment it replaces docs/figures/report_screenshot.png
(the README shows it) instead, so a plain test run leaves the checkout unchanged.

Marked ``browser`` (run with ``pytest -m browser``; CI does); skipped, with the reason, where
Chromium, its driver or selenium is missing."""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from sweep.cli import app

pytestmark = pytest.mark.browser

ROOT = Path(__file__).resolve().parents[2]
SCREENSHOT = ROOT / "docs" / "figures" / "report_screenshot.png"
#: ``NEMATIC_UPDATE_SCREENSHOT=1``: the test's screenshot replaces :data:`SCREENSHOT`.
UPDATE_SCREENSHOT = "NEMATIC_UPDATE_SCREENSHOT"
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")

#: 4 x 2 tiny linear runs across the Fig. 2 transition (the quickstart at 32^2, to t = 4).
CAMPAIGN = """\
name: browser
description: Fig. 2 parameters at 32^2 up to t/tau = 4, sigma2_S vs alpha - B, 2 seeds each
parameters: {noise_modes: 8}
numerics: {resolution: 32, t_final: 4, save_every: 0.5, mechanics: linear}
sweep:
  axes:
    alpha_minus_B: [0.1, 0.3, 0.5, 0.7]
seeds: 2
fits: [transition]
execution: {workers: 2}
"""

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


@pytest.fixture(scope="module")
def browser():
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
        "--window-size=1300,1050",
    ):
        options.add_argument(arg)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    try:
        yield driver
    finally:
        driver.quit()


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("browser")
    path = folder / "browser.yaml"
    path.write_text(CAMPAIGN)
    result = CliRunner().invoke(
        app, ["run", str(path), "--results", str(folder / "results"), "--no-dashboard"]
    )
    assert result.exit_code == 0, result.output
    page = folder / "results" / "browser" / "report.html"
    assert page.is_file(), result.output
    return page


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
