"""Time integrators, compiled: each advances d by one step over (q, v) through the same stages.

An integrator is one function `f(m, d, h) -> h_taken` that evaluates the forces
(`sim.forces`) and the accelerations (`sim.dynamics.accelerations`) where its scheme needs
them, commits the pair memory of the state it ends at, updates (q, v), and sets the step's
mean external wrench on the floating branches (for the momentum balance). `integrate`
dispatches on the model's method; a new integrator is one more such function and its code.

- `symplectic_euler`: the paper's explicit fixed step.
- `adaptive_euler`: symplectic Euler with its error controlled by an embedded estimate
  (Euler against Heun's trapezoid, from the end's forces, which start the next step), and,
  optionally, its steps cut where a bristle's damping switches on or off.
- `rk4`, `dopri5`: explicit Runge-Kutta, fixed and error-controlled.

Revolute and prismatic joints advance their coordinates as `pin.integrate` does (q + h v). A
floating root (a free-flyer or a planar joint on the universe) turns by the exponential of
its angular velocity, as `pin.integrate` turns it, but it carries its whole branch (a robot
and its fingers, a module), and the integrators advance that branch's centroid in the world
frame instead of the root's origin (`place_branch`; a planar branch's stays in its plane):
contact forces come in equal and opposite pairs and the joints' forces are internal, so the
sum of the branches' momentum rates is zero to round-off and the total linear momentum, and
the system's centroid velocity, stay exact. `pin.integrate`'s body-frame twist does not keep
them: its error grows with (omega h)^2.
"""

from __future__ import annotations

import math

import numpy as np

from ..contact.forces import commit_memory, point_velocity
from ..contact.search import LIST_SKIN
from ..jit import njit, njit_inline
from ..linalg import add3, axpy3, cross3, mv3, mv9, put3, quat_times_exp4, sub3
from ..tables import ADAPTIVE_EULER, FREE_FLYER, METHODS, MOTOR, SYMPLECTIC_EULER
from .actuation import sample_controllers
from .dynamics import accelerations
from .forces import contact_forces, forces
from .tree import (
    branch_centroid,
    frame_of,
    frames_at,
    joint_motion,
    joint_quat,
    joint_twist,
    kinematics,
    put_root,
    root_rotation9,
    travel_rate,
)

#: An adaptive step grows at most, and shrinks at least, by these factors per try; its error
#: ratio r scales it by SAFETY r^(-1/p) in between, p the order of its local error estimate
#: (Hairer, Norsett and Wanner, II.4): 5 for dopri5, 2 for adaptive_euler.
GROW_MAX, SHRINK_MIN, SAFETY = 5.0, 0.2, 0.9
#: adaptive_euler with its bristle switches located (`switch_fraction`): a try in which a
#: bristle saturates or lets go earlier than SWITCH_WINDOW of the step from its end is tried
#: again to end just past the switch, if the switch's damping impulse c_b |v| h (1 - theta)
#: would move the lightest floating branch by more than SWITCH_SHARE of the velocity tolerance
#: (a switch misplaced within a step always errs the same way, so its share is kept small);
#: a switch within SWITCH_FLOOR (s) of the step's start is taken as at its start.
SWITCH_WINDOW, SWITCH_SHARE, SWITCH_FLOOR = 0.1, 0.1, 1e-8
#: Numbers per floating root in a Runge-Kutta state: its branch's centroid (world), the root's
#: quaternion, the centroid's velocity (world), the root's angular velocity (its frame); and
#: per revolute or prismatic joint: its coordinate and its speed.
ROOT_STATE, JOINT_STATE = 13, 2


def state_size(tree, branches) -> int:
    """The length of a Runge-Kutta state of a tree (`pack`)."""
    return ROOT_STATE * int(np.sum(branches.floating)) + JOINT_STATE * len(tree.internal)


@njit_inline
def integrate(m, d, h):
    """One step of at most h (s) by the model's integrator: the step taken, s, or 0.0 if an
    adaptive step fell below its least size (the run has diverged)."""
    if m.integrator.method == SYMPLECTIC_EULER:
        symplectic_euler(m, d, h)
        return h
    if m.integrator.method == ADAPTIVE_EULER:
        return adaptive_euler(m, d, h)
    return runge_kutta(m, d, h)


# ------------------------------------------------------------------------------- branches


