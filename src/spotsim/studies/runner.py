"""The runner: how every study's runs are executed, on one of three backends.

A study hands `execute` a run function and its tasks; the runner calls the function on each
task where its `Runner` says and hands each record back, in this process, as the task ends:

- `serial`: here, one task after the other;
- `processes`: a pool of worker processes on this machine (forked on Linux: they inherit the
  loaded compiled kernels and the models built here; spawned elsewhere);
- `dask`: `dask.distributed`, a local cluster of single-threaded worker processes by default or
  an existing scheduler (`scheduler=`, `--scheduler tcp://HOST:PORT`).

Whatever the backend: a run function reports its own problems as its record's status (it
never raises); a task whose worker died is tried once more, then its record is the study's
`failed(task, error)` (`worker died`); Ctrl-C stops the runs and raises KeyboardInterrupt
after every finished record was handed back; a lost Dask scheduler is SchedulerLost. The
wall-time budget of a run is its simulation's own (`run.simulate`'s `wall_limit_s`), the same
on every backend. Each worker process keeps the models it built (`model_for`).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import logging
import math
import multiprocessing
import os
import signal
import sys
from collections import OrderedDict, deque
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ..errors import ScenarioError, SpotsimError
from ..jit import add_sources
from ..scenario import modules_of, to_dict, to_yaml
from ..status import EXCEPTION, INTERRUPTED, WALL_LIMIT, WORKER_DIED

SERIAL, PROCESSES, DASK = "serial", "processes", "dask"
BACKENDS = (SERIAL, PROCESSES, DASK)
#: A run's default wall-time budget in a sweep or an envelope (its run and its error
#: estimate's companion), s.
WALL_LIMIT_S = 600.0
#: The most runs a sweep or an envelope makes unless told otherwise (`--max-points`,
#: `Runner.max_points`): each is a whole run of a second or more, so a larger count is far
#: more often a mistyped range than a plan; it is refused before any point is built.
MAX_POINTS = 10_000
#: Statuses of a record that are not its run's own end: an ensemble or a study started again
#: over its records runs them again.
RUN_AGAIN = (INTERRUPTED, WALL_LIMIT, WORKER_DIED)
#: Models a worker keeps, the least recently used dropped first.
MODELS_KEPT = 8


@dataclass(frozen=True)
class Runner:
    """Where and how a study's runs go: `backend` (`serial`, `processes` or `dask`; a
    `scheduler` address means dask), on `workers` processes (default one per core), each run
    within `wall_limit_s` (None: no budget), at most `max_points` runs in a sweep or an
    envelope; with a progress bar or not."""

    backend: str = DASK
    scheduler: str | None = None
    workers: int | None = None
    wall_limit_s: float | None = WALL_LIMIT_S
    progress: bool = False
    max_points: int = MAX_POINTS

    def __post_init__(self):
        if self.backend not in BACKENDS:
            raise SpotsimError(f"backend {self.backend!r}: must be one of {', '.join(BACKENDS)}")
        if self.scheduler and self.backend != DASK:
            raise SpotsimError(f"a scheduler ({self.scheduler}) runs on the dask backend, not {self.backend}")
        if self.workers is not None and self.workers < 1:
            raise SpotsimError(f"workers = {self.workers}: must be >= 1")

    def worker_count(self, tasks: int | None = None) -> int:
        """The processes a local backend starts: `workers`, or one per core; no more than
        `tasks`."""
        n = self.workers or os.cpu_count() or 1
        return max(1, min(n, tasks)) if tasks else n


def check_budget(count: int, most: int, what: str) -> None:
    """Refuse `count` runs above the budget `most` (ScenarioError naming the option)."""
    if count > most:
        raise ScenarioError([f"{what}: {count} runs, more than the budget of {most}: give --max-points (Python: "
                             "Runner(max_points=...)) to allow more, or fewer points"])


class SchedulerLost(SpotsimError):
    """The Dask scheduler went away during a study: the records handed back before are kept by
    the study, the other tasks were not run."""


class WorkerDied(RuntimeError):
    """A task's worker process died under it twice."""


def worker_died(error: BaseException) -> bool:
    """Whether a task failed because its worker died (here or on Dask), not by its own error."""
    return isinstance(error, WorkerDied) or type(error).__name__ == "KilledWorker"


# ----------------------------------------------------------------------------- a run's record


