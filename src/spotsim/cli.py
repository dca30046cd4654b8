"""`spotsim` command line (run, validate, plot, replay, study): a thin layer over the library.

Exit codes: 0 completed (or valid), 2 bad input, 3 incomplete, 4 diverged, 130 interrupted.
`run --ensemble N` exits with its worst member's: 0 all completed, 3 some incomplete, 4 some
diverged, 1 some failed (an exception, or a perturbed start rejected), 130 interrupted.
`study` exits 0 when it ran to its end, 1 when a stability case failed (an uncaught exception
or a silent NaN: what the simulator must never do), 2 on bad input, 130 when interrupted.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

from . import study_figures, study_reports
from .errors import ScenarioError, SpotsimError
from .jit import announce_compiling
from .measures import CAMERA_HZ
from .paths import results_dir
from .status import (
    COMPLETED,
    DIVERGED,
    EXCEPTION,
    INCOMPLETE,
    INTERRUPTED,
    NOT_CAPTURED,
    REJECTED,
    WEDGED_TILT_DEG,
    run_outcome,
)
from .studies.ensemble import ALL_AXES, FAMILIES
from .studies.estimate import MIN_SPREAD_COUNT, SPREAD_MEMBERS

DEFAULT_SCENARIO = "single_arm_case_I.yaml"
#: `run`'s exit code by the run's status (`status`).
EXIT = {COMPLETED: 0, INCOMPLETE: 3, DIVERGED: 4, NOT_CAPTURED: 5, INTERRUPTED: 130}


class _Parser(argparse.ArgumentParser):
    """argparse's parser, its errors one line (`spotsim run: argument --seed: -1: must be >= 0`)
    and exit code 2, without the usage block."""

    def error(self, message):
        self.exit(2, f"{self.prog}: {message}\n")


def _at_least(minimum: int):
    """An argparse type: a whole number >= `minimum`."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text}: must be a whole number") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"{text}: must be >= {minimum}")
        return value
    return parse


COUNT, SEED = _at_least(1), _at_least(0)


def _spread_members(text: str) -> int:
    """An argparse type: 0 (no spread over starts) or enough starts for a chance range."""
    value = SEED(text)
    if 0 < value < MIN_SPREAD_COUNT:
        raise argparse.ArgumentTypeError(f"{text}: 0 (none) or at least {MIN_SPREAD_COUNT} (a chance range needs "
                                         f"{MIN_SPREAD_COUNT} runs)")
    return value


