"""The cost of a campaign before it runs: the runs it has still to do, costed from its own
finished runs or the calibrated cost model of one run (:mod:`~nematic_solids.sweep.cost.model`),
with the later rounds of an adaptive campaign or of seeds by precision
(:mod:`~nematic_solids.sweep.cost.estimate`: ``nematic run --dry-run``, ``nematic validate
--estimate``). It reads, never writes."""
