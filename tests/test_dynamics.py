"""The compiled dynamics are Pinocchio's: free-body ABA against `pin.aba` on the scenes' models."""

import numpy as np
import pinocchio as pin
import pytest
from conftest import ROOT

import spotsim
from spotsim.sim.bodies import kinematics
from spotsim.sim.data import make_data
from spotsim.sim.dynamics import accelerations

#: Newton-Euler per body and Pinocchio's ABA sum the same terms in another order.
ABA_RTOL = 1e-13


@pytest.mark.parametrize("config, overrides", [("dual_arm_sequential.yaml", []), ("single_arm_case_I.yaml", []),
                                               ("dual_arm_sequential.yaml", ["testbed.mount=air_bearing"])])
@pytest.mark.parametrize("gravity", [(0.0, 0.0, 0.0), (0.3, -9.81, 2.0)])
def test_free_body_dynamics_is_pinocchios_aba(config, overrides, gravity):
    """On random states and wrenches of a scene (the dual arm: robot and two modules, each a
    free body, in space or on the testbed's planar joints; Case I: one module), the compiled
    accelerations are Pinocchio's ABA."""
    s = spotsim.load_scenario(ROOT / "config" / config, overrides)
    model = spotsim.build_model(spotsim.replace(s, simulation={"gravity_m_s2": gravity}))
    m = model.pin_model
    pd = m.createData()
    data = make_data(model)
    rng = np.random.default_rng(5)
    for _ in range(50):
        q = pin.randomConfiguration(m, -np.ones(m.nq), np.ones(m.nq))
        v = rng.normal(scale=2.0, size=m.nv)
        f_local = rng.normal(scale=30.0, size=(m.njoints, 6))
        data.assign(q=q, v=v, loads=data.loads._replace(f_local=f_local))
        kinematics(model.sim, data)
        accelerations(model.sim, data)
        f_ext = pin.StdVec_Force()
        for w in f_local:
            f_ext.append(pin.Force(w))
        expected = pin.aba(m, pd, q, v, np.zeros(m.nv), f_ext)
        assert np.abs(data.a - expected).max() <= ABA_RTOL * np.abs(expected).max()
