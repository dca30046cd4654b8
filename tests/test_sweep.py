"""Sweeps: their points, their verdicts, and their runs on Dask (a local cluster and a real
scheduler with two workers), through a killed worker, an interruption and a killed sweep."""

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import CASE_I

from spotsim import ScenarioError, SpotsimError, load_scenario
from spotsim.cli import main
from spotsim.status import (
    DIVERGED,
    EXCEPTION,
    INCOMPLETE,
    NOT_CAPTURED,
    REJECTED,
    SEATED,
    WALL_LIMIT,
    WEDGED,
    WORKER_DIED,
    run_outcome,
)
from spotsim.studies import runner as rn
from spotsim.studies import sweep as sw
from spotsim.studies.runner import Runner, SchedulerLost, append_record, read_records
from spotsim.studies.runs import RunOptions, run_task

HERE = Runner("serial")  # fake runs, in the test's own process
#: Three short Case I points, x_a offset -1, 0 and 1 mm (each ~0.2 s and its companion).
VARY = ["module.initial_offset_mm.0=-1:1:3"]
#: Columns that depend on the machine or the worker, not on the physics.
NOT_PHYSICS = ("wall_time_s", "run_wall_time_s", "companion_wall_time_s", "worker")


def physics(table):
    """The table's physics: every column but wall times and workers, rows by key."""
    return table.drop(columns=[c for c in NOT_PHYSICS if c in table]).sort_values("key").reset_index(drop=True)


# ----------------------------------------------------------------------------- the points


def test_a_vary_axis_reads_a_range_or_a_list():
    assert sw.parse_vary("module.initial_offset_mm.1=-2:2:5") == ("module.initial_offset_mm.1",
                                                                  [-2.0, -1.0, 0.0, 1.0, 2.0])
    assert sw.parse_vary("friction.mu_k=0.1,0.2") == ("friction.mu_k", [0.1, 0.2])
    assert sw.parse_vary("simulation.integrator.velocity_tol_m_s=1e-6,2.5e-6")[1] == [1e-6, 2.5e-6]
    for bad in ("module.mass_kg", "module.mass_kg=1:2", "module.mass_kg=1:2:x", "module.mass_kg=1,,2"):
        with pytest.raises(ScenarioError):
            sw.parse_vary(bad)


def test_a_grid_is_every_combination_of_its_axes_in_order():
    spec = sw.spec_of(["module.initial_offset_mm.0=0,1", "module.initial_rpy_deg.2=-5:5:3"])
    points = spec.resolved()
    assert len(points) == 6
    assert points[0] == {"module.initial_offset_mm.0": 0, "module.initial_rpy_deg.2": -5.0}
    assert points[-1] == {"module.initial_offset_mm.0": 1, "module.initial_rpy_deg.2": 5.0}


def test_a_joined_axis_sets_its_keys_together():
    """`--vary a+b=...` is one axis: both key paths take each value together (both bevels of a
    groove), crossed with the other axes."""
    spec = sw.spec_of(["geometry.upper_bevel_deg+geometry.lower_bevel_deg=30:60:3", "module.initial_offset_mm.1=0,1"])
    assert spec.count() == 6
    assert spec.keys() == ["geometry.upper_bevel_deg", "geometry.lower_bevel_deg", "module.initial_offset_mm.1"]
    points = sw.resolve_points(CASE_I, spec)
    bevels = [(p.scenario.geometry.upper_bevel_deg, p.scenario.geometry.lower_bevel_deg) for p in points]
    assert bevels == [(30.0, 30.0), (30.0, 30.0), (45.0, 45.0), (45.0, 45.0), (60.0, 60.0), (60.0, 60.0)]


