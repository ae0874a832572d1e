r"""The fast py-pde solvers: adaptive exponential time differencing (ETD) Runge-Kutta.

Both schemes split each field's rate into a stiff linear part and the rest N,

.. math::
    \dot{\hat q} = L_q \hat q + \hat N_q, \quad L_q = -(A_0 + K k^2)/\gamma, \qquad
    \dot A = L_A A + N_A, \quad L_A(x) = -(\zeta + 3 s A_n(x)^2)/\tau ,

so the Frank term and the linear decay of Q are integrated exactly in Fourier space, and the
local cubic of Eq. (5) (stiff once a pattern has formed: :math:`3 s A^2 \sim 25`) with its
pointwise Jacobian frozen at the start of the step (an exponential Rosenbrock-type splitting,
in real space: the split is exact for any frozen L, so the orders are unchanged). Both L are
diagonal (in Fourier space for q, point by point for A), so every :math:`\varphi_k(hL)` is a
pointwise function, :math:`\varphi_k(z) = \sum_j z^j/(j+k)!`.

**ETDRK4** (default, ``numerics.scheme = "etdrk4"``; Krogstad 2005, J. Comput. Phys. 203, 72),
four right-hand sides per step, with :math:`\varphi_k = \varphi_k(hL)`,
:math:`\tilde\varphi_k = \varphi_k(hL/2)`:

.. math::
    a &= e^{Lh/2} u_n + \tfrac h2 \tilde\varphi_1 N_u, \qquad
    b = a + h \tilde\varphi_2 (N_a - N_u), \qquad
    c = e^{Lh} u_n + h \varphi_1 N_u + 2 h \varphi_2 (N_b - N_u), \\
    u_{n+1} &= e^{Lh} u_n + h\big[(\varphi_1 - 3\varphi_2 + 4\varphi_3) N_u
      + (2\varphi_2 - 4\varphi_3)(N_a + N_b) + (4\varphi_3 - \varphi_2) N_c\big].

Error estimate: the same weights with :math:`2 N_a` in place of :math:`N_a + N_b` (Cox &
Matthews' third-order weights on the first-order midpoint stage a), i.e.
:math:`e = h (2\varphi_2 - 4\varphi_3)(N_b - N_a) = O(h^3)`; the step advances with the
fourth-order value (local extrapolation). Measured orders 3.8-4.1 (tests).

**ETDRK2** (``scheme = "etdrk2"``; Cox & Matthews 2002, J. Comput. Phys. 176, 430, Eq. 22):

.. math::
    a = e^{L h} u_n + h\, \varphi_1(L h)\, N(u_n), \qquad
    u_{n+1} = a + h\, \varphi_2(L h)\, \big(N(a) - N(u_n)\big),

with the difference ``u_{n+1} - a`` (O(h^2)) as the error estimate.

**Step control** (both; :mod:`nematic_solids.model.solver_base`, with the shared machinery of
:class:`ETDSolver`): the error estimate against ``numerics.tolerance``, the next step scaled by
:math:`(\mathrm{tol}/\mathrm{err})^{1/p}` and rounded onto a ladder of sizes, a failed stage
retried with h/4; ``adaptive = False`` gives the fixed-step schemes (orders tested).

In linear mechanics the Jaumann spin is computed with the spectral symbol of
:meth:`nematic_solids.model.mechanics.LinearMechanics.spin_multiplier`, reusing the transforms the
step needs anyway, and the whole right-hand side runs as one compiled function
(:mod:`nematic_solids.model.compiled.linear_rhs`) where native FFTW is available and
``Numerics.backend`` is "compiled" (its numpy reference otherwise:
:mod:`nematic_solids.model.split`); the stage algebra is one pass per stage (the backend's
``etd_combination``), and without a protocol the whole ETDRK4 step of linear mechanics is one
compiled call (:mod:`nematic_solids.model.compiled.linear_step`, bitwise this Python step);
finite mechanics uses the generic :meth:`ActiveNematicPDE.rates` path with the displacement-rate
solve (its Krylov solves compiled, :mod:`nematic_solids.model.compiled.finite_krylov`), with the
displacement integrated with the state or Newton warm-started from the last stage's displacement
plus its rate times the time offset.
"""

from __future__ import annotations

import numpy as np

from .compiled import linear_step
from .pde import ActiveNematicPDE

# ETDSolver is imported from here too (nematic_solids.model.simulate)
from .reference_kernels import phi_functions
from .solver_base import Array, ETDSolver, _cached
from .split import SpectralSplit


