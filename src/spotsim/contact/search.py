"""Stage: the sphere pairs to test (paper Sec. 3.1.2, Eq. 6-10), culled or literal.

The culled search takes the face pairs coal's broad phase left within its margin (`d.near`)
and, inside them, only the candidates of a Verlet pair list kept between steps. The paper's
literal search tests every master sphere against every slave sphere; it is the reference the
culled search is tested against. Both give a superset (by SEARCH_SLACK) of the pairs in
contact; the pair-force kernel decides.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..jit import njit, njit_inline
from ..linalg import dot3, mv3
from .detection import NORMAL_EPS

#: The grid search keeps pairs whose penetration, computed in face coordinates, exceeds
#: -SEARCH_SLACK (m); the shared kernel `penetration1` then decides. The slack absorbs the
#: round-off between the two formulas so that the search never drops a pair the kernel keeps.
SEARCH_SLACK = 1e-12
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
#: Found pairs are put in key order by insertion up to this many (the listed search finds them
#: in a few runs, nearly ordered), by argsort past it (insertion would cost ~n^2).
INSERTION_SORT_MAX = 64


class Candidates(NamedTuple):
    """Sphere pairs to test, sorted by key = master * |S2| + slave (keys unique), and how far
    every other sphere pair of the searched face pairs is from touching."""

    master: np.ndarray  # (k,)
    slave: np.ndarray  # (k,)
    key: np.ndarray  # (k,)
    # a lower bound on |c1 - c2| - (r1 + r2) over the sphere pairs of the face pairs searched
    # that are not candidates, m: how far spheres may close before a new pair can start (0:
    # no bound known, as for a face pair searched anew at every step or the literal search)
    clearance: float


class PairList(NamedTuple):
    """The candidate pairs of the face pairs a search has built (`build_pair_list`), grouped
    by face pair, each group ordered by gap."""

    master: np.ndarray  # (n,) master sphere of each candidate
    slave: np.ndarray  # (n,) slave sphere
    centre_J: np.ndarray  # (n, 3) the master sphere's centre, its joint's frame, m
    node: np.ndarray  # (n, 2) the slave sphere's grid node in its face's coordinates, m
    gap: np.ndarray  # (n,) |c1 - c2| - (r1 + r2) at the build, m
    start: np.ndarray  # (n_table,) each face pair's first candidate
    stop: np.ndarray  # (n_table,) one past its last
    built: np.ndarray  # (n_table,) whether the face pair was among those the list was built for
    scan: np.ndarray  # (n_table,) whether it is searched anew at every step instead (not a ball)
    normal_W: np.ndarray  # (n_table, 3) its common normal (world) at the build
    A: np.ndarray  # (n_table, 3, 3) its map of master centres to face coordinates at the build (ball regime)
    off: np.ndarray  # (n_table, 3) and the map's offset (`FaceFrame`)


def empty_pair_list(n_face_pairs: int) -> PairList:
    """A pair list that holds nothing and must be built at its first use."""
    none = np.zeros(0, dtype=np.int64)
    ints, flags = np.zeros(n_face_pairs, dtype=np.int64), np.zeros(n_face_pairs, dtype=np.bool_)
    return PairList(none, none, np.zeros((0, 3)), np.zeros((0, 2)), np.zeros(0), ints, ints.copy(), flags, flags.copy(),
                    np.zeros((n_face_pairs, 3)), np.zeros((n_face_pairs, 3, 3)), np.zeros((n_face_pairs, 3)))


def no_candidates() -> Candidates:
    none = np.zeros(0, dtype=np.int64)
    return Candidates(none, none.copy(), none.copy(), 0.0)


@njit
def find_pairs(m, d):
    """Stage: d.candidates, the sphere pairs to test at the current kinematics: the culled
    search (`listed_search`), or the paper's literal one (`literal_search`) when m.literal."""
    if m.literal:
        d.candidates = literal_search(m, d)
    else:
        d.candidates = listed_search(m, d)


@njit
def grow(a):
    """a with its first axis doubled (the new half uninitialised)."""
    return np.concatenate((a, np.empty(a.shape, dtype=a.dtype)))


