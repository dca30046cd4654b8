"""One run of a study and what a study keeps of it, compared and written out.

A run may be given a wall-time budget (`run.simulate`'s, status `wall limit`). Studies write
their CSV a row at a time as runs finish, so that Ctrl-C keeps what was computed.
"""

from __future__ import annotations

import csv
import math
import os
import time
import traceback
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np

from ..errors import SpotsimError
from ..scenario import replace
from ..status import (
    COMPARABLE,
    COMPLETED,
    EXCEPTION,
    NOT_CAPTURED,
    REJECTED,
    WALL_LIMIT,
    run_outcome,
)
from .runner import Record, Task

# ----------------------------------------------------------------------------- a scenario's variants


def step_scaled(s, factor: float):
    """`s` with its dynamics steps `factor` times as long, or None where that is not a whole
    number of substeps. Fixed steps: substeps / factor. adaptive_euler: its steps go as
    velocity_tol^(1/2) and its onset guard's as onset_depth, so velocity_tol x factor^2 and
    onset_depth x factor. dopri5: rtol and atol x factor."""
    i = s.simulation.integrator
    if i.method == "dopri5":
        return replace(s, simulation={"integrator": {"rtol": i.rtol * factor, "atol": i.atol * factor}})
    if i.method == "adaptive_euler":
        return replace(s, simulation={"integrator": {"velocity_tol_m_s": i.velocity_tol_m_s * factor**2,
                                                     "onset_depth_m": i.onset_depth_m * factor}})
    substeps = s.simulation.substeps / factor
    if substeps < 1 or not math.isclose(substeps, round(substeps)):
        return None
    return replace(s, simulation={"substeps": round(substeps)})


def companion(scenario):
    """The scenario with steps twice as long (`step_scaled`), or None when the integrator
    has none to offer: rk4 and dopri5, which are not first order, or symplectic_euler at an odd
    number of substeps."""
    if scenario.simulation.integrator.method not in ("symplectic_euler", "adaptive_euler"):
        return None
    return step_scaled(scenario, 2.0)


#: The start gaps tried, mm, for a misaligned start that interpenetrates at the scenario's.
START_GAPS_MM = (12.0, 15.0, 20.0, 25.0, 30.0, 40.0)


def clearing_gap(s) -> float | None:
    """The smallest of START_GAPS_MM at which `s`'s fingers and groove do not interpenetrate at
    the start, mm (None if none does)."""
    from ..assemble.model import build_model
    from ..run import initial_contacts

    for gap in START_GAPS_MM:
        if gap > s.end_effector.start_gap_mm:
            wider = replace(s, end_effector={"start_gap_mm": gap})
            if not initial_contacts(build_model(wider)):
                return gap
    return None


def widened(s, gap_mm: float):
    """`s` with its fingers starting `gap_mm` from a centred groove, and as much more time as
    the longer travel takes, for the run and for every grasp phase."""
    extra = (gap_mm - s.end_effector.start_gap_mm) * 1e-3 / s.end_effector.closing_speed_m_s
    return replace(s, end_effector={"start_gap_mm": gap_mm}, simulation={"duration_s": s.simulation.duration_s + extra},
                   completion={"phase_timeout_s": s.completion.phase_timeout_s + extra})


# ----------------------------------------------------------------------------- one run


@dataclass(frozen=True)
class RunOptions:
    """How `run_task` runs a task: named `source`, within the wall-time budget `wall_limit_s`
    (None: none); with `companion`, the error estimate's companion run too, within what is
    left of the budget (`companion`: the same scenario with steps twice as long), its summary
    kept as `about["companion"]` for the study's error estimate (`estimate.error_estimate`);
    with `grow_gap`, a start whose fingers and groove interpenetrate runs with the start gap
    that clears it (`clearing_gap`), kept as `about["start_gap_mm"]`."""

    source: str = "<study>"
    wall_limit_s: float | None = None
    companion: bool = False
    grow_gap: bool = False


