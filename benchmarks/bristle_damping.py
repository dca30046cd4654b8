"""How the bristle damping c_b sets how fast Case II converges in the step: the error budget
of the accurate default.

    python benchmarks/bristle_damping.py [--members 8] [--substeps 80,160,320,1280]

Case II, symplectic Euler at each substep count (dt 1 ms / substeps), an ensemble of MEMBERS
starts (spotsim's default perturbation, seed 0) per setting, for the paper's c_b = 80 N s/m and
for c_b = 8 and 0.08 N s/m, everything else as the paper. Printed per c_b and step: the
median peak contact force norm and residual offset norm over the members, and each median's
difference from that c_b's finest step. The bristle damping acts while a bristle holds (below
s_max) and is switched off when it saturates (Eq. 14-16), so each pair's friction jumps by
c_b |v_t| at every switch; a step resolves the switches only to its own length.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from speed import ROOT, measured_at

import spotsim

CASE_II = ROOT / "config" / "single_arm_case_II.yaml"
DAMPINGS = (80.0, 8.0, 0.08)


def medians(e) -> tuple[float, float, int]:
    done = [m.grasps()[0] for m in e.members if m.status == "completed"]
    return (float(np.median([g["peak_force_norm_N"] for g in done])),
            float(np.median([g["residual_offset_norm_mm"] for g in done])), len(done))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", type=int, default=8)
    ap.add_argument("--substeps", default="80,160,320,1280")
    args = ap.parse_args()
    substeps = [int(x) for x in args.substeps.split(",")]
    base = spotsim.load_scenario(CASE_II)
    print(f"Measured by `python benchmarks/bristle_damping.py` at {measured_at()}: Case II, "
          f"symplectic Euler, {args.members} starts per setting (medians; change from the finest step)\n")
    print("| c_b (N s/m) | step (µs) | peak force (N) | vs finest | residual e (mm) | vs finest | completed "
          "| wall (s) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for c_b in DAMPINGS:
        rows = []
        for n in substeps:
            s = spotsim.replace(base, friction={"bristle_damping_N_s_m": c_b},
                                simulation={"substeps": n, "integrator": {"method": "symplectic_euler"}})
            t0 = time.perf_counter()
            e = spotsim.ensemble(s, args.members, workers=2)
            rows.append((n, *medians(e), time.perf_counter() - t0))
        force_ref, e_ref = rows[-1][1], rows[-1][2]
        for n, force, e, done, wall in rows:
            print(f"| {c_b:g} | {1e3 / n:.3g} | {force:.1f} | {100 * (force / force_ref - 1):+.1f} % | {e:.4f} | "
                  f"{100 * (e / e_ref - 1):+.1f} % | {done}/{args.members} | {wall:.0f} |", flush=True)


if __name__ == "__main__":
    main()
