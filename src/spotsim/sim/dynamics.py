"""Stage: the joints' accelerations under the joint forces, the contact wrenches and gravity
(paper Eq. 22-23): Pinocchio's articulated-body algorithm over the kinematic tree.

M(q) v' + C(q, v) = tau + tau_passive + sum_k J_k^T f_k, solved branch by branch
(`tree.Branches`), with the result in Pinocchio's conventions: the time derivative of v, each
joint's velocity in its own frame (`pin.aba(model, data, q, v, tau, fext)`, with the model's
`armature` on the mass matrix's diagonal; fext, each body's wrench in its joint's frame). The
algorithm runs in the world frame, as Pinocchio's `WORLD` convention does: spatial vectors
(linear, angular) taken at the world origin, so that the kinematics stage's frames serve it
and a child's inertia joins its parent's without a change of frame. The tests hold it to
`pin.aba` and `pin.crba` on every shipped scene and on articulated models of their own.

- tau: the actuators' joint forces (`Data.tau`), plus the passive springs and dampers of
  the joints, -stiffness (q - rest) - damping v.
- A prescribed joint (a finger behind a kinematic drive) moves as its actuator sets it: its
  acceleration is given (zero: the drive holds its speed between samples), the rest of its
  branch responds to that motion (Featherstone's hybrid dynamics), and its actuator's force is
  whatever the motion takes. A change of a prescribed speed is an impulse on its branch
  (`velocity_jump`).
- A branch of one free body (a module) is Newton-Euler: its articulated inertia is its own.
- On the air-bearing table a planar branch falls in gravity's part in the table's plane (the
  bearings carry the rest; taken off here, not left to the joint frames, whose z is the
  normal only to round-off).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba.experimental import structref

from ..jit import njit, njit_inline
from ..linalg import add3, cross3, mtv3, mv3, solve_spd3, sub3
from ..structs import StructProxy, StructType, new_struct, register
from ..tables import FORWARD, MOTOR, PLANAR, PRISMATIC, STUCK
from .tree import ARTICULATED, NEWTON_EULER, branch_centroid, joint_twist, passive_force


class Articulation(NamedTuple):
    """Scratch of the articulated-body algorithm, one row per joint (`Data.work`); spatial
    vectors (linear, angular) in the world frame at its origin."""

    inertia_W: np.ndarray  # (nj, 3, 3) each body's rotational inertia about its centroid, world axes
    centroid_W: np.ndarray  # (nj, 3) its centroid, world, m
    S: np.ndarray  # (nj, 6) a one-dof joint's motion subspace
    c: np.ndarray  # (nj, 6) its velocity-product acceleration v x S v_j
    IA: np.ndarray  # (nj, 6, 6) its articulated inertia
    pA: np.ndarray  # (nj, 6) its articulated bias force
    U: np.ndarray  # (nj, 6) a one-dof joint's IA S
    D: np.ndarray  # (nj,) ... S^T IA S + armature
    u: np.ndarray  # (nj,) ... tau - S^T pA
    acc: np.ndarray  # (nj, 6) its spatial acceleration
    L: np.ndarray  # (6, 6) a root's Cholesky factor
    A: np.ndarray  # (6, 6) scratch: a root's subspace columns
    M: np.ndarray  # (6, 6) scratch: a root's system
    x: np.ndarray  # (3, 6) scratch vectors
    given: np.ndarray  # (nv,) prescribed joints' accelerations (zero), or velocity changes in a jump
    jump: np.ndarray  # (nv,) a velocity jump's response
    unit: np.ndarray  # (nv,) the joint forces whose response `joint_response` asks for (zero otherwise)


@structref.register
class ArticulationType(StructType):
    pass


class ArticulationStruct(StructProxy):
    """Compiled Articulation scratch (see `Articulation`): one pointer to pass or bind."""


register(ArticulationType, Articulation, ArticulationStruct)


def new_articulation(nj: int, nv: int) -> ArticulationStruct:
    return new_struct(Articulation(
        inertia_W=np.zeros((nj, 3, 3)), centroid_W=np.zeros((nj, 3)), S=np.zeros((nj, 6)), c=np.zeros((nj, 6)),
        IA=np.zeros((nj, 6, 6)), pA=np.zeros((nj, 6)), U=np.zeros((nj, 6)), D=np.zeros(nj), u=np.zeros(nj),
        acc=np.zeros((nj, 6)), L=np.zeros((6, 6)), A=np.zeros((6, 6)), M=np.zeros((6, 6)), x=np.zeros((3, 6)),
        given=np.zeros(nv), jump=np.zeros(nv), unit=np.zeros(nv)))


# ------------------------------------------------------------------------------- one free body


@njit_inline
def body_acceleration(t, j, R, v, f, tau_O, g_W, planar):
    """One free body's (a_O, alpha), two 3-tuples: the articulated-body algorithm of a branch
    whose articulated inertia is the body's own, Newton about its centroid (world) and Euler
    about it (body axes), given its rotation R (3, 3) in the world.

    v: (nv,) velocities. f, tau_O: the wrench on its body, force and moment about the joint
    origin in the joint frame, N and N m (3-tuples). g_W: (3,) gravity, m/s^2. planar: on a
    planar joint its centroid accelerates by the in-plane force and gravity, and it turns by the
    moment about its centroid along the normal over I_zz (with omega along the normal,
    omega x I omega has no normal component).
    """
    m, c, I_G = t.mass[j], t.lever[j], t.inertia_G[j]
    v_O, w = joint_twist(t, j, v)
    g = mtv3(R, g_W)
    tau_G = sub3(tau_O, cross3(c, f))
    if planar:
        a_G = (f[0] / m + g[0], f[1] / m + g[1], 0.0)
        alpha = (0.0, 0.0, tau_G[2] / I_G[2, 2])
    else:
        a_G = (f[0] / m + g[0], f[1] / m + g[1], f[2] / m + g[2])
        alpha = solve_spd3(I_G, sub3(tau_G, cross3(w, mv3(I_G, w))))
    return _origin_acceleration(a_G, alpha, c, v_O, w), alpha


@njit_inline
def _origin_acceleration(a_G, alpha, c, v_O, w):
    """The twist's linear rate a_O (body frame) of a body whose centroid c accelerates by a_G
    (body axes): the centroid's acceleration is that of the origin plus alpha x c + w x (w x
    c), and the twist's linear part is the origin's velocity in the turning body frame."""
    return sub3(sub3(sub3(a_G, cross3(alpha, c)), cross3(w, cross3(w, c))), cross3(w, v_O))


@njit_inline
def _newton_euler(m, d, b):
    """Branch b, one free body: its accelerations into d.a, under the contact wrench and its
    joint force d.tau (a wrench in its frame)."""
    t = m.tree
    j = m.branches.joint[b]
    iv = t.idx_v[j]
    fl, tau = d.loads.f_local, d.tau
    planar = t.kind[j] == PLANAR
    if planar:  # its joint force: (v_O,x, v_O,y, omega_z)
        f, tau_O = (fl[j, 0] + tau[iv], fl[j, 1] + tau[iv + 1], fl[j, 2]), (fl[j, 3], fl[j, 4], fl[j, 5] + tau[iv + 2])
    else:
        f = (fl[j, 0] + tau[iv], fl[j, 1] + tau[iv + 1], fl[j, 2] + tau[iv + 2])
        tau_O = (fl[j, 3] + tau[iv + 3], fl[j, 4] + tau[iv + 4], fl[j, 5] + tau[iv + 5])
    a_O, alpha = body_acceleration(t, j, d.R_W[j], d.v, f, tau_O, m.branches.gravity_W[b], planar)
    if planar:
        d.a[iv], d.a[iv + 1], d.a[iv + 2] = a_O[0], a_O[1], alpha[2]
    else:
        d.a[iv], d.a[iv + 1], d.a[iv + 2] = a_O[0], a_O[1], a_O[2]
        d.a[iv + 3], d.a[iv + 4], d.a[iv + 5] = alpha[0], alpha[1], alpha[2]


# ------------------------------------------------------------------------------- spatial algebra


@njit_inline
def _rotated9(R, I):
    """R I R^T for two 3x3 arrays, as a 9-tuple row by row."""
    a = mv3(I, (R[0, 0], R[0, 1], R[0, 2]))  # I times the rows of R: the columns of I R^T
    b = mv3(I, (R[1, 0], R[1, 1], R[1, 2]))
    c = mv3(I, (R[2, 0], R[2, 1], R[2, 2]))
    return (R[0, 0] * a[0] + R[0, 1] * a[1] + R[0, 2] * a[2], R[0, 0] * b[0] + R[0, 1] * b[1] + R[0, 2] * b[2],
            R[0, 0] * c[0] + R[0, 1] * c[1] + R[0, 2] * c[2], R[1, 0] * a[0] + R[1, 1] * a[1] + R[1, 2] * a[2],
            R[1, 0] * b[0] + R[1, 1] * b[1] + R[1, 2] * b[2], R[1, 0] * c[0] + R[1, 1] * c[1] + R[1, 2] * c[2],
            R[2, 0] * a[0] + R[2, 1] * a[1] + R[2, 2] * a[2], R[2, 0] * b[0] + R[2, 1] * b[1] + R[2, 2] * b[2],
            R[2, 0] * c[0] + R[2, 1] * c[1] + R[2, 2] * c[2])


@njit_inline
def _rigid_times(mass, c, I_G, v, w):
    """A rigid body's spatial inertia (mass, centroid c, rotational inertia I_G about it, a 3x3
    array, in the frame of the spatial vectors) times the motion (v, w): the momentum (f, tau),
    3-tuples, tau about the frame's origin."""
    f = (mass * (v[0] + w[1] * c[2] - w[2] * c[1]), mass * (v[1] + w[2] * c[0] - w[0] * c[2]),
         mass * (v[2] + w[0] * c[1] - w[1] * c[0]))
    return f, add3(mv3(I_G, w), cross3(c, f))


