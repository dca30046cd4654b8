"""spotsim installs from a wheel: the scenes and scenarios ship inside the package and are found
from any directory."""

import os
import subprocess
import sys
import zipfile

import pytest
from conftest import ROOT


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    """The wheel of this checkout, built as pip builds it for a non-editable install."""
    out = tmp_path_factory.mktemp("wheel")
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", str(out), str(ROOT)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    (path,) = out.glob("spotsim-*.whl")
    return path


def test_wheel_ships_every_scene_and_scenario(wheel):
    """Every XACRO of urdf/ and every YAML of config/ is in the wheel, inside the package."""
    names = set(zipfile.ZipFile(wheel).namelist())
    for folder, pattern in (("urdf", "*.xacro"), ("config", "*.yaml")):
        for path in (ROOT / folder).glob(pattern):
            assert f"spotsim/{folder}/{path.name}" in names


def test_unpacked_wheel_validates_its_own_scenario_from_any_directory(wheel, tmp_path):
    """The package as the wheel installs it, run from a directory outside the checkout, finds
    its scenarios and scenes through importlib.resources and validates the default one."""
    site = tmp_path / "site"
    zipfile.ZipFile(wheel).extractall(site)
    env = {**os.environ, "PYTHONPATH": str(site)}
    env.pop("SPOTSIM_ROOT", None)
    where = subprocess.run([sys.executable, "-c", "from spotsim.assemble.assets import CONFIG_DIR, URDF_DIR;"
                            "print(CONFIG_DIR); print(URDF_DIR)"], cwd=tmp_path, env=env, capture_output=True,
                           text=True, timeout=120)
    assert where.returncode == 0, where.stderr
    config, urdf = where.stdout.split()
    assert config == str(site / "spotsim" / "config") and urdf == str(site / "spotsim" / "urdf")
    proc = subprocess.run([sys.executable, "-m", "spotsim.cli", "validate", f"{config}/single_arm_case_I.yaml"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert "name: single_arm_case_I" in proc.stdout
    # and by name, from the API and the command line alike
    proc = subprocess.run([sys.executable, "-c", "import spotsim; print(spotsim.load_scenario('case_III').name)"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0 and proc.stdout.split() == ["single_arm_case_III"], proc.stderr
    proc = subprocess.run([sys.executable, "-m", "spotsim.cli", "validate", "single_arm_case_II"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0 and "name: single_arm_case_II" in proc.stdout, proc.stderr


def test_output_into_a_closed_pipe_ends_quietly():
    """`spotsim validate case_I | head -1`: the reader gone, the command ends without a traceback
    or Python's 'Exception ignored' message, as a Unix filter does."""
    proc = subprocess.Popen([sys.executable, "-m", "spotsim.cli", "validate", "case_I"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    proc.stdout.close()  # before the scenario is loaded: its first write finds no reader
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 1 and err == b""
