"""The paper's figures from a campaign's results: ``results/<name>/figures/<fig>.{png,pdf}``.

Every figure reads only results files: ``phase.nc``, ``fits.nc`` (written just before from
the fits the figure needs, :mod:`nematic_solids.sweep.analysis`) and the run files
``runs/<run_id>.nc``.

Its modules (under :mod:`nematic_solids.sweep.figures`):

- ``common``: the results folder, grid points and runs, formats, options
- ``snapshot``: one run's snapshot, director over the I1bar background
- ``fig2``, ``fig3``, ``fig4``, ``figA1``: one module per figure of the paper
- ``registry``: the figures by name, the fits each needs, when each applies
- ``produce``: plan, draw and write them (``nematic figures``, and the end of ``nematic run``)
- ``failed``: the fits and figures that failed, kept for the report (``failed_products.json``)

What each figure shows, and its options, is documented for users in docs/campaigns/figures.md.
"""
