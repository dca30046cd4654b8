"""A run's discretisation error estimate: its companion, its arithmetic, and the CLI's summary."""

import csv
import json

import pytest
from conftest import ROOT

import spotsim
from spotsim.cli import main
from spotsim.studies import ensemble as ensemble_module
from spotsim.studies import estimate as estimate_module
from spotsim.studies.accuracy import parse_setting
from spotsim.studies.estimate import (
    MIN_SPREAD_COUNT,
    QUANTITIES,
    companion,
    error_estimate,
    quantities,
    study_spread,
    typical_spread,
    typical_spreads,
    validate,
    validation_table,
)


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


def stats(low, high, count=MIN_SPREAD_COUNT):
    return {"median": (low + high) / 2, "p10": low, "p90": high, "min": low, "max": high, "count": count}


def test_the_bound_adds_the_chance_range_over_starts_to_the_uncertainty():
    """With a spread over starts, each quantity's chance range is its largest minus its
    smallest value and the bound is the uncertainty plus it; a quantity the spread lacks, or a
    run without a spread, has neither."""
    run = summary(grasp(0.15, 50.0, 2.0), grasp(0.05, 80.0, 9.0))
    other = summary(grasp(0.12, 51.0, 1.9), grasp(0.06, 78.0, 9.5))
    spread = {"source": "ensemble", "about": "test",
              "grasps": {"grasp_1": {"peak_force_norm_N": stats(45.0, 55.0), "residual_norm_mm": stats(0.1, 0.2)},
                         "grasp_2": {}}}
    first, second = error_estimate(run, other, spread)["grasps"]
    force = first["peak_force_norm_N"]
    assert force["chance"] == 10.0 and force["bound"] == 3.0 + 10.0 and force["spread"]["p90"] == 55.0
    assert first["residual_offset_norm_mm"]["bound"] == pytest.approx(3 * 0.03 + 0.1, abs=1e-15)
    assert first["peak_torque_norm_Nm"]["bound"] is None and first["peak_torque_norm_Nm"]["chance"] is None
    assert all(q["bound"] is None for q in second.values())
    alone = error_estimate(run, other)
    assert alone["spread"]["source"] is None and alone["grasps"][0]["peak_force_norm_N"]["bound"] is None
    few = {"source": "ensemble", "about": "test",
           "grasps": {"grasp_1": {"peak_force_norm_N": stats(45.0, 55.0, MIN_SPREAD_COUNT - 1)}}}
    assert error_estimate(run, other, few)["grasps"][0]["peak_force_norm_N"]["bound"] is None  # too few runs


class FakeMember:
    def __init__(self, index, force):
        self.index, self.summary = index, summary(grasp(0.1, force, 2.0))


def test_validation_runs_perturbed_starts_of_its_own_seed_and_counts_the_bound(case_I, monkeypatch):
    """`validate` asks each ensemble for n + 1 members of its seed and drops member 0 (the
    unperturbed start, which every seed shares), and counts a true error within the bound
    (uncertainty + chance range) of the scenario's typical spread."""
    calls = []
    forces = {"run": 50.0, "companion": 51.0, "reference": 60.0}  # estimate 1, uncertainty 3, error 10

    def fake_ensemble(scenario, n, seed, workers, progress):
        integrator = scenario.simulation.integrator
        kind = ("reference" if integrator.method != "adaptive_euler" else
                "companion" if integrator.velocity_tol_m_s != case_I.simulation.integrator.velocity_tol_m_s else "run")
        calls.append((kind, n, seed))
        return type("E", (), {"members": [FakeMember(i, forces[kind]) for i in range(n)]})()

    monkeypatch.setattr(ensemble_module, "ensemble", fake_ensemble)
    spread = {"source": "study", "about": "test", "grasps": {"grasp": {"peak_force_norm_N": stats(45.0, 53.0)}}}
    monkeypatch.setattr(estimate_module, "typical_spread", lambda s: spread)
    rows = validate(case_I, parse_setting("symplectic_euler:20").apply(case_I), 3, seed=5)
    assert sorted(calls) == [("companion", 4, 5), ("reference", 4, 5), ("run", 4, 5)]
    force = [r for r in rows if r["quantity"] == "peak_force_norm_N"]
    assert [r["member"] for r in force] == [1, 2, 3]
    assert all(r["bound"] == 3.0 + 8.0 and r["error"] == 10.0 and r["within_bound"] for r in force)
    assert not any(r["within_uncertainty"] for r in force)
    table = {q["quantity"]: q for q in validation_table(rows)}
    assert (table["peak_force_norm_N"]["within_bound"], table["peak_force_norm_N"]["bounded"]) == (3, 3)
    assert table["peak_torque_norm_Nm"]["within_bound"] is None  # the spread lacks it: no bound


