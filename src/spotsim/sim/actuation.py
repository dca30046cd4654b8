"""Stage: the actuators, one finger drive per end-effector (paper Sec. 2.4).

An end-effector's drive moves its two fingers, each a body on its prismatic joint whose
coordinate is the finger's opening, symmetrically (a linkage mirrors them), through a
self-locking transmission (a worm or lead screw): the fingers never open under load. Its
load, the grasp force, is the mean of its fingers' contact loads along their joints (the
contact wrench's generalized force on each joint, `actuation`).

Its controller is digital: every `control_period_s` it reads the load and sets the fingers'
speed, held until the next reading (a zero-order hold). Its readings are the Model's periodic
events (`next_event`): an adaptive integrator ends a step at each. Both laws prescribe the
finger joints' motion (`tree.Tree.prescribed`): between readings the joints keep their speed
whatever the load, so the drive's force is the constraint force the dynamics needs (computed
nowhere it is not reported), and a new speed is an impulse on the robot (`dynamics.velocity_jump`),
which keeps its momentum.

- `kinematic`, a current-limited DC motor with a speed limit: its torque-speed
  line v0 (1 - F / F_g) runs from the no-load speed v0 to the stall force, the grasp load F_g
  (the current limit, through the transmission), and a speed loop caps it at the closing speed
  v_c. The fingers close at v_c while F <= slowdown F_g (v0 = v_c / (1 - slowdown)), slow down
  along the line above it, and stop at F_g; the motor presses at most F_g, and a load above it
  is carried by the self-locking transmission. The speed is a continuous function of the load.
- `relay`, the earlier model, kept for comparison: the fingers close at v_c until F reaches
  F_g, then stop dead, and close again at v_c once F falls below `resume_fraction` of F_g.
- `motor` (the default) prescribes nothing: a motor's torque pushes the fingers through a
  gearhead and a self-locking lead screw (`dynamics.transmissions`); its digital speed loop
  reads their speed by an encoder every `speed_loop_period_s` and sets the current
  (`speed_loop`), and its transmission sticks and slides at the steps' boundaries
  (`transmission_events`). Its readings end an adaptive integrator's steps too, unless they
  are quiet and the integrator may pass them (`quiet_readings`).

Only the active grasp's drive moves; the others hold.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..jit import njit
from ..tables import BACKWARD, FORWARD, KINEMATIC, MOTOR, STUCK
from .dynamics import apply_screw, closing_response, drive_fingers, joint_response, screw_force, velocity_jump
from .tree import kinematics

#: A step ending within this share of a controller period before the drive is due ends at
#: its due time: the steps' times carry round-off.
DUE_ROUND_OFF = 1e-9


class Actuators(NamedTuple):
    """The actuated joints, one row each: the fingers on their prismatic joints, whose
    coordinate is the opening (m) and whose closing is a negative speed."""

    joint: np.ndarray  # (n_a,) its joint
    drive: np.ndarray  # (n_a,) its drive (its end-effector)


class Drives(NamedTuple):
    """The finger drives, one row per end-effector."""

    law: np.ndarray  # (n_ee,) index in tables.DRIVES
    closing_speed: np.ndarray  # (n_ee,) the speed limit, m/s
    grasp_load: np.ndarray  # (n_ee,) the stall force, N
    no_load_speed: np.ndarray  # (n_ee,) the kinematic law's torque-speed line at zero load, m/s
    resume_fraction: np.ndarray  # (n_ee,) the relay: a stalled drive closes again below this share of the grasp load
    period: np.ndarray  # (n_ee,) the controller's period: it reads (and sets) the speed this often, s
    # the motor drive (`motor`): its transmission's ratio rho, rad of rotor per m of each finger's travel
    ratio: np.ndarray  # (n_ee,) rad/m
    forward: np.ndarray  # (n_ee,) its efficiency, the power flowing from the motor to the fingers
    backward: np.ndarray  # (n_ee,) ... flowing back (<= 0: self-locking, the load cannot drive it)
    rotor: np.ndarray  # (n_ee,) the rotor's inertia, kg m^2
    torque_constant: np.ndarray  # (n_ee,) N m/A (and back-EMF constant, V s/rad)
    resistance: np.ndarray  # (n_ee,) the motor's terminal resistance, ohm
    voltage: np.ndarray  # (n_ee,) the supply voltage, V
    current_limit: np.ndarray  # (n_ee,) the current loop's clamp, A
    gain: np.ndarray  # (n_ee,) the speed loop's proportional gain, A per m/s of closing speed
    integral_time: np.ndarray  # (n_ee,) its integral time, s
    back_calculation: np.ndarray  # (n_ee,) bool: its anti-windup tracks the clamp, else stops the integral


@njit
def actuation(m, d):
    """Stage, after the wrenches: each actuated joint's contact load d.load (N, the contact
    wrench's generalized force on the joint, S^T f, never negative: a finger is pushed open).
    Both drives prescribe their joints' motion, so they put no joint force into d.tau (it
    stays zero): the dynamics gives the force the motion takes. A drive that pushes with a
    force of its own writes it there."""
    t = m.tree
    for i in range(m.actuators.joint.shape[0]):
        j = m.actuators.joint[i]
        f = d.loads.f_local[j]
        load = f[0] * t.axis[j, 0] + f[1] * t.axis[j, 1] + f[2] * t.axis[j, 2]
        d.load[i] = max(load, 0.0)


@njit
def kinematic_speed(p, ee, load, stiffness, damping, speed, h):
    """The kinematic drive's closing speed (m/s) for a step of h (s): the speed v at which its
    law v = min(v_c, v0 (1 - F / F_g)), never negative, holds with the load the step will end
    at, F = load + damping (v - speed) + stiffness h v (N), linearised about the last
    evaluation's load, made at the closing speed `speed`, with its slopes in the finger's
    advance (stiffness, N/m) and speed (damping, N s/m).

    Taken at the last load alone (explicitly), the law would be a stiff feedback loop: a
    contact's slopes turn the speed the load allows within microseconds, and the damping's
    share at once, so that explicit decisions overshoot and alternate between stop and
    closing. At the step's end (implicitly, as backward Euler) the load approaches the grasp
    load without overshoot at any step; as h -> 0 with the slopes the law itself. p: the
    Drives, ee: the drive's row.
    """
    unloaded = 1.0 - (load - damping * speed) / p.grasp_load[ee]
    v = p.no_load_speed[ee] * unloaded / (1.0 + p.no_load_speed[ee] * (damping + stiffness * h) / p.grasp_load[ee])
    return min(p.closing_speed[ee], max(0.0, v))


@njit
def grasp_force(m, d, ee):
    """The grasp force on end-effector ee's drive at the last evaluation: the mean of its
    fingers' loads (N), and of their slopes in the fingers' advance (N/m) and speed (N s/m):
    each pair in contact on a finger's body adds its contact's stiffness and damping
    (`contact.forces.Contacts`) projected twice on the finger's axis. Zeros without fingers."""
    t = m.tree
    force = stiffness = damping = 0.0
    n = 0
    c = d.contacts
    for i in range(m.actuators.joint.shape[0]):
        if m.actuators.drive[i] != ee:
            continue
        j = m.actuators.joint[i]
        force += d.load[i]
        a = (d.R_W[j, 0, 0] * t.axis[j, 0] + d.R_W[j, 0, 1] * t.axis[j, 1] + d.R_W[j, 0, 2] * t.axis[j, 2],
             d.R_W[j, 1, 0] * t.axis[j, 0] + d.R_W[j, 1, 1] * t.axis[j, 1] + d.R_W[j, 1, 2] * t.axis[j, 2],
             d.R_W[j, 2, 0] * t.axis[j, 0] + d.R_W[j, 2, 1] * t.axis[j, 1] + d.R_W[j, 2, 2] * t.axis[j, 2])
        for k in range(c.master.shape[0]):
            if m.master.joint[c.master[k]] != j:
                continue
            # closing by dx along the axis indents the pair by (g . a)^2 dx along g and bends a
            # holding bristle by the axis' share in the tangent plane of n_c
            ga = c.direction_W[k, 0] * a[0] + c.direction_W[k, 1] * a[1] + c.direction_W[k, 2] * a[2]
            na = c.normal_W[k, 0] * a[0] + c.normal_W[k, 1] * a[1] + c.normal_W[k, 2] * a[2]
            tangent = 1.0 - na * na
            stiffness += ga * ga * c.normal_stiffness[k] + tangent * c.tangent_stiffness[k]
            damping += ga * ga * c.normal_damping[k] + tangent * c.tangent_damping[k]
        n += 1
    return (force / n, stiffness / n, damping / n) if n else (0.0, 0.0, 0.0)


