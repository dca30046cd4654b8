"""The SPOT air-bearing testbed (paper Sec. 5.2): planar bodies, the table's reactions, the
experiment's displacement measures and their comparison with a marker record."""

import json

import numpy as np
import pinocchio as pin
import pytest
from conftest import ROOT

import spotsim
from spotsim.assemble.robot import TABLE6, grasp_axes, level_arms
from spotsim.cli import main
from spotsim.measures import BODIES, read_markers
from spotsim.sim.data import make_data
from spotsim.sim.dynamics import accelerations, table_load
from spotsim.sim.tree import kinematics

TESTBED = sorted((ROOT / "config").glob("spot_testbed_*.yaml"))
THREE_MM = ROOT / "config" / "spot_testbed_3mm.yaml"
#: Heights and tilts are fixed by the planar joints: what moves them is round-off on
#: millimetre-to-metre numbers.
HEIGHT_ROUND_OFF_M = 1e-12
TILT_ROUND_OFF_RAD = 1e-12
#: In-plane momentum, relative to the largest body's: the free-floating runs' bound
#: (test_dual_arm.LINEAR_MOMENTUM_BOUND), measured ~1e-12.
MOMENTUM_BOUND = 1e-9
#: Halving a first-order error: measured 1.98 over the first 0.6 s (test_dual_arm's band).
FIRST_ORDER_RATIO = (1.6, 2.5)
#: The configs' arm angles are written to 6 decimals of a radian; twelve such roundings tilt a
#: grasp frame by at most about 1e-5 rad.
ANGLE_DIGITS_RAD = 1e-6
LEVEL_TILT_RAD = 1e-5
#: Newton-Euler on a known wrench: a few operations on O(1) numbers.
DYNAMICS_RTOL = 1e-12
#: A grasp shoves TM-2 by about a millimetre along x (README's table): far above round-off.
MOVED_M = 1e-4
#: The levelled arm angles stay near Table 6's (level_arms moves them by at most 4.2 deg).
LEVEL_CHANGE_DEG = 5.0
#: markers.csv writes times to 1e-6 s and values to 6 significant digits (mm values below 10 mm).
CSV_TIME_S = 1e-6
CSV_ROUND_OFF_MM = 1e-5


@pytest.fixture(scope="module")
def run():
    return spotsim.simulate(spotsim.load_scenario(THREE_MM))


def _rotation(quat_xyzw):
    x, y, z, w = quat_xyzw
    return pin.Quaternion(w, x, y, z).toRotationMatrix()


def test_planar_bodies_keep_height_roll_and_pitch_through_both_grasps_and_the_weld(run):
    """The base, TM-1 and TM-2 (TM-1 welded to the robot after the first grasp) keep their
    heights along the table's normal and never tilt from it."""
    assert run.status == "completed", run.summary["message"]
    assert len(run.summary["welds_s"]) == 1
    ts, n = run.timeseries, np.array(run.summary["testbed"]["table_normal"])
    for pos, quat in (("base_pos_m", "base_quat_xyzw"), ("TM-1_pos_m", "TM-1_quat_xyzw"),
                      ("TM-2_pos_m", "TM-2_quat_xyzw")):
        heights = ts[pos] @ n
        assert np.abs(heights - heights[0]).max() <= HEIGHT_ROUND_OFF_M
        R0 = _rotation(ts[quat][0])
        tilt = [np.linalg.norm(_rotation(q) @ R0.T @ n - n) for q in ts[quat]]
        assert max(tilt) <= TILT_ROUND_OFF_RAD
    # the bodies did move in the plane and turn about the normal
    assert np.ptp(ts["TM-2_pos_m"] @ np.array([1.0, 0.0, 0.0])) > MOVED_M


def test_in_plane_momentum_is_conserved_and_angular_momentum_to_the_steps_order(run):
    """The in-plane momentum to round-off. The angular momentum about the normal as the
    integrators keep it: a body on a joint of a turning branch (a finger, TM-1 after its weld)
    sits where the branch's turn puts it, nonlinear in the angle, so symplectic Euler keeps
    it to first order: halving the step halves the drift."""
    m = run.summary["momentum"]
    assert "table's normal" in m["definition"]
    assert m["linear_drift_rel"] <= MOMENTUM_BOUND

    def drift(substeps):
        s = spotsim.replace(run.scenario, simulation={"duration_s": 0.6, "substeps": substeps,
                                                      "integrator": {"method": "symplectic_euler"}})
        return spotsim.simulate(s).summary["momentum"]["angular_drift_rel"]
    assert FIRST_ORDER_RATIO[0] <= drift(10) / drift(20) <= FIRST_ORDER_RATIO[1]