@njit_inline
def branch_force(m, d, b):
    """The force that moves floating branch b's centroid (world, N, a 3-tuple): its contact
    forces and gravity; on the air-bearing table their part in its plane (the table reacts
    the rest)."""
    br = m.branches
    g, M = br.gravity_W[b], br.mass[b]
    F0, F1, F2 = M * g[0], M * g[1], M * g[2]
    for i in range(br.first[b], br.stop[b]):
        j = br.members[i]
        F0 += d.loads.force_W[j, 0]
        F1 += d.loads.force_W[j, 1]
        F2 += d.loads.force_W[j, 2]
    if br.planar[b]:
        n = m.table_normal
        along = F0 * n[0] + F1 * n[1] + F2 * n[2]
        F0, F1, F2 = F0 - along * n[0], F1 - along * n[1], F2 - along * n[2]
    return F0, F1, F2


@njit_inline
def _root_spin(t, j, v):
    """A floating root's angular velocity, its frame (a planar joint's about its z)."""
    return joint_twist(t, j, v)[1]


@njit_inline
def branch_offset(m, d, b):
    """Floating branch b's centroid relative to its root's origin, and the velocity its
    internal joints give it, both in the root's frame (3-tuples), at (d.q, d.v): the centroid
    is at p + R c and moves at v_O + omega x (R c) + R u, for the root at p, turned by R,
    moving at v_O and turning at omega (world). Uses d.now: the branch's kinematics with its
    root at rest at the origin (`tree.frame_of`)."""
    t, br = m.tree, m.branches
    j0 = br.joint[b]
    if br.stop[b] == br.first[b] + 1:  # one body (a module): branch_centroid's sums, its frame at rest at the origin
        M, mass, lever = br.mass[b], t.mass[j0], t.lever[j0]
        return ((mass * lever[0]) / M, (mass * lever[1]) / M, (mass * lever[2]) / M), (0.0, 0.0, 0.0)
    f = d.now
    R_W, p_W, w_W, vo_W = f.R_W, f.p_W, f.w_W, f.vo_W
    for a in range(3):
        for k in range(3):
            R_W[j0, a, k] = 1.0 if a == k else 0.0
        p_W[j0, a] = w_W[j0, a] = vo_W[j0, a] = 0.0
    for i in range(br.first[b] + 1, br.stop[b]):
        frame_of(t, br.members[i], d.q, d.v, R_W, p_W, w_W, vo_W)
    return branch_centroid(m, f, b)


@njit_inline
def root_frame(m, d, b):
    """Floating branch b's root at (d.q, d.v): its rotation in the world (a 9-tuple), its
    origin and the origin's velocity (world, 3-tuples) and its angular velocity (its frame)."""
    t, j = m.tree, m.branches.joint[b]
    R = root_rotation9(t, j, joint_quat(t, j, d.q))
    _, pJ = joint_motion(t, j, d.q)
    vJ, wJ = joint_twist(t, j, d.v)
    return R, add3(mv3(t.R_P[j], pJ), t.p_P[j]), mv9(R, vJ), wJ


@njit_inline
def root_offset(m, d, b, R, w):
    """Where floating branch b's centroid lies from its root's origin (world, m) and how fast
    it moves relative to it (m/s), its root turned by R (a 9-tuple) and turning at w (its
    frame), its other joints as (d.q, d.v) hold them (`branch_offset`): two 3-tuples."""
    c_rel, u_rel = branch_offset(m, d, b)
    r = mv9(R, c_rel)
    return r, add3(cross3(mv9(R, w), r), mv9(R, u_rel))


@njit_inline
def branch_state(m, d, b):
    """Floating branch b's centroid (world) and the velocity of it, 3-tuples, at (d.q, d.v)."""
    R, p, vo, w = root_frame(m, d, b)
    r, u = root_offset(m, d, b, R, w)
    return add3(p, r), add3(vo, u)


#: A reference state of a floating root's branch that `place_branch` moves from: the root's
#: origin and its velocity, the branch's centroid and its velocity, and the root's offset
#: (`root_offset`), all world, 3-tuples each; from nothing (all zero), the placement is absolute.
NO_REFERENCE = ((0.0, 0.0, 0.0),) * 6


@njit_inline
def place_branch(m, d, b, c, u, quat, w, ref):
    """Write floating branch b's root at the unit quaternion quat (x, y, z, w) of its joint,
    turning at w (its frame), and at the origin and velocity that put the branch's centroid at
    c moving at u (world, 3-tuples), its other joints as (d.q, d.v) hold them: the centroid is
    affine in the root's origin and the momentum in its velocity, both with coefficient one.
    The root moves from the reference state ref (`NO_REFERENCE`) by the centroid's change less
    its offset's, so that a branch at rest stays where it is to the bit."""
    t = m.tree
    j = m.branches.joint[b]
    R = root_rotation9(t, j, quat)
    r, u0 = root_offset(m, d, b, R, w)
    p_ref, vo_ref, c_ref, u_ref, r_ref, u0_ref = ref
    origin = add3(p_ref, sub3(sub3(c, c_ref), sub3(r, r_ref)))
    vo = add3(vo_ref, sub3(sub3(u, u_ref), sub3(u0, u0_ref)))
    put_root(t, j, d.q, d.v, R, origin, quat, vo, w)
    return r, u0


