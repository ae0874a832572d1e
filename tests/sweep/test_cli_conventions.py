"""Command-line habits: --version, completion, -v/-q everywhere, one error style, literal
messages (no rich markup eaten), every problem in one pass, honest progress lines."""

from __future__ import annotations

import io
import logging
import re
import time
from types import SimpleNamespace

import typer.core
import typer.main
from rich.progress import Progress
from typer.testing import CliRunner

from nematic_solids import model
from nematic_solids.sweep.cli import app
from nematic_solids.sweep.cli.app import Console
from nematic_solids.sweep.cli.progress import ProgressEvents


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


def flat(text: str) -> str:
    return " ".join(text.split())


def test_version():
    result = invoke("--version")
    assert result.exit_code == 0, result.output
    # the model's version (each run file records it) and the git commit of the code
    assert re.match(
        r"nematic \d+\.\d+\.\d+ \(git ([0-9a-f]{40}(\+dirty)?|unknown)\)", result.output
    ), result.output
    assert result.output.split()[1] == model.__version__


def test_shell_completion_is_offered():
    out = invoke("--help").output
    assert "--install-completion" in out
    assert "--show-completion" in out


def test_every_command_takes_verbose_and_quiet():
    group = typer.main.get_command(app)
    assert isinstance(group, typer.core.TyperGroup)
    assert len(group.commands) >= 7
    for name, command in group.commands.items():
        opts = {o for p in command.params for o in getattr(p, "opts", [])}
        assert {"-v", "--verbose", "-q", "--quiet"} <= opts, name


def test_run_has_a_dashboard_switch():
    group = typer.main.get_command(app)
    assert isinstance(group, typer.core.TyperGroup)
    command = group.commands["run"]
    opts = {
        o for p in command.params for o in getattr(p, "opts", []) + getattr(p, "secondary_opts", [])
    }
    assert {"--dashboard", "--no-dashboard"} <= opts