def test_space_filling_samples_are_seeded_and_fill_their_ranges(tmp_path):
    """A Latin hypercube puts exactly one of its n points in each of n equal bins of every
    axis; a Sobol sample is reproducible from its seed and stays within its ranges."""
    ranges = {"module.initial_offset_mm.0": [-10.0, 10.0], "module.initial_rpy_deg.0": [-30.0, 30.0]}
    lhs = sw.SweepSpec(sample={"method": "lhs", "n": 16, "seed": 3, "ranges": ranges}).resolved()
    for k, (lo, hi) in ranges.items():
        bins = np.floor((np.array([p[k] for p in lhs]) - lo) / (hi - lo) * 16).astype(int)
        assert sorted(bins) == list(range(16))
    path = tmp_path / "spec.yaml"
    path.write_text(f"sample: {{method: sobol, n: 8, seed: 1, ranges: {json.dumps(ranges)}}}\n")
    a, b = sw.SweepSpec.from_yaml(path).resolved(), sw.SweepSpec.from_yaml(path).resolved()
    assert a == b and len(a) == 8
    assert all(lo <= p[k] <= hi for p in a for k, (lo, hi) in ranges.items())


def test_bad_sweeps_are_refused_naming_the_key(tmp_path):
    with pytest.raises(ScenarioError, match="module.nothing: not a key path"):
        sw.resolve_points(CASE_I, sw.spec_of(["module.nothing=1,2"]))
    with pytest.raises(ScenarioError, match="not both"):
        sw.spec_of(VARY, sw.SweepSpec(points=[{"module.mass_kg": 2.0}]))
    spec = tmp_path / "bad.yaml"
    spec.write_text("sample: {method: halton, n: 4, ranges: {module.mass_kg: [1, 2]}}\n")
    with pytest.raises(ScenarioError, match="sample.method = halton"):
        sw.SweepSpec.from_yaml(spec)
    assert main(["sweep", str(CASE_I), "--vary", "module.nothing=1,2", "--out", str(tmp_path / "x")]) == 2


def test_more_points_than_the_budget_are_refused_before_they_are_made(tmp_path, capsys):
    """A range, a grid or a sample over the budget is refused naming --max-points, before its
    values or points exist (10**15 values would not fit in memory) and before any file."""
    from spotsim.studies import envelope as env

    with pytest.raises(ScenarioError, match="1000000000000000 runs, more than the budget of 10000: give --max-points"):
        sw.parse_vary("module.initial_offset_mm.1=-5:5:1000000000000000")
    out = tmp_path / "x"
    grid = ["--vary", "module.initial_offset_mm.0=-1:1:101", "--vary", "module.initial_offset_mm.1=-1:1:100"]
    assert main(["sweep", str(CASE_I), *grid, "--out", str(out)]) == 2
    assert "the sweep: 10100 runs, more than the budget of 10000" in capsys.readouterr().err
    spec = tmp_path / "many.yaml"
    spec.write_text("sample: {method: sobol, n: 20000, ranges: {module.mass_kg: [1, 2]}}\n")
    assert main(["sweep", str(CASE_I), "--spec", str(spec), "--max-points", "19999", "--out", str(out)]) == 2
    assert "20000 runs, more than the budget of 19999" in capsys.readouterr().err
    assert main(["envelope", str(CASE_I), "--rays", "100000", "--out", str(out)]) == 2
    assert "the envelope (at most)" in capsys.readouterr().err
    assert not out.exists()
    # the envelope's count is an upper bound of its bisection: here 2 rays x (1 + 6 halvings of 16 mm to 0.25 mm)
    assert env.Search(axes=("y",), planes=()).most_runs() == 14
    report = env.envelope(CASE_I, tmp_path / "y", env.Search(axes=("y",), planes=()), runner=HERE,
                          run=fake_run({"y": 0.1}))
    assert sum(len(r.probes) for r in report.rays) <= 14


def test_a_value_its_rule_refuses_makes_only_that_point_invalid():
    points = sw.resolve_points(CASE_I, sw.spec_of(["module.mass_kg=-1,2.768"]))
    assert points[0].scenario is None and "mass_kg" in points[0].problems[0]
    assert points[1].scenario is not None


