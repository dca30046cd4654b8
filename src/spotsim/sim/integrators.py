"""Time integrators, compiled: each advances d by one step through the same stages.

An integrator is one function `f(m, d, h) -> h_taken` that evaluates the forces
(`sim.forces`) and the accelerations (`sim.dynamics.accelerations`) where its scheme needs
them, commits the pair memory of the state it ends at, updates (q, v), and sets the step's
mean external wrench on the free bodies (for the momentum balance). `integrate` dispatches on
the model's method; a new integrator is one more such function and its code.

- `symplectic_euler`: the paper's explicit fixed step.
- `adaptive_euler`: symplectic Euler with its error controlled by an embedded estimate
  (Euler against Heun's trapezoid, from the end's forces, which start the next step), and,
  optionally, its steps cut where a bristle's damping switches on or off.
- `rk4`, `dopri5`: explicit Runge-Kutta, fixed and error-controlled.

Free bodies hang on free-flyer or planar joints, whose velocity Pinocchio keeps in the body
frame. The integrators advance each free body's centroid in the world frame instead (a planar
body's stays in its plane: its accelerations have no other component, and `set_centroid_state`
keeps its in-plane coordinates): contact forces come
in equal and opposite pairs, so the sum of m_i a_G,i is zero to round-off and the total linear
momentum, and the system's centroid velocity, stay exact. A body-frame twist update does not
keep them: its error grows with (omega h)^2.
"""

from __future__ import annotations

import math

import numpy as np

from ..contact.forces import commit_memory
from ..jit import njit, njit_inline
from ..linalg import axpy3, put3, quat_times_exp4
from .bodies import (
    body_rotation,
    centroid_acceleration,
    centroid_state,
    centroid_of,
    free_origin3,
    free_quat,
    free_twist,
    joint_quat,
    kinematics,
    planar_origin3,
    planar_quat,
    planar_twist,
    set_centroid_state,
    set_free_state,
    set_planar_state,
    travel_rate,
    twist,
)
from .data import RK_STATE
from .dynamics import accelerations
from .forces import contact_forces, forces

#: The integrators, by their scenario names; a Model names its own by its index here.
METHODS = ("symplectic_euler", "rk4", "dopri5", "adaptive_euler")
SYMPLECTIC_EULER = METHODS.index("symplectic_euler")
ADAPTIVE_EULER = METHODS.index("adaptive_euler")
#: The error-controlled methods.
ADAPTIVE = ("dopri5", "adaptive_euler")
#: An adaptive step grows at most, and shrinks at least, by these factors per try; its error
#: ratio r scales it by SAFETY r^(-1/p) in between, p the order of its local error estimate
#: (Hairer, Norsett and Wanner, II.4): 5 for dopri5, 2 for adaptive_euler.
GROW_MAX, SHRINK_MIN, SAFETY = 5.0, 0.2, 0.9
#: adaptive_euler with its bristle switches located (`switch_fraction`): a try in which a
#: bristle saturates or lets go earlier than SWITCH_WINDOW of the step from its end is tried
#: again to end just past the switch, if the switch's damping impulse c_b |v| h (1 - theta)
#: would move the lightest free body by more than SWITCH_SHARE of the velocity tolerance
#: (a switch misplaced within a step always errs the same way, so its share is kept small);
#: a switch within SWITCH_FLOOR (s) of the step's start is taken as at its start.
SWITCH_WINDOW, SWITCH_SHARE, SWITCH_FLOOR = 0.1, 0.1, 1e-8


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


# ------------------------------------------------------------------------- symplectic Euler


@njit_inline
def _euler_body(R, c, origin, quat, v_O, w, a_O, alpha, h):
    """A body's symplectic Euler step, given its rotation R (3, 3), centroid c (body frame),
    origin (world), joint quaternion and twist (v_O, w) and the twist's derivative (a_O,
    alpha): v_G += h a_G and w += h alpha, then x_G += h v_G and R <- R exp(h w), centroid in
    world, rotation in body. Returns the new (p_G, v_G, quaternion, w)."""
    p_G, v_G = centroid_of(origin, R, c, v_O, w)
    a_G = centroid_acceleration(R, c, v_O, w, a_O, alpha)
    v_G = axpy3(h, a_G, v_G)
    w = axpy3(h, alpha, w)
    # a unit quaternion, or the round-off in R compounds from step to step
    return axpy3(h, v_G, p_G), v_G, quat_times_exp4(quat, h * w[0], h * w[1], h * w[2]), w


