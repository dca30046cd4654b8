"""What adaptive_euler's staggered kick changes: both kicks' ensembles against the converged
fixed step from the same starts.

    python benchmarks/kick.py [--members 32]

Cases I-III and the dual-arm run, each on both families of perturbed starts (`spotsim run
--perturb`: all axes and angles, and one axis at a time), as ensembles of MEMBERS starts (seed
0) with each velocity update spanning its own step (`simulation.integrator.kick: step`) and the
mean of the last step and its own (`staggered`, the default), each at the default velocity
tolerance and at a quarter and an eighth of it. Each is compared, by the ensemble accuracy
study's own comparison (`studies.accuracy_ensemble.compare`), with the drive comparison's
ensemble at symplectic Euler's 0.78 us from the same starts
(docs/results/drives/CASE/motor_finer*/members.csv, which `docs/generate.py drives` computes).
Printed per case, family, kick, tolerance and grasp: the steps and the wall time per member, the
peak force's and peak torque's member-by-member differences from the reference (with their
sampling errors), the residual offset's median difference and KS p-value.
"""

from __future__ import annotations

import argparse

import numpy as np
from against import CASES, against
from speed import ROOT, measured_at, pct

import spotsim
from spotsim.studies.ensemble import ALL_AXES, ONE_AXIS
from spotsim.studies.estimate import read_members
from spotsim.tables import KICKS

#: The velocity tolerance's divisors: the default's, a quarter and an eighth of it.
TOLERANCES = (1, 4, 8)


def reference(name: str, family: str) -> list[dict]:
    """The drive comparison's members at the converged fixed step, from the same starts."""
    leaf = "motor_finer" + ("" if family == ALL_AXES else f"_{family}")
    path = ROOT / "docs" / "results" / "drives" / name / leaf / "members.csv"
    if not path.exists():
        raise SystemExit(f"no reference at {path.relative_to(ROOT)}: run `python docs/generate.py drives motor`")
    return read_members(path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", type=int, default=32)
    args = ap.parse_args()
    print(f"Measured by `python benchmarks/kick.py` at {measured_at()}: {args.members} starts per family (seed 0), "
          f"each kick against symplectic Euler at 0.78 µs from the same starts\n")
    print("| case | starts | kick | velocity tolerance (m/s) | grasp | steps per member | wall per member (s) "
          "| peak force, member by member | peak torque, member by member | residual median | residual KS p |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for title, name in CASES:
        base = spotsim.load_scenario(ROOT / "config" / f"{name}.yaml")
        for family in (ALL_AXES, ONE_AXIS):
            ref = reference(name, family)
            for divisor, kick in ((d, k) for d in TOLERANCES for k in KICKS):
                tol = base.simulation.integrator.velocity_tol_m_s / divisor
                s = spotsim.replace(base, simulation={"integrator": {"kick": kick, "velocity_tol_m_s": tol}})
                ran, prefixes, c = against(s, ref, args.members, family)
                steps = np.mean([x["steps"] for x in ran])
                wall = np.median([x["wall_time_s"] for x in ran])
                for g, p in enumerate(prefixes):
                    force = pct(c[p + "peak_force_paired_rel"], c[p + "peak_force_paired_rel_error"])
                    torque = pct(c[p + "peak_torque_paired_rel"], c[p + "peak_torque_paired_rel_error"])
                    residual = pct(c[p + "residual_median_rel"], c[p + "residual_median_rel_error"])
                    ks = c[p + "residual_ks_p"]
                    print(f"| {title} | {family.replace('_', ' ')} | {kick} | {tol:g} | {g + 1} | {steps:.0f} "
                          f"| {wall:.3f} | {force} | {torque} | {residual} | {ks:.2g} |", flush=True)


if __name__ == "__main__":
    main()
