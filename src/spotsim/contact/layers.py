"""The sphere layers of a scene, stacked by role, and the face pairs that may touch.

Master spheres lie on the fingers' faces, slave spheres on the grooves' (paper Sec. 3.1.1-3.1.2).
Each is given in the frame of the joint that carries its body. The spheres of one face are
contiguous and share its normal.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class MasterSpheres(NamedTuple):
    """The finger spheres (set S1), one row each."""

    centre_J: np.ndarray  # (n, 3) centre in its joint's frame, m
    normal_J: np.ndarray  # (n, 3) its face's outward normal, same frame
    joint: np.ndarray  # (n,) the joint carrying its body
    face: np.ndarray  # (n,) its face, numbered over the master faces


class SlaveSpheres(NamedTuple):
    """The groove spheres (set S2), one row each, and each slave face's grid."""

    centre_J: np.ndarray  # (n, 3) centre in its joint's frame, m
    normal_J: np.ndarray  # (n, 3) its face's outward normal
    joint: np.ndarray  # (n,)
    face: np.ndarray  # (n,) its face, numbered over the slave faces
    maps: np.ndarray  # (n_faces, ni, nj) the sphere at each node of each face's grid, -1 where none


class FaceTable(NamedTuple):
    """The face pairs (one master face, one slave face) that may touch, one row each; row i is
    also the i-th collision pair of the scene's coal geometry."""

    master_start: np.ndarray  # (n,) first master sphere of the pair's master face
    master_stop: np.ndarray  # (n,) one past its last
    master_joint: np.ndarray  # (n,)
    slave_joint: np.ndarray  # (n,)
    slave_face: np.ndarray  # (n,) index into the slave grids (`SlaveSpheres.maps`)
    origin_J: np.ndarray  # (n, 3) the slave grid's reference vertex, its joint's frame, m
    t1_J: np.ndarray  # (n, 3) the slave grid's in-plane axes and outward normal
    t2_J: np.ndarray
    n_J: np.ndarray
    shape: np.ndarray  # (n, 2) grid size
    # the mean of the master face's centres (its joint's frame) and the farthest of them from
    # it, m: `search._moved` bounds every centre's motion from these
    master_centre_J: np.ndarray  # (n, 3)
    master_radius: np.ndarray  # (n,)