class FaceFrame(NamedTuple):
    """A face pair's search frame (`face_frame`)."""

    facing: bool  # its faces face each other: Eq. (6) is defined
    nu: float  # the common normal in face coordinates (u, v along the slave face, h along its normal)
    nv: float
    nh: float
    off: tuple  # the offset of the map A c + off of master centres to face coordinates, m
    normal_W: tuple  # the common normal in world


@njit_inline
def face_frame(m, d, f, A):
    """Face pair f's search frame at d's kinematics, a FaceFrame: the map
    A c + off takes a master centre c in its joint's frame to face coordinates (u, v, height
    above the face plane). A: (3, 3), the map's matrix, written in place (left as it was when
    the faces do not face each other)."""
    js, jm, first = m.faces.slave_joint[f], m.faces.master_joint[f], m.faces.master_start[f]
    b0, b1, b2 = mv3(d.R_W[js], m.faces.t1_J[f]), mv3(d.R_W[js], m.faces.t2_J[f]), mv3(d.R_W[js], m.faces.n_J[f])
    nm = mv3(d.R_W[jm], m.master.normal_J[first])
    dn = (b2[0] - nm[0], b2[1] - nm[1], b2[2] - nm[2])
    norm = math.sqrt(dot3(dn, dn))
    if norm <= NORMAL_EPS:
        return FaceFrame(False, 0.0, 0.0, 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))  # facing the same way: never a pair
    n_W = (dn[0] / norm, dn[1] / norm, dn[2] / norm)
    # the common normal in face coordinates
    nu, nv, nh = dot3(dn, b0) / norm, dot3(dn, b1) / norm, dot3(dn, b2) / norm
    o = mv3(d.R_W[js], m.faces.origin_J[f])
    # a master centre c (its joint's frame) in face coordinates is A c + off: the rows of A are
    # the face axes in the master's frame, and off holds the master origin
    for k in range(3):
        A[0, k] = d.R_W[jm, 0, k] * b0[0] + d.R_W[jm, 1, k] * b0[1] + d.R_W[jm, 2, k] * b0[2]
        A[1, k] = d.R_W[jm, 0, k] * b1[0] + d.R_W[jm, 1, k] * b1[1] + d.R_W[jm, 2, k] * b1[2]
        A[2, k] = d.R_W[jm, 0, k] * b2[0] + d.R_W[jm, 1, k] * b2[1] + d.R_W[jm, 2, k] * b2[2]
    e = (d.p_W[jm, 0] - o[0] - d.p_W[js, 0], d.p_W[jm, 1] - o[1] - d.p_W[js, 1], d.p_W[jm, 2] - o[2] - d.p_W[js, 2])
    off = (dot3(e, b0), dot3(e, b1), dot3(e, b2))
    return FaceFrame(True, nu, nv, nh, off, n_W)


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
def grid_search(m, d, near):
    """The sphere pairs in contact (Eq. 6-10) inside the face pairs `near` (indices into
    m.faces), found locally, as Candidates (a superset by SEARCH_SLACK).

    The slave spheres of a face lie on a regular grid of step r2, r2 above its plane, so each
    master centre's grid coordinates (u, v) and lift above the plane bound the slave spheres
    within the cutoff to a small window: no distance to a far sphere is computed. Inside the
    window, the common normal is the face pair's, so Eq. (8) is evaluated in face coordinates.
    """
    table, C1_J, maps = m.faces, m.master.centre_J, m.slave.maps
    r1, radius, cutoff = m.law.r1, m.law.r2, m.law.cutoff
    found_m = np.empty(64, dtype=np.int64)
    found_s = np.empty(64, dtype=np.int64)
    n_found = 0
    R = r1 + radius
    A = np.empty((3, 3))
    for f in near:
        facing, nu, nv, nh, off, _ = face_frame(m, d, f, A)
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
    key = found_m[:n_found] * m.slave.centre_J.shape[0] + found_s[:n_found]
    order = np.argsort(key)
    return Candidates(found_m[:n_found][order], found_s[:n_found][order], key[order], 0.0)


