"""What a run records at the end of each record interval, compiled.

`close_interval` is the run loop's work between two record intervals: the divergence checks
(a non-finite state, energy growth in a passive phase), one row of the time series
(`sample`) and the momentum balance. The compiled loop (`compiled.intervals`) calls it after
each interval it runs, the step-by-step path of `run.simulate` after each of its own, so the
two record the same rows.

A row is one float vector laid out by `Layout`; `run.Recorder` stacks the rows and splits
them into the named time series at the end. Frames are computed from q directly: every body
is free (a free-flyer child of the world) or fixed, so a frame is a body's pose times a
constant placement.
"""

from __future__ import annotations

import math

import numpy as np

from .bodies import (add3, bodies_centroid3, bodies_momentum, body_origin3, body_rotation_into, kinetic_energy,
                     mm_into, mtv3, mv3, sub3)
from .contact.friction import SLIPPING, STICKING
from .jit import njit, njit_inline
from .stability import ENERGY_FLOOR_J, ENERGY_GROWTH, mechanical_energy

#: What `close_interval` found: nothing wrong, a non-finite state (no row written), energy
#: growth in a passive phase, or more energy than the drives could have put in (the row
#: written for both).
OK, NONFINITE, ENERGY, ENERGY_WORK = range(4)

# slots of the record state `rs` (float array), kept between intervals and across welds:
# the energy when the passive phase began and at the last record, the largest single-body
# momenta, the momentum drifts, the momentum at the start, the energy at the start and the
# work the finger drives have done since, J
E_PASSIVE, E_NOW, P_MAX, L_MAX, DRIFT_LIN, DRIFT_ANG, P0, L0, E_START, DRIVE_WORK = 0, 1, 2, 3, 4, 5, 6, 9, 12, 13
N_RECORD_STATE = 14

#: Time series recorded as integers (the others are floats).
INTEGER_SERIES = ("pairs_slipping", "pairs_sticking", "phase", "grasp")


class Layout:
    """The time series of a run and their columns in a row, fixed by its first model.

    columns: {name: (first column, width)}; a width-1 series is a 1-D array, the others
    (n, width).
    """

    def __init__(self, model):
        n_f = len(model.fingers)
        spec = [("t", 1), ("module_pos_m", 3), ("module_quat_xyzw", 4), ("offset_mm", 3), ("rpy_deg", 3),
                ("module_vel_m_s", 3), ("module_omega_rad_s", 3), ("force_N", 3), ("torque_Nm", 3),
                ("finger_opening_mm", n_f), ("finger_load_N", n_f), ("pairs_slipping", 1),
                ("pairs_sticking", 1), ("phase", 1), ("grasp", 1), ("max_penetration_um", 1)]
        self.free_robot = bool(model.robot_joint)
        if self.free_robot:
            spec += [("robot_centroid_m", 3), ("base_pos_m", 3), ("base_quat_xyzw", 4), ("system_centroid_m", 3)]
            for mod in model.modules:
                spec += [(f"{mod.name}_pos_m", 3), (f"{mod.name}_quat_xyzw", 4)]
            spec += [(f"{e.name}_pos_m", 3) for e in model.end_effectors]
        self.columns, start = {}, 0
        for name, width in spec:
            self.columns[name] = (start, width)
            start += width
        self.width = start
        self.fingers = [f.name for f in model.fingers]

    def split(self, rows: np.ndarray) -> dict[str, np.ndarray]:
        """The named series of stacked rows (n, width)."""
        out = {}
        for name, (start, width) in self.columns.items():
            x = rows[:, start] if width == 1 else rows[:, start:start + width]
            out[name] = x.astype(np.int64) if name in INTEGER_SERIES else x.copy()
        return out