def _rate(text: str) -> float:
    """An argparse type: a positive, finite rate (Hz)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text}: must be a number") from None
    if not (math.isfinite(value) and 0 < value <= MAX_SAMPLE_HZ):
        raise argparse.ArgumentTypeError(f"{text}: must be in (0, {MAX_SAMPLE_HZ:g}] Hz")
    return value


#: The fastest camera rate `--sample-hz` takes: ten times a run's default record rate.
MAX_SAMPLE_HZ = 10_000.0


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="spotsim", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a scenario and write its results")
    run.add_argument("config", nargs="?", help=f"scenario YAML, or a shipped scenario's name (`spotsim list`; "
                                              f"default: config/{DEFAULT_SCENARIO})")
    run.add_argument("--out", help="results directory (default: results/<scenario name>, with --set "
                                   "results/<scenario name>+<the changes>; with --ensemble, its ensemble/)")
    run.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                     help="override a scenario key, validated like the file (repeatable)")
    run.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    run.add_argument("--no-error-estimate", action="store_true",
                     help="skip the companion run that estimates the discretisation error (about half a run)")
    run.add_argument("--spread-members", type=_spread_members, default=SPREAD_MEMBERS, metavar="N",
                     help=f"a completed run of a scenario that no study has seen: its spread over N starts around "
                          f"its own, which gives its error bound (default {SPREAD_MEMBERS}; 0: none)")
    run.add_argument("--quiet", action="store_true", help="no progress bar, and one line: the run's verdict")
    run.add_argument("--replay", action="store_true", help="replay the run in Meshcat when it ends")
    run.add_argument("--zmq-url", help="with --replay: the Meshcat server to use (default: start one)")
    run.add_argument("--ensemble", type=COUNT, metavar="N",
                     help="run N members from starts perturbed within +-10 um and +-0.01 deg (member 0 "
                          "unperturbed) and write their statistics (ensemble.json, members.csv)")
    run.add_argument("--seed", type=SEED, default=0, metavar="S", help="with --ensemble: the perturbations' seed "
                                                                      "(default 0)")
    run.add_argument("--workers", type=COUNT, metavar="W", help="with --ensemble: processes (default: CPU count)")
    run.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="with --ensemble: run the members on this "
                                                                     "Dask scheduler's workers")
    run.add_argument("--perturb", choices=FAMILIES, default=ALL_AXES,
                     help="with --ensemble: which start coordinates a member moves: all (default) or one_axis "
                          "(member i only the (i-1) mod 6-th of x, y, z, roll, pitch, yaw)")
    run.add_argument("--sample-hz", type=_rate, default=CAMERA_HZ, metavar="HZ",
                     help=f"a dual-arm run's markers.csv: its bodies' displacements sampled at this rate, as a "
                          f"motion camera records them (default {CAMERA_HZ:g} Hz, the SPOT testbed's)")
    val = sub.add_parser("validate", help="print the resolved scenario, or every problem in it")
    val.add_argument("config", help="scenario YAML, or a shipped scenario's name")
    sub.add_parser("list", help="the shipped scenarios: their names (which run, validate, sweep, envelope and "
                                "study take in place of a file) and descriptions")
    val.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE")
    plot = sub.add_parser("plot", help="regenerate the figures of a run's results directory, or draw an ensemble's, "
                                       "a sweep's, an envelope's or an accuracy study's")
    plot.add_argument("result_dir")
    plot.add_argument("--sample-hz", type=_rate, default=CAMERA_HZ, metavar="HZ",
                      help=f"the camera rate of the displacement figure's samples (default {CAMERA_HZ:g} Hz)")
    plot.add_argument("--markers", metavar="CSV", help="a measured marker record (time_s, then <body>_x_mm, "
                      "<body>_y_mm, <body>_yaw_deg displacements): plotted against the run, with the error per grasp")
    rep = sub.add_parser("replay", help="replay a run in Meshcat, in the browser or as one HTML file")
    rep.add_argument("result_dir")
    rep.add_argument("--html", metavar="FILE", help="write a self-contained HTML file instead (no server)")
    rep.add_argument("--zmq-url", help="the Meshcat server to use (default: start one)")
    rep.add_argument("--rate", type=float, default=100.0, metavar="HZ",
                     help="display frames per simulated second (default 100, the recorded rate)")
    rep.add_argument("--no-spheres", action="store_true", help="hide the sphere layers")
    rep.add_argument("--force-scale", type=float, metavar="MM_PER_N",
                     help="force arrow length per newton (default: a typical load draws 80 mm)")
    rep.add_argument("--no-loop", action="store_true", help="play once instead of looping")
    rep.add_argument("--no-browser", action="store_true", help="do not open a browser")
    _study_parser(sub)
    _sweep_parser(sub)
    _envelope_parser(sub)
    return p


def _envelope_parser(sub) -> None:
    from .studies.envelope import AXES, LIMIT, PLANE_RAYS, RESOLUTION
    from .studies.runner import MAX_POINTS, WALL_LIMIT_S
    from .studies.sweep import PRECISION_MM

    en = sub.add_parser("envelope", help="the capture envelope of a single-arm scenario, by bisection along rays")
    en.add_argument("config", help="scenario YAML, or a shipped scenario's name (single arm)")
    en.add_argument("--axes", default=",".join(AXES), help=f"axes searched both ways (default {','.join(AXES)})")
    en.add_argument("--planes", default="x-y,roll-yaw", help="planes fanned with rays, or 'none' (default "
                                                             "x-y,roll-yaw)")
    en.add_argument("--rays", type=COUNT, default=PLANE_RAYS, metavar="N",
                    help=f"rays around each plane (default {PLANE_RAYS})")
    en.add_argument("--resolution-mm", type=float, default=RESOLUTION["mm"], metavar="MM")
    en.add_argument("--resolution-deg", type=float, default=RESOLUTION["deg"], metavar="DEG")
    en.add_argument("--limit-mm", type=float, default=LIMIT["mm"], metavar="MM", help="farthest offset searched")
    en.add_argument("--limit-deg", type=float, default=LIMIT["deg"], metavar="DEG", help="farthest angle searched")
    en.add_argument("--precision-mm", type=float, default=PRECISION_MM, metavar="MM",
                    help=f"a closed grasp's residual offset within it (and its tilt within {WEDGED_TILT_DEG:g} deg) "
                         f"is seated, captured (default {PRECISION_MM:g}, the ensembles')")
    en.add_argument("--out", help="output directory (default results/<scenario name>/envelope); started again "
                                  "over it, probes already run are not run again")
    _runner_arguments(en)
    en.add_argument("--wall-limit", type=float, default=WALL_LIMIT_S, metavar="S", help="budget of each probe")
    en.add_argument("--max-points", type=COUNT, default=MAX_POINTS, metavar="N",
                    help=f"refuse a search that may run more probes (default {MAX_POINTS})")
    en.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                    help="override a scenario key for every probe (repeatable)")
    en.add_argument("--members", type=COUNT, default=1, metavar="N",
                    help="near each boundary, run its bracket as ensembles of N perturbed starts and report the "
                         "capture fraction (default 1: the bisection alone)")
    en.add_argument("--seed", type=SEED, default=0, metavar="S", help="with --members: the perturbations' seed")
    en.add_argument("--quiet", action="store_true", help="no progress bar")


def _envelope(args) -> int:
    """`spotsim envelope`: exit 0, 2 on bad input, 130 if interrupted."""
    from .scenario import load_scenario
    from .studies.envelope import AXES, PLANES, Search, envelope

    try:
        path = _config_path(args.config)
        axes = tuple(a for a in args.axes.split(",") if a) if args.axes != "none" else ()
        bad = [a for a in axes if a not in AXES]
        planes = () if args.planes == "none" else tuple(tuple(p.split("-")) for p in args.planes.split(","))
        bad += ["-".join(p) for p in planes if p not in PLANES]
        if bad:
            raise ScenarioError([f"--axes/--planes: {', '.join(bad)}: not one of {', '.join(AXES)} / "
                                 f"{', '.join('-'.join(p) for p in PLANES)}"])
        for name in ("resolution_mm", "resolution_deg", "limit_mm", "limit_deg"):
            if not getattr(args, name) > 0:
                raise ScenarioError([f"--{name.replace('_', '-')} = {getattr(args, name)}: must be positive"])
        runner = _runner(args)
        out = Path(args.out) if args.out else results_dir(load_scenario(path, args.set).name, args.set, "envelope")
        search = Search(axes, planes, args.rays, {"mm": args.resolution_mm, "deg": args.resolution_deg},
                        {"mm": args.limit_mm, "deg": args.limit_deg}, args.precision_mm, args.members, args.seed)
        report = envelope(path, out, search, runner=runner, sets=args.set)
    except SpotsimError as e:
        return _bad_input(e)
    _draw(study_figures.plot_envelope, out)
    print((out / "envelope.md").read_text(), end="")
    probes = sum(len(r.probes) for r in report.rays)
    near = sum(n for r in report.rays for _, n in r.chance.values())
    print(f"{probes} bisection probes" + (f" and {near} runs near the boundaries" if near else "")
          + f"; {report.runs} of them run now, the others found in {out}")
    return 130 if report.interrupted else 0


def _sweep_parser(sub) -> None:
    from .studies.runner import MAX_POINTS, WALL_LIMIT_S
    from .studies.sweep import PRECISION_MM

    sw = sub.add_parser("sweep", help="run a scenario over variations of its keys on Dask, resumable")
    sw.add_argument("config", help="scenario YAML, or a shipped scenario's name")
    sw.add_argument("--vary", action="append", default=[], metavar="KEY.PATH=LO:HI:N|A,B,C",
                    help="an axis of a grid: N values from LO to HI, or the values listed (repeatable; "
                         "module.initial_offset_mm.1 is one component)")
    sw.add_argument("--spec", metavar="FILE", help="a YAML spec of the points: a grid, a Sobol or Latin "
                                                    "hypercube sample over ranges, or a list (docs/usage.md)")
    sw.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                    help="override a scenario key at every point (repeatable)")
    sw.add_argument("--out", help="output directory (default results/<scenario name>/sweep); a sweep started "
                                  "again over it runs only the points it lacks")
    _runner_arguments(sw)
    sw.add_argument("--wall-limit", type=float, default=WALL_LIMIT_S, metavar="S",
                    help=f"wall-time budget of each point (default {WALL_LIMIT_S:g} s)")
    sw.add_argument("--max-points", type=COUNT, default=MAX_POINTS, metavar="N",
                    help=f"refuse a sweep of more points (default {MAX_POINTS})")
    sw.add_argument("--precision-mm", type=float, default=PRECISION_MM, metavar="MM",
                    help=f"a closed grasp's residual offset within it (and its tilt within {WEDGED_TILT_DEG:g} deg) "
                         f"is seated, else wedged (default {PRECISION_MM:g}, the ensembles')")
    sw.add_argument("--no-error-estimate", action="store_true", help="skip each point's companion run")
    sw.add_argument("--quiet", action="store_true", help="no progress bar")


def _runner_arguments(parser, backend: bool = True) -> None:
    """The runner's options: where the runs go (`studies.runner.Runner`)."""
    from .studies.runner import BACKENDS, DASK

    if backend:
        parser.add_argument("--backend", choices=BACKENDS, default=DASK,
                            help="where the runs go: a Dask cluster (default), a pool of processes here, or here "
                                 "one after the other")
    parser.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="an existing Dask scheduler (default: a "
                                                                         "local cluster)")
    parser.add_argument("--workers", type=COUNT, metavar="W", help="local cluster or pool: worker processes "
                                                                 "(default: one per core)")