@njit_inline
def _euler_bodies(m, d, q, v, h):
    """Every free body's symplectic Euler step of h (s) from (q, v), in place, with the
    accelerations d.a and rotations d.R_W of the last evaluation (made at (q, v))."""
    _euler_kind(m, d, m.bodies.free_rows, q, v, h, free_twist, free_origin3, free_quat, set_free_state)
    _euler_kind(m, d, m.bodies.planar_rows, q, v, h, planar_twist, planar_origin3, planar_quat, set_planar_state)


@njit_inline
def _euler_kind(m, d, rows, q, v, h, twist_of, origin_of, quat_of, set_state):
    """`_euler_bodies` for the bodies of one joint kind (rows), read and written through that
    kind's accessors."""
    for b in rows:
        v_O, w = twist_of(m.bodies, b, v)
        a_O, alpha = twist_of(m.bodies, b, d.a)
        p_G, v_G, quat, w = _euler_body(d.R_W[m.bodies.joint[b]], m.bodies.lever[b], origin_of(m.bodies, b, q),
                                        quat_of(m.bodies, b, q), v_O, w, a_O, alpha, h)
        set_state(m.bodies, b, q, v, p_G, v_G, quat, w)


@njit_inline
def rates_changed(d):
    """Whether the finger rates differ from those of the last evaluation (d.fsal_rate): the
    drive has decided a new rate since, and the pairs' normal forces may have jumped."""
    return not np.array_equal(d.fsal_rate, d.opening_rate)


@njit
def symplectic_euler(m, d, h):
    """Semi-implicit Euler, the paper's fixed-step explicit scheme: forces and accelerations
    at the step's start, velocities first, then positions with the new velocities."""
    forces(m, d, h, rates_changed(d))
    d.fsal_rate[:] = d.opening_rate
    commit_memory(d)
    accelerations(m, d)
    _euler_bodies(m, d, d.q, d.v, h)
    d.external_force_W[:] = d.loads.external_force_W
    d.external_torque_O_W[:] = d.loads.external_torque_O_W
    d.evaluations += 1
    d.accepted += 1


# ------------------------------------------------------------------- adaptive symplectic Euler


@njit
def onset_step(m, d):
    """The longest step adaptive_euler's onset guard allows at d's state, s: while a pair may
    start (coal keeps face pairs within its margin), a step moves no two spheres closer by
    more than the onset depth, so that a pair that starts during a step sinks no deeper into
    it before the error estimate sees its force. inf when no pair can start."""
    if not m.literal and d.near.shape[0] == 0:
        return math.inf
    rate = travel_rate(m, d)
    return m.integrator.onset_depth / rate if rate > 0.0 else math.inf


@njit_inline
def _centroid_accelerations(m, d, out):
    """Each free body's centroid acceleration (world) and angular acceleration (body) at d's
    last evaluation, into out (n_bodies, 6)."""
    _centroid_accelerations_kind(m, d, m.bodies.free_rows, out, free_twist)
    _centroid_accelerations_kind(m, d, m.bodies.planar_rows, out, planar_twist)


@njit_inline
def _centroid_accelerations_kind(m, d, rows, out, twist_of):
    """`_centroid_accelerations` for the bodies of one joint kind (rows)."""
    for b in rows:
        v_O, w = twist_of(m.bodies, b, d.v)
        a_O, alpha = twist_of(m.bodies, b, d.a)
        _put_acceleration(out, b, centroid_acceleration(d.R_W[m.bodies.joint[b]], m.bodies.lever[b], v_O, w, a_O,
                                                        alpha), alpha)


@njit_inline
def _put_acceleration(out, b, a_G, alpha):
    """Row b of out (n_bodies, 6): a_G, then alpha."""
    for x in range(3):
        out[b, x] = a_G[x]
        out[b, 3 + x] = alpha[x]


@njit
def euler_error(m, acc0, acc1, h):
    """The error ratio of a symplectic Euler step of h (s) whose start and end accelerations
    are acc0 and acc1 (n_bodies, 6; `_centroid_accelerations`): the largest over the free
    bodies of its velocity error estimate h/2 |a1 - a0| (Euler against Heun's trapezoid) at
    any of its contact spheres, which lie within its lever of its centroid, over velocity_tol."""
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
    speed = SWITCH_SHARE * m.integrator.velocity_tol * np.min(m.bodies.mass) / (m.law.bristle.c_b * h)
    j, n = 0, after.key.shape[0]
    for i in range(before.key.shape[0]):
        while j < n and after.key[j] < before.key[i]:
            j += 1
        if j < n and after.key[j] == before.key[i] and (before.slack[i] > 0.0) != (after.slack[j] > 0.0):
            at = before.slack[i] / (before.slack[i] - after.slack[j])
            if after.speed[j] * (1.0 - at) > speed:
                theta = min(theta, at)
    return theta


