"""Every example runs, and the figures it prints are the simulator's."""

import re
import subprocess
import sys

import numpy as np
import pytest
from conftest import CASE_I, ROOT

import spotsim
from spotsim.assemble.assets import URDF_DIR, compile_xacro
from spotsim.assemble.faces import contact_faces, sphere_layer
from spotsim.assemble.scene import geometry_args
from spotsim.scenario import Contact, Geometry

EXAMPLES = sorted((ROOT / "examples").glob("*.py"))
#: Printed figures carry 3-4 decimals: they agree with the summary to half their last digit.
PRINTED = {"mm3": 5e-4, "mm4": 5e-5, "N2": 5e-3}
#: A marker record's values are written to 6 significant digits; the sample's are ~0.1 mm or deg,
#: under 10, so two writings of the same record agree to 1e-5.
MARKER_DIGITS = 1e-5
#: The sample's pooled RMS against its stated noise: about 1,900 samples a kind give the RMS a
#: sampling error of 1 / sqrt(2 n) = 1.6 %; 10 % is six of those.
NOISE_RMS_REL = 0.1


def run(path, *args):
    proc = subprocess.run([sys.executable, str(path), *args], capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def numbers(text):
    return [float(x) for x in re.findall(r"[-+]?\d+\.\d+(?:e[-+]\d+)?", text)]


def test_every_example_is_tested():
    """Each example has a test below that runs it (and opens with a docstring saying how)."""
    tested = {"case_I_from_python.py", "compare_searches.py", "design_sweep.py", "dual_arm_sequential.py",
              "sample_markers.py", "sensitivity.py", "sphere_layers.py"}
    assert {p.name for p in EXAMPLES} == tested
    for path in EXAMPLES:
        assert path.read_text().startswith('"""'), path.name


def test_case_I_example_prints_the_runs_residual_offset_and_peak_force():
    """The Case I example completes and prints the run's residual offset and peak force: those
    of the same scenario simulated here (the simulation is deterministic)."""
    out = run(ROOT / "examples" / "case_I_from_python.py")
    assert "status: completed" in out
    grasp = spotsim.simulate(spotsim.load_scenario(CASE_I)).grasp
    line = next(x for x in out.splitlines() if x.startswith("residual offset"))
    x, y, z, e = numbers(line)
    assert np.allclose([x, y, z], grasp["residual_offset_mm"], rtol=0, atol=PRINTED["mm4"])
    assert e == pytest.approx(grasp["residual_offset_norm_mm"], abs=PRINTED["mm4"])
    force = numbers(next(x for x in out.splitlines() if x.startswith("peak contact force")))
    assert np.allclose(force, grasp["peak_force_N"], rtol=0, atol=PRINTED["N2"])


def test_sphere_layer_example_prints_counts_and_spacing():
    """The layer example reports each layer's sphere count, a spacing equal to its radius and
    centres one radius above the face."""
    out = run(ROOT / "examples" / "sphere_layers.py")
    assert "r = 0.7 mm, spacing 0.700 / 0.700 mm, centres 0.700-0.700 mm" in out
    assert "r = 0.8 mm, spacing 0.800 / 0.800 mm, centres 0.800-0.800 mm" in out
    faces = {f.name: f for f in contact_faces(compile_xacro(URDF_DIR / "single_arm_scene.urdf.xacro",
                                                            geometry_args(Geometry())))}
    contact = Contact()
    for name, radius_mm in (("ee_finger_upper_flank_pos", contact.sphere_radius_finger_mm),
                            ("tm_groove_upper_flank_pos", contact.sphere_radius_groove_mm)):
        count = len(sphere_layer(faces[name].vertices_L, radius_mm * 1e-3).centres)
        assert re.search(rf"{name}\s.*: +{count} spheres", out), (name, count)


def test_compare_searches_example_finds_them_equal():
    """Along a real run, the culled and the all-pairs search agree on every compared state,
    pairs and forces alike."""
    out = run(ROOT / "examples" / "compare_searches.py", "--until", "0.6")
    same, checked = map(int, re.search(r"same pairs in (\d+) of (\d+)", out).groups())
    assert same == checked > 10
    assert float(re.search(r"largest force difference ([0-9.e+-]+)", out).group(1)) <= 1e-12


def test_dual_arm_example_prints_the_runs_displacements_and_forces():
    """The dual-arm example prints, per grasp, the robot centroid's displacement and the peak
    force and torque of the run: those of the same scenario simulated here."""
    out = run(ROOT / "examples" / "dual_arm_sequential.py", "--duration", "0.7")
    s = spotsim.replace(spotsim.load_scenario(ROOT / "config" / "dual_arm_sequential.yaml"),
                        simulation={"duration_s": 0.7})
    first = spotsim.simulate(s).summary["grasps"][0]
    lines = out.splitlines()
    at = lines.index("EE-1 on TM-1:")
    displacement = numbers(lines[at + 1])[:3]
    assert np.allclose(displacement, first["robot_centroid_displacement_mm"], rtol=0, atol=PRINTED["mm3"])
    force, torque = numbers(lines[at + 2])[:2]
    assert force == pytest.approx(first["peak_force_norm_N"], abs=PRINTED["N2"])
    assert torque == pytest.approx(first["peak_torque_norm_Nm"], abs=PRINTED["N2"])


def test_design_sweep_example_prints_each_geometrys_envelope_and_run(tmp_path):
    """The quick design sweep: a line per geometry whose y_a bracket is one resolution wide, and
    whose Case I run is the scenario's with that geometry simulated here."""
    out = run(ROOT / "examples" / "design_sweep.py", "--quick", "--out", str(tmp_path), "--workers", "2")
    lines = [x for x in out.splitlines() if x.startswith("bevel ")]
    assert len(lines) == 2 and (tmp_path / "design_sweep.png").exists()
    for line, bevel in zip(lines, (40, 50), strict=True):
        lo, hi = (float(m) for m in re.search(r"y\+ captured to ([\d.]+) \(not at ([\d.]+)\)", line).groups())
        assert hi - lo == pytest.approx(1.0)
        sets = [f"geometry.{k}={v}" for k, v in (("upper_bevel_deg", bevel), ("lower_bevel_deg", bevel))]
        grasp = spotsim.simulate(spotsim.load_scenario(CASE_I, sets)).grasp
        residual = float(re.search(r"residual ([\d.]+) mm", line).group(1))
        assert residual == pytest.approx(grasp["residual_offset_norm_mm"], abs=PRINTED["mm4"])


def test_sensitivity_example_writes_each_settings_run_and_its_chart(tmp_path):
    """The quick sensitivity study: from the unperturbed start alone, each setting's row is the
    motor-driven Case I run with that parameter moved, simulated here; started again over the
    same directory it runs nothing."""
    import csv

    out = run(ROOT / "examples" / "sensitivity.py", "--quick", "--out", str(tmp_path), "--workers", "1")
    with (tmp_path / "sensitivity.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert [(r["parameter"], r["side"]) for r in rows] == [
        ("default", "default"), ("current limit ±50 %", "low"), ("current limit ±50 %", "high"),
        ("restitution 0.5, 0.95", "low"), ("restitution 0.5, 0.95", "high")]
    assert (tmp_path / "sensitivity.png").exists() and len(out.splitlines()) == 7
    for r in rows[::2]:
        sets = ["end_effector.drive=motor", *r["sets"].split()]
        summary = spotsim.simulate(spotsim.load_scenario(CASE_I, sets)).summary
        grasp = summary["grasps"][0]
        assert float(r["peak_force_norm_N_median"]) == grasp["peak_force_norm_N"]
        assert float(r["residual_norm_mm_median"]) == grasp["residual_offset_norm_mm"]
        assert float(r["completed_s_median"]) == grasp["completed_s"]
    again = run(ROOT / "examples" / "sensitivity.py", "--quick", "--out", str(tmp_path), "--workers", "1")
    assert len(again.splitlines()) == 2  # the CSV and the chart: no setting ran


def test_sample_markers_example_writes_the_shipped_record_the_runs_plus_its_noise(tmp_path):
    """The sample marker record: the file the example writes is the one shipped in examples/,
    and it differs from the 3 mm testbed run's own camera record (simulated here) by the stated
    noise alone: each kind's pooled RMS within NOISE_RMS_REL of it."""
    import importlib.util

    from spotsim.measures import read_markers

    out = tmp_path / "markers.csv"
    run(ROOT / "examples" / "sample_markers.py", "--out", str(out))
    times, sample = read_markers(out)
    shipped_t, shipped = read_markers(ROOT / "examples" / "markers_sample.csv")
    assert np.array_equal(times, shipped_t) and sample.keys() == shipped.keys()
    assert all(np.allclose(sample[k], shipped[k], rtol=0, atol=MARKER_DIGITS) for k in sample)
    spec = importlib.util.spec_from_file_location("sample_markers", ROOT / "examples" / "sample_markers.py")
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    result = spotsim.simulate(spotsim.load_scenario("spot_testbed_3mm"))
    clean_t, clean = read_markers(spotsim.write_results(result, tmp_path / "run", figures=False) / "markers.csv")
    assert np.array_equal(clean_t, times)
    for unit, noise in (("_mm", example.NOISE_MM), ("_deg", example.NOISE_DEG)):
        diff = np.concatenate([sample[k] - clean[k] for k in sample if k.endswith(unit)])
        assert np.sqrt(np.mean(diff**2)) == pytest.approx(noise, rel=NOISE_RMS_REL)
