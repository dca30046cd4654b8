"""The culled search (coal broad phase + grid-local search) against the paper's all-pairs search."""

import numpy as np
import pinocchio as pin

from conftest import restore
from spotsim.step import (broad_phase, candidate_pairs, contact_forces, kinematics, literal_pairs,
                          sphere_pairs, wrenches)

#: Both searches feed the same kernel; forces may differ only by the order of summation.
FORCE_RTOL = 1e-12


def contacts_by(model, snap, search):
    data = restore(snap)
    kinematics(model, data)
    if search == "all":
        m, s = literal_pairs(model, data)
    else:
        m, s, _ = candidate_pairs(model, data, broad_phase(model, data))
    from spotsim.step import Contacts

    key = m * len(model.slave.centres_J) + s
    order = np.argsort(key)
    return contact_forces(model, data, Contacts(m[order], s[order], key[order]), 1e-4)


def test_culled_search_finds_exactly_the_all_pairs_contacts(model_I, recorded_states):
    """On states recorded from Case I, both searches find the same pairs and the same forces."""
    total = 0
    for snap in recorded_states:
        culled, literal = contacts_by(model_I, snap, "culled"), contacts_by(model_I, snap, "all")
        assert np.array_equal(culled.key, literal.key)
        scale = np.abs(literal.force_W).max()
        assert np.abs(culled.force_W - literal.force_W).max() <= FORCE_RTOL * scale
        total += len(literal.key)
    assert total > 100  # the states really are in multi-point contact


def test_broad_phase_culls_far_face_pairs(model_I, recorded_states):
    """Coal keeps only face pairs within the security margin: far fewer than all 16."""
    data = restore(recorded_states[-1])
    kinematics(model_I, data)
    kept = broad_phase(model_I, data)
    assert 0 < len(kept) < len(model_I.face_pairs)


def test_broad_phase_keeps_nothing_while_the_fingers_are_open(model_I):
    """At the start the fingers are 9 mm from the groove: coal culls every face pair."""
    from spotsim.step import make_data

    data = make_data(model_I)
    kinematics(model_I, data)
    assert len(broad_phase(model_I, data)) == 0


def test_action_equals_reaction_about_any_point(model_I, recorded_states):
    """The wrenches on the finger bodies and on the module sum to zero about any point."""
    rng = np.random.default_rng(3)
    for snap in recorded_states[::3]:
        data = restore(snap)
        kinematics(model_I, data)
        c = contact_forces(model_I, data, sphere_pairs(model_I, data), 1e-4)
        f_ext = wrenches(model_I, data, c)
        scale = np.abs(c.force_W).sum()
        for point in rng.normal(scale=0.5, size=(3, 3)):
            F, T = np.zeros(3), np.zeros(3)
            for j in model_I.contact_joints:
                f_W = pin.SE3(data.R_W[j], data.p_W[j]).act(f_ext[j])  # about the world origin
                F += f_W.linear
                T += f_W.angular - np.cross(point, f_W.linear)
            assert np.linalg.norm(F) <= 1e-12 * scale
            assert np.linalg.norm(T) <= 1e-12 * scale
