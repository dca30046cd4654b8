"""The motor drive's default, checked over many starts: back-calculation at a 0.1 ms speed loop,
steps that pass its quiet readings (at most 0.4 ms), at each velocity tolerance.

    python benchmarks/drive_default.py [--members 128] [--tols 1e-5,3e-6] [--cases NAME ...]
                                       [--families all one_axis] [--finer NAME:FAMILY ...] [--cache DIR]
                                       [--kick step|staggered]

For each case and start family (all axes and angles; one axis at a time) and each velocity
tolerance of TOLS, ensembles of MEMBERS starts (seed 0) of the drive DRIVE with the steps STEPS,
checked as the drive comparison checks the default (`studies.accuracy_ensemble.check_rows`):

1. against the converged reference from the same starts with the same drive (symplectic Euler
   at 3.125 us): the ensemble accuracy studies' targets (`reference_verdict`);
2. against the same ensemble with the speed loop's period divided by ten (0.01 ms), at the same
   tolerance: no median moved by more than 3 %, the seated share within the other's 90 %
   interval (`period_verdict`);
3. for the case and family pairs given by --finer, against the reference's step divided by four
   (0.78 us, the drive comparison's converged reference), and the reference against it: where
   3.125 us is itself not converged, and where a difference needs a reference converged beyond it.

The 32 members of the drive comparison resolve a peak force's median of member-by-member
differences to about ±1 % and a residual median to ±3-7 %, about the targets themselves; this
benchmark takes four times as many. With --cache, each ensemble's member rows are kept in DIR
(one pickle per case, family, member count and setting, the kick named) and reused when run
again. Its speed is benchmarks/drive_readings.py's to measure (with the machine to itself), not
this one's. With --kick, the checked setting's velocity updates span that kick
(`simulation.integrator.kick`) instead of the scenario's own.
"""

from __future__ import annotations

import argparse
import pickle
from pathlib import Path

from against import CASES, ensemble_rows, rel
from speed import ROOT, measured_at

import spotsim
from spotsim.scenario import Integrator
from spotsim.studies.accuracy_ensemble import check_rows, period_verdict, reference_verdict
from spotsim.studies.ensemble import FAMILIES
from spotsim.tables import KICKS

#: The drive: the motor with back-calculation, its speed loop read every 0.1 ms.
DRIVE = ["end_effector.motor.anti_windup=back_calculation", "end_effector.motor.speed_loop_period_s=1e-4"]
#: The period check's speed loop: a tenth of DRIVE's.
LOOP_TENTH = ["end_effector.motor.speed_loop_period_s=1e-5"]
#: The steps: passing the loop's quiet readings, at most 0.4 ms.
STEPS = ["simulation.integrator.drive_readings=pass_quiet", "simulation.integrator.h_max_s=4e-4"]
#: The reference: symplectic Euler at dt_s / 320 (3.125 us at the shipped 1 ms), and its step
#: divided by four (`--finer`: where the reference is itself not converged).
REFERENCE = ["simulation.integrator.method=symplectic_euler", "simulation.substeps=320"]
FINER = ["simulation.integrator.method=symplectic_euler", "simulation.substeps=1280"]


