"""The campaign manager: declarative YAML campaigns fanned out over dask, resumable on disk,
aggregated into netCDF phase diagrams, fits and the paper's figures.

Module map (docs/architecture.md has one line per module and the direction of imports):

- the shared base, at the top: :mod:`sweep.errors`, :mod:`sweep.limits` (the exceptions;
  bounds checked before anything runs), :mod:`sweep.campaign` (a validated campaign as frozen
  data), :mod:`sweep.identity` (run_id), :mod:`sweep.expand` (Campaign -> grid points and
  runs), :mod:`sweep.files`, :mod:`sweep.store`, :mod:`sweep.outputs.stored` (atomic files; the
  results folder: records, manifest, lock, the campaign copy), :mod:`sweep.provenance`,
  :mod:`sweep.startup`
- :mod:`sweep.spec`: campaign YAML -> :class:`~sweep.campaign.Campaign`, one reader per
  section (and a collection of campaigns)
- :mod:`sweep.run`: what remains to do, the dask driver, the worker task, the cluster and its
  workers, failure triage, the driver in the background, the cost before launch
- :mod:`sweep.outputs`: phase.nc, status, the results as tables (:func:`open_campaign`,
  ``nematic export``), what changed in the campaign file
- :mod:`sweep.refine`, :mod:`sweep.precision`, :mod:`sweep.verify`: adaptive rounds, seeds by
  precision, verification
- :mod:`sweep.analysis` (the fits, fits.nc), :mod:`sweep.figures` (the paper's figures),
  :mod:`sweep.report` (report.html)
- :mod:`sweep.cli`: the ``nematic`` program (typer; also ``python -m sweep``)

It knows the physics only through :class:`model.parameters.Parameters`,
:class:`model.parameters.Numerics`, :func:`model.simulate.run` and a few more entries
(:mod:`model.stability`, :mod:`model.warmup`, :mod:`model.errors`).
"""

from typing import Any

__all__ = ["open_campaign"]


def __getattr__(name: str) -> Any:
    """``sweep.open_campaign`` (:func:`sweep.outputs.tables.open_campaign`), imported on first
    use so that ``import sweep`` (the command line) does not load pandas."""
    if name == "open_campaign":
        from .outputs.tables import open_campaign

        return open_campaign
    raise AttributeError(f"module 'sweep' has no attribute {name!r}")
