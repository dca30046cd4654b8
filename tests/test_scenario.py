"""Strict scenarios: every shipped config validates; broken ones fail with one clear line each."""

import subprocess
import sys

import pytest
import yaml
from conftest import CASE_I, CONFIGS

import spotsim
from spotsim.assemble.scene import xacro_defaults_agree
from spotsim.cli import main
from spotsim.scenario import Geometry, from_dict, to_dict


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_every_shipped_config_validates(path, capsys):
    """`spotsim validate` accepts each YAML in config/ and prints a scenario that reloads equal."""
    assert main(["validate", str(path)]) == 0
    printed = capsys.readouterr().out
    assert from_dict(yaml.safe_load(printed)) == spotsim.load_scenario(path)


def merged(change):
    raw = yaml.safe_load(CASE_I.read_text())
    for section, values in change.items():
        raw[section] = {**raw.get(section, {}), **values}
    return raw


def test_missing_key_is_reported(tmp_path, capsys):
    """A required key left out is named in the error."""
    raw = yaml.safe_load(CASE_I.read_text())
    del raw["end_effector"]["closing_speed_m_s"]
    path = tmp_path / "missing.yaml"
    path.write_text(yaml.safe_dump(raw))
    assert main(["validate", str(path)]) == 2
    assert "end_effector.closing_speed_m_s = (missing): required key" in capsys.readouterr().err


def test_all_problems_are_reported_in_one_pass(tmp_path, capsys):
    """Several problems in one file are all listed, each on its own line."""
    raw = merged({"contact": {"restitution": 2.0, "bogus": 1}, "module": {"mass_kg": -1}})
    path = tmp_path / "many.yaml"
    path.write_text(yaml.safe_dump(raw))
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert all(s in err for s in ("contact.restitution", "contact.bogus", "module.mass_kg"))


def test_set_overrides_are_validated_like_the_file(capsys):
    """`--set` changes a key with the same validation as the file."""
    assert main(["validate", str(CASE_I), "--set", "contact.restitution=0.5"]) == 0
    assert yaml.safe_load(capsys.readouterr().out)["contact"]["restitution"] == 0.5
    assert main(["validate", str(CASE_I), "--set", "contact.restitution=-1"]) == 2
    assert "contact.restitution = -1: must be in (0, 1]" in capsys.readouterr().err
    assert main(["validate", str(CASE_I), "--set", "contact.nonsense=1"]) == 2


def test_misalignment_outside_the_tolerance_warns_but_validates(capsys):
    """An initial offset beyond +-10 mm is a warning, not an error: studies go there on purpose."""
    assert main(["validate", str(CASE_I), "--set", "module.initial_offset_mm=[0, -11, 0]",
                 "--set", "end_effector.start_gap_mm=20"]) == 0
    assert "outside the claimed +-10.0 mm tolerance" in capsys.readouterr().err


def test_cli_reports_bad_input_without_a_traceback(tmp_path):
    """The installed command exits 2 on a bad file and prints no traceback."""
    path = tmp_path / "bad.yaml"
    path.write_text("name: x\nsimulation: [1, 2]\n")
    proc = subprocess.run([sys.executable, "-m", "spotsim.cli", "validate", str(path)],
                          capture_output=True, text=True)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "simulation = [1, 2]: must be a mapping" in proc.stderr


def test_numbers_in_exponent_form_are_numbers_in_files_and_overrides(tmp_path):
    """1e-6 and 2e0 are numbers, as YAML 1.2 reads them (YAML 1.1 reads them as strings)."""
    text = CASE_I.read_text().replace("duration_s: 2.0", "duration_s: 2e0")
    assert "2e0" in text
    path = tmp_path / "exp.yaml"
    path.write_text(text)
    s = spotsim.load_scenario(path, ["simulation.integrator.velocity_tol_m_s=1e-6", "contact.skin_mm=5E-1"])
    assert s.simulation.duration_s == 2.0 and s.simulation.integrator.velocity_tol_m_s == 1e-6
    assert s.contact.skin_mm == 0.5
    from spotsim.scenario import parse_yaml

    # numbers need a digit; the rest stays text (a dot alone, a bare exponent, a sign)
    assert parse_yaml("[1e-6, 2E3, .5, 1., -.inf, ., -., e5, 1e, +]", "x")[:4] == [1e-6, 2000.0, 0.5, 1.0]
    assert parse_yaml("[1e-6, 2E3, .5, 1., -.inf, ., -., e5, 1e, +]", "x")[5:] == [".", "-.", "e5", "1e", "+"]


