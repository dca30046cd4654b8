"""How each velocity kick converges on one impact: the peak force of Case III's first impact,
from the scenario's own start, against symplectic Euler at ever finer fixed steps.

    python benchmarks/impact_peak.py

Case III, run to END_S: past its first impact (the fingers first touch the groove at
0.2728 s and let go at 0.2740 s; they touch again at 0.3248 s), so that a run's peak force is
that impact's. One impact from one start is deterministic: it is not told apart from the
chaos of the bounces that follow, which an ensemble compares only as a distribution. The
reference is symplectic Euler at dt_s / 5120 (0.195 us at the shipped 1 ms); printed for the
fixed steps and for adaptive Euler with each kick (`simulation.integrator.kick`) at each
velocity tolerance: the steps, the peak force and its difference from the reference.
"""

from __future__ import annotations

from speed import ROOT, measured_at

import spotsim
from spotsim.tables import KICKS

#: Case III's shipped scenario.
CONFIG = ROOT / "config" / "single_arm_case_III.yaml"
#: Past Case III's first impact, before its second (s).
END_S = 0.3
#: Symplectic Euler's substeps of dt_s, coarse to fine; the last is the reference.
SUBSTEPS = (320, 1280, 5120)
#: The velocity tolerances, m/s: the default (3e-6) and around it.
TOLERANCES = (1e-5, 3e-6, 1e-6, 3e-7, 1e-7)


def peak(sets: list[str]) -> tuple[float, int]:
    """Case III's peak force (N) over END_S with the scenario keys `sets`, and its steps."""
    s = spotsim.load_scenario(CONFIG, sets + [f"simulation.duration_s={END_S}"])
    r = spotsim.simulate(s)
    return r.grasp["peak_force_norm_N"], r.summary["steps"]


def main() -> None:
    dt = spotsim.load_scenario(CONFIG).simulation.dt_s
    fixed = {n: peak(["simulation.integrator.method=symplectic_euler", f"simulation.substeps={n}"]) for n in SUBSTEPS}
    ref = fixed[SUBSTEPS[-1]][0]
    print(f"Measured by `python benchmarks/impact_peak.py` at {measured_at()}: Case III's first impact from its own "
          f"start, against symplectic Euler at {dt / SUBSTEPS[-1] * 1e6:.3f} µs\n")
    print("| integrator | kick | velocity tolerance (m/s) | steps | peak force (N) | against the reference |")
    print("| --- | --- | --- | --- | --- | --- |")
    for n, (f, steps) in fixed.items():
        print(f"| symplectic Euler, {dt / n * 1e6:.3f} µs | – | – | {steps} | {f:.4f} | {(f / ref - 1) * 100:+.3f} % |")
    for kick in KICKS:
        for tol in TOLERANCES:
            f, steps = peak([f"simulation.integrator.kick={kick}", f"simulation.integrator.velocity_tol_m_s={tol}"])
            print(f"| adaptive Euler | {kick} | {tol:g} | {steps} | {f:.4f} | {(f / ref - 1) * 100:+.3f} % |",
                  flush=True)


if __name__ == "__main__":
    main()