# ------------------------------------------------------------------------- symplectic Euler


@njit_inline
def _advance_joints(m, d, b, h, kick, first):
    """The revolute and prismatic joints of branch b from its `first` member on: v += kick a,
    then q += h v."""
    t, br = m.tree, m.branches
    for i in range(br.first[b] + first, br.stop[b]):
        j = br.members[i]
        iv = t.idx_v[j]
        d.v[iv] += kick * d.a[iv]
        d.q[t.idx_q[j]] += h * d.v[iv]


@njit
def _euler_update(m, d, h, kick):
    """Every joint's symplectic Euler step of h (s) from (q, v), in place, with the
    accelerations d.a of the last evaluation (made at q, at v before any controller's impulse
    since): velocities first, by kick (s) of them, then positions with the new velocities. A
    floating branch's centroid moves on its momentum (v_c += kick F / M, x_c += h v_c) and its
    root turns by exp(h omega)."""
    t, br = m.tree, m.branches
    # a free-flying root's offset as the last update placed it, if nothing moved since: the
    # same numbers root_offset gives (its quaternion and spin are stored as they were given)
    placed = d.placed[0] and _unchanged(d.q, d.placed_q) and _unchanged(d.v, d.placed_v)
    for b in range(br.joint.shape[0]):
        if not br.floating[b]:
            _advance_joints(m, d, b, h, kick, 0)
            continue
        j = br.joint[b]
        R0, p0, vo0, w0 = root_frame(m, d, b)
        if placed and t.kind[j] == FREE_FLYER:
            o = d.placed_offset[b]
            r0, u00 = (o[0], o[1], o[2]), (o[3], o[4], o[5])
        else:
            r0, u00 = root_offset(m, d, b, R0, w0)  # before its joints move
        c0, u0 = add3(p0, r0), add3(vo0, u00)
        _advance_joints(m, d, b, h, kick, 1)
        F, M = branch_force(m, d, b), br.mass[b]
        u = (u0[0] + kick * (F[0] / M), u0[1] + kick * (F[1] / M), u0[2] + kick * (F[2] / M))
        c = axpy3(h, u, c0)
        w = axpy3(kick, _root_spin(t, j, d.a), w0)
        # a unit quaternion, or the round-off in R compounds from step to step
        quat = quat_times_exp4(joint_quat(t, j, d.q), h * w[0], h * w[1], h * w[2])
        r, u_off = place_branch(m, d, b, c, u, quat, w, (p0, vo0, c0, u0, r0, u00))
        for a in range(3):
            d.placed_offset[b, a], d.placed_offset[b, 3 + a] = r[a], u_off[a]
    d.placed_q[:] = d.q
    d.placed_v[:] = d.v
    d.placed[0] = True


@njit_inline
def _unchanged(x, before):
    """Whether x holds the values of before, every one."""
    for i in range(x.shape[0]):
        if x[i] != before[i]:
            return False
    return True


@njit
def symplectic_euler(m, d, h):
    """Semi-implicit Euler, the paper's fixed-step explicit scheme: forces and accelerations
    at the step's start, velocities first, then positions with the new velocities. Velocity
    first also for the controllers that prescribe their fingers' speed: those due at the
    step's end read the start's loads and set the speeds the step's position update uses
    (`actuation.sample_controllers`). A motor drive prescribes nothing: it reads the step's
    end, as after any other integrator's step (its encoder reads the opening at its reading's
    time)."""
    forces(m, d, h, d.jumped)
    d.jumped = False
    commit_memory(d)
    accelerations(m, d)
    motor = m.drives.law[m.grasps.ee[d.active]] == MOTOR
    if not motor:
        sample_controllers(m, d, d.t + h, h)
    _euler_update(m, d, h, h)
    if motor:
        sample_controllers(m, d, d.t + h, h)
    d.external_force_W[:] = d.loads.external_force_W
    d.external_torque_O_W[:] = d.loads.external_torque_O_W
    d.evaluations += 1
    d.accepted += 1


# ------------------------------------------------------------------- adaptive symplectic Euler


@njit_inline
def evaluated_here(d):
    """Whether d's last force evaluation was made at its present state (a kept step's end, the
    next step's first stage)."""
    return d.fsal and d.fsal_t == d.t


