"""How the kinematic drive's controller period sets the default's error: its ensembles against
converged ensembles with the same starts, at its default period and at shorter ones.

    python benchmarks/drive_period.py [--members 32] [--periods 1e-4,1e-5]

Cases I-III and the dual-arm run with `end_effector.drive: kinematic`, each as an ensemble of
MEMBERS starts (spotsim's default perturbation, seed 0), at each `end_effector.control_period_s`
in PERIODS: the default integrator against symplectic Euler at 0.78125 us from the same starts,
run here. Compared by the ensemble accuracy study's own comparison
(`studies.accuracy_ensemble.compare`): printed per case, period and grasp, the reference's
median peak force and residual offset, the default's median force against the reference's
(with its sampling error), the median of the members' own differences (the study's target), the
residual's median and KS p-value, and the wall time per member of both.
"""

from __future__ import annotations

import argparse

from against import ensemble_rows, medians, rel
from bristle_switches import CASES, pct
from speed import ROOT, measured_at

import spotsim
from spotsim.studies.accuracy_ensemble import compare
from spotsim.studies.ensemble import grasp_prefix

#: The reference's step: the accuracy study's, symplectic Euler at 1/1280 of the 1 ms record step.
FINE = {"method": "symplectic_euler"}
FINE_SUBSTEPS = 1280


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", type=int, default=32)
    ap.add_argument("--periods", default="1e-4,1e-5", help="control periods, s, comma-separated")
    args = ap.parse_args()
    periods = [float(x) for x in args.periods.split(",")]
    print(f"Measured by `python benchmarks/drive_period.py` at {measured_at()}: "
          f"{args.members} starts per setting, each against symplectic Euler at 0.78125 µs from the same starts "
          f"and with the same controller period\n")
    print("| case | controller period (ms) | grasp | reference peak force, median (N) "
          "| reference residual offset, median (mm) | default peak force vs reference "
          "| member by member | residual median vs reference | residual KS p "
          "| wall per member, default / reference (s) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for title, name in CASES:
        base = spotsim.load_scenario(ROOT / "config" / f"{name}.yaml", ["end_effector.drive=kinematic"])
        for period in periods:
            s = spotsim.replace(base, end_effector={"control_period_s": period})
            ref, ref_wall, _ = ensemble_rows(
                spotsim.replace(s, simulation={"substeps": FINE_SUBSTEPS, "integrator": FINE}), args.members)
            rows, wall, n_grasps = ensemble_rows(s, args.members)
            c = compare(rows, ref, n_grasps, n_grasps > 1)
            for g in range(n_grasps):
                p = grasp_prefix(g, n_grasps)
                force, residual = medians(ref, p)
                print(f"| {title} | {period * 1e3:g} | {g + 1} | {force:.1f} | {residual:.3g} "
                      f"| {rel(c, p + 'peak_force_median_rel')} "
                      f"| {pct(c[p + 'peak_force_paired_rel'])} "
                      f"| {rel(c, p + 'residual_median_rel')} "
                      f"| {c[p + 'residual_ks_p']:.2g} | {wall:.3f} / {ref_wall:.2f} |", flush=True)


if __name__ == "__main__":
    main()
