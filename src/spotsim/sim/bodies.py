"""Free bodies (free-flyer or planar joints) as arrays: their kinematics, centroid states and
momenta.

After the locked joints are reduced away every body of a scene is either fixed (joint 0) or
free: a free-flyer child of the world, or, on the air-bearing testbed, a planar joint child of
the world (in-plane translation and rotation about the joint's z, the table's normal). The
placements and velocities the contact needs follow from q and v directly. A free-flyer's q is
Pinocchio's XYZQUAT order, (x, y, z, qx, qy, qz, qw); a planar joint's is (x, y, cos theta,
sin theta). Pinocchio keeps both velocities in the body frame: v = (v_O, omega) for a
free-flyer, (v_O,x, v_O,y, omega_z) for a planar joint, whose other three components are zero.
Each quantity has a form for each kind, and a dispatcher on the body's kind (below).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from ..errors import ModelError
from ..jit import njit, njit_inline
from ..linalg import (
    add3,
    cross3,
    mm9,
    mtv3,
    mtv9,
    mv3,
    mv9,
    put3,
    put9,
    quat_rotation9,
    sub3,
)


class FreeBodies(NamedTuple):
    """The free-flyer joints of a model, one row each."""

    joint: np.ndarray  # (n,) joint index
    idx_q: np.ndarray  # (n,) first index of its configuration in q (xyz, then quaternion)
    idx_v: np.ndarray  # (n,) first index of its velocity in v (v_O, then omega; body frame)
    R_P: np.ndarray  # (n, 3, 3) the joint's placement in the world (its parent), rotation
    p_P: np.ndarray  # (n, 3) and translation, m
    lever: np.ndarray  # (n, 3) the body's centroid in its joint frame, m
    mass: np.ndarray  # (n,) kg
    inertia_G: np.ndarray  # (n, 3, 3) rotational inertia about the centroid, joint axes, kg m^2
    planar: np.ndarray  # (n,) bool: a planar joint (its plane the joint's xy, its normal the joint's z)
    free_rows: np.ndarray  # the rows of the free-flyers, and
    planar_rows: np.ndarray  # of the planar joints: the per-step loops run over each kind in turn


#: The joint kinds the compiled core integrates, by Pinocchio's short names.
FREE_FLYER, PLANAR = "JointModelFreeFlyer", "JointModelPlanar"


def free_joints(model: pin.Model) -> list[int]:
    """The joints of `model` that are free-flyers or planar joints."""
    return [j for j in range(1, model.njoints) if model.joints[j].shortname() in (FREE_FLYER, PLANAR)]


def free_bodies(model: pin.Model) -> FreeBodies:
    """The free-flyer and planar joints of `model`, which must be all its joints, each a child
    of the world (raises ModelError otherwise)."""
    joints = free_joints(model)
    others = [model.names[j] for j in range(1, model.njoints) if j not in joints or model.parents[j] != 0]
    if others:
        raise ModelError(f"joints {others} are neither locked nor free-flyers or planar joints on the world: the "
                         "compiled core integrates free bodies only")
    ints = lambda values: np.array(values, dtype=np.int64)
    return FreeBodies(ints(joints), ints([model.idx_qs[j] for j in joints]),
                      ints([model.idx_vs[j] for j in joints]),
                      np.array([model.jointPlacements[j].rotation for j in joints]).reshape(-1, 3, 3),
                      np.array([model.jointPlacements[j].translation for j in joints]).reshape(-1, 3),
                      np.array([model.inertias[j].lever for j in joints]).reshape(-1, 3),
                      np.array([model.inertias[j].mass for j in joints], dtype=float),
                      np.array([model.inertias[j].inertia for j in joints]).reshape(-1, 3, 3),
                      np.array([model.joints[j].shortname() == PLANAR for j in joints], dtype=bool),
                      ints([b for b, j in enumerate(joints) if model.joints[j].shortname() == FREE_FLYER]),
                      ints([b for b, j in enumerate(joints) if model.joints[j].shortname() == PLANAR]))


# ------------------------------------------------------------------------------- joints
# Each quantity has a free-flyer and a planar form, and a dispatcher on the body's kind. A
# test on the kind next to reads of the bodies' arrays keeps numba from pruning their
# reference counts, which cost 20-110 ns a call (measured). So each form is split into a
# struct-free part on the joint's slice of q or v (the `_at` forms), and the dispatchers hand
# the choice between them to a compiled call that sees plain arrays only (`by_kind`). The
# per-step loops (`kinematics`, the integrators, the dynamics) run over the rows of each kind
# in turn (`free_rows`, `planar_rows`), handing one loop body the kind's forms.


@njit
def by_kind(planar, planar_form, free_form, x, i):
    """planar_form(x, i) if planar, else free_form(x, i): the one place a dispatcher tests a
    body's kind, on plain arrays only (x: q or v; i: the joint's first index in it)."""
    if planar:
        return planar_form(x, i)
    return free_form(x, i)


@njit_inline
def free_twist_at(v, iv):
    """A free-flyer's velocity in its joint frame, (v_O, omega), two 3-tuples, from v[iv:]."""
    return (v[iv], v[iv + 1], v[iv + 2]), (v[iv + 3], v[iv + 4], v[iv + 5])


