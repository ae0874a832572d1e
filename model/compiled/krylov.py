"""The pieces of the compiled Krylov solvers (numba): Givens rotations, back substitution,
weighted inner products and the fused Arnoldi step, shared by
:func:`nematic_solids.model.compiled.linear_rhs.spin_gmres` and
:mod:`nematic_solids.model.compiled.finite_krylov`.

numpy twin: :mod:`nematic_solids.model.krylov` (the same algorithms on arrays with a caller-supplied
inner product); tested to agree in ``tests/model/test_krylov.py``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .arith import rmul


@njit(cache=True)
def givens_column(H, g, cs, sn, k):  # pragma: no cover - compiled
    """GMRES's least-squares update for Hessenberg column ``k``: apply the previous Givens
    rotations to it, make the k-th one that zeroes ``H[k + 1, k]``, and rotate the residual
    vector ``g`` (|g[k + 1]| is then the residual norm of the current iterate)."""
    for i in range(k):
        t = cs[i] * H[i, k] + sn[i] * H[i + 1, k]
        H[i + 1, k] = -sn[i] * H[i, k] + cs[i] * H[i + 1, k]
        H[i, k] = t
    denom = np.hypot(H[k, k], H[k + 1, k])
    if denom == 0.0:
        denom = 1e-300
    cs[k] = H[k, k] / denom
    sn[k] = H[k + 1, k] / denom
    H[k, k] = denom
    H[k + 1, k] = 0.0
    g[k + 1] = -sn[k] * g[k]
    g[k] = cs[k] * g[k]


@njit(cache=True)
def solve_upper(H, g, m):  # pragma: no cover - compiled
    """``y`` with ``triu(H[:m, :m]) y = g[:m]`` by back substitution."""
    y = np.zeros(m)
    for i in range(m - 1, -1, -1):
        acc = g[i]
        for j in range(i + 1, m):
            acc -= H[i, j] * y[j]
        y[i] = acc / H[i, i]
    return y


@njit(cache=True, fastmath={"reassoc"})
def _wdot(wf, af, bf):  # pragma: no cover - compiled
    """The weighted real inner product of the flat complex arrays ``af``, ``bf`` (one
    block, of the length of ``wf``). Compiled with reassociation allowed (and nothing
    else: no contraction into FMAs), so that LLVM vectorises the sum: its order is then
    that of the compiled loop (SIMD lanes, then a fixed tree), fixed for a given machine and
    independent of the arrays' alignment (tested), not the order of ``numpy.sum``; 3x faster
    than the scalar sum at 128^2 (measured)."""
    s = 0.0
    for i in range(wf.size):
        s += wf[i] * (af[i].real * bf[i].real + af[i].imag * bf[i].imag)
    return s


@njit(cache=True)
def weighted_inner(a, b, w):  # pragma: no cover - compiled
    r""":math:`\sum w\, \mathrm{Re}(\bar a b)` for C-contiguous complex arrays ``a``, ``b``
    whose trailing axes have the shape of ``w`` (``w`` repeats over leading axes): the
    real-space inner product of half spectra when ``w`` holds the Parseval weights / N^2.
    Summed block by block (a block per leading index) in :func:`_wdot`'s order."""
    af = a.reshape(-1)
    bf = b.reshape(-1)
    wf = w.reshape(-1)
    nw = wf.size
    s = 0.0
    for block in range(af.size // nw):
        lo, hi = block * nw, (block + 1) * nw
        s += _wdot(wf, af[lo:hi], bf[lo:hi])
    return s


@njit(cache=True, fastmath={"reassoc"})
def _axpy_wdot(wf, yf, alpha, xf, af):  # pragma: no cover - compiled
    """``y += alpha x`` for one block of the flat arrays (of the length of ``wf``), fused
    with :func:`_wdot` of ``a`` and the updated ``y``. The update is exact as written (no FMA
    contraction); only the sum is reassociated. ``a`` must not overlap ``y`` (LLVM's run-time
    overlap check would take a scalar loop); :func:`_axpy_norm2` is the case ``a = y``."""
    s = 0.0
    for i in range(wf.size):
        yf[i] += rmul(alpha, xf[i])
        s += wf[i] * (af[i].real * yf[i].real + af[i].imag * yf[i].imag)
    return s


@njit(cache=True, fastmath={"reassoc"})
def _axpy_norm2(wf, yf, alpha, xf):  # pragma: no cover - compiled
    """``y += alpha x`` for one block, fused with the weighted squared norm of the updated
    ``y`` (:func:`_axpy_wdot` with ``a = y``, without the overlap that keeps it scalar)."""
    s = 0.0
    for i in range(wf.size):
        v = yf[i] + rmul(alpha, xf[i])
        yf[i] = v
        s += wf[i] * (v.real * v.real + v.imag * v.imag)
    return s


@njit(cache=True)
def axpy_inner(y, alpha, x, a, w):  # pragma: no cover - compiled
    """``y += alpha * x``, then return :func:`weighted_inner` ``(a, y, w)``, in one pass over
    memory (the same as the two calls to roundoff: the vectorised sums may group
    differently). ``a`` is either ``y`` itself (then it is the squared norm of the updated
    ``y``, by :func:`_axpy_norm2`) or does not overlap it."""
    yf = y.reshape(-1)
    xf = x.reshape(-1)
    af = a.reshape(-1)
    wf = w.reshape(-1)
    nw = wf.size
    norm = a.ctypes.data == y.ctypes.data  # a is y (else a must not overlap y)
    s = 0.0
    for block in range(yf.size // nw):
        lo, hi = block * nw, (block + 1) * nw
        if norm:
            s += _axpy_norm2(wf, yf[lo:hi], alpha, xf[lo:hi])
        else:
            s += _axpy_wdot(wf, yf[lo:hi], alpha, xf[lo:hi], af[lo:hi])
    return s


@njit(cache=True)
def mgs_column(V, wv, H, k, w):  # pragma: no cover - compiled
    """Modified Gram-Schmidt of ``wv`` against the basis ``V[0..k]`` (GMRES's Arnoldi
    step): ``H[i, k]`` = <V_i, wv>, ``wv -= H[i, k] V_i`` in turn; returns ``|wv|`` after.
    Each subtraction is fused with the next inner product (:func:`axpy_inner`): the same
    arithmetic as the plain loop, with half the passes over memory."""
    H[0, k] = weighted_inner(V[0], wv, w)
    for i in range(1, k + 1):
        H[i, k] = axpy_inner(wv, -H[i - 1, k], V[i - 1], V[i], w)
    return np.sqrt(max(axpy_inner(wv, -H[k, k], V[k], wv, w), 0.0))


@njit(cache=True)
def arnoldi_column(V, wv, H, g, cs, sn, k, w):  # pragma: no cover - compiled
    """One Arnoldi step of the compiled GMRESes for the new vector ``wv``: Gram-Schmidt
    against ``V[0..k]`` (:func:`mgs_column`), ``H[k + 1, k]`` = its norm, and the Givens
    update of the least-squares problem (:func:`givens_column`); returns the norm."""
    h_next = mgs_column(V, wv, H, k, w)
    H[k + 1, k] = h_next
    givens_column(H, g, cs, sn, k)
    return h_next


@njit(cache=True)
def any_nonzero(x):  # pragma: no cover - compiled
    """Whether any component of the C-contiguous array ``x`` (real or complex) is nonzero
    (``np.any(x)``, for which numba tests complex elements one at a time: 7x slower at
    128^2, measured); one branch-free pass over its real components, which LLVM vectorises."""
    xf = x.reshape(-1)
    acc = False
    for i in range(xf.size):
        v = xf[i]
        acc |= (v.real != 0.0) | (v.imag != 0.0)
    return acc


@njit(cache=True)
def axpy(y, alpha, x):  # pragma: no cover - compiled
    """``y += alpha * x`` in place (C-contiguous arrays of one shape; no temporary)."""
    yf = y.reshape(-1)
    xf = x.reshape(-1)
    for i in range(yf.size):
        yf[i] += rmul(alpha, xf[i])


@njit(cache=True)
def axpy_sum(x, y, B, m):  # pragma: no cover - compiled
    """``x += y[0] B[0] + ... + y[m-1] B[m-1]`` in one pass over ``x`` (the GMRES solution
    update from a basis ``B``); the terms are added to each element in that order, so it is
    bitwise the same as m calls of :func:`axpy`, with one read and write of ``x`` from memory
    (block by block: each block of x stays in cache while the m terms are added)."""
    xf = x.reshape(-1)
    size = xf.size
    Bf = B.reshape((B.shape[0], size))
    block = 512  # x's block stays in L1 while the m terms are added to it
    for lo in range(0, size, block):
        hi = min(lo + block, size)
        xb = xf[lo:hi]
        for i in range(m):
            c = y[i]
            bb = Bf[i, lo:hi]  # 1-D views: the loop below vectorises (3x faster, measured)
            for p in range(hi - lo):  # complex: componentwise, the same values as c * b
                xb[p] = xb[p] + rmul(c, bb[p])


@njit(cache=True)
def scaled(dst, x, alpha):  # pragma: no cover - compiled
    """``dst[...] = x / alpha`` in place (C-contiguous arrays of one shape)."""
    df = dst.reshape(-1)
    xf = x.reshape(-1)
    for i in range(df.size):  # component by component (numba would divide as complex)
        df[i] = complex(xf[i].real / alpha, xf[i].imag / alpha)


# --- the one compiled GMRES and PCG -------------------------------------------------------


def apply_operator(op, x, out, aux):  # pragma: no cover - compiled through its overloads
    """``out = A x`` (and ``aux = L x``, the operator's auxiliary linear output, where it has
    one) for the operator ``op``, a named tuple of its data: implemented for each operator
    type by an ``@overload`` in the module that defines it (resolved at compile time, so the
    GMRES below stays cacheable: no function is passed at run time)."""
    raise NotImplementedError("apply_operator runs compiled, through its overloads")


def apply_operator_given_aux(op, x, aux, out):  # pragma: no cover - compiled overloads
    """``out = A x`` for an ``x`` whose auxiliary output ``aux = L x`` is known (the rest of
    :func:`apply_operator` after L x: for the finite-strain rate operator, whose L is the
    real-space gradient, the stress and its divergence without the four inverse transforms)."""
    raise NotImplementedError("apply_operator_given_aux runs compiled, through its overloads")


def precondition(op, v, out):  # pragma: no cover - compiled through its overloads
    """``out = M v``, the right preconditioner of ``op`` (a no-op where ``out`` is ``v``: the
    unpreconditioned operators pass the Krylov basis as its own preconditioned basis)."""
    raise NotImplementedError("precondition runs compiled, through its overloads")


@njit(cache=True)
def gmres(op, b, x0, Lx0, w, rtol, maxiter, V, Z, LZ):  # pragma: no cover - compiled
    """Right-preconditioned restarted GMRES (Saad Alg. 9.5) for the operator ``op`` from
    ``x0``, with the Parseval-weighted inner product ``w``: the same algorithm, step for step,
    as :func:`nematic_solids.model.krylov._gmres` (its numpy twin). Returns ``(x, L x, iterations,
    converged, operator applications, applications given L x)``.

    A zero ``x0`` costs no operator application (its residual is ``b``, its ``L x`` zero).
    A non-empty ``Lx0`` is the known auxiliary output ``L x0`` of the start: its residual
    is then :func:`apply_operator_given_aux` (counted apart: it costs the operator's
    application less L).
    The auxiliary output ``L x`` is accumulated from the ``L z`` of the basis, so a converged
    cycle needs no extra application. Work arrays, caller-owned (megabytes are not allocated
    on every call): ``V`` the Krylov basis (restart + 1 spectra), ``Z`` its preconditioned
    basis (restart spectra; ``V`` itself for an unpreconditioned operator), ``LZ`` the
    auxiliary outputs of ``Z`` (restart entries of the auxiliary output's shape and dtype;
    zero-sized where the operator has none)."""
    restart = V.shape[0] - 1
    shape = b.shape
    Ax = np.empty(shape, dtype=np.complex128)
    Lx = np.empty(LZ.shape[1:], LZ.dtype)
    wv = np.empty(shape, dtype=np.complex128)
    H = np.zeros((restart + 1, restart))
    g = np.zeros(restart + 1)
    cs = np.zeros(restart)
    sn = np.zeros(restart)
    x = x0.copy()
    bnorm = np.sqrt(weighted_inner(b, b, w))
    if bnorm == 0.0:
        bnorm = 1.0
    total = 0
    nop = 0
    naux = 0
    zero_start = not any_nonzero(x)  # then r = b and L x = 0: no operator application
    known_aux = Lx0.size > 0 and not zero_start
    while True:
        if zero_start:  # r = b - 0 is b, bitwise (-0.0 - 0.0 is -0.0): no pass over it
            Lx[...] = 0.0
            r = b
            zero_start = False
        elif known_aux:  # L x0 given: A x0 from it (the first residual only)
            Lx[...] = Lx0
            apply_operator_given_aux(op, x, Lx, Ax)
            naux += 1
            known_aux = False
            r = b - Ax
        else:
            apply_operator(op, x, Ax, Lx)
            nop += 1
            r = b - Ax
        beta = np.sqrt(weighted_inner(r, r, w))
        if beta <= rtol * bnorm:
            return x, Lx, total, True, nop, naux
        if total >= maxiter:
            return x, Lx, total, False, nop, naux
        scaled(V[0], r, beta)
        H[:, :] = 0.0
        g[:] = 0.0
        g[0] = beta
        k = 0
        h_next = 0.0
        for k in range(restart):
            precondition(op, V[k], Z[k])
            apply_operator(op, Z[k], wv, LZ[k])
            nop += 1
            h_next = arnoldi_column(V, wv, H, g, cs, sn, k, w)
            total += 1
            if abs(g[k + 1]) <= rtol * bnorm or total >= maxiter or h_next <= 1e-14 * beta:
                break
            scaled(V[k + 1], wv, h_next)
        m = k + 1
        y = solve_upper(H, g, m)
        axpy_sum(x, y, Z, m)  # one pass each, bitwise m axpys
        axpy_sum(Lx, y, LZ, m)
        if abs(g[m]) <= rtol * bnorm or h_next <= 1e-14 * beta:
            return x, Lx, total, True, nop, naux


@njit(cache=True)
def pcg(op, b, x0, w, rtol, maxiter):  # pragma: no cover - compiled
    """Preconditioned conjugate gradients (Saad Alg. 9.1) for the symmetric positive definite
    operator ``op`` from ``x0``: the same algorithm, step for step, as
    :func:`nematic_solids.model.krylov.pcg` (its numpy twin). Stops when the preconditioned residual
    norm :math:`\\sqrt{r \\cdot M r}` falls below ``rtol`` times that of ``b``. Returns ``(x,
    iterations, status, operator applications)``, status 0 ok, 1 maxiter, 2 indefinite (a direction
    of non-positive curvature)."""
    x = x0.copy()
    nop = 0
    no_aux = np.empty(0, dtype=np.complex128)
    if any_nonzero(x):
        Ax = np.empty_like(b)
        apply_operator(op, x, Ax, no_aux)
        nop += 1
        r = b - Ax
    else:
        r = b.copy()
    z = np.empty_like(b)
    precondition(op, r, z)
    p = z.copy()
    rz = weighted_inner(r, z, w)
    Mb = np.empty_like(b)
    precondition(op, b, Mb)
    ref = np.sqrt(abs(weighted_inner(b, Mb, w)))
    if ref == 0.0:
        ref = 1.0
    Ap = np.empty_like(b)
    for it in range(maxiter + 1):
        if np.sqrt(abs(rz)) <= rtol * ref:
            return x, it, 0, nop
        if it == maxiter:
            break
        apply_operator(op, p, Ap, no_aux)
        nop += 1
        pAp = weighted_inner(p, Ap, w)
        if pAp <= 0:
            return x, it, 2, nop
        step = rz / pAp
        axpy(x, step, p)
        axpy(r, -step, Ap)
        precondition(op, r, z)
        rz_new = weighted_inner(r, z, w)
        p = z + (rz_new / rz) * p
        rz = rz_new
    return x, maxiter, 1, nop
