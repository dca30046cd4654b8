"""The force of each sphere pair (Eq. 6-17) and one wrench per body (Eq. 18-21), compiled.

`pair_forces` chains the contact law's kernels (detection, normal force, bristle friction)
over the candidate pairs of one step, with each pair's memory carried from the last step;
`body_wrenches` sums the pair forces into one wrench per body.
"""

from __future__ import annotations

import math

import numpy as np

from ..bodies import add3, mv3
from ..jit import njit, njit_inline
from .detection import contact_point1, penetration1
from .friction import bristle1
from .normal import indentation, normal_force1


@njit
def _point_velocity(vo, w, o, point):
    """Velocity of `point` riding on a body whose origin o moves at vo and which turns at w
    (world), as a 3-tuple."""
    r0, r1, r2 = point[0] - o[0], point[1] - o[1], point[2] - o[2]
    return (vo[0] + w[1] * r2 - w[2] * r1, vo[1] + w[2] * r0 - w[0] * r2, vo[2] + w[0] * r1 - w[1] * r0)


@njit_inline
def pair_forces(master, slave, key, C1_J, N1_J, joint1, finger1, axis1_J, C2_J, N2_J, joint2,
                R_W, p_W, w_W, vo_W, opening, opening_rate, mem_key, mem_s, mem_vminus,
                r1, r2, K, damping, floor, h, bristle):
    """Normal (Eq. 11-13) and bristle friction (Eq. 14-17) force of each candidate pair.

    master, slave, key: (k,) candidate pairs, sorted by key. C1_J, N1_J, joint1, finger1,
    axis1_J: the master spheres' centres (fingers at opening 0), normals, joints, fingers and
    opening axes, in their joints' frames; C2_J, N2_J, joint2: the slave spheres'.
    R_W, p_W, w_W, vo_W: (njoints, ...) each joint's rotation, origin, angular velocity and
    origin velocity, world. opening, opening_rate: (n_fingers,) m and m/s. mem_key, mem_s, mem_vminus: the
    memory of the last step's pairs (sorted keys, bristle deflection, onset approach speed).
    r1, r2: radii, m; K: Hertz stiffness; damping: Zhang factor; floor: least onset approach
    speed, m/s; h: step, s; bristle: BristleParams.
    Returns, for the pairs in contact only (sorted by key): master, slave, key, phi (m),
    contact point (m), master and slave centres (m), force on the master (N, world), relative
    speed at the point (m/s), state, and the new memory (deflection, onset approach speed).
    One pass over the pairs, each one's arithmetic in scalars.
    """
    k = master.shape[0]
    # the outputs as rows of three blocks: an allocation costs ~25 ns, a step makes dozens
    ints, scalars, vectors = np.empty((4, k), dtype=np.int64), np.empty((3, k)), np.empty((5, k, 3))
    out_m, out_s, out_key, state_out = ints[0], ints[1], ints[2], ints[3]
    phi_out, speed_out, v_minus_out = scalars[0], scalars[1], scalars[2]
    point_out, c1_out, c2_out, force_out, s_out = vectors[0], vectors[1], vectors[2], vectors[3], vectors[4]
    n_mem = mem_key.shape[0]
    pos = 0  # both key lists are sorted: the memory is merged, not searched
    n = 0
    for i in range(k):
        m, sl = master[i], slave[i]
        j1, j2 = joint1[m], joint2[sl]
        R1, R2 = R_W[j1], R_W[j2]
        shift = opening[finger1[m]]  # the finger has slid along its axis
        c1 = add3(mv3(R1, (C1_J[m, 0] + shift * axis1_J[m, 0], C1_J[m, 1] + shift * axis1_J[m, 1],
                           C1_J[m, 2] + shift * axis1_J[m, 2])), p_W[j1])
        c2 = add3(mv3(R2, C2_J[sl]), p_W[j2])
        n_c, phi, hit = penetration1(c1, mv3(R1, N1_J[m]), r1, c2, mv3(R2, N2_J[sl]), r2)
        if not hit:
            continue
        point = contact_point1(c1, c2, r1, r2, n_c, phi)
        slide = mv3(R1, axis1_J[m])
        rate = opening_rate[finger1[m]]
        v_A = _point_velocity(vo_W[j1], w_W[j1], p_W[j1], point)
        v_B = _point_velocity(vo_W[j2], w_W[j2], p_W[j2], point)
        v_rel = ((slide[0] * rate + v_A[0]) - v_B[0], (slide[1] * rate + v_A[1]) - v_B[1],
                 (slide[2] * rate + v_A[2]) - v_B[2])
        # rate of delta = phi / 2
        delta_dot = -0.5 * (v_rel[0] * n_c[0] + v_rel[1] * n_c[1] + v_rel[2] * n_c[2])
        # a pair in contact at the last step keeps its onset speed and bristle; a new one
        # starts from its approach speed (floored) and an unbent bristle
        while pos < n_mem and mem_key[pos] < key[i]:
            pos += 1
        if pos < n_mem and mem_key[pos] == key[i]:
            v_minus = mem_vminus[pos]
            s_prev = (mem_s[pos, 0], mem_s[pos, 1], mem_s[pos, 2])
        else:
            v_minus = max(delta_dot, floor)
            s_prev = (0.0, 0.0, 0.0)
        F_n = normal_force1(indentation(phi), delta_dot, v_minus, K, damping)
        s, F_f, state = bristle1(s_prev, v_rel, n_c, F_n, h, bristle)
        out_m[n], out_s[n], out_key[n] = m, sl, key[i]
        phi_out[n], v_minus_out[n], state_out[n] = phi, v_minus, state
        for a in range(3):
            point_out[n, a], c1_out[n, a], c2_out[n, a], s_out[n, a] = point[a], c1[a], c2[a], s[a]
            force_out[n, a] = F_n * n_c[a] + F_f[a]  # Eq. (18): f_i = F_n,i + F_f,i
        speed_out[n] = math.sqrt(v_rel[0] ** 2 + v_rel[1] ** 2 + v_rel[2] ** 2)
        n += 1
    return (out_m[:n], out_s[:n], out_key[:n], phi_out[:n], point_out[:n], c1_out[:n], c2_out[:n], force_out[:n],
            speed_out[:n], state_out[:n], s_out[:n], v_minus_out[:n])


