"""The single-arm experiment's rig (`assemble.rig`): the bungee the module hangs on and the
dynamometer under the arm, against their closed forms; what the instrument reads."""

import math

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg
from conftest import ROOT

import spotsim
from spotsim.assemble.rig import DYNAMOMETER_JOINTS, stiffnesses
from spotsim.run import Stepper

EXPERIMENT = ROOT / "config" / "single_arm_experiment.yaml"
#: The issue's bound on a mode's period against its closed form.
PERIOD_REL = 1e-2
#: The static load against the weight: both are the same gravity on the same bodies, so round-off.
STATIC_REL = 1e-9
#: At rest the reading is zero up to round-off on loads of ~100 N over ~1e4 steps.
AT_REST_N = 1e-6
#: Momentum drift relative to the largest body momentum, the module's: round-off over the run
#: (the bungee's pull and gravity are in the external impulse), as test_compliance holds it.
LINEAR_MOMENTUM_BOUND = 1e-9


def zero_crossing_period(t, y, rest=0.0):
    """Twice the mean spacing of y's crossings of `rest` (linearly interpolated), s."""
    y = y - rest
    at = np.nonzero(np.sign(y[:-1]) != np.sign(y[1:]))[0]
    crossings = t[at] - y[at] * (t[at + 1] - t[at]) / (y[at + 1] - y[at])
    assert len(crossings) >= 3
    return 2.0 * float(np.diff(crossings).mean())


def test_the_hung_module_swings_and_bounces_at_the_bungees_derived_periods():
    """Displaced 1 mm sideways and 1 mm up from where it hangs (the fingers far off: the drive
    closes at 1 mm/s), the module swings as a pendulum of the bungee's loaded length,
    T = 2 pi sqrt(L / g), and bounces on its stiffness, T = 2 pi sqrt(m / k): the paper's 1.6 s
    and 0.91 Hz, from which the defaults are derived."""
    s = spotsim.load_scenario(EXPERIMENT, ["suspension.damping_ratio=0", "end_effector.closing_speed_m_s=1e-4"])
    model = spotsim.build_model(s)
    joint = model.modules[0].joint
    iq = model.pin_model.idx_qs[joint]
    stepper = Stepper(model)
    d = stepper.data
    rest = np.asarray(d.q)[iq + 1:iq + 3].copy()
    d.q[iq + 1] += 1e-3  # world y: sideways, along the closing axis
    d.q[iq + 2] += 1e-3  # world z: up
    t, side, up = [], [], []
    while d.t < 2.5:
        stepper.step(1e-3)
        t.append(d.t)
        side.append(d.q[iq + 1])
        up.append(d.q[iq + 2])
    assert d.pair_steps == 0  # nothing touched it
    t = np.array(t)
    b, g = s.suspension, 9.81
    assert zero_crossing_period(t, np.array(side), rest[0]) == pytest.approx(
        2 * math.pi * math.sqrt(b.loaded_length_m / g), rel=PERIOD_REL)
    assert zero_crossing_period(t, np.array(up), rest[1]) == pytest.approx(
        2 * math.pi * math.sqrt(s.module.mass_kg / b.stiffness_N_m), rel=PERIOD_REL)


def test_the_dynamometer_carries_the_arms_weight_from_the_start_and_reads_zero_at_rest():
    """Its springs hold the start still: their static load is the weight of everything on the
    plate, M g, and its moment about the plate's top centre, r_G x M g (closed form from the
    bodies' masses and centroids); with nothing touching, the reading (the load since the
    start) stays zero."""
    s = spotsim.load_scenario(EXPERIMENT, ["end_effector.closing_speed_m_s=0.001", "simulation.duration_s=0.2"])
    model = spotsim.build_model(s)
    pm = model.pin_model
    data = pm.createData()
    pin.forwardKinematics(pm, data, model.q0)
    first = pm.getJointId(DYNAMOMETER_JOINTS[0])
    carried = [j for j in range(first, pm.njoints) if not pm.names[j].startswith("tm_")]
    mass = sum(pm.inertias[j].mass for j in carried)
    centroid = sum(pm.inertias[j].mass * data.oMi[j].act(pm.inertias[j].lever) for j in carried) / mass
    weight = mass * np.array(s.simulation.gravity_m_s2)
    origin = data.oMi[pm.getJointId("dyn_rx")].translation
    expected = np.r_[-weight, -np.cross(centroid - origin, weight)]  # what the springs push up with
    held = np.array([model.springs[name][0] * model.springs[name][2] for name in DYNAMOMETER_JOINTS])
    assert held == pytest.approx(expected, rel=STATIC_REL, abs=STATIC_REL * abs(weight[2]))
    result = spotsim.simulate(s, model=model)
    reading = np.c_[result.timeseries["dynamometer_force_N"], result.timeseries["dynamometer_moment_Nm"]]
    assert np.abs(reading).max() < AT_REST_N


def test_the_loaded_dynamometer_rings_at_its_natural_frequency():
    """Undamped, without gravity, with a rigid arm: displaced along one of its modes (K phi =
    omega^2 M phi, K its six stiffnesses, M its joints' block of the mass matrix with the arm
    on it), the plate rings at that omega: its vertical mode here, from the reading's zero
    crossings."""
    s = spotsim.load_scenario(EXPERIMENT, ["dynamometer.damping_ratio=0", "simulation.gravity_m_s2=[0,0,0]",
                                           "suspension.kind=none", "arm.compliance.joints=rigid",
                                           "end_effector.closing_speed_m_s=0.001"])
    model = spotsim.build_model(s)
    pm = model.pin_model
    iv = [pm.idx_vs[pm.getJointId(name)] for name in DYNAMOMETER_JOINTS]
    iq = [pm.idx_qs[pm.getJointId(name)] for name in DYNAMOMETER_JOINTS]
    M = pin.crba(pm, pm.createData(), model.q0)
    M = (np.triu(M) + np.triu(M, 1).T)[np.ix_(iv, iv)]
    w2, phi = scipy.linalg.eigh(np.diag(stiffnesses(s.dynamometer)), M)
    mode = int(np.argmax(np.abs(phi[2])))  # the one that moves most along z
    omega, shape = math.sqrt(w2[mode]), phi[:, mode] / abs(phi[2, mode])
    stepper = Stepper(model)
    d = stepper.data
    d.q[iq] = 1e-7 * shape
    period = 2 * math.pi / omega
    t, z = [], []
    while d.t < 6.2 * period:
        stepper.step(period / 400)
        t.append(d.t)
        z.append(d.q[iq[2]])
    assert zero_crossing_period(np.array(t), np.array(z)) == pytest.approx(period, rel=PERIOD_REL)


def test_the_experiment_records_the_dynamometers_reading_beside_the_contact_force(tmp_path):
    """The replica runs to completion; its summary gives the dynamometer's peaks per axis
    beside the contact force's, its figure both; momentum balances with the bungee's pull
    and gravity in the external impulse."""
    result = spotsim.simulate(spotsim.load_scenario(EXPERIMENT))
    assert result.summary["status"] == "completed"
    rig = result.summary["dynamometer"]
    assert len(rig["peak_force_N"]) == 3 and len(rig["peak_moment_Nm"]) == 3
    assert all(x > 0 for x in rig["peak_force_N"])
    assert result.summary["momentum"]["linear_drift_rel"] < LINEAR_MOMENTUM_BOUND
    spotsim.write_results(result, tmp_path)
    assert (tmp_path / "figures" / "dynamometer.png").is_file()
