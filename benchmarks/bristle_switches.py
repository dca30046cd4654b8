"""What locating the bristle switches buys adaptive_euler: its ensembles against the converged
reference, with and without `simulation.integrator.bristle_switches: located`.

    python benchmarks/bristle_switches.py [--members 32]

Cases I-III and the dual-arm run, each as an ensemble of MEMBERS starts (spotsim's default
perturbation, seed 0) at: the default (switches within the step), the switches located, and
the switches located at a quarter of the velocity tolerance. Each is compared, by the ensemble
accuracy study's own comparison (`studies.accuracy_ensemble.compare`), with the study's
converged reference from the same starts: symplectic Euler at 0.78125 us, read from
docs/results/accuracy_ensemble/<case>/members/. Printed per case, setting and grasp: the
median peak force and residual offset against the reference's (with their sampling errors),
the residual's KS p-value, and per member the wall time, force evaluations and switch cuts.
"""

from __future__ import annotations

import argparse

import numpy as np
from against import CASES, against
from speed import ROOT, measured_at, pct

import spotsim
from spotsim.studies.estimate import read_members

REFERENCE = "symplectic_euler_h_0.00078125_ms.csv"


def settings(tol: float):
    """(label, integrator changes) of the settings compared."""
    return (("within the step (default)", {}),
            ("located", {"bristle_switches": "located"}),
            (f"located, tol {tol / 4:g} m/s", {"bristle_switches": "located", "velocity_tol_m_s": tol / 4}))


def reference_rows(name: str) -> list[dict]:
    """The reference ensemble's members table."""
    return read_members(ROOT / "docs" / "results" / "accuracy_ensemble" / name / "members" / REFERENCE)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", type=int, default=32)
    args = ap.parse_args()
    print(f"Measured by `python benchmarks/bristle_switches.py` at {measured_at()}: "
          f"{args.members} starts per setting, against the converged reference's same starts (symplectic Euler, "
          f"0.78125 µs)\n")
    print("| case | bristle switches | grasp | peak force vs reference, medians | member by member "
          "| residual median vs reference | residual KS p | wall per member (s) | force evaluations per member "
          "| switch cuts per member |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for title, name in CASES:
        base = spotsim.load_scenario(ROOT / "config" / f"{name}.yaml")
        ref = reference_rows(name)
        tol = base.simulation.integrator.velocity_tol_m_s
        for label, changes in settings(tol):
            s = spotsim.replace(base, simulation={"integrator": changes}) if changes else base
            ran, prefixes, c = against(s, ref, args.members)
            wall = np.median([x["wall_time_s"] for x in ran])
            evaluations = np.mean([x["integrator"]["force_evaluations"] for x in ran])
            cuts = np.mean([x["integrator"]["switch_cuts"] for x in ran])
            for g, p in enumerate(prefixes):
                force = pct(c[p + "peak_force_median_rel"], c[p + "peak_force_median_rel_error"])
                paired = pct(c[p + "peak_force_paired_rel"], c[p + "peak_force_paired_rel_error"])
                residual = pct(c[p + "residual_median_rel"], c[p + "residual_median_rel_error"])
                print(f"| {title} | {label} | {g + 1} | {force} | {paired} | {residual} "
                      f"| {c[p + 'residual_ks_p']:.2g} | {wall:.3f} | {evaluations:.3g} | {cuts:.3g} |", flush=True)


if __name__ == "__main__":
    main()
