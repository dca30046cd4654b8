"""Sweeps: one scenario run over many variations of its keys, on Dask, resumable.

A sweep's points each set some scenario keys, by the key paths `--set` takes (a whole-number
part picks a sequence's item: `module.initial_offset_mm.1`):

- a grid over axes, `--vary key=LO:HI:N` (N values from LO to HI) or `--vary key=A,B,C`;
- a space-filling sample over ranges, Sobol or Latin hypercube (`scipy.stats.qmc`), seeded;
- a list of points;

the last two from a spec file (`--spec`, `SweepSpec.from_yaml`). Every point is a full run at
the scenario's accuracy, with its error estimate (`studies.estimate`) unless turned off.

The output directory holds:

- `spec.yaml`: the resolved spec (the scenario file, the fixed overrides and every point);
- `points.jsonl`: a line per finished point, appended and flushed when it ends. A point's key
  is a hash of its resolved scenario and of spotsim's code (`code_fingerprint`): a sweep
  started again over the same directory runs only the points without a line, and every point
  again once the code has changed; a last line cut short by a kill is dropped when read, and a file
  with any other line that is not a record is refused, left as it is;
- `sweep.parquet` and `sweep.csv`: the table, a row per point in the spec's order, written to
  a temporary file and renamed over the last one when the sweep ends or stops.

The points run on the study runner (`runner.execute`): by default on `dask.distributed`, a
local cluster of one single-threaded worker process per core, or an existing scheduler
(`scheduler=`, `--scheduler tcp://HOST:PORT`); `Runner(backend="processes")` or `"serial"`
runs them on this machine without Dask. A worker keeps the models it built by their scene
(the scenario without the modules' starts), so points that change only the starts share one
model, and points that change no more than the contact, friction, drive or integrator
parameters share one compiled scene; it loads numba's kernels once. A point that raises,
diverges or spends its wall-time budget is a row with its status; one whose worker died is
tried once more (on Dask, the local cluster's `allowed-failures`; an existing scheduler's own
setting rules there) and is then recorded as `worker died`.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import itertools
import json
import math
import os
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from ..errors import ScenarioError, SpotsimError
from ..files import atomic_write
from ..scenario import from_dict, modules_of, parse_yaml, read_yaml, set_value, to_dict
from ..status import (
    WEDGED_OFFSET_MM,
    run_outcome,
)
from .ensemble import Start, grasp_prefix, member_row
from .runner import (
    MAX_POINTS,
    Record,
    Runner,
    SchedulerLost,
    Task,
    append_record,
    check_budget,
    execute,
    plain,
    read_records,
    scenario_key,
    warm_worker,
)

#: A point's verdict is its run's outcome (`status.run_outcome`: seated, wedged, not captured,
#: incomplete, diverged), with the residual offset beyond which a closed grasp is wedged: by
#: default the ensembles' (`status.WEDGED_OFFSET_MM`). Points that did not run have none.
PRECISION_MM = WEDGED_OFFSET_MM
SAMPLERS = ("sobol", "lhs")
#: A grid axis that sets several keys to the same values, together: `--vary a+b=LO:HI:N` (both
#: bevels of a groove, say), not a product of two axes.
JOINED = "+"
POINTS_FILE, SPEC_FILE, TABLE = "points.jsonl", "spec.yaml", "sweep"


# ----------------------------------------------------------------------------- the spec


def _number(text: str):
    """A value of `--vary`, read as `--set` reads one (`scenario.parse_yaml`: 1e-6 a number)."""
    return parse_yaml(text, f"--vary: {text}")


def parse_range(text: str, where: str, most: int = MAX_POINTS) -> list:
    """`LO:HI:N` as N values from LO to HI (N >= 2; N = 1 gives LO), or `A,B,C` as a list; N
    above `most` (the budget of points) is refused before the values are made."""
    if ":" in text:
        parts = text.split(":")
        try:
            lo, hi, n = float(_number(parts[0])), float(_number(parts[1])), int(parts[2])
        except (ValueError, TypeError, IndexError):
            raise ScenarioError([f"{where} = {text}: must read LO:HI:N (N a whole number) or A,B,C"]) from None
        if len(parts) != 3 or n < 1 or not (math.isfinite(lo) and math.isfinite(hi)):
            raise ScenarioError([f"{where} = {text}: must read LO:HI:N with finite LO, HI and N >= 1"])
        check_budget(n, most, f"{where} = {text}")
        return [float(x) for x in np.linspace(lo, hi, n)]
    values = [_number(x) for x in text.split(",")]
    if any(v is None for v in values):
        raise ScenarioError([f"{where} = {text}: an empty value"])
    return values


def parse_vary(assignment: str, most: int = MAX_POINTS) -> tuple[str, list]:
    """`key.path=LO:HI:N` or `key.path=A,B,C` as (key path, values), at most `most` of them;
    `a.path+b.path=...` sets both key paths to each value together (one axis)."""
    if "=" not in assignment:
        raise ScenarioError([f"--vary: {assignment}: must read key.path=LO:HI:N or key.path=A,B,C"])
    path, text = (x.strip() for x in assignment.split("=", 1))
    return path, parse_range(text, f"--vary: {path}", most)


@dataclass
class SweepSpec:
    """The points of a sweep: a grid over `grid` (key path -> values), a `sample` (method,
    n, seed, ranges: key path -> [lo, hi]), or listed `points` (each key path -> value); `sets`
    are overrides every point takes (`--set`)."""

    grid: dict = field(default_factory=dict)
    sample: dict | None = None
    points: list = field(default_factory=list)
    sets: list = field(default_factory=list)

    @classmethod
    def from_yaml(cls, path: str | Path, most: int = MAX_POINTS) -> SweepSpec:
        """A spec file: `set` (a list of key.path=value), then one of `grid` (key path: a list
        or 'LO:HI:N'), `sample` (method: sobol or lhs, n, seed, ranges: key path: [lo, hi]) or
        `points` (a list of mappings of key path to value); a range of more than `most` values
        is refused before it is made."""
        path = Path(path)
        raw = read_yaml(path)
        if not isinstance(raw, dict):
            raise ScenarioError([f"{path}: a sweep spec is a mapping of set, grid, sample or points"])
        unknown = sorted(set(raw) - {"set", "grid", "sample", "points", "scenario"})
        if unknown:
            raise ScenarioError([f"{path}: {k}: not a key of a sweep spec (set, grid, sample, points)"
                                 for k in unknown])
        grid = {}
        for k, v in (raw.get("grid") or {}).items():
            grid[str(k)] = parse_range(str(v), f"{path}: grid.{k}", most) if isinstance(v, str) else (
                list(v) if isinstance(v, list) else [v])
        spec = cls(grid=grid, sample=raw.get("sample"), points=list(raw.get("points") or []),
                   sets=[str(s) for s in raw.get("set") or []])
        spec.check(str(path))
        return spec

    def check(self, where: str = "sweep") -> None:
        problems = []
        kinds = [bool(self.grid), self.sample is not None, bool(self.points)]
        if sum(kinds) != 1:
            problems.append(f"{where}: give exactly one of a grid (--vary), a sample or a list of points")
        if self.sample is not None:
            s = self.sample
            if not isinstance(s, dict) or s.get("method") not in SAMPLERS:
                problems.append(f"{where}: sample.method = {s.get('method') if isinstance(s, dict) else s}: "
                                f"must be one of {', '.join(SAMPLERS)}")
            elif not isinstance(s.get("n"), int) or s["n"] < 1:
                problems.append(f"{where}: sample.n = {s.get('n')}: must be a whole number >= 1")
            elif not isinstance(s.get("ranges"), dict) or not s["ranges"]:
                problems.append(f"{where}: sample.ranges: must map key paths to [lo, hi]")
            else:
                for k, r in s["ranges"].items():
                    ok = isinstance(r, list) and len(r) == 2 and all(isinstance(x, (int, float)) for x in r)
                    if not ok or not r[0] < r[1]:
                        problems.append(f"{where}: sample.ranges.{k} = {r}: must be [lo, hi] with lo < hi")
        for i, p in enumerate(self.points):
            if not isinstance(p, dict) or not p:
                problems.append(f"{where}: points[{i}]: must map key paths to values")
        for k, values in self.grid.items():
            if not values:
                problems.append(f"{where}: grid.{k}: no values")
        if problems:
            raise ScenarioError(problems)

    def count(self) -> int:
        """How many points the spec gives, without making them."""
        if self.grid:
            return math.prod(len(v) for v in self.grid.values())
        if self.sample is not None:
            return int(self.sample["n"])
        return len(self.points)

    def keys(self) -> list[str]:
        """The key paths the points set (a grid axis `a+b` sets both a and b)."""
        if self.grid:
            return [k for axis in self.grid for k in axis.split(JOINED)]
        if self.sample is not None:
            return [str(k) for k in self.sample["ranges"]]
        return list(dict.fromkeys(str(k) for p in self.points for k in p))

    def resolved(self) -> list[dict]:
        """Every point as key path -> value, in the spec's order."""
        self.check()
        if self.grid:
            axes = [axis.split(JOINED) for axis in self.grid]
            return [{k: v for keys, v in zip(axes, combo, strict=True) for k in keys}
                    for combo in itertools.product(*self.grid.values())]
        if self.sample is not None:
            from scipy.stats import qmc

            s, keys = self.sample, self.keys()
            seed = int(s.get("seed", 0))
            if s["method"] == "sobol":
                sampler = qmc.Sobol(len(keys), scramble=True, seed=seed)
                n = s["n"]
                unit = sampler.random_base2(int(math.log2(n))) if n & (n - 1) == 0 else sampler.random(n)
            else:
                unit = qmc.LatinHypercube(len(keys), seed=seed).random(s["n"])
            lo = [float(s["ranges"][k][0]) for k in keys]
            hi = [float(s["ranges"][k][1]) for k in keys]
            return [dict(zip(keys, map(float, row), strict=True)) for row in qmc.scale(unit, lo, hi)]
        return [{str(k): v for k, v in p.items()} for p in self.points]


