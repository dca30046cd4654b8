"""Sphere-pair detection along the common normal (paper Sec. 3.1.2, Eq. 6-10)."""

from __future__ import annotations

import numpy as np

#: Two spheres whose face normals differ by less than this (|n2 - n1|) face the same way and
#: cannot touch across a common normal: Eq. (6) is undefined for them, so they never pair.
NORMAL_EPS = 1e-9


def penetration(c1, n1, r1, c2, n2, r2):
    """Eq. (6), (8)-(10): common normal and penetration of sphere pairs.

    c1, n1: (k, 3) master centres and face normals in world, m; r1 master radius, m.
    c2, n2: (k, 3) slave centres and normals; r2 slave radius.
    Returns n_c (k, 3), phi (k,) in m (how far A must move along n_c to just touch B), and
    in_contact (k,) bool: the root of Eq. (8) is real and phi > 0.
    """
    dn = n2 - n1
    norm = np.sqrt(np.einsum("ij,ij->i", dn, dn))
    facing = norm > NORMAL_EPS
    n_c = dn / np.where(facing, norm, 1.0)[:, None]
    rel = c1 - c2
    chi = np.einsum("ij,ij->i", n_c, rel)  # Eq. (9)
    w = np.einsum("ij,ij->i", rel, rel) - (r1 + r2) ** 2  # Eq. (10)
    disc = chi * chi - w
    phi = -chi + np.sqrt(np.maximum(disc, 0.0))  # Eq. (8)
    return n_c, phi, facing & (disc >= 0.0) & (phi > 0.0)


def contact_point(c1, c2, r1, r2, n_c, phi):
    """One contact point per pair, shared by both bodies, m (k, 3).

    [reading] With d = c1 - c2 + phi n_c (Eq. 7), the spheres would just touch at
    c2 + r2/(r1 + r2) d; the point used is that tangency point moved back by phi/2 along n_c,
    the middle of the overlap. For coaxial spheres it lies halfway through the overlap.
    """
    d = c1 - c2 + phi[:, None] * n_c  # Eq. (7)
    return c2 + (r2 / (r1 + r2)) * d - 0.5 * phi[:, None] * n_c


def cutoff_distance(r1: float, r2: float, max_penetration: float) -> float:
    """Largest centre distance |c1 - c2| of a pair in contact whose phi <= max_penetration, m.

    If chi > 0, phi > 0 needs w < 0, i.e. |c1 - c2| < r1 + r2. If chi <= 0, phi >= |chi| and
    the distance across n_c is at most r1 + r2, so |c1 - c2|^2 <= (r1 + r2)^2 + phi^2. A run
    stops (diverged) before phi exceeds a sphere radius, so searching within this distance
    finds every pair the all-pairs search finds.
    """
    return float(np.hypot(r1 + r2, max_penetration))