@dataclass
class Record:
    """What a study keeps of one run, the same on every backend and in every records file:
    its `key` (its scenario and spotsim's code, `scenario_key`; None for a run no scenario
    names), its `index` in the study, status and message, the summary.json dictionary of its
    run (None when it did not run), the run's wall time with what came before it in the task
    (model, start check, companion run) and the worker process's id; `about`: the study's own
    (a sweep point's values and start gap, an ensemble member's start)."""

    key: str | None
    index: int
    status: str
    message: str
    summary: dict | None = None
    wall_time_s: float = math.nan
    worker: int | None = None
    about: dict = dataclasses.field(default_factory=dict)

    def grasps(self) -> list[dict]:
        """The summary's grasps; none when the run did not run."""
        return self.summary["grasps"] if self.summary else []

    @classmethod
    def of_json(cls, d: dict) -> Record:
        """A record from its line of a records file (fields it does not know go to `about`; a
        line without index or message, as an earlier spotsim may have written, gets -1 and '')."""
        known = {f.name for f in dataclasses.fields(cls)}
        about = {**d.get("about", {}), **{k: v for k, v in d.items() if k not in known}}
        fields = {"index": -1, "message": "", **{k: v for k, v in d.items() if k in known and k != "about"}}
        return cls(**fields, about=about)


@dataclass(frozen=True)
class Task:
    """One run a study asks for: its scenario (None for one that is not valid: `problems` say
    why), its index in the study, its key (`scenario_key`; None: kept nowhere) and the study's
    own about it (a sweep point's values, an ensemble member's start), which its record keeps."""

    scenario: object = None
    index: int = 0
    key: str | None = None
    about: dict = dataclasses.field(default_factory=dict)
    problems: tuple = ()


def failed(task: Task, error: BaseException) -> Record:
    """The record of a task that failed outside its run: its worker died (twice), or it could
    not be sent."""
    return Record(task.key, task.index, WORKER_DIED if worker_died(error) else EXCEPTION,
                  f"{type(error).__name__}: {error}", about=dict(task.about))


# ----------------------------------------------------------------------------- execute


def execute(run: Callable, tasks, runner: Runner, finished: Callable, failed: Callable = failed, *,
            what: str = "study", total: int | None = None, warm: Callable | None = None) -> int:
    """Call `run(task)` for every task on `runner`'s backend, and for each task a finished one
    brings: `finished(task, record)` is called here as each ends and returns more tasks (or
    None). `run` (picklable: a module's function or a partial of one) must not raise; a task
    that fails anyway, by its worker's death or an error in sending it, gets
    `failed(task, error)` as its record. `warm()`, if given, runs once in every worker before
    its first task (here before forking). A bar of `total` tasks shows progress when
    `runner.progress`. Ctrl-C: KeyboardInterrupt, after the records handed back. Returns how
    many tasks ran."""
    from ..run import progress_bar

    tasks = list(tasks)
    if not tasks:  # nothing to run: no pool or cluster started
        return 0
    bar = progress_bar(total, runner.progress, what=what, unit="run")
    count = [0]

    def done(task, record):
        count[0] += 1
        bar.update(1)
        return finished(task, record) or []

    try:
        if runner.backend == DASK:
            _on_dask(run, tasks, runner, done, failed, warm)
        elif runner.backend == PROCESSES and not _in_daemon():
            _on_processes(run, deque(tasks), runner, done, failed, warm)
        else:
            if warm is not None:
                warm()
            queue = deque(tasks)
            while queue:
                task = queue.popleft()
                queue.extend(done(task, run(task)))
    finally:
        bar.close()
    return count[0]


def _in_daemon() -> bool:
    """Whether this is a pool's or Dask's worker, which may not start processes of its own: its
    runs on the processes backend are serial."""
    return multiprocessing.current_process().daemon


def _ignore_ctrl_c(warm) -> None:
    """A pool worker's start: Ctrl-C is the parent's to handle; warm up if asked."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if warm is not None:
        warm()


def _on_processes(run, queue: deque, runner: Runner, done, failed, warm) -> None:
    """The tasks on a pool of worker processes; a pool broken by a worker's death is started
    again, its tasks in flight tried once more."""
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    fork = sys.platform.startswith("linux")  # elsewhere the pool spawns: each worker loads the kernels
    if fork and warm is not None:
        warm()  # here once, for every worker to inherit
    ctx = multiprocessing.get_context("fork" if fork else "spawn")
    tries: dict[int, int] = {}
    while queue:
        pool = ProcessPoolExecutor(runner.worker_count(len(queue)), mp_context=ctx, initializer=_ignore_ctrl_c,
                                   initargs=(None if fork else warm,))
        pending: dict = {}
        try:
            while queue or pending:
                while queue:
                    task = queue.popleft()
                    pending[pool.submit(run, task)] = task
                ended, _ = wait(pending, return_when=FIRST_COMPLETED)
                for future in ended:
                    task = pending[future]
                    try:
                        record = future.result()
                    except BrokenProcessPool:
                        raise
                    except Exception as e:  # noqa: BLE001 - the task's failure (its arguments would not pickle)
                        record = failed(task, e)
                    del pending[future]
                    queue.extend(done(task, record))
        except BrokenProcessPool:  # a worker died: every task in flight lost its result
            for task in pending.values():
                tries[id(task)] = tries.get(id(task), 0) + 1
                if tries[id(task)] > 1:
                    queue.extend(done(task, failed(task, WorkerDied("its worker process died twice"))))
                else:
                    queue.appendleft(task)
        finally:
            _stop(pool)


def _stop(pool) -> None:
    """Stop a pool's workers now, whatever they are running."""
    for p in list((getattr(pool, "_processes", None) or {}).values()):
        if p.is_alive():
            p.kill()
    pool.shutdown(wait=True, cancel_futures=True)


