"""Speed of a sweep on Dask: points per second, the overhead beyond the simulations, and the
scaling from one worker to two.

    python benchmarks/sweep.py [--points 1000] [--scaling-points 200] [--no-error-estimate]

1. A Case I sweep of POINTS initial offsets (a grid over x_a and y_a within +-3 mm) on the
   default local cluster (one worker per core), each point with its error estimate: wall time,
   points per second, and the overhead beyond the simulations: the point tasks' wall time
   against their runs' and companions' (the simulation loop's own wall times), and the whole
   sweep's wall time times the workers against the same.
2. The first SCALING_POINTS of them on one worker and on two: the speed-up and its share of
   linear.

Each sweep writes to a fresh temporary directory (nothing resumed). Wall times are those of a
machine that may be busy.
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
import time
from pathlib import Path

from speed import measured_at

from spotsim.studies import sweep as sw
from spotsim.studies.runner import Runner

ROOT = Path(__file__).resolve().parents[1]
CASE_I = ROOT / "config" / "single_arm_case_I.yaml"


def grid(n: int) -> list[str]:
    """`--vary` axes of about n points: a square grid over x_a and y_a within +-3 mm."""
    side = max(int(round(math.sqrt(n))), 1)
    return [f"module.initial_offset_mm.0=-3:3:{side}", f"module.initial_offset_mm.1=-3:3:{side}"]


def simulation_s(table) -> float:
    """The simulation loops' wall time summed over the points: each run's and its companion's."""
    return float(table["run_wall_time_s"].sum() + table["companion_wall_time_s"].fillna(0.0).sum())


def timed(vary, workers: int, estimate: bool):
    with tempfile.TemporaryDirectory() as out:
        t0 = time.perf_counter()
        report = sw.run_sweep(CASE_I, sw.spec_of(vary), out, runner=Runner(workers=workers),
                              error_estimate=estimate)
        return report, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=1000)
    ap.add_argument("--scaling-points", type=int, default=200)
    ap.add_argument("--no-error-estimate", action="store_true")
    args = ap.parse_args()
    estimate = not args.no_error_estimate
    cores = os.cpu_count() or 1
    print(f"Measured by `python benchmarks/sweep.py` at {measured_at()}")

    report, wall = timed(grid(args.points), cores, estimate)
    t = report.table
    sim = simulation_s(t)
    tasks = float(t["wall_time_s"].sum())
    print(f"Case I sweep of {len(t)} initial offsets on {cores} workers"
          f"{' with error estimates' if estimate else ''}: {wall:.1f} s wall (cluster start and kernel "
          f"loading included), {len(t) / wall:.2f} points/s; verdicts {dict(report.counts())}")
    print(f"  the points' tasks {tasks:.1f} s against their simulations' {sim:.1f} s: overhead "
          f"{100 * (tasks / sim - 1):.1f} % per point ({1e3 * (tasks - sim) / len(t):.1f} ms)")
    print(f"  the sweep's wall time x {cores} workers against the simulations: overhead "
          f"{100 * (wall * cores / sim - 1):.1f} %")

    small = grid(args.scaling_points)
    one, wall1 = timed(small, 1, estimate)
    two, wall2 = timed(small, 2, estimate)
    print(f"scaling, {len(one.table)} points: 1 worker {wall1:.1f} s, 2 workers {wall2:.1f} s: speed-up "
          f"{wall1 / wall2:.2f}, {wall1 / wall2 / 2:.2f} of linear")


if __name__ == "__main__":
    main()
