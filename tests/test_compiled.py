"""The compiled loop does what the step-by-step path does, and its dynamics are Pinocchio's ABA."""

import numpy as np
import pinocchio as pin
import pytest

import spotsim
from conftest import ROOT
from spotsim import compiled
from spotsim.bodies import free_bodies, free_body_accelerations

#: Newton-Euler per body and Pinocchio's ABA sum the same terms in another order.
ABA_RTOL = 1e-13


@pytest.mark.parametrize("gravity", [(0.0, 0.0, 0.0), (0.3, -9.81, 2.0)])
def test_free_body_dynamics_is_pinocchios_aba(gravity):
    """On random states and wrenches of the dual-arm scene (robot and two modules, each a free
    body), the compiled dynamics give Pinocchio's ABA accelerations."""
    s = spotsim.load_scenario(ROOT / "config" / "dual_arm_sequential.yaml")
    model = spotsim.build_model(spotsim.replace(s, simulation={"gravity_m_s2": gravity}))
    m = model.pin_model
    d = m.createData()
    rng = np.random.default_rng(5)
    for _ in range(100):
        q = pin.randomConfiguration(m, -np.ones(m.nq), np.ones(m.nq))
        v = rng.normal(scale=2.0, size=m.nv)
        f_local = rng.normal(scale=30.0, size=(m.njoints, 6))
        f_ext = pin.StdVec_Force()
        for w in f_local:
            f_ext.append(pin.Force(w))
        expected = pin.aba(m, d, q, v, np.zeros(m.nv), f_ext)
        got = free_body_accelerations(model.bodies, q, v, f_local, m.gravity.linear.copy())
        assert np.abs(got - expected).max() <= ABA_RTOL * np.abs(expected).max()


def _same_dynamics_as_compiled(monkeypatch):
    """Make the step-by-step path's ABA the compiled loop's, so that the two paths must agree
    to the last bit: any difference is then a difference in what the loop does."""
    def aba(m, d, q, v, tau, f_ext):
        f_local = np.array([f.vector for f in f_ext])
        return free_body_accelerations(free_bodies(m), q, v, f_local, m.gravity.linear.copy())

    monkeypatch.setattr(pin, "aba", aba)


@pytest.mark.parametrize("config, duration", [("single_arm_case_I.yaml", 0.8), ("dual_arm_sequential.yaml", 3.0)])
def test_compiled_loop_takes_exactly_the_steps_of_the_python_path(config, duration, monkeypatch):
    """Case I through its self-centring, and the dual-arm run through both grasps and the weld:
    the compiled loop and the step-by-step path record identical runs."""
    s = spotsim.load_scenario(ROOT / "config" / config)
    s = spotsim.replace(s, simulation={"duration_s": duration})
    _same_dynamics_as_compiled(monkeypatch)
    fast = spotsim.simulate(s)
    monkeypatch.setattr(compiled, "applies", lambda model, integrator: False)
    slow = spotsim.simulate(s)
    assert fast.summary["steps"] == slow.summary["steps"] > 1000
    assert fast.summary["pair_steps"] == slow.summary["pair_steps"] > 1000
    for key, series in slow.timeseries.items():
        assert np.array_equal(fast.timeseries[key], series), key
    assert fast.summary["grasps"] == slow.summary["grasps"]
    assert fast.summary["status"] == slow.summary["status"]
    assert fast.summary["momentum"] == slow.summary["momentum"]
    assert fast.summary["free_flight_steps"] == slow.summary["free_flight_steps"]
    for key, array in slow.replay.items():
        assert np.array_equal(fast.replay[key], array), key


@pytest.mark.parametrize("config, changes, cause", [
    ("dual_arm_sequential.yaml", {"simulation": {"substeps": 1}}, "while the drive held"),
    ("single_arm_case_I.yaml", {"simulation": {"substeps": 1}}, "the finger drives did"),
    ("single_arm_case_I.yaml", {"end_effector": {"closing_speed_m_s": 2.0}}, "exceeds the sphere radius")])
def test_compiled_loop_detects_divergence_as_the_python_path_does(config, changes, cause, monkeypatch):
    """Runs that diverge: the paper's setting (symplectic Euler at 1 ms) by energy growth in a
    passive phase (dual arm) and by more energy than the drives put in (Case I), and fingers
    closing at 2 m/s by penetration. Both paths stop at the same step with the same message
    and record (the last record kept after an energy check)."""
    s = spotsim.replace(spotsim.load_scenario(ROOT / "config" / config), **changes)
    _same_dynamics_as_compiled(monkeypatch)
    fast = spotsim.simulate(s)
    monkeypatch.setattr(compiled, "applies", lambda model, integrator: False)
    slow = spotsim.simulate(s)
    assert fast.status == slow.status == "diverged" and cause in fast.summary["message"]
    assert fast.summary["message"] == slow.summary["message"]
    assert fast.summary["steps"] == slow.summary["steps"]
    for key, series in slow.timeseries.items():
        assert np.array_equal(fast.timeseries[key], series), key
    assert fast.summary["momentum"] == slow.summary["momentum"]
