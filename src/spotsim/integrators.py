"""Time integrators, one small interface: advance (q, v) by h given the acceleration."""

from __future__ import annotations

import numpy as np
import pinocchio as pin


class SymplecticEuler:
    """Semi-implicit Euler: v <- v + h a(q, v); q <- q (+) h v_new (Pinocchio's integrate).

    `prescribed` maps velocity indices to velocities imposed for the coming step (the
    fingers' actuator); their accelerations are ignored.
    """

    name = "symplectic_euler"
    order = 1

    def step(self, model: pin.Model, q: np.ndarray, v: np.ndarray, a: np.ndarray, h: float,
             prescribed: dict[int, float]) -> tuple[np.ndarray, np.ndarray]:
        v_new = v + h * a
        for iv, value in prescribed.items():
            v_new[iv] = value
        return pin.integrate(model, q, h * v_new), v_new


INTEGRATORS = {SymplecticEuler.name: SymplecticEuler}


def make_integrator(name: str):
    try:
        return INTEGRATORS[name]()
    except KeyError:
        raise ValueError(f"unknown integrator {name!r}; valid: {', '.join(INTEGRATORS)}") from None
