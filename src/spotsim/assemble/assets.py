"""Where spotsim's assets live and how XACRO becomes URDF (xacrodoc, no ROS)."""

from __future__ import annotations

import os
import sys
import sysconfig
from functools import lru_cache
from pathlib import Path

from ..errors import ModelError
from ..paths import CONFIG_DIR, ROOT, URDF_DIR  # noqa: F401 (where the assets are: `paths`)


@lru_cache(maxsize=1)
def example_robot_data_dir() -> Path:
    """The example-robot-data share directory (version 6 ships data only, under cmeel)."""
    for entry in [sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"], *sys.path]:
        candidate = Path(entry) / "cmeel.prefix" / "share" / "example-robot-data"
        if (candidate / "robots").is_dir():
            return candidate
    raise ModelError(
        "example-robot-data not found under any cmeel prefix; install it with "
        "`pip install example-robot-data`"
    )


#: example-robot-data's arm URDFs, by the `arm_model` names scenarios use.
ARM_URDFS = {"z1": "robots/z1_description/urdf/z1.urdf", "ur3": "robots/ur_description/urdf/ur3_robot.urdf",
             "ur5": "robots/ur_description/urdf/ur5_robot.urdf", "ur10": "robots/ur_description/urdf/ur10_robot.urdf"}


def generated_dir() -> Path:
    """Where spotsim writes the arm descriptions it derives (a per-user cache)."""
    path = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "spotsim" / "generated"
    path.mkdir(parents=True, exist_ok=True)
    return path


def prefixed_arm(arm: str, prefix: str) -> Path:
    """An example-robot-data arm as a URDF fragment whose links and joints carry `prefix`.

    example-robot-data ships each arm as one URDF with fixed names, so two copies in one robot
    would clash. Only links and joints are kept (no world link, transmissions or plugins); the
    fragment is written to `generated_dir()` and included by the robot's XACRO as
    `$(find spotsim_generated)/<arm>_<prefix>.urdf`.
    """
    import xml.etree.ElementTree as ET

    source = example_robot_data_dir() / ARM_URDFS[arm]
    try:
        root = ET.parse(source).getroot()
    except (OSError, ET.ParseError) as e:
        raise ModelError(f"{source}: cannot read the {arm} URDF: {e}") from e
    out = ET.Element("robot", {"name": f"{prefix}{arm}"})
    for el in root:
        if el.tag == "link" and el.get("name") != "world":
            el.set("name", prefix + el.get("name"))
            out.append(el)
        elif el.tag == "joint" and el.find("parent").get("link") != "world":
            el.set("name", prefix + el.get("name"))
            for tag in ("parent", "child"):
                el.find(tag).set("link", prefix + el.find(tag).get("link"))
            out.append(el)
    path = generated_dir() / f"{arm}_{prefix}.urdf"
    text = ET.tostring(out, encoding="unicode")
    if not path.exists() or path.read_text() != text:
        tmp = path.with_suffix(".tmp")
        tmp.write_text(text)
        os.replace(tmp, path)
    return path


def compile_xacro(path: Path, args: dict[str, object]) -> str:
    """Compile a XACRO file with substitution `args` into a URDF string.

    `$(find spotsim)` resolves to the repository root and `$(find example-robot-data)` to the
    installed robot data, so mesh paths come out absolute (file://). The same file with the
    same arguments compiles once per process (xacro takes ~0.1 s, most of a scene's build).
    """
    return _compile_xacro(str(path), tuple(sorted((k, str(v)) for k, v in args.items())))


@lru_cache(maxsize=64)
def _compile_xacro(path: str, args: tuple[tuple[str, str], ...]) -> str:
    from xacrodoc import XacroDoc, packages

    packages.update_package_cache(
        {"spotsim": str(ROOT), "example-robot-data": str(example_robot_data_dir()),
         "spotsim_generated": str(generated_dir())}
    )
    try:
        doc = XacroDoc.from_file(path, walk_up=False, subargs=dict(args))
        return doc.to_urdf_string()
    except Exception as e:  # xacro raises bare Exceptions of several kinds
        raise ModelError(f"{path}: XACRO compilation failed: {e}") from e


def _number_or_text(text: str):
    try:
        return float(text)
    except ValueError:
        return text


def xacro_arg_defaults(path: Path) -> dict[str, float | str]:
    """The `<xacro:arg name=... default=...>` declarations of a XACRO file (numbers as floats)."""
    import xml.etree.ElementTree as ET

    ns = "{http://www.ros.org/wiki/xacro}"
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as e:
        raise ModelError(f"{path}: cannot read XACRO: {e}") from e
    return {el.get("name"): _number_or_text(el.get("default")) for el in root.iter(f"{ns}arg")}
