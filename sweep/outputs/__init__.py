"""What a campaign's results folder says, read back: ``phase.nc``
(:mod:`~nematic_solids.sweep.outputs.aggregate`), where the campaign stands
(:mod:`~nematic_solids.sweep.outputs.status`), the results as tables from Python
(:mod:`~nematic_solids.sweep.outputs.tables`) and what changed in the campaign file since the
results were made (:mod:`~nematic_solids.sweep.outputs.changes`). It never imports
:mod:`nematic_solids.sweep.run` (whose driver calls it) nor the command line."""