@njit
def current_speed(m, d):
    """The active drive's closing speed, m/s (0 without fingers)."""
    ee = m.grasps.ee[d.active]
    for i in range(m.actuators.joint.shape[0]):
        if m.actuators.drive[i] == ee:
            return -d.v[m.tree.idx_v[m.actuators.joint[i]]]
    return 0.0


@njit
def closing_speed(m, d, ee, h):
    """End-effector ee's closing speed for a coming step of h (s), m/s, from the last
    evaluation's grasp force, by its drive's law (the relay updates its state)."""
    p = m.drives
    force, stiffness, damping = grasp_force(m, d, ee)
    if p.law[ee] == KINEMATIC:
        return kinematic_speed(p, ee, force, stiffness, damping, current_speed(m, d), h)
    if force >= p.grasp_load[ee]:
        d.stalled[ee] = True
    elif force < p.resume_fraction[ee] * p.grasp_load[ee]:
        d.stalled[ee] = False
    return 0.0 if d.stalled[ee] else p.closing_speed[ee]


@njit
def _decide(m, d, t, horizon):
    """The active drive's reading at time t (s), from the last evaluation's loads: its
    fingers' speed until it is next due, `horizon` (s) later, set by an impulse
    (`dynamics.velocity_jump`; d.jumped when a speed changed). Returns its speed before and
    after (m/s)."""
    ee = m.grasps.ee[d.active]
    d.sample_t = t + horizon
    before = current_speed(m, d)
    speed = closing_speed(m, d, ee, horizon)
    n = 0
    for i in range(m.actuators.joint.shape[0]):
        n += m.actuators.drive[i] == ee
    joints, speeds = np.empty(n, dtype=np.int64), np.empty(n)
    n = 0
    for i in range(m.actuators.joint.shape[0]):
        if m.actuators.drive[i] == ee:
            joints[n], speeds[n] = m.actuators.joint[i], -speed
            n += 1
    if velocity_jump(m, d, joints, speeds):
        d.jumped = True
    return before, speed


