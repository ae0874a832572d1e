"""The well-posedness margins over the grid (numba): for finite strain the smallest determinant
of the rate problem's symbol over points and sampled directions, for small strain
:math:`1 - (\\alpha - B) \\max S`.

numpy twins: :func:`nematic_solids.model.reference_kernels.finite_margin_kernel` (every point
sampled, from :func:`nematic_solids.model.wellposedness.finite_symbol_det`) and
:func:`nematic_solids.model.wellposedness.linear_margin`; tested to agree in
``tests/model/test_wellposedness.py``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .constitutive import PACKED


@njit(cache=True)
def finite_margin_kernel(K, E, cos_t, sin_t, scale):  # pragma: no cover - compiled
    r"""(min over points and sampled directions of det M / scale, flat index, angle index),
    for the packed tangent ``K``
    (:func:`nematic_solids.model.compiled.constitutive.tangent_kernel`).

    A point is sampled only if it can beat the minimum so far: each entry of M is
    :math:`a + b \cos 2\phi + c \sin 2\phi`, so :math:`\det M = d_0 + d_2 \cdot
    (\cos 2\phi, \sin 2\phi) + d_4 \cdot (\cos 4\phi, \sin 4\phi)` is bounded below by
    :math:`d_0 - |d_2| - |d_4|`; a point whose bound is not below the minimum cannot lower it
    (the comparison is strict), so the result is that of sampling every point."""
    nx, ny = E.shape[2], E.shape[3]
    na = cos_t.shape[0]
    best = np.inf
    best_i = 0
    best_a = 0
    ent = np.empty((2, 2, 3))  # M_ik = ent[i, k, 0] c^2 + ent[i, k, 1] c s + ent[i, k, 2] s^2
    tri = np.empty((2, 2, 3))  # M_ik = tri[i, k, 0] + tri[i, k, 1] cos 2phi + tri[..., 2] sin
    for x in range(nx):
        for y in range(ny):
            for i in range(2):
                for k in range(2):
                    ent[i, k, 0] = K[PACKED[2 * i, 2 * k], x, y]
                    ent[i, k, 1] = (
                        K[PACKED[2 * i, 2 * k + 1], x, y] + K[PACKED[2 * i + 1, 2 * k], x, y]
                    )
                    ent[i, k, 2] = K[PACKED[2 * i + 1, 2 * k + 1], x, y]
                e0 = 0.5 * E[i, 0, x, y]
                e1 = 0.5 * E[i, 1, x, y]
                # (E k)_i t_k / 2 with t = (-s, c)
                ent[i, 0, 1] -= e0
                ent[i, 0, 2] -= e1
                ent[i, 1, 0] += e0
                ent[i, 1, 1] += e1
            for i in range(2):
                for k in range(2):
                    tri[i, k, 0] = 0.5 * (ent[i, k, 0] + ent[i, k, 2])
                    tri[i, k, 1] = 0.5 * (ent[i, k, 0] - ent[i, k, 2])
                    tri[i, k, 2] = 0.5 * ent[i, k, 1]
            d0 = 0.0
            d2c = 0.0
            d2s = 0.0
            d4c = 0.0
            d4s = 0.0
            size = 0.0
            for sign, (i1, k1, i2, k2) in ((1.0, (0, 0, 1, 1)), (-1.0, (0, 1, 1, 0))):
                a1, b1, c1 = tri[i1, k1, 0], tri[i1, k1, 1], tri[i1, k1, 2]
                a2, b2, c2 = tri[i2, k2, 0], tri[i2, k2, 1], tri[i2, k2, 2]
                d0 += sign * (a1 * a2 + 0.5 * (b1 * b2 + c1 * c2))
                d2c += sign * (a1 * b2 + b1 * a2)
                d2s += sign * (a1 * c2 + c1 * a2)
                d4c += sign * 0.5 * (b1 * b2 - c1 * c2)
                d4s += sign * 0.5 * (b1 * c2 + c1 * b2)
                size += (abs(a1) + abs(b1) + abs(c1)) * (abs(a2) + abs(b2) + abs(c2))
            # sqrt, not hypot (3x slower): the values are O(1), and the 1e-12 size margin covers
            # the ulp it may be off
            bound = (
                d0 - np.sqrt(d2c * d2c + d2s * d2s) - np.sqrt(d4c * d4c + d4s * d4s) - 1e-12 * size
            )
            if bound / scale >= best:
                continue
            for a in range(na):
                c = cos_t[a]
                s = sin_t[a]
                cc = c * c
                cs = c * s
                ss = s * s
                m00 = ent[0, 0, 0] * cc + ent[0, 0, 1] * cs + ent[0, 0, 2] * ss
                m01 = ent[0, 1, 0] * cc + ent[0, 1, 1] * cs + ent[0, 1, 2] * ss
                m10 = ent[1, 0, 0] * cc + ent[1, 0, 1] * cs + ent[1, 0, 2] * ss
                m11 = ent[1, 1, 0] * cc + ent[1, 1, 1] * cs + ent[1, 1, 2] * ss
                d = (m00 * m11 - m01 * m10) / scale
                if d < best:
                    best = d
                    best_i = x * ny + y
                    best_a = a
    return best, best_i, best_a


@njit(cache=True)
def linear_margin_kernel(q1, q2, alpha_minus_B):  # pragma: no cover - compiled
    """The small-strain margin :math:`1 - (\\alpha - B) \\max S` and the flat index of the
    maximum of :math:`(\\alpha - B) S`, :math:`S = \\sqrt{q_1^2 + q_2^2}`, in one pass: the
    values of :func:`nematic_solids.model.wellposedness.linear_margin` (the same products; the
    first index of the maximum, as ``numpy.argmax``; a NaN is the maximum, as there)."""
    nx, ny = q1.shape
    best = -np.inf
    best_i = 0
    row = np.empty(ny)
    for x in range(nx):
        for y in range(ny):  # a row of (alpha - B) S: vectorised (the square root too)
            row[y] = alpha_minus_B * np.sqrt(q1[x, y] ** 2 + q2[x, y] ** 2)
        for y in range(ny):  # its first maximum: compares only
            v = row[y]
            if v > best or (v != v and best == best):
                best = v
                best_i = x * ny + y  # the index in C order, as numpy's
    return 1.0 - best, best_i
