"""The compiled layer (numba, cached on disk: ``cache=True``), one module per concept, each
naming its numpy twin:

=====================  ===================================================================
module                 numpy twin
=====================  ===================================================================
``arith``              the plain products ``c * z``, ``1j * c * z``
``constitutive``       :mod:`model.constitutive` (through :mod:`model.reference_kernels`)
``spectral``           :mod:`model.reference_kernels` (:class:`model.fourier.SpectralGrid`)
``etd``                :mod:`model.reference_kernels` (``phi_functions``)
``rates``              :mod:`model.reference_kernels` (:mod:`model.pde`'s expressions)
``wellposedness``      :func:`model.wellposedness.finite_margin_samples`
``krylov``             :mod:`model.krylov`
``linear_rhs``         :meth:`model.split.SpectralSplit.reference`
``finite_krylov``      :func:`model.krylov.pcg`, :func:`model.krylov.gmres` on the operators
                       of :class:`model.mechanics.FiniteMechanics`
``fftw``               :class:`model.fourier.FFT` with scipy.fft
``kernels``            the kernel set of ``Numerics.backend = "compiled"``
=====================  ===================================================================

Nothing here imports the classes that call it.
"""