class ETDRK2Solver(ETDSolver):
    """Adaptive ETDRK2 (Cox & Matthews ETD2RK, embedded ETD1 error estimate)."""

    name = "etdrk2"
    error_order = 2

    def step(self, u: Array, t: float, h: float) -> tuple[Array, float]:
        """One ETDRK2 step; returns (new state, error estimate)."""
        g = self.pde.spectral
        q_hat = self._spectrum(u[:2])
        A = u[2]
        self._checkpointed = False
        fin = self._integrated_mechanics()
        d0 = fin.u_hat if fin is not None else None
        Nq0, Adot0 = self.split(u, q_hat, t, d0)
        self.check_wellposed(u, t)
        self._checkpoint()
        E, phi1, phi2 = self._phis(h)
        p = self.pde.params
        LA, phi1A, phi2A = self.k.activity_exponential(A, h, p.zeta, p.s, p.tau)
        aq_hat = E * q_hat + h * phi1 * Nq0
        aA = A + h * phi1A * Adot0  # = e^{L h} A + h phi1 (Adot - L A)
        a = np.concatenate([g.inverse(aq_hat), aA[None]])
        # the displacement: ETD with L = 0, i.e. Heun's method (its deformation gradient
        # alongside, in real space, from the rates' gradients)
        da = V0 = G0 = Fa = None
        if fin is not None and d0 is not None:
            V0, G0 = fin.udot_hat, fin.udot_grad
            d0 = np.ascontiguousarray(d0)
            da = self.k.rk_stage(d0, h, V0)
            if self.carry_deformation:
                Fa = self.k.rk_stage(np.ascontiguousarray(fin.deformation_of(d0)), h, G0)
        else:  # first-order predictor of Newton's start
            self.pde.mechanics.predict(h)
        Nqa, Adota = self.split(a, aq_hat, t + h, da, Fa)
        corr_q = h * phi2 * (Nqa - Nq0)
        corr_A = h * phi2A * (Adota - Adot0 - LA * (aA - A))
        if fin is None or da is None or V0 is None or G0 is None:
            return self._finish(u, q_hat, aq_hat + corr_q, aA + corr_A, corr_q, corr_A)
        corr_d = 0.5 * h * (fin.udot_hat - V0)
        corr_G = 0.5 * h * (fin.udot_grad - G0)
        return self._finish(
            u,
            q_hat,
            aq_hat + corr_q,
            aA + corr_A,
            corr_q,
            corr_A,
            (da + corr_d, None if Fa is None else Fa + corr_G),
            corr_G,
        )


