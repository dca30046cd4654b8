"""Small 3-D products written out, compiled.

numba sends `@` on 3x3 arrays to BLAS, whose call costs more than the product. The tuple forms
(`mv3` ...) allocate nothing (a small array costs ~25 ns to allocate, several times the
arithmetic); rotations held as 9-tuples are row by row. Quaternions are (x, y, z, w).
"""

from __future__ import annotations

import math

import numpy as np

from .jit import njit, njit_inline


@njit
def dot3(a, b):
    """a . b for two 3-vectors."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit
def mv3(R, x):
    """R x for a 3x3 R and a 3-vector x, as a 3-tuple."""
    return (R[0, 0] * x[0] + R[0, 1] * x[1] + R[0, 2] * x[2],
            R[1, 0] * x[0] + R[1, 1] * x[1] + R[1, 2] * x[2],
            R[2, 0] * x[0] + R[2, 1] * x[1] + R[2, 2] * x[2])


@njit
def mtv3(R, x):
    """R^T x for a 3x3 R and a 3-vector x, as a 3-tuple."""
    return (R[0, 0] * x[0] + R[1, 0] * x[1] + R[2, 0] * x[2],
            R[0, 1] * x[0] + R[1, 1] * x[1] + R[2, 1] * x[2],
            R[0, 2] * x[0] + R[1, 2] * x[1] + R[2, 2] * x[2])


@njit
def mv9(R, x):
    """`mv3` for R a 9-tuple, row by row."""
    return (R[0] * x[0] + R[1] * x[1] + R[2] * x[2],
            R[3] * x[0] + R[4] * x[1] + R[5] * x[2],
            R[6] * x[0] + R[7] * x[1] + R[8] * x[2])


@njit
def mm9(A, B):
    """A B for A (3, 3) and B a 9-tuple, as a 9-tuple (row by row)."""
    return (A[0, 0] * B[0] + A[0, 1] * B[3] + A[0, 2] * B[6],
            A[0, 0] * B[1] + A[0, 1] * B[4] + A[0, 2] * B[7],
            A[0, 0] * B[2] + A[0, 1] * B[5] + A[0, 2] * B[8],
            A[1, 0] * B[0] + A[1, 1] * B[3] + A[1, 2] * B[6],
            A[1, 0] * B[1] + A[1, 1] * B[4] + A[1, 2] * B[7],
            A[1, 0] * B[2] + A[1, 1] * B[5] + A[1, 2] * B[8],
            A[2, 0] * B[0] + A[2, 1] * B[3] + A[2, 2] * B[6],
            A[2, 0] * B[1] + A[2, 1] * B[4] + A[2, 2] * B[7],
            A[2, 0] * B[2] + A[2, 1] * B[5] + A[2, 2] * B[8])


@njit
def mm33(A, B):
    """A B for two 3x3 matrices, as a 9-tuple (row by row)."""
    return (A[0, 0] * B[0, 0] + A[0, 1] * B[1, 0] + A[0, 2] * B[2, 0],
            A[0, 0] * B[0, 1] + A[0, 1] * B[1, 1] + A[0, 2] * B[2, 1],
            A[0, 0] * B[0, 2] + A[0, 1] * B[1, 2] + A[0, 2] * B[2, 2],
            A[1, 0] * B[0, 0] + A[1, 1] * B[1, 0] + A[1, 2] * B[2, 0],
            A[1, 0] * B[0, 1] + A[1, 1] * B[1, 1] + A[1, 2] * B[2, 1],
            A[1, 0] * B[0, 2] + A[1, 1] * B[1, 2] + A[1, 2] * B[2, 2],
            A[2, 0] * B[0, 0] + A[2, 1] * B[1, 0] + A[2, 2] * B[2, 0],
            A[2, 0] * B[0, 1] + A[2, 1] * B[1, 1] + A[2, 2] * B[2, 1],
            A[2, 0] * B[0, 2] + A[2, 1] * B[1, 2] + A[2, 2] * B[2, 2])


@njit_inline
def mm_into(A, B, out):
    """A B for two 3x3 matrices, written into out (3, 3)."""
    for a in range(3):
        for b in range(3):
            out[a, b] = A[a, 0] * B[0, b] + A[a, 1] * B[1, b] + A[a, 2] * B[2, b]


@njit
def cross3(a, b):
    """a x b for two 3-vectors, as a 3-tuple."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit
