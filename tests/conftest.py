"""Shared fixtures: the shipped scenarios, their models, and states recorded from a real run."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest

import spotsim
from spotsim.integrators import make_integrator
from spotsim.step import make_data, step

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
    """Snapshots of Data taken during Case I's self-centring, each with sphere pairs in contact.

    Taken every 10 ms from first contact (~0.43 s) to 0.75 s, while the module bounces and
    slides: the states the culled search must get exactly right.
    """
    data = make_data(model_I)
    integrator = make_integrator("symplectic_euler", model_I.pin_model)
    h = model_I.scenario.simulation.dt_s / model_I.scenario.simulation.substeps
    states, next_t = [], 0.0
    while data.t < 0.75:
        c = step(model_I, data, h, integrator)
        if len(c.key) and data.t >= next_t:
            states.append(_snapshot(data))
            next_t = data.t + 0.01
    assert len(states) >= 10
    return states


def _snapshot(data):
    """A copy of the parts of Data a contact evaluation reads and writes."""
    snap = copy.copy(data)
    snap.q, snap.v = data.q.copy(), data.v.copy()
    snap.pin_data = data.pin_data.copy()
    snap.R_W, snap.p_W, snap.w_W, snap.vo_W = (a.copy() for a in (data.R_W, data.p_W, data.w_W, data.vo_W))
    snap.mem_key, snap.mem_s, snap.mem_vminus = data.mem_key.copy(), data.mem_s.copy(), data.mem_vminus.copy()
    snap.finger_load = data.finger_load.copy()
    return snap


def restore(snap):
    """A fresh working copy of a snapshot, so each evaluation starts from the same memory."""
    return _snapshot(snap)