def rows_of(name: str, family: str, members: int, tag: str, sets: list[str], cache: Path | None):
    """An ensemble's (member rows, wall per member (s), grasps), from the cache if it is there."""
    path = cache / f"rows_{name}_{family}_{members}_{tag}.pkl" if cache else None
    if path and path.exists():
        return pickle.loads(path.read_bytes())
    out = ensemble_rows(spotsim.load_scenario(ROOT / "config" / f"{name}.yaml", sets), members, family)
    if path:
        path.write_bytes(pickle.dumps(out))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", type=int, default=128)
    ap.add_argument("--tols", default="1e-5,3e-6", help="velocity tolerances, m/s, comma-separated")
    default_cases = [name for _, name in CASES]
    ap.add_argument("--cases", nargs="+", default=default_cases, choices=default_cases)
    ap.add_argument("--families", nargs="+", default=list(FAMILIES), choices=list(FAMILIES))
    ap.add_argument("--finer", nargs="+", default=[], metavar="NAME:FAMILY",
                    help="also check these against the step four times finer than the reference's")
    ap.add_argument("--cache", type=Path, help="keep and reuse each ensemble's member rows here")
    ap.add_argument("--kick", choices=KICKS, help="the checked setting's kick (default: the scenario's own)")
    args = ap.parse_args()
    if args.cache:
        args.cache.mkdir(parents=True, exist_ok=True)
    tols = args.tols.split(",")
    titles = {name: title for title, name in CASES}
    shown = [f"--members {args.members}", f"--tols {args.tols}"]
    if args.cases != default_cases:
        shown.append("--cases " + " ".join(args.cases))
    if args.families != list(FAMILIES):
        shown.append("--families " + " ".join(args.families))
    if args.finer:
        shown.append("--finer " + " ".join(args.finer))
    kick = []
    if args.kick:
        shown.append(f"--kick {args.kick}")
        kick = [f"simulation.integrator.kick={args.kick}"]
    tagged = f",{args.kick or Integrator().kick}"
    print(f"Measured by `python benchmarks/drive_default.py {' '.join(shown)}` at "
          f"{measured_at()}: {args.members} starts (seed 0) per ensemble; the drive "
          f"{', '.join(s.split('.')[-1] for s in DRIVE)}; the steps "
          f"{', '.join(s.split('.')[-1] for s in STEPS + kick)}\n")
    print("| case | starts | velocity tolerance (m/s) | compared | grasp | peak force (N): median, its difference "
          "| member by member | residual e (mm): median, its difference | residual KS p | completion time "
          "| robot centroid displacement | seated [the other's 90 % interval] | verdict |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for name in args.cases:
        dual = name.startswith("dual")
        for family in args.families:
            ref = rows_of(name, family, args.members, "fine", DRIVE + REFERENCE, args.cache)[0]
            finer = (rows_of(name, family, args.members, "finer", DRIVE + FINER, args.cache)[0]
                     if f"{name}:{family}" in args.finer else None)
            for tol in tols:
                step = [*STEPS, *kick, f"simulation.integrator.velocity_tol_m_s={tol}"]
                rows = rows_of(name, family, args.members, f"tol{tol}{tagged}", DRIVE + step, args.cache)[0]
                tenth = rows_of(name, family, args.members, f"tol{tol}{tagged},loop1e-5", DRIVE + step + LOOP_TENTH,
                                args.cache)[0]
                checks = [("against fine (3.125 µs)", check_rows(rows, ref, dual), reference_verdict),
                          ("speed loop 0.1 → 0.01 ms", check_rows(tenth, rows, dual), period_verdict)]
                if finer is not None:
                    checks.append(("against finer (0.78 µs)", check_rows(rows, finer, dual), reference_verdict))
                    if tol == tols[-1]:
                        checks.append(("fine against finer", check_rows(ref, finer, dual), reference_verdict))
                for label, xs, verdict in checks:
                    for x in xs:
                        print(f"| {titles[name]} | {family.replace('_', ' ')} | {tol} | {label} "
                              f"| {x['grasp'] if dual else '–'} "
                              f"| {x['peak_force_median_N']:.1f}: {rel(x, 'peak_force_median_rel')} "
                              f"| {rel(x, 'peak_force_paired_rel')} "
                              f"| {x['residual_median_mm']:.3g}: {rel(x, 'residual_median_rel')} "
                              f"| {x['residual_ks_p']:.2g} | {rel(x, 'completion_median_rel')} "
                              f"| {rel(x, 'centroid_median_rel') if dual else '–'} "
                              f"| {x['seated'] * 100:.0f} % [{x['seated_interval'][0] * 100:.0f}, "
                              f"{x['seated_interval'][1] * 100:.0f}] | {verdict(x)} |", flush=True)


if __name__ == "__main__":
    main()
