"""The integrator advances free bodies' centroids in the world frame."""

import numpy as np
import pinocchio as pin
import pytest

from spotsim.integrators import centroid_acceleration, centroid_state, make_integrator

#: Round-off on O(1) numbers over a few thousand steps.
ROUND_OFF = 1e-12


def tumbling_body(lever=(0.05, -0.02, 0.01)):
    """A free body with an off-centre centroid and a full, unequal inertia."""
    m = pin.Model()
    j = m.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "body")
    I = np.array([[0.4, 0.01, 0.02], [0.01, 0.3, 0.015], [0.02, 0.015, 0.2]])
    m.appendBodyToJoint(j, pin.Inertia(3.0, np.array(lever), I), pin.SE3.Identity())
    m.gravity = pin.Motion.Zero()
    return m


def test_force_free_tumbling_body_keeps_its_momentum_and_straight_path():
    """With no force, a tumbling body's centroid moves on a straight line at constant velocity."""
    model = tumbling_body()
    data = model.createData()
    q = pin.neutral(model)
    v = np.array([0.1, -0.2, 0.05, 2.0, -1.0, 3.0])
    integrator = make_integrator("symplectic_euler", model)
    p0, vG0, _, _ = centroid_state(model, 1, q, v)
    h = 1e-3
    for k in range(1, 2001):
        a = pin.aba(model, data, q, v, np.zeros(6))
        q, v = integrator.step(model, q, v, a, h)
    p, vG, _, _ = centroid_state(model, 1, q, v)
    assert np.linalg.norm(vG - vG0) <= ROUND_OFF
    assert np.linalg.norm(p - (p0 + 2000 * h * vG0)) <= ROUND_OFF


def test_centroid_acceleration_is_force_over_mass():
    """ABA's spatial acceleration, turned into the centroid's world acceleration, is F / m."""
    model = tumbling_body()
    data = model.createData()
    rng = np.random.default_rng(5)
    q = pin.integrate(model, pin.neutral(model), rng.normal(size=6))
    v = rng.normal(size=6)
    f_local = pin.Force(rng.normal(size=3), rng.normal(size=3))  # at the joint origin, body axes
    a = pin.aba(model, data, q, v, np.zeros(6), [pin.Force.Zero(), f_local])
    R = pin.XYZQUATToSE3(q).rotation
    assert np.allclose(centroid_acceleration(model, 1, q, v, a), R @ f_local.linear / 3.0,
                       rtol=0, atol=ROUND_OFF)


def test_unknown_integrator_lists_the_valid_ones():
    with pytest.raises(ValueError, match="symplectic_euler"):
        make_integrator("leapfrog", tumbling_body())


def test_bodies_momentum_matches_pinocchio():
    """The compiled momentum of free bodies equals Pinocchio's spatial momentum in world."""
    from spotsim.bodies import bodies_momentum, free_bodies
    from spotsim.weld import world_momentum

    model = tumbling_body()
    j = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3(pin.rpy.rpyToMatrix(0.3, -0.2, 1.0), np.ones(3)), "second")
    model.appendBodyToJoint(j, pin.Inertia.Random(), pin.SE3.Identity())
    data = model.createData()
    rng = np.random.default_rng(7)
    q = pin.integrate(model, pin.neutral(model), rng.normal(size=model.nv))
    v = rng.normal(size=model.nv)
    pin.forwardKinematics(model, data, q, v)
    h = [world_momentum(data.oMi[k], model.inertias[k], data.v[k]) for k in (1, 2)]
    P, L, p_max, l_max, c = bodies_momentum(free_bodies(model), np.arange(2), q, v)
    assert np.allclose(P, h[0].linear + h[1].linear, rtol=0, atol=ROUND_OFF)
    assert np.allclose(L, h[0].angular + h[1].angular, rtol=0, atol=ROUND_OFF)
    assert p_max == pytest.approx(max(np.linalg.norm(x.linear) for x in h), abs=ROUND_OFF)
    masses = [model.inertias[k].mass for k in (1, 2)]
    centroids = [data.oMi[k].act(model.inertias[k].lever) for k in (1, 2)]
    assert np.allclose(c, np.average(centroids, axis=0, weights=masses), rtol=0, atol=ROUND_OFF)
