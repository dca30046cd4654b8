"""Steps that pass a motor drive's quiet speed-loop readings: what they save and what they move.

    python benchmarks/drive_readings.py [--members 32] [--rounds 7] [--cases dual_arm_sequential ...]
                                        [--drives default,back_calculation_0.1ms] [--no-ensembles]

With `simulation.integrator.drive_readings: pass_quiet` an adaptive step may pass the readings
of the speed loop that leave its current as it is (the transmission stuck, the loop pressing
at its clamp and kept there, `sim.actuation.quiet_readings`); with `each` every reading ends a
step. For each drive setting of DRIVES, under each setting of READINGS (`each`; `pass_quiet` with
steps of at most 1 ms; `pass_quiet` with steps of at most 0.4 ms), at a velocity tolerance of
1e-5 m/s (COMMON; the settings under which docs/results/drive_readings.md was measured, each
named explicitly so that the defaults do not change what it measures):

1. speed: the whole run of each case under each, alternating, ROUNDS rounds in one process:
   the median wall time, the ratio of `each`'s median to it, the real-time factor, the
   accepted and rejected steps;
2. accuracy (unless --no-ensembles): for each case and start family (all axes and angles; one
   axis at a time), an ensemble of MEMBERS starts (seed 0) under each, compared with the
   converged reference from the same starts with the same drive (symplectic Euler at
   3.125 us) by the ensemble accuracy study's own comparison
   (`studies.accuracy_ensemble.compare`), with the completion time's median and the median of
   the members' own differences from the reference's; and with `each`, member by member.
"""

from __future__ import annotations

import argparse
import statistics

import numpy as np
from against import ensemble_rows, medians, rel
from speed import ROOT, measured_at

import spotsim
from spotsim.studies.accuracy_ensemble import compare
from spotsim.studies.ensemble import ALL_AXES, ONE_AXIS, grasp_prefix

#: (name, its --sets) of the drive settings compared: the motor drive with conditional integration
#: at a 0.4 ms speed loop, and with back-calculation at a 0.1 ms loop (the default).
DRIVES = {"conditional_0.4ms": ["end_effector.motor.anti_windup=conditional",
                                "end_effector.motor.speed_loop_period_s=4e-4"],
          "back_calculation_0.1ms": ["end_effector.motor.anti_windup=back_calculation",
                                     "end_effector.motor.speed_loop_period_s=1e-4"]}
#: The --sets every setting shares: the velocity tolerance the comparison was made at.
COMMON = ["simulation.integrator.velocity_tol_m_s=1e-5"]
CASES = ("dual_arm_sequential", "single_arm_case_I", "single_arm_case_II", "single_arm_case_III")
#: The converged reference: symplectic Euler at dt_s / 320 (3.125 us at the shipped 1 ms).
REFERENCE = {"substeps": 320, "integrator": {"method": "symplectic_euler"}}
#: (name, its --sets) of the settings of the steps compared: every reading ends a step; a step
#: may pass the quiet ones, up to 1 ms or up to 0.4 ms, the conditional drive's speed-loop period
#: (the longest step its readings allowed in a clamp).
READINGS = {"each": ["simulation.integrator.drive_readings=each", "simulation.integrator.h_max_s=1e-3"],
            "pass_quiet": ["simulation.integrator.drive_readings=pass_quiet", "simulation.integrator.h_max_s=1e-3"],
            "pass_quiet, h_max 0.4 ms": ["simulation.integrator.drive_readings=pass_quiet",
                                         "simulation.integrator.h_max_s=4e-4"]}


def scenario(name: str, drive: str, readings: str):
    return spotsim.load_scenario(ROOT / "config" / f"{name}.yaml", [*DRIVES[drive], *COMMON, *READINGS[readings]])


