"""Seeds by precision: a campaign's ``precision:`` section runs each grid point's seeds in
order (the campaign's first ``initial``, then ``add`` more per round) until the point is
decided: its observable's seed mean is precise enough, its pattern class is unanimous, or
every seed has run (the cap).

- :mod:`nematic_solids.sweep.spec.precision`: the section's reader and checks
  (:class:`PrecisionSpec` is in :mod:`nematic_solids.sweep.campaign`).
- :mod:`nematic_solids.sweep.precision.decide`: the pure decision of a point from its seeds' values
  (the Student-t interval of the mean, the unanimity of the class).
- :mod:`nematic_solids.sweep.precision.rounds`: the rounds replayed from the run files
  (:func:`replay`), the plan file ``precision.json``, the expansion for ``phase.nc`` and ``nematic
  status`` (``seed_count``, ``seed_decision``) and the text ``validate`` and ``status`` print.

``nematic run`` drives the rounds with the adaptive campaigns' loop
(:func:`nematic_solids.sweep.refine.driver.drive_rounds`). With a ``refine:`` section the same
decisions are taken at every point of the adaptive campaign, grid and refined
(:mod:`nematic_solids.sweep.refine.seeds`), in the rounds :mod:`nematic_solids.sweep.refine.rounds`
replays.
"""
