"""Verification: a campaign's convergence and sensitivity checks (its ``verify:`` section).

- :mod:`nematic_solids.sweep.spec.verify`: the ``verify:`` section
  (:class:`~nematic_solids.sweep.campaign.VerifySpec`), its check, and a variant's settings at a
  point (:func:`~nematic_solids.sweep.spec.verify.resolve`).
- :mod:`nematic_solids.sweep.verify.sample`: the sampled points (both sides of each fitted
  transition, the grid's corners, or the points listed), their base runs and the variants' runs.
- :mod:`nematic_solids.sweep.verify.measure`: ``verify.nc`` (values, relative changes, verdicts, the
  transitions recomputed).
- :mod:`nematic_solids.sweep.verify.summary`: ``verify.nc`` read back, its one-line summary and the
  rows of the report's and ``status -v``'s tables.
- :mod:`nematic_solids.sweep.verify.driver`: running a verification on one dask cluster (``nematic
  verify``, and ``nematic run`` of a campaign with a ``verify:`` section).
"""

#: A verdict (the flag values of verify.nc's ``*_verdict`` and ``converged``).
CONVERGED, CHANGED, NOT_COMPARED, MISSING = 1, 0, -1, -2
#: The verification's file in the campaign's results folder.
VERIFY = "verify.nc"
#: What every reader of verify.nc relies on.
REQUIRED = ("converged", "patterned", "patterned_base", "variant_name", "label", "why")


def stale(missing: list[str]) -> str:
    """Why a verify.nc without the ``missing`` variables cannot be read."""
    return (
        f"it has no {', '.join(missing)} (written by another version: rerun nematic "
        "verify, which rewrites it from the runs)"
    )
