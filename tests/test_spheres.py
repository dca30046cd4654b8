"""Virtual sphere layers, paper Eq. (1)-(5)."""

import numpy as np
import pytest

from spotsim.assemble.faces import face_basis, sphere_layer
from spotsim.errors import ModelError

#: Geometry here is exact up to double round-off on millimetre numbers.
TOL = 1e-12

SQUARE = np.array([[0, 0, 0], [4e-3, 0, 0], [4e-3, 2e-3, 0], [0, 2e-3, 0]], dtype=float)


def test_normal_and_basis_of_a_counter_clockwise_square():
    """Eq. (2)-(3): the outward normal of a CCW face is +z, t1 along its first edge, t2 = n x t1."""
    n, t1, t2 = face_basis(SQUARE)
    assert np.allclose(n, [0, 0, 1]) and np.allclose(t1, [1, 0, 0]) and np.allclose(t2, [0, 1, 0])


def test_spheres_are_tangent_to_the_face_on_a_grid_of_step_r():
    """Eq. (4)-(5): centres sit r above the face, on a grid of step r covering the face."""
    r = 0.5e-3
    layer = sphere_layer(SQUARE, r)
    assert np.allclose(layer.centres[:, 2], r, atol=TOL)  # tangent: centre at distance r
    assert len(layer.centres) == 9 * 5  # 0..4 mm by 0.5 mm, 0..2 mm by 0.5 mm, edges included
    xs, ys = np.unique(layer.centres[:, 0].round(12)), np.unique(layer.centres[:, 1].round(12))
    assert np.allclose(np.diff(xs), r, atol=TOL) and np.allclose(np.diff(ys), r, atol=TOL)


def test_grid_keeps_only_points_inside_the_polygon():
    """A triangle keeps the grid points inside it, edges included, and none outside."""
    tri = np.array([[0, 0, 0], [2e-3, 0, 0], [0, 2e-3, 0]], dtype=float)
    layer = sphere_layer(tri, 1e-3)
    pts = {tuple(p) for p in (layer.centres[:, :2] * 1e3).round(9)}
    assert pts == {(0, 0), (1, 0), (2, 0), (0, 1), (1, 1), (0, 2)}


def test_index_map_points_back_at_each_sphere():
    """The grid index map inverts the spheres' grid indices."""
    layer = sphere_layer(SQUARE, 0.7e-3)
    i, j = layer.grid_ij.T
    assert np.array_equal(layer.index_map[i, j], np.arange(len(layer.centres)))


def test_collinear_vertices_are_rejected():
    """A face whose first three vertices are collinear has no normal."""
    with pytest.raises(ModelError):
        face_basis(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], dtype=float))


def test_shipped_faces_have_unit_normals_pointing_at_their_partner(model_I):
    """Every finger face's normal points out of the finger, every groove face's into the cavity."""
    M, S = model_I.master, model_I.slave
    assert np.allclose(np.linalg.norm(M.normal_J, axis=1), 1) and np.allclose(np.linalg.norm(S.normal_J, axis=1), 1)
    # each finger face has a groove face whose normal is exactly opposite once seated
    from spotsim.contact.search import world_spheres
    from spotsim.sim.data import make_data
    from spotsim.sim.tree import kinematics

    data = make_data(model_I)
    kinematics(model_I.sim, data)
    _, N1, _, N2 = world_spheres(model_I.sim, data)
    for f in np.unique(M.face):
        n = N1[M.face == f][0]
        assert np.min(N2 @ n) == pytest.approx(-1.0, abs=1e-9)
