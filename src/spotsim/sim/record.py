"""What a run records at the end of each record interval, compiled.

`close_interval` is the loop's work between two record intervals: the divergence checks (a
non-finite state, energy growth), one row of the time series (`sample`), the momentum balance,
and the replay's contact snapshot when one is due. A row is one float vector laid out by
`Layout`; the run stacks the rows and splits them into named time series at the end. Frames
are those of the state as it is (`tree.current_frames`, into d.now): a frame is its joint's
pose times a constant placement.
"""

from __future__ import annotations

import math

import numpy as np

from ..contact.friction import SLIPPING, STICKING
from ..contact.search import grow
from ..jit import njit, njit_inline
from ..linalg import add3, dot3, mm_into, mtv3, mv3, sub3
from .actuation import current_speed
from .data import Snapshots
from .events import ENERGY, ENERGY_WORK, NONFINITE, RAN
from .stability import ENERGY_FLOOR_J, ENERGY_GROWTH, mechanical_energy
from .tree import centroid3, current_frames, gravity_energy, momenta, passive_force

#: Contact snapshots per simulated second kept for `spotsim replay`: its highest display rate.
#: 100 Hz is ten samples of a 10 ms bounce.
REPLAY_RATE_HZ = 100.0
#: Time series recorded as integers (the others are floats).
INTEGER_SERIES = ("pairs_slipping", "pairs_sticking", "phase", "grasp")


class Layout:
    """The time series of a run and their columns in a row, fixed by its unwelded scene.

    fingers: the scene's finger names; free_robot: the robot floats; modules, end_effectors:
    their names; arm_joints: the compliant arms' joints (none: rigid arms), whose angles
    `arm_joint_angles_rad` records. columns: {name: (first column, width)}; a width-1 series is
    a 1-D array, the others (n, width).
    """

    def __init__(self, fingers: list[str], free_robot: bool, modules: list[str], end_effectors: list[str],
                 arm_joints: tuple[str, ...] = (), dynamometer: bool = False):
        n_f = len(fingers)
        spec = [("t", 1), ("module_pos_m", 3), ("module_quat_xyzw", 4), ("offset_mm", 3), ("rpy_deg", 3),
                ("module_vel_m_s", 3), ("module_omega_rad_s", 3), ("force_N", 3), ("torque_Nm", 3),
                ("finger_opening_mm", n_f), ("finger_load_N", n_f), ("pairs_slipping", 1),
                ("pairs_sticking", 1), ("phase", 1), ("grasp", 1), ("max_penetration_um", 1),
                ("energy_J", 1), ("drive_work_J", 1), ("drive_speed_mm_s", 1)]
        self.free_robot = free_robot
        if free_robot:
            spec += [("robot_centroid_m", 3), ("base_pos_m", 3), ("base_quat_xyzw", 4), ("system_centroid_m", 3)]
            for name in modules:
                spec += [(f"{name}_pos_m", 3), (f"{name}_quat_xyzw", 4)]
            spec += [(f"{name}_pos_m", 3) for name in end_effectors]
        if arm_joints:
            spec.append(("arm_joint_angles_rad", len(arm_joints)))
        if dynamometer:
            spec += [("dynamometer_force_N", 3), ("dynamometer_moment_Nm", 3)]
        self.columns, start = {}, 0
        for name, width in spec:
            self.columns[name] = (start, width)
            start += width
        self.width = start
        self.fingers = list(fingers)
        self.arm_joints = tuple(arm_joints)
        self.dynamometer = dynamometer

    def split(self, rows: np.ndarray) -> dict[str, np.ndarray]:
        """The named series of stacked rows (n, width)."""
        out = {}
        for name, (start, width) in self.columns.items():
            x = rows[:, start] if width == 1 else rows[:, start:start + width]
            out[name] = x.astype(np.int64) if name in INTEGER_SERIES else x.copy()
        return out


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
def _frame(m, d, i, R):
    """Frame i of m.record in the world at d's state (the kinematics d.now): its rotation,
    written into R (3, 3), and its origin (3-tuple)."""
    j = m.record.joint[i]
    mm_into(d.now.R_W[j], m.record.R[i], R)
    return add3((d.now.p_W[j, 0], d.now.p_W[j, 1], d.now.p_W[j, 2]), mv3(d.now.R_W[j], m.record.p[i]))


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


