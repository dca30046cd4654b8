"""The motor drive (`end_effector.drive: motor`): a current-limited motor behind a gearhead and a
lead screw whose nut halves close both fingers alike (a mirror linkage), its transmission a
stick-slip element (`sim.dynamics.transmissions`, `sim.actuation.transmission_events`)."""

import math

import numpy as np
import pytest
from conftest import CASE_I, ROOT

import spotsim
from spotsim.assemble.model import motor_drive, screw_efficiencies
from spotsim.run import Stepper
from spotsim.sim.actuation import (
    motor_closing,
    motor_opening,
    next_event,
    quiet_readings,
    sample_controllers,
    speed_loop,
    transmission_events,
)
from spotsim.sim.dynamics import accelerations, joint_response
from spotsim.sim.tree import kinematics
from spotsim.tables import BACKWARD, FORWARD, STUCK

LEAD, DIAMETER, FLANK = 0.7e-3, 3.545e-3, math.radians(30.0)
#: Relative round-off of the speed loop's arithmetic, with room for a few operations.
ROUND_OFF = 1e-12
#: The held clamp's closed form against 200 readings: each reading's time step is a difference of
#: reading times (exact to ~1e-16 relative), so the recursion drifts from the closed form by far
#: less than this.
CLOSED_FORM_REL = 1e-9


def motor_model(*sets):
    return spotsim.build_model(spotsim.load_scenario(CASE_I, ["end_effector.drive=motor", *sets]))


def finger_dofs(model):
    t = model.sim.tree
    return [int(t.idx_v[j]) for j in model.sim.actuators.joint]


def test_a_frictionless_screw_is_lossless_and_self_locking_starts_where_its_backward_efficiency_crosses_zero():
    assert screw_efficiencies(LEAD, DIAMETER, FLANK, 0.0) == pytest.approx((1.0, 1.0), abs=1e-15)
    lead_angle = math.atan(LEAD / (math.pi * DIAMETER))
    k = math.cos(FLANK) * math.tan(lead_angle)  # cos(alpha) tan(lambda): eta_b = 0
    forward, backward = screw_efficiencies(LEAD, DIAMETER, FLANK, k)
    assert backward == pytest.approx(0.0, abs=1e-12)
    assert forward < 0.5  # a self-locking screw wastes more than half the motor's work
    assert screw_efficiencies(LEAD, DIAMETER, FLANK, 1.01 * k)[1] < 0.0 < screw_efficiencies(LEAD, DIAMETER, FLANK,
                                                                                           0.99 * k)[1]


def test_a_step_of_current_accelerates_both_fingers_alike_with_the_rotors_reflected_inertia():
    """Case I's fixed hand, its fingers in free flight: at a constant current i the pair's
    closing speed grows at eta_f rho K_t i / (eta_f J rho^2 + 2 m_f): the rotor's inertia J
    reaches the fingers through the transmission's ratio rho and, the power flowing forward,
    its efficiency eta_f."""
    model = motor_model()
    m = model.sim
    stepper = Stepper(model)
    d = stepper.data
    current = 0.2
    d.current[0] = current
    d.assign(sample_t=math.inf)  # the speed loop never reads: the current stays
    md = motor_drive(model.scenario.end_effector.motor)
    finger_mass = model.pin_model.inertias[int(m.actuators.joint[0])].mass
    rate = md.forward * md.ratio * md.torque_constant * current / (md.forward * md.reflected_inertia + 2 * finger_mass)
    v0 = motor_closing(m, d, 0)
    while d.t < 0.05:
        stepper.step(min(1e-4, 0.05 - d.t))
        assert d.transmission[0] == FORWARD
        assert d.contacts.key.shape[0] == 0  # free flight
    dofs = finger_dofs(model)
    assert d.v[dofs[0]] == d.v[dofs[1]]  # the linkage: to the bit
    assert motor_closing(m, d, 0) - v0 == pytest.approx(rate * d.t, rel=1e-3)


