"""The default step, compiled whole: the record intervals between two returns in one call.

For the default setting (symplectic Euler, the culled search, a scene of free bodies only)
the stages of `step.step` run in one compiled loop: contact (`step._contact_kernels`' chain),
the dynamics (`bodies.free_body_accelerations`, ABA for free bodies) and the update
(`integrators._symplectic_euler`) in one pass (`integrators.free_bodies_step`), the finger
drive, the travel bounds, the grasp phase, and the run loop's per-substep bookkeeping (peaks,
external impulses, divergence by penetration); and, at each interval's end, the run loop's
record (`record.close_interval`) and the replay's contact snapshot when one is due. The loop
returns to Python when coal's face pairs must be refreshed (the Verlet skin is used up), after
RECORDS_PER_CALL records, when the grasp phase completes or times out, or when the run
diverges. It does what `step.step` and the run loop do, in the same order and with the same
arithmetic; the tests hold the two to that. Its kernels are compiled into it
(`jit.njit_inline`): a compiled call passing a dozen arrays costs a few hundred ns.
"""

from __future__ import annotations

import math

import numpy as np

from .bodies import body_kinematics, cross, mv
from .contact.forces import body_wrenches, contact_summary, pair_forces, raise_peaks
from .contact.search import grow, listed_search
from .grasp import PHASES
from .integrators import SymplecticEuler, free_bodies_step
from .jit import direct, njit, njit_inline
from .record import DRIVE_WORK, ENERGY as ENERGY_RECORD, ENERGY_WORK as ENERGY_WORK_RECORD, NONFINITE as NONFINITE_RECORD
from .record import close_interval, drive_power
from .step import FREE_FLIGHT_SAFETY, Contacts, StateOverflow, _travel_rate, near_face_pairs

#: Why `substeps` or `intervals` returned: all their steps or records ran; the skin is used up
#: (refresh coal and go on); the grasp phase completed or timed out; a pair penetrated deeper
#: than a sphere radius; the state became non-finite; energy grew in a passive phase, or past
#: what the drives could have put in (`record.close_interval`).
RAN, REFRESH, STOPPED, TOO_DEEP, NONFINITE, ENERGY, ENERGY_WORK = range(7)
#: ... and, from `run_records` only: coal could not bound the state (the run has diverged).
OVERFLOW = 7
#: Record intervals per call of `intervals` at most: each return to Python updates the
#: progress bar and lets Ctrl-C in; 250 intervals are 0.25 s simulated at the default dt.
RECORDS_PER_CALL = 250

# slots of the loop's scalar state, read and written in place
(T, TRAVEL, STALLED, PHASE, HELD_SINCE, T_CENTRING, T_COMPLETE, HELD, STEPS, PAIR_STEPS, PEAK_PAIRS, LEFT, H,
 FLIGHTS) = range(14)
N_SCALARS = 14


def applies(model, integrator) -> bool:
    """Whether the compiled loop can run this scene: symplectic Euler, the culled search and
    free bodies only (`SymplecticEuler.only_free`)."""
    return (isinstance(integrator, SymplecticEuler) and integrator.only_free
            and model.params.broad_phase != "none")


def loop_args(model) -> tuple:
    """The model's constant arguments of `substeps`, in its order."""
    rows, reach = model.reach_table
    return (model.bodies, np.array(model.pin_model.gravity.linear), rows, reach, model.fixed_contact,
            model.contact_kernel_args)


