"""The culled search (coal broad phase + grid-local search) against the paper's all-pairs search."""

import numpy as np
import pinocchio as pin

from spotsim.contact.forces import pair_forces
from spotsim.contact.search import grid_search, literal_search
from spotsim.contact.wrenches import body_wrenches
from spotsim.sim.bodies import kinematics
from spotsim.sim.broadphase import BroadPhase
from spotsim.sim.data import make_data

#: Both searches feed the same kernel; forces may differ only by the order of summation.
FORCE_RTOL = 1e-12
#: Action equals reaction: the wrenches sum to zero up to round-off on their own scale.
BALANCE_RTOL = 1e-12


def contacts_by(model, state, search):
    """The contacts of a copy of `state` (its pair memory untouched) found by `search`."""
    data = state.copy()
    kinematics(model.sim, data)
    if search == "literal":
        candidates = literal_search(model.sim, data)
    else:
        candidates = grid_search(model.sim, data, BroadPhase(model).near(data.q, data.opening))
    data.assign(candidates=candidates)
    pair_forces(model.sim, data, 1e-4)
    return data


def test_culled_search_finds_exactly_the_all_pairs_contacts(model_I, recorded_states):
    """On states recorded from Case I, both searches find the same pairs and the same forces."""
    total = 0
    for state in recorded_states:
        culled = contacts_by(model_I, state, "culled").contacts
        literal = contacts_by(model_I, state, "literal").contacts
        assert np.array_equal(culled.key, literal.key)
        scale = np.abs(literal.force_W).max()
        assert np.abs(culled.force_W - literal.force_W).max() <= FORCE_RTOL * scale
        total += len(literal.key)
    assert total > 100  # the states really are in multi-point contact


def test_broad_phase_culls_far_face_pairs(model_I, recorded_states):
    """Coal keeps only face pairs within the security margin: far fewer than all 16."""
    data = recorded_states[-1]
    kept = BroadPhase(model_I).near(data.q, data.opening)
    assert 0 < len(kept) < len(model_I.sim.faces.master_start)


def test_broad_phase_keeps_nothing_while_the_fingers_are_open(model_I):
    """At the start the fingers are 9 mm from the groove: coal culls every face pair."""
    data = make_data(model_I)
    assert len(BroadPhase(model_I).near(data.q, data.opening)) == 0


def test_action_equals_reaction_about_any_point(model_I, recorded_states):
    """The wrenches on the finger bodies and on the module sum to zero about any point, and
    each body's wrench in its joint's frame is its world wrench."""
    rng = np.random.default_rng(3)
    for state in recorded_states[::3]:
        data = contacts_by(model_I, state, "culled")
        body_wrenches(model_I.sim, data)
        loads = data.loads
        scale = np.abs(data.contacts.force_W).sum()
        for point in rng.normal(scale=0.5, size=(3, 3)):
            F = loads.force_W.sum(axis=0)
            T = loads.torque_O_W.sum(axis=0) - np.cross(point, F)
            assert np.linalg.norm(F) <= BALANCE_RTOL * scale
            assert np.linalg.norm(T) <= BALANCE_RTOL * scale
        for j in model_I.contact_joints:
            world = pin.SE3(data.R_W[j], data.p_W[j]).act(pin.Force(loads.f_local[j]))
            assert np.allclose(world.linear, loads.force_W[j], rtol=0, atol=BALANCE_RTOL * scale)
            assert np.allclose(world.angular, loads.torque_O_W[j], rtol=0, atol=BALANCE_RTOL * scale)
