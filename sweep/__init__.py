"""The campaign manager: declarative YAML campaigns fanned out over dask, resumable on disk,
aggregated into netCDF phase diagrams, fits and the paper's figures.

Module map (docs/architecture.md has one line per module and the direction of imports):

- the shared base, at the top: :mod:`nematic_solids.sweep.errors`,
  :mod:`nematic_solids.sweep.limits` (the exceptions; bounds checked before anything runs),
  :mod:`nematic_solids.sweep.campaign` (a validated campaign as frozen data),
  :mod:`nematic_solids.sweep.identity` (run_id), :mod:`nematic_solids.sweep.expand` (Campaign ->
  grid points and runs), :mod:`nematic_solids.sweep.files`, :mod:`nematic_solids.sweep.store`,
  :mod:`nematic_solids.sweep.outputs.stored` (atomic files; the results folder: records, manifest,
  lock, the campaign copy), :mod:`nematic_solids.sweep.provenance`,
  :mod:`nematic_solids.sweep.startup`
- :mod:`nematic_solids.sweep.spec`: campaign YAML ->
  :class:`~nematic_solids.sweep.campaign.Campaign`, one reader per section (and a collection of
  campaigns)
- :mod:`nematic_solids.sweep.run`: what remains to do, the dask driver, the worker task, the cluster
  and its workers, failure triage, the driver in the background, the cost before launch
- :mod:`nematic_solids.sweep.outputs`: phase.nc, status, the results as tables
  (:func:`open_campaign`, ``nematic export``), what changed in the campaign file
- :mod:`nematic_solids.sweep.refine`, :mod:`nematic_solids.sweep.precision`,
  :mod:`nematic_solids.sweep.verify`: adaptive rounds, seeds by precision, verification
- :mod:`nematic_solids.sweep.analysis` (the fits, fits.nc), :mod:`nematic_solids.sweep.figures` (the
  paper's figures), :mod:`nematic_solids.sweep.report` (report.html)
- :mod:`nematic_solids.sweep.cli`: the ``nematic`` program (typer; also ``python -m
  nematic_solids.sweep``)

It knows the physics only through :class:`nematic_solids.model.parameters.Parameters`,
:class:`nematic_solids.model.parameters.Numerics`, :func:`nematic_solids.model.simulate.run` and a
few more entries (:mod:`nematic_solids.model.stability`, :mod:`nematic_solids.model.warmup`,
:mod:`nematic_solids.model.errors`).
"""

from typing import Any

__all__ = ["open_campaign"]


def __getattr__(name: str) -> Any:
    """``sweep.open_campaign`` (:func:`nematic_solids.sweep.outputs.tables.open_campaign`), imported
    on first use so that ``from nematic_solids import sweep`` (the command line) does not load
    pandas."""
    if name == "open_campaign":
        from .outputs.tables import open_campaign

        return open_campaign
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