@njit_inline
def _add_rigid(M, mass, c, I_G):
    """Add the 6x6 spatial inertia (linear first) of a rigid body (mass, centroid c, I_G a 3x3
    array about the centroid, the frame's axes) to M: [[m, -m [c]x], [m [c]x, I_G - m [c]x [c]x]]."""
    cc = c[0] * c[0] + c[1] * c[1] + c[2] * c[2]
    for a in range(3):
        M[a, a] += mass
        for k in range(3):
            M[3 + a, 3 + k] += I_G[a, k] + mass * ((cc if a == k else 0.0) - c[a] * c[k])
    # m [c]x below the diagonal, its transpose above
    cx = ((0.0, -c[2], c[1]), (c[2], 0.0, -c[0]), (-c[1], c[0], 0.0))
    for a in range(3):
        for k in range(3):
            if a != k:
                M[3 + a, k] += mass * cx[a][k]
                M[k, 3 + a] += mass * cx[a][k]


@njit_inline
def _rigid_solve(M, f, tau, scratch):
    """The motion a (6-tuple, linear first) at which a rigid body of spatial inertia M (6, 6)
    has the momentum rate (f, tau): with h = m c, M = [[m, -[h]x], [[h]x, I_O]], so
    alpha = I_G^-1 (tau - c x f) about the centroid and a = (f + h x alpha) / m."""
    mass = M[0, 0]
    h = (-M[4, 2], M[3, 2], -M[3, 1])
    hh = h[0] * h[0] + h[1] * h[1] + h[2] * h[2]
    for a in range(3):
        for k in range(3):
            scratch[a, k] = M[3 + a, 3 + k] + (h[a] * h[k] - (hh if a == k else 0.0)) / mass
    c = (h[0] / mass, h[1] / mass, h[2] / mass)
    alpha = solve_spd3(scratch, sub3(tau, cross3(c, f)))
    hxa = cross3(h, alpha)
    return ((f[0] + hxa[0]) / mass, (f[1] + hxa[1]) / mass, (f[2] + hxa[2]) / mass, alpha[0], alpha[1], alpha[2])


