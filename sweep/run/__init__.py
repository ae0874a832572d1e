"""Running a campaign: what remains to do (:mod:`~sweep.run.todo`), the driver that feeds
dask (:mod:`~sweep.run.driver`), the worker task (:mod:`~sweep.run.task`), the cluster and
its workers (:mod:`~sweep.run.clusters`, :mod:`~sweep.run.workers`,
:mod:`~sweep.run.lifetime`), failure triage (:mod:`~sweep.run.failures`), a driver in the
background (:mod:`~sweep.run.detach`) and the cost before launch (:mod:`~sweep.cost.estimate`,
:mod:`~sweep.cost.model`). It uses the shared base (``sweep.campaign``, ``store``,
``expand``, ...) and :mod:`sweep.outputs`; :mod:`sweep.spec` never imports it."""