def _on_dask(run, first: list, runner: Runner, done, failed, warm) -> None:
    """The tasks on Dask (every worker warmed first, and each that joins later); a task's
    failure is its `failed` record; a lost scheduler is SchedulerLost."""
    from distributed import as_completed

    with dask_client(runner) as client:
        if warm is not None:
            _warm_workers(client, warm)
        pending, tasks = as_completed(), {}

        def submit(batch):
            for task in batch:
                future = client.submit(run, task, pure=False)
                tasks[future.key] = task
                pending.add(future)

        submit(first)
        for future in pending:
            task = tasks.pop(future.key)
            submit(done(task, _result(task, future, failed)))


def _result(task, future, failed):
    """The record of a finished Dask task: its run's, or its failure's. A result that cannot
    be had because the client lost its scheduler (futures cancelled, the connection closed) is
    no task's failure: SchedulerLost."""
    from distributed.client import FutureCancelledError
    from distributed.comm.core import CommClosedError

    try:
        return future.result()
    except (FutureCancelledError, CommClosedError, OSError) as e:
        raise SchedulerLost(f"the Dask scheduler was lost ({type(e).__name__})") from e
    except Exception as e:  # noqa: BLE001 - the task's failure, not the study's
        return failed(task, e)


def _warm_workers(client, warm) -> None:
    """`warm()` on every worker of `client`, now and as each joins later (a worker plugin, set
    up before the worker takes a task). A worker lost meanwhile, or whose warm-up raised, is
    passed over: a task that lands on a worker builds what it needs there."""
    from distributed.diagnostics.plugin import WorkerPlugin

    class Warm(WorkerPlugin):
        def setup(self, worker):
            warm()

    try:
        client.register_plugin(Warm(), name="spotsim-warm")  # replaces an earlier study's
    except Exception:  # noqa: BLE001 - a worker lost while it warmed, or a warm-up that raised
        pass


@contextmanager
def dask_client(runner: Runner):
    """A dask.distributed Client: of `runner.scheduler`, or of a local cluster of
    `runner.workers` single-threaded worker processes (default one per core) whose scheduler
    lets a task's worker die once (`allowed-failures`) before it gives up on the task."""
    import dask
    from distributed import Client, LocalCluster

    local = None
    quiet = _quiet_dask()  # a lost worker or scheduler is reported by the study, not by Dask's logs
    try:
        with dask.config.set({"distributed.scheduler.allowed-failures": 1}):
            if runner.scheduler:
                try:
                    client = Client(runner.scheduler, timeout="30s")
                except (OSError, ValueError) as e:  # no answer; an address distributed cannot parse
                    raise SpotsimError(f"--scheduler {runner.scheduler}: cannot connect: {e}") from e
            else:
                # started empty, then scaled: a worker lost while it starts is started again by the
                # cluster instead of failing its construction
                local = LocalCluster(n_workers=0, threads_per_worker=1, processes=True, dashboard_address=":0",
                                     silence_logs=logging.CRITICAL)
                client = Client(local)
                local.scale(runner.worker_count())
        try:
            yield client
        finally:
            client.close()
            if local is not None:
                local.close()
    finally:
        quiet()


def _quiet_dask():
    """Raise Dask's loggers to CRITICAL; returns the function that restores them."""
    names = [n for n in logging.root.manager.loggerDict if n.split(".")[0] in ("distributed", "tornado")]
    loggers = [logging.getLogger(n) for n in ("distributed", "tornado", "asyncio", *names)]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.CRITICAL)

    def restore():
        for lg, level in zip(loggers, levels, strict=True):
            lg.setLevel(level)
    return restore


# ----------------------------------------------------------------------------- keys


@functools.cache
def code_fingerprint() -> str:
    """A hash of the code a study's run runs: spotsim's modules and the URDF/XACRO files it builds
    its scenes from, by their paths and contents."""
    from ..assemble.assets import URDF_DIR

    package = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    add_sources(digest, package, sorted(package.rglob("*.py")))
    add_sources(digest, URDF_DIR, sorted([*URDF_DIR.rglob("*.xacro"), *URDF_DIR.rglob("*.urdf")]))
    return digest.hexdigest()


