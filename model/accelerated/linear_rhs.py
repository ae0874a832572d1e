r"""The small-strain split right-hand side in JAX, for one seed (``jax.vmap`` batches it):
what :meth:`nematic_solids.model.split.SpectralSplit.reference` and
:func:`nematic_solids.model.compiled.linear_rhs.linear_split` compute. From q1, q2, A and the
spectra :math:`\hat q` of q1, q2,

.. math::
    \hat H = \widehat{b(q, A)\, q} + B\, \widehat{\mathrm{dev}\, e}, \quad
    R = \hat H/\gamma + L_q \hat q, \quad
    (I - M)\,\hat\omega = \Omega[R], \quad M \hat\omega = \Omega[\widehat{2 \omega J q}], \\
    \hat N_q = R + \widehat{2\omega J q} - L_q \hat q, \qquad
    \dot A = (-\zeta A - \chi\, \mathrm{tr}\,\sigma - s A^3)/\tau \quad (\text{Eq. 5}),

with :math:`b = A + C\, Q:Q - 2 B' \mathrm{tr}\, e` (Eq. 4: H = -(A + A0 + C Q:Q - 2 B'
(J - 1)) Q + B dev Ebar + K lap Q, of which A0 and the Frank term are in :math:`L_q = -(A_0 +
K k^2)/\gamma`), the small-strain response (docs/model/equations.md: the Green operator
of the isotropic medium) as the real Fourier symbols ``S[r, c]`` of
:meth:`nematic_solids.model.mechanics.LinearMechanics.response_symbols` (outputs r: dev e (2
components), tr e, tr sigma; inputs c: q1 hat, q2 hat, -B' Q:Q hat) plus the applied mean strain
eps, and the Jaumann spin :math:`\hat\omega = -\tfrac12 (\alpha - B)\, \hat t \cdot \hat{\dot Q}
\cdot \hat k` (the spin symbols ``m1``, ``m2`` of
:meth:`nematic_solids.model.mechanics.LinearMechanics.spin_multiplier`) with its feedback on
:math:`\dot Q` solved by GMRES from zero (:mod:`nematic_solids.model.accelerated.krylov`) to
``spin_tol``.

The symbols are made by the numpy reference's own code (:func:`setup`), so the two share
one definition of the mechanics; only the pointwise algebra and the transforms are here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple, TypeAlias

import jax
import jax.numpy as jnp
import numpy as np

from ..parameters import Numerics, Parameters
from ..pde import ActiveNematicPDE
from .dtypes import real_dtype, wide_sum
from .krylov import gmres_aux

Array: TypeAlias = jax.Array
#: a constant array: made on the host (numpy), then put on the device (a jax.Array)
Constant: TypeAlias = Any


class Symbols(NamedTuple):
    """The run's constant Fourier symbols (half spectra, shape (N, N // 2 + 1)): ``Lq``,
    the spin symbols ``m1``, ``m2``, the small-strain response ``S`` (4, 3, ...), the
    Parseval weights over N^2 ``w`` (the real-space inner product of half spectra)."""

    Lq: Constant
    m1: Constant
    m2: Constant
    S: Constant
    w: Constant


@dataclass(frozen=True)
class Constants:
    """The scalars of Eqs. (4)-(5) and of the spin solve (fixed at trace time under
    ``jax.jit``): the grid size ``n``, ``mean_dev`` = eps N^2 (the applied mean strain on the
    zero mode of the unnormalised spectrum), ``amb`` = alpha - B."""

    n: int
    B: float
    Bp: float
    C: float
    gamma: float
    zeta: float
    chi: float
    s: float
    tau: float
    mean_dev: float
    amb: float
    spin_tol: float
    spin_maxiter: int
    restart: int = 30
    #: the name of the seeds' axis under ``jax.vmap`` (None: one seed, unbatched)
    batch_axis: str | None = None
    #: the fields' precision (``Numerics.precision``;
    #: :mod:`nematic_solids.model.accelerated.dtypes`)
    precision: str = "float64"


def setup(params: Parameters, numerics: Numerics) -> tuple[Symbols, Constants]:
    """The symbols (numpy arrays) and constants of a small-strain run, from the numpy
    reference's PDE and :class:`nematic_solids.model.mechanics.LinearMechanics`."""
    eq = ActiveNematicPDE(params, numerics.replace(backend="numpy"))
    p, g, mech = eq.params, eq.spectral, eq.mechanics
    m1, m2 = mech.spin_symbols  # type: ignore[attr-defined]
    symbols = Symbols(
        Lq=-(p.A0 + p.K * g.k2) / p.gamma,
        m1=np.asarray(m1),
        m2=np.asarray(m2),
        S=mech.response_symbols(),  # type: ignore[attr-defined]
        w=g.weights / g.n**2,
    )
    consts = Constants(
        n=g.n,
        B=p.B,
        Bp=p.B_prime,
        C=p.C,
        gamma=p.gamma,
        zeta=p.zeta,
        chi=p.chi,
        s=p.s,
        tau=p.tau,
        mean_dev=p.eps * g.n**2,
        amb=p.alpha_minus_B,
        spin_tol=numerics.spin_tol,
        spin_maxiter=mech.spin_maxiter,  # type: ignore[attr-defined]
        precision=numerics.precision,
    )
    return symbols, consts


