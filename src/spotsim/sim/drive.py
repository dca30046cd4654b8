"""Stage: the finger drive (paper Sec. 2.4), one per end-effector.

A self-locking drive closes both fingers of its end-effector symmetrically (a linkage mirrors
them). It closes at the closing speed until the grasp force, the mean of its fingers' contact
loads along their opening axes, reaches the grasp load; it then holds until the grasp force
falls below `resume_fraction` of the grasp load. The hysteresis keeps a stalled drive from
chattering between closing and holding. Only the active grasp's drive moves; the others hold.
"""

from __future__ import annotations

from ..jit import njit


@njit
def finger_drive(m, d):
    """Stage: d.drive_power, the power the drives put in during the step just taken (its
    finger rates), then the active drive's finger rates for the coming step from the step's
    finger loads."""
    power = 0.0  # a bound: each finger's load along its axis times its sliding speed
    for i in range(d.opening_rate.shape[0]):
        power += d.loads.finger_load[i] * abs(d.opening_rate[i])
    d.drive_power = power
    ee = m.grasps.ee[d.active]
    force, n = 0.0, 0
    for i in range(m.fingers.drive.shape[0]):
        if m.fingers.drive[i] == ee:
            force += d.loads.finger_load[i]
            n += 1
    if n == 0:
        return
    force /= n
    if force >= m.drive.grasp_load:
        d.stalled[ee] = True
    elif force < m.drive.resume_fraction * m.drive.grasp_load:
        d.stalled[ee] = False
    closing = 0.0 if d.stalled[ee] else -m.drive.closing_speed
    for i in range(m.fingers.drive.shape[0]):
        if m.fingers.drive[i] == ee:
            d.opening_rate[i] = closing


@njit
def move_fingers(d, h):
    """Slide every finger by its rate over h (s)."""
    for i in range(d.opening.shape[0]):
        d.opening[i] += h * d.opening_rate[i]
