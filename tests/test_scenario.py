"""Strict scenarios: every shipped config validates; broken ones fail with one clear line each."""

import subprocess
import sys

import pytest
import yaml
from conftest import CASE_I, CONFIGS

import spotsim
from spotsim.cli import main
from spotsim.scenario import Geometry, from_dict, to_dict, xacro_defaults_agree


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_every_shipped_config_validates(path, capsys):
    """`spotsim validate` accepts each YAML in config/ and prints a scenario that reloads equal."""
    assert main(["validate", str(path)]) == 0
    printed = capsys.readouterr().out
    assert from_dict(yaml.safe_load(printed)) == spotsim.load_scenario(path)


#: Geometry and size a run cannot have, either kind of scenario: one line each.
SHAPES_BROKEN = {
    "finger wider than the mouth": ({"geometry": {"finger_slant_mm": 16.0}},
                                    "geometry.finger_slant_mm = 16.0: a finger must fit its groove's mouth "
                                    "(finger_tip_half_width_mm + finger_slant_mm sin bevel <= depth tan bevel): the "
                                    "upper finger is 13.3 mm wide each side of its ridge, its groove's mouth 13 mm; "
                                    "the lower finger"),
    "groove sphere wider than a flank": ({"contact": {"sphere_radius_groove_mm": 10.0}},
                                         "contact.sphere_radius_groove_mm = 10.0: a sphere must fit a groove's flank: "
                                         "the upper groove's flank is 18.4 mm on its shorter side; the lower"),
    "finger sphere wider than a flank": ({"contact": {"sphere_radius_finger_mm": 4.5}},
                                         "contact.sphere_radius_finger_mm = 4.5: a sphere must fit a finger's flank: "
                                         "it is 8 mm on its shorter side"),
    "too many spheres": ({"contact": {"sphere_radius_groove_mm": 0.01}},
                         "contact.sphere_radius_groove_mm = 0.01: the sphere layers would hold about "),
    "too many records": ({"simulation": {"duration_s": 1.0e5, "dt_s": 1.0e-3}},
                         "simulation.duration_s = 100000.0: 1e+08 recorded intervals of dt_s = 0.001, more than the "
                         "5e+06 a run may record"),
}

BROKEN = {
    "unknown key": ({"contact": {"restitutoin": 0.8}}, "contact.restitutoin = 0.8: unknown key"),
    "wrong type": ({"end_effector": {"closing_speed_m_s": "fast"}},
                   "end_effector.closing_speed_m_s = fast: must be a number"),
    "non-finite": ({"simulation": {"duration_s": float("nan")}}, "simulation.duration_s = .nan: must be finite"),
    "negative mass": ({"module": {"mass_kg": -2.768}}, "module.mass_kg = -2.768: must be > 0"),
    "negative radius": ({"contact": {"sphere_radius_groove_mm": -0.8}},
                        "contact.sphere_radius_groove_mm = -0.8: must be > 0"),
    "zero step": ({"simulation": {"dt_s": 0.0}}, "simulation.dt_s = 0.0: must be > 0"),
    "restitution above 1": ({"contact": {"restitution": 1.7}}, "contact.restitution = 1.7: must be in (0, 1]"),
    "restitution zero": ({"contact": {"restitution": 0.0}}, "contact.restitution = 0.0: must be in (0, 1]"),
    "mu_k above mu_s": ({"friction": {"mu_k": 0.4}}, "friction.mu_k = 0.4: must not exceed friction.mu_s = 0.3"),
    "wrong list length": ({"module": {"initial_offset_mm": [0, -3]}},
                          "module.initial_offset_mm = [0, -3]: must be a list of 3 numbers"),
    "bad choice": ({"contact": {"broad_phase": "bvh"}}, "contact.broad_phase = bvh: must be one of coal, none"),
    "joint limit": ({"arm": {"joint_angles_rad": [0, -1.0, -1.0, 0, 0, 0]}},
                    "arm.joint_angles_rad[1] = -1.0: must be within the joint2 limits"),
    **SHAPES_BROKEN,
    "interpenetration": ({"end_effector": {"start_gap_mm": 1.0}},
                         "module.initial_offset_mm = [0.0, -3.0, 0.0]: fingers and groove interpenetrate"),
}


