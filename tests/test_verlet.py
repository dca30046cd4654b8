"""The broad phase's Verlet skin: reusing coal's face pairs never loses a contact."""

import numpy as np

from conftest import restore
from spotsim.step import broad_phase, candidate_pairs, kinematics, make_data, step, travel_rate
from spotsim.integrators import make_integrator


def test_reused_face_pairs_find_every_contact(model_I):
    """Along Case I, the skin-reused face pairs give the same sphere pairs as a fresh broad phase."""
    data = make_data(model_I)
    integrator = make_integrator("symplectic_euler", model_I.pin_model)
    h = 1e-4
    checked = reused = 0
    while data.t < 0.75:
        step(model_I, data, h, integrator)
        if data.t > 0.42 and round(data.t / h) % 25 == 0:
            snap = restore(data)
            kinematics(model_I, snap)
            fresh = candidate_pairs(model_I, snap, broad_phase(model_I, snap))
            kept = candidate_pairs(model_I, snap, data.near_pairs)
            assert np.array_equal(fresh[2], kept[2])  # keys, sorted
            checked += 1
            reused += data.travel > 0
    assert checked > 10 and reused > 0


def test_travel_rate_bounds_the_fingers_and_the_module(model_I):
    """The travel bound counts at least the closing fingers' speed once they move."""
    data = make_data(model_I)
    integrator = make_integrator("symplectic_euler", model_I.pin_model)
    step(model_I, data, 1e-4, integrator)
    assert travel_rate(model_I, data) >= model_I.scenario.end_effector.closing_speed_m_s
