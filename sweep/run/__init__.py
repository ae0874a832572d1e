"""Running a campaign: what remains to do (:mod:`~nematic_solids.sweep.run.todo`), the driver that
feeds dask (:mod:`~nematic_solids.sweep.run.driver`), the worker task
(:mod:`~nematic_solids.sweep.run.task`), the cluster and its workers
(:mod:`~nematic_solids.sweep.run.clusters`, :mod:`~nematic_solids.sweep.run.workers`,
:mod:`~nematic_solids.sweep.run.lifetime`), failure triage
(:mod:`~nematic_solids.sweep.run.failures`), a driver in the background
(:mod:`~nematic_solids.sweep.run.detach`) and the cost before launch
(:mod:`~nematic_solids.sweep.cost.estimate`, :mod:`~nematic_solids.sweep.cost.model`). It uses the
shared base (``nematic_solids.sweep.campaign``, ``store``, ``expand``, ...) and
:mod:`nematic_solids.sweep.outputs`; :mod:`nematic_solids.sweep.spec` never imports it."""