def test_one_sequence_component_is_set_by_its_index():
    s = load_scenario(CASE_I, ["module.initial_offset_mm.1=2.5", "module.initial_rpy_deg.2=1.5"])
    assert s.module.initial_offset_mm == (0.0, 2.5, 0.0) and s.module.initial_rpy_deg == (0.0, 0.0, 1.5)
    with pytest.raises(ScenarioError, match="has 3 items: 3 is not one of 0..2"):
        load_scenario(CASE_I, ["module.initial_offset_mm.3=1"])


def test_verdicts():
    """A point's verdict is its run's outcome, the worst of its grasps', by the ensembles'
    thresholds (offset 0.38 mm, or `offset_mm`, a sweep's --precision-mm; tilt 1.25 deg)."""
    def grasp(e, tilt=0.01, done=True, in_grooves=True):
        return {"completed_s": 1.0 if done else None, "residual_offset_norm_mm": e, "in_grooves": in_grooves,
                "residual_rpy_deg": [tilt, 0.0, 0.0]}

    def summary(*grasps):
        return {"grasps": list(grasps)}

    assert run_outcome("completed", summary(grasp(0.01), grasp(0.37))) == SEATED
    assert run_outcome("completed", summary(grasp(0.01), grasp(0.39))) == WEDGED
    assert run_outcome("completed", summary(grasp(0.01, tilt=-1.3))) == WEDGED
    assert run_outcome("completed", summary(grasp(0.45)), offset_mm=0.5) == SEATED
    assert run_outcome("not captured", summary(grasp(0.01), grasp(12.0, in_grooves=False))) == NOT_CAPTURED
    assert run_outcome("incomplete", summary(grasp(0.01), grasp(None, done=False))) == INCOMPLETE
    assert run_outcome("diverged", None) == DIVERGED
    assert run_outcome(WALL_LIMIT, summary(0.1)) == ""
    assert run_outcome(EXCEPTION, None) == ""


def test_a_points_file_cut_by_a_kill_loses_only_its_last_line(tmp_path):
    path = tmp_path / sw.POINTS_FILE
    path.write_text(json.dumps({"key": "a", "status": "completed"}) + "\n" + '{"key": "b", "sta')
    assert list(read_records(path)) == ["a"]
    assert path.read_text().endswith("}\n")  # truncated to its last whole line


def test_a_foreign_points_file_is_refused_and_left_as_it_is(tmp_path, capsys):
    path = tmp_path / sw.POINTS_FILE
    text = json.dumps({"key": "a", "status": "completed"}) + "\nnot a record\n" + '{"key": "b", "sta'
    path.write_text(text)
    with pytest.raises(SpotsimError, match="line 2 is not a study's run record"):
        read_records(path)
    assert path.read_text() == text
    assert main(["sweep", str(CASE_I), "--vary", VARY[0], "--out", str(tmp_path), "--quiet"]) == 2
    assert "line 2 is not a study's run record" in capsys.readouterr().err and path.read_text() == text
    assert not (tmp_path / sw.SPEC_FILE).exists()


def test_a_point_that_raises_is_recorded_with_its_status(monkeypatch):
    import spotsim.run as run

    def broken(*args, **kwargs):
        raise RuntimeError("a bug")

    monkeypatch.setattr(run, "simulate", broken)
    point = sw.resolve_points(CASE_I, sw.spec_of(VARY))[0]
    record = run_task(point, RunOptions(companion=True))
    assert record.status == EXCEPTION and "RuntimeError raised by simulate: a bug" in record.message