@njit_inline
def planar_twist_at(v, iv):
    """A planar joint's velocity in its joint frame, (v_O, omega), two 3-tuples, from v[iv:]:
    its out-of-plane components are zero."""
    return (v[iv], v[iv + 1], 0.0), (0.0, 0.0, v[iv + 2])


@njit_inline
def free_twist(bodies, b, v):
    """A free-flyer's velocity in its joint frame, (v_O, omega), two 3-tuples."""
    return free_twist_at(v, bodies.idx_v[b])


@njit_inline
def planar_twist(bodies, b, v):
    """A planar joint's velocity in its joint frame, (v_O, omega), two 3-tuples."""
    return planar_twist_at(v, bodies.idx_v[b])


@njit_inline
def twist(bodies, b, v):
    """Free body b's velocity in its joint frame, (v_O, omega), two 3-tuples."""
    return by_kind(bodies.planar[b], planar_twist_at, free_twist_at, v, bodies.idx_v[b])


@njit_inline
def set_free_rate(bodies, b, a, a_O, alpha):
    """Writes a free-flyer's twist derivative (a_O, alpha), two 3-tuples, into a (nv,)."""
    iv = bodies.idx_v[b]
    a[iv], a[iv + 1], a[iv + 2] = a_O[0], a_O[1], a_O[2]
    a[iv + 3], a[iv + 4], a[iv + 5] = alpha[0], alpha[1], alpha[2]


@njit_inline
def set_planar_rate(bodies, b, a, a_O, alpha):
    """Writes a planar joint's twist derivative into a (nv,): its in-plane components."""
    iv = bodies.idx_v[b]
    a[iv], a[iv + 1], a[iv + 2] = a_O[0], a_O[1], alpha[2]


@njit_inline
def free_quat_at(q, iq):
    """A free-flyer's joint rotation as its unit quaternion (x, y, z, w), from q[iq:]."""
    return q[iq + 3], q[iq + 4], q[iq + 5], q[iq + 6]


@njit_inline
def planar_quat_at(q, iq):
    """A planar joint's turn about its z as a unit quaternion (x, y, z, w), from q[iq:]."""
    half = 0.5 * math.atan2(q[iq + 3], q[iq + 2])
    return 0.0, 0.0, math.sin(half), math.cos(half)


@njit_inline
def free_quat(bodies, b, q):
    """A free-flyer's joint rotation as its unit quaternion (x, y, z, w), a 4-tuple."""
    return free_quat_at(q, bodies.idx_q[b])