@njit_inline
def _solve_spd(A, b, n, L, out):
    """out[:n] = A[:n, :n]^-1 b[:n] for a symmetric positive-definite A, by Cholesky into L; b
    and out may be the same array."""
    for i in range(n):
        for k in range(i + 1):
            s = A[i, k]
            for x in range(k):
                s -= L[i, x] * L[k, x]
            L[i, k] = math.sqrt(s) if i == k else s / L[k, k]
    for i in range(n):
        s = b[i]
        for x in range(i):
            s -= L[i, x] * out[x]
        out[i] = s / L[i, i]
    for i in range(n - 1, -1, -1):
        s = out[i]
        for x in range(i + 1, n):
            s -= L[x, i] * out[x]
        out[i] = s / L[i, i]


@njit_inline
def _root_columns(kind, R, p, X):
    """A floating root's motion subspace at the world origin: the world spatial motion of each
    of its velocity components (its frame at rotation R (3, 3) and origin p), into the rows of
    X (6, 6); returns how many. A free-flyer's: (R e_k, 0) for v_O, (p x R e_k, R e_k) for
    omega; a planar joint's: v_O,x, v_O,y, omega_z."""
    n = 0
    for k in range(3):
        if kind == PLANAR and k == 2:
            continue
        for a in range(3):
            X[n, a], X[n, 3 + a] = R[a, k], 0.0
        n += 1
    for k in range(3):
        if kind == PLANAR and k < 2:
            continue
        r = (R[0, k], R[1, k], R[2, k])
        pr = cross3(p, r)
        for a in range(3):
            X[n, a], X[n, 3 + a] = pr[a], r[a]
        n += 1
    return n