def test_a_study_spread_pools_the_run_setting_and_the_reference(case_I):
    """`study_spread` takes each quantity's statistics over the members at both settings
    together, leaving out the interrupted ones."""
    def row(status, force):
        return {"member": 0, "status": status, "peak_force_norm_N": force, "residual_norm_mm": None}

    spread = study_spread(case_I, [row("completed", 50.0), row("completed", 60.0)],
                          [row("completed", 40.0), row("interrupted", 99.0)], "test")
    force = spread["grasps"]["grasp"]["peak_force_norm_N"]
    assert (force["min"], force["max"], force["count"]) == (40.0, 60.0, 3)
    assert spread["grasps"]["grasp"]["residual_norm_mm"]["count"] == 0


@pytest.mark.parametrize("name", ["single_arm_case_I", "single_arm_case_II", "single_arm_case_III",
                                  "dual_arm_sequential"])
def test_each_studied_config_finds_its_typical_spread(name):
    """The shipped typical spreads belong to the shipped configs as they are: each studied
    config finds its own (its name and description aside), over both ensembles' members;
    the same scenario at another setting finds none."""
    scenario = spotsim.load_scenario(ROOT / "config" / f"{name}.yaml")
    spread = typical_spread(scenario)
    assert spread is not None and spread["scenario"] == name
    assert typical_spread(spotsim.replace(scenario, name="renamed", description="other words")) == spread
    assert typical_spread(parse_setting("symplectic_euler:20").apply(scenario)) is None
    assert typical_spread(spotsim.replace(scenario, simulation={"integrator": {"kick": "step"}})) is None
    for by in spread["grasps"].values():
        for column in ("residual_norm_mm", "peak_force_norm_N", "peak_torque_norm_Nm"):
            assert by[column]["count"] == 64 and by[column]["min"] <= by[column]["p10"] <= by[column]["max"]
    assert name in {s["scenario"] for s in typical_spreads().values()}
    dual = len(spread["grasps"]) == 2
    run = summary(*[grasp(0.01, 100.0, 5.0, centroid=[0.5, 0.0, 0.0] if dual else None)] * (2 if dual else 1))
    for entry in error_estimate(run, run, spread)["grasps"]:  # every estimated quantity gets its bound
        assert set(entry) == set(QUANTITIES) if dual else set(entry) == set(QUANTITIES) - {
            "robot_centroid_displacement_norm_mm"}
        assert all(q["bound"] is not None and q["bound"] == q["chance"] > 0 for q in entry.values())


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
    against the reference and whether it lies within the estimate; a scenario no study has seen
    (here a shortened run) takes each start's own spread, as `spotsim run` does, and its bound."""
    out = tmp_path / "est"
    code = main(["study", "estimate", "--members", "2", "--workers", "1", "--reference", "symplectic_euler:20",
                 "--duration", "1.5", "--quiet", "--out", str(out)])
    assert code == 0
    rows = list(csv.DictReader((out / "estimate.csv").open()))
    assert {r["member"] for r in rows} == {"1", "2"}  # perturbed starts only: member 0 is every seed's
    for r in rows:
        if r["error"]:
            error, estimate = float(r["error"]), float(r["estimate"])
            assert error == pytest.approx(abs(float(r["value"]) - float(r["reference"])), abs=1e-12)
            assert (r["within"] == "True") == (error <= estimate)
            assert float(r["uncertainty"]) == pytest.approx(3 * estimate, rel=1e-15)
            assert r["spread"] == "starts"  # a shortened run is not the studied scenario
            assert float(r["bound"]) == pytest.approx(float(r["uncertainty"]) + float(r["chance"]), rel=1e-12)
            assert (r["within_bound"] == "True") == (error <= float(r["bound"]))
    text = capsys.readouterr().out
    assert "error within the estimate for" in text and "within the bound for" in text


