"""Stage: the grasp phase, approach -> self-centring -> complete (paper Sec. 3.2 step 3).

A grasp is complete when, for `hold_s` without a break, its finger drive presses at the grasp
load and has come to rest (its fingers close no faster than the contact speed limit: the
actuator within that speed's share of its torque-speed line below the grasp load, the relay
stalled; a motor drive's transmission stuck with its motor at its current limit), every
active contact's relative speed is below the contact speed limit, and the net contact force
on the module is below the net force limit: the paper's rule (Sec. 3.2 step 3, Sec. 5.1;
model.md Sec. 6). On the air-bearing table the net force is its part in the table's
plane: the table reacts the rest.
"""

from __future__ import annotations

import math

from ..contact.wrenches import net_force
from ..jit import njit
from ..tables import APPROACH, COMPLETE, MOTOR, SELF_CENTRING, STUCK
from .actuation import current_speed

#: The hold is complete within this of hold_s, s: the steps' times carry round-off.
HOLD_ROUND_OFF_S = 1e-12


@njit
def completion_checks(m, d):
    """Whether each completion criterion holds at the last step: the drive at rest pressing,
    the contact speeds and the net force on the module within their limits."""
    c = m.completion
    ee = m.grasps.ee[d.active]
    p = m.drives
    if p.law[ee] == MOTOR:
        # stuck, the motor pressing at its current limit (or at what the supply drives at rest): the
        # speed loop's own clamp, not a current compared with V / R, which the back-EMF of a finger
        # speed left by round-off puts an ulp either side of
        pressing = d.transmission[ee] == STUCK and d.saturated[ee]
    else:
        pressing = current_speed(m, d) <= c.max_contact_speed
    return pressing, d.summary.max_speed <= c.max_contact_speed, net_force(m, d) <= c.max_net_force


@njit
def grasp_phase(m, d):
    """Stage: advance the active grasp's phase on the last step's contacts."""
    g, t = d.active, d.t
    n_pairs = d.contacts.key.shape[0]
    if d.phase[g] == APPROACH and n_pairs > 0:
        d.phase[g] = SELF_CENTRING
        d.t_contact[g] = t
    if d.phase[g] != SELF_CENTRING:
        return
    pressing, slow, balanced = completion_checks(m, d)
    if n_pairs > 0 and pressing and slow and balanced:
        if math.isnan(d.held_since):
            d.held_since = t
        if t - d.held_since >= m.completion.hold_s - HOLD_ROUND_OFF_S:
            d.phase[g] = COMPLETE
            d.t_complete[g] = t
    else:
        d.held_since = math.nan


def completion_criteria(model, data) -> dict[str, bool]:
    """Each completion criterion, labelled, and whether it holds at data's last step (for
    messages)."""
    c = model.sim.completion
    drive = ("finger drive stuck, its motor at its current limit" if model.scenario.end_effector.drive == "motor"
             else f"finger drive at rest (<= {c.max_contact_speed:g} m/s) at the grasp load")
    labels = (drive,
              f"contact speeds <= {c.max_contact_speed:g} m/s", f"net contact force <= {c.max_net_force:g} N")
    return dict(zip(labels, (bool(x) for x in completion_checks(model.sim, data)), strict=True))
