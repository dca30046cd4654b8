"""The fingers are bodies on their prismatic joints: the contact sees a finger as any other
body, its pose from the kinematics. On recorded contact states its pairs' forces are those the
earlier side channel gave, which slid each sphere along the finger's axis by its opening on the
body the finger is mounted on and added the opening's rate to its velocity."""

import numpy as np
import pinocchio as pin
import pytest
from conftest import ROOT

import spotsim
from spotsim.contact.detection import contact_point, force_direction, penetration
from spotsim.contact.friction import bristle
from spotsim.contact.normal import indentation, normal_law, onset_rate
from spotsim.run import Stepper
from spotsim.sim.forces import forces

#: Two formulas of one pose (the finger's frame, or its parent's with the slide added) agree to
#: a few dozen ulps of positions of order 1 m; a pair's force moves with its penetration by its
#: normal stiffness, which near its onset makes a large relative change of a small force.
POSITION_ROUND_OFF_M = 1e-14
#: ... and the force's own arithmetic, relative.
FORCE_RTOL = 1e-12
H = 1e-5


def side_channel_force(model, d, k):
    """Contact k of d (after `forces`) by the side channel: the master sphere given on the
    finger's parent body at opening 0, slid along the finger's axis by the opening, moving with
    the parent plus the opening's rate. Returns the force on the master, world, N."""
    m, pm = model.sim, model.pin_model
    c = d.contacts
    mi, sl = c.master[k], c.slave[k]
    jf = int(m.master.joint[mi])
    parent = pm.parents[jf]
    M = pm.jointPlacements[jf]  # the finger's frame in its parent's at opening 0
    axis_P = M.rotation @ m.tree.axis[jf]
    opening, rate = d.q[pm.idx_qs[jf]], d.v[pm.idx_vs[jf]]
    R_P, p_P = d.R_W[parent], d.p_W[parent]
    c1 = R_P @ (M.act(m.master.centre_J[mi]) + opening * axis_P) + p_P
    n1 = R_P @ M.rotation @ m.master.normal_J[mi]
    j2 = int(m.slave.joint[sl])
    c2 = d.R_W[j2] @ m.slave.centre_J[sl] + d.p_W[j2]
    n2 = d.R_W[j2] @ m.slave.normal_J[sl]
    law = m.law
    n_c, phi, hit, side = penetration(c1, n1, law.r1, c2, n2, law.r2)
    assert hit
    point = np.array(contact_point(c1, c2, law.r1, law.r2, n_c, phi))
    v_A = d.vo_W[parent] + np.cross(d.w_W[parent], point - p_P) + R_P @ axis_P * rate
    v_B = d.vo_W[j2] + np.cross(d.w_W[j2], point - d.p_W[j2])
    v_rel = v_A - v_B
    g = np.array(force_direction(c1, c2, n_c, phi, law.gradient, side))
    delta_dot = indentation(-(v_rel @ g))
    mem = d.memory
    at = np.flatnonzero(mem.key == c.key[k])
    if len(at):
        v_minus, s_prev = mem.v_minus[at[0]], tuple(mem.s[at[0]])
    else:
        v_minus, s_prev = onset_rate(delta_dot, law.floor), (0.0, 0.0, 0.0)
    F_n, dF_ddelta, _ = normal_law(indentation(phi), delta_dot, v_minus, law.K, law.damping)
    _, F_f, _, _, _ = bristle(s_prev, tuple(v_rel), n_c, F_n, H, law.bristle, False)
    # how far the force may move with the round-off of the positions (delta = phi / 2)
    tolerance = 0.5 * abs(dF_ddelta) * POSITION_ROUND_OFF_M * (1.0 + law.bristle.mu_s) + \
        FORCE_RTOL * abs(F_n)
    return F_n * g + np.array(F_f), tolerance


def contact_states(config, n=8, every=0.01):
    """Copies of a scenario's Data every `every` seconds from first contact, while in contact."""
    model = spotsim.build_model(spotsim.load_scenario(ROOT / "config" / config))
    stepper = Stepper(model)
    states, next_t = [], 0.0
    while len(states) < n and stepper.data.t < 3.0:
        stepper.step(H)
        v = stepper.data.view()
        if len(v.contacts.key) and v.t >= next_t:
            states.append(stepper.data.copy())
            next_t = v.t + every
    assert len(states) == n
    return model, states


@pytest.mark.parametrize("config", ["single_arm_case_I.yaml", "dual_arm_sequential.yaml"])
def test_a_finger_on_its_joint_gives_the_side_channels_contact_forces(config):
    """On contact states of Case I (the fingers on the fixed base) and of the dual arm (the
    fingers on the floating robot, moving with it), every pair's force on the finger is the
    side channel's: the finger's pose and velocity from its joint are its parent's with the
    opening slid in."""
    model, states = contact_states(config, n=12)
    pairs = 0
    for state in states:
        d = state.copy()
        forces(model.sim, d, H, False)
        v = d.view()
        for k in range(len(v.contacts.key)):
            expected, tolerance = side_channel_force(model, v, k)
            np.testing.assert_allclose(v.contacts.force_W[k], expected, rtol=0, atol=tolerance)
        pairs += len(v.contacts.key)
    assert pairs >= 30  # enough pair forces checked, the states in multi-point contact


def test_each_fingers_load_is_the_generalized_force_on_its_joint(model_I, recorded_states):
    """A finger's load is the contact wrench's generalized force on its prismatic joint
    (Pinocchio's J^T f for the joint's column), the opening force never negative."""
    pm = model_I.pin_model
    pd = pm.createData()
    for state in recorded_states:
        d = state.copy()
        forces(model_I.sim, d, H, False)
        v = d.view()
        pin.computeJointJacobians(pm, pd, v.q)
        for i, f in enumerate(model_I.fingers):
            J = pin.getJointJacobian(pm, pd, f.joint, pin.LOCAL)  # (6, nv), the body's twist per dof
            generalized = J[:, pm.idx_vs[f.joint]] @ v.loads.f_local[f.joint]
            assert v.load[i] == pytest.approx(max(generalized, 0.0), rel=1e-12, abs=1e-12)