def merged(change):
    raw = yaml.safe_load(CASE_I.read_text())
    for section, values in change.items():
        raw[section] = {**raw.get(section, {}), **values}
    return raw


@pytest.mark.parametrize("name", BROKEN)
def test_broken_config_gives_one_clear_error_and_exit_2(name, tmp_path, capsys):
    """Each broken config is rejected before anything runs: one `file: key = value: rule` line."""
    change, expected = BROKEN[name]
    path = tmp_path / "broken.yaml"
    path.write_text(yaml.safe_dump(merged(change)))
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f"{path}: ") and expected in err[0]
    assert not (tmp_path / "out" / "summary.json").exists()


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


def test_unreadable_and_invalid_yaml_files(tmp_path, capsys):
    """A missing file and a file that is not YAML each give one clear line and exit 2."""
    assert main(["validate", str(tmp_path / "nope.yaml")]) == 2
    assert "cannot read" in capsys.readouterr().err
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: [unclosed\n")
    assert main(["validate", str(bad)]) == 2
    assert "not valid YAML" in capsys.readouterr().err


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


def test_a_key_given_twice_names_both_lines(tmp_path, capsys):
    path = tmp_path / "twice.yaml"
    path.write_text(CASE_I.read_text() + "name: again\n")
    first = 1 + CASE_I.read_text().splitlines().index(next(x for x in CASE_I.read_text().splitlines()
                                                            if x.startswith("name:")))
    last = len(path.read_text().splitlines())
    assert main(["validate", str(path)]) == 2
    assert f"{path}: line {last}: duplicate key 'name' (first at line {first})" in capsys.readouterr().err


def test_binary_and_deeply_nested_files_are_one_clear_error(tmp_path, capsys):
    binary = tmp_path / "binary.yaml"
    binary.write_bytes(b"\xff\xfename: x\n")
    assert main(["validate", str(binary)]) == 2
    assert f"{binary}: not UTF-8 text (byte 0" in capsys.readouterr().err
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


DUAL = CASE_I.parent / "dual_arm_sequential.yaml"

DUAL_BROKEN = {
    "unknown kind": ({"kind": "triple_arm"}, "kind = triple_arm: must be one of single_arm, dual_arm"),
    "missing module": ({"tm2": None}, "tm2 = (missing): required key"),
    "arm beyond its limit": ({"robot": {"arm1_joint_angles_rad": [0, 0, 4.0, 0, 0, 0]}},
                             "robot.arm1_joint_angles_rad[2] = 4.0: must be within the arm1_elbow_joint limits"),
    **SHAPES_BROKEN,
    "interpenetration": ({"end_effector": {"start_gap_mm": 1.0}}, "fingers and groove interpenetrate"),
}


@pytest.mark.parametrize("name", DUAL_BROKEN)
def test_broken_dual_arm_config_gives_one_clear_error(name, tmp_path, capsys):
    """Dual-arm scenarios are as strict as single-arm ones: one line, exit 2, nothing run."""
    change, expected = DUAL_BROKEN[name]
    raw = yaml.safe_load(DUAL.read_text())
    for key, value in change.items():
        if value is None:
            del raw[key]
        elif isinstance(value, dict):
            raw[key] = {**raw.get(key, {}), **value}
        else:
            raw[key] = value
    path = tmp_path / "broken.yaml"
    path.write_text(yaml.safe_dump(raw))
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expected in err[0], err


def test_unwritable_results_directory_is_a_clear_error(tmp_path, capsys):
    """An --out that cannot be created gives one line and exit 2, before anything runs."""
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    assert main(["run", str(CASE_I), "--out", str(blocker / "out"), "--quiet"]) == 2
    assert "cannot write results" in capsys.readouterr().err
