"""Kills at random moments never fake a result: 25 SIGKILLs across a run, an ensemble, a
stability study, a sweep and a replot, each at a random time within what the command takes
uncut. Afterwards every results directory either has no summary (ensemble.json,
stability.md, sweep.parquet) or a complete, loadable one, and every file it names is whole."""

from __future__ import annotations

import csv
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import CASE_I

import spotsim
from spotsim.results import FIGURES_SINGLE
from spotsim.studies import sweep as sw
from spotsim.studies.runner import read_records

KILLS = 25
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
SPOTSIM = [sys.executable, "-m", "spotsim.cli"]
SHORT = ["--set", "simulation.duration_s=0.6", "--quiet"]


def command(kind: str, out: Path) -> list[str]:
    return SPOTSIM + {
        "run": ["run", str(CASE_I), "--out", str(out), *SHORT],
        "ensemble": ["run", str(CASE_I), "--ensemble", "2", "--workers", "1", "--out", str(out), *SHORT],
        "study": ["study", "stability", str(CASE_I), "--cases", "baseline,E x100", "--duration", "0.6",
                  "--out", str(out), "--quiet"],
        "sweep": ["sweep", str(CASE_I), "--vary", "contact.restitution=0.7,0.8", "--workers", "1",
                  "--out", str(out), *SHORT],
        "plot": ["plot", str(out)],
    }[kind]


def png_whole(path: Path) -> bool:
    data = path.read_bytes()
    return data.startswith(b"\x89PNG\r\n\x1a\n") and data.endswith(b"IEND\xaeB`\x82")


def check_run(d: Path) -> str:
    """'none' or 'complete' (asserting it), for a run's results directory."""
    if not (d / "summary.json").exists():
        return "none"
    summary, ts = spotsim.read_results(d)
    assert summary["status"] in ("completed", "incomplete", "diverged", "interrupted")
    rows = list(csv.reader((d / "timeseries.csv").open()))
    assert len(rows) == len(ts["t"]) + 1 and all(len(r) == len(rows[0]) for r in rows)
    assert spotsim.load_scenario(d / "scenario.yaml").name == summary["scenario"]
    assert all(png_whole(d / "figures" / f) for f in FIGURES_SINGLE)
    return "complete"


def check_ensemble(d: Path) -> str:
    if not (d / "ensemble.json").exists():
        return "none"
    e = json.loads((d / "ensemble.json").read_text())
    members = list(csv.DictReader((d / "members.csv").open()))
    assert len(members) == e["members"] == 2
    return "complete"


def check_study(d: Path) -> str:
    rows = list(csv.reader((d / "stability.csv").open())) if (d / "stability.csv").exists() else []
    assert all(len(r) == len(rows[0]) for r in rows), "a row written in part"
    if not (d / "stability.md").exists():
        return "none"
    md = (d / "stability.md").read_text()
    assert len(rows) - 1 == 2 and all(f"| {r[0]} |" in md for r in rows[1:])
    return "complete"


def check_sweep(d: Path) -> str:
    records = read_records(d / sw.POINTS_FILE)  # a line cut by the kill is dropped, any other refused
    assert len(records) <= 2
    if not (d / "sweep.parquet").exists():
        return "none"
    import pandas as pd

    assert len(pd.read_parquet(d / "sweep.parquet")) == len(pd.read_csv(d / "sweep.csv")) == 2
    return "complete"


CHECK = {"run": check_run, "ensemble": check_ensemble, "study": check_study, "sweep": check_sweep,
         "plot": check_run}


def killed(cmd: list[str], after_s: float) -> None:
    """Run `cmd` in its own process group and SIGKILL the group after `after_s` (if still running)."""
    proc = subprocess.Popen(cmd, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        proc.wait(timeout=after_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    else:  # it ended first; its workers may not have
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_kills_at_random_times_leave_no_summary_or_a_complete_one(tmp_path):
    kinds = ["run"] * 8 + ["ensemble"] * 5 + ["study"] * 5 + ["sweep"] * 4 + ["plot"] * 3
    assert len(kinds) == KILLS
    uncut: dict[str, float] = {}
    complete_run = tmp_path / "complete"
    for kind in dict.fromkeys(kinds):  # each once to its end: its duration, and a complete result
        out = complete_run if kind in ("run", "plot") else tmp_path / f"uncut_{kind}"
        t0 = time.perf_counter()
        if kind != "plot" or not out.exists():
            assert subprocess.run(command(kind, out), env=ENV, capture_output=True).returncode in (0, 3)
        else:
            assert subprocess.run(command(kind, out), env=ENV, capture_output=True).returncode == 0
        uncut[kind] = time.perf_counter() - t0
        assert CHECK[kind](out) == "complete"
    rng = random.Random(20261124)
    outcomes: dict[str, dict[str, int]] = {k: {"none": 0, "complete": 0} for k in uncut}
    for i, kind in enumerate(kinds):
        out = tmp_path / f"kill_{i:02d}_{kind}"
        if kind == "plot":
            shutil.copytree(complete_run, out)
        killed(command(kind, out), rng.uniform(0.0, 1.0) * uncut[kind])
        outcomes[kind][CHECK[kind](out)] += 1
    print(f"uncut (s): { {k: round(v, 2) for k, v in uncut.items()} }; after the kills: {outcomes}")
    assert sum(sum(o.values()) for o in outcomes.values()) == KILLS
    assert outcomes["plot"]["complete"] == kinds.count("plot")  # a replot never spoils a complete result