@njit
def next_event(m, d):
    """The time of the Model's next periodic event (s): the active drive's next reading, or
    none (inf) while its readings are quiet (`quiet_readings`) and the integrator may pass them
    (`simulation.integrator.drive_readings: pass_quiet`)."""
    ee = m.grasps.ee[d.active]
    if m.integrator.pass_quiet and m.drives.law[ee] == MOTOR and quiet_readings(m, d, ee):
        return np.inf
    return d.sample_t


@njit
def drive_power(m, d):
    """A bound on the power the drives put in at d's speeds, W: a motor drive's shaft power,
    its torque K_t i at the rotor's speed rho x' (the screw's friction takes its share before
    the fingers get it); a drive that prescribes its fingers' speed, each finger's load times
    its joint's speed."""
    p = m.drives
    power = 0.0
    for i in range(m.actuators.joint.shape[0]):
        if p.law[m.actuators.drive[i]] != MOTOR:
            power += d.load[i] * abs(d.v[m.tree.idx_v[m.actuators.joint[i]]])
    for ee in range(p.law.shape[0]):
        if p.law[ee] == MOTOR and drive_fingers(m, ee)[1] >= 0:
            power += abs(p.torque_constant[ee] * d.current[ee] * p.ratio[ee] * motor_closing(m, d, ee))
    return power