def record_args(model, layout: Layout) -> tuple:
    """The model's constant arguments of `sample` and `close_interval`, in their order.

    Frames (rows of frame_row, frame_R, frame_p): each module's groove frame, then each
    end-effector's grasp frame, then the robot's base (its joint frame); frame_row is the row
    in `model.bodies` of the body each rides on, -1 for a fixed one.
    """
    row_of = lambda j: model.body_row[j] if j else -1
    frames = [(row_of(j), M) for j, M in model.groove_placements]
    frames += [(row_of(e.joint), e.placement) for e in model.end_effectors]
    frames.append((row_of(model.robot_joint), None))
    frame_row = np.array([r for r, _ in frames], dtype=np.int64)
    frame_R = np.array([np.eye(3) if M is None else M.rotation for _, M in frames]).reshape(-1, 3, 3)
    frame_p = np.array([np.zeros(3) if M is None else M.translation for _, M in frames]).reshape(-1, 3)
    module_row = np.array([row_of(m.joint) for m in model.modules], dtype=np.int64)
    # each finger of this model among the first model's (a weld may leave some out)
    finger_map = np.array([layout.fingers.index(f.name) for f in model.fingers], dtype=np.int64)
    rows = lambda joints: np.array([model.body_row[j] for j in joints], dtype=np.int64)
    robot_rows = rows([model.robot_joint] if model.robot_joint else [])
    p = model.params
    # the drives' work bounds the energy only without gravity (which does work of its own)
    no_gravity = not np.any(model.pin_model.gravity.linear)
    return (model.bodies, frame_row, frame_R, frame_p, module_row, finger_map, model.all_bodies, robot_rows,
            rows(model.free_joints), layout.free_robot, p.K, p.bristle.k_b, no_gravity)


@njit
def quat_xyzw(R, q):
    """The unit quaternion (x, y, z, w) of a rotation matrix, as Eigen's Quaternion(R)
    computes it (Shepperd's method: the largest of w, x, y, z first), written into q (4,)."""
    trace = R[0, 0] + R[1, 1] + R[2, 2]
    if trace > 0.0:
        t = math.sqrt(trace + 1.0)
        q[3] = 0.5 * t
        t = 0.5 / t
        q[0] = (R[2, 1] - R[1, 2]) * t
        q[1] = (R[0, 2] - R[2, 0]) * t
        q[2] = (R[1, 0] - R[0, 1]) * t
        return
    i = 0
    if R[1, 1] > R[0, 0]:
        i = 1
    if R[2, 2] > R[i, i]:
        i = 2
    j, k = (i + 1) % 3, (i + 2) % 3
    t = math.sqrt(R[i, i] - R[j, j] - R[k, k] + 1.0)
    q[i] = 0.5 * t
    t = 0.5 / t
    q[3] = (R[k, j] - R[j, k]) * t
    q[j] = (R[j, i] + R[i, j]) * t
    q[k] = (R[k, i] + R[i, k]) * t


@njit
def rpy(R):
    """Roll, pitch, yaw (rad) of R = Rz(yaw) Ry(pitch) Rx(roll), pitch in [-pi/2, pi/2]: the
    angles `pinocchio.rpy.matrixToRpy` returns, away from pitch = +-pi/2."""
    return (math.atan2(R[2, 1], R[2, 2]), math.atan2(-R[2, 0], math.sqrt(R[2, 1] ** 2 + R[2, 2] ** 2)),
            math.atan2(R[1, 0], R[0, 0]))


@njit_inline
def _frame(bodies, q, frame_row, frame_R, frame_p, i, R, work):
    """Frame i in the world: its rotation, written into R (3, 3), and its origin (3-tuple).
    work: (3, 3) scratch."""
    b = frame_row[i]
    if b < 0:
        R[:] = frame_R[i]
        return frame_p[i, 0], frame_p[i, 1], frame_p[i, 2]
    body_rotation_into(bodies, b, q, work)
    mm_into(work, frame_R[i], R)
    return add3(body_origin3(bodies, b, q), mv3(work, frame_p[i]))


