"""The recorder's compiled frames and angles are Pinocchio's."""

import numpy as np
import pinocchio as pin
import pytest
from conftest import ROOT

import spotsim
from spotsim.assemble.model import grasp_frame, groove_frame
from spotsim.sim.data import make_data
from spotsim.sim.events import NONFINITE
from spotsim.sim.record import close_interval, quat_xyzw, rpy, sample

#: The compiled kinematics compose the same products as Pinocchio's in another order.
FRAME_TOL = 1e-12
#: Roll-pitch-yaw is compared away from pitch = +-90 deg (|R[2, 0]| = 1), where roll and yaw
#: are not unique and the two formulas may split them differently.
GIMBAL_MARGIN = 1e-6


def test_quaternion_and_rpy_are_pinocchios():
    """On random rotations (and the four branches of the quaternion's extraction), the
    quaternion is pin.SE3ToXYZQUAT's, sign included, and roll-pitch-yaw pin.rpy.matrixToRpy's."""
    rotations = [pin.SE3.Random().rotation for _ in range(300)]
    rotations += [pin.rpy.rpyToMatrix(*a) for a in ([np.pi, 0, 0], [0, np.pi - 0.1, 0], [0, 0, np.pi - 0.1])]
    for R in rotations:
        R = np.ascontiguousarray(R)
        expected = pin.SE3ToXYZQUAT(pin.SE3(R, np.zeros(3)))[3:]
        quat = np.empty(4)
        quat_xyzw(R, quat)
        assert np.abs(quat - expected).max() <= FRAME_TOL
        if abs(abs(R[2, 0]) - 1.0) > GIMBAL_MARGIN:
            assert np.abs(np.array(rpy(R)) - pin.rpy.matrixToRpy(R)).max() <= FRAME_TOL


@pytest.fixture(scope="module")
def dual():
    return spotsim.build_model(spotsim.load_scenario(ROOT / "config" / "dual_arm_sequential.yaml"))


def test_recorded_frames_are_pinocchios(dual):
    """On random dual-arm states, a row's module pose, offset in the grasp frame, robot base
    and end-effector frames are those of Pinocchio's forward kinematics."""
    m = dual.pin_model
    d = m.createData()
    layout = dual.layout
    data = make_data(dual)
    data.assign(active=1)
    col = lambda row, name: row[layout.columns[name][0]:sum(layout.columns[name])]
    rng = np.random.default_rng(8)
    for _ in range(50):
        q = pin.randomConfiguration(m, -np.ones(m.nq), np.ones(m.nq))
        v = rng.normal(size=m.nv)
        data.assign(q=q, v=v)
        pin.forwardKinematics(m, d, q, v)
        row = np.full(layout.width, np.nan)
        sample(dual.sim, data, row)
        assert np.isfinite(row).all()
        oMb, oMa = groove_frame(dual, d, 1), grasp_frame(dual, d, 1)
        assert np.abs(col(row, "module_pos_m") - oMb.translation).max() <= FRAME_TOL
        assert np.abs(col(row, "offset_mm") - oMa.actInv(oMb).translation * 1e3).max() <= FRAME_TOL * 1e3
        R_b = oMb.rotation
        assert np.abs(col(row, "module_vel_m_s") - d.oMi[dual.modules[1].joint].rotation
                      @ d.v[dual.modules[1].joint].linear).max() <= FRAME_TOL
        assert np.abs(pin.Quaternion(col(row, "module_quat_xyzw")).matrix() - R_b).max() <= FRAME_TOL
        base = d.oMi[dual.robot_joint]
        assert np.abs(col(row, "base_pos_m") - base.translation).max() <= FRAME_TOL
        for e, ee in enumerate(dual.end_effectors):
            assert np.abs(col(row, f"{ee.name}_pos_m") - grasp_frame(dual, d, e).translation).max() <= FRAME_TOL


def test_a_non_finite_state_is_caught_and_not_recorded(dual):
    """close_interval reports a NaN in v as NONFINITE and writes no row."""
    data = make_data(dual)
    data.v[3] = np.nan
    assert close_interval(dual.sim, data) == NONFINITE
    assert data.n_rows == 0 and not data.rows.any()