def scenario_key(scenario) -> str:
    """A short hash of a resolved scenario and of the code that runs it (`code_fingerprint`):
    equal scenarios under equal code, equal keys; a record computed by other code is not
    reused (a version of spotsim is its code)."""
    return hashlib.sha256((code_fingerprint() + to_yaml(scenario)).encode()).hexdigest()[:16]


# ----------------------------------------------------------------------------- records


def read_records(path: Path) -> dict[str, Record]:
    """The finished runs of a records file (`append_record`) by key. A last line without its newline (a kill
    while writing) is dropped and cut from the file; any other line that is not a record is an
    error (SpotsimError), and the file is left as it is."""
    out: dict = {}
    if not path.exists():
        return out
    data = path.read_bytes()
    lines = data.splitlines(keepends=True)
    for n, line in enumerate(lines, 1):
        if not line.endswith(b"\n"):
            with path.open("r+b") as f:
                f.truncate(len(data) - len(line))
            break
        try:
            rec = json.loads(line)
        except ValueError:
            rec = None
        if not isinstance(rec, dict) or "key" not in rec or "status" not in rec:
            raise SpotsimError(f"{path}: line {n} is not a study's run record: not resumable; move the file "
                               "or give another --out")
        out.setdefault(rec["key"], Record.of_json(rec))
    return out


def append_record(path: Path, record: Record) -> None:
    """Append a finished run's record as one JSON line,
    synced to disk: the one writer of every resumable study. A write that fails (a full
    disk) is cut back off, so that the file keeps whole lines only, and is a SpotsimError."""
    data = memoryview((json.dumps(dataclasses.asdict(record), default=plain) + "\n").encode())
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    size = os.fstat(fd).st_size
    try:
        while data:
            data = data[os.write(fd, data):]
        os.fsync(fd)
    except OSError as e:
        try:
            os.ftruncate(fd, size)
        except OSError:
            pass  # a line cut short is dropped when the file is read (`read_records`)
        raise SpotsimError(f"{path}: cannot write a finished run: {e.strerror}; the runs before it are "
                           "kept: free some space and run the study again to resume") from e
    finally:
        os.close(fd)


def plain(x):
    """A JSON value of what json cannot write itself: numpy's, a dataclass, else its text."""
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    if dataclasses.is_dataclass(x):
        return dataclasses.asdict(x)
    return str(x)


# ----------------------------------------------------------------------------- a worker's models

#: A process's models by scene key, and compiled scenes (URDF and contact faces) by the
#: XACRO's inputs, the least recently used first.
_MODELS: OrderedDict = OrderedDict()
_SCENES: OrderedDict = OrderedDict()


def scene_key(scenario) -> str:
    """A hash of the scenario without the modules' starts: scenarios with equal scene keys
    share a model (`assemble.model.with_start`)."""
    raw = to_dict(scenario)
    for k in modules_of(scenario):
        raw[k].pop("initial_offset_mm", None)
        raw[k].pop("initial_rpy_deg", None)
    return hashlib.sha256(json.dumps(raw, sort_keys=True, default=str).encode()).hexdigest()


def _kept(cache: OrderedDict, key, value):
    cache[key] = value
    cache.move_to_end(key)
    while len(cache) > MODELS_KEPT:
        cache.popitem(last=False)
    return value


def keep_model(model) -> None:
    """Keep a model built elsewhere among this process's (workers forked later inherit it)."""
    _kept(_MODELS, scene_key(model.scenario), model)


def model_for(scenario, source: str = "<study>"):
    """The Model of `scenario`, from the process's kept models when one shares its scene (only
    the starts differ), else built on the compiled scene of one that shares its XACRO's
    inputs (the geometry and the modules' mass properties: the contact law, friction, drive,
    integrator may differ), else built whole."""
    from ..assemble.model import build_model, with_start
    from ..assemble.scene import scene_spec

    k = scene_key(scenario)
    nominal = _MODELS.get(k)
    if nominal is None:
        spec = scene_spec(scenario)
        xacro = hashlib.sha256(json.dumps([str(spec.xacro), sorted(spec.args.items())], default=str).encode()).digest()
        compiled = _SCENES.get(xacro)
        if compiled is None:
            nominal = build_model(scenario, source)
        else:
            nominal = build_model(scenario, source, urdf=compiled[0], faces=compiled[1])
        _kept(_SCENES, xacro, (nominal.urdf, nominal.faces))
        _kept(_MODELS, k, nominal)
    else:
        _MODELS.move_to_end(k)
    return nominal if nominal.scenario == scenario else with_start(nominal, scenario)


def warm_worker(scenario, source: str = "<study>") -> int:
    """Build the scenario's model and load the compiled loop into this process (once per
    worker, before its first task): the runs' wall times are then their own."""
    from ..run import compile_loop, initial_contacts
    from ..sim.data import make_data

    model = model_for(scenario, source)
    compile_loop(model, make_data(model))
    initial_contacts(model)
    return os.getpid()
