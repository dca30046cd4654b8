"""The free-flying dual-arm robot's mass properties against the paper's Table 5."""

import numpy as np
import pytest

from spotsim.build import assets
from spotsim.build.robot import DUAL_ARM_XACRO, TABLE5, TABLE6, fit_base, locked_robot

#: The issue's bound on the composite's mass and inertia against Table 5 body 3.
TABLE5_RTOL = 0.01


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
