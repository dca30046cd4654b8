"""Stage: the free bodies' accelerations under the contact wrenches and gravity (paper Eq. 22-23).

This is Pinocchio's ABA for a model of free bodies only, each a free-flyer child of the world:
with no joint between them, each body's articulated inertia is its own, and the algorithm
reduces to the Newton-Euler equations of each body. The tests hold it to `pin.aba` on the
scenes' own models. The result is in Pinocchio's convention: the time derivative of each
free-flyer's body-frame twist (v_O, omega).
"""

from __future__ import annotations

from ..jit import njit, njit_inline
from ..linalg import cross3, mtv3, mv3, put3, solve_spd3, sub3


@njit_inline
def free_body_acceleration(bodies, b, R, v, f_local, g_W):
    """Free body b's (a_O, alpha), two 3-tuples, given its rotation R (3, 3).

    v: (nv,) velocities. f_local: (njoints, 6) external wrench on each joint's body, (force,
    moment about the joint origin) in the joint frame, N and N m. g_W: (3,) gravity, m/s^2.
    """
    j, iv = bodies.joint[b], bodies.idx_v[b]
    m, c, I_G = bodies.mass[b], bodies.lever[b], bodies.inertia_G[b]
    v_O, w = v[iv:iv + 3], v[iv + 3:iv + 6]
    f, tau_O = f_local[j, :3], f_local[j, 3:]
    # Newton about the centroid (world) and Euler about it (body axes)
    g = mtv3(R, g_W)
    a_G = (f[0] / m + g[0], f[1] / m + g[1], f[2] / m + g[2])
    alpha = solve_spd3(I_G, sub3(sub3(tau_O, cross3(c, f)), cross3(w, mv3(I_G, w))))
    # the centroid's acceleration is that of the origin plus alpha x c + w x (w x c); the
    # twist's linear part is the origin's velocity in the turning body frame (- w x v_O)
    return sub3(sub3(sub3(a_G, cross3(alpha, c)), cross3(w, cross3(w, c))), cross3(w, v_O)), alpha


@njit
def accelerations(m, d):
    """Stage: d.a (nv,), the free bodies' accelerations at (d.q, d.v) under d.loads.f_local and
    gravity, with the rotations of the last `kinematics`."""
    for b in range(m.bodies.joint.shape[0]):
        a_O, alpha = free_body_acceleration(m.bodies, b, d.R_W[m.bodies.joint[b]], d.v, d.loads.f_local, m.gravity_W)
        put3(d.a, m.bodies.idx_v[b], a_O)
        put3(d.a, m.bodies.idx_v[b] + 3, alpha)
