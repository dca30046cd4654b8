"""The free-flying dual-arm robot's mass properties against the paper's Table 5."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from spotsim.build import assets
from spotsim.build.robot import DUAL_ARM_XACRO, TABLE5, TABLE6, fit_base, locked_robot

#: The issue's bound on the composite's mass and inertia against Table 5 body 3.
TABLE5_RTOL = 0.01
#: Round-off on a composite's eigenvalues: about 1e-16 of its largest moment (~250 kg m^2 with
#: TM-1 2 m off), ~1e-14 of the 4 kg m^2 bound; this leaves a hundredfold margin.
EIGEN_RTOL = 1e-12


@pytest.fixture(scope="module")
def robot():
    for prefix in TABLE6:
        assets.prefixed_arm("ur3", prefix)
    model, j = locked_robot(assets.compile_xacro(DUAL_ARM_XACRO, {}))
    return model.inertias[j]


def test_robot_with_locked_arms_is_table_5_body_3(robot):
    """Arms locked at Table 6's angles, the robot has body 3's mass and inertia about its centroid."""
    target = TABLE5[3]
    assert robot.mass == pytest.approx(target.mass, rel=TABLE5_RTOL)
    assert np.diag(robot.inertia) == pytest.approx(target.inertia, rel=TABLE5_RTOL)


def test_xacro_base_defaults_are_the_fitted_base():
    """The base mass and inertia written in the XACRO are what fit_base computes (6 digits)."""
    fitted = fit_base()
    defaults = assets.xacro_arg_defaults(DUAL_ARM_XACRO)
    for key, value in fitted.items():
        assert defaults[key] == pytest.approx(value, rel=1e-5, abs=1e-6)


def test_table_6_angles_are_within_the_ur3_limits():
    """The paper's joint states are valid UR3 configurations (the reason for the arm choice)."""
    import pinocchio as pin

    m = pin.buildModelFromUrdf(str(assets.example_robot_data_dir() / assets.ARM_URDFS["ur3"]))
    for angles in TABLE6.values():
        q = np.array(angles)
        assert np.all(q >= m.lowerPositionLimit) and np.all(q <= m.upperPositionLimit)


@settings(max_examples=200, deadline=None)
@given(offset=st.tuples(*[st.floats(-2.0, 2.0)] * 3),
       angles=st.tuples(*[st.floats(-np.pi, np.pi)] * 3))
def test_no_placement_of_tm1_gives_table_5_body_4_as_principal_moments(offset, angles):
    """Rigidly joined anywhere, in any orientation, FDR (body 3) and TM-1 (body 1) have, about
    the line through their centroids, only their own moments: the parallel-axis term adds none
    about it. So the composite's smallest principal moment is at most body 3's largest plus
    body 1's largest (4.094 kg m^2), below every moment Table 5 gives body 4 (8.039 least)."""
    import pinocchio as pin

    body3 = pin.Inertia(TABLE5[3].mass, np.zeros(3), np.diag(TABLE5[3].inertia))
    R = pin.rpy.rpyToMatrix(*angles)
    body1 = pin.Inertia(TABLE5[1].mass, np.array(offset), R @ np.diag(TABLE5[1].inertia) @ R.T)
    both = body3 + body1
    bound = max(TABLE5[3].inertia) + max(TABLE5[1].inertia)
    assert np.linalg.eigvalsh(both.inertia).min() <= bound * (1 + EIGEN_RTOL)
    assert bound < min(TABLE5[4].inertia)