def _runner(args):
    """The Runner of `sweep`'s and `envelope`'s options (SpotsimError for a bad budget or a
    scheduler beside another backend)."""
    from .studies.runner import Runner

    if not args.wall_limit > 0:
        raise ScenarioError([f"--wall-limit = {args.wall_limit}: must be positive"])
    return Runner(args.backend, args.scheduler, args.workers, args.wall_limit, not args.quiet, args.max_points)


def _list() -> int:
    """`spotsim list`: each shipped scenario's name and description."""
    from .paths import shipped_scenarios
    from .scenario import read_yaml

    print("shipped scenarios (give a name, or its end after an underscore when only one ends so: case_III):")
    for name, path in shipped_scenarios().items():
        print(f"  {name:24s} {(read_yaml(path) or {}).get('description', '')}")
    return 0


def _bad_input(e: SpotsimError) -> int:
    """Print every problem of a bad input (a ScenarioError's each on its line): exit code 2."""
    for line in e.problems if isinstance(e, ScenarioError) else [str(e)]:
        print(line, file=sys.stderr)
    return 2


def _sweep(args) -> int:
    """`spotsim sweep`: exit 0 when every point has a row (whatever its status), 2 on bad
    input, 130 if interrupted."""
    from .scenario import load_scenario
    from .studies.sweep import run_sweep, spec_of

    try:
        path = _config_path(args.config)
        runner = _runner(args)
        spec = spec_of(args.vary, args.spec, args.set, runner.max_points)
        out = Path(args.out) if args.out else results_dir(load_scenario(path, spec.sets).name, spec.sets, "sweep")
        report = run_sweep(path, spec, out, runner=runner, precision_mm=args.precision_mm,
                           error_estimate=not args.no_error_estimate)
    except SpotsimError as e:
        return _bad_input(e)
    for line in report.lines():
        print(line)
    return 130 if report.interrupted else 0


