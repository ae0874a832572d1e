"""Batch workers retire before their walltime (sweep/run/lifetime.py): the walltime formats, the
rule, the job script the driver submits, and runs lost with their worker staying pending."""

from __future__ import annotations

import pytest

from nematic_solids.sweep.run.lifetime import lifetime_rule, walltime_seconds, worker_lifetime


@pytest.mark.parametrize(
    ("text", "seconds"),
    [
        ("04:00:00", 14400.0),
        ("00:02:00", 120.0),
        ("90:00", 5400.0),
        ("30", 1800.0),
        ("1-00:00:00", 86400.0),
        ("2-12", 2 * 86400.0 + 12 * 3600.0),
        ("1-01:30", 91800.0),
        (600, 600.0),
        ("", None),
        ("soon", None),
        ("00:00:00", None),
        (True, None),
        (-5, None),
    ],
)
def test_walltime_formats(text, seconds):
    assert walltime_seconds(text) == seconds


def test_the_lifetime_rule():
    # a long walltime: stagger capped at 5 min, grace at 60 s
    lifetime, stagger = lifetime_rule(4 * 3600.0)
    assert (lifetime, stagger) == (4 * 3600.0 - 300.0 - 60.0, 300.0)
    # a short one: W / 20 and W / 4; the latest retirement is before the walltime
    lifetime, stagger = lifetime_rule(120.0)
    assert (lifetime, stagger) == (84.0, 6.0)
    for walltime in (60.0, 600.0, 3600.0, 86400.0):
        lifetime, stagger = lifetime_rule(walltime)
        assert 0 < lifetime - stagger < lifetime + stagger < walltime


def test_worker_arguments_from_the_walltime():
    args, line = worker_lifetime(
        "slurm", {"walltime": "00:02:00", "worker_extra_args": ["--resources", "x=1"]}
    )
    assert args == ["--resources", "x=1", "--lifetime", "84s", "--lifetime-stagger", "6s"]
    assert line is not None
    assert "84 s +- 6 s" in line
    # the campaign's own --lifetime wins (["--lifetime", "0"] turns retirement off)
    own = ["--lifetime", "0"]
    assert worker_lifetime("slurm", {"walltime": "01:00:00", "worker_extra_args": own}) == (
        own,
        None,
    )
    # no walltime given: dask-jobqueue's configured default (30 min for SLURM)
    args, _ = worker_lifetime("slurm", {})
    assert args[args.index("--lifetime") + 1] == f"{lifetime_rule(1800.0)[0]:.0f}s"
    # htcondor has no walltime: nothing added
    assert worker_lifetime("htcondor", {}) == ([], None)


def test_the_job_script_retires_its_worker_before_the_walltime(tmp_path):
    from nematic_solids.sweep.campaign import ClusterSpec, ExecutionSpec
    from nematic_solids.sweep.run.driver import make_cluster

    spec = ClusterSpec(
        kind="slurm",
        jobs=1,
        options={"cores": 1, "processes": 1, "memory": "1GB", "walltime": "00:02:00"},
    )
    cluster = make_cluster(ExecutionSpec(cluster=spec), tmp_path)
    try:
        script = cluster.job_script()
        assert "--lifetime 84s --lifetime-stagger 6s" in script, script
        assert "#SBATCH -t 00:02:00" in script, script
        # runs lost with their worker go back to the scheduler a bounded number of times
        from nematic_solids.sweep.run.clusters import WORKER_LOSSES

        assert cluster.scheduler.allowed_failures == WORKER_LOSSES
    finally:
        cluster.close()


def test_records_of_runs_lost_with_their_worker_are_pending():
    from nematic_solids.sweep.store import RETRYABLE_REASONS

    assert "killed_worker" in RETRYABLE_REASONS
