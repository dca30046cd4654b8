"""One simulation step, the paper's Fig. 5 in order, and the bound on how far it moves things.

    integrate: kinematics -> sphere pairs -> pair forces -> wrenches -> actuators -> dynamics -> update
    controllers -> grasp phase -> bookkeeping

The integrator evaluates the forces and the dynamics where its scheme needs them
(`sim.integrators`); the rest runs once per step, after it.
"""

from __future__ import annotations

from ..jit import njit
from ..tables import SYMPLECTIC_EULER
from .actuation import drive_power, sample_controllers
from .bookkeeping import bookkeeping
from .integrators import integrate
from .phase import grasp_phase
from .tree import travel_rate

#: Free flight takes the travel bound at the start of a step times this for the whole step: in
#: zero gravity and without contact the centroid velocities are constant and the fingers close
#: at their set speed; only the spin's direction changes, and bodies are barely moving then.
FREE_FLIGHT_SAFETY = 2.0


@njit
def step(m, d, h):
    """One step of at most h (s): returns the step taken (an adaptive integrator may take
    less), or 0.0 if its step fell below its least size (the run has diverged)."""
    t0 = d.t
    d.drive_power = drive_power(m, d)  # at the speeds the drives hold through the step
    h = integrate(m, d, h)  # forces (Eq. 1-21) -> actuators -> accelerations (Eq. 22-23) -> update
    if h == 0.0:
        return 0.0
    if m.integrator.method != SYMPLECTIC_EULER:  # symplectic Euler samples them inside, velocity first
        sample_controllers(m, d, t0 + h, h)  # the due drive sets its fingers' speed for the coming period
    d.t += h
    d.travel += h * travel_rate(m, d)
    grasp_phase(m, d)  # approach -> self-centring -> complete
    bookkeeping(m, d, d.t - t0 if m.integrator.adaptive else h)
    return h


@njit
def free_flight(m, d):
    """Whether no sphere pair can come into contact within the next record interval, so that
    one step of it (no contact forces, zero gravity) is exact for the centroids: coal's face
    pairs are all beyond its margin and the travel bound over the interval keeps within the
    skin. Never with the literal search, gravity or the joints' springs and dampers (compliant
    arms), whose forces act in flight too."""
    if m.literal or m.gravity_W[0] != 0.0 or m.gravity_W[1] != 0.0 or m.gravity_W[2] != 0.0:
        return False
    t = m.tree
    for k in range(t.stiffness.shape[0]):
        if t.stiffness[k] != 0.0 or t.damping[k] != 0.0:
            return False
    return d.near.shape[0] == 0 and d.travel + FREE_FLIGHT_SAFETY * m.dt * travel_rate(m, d) <= m.limits.skin