@pytest.mark.parametrize("period", [4e-4, 4e-5])
def test_the_speed_loops_integral_is_the_fingers_lag_behind_their_set_travel_whatever_its_period(period):
    """The speed loop reads an encoder (the travel since its last reading over the time
    between): the sum of its errors is the lag itself. Case I's fingers in free flight,
    slowed to 0.9 of the set speed after the drive's first reading, catch up without reaching
    the clamp; at every reading the integral is the gain over the integral time times the
    set speed's travel less the fingers' own."""
    model = motor_model(f"end_effector.motor.speed_loop_period_s={period}")
    m = model.sim
    stepper = Stepper(model)
    d = stepper.data
    p, vc = m.drives, model.scenario.end_effector.closing_speed_m_s
    start = motor_opening(m, d, 0)
    for k in finger_dofs(model):
        d.v[k] = -0.9 * vc
    largest = 0.0
    while d.t < 0.02:
        stepper.step(min(1e-4, 0.02 - d.t))
        assert not d.saturated[0] and abs(d.current[0]) < p.current_limit[0]
        lag = vc * d.encoder_t[0] - (start - d.encoder_opening[0])
        assert d.integral[0] == pytest.approx(p.gain[0] / p.integral_time[0] * lag, rel=1e-9, abs=1e-15)
        largest = max(largest, lag)
    assert largest > 0.1 * vc * period  # the fingers did lag: the identity was not 0 = 0


def fingers_at_rest(*sets):
    """Case I's motor drive with `sets`, its fingers at rest, its speed loop's encoder read at
    t = 0 and its integral zero: the model, its Data, and the drive's set speed (m/s)."""
    model = motor_model(*sets)
    m = model.sim
    d = Stepper(model).data
    for k in finger_dofs(model):
        d.v[k] = 0.0
    d.encoder_t[0], d.encoder_opening[0], d.integral[0] = 0.0, motor_opening(m, d, 0), 0.0
    return model, d, model.scenario.end_effector.closing_speed_m_s


@pytest.mark.parametrize("period", [4e-4, 4e-5])
def test_back_calculation_relaxes_the_integral_to_the_clamp_by_its_closed_form_at_any_period(period):
    """Fingers held at rest ask for more current than the limit c at every reading: under
    back-calculation the integral, from zero, is c (1 - (T_i / (T_i + h))^k) after k readings
    h apart: the clamp itself in the limit, whatever the period."""
    model, d, _ = fingers_at_rest(f"end_effector.motor.speed_loop_period_s={period}",
                                  "end_effector.motor.anti_windup=back_calculation")
    m, p = model.sim, model.sim.drives
    c, keep = p.current_limit[0], p.integral_time[0] / (p.integral_time[0] + period)
    for k in range(1, 201):
        speed_loop(m, d, 0, k * period)
        assert d.saturated[0] and d.current[0] == c
        assert d.integral[0] == pytest.approx(c * (1.0 - keep**k), rel=CLOSED_FORM_REL)
    assert d.integral[0] > 0.1 * c  # it did move towards the clamp


@pytest.mark.parametrize("anti_windup", ["conditional", "back_calculation"])
def test_the_integral_after_a_reading_is_continuous_in_the_speed_read_under_back_calculation_only(anti_windup):
    """One reading from the same state, its encoder's speed swept 1 nm per period at a time
    across the speed at which the clamp starts to hold: under back-calculation the integral
    never moves by more than the gain over the integral time times the travel read (its rate
    unclamped; clamped it does not depend on the reading at all); conditional integration
    jumps there by the whole reading's increment K e h / T_i."""
    model, d, vc = fingers_at_rest(f"end_effector.motor.anti_windup={anti_windup}")
    m, p = model.sim, model.sim.drives
    h, K, T_i, c = p.period[0], p.gain[0], p.integral_time[0], p.current_limit[0]
    start = 0.1 * c
    edge = (c - start) / (K * (1.0 + h / T_i))  # the error at which K e + start + K e h / T_i reaches c
    step = 1e-9 / h
    opening = motor_opening(m, d, 0)
    integrals, clamped = [], []
    for j in range(-50, 51):
        read = vc - edge + j * step
        d.integral[0], d.encoder_t[0], d.encoder_opening[0] = start, 0.0, opening + read * h
        speed_loop(m, d, 0, h)
        integrals.append(d.integral[0])
        clamped.append(bool(d.saturated[0]))
    assert True in clamped and False in clamped  # the sweep crossed the clamp
    moves = np.abs(np.diff(integrals))
    if anti_windup == "back_calculation":
        assert moves.max() <= K * h / T_i * step * (1.0 + ROUND_OFF) + ROUND_OFF * c
    else:
        assert moves.max() > 0.5 * K * edge * h / T_i


