"""Adaptive campaigns: a campaign's ``refine:`` section refines one or several sweep axes
where the outcome changes and adds seeds where it is uncertain (by its own ``seeds:`` or by
the ``precision:`` section's rules), in rounds planned from the run records on disk.

- :mod:`nematic_solids.sweep.spec.refine`: the ``refine:`` section (:class:`RefineSpec`) and its
  check.
- :mod:`nematic_solids.sweep.refine.plan`: the pure planning (the first round; the next round from
  the outcomes of the runs so far; the upper bound on the run count).
- :mod:`nematic_solids.sweep.refine.stats`: what the seeds of one point say (its class, mixed or
  not; the geometric seed mean), boundary cells and uncertain points.
- :mod:`nematic_solids.sweep.refine.seeds`: the seeds each point gets next and why.
- :mod:`nematic_solids.sweep.refine.rounds`: the outcomes read from the results folder, the replay
  of the rounds from them (:func:`replay`), the plan file ``refine.json`` and the expansions the
  rest of :mod:`nematic_solids.sweep` runs, counts and aggregates.
- :mod:`nematic_solids.sweep.refine.driver`: ``nematic run`` of a refined campaign (run a round,
  plan the next, until no cell is left to refine or the rounds are used).
- :mod:`nematic_solids.sweep.refine.report`: the text ``validate`` and ``status`` print.
"""
