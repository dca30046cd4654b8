"""Stage: the force of each sphere pair in contact (paper Eq. 6-17), with per-pair memory.

`pair_forces` chains the contact law's kernels (detection, normal force, bristle friction) over
the candidate pairs of one evaluation; each pair's bristle deflection and onset approach speed
carry over from the last committed evaluation (`Data.memory`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..jit import njit, njit_inline
from ..linalg import add3, mv3
from .detection import contact_point, force_direction, penetration
from .friction import BristleParams, bristle
from .normal import indentation, normal_law, onset_rate


class ContactLaw(NamedTuple):
    """The contact law's constants (paper Tables 1-2 and model.md Sec. 2-4)."""

    r1: float  # master (finger) sphere radius, m
    r2: float  # slave (groove) sphere radius, m
    K: float  # Hertz stiffness, Eq. (13), N/m^1.5
    damping: float  # Zhang factor of Eq. (12), 6 (1 - c_r) / ((2 c_r - 1)^2 + 3)
    floor: float  # least delta_dot_minus, the onset rate of delta = phi / 2 (half an approach speed), m/s
    cutoff: float  # largest centre distance of a pair in contact the run allows, m
    bristle: BristleParams
    common_point: bool  # a pair's force acts at one common point (Eq. 19-21), else at each sphere's centre
    gradient: bool  # normal force along d / (d . n_c) (the gradient of the Hertz potential), else along n_c (Eq. 11)


class Contacts(NamedTuple):
    """The sphere pairs in contact at one force evaluation, sorted by key, one row each."""

    master: np.ndarray  # (k,) master sphere
    slave: np.ndarray  # (k,) slave sphere
    key: np.ndarray  # (k,) master * |S2| + slave
    phi: np.ndarray  # (k,) penetration along the common normal, m
    point_W: np.ndarray  # (k, 3) contact point, world, m
    c1_W: np.ndarray  # (k, 3) master and slave sphere centres, world, m
    c2_W: np.ndarray
    force_W: np.ndarray  # (k, 3) force on the master (finger), world, N; the slave gets the opposite
    speed: np.ndarray  # (k,) |relative velocity| at the contact point, m/s
    state: np.ndarray  # (k,) friction.SLIPPING or friction.STICKING
    s: np.ndarray  # (k, 3) bristle deflection after the evaluation, m
    v_minus: np.ndarray  # (k,) onset indentation rate delta_dot_minus, m/s
    slack: np.ndarray  # (k,) the bristle's slack (`friction.bristle`): it holds while positive, m
    # the pair's linearisation, for a drive that reads how its load grows as it pushes on: the
    # normal force F_n g grows by normal_stiffness (N/m) and normal_damping (N s/m) per unit
    # of the master's advance and speed along g; a holding bristle by tangent_stiffness and
    # tangent_damping in the tangent plane of n_c (k_b, and c_b over the share of the step it
    # held; zero for a saturated one, which held none of it)
    direction_W: np.ndarray  # (k, 3) g, the normal force's direction (`detection.force_direction`)
    normal_W: np.ndarray  # (k, 3) n_c, the common normal
    normal_stiffness: np.ndarray  # (k,)
    normal_damping: np.ndarray  # (k,)
    tangent_stiffness: np.ndarray  # (k,)
    tangent_damping: np.ndarray  # (k,)


class Memory(NamedTuple):
    """What each pair carries from one committed evaluation to the next, sorted by key."""

    key: np.ndarray  # (k,)
    s: np.ndarray  # (k, 3) bristle deflection, m
    v_minus: np.ndarray  # (k,) onset indentation rate delta_dot_minus, m/s
    slack: np.ndarray  # (k,) the bristle's slack, m


def no_contacts() -> Contacts:
    ints, vec = lambda: np.zeros(0, dtype=np.int64), lambda: np.zeros((0, 3))
    return Contacts(master=ints(), slave=ints(), key=ints(), phi=np.zeros(0), point_W=vec(), c1_W=vec(), c2_W=vec(),
                    force_W=vec(), speed=np.zeros(0), state=ints(), s=vec(), v_minus=np.zeros(0), slack=np.zeros(0),
                    direction_W=vec(), normal_W=vec(), normal_stiffness=np.zeros(0), normal_damping=np.zeros(0),
                    tangent_stiffness=np.zeros(0), tangent_damping=np.zeros(0))


def no_memory() -> Memory:
    return Memory(np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros(0), np.zeros(0))


@njit_inline
def commit_memory(d):
    """The contacts of the last evaluation become the pairs' memory."""
    c = d.contacts
    d.memory = Memory(c.key, c.s, c.v_minus, c.slack)


@njit
def point_velocity(vo, w, o, point):
    """Velocity of `point` riding on a body whose origin o moves at vo and which turns at w
    (world), as a 3-tuple."""
    r0, r1, r2 = point[0] - o[0], point[1] - o[1], point[2] - o[2]
    return (vo[0] + w[1] * r2 - w[2] * r1, vo[1] + w[2] * r0 - w[0] * r2, vo[2] + w[0] * r1 - w[1] * r0)


