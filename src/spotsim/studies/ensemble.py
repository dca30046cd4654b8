"""An ensemble: one scenario run from many starts perturbed within a stated tolerance.

At a converged step the residual offset of a grasp depends on microscopic details of its
start (model.md Sec. 9): a run is one sample of a distribution. `ensemble` runs N copies of a
scenario, each module's start moved uniformly within +-`offset_tol_mm` on each of x, y, z of
`initial_offset_mm` and +-`rpy_tol_deg` on each of roll, pitch, yaw of `initial_rpy_deg`,
in parallel processes, and reports per member its summary and across members the statistics
of each headline quantity and the share of each outcome class.

Member 0 is the scenario's own, unperturbed start; members 1..N-1 draw their perturbations
from numpy's `default_rng(seed)`, member after member, so the first k members of an ensemble
are the same whatever its size.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import SpotsimError
from ..scenario import modules_of, replace
from ..status import WEDGED_OFFSET_MM, WEDGED_TILT_DEG, grasp_outcome
from .runner import RUN_AGAIN, Record, Task, scenario_key

#: Default perturbation of each module's start: +-10 um on each axis of the offset and
#: +-0.01 deg on each of roll, pitch, yaw, well below any tolerance a drawing would state and
#: far above the nanometres that already change the outcome.
OFFSET_TOL_MM = 0.01
RPY_TOL_DEG = 0.01
#: Families of perturbed starts: which of a module's six start coordinates (x, y, z, roll,
#: pitch, yaw) a member moves. `all`: every one; `one_axis`: member i only coordinate (i - 1)
#: mod 6, so that a result converged over one family is tested on starts of another shape.
ALL_AXES, ONE_AXIS = "all", "one_axis"
FAMILIES = {ALL_AXES: "uniform in [-tol, tol] on each of x, y, z and roll, pitch, yaw of each module's start",
            ONE_AXIS: "uniform in [-tol, tol] on one of x, y, z, roll, pitch, yaw of each module's start, "
                      "member i on the (i - 1) mod 6-th"}


#: Statuses of members that did not run to an outcome of their own: left out of every share.
NOT_RUN = ("interrupted",)


# ----------------------------------------------------------------------------- starts


@dataclass(frozen=True)
class Start:
    """One member's start: per module section (`module`, or `tm1`, `tm2`), its
    `initial_offset_mm` and `initial_rpy_deg`."""

    offsets_mm: dict[str, tuple[float, float, float]]
    rpy_deg: dict[str, tuple[float, float, float]]

    def as_dict(self) -> dict:
        return {k: {"initial_offset_mm": list(self.offsets_mm[k]), "initial_rpy_deg": list(self.rpy_deg[k])}
                for k in self.offsets_mm}


def perturbed_starts(scenario, n: int, seed: int = 0, offset_tol_mm: float = OFFSET_TOL_MM,
                     rpy_tol_deg: float = RPY_TOL_DEG, family: str = ALL_AXES) -> list[Start]:
    """The starts of an ensemble of n members: member 0 the scenario's own, the others each
    module's start plus a uniform draw in [-tol, tol] on each axis (6 draws per module, in the
    order x, y, z, roll, pitch, yaw, modules in `modules_of` order, member after member); in
    the `one_axis` family (`FAMILIES`) member i keeps only its draw on axis (i - 1) mod 6."""
    if family not in FAMILIES:
        raise SpotsimError(f"perturbation family {family!r}: must be one of {', '.join(FAMILIES)}")
    sections = modules_of(scenario)
    rng = np.random.default_rng(seed)
    draws = rng.uniform(-1.0, 1.0, size=(max(n - 1, 0), len(sections), 6))
    if family == ONE_AXIS:
        keep = np.arange(6)[None, :] == (np.arange(draws.shape[0]) % 6)[:, None]
        draws *= keep[:, None, :]
    tol = np.array([offset_tol_mm] * 3 + [rpy_tol_deg] * 3)
    starts = []
    for i in range(n):
        offsets, rpys = {}, {}
        for k, (name, m) in enumerate(sections.items()):
            d = draws[i - 1, k] * tol if i else np.zeros(6)
            offsets[name] = tuple(float(x) for x in np.add(m.initial_offset_mm, d[:3]))
            rpys[name] = tuple(float(x) for x in np.add(m.initial_rpy_deg, d[3:]))
        starts.append(Start(offsets, rpys))
    return starts


def member_scenario(scenario, start: Start):
    """The scenario started at `start` (validated again)."""
    return replace(scenario, **start.as_dict())


# ----------------------------------------------------------------------------- one member


def start_of(m: Record) -> Start:
    """A member's start, from its record."""
    start = m.about["start"]
    return Start({k: tuple(v["initial_offset_mm"]) for k, v in start.items()},
                 {k: tuple(v["initial_rpy_deg"]) for k, v in start.items()})


