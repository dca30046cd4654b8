"""The finger drive: the kinematic drive's law (self-locking, force-limited, continuous in the
load), a finger closing on a rigid stop, and what a whole run's drive does."""

import numpy as np
import pytest
from conftest import ROOT
from hypothesis import given, settings
from hypothesis import strategies as st

import spotsim
from spotsim.assemble.model import drives
from spotsim.sim.actuation import kinematic_speed

CASE_I = ROOT / "config" / "single_arm_case_I.yaml"
#: Round-off of the law's arithmetic: relative, and absolute on speeds (m/s; the law's speeds
#: are ~1e-2 m/s, so 1e-15 is a few ulps).
ROUND_OFF = 1e-12
SPEED_ROUND_OFF = 1e-15
#: The linearised law solved in closed form against the same line evaluated back: the solve
#: divides once, so agreement to 1e-9 relative leaves round-off three orders of margin.
LINE_TOLERANCE = 1e-9
#: Rows the rigid stop holds for: 0.2 s after touch to the end, at 1 ms records, at least.
HELD_ROWS = 500
#: A drive at rest closes no faster than the contact speed limit (1e-4 m/s), so its load is
#: within 1e-4 / v0 = 0.36 % below the grasp load; Hertz contact is convex, so the linearised
#: law's last period may press a little past it. The stop's reaction is held to 1 %.
STOP_TOLERANCE = 0.01

#: This file tests the kinematic drive (the default is the motor, tests/test_motor.py)
KINEMATIC = ["end_effector.drive=kinematic"]
#: Case I's drive, one end-effector's row (the finger mass only sets a motor's speed-loop gain)
DRIVES = drives(spotsim.load_scenario(CASE_I, KINEMATIC).end_effector, 1, finger_mass=0.0)
F_G, V_C, V_0 = DRIVES.grasp_load[0], DRIVES.closing_speed[0], DRIVES.no_load_speed[0]


def drive_speed(load, stiffness, damping, speed, h):
    """The kinematic drive's speed for Case I's drive (`actuation.kinematic_speed`), m/s."""
    return kinematic_speed(DRIVES, 0, load, stiffness, damping, speed, h)


loads = st.floats(0.0, 1e4)
slopes = st.floats(0.0, 1e8)
dampings = st.floats(0.0, 1e4)
speeds = st.floats(0.0, V_C)
steps = st.floats(1e-7, 1e-2)


def end_load(load, stiffness, damping, speed, h, v):
    """The load at the end of a period of h at speed v, linearised (the law's own model)."""
    return load + damping * (v - speed) + stiffness * h * v


@settings(max_examples=300, deadline=None)
@given(loads, slopes, dampings, speeds, steps)
def test_kinematic_drive_never_opens_never_exceeds_its_speed_and_presses_at_most_the_grasp_load(load, k, c, speed, h):
    """Self-locking: the speed is never negative (the fingers never open), whatever the load;
    the speed loop caps it at the closing speed; and while it closes, the load the period
    ends at is below the grasp load (the motor pushes no harder than its current limit)."""
    v = drive_speed(load, k, c, speed, h)
    assert 0.0 <= v <= V_C
    if v > 0.0:
        assert end_load(load, k, c, speed, h, v) < F_G * (1 + ROUND_OFF)


@settings(max_examples=300, deadline=None)
@given(loads, slopes, dampings, speeds, steps)
def test_kinematic_drive_holds_its_torque_speed_line_at_the_end_of_the_period(load, k, c, speed, h):
    """Between the stop and the speed limit the speed is the torque-speed line's at the load
    the period ends at (backward Euler): v = v0 (1 - F_end / F_g)."""
    v = drive_speed(load, k, c, speed, h)
    if 0.0 < v < V_C:
        line = V_0 * (1.0 - end_load(load, k, c, speed, h, v) / F_G)
        assert v == pytest.approx(line, rel=LINE_TOLERANCE, abs=SPEED_ROUND_OFF)