@njit
def pair_forces(m, d, h, jump):
    """Stage: d.contacts, the normal (Eq. 11-13) and bristle friction (Eq. 14-17) force of each
    candidate pair in contact, at d's kinematics, its bristles bent over h (s) from d.memory;
    `jump`: the finger rates changed since the memory's evaluation, and h is the step to come
    (`friction.bristle`). Returns how many saturated pairs held a share of the step (none
    without a jump).

    One pass over the candidates, each pair's arithmetic in scalars. A pair in the memory
    keeps its onset indentation rate and bristle; a new one starts from its indentation rate
    (floored) and an unbent bristle. The normal force acts along `force_direction` (n_c in
    the paper's law); friction's tangent plane is always that of n_c. The memory is left as
    it is (`commit_memory`).
    """
    k = d.candidates.master.shape[0]
    # the outputs as rows of three blocks: an allocation costs ~25 ns, a step makes dozens
    ints, scalars, vectors = np.empty((4, k), dtype=np.int64), np.empty((8, k)), np.empty((7, k, 3))
    out_m, out_s, out_key, state_out = ints[0], ints[1], ints[2], ints[3]
    phi_out, speed_out, v_minus_out, slack_out = scalars[0], scalars[1], scalars[2], scalars[3]
    k_n_out, c_n_out, k_t_out, c_t_out = scalars[4], scalars[5], scalars[6], scalars[7]
    point_out, c1_out, c2_out, force_out, s_out = vectors[0], vectors[1], vectors[2], vectors[3], vectors[4]
    g_out, n_out = vectors[5], vectors[6]
    r1, r2 = m.law.r1, m.law.r2
    n_mem = d.memory.key.shape[0]
    pos = 0  # both key lists are sorted: the memory is merged, not searched
    n = shared = 0
    # fields are read where they are used: numba then takes no reference to them (a local
    # holding an array costs two atomic reference counts a call)
    for i in range(k):
        mi, sl = d.candidates.master[i], d.candidates.slave[i]
        j1, j2 = m.master.joint[mi], m.slave.joint[sl]
        c1 = add3(mv3(d.R_W[j1], m.master.centre_J[mi]), d.p_W[j1])
        c2 = add3(mv3(d.R_W[j2], m.slave.centre_J[sl]), d.p_W[j2])
        n_c, phi, hit, side = penetration(c1, mv3(d.R_W[j1], m.master.normal_J[mi]), r1, c2,
                                          mv3(d.R_W[j2], m.slave.normal_J[sl]), r2)
        if not hit:
            continue
        point = contact_point(c1, c2, r1, r2, n_c, phi)
        v_A = point_velocity(d.vo_W[j1], d.w_W[j1], d.p_W[j1], point)
        v_B = point_velocity(d.vo_W[j2], d.w_W[j2], d.p_W[j2], point)
        v_rel = (v_A[0] - v_B[0], v_A[1] - v_B[1], v_A[2] - v_B[2])
        v_n = v_rel  # the rate the normal damping reads
        if d.lead > 0.0:  # ... level with the positions, whose kinematics d.now holds (`integrators.end_forces`)
            u_A = point_velocity(d.now.vo_W[j1], d.now.w_W[j1], d.now.p_W[j1], point)
            u_B = point_velocity(d.now.vo_W[j2], d.now.w_W[j2], d.now.p_W[j2], point)
            v_n = (u_A[0] - u_B[0], u_A[1] - u_B[1], u_A[2] - u_B[2])
        g = force_direction(c1, c2, n_c, phi, m.law.gradient, side)
        # rate of delta = phi / 2, which is linear: the indentation of phi's rate -(v . g)
        delta_dot = indentation(-(v_n[0] * g[0] + v_n[1] * g[1] + v_n[2] * g[2]))
        key = d.candidates.key[i]
        while pos < n_mem and d.memory.key[pos] < key:
            pos += 1
        if pos < n_mem and d.memory.key[pos] == key:
            v_minus = d.memory.v_minus[pos]
            s_prev = (d.memory.s[pos, 0], d.memory.s[pos, 1], d.memory.s[pos, 2])
        else:
            v_minus = onset_rate(delta_dot, m.law.floor)
            s_prev = (0.0, 0.0, 0.0)
        F_n, dF_ddelta, dF_drate = normal_law(indentation(phi), delta_dot, v_minus, m.law.K, m.law.damping)
        s, F_f, state, slack, held = bristle(s_prev, v_rel, n_c, F_n, h, m.law.bristle, jump)
        out_m[n], out_s[n], out_key[n] = mi, sl, key
        phi_out[n], v_minus_out[n], state_out[n], slack_out[n] = phi, v_minus, state, slack
        for a in range(3):
            point_out[n, a], c1_out[n, a], c2_out[n, a], s_out[n, a] = point[a], c1[a], c2[a], s[a]
            force_out[n, a] = F_n * g[a] + F_f[a]  # Eq. (18): f_i = F_n,i + F_f,i
            g_out[n, a], n_out[n, a] = g[a], n_c[a]
        speed_out[n] = math.sqrt(v_rel[0] ** 2 + v_rel[1] ** 2 + v_rel[2] ** 2)
        # advancing by dx along g indents the pair by dx / 2 (delta = phi / 2)
        k_n_out[n], c_n_out[n] = 0.5 * dF_ddelta, 0.5 * dF_drate
        k_t_out[n] = m.law.bristle.k_b if held > 0.0 and slack > 0.0 else 0.0
        c_t_out[n] = held * m.law.bristle.c_b
        if held > 0.0 and slack <= 0.0:
            shared += 1
        n += 1
    d.contacts = Contacts(master=out_m[:n], slave=out_s[:n], key=out_key[:n], phi=phi_out[:n], point_W=point_out[:n],
                          c1_W=c1_out[:n], c2_W=c2_out[:n], force_W=force_out[:n], speed=speed_out[:n],
                          state=state_out[:n], s=s_out[:n], v_minus=v_minus_out[:n], slack=slack_out[:n],
                          direction_W=g_out[:n], normal_W=n_out[:n], normal_stiffness=k_n_out[:n],
                          normal_damping=c_n_out[:n], tangent_stiffness=k_t_out[:n], tangent_damping=c_t_out[:n])
    return shared