def test_a_start_that_interpenetrates_runs_with_the_gap_that_clears_it_when_asked():
    """An envelope's probe (grow_gap): the start gap widened to the smallest of START_GAPS_MM at
    which fingers and groove clear, kept in the record; without it, the start is rejected."""
    from spotsim.studies.runs import START_GAPS_MM

    s = load_scenario(CASE_I, ["end_effector.start_gap_mm=1.0", "simulation.duration_s=0.3"])
    task = rn.Task(s, 0, "k", {"values": {}})
    plain, grown = run_task(task), run_task(task, RunOptions(grow_gap=True))
    assert plain.status == REJECTED and "interpenetrate" in plain.message and "start_gap_mm" not in plain.about
    assert grown.status != REJECTED and grown.about["start_gap_mm"] == START_GAPS_MM[0] == 12.0
    assert grown.about["values"] == {} and grown.summary is not None


# ----------------------------------------------------------------------------- on Dask


@pytest.fixture(scope="module")
def local(tmp_path_factory):
    """The three points on the default local cluster (two workers)."""
    out = tmp_path_factory.mktemp("sweep_local")
    return sw.run_sweep(CASE_I, sw.spec_of(VARY), out, runner=Runner(workers=2))


def test_a_sweep_writes_a_row_per_point_with_its_verdict_and_error_estimate(local):
    t = local.table
    assert len(t) == 3 and local.ran == 3 and not local.interrupted
    assert list(t["module.initial_offset_mm.0"]) == [-1.0, 0.0, 1.0]
    assert set(t["status"]) == {"completed"} and set(t["verdict"]) == {SEATED}
    assert (t["residual_norm_mm"] < sw.PRECISION_MM).all() and (t["peak_force_norm_N"] > 0).all()
    assert t["peak_force_error_N"].notna().all() and t["residual_error_mm"].notna().all()
    assert (local.out / "sweep.parquet").exists() and (local.out / "sweep.csv").exists()
    assert (local.out / "spec.yaml").exists()
    assert main(["plot", str(local.out)]) == 0  # a sweep's directory: its points against the varied key
    assert (local.out / "figures" / "sweep.png").read_bytes().startswith(b"\x89PNG")


def test_a_finished_sweep_started_again_runs_nothing(local):
    again = sw.run_sweep(CASE_I, sw.spec_of(VARY), local.out, runner=Runner(workers=2))
    assert again.ran == 0 and again.reused == 3
    assert physics(again.table).equals(physics(local.table))


@pytest.mark.parametrize("backend", ["processes", "serial"])
def test_a_sweep_on_a_pool_or_in_process_gives_the_local_clusters_table(local, tmp_path, backend):
    """The same three points on the runner's other backends: the same table, physics column by
    column."""
    other = sw.run_sweep(CASE_I, sw.spec_of(VARY), tmp_path, runner=Runner(backend, workers=2))
    assert other.ran == 3 and physics(other.table).equals(physics(local.table))


def test_a_point_computed_by_other_code_is_not_reused(local, monkeypatch):
    """A point's key covers spotsim's code: under other code (another fingerprint) none of the
    finished points matches the spec's, so a resumed sweep runs them all again."""
    done = read_records(local.out / sw.POINTS_FILE)
    assert {p.key for p in sw.resolve_points(CASE_I, sw.spec_of(VARY))} == set(done)
    monkeypatch.setattr(rn, "code_fingerprint", lambda: "other code")
    assert not {p.key for p in sw.resolve_points(CASE_I, sw.spec_of(VARY))} & set(done)


