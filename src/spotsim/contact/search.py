"""Which sphere pairs to test: coal broad phase over face patches, then a local grid search.

The paper's literal search (every master sphere against every slave sphere) is kept as
`all_pairs`, the reference the culled search is tested against.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..bodies import mv3
from ..jit import njit, njit_inline
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


class FaceTable(NamedTuple):
    """The face pairs of a model stacked as arrays, for the compiled search (one row a pair)."""

    master_start: np.ndarray  # (n,) first master sphere of the pair's master face
    master_stop: np.ndarray  # (n,) one past its last
    master_joint: np.ndarray  # (n,)
    slave_joint: np.ndarray  # (n,)
    slave_face: np.ndarray  # (n,) index into the stacked slave grids (`maps`)
    origin_J: np.ndarray  # (n, 3) the slave grid's reference vertex, its joint's frame, m
    t1_J: np.ndarray  # (n, 3) the slave grid's in-plane axes and outward normal
    t2_J: np.ndarray
    n_J: np.ndarray
    shape: np.ndarray  # (n, 2) grid size
    # the mean of the master face's centres (its joint's frame, fingers at opening 0) and the
    # farthest of them from it, m: `_moved` bounds every centre's motion from these
    master_centre_J: np.ndarray  # (n, 3)
    master_radius: np.ndarray  # (n,)


def face_table(face_pairs, master_centres_J: np.ndarray) -> FaceTable:
    """The face pairs as one `FaceTable`; master_centres_J: (|S1|, 3) every master centre."""
    n = len(face_pairs)
    faces = [master_centres_J[fp.master_slice] for fp in face_pairs]
    centre = np.array([c.mean(axis=0) for c in faces], dtype=float).reshape(n, 3)
    radius = np.array([np.linalg.norm(c - m, axis=1).max() for c, m in zip(faces, centre)], dtype=float)
    vec = lambda name: np.array([getattr(fp.slave, name) for fp in face_pairs], dtype=float).reshape(n, 3)
    ints = lambda values: np.array(values, dtype=np.int64)
    return FaceTable(ints([fp.master_slice.start for fp in face_pairs]),
                     ints([fp.master_slice.stop for fp in face_pairs]),
                     ints([fp.master_joint for fp in face_pairs]),
                     ints([fp.slave.joint for fp in face_pairs]),
                     ints([fp.slave.face for fp in face_pairs]),
                     vec("origin_J"), vec("t1_J"), vec("t2_J"), vec("n_J"),
                     ints([fp.slave.shape for fp in face_pairs]).reshape(n, 2), centre, radius)


@njit
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit_inline
def _face_frame(f, table, N1_J, finger1, axis1_J, opening, R_W, p_W, A):
    """Face pair f's search frame: whether its faces face each other (Eq. 6 defined), the
    common normal in face coordinates (n_u, n_v, n_h), the offset `off` of the affine map
    A c + off taking a master centre c in its joint's frame to face coordinates (u, v, height
    above the face plane), and the common normal in world (3-tuple). A: (3, 3), the map's
    matrix, written in place (left as it was when the faces do not face each other)."""
    Rs, ps = R_W[table.slave_joint[f]], p_W[table.slave_joint[f]]
    b0, b1, b2 = mv3(Rs, table.t1_J[f]), mv3(Rs, table.t2_J[f]), mv3(Rs, table.n_J[f])
    Rm, pm = R_W[table.master_joint[f]], p_W[table.master_joint[f]]
    nm = mv3(Rm, N1_J[table.master_start[f]])
    dn = (b2[0] - nm[0], b2[1] - nm[1], b2[2] - nm[2])
    norm = math.sqrt(_dot(dn, dn))
    if norm <= NORMAL_EPS:
        return False, 0.0, 0.0, 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)  # faces facing the same way never pair
    n_W = (dn[0] / norm, dn[1] / norm, dn[2] / norm)
    # the common normal in face coordinates
    nu, nv, nh = _dot(dn, b0) / norm, _dot(dn, b1) / norm, _dot(dn, b2) / norm
    o = mv3(Rs, table.origin_J[f])
    # a master centre c (its joint's frame) in face coordinates is A c + off: the rows of A are
    # the face axes in the master's frame, and off holds the master origin and the finger's
    # opening, which shifts all the face's spheres alike (a face is on one finger)
    for k in range(3):
        A[0, k] = Rm[0, k] * b0[0] + Rm[1, k] * b0[1] + Rm[2, k] * b0[2]
        A[1, k] = Rm[0, k] * b1[0] + Rm[1, k] * b1[1] + Rm[2, k] * b1[2]
        A[2, k] = Rm[0, k] * b2[0] + Rm[1, k] * b2[1] + Rm[2, k] * b2[2]
    first = table.master_start[f]
    x = opening[finger1[first]]
    shift = (x * axis1_J[first, 0], x * axis1_J[first, 1], x * axis1_J[first, 2])
    e = (pm[0] - o[0] - ps[0], pm[1] - o[1] - ps[1], pm[2] - o[2] - ps[2])
    off = (A[0, 0] * shift[0] + A[0, 1] * shift[1] + A[0, 2] * shift[2] + _dot(e, b0),
           A[1, 0] * shift[0] + A[1, 1] * shift[1] + A[1, 2] * shift[2] + _dot(e, b1),
           A[2, 0] * shift[0] + A[2, 1] * shift[1] + A[2, 2] * shift[2] + _dot(e, b2))
    return True, nu, nv, nh, off, n_W


@njit
def _lift(A, off, c, radius):
    """Height of master centre c (its joint's frame) above the plane of the slave centres, m
    (they lie `radius` above the face plane)."""
    return A[2, 0] * c[0] + A[2, 1] * c[1] + A[2, 2] * c[2] + off[2] - radius


@njit
def _face_xy(A, off, c):
    """Master centre c's in-plane face coordinates, m."""
    return (A[0, 0] * c[0] + A[0, 1] * c[1] + A[0, 2] * c[2] + off[0],
            A[1, 0] * c[0] + A[1, 1] * c[1] + A[1, 2] * c[2] + off[1])


@njit
def _node_hit(du, dv, lift, w0, nu, nv, nh, cutoff):
    """Whether the pair of a master centre and a slave grid node may be in contact (Eq. 8-10
    in face coordinates, a superset by SEARCH_SLACK): du, dv, the centre's in-plane offset from
    the node, and lift, its height above the plane of the slave centres, m; w0 = lift^2 - R^2."""
    chi = nu * du + nh * lift + nv * dv
    disc = chi * chi - (du * du + w0 + dv * dv)
    if disc < -SEARCH_SLACK * cutoff:
        return False
    # phi = -chi + sqrt(disc) > -SEARCH_SLACK, tested without the root
    return not (chi > SEARCH_SLACK and max(disc, 0.0) <= (chi - SEARCH_SLACK) ** 2)


@njit
def _push(found_m, found_s, n_found, row, s):
    """Append (row, s) to the growing buffers; returns them (reallocated when full)."""
    if n_found == found_m.shape[0]:
        found_m, found_s = grow(found_m), grow(found_s)
    found_m[n_found], found_s[n_found] = row, s
    return found_m, found_s


@njit
def grid_search(near, table, C1_J, N1_J, finger1, axis1_J, opening, maps, n_slave, R_W, p_W, r1, radius,
                cutoff):
    """Sphere pairs in contact (Eq. 6-10) inside the face pairs `near`, found locally.

    The slave spheres of a face lie on a regular grid of step `radius`, `radius` above its
    plane, so each master centre's grid coordinates (u, v) and lift above the plane bound
    the slave spheres within `cutoff` (m) to a small window: no distance to a far sphere is
    computed. Inside the window, the common normal is the face pair's, so Eq. (8) is
    evaluated in face coordinates.
    near: (m,) indices into `table` (a FaceTable) of the face pairs to search.
    maps: (n_faces, ni, nj) global slave index of each grid node, -1 where there is none;
    n_slave: the number of slave spheres.
    C1_J, N1_J: (|S1|, 3) master centres (fingers at opening 0) and normals in their joints'
    frames; finger1, axis1_J: each master sphere's finger and its opening axis; opening:
    (n_fingers,) the fingers' openings, m. R_W, p_W: joint poses.
    r1, radius: master and slave sphere radii, m.
    Returns (master index, slave index, key = master * n_slave + slave) of the pairs, sorted
    by key (a superset by SEARCH_SLACK of the pairs in contact).
    """
    found_m = np.empty(64, dtype=np.int64)
    found_s = np.empty(64, dtype=np.int64)
    n_found = 0
    R = r1 + radius
    A = np.empty((3, 3))
    for f in near:
        facing, nu, nv, nh, off, _ = _face_frame(f, table, N1_J, finger1, axis1_J, opening, R_W, p_W, A)
        if not facing:
            continue
        n_uv = math.hypot(nu, nv)
        ni, nj = table.shape[f, 0], table.shape[f, 1]
        face = table.slave_face[f]
        for row in range(table.master_start[f], table.master_stop[f]):
            c = C1_J[row]
            lift = _lift(A, off, c, radius)
            if abs(lift) >= cutoff:  # slave centres lie `radius` above the face plane
                continue
            x, y = _face_xy(A, off, c)
            u, v = x / radius, y / radius  # in grid steps
            # within cutoff in 3-D means within sqrt(cutoff^2 - lift^2) in the face plane
            reach = math.sqrt(max(cutoff * cutoff - lift * lift, 0.0)) / radius
            if not (-reach < u < ni - 1 + reach and -reach < v < nj - 1 + reach):
                continue
            # A row lifted by at least r1 + r2 has w >= 0, so it can touch only where chi < 0;
            # chi is at least n_h lift - |n_uv| (in-plane reach), which rules most such rows out.
            if not (lift < R + SEARCH_SLACK or nh * lift <= n_uv * reach * radius + SEARCH_SLACK):
                continue
            # Where chi stays above SEARCH_SLACK over the whole window, a pair touches only
            # if w < 2 chi SEARCH_SLACK: its centres lie within the ball of radius ~R, whose
            # trace on the grid is a much smaller circle than the cutoff's
            if nh * lift - n_uv * reach * radius > SEARCH_SLACK:
                ball = R * R + 2.0 * cutoff * SEARCH_SLACK - lift * lift
                if ball < 0.0:
                    continue
                reach = min(reach, math.sqrt(ball) / radius)
            w0 = lift * lift - R * R
            for i in range(max(math.ceil(u - reach), 0), min(math.floor(u + reach), ni - 1) + 1):
                # the nodes of this grid row within reach: a chord of the reach circle
                half = math.sqrt(max(reach * reach - (u - i) ** 2, 0.0))
                for j in range(max(math.ceil(v - half), 0), min(math.floor(v + half), nj - 1) + 1):
                    s = maps[face, i, j]
                    if s >= 0 and _node_hit(x - i * radius, y - j * radius, lift, w0, nu, nv, nh, cutoff):
                        found_m, found_s = _push(found_m, found_s, n_found, row, s)
                        n_found += 1
    key = found_m[:n_found] * n_slave + found_s[:n_found]
    order = np.argsort(key)
    return found_m[:n_found][order], found_s[:n_found][order], key[order]


#: The pair list's reach beyond contact, m: it keeps the candidate pairs whose centres lie
#: within r1 + r2 + LIST_SKIN. A candidate is tested only once the spheres may have closed its
#: gap, so a wider skin costs little per step; a rebuild costs ~50 us.
LIST_SKIN = 30e-6
#: ... and while each listed face pair's common normal stays within this of the normal it was
#: built with (|n - n_built|, unit vectors): the listed pairs are then those of the ball regime.
LIST_NORMAL_TOL = 0.01
#: A candidate is tested while its gap at the build is at most the bound on how far its master
#: sphere has moved since then plus this, m: far above the round-off of the gaps and the bound
#: (~1e-16 m) and the SEARCH_SLACK band of the test (< 1e-12 m), far below a sphere's motion.
GAP_SLACK = 1e-9


class PairList(NamedTuple):
    """The candidate pairs of the face pairs a search has built (`build_pair_list`), grouped
    by face pair, each group ordered by gap."""

    master: np.ndarray  # (n,) master sphere of each candidate
    slave: np.ndarray  # (n,) slave sphere
    centre_J: np.ndarray  # (n, 3) the master sphere's centre, its joint's frame (fingers at opening 0), m
    node: np.ndarray  # (n, 2) the slave sphere's grid node in its face's coordinates, m
    gap: np.ndarray  # (n,) |c1 - c2| - (r1 + r2) at the build, m
    start: np.ndarray  # (n_table,) each face pair's first candidate
    stop: np.ndarray  # (n_table,) one past its last
    built: np.ndarray  # (n_table,) whether the face pair was among those the list was built for
    scan: np.ndarray  # (n_table,) whether it is searched anew at every step instead (not a ball)
    normal_W: np.ndarray  # (n_table, 3) its common normal (world) at the build
    A: np.ndarray  # (n_table, 3, 3) its map of master centres to face coordinates at the build (ball regime)
    off: np.ndarray  # (n_table, 3) and the map's offset (`_face_frame`)


def empty_pair_list(n_face_pairs: int) -> PairList:
    """A pair list that holds nothing and must be built at its first use."""
    none = np.zeros(0, dtype=np.int64)
    ints, flags = np.zeros(n_face_pairs, dtype=np.int64), np.zeros(n_face_pairs, dtype=np.bool_)
    return PairList(none, none, np.zeros((0, 3)), np.zeros((0, 2)), np.zeros(0), ints, ints.copy(), flags, flags.copy(),
                    np.zeros((n_face_pairs, 3)), np.zeros((n_face_pairs, 3, 3)), np.zeros((n_face_pairs, 3)))


@njit
def build_pair_list(near, table, C1_J, N1_J, finger1, axis1_J, opening, maps, n_slave, R_W, p_W, r1, radius,
                    cutoff):
    """The candidate pairs of the face pairs `near` that can come into contact while the
    spheres move less than LIST_SKIN relative to each other (a Verlet list).

    A face pair whose common normal makes chi = n . (c1 - c2) clearly positive for every pair
    within reach is in the ball regime: a pair there touches only if its centres are closer
    than r1 + r2 (+ round-off), so the list keeps the pairs closer than r1 + r2 + LIST_SKIN,
    with their gap, each face pair's candidates ordered by gap. Chi moves by at most the
    spheres' motion plus the normal's turn times the cutoff, which the margin covers. Any
    other face pair (faces tilted far from each other) is marked to be searched anew at every
    step. Arguments as `grid_search`; returns a `PairList`.
    """
    n_table = table.master_start.shape[0]
    built = np.zeros(n_table, dtype=np.bool_)
    scan = np.zeros(n_table, dtype=np.bool_)
    start, stop = np.zeros(n_table, dtype=np.int64), np.zeros(n_table, dtype=np.int64)
    normal_W, A_b, off_b = np.zeros((n_table, 3)), np.zeros((n_table, 3, 3)), np.zeros((n_table, 3))
    cap = 256
    lm, ls, gap = np.empty(cap, dtype=np.int64), np.empty(cap, dtype=np.int64), np.empty(cap)
    node_u, node_v = np.empty(cap), np.empty(cap)  # the node's face coordinates, m
    n = 0
    R = r1 + radius
    reach_3d = R + LIST_SKIN
    chi_margin = LIST_SKIN + LIST_NORMAL_TOL * cutoff + SEARCH_SLACK
    inv = 1.0 / radius  # the list needs no exact grid coordinates: GAP_SLACK absorbs round-off
    for f in near:
        built[f] = True
        A = A_b[f]
        facing, nu, nv, nh, off, n_W = _face_frame(f, table, N1_J, finger1, axis1_J, opening, R_W, p_W, A)
        if not facing:
            scan[f] = True
            continue
        n_uv = math.hypot(nu, nv)
        ni, nj = table.shape[f, 0], table.shape[f, 1]
        face = table.slave_face[f]
        first, ball = n, True
        for row in range(table.master_start[f], table.master_stop[f]):
            c = C1_J[row]
            lift = _lift(A, off, c, radius)
            if abs(lift) >= cutoff + LIST_SKIN:  # no slave centre within the cutoff meanwhile
                continue
            if nh * lift - n_uv * (cutoff + LIST_SKIN) <= chi_margin:
                ball = False
                break
            if lift >= reach_3d:
                continue
            r_sq = reach_3d * reach_3d - lift * lift  # in-plane reach squared, m^2
            reach = math.sqrt(r_sq) * inv
            u = (A[0, 0] * c[0] + A[0, 1] * c[1] + A[0, 2] * c[2] + off[0]) * inv
            v = (A[1, 0] * c[0] + A[1, 1] * c[1] + A[1, 2] * c[2] + off[1]) * inv
            j0, j1 = max(math.ceil(v - reach), 0), min(math.floor(v + reach), nj - 1)
            for i in range(max(math.ceil(u - reach), 0), min(math.floor(u + reach), ni - 1) + 1):
                du = (u - i) * radius
                for j in range(j0, j1 + 1):
                    dv = (v - j) * radius
                    s = maps[face, i, j]
                    if s < 0 or du * du + dv * dv >= r_sq:
                        continue
                    if n == lm.shape[0]:
                        lm, ls, gap = grow(lm), grow(ls), grow(gap)
                        node_u, node_v = grow(node_u), grow(node_v)
                    lm[n], ls[n], node_u[n], node_v[n] = row, s, i * radius, j * radius
                    gap[n] = math.sqrt(du * du + dv * dv + lift * lift) - R
                    n += 1
        if not ball:
            scan[f] = True
            n = first
            continue
        order = np.argsort(gap[first:n]) + first
        lm[first:n], ls[first:n], node_u[first:n], node_v[first:n], gap[first:n] = (
            lm[order], ls[order], node_u[order], node_v[order], gap[order])
        start[f], stop[f] = first, n
        normal_W[f, 0], normal_W[f, 1], normal_W[f, 2] = n_W
        off_b[f, 0], off_b[f, 1], off_b[f, 2] = off
    # each candidate's master centre and node side by side, for the test at every step
    centre, node = np.empty((n, 3)), np.empty((n, 2))
    for q in range(n):
        centre[q, 0], centre[q, 1], centre[q, 2] = C1_J[lm[q], 0], C1_J[lm[q], 1], C1_J[lm[q], 2]
        node[q, 0], node[q, 1] = node_u[q], node_v[q]
    return PairList(lm[:n].copy(), ls[:n].copy(), centre, node, gap[:n].copy(), start, stop, built,
                    scan, normal_W, A_b, off_b)


@njit
def grow(a):
    return np.concatenate((a, np.empty(a.shape[0], dtype=a.dtype)))


@njit_inline
def _moved(A, off, A_b, off_b, centre, spread):
    """A bound on how far any master centre of a face pair has moved in face coordinates
    (relative to the slave spheres) since the pair list's build, m: the map x = A c + off
    moved every centre c = centre + d (|d| <= spread) by (A - A_b) centre + (off - off_b) +
    (A - A_b) d, the last at most |A - A_b|_F spread."""
    shift = 0.0
    norm_sq = 0.0
    for r in range(3):
        x = off[r] - off_b[r]
        for k in range(3):
            d = A[r, k] - A_b[r, k]
            x += d * centre[k]
            norm_sq += d * d
        shift += x * x
    return math.sqrt(shift) + math.sqrt(norm_sq) * spread


@njit_inline
def listed_search(near, table, C1_J, N1_J, finger1, axis1_J, opening, maps, n_slave, R_W, p_W, r1, radius,
                  cutoff, pair_list):
    """`grid_search`'s pairs, tested only among the candidates of a pair list kept between
    steps (`build_pair_list`).

    The list is rebuilt when a face pair in `near` was not among those it was built for, a
    face pair's normal has turned, or its master spheres may have moved LIST_SKIN relative
    to its slave spheres since the build (`_moved`, computed from the two poses: exact, not
    integrated over the steps). Within a face pair, only the candidates whose gap at the build
    that motion could have closed are tested. Returns (master, slave, key) as `grid_search`
    does, and the pair list.
    """
    k = near.shape[0]
    # each face pair's map (rows 0-2) and offset (row 3), its normal in face coordinates (row
    # 4) and the bound on its motion (row 5, first entry), in one block: a step makes dozens
    # of small arrays, ~25 ns each
    frames = np.empty((k, 6, 3))
    moved = frames[:, 5, 0]
    valid = True
    for m in range(k):
        f = near[m]
        A = frames[m][:3]
        facing, nu, nv, nh, off, n_W = _face_frame(f, table, N1_J, finger1, axis1_J, opening, R_W, p_W, A)
        frames[m, 3, 0], frames[m, 3, 1], frames[m, 3, 2] = off
        frames[m, 4, 0], frames[m, 4, 1], frames[m, 4, 2] = nu, nv, nh
        if not pair_list.built[f]:
            valid = False
        elif not pair_list.scan[f]:
            turn = math.sqrt((n_W[0] - pair_list.normal_W[f, 0]) ** 2 + (n_W[1] - pair_list.normal_W[f, 1]) ** 2
                             + (n_W[2] - pair_list.normal_W[f, 2]) ** 2)
            moved[m] = _moved(A, off, pair_list.A[f], pair_list.off[f], table.master_centre_J[f],
                              table.master_radius[f])
            if not facing or turn > LIST_NORMAL_TOL or moved[m] >= LIST_SKIN - GAP_SLACK:
                valid = False
    if not valid:
        pair_list = build_pair_list(near, table, C1_J, N1_J, finger1, axis1_J, opening, maps, n_slave, R_W, p_W,
                                    r1, radius, cutoff)
        moved[:] = 0.0
    lm, ls, centre, node, gap = pair_list.master, pair_list.slave, pair_list.centre_J, pair_list.node, pair_list.gap
    R = r1 + radius
    n_out = 0
    for m in range(k):
        n_out += pair_list.stop[near[m]] - pair_list.start[near[m]]
    out = np.empty((2, n_out), dtype=np.int64)
    out_m, out_s = out[0], out[1]
    n = n_searched = 0
    for m in range(k):
        f = near[m]
        if pair_list.scan[f]:
            n_searched += 1
            continue
        F = frames[m]
        nu, nv, nh = F[4, 0], F[4, 1], F[4, 2]
        # the map's entries as scalars: `_face_xy` and `_lift`, term by term in their order
        a00, a01, a02, a10, a11, a12 = F[0, 0], F[0, 1], F[0, 2], F[1, 0], F[1, 1], F[1, 2]
        a20, a21, a22, o0, o1, o2 = F[2, 0], F[2, 1], F[2, 2], F[3, 0], F[3, 1], F[3, 2]
        reach = moved[m] + GAP_SLACK
        for idx in range(pair_list.start[f], pair_list.stop[f]):
            if gap[idx] > reach:
                break  # ordered by gap: no later candidate can touch either
            c0, c1, c2 = centre[idx, 0], centre[idx, 1], centre[idx, 2]
            lift = a20 * c0 + a21 * c1 + a22 * c2 + o2 - radius
            du = a00 * c0 + a01 * c1 + a02 * c2 + o0 - node[idx, 0]
            dv = a10 * c0 + a11 * c1 + a12 * c2 + o1 - node[idx, 1]
            if _node_hit(du, dv, lift, lift * lift - R * R, nu, nv, nh, cutoff):
                out_m[n], out_s[n] = lm[idx], ls[idx]
                n += 1
    out_m, out_s = out_m[:n], out_s[:n]
    if n_searched:  # face pairs outside the ball regime: searched anew
        searched = np.empty(n_searched, dtype=np.int64)
        n_searched = 0
        for f in near:
            if pair_list.scan[f]:
                searched[n_searched] = f
                n_searched += 1
        sm, ss, _ = grid_search(searched, table, C1_J, N1_J, finger1, axis1_J, opening, maps, n_slave, R_W, p_W,
                                r1, radius, cutoff)
        out_m, out_s = np.concatenate((out_m, sm)), np.concatenate((out_s, ss))
    return _by_key(out_m, out_s, n_slave), pair_list  # by key, as grid_search returns them


@njit
def _by_key(master, slave, n_slave):
    """(master, slave, key = master n_slave + slave) ordered by key, the keys unique; master
    and slave are reordered in place. By insertion: the listed search finds its pairs in a
    few runs (one per face pair), so its order is nearly the keys'."""
    n = master.shape[0]
    key = master * n_slave + slave
    if n > 64:  # far from sorted, insertion would cost ~n^2
        order = np.argsort(key)
        return master[order], slave[order], key[order]
    for a in range(1, n):
        k, m, s = key[a], master[a], slave[a]
        b = a - 1
        while b >= 0 and key[b] > k:
            key[b + 1], master[b + 1], slave[b + 1] = key[b], master[b], slave[b]
            b -= 1
        key[b + 1], master[b + 1], slave[b + 1] = k, m, s
    return master, slave, key


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