@njit
def onset_step(m, d):
    """The longest step adaptive_euler's onset guard allows at d's state, s: while a pair may
    start (coal keeps face pairs within its margin), a step moves no two spheres closer by
    more than the onset depth, so that a pair that starts during a step sinks no deeper into
    it before the error estimate sees its force, at the bound on any two spheres' approach
    (`tree.travel_rate`). With `onset_clearance`, where the last search was made at this state
    (the step's first stage), by more than the clearance of the pairs not in contact
    (`Candidates.clearance`) plus the onset depth, at the bound on the approach of the spheres
    of its face pairs (`approach_rate`). inf when no pair can start."""
    if not m.literal and d.near.shape[0] == 0:
        return math.inf
    rate, clearance = travel_rate(m, d), 0.0
    if m.integrator.onset_clearance and not m.literal and evaluated_here(d):
        rate, clearance = min(rate, approach_rate(m, d)), d.candidates.clearance
    return (clearance + m.integrator.onset_depth) / rate if rate > 0.0 else math.inf


@njit
def approach_rate(m, d):
    """A bound on how fast a master and a slave sphere of any face pair in d.near that may
    start touching within a step approach each other, m/s, at d's kinematics: per face pair,
    the relative velocity of its two bodies at its master spheres' centre, plus their relative
    turn times the master spheres' spread about it, plus the slave body's turn times the
    distance of such a pair: the search's cutoff (off the ball regime a pair may touch with its
    centres that far apart; r1 + r2 in it, if larger) plus what the step may close
    (`Candidates.clearance` is at most LIST_SKIN, plus the onset depth)."""
    faces = m.faces
    reach = max(m.law.cutoff, m.law.r1 + m.law.r2) + LIST_SKIN + m.integrator.onset_depth
    rate = 0.0
    for f in d.near:
        jm, js = faces.master_joint[f], faces.slave_joint[f]
        c = add3(mv3(d.R_W[jm], faces.master_centre_J[f]), (d.p_W[jm, 0], d.p_W[jm, 1], d.p_W[jm, 2]))
        rel = sub3(point_velocity(d.vo_W[jm], d.w_W[jm], d.p_W[jm], c),
                   point_velocity(d.vo_W[js], d.w_W[js], d.p_W[js], c))
        turn = sub3((d.w_W[jm, 0], d.w_W[jm, 1], d.w_W[jm, 2]), (d.w_W[js, 0], d.w_W[js, 1], d.w_W[js, 2]))
        w_s = math.sqrt(d.w_W[js, 0] ** 2 + d.w_W[js, 1] ** 2 + d.w_W[js, 2] ** 2)
        rate = max(rate, math.sqrt(rel[0] ** 2 + rel[1] ** 2 + rel[2] ** 2)
                   + math.sqrt(turn[0] ** 2 + turn[1] ** 2 + turn[2] ** 2) * faces.master_radius[f] + w_s * reach)
    return rate


@njit
def error_rates(m, d, out):
    """What the adaptive Euler error compares at d's last evaluation, into out (n_rows, 6):
    per floating branch its centroid's acceleration (world) and its root's angular
    acceleration (its frame); per revolute or prismatic joint, its acceleration (column 3)."""
    t, br = m.tree, m.branches
    for b in range(br.joint.shape[0]):
        F, alpha = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
        if br.floating[b]:
            F, M = branch_force(m, d, b), br.mass[b]
            F = (F[0] / M, F[1] / M, F[2] / M)
            alpha = _root_spin(t, br.joint[b], d.a)
        for x in range(3):
            out[b, x] = F[x]
            out[b, 3 + x] = alpha[x]
    nb = br.joint.shape[0]
    for i in range(t.internal.shape[0]):
        for x in range(6):
            out[nb + i, x] = 0.0
        out[nb + i, 3] = d.a[t.idx_v[t.internal[i]]]


@njit
def euler_error(m, acc0, acc1, h):
    """The error ratio of a symplectic Euler step of h (s) whose start and end rates are acc0
    and acc1 (`error_rates`): the largest over its rows of its velocity error estimate h/2
    |a1 - a0| (Euler against Heun's trapezoid) at any contact sphere that row moves, which
    lies within its lever (of a branch's centroid; per unit of a joint's coordinate), over
    velocity_tol."""
    p = m.integrator
    ratio = 0.0
    for b in range(acc0.shape[0]):
        da = math.sqrt((acc1[b, 0] - acc0[b, 0]) ** 2 + (acc1[b, 1] - acc0[b, 1]) ** 2 + (acc1[b, 2] - acc0[b, 2]) ** 2)
        dalpha = math.sqrt((acc1[b, 3] - acc0[b, 3]) ** 2 + (acc1[b, 4] - acc0[b, 4]) ** 2 +
                           (acc1[b, 5] - acc0[b, 5]) ** 2)
        ratio = max(ratio, 0.5 * h * (da + p.lever[b] * dalpha) / p.velocity_tol)
    return ratio


