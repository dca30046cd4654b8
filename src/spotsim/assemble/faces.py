"""Virtual sphere layers on planar contact faces (paper Sec. 3.1.1, Eq. 1-5).

A face is a convex planar polygon given by its vertices in its body frame. Its layer is a
regular grid of step r over the face, each point lifted by r along the outward normal so
that every sphere is tangent to the face.
"""

from __future__ import annotations

import functools
import io
import re
from dataclasses import dataclass

import numpy as np

from ..errors import ModelError

#: Points this close outside a face edge (in units of the grid step) still count as inside,
#: so that grid points landing on an edge are not lost to round-off.
EDGE_TOLERANCE = 1e-9


#: The kinds of contact face, by the end of their collision's name: a groove's or a finger's
#: flank (`*_flank_pos`, `*_flank_neg`), a finger's truncated tip (`*_tip`) and the adapter's
#: land beside a groove's mouth (`*_land_pos`, `*_land_neg`).
FACE_KINDS = {"flank": re.compile(r"_flank_(pos|neg)$"), "tip": re.compile(r"_tip$"),
              "land": re.compile(r"_land_(pos|neg)$")}
#: The kinds of face whose sphere layer is inset by its radius from the face's edges (`inset`):
#: the lands, so that their spheres end at the mouth's edge instead of reaching r2 past it, over
#: the mouth, where they caught a tip still inside it (a start 10 mm off, within the claimed
#: tolerance, ended held on the edge 11.3 mm off). The flanks keep the paper's layers, and so do
#: the tips: inset as well, a tip 12 mm off rests on a single row of the land's edge spheres and
#: the run's steps underflow.
INSET_KINDS = ("land",)
#: The kinds of master (finger) and slave (module) face that can touch: a flank its groove's
#: flank, a tip the land it comes down on beside a mouth. A tip's edge spheres stand past its
#: flank's plane, so a tip is not paired with a groove's flank: at the seat they would press it.
TOUCHING_KINDS = (("flank", "flank"), ("tip", "land"))


@dataclass(frozen=True)
class Face:
    """A planar contact face: `vertices_L` (k, 3) in the frame of link `link`, m; its `kind`
    one of FACE_KINDS."""

    name: str
    link: str
    vertices_L: np.ndarray
    box_size: np.ndarray
    T_LC: np.ndarray  # (4, 4) pose of the face's box in the link frame
    kind: str = "flank"


@dataclass(frozen=True)
class SphereLayer:
    """The spheres of one face, in the face's body frame.

    centres: (m, 3) sphere centres, m.  normal: (3,) outward unit normal.
    origin, t1, t2: the grid's reference vertex N_0 and in-plane basis (Eq. 3-4).
    grid_ij: (m, 2) grid indices of each sphere; index_map: (ni, nj) sphere index or -1.
    """

    radius: float
    centres: np.ndarray
    normal: np.ndarray
    origin: np.ndarray
    t1: np.ndarray
    t2: np.ndarray
    grid_ij: np.ndarray
    index_map: np.ndarray


