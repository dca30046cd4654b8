"""The integrators over (q, v), joint kind by joint kind: revolute and prismatic coordinates and
the floating roots' rotations as `pin.integrate` moves them, the roots' branches on their
momentum; and an articulated free-floating arm, driven by internal joint forces, keeps its
linear momentum to round-off and its angular momentum at each integrator's order."""

import numpy as np
import pinocchio as pin
import pytest

from spotsim.sim.bare import bare
from spotsim.sim.dynamics import accelerations
from spotsim.sim.integrators import _euler_update, derivative, pack, unpack
from spotsim.sim.tree import kinematics

#: Round-off on O(1) numbers over a few thousand steps.
ROUND_OFF = 1e-12
#: Halving the step cuts a first-order method's error by ~2 and a fourth-order one's by ~16.
FIRST_ORDER, FOURTH_ORDER = (1.8, 2.2), 10.0


def arm(root) -> pin.Model:
    """A floating (or fixed) base carrying a six-joint arm of revolute joints about x, y, z
    and an unaligned axis, and a prismatic finger on its last link: zero gravity."""
    rng = np.random.default_rng(3)
    m = pin.Model()
    parent = 0
    if root is not None:
        parent = m.addJoint(0, root, pin.SE3(np.eye(3), np.array([0.1, -0.2, 0.3])), "base")
        m.appendBodyToJoint(parent, pin.Inertia(20.0, np.array([0.01, 0.0, -0.02]), np.diag([1.0, 1.2, 0.8])),
                            pin.SE3.Identity())
    axes = [pin.JointModelRZ(), pin.JointModelRY(), pin.JointModelRY(), pin.JointModelRX(),
            pin.JointModelRevoluteUnaligned(np.array([0.0, 0.6, 0.8])), pin.JointModelRZ(), pin.JointModelPZ()]
    for k, joint in enumerate(axes):
        placement = pin.SE3(pin.rpy.rpyToMatrix(*rng.normal(scale=0.3, size=3)), np.array([0.0, 0.05, 0.15]))
        parent = m.addJoint(parent, joint, placement, f"j{k}")
        m.appendBodyToJoint(parent, pin.Inertia(rng.uniform(0.5, 3.0), rng.normal(scale=0.03, size=3),
                                                np.diag(rng.uniform(0.005, 0.02, size=3))), pin.SE3.Identity())
    m.gravity = pin.Motion.Zero()
    return m


def compiled(model):
    return bare(model)


def start(model, d, spin=(0.3, -0.5, 0.9)):
    """A moving start: the base drifting and spinning, the arm's joints turning."""
    rng = np.random.default_rng(4)
    d.q[:] = pin.neutral(model)
    d.v[:] = rng.normal(scale=0.5, size=model.nv)
    if model.joints[1].shortname() == "JointModelFreeFlyer":
        d.v[3:6] = spin


def drive(model, d, t):
    """Internal joint forces: each arm joint driven by a torque of its own frequency."""
    for j in range(1, model.njoints):
        if model.nvs[j] == 1:
            d.tau[model.idx_vs[j]] = 2.0 * np.sin(3.0 * j * t + j)


def momentum(model, q, v):
    """The whole tree's linear momentum and angular momentum about the world origin (Pinocchio)."""
    data = model.createData()
    h = pin.computeCentroidalMomentum(model, data, q, v)
    c = data.com[0]
    return h.linear.copy(), h.angular + np.cross(c, h.linear)


def symplectic(model, m, d, h, steps):
    """Symplectic Euler (the integrators' update, `_euler_update`) over the bare tree."""
    for k in range(steps):
        drive(model, d, k * h)
        kinematics(m, d)
        accelerations(m, d)
        _euler_update(m, d, h, h)


def rk4(model, m, d, h, steps):
    """Classical RK4 over the integrators' Runge-Kutta state (`pack`, `unpack`, `derivative`)."""

    def rate(y, t):
        unpack(m, d, y)
        drive(model, d, t)
        kinematics(m, d)
        accelerations(m, d)
        return derivative(m, d, y)

    for k in range(steps):
        t = k * h
        y = pack(m, d)
        k1 = rate(y, t)
        k2 = rate(y + 0.5 * h * k1, t + 0.5 * h)
        k3 = rate(y + 0.5 * h * k2, t + 0.5 * h)
        k4 = rate(y + h * k3, t + h)
        unpack(m, d, y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4))