#: The records file of an ensemble's members (`runner.append_record`), in its output directory.
MEMBERS_FILE = "members.jsonl"
def member_task(scenario, index: int, start: Start, keyed: bool) -> Task:
    """The task of a member (`runner.Task`): the scenario at its start, keyed (`scenario_key`)
    if `keyed`; a start that is no valid scenario is a task without one (its run `rejected`)."""
    about = {"start": start.as_dict()}
    try:
        mine = member_scenario(scenario, start)
    except SpotsimError as e:  # the perturbed start's own problem
        return Task(None, index, None, about, (str(e).replace("\n", "; "),))
    return Task(mine, index, scenario_key(mine) if keyed else None, about)


# ----------------------------------------------------------------------------- the ensemble


@dataclass
class EnsembleResult:
    """An ensemble's members (in index order; those never run are `interrupted`) and what it
    was run with. `statistics` and `classes` are computed from the members (see `summarise`)."""

    scenario: object
    seed: int
    offset_tol_mm: float
    rpy_tol_deg: float
    members: list[Record]
    interrupted: bool = False
    wall_time_s: float = math.nan
    workers: int = 1
    family: str = ALL_AXES
    reused: int = 0  # members found in the records file of an earlier run (`ensemble`'s out_dir)
    summary: dict = field(init=False)
    error_estimate: dict | None = None  # member 0's (`studies.estimate`), when one was made

    def __post_init__(self):
        self.summary = summarise(self)

    @property
    def statuses(self) -> dict[str, int]:
        return self.summary["statuses"]

    @property
    def statistics(self) -> dict:
        return self.summary["statistics"]

    @property
    def classes(self) -> dict:
        return self.summary["classes"]


