"""The motor drive's speed loop under each anti-windup: how far its results move as the loop's
period is shortened.

    python benchmarks/anti_windup.py [--members 32] [--periods 4e-4,1.3e-4,4e-5,1.3e-5]

The dual arm and Case III over one-axis starts, Case I over all-axes starts (the families in
which the period moved the results most), each as an ensemble of MEMBERS starts (seed 0) at
every `end_effector.motor.speed_loop_period_s` in PERIODS, under conditional integration and
under back-calculation (`end_effector.motor.anti_windup`), at the default integrator. Each
period but the last is compared with the last (the shortest) by the ensemble accuracy study's
own comparison (`studies.accuracy_ensemble.compare`), as the default is with a reference:
printed per case, anti-windup, period and grasp, its median peak force and residual offset, its
peak force's median against the last period's (with its sampling error) and the median of the
members' own differences (with its error), its residual median against the last period's and
their KS p-value, and the wall time per member at both periods.
"""

from __future__ import annotations

import argparse

from against import ensemble_rows, medians, rel
from speed import ROOT, measured_at

import spotsim
from spotsim.studies.accuracy_ensemble import compare
from spotsim.studies.ensemble import ALL_AXES, ONE_AXIS, grasp_prefix

#: (title, shipped config, start family) of the cases run.
CASES = (("dual arm", "dual_arm_sequential", ONE_AXIS), ("Case III", "single_arm_case_III", ONE_AXIS),
         ("Case I", "single_arm_case_I", ALL_AXES))
ANTI_WINDUPS = ("conditional", "back_calculation")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", type=int, default=32)
    ap.add_argument("--periods", default="4e-4,1.3e-4,4e-5,1.3e-5",
                    help="speed-loop periods, s, comma-separated; the others are compared with the last")
    args = ap.parse_args()
    periods = [float(x) for x in args.periods.split(",")]
    print(f"Measured by `python benchmarks/anti_windup.py` at {measured_at()}: {args.members} starts per setting "
          f"(seed 0), the default integrator, each period against {periods[-1] * 1e3:g} ms from the same starts\n")
    print("| case, starts | anti-windup | period against the last (ms) | grasp | peak force, median (N) "
          "| residual offset, median (mm) | peak force median's difference | member by member "
          "| residual median's difference | residual KS p | wall per member, this / the last (s) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for title, name, family in CASES:
        for aw in ANTI_WINDUPS:
            runs = []
            for period in periods:
                s = spotsim.load_scenario(ROOT / "config" / f"{name}.yaml", [
                    f"end_effector.motor.anti_windup={aw}", f"end_effector.motor.speed_loop_period_s={period}"])
                runs.append(ensemble_rows(s, args.members, family))
            last, last_wall, n_grasps = runs[-1]
            for period, (rows, wall, _) in zip(periods[:-1], runs[:-1], strict=True):
                c = compare(rows, last, n_grasps, n_grasps > 1)
                for g in range(n_grasps):
                    p = grasp_prefix(g, n_grasps)
                    force, residual = medians(rows, p)
                    print(f"| {title}, {family.replace('_', ' ')} | {aw.replace('_', '-')} | {period * 1e3:g} against "
                          f"{periods[-1] * 1e3:g} | {g + 1} | {force:.1f} | {residual:.3g} "
                          f"| {rel(c, p + 'peak_force_median_rel')} | {rel(c, p + 'peak_force_paired_rel')} "
                          f"| {rel(c, p + 'residual_median_rel')} "
                          f"| {c[p + 'residual_ks_p']:.2g} | {wall:.3f} / {last_wall:.3f} |", flush=True)


if __name__ == "__main__":
    main()
