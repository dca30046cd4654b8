"""Stage: one wrench per body from the pair forces (paper Eq. 18-21), and what a step watches.

Each pair's force f_i acts on the master sphere's body (+f_i, a finger) and on the slave's
(-f_i, a module) at one common contact point; the sum is one wrench per body, expressed for the
dynamics in each joint's frame. `contact_summary` reduces the wrench on the active grasp's module to what the run
watches and records.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..jit import njit, njit_inline
from ..linalg import add3, dot3, mv3


class Loads(NamedTuple):
    """The contact wrenches of one force evaluation."""

    f_local: np.ndarray  # (njoints, 6) each joint's wrench (force, moment about its origin), its own frame
    force_W: np.ndarray  # (njoints, 3) each body's contact force, world, N
    torque_O_W: np.ndarray  # (njoints, 3) its moment about the world origin, N m
    external_force_W: np.ndarray  # (3,) what bodies outside the floating branches exert on those inside, N
    external_torque_O_W: np.ndarray  # (3,) its moment about the world origin, N m


class Summary(NamedTuple):
    """What a step watches of the active grasp: the combined contact force on its module and
    its moment about the module's centroid, both in the grasp frame O_a, and the extremes over
    the pairs in contact (zero without contact)."""

    force_A: tuple  # (3,) N
    torque_A: tuple  # (3,) N m
    max_speed: float  # fastest relative speed at a contact, m/s
    max_penetration: float  # deepest penetration, m


def no_loads(njoints: int) -> Loads:
    return Loads(f_local=np.zeros((njoints, 6)), force_W=np.zeros((njoints, 3)), torque_O_W=np.zeros((njoints, 3)),
                 external_force_W=np.zeros(3), external_torque_O_W=np.zeros(3))


def no_summary() -> Summary:
    return Summary(force_A=(0.0, 0.0, 0.0), torque_A=(0.0, 0.0, 0.0), max_speed=0.0, max_penetration=0.0)


@njit_inline
def _add_wrench(F, T, ext_f, ext_t, j, external, p, o, sign, f):
    """Add sign f (3-tuple), acting at p (3-tuple, world), to body j's force F[j] and moment
    T[j] about its origin o (3-tuple), and to the external wrench when `external` (the partner
    body does not float, and j does)."""
    r0, r1, r2 = p[0] - o[0], p[1] - o[1], p[2] - o[2]
    F[j, 0] += sign * f[0]
    F[j, 1] += sign * f[1]
    F[j, 2] += sign * f[2]
    T[j, 0] += sign * (r1 * f[2] - r2 * f[1])
    T[j, 1] += sign * (r2 * f[0] - r0 * f[2])
    T[j, 2] += sign * (r0 * f[1] - r1 * f[0])
    if external:
        ext_f[0] += sign * f[0]
        ext_f[1] += sign * f[1]
        ext_f[2] += sign * f[2]
        ext_t[0] += sign * (p[1] * f[2] - p[2] * f[1])
        ext_t[1] += sign * (p[2] * f[0] - p[0] * f[2])
        ext_t[2] += sign * (p[0] * f[1] - p[1] * f[0])


@njit
def body_wrenches(m, d):
    """Stage: d.loads, one wrench per body from d.contacts (Eq. 18-21), +f_i on the master
    sphere's body, -f_i on the slave's, at the common contact point (or, with m.law.common_point
    False, each at its own sphere's centre: the negative control). What a body outside the
    floating branches exerts on one inside is the external wrench (`tree.Tree.free`)."""
    njoints = d.R_W.shape[0]
    # F, T (moment about each joint's origin, world axes), T_O and the external wrench as
    # blocks of one array (njoints + 1 rows: at least the external wrench's two): an
    # allocation costs ~25 ns, a step makes dozens
    block = np.zeros((4, njoints + 1, 3))
    F, T, T_O, ext_f, ext_t = block[0][:njoints], block[1][:njoints], block[2][:njoints], block[3][0], block[3][1]
    common_point = m.law.common_point
    # the pair loop reads its arrays through locals: read through the structures inside it,
    # it takes twice as long (measured with 37 pairs: 1.69 us against 0.75 us a call)
    R_W, p_W = d.R_W, d.p_W
    c = d.contacts
    master, slave, force_W, point_W, c1_W, c2_W = c.master, c.slave, c.force_W, c.point_W, c.c1_W, c.c2_W
    master_joint, slave_joint, free = m.master.joint, m.slave.joint, m.tree.free
    for i in range(master.shape[0]):
        j1, j2 = master_joint[master[i]], slave_joint[slave[i]]
        f = (force_W[i, 0], force_W[i, 1], force_W[i, 2])
        if common_point:
            p1 = p2 = (point_W[i, 0], point_W[i, 1], point_W[i, 2])
        else:
            p1 = (c1_W[i, 0], c1_W[i, 1], c1_W[i, 2])
            p2 = (c2_W[i, 0], c2_W[i, 1], c2_W[i, 2])
        _add_wrench(F, T, ext_f, ext_t, j1, free[j1] and not free[j2], p1, (p_W[j1, 0], p_W[j1, 1], p_W[j1, 2]),
                    1.0, f)
        _add_wrench(F, T, ext_f, ext_t, j2, free[j2] and not free[j1], p2, (p_W[j2, 0], p_W[j2, 1], p_W[j2, 2]),
                    -1.0, f)
    local = np.empty((njoints, 6))
    for j in range(njoints):
        for a in range(3):
            local[j, a] = R_W[j, 0, a] * F[j, 0] + R_W[j, 1, a] * F[j, 1] + R_W[j, 2, a] * F[j, 2]
            local[j, 3 + a] = R_W[j, 0, a] * T[j, 0] + R_W[j, 1, a] * T[j, 1] + R_W[j, 2, a] * T[j, 2]
        T_O[j, 0] = T[j, 0] + p_W[j, 1] * F[j, 2] - p_W[j, 2] * F[j, 1]
        T_O[j, 1] = T[j, 1] + p_W[j, 2] * F[j, 0] - p_W[j, 0] * F[j, 2]
        T_O[j, 2] = T[j, 2] + p_W[j, 0] * F[j, 1] - p_W[j, 1] * F[j, 0]
    d.loads = Loads(f_local=local, force_W=F, torque_O_W=T_O, external_force_W=ext_f, external_torque_O_W=ext_t)


@njit_inline
def _grasp_axis(m, d, g, a):
    """Axis a of grasp g's frame O_a in world: column a of R_W[ee joint] R_ee, a 3-tuple."""
    j = m.grasps.ee_joint[g]
    return (d.R_W[j, 0, 0] * m.grasps.R_ee[g, 0, a] + d.R_W[j, 0, 1] * m.grasps.R_ee[g, 1, a] +
            d.R_W[j, 0, 2] * m.grasps.R_ee[g, 2, a],
            d.R_W[j, 1, 0] * m.grasps.R_ee[g, 0, a] + d.R_W[j, 1, 1] * m.grasps.R_ee[g, 1, a] +
            d.R_W[j, 1, 2] * m.grasps.R_ee[g, 2, a],
            d.R_W[j, 2, 0] * m.grasps.R_ee[g, 0, a] + d.R_W[j, 2, 1] * m.grasps.R_ee[g, 1, a] +
            d.R_W[j, 2, 2] * m.grasps.R_ee[g, 2, a])


@njit
def contact_summary(m, d):
    """Stage: d.summary, the wrench on the active grasp's module from d.loads in its grasp
    frame O_a (its moment about the module's centroid), and the extremes over d.contacts."""
    g = d.active
    j = m.grasps.module_joint[g]
    r_G = add3(mv3(d.R_W[j], m.grasps.module_lever[g]), d.p_W[j])
    f = (d.loads.force_W[j, 0], d.loads.force_W[j, 1], d.loads.force_W[j, 2])
    T = (d.loads.torque_O_W[j, 0], d.loads.torque_O_W[j, 1], d.loads.torque_O_W[j, 2])
    tau = (T[0] - (r_G[1] * f[2] - r_G[2] * f[1]), T[1] - (r_G[2] * f[0] - r_G[0] * f[2]),
           T[2] - (r_G[0] * f[1] - r_G[1] * f[0]))
    x, y, z = _grasp_axis(m, d, g, 0), _grasp_axis(m, d, g, 1), _grasp_axis(m, d, g, 2)
    fastest = deepest = 0.0
    if d.contacts.speed.shape[0]:
        fastest, deepest = d.contacts.speed.max(), d.contacts.phi.max()
    d.summary = Summary(force_A=(dot3(x, f), dot3(y, f), dot3(z, f)),
                        torque_A=(dot3(x, tau), dot3(y, tau), dot3(z, tau)),
                        max_speed=fastest, max_penetration=deepest)


@njit_inline
def net_force(m, d):
    """|the combined contact force on the active grasp's module| that can move it, N: all of
    it in space; on the air-bearing table its part in the table's plane (the table reacts the
    rest)."""
    f = d.summary.force_A
    total = f[0] * f[0] + f[1] * f[1] + f[2] * f[2]
    n_W = m.table_normal
    if n_W[0] == 0.0 and n_W[1] == 0.0 and n_W[2] == 0.0:
        return math.sqrt(total)
    g = d.active
    along = (dot3(_grasp_axis(m, d, g, 0), n_W) * f[0] + dot3(_grasp_axis(m, d, g, 1), n_W) * f[1]
             + dot3(_grasp_axis(m, d, g, 2), n_W) * f[2])
    return math.sqrt(max(0.0, total - along * along))
