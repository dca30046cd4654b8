"""A corpus of named bad inputs, each with the exact message a user gets: configs, `--set`
values, geometries and results directories. Every one is refused with exit code 2, its
message and nothing else on stderr (no traceback), and nothing written."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import CASE_I
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import spotsim
from spotsim.cli import main

DUAL = CASE_I.parent / "dual_arm_sequential.yaml"
TEXT = CASE_I.read_text()


@dataclass(frozen=True)
class Bad:
    """A bad input: `make(tmp)` writes it and returns the command line; `lines` are the exact
    stderr lines, with {tmp} for the test's directory."""

    make: object
    lines: tuple[str, ...]


def config(change: dict, base: Path = CASE_I, *more):
    """`spotsim run` of the base config with each section's keys changed."""
    def make(tmp: Path):
        raw = yaml.safe_load(base.read_text())
        for section, values in change.items():
            if values is None:
                del raw[section]
            else:
                raw[section] = {**raw.get(section, {}), **values} if isinstance(values, dict) else values
        path = tmp / "bad.yaml"
        path.write_text(yaml.safe_dump(raw))
        return ["run", str(path), "--out", str(tmp / "out"), "--quiet", *more]
    return make


def text(content: str | bytes):
    """`spotsim run` of a file holding `content` as it is."""
    def make(tmp: Path):
        path = tmp / "bad.yaml"
        (path.write_bytes if isinstance(content, bytes) else path.write_text)(content)
        return ["run", str(path), "--out", str(tmp / "out"), "--quiet"]
    return make


def override(*sets: str):
    """`spotsim run` of Case I with `--set` overrides."""
    def make(tmp: Path):
        return ["run", str(CASE_I), "--out", str(tmp / "out"), "--quiet", *(a for s in sets for a in ("--set", s))]
    return make


def results(write, command="plot"):
    """`spotsim plot` (or `replay`) of a results directory that `write(dir)` fills."""
    def make(tmp: Path):
        d = tmp / "out"
        d.mkdir()
        write(d)
        return [command, str(d), *(["--no-browser"] if command == "replay" else [])]
    return make


def _run_dir(d: Path) -> None:
    """A complete, valid results directory of a short Case I run."""
    r = spotsim.simulate(spotsim.replace(spotsim.load_scenario(CASE_I), simulation={"duration_s": 0.01}))
    spotsim.write_results(r, d, figures=False)


def _with(change):
    def write(d: Path):
        _run_dir(d)
        change(d)
    return write


def _summary(update):
    def change(d: Path):
        s = json.loads((d / "summary.json").read_text())
        update(s)
        (d / "summary.json").write_text(json.dumps(s))
    return _with(change)


def _cut(name: str):
    def change(d: Path):
        data = (d / name).read_bytes()
        (d / name).write_bytes(data[: len(data) // 2])
    return _with(change)


def _foreign_npz(d: Path) -> None:
    _run_dir(d)
    np.savez(d / "timeseries.npz", pressure=np.zeros(3))


def _foreign_points(tmp: Path):
    (tmp / "out").mkdir()
    (tmp / "out" / "points.jsonl").write_text("time,x\n0,1\n")
    return ["sweep", str(CASE_I), "--vary", "contact.restitution=0.7,0.8", "--out", str(tmp / "out"), "--quiet"]

def _urdf(old: str, new: str):
    """build_model of Case I from its own compiled URDF with `old` replaced by `new`."""
    def make(tmp: Path):
        return ("urdf", old, new)
    return make


DEEP = "a: " + "[" * 2000 + "]" * 2000 + "\n"
BOMB = "".join(f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9) if i else 'x'}]\n" for i in range(7))