def _study_parser(sub) -> None:
    from .studies.accuracy import GRIDS
    from .studies.estimate import VALIDATION_SEED
    from .studies.stability import STABILITY_WALL_LIMIT_S

    study = sub.add_parser("study", help="accuracy against run time, or stability, over many runs")
    verbs = study.add_subparsers(dest="study", required=True)
    acc = verbs.add_parser("accuracy", help="work-precision: a confirmed reference, then integrator x step")
    stab = verbs.add_parser("stability", help="stiff and extreme cases: predicted stable step and verdict")
    est = verbs.add_parser("estimate", help="each run's error estimate against a converged reference, over starts")
    spreads = verbs.add_parser("spreads", help="the typical spreads over starts of studied scenarios, from their "
                                               "ensemble accuracy studies: the file a run's bound reads")
    spreads.add_argument("studies", nargs="+", metavar="CONFIG=STUDY_DIR",
                         help="a scenario (file or shipped name) and the directory of its `spotsim study accuracy "
                              "--ensemble N`, which ran it at its own setting")
    spreads.add_argument("--out", required=True, metavar="FILE",
                         help="the spreads file to write (spotsim's own: src/spotsim/studies/typical_spread.json)")
    for v in (acc, stab, est):
        v.add_argument("config", nargs="?", help=f"scenario YAML, or a shipped scenario's name (default: "
                                                 f"config/{DEFAULT_SCENARIO})")
        v.add_argument("--out", help="output directory (default: results/study/<scenario name>)")
        v.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                       help="override a scenario key for every run (repeatable)")
        v.add_argument("--duration", type=float, metavar="S", help="simulation.duration_s of every run")
        v.add_argument("--quiet", action="store_true", help="no progress bar")
    acc.add_argument("--grid", choices=list(GRIDS), default="default",
                     help="the settings swept and the reference (default: default; see docs/usage.md)")
    acc.add_argument("--quick", action="store_true", help="the suite's grid: Case I's first contact, 7 runs")
    acc.add_argument("--methods", metavar="M,M", help="only these of symplectic_euler, adaptive_euler, rk4, dopri5")
    acc.add_argument("--substeps", metavar="N,N", help="the fixed-step methods' substeps (replaces the grid's)")
    acc.add_argument("--rtols", metavar="R,R", help="dopri5's relative tolerances (replaces the grid's)")
    acc.add_argument("--tols", metavar="T,T", help="adaptive_euler's velocity tolerances, m/s (replaces the grid's)")
    acc.add_argument("--sphere-scales", metavar="F,F", help="factors on both sphere radii (default: the grid's)")
    acc.add_argument("--reference", metavar="METHOD:VALUE",
                     help="the reference, e.g. symplectic_euler:80, adaptive_euler:1e-6 or dopri5:1e-7; its "
                          "refinement confirms it")
    acc.add_argument("--wall-limit", type=float, metavar="S", help="wall-time budget of each run (default: none)")
    acc.add_argument("--no-plot", action="store_true", help="skip the work-precision plot")
    est.add_argument("--members", type=COUNT, default=8, metavar="N", help="starts compared (default 8)")
    est.add_argument("--spread-members", type=_spread_members, default=SPREAD_MEMBERS, metavar="N",
                     help=f"a scenario that no study has seen: each start's spread over N starts around it, as "
                          f"`spotsim run` measures it (default {SPREAD_MEMBERS}; 0: none)")
    est.add_argument("--reference", metavar="METHOD:VALUE", default="symplectic_euler:1280",
                     help="the converged setting (default symplectic_euler:1280, 0.78125 us at dt 1 ms: the "
                          "ensemble accuracy studies' confirmed reference)")
    est.add_argument("--workers", type=COUNT, metavar="W", help="parallel processes (default: one per core)")
    est.add_argument("--seed", type=SEED, default=VALIDATION_SEED, metavar="S",
                     help=f"the starts' seed (default {VALIDATION_SEED}: other starts than the ensemble accuracy "
                          "study's, seed 0, whose spreads the bound uses)")
    acc.add_argument("--ensemble", type=COUNT, metavar="N",
                     help="run every setting as an N-member ensemble from the same perturbed starts and compare "
                          "distributions (KS test, medians) with the reference's ensemble")
    acc.add_argument("--seed", type=SEED, default=0, metavar="S", help="with --ensemble: the starts' seed (default 0)")
    acc.add_argument("--workers", type=COUNT, metavar="W", help="with --ensemble: processes (default: CPU count)")
    acc.add_argument("--confirmation-members", type=COUNT, metavar="K",
                     help="with --ensemble: run the confirmation on the first K starts only (default: N)")
    stab.add_argument("--cases", metavar="NAME,NAME",
                      help="cases or groups (stiff, extreme, baseline); spaces ignored, e.g. 'Ex100,y_a+10mm'")
    stab.add_argument("--quick", action="store_true", help="the suite's cases, each 1.5 s simulated")
    stab.add_argument("--wall-limit", type=float, metavar="S", default=STABILITY_WALL_LIMIT_S,
                      help=f"wall-time budget of each case (default {STABILITY_WALL_LIMIT_S:g} s)")


