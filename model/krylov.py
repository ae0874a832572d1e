"""Krylov solvers on arbitrary array-shaped unknowns with a caller-supplied inner product.

The mechanics works on Fourier half spectra, whose real-space inner product carries Parseval
weights, so scipy's vector solvers (plain Euclidean dot) do not fit; these are the textbook
algorithms (Saad, *Iterative Methods for Sparse Linear Systems*, 2nd ed., Alg. 9.1
preconditioned CG and Alg. 9.5 right-preconditioned GMRES).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

Array = np.ndarray
Op = Callable[[Array], Array]
Inner = Callable[[Array, Array], float]


def pcg(
    A: Op, b: Array, x0: Array, M: Op, inner: Inner, *, rtol: float, maxiter: int
) -> tuple[Array, int, str]:
    """Preconditioned conjugate gradients for symmetric positive definite ``A``.

    Stops when the preconditioned residual norm ``sqrt(r.M r)`` falls below ``rtol`` times
    that of ``b``. Returns ``(x, iterations, status)`` with status "ok", "maxiter" or
    "indefinite" (a direction of non-positive curvature: the operator is not SPD).
    """
    x = x0.copy()
    r = b - A(x) if np.any(x) else b.copy()  # a zero start needs no operator application
    z = M(r)
    p = z.copy()
    rz = inner(r, z)
    ref = np.sqrt(abs(inner(b, M(b)))) or 1.0
    for it in range(maxiter + 1):
        if np.sqrt(abs(rz)) <= rtol * ref:
            return x, it, "ok"
        if it == maxiter:
            break
        Ap = A(p)
        pAp = inner(p, Ap)
        if pAp <= 0:
            return x, it, "indefinite"
        step = rz / pAp
        x += step * p
        r -= step * Ap
        z = M(r)
        rz_new = inner(r, z)
        p = z + (rz_new / rz) * p
        rz = rz_new
    return x, maxiter, "maxiter"


def gmres(
    A: Op, b: Array, x0: Array, M: Op, inner: Inner, *, rtol: float, maxiter: int, restart: int = 30
) -> tuple[Array, int, str]:
    """Right-preconditioned restarted GMRES: solve ``A x = b`` as ``A M y = b, x = M y``.

    Stops when ``||b - A x|| <= rtol ||b||``. Returns ``(x, iterations, status)``.
    """
    x, it, status, _ = _gmres(
        lambda v: (A(v), None), b, x0, M, inner, rtol=rtol, maxiter=maxiter, restart=restart
    )
    return x, it, status


def gmres_aux(
    op: Callable[[Array], tuple[Array, Array]],
    b: Array,
    x0: Array,
    M: Op,
    inner: Inner,
    *,
    rtol: float,
    maxiter: int,
    restart: int = 30,
    Lx0: Array | None = None,
    op_given_aux: Callable[[Array, Array], Array] | None = None,
) -> tuple[Array, int, str, Array]:
    """GMRES for an operator that returns ``(A v, L v)``, L another linear map: also returns
    ``L x`` for the solution, taken from the final true-residual evaluation (so a quantity the
    operator computes anyway need not be recomputed). ``Lx0``, if given, is ``L x0`` of the
    start, and ``op_given_aux(v, L v)`` is then ``A v`` from it: the start's residual uses
    them (for the finite-strain rate operator, whose L is the real-space gradient, four
    transforms fewer; compiled twin: :func:`nematic_solids.model.compiled.krylov.gmres`)."""
    x, it, status, Lx = _gmres(
        op,
        b,
        x0,
        M,
        inner,
        rtol=rtol,
        maxiter=maxiter,
        restart=restart,
        Lx0=Lx0,
        op_given_aux=op_given_aux,
    )
    if Lx is None:  # a zero start that needed no iteration (b = 0): L x = L 0
        Lx = op(x)[1]
    return x, it, status, Lx


def _gmres(
    op: Callable[[Array], tuple[Array, Array | None]],
    b: Array,
    x0: Array,
    M: Op,
    inner: Inner,
    *,
    rtol: float,
    maxiter: int,
    restart: int,
    Lx0: Array | None = None,
    op_given_aux: Callable[[Array, Array], Array] | None = None,
) -> tuple[Array, int, str, Array | None]:
    """Restarted GMRES; the auxiliary output ``L x`` is accumulated from the ``L z`` of the
    basis (L is linear), so a cycle that converges needs no extra operator application: the
    stopping test uses the Givens-rotated residual estimate, the true residual is recomputed
    only at a restart. A zero start ``x0 = 0`` needs no operator application for its residual
    (it is ``b``; ``L x`` is then None until the first update); a start whose ``L x0`` is
    given (``Lx0``, with ``op_given_aux``) takes its residual from it."""
    x = x0.copy()
    bnorm = np.sqrt(inner(b, b)) or 1.0
    total = 0
    Lx: Array | None = None
    zero_start = not np.any(x)  # then r = b and L x = 0: no operator application
    known_aux = Lx0 is not None and op_given_aux is not None and not zero_start
    while True:
        if zero_start:
            r, zero_start = b.copy(), False
        elif known_aux and Lx0 is not None and op_given_aux is not None:
            Lx, known_aux = Lx0.copy(), False
            r = b - op_given_aux(x, Lx)
        else:
            Ax, Lx = op(x)
            r = b - Ax  # the true residual (and L x of the current iterate)
        beta = np.sqrt(inner(r, r))
        if beta <= rtol * bnorm or total >= maxiter:
            return x, total, ("ok" if beta <= rtol * bnorm else "maxiter"), Lx
        V = [r / beta]
        Z: list[Array] = []
        LZ: list[Array | None] = []
        H = np.zeros((restart + 1, restart))
        g = np.zeros(restart + 1)
        g[0] = beta
        cs = np.zeros(restart)
        sn = np.zeros(restart)
        k = 0
        for k in range(restart):
            z = M(V[k])
            Z.append(z)
            w, Lz = op(z)
            LZ.append(Lz)
            for i in range(k + 1):  # modified Gram-Schmidt
                H[i, k] = inner(V[i], w)
                w = w - H[i, k] * V[i]
            h_next = np.sqrt(max(inner(w, w), 0.0))
            H[k + 1, k] = h_next
            givens_column(H, g, cs, sn, k)
            total += 1
            if abs(g[k + 1]) <= rtol * bnorm or total >= maxiter or h_next <= 1e-14 * beta:
                break  # converged, out of budget, or happy breakdown (exact solution)
            V.append(w / h_next)
        m = k + 1
        y = np.linalg.solve(np.triu(H[:m, :m]), g[:m])
        for i in range(m):
            x = x + y[i] * Z[i]
            Lz_i = LZ[i]
            if Lz_i is not None:  # (None: the operator has no auxiliary output)
                Lx = y[i] * Lz_i if Lx is None else Lx + y[i] * Lz_i
        if abs(g[m]) <= rtol * bnorm or h_next <= 1e-14 * beta:
            return x, total, "ok", Lx


def givens_column(H: Array, g: Array, cs: Array, sn: Array, k: int) -> None:
    """Apply the previous rotations to column ``k`` of the Hessenberg matrix ``H``, then the
    new rotation that zeroes ``H[k + 1, k]``, updating the residual vector ``g`` (Saad
    Alg. 6.9's Givens QR; compiled twin:
    :func:`nematic_solids.model.compiled.krylov.givens_column`)."""
    for i in range(k):
        t = cs[i] * H[i, k] + sn[i] * H[i + 1, k]
        H[i + 1, k] = -sn[i] * H[i, k] + cs[i] * H[i + 1, k]
        H[i, k] = t
    denom = float(np.hypot(H[k, k], H[k + 1, k])) or 1e-300
    cs[k] = H[k, k] / denom
    sn[k] = H[k + 1, k] / denom
    H[k, k] = denom
    H[k + 1, k] = 0.0
    g[k + 1] = -sn[k] * g[k]
    g[k] = cs[k] * g[k]
