"""A run's discretisation error estimate: its companion, its arithmetic, and the CLI's summary."""

import csv
import json

import pytest

import spotsim
from spotsim.cli import main
from spotsim.studies.estimate import QUANTITIES, companion, error_estimate, quantities


def test_companion_takes_steps_twice_as_long(case_I):
    """adaptive_euler: 4x the velocity tolerance (steps ~ tol^(1/2)) and 2x the onset depth;
    symplectic_euler: half the substeps; none where the integrator cannot offer it."""
    i = case_I.simulation.integrator
    c = companion(case_I)
    assert c.simulation.integrator.method == i.method == "adaptive_euler"
    assert c.simulation.integrator.velocity_tol_m_s == 4 * i.velocity_tol_m_s
    assert c.simulation.integrator.onset_depth_m == 2 * i.onset_depth_m
    fixed = spotsim.replace(case_I, simulation={"substeps": 10, "integrator": {"method": "symplectic_euler"}})
    assert companion(fixed).simulation.substeps == 5
    assert companion(spotsim.replace(fixed, simulation={"substeps": 5})) is None
    assert companion(spotsim.replace(case_I, simulation={"integrator": {"method": "rk4"}})) is None


def grasp(residual=None, force=50.0, torque=2.0, centroid=None, done=True):
    g = {"completed_s": 1.0 if done else None, "residual_offset_norm_mm": residual, "peak_force_norm_N": force,
         "peak_torque_norm_Nm": torque}
    if centroid is not None:
        g["robot_centroid_displacement_mm"] = centroid
    return g


def summary(*grasps):
    return {"grasps": list(grasps), "status": "completed", "integrator": {"method": "adaptive_euler"},
            "wall_time_s": 0.1}


def test_estimate_is_the_difference_to_the_companion():
    """Each quantity's estimate is |run - companion|; a grasp the companion did not complete
    has none; the centroid displacement is estimated on a free-floating robot only."""
    run = summary(grasp(0.15, 50.0, 2.0), grasp(0.05, 80.0, 9.0, centroid=[0.3, 0.4, 0.0]))
    other = summary(grasp(0.12, 51.0, 1.9), grasp(done=False, centroid=[0.0, 0.0, 0.0]))
    e = error_estimate(run, other)
    first, second = e["grasps"]
    assert first["residual_offset_norm_mm"]["estimate"] == pytest.approx(0.03, abs=1e-15)
    assert first["peak_force_norm_N"]["estimate"] == 1.0 and first["peak_force_norm_N"]["estimate_rel"] == 0.02
    assert first["peak_force_norm_N"]["uncertainty"] == 3.0  # Roache's GCI from two steps
    assert first["residual_offset_norm_mm"]["distribution"] and not first["peak_force_norm_N"]["distribution"]
    assert "robot_centroid_displacement_norm_mm" not in first
    assert second["robot_centroid_displacement_norm_mm"]["value"] == pytest.approx(0.5, abs=1e-15)
    assert all(q["estimate"] is None for q in second.values())
    assert set(quantities(run)[1]) == set(QUANTITIES)


def test_no_companion_is_said_not_estimated():
    """An integrator without a companion gets a note, not numbers."""
    e = error_estimate(summary(grasp(0.1)), None)
    assert e["companion"] is None and "not estimated" in e["note"]


def test_run_writes_its_error_estimate_unless_told_not_to(tmp_path):
    """`spotsim run` puts the estimate in summary.json; --no-error-estimate leaves it out."""
    out = tmp_path / "a"
    args = ["run", "--out", str(out), "--quiet", "--no-figures", "--set", "simulation.duration_s=0.5"]
    assert main(args) == 3
    entry = json.loads((out / "summary.json").read_text())["error_estimate"]
    assert entry["companion"]["status"] == "incomplete"
    assert entry["grasps"][0]["peak_force_norm_N"]["estimate"] is None  # incomplete: nothing to compare
    out = tmp_path / "b"
    assert main([*args[:2], str(out), *args[3:], "--no-error-estimate"]) == 3
    assert "error_estimate" not in json.loads((out / "summary.json").read_text())


def test_estimate_study_compares_each_start_with_the_reference(tmp_path, capsys):
    """`spotsim study estimate` writes a row per start, grasp and quantity with the true error
    against the reference and whether it lies within the estimate."""
    out = tmp_path / "est"
    code = main(["study", "estimate", "--members", "2", "--workers", "1", "--reference", "symplectic_euler:20",
                 "--duration", "1.5", "--quiet", "--out", str(out)])
    assert code == 0
    rows = list(csv.DictReader((out / "estimate.csv").open()))
    assert {r["member"] for r in rows} == {"0", "1"}
    for r in rows:
        if r["error"]:
            error, estimate = float(r["error"]), float(r["estimate"])
            assert error == pytest.approx(abs(float(r["value"]) - float(r["reference"])), abs=1e-12)
            assert (r["within"] == "True") == (error <= estimate)
            assert float(r["uncertainty"]) == pytest.approx(3 * estimate, rel=1e-15)
    assert "error within the estimate for" in capsys.readouterr().out