def add3(a, b):
    """a + b for two 3-vectors, as a 3-tuple."""
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@njit
def sub3(a, b):
    """a - b for two 3-vectors, as a 3-tuple."""
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@njit
def axpy3(k, x, y):
    """y + k x for a scalar k and two 3-vectors, as a 3-tuple."""
    return (y[0] + k * x[0], y[1] + k * x[1], y[2] + k * x[2])


@njit
def norm3(x):
    """|x| for a 3-vector."""
    return math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])


@njit
def put3(out, i, x):
    """out[i:i + 3] = x for a 3-vector x, in place."""
    out[i], out[i + 1], out[i + 2] = x[0], x[1], x[2]


@njit
def mv(R, x):
    """R x for a 3x3 R and a 3-vector x, as an array."""
    out = np.empty(3)
    put3(out, 0, mv3(R, x))
    return out


@njit
def cross(a, b):
    """a x b for two 3-vectors, as an array."""
    out = np.empty(3)
    put3(out, 0, cross3(a, b))
    return out


@njit
def quat_rotation9(x, y, z, w):
    """The rotation matrix of the unit quaternion (x, y, z, w) as a 9-tuple, row by row."""
    return (1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w),
            2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w),
            2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y))


@njit
def put9(out, R):
    """Write the 9-tuple R (row by row) into out (3, 3)."""
    out[0, 0], out[0, 1], out[0, 2] = R[0], R[1], R[2]
    out[1, 0], out[1, 1], out[1, 2] = R[3], R[4], R[5]
    out[2, 0], out[2, 1], out[2, 2] = R[6], R[7], R[8]


@njit
def quat_times_exp4(q, t0, t1, t2):
    """q exp(t) for the quaternion q (x, y, z, w) and a rotation vector t in q's own frame
    (R <- R exp(t)), normalised, as a 4-tuple."""
    angle = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    half = 0.5 * angle
    # sin(half) / angle, with its series where the division loses digits
    k = 0.5 - angle * angle / 48.0 if angle < 1e-4 else math.sin(half) / angle
    dx, dy, dz, dw = k * t0, k * t1, k * t2, math.cos(half)
    x, y, z, w = q[0], q[1], q[2], q[3]
    o0 = w * dx + x * dw + y * dz - z * dy
    o1 = w * dy - x * dz + y * dw + z * dx
    o2 = w * dz + x * dy - y * dx + z * dw
    o3 = w * dw - x * dx - y * dy - z * dz
    norm = math.sqrt(o0 ** 2 + o1 ** 2 + o2 ** 2 + o3 ** 2)
    return o0 / norm, o1 / norm, o2 / norm, o3 / norm


@njit
def solve_spd3(M, b):
    """M^-1 b for a symmetric positive-definite 3x3 M (a rotational inertia), by Cholesky, as a
    3-tuple."""
    l00 = math.sqrt(M[0, 0])
    l10 = M[1, 0] / l00
    l20 = M[2, 0] / l00
    l11 = math.sqrt(M[1, 1] - l10 * l10)
    l21 = (M[2, 1] - l20 * l10) / l11
    l22 = math.sqrt(M[2, 2] - l20 * l20 - l21 * l21)
    y0 = b[0] / l00
    y1 = (b[1] - l10 * y0) / l11
    y2 = (b[2] - l20 * y0 - l21 * y1) / l22
    x2 = y2 / l22
    x1 = (y1 - l21 * x2) / l11
    x0 = (y0 - l10 * x1 - l20 * x2) / l00
    return (x0, x1, x2)