def pressing_stuck(*sets):
    """Case I's motor drive with `sets`, its fingers at rest and its transmission stuck, its
    speed loop pressing at the current limit after a reading at t = 0, the next due one
    period later: the model, its Data, and the speed loop's period (s)."""
    model, d, _ = fingers_at_rest(*sets)
    m = model.sim
    period = m.drives.period[0]
    speed_loop(m, d, 0, 0.0)
    d.transmission[0] = STUCK
    kinematics(m, d)
    accelerations(m, d)
    assert d.saturated[0] and d.current[0] == m.drives.current_limit[0] and d.sample_t == period
    return model, d, period


@pytest.mark.parametrize("anti_windup", ["conditional", "back_calculation"])
def test_a_step_may_pass_the_readings_of_a_stuck_drive_pressing_at_its_clamp_and_takes_them_at_their_times(
        anti_windup):
    """Stuck and pressing at the clamp, the drive's readings are quiet: with `pass_quiet` no
    event ends a step there (with `each`, the next reading does), and each of 1000 readings
    one by one keeps the current. A step passing 7 of them leaves the loop as those 7 taken
    one by one at their times do."""
    model, d, period = pressing_stuck(f"end_effector.motor.anti_windup={anti_windup}",
                                      "end_effector.motor.speed_loop_period_s=1e-4",
                                      "simulation.integrator.drive_readings=each")
    assert quiet_readings(model.sim, d, 0) and next_event(model.sim, d) == d.sample_t == period
    model, d, period = pressing_stuck(f"end_effector.motor.anti_windup={anti_windup}",
                                      "end_effector.motor.speed_loop_period_s=1e-4",
                                      "simulation.integrator.drive_readings=pass_quiet")
    m = model.sim
    assert quiet_readings(m, d, 0) and next_event(m, d) == math.inf
    start = d.integral[0]
    for k in range(1, 1001):
        speed_loop(m, d, 0, k * period)
        assert d.saturated[0] and d.current[0] == m.drives.current_limit[0]
    d.integral[0], d.encoder_t[0], d.sample_t = start, 0.0, period
    for k in range(1, 8):
        speed_loop(m, d, 0, k * period)
    one_by_one = d.integral[0], d.encoder_t[0], d.sample_t
    d.integral[0], d.encoder_t[0], d.sample_t = start, 0.0, period
    sample_controllers(m, d, 7.5 * period, 7.5 * period)
    assert d.integral[0] == pytest.approx(one_by_one[0], rel=ROUND_OFF)
    assert d.encoder_t[0] == pytest.approx(one_by_one[1], rel=ROUND_OFF)
    assert d.sample_t == pytest.approx(one_by_one[2], rel=ROUND_OFF)
    assert 7.5 * period < d.sample_t < 8.5 * period  # every reading due taken, the next on their grid


@pytest.mark.parametrize("anti_windup", ["conditional", "back_calculation"])
def test_readings_are_not_quiet_unless_stuck_and_kept_at_the_clamp(anti_windup):
    """Sliding, below the clamp, or with a next reading that leaves it (the fingers read
    closing far faster than the set speed since the last), a reading ends the step."""
    model, d, period = pressing_stuck(f"end_effector.motor.anti_windup={anti_windup}",
                                      "simulation.integrator.drive_readings=pass_quiet")
    m = model.sim
    vc = model.scenario.end_effector.closing_speed_m_s
    d.transmission[0] = FORWARD
    assert not quiet_readings(m, d, 0) and next_event(m, d) == d.sample_t
    d.transmission[0] = STUCK
    d.saturated[0] = False
    assert not quiet_readings(m, d, 0)
    d.saturated[0] = True
    d.encoder_opening[0] = motor_opening(m, d, 0) + 100.0 * vc * period  # it closed at 100 v_c since
    assert not quiet_readings(m, d, 0) and next_event(m, d) == d.sample_t


