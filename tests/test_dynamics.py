"""The compiled dynamics are Pinocchio's: the articulated-body algorithm against `pin.aba`, its
mass matrix against `pin.crba` (armature included), prescribed joints and their impulses
against the joint-space equations, and each joint kind's motion against Pinocchio's."""

import numpy as np
import pinocchio as pin
import pytest
from conftest import CONFIGS

import spotsim
from spotsim.errors import ModelError
from spotsim.sim.bare import bare
from spotsim.sim.data import make_data
from spotsim.sim.dynamics import accelerations, velocity_jump
from spotsim.sim.tree import NEWTON_EULER, kinematic_tree, kinematics, no_springs

#: The compiled algorithm and Pinocchio's sum the same terms in another order: 1e-12 of the
#: largest acceleration is a thousand times their round-off on these models.
ABA_RTOL = 1e-12
RANDOM_STATES = 20

def articulated_model(rng, root, n=6) -> pin.Model:
    """A random tree in depth-first order (a URDF's): a free-flyer, planar or no root, then n
    revolute and prismatic joints about or along random axes, each on a random earlier joint."""
    m = pin.Model()
    joints = [0]
    if root is not None:
        j = m.addJoint(0, root, pin.SE3.Random(), "root")
        m.appendBodyToJoint(j, pin.Inertia.Random(), pin.SE3.Identity())
        joints = [j]
    parents = list(joints)
    for k in range(n):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        model = [pin.JointModelRX(), pin.JointModelRY(), pin.JointModelPZ(), pin.JointModelRevoluteUnaligned(axis),
                 pin.JointModelPrismaticUnaligned(axis)][k % 5]
        # depth first: each joint hangs from the last one or from one of its ancestors
        parent = parents[rng.integers(len(parents))]
        parents = parents[:parents.index(parent) + 1]
        j = m.addJoint(parent, model, pin.SE3.Random(), f"j{k}")
        m.appendBodyToJoint(j, pin.Inertia.Random(), pin.SE3.Identity())
        parents.append(j)
    m.gravity = pin.Motion(rng.normal(size=3) * 5.0, np.zeros(3))
    return m


def compiled(model, prescribed=(), stiffness=None, rest=None, torque_limit=None):
    """The compiled tree of a Pinocchio model and a Data for it (`sim.bare`), with linear
    springs (stiffness, rest), clamped to torque_limit, if given."""
    springs = no_springs(model)
    for array, values in ((springs.stiffness, stiffness), (springs.rest, rest), (springs.torque_limit, torque_limit)):
        if values is not None:
            array[:] = values
    return bare(model, prescribed, springs)


def random_state(model, rng, data):
    """Write a random q, v, tau and contact wrenches into data; returns Pinocchio's fext."""
    data.q[:] = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    data.v[:] = rng.normal(scale=2.0, size=model.nv)
    data.tau[:] = rng.normal(scale=5.0, size=model.nv)
    data.loads.f_local[:] = rng.normal(scale=30.0, size=(model.njoints, 6))
    fext = pin.StdVec_Force()
    for w in data.loads.f_local:
        fext.append(pin.Force(w))
    return fext


def mass_matrix(model, q):
    """Pinocchio's joint-space mass matrix (armature on its diagonal), both triangles."""
    M = pin.crba(model, model.createData(), q)
    return np.triu(M) + np.triu(M, 1).T


def assert_close(actual, expected, rtol=ABA_RTOL):
    scale = np.abs(expected).max()
    assert np.abs(actual - expected).max() <= rtol * scale, (actual, expected)


ROOTS = {"fixed": None, "free-flyer": pin.JointModelFreeFlyer(), "planar": pin.JointModelPlanar()}


def passive_forces(model, tree, q, v):
    """The joints' passive springs and dampers of a compiled tree at (q, v), each clamped to its
    limit (Pinocchio leaves them to the caller)."""
    out = np.zeros(model.nv)
    for j in range(1, model.njoints):
        if model.nvs[j] == 1:
            i = model.idx_vs[j]
            f = -tree.stiffness[i] * (q[model.idx_qs[j]] - tree.rest[i]) - tree.damping[i] * v[i]
            out[i] = np.clip(f, -tree.torque_limit[i], tree.torque_limit[i])
    return out