@njit_inline
def substeps(h, q, v, R_W, p_W, w_W, vo_W, near, opening, opening_rate, mem_key, mem_s, mem_vminus,
             pair_list, s, peak_f, peak_t, peak_n, J, JL, rs, mine, watch, limits, consts):
    """The s[LEFT] steps of h (s) left in a record interval (fewer if it must return) of
    `step.step` with symplectic Euler, and the run loop's bookkeeping of each, compiled.

    s: (N_SCALARS,) the scalar state (slots T ... FLIGHTS), in place. peak_f, peak_t,
    peak_n: the active grasp's peaks (`contact.forces.raise_peaks`), in place. J, JL: (3,)
    external impulse on the free bodies and its moment about the world origin, in place. rs:
    the record state (`record.close_interval`), whose drive work is added to in place.
    mine: the active drive's fingers. watch: the active grasp's `Model.watch_args`. limits:
    (skin, deepest penetration, phase start, phase time-out, hold time, contact speed limit,
    net force limit, closing speed, grasp load, resume fraction), SI units. consts:
    `loop_args`. Returns the new q, v and pair list, the last step's pairs (whose memory is
    the new pair memory), loads and summary (as `step._contact_kernels`), and why it returned
    (RAN, REFRESH, STOPPED or TOO_DEEP).
    """
    bodies, g_W, rows, reach, fixed_contact, contact_args = consts
    skin, max_phi, start, timeout, hold_s, max_speed, max_force, speed, grasp_load, resume = limits
    ee_joint, R_ee, module_joint, lever = watch
    gravity = g_W[0] != 0.0 or g_W[1] != 0.0 or g_W[2] != 0.0
    event = RAN
    while s[LEFT] > 0:
        # forces -> dynamics -> integrate (SymplecticEuler.advance)
        # step._contact_kernels' chain, written out here: called, it cost ~4 us more a step (its
        # ~40 arguments in and ~30 arrays out), and numba cannot inline it (Python passes a call
        # of more than 30 arguments as *args, which numba's inlining refuses)
        (_, table, maps, C1_J, N1_J, joint1, finger1, axis1_J, C2_J, N2_J, joint2, r1, r2, K, damping, floor,
         cutoff, bristle, common_point, finger_parent, finger_axis_J) = contact_args
        body_kinematics(bodies, q, v, R_W, p_W, w_W, vo_W)
        (master, slave, key), pair_list = listed_search(
            near, table, C1_J, N1_J, finger1, axis1_J, opening, maps, C2_J.shape[0], R_W, p_W, r1, r2, cutoff,
            pair_list)
        pairs = pair_forces(master, slave, key, C1_J, N1_J, joint1, finger1, axis1_J, C2_J, N2_J, joint2,
                            R_W, p_W, w_W, vo_W, opening, opening_rate, mem_key, mem_s, mem_vminus,
                            r1, r2, K, damping, floor, h, bristle)
        loads = body_wrenches(pairs[0], pairs[1], pairs[7], pairs[4], pairs[5], pairs[6], common_point,
                              joint1, joint2, finger1, finger_parent, finger_axis_J, R_W, p_W, R_W.shape[0])
        summary = contact_summary(loads[1], loads[2], R_W, p_W, ee_joint, R_ee, module_joint, lever, pairs[8],
                                  pairs[3])
        mem_key, mem_s, mem_vminus = pairs[2], pairs[10], pairs[11]
        q, v = free_bodies_step(bodies, R_W, q, v, loads[0], g_W, h)
        s[LEFT] -= 1
        power = drive_power(loads[5], opening_rate)  # at this step's rate, before the drive sets the next
        # the active drive sets its fingers' rate from this step's loads (grasp.FingerDrive)
        if mine.shape[0]:
            force = 0.0
            for i in mine:
                force += loads[5][i]
            force /= mine.shape[0]
            if force >= grasp_load:
                s[STALLED] = 1.0
            elif force < resume * grasp_load:
                s[STALLED] = 0.0
            rate = 0.0 if s[STALLED] else -speed
            for i in mine:
                opening_rate[i] = rate
        for i in range(opening.shape[0]):
            opening[i] += h * opening_rate[i]
        s[T] += h
        rs[DRIVE_WORK] += h * power
        s[TRAVEL] += h * _travel_rate(bodies.idx_v, rows, reach, v, opening_rate)
        # the grasp phase (grasp.GraspPhase.update)
        n_pairs = pairs[2].shape[0]
        t = s[T]
        if s[PHASE] == 0 and n_pairs > 0:
            s[PHASE], s[T_CENTRING] = 1, t
        if s[PHASE] == 1:
            net = math.sqrt(summary[0] * summary[0] + summary[1] * summary[1] + summary[2] * summary[2])
            if n_pairs > 0 and s[STALLED] and summary[6] <= max_speed and net <= max_force:
                if math.isnan(s[HELD_SINCE]):
                    s[HELD_SINCE] = t
                if t - s[HELD_SINCE] >= hold_s - 1e-12:
                    s[PHASE], s[T_COMPLETE] = 2, t
            else:
                s[HELD_SINCE] = np.nan
        # the run loop's bookkeeping of the step
        if not s[STALLED]:
            s[HELD] = 0.0
        s[STEPS] += 1
        s[PAIR_STEPS] += n_pairs
        if n_pairs:
            raise_peaks(peak_f, peak_t, peak_n, summary)
            s[PEAK_PAIRS] = max(s[PEAK_PAIRS], n_pairs)
        if fixed_contact:
            for i in range(3):
                J[i] += h * loads[3][i]
                JL[i] += h * loads[4][i]
        if gravity:
            for b in range(bodies.joint.shape[0]):
                j = bodies.joint[b]
                r_G = p_W[j] + mv(R_W[j], bodies.lever[b])
                J += h * bodies.mass[b] * g_W
                JL += h * cross(r_G, bodies.mass[b] * g_W)
        if n_pairs and summary[7] > max_phi:
            event = TOO_DEEP
            break
        if s[PHASE] == 2 or t - start > timeout:
            event = STOPPED
            break
        if s[TRAVEL] > skin and s[LEFT] > 0:
            event = REFRESH
            break
    return q, v, pair_list, pairs, loads, summary, event