@njit_inline
def planar_quat(bodies, b, q):
    """A planar joint's turn about its z as a unit quaternion (x, y, z, w), a 4-tuple."""
    return planar_quat_at(q, bodies.idx_q[b])


@njit_inline
def joint_quat(bodies, b, q):
    """The rotation of free body b's joint as a unit quaternion (x, y, z, w), a 4-tuple."""
    return by_kind(bodies.planar[b], planar_quat_at, free_quat_at, q, bodies.idx_q[b])


# ------------------------------------------------------------------------------- poses


@njit_inline
def free_turn9_at(q, iq):
    """A free-flyer's joint rotation, row by row, from q[iq:]."""
    return quat_rotation9(q[iq + 3], q[iq + 4], q[iq + 5], q[iq + 6])


@njit_inline
def planar_turn9_at(q, iq):
    """A planar joint's rotation about its z, row by row, from q[iq:] = (x, y, cos, sin)."""
    c, s = q[iq + 2], q[iq + 3]
    return c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0


@njit_inline
def free_shift3_at(q, iq):
    """A free-flyer's joint translation, from q[iq:]."""
    return q[iq], q[iq + 1], q[iq + 2]


@njit_inline
def planar_shift3_at(q, iq):
    """A planar joint's translation, in its plane, from q[iq:]."""
    return q[iq], q[iq + 1], 0.0


@njit_inline
def free_rotation9(bodies, b, q):
    """A free-flyer's rotation in the world, row by row: R_P times its quaternion's."""
    return mm9(bodies.R_P[b], free_turn9_at(q, bodies.idx_q[b]))


@njit_inline
def planar_rotation9(bodies, b, q):
    """A planar joint's rotation in the world, row by row: R_P times its turn about z."""
    return mm9(bodies.R_P[b], planar_turn9_at(q, bodies.idx_q[b]))


@njit_inline
def free_origin3(bodies, b, q):
    """A free-flyer's origin in the world, a 3-tuple."""
    return add3(mv3(bodies.R_P[b], free_shift3_at(q, bodies.idx_q[b])), bodies.p_P[b])


@njit_inline
def planar_origin3(bodies, b, q):
    """A planar joint's origin in the world, a 3-tuple."""
    return add3(mv3(bodies.R_P[b], planar_shift3_at(q, bodies.idx_q[b])), bodies.p_P[b])


@njit_inline
def body_rotation9(bodies, b, q):
    """Rotation of free body b in the world as a 9-tuple, row by row."""
    return mm9(bodies.R_P[b], by_kind(bodies.planar[b], planar_turn9_at, free_turn9_at, q, bodies.idx_q[b]))


@njit_inline
def body_rotation_into(bodies, b, q, out):
    """`body_rotation9`, written into out (3, 3)."""
    put9(out, body_rotation9(bodies, b, q))


@njit
def body_rotation(bodies, b, q):
    """Rotation (3, 3) of free body b in the world, from q."""
    R = np.empty((3, 3))
    body_rotation_into(bodies, b, q, R)
    return R


@njit_inline
def body_origin3(bodies, b, q):
    """Origin of free body b in the world, from q, as a 3-tuple."""
    return add3(mv3(bodies.R_P[b], by_kind(bodies.planar[b], planar_shift3_at, free_shift3_at, q, bodies.idx_q[b])),
                bodies.p_P[b])


@njit_inline
def _pose_into(d, j, R, origin, v_O, w):
    """Write a body's world rotation R (9-tuple), origin and twist (joint frame) into row j
    of d.R_W, d.p_W, d.vo_W, d.w_W."""
    put9(d.R_W[j], R)
    put3(d.p_W[j], 0, origin)
    put3(d.vo_W[j], 0, mv9(R, v_O))
    put3(d.w_W[j], 0, mv9(R, w))