# ------------------------------------------------------------------------------- the algorithm


@njit
def _articulated(m, d, b, bias, out, inertias):
    """Branch b by the articulated-body algorithm in the world frame, at the kinematics of the
    last `kinematics` (d.R_W ...): its joints' accelerations into out (nv,).

    bias: the velocity products, gravity, the contact wrenches and the joint forces act, and
    prescribed joints accelerate as w_given (zero); else none acts, and out is the branch's
    response to prescribed velocity changes w_given (an impulse: M dv = S^T lambda on the
    prescribed joints) and to the joint forces d.work.unit on the others.

    inertias=False (not with bias): the articulated inertias, the subspaces and U, D are those
    the last pass over branch b left in d.work, which must have been made at the same
    kinematics; they depend on no force, so only the forces' recursion runs again."""
    t, br, w = m.tree, m.branches, d.work
    q, v, f_local = d.q, d.v, d.loads.f_local
    R_W, p_W, w_W, vo_W = d.R_W, d.p_W, d.w_W, d.vo_W
    # the scratch's arrays bound once: read through the structure in the loops, each read
    # would cost its reference counts at every use
    w_inertia_W, w_centroid_W, w_S, w_c, w_IA, w_pA = w.inertia_W, w.centroid_W, w.S, w.c, w.IA, w.pA
    w_U, w_D, w_u, w_acc, w_given = w.U, w.D, w.u, w.acc, w.given
    # pass 1, root to leaves: each body's inertia and bias force, each joint's subspace
    for i in range(br.first[b], br.stop[b]):
        j = br.members[i]
        for a in range(6):
            w_c[j, a] = 0.0
            w_pA[j, a] = 0.0
        if not inertias:
            continue
        R = R_W[j]
        p = (p_W[j, 0], p_W[j, 1], p_W[j, 2])
        c = add3(p, mv3(R, t.lever[j]))
        I9 = _rotated9(R, t.inertia_G[j])
        for a in range(3):
            w_centroid_W[j, a] = c[a]
            for k in range(3):
                w_inertia_W[j, a, k] = I9[3 * a + k]
        if t.nv[j] == 1:  # its motion subspace at the world origin
            ax = mv3(R, t.axis[j])
            lin, ang = (ax, (0.0, 0.0, 0.0)) if t.kind[j] == PRISMATIC else (cross3(p, ax), ax)
            for a in range(3):
                w_S[j, a], w_S[j, 3 + a] = lin[a], ang[a]
        if not (t.prescribed[j] and t.leaf[j]):
            for a in range(6):
                for k in range(6):
                    w_IA[j, a, k] = 0.0
            _add_rigid(w_IA[j], t.mass[j], c, w_inertia_W[j])
        if not bias:
            continue
        om = (w_W[j, 0], w_W[j, 1], w_W[j, 2])
        vel = sub3((vo_W[j, 0], vo_W[j, 1], vo_W[j, 2]), cross3(om, p))  # the body's point at the origin
        if t.nv[j] == 1 and t.parent[j]:  # c = v x S qdot: the subspace turns with the body
            qd = v[t.idx_v[j]]
            sl = (qd * w_S[j, 0], qd * w_S[j, 1], qd * w_S[j, 2])
            sa = (qd * w_S[j, 3], qd * w_S[j, 4], qd * w_S[j, 5])
            cl, ca = add3(cross3(om, sl), cross3(vel, sa)), cross3(om, sa)
            for a in range(3):
                w_c[j, a], w_c[j, 3 + a] = cl[a], ca[a]
        f, tau = _rigid_times(t.mass[j], c, w_inertia_W[j], vel, om)
        # v x* (I v) - f_ext, the contact wrench taken from its joint's frame to the origin
        fe = mv3(R, (f_local[j, 0], f_local[j, 1], f_local[j, 2]))
        te = add3(mv3(R, (f_local[j, 3], f_local[j, 4], f_local[j, 5])), cross3(p, fe))
        pf, pt = cross3(om, f), add3(cross3(om, tau), cross3(vel, f))
        for a in range(3):
            w_pA[j, a] = pf[a] - fe[a]
            w_pA[j, 3 + a] = pt[a] - te[a]
    # pass 2, leaves to root: articulated inertias and bias forces, summed at the origin
    for i in range(br.stop[b] - 1, br.first[b] - 1, -1):
        j = br.members[i]
        par = t.parent[j]
        iv = t.idx_v[j]
        if t.nv[j] > 1:  # a floating root: solved in pass 3
            continue
        if t.prescribed[j]:
            # the joint moves as given: its whole inertia passes to the parent
            if par == 0:
                continue
            g = w_given[iv]
            acc_l = (w_c[j, 0] + g * w_S[j, 0], w_c[j, 1] + g * w_S[j, 1], w_c[j, 2] + g * w_S[j, 2])
            acc_a = (w_c[j, 3] + g * w_S[j, 3], w_c[j, 4] + g * w_S[j, 4], w_c[j, 5] + g * w_S[j, 5])
            if t.leaf[j]:  # a rigid body
                f, tau = _rigid_times(t.mass[j], w_centroid_W[j], w_inertia_W[j], acc_l, acc_a)
                if inertias:
                    _add_rigid(w_IA[par], t.mass[j], w_centroid_W[j], w_inertia_W[j])
                for a in range(3):
                    w_pA[par, a] += w_pA[j, a] + f[a]
                    w_pA[par, 3 + a] += w_pA[j, 3 + a] + tau[a]
                continue
            for a in range(6):
                x = w_pA[j, a]
                for k in range(3):
                    x += w_IA[j, a, k] * acc_l[k] + w_IA[j, a, 3 + k] * acc_a[k]
                w_pA[par, a] += x
                if inertias:
                    for k in range(6):
                        w_IA[par, a, k] += w_IA[j, a, k]
            continue
        if inertias:
            for a in range(6):
                x = 0.0
                for k in range(6):
                    x += w_IA[j, a, k] * w_S[j, k]
                w_U[j, a] = x
            w_D[j] = _dot6(w_S[j], w_U[j]) + t.armature[iv]
        D = w_D[j]
        if bias:
            tau = d.tau[iv] + passive_force(t, iv, q[t.idx_q[j]], v[iv])
        else:
            tau = w.unit[iv]
        w_u[j] = tau - _dot6(w_S[j], w_pA[j])
        if par == 0:
            continue
        # to the parent: IA - U U^T / D, and pA + Ia c + U u / D (without inertias, c is zero)
        for a in range(6):
            x = w_pA[j, a] + w_U[j, a] * w_u[j] / D
            if inertias:
                for k in range(6):
                    Ia = w_IA[j, a, k] - w_U[j, a] * w_U[j, k] / D
                    x += Ia * w_c[j, k]
                    w_IA[par, a, k] += Ia
            w_pA[par, a] += x
    # pass 3, root to leaves: accelerations
    for i in range(br.first[b], br.stop[b]):
        j = br.members[i]
        par = t.parent[j]
        iv = t.idx_v[j]
        if t.prescribed[j] and t.leaf[j]:  # its acceleration is given, and nothing hangs from it
            out[iv] = w_given[iv]
            continue
        if par:
            for a in range(6):
                w_acc[j, a] = w_acc[par, a] + w_c[j, a]
        else:  # the universe accelerates against gravity (Featherstone's device)
            g = br.gravity_W[b]
            for a in range(3):
                w_acc[j, a] = -g[a] if bias else 0.0
                w_acc[j, 3 + a] = 0.0
        if t.nv[j] > 1:
            _root_acceleration(m, d, b, j, bias, out)
            continue
        if t.prescribed[j]:
            qdd = w_given[iv]
        else:
            qdd = (w_u[j] - _dot6(w_U[j], w_acc[j])) / w_D[j]
        out[iv] = qdd
        for a in range(6):
            w_acc[j, a] += qdd * w_S[j, a]