@njit
def switch_fraction(m, before, after, h):
    """The earliest fraction of a try of h (s) at which a bristle switches its damping c_b v_t
    (saturates, or lets go), by linear interpolation of its slack (`friction.bristle`) from
    before (the committed memory, at the try's start) to after (its end's contacts); 1.0 if
    none does, or none whose misplaced damping impulse matters (SWITCH_SHARE). A pair in one
    of the two alone (sorted by key) has no switch to locate."""
    if m.law.bristle.c_b == 0.0:  # no damping to switch
        return 1.0
    theta = 1.0
    # the least relative speed (m/s) at which a switch misplaced by the rest of the step moves
    # the lightest body by SWITCH_SHARE of the tolerance
    speed = SWITCH_SHARE * m.integrator.velocity_tol * m.integrator.lightest / (m.law.bristle.c_b * h)
    j, n = 0, after.key.shape[0]
    for i in range(before.key.shape[0]):
        while j < n and after.key[j] < before.key[i]:
            j += 1
        if j < n and after.key[j] == before.key[i] and (before.slack[i] > 0.0) != (after.slack[j] > 0.0):
            at = before.slack[i] / (before.slack[i] - after.slack[j])
            if after.speed[j] * (1.0 - at) > speed:
                theta = min(theta, at)
    return theta


@njit_inline
def kick_of(m, d, h, here):
    """How long adaptive Euler's step of h (s) applies its start's forces to the velocities, s:
    h; with staggered kicks, from a start that is the last accepted step's end (`here`), the
    mean of that step and h. Symplectic Euler's velocities lie half a step behind its positions
    (it is the leapfrog scheme), so the velocity update between the half steps around the
    start spans (h_last + h) / 2: spanning h instead, each change of step puts (h - h_last) a / 2
    into the velocities, which the error estimate does not see. (Under a constant force, staggered
    kicks leave the positions off the exact motion by the first step's half alone, g t h_0 / 2,
    as at a fixed step h_0; kicks of h by g sum(h^2) / 2.) Not across a fresh start after a
    controller's impulse: its forces are applied back to the last step's middle."""
    if m.integrator.staggered and here and d.h_last > 0.0:
        return 0.5 * (d.h_last + h)
    return h


@njit
def end_forces(m, d, h):
    """The forces and accelerations at the end of adaptive Euler's try of h (s), its bristles
    bent over h from the memory (`forces`). With staggered kicks the state's velocities are
    the try's own, which lie h/2 behind its end (`kick_of`): read there, the contacts' normal
    damping lags the indentation by h/2, an error of the step's order that the error
    estimate does not see, and which raises an impact's peak. Their normal damping reads the
    indentation rate at the velocities brought level with the positions, v + h/2 a (the
    start's accelerations: to the step's order), whose kinematics d.now holds while d.lead
    is set (`pair_forces`); the bristles, whose deflection grows by the state's own motion,
    and the actuators read the state's own velocities."""
    if m.integrator.staggered:
        d.lead = 0.5 * h
        frames_at(m, d, d.v + d.lead * d.a)
    forces(m, d, h, np.bool_(False))
    accelerations(m, d)
    d.lead = 0.0