@njit_inline
def _add_wrench(F, T, ext_f, ext_t, j, partner, p, sign, f, p_W):
    """Add sign f (3-tuple), acting at p (3-tuple, world), to body j's force F[j] and moment
    T[j] about its origin, and to the external wrench when the partner body is fixed."""
    r0, r1, r2 = p[0] - p_W[j, 0], p[1] - p_W[j, 1], p[2] - p_W[j, 2]
    F[j, 0] += sign * f[0]
    F[j, 1] += sign * f[1]
    F[j, 2] += sign * f[2]
    T[j, 0] += sign * (r1 * f[2] - r2 * f[1])
    T[j, 1] += sign * (r2 * f[0] - r0 * f[2])
    T[j, 2] += sign * (r0 * f[1] - r1 * f[0])
    # what a fixed body exerts on a free one is external; between free bodies internal
    if partner == 0 and j != 0:
        ext_f[0] += sign * f[0]
        ext_f[1] += sign * f[1]
        ext_f[2] += sign * f[2]
        ext_t[0] += sign * (p[1] * f[2] - p[2] * f[1])
        ext_t[1] += sign * (p[2] * f[0] - p[0] * f[2])
        ext_t[2] += sign * (p[0] * f[1] - p[1] * f[0])


@njit_inline
def body_wrenches(master, slave, force, point, c1, c2, common_point, joint1, joint2, finger1,
                  finger_parent, finger_axis_J, R_W, p_W, njoints):
    """One wrench per body (Eq. 18-21): +f_i on the finger's body, -f_i on the module's.

    force: (k, 3) on the masters, world, N; point: (k, 3) contact points; c1, c2: sphere
    centres, where each body's force acts instead when common_point is False (the negative
    control). finger_parent, finger_axis_J: each finger's body joint and opening axis.
    Returns: (njoints, 6) each joint's wrench (force, moment about its origin) in its own
    frame; (njoints, 3) force and (njoints, 3) moment about the world origin, world axes;
    the force and moment (world origin) that fixed bodies (joint 0) exert on free ones; and
    (n_fingers,) each finger's load along its opening axis, N (never negative).
    """
    # F, T (moment about each joint's origin, world axes), T_O and the external wrench as
    # blocks of one array (njoints + 1 rows: at least the external wrench's two): an
    # allocation costs ~25 ns, a step makes dozens
    block = np.zeros((4, njoints + 1, 3))
    F, T, T_O, ext_f, ext_t = block[0][:njoints], block[1][:njoints], block[2][:njoints], block[3][0], block[3][1]
    load = np.zeros(finger_parent.shape[0])
    for i in range(master.shape[0]):
        j1, j2 = joint1[master[i]], joint2[slave[i]]
        f = (force[i, 0], force[i, 1], force[i, 2])
        p1 = (point[i, 0], point[i, 1], point[i, 2]) if common_point else (c1[i, 0], c1[i, 1], c1[i, 2])
        p2 = (point[i, 0], point[i, 1], point[i, 2]) if common_point else (c2[i, 0], c2[i, 1], c2[i, 2])
        _add_wrench(F, T, ext_f, ext_t, j1, j2, p1, 1.0, f, p_W)
        _add_wrench(F, T, ext_f, ext_t, j2, j1, p2, -1.0, f, p_W)
        fg = finger1[master[i]]
        j = finger_parent[fg]
        for a in range(3):
            load[fg] += f[a] * (R_W[j, a, 0] * finger_axis_J[fg, 0] + R_W[j, a, 1] * finger_axis_J[fg, 1]
                                + R_W[j, a, 2] * finger_axis_J[fg, 2])
    local = np.empty((njoints, 6))
    for j in range(njoints):
        R, p = R_W[j], p_W[j]
        for a in range(3):
            local[j, a] = R[0, a] * F[j, 0] + R[1, a] * F[j, 1] + R[2, a] * F[j, 2]
            local[j, 3 + a] = R[0, a] * T[j, 0] + R[1, a] * T[j, 1] + R[2, a] * T[j, 2]
        T_O[j, 0] = T[j, 0] + p[1] * F[j, 2] - p[2] * F[j, 1]
        T_O[j, 1] = T[j, 1] + p[2] * F[j, 0] - p[0] * F[j, 2]
        T_O[j, 2] = T[j, 2] + p[0] * F[j, 1] - p[1] * F[j, 0]
    for k in range(load.shape[0]):
        load[k] = max(load[k], 0.0)
    return local, F, T_O, ext_f, ext_t, load


