"""Speed of spotsim's default setting against the paper's literal all-pairs search.

    python benchmarks/speed.py [--cases I II III dual] [--repeat N] [--window STEPS] [--full-literal]

For each scenario, in one run of this script:

1. the whole run at its default setting (coal broad phase + grid search, compiled loop), the
   fastest of REPEAT runs: wall time of the simulation loop, steps per second, nanoseconds
   per active pair per step (loop wall time over the sphere pairs in contact summed over the
   steps) and the real-time factor (simulated over wall time; above 1 is faster than real
   time);
2. the paper's literal search on the same states: from first contact, WINDOW dynamics steps
   of the default run, each evaluated once more with every master sphere against every
   slave sphere (the reference path, `contact.broad_phase: none`). The ratio literal/fast is
   that of the contact stage (kinematics -> pairs -> forces -> wrenches) per step, and of a
   whole step (adding the stages both share), on identical states, both on the step-by-step
   path; and the literal step against the default run's own mean step (the compiled loop's);
3. with --full-literal, the whole run again with `contact.broad_phase=none` (Case I takes
   ~12 min, the dual-arm run hours), and the whole-run ratio.

Timings are wall-clock on an otherwise idle machine; the script prints the CPU it ran on.
"""

from __future__ import annotations

import argparse
import copy
import os
import platform
import time
from pathlib import Path

# one BLAS thread: the literal search's block products ran 5x slower with two threads on this
# 2-core machine when the other core was busy (0.29 s against 0.06 s a step for Case I)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import pinocchio as pin  # noqa: E402

import spotsim  # noqa: E402
from spotsim.integrators import make_integrator  # noqa: E402
from spotsim.step import contact_stage, make_data, step  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CASES = {"I": "single_arm_case_I.yaml", "II": "single_arm_case_II.yaml", "III": "single_arm_case_III.yaml",
         "dual": "dual_arm_sequential.yaml"}


def cpu_name() -> str:
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return platform.processor() or "unknown"


def snapshot(data):
    """A copy of `data` that a contact evaluation may change without touching `data`."""
    snap = copy.copy(data)
    for name in ("q", "v", "R_W", "p_W", "w_W", "vo_W", "opening", "opening_rate", "finger_load"):
        setattr(snap, name, getattr(data, name).copy())
    snap.f_ext = [f.copy() for f in data.f_ext]
    snap.f_views = [f.vector for f in snap.f_ext]
    return snap


def contact_window(scenario, steps: int):
    """Per-step wall time of the contact stage, culled and literal, and of a whole step, on
    `steps` consecutive dynamics steps from first contact of the default run."""
    fast = spotsim.build_model(scenario)
    literal = spotsim.build_model(spotsim.replace(scenario, contact={"broad_phase": "none"}))
    data = make_data(fast)
    integrator = make_integrator(scenario.simulation.integrator, fast.pin_model)
    h = scenario.simulation.dt_s / scenario.simulation.substeps
    while data.t < scenario.simulation.duration_s and not len(step(fast, data, h, integrator).key):
        pass
    t_fast = t_literal = t_step = 0.0
    pairs = 0
    states = []
    for _ in range(steps):  # the default path alone first, so that the literal search's memory
        states.append(snapshot(data))  # traffic does not slow it down
        t0 = time.perf_counter()
        contact_stage(fast, snapshot(data), h)
        t_fast += time.perf_counter() - t0
        t0 = time.perf_counter()
        step(fast, data, h, integrator)
        t_step += time.perf_counter() - t0
    for state in states:
        t0 = time.perf_counter()
        c = contact_stage(literal, state, h)
        t_literal += time.perf_counter() - t0
        pairs += len(c.key)
    return t_fast / steps, t_literal / steps, t_step / steps, pairs / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    parser.add_argument("--window", type=int, default=200, help="lockstep steps from first contact")
    parser.add_argument("--repeat", type=int, default=3, metavar="N",
                        help="time the default run N times and report the fastest (this machine is shared: "
                             "one run varies by ~15 percent)")
    parser.add_argument("--full-literal", action="store_true", help="also run each case whole with the literal search")
    args = parser.parse_args()

    print(f"machine: {cpu_name()}, {len(__import__('os').sched_getaffinity(0))} cores; "
          f"Python {platform.python_version()}, Pinocchio {pin.__version__}")
    rows = []
    for name in args.cases:
        scenario = spotsim.load_scenario(ROOT / "config" / CASES[name])
        spotsim.simulate(scenario)  # a whole run first: every kernel loaded from numba's cache
        runs = [spotsim.simulate(scenario).summary for _ in range(max(args.repeat, 1))]
        s = min(runs, key=lambda x: x["wall_time_s"])
        walls = sorted(x["wall_time_s"] for x in runs)
        wall, steps = s["wall_time_s"], s["steps"]
        fast_c, literal_c, whole, pairs = contact_window(scenario, args.window)
        row = dict(case=name, status=s["status"], sim_s=s["sim_time_s"], wall_s=wall, steps=steps,
                   steps_per_s=steps / wall, ns_per_pair_step=wall / max(s["pair_steps"], 1) * 1e9,
                   realtime=s["sim_time_s"] / wall, contact_fast_us=fast_c * 1e6,
                   contact_literal_us=literal_c * 1e6, step_us=whole * 1e6, window_pairs=pairs,
                   stage_ratio=literal_c / fast_c, step_ratio=(whole - fast_c + literal_c) / whole,
                   # the literal step against the default run's own mean step (the compiled loop)
                   run_step_ratio=(whole - fast_c + literal_c) / (wall / steps))
        if args.full_literal:
            lit = spotsim.simulate(spotsim.replace(scenario, contact={"broad_phase": "none"}))
            row["literal_wall_s"] = lit.summary["wall_time_s"]
            row["run_ratio"] = lit.summary["wall_time_s"] / wall
        rows.append(row)
        print(f"\n{name}: {s['status']} at {s['sim_time_s']:.3f} s simulated")
        print(f"  default: wall {wall:.3f} s (fastest of {len(walls)}: "
              f"{', '.join(f'{w:.3f}' for w in walls)}), {steps} steps ({s['free_flight_steps']} free-flight), "
              f"{row['steps_per_s']:.0f} steps/s, {row['ns_per_pair_step']:.0f} ns per active pair per step, "
              f"real-time factor {row['realtime']:.2f}")
        print(f"  {args.window} steps from first contact ({pairs:.1f} pairs on average): contact stage "
              f"{row['contact_fast_us']:.1f} us culled vs {row['contact_literal_us']:.0f} us literal "
              f"({row['stage_ratio']:.0f}x); whole step {row['step_us']:.1f} us vs "
              f"{row['step_us'] - row['contact_fast_us'] + row['contact_literal_us']:.0f} us ({row['step_ratio']:.0f}x); "
              f"the default run's mean step {wall / steps * 1e6:.1f} us ({row['run_step_ratio']:.0f}x)")
        if args.full_literal:
            print(f"  literal whole run: wall {row['literal_wall_s']:.1f} s ({row['run_ratio']:.0f}x)")
    print("\n| case | simulated s | wall s | steps/s | ns / pair / step | real-time factor | literal/fast, contact stage "
          "| literal/fast, step | literal step / default run's mean step |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        print(f"| {r['case']} | {r['sim_s']:.3f} | {r['wall_s']:.3f} | {r['steps_per_s']:.0f} | "
              f"{r['ns_per_pair_step']:.0f} | {r['realtime']:.2f} | {r['stage_ratio']:.0f} | {r['step_ratio']:.0f} | "
              f"{r['run_step_ratio']:.0f} |")


if __name__ == "__main__":
    main()
