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


def cross(a, b):
    """a x b for two 3-vectors; np.cross costs ~10 us a call on this size."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def free_flyers(model: pin.Model) -> list[int]:
    """The joints of `model` that are free-flyers."""
    return [j for j in range(1, model.njoints) if model.joints[j].shortname() == "JointModelFreeFlyer"]


def centroid_state(model: pin.Model, j: int, q, v):
    """World centroid position and velocity, rotation, and body angular velocity of free body j."""
    iq, iv = model.idx_qs[j], model.idx_vs[j]
    M = model.jointPlacements[j] * pin.XYZQUATToSE3(q[iq:iq + 7])
    c = model.inertias[j].lever
    v_O, w = v[iv:iv + 3], v[iv + 3:iv + 6]
    R = M.rotation
    return M.translation + R @ c, R @ (v_O + cross(w, c)), R, w


def centroid_acceleration(model: pin.Model, j: int, q, v, a):
    """Classical acceleration of free body j's centroid in world, from Pinocchio's spatial a."""
    iq, iv = model.idx_qs[j], model.idx_vs[j]
    R = (model.jointPlacements[j] * pin.XYZQUATToSE3(q[iq:iq + 7])).rotation
    return _centroid_acceleration(R, model.inertias[j].lever, v[iv:iv + 3], v[iv + 3:iv + 6],
                                  a[iv:iv + 3], a[iv + 3:iv + 6])


def _centroid_acceleration(R, c, v_O, w, a_O, alpha):
    """d/dt of R (v_O + w x c): the centroid's world acceleration from the body-frame twist
    (v_O, w) and its derivative (a_O, alpha); c is the centroid in the body frame."""
    return R @ (a_O + cross(w, v_O) + cross(alpha, c) + cross(w, cross(w, c)))


def set_centroid_state(model: pin.Model, j: int, q, v, p_G, v_G, R, w) -> None:
    """Write free body j's configuration and velocity from its world centroid state, in place."""
    iq, iv = model.idx_qs[j], model.idx_vs[j]
    c = model.inertias[j].lever
    M = model.jointPlacements[j].inverse() * pin.SE3(R, p_G - R @ c)
    xyzquat = pin.SE3ToXYZQUAT(M)
    # a unit quaternion, or the round-off in R compounds from step to step
    xyzquat[3:] /= np.linalg.norm(xyzquat[3:])
    q[iq:iq + 7] = xyzquat
    v[iv:iv + 3] = R.T @ v_G - cross(w, c)
    v[iv + 3:iv + 6] = w


class SymplecticEuler:
    """Semi-implicit Euler, the paper's fixed-step explicit scheme.

    Free bodies: v_G += h a_G and omega += h alpha, then x_G += h v_G and R <- R exp(h omega),
    centroid in world, rotation in body. Other joints: v += h a, q <- q (+) h v.
    """

    name = "symplectic_euler"
    order = 1

    def __init__(self, model: pin.Model):
        self.free = free_flyers(model)

    def step(self, model: pin.Model, q: np.ndarray, v: np.ndarray, a: np.ndarray,
             h: float) -> tuple[np.ndarray, np.ndarray]:
        v_new = v + h * a
        q_new = q.copy() if len(self.free) * 7 == model.nq else pin.integrate(model, q, h * v_new)
        for j in self.free:
            iv = model.idx_vs[j]
            p_G, v_G, R, w = centroid_state(model, j, q, v)
            a_G = _centroid_acceleration(R, model.inertias[j].lever, v[iv:iv + 3], w,
                                         a[iv:iv + 3], a[iv + 3:iv + 6])
            v_G = v_G + h * a_G
            w = v_new[iv + 3:iv + 6]
            set_centroid_state(model, j, q_new, v_new, p_G + h * v_G, v_G, R @ pin.exp3(h * w), w)
        return q_new, v_new


INTEGRATORS = {SymplecticEuler.name: SymplecticEuler}


def make_integrator(name: str, model: pin.Model):
    """The integrator `name` for `model`."""
    try:
        return INTEGRATORS[name](model)
    except KeyError:
        raise ValueError(f"unknown integrator {name!r}; valid: {', '.join(INTEGRATORS)}") from None