CORPUS = {
    # ------------------------------------------------------------------ configs
    "unknown key": Bad(config({"contact": {"restitutoin": 0.8}}), (
        "{tmp}/bad.yaml: contact.restitutoin = 0.8: unknown key (valid: broad_phase, skin_mm, restitution, "
        "approach_speed_floor_m_s, normal_direction, force_point, youngs_modulus_finger_Pa, "
        "youngs_modulus_groove_Pa, poisson_finger, poisson_groove, sphere_radius_finger_mm, "
        "sphere_radius_groove_mm)",
    )),
    "wrong type": Bad(config({"end_effector": {"closing_speed_m_s": "fast"}}), (
        "{tmp}/bad.yaml: end_effector.closing_speed_m_s = fast: must be a number",
    )),
    "not finite": Bad(config({"simulation": {"duration_s": float("nan")}}), (
        "{tmp}/bad.yaml: simulation.duration_s = .nan: must be finite",
    )),
    "negative mass": Bad(config({"module": {"mass_kg": -2.768}}), (
        "{tmp}/bad.yaml: module.mass_kg = -2.768: must be > 0",
    )),
    "zero step": Bad(config({"simulation": {"dt_s": 0.0}}), (
        "{tmp}/bad.yaml: simulation.dt_s = 0.0: must be > 0",
    )),
    "restitution above 1": Bad(config({"contact": {"restitution": 1.7}}), (
        "{tmp}/bad.yaml: contact.restitution = 1.7: must be in (0, 1]",
    )),
    "mu_k above mu_s": Bad(config({"friction": {"mu_k": 0.4}}), (
        "{tmp}/bad.yaml: friction.mu_k = 0.4: must not exceed friction.mu_s = 0.3",
    )),
    "list of two": Bad(config({"module": {"initial_offset_mm": [0, -3]}}), (
        "{tmp}/bad.yaml: module.initial_offset_mm = [0, -3]: must be a list of 3 numbers",
    )),
    "no such choice": Bad(config({"contact": {"broad_phase": "bvh"}}), (
        "{tmp}/bad.yaml: contact.broad_phase = bvh: must be one of coal, none",
    )),
    "arm beyond its limit": Bad(config({"arm": {"joint_angles_rad": [0, -1.0, -1.0, 0, 0, 0]}}), (
        "{tmp}/bad.yaml: arm.joint_angles_rad[1] = -1.0: must be within the joint2 limits [0.0000, 2.9671] rad",
    )),
    "section not a mapping": Bad(config({"simulation": [1, 2]}), (
        "{tmp}/bad.yaml: simulation = [1, 2]: must be a mapping",
    )),
    "unknown kind": Bad(config({"kind": "triple_arm"}), (
        "{tmp}/bad.yaml: kind = triple_arm: must be one of single_arm, dual_arm",
    )),
    "interpenetrating start": Bad(config({"end_effector": {"start_gap_mm": 1.0}}), (
        "{tmp}/bad.yaml: module.initial_offset_mm = [0.0, -3.0, 0.0]: fingers and groove interpenetrate at the "
        "start (3740 sphere pairs); widen end_effector.start_gap_mm = 1.0 or move the module",
    )),
    "name with a slash": Bad(config({"name": "../elsewhere"}), (
        "{tmp}/bad.yaml: name = ../elsewhere: must be 1-100 letters, digits, '.', '_' or '-', the first a letter "
        "or digit (it names the results directory)",
    )),
    "description too long": Bad(config({"description": "x" * 10_001}), (
        "{tmp}/bad.yaml: description = xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx... (10001 "
        "characters): must be at most 10000 characters, not 10001",
    )),
    "inertia not positive definite": Bad(config({"module": {"inertia_kg_m2": {"ixx": 1e-3, "iyy": 1e-3,
                                                                              "izz": 1e-3, "ixy": 2e-3}}}), (
        "{tmp}/bad.yaml: module.inertia_kg_m2 = {ixx: 0.001, ixy: 0.002, ixz: 0.0, iyy: 0.001, iyz: 0.0, izz: "
        "0.001}: must be positive definite (its principal moments are -0.001, 0.001, 0.003 kg m^2)",
    )),
    "inertia no body has": Bad(config({"module": {"inertia_kg_m2": {"ixx": 1e-3, "iyy": 1e-3, "izz": 3e-3}}}), (
        "{tmp}/bad.yaml: module.inertia_kg_m2 = {ixx: 0.001, ixy: 0.0, ixz: 0.0, iyy: 0.001, iyz: 0.0, izz: "
        "0.003}: no rigid body has principal moments 0.001, 0.001, 0.003 kg m^2 (the largest must not exceed the "
        "sum of the other two)",
    )),
    "smallest step above the largest": Bad(config({"simulation": {"dt_s": 1e-3, "duration_s": 2.0,
                                                                 "integrator": {"h_min_s": 1e-2, "h_max_s": 1e-3}}}), (
        "{tmp}/bad.yaml: simulation.integrator.h_min_s = 0.01: must not exceed simulation.integrator.h_max_s = "
        "0.001",
    )),
    "too many records": Bad(config({"simulation": {"duration_s": 1.0e5, "dt_s": 1.0e-3}}), (
        "{tmp}/bad.yaml: simulation.duration_s = 100000.0: 1e+08 recorded intervals of dt_s = 0.001, more than "
        "the 5e+06 a run may record: shorten the run or lengthen dt_s",
    )),
    "too many steps": Bad(config({"simulation": {"dt_s": 1e-3, "duration_s": 2.0, "substeps": 100_000,
                                                 "integrator": {"method": "rk4"}}}), (
        "{tmp}/bad.yaml: simulation.substeps = 100000: 2e+08 dynamics steps (duration_s / dt_s x substeps) of "
        "rk4, more than the 1e+08 a run may take: lower substeps or use adaptive_euler",
    )),
    "substeps beyond a million": Bad(config({"simulation": {"dt_s": 1e-3, "duration_s": 2.0, "substeps": 10**30}}), (
        "{tmp}/bad.yaml: simulation.substeps = 1000000000000000000000000000000: must be in [1, 1000000]",
    )),
    "dual arm without TM-2": Bad(config({"tm2": None}, DUAL), (
        "{tmp}/bad.yaml: tm2 = (missing): required key",
    )),
    "a key twice": Bad(text(TEXT + "name: again\n"), (
        "{tmp}/bad.yaml: line 24: duplicate key 'name' (first at line 6)",
    )),
    "not UTF-8": Bad(text(b"\xff\xfename: x\n"), (
        "{tmp}/bad.yaml: not UTF-8 text (byte 0: b'\\xff')",
    )),
    "not YAML": Bad(text("name: [unclosed\n"), (
        "{tmp}/bad.yaml: line 2: not valid YAML: expected ',' or ']', but got '<stream end>'",
    )),
    "nested too deeply": Bad(text(DEEP), (
        "{tmp}/bad.yaml: nested too deeply to read",
    )),
    "aliases expanding": Bad(text(BOMB), (
        "{tmp}/bad.yaml: line 6: more than 1e+05 values, aliases expanded",
    )),
    "file too large": Bad(text(TEXT + "# " + "x" * 1_000_000 + "\n"), (
        "{tmp}/bad.yaml: more than the 1e+06 bytes a scenario file may hold",
    )),
    "empty file": Bad(text(""), (
        "{tmp}/bad.yaml: name = (missing): required key",
        "{tmp}/bad.yaml: simulation = (missing): required key",
        "{tmp}/bad.yaml: arm = (missing): required key",
        "{tmp}/bad.yaml: end_effector = (missing): required key",
        "{tmp}/bad.yaml: module = (missing): required key"
    )),
    "a list, not a scenario": Bad(text("- 1\n- 2\n"), (
        "{tmp}/bad.yaml: <top> = [1, 2]: must be a mapping",
    )),
    "missing file": Bad(lambda tmp: ["run", str(tmp / "nope.yaml"), "--out", str(tmp / "out")], (
        "{tmp}/nope.yaml: cannot read: No such file or directory",
    )),
    "dual arm: an arm beyond its limit": Bad(config({"robot": {"arm1_joint_angles_rad": [0, 0, 4.0, 0, 0, 0]}}, DUAL), (
        "{tmp}/bad.yaml: robot.arm1_joint_angles_rad[2] = 4.0: must be within the arm1_elbow_joint limits "
        "[-3.1416, 3.1416] rad",
    )),
    "dual arm: interpenetrating start": Bad(config({"end_effector": {"start_gap_mm": 1.0}}, DUAL), (
        "{tmp}/bad.yaml: tm1.initial_offset_mm = [0.0, -2.5, 0.0]; tm2.initial_offset_mm = [0.0, -2.5, 0.0]: "
        "fingers and groove interpenetrate at the start (7194 sphere pairs); widen end_effector.start_gap_mm = 1.0 "
        "or move the module",
    )),
    "dual arm: finger wider than the mouth": Bad(config({"geometry": {"finger_slant_mm": 16.0}}, DUAL), (
        "{tmp}/bad.yaml: geometry.finger_slant_mm = 16.0: a finger must fit its groove's mouth "
        "(finger_tip_half_width_mm + finger_slant_mm sin bevel <= depth tan bevel): the upper finger is 13.3 mm "
        "wide each side of its ridge, its groove's mouth 13 mm; the lower finger is 13.3 mm wide each side of its "
        "ridge, its groove's mouth 13 mm",
    )),
    # ------------------------------------------------------------------ --set values
    "--set without =": Bad(override("contact.restitution"), (
        "--set: contact.restitution: must read key.path=value",
    )),
    "--set unknown key": Bad(override("contact.nonsense=1"), (
        "{root}/config/single_arm_case_I.yaml: contact.nonsense = 1: unknown key (valid: broad_phase, skin_mm, "
        "restitution, approach_speed_floor_m_s, normal_direction, force_point, youngs_modulus_finger_Pa, "
        "youngs_modulus_groove_Pa, poisson_finger, poisson_groove, sphere_radius_finger_mm, "
        "sphere_radius_groove_mm)",
    )),
    "--set index beyond the list": Bad(override("module.initial_offset_mm.5=1"), (
        "--set: module.initial_offset_mm.5: module.initial_offset_mm has 3 items: 5 is not one of 0..2",
    )),
    "--set value not YAML": Bad(override("contact.restitution=[1,"), (
        "--set: contact.restitution = [1,: line 1: not valid YAML: expected the node content, but found '<stream "
        "end>'",
    )),
    "--set number for a string": Bad(override("name=1e5"), (
        "{root}/config/single_arm_case_I.yaml: name = 100000.0: must be a string",
    )),
    "--set into a number": Bad(override("contact.restitution.x=1"), (
        "{root}/config/single_arm_case_I.yaml: contact.restitution = {x: 1}: must be a number",
    )),
    # ------------------------------------------------------------------ options
    "unknown option": Bad(lambda tmp: ["run", "--bogus"], ("spotsim: unrecognized arguments: --bogus",)),
    "negative seed": Bad(lambda tmp: ["run", str(CASE_I), "--ensemble", "2", "--seed", "-1"],
                         ("spotsim run: argument --seed: -1: must be >= 0",)),
    "no workers": Bad(lambda tmp: ["sweep", str(CASE_I), "--vary", "contact.restitution=0.7,0.8", "--workers", "0"],
                      ("spotsim sweep: argument --workers: 0: must be >= 1",)),
    "workers without an ensemble": Bad(lambda tmp: ["run", str(CASE_I), "--workers", "2"],
                                       ("--workers: only with --ensemble N",)),
    "a start family without an ensemble": Bad(lambda tmp: ["run", str(CASE_I), "--perturb", "one_axis"],
                                              ("--perturb: only with --ensemble N",)),
    "unknown start family": Bad(lambda tmp: ["run", str(CASE_I), "--ensemble", "2", "--perturb", "diagonal"],
                                ("spotsim run: argument --perturb: invalid choice: 'diagonal' (choose from 'all', "
                                 "'one_axis')",)),
    "scheduler without a port": Bad(lambda tmp: ["sweep", str(CASE_I), "--vary", "contact.restitution=0.7,0.8",
                                                 "--scheduler", "nonsense", "--out", str(tmp / "out"), "--quiet"],
                                    ("--scheduler nonsense: cannot connect: missing port number in address "
                                     "'nonsense'",)),
    # ------------------------------------------------------------------ geometries
    "finger wider than the mouth": Bad(config({"geometry": {"finger_slant_mm": 16.0}}), (
        "{tmp}/bad.yaml: geometry.finger_slant_mm = 16.0: a finger must fit its groove's mouth "
        "(finger_tip_half_width_mm + finger_slant_mm sin bevel <= depth tan bevel): the upper finger is 13.3 mm "
        "wide each side of its ridge, its groove's mouth 13 mm; the lower finger is 13.3 mm wide each side of "
        "its ridge, its groove's mouth 13 mm",
    )),
    "groove sphere wider than a flank": Bad(config({"contact": {"sphere_radius_groove_mm": 10.0}}), (
        "{tmp}/bad.yaml: contact.sphere_radius_groove_mm = 10.0: a sphere must fit a groove's flank: the upper "
        "groove's flank is 18.4 mm on its shorter side; the lower groove's flank is 18.4 mm on its shorter side",
    )),
    "finger sphere wider than a flank": Bad(config({"contact": {"sphere_radius_finger_mm": 4.5}}), (
        "{tmp}/bad.yaml: contact.sphere_radius_finger_mm = 4.5: a sphere must fit a finger's flank: it is 8 mm "
        "on its shorter side",
    )),
    "too many spheres": Bad(config({"contact": {"sphere_radius_groove_mm": 0.01}}), (
        "{tmp}/bad.yaml: contact.sphere_radius_groove_mm = 0.01: the sphere layers would hold about 4.8e+07 "
        "spheres, more than the 2e+06 a run may allocate: use larger spheres",
    )),
    "groove deeper than the adapter": Bad(config({"geometry": {"upper_depth_mm": 17.0}}), (
        "{tmp}/bad.yaml: geometry.upper_depth_mm = 17.0: must not exceed geometry.adapter_half_thickness_mm = 16.0",
    )),
    "bevel of 90 degrees": Bad(config({"geometry": {"lower_bevel_deg": 90.0}}), (
        "{tmp}/bad.yaml: geometry.lower_bevel_deg = 90.0: must be in (0, 90) deg",
    )),
    "edge of zero length": Bad(config({"geometry": {"bevel_edge_length_mm": 0.0}}), (
        "{tmp}/bad.yaml: geometry.bevel_edge_length_mm = 0.0: must be > 0",
    )),
    "URDF mass NaN": Bad(_urdf('<mass value="2.768"', '<mass value="nan"'), (
        "link tm_module: inertial mass value='nan' must be finite numbers",
    )),
    "URDF negative mass": Bad(_urdf('<mass value="2.768"', '<mass value="-2.768"'), (
        "link tm_module: mass -2.768 kg must be >= 0",
    )),
    "URDF inertia not positive definite": Bad(_urdf('ixy="5.349e-05"', 'ixy="1.0"'), (
        "link tm_module: inertia [[0.004739, 1.0, 3.76e-05], [1.0, 0.004668, 7.25e-05], [3.76e-05, 7.25e-05, "
        "0.004707]] is not positive semi-definite",
    )),
    # ------------------------------------------------------------------ results directories
    "results: missing": Bad(lambda tmp: ["plot", str(tmp / "nowhere")], (
        "{tmp}/nowhere: no such results directory",
    )),
    "results: empty directory": Bad(results(lambda d: None), (
        "{tmp}/out: no summary.json: not a spotsim results directory, or its run has not finished writing it",
    )),
    "results: summary not JSON": Bad(results(_with(lambda d: (d / "summary.json").write_text("{cut"))), (
        "{tmp}/out: summary.json is not valid JSON (Expecting property name enclosed in double quotes at line 1 "
        "column 2)",
    )),
    "results: summary not an object": Bad(results(_with(lambda d: (d / "summary.json").write_text("[1]"))), (
        "{tmp}/out: summary.json is not a run's summary (a JSON object)",
    )),
    "results: timeseries cut short": Bad(results(_cut("timeseries.npz")), (
        "{tmp}/out: timeseries.npz: not a readable .npz (BadZipFile: File is not a zip file)",
    )),
    "results: foreign timeseries": Bad(results(_foreign_npz), (
        "{tmp}/out: timeseries.npz lacks t, offset_mm, force_N, torque_Nm, pairs_slipping, pairs_sticking: not a "
        "run's time series",
    )),
    "results: older format": Bad(results(_summary(lambda s: s.pop("results_format"))), (
        "{tmp}/out: summary.json has no results_format (written by spotsim 0.1.0); this spotsim reads format 1: "
        "run the scenario again",
    )),
    "results: newer format": Bad(results(_summary(lambda s: s.update(results_format=99))), (
        "{tmp}/out: summary.json has results format 99 (written by spotsim 0.1.0); this spotsim reads format 1: "
        "run the scenario again",
    )),
    "results: replay cut short": Bad(results(_cut("replay.npz"), "replay"), (
        "{tmp}/out: replay.npz: not a readable .npz (BadZipFile: File is not a zip file)",
    )),
    "results: a single array": Bad(results(_with(lambda d: np.save(d / "ts.npy", np.zeros(3))
                                                 or (d / "ts.npy").replace(d / "timeseries.npz"))), (
        "{tmp}/out: timeseries.npz: a single array, not an .npz archive of them",
    )),
    "sweep: a foreign points file": Bad(_foreign_points, (
        "{tmp}/out/points.jsonl: line 1 is not a study's run record: not resumable; move the file or give "
        "another --out",
    )),
}