def speed(names, drives, rounds: int) -> None:
    print("| drive | case | steps | wall, median (s) | each / this | real time | accepted steps | rejected steps |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for drive in drives:
        for name in names:
            models = {r: spotsim.build_model(scenario(name, drive, r)) for r in READINGS}
            for r in READINGS:  # compiled and warm
                spotsim.simulate(models[r].scenario, model=models[r])
            walls = {r: [] for r in READINGS}
            last = {}
            for _ in range(rounds):
                for r in READINGS:
                    last[r] = spotsim.simulate(models[r].scenario, model=models[r]).summary
                    walls[r].append(last[r]["wall_time_s"])
            wall = {r: statistics.median(walls[r]) for r in READINGS}
            for r in READINGS:
                i = last[r]["integrator"]
                print(f"| {drive} | {name} | {r} | {wall[r]:.3f} | {wall['each'] / wall[r]:.2f} "
                      f"| {last[r]['sim_time_s'] / wall[r]:.1f} | {i['accepted_steps']} | {i['rejected_steps']} |",
                      flush=True)


def completion_shift(rows: list[dict], ref: list[dict], p: str) -> tuple[float, float]:
    """The median completion time (s) of the grasp with column prefix p over member rows, and
    the median of the members' own differences from the reference's (ms), over the members
    that completed in both."""
    done = {r["member"]: r[p + "completed_s"] for r in ref if r.get(p + "completed_s") is not None}
    own = [r[p + "completed_s"] for r in rows if r.get(p + "completed_s") is not None]
    shift = [1e3 * (r[p + "completed_s"] - done[r["member"]]) for r in rows
             if r.get(p + "completed_s") is not None and r["member"] in done]
    return float(np.median(own)), float(np.median(shift))


def accuracy(names, drives, members: int) -> None:
    print(f"\n{members} starts per ensemble (seed 0), each against the reference (symplectic Euler at 3.125 µs, "
          "the same drive) from the same starts; last column: against each\n")
    print("| drive | case, starts | grasp | readings | peak force, median (N) | residual, median (mm) "
          "| peak force, member by member | peak torque, member by member | residual median's difference "
          "| residual KS p | meets the targets | completion, median (s) | completion's difference, median (ms) "
          "| peak force against each, member by member |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for drive in drives:
        for name in names:
            for family in (ALL_AXES, ONE_AXIS):
                ref, _, n = ensemble_rows(spotsim.replace(scenario(name, drive, "each"), simulation=REFERENCE),
                                          members, family)
                rows = {r: ensemble_rows(scenario(name, drive, r), members, family)[0] for r in READINGS}
                against_each = {r: compare(rows[r], rows["each"], n, n > 1) for r in READINGS if r != "each"}
                for r in READINGS:
                    c = compare(rows[r], ref, n, n > 1)
                    for g in range(n):
                        p = grasp_prefix(g, n)
                        force, residual = medians(rows[r], p)
                        completion, shift = completion_shift(rows[r], ref, p)
                        own = rel(against_each[r], p + "peak_force_paired_rel") if r != "each" else ""
                        print(f"| {drive} | {name}, {family.replace('_', ' ')} | {g + 1} | {r} | {force:.1f} "
                              f"| {residual:.3g} "
                              f"| {rel(c, p + 'peak_force_paired_rel')} | {rel(c, p + 'peak_torque_paired_rel')} "
                              f"| {rel(c, p + 'residual_median_rel')} "
                              f"| {c[p + 'residual_ks_p']:.2g} | {c['meets_targets']} | {completion:.3f} "
                              f"| {shift:+.1f} | {own} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", type=int, default=32)
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=CASES)
    ap.add_argument("--drives", default=",".join(DRIVES), help=f"comma-separated, of {', '.join(DRIVES)}")
    ap.add_argument("--no-ensembles", action="store_true", help="the speed table only")
    args = ap.parse_args()
    drives = args.drives.split(",")
    if set(drives) - set(DRIVES):
        ap.error(f"--drives {args.drives}: choose from {', '.join(DRIVES)}")
    print(f"Measured by `python benchmarks/drive_readings.py` at {measured_at()}\n")
    speed(args.cases, drives, args.rounds)
    if not args.no_ensembles:
        accuracy(args.cases, drives, args.members)


if __name__ == "__main__":
    main()
