"""Ensembles: a scenario run from starts perturbed within a stated tolerance, and the
statistics and outcome classes across its members."""

import csv
import json
from dataclasses import astuple

import numpy as np
import pytest
from conftest import CASE_I, ROOT

import spotsim
from spotsim.assemble.model import with_start
from spotsim.cli import ensemble_exit, main
from spotsim.errors import SpotsimError
from spotsim.studies import ensemble as ens
from spotsim.studies import runs
from spotsim.studies.ensemble import EnsembleResult, Start, member_scenario, member_task, perturbed_starts
from spotsim.studies.runner import Record, keep_model
from spotsim.studies.runs import run_task

#: Case I at the default step: a whole member runs in well under a second.
SHORT_S = 0.6  # s simulated where a member need not complete: past first contact (~0.43 s)


def comparable(summary: dict) -> dict:
    """A summary without what differs between two runs of the same thing: the wall time."""
    return {k: v for k, v in summary.items() if k != "wall_time_s"}


def rows(e: EnsembleResult) -> list[dict]:
    return [{k: v for k, v in r.items() if k != "wall_time_s"} for r in e.summary["rows"]]


def same_fields(a, b) -> bool:
    """Whether two compiled Models' fields hold the same values (named tuples and structures
    of arrays)."""
    from spotsim.structs import StructProxy

    if isinstance(a, StructProxy):
        return same_fields(a.view(), b.view())
    if isinstance(a, tuple):
        return len(a) == len(b) and all(same_fields(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and np.array_equal(a, b)
    return a == b


def test_the_same_seed_gives_the_same_starts_and_another_seed_others(case_I):
    """Starts depend on the seed alone, and the first k members are the same whatever n."""
    a, b = perturbed_starts(case_I, 6, seed=3), perturbed_starts(case_I, 6, seed=3)
    assert a == b and perturbed_starts(case_I, 4, seed=3) == a[:4]
    assert perturbed_starts(case_I, 6, seed=4)[1:] != a[1:]


@pytest.mark.parametrize("config", ["single_arm_case_I.yaml", "dual_arm_sequential.yaml"])
def test_starts_lie_within_the_tolerances(config):
    """Member 0 is the scenario's start; every other member's module starts lie within
    +-offset_tol_mm and +-rpy_tol_deg of it on each axis, and each axis is perturbed."""
    s = spotsim.load_scenario(ROOT / "config" / config)
    starts = perturbed_starts(s, 200, seed=0, offset_tol_mm=0.01, rpy_tol_deg=0.02)
    for name, m in spotsim.scenario.modules_of(s).items():
        assert starts[0].offsets_mm[name] == m.initial_offset_mm and starts[0].rpy_deg[name] == m.initial_rpy_deg
        d_off = np.array([st.offsets_mm[name] for st in starts[1:]]) - m.initial_offset_mm
        d_rpy = np.array([st.rpy_deg[name] for st in starts[1:]]) - m.initial_rpy_deg
        assert np.all(np.abs(d_off) <= 0.01) and np.all(np.abs(d_rpy) <= 0.02)
        # 199 uniform draws reach beyond half the tolerance on each side of each axis
        assert np.all(d_off.max(axis=0) > 0.005) and np.all(d_off.min(axis=0) < -0.005)
        assert np.all(d_rpy.max(axis=0) > 0.01) and np.all(d_rpy.min(axis=0) < -0.01)



def test_the_one_axis_family_moves_one_coordinate_per_member_in_turn():
    """In the one_axis family member i moves only coordinate (i - 1) mod 6 of each module, by
    the draw the all-axes family gives it there; an unknown family is refused."""
    s = spotsim.load_scenario(ROOT / "config" / "dual_arm_sequential.yaml")
    every, one = perturbed_starts(s, 14, seed=5), perturbed_starts(s, 14, seed=5, family="one_axis")
    assert one[0] == every[0]
    for name, m in spotsim.scenario.modules_of(s).items():
        nominal = np.array([*m.initial_offset_mm, *m.initial_rpy_deg])
        for i in range(1, 14):
            d_one = np.array([*one[i].offsets_mm[name], *one[i].rpy_deg[name]]) - nominal
            d_all = np.array([*every[i].offsets_mm[name], *every[i].rpy_deg[name]]) - nominal
            axis = (i - 1) % 6
            assert np.flatnonzero(d_one).tolist() == [axis] and d_one[axis] == d_all[axis]
    with pytest.raises(SpotsimError, match="family"):
        perturbed_starts(s, 3, family="diagonal")

@pytest.mark.parametrize("config", ["single_arm_case_I.yaml", "dual_arm_sequential.yaml"])
def test_a_start_swapped_into_a_model_is_the_model_built_from_it(config):
    """with_start gives bit for bit the q0 and finger openings of a fresh build_model of the
    perturbed scenario, and that build's compiled Model is the nominal one's: nothing else of a
    Model depends on the start (the openings at touch are computed with the module centred)."""
    s = spotsim.load_scenario(ROOT / "config" / config)
    nominal = spotsim.build_model(s)
    perturbed = member_scenario(s, perturbed_starts(s, 2, seed=7)[1])
    fresh, swapped = spotsim.build_model(perturbed), with_start(nominal, perturbed)
    assert not np.array_equal(nominal.q0, fresh.q0)
    assert np.array_equal(swapped.q0, fresh.q0) and swapped.scenario == perturbed
    assert swapped.spec == fresh.spec and swapped.urdf == fresh.urdf
    assert same_fields(tuple(map(astuple, swapped.fingers)), tuple(map(astuple, fresh.fingers)))
    assert same_fields(fresh.sim.fields, nominal.sim.fields)
    with pytest.raises(ValueError, match="more than the modules' starts"):
        with_start(nominal, spotsim.replace(perturbed, end_effector={"closing_speed_m_s": 0.02}))


@pytest.mark.parametrize("config", ["single_arm_case_I.yaml", "dual_arm_sequential.yaml"])
def test_a_member_on_the_shared_model_is_a_fresh_simulate_of_its_scenario(config):
    """A member run on the nominal Model with its start swapped in gives the summary of a
    fresh simulate() of its perturbed scenario, bit for bit (through the dual arm's weld too)."""
    s = spotsim.load_scenario(ROOT / "config" / config)
    start = perturbed_starts(s, 3, seed=11)[2]
    keep_model(spotsim.build_model(s))  # the nominal model a worker holds
    one = run_task(member_task(s, 2, start, keyed=False))
    fresh = spotsim.simulate(member_scenario(s, start))
    assert one.status == fresh.status == "completed"
    assert comparable(one.summary) == comparable(fresh.summary)


def test_the_same_seed_gives_the_same_results_serial_or_in_a_pool(case_I, model_I):
    """An ensemble rerun with the same seed, one process or two, gives the same members; its
    member 0 is the unperturbed scenario's run."""
    a = spotsim.ensemble(case_I, 3, seed=5, workers=1, model=model_I)
    b = spotsim.ensemble(case_I, 3, seed=5, workers=2, model=model_I)
    assert rows(a) == rows(b) and a.statuses == {"completed": 3}
    assert comparable(a.members[0].summary) == comparable(spotsim.simulate(case_I, model=model_I).summary)
    assert len({r["residual_norm_mm"] for r in rows(a)}) == 3  # the perturbations change the outcome


def test_a_failing_member_is_counted_and_the_others_run(case_I, model_I, monkeypatch):
    """A member whose run raises is reported as `exception` with the error; the pool's other
    members run to their own ends."""
    import spotsim.run as run

    real, bad = run.simulate, perturbed_starts(case_I, 4, seed=0)[2]

    def failing(scenario, **kw):
        if scenario.module.initial_offset_mm == bad.offsets_mm["module"]:
            raise RuntimeError("a bug in member 2")
        return real(scenario, **kw)

    monkeypatch.setattr(run, "simulate", failing)  # the forked workers inherit the patch
    e = spotsim.ensemble(case_I, 4, workers=2, model=model_I)
    assert [m.status for m in e.members] == ["completed", "completed", "exception", "completed"]
    assert "RuntimeError" in e.members[2].message and "a bug in member 2" in e.members[2].message
    assert e.classes["grasp"]["exception"] == {"count": 1, "fraction": 0.25}
    assert e.statistics["grasp"]["residual_norm_mm"]["count"] == 3


def _member(i, status, norm=None, roll=0.0, peak=50.0, completed=1.0):
    grasp = {"completed_s": completed if norm is not None else None,
             "residual_offset_mm": None if norm is None else [0.0, -norm, 0.0],
             "residual_offset_norm_mm": norm, "residual_rpy_deg": None if norm is None else [roll, 0.0, 0.0],
             "peak_force_norm_N": peak, "peak_torque_norm_Nm": 1.0}
    start = Start({"module": (0.0, -3.0, 0.0)}, {"module": (0.0, 0.0, 0.0)})
    summary = None if status == "interrupted" else {"grasps": [grasp], "sim_time_s": 1.0, "wall_time_s": 0.1}
    return Record(None, i, status, status, summary, about={"start": start.as_dict()})


def test_statistics_and_classes_of_hand_made_members(case_I):
    """On five completed members (two wedged by offset or by tilt), one incomplete, one diverged
    and one interrupted: percentiles by linear interpolation over the completed; classes over
    the members that ran, the interrupted left out."""
    from spotsim.status import WEDGED_OFFSET_MM, WEDGED_TILT_DEG

    tilt, off = WEDGED_TILT_DEG, WEDGED_OFFSET_MM
    members = [_member(0, "completed", 0.1, peak=10), _member(1, "completed", 0.2, peak=20),
               _member(2, "completed", 0.15, roll=-1.5 * tilt, peak=30),  # tilted: wedged
               _member(3, "completed", 1.5 * off, peak=40),  # off centre: wedged
               _member(4, "completed", 0.25, peak=50), _member(5, "incomplete"), _member(6, "diverged"),
               _member(7, "interrupted")]
    e = EnsembleResult(case_I, 0, 0.01, 0.01, members)
    peak = e.statistics["grasp"]["peak_force_norm_N"]
    assert peak == {"median": 30.0, "p10": 14.0, "p90": 46.0, "min": 10.0, "max": 50.0, "count": 5}
    assert e.statistics["grasp"]["residual_norm_mm"]["median"] == pytest.approx(0.2)
    assert e.statistics["grasp"]["residual_tilt_deg"]["max"] == pytest.approx(1.5 * tilt)
    assert e.classes["grasp"] == {"seated": {"count": 3, "fraction": 3 / 7}, "wedged": {"count": 2, "fraction": 2 / 7},
                                  "incomplete": {"count": 1, "fraction": 1 / 7},
                                  "diverged": {"count": 1, "fraction": 1 / 7}}
    assert e.statuses == {"completed": 5, "incomplete": 1, "diverged": 1, "interrupted": 1}
    assert ens.statistics([None, float("nan")])["count"] == 0


def test_the_exit_code_is_the_worst_members():
    """0 when every member completed; else the code of the worst status among them."""
    assert ensemble_exit({"completed": 4}, False) == 0
    assert ensemble_exit({"completed": 3, "incomplete": 1}, False) == 3
    assert ensemble_exit({"incomplete": 1, "diverged": 1}, False) == 4
    assert ensemble_exit({"diverged": 1, "exception": 1}, False) == 1
    assert ensemble_exit({"completed": 1, "interrupted": 3}, True) == 130


def test_the_command_line_writes_the_ensemble_and_exits_with_its_code(tmp_path, capsys):
    """`spotsim run --ensemble 3` on runs cut short by the time-out writes ensemble.json,
    members.csv and scenario.yaml, prints the table and exits 3 (incomplete); bad options
    exit 2 before anything runs."""
    out = tmp_path / "ens"
    code = main(["run", str(CASE_I), "--ensemble", "3", "--seed", "2", "--workers", "2", "--out", str(out),
                 "--quiet", "--set", f"simulation.duration_s={SHORT_S}"])
    assert code == 3
    doc = json.loads((out / "ensemble.json").read_text())
    assert doc["members"] == 3 and doc["seed"] == 2 and doc["statuses"] == {"incomplete": 3}
    assert doc["perturbation"]["offset_tol_mm"] == 0.01 and len(doc["starts"]) == 3
    assert doc["starts"][1]["module"]["initial_offset_mm"] == list(perturbed_starts(
        spotsim.load_scenario(CASE_I), 3, seed=2)[1].offsets_mm["module"])
    table = (out / "members.csv").read_text().splitlines()
    assert len(table) == 4 and table[0].startswith("member,status,module_offset_x_mm")
    assert (out / "scenario.yaml").exists() and "outcome" in capsys.readouterr().out
    assert doc["error_estimate"]["spread"]["source"] == "ensemble"  # member 0's bound: this ensemble's spread
    assert main(["run", str(CASE_I), "--ensemble", "0", "--out", str(tmp_path / "bad"), "--quiet"]) == 2


def test_ctrl_c_keeps_the_members_that_finished(tmp_path, monkeypatch):
    """Ctrl-C during member 2 stops the ensemble: members 0 and 1 are kept and written, the
    others are `interrupted`, and the command exits 130."""
    real = runs.run_task

    def interrupting(task, options):
        if task.index == 2:
            raise KeyboardInterrupt
        return real(task, options)

    monkeypatch.setattr(runs, "run_task", interrupting)
    out = tmp_path / "ens"
    code = main(["run", str(CASE_I), "--ensemble", "4", "--workers", "1", "--out", str(out), "--quiet",
                 "--set", f"simulation.duration_s={SHORT_S}"])
    doc = json.loads((out / "ensemble.json").read_text())
    assert code == 130 and doc["status"] == "interrupted"
    assert [s["status"] for s in doc["starts"]] == ["incomplete", "incomplete", "interrupted", "interrupted"]
    assert doc["classes"]["grasp"] == {"incomplete": {"count": 2, "fraction": 1.0}}


def test_an_interrupted_ensemble_started_again_runs_only_the_members_it_lacks(tmp_path, monkeypatch):
    """Ctrl-C during member 2 of 4: members 0 and 1 are in members.jsonl; the same command again
    runs members 2 and 3 only and gives the members an uninterrupted ensemble gives; under
    other code (another fingerprint) it runs them all again."""
    from spotsim.studies import runner as rn

    real = runs.run_task
    ran = []

    def interrupting(task, options):
        ran.append(task.index)
        if ran == [0, 1, 2]:  # the first command's third member
            raise KeyboardInterrupt
        return real(task, options)

    monkeypatch.setattr(runs, "run_task", interrupting)
    out = tmp_path / "ens"
    cmd = ["run", str(CASE_I), "--ensemble", "4", "--workers", "1", "--out", str(out), "--quiet",
           "--no-error-estimate", "--set", f"simulation.duration_s={SHORT_S}"]
    assert main(cmd) == 130 and ran == [0, 1, 2]
    assert len((out / ens.MEMBERS_FILE).read_text().splitlines()) == 2
    assert main(cmd) == 3 and ran == [0, 1, 2, 2, 3]  # incomplete (shortened), each member run once to its end
    resumed = json.loads((out / "ensemble.json").read_text())
    assert resumed["reused_members"] == 2 and resumed["statuses"] == {"incomplete": 4}
    fresh = tmp_path / "fresh"
    assert main([*cmd[:7], str(fresh), *cmd[8:]]) == 3
    def table(d):  # the members table, without the machine's wall times
        return [{k: v for k, v in r.items() if k != "wall_time_s"} for r in csv.DictReader(open(d / "members.csv"))]

    assert table(out) == table(fresh)
    monkeypatch.setattr(rn, "code_fingerprint", lambda: "other code")
    del ran[:]
    ran.append("other code")
    assert main(cmd) == 3 and ran == ["other code", 0, 1, 2, 3]
