"""The fits of a campaign's phase diagram, with their uncertainties (``fits.nc``).

Its modules (under :mod:`nematic_solids.sweep.analysis`):

- ``statistics``: seed means, the seed bootstrap, intervals, lines
- ``phase``: reading phase.nc: sweep dims, fixed parameters, selections
- ``options``: the options every fit takes and their check
- ``transition``, ``sizes`` (``alpha_cr``, ``scaling``), ``anisotropy``, ``stability``: one
  module per fit
- ``registry``: the fits by name
- ``fits_file``: computing and writing ``fits.nc``; reading results back

What each fit computes, and its options, is documented for users in docs/campaigns/fits.md.
"""