@njit_inline
def _root_acceleration(m, d, b, j, bias, out):
    """Floating root j's accelerations (its velocity's rate, its frame) into out and its spatial
    acceleration (world) into d.work.acc[j], which holds the universe's on entry: its
    subspace's columns X (`_root_columns`), X^T IA X qdd = X^T (tau_W - pA - IA a0)."""
    t, w = m.tree, d.work
    w_IA, w_pA, w_acc, w_A, w_M, w_L, w_x = w.IA, w.pA, w.acc, w.A, w.M, w.L, w.x
    iv = t.idx_v[j]
    a0 = w_acc[j]
    rhs = w_x[0]  # the force on the root's articulated body at the universe's acceleration
    for a in range(6):
        x = -w_pA[j, a]
        for k in range(6):
            x -= w_IA[j, a, k] * a0[k]
        rhs[a] = x
    R = d.R_W[j]
    p = (d.p_W[j, 0], d.p_W[j, 1], d.p_W[j, 2])
    if bias:  # the joint force, a wrench in the root's frame, at the origin
        if t.kind[j] == PLANAR:
            ft, tt = (d.tau[iv], d.tau[iv + 1], 0.0), (0.0, 0.0, d.tau[iv + 2])
        else:
            ft, tt = (d.tau[iv], d.tau[iv + 1], d.tau[iv + 2]), (d.tau[iv + 3], d.tau[iv + 4], d.tau[iv + 5])
        fw = mv3(R, ft)
        tw = add3(mv3(R, tt), cross3(p, fw))
        for a in range(3):
            rhs[a] += fw[a]
            rhs[3 + a] += tw[a]
    if m.branches.rigid[b] and t.kind[j] != PLANAR:
        # the branch moves as one rigid body (every other joint prescribed): its inertia is a
        # rigid body's, solved about its centroid, and the root's rate is its motion in its frame
        acc = _rigid_solve(w_IA[j], (rhs[0], rhs[1], rhs[2]), (rhs[3], rhs[4], rhs[5]), w_A)
        lin, ang = (acc[0], acc[1], acc[2]), (acc[3], acc[4], acc[5])
        for a in range(3):
            w_acc[j, a] += lin[a]
            w_acc[j, 3 + a] += ang[a]
        # the world motion (lin, ang) at the origin in the root's frame: R^T (lin - p x ang), R^T ang
        vl, va = mtv3(R, sub3(lin, cross3(p, ang))), mtv3(R, ang)
        out[iv], out[iv + 1], out[iv + 2] = vl[0], vl[1], vl[2]
        out[iv + 3], out[iv + 4], out[iv + 5] = va[0], va[1], va[2]
        return
    n = _root_columns(t.kind[j], R, p, w_A)
    sol, IX, D = w_x[1], w_x[2], w_M
    for x in range(n):
        s = 0.0
        for a in range(6):
            s += w_A[x, a] * rhs[a]
        sol[x] = s
    # D = X^T IA X, with the rotors' armature on its diagonal
    for x in range(n):
        for a in range(6):
            s = 0.0
            for k in range(6):
                s += w_IA[j, a, k] * w_A[x, k]
            IX[a] = s
        for y in range(x, n):
            s = 0.0
            for a in range(6):
                s += w_A[y, a] * IX[a]
            D[x, y] = D[y, x] = s
        D[x, x] += t.armature[iv + x]
    _solve_spd(D, sol, n, w_L, sol)
    for x in range(n):
        out[iv + x] = sol[x]
        for a in range(6):
            w_acc[j, a] += sol[x] * w_A[x, a]