@njit_inline
def _put_pose(row, at, p, R):
    """Write origin p (3,) and the quaternion of R (x, y, z, w) at row[at:]; returns the next
    free column."""
    at = _put(row, at, p)
    quat_xyzw(R, row[at:at + 4])
    return at + 4


@njit
def _put(row, at, x, scale=1.0):
    for i in range(len(x)):
        row[at + i] = scale * x[i]
    return at + len(x)


@njit_inline
def sample(row, t, q, v, summary, n_pairs, state, opening, finger_load, last_open, phase, grasp, ee, k, args):
    """Write one row of the time series (`Layout`): the active grasp's module (end-effector
    `ee`, module `k`), its offset in the grasp frame, the last step's contact wrench and pairs,
    the fingers, and for a free-flying robot its centroids and frames.

    summary, n_pairs, state: the last step's `contact_summary`, pair count and pair states;
    last_open: each first-model finger's last opening, m, updated in place.
    """
    bodies, frame_row, frame_R, frame_p, module_row, finger_map, _, robot_rows, system_rows, free_robot = args[:10]
    n_mod = module_row.shape[0]
    n_ee = frame_row.shape[0] - n_mod - 1
    R = np.empty((4, 3, 3))  # scratch: an allocation costs ~25 ns, a row needs a dozen rotations
    R_b, R_a, R_ab, work = R[0], R[1], R[2], R[3]
    p_b = _frame(bodies, q, frame_row, frame_R, frame_p, k, R_b, work)
    p_a = _frame(bodies, q, frame_row, frame_R, frame_p, n_mod + ee, R_a, work)
    row[0] = t
    at = 1
    at = _put_pose(row, at, p_b, R_b)
    at = _put(row, at, mtv3(R_a, sub3(p_b, p_a)), 1e3)  # O_b in O_a
    for i in range(3):  # R_a^T R_b
        for j in range(3):
            R_ab[i, j] = R_a[0, i] * R_b[0, j] + R_a[1, i] * R_b[1, j] + R_a[2, i] * R_b[2, j]
    at = _put(row, at, rpy(R_ab), 180.0 / math.pi)
    # the module's velocity and angular velocity, world
    b = module_row[k]
    if b >= 0:
        iv = bodies.idx_v[b]
        body_rotation_into(bodies, b, q, work)
        at = _put(row, at, mv3(work, v[iv:iv + 3]))
        at = _put(row, at, mv3(work, v[iv + 3:iv + 6]))
    else:
        row[at:at + 6] = 0.0
        at += 6
    # on the module, in O_a: force, and moment about its centroid
    for i in range(6):
        row[at + i] = summary[i] if n_pairs else 0.0
    at += 6
    for i in range(finger_map.shape[0]):
        last_open[finger_map[i]] = opening[i]
    at = _put(row, at, last_open, 1e3)
    row[at:at + last_open.shape[0]] = 0.0  # the loads of fingers a weld left out
    for i in range(finger_map.shape[0]):
        row[at + finger_map[i]] = finger_load[i]
    at += last_open.shape[0]
    n_slip = n_stick = 0
    for i in range(n_pairs):
        n_slip += state[i] == SLIPPING
        n_stick += state[i] == STICKING
    at = _put(row, at, (float(n_slip), float(n_stick), float(phase), float(grasp),
                        summary[7] * 1e6 if n_pairs else 0.0))
    if free_robot:
        at = _put(row, at, bodies_centroid3(bodies, robot_rows, q))
        p = _frame(bodies, q, frame_row, frame_R, frame_p, frame_row.shape[0] - 1, R_b, work)
        at = _put_pose(row, at, p, R_b)
        at = _put(row, at, bodies_centroid3(bodies, system_rows, q))
        for i in range(n_mod):
            p = _frame(bodies, q, frame_row, frame_R, frame_p, i, R_b, work)
            at = _put_pose(row, at, p, R_b)
        for i in range(n_ee):
            p = _frame(bodies, q, frame_row, frame_R, frame_p, n_mod + i, R_b, work)
            at = _put(row, at, p)