@njit
def intervals(n_records, dt, n_sub, q, v, R_W, p_W, w_W, vo_W, near, opening, opening_rate, mem_key, mem_s,
              mem_vminus, pair_list, s, peak_f, peak_t, peak_n, J, JL, mine, watch, limits, consts, rows, rs,
              last_open, grasp, ee, k, record, first_row, every, module_joints):
    """Up to n_records record intervals of dt (s) of the run loop, compiled: each a free-flight
    step of dt when nothing can touch within it (zero gravity, coal's face pairs beyond the
    margin, the travel bound within the skin: `step.free_flight`), else n_sub `substeps`;
    then `record.close_interval`, whose rows go into rows (n_records, width), and the
    replay's snapshot of each row recorded whose index is a multiple of `every`.

    Must be entered with the skin not used up (s[TRAVEL] <= skin) or within an interval
    (s[LEFT] > 0): it then takes at least one step. Arguments as `substeps`, and: rs, J, JL,
    last_open, grasp, ee, k, record: `record.close_interval`'s; first_row: the run's index of
    the first row written here; module_joints: (n_modules,) each module's joint, 0 once
    welded. Returns as `substeps` (the event RAN when n_records rows are written, NONFINITE
    or ENERGY as `close_interval` finds), the rows written and the snapshots (`_snapshot`).
    """
    bodies, g_W, reach_rows, reach, _, _ = consts
    skin, start, timeout = limits[0], limits[2], limits[3]
    gravity = g_W[0] != 0.0 or g_W[1] != 0.0 or g_W[2] != 0.0
    n_rows = 0
    cap = n_records // every + 1
    snaps = (np.empty(cap, dtype=np.int64), np.empty(cap, dtype=np.int64),
             np.empty((cap, module_joints.shape[0], 3)), np.empty(16 * cap, dtype=np.int64),
             np.empty(16 * cap, dtype=np.int64), np.empty(16 * cap, dtype=np.int64))
    n_snap = n_snapped = 0
    while True:
        if s[LEFT] == 0:  # a new interval
            if s[TRAVEL] > skin:
                event = REFRESH
                break
            flight = (not gravity and near.shape[0] == 0 and s[TRAVEL] + FREE_FLIGHT_SAFETY * dt * _travel_rate(
                bodies.idx_v, reach_rows, reach, v, opening_rate) <= skin)
            s[FLIGHTS] += flight
            s[LEFT], s[H] = (1.0, dt) if flight else (float(n_sub), dt / n_sub)
            s[HELD] = s[STALLED]  # the drive holds through the interval so far
        q, v, pair_list, pairs, loads, summary, event = substeps(
            s[H], q, v, R_W, p_W, w_W, vo_W, near, opening, opening_rate, mem_key, mem_s, mem_vminus, pair_list, s,
            peak_f, peak_t, peak_n, J, JL, rs, mine, watch, limits, consts)
        mem_key, mem_s, mem_vminus = pairs[2], pairs[10], pairs[11]
        if event == REFRESH or event == TOO_DEEP:
            break
        s[LEFT] = 0.0  # the interval ends here (early if its phase ended)
        code = close_interval(rows[n_rows], rs, J, JL, s[HELD] != 0.0, s[T], q, v, pairs[3], pairs[10], summary,
                              pairs[2].shape[0], pairs[9], opening, loads[5], last_open, int(s[PHASE]), grasp, ee, k,
                              record)
        if code == NONFINITE_RECORD:
            event = NONFINITE
            break
        n_rows += 1
        if (first_row + n_rows - 1) % every == 0:
            snaps = _snapshot(snaps, n_snap, n_snapped, first_row + n_rows - 1, pairs, loads[1], module_joints)
            n_snap += 1
            n_snapped += pairs[0].shape[0]
        if code == ENERGY_RECORD or code == ENERGY_WORK_RECORD:
            event = ENERGY if code == ENERGY_RECORD else ENERGY_WORK
            break
        if s[PHASE] == 2 or s[T] - start > timeout:
            event = STOPPED
            break
        if n_rows == n_records:
            event = RAN
            break
    return (q, v, pair_list, pairs, loads, summary, event, n_rows,
            (snaps[0][:n_snap], snaps[1][:n_snap], snaps[2][:n_snap], snaps[3][:n_snapped], snaps[4][:n_snapped],
             snaps[5][:n_snapped]))