@njit_inline
def _dot6(x, y):
    return x[0] * y[0] + x[1] * y[1] + x[2] * y[2] + x[3] * y[3] + x[4] * y[4] + x[5] * y[5]


@njit
def accelerations(m, d):
    """Stage: d.a (nv,), the joints' accelerations at (d.q, d.v) under the joint forces d.tau
    and the passive springs and dampers, the contact wrenches d.loads.f_local and gravity;
    prescribed joints' are given (zero), with the rotations of the last `kinematics`; then
    the motor drives' transmissions (`transmissions`)."""
    br = m.branches
    for b in range(br.joint.shape[0]):
        mode = br.mode[b]
        if mode == NEWTON_EULER:
            _newton_euler(m, d, b)
        elif mode == ARTICULATED:
            _articulated(m, d, b, np.bool_(True), d.a, np.bool_(True))
        else:  # every joint prescribed
            for i in range(br.first[b], br.stop[b]):
                iv = m.tree.idx_v[br.members[i]]
                d.a[iv] = d.work.given[iv]
    transmissions(m, d)


# -------------------------------------------------------------- the motor drives' transmissions
# A motor drive (`sim.actuation`) closes its end-effector's two fingers through a gearhead and a
# lead screw whose nut halves a mirror linkage moves alike: one degree of freedom, x, each
# finger's closing travel. The screw's total closing force F on the pair is set by its
# transmission's state (`tables.TRANSMISSION_STATES`, as Modelica's `LossyGear`):
#
# - sliding, the motor's torque tau_m = K_t i less the rotor's inertia J (B = J rho^2 on the
#   pair's coordinate) passed on with the efficiency of the power's direction: forward (from
#   the motor to the fingers) F = eta_f (rho tau_m - B x''), backward eta_b F = rho tau_m - B x''
#   (with eta_b <= 0, a self-locking screw, only while the fingers are light enough against
#   the rotor's inertia that the motor's side still gives: eta_b + B g > 0);
# - stuck, x'' = 0: F is whatever holds the fingers (the constraint's force), until it leaves
#   the band that the friction of the screw can hold (`sim.actuation.transmission_events`).
#
# The linkage shares F between the fingers so that they accelerate alike: the joint forces
# (phi1, phi2) = (-F/2 + lambda, -F/2 - lambda) on their opening coordinates, lambda the
# linkage's reaction. Both are internal forces: momentum is kept. With x'' = x0'' + g F (the
# accelerations without the drive, and M^-1's block of the finger joints, `joint_response`),
# each state's F is closed-form.