def face_basis(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eq. (2)-(3): outward unit normal n and in-plane basis t1, t2 = n x t1 of a face.

    The vertices are ordered counter-clockwise seen from outside the face.
    """
    N1, N2, N3 = vertices[0], vertices[1], vertices[2]
    n = np.cross(N2 - N1, N3 - N1)
    if np.linalg.norm(n) == 0.0 or np.linalg.norm(N2 - N1) == 0.0:
        raise ModelError("degenerate contact face: its first three vertices are collinear")
    n = n / np.linalg.norm(n)
    t1 = (N2 - N1) / np.linalg.norm(N2 - N1)
    return n, t1, np.cross(n, t1)


def inset(vertices: np.ndarray, distance: float) -> np.ndarray | None:
    """A convex planar face's vertices (k, 3) with every edge moved `distance` (m) inward, in
    the same order; None when nothing of the face is left.

    A sphere layer's spheres stand on the face's outline as well as inside it, so they bulge
    one radius past its edges; on a face inset by the radius they end at the edges."""
    n, t1, t2 = face_basis(vertices)
    N0 = vertices[0]
    uv = np.stack([(vertices - N0) @ t1, (vertices - N0) @ t2], axis=1)
    edges = np.roll(uv, -1, axis=0) - uv
    inward = np.stack([-edges[:, 1], edges[:, 0]], axis=1) / np.linalg.norm(edges, axis=1)[:, None]  # CCW: left
    points = uv + distance * inward  # a point on each moved edge line
    out = []
    for k in range(len(uv)):  # vertex k is where edge k-1 and edge k meet
        p1, d1, p2, d2 = points[k - 1], edges[k - 1], points[k], edges[k]
        det = d1[0] * d2[1] - d1[1] * d2[0]
        t = ((p2[0] - p1[0]) * d2[1] - (p2[1] - p1[1]) * d2[0]) / det
        out.append(p1 + t * d1)
    out = np.array(out)
    new_edges = np.roll(out, -1, axis=0) - out
    if np.any(np.einsum("ij,ij->i", new_edges, edges) <= 0):  # an edge turned round: nothing left
        return None
    return N0 + out[:, :1] * t1 + out[:, 1:] * t2


def sphere_layer(vertices: np.ndarray, radius: float) -> SphereLayer:
    """Eq. (2)-(5): the sphere layer of radius `radius` (m) on a convex planar face.

    Layers are kept by their vertices and radius (a weld, a study's runs build the same faces
    again); the returned layer's arrays must not be written to."""
    vertices = np.asarray(vertices, dtype=float)
    return _sphere_layer(vertices.tobytes(), vertices.shape, float(radius))


@functools.lru_cache(maxsize=1024)
def _sphere_layer(vertices_bytes: bytes, shape: tuple, radius: float) -> SphereLayer:
    vertices = np.frombuffer(vertices_bytes).reshape(shape)
    n, t1, t2 = face_basis(vertices)
    N0 = vertices[0]
    uv = np.stack([(vertices - N0) @ t1, (vertices - N0) @ t2], axis=1) / radius
    i = np.arange(np.ceil(uv[:, 0].min() - EDGE_TOLERANCE), np.floor(uv[:, 0].max() + EDGE_TOLERANCE) + 1)
    j = np.arange(np.ceil(uv[:, 1].min() - EDGE_TOLERANCE), np.floor(uv[:, 1].max() + EDGE_TOLERANCE) + 1)
    I, J = np.meshgrid(i, j, indexing="ij")
    ij = np.stack([I.ravel(), J.ravel()], axis=1)
    # inside a convex polygon: on the inner side of every edge (counter-clockwise order)
    edges = np.roll(uv, -1, axis=0) - uv
    rel = ij[:, None, :] - uv[None, :, :]
    cross = edges[None, :, 0] * rel[:, :, 1] - edges[None, :, 1] * rel[:, :, 0]
    inside = np.all(cross >= -EDGE_TOLERANCE * np.linalg.norm(edges, axis=1), axis=1)
    ij = ij[inside]
    points = N0 + radius * (ij[:, :1] * t1 + ij[:, 1:] * t2)  # Eq. (4)
    centres = points + radius * n  # Eq. (5)
    i0, j0 = int(i[0]), int(j[0])
    grid_ij = (ij - [i0, j0]).astype(np.int64)
    index_map = -np.ones((len(i), len(j)), dtype=np.int64)
    index_map[grid_ij[:, 0], grid_ij[:, 1]] = np.arange(len(grid_ij))
    origin = N0 + radius * (i0 * t1 + j0 * t2)
    layer = SphereLayer(radius, centres, n, origin, t1, t2, grid_ij, index_map)
    for x in (centres, n, origin, t1, t2, grid_ij, index_map):  # shared by every caller
        x.flags.writeable = False
    return layer


def box_top_face(size: np.ndarray, T_LC: np.ndarray) -> np.ndarray:
    """Corners (4, 3), counter-clockwise from outside, of the +z face of a box collision.

    size: (3,) box edge lengths, m.  T_LC: (4, 4) pose of the box in its link frame.
    """
    sx, sy, sz = 0.5 * np.asarray(size)
    corners = np.array([[-sx, -sy, sz], [sx, -sy, sz], [sx, sy, sz], [-sx, sy, sz]])
    return corners @ T_LC[:3, :3].T + T_LC[:3, 3]


def contact_faces(urdf: str) -> list[Face]:
    """The contact faces of a URDF: every box collision whose name ends as one of FACE_KINDS,
    the flanks first (in the URDF's order, then the other kinds in theirs).

    Read with yourdfpy, which keeps collision names (Pinocchio renames them).
    """
    import yourdfpy

    try:
        robot = yourdfpy.URDF.load(io.BytesIO(urdf.encode()), load_meshes=False,
                                   build_scene_graph=False, load_collision_meshes=False)
    except Exception as e:
        raise ModelError(f"cannot parse URDF with yourdfpy: {e}") from e
    faces = []
    for link in robot.robot.links:
        for col in link.collisions:
            kind = next((k for k, pattern in FACE_KINDS.items() if col.name and pattern.search(col.name)), None)
            if kind is None:
                continue
            if col.geometry.box is None:
                raise ModelError(f"contact face {col.name} on {link.name} must be a box collision")
            T = np.eye(4) if col.origin is None else np.asarray(col.origin)
            size = np.asarray(col.geometry.box.size, dtype=float)
            faces.append(Face(col.name, link.name, box_top_face(size, T), size, T, kind))
    return sorted(faces, key=lambda f: f.kind != "flank")
