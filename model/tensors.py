"""Grid tensor algebra for 2 x 2 tensors stored components first: ``T[i, j, x, y]``.

Explicit 2-D formulas (no ``np.linalg`` on tiny matrices): they are exact and vectorise. They
take numpy arrays or JAX arrays alike (:func:`namespace`), so that the accelerated backend
(:mod:`nematic_solids.model.accelerated`) evaluates the numpy reference's own formulas.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: a numpy array or a JAX array (the formulas take either: :func:`namespace`)
Array = Any


def namespace(*arrays: Any) -> Any:
    """The array library of ``arrays``: ``jax.numpy`` if one is a JAX array (or a tracer of
    one, under ``jax.jit``), else numpy (imported lazily: nothing here needs JAX)."""
    for a in arrays:
        if type(a).__module__.startswith(("jax", "jaxlib")):
            import jax.numpy as jnp

            return jnp
    return np


def det(T: Array) -> Array:
    return T[0, 0] * T[1, 1] - T[0, 1] * T[1, 0]


def inv(T: Array) -> Array:
    d = det(T)
    xp = namespace(T)
    return xp.stack([xp.stack([T[1, 1], -T[0, 1]]), xp.stack([-T[1, 0], T[0, 0]])]) / d


def transpose(T: Array) -> Array:
    return namespace(T).swapaxes(T, 0, 1)


def matmul(A: Array, B: Array) -> Array:
    """``(A B)_ij = A_ik B_kj`` (explicit 2 x 2 products: much faster than einsum here)."""
    xp = namespace(A, B)
    return xp.stack(
        [
            xp.stack(
                [A[0, 0] * B[0, 0] + A[0, 1] * B[1, 0], A[0, 0] * B[0, 1] + A[0, 1] * B[1, 1]]
            ),
            xp.stack(
                [A[1, 0] * B[0, 0] + A[1, 1] * B[1, 0], A[1, 0] * B[0, 1] + A[1, 1] * B[1, 1]]
            ),
        ]
    )


def ddot(A: Array, B: Array) -> Array:
    """Double contraction ``A : B = A_ij B_ij``."""
    return A[0, 0] * B[0, 0] + A[0, 1] * B[0, 1] + A[1, 0] * B[1, 0] + A[1, 1] * B[1, 1]


def trace(T: Array) -> Array:
    return T[0, 0] + T[1, 1]


def identity(shape: tuple[int, ...], like: Any = None) -> Array:
    """The identity tensor on a grid of ``shape`` (in the array library and, for JAX, the
    precision of ``like``)."""
    xp = namespace(like)
    if xp is np:
        eye = np.zeros((2, 2, *shape))
        eye[0, 0] = 1.0
        eye[1, 1] = 1.0
        return eye
    dtype = getattr(like, "dtype", None)
    one, zero = xp.ones(shape, dtype), xp.zeros(shape, dtype)
    return xp.stack([xp.stack([one, zero]), xp.stack([zero, one])])


#: the (a, b) entries, a <= b, of a symmetric 4 x 4 matrix in packed order (row by row)
PACKED_PAIRS = tuple((a, b) for a in range(4) for b in range(a, 4))


def pack_symmetric(K: Array) -> Array:
    """A major-symmetric fourth-order field ``K[i, J, k, L, ...]`` packed as the upper
    triangle of the 4 x 4 matrix ``K[2 i + J, 2 k + L]``: shape (10, ...), in
    :data:`PACKED_PAIRS` order (the layout of the backends' ``tangent_kernel``)."""
    M = K.reshape(4, 4, *K.shape[4:])
    return np.stack([M[a, b] for a, b in PACKED_PAIRS])


def unpack_symmetric(Kp: Array) -> Array:
    """The full ``K[i, J, k, L, ...]`` of a packed field (:func:`pack_symmetric`)."""
    M = np.empty((4, 4, *Kp.shape[1:]))
    for c, (a, b) in enumerate(PACKED_PAIRS):
        M[a, b] = M[b, a] = Kp[c]
    return M.reshape(2, 2, 2, 2, *Kp.shape[1:])


def nematic(q1: Array, q2: Array) -> Array:
    """The traceless symmetric tensor ``Q = [[q1, q2], [q2, -q1]]`` (q1 = S cos 2 theta,
    q2 = S sin 2 theta, so Q = S (2 n n - I) and Q : Q = 2 S^2)."""
    xp = namespace(q1, q2)
    return xp.stack([xp.stack([q1, q2]), xp.stack([q2, -q1])])
