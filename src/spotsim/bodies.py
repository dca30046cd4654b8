"""Free bodies (free-flyer joints) as arrays, and their kinematics, compiled.

After the locked joints are reduced away every body that carries a contact face is either
fixed (joint 0) or free (a free-flyer child of the world), so the placements and velocities
the contact needs follow from q and v directly. Quaternions are Pinocchio's XYZQUAT order:
(x, y, z, qx, qy, qz, qw).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from .jit import njit, njit_inline


class FreeBodies(NamedTuple):
    """The free-flyer joints of a model (one row each)."""

    joint: np.ndarray  # (n,) joint index
    idx_q: np.ndarray  # (n,) first index of its configuration in q (xyz, then quaternion)
    idx_v: np.ndarray  # (n,) first index of its velocity in v (v_O, then omega; body frame)
    R_P: np.ndarray  # (n, 3, 3) the joint's placement in the world (its parent), rotation
    p_P: np.ndarray  # (n, 3) and translation, m
    lever: np.ndarray  # (n, 3) the body's centroid in its joint frame, m
    mass: np.ndarray  # (n,) kg
    inertia_G: np.ndarray  # (n, 3, 3) rotational inertia about the centroid, joint axes, kg m^2


def free_flyers(model: pin.Model) -> list[int]:
    """The joints of `model` that are free-flyers."""
    return [j for j in range(1, model.njoints) if model.joints[j].shortname() == "JointModelFreeFlyer"]


def free_bodies(model: pin.Model) -> FreeBodies:
    """The free-flyer joints of `model`, which must all be children of the world."""
    joints = free_flyers(model)
    if any(model.parents[j] != 0 for j in joints):
        raise ValueError("a free-flyer joint is not a child of the world")
    ints = lambda values: np.array(values, dtype=np.int64)
    return FreeBodies(ints(joints), ints([model.idx_qs[j] for j in joints]),
                      ints([model.idx_vs[j] for j in joints]),
                      np.array([model.jointPlacements[j].rotation for j in joints]).reshape(-1, 3, 3),
                      np.array([model.jointPlacements[j].translation for j in joints]).reshape(-1, 3),
                      np.array([model.inertias[j].lever for j in joints]).reshape(-1, 3),
                      np.array([model.inertias[j].mass for j in joints], dtype=float),
                      np.array([model.inertias[j].inertia for j in joints]).reshape(-1, 3, 3))


# 3x3 products written out: numba sends `@` to BLAS, whose call costs more than the product.
# The tuple forms (mv3 ...) allocate nothing (a small array costs ~25 ns to allocate); the
# array forms wrap them.

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
def mtv9(R, x):
    """`mtv3` for R a 9-tuple, row by row."""
    return (R[0] * x[0] + R[3] * x[1] + R[6] * x[2],
            R[1] * x[0] + R[4] * x[1] + R[7] * x[2],
            R[2] * x[0] + R[5] * x[1] + R[8] * x[2])


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
def put3(out, i, x):
    """out[i:i + 3] = x for a 3-vector x, in place."""
    out[i], out[i + 1], out[i + 2] = x[0], x[1], x[2]


@njit
def mv(R, x):
    """R x for a 3x3 R and a 3-vector x."""
    out = np.empty(3)
    put3(out, 0, mv3(R, x))
    return out


@njit_inline
def mm_into(A, B, out):
    """A B for two 3x3 matrices, written into out (3, 3)."""
    for a in range(3):
        for b in range(3):
            out[a, b] = A[a, 0] * B[0, b] + A[a, 1] * B[1, b] + A[a, 2] * B[2, b]


@njit
def cross(a, b):
    """a x b for two 3-vectors."""
    out = np.empty(3)
    put3(out, 0, cross3(a, b))
    return out


@njit
def quat_rotation9(x, y, z, w):
    """The rotation matrix of the unit quaternion (x, y, z, w) as a 9-tuple, row by row: an
    array costs ~60 ns to allocate, several times the arithmetic."""
    return (1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w),
            2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w),
            2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y))


@njit
def _put9(out, R):
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
def body_rotation(bodies, b, q):
    """Rotation (3, 3) of free body b in the world, from q."""
    R = np.empty((3, 3))
    body_rotation_into(bodies, b, q, R)
    return R


@njit
def body_rotation_into(bodies, b, q, out):
    """`body_rotation`, written into out (3, 3)."""
    _put9(out, body_rotation9(bodies, b, q))


@njit
def body_rotation9(bodies, b, q):
    """`body_rotation` as a 9-tuple, row by row: R_P times the rotation of the joint's
    quaternion (`mm9`, `quat_rotation9`)."""
    iq = bodies.idx_q[b]
    return mm9(bodies.R_P[b], quat_rotation9(q[iq + 3], q[iq + 4], q[iq + 5], q[iq + 6]))


@njit
def body_origin3(bodies, b, q):
    """Origin of free body b in the world, from q, as a 3-tuple."""
    iq = bodies.idx_q[b]
    return add3(mv3(bodies.R_P[b], q[iq:iq + 3]), bodies.p_P[b])


@njit_inline
def body_kinematics(bodies, q, v, R_W, p_W, w_W, vo_W):
    """Each free body's rotation, origin, angular velocity and origin velocity in the world,
    written into rows bodies.joint of R_W, p_W, w_W, vo_W (njoints, ...)."""
    for b in range(bodies.joint.shape[0]):
        j, iv = bodies.joint[b], bodies.idx_v[b]
        R = R_W[j]
        body_rotation_into(bodies, b, q, R)
        put3(p_W[j], 0, body_origin3(bodies, b, q))
        put3(vo_W[j], 0, mv3(R, v[iv:iv + 3]))
        put3(w_W[j], 0, mv3(R, v[iv + 3:iv + 6]))


@njit_inline
def body_momentum3(bodies, b, q, v):
    """Free body b's linear momentum, its angular momentum about the world origin and its
    centroid (world), as 3-tuples."""
    iv = bodies.idx_v[b]
    R = body_rotation9(bodies, b, q)
    m, lever = bodies.mass[b], bodies.lever[b]
    w = v[iv + 3:iv + 6]
    v_G = mv9(R, add3(v[iv:iv + 3], cross3(w, lever)))
    p_G = add3(body_origin3(bodies, b, q), mv9(R, lever))
    p_b = (m * v_G[0], m * v_G[1], m * v_G[2])
    l_b = add3(cross3(p_G, p_b), mv9(R, mv3(bodies.inertia_G[b], w)))
    return p_b, l_b, p_G


@njit_inline
def bodies_momentum(bodies, rows, q, v):
    """Linear and angular momentum (about the world origin) of the free bodies `rows`, summed,
    and the largest single body's linear and angular momentum magnitudes: (3,), (3,), float,
    float. Also their centroid (3,), m."""
    P, L, c = np.zeros(3), np.zeros(3), np.zeros(3)
    p_max = l_max = m_sum = 0.0
    for b in rows:
        p_b, l_b, p_G = body_momentum3(bodies, b, q, v)
        m = bodies.mass[b]
        for i in range(3):
            P[i] += p_b[i]
            L[i] += l_b[i]
            c[i] += m * p_G[i]
        m_sum += m
        p_max = max(p_max, math.sqrt(p_b[0] ** 2 + p_b[1] ** 2 + p_b[2] ** 2))
        l_max = max(l_max, math.sqrt(l_b[0] ** 2 + l_b[1] ** 2 + l_b[2] ** 2))
    return P, L, p_max, l_max, c / m_sum


@njit_inline
def bodies_centroid3(bodies, rows, q):
    """The centroid of the free bodies `rows` (world, m) as a 3-tuple: `bodies_momentum`'s,
    without the momenta."""
    c0 = c1 = c2 = m_sum = 0.0
    for b in rows:
        m = bodies.mass[b]
        p_G = add3(body_origin3(bodies, b, q), mv9(body_rotation9(bodies, b, q), bodies.lever[b]))
        c0 += m * p_G[0]
        c1 += m * p_G[1]
        c2 += m * p_G[2]
        m_sum += m
    return c0 / m_sum, c1 / m_sum, c2 / m_sum


@njit_inline
def kinetic_energy(bodies, q, v):
    """Kinetic energy of all free bodies, J: 1/2 m |v_G|^2 + 1/2 omega . I_G omega."""
    total = 0.0
    for b in range(bodies.joint.shape[0]):
        iv = bodies.idx_v[b]
        w = v[iv + 3:iv + 6]
        v_G = add3(v[iv:iv + 3], cross3(w, bodies.lever[b]))  # body axes; the norm is frame-free
        Iw = mv3(bodies.inertia_G[b], w)
        total += 0.5 * bodies.mass[b] * (v_G[0] * v_G[0] + v_G[1] * v_G[1] + v_G[2] * v_G[2]) + \
            0.5 * (w[0] * Iw[0] + w[1] * Iw[1] + w[2] * Iw[2])
    return total


@njit
def _solve3(M, b):
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


@njit
def free_body_accelerations(bodies, q, v, f_local, g_W):
    """ABA of a model made of free bodies only, each a free-flyer child of the world: with no
    joint between them, each body's articulated inertia is its own, and the algorithm reduces
    to the Newton-Euler equations of each body. Returns a (nv,) in Pinocchio's convention (the
    time derivative of each free-flyer's body-frame twist (v_O, omega)).

    f_local: (njoints, 6) external wrench on each joint's body, (force, moment about the joint
    origin) in the joint frame, N and N m. g_W: (3,) gravity, m/s^2.
    """
    a = np.zeros(v.shape[0])
    for b in range(bodies.joint.shape[0]):
        a_O, alpha = free_body_acceleration(bodies, b, body_rotation(bodies, b, q), v, f_local, g_W)
        put3(a, bodies.idx_v[b], a_O)
        put3(a, bodies.idx_v[b] + 3, alpha)
    return a


@njit_inline
def free_body_acceleration(bodies, b, R, v, f_local, g_W):
    """Free body b's part of `free_body_accelerations` given its rotation R (3, 3): the time
    derivative of its body-frame twist, (a_O, alpha) as two 3-tuples."""
    j, iv = bodies.joint[b], bodies.idx_v[b]
    m, c, I_G = bodies.mass[b], bodies.lever[b], bodies.inertia_G[b]
    v_O, w = v[iv:iv + 3], v[iv + 3:iv + 6]
    f, tau_O = f_local[j, :3], f_local[j, 3:]
    # Newton about the centroid (world) and Euler about it (body axes)
    g = mtv3(R, g_W)
    a_G = (f[0] / m + g[0], f[1] / m + g[1], f[2] / m + g[2])
    alpha = _solve3(I_G, sub3(sub3(tau_O, cross3(c, f)), cross3(w, mv3(I_G, w))))
    # the centroid's acceleration is that of the origin plus alpha x c + w x (w x c); the
    # twist's linear part is the origin's velocity in the turning body frame (- w x v_O)
    return sub3(sub3(sub3(a_G, cross3(alpha, c)), cross3(w, cross3(w, c))), cross3(w, v_O)), alpha
