"""The campaign manager: declarative YAML campaigns fanned out over dask, resumable on disk,
aggregated into netCDF phase diagrams.

Module map (imports go down this list, never up):

- :mod:`sweep.errors`     the exception hierarchy (bad input, locked campaign)
- :mod:`sweep.spec`       campaign YAML -> validated :class:`~sweep.spec.Campaign`
- :mod:`sweep.identity`   run_id: hash of canonical parameters + seed + numerics + schema
- :mod:`sweep.expand`     Campaign -> grid points and runs (with their run_ids)
- :mod:`sweep.store`      results/<name>/: atomic run files, per-run records, manifest, lock
- :mod:`sweep.execute`    the worker task and the dask driver (local, scheduler, jobqueue)
- :mod:`sweep.status`     done / failed / pending counts without opening the netCDF files
- :mod:`sweep.aggregate`  results/<name>/phase.nc
- :mod:`sweep.provenance` code version and git commit
- :mod:`sweep.cli`        the ``nematic`` program (typer; also ``python -m sweep``): parses
  and calls; ``cli_simulate``, ``cli_stability``, ``cli_figures`` add their commands to it

It knows the physics only through :class:`model.parameters.Parameters`,
:class:`model.parameters.Numerics` and :func:`model.simulate.run`.
"""