def test_deeply_nested_file_is_one_clear_error_from_the_installed_command(tmp_path):
    """Python's recursion limit is reached in a subprocess as it would be for a user."""
    deep = tmp_path / "deep.yaml"
    deep.write_text("a: " + "[" * 2000 + "]" * 2000 + "\n")
    proc = subprocess.run([sys.executable, "-m", "spotsim.cli", "validate", str(deep)], capture_output=True, text=True)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert f"{deep}: nested too deeply to read" in proc.stderr


def test_xacro_defaults_match_the_documented_geometry_defaults():
    """The scene XACRO's argument defaults equal the scenario's Geometry defaults (one truth)."""
    assert xacro_defaults_agree() == []


def test_scenario_round_trips_through_python(case_I):
    """A scenario built in Python from another's dict, with one change, validates again."""
    changed = spotsim.replace(case_I, end_effector={"closing_speed_m_s": 0.018})
    assert changed.end_effector.closing_speed_m_s == 0.018
    assert to_dict(changed)["module"] == to_dict(case_I)["module"]
    assert isinstance(case_I.geometry, Geometry)


def test_replace_changes_only_the_keys_it_names_at_any_depth(case_I):
    """A change to a nested section keeps that section's other keys (here, the integrator's)."""
    tight = spotsim.replace(case_I, simulation={"integrator": {"velocity_tol_m_s": 3e-6, "h_max_s": 4e-4}})
    step = spotsim.replace(tight, simulation={"integrator": {"kick": "step"}})
    i = step.simulation.integrator
    assert (i.kick, i.velocity_tol_m_s, i.h_max_s) == ("step", 3e-6, 4e-4)
    assert step.simulation.dt_s == case_I.simulation.dt_s


def test_unwritable_results_directory_is_a_clear_error(tmp_path, capsys):
    """An --out that cannot be created gives one line and exit 2, before anything runs."""
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    assert main(["run", str(CASE_I), "--out", str(blocker / "out"), "--quiet"]) == 2
    assert "cannot write results" in capsys.readouterr().err


def test_shipped_scenarios_are_found_by_name_from_any_directory(tmp_path, monkeypatch, capsys):
    """A shipped scenario by its name, or by the end of it after an underscore when only one
    ends so, in load_scenario, validate, run and sweep; `spotsim list` names them all; an
    ambiguous or unknown name is one clear error."""
    from spotsim.paths import shipped_scenarios

    monkeypatch.chdir(tmp_path)
    shipped = shipped_scenarios()
    assert set(shipped) == {p.stem for p in CONFIGS}
    assert spotsim.load_scenario("case_III").name == "single_arm_case_III"
    assert spotsim.load_scenario("single_arm_case_II.yaml").name == "single_arm_case_II"
    assert spotsim.load_scenario("testbed_3mm", ["simulation.duration_s=1"]).name == "spot_testbed_3mm"
    assert main(["list"]) == 0
    listed = capsys.readouterr().out
    assert all(name in listed for name in shipped)
    assert main(["validate", "case_I"]) == 0 and "name: single_arm_case_I" in capsys.readouterr().out
    assert main(["run", "case_I", "--set", "simulation.duration_s=0.05", "--no-error-estimate", "--no-figures",
                 "--quiet", "--out", str(tmp_path / "run")]) == 3  # the time-out: it ran
    assert (tmp_path / "run" / "summary.json").exists()
    capsys.readouterr()
    # a sweep by name: found, then refused by its budget before anything runs
    assert main(["sweep", "case_I", "--vary", "friction.mu_k=0.1,0.2", "--max-points", "1"]) == 2
    assert f"{shipped['single_arm_case_I']}: the sweep: 2 runs, more than the budget of 1" in capsys.readouterr().err
    assert main(["validate", "3mm"]) == 2
    assert "spot_offset_3mm, spot_testbed_3mm" in capsys.readouterr().err
    assert main(["validate", "no_such_case"]) == 2
    assert "no shipped scenario of that name" in capsys.readouterr().err
