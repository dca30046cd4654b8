"""Speed of spotsim: its default runs, the paper's literal search, the integrators, and a
comparison with another revision alternating in one process.

    python benchmarks/speed.py [--cases I II III dual] [--repeat N] [--window STEPS]
                               [--ensemble N] [--against REV [--rounds N]] [--set KEY=VALUE ...]

In one run of this script, for each scenario:

1. the whole run at its default setting (culled search, adaptive Euler), the fastest of
   REPEAT runs: wall time of the run, steps per second, the real-time factor (simulated over
   wall time; above 1 is faster than real time);
2. the contact stage (kinematics -> pairs -> forces -> wrenches, `sim.forces.forces`) with the
   culled and with the paper's literal all-pairs search, on the same WINDOW states from first
   contact, each timed in a compiled loop, and the literal stage against the default run's
   mean step;
3. (Case I) the force evaluations of the integrators against a symplectic-Euler step: each
   integrator's whole run (fixed steps at 0.1 ms, dopri5 at rtol 1e-5, adaptive Euler at its
   default), wall time over evaluations; and (Case I) an ENSEMBLE-member ensemble's wall time
   on every core;
4. with --against REV: the whole default runs of this checkout and of revision REV (its
   src/spotsim imported as `spotsim_base`), alternating, ROUNDS pairs: the median of the
   paired ratios REV / this (above 1: this checkout is faster) and their quartiles.

--set overrides a key of every scenario run (both revisions' with --against), as `spotsim run
--set` does: `--set end_effector.drive=motor` times the motor drive.

Wall times are those of a machine that may be busy: the ratios of item 4 are what holds.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pinocchio as pin
from numba import njit

import spotsim
from spotsim.run import Stepper
from spotsim.sim.forces import forces

ROOT = Path(__file__).resolve().parents[1]
CASES = {"I": "single_arm_case_I.yaml", "II": "single_arm_case_II.yaml", "III": "single_arm_case_III.yaml",
         "dual": "dual_arm_sequential.yaml"}


def cpu_name() -> str:
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return platform.processor() or "unknown"


def head_commit() -> str:
    """The checkout's commit, short."""
    return subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True).stdout.strip()


def pct(x: float, err: float | None = None) -> str:
    """A relative difference in per cent, signed, with its sampling error if given."""
    return f"{100 * x:+.1f} %" + (f" ± {100 * err:.1f} %" if err is not None else "")


def measured_at() -> str:
    """Where a benchmark ran: `spotsim COMMIT on CPU, N cores`, COMMIT marked -dirty when
    tracked files other than the results (docs/results/) differ from it."""
    dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--untracked-files=no", "--", ".",
                            ":!docs/results"], capture_output=True, text=True).stdout.strip()
    return f"spotsim {head_commit()}{'-dirty' if dirty else ''} on {cpu_name()}, {os.cpu_count()} cores"


@njit
def repeat_forces(m, d, h, n):
    """The contact stage n times on one state (the pair memory is not committed: each call
    sees the same state)."""
    for _ in range(n):
        forces(m, d, h, False)


def fastest(scenario, model, repeat: int) -> dict:
    """The summary of the fastest of `repeat` runs, with the wall times of all."""
    spotsim.simulate(scenario, model=model)  # every kernel loaded from numba's cache
    runs = [spotsim.simulate(scenario, model=model).summary for _ in range(max(repeat, 1))]
    best = min(runs, key=lambda s: s["wall_time_s"])
    return {**best, "walls": sorted(s["wall_time_s"] for s in runs)}


