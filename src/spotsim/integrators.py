"""Time integrators, one small interface: advance (q, v) by h given the acceleration a(q, v).

Free bodies hang on free-flyer joints, whose velocity Pinocchio keeps in the body frame. The
integrators advance each free body's centroid in the world frame instead: contact forces come
in equal and opposite pairs, so the sum of m_i a_G,i is zero to round-off and the total linear
momentum, and the system's centroid velocity, stay exact. A body-frame twist update does not
keep them: its error grows with (omega dt)^2.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from .bodies import (add3, axpy3, body_origin3, body_rotation, cross3, free_bodies, free_body_acceleration, mm9,
                     mtv3, mtv9, mv3, mv9, put3, quat_rotation9, quat_times_exp4, sub3)
from .errors import SimulationError
from .jit import direct, njit, njit_inline
from .step import contact_stage


@njit
def _centroid_state(bodies, b, q, v):
    """World centroid position and velocity, rotation, and body angular velocity of free body
    b: 3-tuple, 3-tuple, (3, 3), 3-tuple."""
    return _centroid_state_at(bodies, b, body_rotation(bodies, b, q), q, v)


@njit
def _centroid_state_at(bodies, b, R, q, v):
    """`_centroid_state` given the body's rotation R (from q)."""
    iv = bodies.idx_v[b]
    c = bodies.lever[b]
    v_O, w = v[iv:iv + 3], v[iv + 3:iv + 6]
    return add3(body_origin3(bodies, b, q), mv3(R, c)), mv3(R, add3(v_O, cross3(w, c))), R, (w[0], w[1], w[2])


@njit
def _centroid_acceleration(R, c, v_O, w, a_O, alpha):
    """d/dt of R (v_O + w x c): the centroid's world acceleration from the body-frame twist
    (v_O, w) and its derivative (a_O, alpha); c is the centroid in the body frame. A 3-tuple."""
    return mv3(R, add3(add3(add3(a_O, cross3(w, v_O)), cross3(alpha, c)), cross3(w, cross3(w, c))))


@njit
def _set_centroid_state(bodies, b, q, v, p_G, v_G, quat, w):
    """Write free body b's configuration and velocity from its world centroid state and its
    joint's quaternion (x, y, z, w), in place."""
    iq, iv = bodies.idx_q[b], bodies.idx_v[b]
    c = bodies.lever[b]
    Rq = quat_rotation9(quat[0], quat[1], quat[2], quat[3])
    R_P = bodies.R_P[b]
    # p_G = p_P + R_P (x + Rq c)
    put3(q, iq, sub3(mtv3(R_P, sub3(p_G, bodies.p_P[b])), mv9(Rq, c)))
    q[iq + 3], q[iq + 4], q[iq + 5], q[iq + 6] = quat[0], quat[1], quat[2], quat[3]
    put3(v, iv, sub3(mtv9(mm9(R_P, Rq), v_G), cross3(w, c)))
    put3(v, iv + 3, w)


@njit
def _symplectic_euler_bodies(bodies, q, v, a, h, q_new, v_new):
    """The free bodies' part of a symplectic Euler step, into q_new, v_new."""
    for b in range(bodies.joint.shape[0]):
        iv = bodies.idx_v[b]
        _symplectic_euler_body(bodies, b, body_rotation(bodies, b, q), q, v, a[iv:iv + 3], a[iv + 3:iv + 6], h,
                               q_new, v_new)


@njit_inline
def _symplectic_euler_body(bodies, b, R, q, v, a_O, alpha, h, q_new, v_new):
    """Free body b's symplectic Euler step, into q_new, v_new, given its rotation R (from q) and
    its twist's derivative (a_O, alpha)."""
    iq = bodies.idx_q[b]
    iv = bodies.idx_v[b]
    p_G, v_G, R, w = _centroid_state_at(bodies, b, R, q, v)
    a_G = _centroid_acceleration(R, bodies.lever[b], v[iv:iv + 3], w, a_O, alpha)
    v_G = axpy3(h, a_G, v_G)
    w = axpy3(h, alpha, w)
    # a unit quaternion, or the round-off in R compounds from step to step
    quat = quat_times_exp4(q[iq + 3:iq + 7], h * w[0], h * w[1], h * w[2])
    _set_centroid_state(bodies, b, q_new, v_new, axpy3(h, v_G, p_G), v_G, quat, w)


