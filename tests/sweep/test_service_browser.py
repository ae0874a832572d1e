"""The service's dashboard in headless Chromium (selenium, Debian's chromium and
chromium-driver), against a real ``nematic serve``: the page opened with the token (which
becomes a cookie), a campaign's page that fills in as runs finish without a reload (pushed by
the event stream; a run recorded later reaches it as an update after its cursor), a click on
a point that shows its runs and a run's sigma2_S(t), and no request that leaves the service
(no CDN). Marked ``browser``; skipped, with the reason, where
Chromium, its driver or selenium is missing. A screenshot of the page is saved in the test's
temporary folder."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest
from sweep_helpers import kill_group, wait_group_gone
from test_report_browser import headless_chromium, sent_requests
from test_service_process import TINY, invoke, start_service, wait_state

from nematic_solids.sweep.service.paths import ServicePaths

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def chromium():
    # no network: a proxy that is not there, for any host but the service (127.0.0.1)
    yield from headless_chromium("1300,1000", "127.0.0.1")


def wait_js(driver, script: str, ready, timeout: float, what: str):
    deadline = time.monotonic() + timeout
    value = None
    while time.monotonic() < deadline:
        value = driver.execute_script(script)
        if ready(value):
            return value
        time.sleep(0.1)
    raise TimeoutError(f"timed out after {timeout} s waiting for {what} (last: {value!r})")


def submit(path: Path, root: Path, *args: str) -> int:
    result = invoke("submit", path, "--results", root, *args)
    assert result.exit_code == 0, result.output
    return int(result.output.split(" as ")[1].split()[0])


def test_the_dashboard_fills_in_without_reload_and_a_click_shows_a_run(chromium, tmp_path):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    root = tmp_path / "results"
    path = tmp_path / "tiny.yaml"
    path.write_text(TINY.format(name="tiny"))
    proc = start_service(root, tmp_path / "serve.log")
    try:
        first = submit(path, root, "--seeds", "1")
        assert wait_state(root, first, ("done", "failed"), 300)["state"] == "done"
        paths = ServicePaths(root)
        info = paths.running()
        assert info is not None
        url, token = info["url"], paths.read_token()
        sent_requests(chromium)  # forget earlier requests
        chromium.get(f"{url}?token={token}")
        assert "token" not in chromium.current_url  # exchanged for the cookie
        cookie = chromium.get_cookie("nematic_token")
        assert cookie is not None
        assert cookie["httpOnly"]
        wait_js(
            chromium,
            "return [...document.querySelectorAll('#campaigns a')].map(a => a.textContent)",
            lambda v: v == ["tiny"],
            30,
            "the campaign listed",
        )
        chromium.get(f"{url}campaigns/tiny")
        ok = "return document.body.dataset.ok"
        wait_js(chromium, ok, lambda v: v == "2", 30, "the two runs of seed 0")
        chromium.execute_script("window.notReloaded = true")
        assert chromium.find_element(By.ID, "live").text in ("live", "connecting")
        # more seeds of the same campaign: the page fills in as they finish
        second = submit(path, root, "--seeds", "2")
        seen = wait_js(
            chromium,
            "return [document.body.dataset.ok, document.getElementById('state').textContent]",
            lambda v: v[0] == "4" and v[1] == "done",
            300,
            "the four runs shown",
        )
        assert seen == ["4", "done"]
        assert chromium.execute_script("return window.notReloaded") is True
        assert wait_state(root, second, ("done",), 60)["state"] == "done"
        # a run recorded again (as any driver of the root records one): the page gets an
        # update after its cursor, not the whole page, and shows the same
        from nematic_solids.sweep.catalogue import open_catalogue
        from nematic_solids.sweep.catalogue.index import record_rows
        from nematic_solids.sweep.store import CampaignStore

        store = CampaignStore(root, "tiny")
        rid = next(iter(store.scan(save=False)))
        with open_catalogue(root) as catalogue:
            catalogue.record(list(record_rows(store, [rid])), {"tiny": "tiny"})
            recorded = catalogue.last_seq()
        seen = wait_js(
            chromium,
            "return [Number(document.body.dataset.seq), document.body.dataset.delta]",
            lambda v: v[0] >= recorded,
            30,
            "the page past the run recorded",
        )
        assert seen[1] == "true"  # brought by an update after the page's cursor
        assert chromium.execute_script("return document.body.dataset.ok") == "4"
        assert chromium.execute_script("return window.notReloaded") is True
        # a click on a point shows its runs and one run's series
        point = chromium.find_elements(By.CSS_SELECTOR, "#phase circle.point")[1]
        key = point.get_attribute("data-key")
        ActionChains(chromium).move_to_element(point).click().perform()
        shown = wait_js(
            chromium,
            "const r = document.getElementById('run');"
            "const line = document.querySelector('#series path.series-line');"
            "return r && line ? [r.dataset.run, line.getAttribute('d').length,"
            " document.querySelector('#point h3').textContent] : null",
            lambda v: v is not None,
            30,
            "the run view",
        )
        run_id, drawn, where = shown
        assert where == key == "alpha_minus_B=0.2"
        runs = {p.stem for p in (root / "tiny" / "runs").glob("*.nc")}
        assert run_id in runs
        assert drawn > 20
        chromium.save_screenshot(str(tmp_path / "dashboard.png"))
        requests = [u for u in sent_requests(chromium) if not u.startswith("data:")]
        assert requests
        assert all(u.startswith(url) for u in requests), requests  # no CDN, nothing outside
        severe = [e for e in chromium.get_log("browser") if e["level"] == "SEVERE"]
        assert not severe, severe
    finally:
        os.kill(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=120)
        finally:
            kill_group(proc)
    wait_group_gone(proc.pid)
