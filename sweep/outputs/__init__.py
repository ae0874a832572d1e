"""What a campaign's results folder says, read back: ``phase.nc``
(:mod:`~sweep.outputs.aggregate`), where the campaign stands (:mod:`~sweep.outputs.status`),
the results as tables from Python (:mod:`~sweep.outputs.tables`) and what changed in the
campaign file since the results were made (:mod:`~sweep.outputs.changes`). It never imports
:mod:`sweep.run` (whose driver calls it) nor the command line."""