@njit
def _snapshot(snaps, n_snap, n_snapped, row, pairs, joint_force_W, module_joints):
    """Add the replay's snapshot of row to snaps, which hold n_snap snapshots of n_snapped
    pairs in all: (row, pairs in contact, each module's contact force (n_modules, 3), world)
    per snapshot, and (master, slave, state) per pair. Returns snaps (grown when full)."""
    row_of, count, force, master, slave, state = snaps
    n = pairs[0].shape[0]
    while n_snapped + n > master.shape[0]:
        master, slave, state = grow(master), grow(slave), grow(state)
    row_of[n_snap], count[n_snap] = row, n
    master[n_snapped:n_snapped + n] = pairs[0]
    slave[n_snapped:n_snapped + n] = pairs[1]
    state[n_snapped:n_snapped + n] = pairs[9]
    for m in range(module_joints.shape[0]):
        j = module_joints[m]
        for a in range(3):
            force[n_snap, m, a] = joint_force_W[j, a] if j else 0.0  # a welded module takes no contact
    return row_of, count, force, master, slave, state


_intervals = direct(intervals)


def run_records(model, data, n_records: int, rec, J: np.ndarray, JL: np.ndarray, start: float, timeout: float,
                max_phi: float) -> tuple[int, int, int, int, int]:
    """Up to n_records record intervals of the active grasp (fewer if its phase ends or the run
    diverges), with coal refreshed as the skin requires; data is left as `step.step` leaves
    it, and the rows and the replay's snapshots go to the recorder rec (`run.Recorder`).

    J, JL: the external impulse and its moment, added to in place; start, timeout: the
    phase's start and time-out, s; max_phi: the deepest penetration allowed, m. Returns (why
    it returned: RAN, STOPPED, TOO_DEEP, NONFINITE, ENERGY, ENERGY_WORK or OVERFLOW; rows
    recorded; steps taken; pair steps; free-flight steps; with OVERFLOW, why coal could not
    bound the state).
    """
    sim = model.scenario.simulation
    s = np.zeros(N_SCALARS)
    ee, k = model.grasps[data.active]
    drive, phase = data.drives[ee], data.phase
    peaks = rec.peaks[data.active]
    limits = (model.params.skin, max_phi, start, timeout, phase.hold_s, phase.max_contact_speed,
              phase.max_net_force, drive.speed, drive.grasp_load, drive.resume_fraction)
    s[T] = data.t
    s[STALLED], s[PHASE] = drive.stalled, PHASES.index(phase.phase)
    s[HELD_SINCE] = np.nan if phase._held_since is None else phase._held_since
    s[PEAK_PAIRS] = peaks["pairs"]
    if len(rec.buffer) < n_records:
        rec.buffer = np.empty((n_records, rec.layout.width))
    module_joints = np.array([mod.joint for mod in model.modules], dtype=np.int64)
    n_rows, event, overflow = 0, REFRESH, ""
    while event == REFRESH:
        try:
            near = near_face_pairs(model, data)  # refreshed when the skin is used up
        except StateOverflow as e:
            event, overflow = OVERFLOW, str(e)
            break
        s[TRAVEL] = data.travel
        data.q, data.v, data.pair_list, pairs, loads, summary, event, rows, snaps = _intervals(
            n_records - n_rows, sim.dt_s, sim.substeps, data.q, data.v, data.R_W, data.p_W, data.w_W, data.vo_W,
            near, data.opening, data.opening_rate, data.mem_key, data.mem_s, data.mem_vminus, data.pair_list, s,
            peaks["force"], peaks["torque"], peaks["norms"], J, JL, model.drive_fingers[ee],
            model.watch_args[data.active], limits, model.loop_args, rec.buffer, rec.state, rec.last_open,
            data.active, ee, k, rec.args(model), rec.n_rows, rec.replay_every, module_joints)
        _leave(data, s, pairs, loads, summary)
        drive.stalled = bool(s[STALLED])
        phase.phase = PHASES[int(s[PHASE])]
        phase._held_since = None if math.isnan(s[HELD_SINCE]) else float(s[HELD_SINCE])
        for slot, name in ((T_CENTRING, PHASES[1]), (T_COMPLETE, PHASES[2])):
            if s[slot] and name not in phase.times:
                phase.times[name] = float(s[slot])
        rec.add_rows(model, data, rec.buffer[:rows], snapshots=snaps)
        n_rows += rows
    peaks["pairs"] = int(s[PEAK_PAIRS])
    return event, n_rows, int(s[STEPS]), int(s[PAIR_STEPS]), int(s[FLIGHTS]), overflow


def _leave(data, s, pairs, loads, summary) -> None:
    """Put the loop's last step into data as `step.step` leaves it."""
    data.t, data.travel = float(s[T]), float(s[TRAVEL])
    data.contacts = Contacts(*pairs[:10])
    data.contacts.memory = (data.contacts.key, pairs[10], pairs[11])
    data.mem_key, data.mem_s, data.mem_vminus = data.contacts.memory
    (local, data.joint_force_W, data.joint_torque_O_W, data.external_force_W, data.external_torque_O_W,
     data.finger_load) = loads
    for view, w in zip(data.f_views, local):
        view[:] = w
    data.summary = summary
