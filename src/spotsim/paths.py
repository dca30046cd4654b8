"""Where spotsim's assets live (its `urdf/` and `config/`), and the scenarios it ships, by name."""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

from .errors import ModelError


def assets_root() -> Path:
    """The directory holding spotsim's `urdf/` and `config/`: inside the installed package (a
    wheel ships them there), else the checkout's top level (an editable install). The
    environment variable SPOTSIM_ROOT overrides both."""
    if os.environ.get("SPOTSIM_ROOT"):
        return Path(os.environ["SPOTSIM_ROOT"])
    packaged = resources.files("spotsim")
    if packaged.joinpath("urdf").is_dir():
        return Path(str(packaged))
    checkout = Path(__file__).resolve().parents[2]
    if (checkout / "urdf").is_dir():
        return checkout
    raise ModelError(f"spotsim's urdf/ is neither in the package ({packaged}) nor in a checkout ({checkout}); "
                     "reinstall spotsim")


ROOT = assets_root()
URDF_DIR = ROOT / "urdf"
CONFIG_DIR = ROOT / "config"


def shipped_scenarios() -> dict[str, Path]:
    """The scenarios spotsim ships (config/*.yaml), by name (the file's stem)."""
    return {p.stem: p for p in sorted(CONFIG_DIR.glob("*.yaml"))}


def scenario_file(arg: str | Path) -> Path:
    """The scenario file `arg` names: a file that exists, as given; else a shipped scenario by
    its name (`single_arm_case_III`, with or without `.yaml`) or by the end of its name after an
    underscore when only one ends so (`case_III`). A YAML path that does not exist is returned
    as given (reading it reports it); a name that no shipped scenario has, or that several end
    with, is a ScenarioError."""
    from .errors import ScenarioError

    path = Path(arg)
    if path.exists() or len(path.parts) != 1:
        return path
    name = path.name.removesuffix(".yaml")
    shipped = shipped_scenarios()
    if name in shipped:
        return shipped[name]
    ending = [stem for stem in shipped if stem.endswith("_" + name)]
    if len(ending) > 1:
        raise ScenarioError([f"{arg}: names several shipped scenarios ({', '.join(ending)}): give the whole name"])
    if ending:
        return shipped[ending[0]]
    if path.suffix not in (".yaml", ".yml"):
        raise ScenarioError([f"{arg}: no such file, and no shipped scenario of that name (`spotsim list` names them)"])
    return path


#: The longest name of the overrides in a default results directory; longer ones end in a hash.
CHANGES_NAME_MAX = 60


def results_dir(name: str, sets=(), *sub: str) -> Path:
    """The default results directory of a scenario `name` run with the overrides `sets`
    (`--set key.path=value`): results/<name>, or, with overrides, results/<name>+<each key's
    last part=value, joined by +>, so that a changed run never lands in (and overwrites) the
    scenario's own directory; a name over CHANGES_NAME_MAX characters is cut and ends in a hash
    of the overrides. `sub`: further parts (ensemble, sweep, envelope)."""
    import hashlib
    import re

    if sets:
        parts = []
        for s in sets:
            key, _, value = str(s).partition("=")
            parts.append(re.sub(r"[^A-Za-z0-9._=,+-]", "", f"{key.strip().rsplit('.', 1)[-1]}={value.strip()}"))
        changes = "+".join(parts)
        if len(changes) > CHANGES_NAME_MAX:
            digest = hashlib.sha256("\n".join(map(str, sets)).encode()).hexdigest()[:8]
            changes = f"{changes[:CHANGES_NAME_MAX - 9]}-{digest}"
        name = f"{name}+{changes}"
    return Path("results", name, *sub)
