"""Results where users analyse them: ``sweep.open_campaign`` (the phase diagram as an xarray
Dataset with a seed dimension, the runs as a pandas table) and ``nematic export`` (CSV,
Parquet), on the small real campaign and on a zip grid with made-up records."""

from __future__ import annotations

import math
import sys

import numpy as np
import pandas as pd
import pytest
import xarray as xr
from sweep_helpers import records
from typer.testing import CliRunner

from nematic_solids import sweep
from nematic_solids.sweep.analysis.fits_file import write_fits
from nematic_solids.sweep.cli import app
from nematic_solids.sweep.errors import ExportError, StoreError
from nematic_solids.sweep.expand import expand
from nematic_solids.sweep.outputs.aggregate import build_phase
from nematic_solids.sweep.outputs.tables import (
    open_campaign,
    parquet_engine,
    runs_table,
    write_table,
)
from nematic_solids.sweep.spec import parse_campaign
from nematic_solids.sweep.store import Record


def invoke(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


def flat(text: str) -> str:
    return " ".join(text.split())


def per_seed_variables(ds: xr.Dataset) -> list[str]:
    return [str(n) for n, v in ds.data_vars.items() if "seed" in v.dims]


def test_open_campaign_by_file_or_name(small):
    by_file = sweep.open_campaign(small.path, results=small.results)
    by_name = open_campaign("small", results=small.results)
    assert by_file.campaign.name == by_name.campaign.name == "small"
    phase = by_name.phase()
    assert phase["sigma2_S"].dims == ("alpha_minus_B", "seed")
    with xr.open_dataset(small.results / "small" / "phase.nc") as written:
        for name in ("sigma2_S", "lambda_peak", "sigma2_S_mean"):
            np.testing.assert_array_equal(phase[name].values, written[name].values)
        np.testing.assert_array_equal(phase["status"].values, written["status"].values)


def test_the_runs_table_has_one_row_per_run_with_every_axis_and_scalar(small):
    table = open_campaign(small.path, results=small.results).runs()
    recs = records(small.runs)
    phase = open_campaign(small.path, results=small.results).phase()
    assert len(table) == len(small.ids) == 6
    assert sorted(table["run_id"]) == sorted(small.ids)
    assert list(table.columns[:5]) == ["alpha_minus_B", "seed", "run_id", "status", "reason"]
    assert set(per_seed_variables(phase)) <= set(table.columns)
    for row in table.itertuples(index=False):
        rec = recs[row.run_id]
        assert row.alpha_minus_B == rec["coords"]["alpha_minus_B"]
        assert row.seed == rec["seed"]
        assert row.status == rec["status"]
        assert row.run_time == rec["wall_time"]  # ok and failed runs: the seconds it took
        assert row.run_time > 0
        if rec["status"] == "ok":
            assert row.sigma2_S == rec["scalars"]["sigma2_S_final"]
            assert row.t_peak == rec["scalars"]["t_peak"]
        else:
            assert row.reason == rec["reason"]
            assert math.isnan(row.sigma2_S)


def test_export_writes_the_table_as_csv(copy_of_small):
    gone = copy_of_small.ids[0]  # a run without a record is no row
    (copy_of_small.runs / f"{gone}.json").unlink()
    result = invoke("export", "small", "--results", copy_of_small.results)
    assert result.exit_code == 0, result.output
    path = copy_of_small.results / "small" / "runs.csv"
    assert f"wrote {path}: 5 run(s) (3 ok, 2 failed)" in flat(result.output)
    table = pd.read_csv(path, keep_default_na=False, na_values=[""])
    expected = open_campaign(copy_of_small.path, results=copy_of_small.results).runs()
    assert list(table.columns) == list(expected.columns)
    assert gone not in set(table["run_id"])
    pd.testing.assert_frame_equal(
        table[["alpha_minus_B", "seed", "sigma2_S"]],
        expected[["alpha_minus_B", "seed", "sigma2_S"]],
    )
    assert not list(path.parent.glob(".*.tmp"))
    out = copy_of_small.results.parent / "elsewhere" / "small.csv"
    result = invoke(
        "export", copy_of_small.path, "--results", copy_of_small.results, "--output", out
    )
    assert result.exit_code == 0, result.output
    assert len(pd.read_csv(out)) == 5


def test_export_refuses_what_it_cannot_do(copy_of_small, tmp_path):
    bad = invoke("export", "small", "--results", copy_of_small.results, "--format", "xlsx")
    assert bad.exit_code == 2
    assert "error: --format: got 'xlsx'; allowed: csv, parquet" in flat(bad.output)
    missing = invoke("export", "nothing", "--results", copy_of_small.results)
    assert missing.exit_code == 2
    assert "no results of a campaign named 'nothing'" in flat(missing.output)
    assert "Traceback" not in missing.output
    with pytest.raises(StoreError, match="no campaign file"):
        open_campaign(tmp_path / "absent.yaml")


def test_parquet_without_pyarrow_names_the_extra_to_install(copy_of_small, monkeypatch):
    # no Parquet engine importable (as on a machine without the extra)
    monkeypatch.setitem(sys.modules, "pyarrow", None)
    monkeypatch.setitem(sys.modules, "fastparquet", None)
    with pytest.raises(ExportError, match=r"pip install 'active-nematic-solids\[parquet\]'"):
        parquet_engine()
    result = invoke("export", "small", "--results", copy_of_small.results, "--format", "parquet")
    assert result.exit_code == 2
    assert "error: Parquet needs pyarrow" in flat(result.output)
    assert not (copy_of_small.results / "small" / "runs.parquet").exists()


def test_parquet_round_trips(copy_of_small, tmp_path):
    table = open_campaign("small", results=copy_of_small.results).runs()
    write_table(table, tmp_path / "runs.parquet", "parquet")
    pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "runs.parquet"), table)