@settings(max_examples=300, deadline=None)
@given(loads, loads, slopes, dampings, speeds, steps)
def test_kinematic_drive_speed_is_continuous_in_the_load(a, b, k, c, speed, h):
    """No jump: two loads give speeds no further apart than the torque-speed line's slope
    v0 / F_g times their difference (the slopes only flatten it)."""
    va, vb = (drive_speed(x, k, c, speed, h) for x in (a, b))
    assert abs(va - vb) <= V_0 / F_G * abs(a - b) * (1 + ROUND_OFF) + SPEED_ROUND_OFF


def test_kinematic_drive_closes_at_full_speed_until_the_slowdown_and_stops_at_the_grasp_load():
    """Without slopes the law is the motor's line capped by the speed limit: full speed up to
    half the grasp load, linear down to zero at it, zero beyond."""
    F_g, v_c = F_G, V_C
    speed = lambda F: drive_speed(F, 0.0, 0.0, 0.0, 1e-4)
    assert speed(0.0) == speed(0.5 * F_g) == v_c
    assert speed(0.75 * F_g) == pytest.approx(0.5 * v_c)
    assert speed(F_g) == speed(2 * F_g) == speed(1e6) == 0.0


@pytest.fixture(scope="module")
def rigid_stop():
    """Case I's fingers closing on a centred module 10^12 kg heavy: a rigid stop (the net
    force its grooves' asymmetry leaves, a few N, moves it by picometres in a second)."""
    s = spotsim.load_scenario(CASE_I, KINEMATIC)
    s = spotsim.replace(s, simulation={"duration_s": 1.5},
                        module={"mass_kg": 1e12, "initial_offset_mm": (0.0, 0.0, 0.0),
                                "inertia_kg_m2": {"ixx": 1e10, "iyy": 1e10, "izz": 1e10, "ixy": 0.0,
                                                  "ixz": 0.0, "iyz": 0.0}})
    return spotsim.simulate(s)


def test_finger_on_a_rigid_stop_reaches_the_grasp_load_and_holds_it(rigid_stop):
    """The drive closes, slows and stops pressing the stop with the grasp load: the stop's
    reaction on the fingers (their mean load, what the drive carries) is the grasp load
    within 1 % from 0.2 s after the first contact on, and the drive is at rest there."""
    ts = rigid_stop.timeseries
    touch = rigid_stop.grasp["contact_onset_s"]
    held = ts["t"] >= touch + 0.2
    assert held.sum() >= HELD_ROWS
    np.testing.assert_allclose(ts["finger_load_N"][held].mean(axis=1), F_G, rtol=STOP_TOLERANCE)
    at_rest_mm_s = rigid_stop.scenario.completion.max_contact_speed_m_s * 1e3  # the contact speed limit
    assert np.all(ts["drive_speed_mm_s"][held] <= at_rest_mm_s)
    assert np.all(np.diff(ts["finger_opening_mm"], axis=0) <= 0.0)


def test_a_run_never_opens_the_fingers_and_its_drive_never_jumps_to_full_speed():
    """Case I with the kinematic drive: the recorded openings never grow, the speed is never
    negative nor above the closing speed, and the drive never stops dead and resumes at
    full speed as the relay does."""
    case_I = spotsim.load_scenario(CASE_I, KINEMATIC)
    r = spotsim.simulate(case_I)
    assert r.status == "completed"
    speed = r.timeseries["drive_speed_mm_s"]
    assert np.all(speed >= 0.0) and np.all(speed <= V_C * 1e3 * (1 + ROUND_OFF))
    assert np.all(np.diff(r.timeseries["finger_opening_mm"], axis=0) <= 0.0)
    g = r.summary["grasps"][0]
    assert g["drive_largest_speed_step_mm_s"] < V_C * 1e3
    relay = spotsim.simulate(spotsim.replace(case_I, end_effector={"drive": "relay"}))
    assert relay.summary["grasps"][0]["drive_largest_speed_step_mm_s"] == pytest.approx(V_C * 1e3)
    assert relay.summary["grasps"][0]["drive_resumes"] > g["drive_resumes"]