def _numbers(text: str | None, kind, what: str):
    """A comma-separated list of numbers, or None; ValueError names the option."""
    if text is None:
        return None
    try:
        values = tuple(kind(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise ValueError(f"{what} {text}: must be comma-separated {kind.__name__}s") from None
    if not values or any(not v > 0 for v in values):
        raise ValueError(f"{what} {text}: every value must be > 0")
    return values


def _spreads(args) -> int:
    """`spotsim study spreads`: write the spreads file of the studies given; exit 2 on bad input."""
    from .scenario import load_scenario
    from .studies.estimate import spread_from_study, write_spreads

    try:
        entries = []
        for pair in args.studies:
            config, sep, study_dir = pair.partition("=")
            if not sep or not config or not study_dir:
                raise ScenarioError([f"{pair}: must read CONFIG=STUDY_DIR"])
            path = _config_path(config)
            entries.append(spread_from_study(load_scenario(path), study_dir))
        write_spreads(entries, args.out)
    except SpotsimError as e:
        return _bad_input(e)
    for e in entries:
        print(f"{e['scenario']}: {e['about']}")
    print(f"  {args.out}")
    return 0


def _study(args) -> int:
    """`spotsim study accuracy|stability|estimate` (and `spreads`): exit 2 on bad input, 130 if
    interrupted, 1 if a stability case failed, else 0."""
    if args.study == "spreads":
        return _spreads(args)
    from .studies import accuracy, stability

    overrides = list(args.set)
    duration = args.duration
    try:
        if duration is not None and not duration > 0:
            raise ValueError(f"--duration {duration}: must be > 0")
        if args.study == "accuracy":
            grid = accuracy.GRIDS["quick" if args.quick else args.grid]
            chosen = accuracy.narrowed(
                grid, args.methods.split(",") if args.methods else None, _numbers(args.substeps, int, "--substeps"),
                _numbers(args.rtols, float, "--rtols"), _numbers(args.tols, float, "--tols"),
                _numbers(args.sphere_scales, float, "--sphere-scales"),
                accuracy.parse_setting(args.reference) if args.reference else None)
            if args.wall_limit is not None and not args.wall_limit > 0:
                raise ValueError(f"--wall-limit {args.wall_limit}: must be > 0")
            if args.ensemble is None:
                given = [o for o, v in (("--seed", args.seed != 0), ("--workers", args.workers is not None),
                                        ("--confirmation-members", args.confirmation_members is not None)) if v]
                if given:
                    raise ValueError(f"{', '.join(given)}: only with --ensemble N")
            else:
                if args.wall_limit is not None:
                    raise ValueError("--wall-limit: not with --ensemble")
            duration = duration or grid.duration_s
        elif args.study == "estimate":
            reference = accuracy.parse_setting(args.reference)
        else:
            if args.wall_limit is not None and not args.wall_limit > 0:
                raise ValueError(f"--wall-limit {args.wall_limit}: must be > 0")
            names = args.cases.split(",") if args.cases else list(stability.QUICK_CASES) if args.quick else None
            cases = stability.select_cases(names) if names else stability.stability_cases()
            duration = duration or (stability.QUICK_DURATION_S if args.quick else None)
    except ValueError as e:
        print(e, file=sys.stderr)
        return 2
    if duration is not None:
        overrides.append(f"simulation.duration_s={duration}")
    try:
        path = _config_path(args.config)
    except ScenarioError as e:
        return _bad_input(e)
    loaded = _load_or_report(path, overrides)
    if loaded is None:
        return 2
    scenario, _ = loaded
    out = Path(args.out) if args.out else Path("results", "study", results_dir(scenario.name, args.set).name)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        print(f"{out}: cannot write results: {e.strerror}", file=sys.stderr)
        return 2
    progress = not args.quiet
    if args.study == "estimate":
        return _estimate_study(scenario, reference, args, out, progress)
    try:
        if args.study == "accuracy":
            report = accuracy.accuracy_study(scenario, chosen.settings(), chosen.reference, out, source=str(path),
                                             progress=progress, wall_limit_s=args.wall_limit,
                                             ensemble=args.ensemble, seed=args.seed, workers=args.workers,
                                             confirmation_members=args.confirmation_members)
            print(f"{scenario.name}: accuracy, {len(report.rows)} runs" if args.ensemble is None else
                  f"{scenario.name}: accuracy over ensembles of {args.ensemble} (seed {args.seed}), "
                  f"{len(report.rows)} settings")
            for line in study_reports.findings(report):
                print(f"  {line}")
        else:
            report = stability.stability_study(scenario, cases, out, source=str(path), progress=progress,
                                           wall_limit_s=args.wall_limit)
            print(f"{scenario.name}: stability, {len(report.rows)} cases")
            for r in report.rows:
                print(f"  {r['case']}: {r['verdict']} - {r['message']}")
        report.files += study_reports.write_markdown(scenario, report, out)
        if args.study == "accuracy" and not args.no_plot and report.rows:
            report.files += _draw(study_figures.plot_accuracy if args.ensemble is None else
                                  study_figures.plot_accuracy_ensemble, out)
    except OSError as e:
        print(f"{out}: cannot write results: {e.strerror}", file=sys.stderr)
        return 2
    except SpotsimError as e:  # a results directory it cannot prepare (`files.prepare`)
        return _bad_input(e)
    for f in report.files:
        print(f"  {f}")
    if report.interrupted:
        print("interrupted: the rows written are the runs that finished", file=sys.stderr)
        return 130
    return 1 if args.study == "stability" and report.failures else 0


def _draw(plot, out: Path) -> list[Path]:
    """A study's figure (`study_figures`), drawn from the tables it wrote; a figure that fails
    is one line on stderr and never costs the study's results."""
    try:
        return plot(out)
    except Exception as e:  # noqa: BLE001 - the results are written: the figure is extra
        print(f"{out}: no figure: {type(e).__name__}: {e}", file=sys.stderr)
        return []


def _estimate_study(scenario, reference, args, out: Path, progress: bool) -> int:
    """`spotsim study estimate`: estimate.csv, and per quantity how often the true error lay
    within the estimate. Exit 0, 2 when the integrator has no companion, 130 if interrupted."""
    import csv
    import io

    from .files import atomic_write
    from .studies.estimate import validate, validation_table

    try:
        rows = validate(scenario, reference.apply(scenario), args.members, seed=args.seed, workers=args.workers,
                        progress=progress, spread_members=args.spread_members)
    except ValueError as e:
        print(e, file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    path = out / "estimate.csv"
    text = io.StringIO()
    w = csv.DictWriter(text, fieldnames=list(rows[0]) if rows else ["member"])
    w.writeheader()
    w.writerows(rows)
    atomic_write(path, text.getvalue())
    print(f"{scenario.name}: error estimate against {reference.label(scenario.simulation.dt_s)}, "
          f"{args.members} perturbed starts (seed {args.seed})")
    for r in validation_table(rows):
        kind = " (a distribution)" if r["distribution"] else ""
        bound = ("no bound (no spread over starts: --spread-members 0)" if r["within_bound"] is None else
                 f"within the bound for {r['within_bound']} of {r['bounded']} (median bound {r['median_bound']:.3g})")
        print(f"  grasp {r['grasp']} {r['quantity']}{kind}: error within the estimate for {r['within']} of "
              f"{r['members']}, within the uncertainty (3x) for {r['within_uncertainty']}, {bound}; median "
              f"estimate {r['median_estimate']:.3g}, median error {r['median_error']:.3g}")
    print(f"  {path}")
    return 0


def _replay(result_dir, args, run_code=None) -> int:
    """`spotsim replay` (and `run --replay`): exit 2 on bad input, else 0 (or the run's code)."""
    try:
        import meshcat  # noqa: F401
        import umsgpack  # noqa: F401
        import zmq  # noqa: F401
    except ImportError as e:
        print(f"spotsim replay needs meshcat ({e}); install it with `pip install meshcat`", file=sys.stderr)
        return 2
    from . import replay

    if getattr(args, "force_scale", None) is not None and not args.force_scale > 0:
        print(f"--force-scale {args.force_scale}: must be > 0", file=sys.stderr)
        return 2
    try:
        run = replay.load_run(result_dir)
        commands, info = replay.build(run, rate_hz=getattr(args, "rate", 100.0),
                                      spheres=not getattr(args, "no_spheres", False),
                                      force_mm_per_N=getattr(args, "force_scale", None),
                                      loop=not getattr(args, "no_loop", False))
    except SpotsimError as e:
        print(e, file=sys.stderr)
        return 2
    if run.snapshots is None:
        print(f"warning: {result_dir} has no replay.npz (recorded by an older spotsim): no spheres and no "
              f"force arrows", file=sys.stderr)
    what = f"{info.frames} frames at {info.rate_hz:g} Hz over {info.duration_s:.3f} s simulated"
    if getattr(args, "html", None):
        out = Path(args.html)
        try:
            replay.write_html(out, replay.static_html(commands, info, run.summary.get("scenario", "spotsim")))
        except OSError as e:
            print(f"{out}: cannot write: {e.strerror}", file=sys.stderr)
            return 2
        print(f"{out}: {out.stat().st_size / 1e6:.2f} MB, {what}; force arrows {info.force_mm_per_N:g} mm/N")
        print(f"  open it in a browser; ?t=<s> shows an instant, ?view={'|'.join(info.views)} a camera")
        return 0 if run_code is None else run_code
    try:
        server = replay.Server(args.zmq_url)
        server.send(commands)
    except SpotsimError as e:
        print(e, file=sys.stderr)
        return 2
    print(f"replaying {result_dir} ({what}) at {server.web_url}")
    if server.proc is None:  # someone else's server: the scene stays there
        server.close()
        return 0 if run_code is None else run_code
    if not getattr(args, "no_browser", False):
        import webbrowser

        webbrowser.open(server.web_url, new=2)
    print("the Meshcat server runs until Ctrl-C")
    try:
        server.proc.wait()
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
    return 0 if run_code is None else run_code


#: `run --ensemble`'s exit code: that of the worst member status present, in this order.
ENSEMBLE_EXIT = ((INTERRUPTED, 130), (EXCEPTION, 1), (REJECTED, 1), (DIVERGED, 4), (NOT_CAPTURED, 5), (INCOMPLETE, 3))


def ensemble_exit(statuses: dict[str, int], interrupted: bool) -> int:
    """`run --ensemble`'s exit code from its members' status counts."""
    if interrupted:
        return 130
    return next((code for status, code in ENSEMBLE_EXIT if statuses.get(status)), 0)


def _ensemble(args, scenario, model, path: Path, out: Path) -> int:
    """`spotsim run --ensemble N`: exit 2 on bad input, else `ensemble_exit`."""
    from .studies.ensemble import ensemble, report_lines, write_ensemble

    bad = []
    if args.replay:
        bad.append("--replay: not with --ensemble (replay a member by running its start from ensemble.json)")
    if bad:
        print("\n".join(bad), file=sys.stderr)
        return 2
    from .files import prepare
    from .studies.ensemble import ENSEMBLE_JSON

    try:
        prepare(out, ENSEMBLE_JSON)
    except SpotsimError as err:
        return _bad_input(err)
    runner = None
    if args.scheduler:  # the members on Dask
        from .studies.runner import DASK, Runner

        runner = Runner(DASK, args.scheduler, args.workers, None, not args.quiet)
    try:
        e = ensemble(scenario, args.ensemble, seed=args.seed, family=args.perturb, workers=args.workers,
                     progress=not args.quiet, model=model, source=str(path), runner=runner, out_dir=out)
    except SpotsimError as err:  # a scheduler that cannot be reached, or was lost
        return _bad_input(err)
    first = e.members[0] if e.members else None
    if not args.no_error_estimate and not e.interrupted and first is not None and first.summary:
        from .studies.estimate import estimate

        try:  # member 0 runs the scenario's own start: its companion estimates the step's share
            e.error_estimate = estimate(scenario, first.summary, source=str(path), ensemble=e)
        except KeyboardInterrupt:
            e.interrupted = True
    try:
        files = write_ensemble(e, out)
    except OSError as err:
        print(f"{out}: cannot write results: {err.strerror}", file=sys.stderr)
        return 2
    counts = ", ".join(f"{k} {v}" for k, v in sorted(e.statuses.items()))
    family = "" if e.family == ALL_AXES else f", {e.family}"
    print(f"{scenario.name}: ensemble of {len(e.members)} (seed {e.seed}, +-{e.offset_tol_mm:g} mm, "
          f"+-{e.rpy_tol_deg:g} deg{family}): {counts}")
    print("  median [p10, p90] over the completed members:")
    for line in report_lines(e):
        print(line)
    if e.error_estimate is not None:
        print(estimate_lines(e.error_estimate).replace("  error estimate, per quantity", "  member 0's error estimate, "
                                                                                     "per quantity", 1))
    print(f"  wall time {e.wall_time_s:.2f} s on {e.workers} worker{'s' if e.workers > 1 else ''}"
          + (f"; {e.reused} members from an earlier run over {out} (members.jsonl)" if e.reused else ""))
    for f in files:
        print(f"  {f}")
    if e.interrupted:
        print("interrupted: the members that finished are kept", file=sys.stderr)
    return ensemble_exit(e.statuses, e.interrupted)


def verdict_line(s: dict) -> str:
    """A run in one line: its status and why, then per closed grasp its residual offset e, tilt
    (the larger of |roll| and |pitch|) and peak |F|, each with how far it may lie from the
    converged run from its start (the error estimate's bound: its step error, 3 x the
    estimate, plus the start-to-start scatter, the chance range) where there is one."""
    estimate = (s.get("error_estimate") or {}).get("grasps") or []
    parts = []
    for g, grasp in enumerate(s["grasps"]):
        if grasp["completed_s"] is None:
            continue
        q = estimate[g] if g < len(estimate) else {}

        def within(name, unit, fmt):
            b = q.get(name) or {}
            if b.get("bound") is None:
                return ""
            return (f" (within {b['bound']:{fmt}} {unit} of a converged run: {b['uncertainty']:{fmt}} step error + "
                    f"{b['chance']:{fmt}} start-to-start scatter)")

        tilt = max(abs(x) for x in grasp["residual_rpy_deg"][:2])
        label = f"{grasp['module']}: " if len(s["grasps"]) > 1 else ""
        parts.append(f"{label}e = {grasp['residual_offset_norm_mm']:.4f} mm"
                     f"{within('residual_offset_norm_mm', 'mm', '.2g')}, tilt {tilt:.2f} deg, peak |F| "
                     f"{grasp['peak_force_norm_N']:.1f} N{within('peak_force_norm_N', 'N', '.3g')}")
    outcome = run_outcome(s["status"], s)
    said = f" ({outcome})" if outcome and outcome != s["status"] else ""
    return f"{s['scenario']}: {s['status']}{said} - {s['message']}" + "".join(f"; {p}" for p in parts)


def print_details(s: dict, out: Path) -> None:
    """What `spotsim run` prints after its verdict line (not with --quiet): each grasp's times,
    residual, peaks and drive, the dynamometer's peaks, the error estimate, the wall time."""
    for g in s["grasps"]:
        when = lambda t: "never" if t is None else f"at {t:.4f} s"
        print(f"  {g['end_effector']} on {g['module']}: first contact {when(g['contact_onset_s'])}, "
              f"complete {when(g['completed_s'])}")
        if g["residual_offset_mm"] is not None:
            x, y, z = g["residual_offset_mm"]
            print(f"    residual offset [{x:.4f}, {y:.4f}, {z:.4f}] mm, e = {g['residual_offset_norm_mm']:.4f} mm")
        print(f"    peak force {json.dumps([round(f, 3) for f in g['peak_force_N']])} N")
        if s["drive"] == "motor":  # its records (run summary), not a prescribed speed's
            states = ", ".join(f"{k} {v:.3f} s" for k, v in g["transmission_time_s"].items())
            print(f"    finger drive (motor): peak current {g['motor_peak_current_A']:.3f} A, transmission "
                  f"{states}, {g['transmission_stops']} stops")
        else:
            print(f"    finger drive ({s['drive']}): {g['drive_resumes']} resumes, largest speed step "
                  f"{g['drive_largest_speed_step_mm_s']:.2f} mm/s")
        if "robot_centroid_displacement_mm" in g:
            print(f"    robot centroid displacement "
                  f"{json.dumps([round(d, 4) for d in g['robot_centroid_displacement_mm']])} mm")
    if "peak_force_N" in s.get("dynamometer", {}):
        dyn = s["dynamometer"]
        print(f"  dynamometer ({dyn['filter_cutoff_Hz']:g} Hz low-pass, {dyn['sampling_Hz']:g} Hz): peak force "
              f"{json.dumps([round(f, 3) for f in dyn['peak_force_N']])} N (axes of O_a)")
    if "error_estimate" in s:
        print(estimate_lines(s["error_estimate"]))
    print(f"  wall time {s['wall_time_s']:.2f} s for {s['sim_time_s']:.3f} s simulated")
    print(f"  results in {out}")


def estimate_lines(entry: dict) -> str:
    """The error estimate of a run, for the terminal, in words."""
    if "grasps" not in entry:
        return f"  error estimate: {entry['note']}"
    names = {"residual_offset_norm_mm": ("e", "mm"), "peak_force_norm_N": ("peak |F|", "N"),
             "peak_torque_norm_Nm": ("peak |T|", "N m"), "robot_centroid_displacement_norm_mm": ("|centroid d|", "mm")}
    spread = entry.get("spread") or {}
    lines = ["  error estimate, per quantity: its value; its step error (how far it moved in a companion run with "
             "steps twice as long) and that error's uncertainty (3 x); the start-to-start scatter (the range over "
             "starts a few micrometres apart); and the bound (uncertainty + scatter): how far the value may lie from "
             "the converged run from the same start",
             f"  starts: {spread.get('about', 'none')}"]
    for g, grasp in enumerate(entry["grasps"]):
        cells = []
        for name, q in grasp.items():
            label, unit = names[name]
            if q["estimate"] is not None:
                bound = "" if q["bound"] is None else f", scatter {q['chance']:.3g}, bound {q['bound']:.3g}"
                cells.append(f"{label} = {q['value']:.4g} {unit}: step error {q['estimate']:.3g} (uncertainty "
                             f"{q['uncertainty']:.3g}){bound}")
        lines.append(f"    grasp {g + 1}: " + ("; ".join(cells) or "not estimated (incomplete)"))
    return "\n".join(lines)


def _config_path(arg: str | None) -> Path:
    """The scenario file of a command's argument: a file, or a shipped scenario by name
    (`paths.scenario_file`); none: the default scenario."""
    from .paths import CONFIG_DIR, scenario_file

    return scenario_file(arg) if arg else CONFIG_DIR / DEFAULT_SCENARIO


def _load(path: Path, overrides):
    from .assemble.model import build_model
    from .run import check_start
    from .scenario import load_scenario

    scenario = load_scenario(path, overrides)
    model = build_model(scenario, str(path))
    check_start(model, str(path))
    return scenario, model


def _load_or_report(path: Path, overrides):
    """(scenario, model) of a config, or None after printing every problem with it."""
    try:
        return _load(path, overrides)
    except ScenarioError as e:
        for line in e.problems:
            print(line, file=sys.stderr)
    except SpotsimError as e:
        print(f"{path}: {e}", file=sys.stderr)
    return None


def main(argv=None) -> int:
    """The `spotsim` command: its exit code. Output piped into a reader that stops early (`|
    head`) ends the command quietly, as a Unix filter does."""
    try:
        return _main(argv)
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit's flush
        return 1


def _compiling() -> None:
    import numba

    print(f"spotsim: compiling its kernels for this machine, once after an install or an update: a few minutes "
          f"(cached in {numba.config.CACHE_DIR})", file=sys.stderr, flush=True)


def _main(argv) -> int:
    try:
        args = _parser().parse_args(argv)
    except SystemExit as e:  # --help (0) or a bad option (2, one line printed)
        return e.code
    # on a terminal, as the progress bars
    announce_compiling(None if getattr(args, "quiet", False) or not sys.stderr.isatty() else _compiling)
    if args.command == "list":
        return _list()
    if args.command == "replay":
        return _replay(args.result_dir, args)
    if args.command == "study":
        return _study(args)
    if args.command == "sweep":
        return _sweep(args)
    if args.command == "envelope":
        return _envelope(args)
    if args.command == "plot":
        from .results import replot

        try:
            figures, errors = replot(args.result_dir, args.sample_hz, args.markers)
        except SpotsimError as e:
            print(e, file=sys.stderr)
            return 2
        for figure in figures:
            print(figure)
        if errors:
            print("simulated - measured, per grasp (RMS, largest), over the markers within each grasp:")
            for e in errors:
                unit = e["column"].rsplit("_", 1)[1]
                text = "no markers" if e["samples"] == 0 else f"{e['rms']:.4g} {unit}, {e['max']:.4g} {unit}"
                print(f"  grasp {e['grasp']} {e['column']}: {text} ({e['samples']} markers)")
        return 0
    if args.command == "run" and args.ensemble is None:
        given = [o for o, v in (("--seed", args.seed != 0), ("--workers", args.workers is not None),
                                ("--perturb", args.perturb != ALL_AXES), ("--scheduler", args.scheduler)) if v]
        if given:
            print(f"{', '.join(given)}: only with --ensemble N", file=sys.stderr)
            return 2
    try:
        path = _config_path(getattr(args, "config", None))
    except ScenarioError as e:
        return _bad_input(e)
    loaded = _load_or_report(path, args.set)
    if loaded is None:
        return 2
    scenario, model = loaded
    from .scenario import to_yaml, tolerance_warnings
    from .sim.stability import stability_warnings

    for w in tolerance_warnings(scenario) + stability_warnings(model):
        print(f"warning: {path}: {w}", file=sys.stderr)
    if args.command == "validate":
        print(to_yaml(scenario), end="")
        return 0

    from .results import run_scenario

    if args.replay:  # before the run: a missing meshcat is bad input, found before anything ran
        try:
            import meshcat  # noqa: F401
        except ImportError as e:
            print(f"--replay needs meshcat ({e}); install it with `pip install meshcat`", file=sys.stderr)
            return 2
    if args.ensemble is not None:  # by default beside the single run's files, not among them
        out = Path(args.out) if args.out else results_dir(scenario.name, args.set, "ensemble")
        return _ensemble(args, scenario, model, path, out)
    out = Path(args.out) if args.out else results_dir(scenario.name, args.set)
    try:
        result = run_scenario(scenario, out, model=model, source=str(path), error_estimate=not args.no_error_estimate,
                              spread_members=args.spread_members, figures=not args.no_figures,
                              sample_hz=args.sample_hz, progress=not args.quiet)
    except SpotsimError as e:
        return _bad_input(e)
    s = result.summary
    print(verdict_line(s))
    if not args.quiet:
        print_details(s, out)
    if args.replay:
        return _replay(out, args, run_code=EXIT[s["status"]])
    return EXIT[s["status"]]


if __name__ == "__main__":
    sys.exit(main())
