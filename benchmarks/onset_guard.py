"""What adaptive_euler's onset guard costs and what it buys: its two guards' ensembles against a
fine fixed step from the same starts.

    python benchmarks/onset_guard.py [--members 32]

Cases I-III and the dual-arm run, each on both families of perturbed starts (`spotsim run
--perturb`: all axes and angles, and one axis at a time), as ensembles of MEMBERS starts (seed
0) at: adaptive Euler with the travel guard (`simulation.integrator.onset_guard: travel`), with
the clearance guard (`clearance`, the default), and symplectic Euler at 3.125 us (the drive comparison's
fine step, computed here from the same starts). Each adaptive ensemble is compared, by the
ensemble accuracy study's own comparison (`studies.accuracy_ensemble.compare`), with the
fine one. Printed per case, family, guard and grasp: the steps and the wall time per member,
the peak force's member-by-member difference from the fine step (with its sampling error),
the residual offset's median difference and KS p-value.
"""

from __future__ import annotations

import argparse

import numpy as np
from against import CASES, against, member_rows
from speed import ROOT, measured_at, pct

import spotsim
from spotsim.studies.ensemble import ALL_AXES, ONE_AXIS

GUARDS = ("travel", "clearance")
#: The fine step: symplectic Euler at the record interval over this many substeps (3.125 us at 1 ms).
FINE_SUBSTEPS = 320


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", type=int, default=32)
    args = ap.parse_args()
    print(f"Measured by `python benchmarks/onset_guard.py` at {measured_at()}: {args.members} starts per family "
          f"(seed 0), each guard against symplectic Euler at 3.125 µs from the same starts\n")
    print("| case | starts | onset guard | grasp | steps per member | wall per member (s) | peak force, member by "
          "member vs fine | residual median vs fine | residual KS p |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for title, name in CASES:
        base = spotsim.load_scenario(ROOT / "config" / f"{name}.yaml")
        for family in (ALL_AXES, ONE_AXIS):
            fine = spotsim.replace(base, simulation={"substeps": FINE_SUBSTEPS,
                                                     "integrator": {"method": "symplectic_euler"}})
            ref = member_rows(spotsim.ensemble(fine, args.members, family=family, workers=2))
            for guard in GUARDS:
                s = spotsim.replace(base, simulation={"integrator": {"onset_guard": guard}})
                ran, prefixes, c = against(s, ref, args.members, family)
                steps = np.mean([x["steps"] for x in ran])
                wall = np.median([x["wall_time_s"] for x in ran])
                for g, p in enumerate(prefixes):
                    paired = pct(c[p + "peak_force_paired_rel"], c[p + "peak_force_paired_rel_error"])
                    residual = pct(c[p + "residual_median_rel"], c[p + "residual_median_rel_error"])
                    print(f"| {title} | {family.replace('_', ' ')} | {guard} | {g + 1} | {steps:.0f} | {wall:.3f} "
                          f"| {paired} | {residual} | {c[p + 'residual_ks_p']:.2g} |", flush=True)


if __name__ == "__main__":
    main()