@njit
def adaptive_euler(m, d, h):
    """One accepted symplectic Euler step with its error controlled, of at most min(h, the
    onset guard): returns the step taken, or 0.0 if it fell below h_min.

    A try of h updates velocities then positions with the accelerations at the start, then
    evaluates the forces at its end (`end_forces`), bending the bristles over h from the memory; h/2 |a_end
    - a_start| (`euler_error`) estimates its error. A kept try commits the memory, and its end
    evaluation is the next step's start: one evaluation a try. A rejected one goes back to
    the start (state, contacts) and tries SAFETY r^(-1/2) of h. Prescribed joints keep their
    speed through the step; a new speed (a controller's impulse since the last evaluation)
    re-evaluates the start for each try, the committed bristles bent over it (as symplectic
    Euler's start bends them over its step; a bristle that the new speed's jump of the normal
    force lets hold damps for its share of the try, `friction.bristle`: a closed-form impulse,
    which the error estimate leaves out), so that a rejected try leaves no trace. Its pairs are those
    the last evaluation found at the same poses (`contact_forces`).

    With its bristle switches located (the model's `locate_switches`), a try in which a
    bristle saturates or lets go well before its end (`switch_fraction`) is tried again to end
    just past the switch: its damping c_b v_t then acts for the part of the step it should,
    where the start's forces would apply it (or not) for the whole step. Such a cut is not a
    rejection: the step after it may grow from the uncut try.
    """
    p = m.integrator
    h = min(h, onset_step(m, d))
    # a new finger rate (or no last evaluation to reuse): the start is evaluated for each try,
    # its bristles bent over the try from the committed memory, as symplectic Euler bends
    # them. A new rate changes the pairs' normal damping at once, and a sliding pair's
    # bristle left at its old limit would hold, adding c_b v_t for a whole step.
    here = evaluated_here(d)
    changed = d.jumped
    fresh = not here or changed
    acc, external = d.rates, d.start_external
    q0, v0, a0 = d.start_q, d.start_v, d.start_a
    q0[:], v0[:], a0[:] = d.q, d.v, d.a
    start = (d.candidates, d.contacts, d.loads, d.summary)  # put back after a rejection (a fresh start: its pairs)
    rejected = False
    h_free = 0.0  # the step the error control alone took, before a switch cut it
    while True:
        if fresh:
            if here:  # only velocities changed (a controller's impulse): the pairs found at this state stand
                kinematics(m, d)
                d.candidates = start[0]
                shared = contact_forces(m, d, h, changed)
            else:
                shared = forces(m, d, h, changed)
            accelerations(m, d)
            d.evaluations += 1
            error_rates(m, d, acc[0])
            if shared:
                # the damping that the new rate's jump lets a saturated bristle hold is its
                # closed-form impulse over the try (`friction.bristle`), not a force the step
                # samples: the step moves with it, and its error estimate compares the end
                # with the start without it
                with_share = (d.contacts, d.loads, d.summary, d.a.copy())
                contact_forces(m, d, h, np.bool_(False))
                accelerations(m, d)
                d.evaluations += 1
                error_rates(m, d, acc[0])
                d.contacts, d.loads, d.summary = with_share[:3]
                d.a[:] = with_share[3]
        elif not rejected:
            error_rates(m, d, acc[0])
        if fresh or not rejected:
            external[:3] = d.loads.external_force_W
            external[3:] = d.loads.external_torque_O_W
        kick = kick_of(m, d, h, here)
        _euler_update(m, d, h, kick)
        end_forces(m, d, h)
        d.evaluations += 1
        error_rates(m, d, acc[1])
        ratio = euler_error(m, acc[0], acc[1], h)
        theta = switch_fraction(m, d.memory, d.contacts, h) if p.locate_switches else 1.0
        early = theta < 1.0 - SWITCH_WINDOW and theta * h > SWITCH_FLOOR
        if ratio <= 1.0 and not early:
            grow = GROW_MAX if ratio == 0.0 else min(GROW_MAX, max(SHRINK_MIN, SAFETY / math.sqrt(ratio)))
            # no growth right after a rejection (Hairer, Norsett and Wanner, II.4); a step
            # cut at a switch does not hold back the next
            d.h_next = min(p.h_max, max(h * (min(grow, 1.0) if rejected else grow), h_free))
            break
        d.q[:], d.v[:] = q0, v0
        if not fresh:  # a fresh start is evaluated again for the next try
            d.a[:] = a0
            kinematics(m, d)
            d.candidates, d.contacts, d.loads, d.summary = start
        tried = h
        if ratio > 1.0:
            rejected = True
            d.rejected += 1
            h *= max(SHRINK_MIN, SAFETY / math.sqrt(ratio))
        if early:  # the next try ends just past the switch
            if ratio <= 1.0:
                h_free = tried
            d.cut += 1
            h = min(h, theta * (1.0 + 0.5 * SWITCH_WINDOW) * tried)
        if h < p.h_min:
            return 0.0
    commit_memory(d)
    d.accepted += 1
    d.kick, d.h_last = kick, h
    d.fsal, d.fsal_t = True, d.t + h
    d.jumped = False
    # the step's impulse is that of the start's forces (the velocity update's)
    d.external_force_W[:] = external[:3]
    d.external_torque_O_W[:] = external[3:]
    return h


# --------------------------------------------------------------------------- Runge-Kutta
# The Runge-Kutta state y: per floating root ROOT_STATE numbers (its branch's centroid and
# centroid velocity in the world, the root's unit quaternion and angular velocity), then per
# revolute or prismatic joint its coordinate and speed. Pairwise contact forces and internal
# joint forces keep the sum of the branches' momentum rates zero at every stage, so a linear
# combination of stages keeps the total linear momentum to round-off.