def assert_prescribed_solve(model, d, fext, P, F, tree=None):
    """With the joints P prescribed (accelerating as given: zero), the others' accelerations
    d.a[F] solve the joint-space equations with `pin.crba`'s mass matrix and `pin.rnea`'s bias,
    the passive springs and dampers of `tree` (if given) with the joint forces. Returns that
    mass matrix."""
    M = mass_matrix(model, d.q)
    b = pin.rnea(model, model.createData(), d.q, d.v, np.zeros(model.nv), fext)
    assert np.all(d.a[P] == 0.0)
    tau = d.tau + (passive_forces(model, tree, d.q, d.v) if tree is not None else 0.0)
    assert_close(d.a[F], np.linalg.solve(M[np.ix_(F, F)], (tau - b)[F]))
    return M


@pytest.mark.parametrize("root", list(ROOTS))
def test_articulated_dynamics_is_pinocchios_aba(root):
    """On random trees of revolute and prismatic joints (on the world, a free-flyer or a planar
    joint), random states, joint forces and contact wrenches, with armature, the joints'
    passive springs and dampers, clamped to their torque limits (a servo's; about half the
    joints' clamps hold here): the compiled accelerations are `pin.aba`'s, and the mass matrix
    they solve is `pin.crba`'s with the armature."""
    rng = np.random.default_rng(11)
    for _ in range(4):
        model = articulated_model(rng, ROOTS[root])
        model.armature = np.abs(rng.normal(size=model.nv)) * 0.3  # the root's rotor too
        stiffness, rest = np.abs(rng.normal(size=model.nv)) * 50.0, rng.normal(size=model.nv)
        model.damping = np.abs(rng.normal(size=model.nv))
        for j in range(1, model.njoints):  # the root's dofs: no spring
            if model.nvs[j] > 1:
                sl = slice(model.idx_vs[j], model.idx_vs[j] + model.nvs[j])
                stiffness[sl], model.damping[sl] = 0.0, 0.0
        limit = np.abs(rng.normal(size=model.nv)) * 50.0
        m, d = compiled(model, stiffness=stiffness, rest=rest, torque_limit=limit)
        for _ in range(RANDOM_STATES):
            fext = random_state(model, rng, d)
            kinematics(m, d)
            accelerations(m, d)
            passive = d.tau.copy()
            for j in range(1, model.njoints):
                if model.nvs[j] == 1:
                    i = model.idx_vs[j]
                    spring = -stiffness[i] * (d.q[model.idx_qs[j]] - rest[i]) - model.damping[i] * d.v[i]
                    passive[i] += np.clip(spring, -limit[i], limit[i])
            plain = model.copy()
            plain.damping = np.zeros(model.nv)  # Pinocchio's ABA leaves damping to the caller
            assert_close(d.a, pin.aba(plain, plain.createData(), d.q, d.v, passive, fext))
            # the same accelerations solve M a = tau - b with Pinocchio's M (armature) and b
            b = pin.rnea(plain, plain.createData(), d.q, d.v, np.zeros(model.nv), fext)
            assert_close(mass_matrix(plain, d.q) @ d.a, passive - b)


@pytest.mark.parametrize("root", list(ROOTS))
def test_prescribed_joints_move_as_given_and_their_branch_responds(root):
    """Prescribed joints (a kinematic drive's fingers) accelerate as given (zero), and the
    other joints as the joint-space equations with those accelerations imposed say,
    M_ff a_f = tau_f - b_f (Featherstone's hybrid dynamics); a change of the prescribed speeds
    is an impulse, M_ff dv_f = -M_fp dv_p, which keeps the momentum of a floating branch."""
    rng = np.random.default_rng(12)
    for _ in range(4):
        model = articulated_model(rng, ROOTS[root])
        one_dof = [j for j in range(1, model.njoints) if model.nvs[j] == 1]
        prescribed = [j for j in one_dof if rng.random() < 0.5] or one_dof[-1:]
        m, d = compiled(model, prescribed)
        P = [model.idx_vs[j] for j in prescribed]
        F = [i for i in range(model.nv) if i not in P]
        for _ in range(RANDOM_STATES):
            fext = random_state(model, rng, d)
            kinematics(m, d)
            accelerations(m, d)
            M = assert_prescribed_solve(model, d, fext, P, F)
            before = d.v.copy()
            change = rng.normal(size=len(P))
            velocity_jump(m, d, np.array(prescribed), before[P] + change)
            assert_close(d.v[P] - before[P], change)
            expected = np.linalg.solve(M[np.ix_(F, F)], -M[np.ix_(F, P)] @ change)
            assert_close(d.v[F] - before[F], expected)
            if root == "free-flyer":  # the impulse is internal: the branch's momentum stays
                h = [pin.computeCentroidalMomentum(model, model.createData(), d.q, x).linear for x in (before, d.v)]
                assert_close(h[1], h[0], rtol=1e-12)