def outcome(bad: Bad, tmp: Path, capsys) -> tuple[int, list[str]]:
    """The exit code and stderr lines of the bad input's command; for a URDF, what
    `build_model` raises (as exit 2 and its message)."""
    argv = bad.make(tmp)
    if argv[0] == "urdf":
        scenario = spotsim.load_scenario(CASE_I)
        urdf = spotsim.build_model(scenario).urdf
        assert argv[1] in urdf
        with pytest.raises(spotsim.ModelError) as e:
            spotsim.build_model(scenario, urdf=urdf.replace(argv[1], argv[2], 1))
        return 2, str(e.value).splitlines()
    capsys.readouterr()
    code = main(argv)
    return code, capsys.readouterr().err.strip().splitlines()


@pytest.mark.parametrize("name", CORPUS)
def test_each_bad_input_gives_its_exact_message(name, tmp_path, capsys):
    bad = CORPUS[name]
    code, lines = outcome(bad, tmp_path, capsys)
    root = str(CASE_I.parents[1])
    expected = [line.replace("{tmp}", str(tmp_path)).replace("{root}", root) for line in bad.lines]
    assert (code, lines) == (2, expected)
    assert not (tmp_path / "out" / "summary.json").exists() or name.startswith("results:")


def test_the_corpus_holds_at_least_40_inputs():
    assert len(CORPUS) >= 40


