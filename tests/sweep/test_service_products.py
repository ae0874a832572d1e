"""The service's runner reports a campaign whose fits or figures failed as ``nematic run``
does (exit 4 there): not done, but failed, naming the products and their redraw command, with
its runs kept."""

from __future__ import annotations

import pytest

pytest.importorskip("fastapi")

from test_service_api import CAMPAIGN as SERVICE_CAMPAIGN

from nematic_solids.sweep.figures.failed import read_failed
from nematic_solids.sweep.service.catalogue_link import open_service_database
from nematic_solids.sweep.service.queue import DONE, FAILED
from nematic_solids.sweep.service.runner import Changes, ClusterPool, Runner

#: the service tests' small campaign, drawing Fig. 2 on one worker
CAMPAIGN = SERVICE_CAMPAIGN + "figures: [fig2]\nexecution: {{workers: 1}}\n"


def test_a_campaign_whose_figure_fails_is_failed_and_one_drawn_is_done(tmp_path):
    """Two campaigns on the runner's one cluster: the first's figures folder is a file."""
    catalogue, queue = open_service_database(tmp_path)
    folder = tmp_path / "broken"
    folder.mkdir()
    (folder / "figures").write_text("not a folder")  # where the figures go: they cannot
    ids = [
        queue.submit(name, f"/nowhere/{name}.yaml", CAMPAIGN.format(name=name), {}, 0).id
        for name in ("broken", "fine")
    ]
    pool = ClusterPool(tmp_path)
    runner = Runner(tmp_path, queue, pool, Changes())
    try:
        for _ in ids:
            entry = queue.next()
            assert entry is not None
            runner.run_entry(entry)
    finally:
        pool.close()
    broken, fine = (queue.get(i) for i in ids)
    assert broken.state == FAILED, broken.message
    assert broken.message.startswith(
        "all runs ok, but 1 fit(s) or figure(s) failed (figure fig2)"
    ), broken.message
    assert "nematic figures broken redraws them" in broken.message
    assert list(read_failed(folder)) == ["figure fig2"]
    assert (folder / "phase.nc").is_file()  # the runs are kept
    assert fine.state == DONE, fine.message
    assert fine.message == "all runs ok"
    assert (tmp_path / "fine" / "figures").is_dir()