def stuck_under(model, load):
    """Case I's motor drive at rest, its transmission stuck at its current limit, its fingers
    pushed open by `load` (N, in all, half on each): the transmission's state its events give,
    and the fingers' closing acceleration then."""
    m = model.sim
    d = Stepper(model).data
    dofs = finger_dofs(model)
    d.v[:] = 0.0
    d.transmission[0] = STUCK
    d.current[0] = model.scenario.end_effector.motor.current_limit_A
    for iv in dofs:
        d.tau[iv] = 0.5 * load
    kinematics(m, d)
    accelerations(m, d)
    assert d.screw_force[0] == pytest.approx(load, rel=1e-9)  # stuck: it holds the load
    transmission_events(m, d, 0)
    return int(d.transmission[0]), -d.a[dofs[0]]


@pytest.mark.parametrize("friction", [0.13, 0.02])
def test_a_stuck_transmission_holds_the_band_its_efficiencies_give_and_slides_beyond_it(friction):
    """At the motor's force A = rho K_t i_max: below eta_f A the motor closes the fingers; a
    self-locking screw (friction 0.13) holds any load above it; a back-drivable one (0.02)
    holds up to A / eta_b and the load opens it beyond."""
    model = motor_model(f"end_effector.motor.screw_friction={friction}")
    md = motor_drive(model.scenario.end_effector.motor)
    drive = md.ratio * md.torque_constant * model.scenario.end_effector.motor.current_limit_A
    state, closing = stuck_under(model, 0.99 * md.forward * drive)
    assert state == FORWARD and closing > 0.0
    assert stuck_under(model, 1.01 * md.forward * drive)[0] == STUCK
    if md.backward <= 0.0:
        assert friction == 0.13
        for load in (10 * drive, 1e3 * drive):
            assert stuck_under(model, load)[0] == STUCK
    else:
        assert friction == 0.02
        assert stuck_under(model, 0.99 * drive / md.backward)[0] == STUCK
        state, closing = stuck_under(model, 1.01 * drive / md.backward)
        assert state == BACKWARD and closing < 0.0


def test_a_lossless_drive_closing_slowly_on_a_heavy_module_presses_with_its_stall_force():
    """A lossless transmission (no screw friction, gearhead efficiency 1) closing at 0.2 mm/s
    on a module 10^4 times heavier: the fingers come to rest against it, where a lossless
    transmission's stuck band is one force, the motor's rho K_t i_max. The heavy module rings
    on the contacts' springs for longer than the run (the grasp does not complete) and the
    fingers follow it within 0.1 um, but over its last half second their mean load is half
    that force each."""
    s = spotsim.load_scenario(CASE_I, [
        "end_effector.drive=motor", "end_effector.motor.screw_friction=0", "end_effector.motor.gear_efficiency=1",
        "end_effector.closing_speed_m_s=0.0002", "end_effector.start_gap_mm=0.05", "module.initial_offset_mm=[0,0,0]",
        "module.mass_kg=25000", "module.inertia_kg_m2.ixx=1000", "module.inertia_kg_m2.iyy=1000",
        "module.inertia_kg_m2.izz=1000"])
    r = spotsim.simulate(s)
    md = motor_drive(s.end_effector.motor)
    stall = md.ratio * md.torque_constant * s.end_effector.motor.current_limit_A
    t = np.asarray(r.timeseries["t"])
    load = np.asarray(r.timeseries["finger_load_N"])[t > t[-1] - 0.5]
    opening = np.asarray(r.timeseries["finger_opening_mm"])[t > t[-1] - 0.5]
    assert md.forward == 1.0 and md.backward == 1.0
    assert np.ptp(opening) < 1e-4  # at rest against the module: within 0.1 um
    assert load.mean() == pytest.approx(0.5 * stall, rel=1e-2)


def test_the_motor_drive_keeps_the_free_floating_robots_momentum():
    """The motor's forces act between the hand and its fingers, the linkage's between the
    fingers, the stops' impulses on both: all internal. The dual arm's total linear momentum
    holds to round-off."""
    r = spotsim.simulate(spotsim.load_scenario(CASE_I.with_name("dual_arm_sequential.yaml"),
                                               ["end_effector.drive=motor"]))
    assert r.status == "completed"
    assert r.summary["momentum"]["linear_drift_rel"] <= 1e-11


