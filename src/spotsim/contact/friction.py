"""Three-dimensional bristle friction with per-pair memory (paper Sec. 3.1.4, Eq. 14-17)."""

from __future__ import annotations

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
def bristle(s_prev, v, n_c, F_n, dt, p):
    """One step of the bristle law for one pair.

    s_prev: deflection carried from the last step (zero at onset), m. v: velocity of A's
    contact point relative to B's, m/s. n_c: common normal. (3-vectors.) F_n: normal force
    magnitude, N. dt: step, s. p: BristleParams.
    Returns the deflection s, the friction force on A (N), both 3-tuples, the pair state, and
    the bristle's slack, m: s_max less the length it would have without its limit (Eq. 15's
    first branch). The bristle holds while its slack is positive (the force then grows with
    the tangential motion by k_b per metre and c_b per m/s) and saturates when it reaches zero.
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
    s0, s1, s2 = s0 + v_t[0] * dt, s1 + v_t[1] * dt, s2 + v_t[2] * dt  # Eq. (15), first branch
    slack = s_max - norm3((s0, s1, s2))
    saturated = slack <= 0.0
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
    # c_b * 2 s_max / dt, which grows without bound as dt shrinks.
    s_dot = (0.0, 0.0, 0.0) if saturated else v_t
    F_f = (-p.k_b * s0 - p.c_b * s_dot[0], -p.k_b * s1 - p.c_b * s_dot[1], -p.k_b * s2 - p.c_b * s_dot[2])  # Eq. (14)
    return (s0, s1, s2), F_f, SLIPPING if slipping else STICKING, slack