@njit_inline
def drive_fingers(m, ee):
    """The actuator rows of end-effector ee's two fingers, (-1, -1) if they are not in the model."""
    first = second = np.int64(-1)  # not a literal: the kernels it is passed to compile once (jit.py)
    for i in range(m.actuators.joint.shape[0]):
        if m.actuators.drive[i] == ee:
            if first < 0:
                first = i
            else:
                second = i
    return first, second


@njit_inline
def _mirror(m, d, r1, r2, force):
    """The joint forces (phi1, phi2) on fingers r1 and r2 (opening positive) that a total
    closing force `force` (N) of the screw comes to through the mirror linkage, and the
    fingers' common closing acceleration then (m/s^2)."""
    t = m.tree
    iv1, iv2 = t.idx_v[m.actuators.joint[r1]], t.idx_v[m.actuators.joint[r2]]
    g11, g12, g22 = d.response[r1, iv1], d.response[r2, iv1], d.response[r2, iv2]
    a1, a2 = d.drive_free[r1], d.drive_free[r2]
    share = (0.5 * force * (g11 - g22) - (a1 - a2)) / (g11 + g22 - 2.0 * g12)
    phi1, phi2 = -0.5 * force + share, -0.5 * force - share
    return phi1, phi2, -(a1 + g11 * phi1 + g12 * phi2)


@njit_inline
def closing_response(m, d, r1, r2):
    """The fingers' closing acceleration without the screw's force (m/s^2), and its rate in
    that force (m/s^2 per N)."""
    x0 = _mirror(m, d, r1, r2, 0.0)[2]
    return x0, _mirror(m, d, r1, r2, 1.0)[2] - x0


@njit
def screw_force(m, d, ee, r1, r2):
    """The screw's total closing force on end-effector ee's fingers (N) in its transmission's
    state d.transmission[ee], at the motor current d.current[ee]."""
    p = m.drives
    x0, g = closing_response(m, d, r1, r2)
    state = d.transmission[ee]
    if state == STUCK:
        return -x0 / g
    B = p.rotor[ee] * p.ratio[ee] ** 2
    A = p.ratio[ee] * p.torque_constant[ee] * d.current[ee]
    if state == FORWARD:
        return p.forward[ee] * (A - B * x0) / (1.0 + p.forward[ee] * B * g)
    return (A - B * x0) / (p.backward[ee] + B * g)


@njit
def apply_screw(m, d, ee, r1, r2, force):
    """Put the screw's total closing force `force` (N) on end-effector ee's fingers into d.a,
    in place of the one it put there before (d.drive_force)."""
    phi1, phi2, _ = _mirror(m, d, r1, r2, force)
    d1, d2 = phi1 - d.drive_force[r1], phi2 - d.drive_force[r2]
    for k in range(d.a.shape[0]):
        d.a[k] += d1 * d.response[r1, k] + d2 * d.response[r2, k]
    d.drive_force[r1], d.drive_force[r2] = phi1, phi2
    d.screw_force[ee] = force