def ensemble(scenario, n: int, *, seed: int = 0, offset_tol_mm: float = OFFSET_TOL_MM,
             rpy_tol_deg: float = RPY_TOL_DEG, family: str = ALL_AXES, workers: int | None = None,
             progress: bool = False, model=None, source: str = "<scenario>", runner=None,
             out_dir=None) -> EnsembleResult:
    """Run `scenario` from n starts, member 0 unperturbed and the others perturbed within the
    tolerances on the axes of `family` (`perturbed_starts`), on `runner` (`runner.Runner`; by
    default a pool of `workers` processes, os.cpu_count() when None; 1 runs them here, one
    after the other).

    out_dir: each member's record is appended to its MEMBERS_FILE as the member ends, and a
    member whose record is there (its scenario and spotsim's code the same) is not run again:
    an interrupted ensemble started again over the directory runs only what it lacks.

    model: the scenario's Model if already built (each worker process otherwise builds it once).
    Never raises on a member's physics or failure: each is counted with its status. Ctrl-C
    stops the ensemble; the members that finished are kept, the others are `interrupted`.
    """
    import functools
    import time

    from .runner import (
        PROCESSES,
        SERIAL,
        Runner,
        SchedulerLost,
        append_record,
        execute,
        keep_model,
        read_records,
        warm_worker,
    )
    from .runs import RunOptions, run_task

    if not (isinstance(n, int | np.integer) and n >= 1):
        raise SpotsimError(f"ensemble size n = {n}: must be an integer >= 1")
    for name, tol in (("offset_tol_mm", offset_tol_mm), ("rpy_tol_deg", rpy_tol_deg)):
        if not (math.isfinite(tol) and tol >= 0):
            raise SpotsimError(f"{name} = {tol}: must be finite and >= 0")
    if runner is None:  # a pool of `workers` (Runner checks them); a pool of one: here, one after the other
        runner = Runner(PROCESSES, workers=workers or None, wall_limit_s=None, progress=progress)
        if runner.worker_count(n) == 1:
            runner = dataclasses.replace(runner, backend=SERIAL)
    if model is None:  # here first: a scenario that cannot be built fails before any worker starts
        from ..assemble.model import build_model

        model = build_model(scenario, source)
    elif model.scenario != scenario:
        raise SpotsimError("ensemble: `model` was built from another scenario than `scenario`")
    keep_model(model)  # the workers' (forked) or this process's nominal model
    starts = perturbed_starts(scenario, n, seed, offset_tol_mm, rpy_tol_deg, family)
    members: list[Record | None] = [None] * n
    records = None if out_dir is None else Path(out_dir) / MEMBERS_FILE
    tasks = [member_task(scenario, i, start, records is not None) for i, start in enumerate(starts)]
    done = {} if records is None else read_records(records)
    if records is not None:
        records.parent.mkdir(parents=True, exist_ok=True)
    for task in tasks:
        if task.key in done and done[task.key].status not in RUN_AGAIN:
            members[task.index] = dataclasses.replace(done[task.key], index=task.index)
    reused = sum(m is not None for m in members)

    def finished(task, m: Record):
        members[m.index] = m
        if m.status == "interrupted":  # Ctrl-C ended this member's run
            raise KeyboardInterrupt
        if records is not None and m.key is not None and m.status not in RUN_AGAIN:
            append_record(records, m)

    interrupted = False
    wall0 = time.perf_counter()
    try:
        execute(functools.partial(run_task, options=RunOptions(source)), [t for t in tasks if members[t.index] is None],
                runner, finished, what="ensemble", total=n - reused,
                warm=functools.partial(warm_worker, scenario, source))
    except KeyboardInterrupt:
        interrupted = True
    except SchedulerLost as e:
        kept = f", kept in {records}: run it again to resume" if records is not None else ""
        raise SchedulerLost(f"{e}: {sum(m is not None for m in members)} of {n} members finished{kept}") from e
    wall = time.perf_counter() - wall0
    for i, m in enumerate(members):
        if m is None:
            members[i] = Record(None, i, "interrupted", "not run: the ensemble was interrupted",
                                about={"start": starts[i].as_dict()})
    return EnsembleResult(scenario, seed, offset_tol_mm, rpy_tol_deg, members, interrupted, wall,
                          runner.worker_count(n) if runner.backend != SERIAL else 1, family, reused)


# ----------------------------------------------------------------------------- statistics


def finite(values) -> np.ndarray:
    """The values that are neither None nor nan nor infinite, as an array."""
    return np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float)


def statistics(values) -> dict:
    """median, 10th and 90th percentiles (numpy's linear interpolation), min, max and count of
    the finite values (None, count 0, when there are none)."""
    x = finite(values)
    if not len(x):
        return {"median": None, "p10": None, "p90": None, "min": None, "max": None, "count": 0}
    p10, median, p90 = np.percentile(x, [10, 50, 90])
    return {"median": float(median), "p10": float(p10), "p90": float(p90), "min": float(x.min()),
            "max": float(x.max()), "count": int(len(x))}