@njit_inline
def free_bodies_step(bodies, R_W, q, v, f_local, g_W, h):
    """`bodies.free_body_accelerations` and `_symplectic_euler` in one pass, for a model of
    free bodies only, with each body's rotation R_W[joint] at q (`bodies.body_kinematics`):
    the new (q, v), to the bit as the two give them."""
    q_new, v_new = q.copy(), v.copy()  # every entry is a free body's, and is written below
    for b in range(bodies.joint.shape[0]):
        R = R_W[bodies.joint[b]]
        a_O, alpha = free_body_acceleration(bodies, b, R, v, f_local, g_W)
        _symplectic_euler_body(bodies, b, R, q, v, a_O, alpha, h, q_new, v_new)
    return q_new, v_new


@njit
def _symplectic_euler(bodies, q, v, a, h):
    """A symplectic Euler step of a model made of free bodies only: new (q, v)."""
    q_new, v_new = q.copy(), v + h * a
    _symplectic_euler_bodies(bodies, q, v, a, h, q_new, v_new)
    return q_new, v_new


def centroid_state(model: pin.Model, j: int, q, v):
    """World centroid position and velocity, rotation, and body angular velocity of free body j."""
    bodies = free_bodies(model)
    p_G, v_G, R, w = _centroid_state(bodies, list(bodies.joint).index(j), np.asarray(q, float),
                                     np.asarray(v, float))
    return np.array(p_G), np.array(v_G), R, np.array(w)


def centroid_acceleration(model: pin.Model, j: int, q, v, a):
    """Classical acceleration of free body j's centroid in world, from Pinocchio's spatial a."""
    iv = model.idx_vs[j]
    _, _, R, w = centroid_state(model, j, q, v)
    return np.array(_centroid_acceleration(R, model.inertias[j].lever, v[iv:iv + 3], w, a[iv:iv + 3],
                                           a[iv + 3:iv + 6]))


class SymplecticEuler:
    """Semi-implicit Euler, the paper's fixed-step explicit scheme.

    Free bodies: v_G += h a_G and omega += h alpha, then x_G += h v_G and R <- R exp(h omega),
    centroid in world, rotation in body. Other joints: v += h a, q <- q (+) h v.
    """

    name = "symplectic_euler"
    order = 1
    adaptive = False
    moves_fingers = False  # the step's drive moves them (step.step), at the rate it sets

    def __init__(self, model: pin.Model, spec=None):
        self.bodies = free_bodies(model)
        self.only_free = len(self.bodies.joint) * 7 == model.nq
        self.h = None
        self._update = direct(_symplectic_euler)  # this model's argument types, fixed

    def step(self, model: pin.Model, q: np.ndarray, v: np.ndarray, a: np.ndarray,
             h: float) -> tuple[np.ndarray, np.ndarray]:
        """(q, v) after h, given the acceleration a at (q, v)."""
        if self.only_free:
            return self._update(self.bodies, q, v, a, h)
        v_new = v + h * a
        q_new = pin.integrate(model, q, h * v_new)
        _symplectic_euler_bodies(self.bodies, q, v, a, h, q_new, v_new)
        return q_new, v_new

    def advance(self, model, data, h: float):
        """One step of h of the scene: contact forces at the start, ABA, update. Returns the
        contacts that acted and the step taken."""
        contacts = contact_stage(model, data, h)
        m = model.pin_model
        a = pin.aba(m, data.pin_data, data.q, data.v, data.tau, data.f_ext)
        data.q, data.v = self.step(m, data.q, data.v, a, h)
        return contacts, h

    def stats(self) -> dict:
        return {"method": self.name}


# --------------------------------------------------------------------------- Runge-Kutta
# The free bodies' state for Runge-Kutta methods: per body 13 numbers, the centroid's world
# position, the joint's unit quaternion (x, y, z, w), the centroid's world velocity and the
# body angular velocity. Pairwise contact forces keep sum m a_G = 0 at every stage, so a
# linear combination of stages keeps the total linear momentum to round-off.

STATE = 13


@njit
def _pack(bodies, q, v):
    """The Runge-Kutta state y of the free bodies at (q, v)."""
    y = np.empty(STATE * bodies.joint.shape[0])
    for b in range(bodies.joint.shape[0]):
        p_G, v_G, _, w = _centroid_state(bodies, b, q, v)
        iq, o = bodies.idx_q[b], STATE * b
        put3(y, o, p_G)
        y[o + 3:o + 7] = q[iq + 3:iq + 7]
        put3(y, o + 7, v_G)
        put3(y, o + 10, w)
    return y