def test_the_grasps_press_the_table_and_the_table_reacts(run):
    """The contact's out-of-plane wrench is reported as the table's load, and moves nothing."""
    for g in run.summary["grasps"]:
        assert g["table_force_peak_N"] > 0 and g["table_moment_peak_Nm"] > 0
    heights = run.summary["testbed"]["heights_mm"]
    assert set(heights) == {"base", "TM-1", "TM-2"}


@pytest.mark.parametrize("path", TESTBED, ids=lambda p: p.name)
def test_the_testbed_configs_complete(path):
    r = spotsim.simulate(spotsim.load_scenario(path))
    assert r.status == "completed", r.summary["message"]
    assert all(g["in_grooves"] for g in r.summary["grasps"])
    for g, grasp in enumerate(r.summary["grasps"]):
        for column, a in grasp["displacements"].items():
            assert a["peak_to_peak"] >= abs(a["max_excursion"]), column
        moved = {body: max(grasp["displacements"][f"{body}_{c}"]["peak_to_peak"] for c in ("x_mm", "y_mm"))
                 for body in ("TM-1", "TM-2")}
        assert moved[f"TM-{g + 1}"] > 0  # the grasp pushes its module
        if g == 0:
            assert moved["TM-2"] == 0.0  # untouched, at rest on its air bearing


def test_a_planar_body_moves_as_m_and_Izz_say_and_an_out_of_plane_wrench_moves_nothing():
    """TM-2 on its planar joint: a known in-plane force and moment about the normal give
    a_G = F / m and alpha = tau / I_nn; a force along the normal and a moment about an
    in-plane axis give nothing, and are the table's load."""
    model = spotsim.build_model(spotsim.load_scenario(THREE_MM))
    sim, data = model.sim, make_data(model)
    kinematics(sim, data)
    j = model.modules[1].joint
    b = list(sim.branches.joint).index(j)
    pm = model.pin_model
    m, c = pm.inertias[j].mass, pm.inertias[j].lever
    R, p_O = data.R_W[j].copy(), data.p_W[j].copy()
    n = sim.table_normal
    p_G = p_O + R @ c
    I_nn = n @ R @ pm.inertias[j].inertia @ R.T @ n
    pd = pm.createData()
    in_plane, across = np.array([3.0, 0.0, -4.0]), np.array([1.5, 0.0, 2.0])
    assert abs(in_plane @ n) == 0 and abs(across @ n) == 0

    def accelerate(F_W, tau_G_W):
        f_local = np.zeros_like(data.loads.f_local)
        f_local[j, :3] = R.T @ F_W
        f_local[j, 3:] = R.T @ (tau_G_W + np.cross(p_G - p_O, F_W))
        force_W = np.zeros_like(data.loads.force_W)
        force_W[j] = F_W
        torque_O_W = np.zeros_like(data.loads.torque_O_W)
        torque_O_W[j] = tau_G_W + np.cross(p_G, F_W)
        data.assign(loads=data.loads._replace(f_local=f_local, force_W=force_W, torque_O_W=torque_O_W))
        accelerations(sim, data)
        # the centroid's classical acceleration (Pinocchio's), in world
        pin.forwardKinematics(pm, pd, data.q, data.v, data.a)
        acc, twist = pd.a[j], pd.v[j]
        a_G = R @ (acc.linear + np.cross(acc.angular, c) + np.cross(twist.angular, twist.linear +
                                                                      np.cross(twist.angular, c)))
        return a_G, R @ acc.angular, b

    a_G, alpha, _ = accelerate(in_plane, 0.7 * n)
    np.testing.assert_allclose(a_G, in_plane / m, rtol=DYNAMICS_RTOL, atol=DYNAMICS_RTOL)
    np.testing.assert_allclose(alpha, 0.7 / I_nn * n, rtol=DYNAMICS_RTOL, atol=DYNAMICS_RTOL)
    a_G, alpha, b = accelerate(25.0 * n, 0.9 * across)
    np.testing.assert_allclose(a_G, 0.0, atol=DYNAMICS_RTOL)
    np.testing.assert_allclose(alpha, 0.0, atol=DYNAMICS_RTOL)
    force, moment = table_load(sim, data, b)
    assert force == pytest.approx(25.0, rel=DYNAMICS_RTOL)
    assert moment == pytest.approx(0.9 * np.linalg.norm(across), rel=DYNAMICS_RTOL)


def test_the_testbed_arm_angles_level_both_grasp_frames():
    """The configs' arm angles are `level_arms`' (to their 6 decimals), and there both grasp
    frames' y_a lie along the table's normal (world y): their x_a and z_a are in its plane."""
    s = spotsim.load_scenario(THREE_MM)
    angles = {"arm1_": s.robot.arm1_joint_angles_rad, "arm2_": s.robot.arm2_joint_angles_rad}
    fitted = level_arms(s.testbed.table_normal)
    for prefix, values in angles.items():
        np.testing.assert_allclose(values, fitted[prefix], atol=ANGLE_DIGITS_RAD)
        assert np.degrees(np.abs(np.array(values) - TABLE6[prefix])).max() < LEVEL_CHANGE_DEG
    for R in grasp_axes(spotsim.build_model(s).urdf, angles):
        assert np.linalg.norm(np.cross(R[:, 1], s.testbed.table_normal)) <= LEVEL_TILT_RAD