class ETDRK4Solver(ETDSolver):
    """Adaptive fourth-order ETD Runge-Kutta of Krogstad (2005), with an embedded O(h^3)
    error estimate (see module docstring)."""

    name = "etdrk4"
    error_order = 3

    def __init__(self, pde: ActiveNematicPDE, **kwargs):
        super().__init__(pde, **kwargs)
        self._weight_cache: dict[float, tuple[Array, Array, dict[str, tuple[Array, ...]]]] = {}
        #: the split where the whole step runs compiled
        #: (:mod:`nematic_solids.model.compiled.linear_step`: linear mechanics compiled, no
        #: protocol, whose constants would change between the stages); else None
        split = self._split
        self._compiled_split = (
            split
            if isinstance(split, SpectralSplit)
            and split.compiled_data is not None
            and not pde.protocol
            else None
        )

    def step(self, u: Array, t: float, h: float) -> tuple[Array, float]:
        """One Krogstad ETDRK4 step; returns (new state, error estimate)."""
        if self._compiled_split is not None:
            return self._compiled_step(u, t, h, self._compiled_split)
        g = self.pde.spectral
        p = self.pde.params
        self._checkpointed = False
        q_hat = self._spectrum(u[:2])
        A = u[2]
        E, E2, wq = self._krogstad_weights(h)
        LA, W = self.k.activity_krogstad(A, h, p.zeta, p.s, p.tau)  # pointwise L_A: no cache
        EA, EA2 = W[0], W[1]
        wA = {"a": (W[2],), "b": (W[3], W[4]), "c": (W[5], W[6]), "new": (W[7], W[8], W[8], W[9])}
        comb = self.k.etd_combination

        def combo_q(Eq: Array, x: Array, w: tuple[Array, ...], N: tuple[Array, ...]) -> Array:
            return comb(Eq, x, h, w, N)

        def combo_A(Ea: Array, x: Array, w: tuple[Array, ...], N: tuple[Array, ...]) -> Array:
            return comb(Ea, x[None], h, w, tuple(n[None] for n in N))[0]

        fin = self._integrated_mechanics()

        def rhs(
            q_s: Array, A_s: Array, t_s: float, d_s: Array | None, F_s: Array | None
        ) -> tuple[Array, Array]:
            """Stage (q spectra, A[, displacement spectrum and its deformation gradient]) ->
            (N_q hat, N_A) with N_A = Adot - L_A A (the displacement rate is then the
            mechanics' udot_hat, its gradient udot_grad)."""
            stage = np.empty((3,) + A_s.shape)
            g.inverse(q_s, out=stage[:2])
            stage[2] = A_s
            Nq, Adot = self.split(stage, q_s, t_s, d_s, F_s)
            return Nq, Adot - LA * A_s

        d0 = fin.u_hat if fin is not None else None
        Nq_u, Adot_u = self.split(u, q_hat, t, d0)
        self.check_wellposed(u, t)
        NA_u = Adot_u - LA * A
        self._checkpoint()
        # the integrated displacement (L = 0: the weights become the classical RK4's,
        # phi_k(0) = 1/k!): d_a = d + h/2 V_u, d_b = d + h/2 V_a, d_c = d + h V_b, and its
        # deformation gradient alongside in real space, F_a = F + h/2 grad V_u, ..., from
        # the rates' gradients that the rate solves return (no transforms)
        V: list[Array] = []  # the rates (spectra)
        G: list[Array] = []  # their gradients
        d_a = d_b = d_c = F0 = F_a = F_b = F_c = None
        rk = self.k.rk_stage  # x0 + c v in one pass
        if fin is not None and d0 is not None:
            d0 = np.ascontiguousarray(d0)
            # (without carrying F, under a protocol of eps: each stage transforms its own)
            carry = self.carry_deformation
            F0 = np.ascontiguousarray(fin.deformation_of(d0)) if carry else np.empty(0)
            V.append(fin.udot_hat)
            G.append(fin.udot_grad)
            d_a = rk(d0, 0.5 * h, V[0])
            F_a = rk(F0, 0.5 * h, G[0]) if carry else None
        else:  # Newton's start: the displacement extrapolated with its rate
            self.pde.mechanics.predict(0.5 * h)
        # stage a (t + h/2): ETD1 half step
        Nq_a, NA_a = rhs(
            combo_q(E2, q_hat, wq["a"], (Nq_u,)),
            combo_A(EA2, A, wA["a"], (NA_u,)),
            t + 0.5 * h,
            d_a,
            F_a,
        )
        if fin is not None and d0 is not None and F0 is not None:
            V.append(fin.udot_hat)
            G.append(fin.udot_grad)
            d_b = rk(d0, 0.5 * h, V[1])
            F_b = rk(F0, 0.5 * h, G[1]) if carry else None
        # stage b (t + h/2): Krogstad's correction with phi_2, a + h phi_2(h/2) (N_a - N_u)
        Nq_b, NA_b = rhs(
            combo_q(E2, q_hat, wq["b"], (Nq_u, Nq_a)),
            combo_A(EA2, A, wA["b"], (NA_u, NA_a)),
            t + 0.5 * h,
            d_b,
            F_b,
        )
        if fin is not None and d0 is not None and F0 is not None:
            V.append(fin.udot_hat)
            G.append(fin.udot_grad)
            d_c = rk(d0, h, V[2])
            F_c = rk(F0, h, G[2]) if carry else None
        else:
            self.pde.mechanics.predict(0.5 * h)
        # stage c (t + h)
        Nq_c, NA_c = rhs(
            combo_q(E, q_hat, wq["c"], (Nq_u, Nq_b)),
            combo_A(EA, A, wA["c"], (NA_u, NA_b)),
            t + h,
            d_c,
            F_c,
        )
        # the fourth-order combination
        new_q_hat = combo_q(E, q_hat, wq["new"], (Nq_u, Nq_a, Nq_b, Nq_c))
        new_A = combo_A(EA, A, wA["new"], (NA_u, NA_a, NA_b, NA_c))
        # embedded estimate: the same weights with N_a in place of (N_a + N_b)/2, i.e. the
        # Cox-Matthews third-order weights on the first-order midpoint stage: O(h^3)
        err_q = h * wq["new"][1] * (Nq_b - Nq_a)
        err_A = h * wA["new"][1] * (NA_b - NA_a)
        if fin is None or d0 is None or F0 is None:
            return self._finish(u, q_hat, new_q_hat, new_A, err_q, err_A)
        V.append(fin.udot_hat)
        G.append(fin.udot_grad)
        new_d = self.k.rk4_update(d0, h / 6.0, *V)  # d0 + h/6 (V0 + 2 V1 + 2 V2 + V3)
        new_F = self.k.rk4_update(F0, h / 6.0, *G) if self.carry_deformation else None
        return self._finish(
            u, q_hat, new_q_hat, new_A, err_q, err_A, (new_d, new_F), (h / 3.0) * (G[2] - G[1])
        )

    def _compiled_step(
        self, u: Array, t: float, h: float, split: SpectralSplit
    ) -> tuple[Array, float]:
        """:meth:`step` by its compiled twin
        (:func:`nematic_solids.model.compiled.linear_step.krogstad_linear_step`: the same
        kernels in the same order, so the same bits); the well-posedness check of the start
        comes first, the spin solves are booked in the order of the stages."""
        p, mech = self.pde.params, split.mech
        self._checkpointed = False
        u = np.ascontiguousarray(u)
        q_hat = np.ascontiguousarray(self._spectrum(u[:2]))
        E, E2, wq = self._krogstad_weights(h)
        self.check_wellposed(u, t)
        max_norm = self.error_norm == "max"
        new, new_q_hat, Nq_a, Nq_b, NA_a, NA_b, w_ab, its, ok, omega, err, nfft = (
            linear_step.krogstad_linear_step(
                u, q_hat, h, E, E2, wq["a"], wq["b"], wq["c"], wq["new"],
                p.zeta, p.s, p.tau, mech.zero_hat, split.compiled_data, max_norm,
            )
        )  # fmt: skip
        self.pde.spectral.fft.count += nfft
        self.stats["rhs"] += 4
        for i, offset in enumerate((0.0, 0.5 * h, 0.5 * h, h)):
            mech.accept_spin(omega, int(its[i]), bool(ok[i]), t + offset)
        self._checkpoint()
        if max_norm:  # formed in the compiled step: the value _finish would give
            return self._finish(u, q_hat, new_q_hat, new[2], None, None, new=new, err=err)
        err_q = h * wq["new"][1] * (Nq_b - Nq_a)  # as in step
        err_A = h * w_ab * (NA_b - NA_a)
        return self._finish(u, q_hat, new_q_hat, new[2], err_q, err_A, new=new)

    @staticmethod
    def _weights_from(
        f1: Array, f2: Array, f3: Array, g1: Array, g2: Array
    ) -> dict[str, tuple[Array, ...]]:
        """The stage and update weights of Krogstad's scheme from phi_k(hL) (f) and
        phi_k(hL/2) (g): a = e^{Lh/2} u + h [g1/2] N_u, b = e^{Lh/2} u + h [g1/2 - g2, g2]
        (N_u, N_a), c = e^{Lh} u + h [f1 - 2 f2, 2 f2] (N_u, N_b), u_{n+1} = e^{Lh} u +
        h [w_u, w_ab, w_ab, w_c] (N_u, N_a, N_b, N_c) (module docstring)."""
        w_ab = 2.0 * f2 - 4.0 * f3
        return {
            "a": (0.5 * g1,),
            "b": (0.5 * g1 - g2, g2),
            "c": (f1 - 2.0 * f2, 2.0 * f2),
            "new": (f1 - 3.0 * f2 + 4.0 * f3, w_ab, w_ab, 4.0 * f3 - f2),
        }

    def _krogstad_weights(self, h: float) -> tuple[Array, Array, dict[str, tuple[Array, ...]]]:
        """``(e^{L_q h}, e^{L_q h/2}, weights)`` for the q spectra, cached per step size
        (:func:`nematic_solids.model.solver_base._cached`; the phi functions themselves are not
        kept)."""

        def make() -> tuple[Array, Array, dict[str, tuple[Array, ...]]]:
            E, f1, f2, f3 = phi_functions(self.Lq * h, 3)
            E2, g1, g2 = phi_functions(self.Lq * (0.5 * h), 2)
            return E, E2, self._weights_from(f1, f2, f3, g1, g2)

        return _cached(self._weight_cache, h, make)


#: the schemes ``numerics.scheme`` may name
SCHEMES: dict[str, type[ETDSolver]] = {"etdrk4": ETDRK4Solver, "etdrk2": ETDRK2Solver}