@njit
def transmissions(m, d):
    """The motor drives' forces on their fingers, by their transmissions' states, added to the
    accelerations d.a of the articulated-body algorithm (which left them out), with the finger
    joints' responses (d.response) that their controllers' events use. Called right after the
    articulated-body pass over the fingers' branch, whose inertias the responses reuse."""
    p = m.drives
    for ee in range(p.law.shape[0]):
        if p.law[ee] != MOTOR:
            continue
        r1, r2 = drive_fingers(m, ee)
        if r2 < 0:
            continue
        for r in (r1, r2):
            j = m.actuators.joint[r]
            d.drive_free[r] = d.a[m.tree.idx_v[j]]
            d.drive_force[r] = 0.0
            joint_response(m, d, j, d.response[r], np.bool_(False))  # the same frames as the pass just made
        apply_screw(m, d, ee, r1, r2, screw_force(m, d, ee, r1, r2))


@njit
def joint_response(m, d, j, out, inertias):
    """out (nv,): M^-1 e_j, the accelerations that a unit force on one-dof joint j gives its
    branch (zero elsewhere), or the velocity change a unit impulse on it gives; at the frames
    of the last `kinematics`. Its rows for two joints are the joints' block of M^-1.
    inertias=False: reuse the articulated inertias of the last pass over j's branch, made at
    those frames (`_articulated`)."""
    t = m.tree
    iv = t.idx_v[j]
    out[:] = 0.0
    d.work.unit[iv] = 1.0
    _articulated(m, d, t.branch[j], np.bool_(False), out, inertias)
    d.work.unit[iv] = 0.0


@njit
def velocity_jump(m, d, joints, speeds):
    """Set the prescribed `joints` (one dof each) to `speeds`, and every other joint of their
    branches to the velocity that the impulse doing so leaves it with (M dv = S^T lambda on
    the prescribed joints): momentum is kept. The frames are those of the last `kinematics`,
    which must be made at d.q. Returns whether any velocity changed."""
    t, br, w = m.tree, m.branches, d.work
    changed = False
    for i in range(joints.shape[0]):
        iv = t.idx_v[joints[i]]
        w.given[iv] = speeds[i] - d.v[iv]
        changed = changed or w.given[iv] != 0.0
    if changed:
        for b in range(br.joint.shape[0]):
            if br.mode[b] != ARTICULATED or not _jumps(m, d, b):
                continue
            _articulated(m, d, b, np.bool_(False), w.jump, np.bool_(True))
            for k in range(br.first[b], br.stop[b]):
                j = br.members[k]
                if not t.prescribed[j]:
                    for x in range(t.nv[j]):
                        d.v[t.idx_v[j] + x] += w.jump[t.idx_v[j] + x]
    for i in range(joints.shape[0]):
        iv = t.idx_v[joints[i]]
        d.v[iv] = speeds[i]
        w.given[iv] = 0.0
    return changed


@njit_inline
def _jumps(m, d, b):
    """Whether a prescribed joint of branch b changes its velocity (d.work.given)."""
    br, t = m.branches, m.tree
    for i in range(br.first[b], br.stop[b]):
        j = br.members[i]
        if t.prescribed[j] and d.work.given[t.idx_v[j]] != 0.0:
            return True
    return False


@njit_inline
def table_load(m, d, b):
    """What floating branch b's contact wrench presses into its table (a planar branch): the
    force along the normal, N, and the moment about its centroid in the plane, N m, as
    magnitudes: the bearings and the table react them, and nothing moves by them. From the
    kinematics and loads of the last evaluation."""
    br = m.branches
    n = m.table_normal
    F0 = F1 = F2 = T0 = T1 = T2 = 0.0
    for i in range(br.first[b], br.stop[b]):
        j = br.members[i]
        F0 += d.loads.force_W[j, 0]
        F1 += d.loads.force_W[j, 1]
        F2 += d.loads.force_W[j, 2]
        T0 += d.loads.torque_O_W[j, 0]
        T1 += d.loads.torque_O_W[j, 1]
        T2 += d.loads.torque_O_W[j, 2]
    c, _ = branch_centroid(m, d, b)
    F = (F0, F1, F2)
    tau_G = sub3((T0, T1, T2), cross3(c, F))
    along = tau_G[0] * n[0] + tau_G[1] * n[1] + tau_G[2] * n[2]
    in_plane = sub3(tau_G, (along * n[0], along * n[1], along * n[2]))
    return (abs(F0 * n[0] + F1 * n[1] + F2 * n[2]),
            math.sqrt(in_plane[0] ** 2 + in_plane[1] ** 2 + in_plane[2] ** 2))
