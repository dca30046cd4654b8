"""Time integrators, one small interface: advance (q, v) by h given the acceleration a(q, v).

Free bodies hang on free-flyer joints, whose velocity Pinocchio keeps in the body frame. The
integrators advance each free body's centroid in the world frame instead: contact forces come
in equal and opposite pairs, so the sum of m_i a_G,i is zero to round-off and the total linear
momentum, and the system's centroid velocity, stay exact. A body-frame twist update does not
keep them: its error grows with (omega dt)^2.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .bodies import body_pose, free_bodies, quat_times_exp, quat_to_rotation
from .jit import njit


@njit
def _cross(a, b):
    """a x b for two 3-vectors."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@njit
def _centroid_state(bodies, b, q, v):
    """World centroid position and velocity, rotation, and body angular velocity of free body b."""
    iv = bodies.idx_v[b]
    R, p = body_pose(bodies, b, q)
    c = bodies.lever[b]
    v_O, w = v[iv:iv + 3], v[iv + 3:iv + 6]
    return p + R @ c, R @ (v_O + _cross(w, c)), R, w.copy()


@njit
def _centroid_acceleration(R, c, v_O, w, a_O, alpha):
    """d/dt of R (v_O + w x c): the centroid's world acceleration from the body-frame twist
    (v_O, w) and its derivative (a_O, alpha); c is the centroid in the body frame."""
    return R @ (a_O + _cross(w, v_O) + _cross(alpha, c) + _cross(w, _cross(w, c)))


@njit
def _set_centroid_state(bodies, b, q, v, p_G, v_G, quat, w):
    """Write free body b's configuration and velocity from its world centroid state and its
    joint's quaternion (x, y, z, w), in place."""
    iq, iv = bodies.idx_q[b], bodies.idx_v[b]
    c = bodies.lever[b]
    Rq = quat_to_rotation(quat[0], quat[1], quat[2], quat[3])
    R_P = bodies.R_P[b]
    # p_G = p_P + R_P (x + Rq c)
    q[iq:iq + 3] = R_P.T @ (p_G - bodies.p_P[b]) - Rq @ c
    q[iq + 3:iq + 7] = quat
    v[iv:iv + 3] = (R_P @ Rq).T @ v_G - _cross(w, c)
    v[iv + 3:iv + 6] = w


@njit
def _symplectic_euler_bodies(bodies, q, v, a, h, q_new, v_new):
    """The free bodies' part of a symplectic Euler step, into q_new, v_new."""
    for b in range(bodies.joint.shape[0]):
        iq, iv = bodies.idx_q[b], bodies.idx_v[b]
        p_G, v_G, R, w = _centroid_state(bodies, b, q, v)
        a_G = _centroid_acceleration(R, bodies.lever[b], v[iv:iv + 3], w, a[iv:iv + 3], a[iv + 3:iv + 6])
        v_G = v_G + h * a_G
        w = w + h * a[iv + 3:iv + 6]
        # a unit quaternion, or the round-off in R compounds from step to step
        quat = quat_times_exp(q[iq + 3:iq + 7], h * w[0], h * w[1], h * w[2])
        _set_centroid_state(bodies, b, q_new, v_new, p_G + h * v_G, v_G, quat, w)


@njit
def _symplectic_euler(bodies, q, v, a, h):
    """A symplectic Euler step of a model made of free bodies only: new (q, v)."""
    q_new, v_new = q.copy(), v + h * a
    _symplectic_euler_bodies(bodies, q, v, a, h, q_new, v_new)
    return q_new, v_new


def centroid_state(model: pin.Model, j: int, q, v):
    """World centroid position and velocity, rotation, and body angular velocity of free body j."""
    bodies = free_bodies(model)
    return _centroid_state(bodies, list(bodies.joint).index(j), np.asarray(q, float), np.asarray(v, float))


def centroid_acceleration(model: pin.Model, j: int, q, v, a):
    """Classical acceleration of free body j's centroid in world, from Pinocchio's spatial a."""
    iv = model.idx_vs[j]
    _, _, R, w = centroid_state(model, j, q, v)
    return _centroid_acceleration(R, model.inertias[j].lever, v[iv:iv + 3], w, a[iv:iv + 3], a[iv + 3:iv + 6])


class SymplecticEuler:
    """Semi-implicit Euler, the paper's fixed-step explicit scheme.

    Free bodies: v_G += h a_G and omega += h alpha, then x_G += h v_G and R <- R exp(h omega),
    centroid in world, rotation in body. Other joints: v += h a, q <- q (+) h v.
    """

    name = "symplectic_euler"
    order = 1

    def __init__(self, model: pin.Model):
        self.bodies = free_bodies(model)
        self.only_free = len(self.bodies.joint) * 7 == model.nq

    def step(self, model: pin.Model, q: np.ndarray, v: np.ndarray, a: np.ndarray,
             h: float) -> tuple[np.ndarray, np.ndarray]:
        if self.only_free:
            return _symplectic_euler(self.bodies, q, v, a, h)
        v_new = v + h * a
        q_new = pin.integrate(model, q, h * v_new)
        _symplectic_euler_bodies(self.bodies, q, v, a, h, q_new, v_new)
        return q_new, v_new


INTEGRATORS = {SymplecticEuler.name: SymplecticEuler}


def make_integrator(name: str, model: pin.Model):
    """The integrator `name` for `model`."""
    try:
        return INTEGRATORS[name](model)
    except KeyError:
        raise ValueError(f"unknown integrator {name!r}; valid: {', '.join(INTEGRATORS)}") from None
