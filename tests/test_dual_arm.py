"""The free-floating dual-arm robot grasping TM-1 then TM-2 (paper Sec. 5)."""

import numpy as np
import pytest
from conftest import ROOT

import spotsim
from spotsim.status import SEATED, grasp_outcome

DUAL = ROOT / "config" / "dual_arm_sequential.yaml"
#: The issue's bound on total linear momentum drift, relative to the largest body momentum.
LINEAR_MOMENTUM_BOUND = 1e-9
#: The system centroid moves only by round-off: 1 nm over the run is a thousand times that.
CENTROID_BOUND_M = 1e-9
#: Paper's FDR centroid displacements, mm (Sec. 5.1).
PAPER_FIRST, PAPER_SECOND = np.array([-0.637, -0.582, 0.146]), np.array([-0.173, 0.306, -0.05])
#: The paper gives neither its robot's geometry nor its modules' placement: spotsim's
#: displacement magnitudes are held to the paper's within a factor of five, no tighter.
MAGNITUDE_BAND = 5.0
#: Halving dt halves a first-order error; the stick-slip path itself shifts a little with dt,
#: so the measured ratio (2.09) is held to 2 within +25 % / -20 %.
FIRST_ORDER_RATIO = (1.6, 2.5)
#: The negative control must break angular momentum by orders of magnitude, not by noise.
NEGATIVE_CONTROL_FACTOR = 1000
#: The first grasp starts where TM-1 was placed: its offset is recorded exactly, up to round-off.
ROUND_OFF_MM = 1e-9
#: The first grasp shoves the robot by about a millimetre (paper: 0.875 mm): the second grasp's
#: start moves by more than a micrometre and less than the fingers' 10 mm reach into the mouth.
START_CHANGE_MM = (1e-3, 10.0)


@pytest.fixture(scope="module")
def run():
    return spotsim.simulate(spotsim.load_scenario(DUAL))


@pytest.fixture(scope="module")
def window():
    """The first 0.6 s (TM-1's first impacts) with each setting a test compares."""
    base = spotsim.load_scenario(DUAL)

    def simulate(**changes):
        s = spotsim.replace(base, simulation={"duration_s": 0.6, **changes.get("simulation", {})},
                            contact=changes.get("contact", {}))
        return spotsim.simulate(s).summary["momentum"]
    return simulate


@pytest.mark.slow
def test_both_grasps_complete_with_sub_millimetre_offsets(run):
    """EE-1 grasps TM-1, the weld happens once, EE-2 grasps TM-2; both end seated (within the
    classes' offset and tilt) with both fingers in their grooves."""
    assert run.status == "completed", run.summary["message"]
    assert len(run.summary["welds_s"]) == 1
    assert [grasp_outcome(run.status, g) for g in run.summary["grasps"]] == [SEATED, SEATED]
    assert all(g["in_grooves"] for g in run.summary["grasps"])


@pytest.mark.slow
def test_total_linear_momentum_is_conserved(run):
    """Contact forces are pairwise and the centroids advance in world: momentum stays put,
    with the default drive (the motor, whose screw's force and stopping impulses on the fingers
    are internal)."""
    assert run.summary["drive"] == "motor"
    assert run.summary["momentum"]["linear_drift_rel"] <= LINEAR_MOMENTUM_BOUND


@pytest.mark.slow
def test_system_centroid_stays_put(run):
    """Starting at rest, the centroid of robot + modules does not move, weld included."""
    c = run.timeseries["system_centroid_m"]
    assert np.abs(c - c[0]).max() <= CENTROID_BOUND_M


def test_the_first_grasp_moves_ee2_against_tm2_before_the_second_starts(run):
    """Each grasp's start offset is recorded: the first grasp's is TM-1's configured start; the
    second's is TM-2's configured start moved by what the first grasp did to the robot (the
    paper's Sec. 5.2 explanation of the SPOT trends), by a fraction of a millimetre."""
    first, second = run.summary["grasps"]
    assert np.allclose(first["start_offset_change_mm"], 0.0, atol=ROUND_OFF_MM)
    change = np.linalg.norm(second["start_offset_change_mm"])
    assert START_CHANGE_MM[0] < change < START_CHANGE_MM[1], change
    tm2 = spotsim.load_scenario(DUAL).tm2.initial_offset_mm
    assert np.allclose(np.subtract(second["start_offset_mm"], tm2), second["start_offset_change_mm"])


@pytest.mark.slow
def test_second_grasp_disturbs_the_robot_less(run):
    """The heavier composite (the robot with TM-1 welded to it) moves less in the second grasp.
    Its peaks are not asserted: nothing in the physics orders them (at the default the second
    grasp's peak force is the higher over 32 perturbed starts, 287-309 N against 256-266 N,
    10th-90th percentiles, docs/validation.md)."""
    first, second = run.summary["grasps"]
    d1, d2 = (np.linalg.norm(g["robot_centroid_displacement_mm"]) for g in (first, second))
    assert d2 < d1


@pytest.mark.slow
def test_centroid_displacements_within_the_stated_band_of_the_paper(run):
    """Each grasp's robot centroid displacement is within a factor of five of the paper's."""
    for g, paper in zip(run.summary["grasps"], (PAPER_FIRST, PAPER_SECOND), strict=True):
        ratio = np.linalg.norm(g["robot_centroid_displacement_mm"]) / np.linalg.norm(paper)
        assert 1 / MAGNITUDE_BAND <= ratio <= MAGNITUDE_BAND


@pytest.mark.slow
def test_angular_momentum_error_halves_with_the_step(window):
    """Symplectic Euler is first order in rotation: halving dt halves the angular drift."""
    euler = {"method": "symplectic_euler"}
    coarse = window(simulation={"substeps": 10, "integrator": euler})["angular_drift_rel"]
    fine = window(simulation={"substeps": 20, "integrator": euler})["angular_drift_rel"]
    assert FIRST_ORDER_RATIO[0] <= coarse / fine <= FIRST_ORDER_RATIO[1]


@pytest.mark.slow
def test_forces_at_sphere_centres_break_angular_momentum(window):
    """Negative control: each body's force at its own sphere centre, not one common point,
    leaves a torque imbalance that shows up a thousandfold in angular momentum."""
    common = window()["angular_drift_rel"]
    centres = window(contact={"force_point": "sphere_centres"})["angular_drift_rel"]
    assert centres > NEGATIVE_CONTROL_FACTOR * common