# ----------------------------------------------------------------------------- points


def base_raw(config: Path, sets: list[str]) -> dict:
    """The raw mapping of a scenario file with the fixed overrides applied, validated once."""
    from ..scenario import load_scenario, set_override

    load_scenario(config, sets)  # every problem of the file and its overrides, reported at once
    raw = read_yaml(config) or {}
    for s in sets:
        set_override(raw, s)
    return raw


def resolve_points(config: Path, spec: SweepSpec) -> list[Task]:
    """The spec's points as tasks (`runner.Task`): the point's values in `about["values"]`, its
    key a hash of its resolved scenario and the code (`scenario_key`). A key path the scenario
    does not have is an error of the whole sweep (ScenarioError); a value its rule refuses
    makes that point invalid."""
    raw0 = base_raw(config, spec.sets)
    base = from_dict(raw0, str(config))
    known = to_dict(base)
    bad = [k for k in spec.keys() if not _has_path(known, k)]
    if bad:
        raise ScenarioError([f"{config}: {k}: not a key path of the scenario" for k in bad])
    return [point_task(raw0, values, i, f"{config} [point {i}]") for i, values in enumerate(spec.resolved())]


def point_task(raw0: dict, values: dict, index: int, where: str) -> Task:
    """The task of a point (a sweep's, an envelope's probe): the raw scenario `raw0` with the
    key paths of `values` set, its values in `about["values"]`, keyed by its scenario and the
    code (`scenario_key`); a value that a rule refuses makes a task without a scenario, keyed
    by its values."""
    raw = json.loads(json.dumps(raw0))  # a deep copy of plain data
    try:
        for k, v in values.items():
            set_value(raw, k, v)
        scenario = from_dict(raw, where)
    except ScenarioError as e:
        key = hashlib.sha256(repr(sorted(values.items())).encode()).hexdigest()[:16]
        return Task(None, index, key, {"values": values}, tuple(e.problems))
    return Task(scenario, index, scenario_key(scenario), {"values": values})


