"""One force evaluation: the contact stages of the paper's Fig. 5, in order, and the actuators.

kinematics -> sphere pairs -> pair forces -> wrenches (-> what the step watches) -> tethers ->
actuators.
Every integrator evaluates the forces through `forces` (`sim.integrators`); at a state whose
pairs were just found, with only velocities changed (a controller's impulse), through its last
stages alone (`contact_forces`): the pairs depend on the poses alone.
"""

from __future__ import annotations

from ..contact.forces import pair_forces
from ..contact.search import find_pairs
from ..contact.wrenches import body_wrenches, contact_summary
from ..jit import njit
from .actuation import actuation
from .tether import tether_loads
from .tree import kinematics


@njit
def forces(m, d, h, jump):
    """The contact wrenches and the actuated joints' loads at d's state (q, v), the bristles
    bent over h (s) from d.memory, which is left as it is. `jump`: a controller changed the
    prescribed joints' speeds since the memory's evaluation, and h is the step to come
    (`friction.bristle`). Returns how many saturated pairs held a share of h (`pair_forces`)."""
    kinematics(m, d)  # Eq. (1): the bodies' poses and velocities
    find_pairs(m, d)  # Eq. (6)-(10): culled, or the paper's literal all-pairs search
    return contact_forces(m, d, h, jump)


@njit
def contact_forces(m, d, h, jump):
    """`forces`' stages after the search: the wrenches of d.candidates at d's kinematics, the
    bristles bent over h (s) from d.memory (`forces`), and the actuation stage; returns `forces`'."""
    shared = pair_forces(m, d, h, jump)  # Eq. (11)-(17), per pair
    body_wrenches(m, d)  # Eq. (18)-(21), one wrench per body
    contact_summary(m, d)  # the active module's wrench in O_a, the fastest and deepest pair
    tether_loads(m, d)  # the cords' pulls, after the summary: they are not contact
    actuation(m, d)  # the actuated joints' loads and forces
    return shared
