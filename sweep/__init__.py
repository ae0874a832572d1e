"""The campaign manager: declarative YAML campaigns fanned out over dask, resumable on disk,
aggregated into netCDF phase diagrams, fits and the paper's figures.

Module map (docs/architecture.md has one line per module and the direction of imports):

- :mod:`sweep.errors`, :mod:`sweep.limits`  the exceptions; bounds checked before anything runs
- :mod:`sweep.campaign`   a validated campaign as frozen data, and the names it is checked against
- :mod:`sweep.spec`       campaign YAML -> :class:`~sweep.campaign.Campaign` (with
  :mod:`sweep.yaml_input`, :mod:`sweep.checker` and one reader per section:
  :mod:`sweep.sections`, :mod:`sweep.sweep_section`, :mod:`sweep.execution_section`)
- :mod:`sweep.identity`   run_id: hash of canonical parameters + seed + numerics + schema
- :mod:`sweep.expand`     Campaign -> grid points and runs (with their run_ids)
- :mod:`sweep.files`, :mod:`sweep.store`  atomic files; results/<name>/: records, manifest, lock
- :mod:`sweep.task`, :mod:`sweep.plan`, :mod:`sweep.execute`  the worker task, what remains to
  do, the dask driver; :mod:`sweep.clusters`, :mod:`sweep.workforce` start and watch the cluster
- :mod:`sweep.status`     done / failed / pending counts without opening the netCDF files
- :mod:`sweep.aggregate`  results/<name>/phase.nc
- :mod:`sweep.analysis`   the fits (fits.nc); :mod:`sweep.figures` the paper's figures
- :mod:`sweep.provenance` code version and git commit
- :mod:`sweep.tables`     :func:`open_campaign`: the results from Python (phase diagram
  as an xarray Dataset, runs as a pandas table), ``nematic export``
- :mod:`sweep.cli`        the ``nematic`` program (typer; also ``python -m sweep``)

It knows the physics only through :class:`model.parameters.Parameters`,
:class:`model.parameters.Numerics`, :func:`model.simulate.run` and a few more entries
(:mod:`model.stability`, :mod:`model.warmup`, :mod:`model.errors`).
"""

from typing import Any

__all__ = ["open_campaign"]


def __getattr__(name: str) -> Any:
    """``sweep.open_campaign`` (:func:`sweep.tables.open_campaign`), imported on first use so
    that ``import sweep`` (the command line) does not load pandas."""
    if name == "open_campaign":
        from .tables import open_campaign

        return open_campaign
    raise AttributeError(f"module 'sweep' has no attribute {name!r}")