def _has_path(tree, path: str) -> bool:
    node = tree
    for part in path.split("."):
        if isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        elif isinstance(node, dict) and part in node:
            node = node[part]
        else:
            return False
    return True


# ----------------------------------------------------------------------------- rows


#: Error estimate columns: summary quantity -> column suffix.
ESTIMATED = {"residual_offset_norm_mm": "residual_error_mm", "peak_force_norm_N": "peak_force_error_N",
             "peak_torque_norm_Nm": "peak_torque_error_Nm",
             "robot_centroid_displacement_norm_mm": "centroid_displacement_error_mm"}


def table_row(record: Record, scenario, keys: list[str], precision_mm: float = PRECISION_MM) -> dict:
    """The table's row of a point's record: its key, its values, status, verdict and message,
    each grasp's results (`ensemble.member_row`: class, residual, peaks, completion, the robot
    centroid's displacement) and error estimates, and its wall time."""
    summary = record.summary
    row = {"key": record.key, "index": record.index}
    row.update({k: record.about["values"].get(k) for k in keys})
    row["status"] = record.status
    row["verdict"] = run_outcome(record.status, summary, precision_mm)
    n_grasps = len(modules_of(scenario)) if scenario is not None else 1
    dual = scenario is not None and scenario.kind == "dual_arm"
    start = Start({k: tuple(m.initial_offset_mm) for k, m in modules_of(scenario).items()},
                  {k: tuple(m.initial_rpy_deg) for k, m in modules_of(scenario).items()}) if scenario else Start({}, {})
    results = member_row(dataclasses.replace(record, about={"start": start.as_dict()}), n_grasps, centroid=dual)
    for k in ("member", "status", "message", "wall_time_s", "sim_time_s"):
        results.pop(k, None)
    row.update(results)
    estimate = (summary or {}).get("error_estimate", {})
    for g in range(n_grasps):
        p = grasp_prefix(g, n_grasps)
        entry = estimate["grasps"][g] if estimate.get("grasps") else {}
        for q, name in ESTIMATED.items():
            if q != "robot_centroid_displacement_norm_mm" or dual:
                row[f"{p}{name}"] = (entry.get(q) or {}).get("estimate")
    row["start_gap_mm"] = record.about.get("start_gap_mm")
    row["sim_time_s"] = (summary or {}).get("sim_time_s")
    row["run_wall_time_s"] = (summary or {}).get("wall_time_s")
    row["companion_wall_time_s"] = (estimate.get("companion") or {}).get("wall_time_s")
    row["wall_time_s"] = record.wall_time_s
    row["worker"] = record.worker
    row["message"] = record.message
    return row


