"""Stage: the tethers, elastic cords from fixed points to bodies (a module hung on a bungee).

A tether pulls the point it holds (fixed in its body's joint frame) towards its anchor (fixed
in the world) with k (l - l_0) + c dl/dt along the cord while it is stretched (l > l_0), and
not at all while it is slack: a cord does not push. Its pull is an external force on a
floating body, added to the contact wrenches the dynamics read (d.loads) and to the external
wrench the momentum balance integrates; the contact summary, taken before, does not hold it.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..jit import njit
from ..linalg import add3, cross3, mv3


class Tethers(NamedTuple):
    """The tethers of a scene, one row each (none: zero rows)."""

    joint: np.ndarray  # (n,) the joint whose body it holds
    point: np.ndarray  # (n, 3) the point it holds, in that joint's frame, m
    anchor_W: np.ndarray  # (n, 3) its fixed end, world, m
    stiffness: np.ndarray  # (n,) N/m
    damping: np.ndarray  # (n,) N s/m
    rest_length: np.ndarray  # (n,) its unstretched length, m


def no_tethers() -> Tethers:
    return Tethers(joint=np.zeros(0, dtype=np.int64), point=np.zeros((0, 3)), anchor_W=np.zeros((0, 3)),
                   stiffness=np.zeros(0), damping=np.zeros(0), rest_length=np.zeros(0))


@njit
def _cord(tt, i, R_W, p_W):
    """Tether i's held point's lever from its joint's origin and the point (3-tuples, world),
    the vector from the point to the anchor and its length, m, from the frames given (R_W, p_W
    of a Data or of its Frames)."""
    j = tt.joint[i]
    r = mv3(R_W[j], (tt.point[i, 0], tt.point[i, 1], tt.point[i, 2]))
    p = add3((p_W[j, 0], p_W[j, 1], p_W[j, 2]), r)
    u = (tt.anchor_W[i, 0] - p[0], tt.anchor_W[i, 1] - p[1], tt.anchor_W[i, 2] - p[2])
    return r, p, u, math.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])


@njit
def tether_force(m, i, R_W, p_W, w_W, vo_W):
    """Tether i's pull on its body (3-tuple, world, N) and the point it acts at (3-tuple,
    world), from the frames given (R_W ... of a Data or of its Frames)."""
    tt = m.tethers
    j = tt.joint[i]
    r, p, u, length = _cord(tt, i, R_W, p_W)
    stretch = length - tt.rest_length[i]
    if stretch <= 0.0 or length == 0.0:
        return (0.0, 0.0, 0.0), p
    u = (u[0] / length, u[1] / length, u[2] / length)
    v = add3((vo_W[j, 0], vo_W[j, 1], vo_W[j, 2]), cross3((w_W[j, 0], w_W[j, 1], w_W[j, 2]), r))
    lengthening = -(v[0] * u[0] + v[1] * u[1] + v[2] * u[2])
    pull = max(0.0, tt.stiffness[i] * stretch + tt.damping[i] * lengthening)
    return (pull * u[0], pull * u[1], pull * u[2]), p


@njit
def tether_loads(m, d):
    """Stage: add each tether's pull at d's kinematics to its body's wrench in d.loads (in its
    joint's frame about its origin, and in the world about the world's origin) and to the
    external wrench."""
    loads = d.loads
    for i in range(m.tethers.joint.shape[0]):
        f, p = tether_force(m, i, d.R_W, d.p_W, d.w_W, d.vo_W)
        j = m.tethers.joint[i]
        r = (p[0] - d.p_W[j, 0], p[1] - d.p_W[j, 1], p[2] - d.p_W[j, 2])
        tau = cross3(r, f)
        for a in range(3):
            loads.f_local[j, a] += d.R_W[j, 0, a] * f[0] + d.R_W[j, 1, a] * f[1] + d.R_W[j, 2, a] * f[2]
            loads.f_local[j, 3 + a] += d.R_W[j, 0, a] * tau[0] + d.R_W[j, 1, a] * tau[1] + d.R_W[j, 2, a] * tau[2]
            loads.external_force_W[a] += f[a]
        t_O = cross3(p, f)
        for a in range(3):
            loads.force_W[j, a] += f[a]
            loads.torque_O_W[j, a] += t_O[a]
            loads.external_torque_O_W[a] += t_O[a]


@njit
def tether_energy(m, f):
    """The energy stored in the stretched tethers, 1/2 k (l - l_0)^2 each, J, at the Frames f."""
    total, tt = 0.0, m.tethers
    for i in range(tt.joint.shape[0]):
        stretch = _cord(tt, i, f.R_W, f.p_W)[3] - tt.rest_length[i]
        if stretch > 0.0:
            total += 0.5 * tt.stiffness[i] * stretch * stretch
    return total