def member_row(m: Record, n_grasps: int, centroid: bool) -> dict:
    """The members table's row of one member: its start, status and each grasp's headline
    quantities (None where the grasp did not complete) and class; with `centroid` (a
    free-floating robot) the robot centroid's displacement over each grasp."""
    row = {"member": m.index, "status": m.status}
    start = start_of(m)
    for k in start.offsets_mm:
        for axis, x in zip("xyz", start.offsets_mm[k], strict=True):
            row[f"{k}_offset_{axis}_mm"] = x
        for name, x in zip(("roll", "pitch", "yaw"), start.rpy_deg[k], strict=True):
            row[f"{k}_{name}_deg"] = x
    grasps = m.grasps()
    for g in range(n_grasps):
        entry = grasps[g] if g < len(grasps) else None
        p = grasp_prefix(g, n_grasps)
        done = entry is not None and entry["completed_s"] is not None
        row[f"{p}class"] = grasp_outcome(m.status, entry)
        row[f"{p}completed_s"] = entry["completed_s"] if done else None
        res = entry["residual_offset_mm"] if done else [None] * 3
        for axis, x in zip("xyz", res, strict=True):
            row[f"{p}residual_{axis}_mm"] = x
        row[f"{p}residual_norm_mm"] = entry["residual_offset_norm_mm"] if done else None
        rpy = entry["residual_rpy_deg"] if done else [None] * 3
        for name, x in zip(("roll", "pitch", "yaw"), rpy, strict=True):
            row[f"{p}residual_{name}_deg"] = x
        row[f"{p}residual_tilt_deg"] = max(abs(rpy[0]), abs(rpy[1])) if done else None
        row[f"{p}peak_force_norm_N"] = entry["peak_force_norm_N"] if done else None
        row[f"{p}peak_torque_norm_Nm"] = entry["peak_torque_norm_Nm"] if done else None
        row[f"{p}drive_resumes"] = entry.get("drive_resumes") if done else None
        row[f"{p}drive_largest_speed_step_mm_s"] = entry.get("drive_largest_speed_step_mm_s") if done else None
        if centroid:
            d = entry.get("robot_centroid_displacement_mm") if done else None
            for axis, x in zip("xyz", d or [None] * 3, strict=True):
                row[f"{p}centroid_displacement_{axis}_mm"] = x
            row[f"{p}centroid_displacement_norm_mm"] = float(np.linalg.norm(d)) if d else None
    s = m.summary or {}
    row["sim_time_s"] = s.get("sim_time_s")
    row["wall_time_s"] = s.get("wall_time_s")
    row["message"] = m.message
    return row


def grasp_prefix(g: int, n_grasps: int) -> str:
    """Column prefix of grasp g: none for one grasp, `g1_`, `g2_`... for several."""
    return "" if n_grasps == 1 else f"g{g + 1}_"


def grasp_names(scenario) -> list[str]:
    """The column prefixes of the scenario's grasps (`grasp_prefix`)."""
    n = len(modules_of(scenario))
    return [grasp_prefix(g, n) for g in range(n)]


#: The headline quantities whose statistics an ensemble reports, per grasp (members table
#: columns without the grasp prefix), over the members whose grasp completed.
HEADLINE = ("residual_norm_mm", "residual_x_mm", "residual_y_mm", "residual_z_mm", "residual_roll_deg",
            "residual_pitch_deg", "residual_yaw_deg", "residual_tilt_deg", "peak_force_norm_N",
            "peak_torque_norm_Nm", "completed_s", "drive_resumes", "drive_largest_speed_step_mm_s",
            "centroid_displacement_x_mm", "centroid_displacement_y_mm",
            "centroid_displacement_z_mm", "centroid_displacement_norm_mm")


def grasp_key(g: int, n_grasps: int) -> str:
    """The statistics' key of grasp g: `grasp` for one grasp, `grasp_1`, `grasp_2`... for several."""
    return f"grasp_{g + 1}" if n_grasps > 1 else "grasp"


def headline_statistics(rows: list[dict], n_grasps: int) -> dict:
    """Per grasp (`grasp_key`), the `statistics` of each HEADLINE quantity in the first row's
    columns over the members that ran among members-table rows (`member_row`, or members.csv's
    rows read back)."""
    columns = rows[0] if rows else ()
    rows = [r for r in rows if r["status"] not in NOT_RUN]
    out = {}
    for g in range(n_grasps):
        p = grasp_prefix(g, n_grasps)
        out[grasp_key(g, n_grasps)] = {q: statistics(r.get(f"{p}{q}") for r in rows)
                                       for q in HEADLINE if f"{p}{q}" in columns}
    return out


def summarise(e: EnsembleResult) -> dict:
    """What ensemble.json holds besides the members' starts: the status counts; per grasp the
    statistics of each headline quantity over its completed members and the outcome classes
    (count and fraction of the members that ran: all but the interrupted)."""
    n_grasps = len(modules_of(e.scenario))
    rows = [member_row(m, n_grasps, e.scenario.kind == "dual_arm") for m in e.members]
    statuses: dict[str, int] = {}
    for m in e.members:
        statuses[m.status] = statuses.get(m.status, 0) + 1
    ran = [r for r in rows if r["status"] not in NOT_RUN]
    stats, classes = headline_statistics(rows, n_grasps), {}
    for g in range(n_grasps):
        p = grasp_prefix(g, n_grasps)
        key = grasp_key(g, n_grasps)
        counts: dict[str, int] = {}
        for r in ran:
            counts[r[f"{p}class"]] = counts.get(r[f"{p}class"], 0) + 1
        classes[key] = {c: {"count": k, "fraction": k / len(ran)} for c, k in sorted(counts.items())}
    return {"statuses": statuses, "statistics": stats, "classes": classes, "rows": rows}