@njit
def sample(m, d, row):
    """Write one row of the time series (`Layout`) into row, from the state's kinematics
    (made here, into d.now): the active grasp's module, its offset in the grasp frame, the
    last step's contact wrench and pairs, the fingers, for a free-flying robot its centroids
    and frames, the compliant arms' joint angles and the dynamometer's load."""
    current_frames(m, d)
    g = d.active
    ee, k = m.grasps.ee[g], m.grasps.module[g]
    n_pairs = d.contacts.key.shape[0]
    n_mod = m.record.module_joint.shape[0]
    n_ee = m.record.joint.shape[0] - n_mod - 1
    R = np.empty((3, 3, 3))  # scratch: an allocation costs ~25 ns, a row needs a dozen rotations
    R_b, R_a, R_ab = R[0], R[1], R[2]
    p_b = _frame(m, d, k, R_b)
    p_a = _frame(m, d, n_mod + ee, R_a)
    row[0] = d.t
    at = 1
    at = _put_pose(row, at, p_b, R_b)
    at = _put(row, at, mtv3(R_a, sub3(p_b, p_a)), 1e3)  # O_b in O_a
    for i in range(3):  # R_a^T R_b
        for j in range(3):
            R_ab[i, j] = R_a[0, i] * R_b[0, j] + R_a[1, i] * R_b[1, j] + R_a[2, i] * R_b[2, j]
    at = _put(row, at, rpy(R_ab), 180.0 / math.pi)
    # the module's velocity (its joint origin's) and angular velocity, world
    j = m.record.module_joint[k]
    if j > 0:
        at = _put(row, at, d.now.vo_W[j])
        at = _put(row, at, d.now.w_W[j])
    else:
        row[at:at + 6] = 0.0
        at += 6
    # on the module, in O_a: force, and moment about its centroid
    for i in range(3):
        row[at + i] = d.summary.force_A[i] if n_pairs else 0.0
        row[at + 3 + i] = d.summary.torque_A[i] if n_pairs else 0.0
    at += 6
    n_f = m.record.finger_q.shape[0]
    for i in range(n_f):
        iq = m.record.finger_q[i]
        row[at + i] = 1e3 * (d.q[iq] if iq >= 0 else m.record.locked_opening[i])
    at += n_f
    for i in range(n_f):
        a = m.record.finger_actuator[i]
        row[at + i] = d.load[a] if a >= 0 else 0.0  # a finger a weld locked takes no load
    at += n_f
    n_slip = n_stick = 0
    for i in range(n_pairs):
        n_slip += d.contacts.state[i] == SLIPPING
        n_stick += d.contacts.state[i] == STICKING
    at = _put(row, at, (float(n_slip), float(n_stick), float(d.phase[g]), float(g),
                        d.summary.max_penetration * 1e6 if n_pairs else 0.0, d.energy_now, d.drive_work,
                        current_speed(m, d) * 1e3))
    if m.record.free_robot:
        at = _put(row, at, centroid3(m, d.now, m.record.robot_branches))
        p = _frame(m, d, m.record.joint.shape[0] - 1, R_b)
        at = _put_pose(row, at, p, R_b)
        at = _put(row, at, centroid3(m, d.now, m.record.system_branches))
        for i in range(n_mod):
            p = _frame(m, d, i, R_b)
            at = _put_pose(row, at, p, R_b)
        for i in range(n_ee):
            p = _frame(m, d, n_mod + i, R_b)
            at = _put(row, at, p)
    for i in range(m.record.arm_q.shape[0]):  # the link's angle: the motor side's and the gearbox's
        im = m.record.arm_motor_q[i]
        row[at + i] = d.q[m.record.arm_q[i]] + (d.q[im] if im >= 0 else 0.0)
    at += m.record.arm_q.shape[0]
    for i in range(m.record.mount_q.shape[0]):
        # what the arm and the top plate put on the sensors since the start (its joints start
        # at zero, at rest): the springs' and dampers' pull on the top then, less now
        iv = m.record.mount_v[i]
        row[at + i] = passive_force(m.tree, iv, 0.0, 0.0) - passive_force(m.tree, iv, d.q[m.record.mount_q[i]], d.v[iv])


@njit
def _snapshot(m, d):
    """Add the replay's snapshot of the row just written: the pairs in contact and their
    states, each module's combined contact force (world)."""
    n = d.contacts.master.shape[0]
    i, at = d.n_snapshots, d.n_snapshot_pairs
    if at + n > d.snapshots.master.shape[0]:
        master, slave, state = d.snapshots.master, d.snapshots.slave, d.snapshots.state
        while at + n > master.shape[0]:
            master, slave, state = grow(master), grow(slave), grow(state)
        d.snapshots = Snapshots(row=d.snapshots.row, pairs=d.snapshots.pairs, force_W=d.snapshots.force_W,
                                master=master, slave=slave, state=state)
    d.snapshots.row[i], d.snapshots.pairs[i] = d.row_index, n
    d.snapshots.master[at:at + n] = d.contacts.master
    d.snapshots.slave[at:at + n] = d.contacts.slave
    d.snapshots.state[at:at + n] = d.contacts.state
    for k in range(m.record.module_joint.shape[0]):
        j = m.record.module_joint[k]
        for a in range(3):  # a welded module takes no contact
            d.snapshots.force_W[i, k, a] = d.loads.force_W[j, a] if j > 0 else 0.0
    d.n_snapshots = i + 1
    d.n_snapshot_pairs = at + n


