"""Hertz normal force with Zhang damping (paper Sec. 3.1.3, Eq. 11-13)."""

from __future__ import annotations

import math

import numpy as np

from ..jit import njit

#: Power of the Hertz law for sphere contact (paper: alpha = 1.5). `normal_law` evaluates
#: delta^1.5 as delta sqrt(delta): this value is fixed by the sphere-on-sphere geometry, not a setting.
HERTZ_EXPONENT = 1.5


def hertz_stiffness(E1: float, nu1: float, E2: float, nu2: float, r1: float, r2: float) -> float:
    """Eq. (13): K = 4/3 E1 E2 / (E1 (1 - nu2^2) + E2 (1 - nu1^2)) sqrt(r1 r2 / (r1 + r2)), N/m^1.5."""
    return 4.0 / 3.0 * E1 * E2 / (E1 * (1 - nu2**2) + E2 * (1 - nu1**2)) * np.sqrt(r1 * r2 / (r1 + r2))


def damping_factor(restitution: float) -> float:
    """Zhang et al. factor 6 (1 - c_r) / ((2 c_r - 1)^2 + 3) of Eq. (12): 0 at c_r = 1, 1 at 0.5."""
    return 6.0 * (1.0 - restitution) / ((2.0 * restitution - 1.0) ** 2 + 3.0)


@njit
def indentation(phi):
    """[reading] Local indentation delta = phi / 2 (printed as "phi1 2"), m."""
    return 0.5 * phi


@njit
def hertz_potential(phi, K):
    """The elastic energy a pair stores at penetration phi, J: the integral of the Hertz force
    K delta^a over phi from 0, with delta = phi / 2 (so dphi = 2 ddelta): 2 K delta^(a+1) / (a+1),
    0.8 K (phi/2)^2.5. Under `contact.normal_direction: gradient` the pairs' elastic forces are
    its gradient."""
    return 2.0 * K * indentation(phi) ** (HERTZ_EXPONENT + 1.0) / (HERTZ_EXPONENT + 1.0)


@njit
def onset_rate(delta_dot, floor):
    """delta_dot_minus of a pair at its first step in contact: its indentation rate then (m/s,
    > 0 approaching), raised to `floor` (m/s, a floor on the indentation rate, not on the
    approach speed: see `assemble.model.contact_law`). Zhang's lambda = factor K / delta_dot_minus
    is singular for pairs that slide into contact at zero normal speed."""
    return max(delta_dot, floor)


@njit
def normal_law(delta, delta_dot, delta_dot_minus, K, factor):
    """Eq. (11)-(12) with its slopes: the magnitude of F_n = K delta^a + lambda delta^a
    delta_dot, never pulling (N), and its partial derivatives in delta (N/m) and in delta_dot
    (N s/m); all three 0 where the force is clamped at 0.

    delta: indentation, m.  delta_dot: its rate, m/s (> 0 approaching).
    delta_dot_minus: the indentation rate at the pair's contact onset (`onset_rate`), m/s.
    lambda = factor K / delta_dot_minus.
    """
    rate = 1.0 + factor * delta_dot / delta_dot_minus
    if rate <= 0.0 or delta <= 0.0:
        return 0.0, 0.0, 0.0
    elastic = K * delta * math.sqrt(delta)  # K delta^HERTZ_EXPONENT, without pow's cost
    return elastic * rate, HERTZ_EXPONENT * elastic / delta * rate, elastic * factor / delta_dot_minus


@njit
def normal_force(delta, delta_dot, delta_dot_minus, K, factor):
    """Eq. (11)-(12): the magnitude of F_n (N), clamped at 0 (`normal_law`)."""
    return normal_law(delta, delta_dot, delta_dot_minus, K, factor)[0]