@njit
def sample_controllers(m, d, t, h):
    """The controllers' events at time t (s), the end of a step of h (s): if the active drive
    is due (t at or past d.sample_t), its reading (`_decide`) for a controller period, or the
    step if longer. A motor drive's speed loop reads at t; a step that passed its quiet
    readings (`quiet_readings`, still so at its end: what they read has not moved) takes each
    at its own time.

    The grasp counts the drive's resumes (closing again at more than half its closing speed
    after it had stopped) and its largest speed change from one reading to the next."""
    ee = m.grasps.ee[d.active]
    period = m.drives.period[ee]
    due = t >= d.sample_t - DUE_ROUND_OFF * period
    if m.drives.law[ee] == MOTOR:
        if due and m.integrator.pass_quiet and t > d.sample_t + DUE_ROUND_OFF * period and quiet_readings(m, d, ee):
            while d.sample_t <= t:
                speed_loop(m, d, ee, d.sample_t)
        elif due:
            speed_loop(m, d, ee, t)
        transmission_events(m, d, ee)
        return
    if not due:
        return
    before, speed = _decide(m, d, t, max(period, h))
    g = d.active
    d.drive_jump[g] = max(d.drive_jump[g], abs(speed - before))
    if before == 0.0:
        d.drive_stopped[g] = True
    if d.drive_stopped[g] and speed > 0.5 * m.drives.closing_speed[ee]:
        d.drive_resumes[g] += 1
        d.drive_stopped[g] = False


@njit
def start_drive(m, d):
    """The active drive's first reading, now (a run's or a weld's start, its kinematics made
    here): its start, not a change of speed, so nothing is counted. A motor drive starts
    closing at its set speed, its transmission forward, its speed loop at rest, its encoder
    unread."""
    kinematics(m, d)
    ee = m.grasps.ee[d.active]
    if m.drives.law[ee] != MOTOR:
        _decide(m, d, d.t, m.drives.period[ee])
        return
    r1, r2 = drive_fingers(m, ee)
    _set_closing(m, d, r1, r2, m.drives.closing_speed[ee])
    d.transmission[ee] = FORWARD
    d.integral[ee] = 0.0
    d.encoder_t[ee] = np.nan  # no reading yet
    d.direction[ee] = 1.0
    speed_loop(m, d, ee, d.t)


# -------------------------------------------------------------------------------- the motor


@njit
def _set_closing(m, d, r1, r2, speed):
    """Set both fingers of a motor drive to close at `speed` (m/s) by an impulse on their
    joints (momentum kept: the joints' forces are internal), at the frames of the last
    `kinematics`, which must be made at d.q; their responses made here."""
    t = m.tree
    j1, j2 = m.actuators.joint[r1], m.actuators.joint[r2]
    joint_response(m, d, j1, d.response[r1], np.bool_(True))
    joint_response(m, d, j2, d.response[r2], np.bool_(True))
    iv1, iv2 = t.idx_v[j1], t.idx_v[j2]
    # the responses scaled to order one: their determinant must not underflow (heavy fingers)
    scale = max(d.response[r1, iv1], d.response[r2, iv2])
    g11, g12, g22 = d.response[r1, iv1] / scale, d.response[r2, iv1] / scale, d.response[r2, iv2] / scale
    dv1, dv2 = -speed - d.v[iv1], -speed - d.v[iv2]
    det = (g11 * g22 - g12 * g12) * scale
    p1, p2 = (g22 * dv1 - g12 * dv2) / det, (g11 * dv2 - g12 * dv1) / det
    for k in range(d.v.shape[0]):
        d.v[k] += p1 * d.response[r1, k] + p2 * d.response[r2, k]
    d.v[iv1] = d.v[iv2] = -speed  # to the bit


@njit
def motor_closing(m, d, ee):
    """A motor drive's closing speed (m/s): its fingers' mean."""
    r1, r2 = drive_fingers(m, ee)
    t = m.tree
    return -0.5 * (d.v[t.idx_v[m.actuators.joint[r1]]] + d.v[t.idx_v[m.actuators.joint[r2]]])


@njit
def motor_records(m, d, h):
    """A step of h (s) in the active grasp's motor records: its largest current, its
    transmission's time in each state, its closing fingers' largest deceleration."""
    ee, g = m.grasps.ee[d.active], d.active
    if m.drives.law[ee] != MOTOR:
        return
    r1, r2 = drive_fingers(m, ee)
    d.peak_current[g] = max(d.peak_current[g], abs(d.current[ee]))
    d.transmission_time[g, d.transmission[ee]] += h
    if r2 >= 0 and motor_closing(m, d, ee) > 0.0:  # the closing acceleration is -a of the opening
        d.peak_deceleration[g] = max(d.peak_deceleration[g], d.a[m.tree.idx_v[m.actuators.joint[r1]]])