@njit
def record_row(m, d):
    """Write the next row of d.rows from d's state, and its snapshot when one is due."""
    sample(m, d, d.rows[d.n_rows])
    if d.row_index % m.record.replay_every == 0:
        _snapshot(m, d)
    d.n_rows += 1
    d.row_index += 1


@njit
def begin_record(m, d):
    """The record at a run's start: the momentum and energy the balances start from, the
    largest body momenta, and the first row."""
    current_frames(m, d)
    P, L, p_max, l_max, _ = momenta(m, d.now, m.record.all_branches)
    d.energy_passive = np.nan
    d.gravity_datum = gravity_energy(m, d.now)
    d.momentum_max, d.angular_momentum_max = p_max, l_max
    d.momentum_start[:] = P
    d.angular_momentum_start[:] = L
    # no pair in contact at the start
    d.energy_start = d.energy_now = mechanical_energy(m, d, d.contacts.phi, d.memory.s)
    d.n_rows = d.n_snapshots = d.n_snapshot_pairs = 0
    record_row(m, d)


@njit
def close_interval(m, d):
    """The loop's work at the end of a record interval: returns RAN (nothing wrong), NONFINITE,
    ENERGY or ENERGY_WORK (`events`).

    A NaN or an infinity anywhere in (q, v) is NONFINITE, and nothing is recorded. When the
    drive held the fingers through the whole interval (d.held: a passive phase), the
    mechanical energy may not grow past ENERGY_GROWTH times its value when the phase began
    plus ENERGY_FLOOR_J: else ENERGY. In any phase it may not grow past ENERGY_GROWTH times its
    value at the start plus the work the finger drives have done, plus ENERGY_FLOOR_J: the
    drives are the only source of energy in zero gravity, so more is the integrator's
    (ENERGY_WORK). Both keep the row. Then the row and the momentum balance: the largest drift
    of the floating branches' momentum from its start less the external impulse, and the
    largest single-body momenta.
    """
    if not math.isfinite(np.sum(d.q) + np.sum(d.v)):
        return NONFINITE
    code = RAN
    current_frames(m, d)
    E = mechanical_energy(m, d, d.contacts.phi, d.memory.s)
    d.energy_now = E
    if d.held:
        if math.isnan(d.energy_passive):
            d.energy_passive = E
        elif E > ENERGY_GROWTH * d.energy_passive + ENERGY_FLOOR_J:
            code = ENERGY
    else:
        d.energy_passive = np.nan
    if code == RAN and m.record.energy_bound and E > ENERGY_GROWTH * (d.energy_start + d.drive_work) + ENERGY_FLOOR_J:
        code = ENERGY_WORK
    record_row(m, d)
    P, L, p_b, l_b, _ = momenta(m, d.now, m.record.all_branches)
    d.momentum_max, d.angular_momentum_max = max(d.momentum_max, p_b), max(d.angular_momentum_max, l_b)
    dP = (P[0] - d.momentum_start[0] - d.impulse_W[0], P[1] - d.momentum_start[1] - d.impulse_W[1],
          P[2] - d.momentum_start[2] - d.impulse_W[2])
    dL = (L[0] - d.angular_momentum_start[0] - d.impulse_moment_O_W[0],
          L[1] - d.angular_momentum_start[1] - d.impulse_moment_O_W[1],
          L[2] - d.angular_momentum_start[2] - d.impulse_moment_O_W[2])
    n = m.table_normal
    if n[0] != 0.0 or n[1] != 0.0 or n[2] != 0.0:
        # on the air-bearing table the table's reactions (along its normal, and moments about
        # axes in its plane) change the rest: the in-plane momentum and the angular momentum
        # about the normal are the balance's
        P_n, L_n = dot3(dP, n), dot3(dL, n)
        dP = (dP[0] - P_n * n[0], dP[1] - P_n * n[1], dP[2] - P_n * n[2])
        dL = (L_n * n[0], L_n * n[1], L_n * n[2])
    d.momentum_drift = max(d.momentum_drift, math.sqrt(dP[0] ** 2 + dP[1] ** 2 + dP[2] ** 2))
    d.angular_momentum_drift = max(d.angular_momentum_drift, math.sqrt(dL[0] ** 2 + dL[1] ** 2 + dL[2] ** 2))
    return code