@njit
def kinematics(m, d):
    """Stage 1: each free body's rotation, origin, angular velocity and origin velocity in the
    world, into rows m.bodies.joint of d.R_W, d.p_W, d.w_W, d.vo_W (fixed bodies stay at the
    identity)."""
    _kinematics_kind(m, d, m.bodies.free_rows, free_twist, free_rotation9, free_origin3)
    _kinematics_kind(m, d, m.bodies.planar_rows, planar_twist, planar_rotation9, planar_origin3)


@njit_inline
def _kinematics_kind(m, d, rows, twist_of, rotation9_of, origin3_of):
    """`kinematics` for the bodies of one joint kind (rows), read through its accessors."""
    for b in rows:
        v_O, w = twist_of(m.bodies, b, d.v)
        _pose_into(d, m.bodies.joint[b], rotation9_of(m.bodies, b, d.q), origin3_of(m.bodies, b, d.q), v_O, w)


# ------------------------------------------------------------------------------- centroids


@njit_inline
def centroid_of(origin, R, c, v_O, w):
    """A body's world centroid position and velocity (3-tuples) from its origin and rotation R
    (3, 3) in the world, its centroid c and twist (v_O, w) in its frame."""
    return add3(origin, mv3(R, c)), mv3(R, add3(v_O, cross3(w, c)))


@njit
def centroid_state_at(bodies, b, R, q, v):
    """World centroid position and velocity, rotation, and body angular velocity of free body
    b, given its rotation R (from q): 3-tuple, 3-tuple, R, 3-tuple."""
    v_O, w = twist(bodies, b, v)
    p_G, v_G = centroid_of(body_origin3(bodies, b, q), R, bodies.lever[b], v_O, w)
    return p_G, v_G, R, w


@njit
def centroid_state(bodies, b, q, v):
    """`centroid_state_at` with the rotation computed from q."""
    return centroid_state_at(bodies, b, body_rotation(bodies, b, q), q, v)


@njit
def centroid_acceleration(R, c, v_O, w, a_O, alpha):
    """d/dt of R (v_O + w x c): the centroid's world acceleration from the body-frame twist
    (v_O, w) and its derivative (a_O, alpha); c is the centroid in the body frame. A 3-tuple."""
    return mv3(R, add3(add3(add3(a_O, cross3(w, v_O)), cross3(alpha, c)), cross3(w, cross3(w, c))))


@njit_inline
def _joint_state(bodies, b, p_G, v_G, Rq, w):
    """The joint's translation x and origin velocity v_O (its frame) of free body b whose world
    centroid state is (p_G, v_G), joint rotation Rq (9-tuple) and body angular velocity w."""
    c, R_P = bodies.lever[b], bodies.R_P[b]
    # p_G = p_P + R_P (x + Rq c)
    return (sub3(mtv3(R_P, sub3(p_G, bodies.p_P[b])), mv9(Rq, c)),
            sub3(mtv9(mm9(R_P, Rq), v_G), cross3(w, c)))


@njit_inline
def put_free_state_at(q, v, iq, iv, x, quat, v_O, w):
    """Write a free-flyer's joint translation x, quaternion quat (x, y, z, w), origin velocity
    v_O and angular velocity w into q[iq:] and v[iv:]."""
    put3(q, iq, x)
    q[iq + 3], q[iq + 4], q[iq + 5], q[iq + 6] = quat[0], quat[1], quat[2], quat[3]
    put3(v, iv, v_O)
    put3(v, iv + 3, w)


@njit_inline
def put_planar_state_at(q, v, iq, iv, x, Rq, v_O, w):
    """`put_free_state_at` for a planar joint: the in-plane components, its turn read off its
    rotation Rq (9-tuple; the integrators give it a centroid in its plane and a turn
    about its normal)."""
    turn = math.sqrt(Rq[0] * Rq[0] + Rq[3] * Rq[3])
    q[iq], q[iq + 1], q[iq + 2], q[iq + 3] = x[0], x[1], Rq[0] / turn, Rq[3] / turn
    v[iv], v[iv + 1], v[iv + 2] = v_O[0], v_O[1], w[2]