ZIPPED = """\
name: zipped
parameters: {noise_modes: 8}
numerics: {resolution: 32, t_final: 1}
sweep:
  axes:
    K: [1.0e-4, 2.0e-4]
    eps: [0.0, 0.05]
    alpha_minus_B: [0.1, 0.2, 0.3]
  zip: [[K, eps]]
seeds: 2
"""


def test_a_zip_group_gives_a_column_per_axis():
    expansion = expand(parse_campaign(ZIPPED))
    recs: dict[str, Record] = {
        rid: {"status": "ok", "scalars": {"sigma2_S_final": float(i)}}
        for i, rid in enumerate(expansion.run_ids)
        if i % 3
    }  # every third run missing
    table = runs_table(build_phase(expansion, recs))
    assert list(table.columns[:6]) == ["K", "eps", "alpha_minus_B", "seed", "run_id", "status"]
    assert len(table) == len(recs)
    for row in table.itertuples(index=False):
        i = expansion.position[row.run_id]
        run = expansion.run(i)
        assert (row.K, row.eps, row.alpha_minus_B, row.seed) == (
            run.coords["K"],
            run.coords["eps"],
            run.coords["alpha_minus_B"],
            run.seed,
        )
        assert row.sigma2_S == float(i)


def test_the_guide_notebook_snippet_runs(small):
    """The ``py`` snippet of docs/guide/first_campaign.md, on a small campaign's results."""
    import re
    from pathlib import Path

    import matplotlib

    matplotlib.use("Agg")
    page = Path(__file__).resolve().parents[2] / "docs" / "guide" / "first_campaign.md"
    (snippet,) = re.findall(r"```py\n(.*?)```", page.read_text(), flags=re.S)
    opening = 'sweep.open_campaign("quickstart")'
    assert opening in snippet
    code = snippet.replace(opening, f'sweep.open_campaign("small", results={str(small.results)!r})')
    namespace: dict = {}
    exec(compile(code, "first_campaign.md notebook snippet", "exec"), namespace)
    assert len(namespace["runs"]) == 6
    assert namespace["phase"]["sigma2_S"].dims == ("alpha_minus_B", "seed")


def test_open_by_name_reads_the_campaign_copy_with_its_overrides(tmp_path):
    from nematic_solids.sweep.campaign_copy import campaign_copy_text
    from nematic_solids.sweep.spec import Overrides
    from nematic_solids.sweep.store import CampaignStore

    overrides = Overrides(
        settings={"resolution": 48, "initial": "per_node", "C": 2.5}, seeds=[3, 5], name="reduced"
    )
    store = CampaignStore(tmp_path / "results", "reduced")
    store.root.mkdir(parents=True)
    store.save_campaign_text(campaign_copy_text(ZIPPED, overrides.describe()))  # as `run`
    opened = open_campaign("reduced", results=tmp_path / "results")
    expected = parse_campaign(ZIPPED, overrides=overrides)
    assert opened.campaign.name == "reduced"
    assert opened.campaign.seeds == (3, 5)
    assert opened.campaign.numerics["resolution"] == 48
    assert opened.campaign.parameters["initial"] == "per_node"
    assert opened.campaign.parameters["C"] == 2.5
    assert expand(opened.campaign).run_ids == expand(expected).run_ids


def test_fits_is_fits_nc_read_anew_and_says_how_to_make_it_when_missing(copy_of_small):
    results = open_campaign("small", results=copy_of_small.results)
    root = copy_of_small.results / "small"
    # the run wrote fits.nc: the transition fit that applies to a one-axis grid
    first = results.fits()
    assert "transition_location" in first.data_vars
    assert first.attrs["campaign"] == "small"
    # fits written again (as `nematic figures` writes them) are what the next call returns
    path, failed = write_fits(root, [("transition", {"observable": "mean_S"})])
    assert failed == {}
    again = results.fits()
    with xr.open_dataset(path) as written:
        xr.testing.assert_identical(again, written.load())
    assert '"observable": "mean_S"' in again.attrs["fits"]
    assert '"observable": "mean_S"' not in first.attrs["fits"]
    path.unlink()
    with pytest.raises(StoreError, match="nematic figures"):
        results.fits()