def run_task(task: Task, options: RunOptions = RunOptions()) -> Record:
    """Build, check and simulate a task's scenario here: every study's run. Its record has the
    run's status, message and summary, the wall time of all of it and, in `about`, the
    model's predicted stable step (`prediction`), whether every recorded number is finite
    (`finite`) and, with `options.companion`, the companion's summary. Never raises but on
    the user's Ctrl-C: a scenario that cannot be built or whose fingers and groove
    interpenetrate is `rejected`; anything raised is `exception` (a bug the study reports,
    named with its stage and where it was raised)."""
    from ..run import check_start, initial_contacts, simulate
    from ..sim.stability import predict_step
    from .runner import model_for

    t0, about = time.perf_counter(), dict(task.about)

    def ended(status, message, summary=None):
        return Record(task.key, task.index, status, message, summary, time.perf_counter() - t0, os.getpid(), about)

    if task.scenario is None:
        return ended(REJECTED, "; ".join(task.problems))
    scenario, source = task.scenario, options.source
    try:
        model = model_for(scenario, source)
        if options.grow_gap and initial_contacts(model) and (gap := clearing_gap(scenario)) is not None:
            scenario = widened(scenario, gap)
            model = model_for(scenario, source)
            about["start_gap_mm"] = gap
        about["prediction"] = predict_step(model)
        check_start(model, source)
    except SpotsimError as e:  # the scenario's or its start's own problem, found before anything ran
        return ended(REJECTED, str(e).replace("\n", "; "))
    except Exception as e:  # noqa: BLE001 - a bug: the study reports it and goes on
        return ended(EXCEPTION, raised(e, "the start"))
    try:
        result = simulate(scenario, model=model, source=source, wall_limit_s=options.wall_limit_s)
    except Exception as e:  # noqa: BLE001 - simulate must never raise: the study reports it rather than dies of it
        return ended(EXCEPTION, raised(e, "simulate"))
    about["finite"] = all(bool(np.all(np.isfinite(a))) for a in result.timeseries.values()
                          if np.issubdtype(np.asarray(a).dtype, np.floating))
    summary = result.summary
    other = companion(scenario) if options.companion and summary["status"] != WALL_LIMIT else None
    if other is not None:
        left = None if options.wall_limit_s is None else max(options.wall_limit_s - (time.perf_counter() - t0), 1e-3)
        try:
            twin = simulate(other, model=model_for(other, source), source=source, wall_limit_s=left)
        except Exception as e:  # noqa: BLE001 - the companion's scene is the run's: a bug to report
            return ended(EXCEPTION, raised(e, "the error estimate's companion"))
        about["companion"] = twin.summary
    return ended(summary["status"], summary["message"], summary)


def raised(e: Exception, stage: str) -> str:
    """The message of an exception out of a run's `stage`: its type, text and where. Ctrl-C
    landing in the run is the user's: KeyboardInterrupt."""
    if _caused_by_ctrl_c(e):
        raise KeyboardInterrupt from e
    where = traceback.extract_tb(e.__traceback__)[-1]
    return f"{type(e).__name__} raised by {stage}: {e} ({Path(where.filename).name}:{where.lineno})"


@dataclass
class Outcome:
    """What the accuracy and stability studies compare of one run (`of` its record). Per grasp:
    the offset of O_b from O_a at the end (the residual offset of a completed grasp, mm), the
    peak contact force norm (N) and, on a free-floating robot, the centroid displacement (mm);
    None where the grasp never ran."""

    status: str
    message: str
    wall_time_s: float = math.nan
    sim_time_s: float = math.nan
    completed_s: float = math.nan
    steps: float = math.nan
    force_evaluations: float = math.nan
    rejected_steps: float = math.nan
    offsets: list = field(default_factory=list)
    peaks: list = field(default_factory=list)
    centroids: list = field(default_factory=list)
    linear_drift_rel: float = math.nan
    angular_drift_rel: float = math.nan
    finite: bool = True  # every recorded number finite
    prediction: object = None  # stability.StepPrediction of the run's model
    outcome: str = ""  # the run's (`status.run_outcome`): '' when it did not end on its physics

    @property
    def comparable(self) -> bool:
        return self.status in COMPARABLE

    @classmethod
    def of(cls, r) -> Outcome:
        """What a study keeps of a run's record (`runner.Record`, as `run_task` makes it)."""
        from ..sim.stability import StepPrediction

        s, prediction = r.summary, r.about.get("prediction")
        if isinstance(prediction, dict):  # read back from a records file
            prediction = StepPrediction(**prediction)
        if s is None:
            return cls(r.status, r.message, prediction=prediction)
        integrator = s["integrator"]
        done = [g["completed_s"] for g in s["grasps"]]
        return cls(
            s["status"], s["message"], s["wall_time_s"], s["sim_time_s"],
            done[-1] if s["status"] in (COMPLETED, NOT_CAPTURED) else math.nan,  # every grasp closed
            s["steps"], integrator.get("force_evaluations", s["steps"]), integrator.get("rejected_steps", 0),
            [None if g["final_offset_mm"] is None else np.array(g["final_offset_mm"]) for g in s["grasps"]],
            [g["peak_force_norm_N"] for g in s["grasps"]],
            [np.array(g["robot_centroid_displacement_mm"]) if "robot_centroid_displacement_mm" in g else None
             for g in s["grasps"]],
            s["momentum"]["linear_drift_rel"], s["momentum"]["angular_drift_rel"], r.about.get("finite", True),
            prediction, run_outcome(s["status"], s))


@dataclass(frozen=True)
class Runs:
    """How a study runs its scenarios one at a time (`runs(scenario) -> Outcome`): each in a
    worker process of its own (`runner.execute`, one process forked from this one: a crash in
    compiled code costs that run only), within the wall-time budget `wall_limit_s` (status
    `wall limit`), named `source`. With `records`, a records file (`runner.append_record`)
    keeps each run as it ends and gives it back when the study asks for the same scenario
    under the same code again: a study started again over its directory runs only what it
    lacks. Never raises but on the user's Ctrl-C: a scenario the model or the start check
    rejects is `rejected`, an exception out of `simulate` is `exception` (a bug the study
    reports)."""

    source: str = "<study>"
    wall_limit_s: float | None = None
    records: Path | None = None

    def __call__(self, scenario) -> Outcome:
        from .runner import PROCESSES, RUN_AGAIN, Runner, append_record, execute, read_records, scenario_key

        key = None if self.records is None else scenario_key(scenario)
        if key is not None:
            done = read_records(self.records).get(key)
            if done is not None and done.status not in RUN_AGAIN:
                return Outcome.of(done)
        out = []
        execute(partial(run_task, options=RunOptions(self.source, self.wall_limit_s)), [Task(scenario, key=key)],
                Runner(PROCESSES, workers=1, wall_limit_s=self.wall_limit_s), lambda task, r: out.append(r))
        if key is not None and out[0].status not in RUN_AGAIN:
            append_record(self.records, out[0])  # keyed by its task
        return Outcome.of(out[0])