def contact_window(scenario, steps: int, calls: int = 200) -> dict:
    """The contact stage's time per call, culled and literal, on `steps` consecutive states
    from first contact of the default run (every tenth of them, timed over `calls` calls)."""
    culled = spotsim.build_model(scenario)
    literal = spotsim.build_model(spotsim.replace(scenario, contact={"broad_phase": "none"}))
    stepper = Stepper(culled)
    h = scenario.simulation.dt_s / scenario.simulation.substeps
    while stepper.data.t < scenario.simulation.duration_s and not len(stepper.data.contacts.key):
        stepper.step(h)
    t_culled = t_literal = 0.0
    pairs = n = 0
    for k in range(steps):
        stepper.step(h)
        if k % 10:
            continue
        state = stepper.data.copy()
        repeat_forces(culled.sim, state, h, 1)
        t0 = time.perf_counter()
        repeat_forces(culled.sim, state, h, calls)
        t_culled += (time.perf_counter() - t0) / calls
        state = stepper.data.copy()
        repeat_forces(literal.sim, state, h, 1)
        t0 = time.perf_counter()
        repeat_forces(literal.sim, state, h, 2)
        t_literal += (time.perf_counter() - t0) / 2
        pairs += len(state.contacts.key)
        n += 1
    return {"culled_us": t_culled / n * 1e6, "literal_us": t_literal / n * 1e6, "pairs": pairs / n}


def integrators(scenario) -> list[dict]:
    """Each integrator's whole run at 0.1 ms (dopri5: rtol 1e-5; adaptive_euler: its default):
    wall time per force evaluation."""
    out = []
    for method, integrator in (("symplectic_euler", {}), ("adaptive_euler", {}), ("rk4", {}),
                               ("dopri5", {"rtol": 1e-5, "atol": 1e-8})):
        s = spotsim.replace(scenario, simulation={"substeps": 10, "integrator": {"method": method, **integrator}})
        best = fastest(s, spotsim.build_model(s), 3)
        evaluations = best["integrator"]["force_evaluations"]
        out.append({"method": method, "status": best["status"], "wall_s": best["wall_time_s"], "steps": best["steps"],
                    "evaluations": evaluations, "us_per_evaluation": best["wall_time_s"] / evaluations * 1e6})
    return out


def import_revision(rev: str):
    """Revision `rev` of this repository's src/spotsim, imported as the package spotsim_base."""
    where = Path(tempfile.mkdtemp(prefix="spotsim_base_"))
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "src/spotsim"], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(where)], input=archive, check=True)
    (where / "src" / "spotsim").rename(where / "spotsim_base")
    os.environ.setdefault("SPOTSIM_ROOT", str(ROOT))  # its urdf/ and config/: this checkout's
    sys.path.insert(0, str(where))
    import spotsim_base

    return spotsim_base