@njit
def adaptive_euler(m, d, h):
    """One accepted symplectic Euler step with its error controlled, of at most min(h, the
    onset guard): returns the step taken, or 0.0 if it fell below h_min.

    A try of h updates velocities then positions with the accelerations at the start, then
    evaluates the forces at its end, bending the bristles over h from the memory; h/2 |a_end
    - a_start| (`euler_error`) estimates its error. A kept try commits the memory, and its end
    evaluation is the next step's start: one evaluation a try. A rejected one goes back to
    the start (state, fingers, contacts) and tries SAFETY r^(-1/2) of h. The fingers move at
    the drive's rate through the step; a new rate (the drive's decision) re-evaluates the
    start for each try, the committed bristles bent over it (as symplectic Euler's start
    bends them over its step; a bristle that the new rate's jump of the normal force lets
    hold damps for its share of the try, `friction.bristle`: a closed-form impulse, which the
    error estimate leaves out), so that a rejected try leaves no trace. Its pairs are those
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
    here = d.fsal and d.fsal_t == d.t  # the last evaluation was made at this state
    changed = rates_changed(d)
    fresh = not here or changed
    n = m.bodies.joint.shape[0]
    acc = np.empty((2, n, 6))
    q0, v0, a0, opening0 = d.q.copy(), d.v.copy(), d.a.copy(), d.opening.copy()
    start = (d.candidates, d.contacts, d.loads, d.summary)  # put back after a rejection (a fresh start: its pairs)
    external = np.empty(6)
    rejected = False
    h_free = 0.0  # the step the error control alone took, before a switch cut it
    while True:
        if fresh:
            if here:  # only the finger rates changed: the pairs found at this state stand
                kinematics(m, d)
                d.candidates = start[0]
                shared = contact_forces(m, d, h, changed)
            else:
                shared = forces(m, d, h, changed)
            accelerations(m, d)
            d.evaluations += 1
            _centroid_accelerations(m, d, acc[0])
            if shared:
                # the damping that the new rate's jump lets a saturated bristle hold is its
                # closed-form impulse over the try (`friction.bristle`), not a force the step
                # samples: the step moves with it, and its error estimate compares the end
                # with the start without it
                with_share = (d.contacts, d.loads, d.summary, d.a.copy())
                contact_forces(m, d, h, False)
                accelerations(m, d)
                d.evaluations += 1
                _centroid_accelerations(m, d, acc[0])
                d.contacts, d.loads, d.summary = with_share[:3]
                d.a[:] = with_share[3]
        elif not rejected:
            _centroid_accelerations(m, d, acc[0])
        if fresh or not rejected:
            external[:3] = d.loads.external_force_W
            external[3:] = d.loads.external_torque_O_W
        _euler_bodies(m, d, d.q, d.v, h)
        for i in range(d.opening.shape[0]):
            d.opening[i] = opening0[i] + h * d.opening_rate[i]
        forces(m, d, h, False)
        accelerations(m, d)
        d.evaluations += 1
        _centroid_accelerations(m, d, acc[1])
        ratio = euler_error(m, acc[0], acc[1], h)
        theta = switch_fraction(m, d.memory, d.contacts, h) if p.locate_switches else 1.0
        early = theta < 1.0 - SWITCH_WINDOW and theta * h > SWITCH_FLOOR
        if ratio <= 1.0 and not early:
            grow = GROW_MAX if ratio == 0.0 else min(GROW_MAX, max(SHRINK_MIN, SAFETY / math.sqrt(ratio)))
            # no growth right after a rejection (Hairer, Norsett and Wanner, II.4); a step
            # cut at a switch does not hold back the next
            d.h_next = min(p.h_max, max(h * (min(grow, 1.0) if rejected else grow), h_free))
            break
        d.q[:], d.v[:], d.opening[:] = q0, v0, opening0
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
    d.fsal, d.fsal_t = True, d.t + h
    d.fsal_rate[:] = d.opening_rate
    # the step's impulse is that of the start's forces (the velocity update's)
    d.external_force_W[:] = external[:3]
    d.external_torque_O_W[:] = external[3:]
    return h


# --------------------------------------------------------------------------- Runge-Kutta
# The free bodies' state for Runge-Kutta methods: per body RK_STATE numbers, the centroid's
# world position, the joint's unit quaternion (x, y, z, w), the centroid's world velocity and
# the body angular velocity. Pairwise contact forces keep sum m a_G = 0 at every stage, so a
# linear combination of stages keeps the total linear momentum to round-off.


@njit
def pack(bodies, q, v):
    """The Runge-Kutta state y of the free bodies at (q, v)."""
    y = np.empty(RK_STATE * bodies.joint.shape[0])
    for b in range(bodies.joint.shape[0]):
        p_G, v_G, _, w = centroid_state(bodies, b, q, v)
        o = RK_STATE * b
        put3(y, o, p_G)
        quat = joint_quat(bodies, b, q)
        for i in range(4):
            y[o + 3 + i] = quat[i]
        put3(y, o + 7, v_G)
        put3(y, o + 10, w)
    return y


@njit
def unpack(bodies, y, q, v):
    """Write the state y into (q, v), in place; quaternions normalised."""
    for b in range(bodies.joint.shape[0]):
        o = RK_STATE * b
        quat = y[o + 3:o + 7] / np.linalg.norm(y[o + 3:o + 7])
        set_centroid_state(bodies, b, q, v, y[o:o + 3].copy(), y[o + 7:o + 10].copy(), quat, y[o + 10:o + 13].copy())


@njit
def derivative(bodies, y, q, v, a):
    """dy/dt at the state y = (q, v) given the accelerations a there."""
    dy = np.empty_like(y)
    for b in range(bodies.joint.shape[0]):
        o = RK_STATE * b
        R = body_rotation(bodies, b, q)
        v_O, w = twist(bodies, b, v)
        a_O, alpha = twist(bodies, b, a)
        x, qy, z, qw = y[o + 3], y[o + 4], y[o + 5], y[o + 6]
        dy[o:o + 3] = y[o + 7:o + 10]
        # q' = q (x) (omega, 0) / 2, omega in the body frame
        dy[o + 3] = 0.5 * (qw * w[0] + qy * w[2] - z * w[1])
        dy[o + 4] = 0.5 * (qw * w[1] + z * w[0] - x * w[2])
        dy[o + 5] = 0.5 * (qw * w[2] + x * w[1] - qy * w[0])
        dy[o + 6] = -0.5 * (x * w[0] + qy * w[1] + z * w[2])
        put3(dy, o + 7, centroid_acceleration(R, bodies.lever[b], v_O, w, a_O, alpha))
        put3(dy, o + 10, alpha)
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
def _stage(m, d, y, dt, opening0, commit, external):
    """dy at the state y, dt (s) into the step (the fingers at opening0 + dt times their rates,
    the bristles bent over dt from the memory); its external wrench goes into external (6,).
    commit: the memory is then that of this evaluation."""
    unpack(m.bodies, y, d.q, d.v)
    for i in range(d.opening.shape[0]):
        d.opening[i] = opening0[i] + dt * d.opening_rate[i]
    forces(m, d, dt, False)
    if commit:
        commit_memory(d)
    accelerations(m, d)
    d.evaluations += 1
    external[:3] = d.loads.external_force_W
    external[3:] = d.loads.external_torque_O_W
    return derivative(m.bodies, y, d.q, d.v, d.a)


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
    step's first stage while the finger rates stay as they were. The fingers move at the
    drive's rate through the step.
    """
    p = m.integrator
    s = p.b.shape[0]
    opening0 = d.opening.copy()
    y0 = pack(m.bodies, d.q, d.v)
    k = np.empty((s, y0.shape[0]))
    external = np.empty((s, 6))
    if d.fsal and d.fsal_t == d.t and not rates_changed(d):
        k[0] = d.fsal_dy
        external[0] = d.fsal_external
    else:
        k[0] = _stage(m, d, y0, 0.0, opening0, False, external[0])
    if p.adaptive and d.h_next > 0.0:  # its last step's estimate (before any, h as asked)
        h = min(h, d.h_next)
    while True:
        for i in range(1, s):
            k[i] = _stage(m, d, _combine(y0, h, p.A[i], k, i), p.c[i] * h, opening0, False, external[i])
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
    # the accepted end: commit the pair memory; this is the next step's first stage
    # (it leaves d at y1, the fingers at their opening after h)
    end = np.empty(6)
    d.fsal_dy[:] = _stage(m, d, y1, h, opening0, True, end)
    d.fsal, d.fsal_t = True, d.t + h
    d.fsal_rate[:] = d.opening_rate
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