@njit_inline
def contact_summary(F, T_O, R_W, p_W, ee_joint, R_ee, module_joint, lever, speed, phi):
    """What the run watches each step, as an (8,) array: the combined contact force on the
    active module and its moment about the module's centroid, both in the grasp frame O_a
    (N, N m), the fastest relative speed at a contact (m/s) and the deepest penetration (m).

    F, T_O: (njoints, 3) each body's contact force and moment about the world origin. ee_joint,
    R_ee: the end-effector's joint and its grasp frame's rotation in that joint's frame.
    module_joint, lever: the module's joint and its centroid in that joint's frame.
    speed, phi: (k,) the pairs' relative speeds and penetrations.
    """
    out = np.zeros(8)
    A, B = R_W[ee_joint], R_ee
    r_G = add3(mv3(R_W[module_joint], lever), p_W[module_joint])
    f, T = F[module_joint], T_O[module_joint]
    tau = (T[0] - (r_G[1] * f[2] - r_G[2] * f[1]), T[1] - (r_G[2] * f[0] - r_G[0] * f[2]),
           T[2] - (r_G[0] * f[1] - r_G[1] * f[0]))
    for a in range(3):
        # column a of R = A B, the grasp frame's axes in world
        R0 = A[0, 0] * B[0, a] + A[0, 1] * B[1, a] + A[0, 2] * B[2, a]
        R1 = A[1, 0] * B[0, a] + A[1, 1] * B[1, a] + A[1, 2] * B[2, a]
        R2 = A[2, 0] * B[0, a] + A[2, 1] * B[1, a] + A[2, 2] * B[2, a]
        out[a] = R0 * f[0] + R1 * f[1] + R2 * f[2]
        out[3 + a] = R0 * tau[0] + R1 * tau[1] + R2 * tau[2]
    if speed.shape[0]:
        out[6], out[7] = speed.max(), phi.max()
    return out


@njit_inline
def raise_peaks(force, torque, norms, summary):
    """Raise the per-axis peaks |force|, |torque| (3,) and the peak norms (2,) in place to
    include one step's `contact_summary`."""
    for a in range(3):
        force[a] = max(force[a], abs(summary[a]))
        torque[a] = max(torque[a], abs(summary[3 + a]))
    norms[0] = max(norms[0], math.sqrt(summary[0] ** 2 + summary[1] ** 2 + summary[2] ** 2))
    norms[1] = max(norms[1], math.sqrt(summary[3] ** 2 + summary[4] ** 2 + summary[5] ** 2))