@njit_inline
def set_free_state(bodies, b, q, v, p_G, v_G, quat, w):
    """Write a free-flyer's configuration and velocity from its world centroid state and its
    joint's quaternion (x, y, z, w), in place."""
    Rq = quat_rotation9(quat[0], quat[1], quat[2], quat[3])
    x, v_O = _joint_state(bodies, b, p_G, v_G, Rq, w)
    put_free_state_at(q, v, bodies.idx_q[b], bodies.idx_v[b], x, quat, v_O, w)


@njit_inline
def set_planar_state(bodies, b, q, v, p_G, v_G, quat, w):
    """`set_free_state` for a planar joint: its in-plane components."""
    Rq = quat_rotation9(quat[0], quat[1], quat[2], quat[3])
    x, v_O = _joint_state(bodies, b, p_G, v_G, Rq, w)
    put_planar_state_at(q, v, bodies.idx_q[b], bodies.idx_v[b], x, Rq, v_O, w)


@njit_inline
def set_centroid_state(bodies, b, q, v, p_G, v_G, quat, w):
    """Write free body b's configuration and velocity from its world centroid state and its
    joint's quaternion (x, y, z, w), in place."""
    Rq = quat_rotation9(quat[0], quat[1], quat[2], quat[3])
    x, v_O = _joint_state(bodies, b, p_G, v_G, Rq, w)
    put_state_kind_at(q, v, bodies.idx_q[b], bodies.idx_v[b], x, quat, Rq, v_O, w, bodies.planar[b])


@njit
def put_state_kind_at(q, v, iq, iv, x, quat, Rq, v_O, w, planar):
    """`put_planar_state_at` or `put_free_state_at`."""
    if planar:
        put_planar_state_at(q, v, iq, iv, x, Rq, v_O, w)
    else:
        put_free_state_at(q, v, iq, iv, x, quat, v_O, w)


# ------------------------------------------------------------------------------- momenta


@njit_inline
def body_momentum3(bodies, b, q, v):
    """Free body b's linear momentum, its angular momentum about the world origin and its
    centroid (world), as 3-tuples."""
    R = body_rotation9(bodies, b, q)
    m, lever = bodies.mass[b], bodies.lever[b]
    v_O, w = twist(bodies, b, v)
    v_G = mv9(R, add3(v_O, cross3(w, lever)))
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
        v_O, w = twist(bodies, b, v)
        v_G = add3(v_O, cross3(w, bodies.lever[b]))  # body axes; the norm is frame-free
        Iw = mv3(bodies.inertia_G[b], w)
        total += 0.5 * bodies.mass[b] * (v_G[0] * v_G[0] + v_G[1] * v_G[1] + v_G[2] * v_G[2]) + \
            0.5 * (w[0] * Iw[0] + w[1] * Iw[1] + w[2] * Iw[2])
    return total


# ------------------------------------------------------------------------------- motion bound


@njit
def travel_rate(m, d):
    """A bound on how fast any two contact spheres approach each other, m/s: the sum over the
    free contact bodies of |v_O| + |omega| reach, plus the fastest finger slide."""
    rate = 0.0
    for i in range(d.opening_rate.shape[0]):
        rate = max(rate, abs(d.opening_rate[i]))
    for i in range(m.limits.reach_rows.shape[0]):
        # v = (v_O, omega) in the body's frame; norms are frame-free
        v_O, w = twist(m.bodies, m.limits.reach_rows[i], d.v)
        rate += math.sqrt(v_O[0] ** 2 + v_O[1] ** 2 + v_O[2] ** 2) + \
            math.sqrt(w[0] ** 2 + w[1] ** 2 + w[2] ** 2) * m.limits.reach[i]
    return rate