def alternate(base, config: Path, rounds: int, sets: list[str] = ()) -> dict:
    """Whole default runs of `base` and of this checkout, alternating: the ratios base / this."""
    sb, sn = base.load_scenario(config, list(sets)), spotsim.load_scenario(config, list(sets))
    mb, mn = base.build_model(sb), spotsim.build_model(sn)
    for _ in range(2):
        base.simulate(sb, model=mb), spotsim.simulate(sn, model=mn)
    ratios, walls_b, walls_n = [], [], []
    for _ in range(rounds):
        b = base.simulate(sb, model=mb).summary["wall_time_s"]
        n = spotsim.simulate(sn, model=mn).summary["wall_time_s"]
        walls_b.append(b)
        walls_n.append(n)
        ratios.append(b / n)
    q = statistics.quantiles(ratios, n=4)
    return {"median": statistics.median(ratios), "q1": q[0], "q3": q[2], "base_s": min(walls_b), "this_s": min(walls_n)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    parser.add_argument("--window", type=int, default=200, help="steps from first contact for the contact stage")
    parser.add_argument("--repeat", type=int, default=7, metavar="N", help="time each default run N times")
    parser.add_argument("--ensemble", type=int, default=32, metavar="N", help="members of the timed Case I ensemble")
    parser.add_argument("--against", metavar="REV", help="also alternate whole runs with this git revision")
    parser.add_argument("--rounds", type=int, default=15, metavar="N", help="pairs of alternating runs")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override a key of every scenario run (repeatable)")
    args = parser.parse_args()
    sets = args.set

    print(f"machine: {cpu_name()}, {len(os.sched_getaffinity(0))} cores; Python {platform.python_version()}, "
          f"Pinocchio {pin.__version__}, numba {__import__('numba').__version__}; spotsim at {head_commit()}"
          + (f"; --set {' '.join(sets)}" if sets else ""))
    rows = []
    for name in args.cases:
        scenario = spotsim.load_scenario(ROOT / "config" / CASES[name], sets)
        best = fastest(scenario, spotsim.build_model(scenario), args.repeat)
        window = contact_window(scenario, args.window)
        step_us = best["wall_time_s"] / best["steps"] * 1e6
        rows.append(dict(case=name, sim_s=best["sim_time_s"], wall_s=best["wall_time_s"], walls=best["walls"],
                         steps=best["steps"], steps_per_s=best["steps"] / best["wall_time_s"],
                         realtime=best["sim_time_s"] / best["wall_time_s"], step_us=step_us, **window))
        r = rows[-1]
        print(f"\n{name}: {best['status']} at {best['sim_time_s']:.3f} s simulated; default run {r['wall_s']:.3f} s "
              f"(fastest of {len(r['walls'])}: {', '.join(f'{w:.3f}' for w in r['walls'])}), {best['steps']} steps "
              f"({best['free_flight_steps']} free-flight), {r['steps_per_s']:.0f} steps/s, real-time factor "
              f"{r['realtime']:.2f}")
        print(f"  contact stage from first contact ({r['pairs']:.1f} pairs on average): culled "
              f"{r['culled_us']:.2f} us, literal {r['literal_us']:.0f} us ({r['literal_us'] / r['culled_us']:.0f}x); "
              f"the literal stage against the default run's mean step of {step_us:.2f} us: "
              f"{r['literal_us'] / step_us:.0f}x")
    print("\n| case | simulated s | wall s, fastest | steps/s | real-time factor | contact stage, culled us | "
          "literal us | literal / culled | literal stage / default mean step |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        print(f"| {r['case']} | {r['sim_s']:.3f} | {r['wall_s']:.3f} | {r['steps_per_s']:.0f} | {r['realtime']:.2f} | "
              f"{r['culled_us']:.2f} | {r['literal_us']:.0f} | {r['literal_us'] / r['culled_us']:.0f} | "
              f"{r['literal_us'] / r['step_us']:.0f} |")

    if "I" in args.cases:
        table = integrators(spotsim.load_scenario(ROOT / "config" / CASES["I"], sets))
        se = table[0]["us_per_evaluation"]
        print("\nCase I at 0.1 ms by integrator (fastest of 3):\n")
        print("| integrator | status | wall s | steps | force evaluations | us per evaluation | per evaluation / "
              "symplectic-Euler step |")
        print("| --- | --- | --- | --- | --- | --- | --- |")
        for r in table:
            print(f"| {r['method']} | {r['status']} | {r['wall_s']:.3f} | {r['steps']} | {r['evaluations']} | "
                  f"{r['us_per_evaluation']:.2f} | {r['us_per_evaluation'] / se:.2f} |")

    if "I" in args.cases and args.ensemble:
        from spotsim.studies.ensemble import ensemble

        scenario = spotsim.load_scenario(ROOT / "config" / CASES["I"], sets)
        walls = [ensemble(scenario, args.ensemble).wall_time_s for _ in range(3)]
        print(f"\nCase I ensemble of {args.ensemble} on {len(os.sched_getaffinity(0))} cores (fastest of 3): "
              f"{min(walls):.2f} s wall ({', '.join(f'{w:.2f}' for w in sorted(walls))})")

    if args.against:
        base = import_revision(args.against)
        print(f"\nagainst {args.against}: whole default runs alternating in one process, {args.rounds} pairs\n")
        print("| case | median ratio (base / this) | quartiles | base fastest s | this fastest s |")
        print("| --- | --- | --- | --- | --- |")
        for name in args.cases:
            a = alternate(base, ROOT / "config" / CASES[name], args.rounds, sets)
            print(f"| {name} | {a['median']:.3f} | {a['q1']:.3f}-{a['q3']:.3f} | {a['base_s']:.4f} | "
                  f"{a['this_s']:.4f} |")


if __name__ == "__main__":
    main()
