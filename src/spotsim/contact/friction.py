"""Three-dimensional bristle friction with per-pair memory (paper Sec. 3.1.4, Eq. 14-17)."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..jit import njit

#: Pair states, as the paper's Fig. 9 colours them.
NONE, SLIPPING, STICKING = 0, 1, 2
STATE_NAMES = ("none", "slipping", "sticking")


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
def tangential(v, n_c):
    """Eq. (17): v_t = v - (v . n) n, rows of (k, 3)."""
    out = np.empty_like(v)
    for i in range(v.shape[0]):
        vn = v[i, 0] * n_c[i, 0] + v[i, 1] * n_c[i, 1] + v[i, 2] * n_c[i, 2]
        for a in range(3):
            out[i, a] = v[i, a] - vn * n_c[i, a]
    return out


@njit
def _norm3(x, i):
    return math.sqrt(x[i, 0] * x[i, 0] + x[i, 1] * x[i, 1] + x[i, 2] * x[i, 2])


@njit
def carry_deflection(s, n_c):
    """Keep a carried deflection (k, 3) in the current tangent plane, with its length kept."""
    s_t = tangential(s, n_c)
    for i in range(s.shape[0]):
        old, new = _norm3(s, i), _norm3(s_t, i)
        scale = old / new if new > 0.0 else 0.0
        for a in range(3):
            s_t[i, a] *= scale
    return s_t


@njit
def bristle_step(s_prev, v, n_c, F_n, dt, p):
    """One step of the bristle law for k pairs.

    s_prev: (k, 3) deflection carried from the last step (zero at onset), m.
    v: (k, 3) velocity of A's contact point relative to B's, m/s.  n_c: (k, 3) common normal.
    F_n: (k,) normal force magnitude, N.  dt: step, s.  p: BristleParams.
    Returns s (k, 3), friction force on A (k, 3) in N, and the pair state (k,) int.
    """
    k = s_prev.shape[0]
    s = carry_deflection(s_prev, n_c)
    v_t = tangential(v, n_c)
    F_f = np.empty((k, 3))
    state = np.empty(k, dtype=np.int64)
    for i in range(k):
        speed = _norm3(v_t, i)
        slipping = speed > p.v_d
        s_max = (p.mu_k if slipping else p.mu_s) * F_n[i] / p.k_b  # Eq. (16)
        for a in range(3):
            s[i, a] += v_t[i, a] * dt  # Eq. (15), first branch
        length = _norm3(s, i)
        saturated = length >= s_max
        if saturated:
            # Eq. (15), second branch: the bristle lies at s_max along the sliding direction
            # (along its own deflection when there is no sliding)
            src = v_t if speed > 0.0 else s
            dir_norm = _norm3(src, i)
            for a in range(3):
                s[i, a] = s_max * src[i, a] / dir_norm if dir_norm > 0.0 else 0.0
        for a in range(3):
            # [reading] s_dot is the bristle's deflection rate while it holds (v_t); a
            # saturated bristle lies at s_max and slides, so its rate is zero. Differencing
            # the clamped s instead would turn every reversal of the sliding direction into
            # an impulse of c_b * 2 s_max / dt, which grows without bound as dt shrinks.
            s_dot = 0.0 if saturated else v_t[i, a]
            F_f[i, a] = -p.k_b * s[i, a] - p.c_b * s_dot  # Eq. (14)
        state[i] = SLIPPING if slipping else STICKING
    return s, F_f, state