def forward(a: Array) -> Array:
    """``rfft2`` over the last two axes (unnormalised, as numpy and FFTW)."""
    return jnp.fft.rfft2(a)


def inverse(a: Array, n: int) -> Array:
    """``irfft2`` over the last two axes onto an n x n grid (divides by N^2)."""
    return jnp.fft.irfft2(a, s=(n, n))


def weighted_inner(w: Array) -> Callable[[Array, Array], Array]:
    """The real-space inner product of half spectra, :math:`\\sum w\\, \\mathrm{Re}(\\bar a
    b)` (Parseval; ``w`` repeats over leading axes), accumulated in float64 whatever the
    precision of ``a`` and ``b`` (a float64 scalar)."""

    def inner(a: Array, b: Array) -> Array:
        return wide_sum(w * (a.real * b.real + a.imag * b.imag))

    return inner


class Rate(NamedTuple):
    """One evaluation: ``Nq`` (the spectra of N_q), ``Adot``, the spin solve's
    ``iterations`` and whether it ``converged``, and the ``transforms`` it took."""

    Nq: Array
    Adot: Array
    iterations: Array
    converged: Array
    transforms: Array


def linear_split(q: Array, A: Array, q_hat: Array, sym: Symbols, c: Constants) -> Rate:
    """The split right-hand side of one seed (module docstring): ``q`` (2, N, N), ``A``
    (N, N), ``q_hat`` (2, N, N // 2 + 1)."""
    n = c.n
    q1, q2 = q[0], q[1]
    S = sym.S
    a, b = q_hat[0], q_hat[1]
    nfft = 3
    if c.Bp != 0.0:
        iso = -c.Bp * forward(2.0 * (q1 * q1 + q2 * q2))
        tr_e_hat = S[2, 0] * a + S[2, 1] * b + S[2, 2] * iso
        tr_s_hat = S[3, 0] * a + S[3, 1] * b + S[3, 2] * iso
        tr_e = inverse(tr_e_hat, n)
        nfft += 2
    else:
        tr_s_hat = S[3, 0] * a + S[3, 1] * b
        tr_e = jnp.zeros_like(A)
    tr_s = inverse(tr_s_hat, n)
    bulk = A + c.C * 2.0 * (q1 * q1 + q2 * q2) - 2.0 * c.Bp * tr_e
    R = forward(jnp.stack([-bulk * q1, -bulk * q2]))
    d0 = S[0, 0] * a + S[0, 1] * b
    d1 = S[1, 0] * a + S[1, 1] * b
    if c.Bp != 0.0:
        d0 = d0 + S[0, 2] * iso
        d1 = d1 + S[1, 2] * iso
    d0 = d0.at[0, 0].add(c.mean_dev)  # the applied mean strain
    R = jnp.stack(
        [(R[0] + c.B * d0) / c.gamma + sym.Lq * a, (R[1] + c.B * d1) / c.gamma + sym.Lq * b]
    )
    rhs = sym.m1 * R[0] + sym.m2 * R[1]

    def spin_operator(x: Array) -> tuple[Array, Array]:
        """``((I - M) x, the spectra of 2 omega J q)`` for :math:`\\hat\\omega = x`."""
        omega = inverse(x, n)
        j = forward(jnp.stack([-2.0 * omega * q2, 2.0 * omega * q1]))
        return x - (sym.m1 * j[0] + sym.m2 * j[1]), j

    sol = gmres_aux(
        spin_operator,
        rhs,
        (2,) + rhs.shape,
        weighted_inner(sym.w),
        rtol=c.spin_tol,
        maxiter=c.spin_maxiter,
        restart=c.restart,
        batch_axis=c.batch_axis,
    )
    Nq = R + sol.Lx - sym.Lq * q_hat
    Adot = (-c.zeta * A - c.chi * tr_s - c.s * A * A * A) / c.tau
    return Rate(Nq, Adot, sol.iterations, sol.converged, nfft + 3 * sol.applications)


def symbols_on(sym: Symbols, device: jax.Device, precision: str = "float64") -> Symbols:
    """The symbols as arrays of the run's ``precision`` (real) on ``device``."""
    dtype = real_dtype(precision)
    return Symbols(*(jax.device_put(np.asarray(a, dtype=dtype), device) for a in sym))