def numeric_keys(raw: dict, prefix: str = ""):
    """Every numeric key path of a scenario's resolved mapping, list items by index."""
    for k, v in raw.items():
        path = f"{prefix}{k}"
        if isinstance(v, dict):
            yield from numeric_keys(v, path + ".")
        elif isinstance(v, (list, tuple)):
            yield from (f"{path}.{i}" for i, x in enumerate(v) if isinstance(x, (int, float)))
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            yield path


EXTREMES = ("1e300", "-1e300", "1e-300", "123456789012345678901234567890")


@pytest.mark.parametrize("drive", ["kinematic", "motor"])
@pytest.mark.parametrize("value", EXTREMES)
def test_an_extreme_number_in_any_key_ends_in_an_exit_code_never_an_exception(value, drive, tmp_path, capsys):
    """Each numeric key of Case I set to an extreme value, under each finger drive that reads
    its own keys: refused (2), or run for 50 ms to a status (0, 3, 4); no exception escapes (a
    closing speed of 1e300 m/s raised OverflowError in the stable-step prediction, 1e30
    substeps in the compiled loop, fingers of 1e300 kg ZeroDivisionError in the motor's first
    impulse)."""
    from spotsim.scenario import to_dict

    codes = {}
    chosen = ["--set", f"end_effector.drive={drive}"]
    for key in numeric_keys(to_dict(spotsim.load_scenario(CASE_I))):
        duration = [] if key == "simulation.duration_s" else ["--set", "simulation.duration_s=0.05"]
        codes[key] = main(["run", str(CASE_I), *chosen, "--set", f"{key}={value}", *duration,
                           "--out", str(tmp_path / "out"), "--quiet", "--no-figures", "--no-error-estimate"])
    capsys.readouterr()
    assert set(codes.values()) <= {0, 2, 3, 4}, codes