@njit
def pack(m, d):
    """The Runge-Kutta state y at (d.q, d.v). Uses d.now."""
    t, br = m.tree, m.branches
    y = np.empty(d.fsal_dy.shape[0])
    o = 0
    for b in range(br.joint.shape[0]):
        if not br.floating[b]:
            continue
        j = br.joint[b]
        c, u = branch_state(m, d, b)
        put3(y, o, c)
        quat = joint_quat(t, j, d.q)
        for i in range(4):
            y[o + 3 + i] = quat[i]
        put3(y, o + 7, u)
        put3(y, o + 10, _root_spin(t, j, d.v))
        o += ROOT_STATE
    for j in t.internal:
        y[o], y[o + 1] = d.q[t.idx_q[j]], d.v[t.idx_v[j]]
        o += JOINT_STATE
    return y


@njit
def unpack(m, d, y):
    """Write the state y into (d.q, d.v), in place; quaternions normalised."""
    t, br = m.tree, m.branches
    n_roots = 0
    for b in range(br.joint.shape[0]):
        n_roots += br.floating[b]
    o = ROOT_STATE * n_roots  # the joints first: a root is placed from them
    for j in t.internal:
        d.q[t.idx_q[j]], d.v[t.idx_v[j]] = y[o], y[o + 1]
        o += JOINT_STATE
    o = 0
    for b in range(br.joint.shape[0]):
        if not br.floating[b]:
            continue
        j = br.joint[b]
        norm = math.sqrt(y[o + 3] ** 2 + y[o + 4] ** 2 + y[o + 5] ** 2 + y[o + 6] ** 2)
        quat = (y[o + 3] / norm, y[o + 4] / norm, y[o + 5] / norm, y[o + 6] / norm)
        place_branch(m, d, b, (y[o], y[o + 1], y[o + 2]), (y[o + 7], y[o + 8], y[o + 9]), quat,
                     (y[o + 10], y[o + 11], y[o + 12]), NO_REFERENCE)
        o += ROOT_STATE


@njit
def derivative(m, d, y):
    """dy/dt at the state y = (d.q, d.v), given the accelerations d.a and the loads there."""
    t, br = m.tree, m.branches
    dy = np.empty_like(y)
    o = 0
    for b in range(br.joint.shape[0]):
        if not br.floating[b]:
            continue
        x, qy, z, qw = y[o + 3], y[o + 4], y[o + 5], y[o + 6]
        w0, w1, w2 = y[o + 10], y[o + 11], y[o + 12]
        dy[o:o + 3] = y[o + 7:o + 10]
        # q' = q (x) (omega, 0) / 2, omega in the root's frame
        dy[o + 3] = 0.5 * (qw * w0 + qy * w2 - z * w1)
        dy[o + 4] = 0.5 * (qw * w1 + z * w0 - x * w2)
        dy[o + 5] = 0.5 * (qw * w2 + x * w1 - qy * w0)
        dy[o + 6] = -0.5 * (x * w0 + qy * w1 + z * w2)
        F, M = branch_force(m, d, b), br.mass[b]
        put3(dy, o + 7, (F[0] / M, F[1] / M, F[2] / M))
        put3(dy, o + 10, _root_spin(t, br.joint[b], d.a))
        o += ROOT_STATE
    for j in t.internal:
        dy[o], dy[o + 1] = y[o + 1], d.a[t.idx_v[j]]
        o += JOINT_STATE
    return dy


@njit
def error_norm(err, y0, y1, rtol, atol):
    """RMS of err scaled by atol + rtol max(|y0|, |y1|), per component."""
    total = 0.0
    for i in range(err.shape[0]):
        sc = atol + rtol * max(abs(y0[i]), abs(y1[i]))
        total += (err[i] / sc) ** 2
    return math.sqrt(total / err.shape[0])


@njit
def _stage(m, d, y, dt, commit, external):
    """dy at the state y, dt (s) into the step (the bristles bent over dt from the memory);
    its external wrench goes into external (6,). commit: the memory is then that of this
    evaluation."""
    unpack(m, d, y)
    forces(m, d, dt, np.bool_(False))
    if commit:
        commit_memory(d)
    accelerations(m, d)
    d.evaluations += 1
    external[:3] = d.loads.external_force_W
    external[3:] = d.loads.external_torque_O_W
    return derivative(m, d, y)


