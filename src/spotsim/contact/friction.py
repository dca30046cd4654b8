"""Three-dimensional bristle friction with per-pair memory (paper Sec. 3.1.4, Eq. 14-17)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Pair states, as the paper's Fig. 9 colours them.
NONE, SLIPPING, STICKING = 0, 1, 2
STATE_NAMES = ("none", "slipping", "sticking")


@dataclass(frozen=True)
class BristleParams:
    """Table 2: mu_k, mu_s, bristle stiffness k_b (N/m), damping c_b (N s/m), deadband v_d (m/s)."""

    mu_k: float
    mu_s: float
    k_b: float
    c_b: float
    v_d: float


def tangential(v, n_c):
    """Eq. (17): v_t = v - (v . n) n, rows of (k, 3)."""
    return v - np.einsum("ij,ij->i", v, n_c)[:, None] * n_c


def carry_deflection(s, n_c):
    """Keep a carried deflection (k, 3) in the current tangent plane, with its length kept."""
    s_t = tangential(s, n_c)
    old = np.linalg.norm(s, axis=1)
    new = np.linalg.norm(s_t, axis=1)
    scale = np.divide(old, new, out=np.zeros_like(old), where=new > 0.0)
    return s_t * scale[:, None]


def bristle_step(s_prev, v, n_c, F_n, dt: float, p: BristleParams):
    """One step of the bristle law for k pairs.

    s_prev: (k, 3) deflection carried from the last step (zero at onset), m.
    v: (k, 3) velocity of A's contact point relative to B's, m/s.  n_c: (k, 3) common normal.
    F_n: (k,) normal force magnitude, N.  dt: step, s.
    Returns s (k, 3), friction force on A (k, 3) in N, and the pair state (k,) int.
    """
    s0 = carry_deflection(s_prev, n_c)
    v_t = tangential(v, n_c)
    speed = np.linalg.norm(v_t, axis=1)
    slipping = speed > p.v_d
    s_max = np.where(slipping, p.mu_k, p.mu_s) * F_n / p.k_b  # Eq. (16)
    s = s0 + v_t * dt  # Eq. (15), first branch
    length = np.linalg.norm(s, axis=1)
    saturated = length >= s_max
    # Eq. (15), second branch: the bristle lies at s_max along the sliding direction
    direction = np.where((speed > 0.0)[:, None], v_t, s)
    dir_norm = np.linalg.norm(direction, axis=1)
    unit = np.divide(direction, dir_norm[:, None], out=np.zeros_like(direction),
                     where=(dir_norm > 0.0)[:, None])
    s = np.where(saturated[:, None], s_max[:, None] * unit, s)
    # [reading] s_dot is the bristle's deflection rate while it holds (v_t); a saturated
    # bristle lies at s_max and slides, so its rate is zero. Differencing the clamped s
    # instead would turn every reversal of the sliding direction into an impulse of
    # c_b * 2 s_max / dt, which grows without bound as dt shrinks.
    s_dot = np.where(saturated[:, None], 0.0, v_t)
    F_f = -p.k_b * s - p.c_b * s_dot  # Eq. (14)
    state = np.where(slipping, SLIPPING, STICKING)
    return s, F_f, state