# ----------------------------------------------------------------------------- output


def classification_rule() -> str:
    return (f"a completed grasp with a finger outside its groove is not captured; else wedged when max(|roll|, "
            f"|pitch|) of its residual exceeds {WEDGED_TILT_DEG:g} deg or its residual offset exceeds "
            f"{WEDGED_OFFSET_MM:g} mm, else seated; a grasp that did not complete is classed by its member's status")


def ensemble_json(e: EnsembleResult) -> dict:
    """The ensemble.json dictionary."""
    from ..version import __version__

    s = e.summary
    return {
        "scenario": e.scenario.name,
        "spotsim_version": __version__,
        "status": "interrupted" if e.interrupted else "completed",
        "members": len(e.members),
        "seed": e.seed,
        "perturbation": {"offset_tol_mm": e.offset_tol_mm, "rpy_tol_deg": e.rpy_tol_deg, "family": e.family,
                         "distribution": f"{FAMILIES[e.family]}; member 0 unperturbed"},
        "classification": {"rule": classification_rule(), "wedged_tilt_deg": WEDGED_TILT_DEG,
                           "wedged_offset_mm": WEDGED_OFFSET_MM},
        "statistics_over": "per quantity, the members whose grasp completed (count); classes over the members "
                           "that ran (all but the interrupted)",
        "workers": e.workers,
        "wall_time_s": e.wall_time_s,
        "reused_members": e.reused,
        "statuses": s["statuses"],
        "classes": s["classes"],
        "statistics": s["statistics"],
        "starts": [{"member": m.index, "status": m.status, **m.about["start"]} for m in e.members],
        **({"error_estimate": e.error_estimate} if e.error_estimate is not None else {}),
    }


def members_csv(e: EnsembleResult) -> str:
    """The members table: one row per member (`member_row`), floats to 9 significant digits."""
    rows = e.summary["rows"]
    columns = list(dict.fromkeys(c for r in rows for c in r))
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(columns)
    for r in rows:
        w.writerow(["" if r.get(c) is None else f"{r[c]:.9g}" if isinstance(r[c], float) else r[c] for c in columns])
    return buf.getvalue()


def write_ensemble(e: EnsembleResult, out_dir) -> list[Path]:
    """Write ensemble.json, members.csv and scenario.yaml (the nominal scenario) into out_dir;
    ensemble.json last and atomically."""
    from ..files import atomic_write, prepare
    from ..scenario import to_yaml

    out = prepare(out_dir, ENSEMBLE_JSON)
    files = [out / "members.csv", out / "scenario.yaml", out / ENSEMBLE_JSON]
    atomic_write(files[0], members_csv(e))
    atomic_write(files[1], to_yaml(e.scenario))
    atomic_write(files[2], json.dumps(ensemble_json(e), indent=2, allow_nan=True) + "\n")
    return files


ENSEMBLE_JSON = "ensemble.json"
#: The quantities the command line prints, per grasp, with their format.
PRINTED = (("residual_norm_mm", "residual offset e (mm)", ".3f"), ("residual_tilt_deg", "residual tilt (deg)", ".2f"),
           ("peak_force_norm_N", "peak force |F| (N)", ".1f"), ("completed_s", "completion time (s)", ".3f"),
           ("centroid_displacement_norm_mm", "robot centroid displacement |d| (mm)", ".3f"))


def report_lines(e: EnsembleResult) -> list[str]:
    """A short table of the headline quantities (median [p10, p90], count) and the classes."""
    lines = []
    for key, stats in e.statistics.items():
        lines.append(f"  {key.replace('_', ' ')}:")
        for q, label, f in PRINTED:
            if q in stats and stats[q]["count"]:
                st = stats[q]
                lines.append(f"    {label:<38} {st['median']:{f}} [{st['p10']:{f}}, {st['p90']:{f}}]  "
                             f"n = {st['count']}")
        shares = ", ".join(f"{c} {v['fraction']:.0%} ({v['count']})" for c, v in e.classes[key].items())
        lines.append(f"    {'outcome':<38} {shares or 'none ran'}")
    return lines