@njit
def build_pair_list(m, d, near):
    """The candidate pairs of the face pairs `near` that can come into contact while the
    spheres move less than LIST_SKIN relative to each other (a Verlet list), as a PairList.

    A face pair whose common normal makes chi = n . (c1 - c2) clearly positive for every pair
    within reach is in the ball regime: a pair there touches only if its centres are closer
    than r1 + r2 (+ round-off), so the list keeps the pairs closer than r1 + r2 + LIST_SKIN,
    with their gap, each face pair's candidates ordered by gap. Chi moves by at most the
    spheres' motion plus the normal's turn times the cutoff, which the margin covers. Any
    other face pair (faces tilted far from each other) is marked to be searched anew at every
    step (`grid_search`).
    """
    table, C1_J, maps = m.faces, m.master.centre_J, m.slave.maps
    r1, radius, cutoff = m.law.r1, m.law.r2, m.law.cutoff
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
        facing, nu, nv, nh, off, n_W = face_frame(m, d, f, A)
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
            delta = A[r, k] - A_b[r, k]
            x += delta * centre[k]
            norm_sq += delta * delta
        shift += x * x
    return math.sqrt(shift) + math.sqrt(norm_sq) * spread


@njit
def listed_search(m, d):
    """`grid_search`'s pairs in d.near, tested only among the candidates of the pair list
    d.pair_list, which it rebuilds when it must (`build_pair_list`); returns Candidates.

    The list is rebuilt when a face pair in d.near was not among those it was built for, a
    face pair's normal has turned, or its master spheres may have moved LIST_SKIN relative
    to its slave spheres since the build (`_moved`, computed from the two poses: exact, not
    integrated over the steps). Within a face pair, only the candidates whose gap at the build
    that motion could have closed are tested.
    """
    k = d.near.shape[0]
    # each face pair's map (rows 0-2) and offset (row 3), its normal in face coordinates (row
    # 4) and the bound on its motion (row 5, first entry), in one block: a step makes dozens
    # of small arrays, ~25 ns each
    frames = np.empty((k, 6, 3))
    moved = frames[:, 5, 0]
    valid = True
    for i in range(k):
        f = d.near[i]
        A = frames[i][:3]
        facing, nu, nv, nh, off, n_W = face_frame(m, d, f, A)
        frames[i, 3, 0], frames[i, 3, 1], frames[i, 3, 2] = off
        frames[i, 4, 0], frames[i, 4, 1], frames[i, 4, 2] = nu, nv, nh
        if not d.pair_list.built[f]:
            valid = False
        elif not d.pair_list.scan[f]:
            turn = math.sqrt((n_W[0] - d.pair_list.normal_W[f, 0]) ** 2 + (n_W[1] - d.pair_list.normal_W[f, 1]) ** 2
                             + (n_W[2] - d.pair_list.normal_W[f, 2]) ** 2)
            moved[i] = _moved(A, off, d.pair_list.A[f], d.pair_list.off[f], m.faces.master_centre_J[f],
                              m.faces.master_radius[f])
            if not facing or turn > LIST_NORMAL_TOL or moved[i] >= LIST_SKIN - GAP_SLACK:
                valid = False
    if not valid:
        d.pair_list = build_pair_list(m, d, d.near)
        moved[:] = 0.0
    radius, cutoff = m.law.r2, m.law.cutoff
    R = m.law.r1 + radius
    n_out = 0
    for i in range(k):
        n_out += d.pair_list.stop[d.near[i]] - d.pair_list.start[d.near[i]]
    out = np.empty((2, n_out), dtype=np.int64)
    out_m, out_s = out[0], out[1]
    n = n_searched = 0
    # in the ball regime a pair touches only once its centres are closer than R: the least
    # |c1 - c2| - R of the pairs that are not candidates bounds how far spheres may close
    # before a new pair starts (a tested pair's, exact; an untested one's, its gap at the build
    # less the bound on the motion since; a pair beyond the list, at least LIST_SKIN less it)
    clearance = math.inf
    nearest_sq = math.inf  # the least |c1 - c2|^2 of the tested pairs that miss: one root at the end
    for i in range(k):
        f = d.near[i]
        if d.pair_list.scan[f]:
            n_searched += 1
            continue
        F = frames[i]
        nu, nv, nh = F[4, 0], F[4, 1], F[4, 2]
        # the map's entries as scalars: `_face_xy` and `_lift`, term by term in their order
        a00, a01, a02, a10, a11, a12 = F[0, 0], F[0, 1], F[0, 2], F[1, 0], F[1, 1], F[1, 2]
        a20, a21, a22, o0, o1, o2 = F[2, 0], F[2, 1], F[2, 2], F[3, 0], F[3, 1], F[3, 2]
        reach = moved[i] + GAP_SLACK
        untested = LIST_SKIN
        for idx in range(d.pair_list.start[f], d.pair_list.stop[f]):
            if d.pair_list.gap[idx] > reach:
                untested = d.pair_list.gap[idx]
                break  # ordered by gap: no later candidate can touch either
            c0, c1, c2 = d.pair_list.centre_J[idx, 0], d.pair_list.centre_J[idx, 1], d.pair_list.centre_J[idx, 2]
            lift = a20 * c0 + a21 * c1 + a22 * c2 + o2 - radius
            du = a00 * c0 + a01 * c1 + a02 * c2 + o0 - d.pair_list.node[idx, 0]
            dv = a10 * c0 + a11 * c1 + a12 * c2 + o1 - d.pair_list.node[idx, 1]
            if _node_hit(du, dv, lift, lift * lift - R * R, nu, nv, nh, cutoff):
                out_m[n], out_s[n] = d.pair_list.master[idx], d.pair_list.slave[idx]
                n += 1
            else:
                nearest_sq = min(nearest_sq, du * du + dv * dv + lift * lift)
        clearance = min(clearance, untested - moved[i])
    clearance = min(clearance, math.sqrt(nearest_sq) - R)
    out_m, out_s = out_m[:n], out_s[:n]
    if n_searched:  # face pairs outside the ball regime: searched anew, no clearance known
        clearance = 0.0
        searched = np.empty(n_searched, dtype=np.int64)
        n_searched = 0
        for f in d.near:
            if d.pair_list.scan[f]:
                searched[n_searched] = f
                n_searched += 1
        found = grid_search(m, d, searched)
        out_m, out_s = np.concatenate((out_m, found.master)), np.concatenate((out_s, found.slave))
    return by_key(out_m, out_s, m.slave.centre_J.shape[0], max(clearance, 0.0))