@njit
def _combine(y0, h, weights, k, n_k):
    """y0 + h sum_j weights[j] k[j] over the first n_k stages, the zero weights left out."""
    acc = np.zeros(y0.shape[0])
    for j in range(n_k):
        if weights[j] != 0.0:
            for x in range(acc.shape[0]):
                acc[x] = acc[x] + weights[j] * k[j, x]
    out = np.empty(y0.shape[0])
    for x in range(out.shape[0]):
        out[x] = y0[x] + h * acc[x]
    return out


@njit
def runge_kutta(m, d, h):
    """One accepted step of an explicit Runge-Kutta method (the model's tableau), of h or, if
    adaptive, of at most min(h, d.h_next) with error control: returns the step taken, or 0.0
    if it fell below h_min.

    Each stage evaluates the forces at its state with the pair memory of the step's start
    ([reading] a stage at t0 + c h bends each bristle by v_t c h from its start deflection,
    and new pairs take the stage's approach speed). Only the accepted end commits the memory,
    from its state with the whole step (bending by v_t h); that evaluation is also the next
    step's first stage unless a controller has changed a speed since. Prescribed joints keep
    their speed through the step.
    """
    p = m.integrator
    s = p.b.shape[0]
    y0 = pack(m, d)
    k = np.empty((s, y0.shape[0]))
    external = np.empty((s, 6))
    if evaluated_here(d) and not d.jumped:
        k[0] = d.fsal_dy
        external[0] = d.fsal_external
    else:
        k[0] = _stage(m, d, y0, 0.0, np.bool_(False), external[0])
    if p.adaptive and d.h_next > 0.0:  # its last step's estimate (before any, h as asked)
        h = min(h, d.h_next)
    while True:
        for i in range(1, s):
            k[i] = _stage(m, d, _combine(y0, h, p.A[i], k, i), p.c[i] * h, np.bool_(False), external[i])
        y1 = _combine(y0, h, p.b, k, s)
        if not p.adaptive:
            break
        zero = np.zeros(y0.shape[0])
        ratio = error_norm(_combine(zero, h, p.e, k, s), y0, y1, p.rtol, p.atol)
        if ratio <= 1.0:
            grow = GROW_MAX if ratio == 0.0 else min(GROW_MAX, max(SHRINK_MIN, SAFETY * ratio ** -0.2))
            d.h_next = min(p.h_max, h * grow)
            break
        d.rejected += 1
        h *= max(SHRINK_MIN, SAFETY * ratio ** -0.2)
        if h < p.h_min:
            return 0.0
    d.accepted += 1
    # the step's external impulse: the stages' wrenches, weighted
    mean = np.zeros(6)
    for i in range(s):
        if p.b[i] != 0.0:
            for x in range(6):
                mean[x] = mean[x] + p.b[i] * external[i, x]
    # the accepted end: commit the pair memory; this is the next step's first stage (it
    # leaves d at y1)
    end = np.empty(6)
    d.fsal_dy[:] = _stage(m, d, y1, h, np.bool_(True), end)
    d.fsal, d.fsal_t = True, d.t + h
    d.jumped = False
    d.fsal_external[:] = end
    d.external_force_W[:] = mean[:3]
    d.external_torque_O_W[:] = mean[3:]
    return h


# ------------------------------------------------------------------------------- tableaus


def tableau(method: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The Butcher tableau (A, b, c, e) of an explicit Runge-Kutta method; e: the embedded
    error estimate's weights (empty for a fixed-step method)."""
    if method == "rk4":  # the classical fourth-order method
        A = ((0.0, 0.0, 0.0, 0.0), (0.5, 0.0, 0.0, 0.0), (0.0, 0.5, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0))
        return np.array(A), np.array((1 / 6, 1 / 3, 1 / 3, 1 / 6)), np.array((0.0, 0.5, 0.5, 1.0)), np.zeros(0)
    if method == "dopri5":  # Dormand-Prince 5(4), its last stage at the step's end (FSAL)
        A = np.zeros((7, 7))
        rows = ((), (1 / 5,), (3 / 40, 9 / 40), (44 / 45, -56 / 15, 32 / 9),
                (19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729),
                (9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656),
                (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84))
        for i, row in enumerate(rows):
            A[i, :len(row)] = row
        b = np.array((35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0))
        b4 = np.array((5179 / 57600, 0.0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40))
        return A, b, np.array((0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0)), b - b4
    if method in ("symplectic_euler", "adaptive_euler"):  # not Runge-Kutta
        return np.zeros((0, 0)), np.zeros(0), np.zeros(0), np.zeros(0)
    raise ValueError(f"unknown integrator {method!r}; valid: {', '.join(METHODS)}")