@njit
def rotor_energy(m, d):
    """The kinetic energy of the motor drives' rotors, 1/2 J (rho x')^2 each, J."""
    p = m.drives
    total = 0.0
    for ee in range(p.law.shape[0]):
        if p.law[ee] == MOTOR and drive_fingers(m, ee)[1] >= 0:
            total += 0.5 * p.rotor[ee] * (p.ratio[ee] * motor_closing(m, d, ee)) ** 2
    return total


@njit
def motor_opening(m, d, ee):
    """A motor drive's opening (m): its fingers' mean."""
    r1, r2 = drive_fingers(m, ee)
    t = m.tree
    return 0.5 * (d.q[t.idx_q[m.actuators.joint[r1]]] + d.q[t.idx_q[m.actuators.joint[r2]]])


@njit
def speed_loop(m, d, ee, t):
    """The motor drive's digital speed loop at time t (s): a PI on the closing speed's error
    from its set speed, the current it asks for clamped by the current limit and by what the
    supply voltage drives through the winding against the back-EMF at this speed, held until
    the next reading. The current loop is ideal: the motor's current is the one asked for.

    Anti-windup: by conditional integration, the integral stops while the clamp holds; by
    back-calculation (Astrom and Hagglund), it tracks the clamp, dI/dt = (K e + c - u) / T_i
    with its tracking time the integral time (u the current asked for, c the one got), taken
    by backward Euler over the time h since the last reading: the integral gains K e h / T_i,
    then h / (T_i + h) of the clamp's excess c - u. Under a held clamp it relaxes to the clamp
    by T_i / (T_i + h) a reading; it is continuous in the speed read, where a stop jumps by a
    whole reading's increment as a reading crosses the clamp.

    The speed it reads is an encoder's: the travel since its last reading over the time
    between (at its first reading, the speed itself), and the integral takes each reading's
    error over that time. The integral's sum is then the fingers' lag behind their set
    speed's travel (times the gain over the integral time) whatever the period, and a bounce
    shorter than a period counts by the travel it cost, not by the speed a reading happens
    to catch."""
    p = m.drives
    d.sample_t = t + p.period[ee]
    speed, opening = motor_closing(m, d, ee), motor_opening(m, d, ee)
    elapsed, read = p.period[ee], speed
    if t > d.encoder_t[ee]:
        elapsed = t - d.encoder_t[ee]
        read = (d.encoder_opening[ee] - opening) / elapsed
    d.encoder_opening[ee], d.encoder_t[ee] = opening, t
    r = _reading(p, ee, d.integral[ee], read, speed, elapsed)
    d.integral[ee], d.current[ee], d.saturated[ee] = r.integral, r.current, r.saturated


class Reading(NamedTuple):
    """What one reading of a speed loop leaves (`_reading`)."""

    integral: float  # the loop's integral after it, A
    current: float  # the current it sets, A
    saturated: bool  # it asked for its upper clamp or more: pressing as hard as the current limit and the supply let it


@njit
def _reading(p, ee, integral, read, speed, elapsed):
    """The speed loop's law (`speed_loop`) at one reading of drive ee (p: the Drives): its
    integral before it (A), the closing speed the encoder read and the one the motor turns
    at for its back-EMF (m/s), and the time since the last reading (s)."""
    error = p.closing_speed[ee] - read
    candidate = integral + p.gain[ee] * elapsed / p.integral_time[ee] * error
    wanted = p.gain[ee] * error + candidate
    emf = p.torque_constant[ee] * p.ratio[ee] * speed
    hi = min(p.current_limit[ee], (p.voltage[ee] - emf) / p.resistance[ee])
    lo = max(-p.current_limit[ee], (-p.voltage[ee] - emf) / p.resistance[ee])
    current = min(hi, max(lo, wanted))
    if p.back_calculation[ee]:
        integral = candidate + (current - wanted) * elapsed / (p.integral_time[ee] + elapsed)
    elif current == wanted:
        integral = candidate
    return Reading(integral, current, wanted >= hi)