@njit
def by_key(master, slave, n_slave, clearance):
    """Candidates of (master, slave), ordered by key = master n_slave + slave (keys unique),
    with their `clearance`; master and slave are reordered in place."""
    n = master.shape[0]
    key = master * n_slave + slave
    if n > INSERTION_SORT_MAX:
        order = np.argsort(key)
        return Candidates(master[order], slave[order], key[order], clearance)
    for a in range(1, n):
        k, mm, s = key[a], master[a], slave[a]
        b = a - 1
        while b >= 0 and key[b] > k:
            key[b + 1], master[b + 1], slave[b + 1] = key[b], master[b], slave[b]
            b -= 1
        key[b + 1], master[b + 1], slave[b + 1] = k, mm, s
    return Candidates(master, slave, key, clearance)


@njit
def _runs(face):
    """(n_runs + 1,) the first sphere of each contiguous run of one face, and the end."""
    starts = np.empty(face.shape[0] + 1, dtype=np.int64)
    n = 0
    for i in range(face.shape[0]):
        if i == 0 or face[i] != face[i - 1]:
            starts[n] = i
            n += 1
    starts[n] = face.shape[0]
    return starts[:n + 1]


@njit
def world_spheres(m, d):
    """The world centres and normals of every master and slave sphere at d's kinematics:
    (|S1|, 3) x 2, (|S2|, 3) x 2, m."""
    M, S = m.master, m.slave
    R_W, p_W = d.R_W, d.p_W
    C1, N1 = np.empty_like(M.centre_J), np.empty_like(M.normal_J)
    C2, N2 = np.empty_like(S.centre_J), np.empty_like(S.normal_J)
    for i in range(C1.shape[0]):
        R, p = R_W[M.joint[i]], p_W[M.joint[i]]
        C1[i, 0], C1[i, 1], C1[i, 2] = mv3(R, M.centre_J[i])
        N1[i, 0], N1[i, 1], N1[i, 2] = mv3(R, M.normal_J[i])
        for a in range(3):
            C1[i, a] += p[a]
    for i in range(C2.shape[0]):
        R, p = R_W[S.joint[i]], p_W[S.joint[i]]
        C2[i, 0], C2[i, 1], C2[i, 2] = mv3(R, S.centre_J[i])
        N2[i, 0], N2[i, 1], N2[i, 2] = mv3(R, S.normal_J[i])
        for a in range(3):
            C2[i, a] += p[a]
    return C1, N1, C2, N2