def write_table(rows: list[dict], out: Path):
    """rows as sweep.parquet and sweep.csv, each written whole to a temporary file and then
    renamed over the last one; returns the DataFrame."""
    import pandas as pd

    frame = pd.DataFrame(rows)
    for suffix, write in ((".parquet", lambda p: frame.to_parquet(p, index=False)),
                          (".csv", lambda p: frame.to_csv(p, index=False))):
        final = out / f"{TABLE}{suffix}"
        tmp = out / f".{TABLE}{suffix}.tmp"
        write(tmp)
        os.replace(tmp, final)
    return frame


# ----------------------------------------------------------------------------- the sweep


@dataclass
class SweepReport:
    """What a sweep did: its table (a pandas DataFrame, a row per point), how many points it
    ran now and found done before, whether it was interrupted, and its wall time."""

    table: object
    ran: int
    reused: int
    interrupted: bool
    wall_time_s: float
    out: Path

    def counts(self) -> Counter:
        t = self.table
        return Counter((t["verdict"].where(t["verdict"] != "", t["status"])).tolist()) if len(t) else Counter()

    def failed(self) -> int:
        t = self.table
        return int((t["verdict"] == "").sum()) if len(t) else 0

    def lines(self) -> list[str]:
        t = self.table
        out = [f"{len(t)} points ({self.ran} run now, {self.reused} from before) in {self.wall_time_s:.1f} s"
               + (": interrupted" if self.interrupted else "")]
        out.append("  " + ", ".join(f"{k}: {v}" for k, v in sorted(self.counts().items())))
        if self.failed():
            out.append(f"  {self.failed()} without a verdict (rejected, exception, wall limit, worker died)")
        if len(t):
            slow = t.sort_values("wall_time_s", ascending=False).head(3)
            out.append("  slowest: " + "; ".join(f"point {int(r['index'])} {r['wall_time_s']:.2f} s"
                                                 for _, r in slow.iterrows()))
        out.append(f"  table in {self.out / (TABLE + '.parquet')} and .csv")
        return out


def run_sweep(config, spec: SweepSpec, out_dir, *, runner: Runner = Runner(), precision_mm: float = PRECISION_MM,
              error_estimate: bool = True, on_record=None) -> SweepReport:
    """Run `config` (a scenario file) at every point of `spec` not already in `out_dir`, on
    `runner` (Dask by default), and write the table. Ctrl-C stops it and keeps every finished point
    (report.interrupted); a point's own failure never stops it. `on_record(record)` is called
    after each point is written (tests use it to interrupt or kill)."""
    config, out = Path(config), Path(out_dir)
    spec.check()
    check_budget(spec.count(), runner.max_points, f"{config}: the sweep")
    points = resolve_points(config, spec)
    keys = spec.keys()
    done = read_records(out / POINTS_FILE)  # before anything is written: a foreign file stays as it is
    try:
        out.mkdir(parents=True, exist_ok=True)
        atomic_write(out / SPEC_FILE, yaml.safe_dump(
            {"scenario": str(config), "set": spec.sets, "keys": keys,
             "points": [{"key": p.key, **{k: plain(v) if isinstance(v, np.generic) else v
                                          for k, v in p.about["values"].items()}} for p in points]}, sort_keys=False))
    except OSError as e:
        raise SpotsimError(f"{out}: cannot write the sweep's files: {e.strerror}") from e
    todo = list({p.key: p for p in points if p.key not in done}.values())
    reused = len({p.key for p in points} & set(done))
    t0 = time.perf_counter()
    interrupted = False
    ran = 0
    lost = None
    if todo:
        try:
            ran = run_points(todo, out, done, runner, str(config), error_estimate=error_estimate,
                             on_record=on_record)
        except KeyboardInterrupt:
            interrupted = True
            ran = sum(1 for p in todo if p.key in done)
        except SchedulerLost as e:
            lost = e
    # a record may come from an earlier sweep over the directory: this spec's index and values
    rows = [table_row(dataclasses.replace(done[p.key], index=p.index, about={**done[p.key].about, **p.about}),
                      p.scenario, keys, precision_mm) for p in points if p.key in done]
    try:
        table = write_table(rows, out)
    except OSError as e:
        raise SpotsimError(f"{out}: cannot write the sweep's table: {e.strerror}; every point is kept in "
                           f"{POINTS_FILE}: free some space and run the sweep again to write it") from e
    if lost is not None:
        raise SchedulerLost(f"{lost}: {len(rows)} of {len(points)} points finished, kept in "
                            f"{out / POINTS_FILE} and the table: run the sweep again to resume") from lost
    return SweepReport(table, ran, reused, interrupted, time.perf_counter() - t0, out)


