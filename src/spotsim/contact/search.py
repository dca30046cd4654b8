"""Which sphere pairs to test: coal broad phase over face patches, then a local grid search.

The paper's literal search (every master sphere against every slave sphere) is kept as
`all_pairs`, the reference the culled search is tested against.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .detection import NORMAL_EPS

#: The grid search keeps pairs whose penetration, computed in face coordinates, exceeds
#: -SEARCH_SLACK (m); the shared kernel `penetration` then decides. The slack absorbs the
#: round-off between the two formulas so that the search never drops a pair the kernel keeps.
SEARCH_SLACK = 1e-12



@dataclass(frozen=True)
class LayerSet:
    """All spheres of one role (master: fingers, slave: grooves), stacked.

    centres_J, normals_J: (n, 3) in the frame of the joint carrying each sphere.
    joint: (n,) that joint's index.  face: (n,) index of the face each sphere lies on.
    """

    radius: float
    centres_J: np.ndarray
    normals_J: np.ndarray
    joint: np.ndarray
    face: np.ndarray

    def __post_init__(self):
        groups = tuple((int(j), np.flatnonzero(self.joint == j)) for j in np.unique(self.joint))
        # spheres of one joint are usually contiguous: a slice then avoids a gather per step
        groups = tuple((j, slice(r[0], r[-1] + 1) if r[-1] - r[0] + 1 == len(r) else r) for j, r in groups)
        object.__setattr__(self, "groups", groups)

    def to_world(self, R_W, p_W, centres_J=None):
        """World centres and normals (n, 3) given each joint's rotation R_W[j] and origin p_W[j].

        centres_J: the centres to use instead of `self.centres_J` (fingers that have moved).
        """
        centres_J = self.centres_J if centres_J is None else centres_J
        C, N = np.empty_like(centres_J), np.empty_like(self.normals_J)
        for j, rows in self.groups:
            C[rows] = centres_J[rows] @ R_W[j].T + p_W[j]
            N[rows] = self.normals_J[rows] @ R_W[j].T
        return C, N


@dataclass(frozen=True)
class SlaveGrid:
    """A slave face's grid in its joint frame: sphere (i, j) is index_map[i, j] (-1 if none).

    `face` indexes the stacked maps of all slave faces (`FacePairs.maps`).
    """

    joint: int
    face: int
    origin_J: np.ndarray
    t1_J: np.ndarray
    t2_J: np.ndarray
    n_J: np.ndarray
    shape: tuple[int, int]


@dataclass(frozen=True)
class FacePair:
    """A master face and a slave face that may touch; `geom_pair` is its coal pair index."""

    master_slice: slice
    master_joint: int
    slave: SlaveGrid
    geom_pair: int


def grid_search(face_pairs, C1_J, N1_J, maps, R_W, p_W, r1: float, radius: float, cutoff: float):
    """Sphere pairs in contact (Eq. 6-10) inside the given face pairs, found locally.

    The slave spheres of a face lie on a regular grid of step `radius`, `radius` above its
    plane, so each master centre's grid coordinates (u, v) and lift above the plane bound
    the slave spheres within `cutoff` (m) to a small window: no distance to a far sphere is
    computed. Inside the window, the common normal is the face pair's, so Eq. (8) is
    evaluated in face coordinates.
    maps: (n_faces, ni, nj) global slave index of each grid node, -1 where there is none.
    C1_J, N1_J: (|S1|, 3) master centres and normals in their joints' frames. R_W, p_W: joint poses.
    r1, radius: master and slave sphere radii, m.
    Returns (master index, slave index) arrays of the pairs (a superset by SEARCH_SLACK).
    """
    if not face_pairs:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty
    rows, coords, face, shape, normal = [], [], [], [], []
    for fp in face_pairs:
        g, R, p = fp.slave, R_W[fp.slave.joint], p_W[fp.slave.joint]
        basis = np.stack([R @ g.t1_J, R @ g.t2_J, R @ g.n_J], axis=1)
        Rm, pm = R_W[fp.master_joint], p_W[fp.master_joint]
        dn = basis[:, 2] - Rm @ N1_J[fp.master_slice.start]
        if np.linalg.norm(dn) <= NORMAL_EPS:
            continue  # faces facing the same way never pair (Eq. 6 undefined)
        n = fp.master_slice.stop - fp.master_slice.start
        rows.append(np.arange(fp.master_slice.start, fp.master_slice.stop))
        # master centres in the slave face frame: basis^T (Rm c + pm - O)
        coords.append(C1_J[fp.master_slice] @ (Rm.T @ basis)
                      + (pm - (R @ g.origin_J + p)) @ basis)
        face.append(np.full(n, g.face))
        shape.append(np.broadcast_to(g.shape, (n, 2)))
        normal.append(np.broadcast_to(dn / np.linalg.norm(dn) @ basis, (n, 3)))
    if not rows:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty
    rows, uvh = np.concatenate(rows), np.concatenate(coords)
    face, shape, n_c = np.concatenate(face), np.concatenate(shape), np.concatenate(normal)
    u, v = uvh[:, 0] / radius, uvh[:, 1] / radius
    lift = uvh[:, 2] - radius  # slave centres lie `radius` above the face plane
    # within cutoff in 3-D means within sqrt(cutoff^2 - lift^2) in the face plane
    reach = np.sqrt(np.maximum(cutoff * cutoff - lift * lift, 0.0)) / radius
    near = ((np.abs(lift) < cutoff) & (u > -reach) & (u < shape[:, 0] - 1 + reach)
            & (v > -reach) & (v < shape[:, 1] - 1 + reach))
    # A row lifted by at least r1 + r2 has w >= 0, so it can touch only where chi < 0; chi is
    # at least n_h lift - |n_uv| (in-plane reach), which rules most such rows out.
    R = r1 + radius
    n_uv = np.hypot(n_c[:, 0], n_c[:, 1])
    near &= (lift < R + SEARCH_SLACK) | (n_c[:, 2] * lift <= n_uv * reach * radius + SEARCH_SLACK)
    keep = np.flatnonzero(near)
    if keep.size == 0:
        return keep, keep
    rows, u, v, lift, reach = rows[keep], u[keep], v[keep], lift[keep], reach[keep]
    face, n_c = face[keep], n_c[keep]
    k = int(np.floor(2.0 * reach.max())) + 1
    i = np.ceil(u - reach).astype(np.int64)[:, None, None] + np.arange(k)[None, :, None]
    j = np.ceil(v - reach).astype(np.int64)[:, None, None] + np.arange(k)[None, None, :]
    i, j = np.broadcast_arrays(i, j)
    ni, nj = maps.shape[1:]
    inside = (i >= 0) & (i < ni) & (j >= 0) & (j < nj)
    # c1 - c2 in face coordinates, then Eq. (8)-(10) with the face pair's common normal
    du = (u[:, None, None] - i) * radius
    dv = (v[:, None, None] - j) * radius
    dh = lift[:, None, None]
    chi = n_c[:, 0, None, None] * du + n_c[:, 1, None, None] * dv + n_c[:, 2, None, None] * dh
    disc = chi * chi - (du * du + dv * dv + dh * dh - (r1 + radius) ** 2)
    inside &= (disc >= -SEARCH_SLACK * cutoff) & (-chi + np.sqrt(np.maximum(disc, 0.0)) > -SEARCH_SLACK)
    r_idx, a, b = np.nonzero(inside)
    slave = maps[face[r_idx], i[r_idx, a, b], j[r_idx, a, b]]
    found = slave >= 0
    return rows[r_idx[found]], slave[found]


def face_slices(layers: LayerSet) -> list[slice]:
    """The contiguous run of spheres of each face of a stacked layer set."""
    starts = np.flatnonzero(np.r_[True, np.diff(layers.face) != 0, True])
    return [slice(a, b) for a, b in zip(starts[:-1], starts[1:])]


def all_pairs(master: LayerSet, slave: LayerSet, C1_W, N1_W, C2_W, N2_W):
    """The paper's literal search: every master sphere against every slave sphere, Eq. (6)-(10).

    C*_W, N*_W: (n, 3) world centres and normals of all spheres of each set. The spheres of
    one face share its normal, so the pairs are evaluated a block of two faces at a time
    (one common normal per block); no pair is skipped.
    Returns (master index, slave index) of the pairs in contact (a superset by SEARCH_SLACK;
    the shared kernel `penetration` decides).
    """
    found_m, found_s = [], []
    R = master.radius + slave.radius
    for b in face_slices(slave):
        # coordinates relative to a point of the slave face keep |c1 - c2|^2, expanded below,
        # free of cancellation: centres are within centimetres of it
        origin = C2_W[b.start]
        C2 = C2_W[b] - origin
        C2_sq = np.einsum("ij,ij->i", C2, C2)
        for a in face_slices(master):
            dn = N2_W[b.start] - N1_W[a.start]
            norm = np.linalg.norm(dn)
            if norm <= NORMAL_EPS:
                continue  # faces facing the same way: Eq. (6) undefined, no pair
            n_c = dn / norm
            C1 = C1_W[a] - origin
            chi = (C1 @ n_c)[:, None] - (C2 @ n_c)[None, :]  # Eq. (9)
            w = C1 @ C2.T
            w *= -2.0
            w += np.einsum("ij,ij->i", C1, C1)[:, None]
            w += C2_sq[None, :] - R * R  # Eq. (10)
            # phi = -chi + sqrt(chi^2 - w) > 0 with a real root  <=>  chi^2 >= w and
            # (chi < 0 or w < 0): the same test without a square root
            hit = chi * chi - w >= -SEARCH_SLACK * R
            hit &= (chi < SEARCH_SLACK) | (w < SEARCH_SLACK * R)
            i, j = np.nonzero(hit)
            found_m.append(i + a.start)
            found_s.append(j + b.start)
    if not found_m:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty
    return np.concatenate(found_m), np.concatenate(found_s)
