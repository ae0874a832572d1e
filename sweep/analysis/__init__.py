"""The fits of a campaign's phase diagram, with their uncertainties (``fits.nc``).

- :mod:`~sweep.analysis.statistics`  seed means, the seed bootstrap, intervals, lines
- :mod:`~sweep.analysis.phase`       reading phase.nc: sweep dims, fixed parameters, selections
- :mod:`~sweep.analysis.options`     the options every fit takes and their check
- :mod:`~sweep.analysis.transition`, :mod:`~sweep.analysis.sizes` (``alpha_cr``, ``scaling``),
  :mod:`~sweep.analysis.anisotropy`, :mod:`~sweep.analysis.stability`: one module per fit
- :mod:`~sweep.analysis.registry`    the fits by name
- :mod:`~sweep.analysis.fits_file`   computing and writing ``fits.nc``; reading results back

What each fit computes, and its options, is documented for users in docs/campaigns.md.
"""
