"""Sphere-pair detection along the common normal (paper Sec. 3.1.2, Eq. 6-10)."""

from __future__ import annotations

import math

import numpy as np

from ..jit import njit

#: Two spheres whose face normals differ by less than this (|n2 - n1|) face the same way and
#: cannot touch across a common normal: Eq. (6) is undefined for them, so they never pair.
NORMAL_EPS = 1e-9
#: [reading] A pair whose centres lie less than (r1 + r2) / SIDE_CAP apart along the common
#: normal (chi, Eq. 9) meets side-on, as at a layer's edge: its penetration is at most SIDE_CAP
#: times the spheres' own overlap r1 + r2 - |c1 - c2|. Eq. (8)'s phi is at most (r1 + r2) / chi
#: times that overlap, so the cap leaves every pair with chi >= (r1 + r2) / SIDE_CAP to Eq. (8)
#: (a face-on pair has chi = r1 + r2 less about its penetration), and is continuous where it
#: starts to bind. Without it phi is discontinuous side-on: it grows as sqrt(2 (r1 + r2) s) with
#: the overlap s, and for chi < 0 (A's centre behind B's) it jumps from no contact to -chi as A
#: comes within lateral reach of B.
SIDE_CAP = 2.0


@njit
def penetration(c1, n1, r1, c2, n2, r2):
    """Eq. (6), (8)-(10) for one sphere pair: common normal (3-tuple), penetration phi (m, how
    far A must move along n_c to just touch B, capped side-on: SIDE_CAP), whether they are in
    contact (the root of Eq. (8) is real and phi > 0) and whether the cap set phi. c1, n1, c2,
    n2: 3-vectors (world); r1, r2: radii, m."""
    d0, d1, d2 = n2[0] - n1[0], n2[1] - n1[1], n2[2] - n1[2]
    norm = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    facing = norm > NORMAL_EPS
    if facing:
        d0, d1, d2 = d0 / norm, d1 / norm, d2 / norm
    e0, e1, e2 = c1[0] - c2[0], c1[1] - c2[1], c1[2] - c2[2]
    chi = d0 * e0 + d1 * e1 + d2 * e2  # Eq. (9)
    reach = r1 + r2
    distance2 = e0 * e0 + e1 * e1 + e2 * e2
    w = distance2 - reach ** 2  # Eq. (10)
    disc = chi * chi - w
    phi = -chi + math.sqrt(max(disc, 0.0))  # Eq. (8)
    side = False
    if chi < reach / SIDE_CAP:
        cap = SIDE_CAP * (reach - math.sqrt(distance2))
        if cap < phi:
            phi, side = cap, True
    return (d0, d1, d2), phi, facing and disc >= 0.0 and phi > 0.0, side


@njit
def force_direction(c1, c2, n_c, phi, gradient, side):
    """The direction g of a pair's normal force on the master (3-tuple): the force is F_n g,
    and the pair's indentation rate is -(v . g) / 2.

    gradient False, the paper's law (Eq. 11): g = n_c.
    gradient True, [variant] g = -dphi/dc1, so that the elastic force K delta^1.5 g is the
    gradient of the pair's Hertz potential, and the pair's normal damping opposes the rate of
    phi and only dissipates. From Eq. (8), g = d / (d . n_c) with d = c1 - c2 + phi n_c
    (Eq. 7; differentiate |c1 - c2 + phi n_c| = r1 + r2), and g . n_c = 1; d . n_c =
    sqrt(chi^2 - w) >= chi > 0 for any pair whose phi stays below r1 + r2, which a run's
    divergence check ensures. Capped side-on (`side`, phi = SIDE_CAP (r1 + r2 - |c1 - c2|)),
    g = SIDE_CAP (c1 - c2) / |c1 - c2|, along the line of the centres.
    c1, c2: sphere centres; n_c: common normal (3-vectors, world); phi: penetration, m.
    """
    if not gradient:
        return (n_c[0], n_c[1], n_c[2])
    if side:
        e0, e1, e2 = c1[0] - c2[0], c1[1] - c2[1], c1[2] - c2[2]
        k = SIDE_CAP / math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        return (k * e0, k * e1, k * e2)
    d0, d1, d2 = c1[0] - c2[0] + phi * n_c[0], c1[1] - c2[1] + phi * n_c[1], c1[2] - c2[2] + phi * n_c[2]  # Eq. (7)
    dn = d0 * n_c[0] + d1 * n_c[1] + d2 * n_c[2]
    return (d0 / dn, d1 / dn, d2 / dn)



@njit
def contact_point(c1, c2, r1, r2, n_c, phi):
    """One contact point of a pair, shared by both bodies, m (3-tuple).

    [reading] With d = c1 - c2 + phi n_c (Eq. 7), the spheres would just touch at
    c2 + r2/(r1 + r2) d; the point used is that tangency point moved back by phi/2 along n_c,
    the middle of the overlap. For coaxial spheres it lies halfway through the overlap.
    """
    share = r2 / (r1 + r2)
    return (c2[0] + share * (c1[0] - c2[0] + phi * n_c[0]) - 0.5 * phi * n_c[0],  # Eq. (7)
            c2[1] + share * (c1[1] - c2[1] + phi * n_c[1]) - 0.5 * phi * n_c[1],
            c2[2] + share * (c1[2] - c2[2] + phi * n_c[2]) - 0.5 * phi * n_c[2])



def cutoff_distance(r1: float, r2: float, max_penetration: float) -> float:
    """Largest centre distance |c1 - c2| of a pair in contact whose phi <= max_penetration, m.

    If chi > 0, phi > 0 needs w < 0, i.e. |c1 - c2| < r1 + r2. If chi <= 0, phi >= |chi| and
    the distance across n_c is at most r1 + r2, so |c1 - c2|^2 <= (r1 + r2)^2 + phi^2. A run
    stops (diverged) before phi exceeds a sphere radius, so searching within this distance
    finds every pair the all-pairs search finds.
    """
    return float(np.hypot(r1 + r2, max_penetration))