def test_markers_are_a_camera_record_and_plot_compares_a_measured_one(tmp_path, capsys):
    """`run --sample-hz` writes markers.csv at that rate; `plot --markers` with the run's own
    record finds no error, and with one shifted by 0.1 mm finds 0.1 mm."""
    out = tmp_path / "out"
    assert main(["run", str(THREE_MM), "--out", str(out), "--quiet", "--no-error-estimate", "--sample-hz", "30",
                 "--set", "simulation.duration_s=1.5"]) == 3
    summary = json.loads((out / "summary.json").read_text())
    assert summary["markers"]["sample_hz"] == 30
    t, columns = read_markers(out / "markers.csv")
    recorded = np.load(out / "timeseries.npz")["t"]
    assert len(t) == int(recorded[-1] * 30 + CSV_TIME_S) + 1 and t[1] - t[0] == pytest.approx(1 / 30, abs=CSV_TIME_S)
    assert set(columns) == {f"{b}_{q}" for b in BODIES for q in ("x_mm", "y_mm", "yaw_deg")}
    capsys.readouterr()
    assert main(["plot", str(out), "--markers", str(out / "markers.csv")]) == 0
    printed = capsys.readouterr().out
    assert "grasp 1 base_x_mm" in printed and (out / "figures" / "markers_comparison.png").exists()
    errors = (out / "markers_comparison.csv").read_text().splitlines()[1:]
    assert errors and all(float(line.split(",")[4]) < CSV_ROUND_OFF_MM for line in errors if line.split(",")[2] != "0")
    shifted = tmp_path / "shifted.csv"
    shifted.write_text("time_s,base_x_mm\n" + "".join(f"{a:.6f},{b + 0.1:.6g}\n"
                                                        for a, b in zip(t, columns["base_x_mm"], strict=True)))
    assert main(["plot", str(out), "--markers", str(shifted)]) == 0
    rms = [float(line.split(",")[3]) for line in (out / "markers_comparison.csv").read_text().splitlines()[1:]]
    assert rms and all(x == pytest.approx(0.1, abs=CSV_ROUND_OFF_MM) for x in rms)


@pytest.mark.parametrize("text, message", [
    ("t,base_x_mm\n0,0\n", "first column is time_s"),
    ("time_s,base_q_mm\n0,0\n1,0\n", "are not distinct columns"),
    ("time_s,base_x_mm\n0,0\n1,x\n", "line 3 has a value that is not a number"),
    ("time_s,base_x_mm\n0,0\n0,1\n", "times increasing"),
    ("time_s,base_x_mm\n0,0,1\n", "line 2 has 3 values"),
])
def test_a_bad_marker_record_is_one_clear_line(tmp_path, capsys, text, message):
    out = tmp_path / "out"
    main(["run", str(THREE_MM), "--out", str(out), "--quiet", "--no-error-estimate", "--no-figures",
          "--set", "simulation.duration_s=0.05"])
    bad = tmp_path / "bad.csv"
    bad.write_text(text)
    capsys.readouterr()
    assert main(["plot", str(out), "--markers", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err


def test_the_replay_places_the_floating_bodies_on_their_planar_joints_where_the_run_had_them(tmp_path):
    """On the table the base and the modules float on planar joints: the replay's kinematics
    sets each from its recorded world pose, and every end-effector and module lands on the
    run's own record of it (1 nm) through TM-1's first impacts."""
    from spotsim.replay.run import Kinematics, load_run, recorded_state

    out = tmp_path / "testbed"
    assert main(["run", str(THREE_MM), "--out", str(out), "--quiet", "--no-figures", "--no-error-estimate",
                 "--set", "simulation.duration_s=0.7"]) in (0, 3)
    run = load_run(out)
    kin = Kinematics(run, run.model.pin_model)
    pm = run.model.pin_model
    for row in range(0, len(run.ts["t"]), 50):
        modules, base, opening, arm = recorded_state(run, row)
        data = kin.place(modules, base, opening, arm)
        for ee in run.model.end_effectors:
            placed = (data.oMi[ee.joint] * ee.placement).translation
            assert np.abs(placed - run.ts[f"{ee.name}_pos_m"][row]).max() < 1e-9
        for k, mod in enumerate(run.model.modules):
            placed = data.oMi[mod.joint] * mod.placement
            assert np.abs(placed.translation - modules[k].translation).max() < 1e-9
            assert pm.nqs[mod.joint] == 4  # a planar joint
