"""The paper's figures from a campaign's results: ``results/<name>/figures/<fig>.{png,pdf}``.

Every figure reads only results files: ``phase.nc``, ``fits.nc`` (written just before from
the fits the figure needs, :mod:`sweep.analysis`) and the run files ``runs/<run_id>.nc``.

- :mod:`~sweep.figures.common`    the results folder, grid points and runs, formats, options
- :mod:`~sweep.figures.snapshot`  one run's snapshot, director over the I1bar background
- :mod:`~sweep.figures.fig2`, :mod:`~sweep.figures.fig3`, :mod:`~sweep.figures.fig4`,
  :mod:`~sweep.figures.figA1`: one module per figure of the paper
- :mod:`~sweep.figures.registry`  the figures by name, the fits each needs, when each applies
- :mod:`~sweep.figures.produce`   plan, draw and write them (``nematic figures``, and the
  end of ``nematic run``)

What each figure shows, and its options, is documented for users in docs/campaigns.md.
"""