#: The records file of a study's runs (`Runs`), in its output directory.
RUNS_FILE = "runs.jsonl"


def _caused_by_ctrl_c(e: BaseException) -> bool:
    """Whether a KeyboardInterrupt lies in `e`'s chain of causes: Ctrl-C landing inside one of
    numba's callbacks comes out as a SystemError."""
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False


# ----------------------------------------------------------------------------- comparing


def free_floating(scenario) -> bool:
    return scenario.kind == "dual_arm"


def errors(o: Outcome, ref: Outcome, names: list[str], centroid: bool) -> dict[str, float]:
    """The errors of `o` against `ref`, per grasp: offset (norm of the vector difference, mm,
    and relative to the reference's norm), peak force (relative) and centroid displacement
    (mm, relative); and `max_err_rel`, the largest relative one. nan where either run has
    nothing comparable (diverged, rejected, a grasp that never ran)."""
    out = {}
    ok = o.comparable and ref.comparable
    for g, p in enumerate(names):
        def diff(a, b):
            if not ok or a is None or b is None:
                return math.nan, math.nan
            d = float(np.linalg.norm(np.asarray(a) - np.asarray(b)))
            return d, d / max(float(np.linalg.norm(b)), 1e-300)

        out[f"{p}offset_err_mm"], out[f"{p}offset_err_rel"] = diff(o.offsets[g], ref.offsets[g])
        _, out[f"{p}peak_force_err_rel"] = diff(o.peaks[g], ref.peaks[g])
        if centroid:
            out[f"{p}centroid_err_mm"], out[f"{p}centroid_err_rel"] = diff(o.centroids[g], ref.centroids[g])
    rel = [v for k, v in out.items() if k.endswith("_rel")]
    out["max_err_rel"] = math.nan if any(math.isnan(v) for v in rel) else max(rel)
    return out


def worst(errs: dict[str, float]) -> str:
    """The name of the largest relative error."""
    rel = {k: v for k, v in errs.items() if k.endswith("_rel") and k != "max_err_rel"}
    return max(rel, key=lambda k: -1.0 if math.isnan(rel[k]) else rel[k])


# ----------------------------------------------------------------------------- output


def fmt(x) -> str:
    """A CSV cell: numbers to 6 significant digits, nan spelt out."""
    if isinstance(x, (bool, np.bool_)):
        return "yes" if x else "no"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    if isinstance(x, (float, np.floating)):
        return "nan" if math.isnan(x) else f"{x:.6g}"
    return str(x)


class StudyRows:
    """A study's loop, as a context: its CSV written and flushed a row at a time (`write`; the
    rows kept in `rows`), its progress bar (`bar`, of `total` runs), and Ctrl-C, which ends the
    loop, keeps the rows written and sets `interrupted`."""

    def __init__(self, path: Path, columns: list[str], total: int | None = None, progress: bool = False,
                 what: str = "study"):
        from ..run import progress_bar

        self.path, self.columns, self.rows, self.interrupted = path, columns, [], False
        self._file = open(path, "w", newline="")  # noqa: SIM115 - open across rows, closed on exit
        self._csv = csv.writer(self._file)
        self._csv.writerow(columns)
        self._file.flush()
        self.bar = progress_bar(total, progress, what, "run")

    def write(self, row: dict) -> None:
        missing = [c for c in self.columns if c not in row]
        if missing:
            raise KeyError(f"row lacks {missing}")
        self._csv.writerow([fmt(row[c]) for c in self.columns])
        self._file.flush()
        self.rows.append(row)

    def __enter__(self) -> StudyRows:
        return self

    def __exit__(self, kind, value, traceback) -> bool:
        self.bar.close()
        self._file.close()
        self.interrupted = kind is not None and issubclass(kind, KeyboardInterrupt)
        return self.interrupted


def warm_up(scenario, methods, duration_s: float = 0.5) -> None:
    """Run each method briefly here (dopri5 at a loose tolerance), so that no timed run pays for
    loading its compiled kernels: the processes `Runs` forks inherit them loaded."""
    for method in methods:
        integrator = {"method": method}
        if method == "dopri5":
            integrator.update(rtol=1e-3, atol=1e-6)
        run_task(Task(replace(scenario, simulation={"duration_s": min(duration_s, scenario.simulation.duration_s),
                                                    "integrator": integrator})), RunOptions("<warm-up>"))