@pytest.mark.parametrize("config", [c.name for c in CONFIGS])
@pytest.mark.parametrize("gravity", [(0.0, 0.0, 0.0), (0.3, -9.81, 2.0)])
def test_shipped_scenes_dynamics_is_pinocchios_aba(config, gravity):
    """On every shipped scene (the fingers on their prismatic joints, the robot and modules
    floating), random states and wrenches: with the fingers' motion free, the compiled
    accelerations are `pin.aba`'s, each branch solved by its mode (one free body by
    Newton-Euler, the robot and its fingers by the articulated-body algorithm); with them
    prescribed, as the tree of a run with a drive that prescribes them (kinematic) has them
    (the robot's branch solved as one rigid body), they solve the joint-space equations with
    `pin.crba`'s mass matrix."""
    from conftest import ROOT

    # the bungee (a force outside the tree, `sim.tether`) hangs only in gravity: left out here
    hung = ["suspension.kind=none"] if "suspension" in spotsim.scenario.to_dict(
        spotsim.load_scenario(ROOT / "config" / config)) else []
    s = spotsim.load_scenario(ROOT / "config" / config, ["end_effector.drive=kinematic", *hung])
    if "testbed" in config:  # the table carries gravity along its normal: compared in space
        gravity = (0.0, 0.0, 0.0)
    model = spotsim.build_model(spotsim.replace(s, simulation={"gravity_m_s2": gravity}))
    pm = model.pin_model
    tree, branches = kinematic_tree(pm, (), pm.gravity.linear)
    empty, scratch = bare(pm)  # no drives
    m = empty._replace(tree=tree, branches=branches)
    view = make_data(model).view()
    d = scratch._replace(q=view.q, v=view.v)
    rng = np.random.default_rng(5)
    run = empty._replace(tree=model.sim.tree, branches=model.sim.branches)  # the fingers prescribed
    P = [pm.idx_vs[f.joint] for f in model.fingers]
    F = [i for i in range(pm.nv) if i not in P]
    for _ in range(RANDOM_STATES):
        fext = random_state(pm, rng, d)
        kinematics(m, d)
        accelerations(m, d)
        # the URDF's joint dampers (the compliant arm's joints'), which Pinocchio leaves to the caller
        assert_close(d.a, pin.aba(pm, pm.createData(), d.q, d.v, d.tau - pm.damping * d.v, fext))
        kinematics(run, d)
        accelerations(run, d)
        assert_prescribed_solve(pm, d, fext, P, F, run.tree)
    assert NEWTON_EULER in branches.mode  # the modules


def test_a_joint_kind_the_core_does_not_move_is_refused():
    """A spherical joint (or a free-flyer that does not float on the world) is refused at the
    build, naming the joint and the kinds the core moves."""
    model = pin.Model()
    j = model.addJoint(0, pin.JointModelSpherical(), pin.SE3.Identity(), "ball")
    model.appendBodyToJoint(j, pin.Inertia.Random(), pin.SE3.Identity())
    with pytest.raises(ModelError, match="ball is a JointModelSpherical.*free_flyer, planar, revolute, prismatic"):
        kinematic_tree(model)
    model = pin.Model()
    j = model.addJoint(0, pin.JointModelRX(), pin.SE3.Identity(), "arm")
    k = model.addJoint(j, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "loose")
    for x in (j, k):
        model.appendBodyToJoint(x, pin.Inertia.Random(), pin.SE3.Identity())
    with pytest.raises(ModelError, match="loose is a free_flyer joint on arm"):
        kinematic_tree(model)
