"""Three-dimensional bristle friction with per-pair memory (paper Sec. 3.1.4, Eq. 14-17)."""

from __future__ import annotations

import math
from typing import NamedTuple

from ..jit import njit
from ..linalg import norm3

#: Pair states, as the paper's Fig. 9 colours them.
NONE, SLIPPING, STICKING = 0, 1, 2


class BristleParams(NamedTuple):
    """Table 2: mu_k, mu_s, bristle stiffness k_b (N/m), damping c_b (N s/m), deadband v_d (m/s).

    A named tuple of floats, so that the compiled kernels take it as it is.
    """

    mu_k: float
    mu_s: float
    k_b: float
    c_b: float
    v_d: float


@njit
def _tangential(x, n):
    """Eq. (17): x - (x . n) n, as a 3-tuple."""
    xn = x[0] * n[0] + x[1] * n[1] + x[2] * n[2]
    return (x[0] - xn * n[0], x[1] - xn * n[1], x[2] - xn * n[2])


@njit
def bristle(s_prev, v, n_c, F_n, dt, p, jump):
    """One step of the bristle law for one pair.

    s_prev: deflection carried from the last step (zero at onset), m. v: velocity of A's
    contact point relative to B's, m/s. n_c: common normal. (3-vectors.) F_n: normal force
    magnitude, N. dt: step, s. p: BristleParams. jump: F_n may have jumped since the carried
    deflection's step (the fingers' rates changed: a controller tick), and dt is the step to
    come, over which the force will act.
    Returns the deflection s, the friction force on A (N), both 3-tuples, the pair state, the
    bristle's slack, m: s_max less the length it would have without its limit (Eq. 15's first
    branch), and the share of dt it held. The bristle holds while its slack is positive (the
    force then grows with the tangential motion by k_b per metre and c_b per m/s) and
    saturates when it reaches zero.

    [reading] A jump of the normal force (a finger's rate changing at a controller tick changes
    its pairs' normal damping at once) raises s_max by mu dF_n / k_b at once, and a bristle
    saturated before it holds until it has slid that far: for microseconds, its damping
    c_b v_t adding an impulse of (c_b mu / k_b) dF_n. A step longer than that would see the
    bristle saturated at its end and drop the impulse, which a finer step keeps; after a jump,
    the damping acts for the share of dt the bristle holds (the force is the step's mean), and
    as dt -> 0 the share is 1 while it holds. Without a jump, a saturated bristle does not damp
    (a normal force growing smoothly keeps it saturated as dt -> 0).
    """
    # the carried deflection, kept in the current tangent plane with its length kept
    s = _tangential(s_prev, n_c)
    old, new = norm3(s_prev), norm3(s)
    scale = old / new if new > 0.0 else 0.0
    s0, s1, s2 = s[0] * scale, s[1] * scale, s[2] * scale
    v_t = _tangential(v, n_c)
    speed = norm3(v_t)
    slipping = speed > p.v_d
    s_max = (p.mu_k if slipping else p.mu_s) * F_n / p.k_b  # Eq. (16)
    carried = (s0, s1, s2)
    s0, s1, s2 = s0 + v_t[0] * dt, s1 + v_t[1] * dt, s2 + v_t[2] * dt  # Eq. (15), first branch
    slack = s_max - norm3((s0, s1, s2))
    saturated = slack <= 0.0
    held = 1.0 if not saturated else _held(carried, v_t, speed, s_max, dt) if jump else 0.0
    if saturated:
        # Eq. (15), second branch: the bristle lies at s_max along the sliding direction
        # (along its own deflection when there is no sliding)
        src = v_t if speed > 0.0 else (s0, s1, s2)
        dir_norm = norm3(src)
        if dir_norm > 0.0:
            s0, s1, s2 = s_max * src[0] / dir_norm, s_max * src[1] / dir_norm, s_max * src[2] / dir_norm
        else:
            s0 = s1 = s2 = 0.0
    # [reading] s_dot is the bristle's deflection rate while it holds (v_t); a saturated
    # bristle lies at s_max and slides, so its rate is zero. Differencing the clamped s
    # instead would turn every reversal of the sliding direction into an impulse of
    # c_b * 2 s_max / dt, which grows without bound as dt shrinks. Over dt, the damping
    # c_b v_t acts for the share of it the bristle held.
    c = p.c_b * held
    F_f = (-p.k_b * s0 - c * v_t[0], -p.k_b * s1 - c * v_t[1], -p.k_b * s2 - c * v_t[2])  # Eq. (14)
    return (s0, s1, s2), F_f, SLIPPING if slipping else STICKING, slack, held


@njit
def _held(s, v_t, speed, s_max, dt):
    """The share of dt for which a bristle carried at s and bent at v_t (3-tuples; v_t's
    length `speed`) stays within s_max: the root tau of |s + v_t tau| = s_max over dt, 0.0 if
    it starts at or beyond it."""
    gap = s_max * s_max - (s[0] * s[0] + s[1] * s[1] + s[2] * s[2])
    if gap <= 0.0:
        return 0.0
    if dt <= 0.0 or speed == 0.0:  # unbent, it saturates only by round-off in |s|: as it was
        return 1.0
    av = s[0] * v_t[0] + s[1] * v_t[1] + s[2] * v_t[2]
    v2 = speed * speed
    tau = (math.sqrt(av * av + v2 * gap) - av) / v2
    return min(1.0, tau / dt)