@njit
def _unpack(bodies, y, q, v):
    """Write the state y into (q, v), in place; quaternions normalised."""
    for b in range(bodies.joint.shape[0]):
        o = STATE * b
        quat = y[o + 3:o + 7] / np.linalg.norm(y[o + 3:o + 7])
        _set_centroid_state(bodies, b, q, v, y[o:o + 3].copy(), y[o + 7:o + 10].copy(), quat,
                            y[o + 10:o + 13].copy())


@njit
def _derivative(bodies, y, q, v, a):
    """dy/dt at the state y = (q, v) given ABA's acceleration a there."""
    dy = np.empty_like(y)
    for b in range(bodies.joint.shape[0]):
        o, iv = STATE * b, bodies.idx_v[b]
        R = body_rotation(bodies, b, q)
        w = v[iv + 3:iv + 6]
        x, qy, z, qw = y[o + 3], y[o + 4], y[o + 5], y[o + 6]
        dy[o:o + 3] = y[o + 7:o + 10]
        # q' = q (x) (omega, 0) / 2, omega in the body frame
        dy[o + 3] = 0.5 * (qw * w[0] + qy * w[2] - z * w[1])
        dy[o + 4] = 0.5 * (qw * w[1] + z * w[0] - x * w[2])
        dy[o + 5] = 0.5 * (qw * w[2] + x * w[1] - qy * w[0])
        dy[o + 6] = -0.5 * (x * w[0] + qy * w[1] + z * w[2])
        put3(dy, o + 7, _centroid_acceleration(R, bodies.lever[b], v[iv:iv + 3], w, a[iv:iv + 3],
                                               a[iv + 3:iv + 6]))
        dy[o + 10:o + 13] = a[iv + 3:iv + 6]
    return dy


@njit
def _error_norm(err, y0, y1, rtol, atol):
    """RMS of err scaled by atol + rtol max(|y0|, |y1|), per component."""
    total = 0.0
    for i in range(err.shape[0]):
        sc = atol + rtol * max(abs(y0[i]), abs(y1[i]))
        total += (err[i] / sc) ** 2
    return math.sqrt(total / err.shape[0])


def rk_try(method, f, y0, k1, h):
    """One explicit Runge-Kutta step of h from y0 with the tableau of `method` (A, b, c, e):
    (y1, the embedded error estimate or None). f(y, dt) is dy/dt at y, dt into the step;
    k1 = f(y0, 0)."""
    A, b, c, e = method.A, method.b, method.c, method.e
    k = [k1]
    for i in range(1, len(c)):
        k.append(f(y0 + h * sum(A[i][j] * k[j] for j in range(i) if A[i][j]), c[i] * h))
    y1 = y0 + h * sum(b[i] * k[i] for i in range(len(b)) if b[i])
    return y1, None if e is None else h * sum(e[i] * k[i] for i in range(len(e)) if e[i])


def adaptive_try(method, f, y0, k1, h, rtol, atol, h_min, h_max, trace=None):
    """One accepted step of at most h with error control: (y1, the step taken, the step to
    try next, the steps rejected on the way). Raises StepSizeUnderflow below h_min. `trace`,
    a list f appends to, is cut back to k1's entries before each retry."""
    rejected = 0
    start = None if trace is None else len(trace)
    while True:
        y1, err = rk_try(method, f, y0, k1, h)
        ratio = _error_norm(err, y0, y1, rtol, atol)
        if ratio <= 1.0:
            grow = 5.0 if ratio == 0.0 else min(5.0, max(0.2, 0.9 * ratio ** -0.2))
            return y1, h, min(h_max, h * grow), rejected
        rejected += 1
        h *= max(0.2, 0.9 * ratio ** -0.2)
        if h < h_min:
            raise StepSizeUnderflow(f"adaptive step fell below h_min_s = {h_min:g} s")
        if trace is not None:
            del trace[start:]


class StepSizeUnderflow(SimulationError):
    """The adaptive step fell below its smallest allowed size: the run has diverged."""