def test_an_existing_scheduler_with_two_workers_gives_the_local_clusters_table(local, tmp_path):
    """A real `dask scheduler` and two `dask worker` processes on localhost; the scheduler
    killed during a second sweep ends it with SchedulerLost, its finished points kept."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    file = tmp_path / "scheduler.json"
    bin_dir = Path(sys.executable).parent
    procs = [subprocess.Popen([str(bin_dir / "dask"), "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--no-dashboard", "--scheduler-file", str(file)], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)]
    try:
        for _ in range(300):
            if file.exists() and file.stat().st_size:
                break
            time.sleep(0.1)
        address = json.loads(file.read_text())["address"]
        for _ in range(2):
            procs.append(subprocess.Popen([str(bin_dir / "dask"), "worker", address, "--nthreads", "1",
                                           "--no-dashboard"], env=env, stdout=subprocess.DEVNULL,
                                          stderr=subprocess.DEVNULL, start_new_session=True))
        from distributed import Client

        with Client(address, timeout="60s") as c:
            c.wait_for_workers(2, timeout=120)
        remote = sw.run_sweep(CASE_I, sw.spec_of(VARY), tmp_path / "out", runner=Runner(scheduler=address))

        def kill_the_scheduler(record, written=[]):  # noqa: B006 - the count across calls
            written.append(record)
            if len(written) == 2:
                os.killpg(procs[0].pid, signal.SIGKILL)

        lost = tmp_path / "lost"
        with pytest.raises(SchedulerLost, match="2 of 5 points finished, kept in .* run the sweep again"):
            sw.run_sweep(CASE_I, sw.spec_of(["module.initial_offset_mm.0=-1:1:5"]), lost,
                         runner=Runner(scheduler=address), error_estimate=False, on_record=kill_the_scheduler)
        assert len(read_records(lost / sw.POINTS_FILE)) == 2
    finally:
        for p in procs:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    assert remote.ran == 3
    assert len(set(remote.table["worker"])) == 2  # both workers ran points
    assert physics(remote.table).equals(physics(local.table))


#: When the killer thread kills the first worker process it sees, s after it appears: within
#: its warm-up on this machine (the workers start in about 1 s and warm for 1-2 s). Whatever the
#: moment, the assertions hold: a lost worker costs at most the points it held.
KILL_IN_WARM_UP_S = 1.5


def test_killed_workers_leave_every_point_in_the_table_exactly_once(local, tmp_path):
    """One worker killed while it starts or warms up (a thread), another after the first
    point is written (`on_record`): every point has one record, and each that ran converged."""
    import threading

    import psutil

    killed = []

    def kill_a_starting_worker():
        deadline = time.time() + 120
        while time.time() < deadline:
            workers = [p for p in psutil.Process().children(recursive=True) if "spawn_main" in " ".join(p.cmdline())]
            if workers:
                time.sleep(KILL_IN_WARM_UP_S)
                workers[0].kill()
                killed.append(workers[0].pid)
                return
            time.sleep(0.01)

    def kill_a_worker(record):
        if len(killed) < 2 and record.worker not in killed:
            os.kill(record.worker, signal.SIGKILL)
            killed.append(record.worker)

    threading.Thread(target=kill_a_starting_worker, daemon=True).start()
    spec = sw.spec_of(["module.initial_offset_mm.0=-1:1:5"])
    report = sw.run_sweep(CASE_I, spec, tmp_path, runner=Runner(workers=2), on_record=kill_a_worker)
    assert len(killed) == 2
    keys = [json.loads(line)["key"] for line in (tmp_path / sw.POINTS_FILE).read_text().splitlines()]
    assert len(keys) == len(set(keys)) == 5
    assert sorted(report.table["key"]) == sorted(keys)
    ran = report.table[report.table["status"] != WORKER_DIED]
    assert set(ran["verdict"]) == {SEATED}


def test_an_interrupted_sweep_resumes_with_only_its_missing_points(local, tmp_path):
    def stop_after_two(record, seen=[]):  # noqa: B006 - the count across calls
        seen.append(record.key)
        if len(seen) == 2:
            raise KeyboardInterrupt

    first = sw.run_sweep(CASE_I, sw.spec_of(VARY), tmp_path, runner=Runner(workers=2), on_record=stop_after_two)
    assert first.interrupted and len(first.table) == 2
    resumed = sw.run_sweep(CASE_I, sw.spec_of(VARY), tmp_path, runner=Runner(workers=2))
    assert resumed.ran == 1 and resumed.reused == 2 and not resumed.interrupted
    assert physics(resumed.table).equals(physics(local.table))


def test_failed_points_get_their_status_and_the_sweep_exits_0(tmp_path, capsys):
    spec = tmp_path / "spec.yaml"
    spec.write_text("points:\n  - {module.mass_kg: -1.0}\n  - {module.mass_kg: 2.768}\n")
    code = main(["sweep", str(CASE_I), "--spec", str(spec), "--out", str(tmp_path / "out"), "--workers", "1",
                 "--wall-limit", "0.001", "--quiet"])
    assert code == 0
    text = capsys.readouterr().out
    assert "2 without a verdict" in text
    import pandas as pd

    t = pd.read_parquet(tmp_path / "out" / "sweep.parquet")
    assert list(t["status"]) == [REJECTED, WALL_LIMIT]
    assert "mass_kg" in t["message"][0] and "wall-time budget of 0.001 s spent" in t["message"][1]


def test_a_sweep_killed_with_sigkill_resumes_and_keeps_each_point_once(tmp_path):
    """A sweep killed (SIGKILL, its workers with it) right after its second point is written
    keeps those two; run again over its directory, it runs the other three, each once."""
    out = tmp_path / "out"
    kill_after_two = (
        "import os, signal\n"
        "from spotsim.studies import sweep as sw\n"
        "from spotsim.studies.runner import Runner\n"
        "written = []\n"
        "def on_record(record):\n"
        "    written.append(record)\n"
        "    if len(written) == 2:\n"
        "        os.killpg(0, signal.SIGKILL)\n"
        f"sw.run_sweep({str(CASE_I)!r}, sw.spec_of(['module.initial_offset_mm.0=-1:1:5']), {str(out)!r},\n"
        "             runner=Runner(workers=1), error_estimate=False, on_record=on_record)\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    proc = subprocess.run([sys.executable, "-c", kill_after_two], env=env, stdout=subprocess.DEVNULL,
                          stderr=subprocess.DEVNULL, start_new_session=True, timeout=600)
    assert proc.returncode == -signal.SIGKILL
    points = out / sw.POINTS_FILE
    assert len(read_records(points)) == 2
    cmd = [sys.executable, "-m", "spotsim.cli", "sweep", str(CASE_I), "--vary", "module.initial_offset_mm.0=-1:1:5",
           "--out", str(out), "--workers", "1", "--quiet", "--no-error-estimate"]
    assert subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode == 0
    keys = [json.loads(line)["key"] for line in points.read_text().splitlines()]
    assert len(keys) == len(set(keys)) == 5
    import pandas as pd

    assert len(pd.read_parquet(out / "sweep.parquet")) == 5


# ----------------------------------------------------------------------------- the envelope


def fake_run(boundary: dict):
    """A stand-in for a run: captured (complete, residual 0.01 mm) while each axis' start lies
    inside its `boundary`, else not captured; no simulation."""
    def run(point):
        inside = all(abs(point.about["values"][sw_axis(a)]) < b for a, b in boundary.items())
        summary = {"grasps": [{"residual_offset_norm_mm": 0.01, "completed_s": 1.0, "in_grooves": True,
                               "residual_rpy_deg": [0.01, 0.0, 0.0]} if inside else
                              {"residual_offset_norm_mm": None, "completed_s": None}]}
        return rn.Record(point.key, point.index, "completed" if inside else "incomplete", "", summary, 0.0,
                         about=point.about)
    return run


def sw_axis(a):
    from spotsim.studies.envelope import AXES

    return AXES[a][0]


def test_bisection_finds_a_known_boundary_in_log_runs(tmp_path):
    """A boundary at x = +3.7 / -2.2 mm and roll 12.3 deg: each ray brackets it within its
    resolution in 1 + ceil(log2(limit / resolution)) runs; a resumed envelope runs nothing."""
    from spotsim.studies import envelope as env

    run = fake_run({"x": 3.7, "roll": 12.3})
    asym = lambda point: run(point) if point.about["values"][sw_axis("x")] >= 0 else fake_run({"x": 2.2})(point)  # noqa: E731
    report = env.envelope(CASE_I, tmp_path, env.Search(axes=("x", "roll"), planes=()), runner=HERE, run=asym)
    by = {r.name: r for r in report.rays}
    for name, true in (("x+", 3.7), ("x-", 2.2), ("roll+", 12.3), ("roll-", 12.3)):
        r = by[name]
        assert r.lo < true <= r.hi and r.hi - r.lo <= r.resolution
        assert len(r.probes) == 1 + math.ceil(math.log2(r.limit / r.resolution))
        assert r.beyond == INCOMPLETE  # its fake run never closed
    again = env.envelope(CASE_I, tmp_path, env.Search(axes=("x", "roll"), planes=()), runner=HERE, run=asym)
    assert again.runs == 0 and [r.boundary for r in again.rays] == [r.boundary for r in report.rays]
    text = (tmp_path / "envelope.md").read_text()
    assert "| x (mm) | ±10 |" in text


def test_a_ray_captured_at_its_limit_has_its_boundary_beyond(tmp_path):
    from spotsim.studies import envelope as env

    report = env.envelope(CASE_I, tmp_path, env.Search(axes=("y",), planes=()), runner=HERE, run=fake_run({"y": 100.0}))
    assert all(r.boundary == math.inf and len(r.probes) == 1 for r in report.rays)


def test_an_envelopes_figure_is_drawn_from_its_files(tmp_path):
    """`spotsim plot` on an envelope's directory draws its planes from envelope.csv and its
    points file; a directory without its runs is one line and exit 2."""
    from spotsim.studies import envelope as env

    env.envelope(CASE_I, tmp_path, env.Search(axes=("x", "y"), planes=(("x", "y"),), plane_rays=8), runner=HERE,
                 run=fake_run({"x": 3.7, "y": 5.0}))
    assert main(["plot", str(tmp_path)]) == 0 and (tmp_path / "envelope.png").stat().st_size > 0
    (tmp_path / "points.jsonl").unlink()
    assert main(["plot", str(tmp_path)]) == 2


def test_bad_envelopes_are_refused(tmp_path):
    assert main(["envelope", str(CASE_I), "--axes", "q", "--out", str(tmp_path)]) == 2
    assert main(["envelope", str(CASE_I), "--resolution-mm", "0", "--out", str(tmp_path)]) == 2
    assert main(["envelope", str(CASE_I.parent / "dual_arm_sequential.yaml"), "--out", str(tmp_path)]) == 2


def test_near_the_boundary_the_capture_fraction_is_counted_over_perturbed_starts(tmp_path):
    """Ensembles at each ray's bracket: the stand-in captures every member inside, none outside."""
    from spotsim.studies import envelope as env

    report = env.envelope(CASE_I, tmp_path, env.Search(axes=("x",), planes=(), members=4), runner=HERE,
                          run=fake_run({"x": 3.7}))
    for r in report.rays:
        assert r.chance[r.lo] == (4, 4) and r.chance[r.hi] == (0, 4)
    assert "capture_fraction_at_captured" in (tmp_path / "envelope.csv").read_text()


def test_a_point_that_cannot_be_written_is_cut_back_off_and_one_clear_error(tmp_path, monkeypatch):
    """A full disk while a point's line is written: the part written is cut back off (the file
    keeps whole lines, and resumes), and the sweep stops with one line naming the file."""
    import errno

    points = tmp_path / sw.POINTS_FILE
    first = rn.Record("a", 0, "completed", "")
    append_record(points, first)
    real_write, calls = os.write, []

    def full(fd, data):  # writes 10 bytes, then the disk is full
        calls.append(len(data))
        if len(calls) == 1:
            return real_write(fd, bytes(data[:10]))
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(rn.os, "write", full)
    with pytest.raises(SpotsimError, match=f"{points}: cannot write a finished run: No space left on device; "
                                           "the runs before it are kept"):
        append_record(points, rn.Record("b", 1, "completed", ""))
    monkeypatch.undo()
    assert list(read_records(points)) == ["a"] and points.read_text().count("\n") == 1
