"""Shared fixtures: the shipped scenarios, their models, and states recorded from a real run."""

from __future__ import annotations

from pathlib import Path

import pytest

import spotsim
from spotsim.run import Stepper

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = sorted((ROOT / "config").glob("*.yaml"))
CASE_I = ROOT / "config" / "single_arm_case_I.yaml"


@pytest.fixture(scope="session")
def case_I():
    return spotsim.load_scenario(CASE_I)


@pytest.fixture(scope="session")
def model_I(case_I):
    return spotsim.build_model(case_I)


@pytest.fixture(scope="session")
def recorded_states(model_I):
    """Copies of Case I's Data taken during its self-centring, each with sphere pairs in contact.

    Taken every 10 ms from first contact (~0.43 s) to 0.75 s, while the module bounces and
    slides: the states the culled search must get exactly right.
    """
    stepper = Stepper(model_I)
    h = model_I.scenario.simulation.dt_s / model_I.scenario.simulation.substeps
    states, next_t = [], 0.0
    while stepper.data.t < 0.75:
        stepper.step(h)
        v = stepper.data.view()
        if len(v.contacts.key) and v.t >= next_t:
            states.append(stepper.data.copy())
            next_t = v.t + 0.01
    assert len(states) >= 10
    return states