@njit
def _touches(chi, w, R):
    """Whether phi = -chi + sqrt(chi^2 - w) > 0 with a real root, a superset by SEARCH_SLACK:
    chi^2 >= w and (chi < 0 or w < 0), the same test without a square root (Eq. 8)."""
    return (chi * chi - w >= -SEARCH_SLACK * R) & ((chi < SEARCH_SLACK) | (w < SEARCH_SLACK * R))


@njit
def literal_search(m, d):
    """The paper's literal search: every master sphere against every slave sphere of a face
    that can touch its own (m.faces' pairs), Eq. (6)-(10), as Candidates (a superset by
    SEARCH_SLACK; `penetration` decides).

    The spheres of one face share its normal, so each block of two faces has one common
    normal; no pair is skipped. Coordinates are taken relative to a point of the slave face, so
    that |c1 - c2|^2, expanded, is free of cancellation: centres are within centimetres of it.
    Each block's products c1 . c2 come from one matrix product, and its pairs are counted
    without a branch before the few that touch are listed.
    """
    C1, N1, C2, N2 = world_spheres(m, d)
    R = m.law.r1 + m.law.r2
    table, slave_runs = m.faces, _runs(m.slave.face)
    # each slave centre relative to its face's first, and |c2|^2 - R^2 of Eq. (10): once per face,
    # however many master faces it pairs with
    C2_rel = np.empty_like(C2)
    for b in range(slave_runs.shape[0] - 1):
        C2_rel[slave_runs[b]:slave_runs[b + 1]] = C2[slave_runs[b]:slave_runs[b + 1]] - C2[slave_runs[b]]
    W2 = (C2_rel * C2_rel).sum(axis=1) - R * R
    found_m = np.empty(64, dtype=np.int64)
    found_s = np.empty(64, dtype=np.int64)
    n_found = 0
    for f in range(table.master_start.shape[0]):  # every pair of faces that can touch
        b = table.slave_face[f]
        s0, s1 = slave_runs[b], slave_runs[b + 1]
        C2b, w2 = C2_rel[s0:s1], W2[s0:s1]
        a0, a1 = table.master_start[f], table.master_stop[f]
        dn = (N2[s0, 0] - N1[a0, 0], N2[s0, 1] - N1[a0, 1], N2[s0, 2] - N1[a0, 2])
        norm = math.sqrt(dot3(dn, dn))
        if norm <= NORMAL_EPS:
            continue  # faces facing the same way: Eq. (6) undefined, no pair
        n_c = np.array((dn[0] / norm, dn[1] / norm, dn[2] / norm))
        C1b = C1[a0:a1] - C2[s0]
        products = C1b @ C2b.T  # every c1 . c2 of the block (BLAS)
        chi1, chi2, w1 = C1b @ n_c, C2b @ n_c, (C1b * C1b).sum(axis=1)
        for i in range(a1 - a0):
            row = products[i]
            hits = 0
            for j in range(s1 - s0):  # chi (Eq. 9) and w (Eq. 10) of each pair
                hits += _touches(chi1[i] - chi2[j], w1[i] - 2.0 * row[j] + w2[j], R)
            if hits == 0:
                continue
            for j in range(s1 - s0):
                if _touches(chi1[i] - chi2[j], w1[i] - 2.0 * row[j] + w2[j], R):
                    found_m, found_s = _push(found_m, found_s, n_found, a0 + i, s0 + j)
                    n_found += 1
    key = found_m[:n_found] * C2.shape[0] + found_s[:n_found]
    order = np.argsort(key)
    return Candidates(found_m[:n_found][order], found_s[:n_found][order], key[order], 0.0)
