"""Active nematic solids: the physics (paper: Yang, Guo, Mahadevan, arXiv 2504.07354).

This package never imports :mod:`nematic_solids.sweep`; the campaign manager uses it only through
:class:`nematic_solids.model.parameters.Parameters`,
:class:`nematic_solids.model.parameters.Numerics` and :func:`nematic_solids.model.simulate.run`.
"""

__version__ = "0.2.0"
