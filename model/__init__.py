"""Active nematic solids: the physics (paper: Yang, Guo, Mahadevan, arXiv 2504.07354).

This package never imports :mod:`sweep`; the campaign manager uses it only through
:class:`model.parameters.Parameters`, :class:`model.parameters.Numerics` and
:func:`model.simulate.run`.
"""

__version__ = "0.2.0"