def spec_of(vary=(), spec: SweepSpec | str | Path | None = None, sets=(), most: int = MAX_POINTS) -> SweepSpec:
    """A SweepSpec from `--vary` assignments (a grid), a spec (or its file), and `--set`s; a
    range of more than `most` values is refused before it is made."""
    if spec is not None and not isinstance(spec, SweepSpec):
        spec = SweepSpec.from_yaml(spec, most)
    if spec is not None and vary:
        raise ScenarioError(["give the points either by --vary or by a spec file, not both"])
    if spec is None:
        spec = SweepSpec(grid=dict(parse_vary(v, most) for v in vary))
    spec = dataclasses.replace(spec, sets=[*spec.sets, *sets])
    spec.check()
    return spec


def sweep(config, *, vary=(), spec: SweepSpec | str | Path | None = None, sets=(), out_dir=None, **options):
    """Run a sweep from Python as `spotsim sweep` does (`run_sweep`'s options: `runner=
    Runner(workers=2)`, `precision_mm`, ...) and return its table as a pandas DataFrame, a
    row per point; `table.attrs['report']` is the SweepReport. out_dir: by default
    results/<scenario name>/sweep."""
    from ..paths import results_dir
    from ..scenario import load_scenario

    spec = spec_of(vary, spec, sets, options.get("runner", Runner()).max_points)
    if out_dir is None:
        out_dir = results_dir(load_scenario(config, spec.sets).name, spec.sets, "sweep")
    report = run_sweep(config, spec, out_dir, **options)
    table = report.table
    table.attrs["report"] = report
    return table


def run_on(runner: Runner, first: list[Task], source: str, finished, *, error_estimate: bool = True,
           grow_gap: bool = False, what: str = "sweep", total: int | None = None, run=None) -> int:
    """Run points on `runner` (`runs.run_task`, every worker warmed first on the first point's
    scenario; or `run(point) -> record` if given: tests): the points `first`, then whatever
    `finished(point, record)` returns for each that ends (none for a sweep, a ray's next probe
    for the envelope). Returns how many ran."""
    from .runs import RunOptions, run_task

    scenario = next((p.scenario for p in first if p.scenario is not None), None)
    warm = None if scenario is None or run is not None else functools.partial(warm_worker, scenario, source)
    run = run or functools.partial(run_task, options=RunOptions(source, runner.wall_limit_s, error_estimate, grow_gap))
    return execute(run, first, runner, finished, what=what, total=total, warm=warm)


def run_points(todo: list[Task], out: Path, done: dict, runner: Runner, source: str, *,
               error_estimate: bool = True, grow_gap: bool = False, on_record=None) -> int:
    """Run the points `todo` on `runner`, each record appended to out's points file and put
    in `done` as it ends (then `on_record(record)`), with its error estimate from its
    companion's summary (`runs.RunOptions.companion`); returns how many ran."""
    from . import estimate

    def finished(p, record):
        twin = record.about.pop("companion", None)
        if twin is not None:
            record.summary["error_estimate"] = estimate.error_estimate(record.summary, twin,
                                                                       no_spread=estimate.POINT_NO_SPREAD)
        append_record(out / POINTS_FILE, record)
        done[p.key] = record
        if on_record is not None:
            on_record(record)

    return run_on(runner, todo, source, finished, error_estimate=error_estimate, grow_gap=grow_gap,
                  total=len(todo))