@pytest.fixture(scope="module")
def complete_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("complete")
    _run_dir(d)
    return d


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=st.sampled_from(["summary.json", "timeseries.npz", "replay.npz"]),
       damage=st.sampled_from(["flip", "cut", "empty", "garbage"]), seed=st.integers(0, 2**32 - 1))
def test_a_damaged_results_file_is_one_line_and_exit_2_or_still_reads(name, damage, seed, complete_run, tmp_path,
                                                                       capsys):
    """Bytes flipped, a file cut or emptied or replaced by garbage: `plot` (summary, time
    series) and `replay --html` (replay.npz) end in 0 or in 2 with one line; never an exception
    (a flipped byte made zipfile raise NotImplementedError)."""
    import random
    import shutil

    rng = random.Random(seed)
    d = tmp_path / "damaged"
    shutil.rmtree(d, ignore_errors=True)  # the function's directory serves every example
    shutil.copytree(complete_run, d)
    data = bytearray((d / name).read_bytes())
    if damage == "flip":
        for _ in range(rng.randint(1, 20)):
            data[rng.randrange(len(data))] = rng.randrange(256)
    elif damage == "cut":
        data = data[: rng.randrange(len(data))]
    elif damage == "empty":
        data = bytearray()
    else:
        data = bytearray(rng.randbytes(rng.randint(1, 5000)))
    (d / name).write_bytes(bytes(data))
    argv = ["replay", str(d), "--html", str(tmp_path / "page.html")] if name == "replay.npz" else ["plot", str(d)]
    capsys.readouterr()
    code = main(argv)
    lines = [line for line in capsys.readouterr().err.strip().splitlines() if line]
    assert code == 0 or (code == 2 and len(lines) == 1), (code, lines)
