"""`spotsim` command line (run, validate, plot): a thin layer over the library.

Exit codes: 0 completed (or valid), 2 bad input, 3 incomplete, 4 diverged, 130 interrupted.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from .errors import ScenarioError, SpotsimError

DEFAULT_SCENARIO = "single_arm_case_I.yaml"
EXIT = {"completed": 0, "incomplete": 3, "diverged": 4, "interrupted": 130}


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="spotsim", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a scenario and write its results")
    run.add_argument("config", nargs="?", help=f"scenario YAML (default: config/{DEFAULT_SCENARIO})")
    run.add_argument("--out", help="results directory (default: results/<scenario name>)")
    run.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                     help="override a scenario key, validated like the file (repeatable)")
    run.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    val = sub.add_parser("validate", help="print the resolved scenario, or every problem in it")
    val.add_argument("config")
    val.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE")
    plot = sub.add_parser("plot", help="regenerate the figures of a run's results directory")
    plot.add_argument("result_dir")
    return p


def _config_path(arg: str | None) -> Path:
    from .assets import CONFIG_DIR

    return Path(arg) if arg else CONFIG_DIR / DEFAULT_SCENARIO


def _load(path: Path, overrides):
    from .model import build_model
    from .run import check_start
    from .scenario import load_scenario

    scenario = load_scenario(path, overrides)
    model = build_model(scenario, str(path))
    check_start(model, str(path))
    return scenario, model


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    if args.command == "plot":
        from .results import replot

        try:
            for figure in replot(args.result_dir):
                print(figure)
        except SpotsimError as e:
            print(e, file=sys.stderr)
            return 2
        return 0
    path = _config_path(getattr(args, "config", None))
    try:
        scenario, model = _load(path, args.set)
    except ScenarioError as e:
        for line in e.problems:
            print(line, file=sys.stderr)
        return 2
    except SpotsimError as e:
        print(f"{path}: {e}", file=sys.stderr)
        return 2
    from .scenario import to_yaml, tolerance_warnings

    for w in tolerance_warnings(scenario):
        print(f"warning: {path}: {w}", file=sys.stderr)
    if args.command == "validate":
        print(to_yaml(scenario), end="")
        return 0

    from .results import clear_summary, write_results
    from .run import simulate

    out = Path(args.out) if args.out else Path("results") / scenario.name
    try:
        out.mkdir(parents=True, exist_ok=True)
        clear_summary(out)
    except OSError as e:
        print(f"{out}: cannot write results: {e.strerror}", file=sys.stderr)
        return 2
    result = simulate(scenario, model=model, progress=not args.quiet, source=str(path))
    try:
        write_results(result, out, figures=not args.no_figures)
    except OSError as e:
        print(f"{out}: cannot write results: {e.strerror}", file=sys.stderr)
        return 2
    s = result.summary
    print(f"{s['scenario']}: {s['status']} - {s['message']}")
    for g in s["grasps"]:
        print(f"  {g['end_effector']} on {g['module']}: first contact {g['contact_onset_s']} s, "
              f"complete {g['completed_s']} s")
        if g["residual_offset_mm"] is not None:
            x, y, z = g["residual_offset_mm"]
            print(f"    residual offset [{x:.4f}, {y:.4f}, {z:.4f}] mm, e = {g['residual_offset_norm_mm']:.4f} mm")
        print(f"    peak force {json.dumps([round(f, 3) for f in g['peak_force_N']])} N")
        if "robot_centroid_displacement_mm" in g:
            print(f"    robot centroid displacement "
                  f"{json.dumps([round(d, 4) for d in g['robot_centroid_displacement_mm']])} mm")
    print(f"  wall time {s['wall_time_s']:.2f} s for {s['sim_time_s']:.3f} s simulated")
    print(f"  results in {out}")
    return EXIT[s["status"]]


if __name__ == "__main__":
    sys.exit(main())
