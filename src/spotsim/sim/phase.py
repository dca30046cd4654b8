"""Stage: the grasp phase, approach -> self-centring -> complete (paper Sec. 3.2 step 3).

A grasp is complete when, for `hold_s` without a break, its finger drive presses at the grasp
load and has come to rest (its fingers close no faster than the contact speed limit: the
actuator within that speed's share of its torque-speed line below the grasp load, the relay
stalled; a motor drive's transmission stuck with its motor at its current limit), every
active contact's relative speed is below the contact speed limit, and the net contact force
on the module is below the net force limit: the paper's rule (Sec. 3.2 step 3, Sec. 5.1;
model.md Sec. 6). On the air-bearing table the net force is its part in the table's
plane: the table reacts the rest. A compliant arm's hand rings on its joints' springs, and
the contacts carry the module along: the net force is then taken in the hand's motion
relative to the arm's base (`held_force`), the force that moves the module in the hand.
"""

from __future__ import annotations

import math

from ..contact.wrenches import grasp_axis, net_force
from ..jit import njit
from ..linalg import add3, dot3, mv3, sub3
from ..tables import APPROACH, COMPLETE, MOTOR, SELF_CENTRING, STUCK
from .actuation import current_speed
from .tree import point_acceleration

#: The hold is complete within this of hold_s, s: the steps' times carry round-off.
HOLD_ROUND_OFF_S = 1e-12


@njit
def held_force(m, d):
    """The combined contact force on the active grasp's module in O_a (d.summary's), less what
    carries it along with its hand's motion on the arm's joints: its mass times its hand's
    acceleration at its centroid relative to the arm's base (the fixed world, or the
    free-flying robot's root body). With rigid arms the hand is the base's own body: the
    force as it is."""
    g = d.active
    f = d.summary.force_A
    hand = m.grasps.ee_joint[g]
    b = m.tree.branch[hand]
    base = m.branches.joint[b] if hand and m.branches.floating[b] else 0
    if hand == base:
        return f
    j = m.grasps.module_joint[g]
    c = add3(mv3(d.R_W[j], (m.tree.lever[j, 0], m.tree.lever[j, 1], m.tree.lever[j, 2])),
             (d.p_W[j, 0], d.p_W[j, 1], d.p_W[j, 2]))
    a = sub3(point_acceleration(m, d, hand, c), point_acceleration(m, d, base, c))
    mass = m.tree.mass[j]
    return (f[0] - mass * dot3(grasp_axis(m, d, g, 0), a), f[1] - mass * dot3(grasp_axis(m, d, g, 1), a),
            f[2] - mass * dot3(grasp_axis(m, d, g, 2), a))


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
    return pressing, d.summary.max_speed <= c.max_contact_speed, net_force(m, d, held_force(m, d)) <= c.max_net_force


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