def _bad_campaign(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text(
        "name: bad\nparamters: {B: 0.5}\nnumerics: {t_final: -3}\n"
        "sweep:\n  axes:\n    alpha_minus_B: {linspace: [0.1, 1.0]}\n"
    )
    return path


def test_every_problem_in_one_pass_and_brackets_kept(tmp_path):
    result = invoke("validate", _bad_campaign(tmp_path))
    out = flat(result.output)
    assert result.exit_code == 2
    assert out.startswith("error: invalid campaign")
    assert "3 problem(s)" in out
    assert "unknown key 'paramters'" in out
    assert "numerics.t_final: got -3" in out  # a value error, reported with the structure
    assert "allowed: [start, stop, num] or {start: .., stop: .., num: ..}" in out


def test_set_on_a_swept_axis_names_the_command_line(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("name: c\nsweep:\n  axes:\n    alpha_minus_B: [0.1, 0.5]\nseeds: 1\n")
    result = invoke("validate", path, "--set", "alpha_minus_B=0.2")
    out = flat(result.output)
    assert result.exit_code == 2
    assert "command line --set alpha_minus_B=0.2" in out
    assert "swept axis" in out
    assert "set in 'parameters:'" not in out


def test_quiet_validate_prints_nothing(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("name: c\nsweep:\n  axes:\n    alpha_minus_B: [0.1, 0.5]\nseeds: 1\n")
    assert "valid" in invoke("validate", path).output
    result = invoke("validate", path, "-q")
    assert result.exit_code == 0
    assert result.output == ""


def test_one_error_style_in_stability():
    result = invoke("stability", "--set", "chi=abc")
    assert result.exit_code == 2
    assert flat(result.output).startswith("error: invalid value for 'chi'")


class FakeClock:
    def __init__(self):
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def _events(clock):
    buf = io.StringIO()
    console = Console(file=buf, force_terminal=False, width=200)
    progress = Progress(console=console, disable=True)
    events = ProgressEvents(console, progress, SimpleNamespace(root="r"), clock=clock)
    return events, buf


def _plan(done=0):
    return SimpleNamespace(done=list(range(done)), failed=[], todo=[], skipped=done)


def test_progress_lines_and_a_median_eta():
    clock = FakeClock()
    events, buf = _events(clock)
    events.started(_plan(), total=10, workers=2)
    # the first run compiled the kernels (600 s); the others take 10 s
    for wall in (600.0, 10.0, 10.0):
        clock.t += 6.0
        events.finished_run(SimpleNamespace(), {"status": "ok", "wall_time": wall})
    lines = [ln for ln in buf.getvalue().splitlines() if ln.startswith("progress:")]
    assert len(lines) == 3  # one per completed run (at most one every LOG_MIN seconds)
    assert lines[-1].startswith("progress: 3/10 runs (3 ok, 0 failed, 2 running")
    assert events.eta() == 7 * 10.0 / 2  # median 10 s, not a mean poisoned by the 600 s
    assert lines[-1].endswith("ETA 0:35")
    clock.t += 1.0  # a run within LOG_MIN of the last line: no new line
    failed = SimpleNamespace(run_id="r1", coords={"alpha_minus_B": 0.5})
    events.finished_run(failed, {"status": "failed", "wall_time": 10.0, "reason": "nan"})
    assert buf.getvalue().count("progress:") == 3
    assert "FAILED run r1 (alpha_minus_B=0.5) failed: nan" in buf.getvalue()
    events.close()


def test_progress_heartbeat_without_completions():
    events, buf = _events(time.monotonic)
    events.LOG_EVERY = 0.2
    events.started(_plan(done=1), total=4, workers=2)
    time.sleep(2.5)  # the heartbeat checks every second
    events.close()
    out = buf.getvalue()
    assert "progress: 1/4 runs (0 ok, 0 failed, 2 running" in out
    assert "ETA unknown" in out


def test_py_pde_tracker_time_warning_is_not_printed(caplog):
    """py-pde warns when its trackers take longer than the solver; here the tracker computes
    the observables, so the warning is demoted to DEBUG (hidden unless debug logging)."""
    import nematic_solids.model.simulate  # noqa: F401 - installs the filter

    logger = logging.getLogger("pde.solvers.controller")
    with caplog.at_level(logging.INFO):
        logger.warning(
            "Spent more time on handling trackers (%.3g) than on the actual simulation (%.3g)",
            39.2,
            20.5,
        )
        logger.warning("another warning")
    messages = [r.getMessage() for r in caplog.records]
    assert "another warning" in messages
    assert not any("handling trackers" in m for m in messages)


def test_local_dashboard_on_loopback_or_off():
    from nematic_solids.sweep.campaign import ExecutionSpec
    from nematic_solids.sweep.run.driver import dashboard_link, dask_client

    with dask_client(ExecutionSpec(workers=1), dashboard=True) as client:
        link = dashboard_link(client)
    assert link is not None
    assert link.startswith("http://127.0.0.1:")
    with dask_client(ExecutionSpec(workers=1), dashboard=False) as client:
        assert dashboard_link(client) is None  # the HTTP server answers 404 for the page


def test_dashboard_link_of_an_external_scheduler():
    """A scheduler the campaign connects to (execution.scheduler) serves its own dashboard:
    its link is found the same way, and none when that scheduler serves no dashboard."""
    from distributed import LocalCluster

    from nematic_solids.sweep.campaign import ExecutionSpec
    from nematic_solids.sweep.run.driver import dashboard_link, dask_client

    for served in (True, False):
        with LocalCluster(
            n_workers=0,
            processes=False,
            dashboard_address="127.0.0.1:0",
            scheduler_kwargs={"dashboard": served},
        ) as cluster:
            spec = ExecutionSpec(scheduler=cluster.scheduler_address)
            with dask_client(spec, dashboard=True) as client:
                link = dashboard_link(client)
        if served:  # a link that answered (HTTP 200) while the scheduler ran
            assert link is not None
            assert link.startswith("http://")
        else:
            assert link is None
