"""Helpers shared by the campaign-manager tests (real model runs at 32^2, short t_final)."""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import subprocess
import sys
import time
from html.parser import HTMLParser
from pathlib import Path

from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.run.detach import child_command
from nematic_solids.sweep.spec import load_campaign

#: A small real campaign. alpha - B = 20 fails at once (the finite solver loses ellipticity:
#: (alpha - B) S0 = 2 > G / 2), so the campaign has failures to record.
SMALL = """\
name: {name}
description: campaign-manager test
parameters: {{noise_modes: 8}}
numerics: {{resolution: 32, t_final: {t_final}, save_every: 0.5, snapshot_times: [1]}}
sweep:
  axes:
    alpha_minus_B: {values}
seeds: {seeds}
execution: {{workers: {workers}}}
"""


def write_campaign(
    folder: Path,
    name: str = "small",
    values: str = "[0.1, 0.2, 20.0]",
    seeds: int = 2,
    t_final: float = 2.0,
    workers: int = 2,
) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.yaml"
    path.write_text(
        SMALL.format(name=name, values=values, seeds=seeds, t_final=t_final, workers=workers)
    )
    return path


def run_ids(path: Path) -> list[str]:
    return expand(load_campaign(path)).run_ids


def records(runs_dir: Path) -> dict[str, dict]:
    return {p.stem: json.loads(p.read_text()) for p in runs_dir.glob("*.json")}


def file_stamps(runs_dir: Path) -> dict[str, tuple[int, int]]:
    """(inode, mtime_ns) of every run file: unchanged stamps mean not recomputed."""
    out = {}
    for p in runs_dir.glob("*.nc"):
        st = p.stat()
        out[p.stem] = (st.st_ino, st.st_mtime_ns)
    return out


def start_driver(args: list[str], log: Path) -> subprocess.Popen:
    """``nematic ARGS`` in its own session (so the test can signal it like a terminal), with
    SIGINT at its default disposition as under a terminal: when the tests themselves run as a
    background job of a non-interactive shell (``.ci/run &``), SIGINT is ignored and that
    disposition is inherited, so the driver would never see the Ctrl-C."""
    env = dict(os.environ, PYTHONUNBUFFERED="1", COLUMNS="200")
    with open(log, "wb") as out:
        return subprocess.Popen(
            [*child_command("signal.signal(signal.SIGINT, signal.default_int_handler)"), *args],
            stdout=out,
            stderr=subprocess.STDOUT,
            env=env,
            start_new_session=True,
        )


def wait_for(predicate, timeout: float, what: str, interval: float = 0.2) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(interval)
    raise TimeoutError(f"timed out after {timeout} s waiting for {what}")


def group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


def wait_group_gone(pgid: int, timeout: float = 60.0) -> None:
    """Wait until every process of the process group ``pgid`` (a driver started by
    :func:`start_driver` and its local dask workers) has exited. A killed driver's workers
    outlive it briefly and may still write a run's files; a test reads the run folder only
    after this, so that what it reads is the folder's final state, not a moment of it."""
    wait_for(lambda: not group_alive(pgid), timeout, f"the processes of group {pgid} to exit")


def kill_group(proc: subprocess.Popen) -> None:
    """Clean-up: SIGKILL whatever is left of a driver's session (its own processes only)."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGKILL)
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(timeout=10)


def cli_modules(*args: object) -> tuple[set[str], str]:
    """Run ``nematic ARGS`` in a fresh interpreter: the modules it imported, its output."""
    code = (
        "import atexit, json, runpy, sys\n"
        "atexit.register(lambda: print('MODULES', json.dumps(sorted(sys.modules))))\n"
        f"sys.argv = ['nematic', *{[str(a) for a in args]!r}]\n"
        "runpy.run_module('sweep', run_name='__main__')\n"
    )
    root = Path(__file__).resolve().parents[1]
    done = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": str(root)},
        cwd=root,
        timeout=300,
        check=False,
    )
    output, _, modules = done.stdout.rpartition("MODULES ")
    assert modules, done.stderr
    return set(json.loads(modules)), output + done.stderr


# ------------------------------------------------------------------- pages that work offline
#: A reference to something outside the page's own folder: an absolute URL of a network
#: scheme, or a protocol-relative one (``//host/...``).
_OUTSIDE = re.compile(r"^\s*(?:(?:https?|wss?|ftp):|//)", re.I)
#: Attributes that make a browser fetch or navigate to their value.
_URL_ATTRIBUTES = frozenset(
    {"src", "href", "srcset", "action", "formaction", "poster", "data", "background", "xlink:href"}
)
#: ES module imports and CSS imports/urls naming an absolute URL in literal text.
_SCRIPT_IMPORT = re.compile(
    r"""\bimport\s*\(\s*["'`]([^"'`]+)|\bimport\s+(?:[\w*{}\s,]+\s+from\s+)?["']([^"']+)"""
)
_CSS_URL = re.compile(r"""@import\s+["']([^"']+)|url\(\s*["']?([^"')\s]+)""", re.I)


class _References(HTMLParser):
    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.found: list[str] = []
        self._in: str | None = None
        self._module = False

    def _check(self, where: str, url: str) -> None:
        if _OUTSIDE.match(url):
            self.found.append(f"{where}: {url}")

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        for name, value in attrs:
            if value is None:
                continue
            if name in _URL_ATTRIBUTES:
                for url in value.split(",") if name == "srcset" else [value]:
                    self._check(f"<{tag} {name}>", url.strip().split(" ")[0])
            elif name == "style":
                for m in _CSS_URL.finditer(value):
                    self._check(f"<{tag} style>", m.group(1) or m.group(2))
            elif tag == "meta" and name == "content" and "url=" in value.lower():
                self._check("<meta refresh>", value.lower().split("url=", 1)[1])
        self._in = tag if tag in ("script", "style") else None
        self._module = tag == "script" and dict(attrs).get("type") == "module"

    def handle_endtag(self, tag: str) -> None:
        self._in = None

    def handle_data(self, data: str) -> None:
        if self._in == "style":
            for m in _CSS_URL.finditer(data):
                self._check("<style>", m.group(1) or m.group(2))
        elif self._in == "script":
            # imports of a module by its URL; a URL that is only a string in the code (as
            # in bokeh's bundle: the MathJax CDN address of a provider it does not use) is
            # no reference of the page
            for m in _SCRIPT_IMPORT.finditer(data):
                url = m.group(1) or m.group(2)
                if m.group(1) or self._module:
                    self._check("<script> import", url)


def outside_references(html: str) -> list[str]:
    """Everything the page ``html`` would fetch or link to outside its own folder: the
    network URLs (and ``//host`` ones) in its tags' src/href/srcset/action/... attributes,
    ``<link>`` and ``<base>`` included, in CSS ``url()`` and ``@import``, in a meta refresh,
    and in the ES module imports of its scripts (``import("...")``; ``import ... from "..."``
    in a module script). Empty for a page that works offline."""
    parser = _References()
    parser.feed(html)
    parser.close()
    return parser.found
