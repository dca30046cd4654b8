"""Stage: the free bodies' accelerations under the contact wrenches and gravity (paper Eq. 22-23).

This is Pinocchio's ABA for a model of free bodies only, each a free-flyer or a planar joint,
child of the world: with no joint between them, each body's articulated inertia is its own, and
the algorithm reduces to the Newton-Euler equations of each body. The tests hold it to `pin.aba`
on the scenes' own models. The result is in Pinocchio's convention: the time derivative of each
joint's body-frame velocity, (v_O, omega) for a free-flyer, (v_O,x, v_O,y, omega_z) for a planar
joint.

A planar body's centroid moves in its plane and it turns about the plane's normal (its joint's
z) only: m a_G = the in-plane part of the force and gravity, and I_zz alpha_z = the moment about
the centroid along the normal (with omega along the normal, (omega x I omega) has no normal
component). The rest of the contact wrench, along the normal and about the in-plane axes, the table
reacts (`table_load`).
"""

from __future__ import annotations

import math

from ..jit import njit, njit_inline
from ..linalg import cross3, mtv3, mv3, solve_spd3, sub3
from .bodies import free_twist, planar_twist, set_free_rate, set_planar_rate


@njit_inline
def free_body_acceleration(bodies, b, R, v, f_local, g_W):
    """A free-flyer's (a_O, alpha), two 3-tuples, given its rotation R (3, 3).

    v: (nv,) velocities. f_local: (njoints, 6) external wrench on each joint's body, (force,
    moment about the joint origin) in the joint frame, N and N m. g_W: (3,) gravity, m/s^2.
    """
    j = bodies.joint[b]
    m, c, I_G = bodies.mass[b], bodies.lever[b], bodies.inertia_G[b]
    v_O, w = free_twist(bodies, b, v)
    f, tau_O = f_local[j, :3], f_local[j, 3:]
    # Newton about the centroid (world) and Euler about it (body axes)
    g = mtv3(R, g_W)
    a_G = (f[0] / m + g[0], f[1] / m + g[1], f[2] / m + g[2])
    alpha = solve_spd3(I_G, sub3(sub3(tau_O, cross3(c, f)), cross3(w, mv3(I_G, w))))
    return _origin_acceleration(a_G, alpha, c, v_O, w), alpha


@njit_inline
def planar_body_acceleration(bodies, b, R, v, f_local, g_W):
    """A planar body's (a_O, alpha), two 3-tuples, as `free_body_acceleration`: its centroid
    accelerates by the in-plane force and gravity, and it turns by the moment about its
    centroid along the normal over I_zz (with omega along the normal, omega x I omega has no
    normal component)."""
    j = bodies.joint[b]
    m, c, I_G = bodies.mass[b], bodies.lever[b], bodies.inertia_G[b]
    v_O, w = planar_twist(bodies, b, v)
    f, tau_O = f_local[j, :3], f_local[j, 3:]
    g = mtv3(R, g_W)
    tau_G = sub3(tau_O, cross3(c, f))
    a_G = (f[0] / m + g[0], f[1] / m + g[1], 0.0)
    alpha = (0.0, 0.0, tau_G[2] / I_G[2, 2])
    return _origin_acceleration(a_G, alpha, c, v_O, w), alpha


@njit_inline
def _origin_acceleration(a_G, alpha, c, v_O, w):
    """The twist's linear rate a_O (body frame) of a body whose centroid c accelerates by a_G
    (body axes): the centroid's acceleration is that of the origin plus alpha x c + w x (w x
    c), and the twist's linear part is the origin's velocity in the turning body frame."""
    return sub3(sub3(sub3(a_G, cross3(alpha, c)), cross3(w, cross3(w, c))), cross3(w, v_O))


@njit
def accelerations(m, d):
    """Stage: d.a (nv,), the free bodies' accelerations at (d.q, d.v) under d.loads.f_local and
    gravity, with the rotations of the last `kinematics`."""
    g, n = (m.gravity_W[0], m.gravity_W[1], m.gravity_W[2]), m.table_normal
    # on the table, gravity's part along its normal is the bearings' (taken off here, not left
    # to the joint frames, whose z is the normal only to round-off)
    along = g[0] * n[0] + g[1] * n[1] + g[2] * n[2]
    g_table = (g[0] - along * n[0], g[1] - along * n[1], g[2] - along * n[2])
    _accelerations_kind(m, d, m.bodies.free_rows, g, free_body_acceleration, set_free_rate)
    _accelerations_kind(m, d, m.bodies.planar_rows, g_table, planar_body_acceleration, set_planar_rate)


@njit_inline
def _accelerations_kind(m, d, rows, g, acceleration_of, set_rate):
    """`accelerations` for the bodies of one joint kind (rows), under gravity g (3-tuple)."""
    for b in rows:
        a_O, alpha = acceleration_of(m.bodies, b, d.R_W[m.bodies.joint[b]], d.v, d.loads.f_local, g)
        set_rate(m.bodies, b, d.a, a_O, alpha)


@njit_inline
def table_load(bodies, b, f_local):
    """What free body b's contact wrench presses into its table (a planar body): the force
    along the normal, N, and the moment about its centroid in the plane, N m, as magnitudes:
    the bearings and the table react them, and nothing moves by them."""
    j, c = bodies.joint[b], bodies.lever[b]
    f, tau_O = f_local[j, :3], f_local[j, 3:]
    tau_G = sub3(tau_O, cross3(c, f))
    return abs(f[2]), math.sqrt(tau_G[0] ** 2 + tau_G[1] ** 2)
