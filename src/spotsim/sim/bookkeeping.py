"""Stage: what a run keeps of each step: counts, the active grasp's peaks, the drives' work and
the external impulse on the floating branches (for the momentum balance)."""

from __future__ import annotations

import math

from ..jit import njit
from ..linalg import cross, mv
from ..tables import COMPLETE
from .actuation import current_speed, motor_records
from .dynamics import table_load


@njit
def raise_peaks(m, d):
    """Raise the active grasp's peaks to include the last step's contact wrench and pairs, and
    on the air-bearing table what the floating branches' contact wrenches press into it."""
    g = d.active
    f, tau = d.summary.force_A, d.summary.torque_A
    for a in range(3):
        d.peak_force[g, a] = max(d.peak_force[g, a], abs(f[a]))
        d.peak_torque[g, a] = max(d.peak_torque[g, a], abs(tau[a]))
    d.peak_force_norm[g] = max(d.peak_force_norm[g], math.sqrt(f[0] ** 2 + f[1] ** 2 + f[2] ** 2))
    d.peak_torque_norm[g] = max(d.peak_torque_norm[g], math.sqrt(tau[0] ** 2 + tau[1] ** 2 + tau[2] ** 2))
    d.peak_pairs[g] = max(d.peak_pairs[g], d.contacts.key.shape[0])
    for b in range(m.branches.joint.shape[0]):
        if m.branches.planar[b]:
            force, moment = table_load(m, d, b)
            d.peak_table_force[g] = max(d.peak_table_force[g], force)
            d.peak_table_moment[g] = max(d.peak_table_moment[g], moment)


@njit
def bookkeeping(m, d, h):
    """Stage: count the step of h (s), raise the peaks, add the drives' work and the external
    impulse: the contact forces from bodies that do not float (a fixed base and the fingers on
    it; between floating branches every contact force is internal) and gravity, at the poses
    of the step's last force evaluation, over the span its velocity update gave them (h; with
    staggered kicks, `integrators.kick_of`)."""
    kick = d.kick if m.integrator.staggered else h
    if current_speed(m, d) != 0.0:
        d.held = False
    n = d.contacts.key.shape[0]
    d.steps += 1
    d.pair_steps += n
    d.drive_work += h * d.drive_power
    motor_records(m, d, h)
    g = d.active
    if n and not (d.phase[g] == COMPLETE and d.t > d.t_complete[g]):  # not after it (`completion.record_after`)
        raise_peaks(m, d)
    if m.limits.external_contact:
        for i in range(3):
            d.impulse_W[i] += kick * d.external_force_W[i]
            d.impulse_moment_O_W[i] += kick * d.external_torque_O_W[i]
    if m.gravity_W[0] != 0.0 or m.gravity_W[1] != 0.0 or m.gravity_W[2] != 0.0:
        for j in range(1, m.tree.parent.shape[0]):
            if m.tree.free[j]:
                r_G = d.p_W[j] + mv(d.R_W[j], m.tree.lever[j])
                d.impulse_W[:] += kick * m.tree.mass[j] * m.gravity_W
                d.impulse_moment_O_W[:] += kick * cross(r_G, m.tree.mass[j] * m.gravity_W)