@pytest.mark.parametrize("scheme", ["symplectic_euler", "rk4"])
def test_floating_arm_keeps_linear_momentum_to_round_off_and_angular_at_the_integrators_order(scheme):
    """A free-floating base with a seven-joint arm, zero gravity, every joint driven by its own
    internal torque for 0.2 s: its linear momentum stays to round-off at every step size; its
    angular momentum's drift falls ~2x (symplectic Euler) or >= 10x (RK4) when the step halves."""
    model = arm(pin.JointModelFreeFlyer())
    integrate = symplectic if scheme == "symplectic_euler" else rk4
    drifts = []
    for steps in (400, 800):
        m, d = compiled(model)
        start(model, d)
        P0, L0 = momentum(model, d.q, d.v)
        integrate(model, m, d, 0.2 / steps, steps)
        P, L = momentum(model, d.q, d.v)
        assert np.linalg.norm(P - P0) <= ROUND_OFF * np.linalg.norm(P0)
        drifts.append(np.linalg.norm(L - L0))
    ratio = drifts[0] / drifts[1]
    if scheme == "symplectic_euler":
        assert FIRST_ORDER[0] <= ratio <= FIRST_ORDER[1], drifts
    else:
        assert ratio >= FOURTH_ORDER, drifts


@pytest.mark.parametrize("root", ["free_flyer", "planar", "fixed"])
def test_each_joint_kind_moves_as_pin_integrate_moves_it(root):
    """One force-free step of h from a moving state: revolute and prismatic coordinates move
    to `pin.integrate`'s (q + h v), a floating root turns to its rotation (exp of h omega);
    its origin moves so that its branch's centroid keeps its momentum, which is
    `pin.integrate`'s to first order: its distance from it falls ~4x when h halves."""
    joint = {"free_flyer": pin.JointModelFreeFlyer(), "planar": pin.JointModelPlanar(), "fixed": None}[root]
    model = arm(joint)
    gaps = []
    for h in (1e-3, 5e-4):
        m, d = compiled(model)
        start(model, d)
        q0, v0 = d.q.copy(), d.v.copy()
        kinematics(m, d)
        d.a[:] = 0.0  # force-free: velocities stay, positions move by them
        _euler_update(m, d, h, h)
        expected = pin.integrate(model, q0, h * v0)
        n_root = model.nqs[1] if joint is not None else 0
        np.testing.assert_allclose(d.q[n_root:], expected[n_root:], rtol=0, atol=ROUND_OFF)
        if joint is None:
            continue
        data = model.createData()
        ours, theirs = [pin.forwardKinematics(model, data, x) or data.oMi[1].copy() for x in (d.q, expected)]
        np.testing.assert_allclose(ours.rotation, theirs.rotation, rtol=0, atol=ROUND_OFF)
        gaps.append(np.linalg.norm(ours.translation - theirs.translation))
    if joint is not None:
        assert gaps[0] / gaps[1] >= 3.5, gaps  # second order in h


def test_a_speed_set_between_a_steps_accelerations_and_its_update_keeps_momentum():
    """Symplectic Euler's controllers set prescribed speeds after the step's accelerations and
    before its update (velocity first): with one finger on a floating base jumping alone (no
    mirror finger to cancel its recoil), 200 such steps keep the tree's linear momentum to
    round-off."""
    from spotsim.sim.dynamics import velocity_jump

    m0 = pin.Model()
    base = m0.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "base")
    m0.appendBodyToJoint(base, pin.Inertia(5.0, np.array([0.02, -0.01, 0.0]), np.diag([0.2, 0.3, 0.25])),
                         pin.SE3.Identity())
    finger = m0.addJoint(base, pin.JointModelPZ(), pin.SE3(pin.rpy.rpyToMatrix(0.3, 0.2, 0.1), np.array([0.1, 0, 0])),
                         "finger")
    m0.appendBodyToJoint(finger, pin.Inertia(0.4, np.array([0.0, 0.01, 0.02]), np.diag([1e-3, 1e-3, 5e-4])),
                         pin.SE3.Identity())
    m0.gravity = pin.Motion.Zero()
    m, d = bare(m0, prescribed=[finger])
    d.v[:6] = (0.01, -0.02, 0.005, 0.3, -0.2, 0.4)
    P0, _ = momentum(m0, d.q, d.v)
    h = 1e-3
    for k in range(200):
        kinematics(m, d)
        accelerations(m, d)
        velocity_jump(m, d, np.array([finger]), np.array([0.05 * np.sin(0.1 * k)]))
        _euler_update(m, d, h, h)
    P, _ = momentum(m0, d.q, d.v)
    assert np.linalg.norm(P - P0) <= ROUND_OFF * np.linalg.norm(P0)
