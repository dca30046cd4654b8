"""Stage: the finger drive (paper Sec. 2.4), one per end-effector.

A drive closes both fingers of its end-effector symmetrically (a linkage mirrors them) through
a self-locking transmission (a worm or lead screw): the fingers never open under load. Its
load is the grasp force, the mean of its fingers' contact loads along their opening axes. Two
laws (`end_effector.drive`):

Its controller is digital: every `control_period_s` it reads the load and sets the speed, held
until the next reading (a zero-order hold); an adaptive integrator ends a step at each reading.

- `actuator` (the default), a current-limited DC motor with a speed limit: its torque-speed
  line v0 (1 - F / F_g) runs from the no-load speed v0 to the stall force, the grasp load F_g
  (the current limit, through the transmission), and a speed loop caps it at the closing speed
  v_c. The fingers close at v_c while F <= slowdown F_g (v0 = v_c / (1 - slowdown)), slow down
  along the line above it, and stop at F_g; the motor presses at most F_g, and a load above it
  is carried by the self-locking transmission. The speed is a continuous function of the load.
- `relay`, the earlier model, kept for comparison: the fingers close at v_c until F reaches
  F_g, then stop dead, and close again at v_c once F falls below `resume_fraction` of F_g.

Only the active grasp's drive moves; the others hold.
"""

from __future__ import annotations

from ..jit import njit

#: The drive laws, by their scenario names; DriveParams names its own by its index here.
DRIVES = ("actuator", "relay")
ACTUATOR, RELAY = DRIVES.index("actuator"), DRIVES.index("relay")
#: A step ending within this share of a controller period before the drive is due ends at
#: its due time: the steps' times carry round-off.
DUE_ROUND_OFF = 1e-9


@njit
def actuator_speed(p, load, stiffness, damping, speed, h):
    """The actuator's closing speed (m/s) for a step of h (s): the speed v at which its law
    v = min(v_c, v0 (1 - F / F_g)), never negative, holds with the load the step will end
    at, F = load + damping (v - speed) + stiffness h v (N), linearised about the last
    evaluation's load, made at the closing speed `speed`, with its slopes in the finger's
    advance (stiffness, N/m) and speed (damping, N s/m).

    Taken at the last load alone (explicitly), the law would be a stiff feedback loop: a
    contact's slopes turn the speed the load allows within microseconds, and the damping's
    share at once, so that explicit decisions overshoot and alternate between stop and
    closing. At the step's end (implicitly, as backward Euler) the load approaches the grasp
    load without overshoot at any step; as h -> 0 with the slopes the law itself.
    """
    unloaded = 1.0 - (load - damping * speed) / p.grasp_load
    v = p.no_load_speed * unloaded / (1.0 + p.no_load_speed * (damping + stiffness * h) / p.grasp_load)
    return min(p.closing_speed, max(0.0, v))


@njit
def grasp_force(m, d, ee):
    """The grasp force on end-effector ee's drive at the last evaluation: the mean of its
    fingers' loads along their opening axes (N), and of their slopes in the fingers' advance
    (N/m) and speed (N s/m); zeros without fingers."""
    force = stiffness = damping = 0.0
    n = 0
    for i in range(m.fingers.drive.shape[0]):
        if m.fingers.drive[i] == ee:
            force += d.loads.finger_load[i]
            stiffness += d.loads.finger_stiffness[i]
            damping += d.loads.finger_damping[i]
            n += 1
    return (force / n, stiffness / n, damping / n) if n else (0.0, 0.0, 0.0)


@njit
def current_speed(m, d):
    """The active drive's closing speed in the coming step, m/s (0 without fingers)."""
    ee = m.grasps.ee[d.active]
    for i in range(m.fingers.drive.shape[0]):
        if m.fingers.drive[i] == ee:
            return -d.opening_rate[i]
    return 0.0


@njit
def closing_speed(m, d, ee, h):
    """Stage decision: end-effector ee's closing speed for a coming step of h (s), m/s, from
    the last evaluation's grasp force, by its drive law (the relay updates its state)."""
    p = m.drive
    force, stiffness, damping = grasp_force(m, d, ee)
    if p.law == ACTUATOR:
        return actuator_speed(p, force, stiffness, damping, current_speed(m, d), h)
    if force >= p.grasp_load:
        d.stalled[ee] = True
    elif force < p.resume_fraction * p.grasp_load:
        d.stalled[ee] = False
    return 0.0 if d.stalled[ee] else p.closing_speed


@njit
def _decide(m, d, t, horizon):
    """The active drive's decision at time t (s), from the last evaluation's finger loads:
    its fingers' rates until it is next due, `horizon` (s) later. Returns its speed before
    and after (m/s)."""
    d.drive_t = t + horizon
    ee = m.grasps.ee[d.active]
    before = current_speed(m, d)
    speed = closing_speed(m, d, ee, horizon)
    for i in range(m.fingers.drive.shape[0]):
        if m.fingers.drive[i] == ee:
            d.opening_rate[i] = -speed
    return before, speed


@njit
def finger_drive(m, d, h):
    """Stage, after a step of h (s) from d.t: d.drive_power, the power the drives put in
    during it (at its finger rates); then, if the active drive's controller is due (the step
    ends at or past d.drive_t), its decision (`_decide`) for a controller period, or the
    step if longer.

    The grasp counts the drive's resumes (closing again at more than half its closing speed
    after it had stopped) and its largest speed change from one decision to the next."""
    power = 0.0  # a bound: each finger's load along its axis times its sliding speed
    for i in range(d.opening_rate.shape[0]):
        power += d.loads.finger_load[i] * abs(d.opening_rate[i])
    d.drive_power = power
    t = d.t + h
    if t < d.drive_t - DUE_ROUND_OFF * m.drive.period:
        return
    before, speed = _decide(m, d, t, max(m.drive.period, h))
    g = d.active
    d.drive_jump[g] = max(d.drive_jump[g], abs(speed - before))
    if before == 0.0:
        d.drive_stopped[g] = True
    if d.drive_stopped[g] and speed > 0.5 * m.drive.closing_speed:
        d.drive_resumes[g] += 1
        d.drive_stopped[g] = False


@njit
def start_drive(m, d):
    """The active drive's first decision, now (a run's or a weld's start): its start, not a
    change of speed, so nothing is counted."""
    _decide(m, d, d.t, m.drive.period)


@njit
def move_fingers(d, h):
    """Slide every finger by its rate over h (s)."""
    for i in range(d.opening.shape[0]):
        d.opening[i] += h * d.opening_rate[i]