def test_a_run_takes_the_studys_spread_where_there_is_one_else_its_ensembles(case_I, monkeypatch):
    """`estimate` gives a studied scenario the study's spread (64 runs, validated), another
    scenario its ensemble's, and a lone run of another scenario the spread around its own
    start if it completed (none when told so, or when it did not complete)."""
    import spotsim.run as run_module

    monkeypatch.setattr(run_module, "simulate", lambda s, source: type("R", (), {"summary": summary(grasp(0.1))})())
    ens = type("E", (), {"members": [None] * 20, "seed": 0,
                         "statistics": {"grasp": {"peak_force_norm_N": stats(40.0, 50.0, 20)}}})()
    other = spotsim.replace(case_I, end_effector={"closing_speed_m_s": 0.02})
    assert estimate_module.estimate(case_I, summary(grasp(0.1)), ensemble=ens)["spread"]["source"] == "study"
    mine = estimate_module.estimate(other, summary(grasp(0.1)), ensemble=ens)
    assert mine["spread"]["source"] == "ensemble" and mine["grasps"][0]["peak_force_norm_N"]["chance"] == 10.0
    measured = []

    def around(scenario, members, **_):
        measured.append((scenario, members))
        return {"source": "starts", "about": "", "grasps": {"grasp": {"peak_force_norm_N": stats(45.0, 48.0, 16)}}}

    monkeypatch.setattr(estimate_module, "start_spread", around)
    lone = estimate_module.estimate(other, summary(grasp(0.1)))
    assert lone["spread"]["source"] == "starts" and lone["grasps"][0]["peak_force_norm_N"]["chance"] == 3.0
    assert measured == [(other, estimate_module.SPREAD_MEMBERS)]
    told = estimate_module.estimate(other, summary(grasp(0.1)), spread_members=0)
    assert told["spread"]["source"] is None and "--spread-members 0" in told["spread"]["about"]
    unfinished = {**summary(grasp(0.1)), "status": "incomplete"}
    assert "ended incomplete" in estimate_module.estimate(other, unfinished)["spread"]["about"]
    assert len(measured) == 1


def test_the_shipped_spreads_are_what_the_library_collects_from_the_studies(tmp_path):
    """`spotsim study spreads` over the ensemble accuracy studies in docs/results/ gives the
    package's typical spreads, statistic for statistic, each with its provenance."""
    from conftest import ROOT

    studies = [f"{name}={ROOT / 'docs/results/accuracy_ensemble' / name}" for name in
               ("single_arm_case_I", "single_arm_case_II", "single_arm_case_III", "dual_arm_sequential")]
    out = tmp_path / "spreads.json"
    assert main(["study", "spreads", *studies, "--out", str(out)]) == 0
    made = json.loads(out.read_text())["scenarios"]
    shipped = estimate_module.typical_spreads()
    assert set(made) == set(shipped)
    for key, entry in made.items():
        assert entry["grasps"] == shipped[key]["grasps"]
        assert entry["provenance"]["fingerprint"] == key and entry["provenance"]["members"] == [32, 32]
    assert main(["study", "spreads", f"single_arm_case_I={tmp_path}", "--out", str(out)]) == 2