def rattle_energy(substeps):
    """Case I's module rattling between the fingers of an unpowered, back-drivable, lossless
    motor drive (no current, no screw friction, gearhead efficiency 1), the pair law the
    gradient of its Hertz potential, no damping (restitution 1) and no friction: a passive,
    conservative system. The most its mechanical energy (the rotor's included) rises above
    its lowest since the start, J, at symplectic Euler's step 1 ms / substeps, and its start."""
    s = spotsim.load_scenario(CASE_I, [
        "end_effector.drive=motor", "end_effector.motor.current_limit_A=0", "end_effector.motor.screw_friction=0",
        "end_effector.motor.gear_efficiency=1", "contact.normal_direction=gradient", "contact.restitution=1",
        "friction.mu_k=1e-12", "friction.mu_s=1e-12", "end_effector.start_gap_mm=4", "simulation.duration_s=0.5",
        "simulation.integrator=symplectic_euler", f"simulation.substeps={substeps}"])
    E = np.asarray(spotsim.simulate(s).timeseries["energy_J"])
    return (E - np.minimum.accumulate(E)).max(), E[0]


def test_a_module_rattling_in_an_unpowered_back_drivable_drive_gains_no_energy_as_the_step_is_refined():
    """The drive's forces, its stops and its rotor's inertia add no energy: what the run gains
    is the integrator's error, first order in the step, which shrinks towards zero."""
    coarse, E0 = rattle_energy(100)
    fine, _ = rattle_energy(400)
    assert fine < 0.5 * coarse
    assert fine < 0.01 * E0


def test_a_current_limit_above_what_the_supply_drives_at_rest_still_completes():
    """At rest the winding takes V / R (12 V / 19.8 ohm = 0.606 A) at most: a 1 A limit is not
    reached there, and the grasp completes pressing with the supply's current (a little more
    flows while the load drives the fingers open, the back-EMF then adding to the supply)."""
    s = spotsim.load_scenario(CASE_I, ["end_effector.drive=motor", "end_effector.motor.current_limit_A=1.0"])
    r = spotsim.simulate(s)
    mo = s.end_effector.motor
    assert r.status == "completed"
    assert mo.supply_voltage_V / mo.terminal_resistance_ohm <= r.summary["grasps"][0]["motor_peak_current_A"] < 1.0


def test_the_motor_block_counts_in_a_scenarios_fingerprint_only_under_the_motor_drive():
    from spotsim.scenario import fingerprint

    def key(*sets):
        return fingerprint(spotsim.load_scenario(CASE_I, list(sets)))
    kinematic = "end_effector.drive=kinematic"
    assert key(kinematic) == key(kinematic, "end_effector.motor.gear_ratio=5")
    assert key() != key("end_effector.motor.gear_ratio=5")  # the default drive is the motor
    # the defaults: back-calculation, steps that pass the speed loop's quiet readings
    assert key() == key("end_effector.motor.anti_windup=back_calculation") != key("end_effector.motor.anti_windup="
                                                                                  "conditional")
    assert key() == key("simulation.integrator.drive_readings=pass_quiet") != key("simulation.integrator."
                                                                                 "drive_readings=each")


@pytest.mark.parametrize("config", ["single_arm_case_I.yaml", "dual_arm_sequential.yaml"])
def test_the_fingers_responses_reusing_the_last_pass_are_those_of_a_whole_pass(config):
    """A finger joint's response to a unit force (M^-1's column) taken from the articulated
    inertias of the pass `accelerations` just made is, to the bit, that of a whole pass of
    its own, in contact and with the fingers moving."""
    model = spotsim.build_model(spotsim.load_scenario(ROOT / "config" / config, ["end_effector.drive=motor"]))
    stepper = Stepper(model)
    d, m = stepper.data, model.sim
    while not len(d.contacts.key) and d.t < 2.0:
        stepper.step(1e-4)
    for _ in range(50):
        stepper.step(1e-5)
    assert len(d.contacts.key) and np.any(d.v[finger_dofs(model)] != 0.0)
    kinematics(m, d)
    accelerations(m, d)
    for j in m.actuators.joint:
        reused, whole = np.empty(len(d.v)), np.empty(len(d.v))
        joint_response(m, d, j, reused, False)
        joint_response(m, d, j, whole, True)
        assert np.array_equal(reused, whole)
        assert reused[m.tree.idx_v[j]] > 0.0
