"""The culled search (coal broad phase + grid-local search) against the paper's all-pairs search."""

import numpy as np
import pinocchio as pin

from spotsim.contact.forces import pair_forces
from spotsim.contact.search import grid_search, literal_search
from spotsim.contact.wrenches import body_wrenches
from spotsim.sim.broadphase import BroadPhase
from spotsim.sim.data import make_data
from spotsim.sim.tree import kinematics

#: Both searches feed the same kernel; forces may differ only by the order of summation.
FORCE_RTOL = 1e-12
#: Action equals reaction: the wrenches sum to zero up to round-off on their own scale.
BALANCE_RTOL = 1e-12
#: A tip held by a land presses into it far less than a sphere's radius (700 um), where a tip
#: passing through the adapter reached 2.2 mm.
HELD_PENETRATION_UM = 100


def contacts_by(model, state, search):
    """The contacts of a copy of `state` (its pair memory untouched) found by `search`."""
    data = state.copy()
    kinematics(model.sim, data)
    if search == "literal":
        candidates = literal_search(model.sim, data)
    else:
        candidates = grid_search(model.sim, data, BroadPhase(model).near(data.q))
    data.assign(candidates=candidates)
    pair_forces(model.sim, data, 1e-4, False)
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
    kept = BroadPhase(model_I).near(data.q)
    assert 0 < len(kept) < len(model_I.sim.faces.master_start)


def test_broad_phase_keeps_nothing_while_the_fingers_are_open(model_I):
    """At the start the fingers are 9 mm from the groove: coal culls every face pair."""
    data = make_data(model_I)
    assert len(BroadPhase(model_I).near(data.q)) == 0


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


def test_a_finger_beside_its_groove_lands_on_the_adapter_and_both_searches_agree(case_I):
    """A start 12 mm off along y_a (the upper finger's 4 mm tip across its groove's mouth edge,
    13 mm off the mid-plane): the tip comes down on the land beside the mouth, which holds it
    (the grasp closes with the finger out of its groove: the run is not captured) instead of letting
    it pass through the adapter. On states with tip-land pairs, the culled search finds exactly
    the all-pairs search's."""
    import spotsim
    from spotsim.run import Stepper
    from spotsim.status import NOT_CAPTURED, run_outcome

    s = spotsim.replace(case_I, module={"initial_offset_mm": (0.0, 12.0, 0.0)},
                        end_effector={"start_gap_mm": 12.0})
    result = spotsim.simulate(s)
    grasp = result.grasp
    assert result.status == NOT_CAPTURED and grasp["in_grooves"] is False and grasp["completed_s"] is not None
    assert run_outcome(result.status, result.summary) == NOT_CAPTURED
    assert abs(grasp["residual_offset_mm"][1]) > 11.0  # the tip's inner edge past the 13 mm half-mouth
    assert result.timeseries["max_penetration_um"].max() < HELD_PENETRATION_UM

    model = result.model
    tips = {i for i, n in enumerate(model.face_names[0]) if n.endswith("_tip")}
    stepper, h, on_land = Stepper(model), s.simulation.dt_s / s.simulation.substeps, 0
    while stepper.data.t < 0.9 and on_land < 5:
        stepper.step(h)
        d = stepper.data.view()
        if any(model.master.face[k] in tips for k in d.contacts.master):
            on_land += 1
            culled = contacts_by(model, stepper.data, "culled").contacts
            literal = contacts_by(model, stepper.data, "literal").contacts
            assert np.array_equal(culled.key, literal.key) and len(literal.key) > 0
    assert on_land == 5