@njit
def start_record(rs, q, v, args):
    """The record state at the start of a run: momentum and the largest body momenta."""
    bodies, all_rows = args[0], args[6]
    P, L, p_max, l_max, _ = bodies_momentum(bodies, all_rows, q, v)
    rs[:] = 0.0
    rs[E_PASSIVE] = np.nan
    rs[P_MAX], rs[L_MAX] = p_max, l_max
    rs[P0:P0 + 3] = P
    rs[L0:L0 + 3] = L
    rs[E_START] = kinetic_energy(bodies, q, v)  # no pair in contact at the start


@njit_inline
def drive_power(finger_load, opening_rate):
    """A bound on the power the finger drives put into the bodies during a step, W: each
    finger's load along its axis (N, never negative) times its sliding speed (m/s)."""
    power = 0.0
    for i in range(finger_load.shape[0]):
        power += finger_load[i] * abs(opening_rate[i])
    return power


@njit_inline
def close_interval(row, rs, J, JL, held, t, q, v, phi, mem_s, summary, n_pairs, state, opening, finger_load,
                   last_open, phase, grasp, ee, k, args):
    """The run loop's work at the end of a record interval: returns OK, NONFINITE, ENERGY or
    ENERGY_WORK.

    A NaN or an infinity anywhere in (q, v) is NONFINITE, and nothing is recorded. When the
    drive held the fingers through the whole interval (held: a passive phase), the mechanical
    energy may not grow past ENERGY_GROWTH times its value when the phase began plus
    ENERGY_FLOOR_J (rs[E_PASSIVE], rs[E_NOW]): else ENERGY. In any phase it may not grow past
    ENERGY_GROWTH times its value at the start plus the work the finger drives have done
    (rs[E_START] + rs[DRIVE_WORK]), plus ENERGY_FLOOR_J: the drives are the only source of
    energy in zero gravity, so more is the integrator's (ENERGY_WORK). Both keep the row. Then the row
    (`sample`) and the momentum balance: the largest drift of the free bodies' momentum from
    its start less the external impulse J, JL (rs[DRIFT_LIN], rs[DRIFT_ANG]), and the largest
    single-body momenta (rs[P_MAX], rs[L_MAX]).
    """
    if not math.isfinite(np.sum(q) + np.sum(v)):
        return NONFINITE
    code = OK
    E = mechanical_energy(args[0], q, v, phi, mem_s, args[10], args[11])
    rs[E_NOW] = E
    if held:
        if math.isnan(rs[E_PASSIVE]):
            rs[E_PASSIVE] = E
        elif E > ENERGY_GROWTH * rs[E_PASSIVE] + ENERGY_FLOOR_J:
            code = ENERGY
    else:
        rs[E_PASSIVE] = np.nan
    if code == OK and args[12] and E > ENERGY_GROWTH * (rs[E_START] + rs[DRIVE_WORK]) + ENERGY_FLOOR_J:
        code = ENERGY_WORK
    sample(row, t, q, v, summary, n_pairs, state, opening, finger_load, last_open, phase, grasp, ee, k, args)
    P, L, p_b, l_b, _ = bodies_momentum(args[0], args[6], q, v)
    rs[P_MAX], rs[L_MAX] = max(rs[P_MAX], p_b), max(rs[L_MAX], l_b)
    dP = (P[0] - rs[P0] - J[0], P[1] - rs[P0 + 1] - J[1], P[2] - rs[P0 + 2] - J[2])
    dL = (L[0] - rs[L0] - JL[0], L[1] - rs[L0 + 1] - JL[1], L[2] - rs[L0 + 2] - JL[2])
    rs[DRIFT_LIN] = max(rs[DRIFT_LIN], math.sqrt(dP[0] ** 2 + dP[1] ** 2 + dP[2] ** 2))
    rs[DRIFT_ANG] = max(rs[DRIFT_ANG], math.sqrt(dL[0] ** 2 + dL[1] ** 2 + dL[2] ** 2))
    return code