class RungeKutta:
    """Explicit Runge-Kutta on the free bodies' centroid state, with contact.

    Each stage evaluates the contact forces and ABA at its state, with the pair memory of the
    step's start: [reading] a stage at t0 + c h bends each bristle by v_t c h from its start
    deflection, and new pairs take the stage's approach speed. Only an accepted step commits
    the memory, from its end state with the whole step (bending by v_t h); that evaluation is
    also the next step's first stage. Rejected and repeated steps so leave it untouched.
    The fingers move at the drive's rate through the step.
    """

    adaptive = False
    moves_fingers = True

    def __init__(self, model: pin.Model, spec=None):
        self.bodies = free_bodies(model)
        if len(self.bodies.joint) * 7 != model.nq:
            raise ValueError(f"{self.name} integrates free bodies only; the model has other joints")
        if spec is None:
            from .scenario import Integrator

            spec = Integrator(method=self.name)
        self.spec = spec
        self.h = None  # adaptive: the step to try next
        self.accepted = self.rejected = self.evaluations = 0
        self._first = None  # (data, t, opening rates, dy, external load) of the last commit

    def _stage(self, model, data, y, dt, commit):
        """dy at state y, dt after the step's start, and the contacts there; the external
        force and moment on the free bodies there go to self._ext."""
        _unpack(self.bodies, y, data.q, data.v)
        data.opening = self._opening0 + dt * data.opening_rate
        c = contact_stage(model, data, dt, commit=commit)
        a = pin.aba(model.pin_model, data.pin_data, data.q, data.v, data.tau, data.f_ext)
        self.evaluations += 1
        self._ext.append(np.concatenate([data.external_force_W, data.external_torque_O_W]))
        return _derivative(self.bodies, y, data.q, data.v, a), c

    def advance(self, model, data, h: float):
        """One accepted step of at most h. Returns the contacts at its end and the step taken."""
        self._opening0 = data.opening.copy()
        y0 = _pack(self.bodies, data.q, data.v)
        data.q, data.v = data.q.copy(), data.v.copy()  # the stages write into these copies
        self._ext = []
        last = self._first  # the last commit is this step's first stage if nothing changed since
        if last is not None and last[0] is data and last[1] == data.t and \
                np.array_equal(last[2], data.opening_rate):
            k1 = last[3]
            self._ext.append(last[4])
        else:
            k1 = self._stage(model, data, y0, 0.0, commit=False)[0]

        def f(y, dt):
            return self._stage(model, data, y, dt, commit=False)[0]

        if self.adaptive:
            y1, h, self.h, rejected = adaptive_try(type(self), f, y0, k1, min(h, self.h or h), self.spec.rtol,
                                                   self.spec.atol, self.spec.h_min_s, self.spec.h_max_s, self._ext)
            self.rejected += rejected
        else:
            y1, _ = rk_try(type(self), f, y0, k1, h)
        self.accepted += 1
        # the impulse of the external forces over the step: the stages' forces, weighted
        ext = sum(w * x for w, x in zip(self.b, self._ext[-len(self.b):]) if w)
        # the accepted end: commit the pair memory; this is the next step's first stage
        # (it leaves data at y1, the fingers at their opening after h)
        dy, contacts = self._stage(model, data, y1, h, commit=True)
        self._first = (data, data.t + h, data.opening_rate.copy(), dy, self._ext[-1])
        data.external_force_W, data.external_torque_O_W = ext[:3], ext[3:]
        return contacts, h

    def stats(self) -> dict:
        return {"method": self.name, "accepted_steps": self.accepted, "rejected_steps": self.rejected,
                "force_evaluations": self.evaluations}


class RK4(RungeKutta):
    """The classical fourth-order Runge-Kutta method, fixed step."""

    name = "rk4"
    order = 4
    A = ((), (0.5,), (0.0, 0.5), (0.0, 0.0, 1.0))
    b = (1 / 6, 1 / 3, 1 / 3, 1 / 6)
    c = (0.0, 0.5, 0.5, 1.0)
    e = None


class DormandPrince(RungeKutta):
    """Dormand-Prince 5(4): fifth order with an embedded fourth-order error estimate, adaptive
    (relative and absolute tolerances, step limits, rejected steps counted)."""

    name = "dopri5"
    order = 5
    adaptive = True
    A = ((), (1 / 5,), (3 / 40, 9 / 40), (44 / 45, -56 / 15, 32 / 9),
         (19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729),
         (9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656),
         (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84))
    b = (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0)
    c = (0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0)
    e = tuple(x - y for x, y in zip(b, (5179 / 57600, 0.0, 7571 / 16695, 393 / 640, -92097 / 339200,
                                        187 / 2100, 1 / 40)))


INTEGRATORS = {k.name: k for k in (SymplecticEuler, RK4, DormandPrince)}


def make_integrator(spec, model: pin.Model):
    """The integrator of `spec` (a scenario's `simulation.integrator` block, or a method name)
    for `model`."""
    name = spec if isinstance(spec, str) else spec.method
    try:
        cls = INTEGRATORS[name]
    except KeyError:
        raise ValueError(f"unknown integrator {name!r}; valid: {', '.join(INTEGRATORS)}") from None
    return cls(model, None if isinstance(spec, str) else spec)