@njit
def quiet_readings(m, d, ee):
    """Whether motor drive ee's coming speed-loop readings leave its current as it is, for as
    long as its transmission stays stuck, so that a step may pass them (`next_event`; they
    are taken at their times at its end, `sample_controllers`): the transmission is stuck
    (it holds the fingers: their opening stays, and a state changes only at a step's end) and
    the loop presses at its upper clamp, at which the next reading (of the travel since the
    last) keeps it, and so does a reading after it of less than half the set speed.

    Then every later reading keeps it too: each reads no travel, an error near the set speed
    (positive: a scenario rule), above the one assumed; by back-calculation the excess of the
    current asked for over the clamp decays by T_i / (T_i + h) a reading and gains K e h / T_i
    > 0, so it stays positive; by conditional integration the integral stays while clamped, and
    what is asked grows with the error."""
    p = m.drives
    if d.transmission[ee] != STUCK or not d.saturated[ee]:
        return False
    elapsed = d.sample_t - d.encoder_t[ee]
    if not elapsed > 0.0:  # (nan: no reading yet)
        return False
    speed = motor_closing(m, d, ee)
    first = _reading(p, ee, d.integral[ee], (d.encoder_opening[ee] - motor_opening(m, d, ee)) / elapsed, speed,
                     elapsed)
    if not first.saturated or first.current != d.current[ee]:
        return False
    then = _reading(p, ee, first.integral, 0.5 * p.closing_speed[ee], speed, p.period[ee])
    return then.saturated and then.current == d.current[ee]


@njit
def transmission_events(m, d, ee):
    """The motor drive's transmission at a step's boundary, at the last evaluation's forces
    and responses (`dynamics.transmissions`):

    - sliding, forward and backward swap when the power's direction does; it sticks when
      the fingers' closing speed has reached or crossed zero since the last boundary, or when
      the power would flow back through a self-locking screw from fingers too heavy for the
      rotor's side to give (`dynamics.screw_force`): an impulse on the finger joints stops
      them (the screw's friction, internal: momentum kept);
    - stuck, it slides when the force that holds the fingers leaves the band the screw's
      friction can hold at the motor's torque, forward in the direction the motor drives,
      backward in the direction the load drives (never, self-locking).

    The screw's force in d.a follows its state (`dynamics.apply_screw`)."""
    p = m.drives
    r1, r2 = drive_fingers(m, ee)
    speed = motor_closing(m, d, ee)
    state = d.transmission[ee]
    if state != STUCK:
        flows_back = d.screw_force[ee] * speed < 0.0
        if flows_back != (state == BACKWARD):
            state = BACKWARD if flows_back else FORWARD
        locks = state == BACKWARD and p.backward[ee] + p.rotor[ee] * p.ratio[ee] ** 2 * \
            closing_response(m, d, r1, r2)[1] <= 0.0
        if speed * d.direction[ee] <= 0.0 or locks:
            kinematics(m, d)  # the impulse's frames, at the state as it is
            _set_closing(m, d, r1, r2, 0.0)
            d.jumped = True
            d.transmission_stops[d.active] += 1
            state = STUCK
        else:
            d.direction[ee] = 1.0 if speed > 0.0 else -1.0
    if state == STUCK:
        d.direction[ee] = 0.0
        held = screw_force(m, d, ee, r1, r2)
        drive = p.ratio[ee] * p.torque_constant[ee] * d.current[ee]
        closes = drive >= 0.0
        if (p.forward[ee] * drive > held) == closes and p.forward[ee] * drive != held:
            state = FORWARD  # the motor drives the fingers the way it turns
            d.direction[ee] = 1.0 if closes else -1.0
        elif p.backward[ee] > 0.0 and (drive / p.backward[ee] < held) == closes:
            state = BACKWARD  # the load drives the motor back
            d.direction[ee] = -1.0 if closes else 1.0
    d.transmission[ee] = state
    apply_screw(m, d, ee, r1, r2, screw_force(m, d, ee, r1, r2))
