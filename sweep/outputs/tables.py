"""A campaign's results where users analyse them (a notebook, pandas, a spreadsheet):
:func:`~nematic_solids.sweep.open_campaign` gives the phase diagram as an xarray Dataset with a
``seed`` dimension
(the one ``phase.nc`` holds, built from the run records as
:mod:`nematic_solids.sweep.outputs.aggregate` builds it) and the runs as a tidy pandas table, one
row per finished run; :func:`write_table` writes that table as CSV or Parquet, atomically (``nematic
export``).

Reading takes no lock and writes nothing into the results folder, so it works while a
driver runs the campaign (the runs it has finished so far)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..campaign import Campaign
from ..errors import ExportError, StoreError
from ..files import atomic_path
from ..spec import load_campaign
from ..store import CampaignStore
from .aggregate import STATUS_FAILED, STATUS_MISSING, phase_dataset
from .stored import stored_campaign

if TYPE_CHECKING:
    import pandas as pd
    import xarray as xr

    from ..expand import Expansion

FORMATS = ("csv", "parquet")
#: the per-run variables of the phase diagram that locate a run rather than measure it
RUN_COLUMNS = ("run_id", "status", "reason")


class CampaignResults:
    """One campaign's results folder, read from Python.

    ``phase()`` is the phase diagram (``xarray.Dataset``: every per-run scalar over the sweep
    dims and ``seed``, NaN where a run is missing or failed, with the seed statistics);
    ``runs()`` is the table (``pandas.DataFrame``): one row per finished run (ok or failed),
    with every swept axis, ``seed``, ``run_id``, ``status``, ``reason`` and every per-run
    scalar as columns; ``fits()`` is ``fits.nc`` (``xarray.Dataset``: the campaign's fits with
    their intervals, docs/campaigns/fits.md). Each reads the folder anew at each call."""

    def __init__(self, campaign: Campaign, results: str | Path = "results"):
        self.campaign = campaign
        self.store = CampaignStore(results, campaign.name)

    def __repr__(self) -> str:
        return f"<CampaignResults {self.campaign.name!r} in {self.store.root}>"

    def expansion(self) -> Expansion:
        """The runs the phase diagram spans (an adaptive campaign's rounds replayed)."""
        from ..refine.rounds import expansion_for

        return expansion_for(self.campaign, self.store)

    def phase(self) -> xr.Dataset:
        """The phase diagram, as ``nematic aggregate`` would write it to ``phase.nc``."""
        return phase_dataset(self.expansion(), self.store, self.store.scan(save=False))

    def runs(self) -> pd.DataFrame:
        """One row per finished run: swept axes, seed, run_id, status, reason, scalars."""
        return runs_table(self.phase())

    def fits(self) -> xr.Dataset:
        """The campaign's fits as ``nematic run`` or ``nematic figures`` last wrote them to
        ``fits.nc`` (loaded into memory): each fitted quantity with its interval, units and
        the reason of a NaN in its attributes. Raises
        :class:`~nematic_solids.sweep.errors.StoreError` when there is no fits.nc yet."""
        from ..analysis.fits_file import FITS, load_fits

        path = self.store.root / FITS
        if not path.is_file():
            raise StoreError(
                f"no {path} yet: `nematic figures` computes the fits from phase.nc "
                "(`nematic run` does at its end)"
            )
        return load_fits(self.store.root)


def runs_table(ds: xr.Dataset) -> pd.DataFrame:
    """The tidy table of a phase diagram: its per-seed variables, one row per run that has a
    record (``status`` "ok" or "failed"), the sweep coordinates (a zip group's every axis)
    and ``seed`` as columns, in the campaign's run order."""
    per_run = [str(n) for n, v in ds.data_vars.items() if "seed" in v.dims]
    table = ds[per_run].drop_vars([c for c in ds.coords if not ds[c].dims]).to_dataframe()
    table = table.reset_index()
    table = table[table["status"] != STATUS_MISSING].reset_index(drop=True)
    table["status"] = ["failed" if s == STATUS_FAILED else "ok" for s in table["status"]]
    axes = [
        str(c)
        for c in ds.coords
        if str(c) != "seed" and ds[c].dims and set(ds[c].dims) <= set(ds.dims) - {"seed"}
    ]
    first = [*axes, "seed", *RUN_COLUMNS]
    rest = [c for c in table.columns if c not in first and c not in ds.dims]
    return table[first + rest]


def open_campaign(campaign: str | Path, results: str | Path = "results") -> CampaignResults:
    """Open a campaign's results: ``campaign`` is its YAML file, or its name (the folder
    ``results/<name>/``, read with the campaign copy the last ``nematic run`` left there, its
    command-line overrides included). Raises :class:`~nematic_solids.model.errors.NematicError`
    subclasses with what is wrong (no such file or folder, an invalid campaign)."""
    path = Path(campaign)
    if path.is_file():
        return CampaignResults(load_campaign(path), results)
    if path.suffix in (".yaml", ".yml") or len(path.parts) > 1:
        raise StoreError(f"no campaign file {path}")
    store = CampaignStore(results, str(campaign))
    found = stored_campaign(store)
    if found is None:
        raise StoreError(
            f"no results of a campaign named {campaign!r} in {store.results_root}"
            f" ({store.campaign_copy} is missing); give the campaign file, or "
            "the folder that holds its results (--results; results= in Python)"
        )
    return CampaignResults(found, results)


def write_table(table: pd.DataFrame, path: Path, fmt: str) -> None:
    """Write ``table`` as ``fmt`` (csv or parquet) to ``path``, atomically. Parquet needs
    pyarrow (the ``parquet`` extra); without it an
    :class:`~nematic_solids.sweep.errors.ExportError` says so."""
    if fmt not in FORMATS:
        raise ExportError(f"unknown format {fmt!r}; allowed: {', '.join(FORMATS)}")
    path.parent.mkdir(parents=True, exist_ok=True)
    if fmt == "csv":
        with atomic_path(path) as tmp:
            table.to_csv(tmp, index=False)
        return
    engine = parquet_engine()
    with atomic_path(path) as tmp:
        table.to_parquet(tmp, index=False, engine=engine)


def parquet_engine() -> Any:
    """The engine pandas writes Parquet with (pyarrow, else fastparquet); an
    :class:`~nematic_solids.sweep.errors.ExportError` naming the extra to install when there is
    none."""
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        pass
    else:
        return "pyarrow"
    try:
        import fastparquet  # noqa: F401
    except ImportError:
        raise ExportError(
            "Parquet needs pyarrow, which is not installed here: install it with pip install "
            "'active-nematic-solids[parquet]' (or pip install pyarrow), or export with "
            "--format csv"
        ) from None
    return "fastparquet"
