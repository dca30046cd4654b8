"""Where spotsim's assets live and how XACRO becomes URDF (xacrodoc, no ROS)."""

from __future__ import annotations

import os
import sys
from functools import lru_cache
from pathlib import Path

from .errors import ModelError

#: Repository root: spotsim is installed editable (see README), so `urdf/` and `config/`
#: sit beside `src/`. SPOTSIM_ROOT overrides it for relocated assets.
ROOT = Path(os.environ.get("SPOTSIM_ROOT", Path(__file__).resolve().parents[2]))
URDF_DIR = ROOT / "urdf"
CONFIG_DIR = ROOT / "config"


@lru_cache(maxsize=1)
def example_robot_data_dir() -> Path:
    """The example-robot-data share directory (version 6 ships data only, under cmeel)."""
    for entry in [sys.prefix, *sys.path]:
        for sub in ("lib/python3.11/site-packages/cmeel.prefix/share", "cmeel.prefix/share"):
            candidate = Path(entry) / sub / "example-robot-data"
            if (candidate / "robots").is_dir():
                return candidate
    raise ModelError(
        "example-robot-data not found under any cmeel prefix; install it with "
        "`pip install example-robot-data`"
    )


def compile_xacro(path: Path, args: dict[str, object]) -> str:
    """Compile a XACRO file with substitution `args` into a URDF string.

    `$(find spotsim)` resolves to the repository root and `$(find example-robot-data)` to the
    installed robot data, so mesh paths come out absolute (file://).
    """
    from xacrodoc import XacroDoc, packages

    packages.update_package_cache(
        {"spotsim": str(ROOT), "example-robot-data": str(example_robot_data_dir())}
    )
    try:
        doc = XacroDoc.from_file(
            str(path), walk_up=False, subargs={k: str(v) for k, v in args.items()}
        )
        return doc.to_urdf_string()
    except Exception as e:  # xacro raises bare Exceptions of several kinds
        raise ModelError(f"{path}: XACRO compilation failed: {e}") from e


def xacro_arg_defaults(path: Path) -> dict[str, float]:
    """The `<xacro:arg name=... default=...>` declarations of a XACRO file, as floats."""
    import xml.etree.ElementTree as ET

    ns = "{http://www.ros.org/wiki/xacro}"
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as e:
        raise ModelError(f"{path}: cannot read XACRO: {e}") from e
    return {el.get("name"): float(el.get("default")) for el in root.iter(f"{ns}arg")}
