"""Every example runs and prints what its docstring promises."""

import re
import subprocess
import sys


from conftest import ROOT

EXAMPLES = sorted((ROOT / "examples").glob("*.py"))


def run(path, *args):
    proc = subprocess.run([sys.executable, str(path), *args], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def test_every_example_has_a_docstring_header():
    """Each example opens with a docstring saying what it does and how to run it."""
    for path in EXAMPLES:
        assert path.read_text().startswith('"""'), path.name


def test_case_I_example_prints_the_residual_offset():
    """The Case I example completes and prints a sub-millimetre residual offset."""
    out = run(ROOT / "examples" / "case_I_from_python.py")
    assert "status: completed" in out
    e = float(re.search(r"e = ([0-9.]+) mm", out).group(1))
    assert e < 1.0


def test_sphere_layer_example_prints_counts_and_spacing():
    """The layer example reports spacing equal to each radius and centres one radius above."""
    out = run(ROOT / "examples" / "sphere_layers.py")
    assert "r = 0.7 mm, spacing 0.700 / 0.700 mm, centres 0.700-0.700 mm" in out
    assert "r = 0.8 mm, spacing 0.800 / 0.800 mm, centres 0.800-0.800 mm" in out


def test_compare_searches_example_finds_them_equal():
    """Along a real run, the culled and the all-pairs search agree on every compared state."""
    out = run(ROOT / "examples" / "compare_searches.py", "--until", "0.5")
    checked = re.search(r"same pairs in (\d+) of (\d+)", out)
    assert checked and checked.group(1) == checked.group(2) and int(checked.group(2)) > 0


def test_dual_arm_example_prints_displacements_and_forces():
    """The dual-arm example prints, per grasp, the centroid displacement and the peak force."""
    out = run(ROOT / "examples" / "dual_arm_sequential.py", "--duration", "0.7")
    assert "EE-1 on TM-1:" in out and "robot centroid displacement" in out and "peak contact force" in out
