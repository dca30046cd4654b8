"""What a motor-driven grasp depends on: one parameter at a time, Case I's peak force, residual
offset and completion time, as a tornado chart.

    python examples/sensitivity.py [--members N] [--out DIR] [--workers W] [--figure PNG] [--quick]

Case I with the motor drive (`end_effector.drive: motor`) at the default integrator, each
parameter set to a low and a high value with every other at its default: the drive's reflected
inertia (through the rotor's), its current limit, the screw's friction across its self-locking
threshold, the speed loop's period, the closing speed, and the contact's parameters that the
paper leaves open or that vary between parts (the finger-groove friction, the restitution,
Young's modulus of both parts). Each setting is an ensemble of N perturbed starts (seed 0, the
same starts for every setting): a grasp's peak force and residual offset are distributions
over microscopic start perturbations, not numbers. Writes sensitivity.csv (per setting, each
quantity's median, 10th and 90th percentiles and the median's bootstrap sampling error) and the
tornado chart (each median over the default's, on a log scale, the default's sampling error
shaded). An interrupted study keeps the settings it finished; started again over the same
--out it runs only those it lacks.

--quick: the current limit and the restitution only, from the unperturbed start alone (seconds).
"""

from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path

import numpy as np

import spotsim
from spotsim.status import SEATED, WEDGED
from spotsim.studies.accuracy_ensemble import BOOTSTRAP
from spotsim.studies.ensemble import ensemble, finite

CONFIG = Path(__file__).resolve().parents[1] / "config" / "single_arm_case_I.yaml"
BASE = ["end_effector.drive=motor"]
#: The scenario every setting moves one parameter of.
SCENARIO = spotsim.load_scenario(CONFIG, BASE)


def _scaled(key: str, low: float, high: float) -> tuple[str, float, float]:
    """(key, low, high): the key's value in SCENARIO times low and high."""
    value = SCENARIO
    for part in key.split("."):
        value = getattr(value, part)
    return key, float(f"{value * low:.6g}"), float(f"{value * high:.6g}")


#: (label, [(key, low, high), ...]): each parameter's low and high setting; keys moved together
#: keep their ratio (the kinetic friction stays 0.26 / 0.30 of the static one).
PARAMETERS = [
    ("reflected inertia ×0.1, ×10", [_scaled("end_effector.motor.rotor_inertia_g_cm2", 0.1, 10)]),
    ("current limit ±50 %", [_scaled("end_effector.motor.current_limit_A", 0.5, 1.5)]),
    ("screw friction 0.03 (back-drivable), 0.26", [("end_effector.motor.screw_friction", 0.03, 0.26)]),
    ("speed-loop period ×0.1, ×10", [_scaled("end_effector.motor.speed_loop_period_s", 0.1, 10)]),
    ("closing speed 10, 22 mm/s", [("end_effector.closing_speed_m_s", 0.010, 0.022)]),
    ("finger–groove friction μs 0.1, 1", [("friction.mu_s", 0.1, 1.0), ("friction.mu_k", 0.26 / 3, 2.6 / 3)]),
    ("restitution 0.5, 0.95", [("contact.restitution", 0.5, 0.95)]),
    ("Young's modulus 35, 210 GPa", [("contact.youngs_modulus_finger_Pa", 35e9, 210e9),
                                     ("contact.youngs_modulus_groove_Pa", 35e9, 210e9)]),
]
#: (members-table column, label, unit) of the quantities charted.
QUANTITIES = [("peak_force_norm_N", "peak force", "N"), ("residual_norm_mm", "residual offset e", "mm"),
              ("completed_s", "completion time", "s")]
COLUMNS = ["parameter", "side", "sets", "members", "completed"] + [
    f"{q}_{s}" for q, _, _ in QUANTITIES for s in ("median", "p10", "p90", "median_error")]


QUICK = ("current limit ±50 %", "restitution 0.5, 0.95")


def settings(parameters=PARAMETERS) -> list[tuple[str, str, list[str]]]:
    """(parameter, side, --sets) of every setting of `parameters`, the default first."""
    out = [("default", "default", [])]
    for label, keys in parameters:
        for side, i in (("low", 1), ("high", 2)):
            out.append((label, side, [f"{k[0]}={k[i]!r}" for k in keys]))
    return out


def median_error(values: np.ndarray, seed: int = 0) -> float:
    """The bootstrap standard deviation of the median of values."""
    if values.size < 2:
        return math.nan
    rng = np.random.default_rng(seed)
    return float(np.std(np.median(rng.choice(values, (BOOTSTRAP, values.size)), axis=1)))


def row(parameter: str, side: str, sets: list[str], e) -> dict:
    """The CSV row of one setting's ensemble: its statistics over the completed members, and
    each median's sampling error."""
    rows = [r for r in e.summary["rows"] if r["class"] in (SEATED, WEDGED)]
    out = {"parameter": parameter, "side": side, "sets": " ".join(sets), "members": len(e.members),
           "completed": len(rows)}
    for q, _, _ in QUANTITIES:
        st = e.statistics["grasp"][q]
        out.update({f"{q}_{k}": math.nan if st[k] is None else st[k] for k in ("median", "p10", "p90")})
        out[f"{q}_median_error"] = median_error(finite(r.get(q) for r in rows))
    return out


def run(out: Path, members: int, workers: int | None, parameters=PARAMETERS) -> list[dict]:
    """Every setting's ensemble, resuming over out/sensitivity.csv."""
    path = out / "sensitivity.csv"
    done = {}
    if path.exists():
        with path.open(newline="") as f:
            done = {(r["parameter"], r["side"]): r for r in csv.DictReader(f)}
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for parameter, side, sets in settings(parameters):
        if (parameter, side) in done and int(done[(parameter, side)]["members"]) == members:
            rows.append({k: (v if k in ("parameter", "side", "sets") else float(v))
                         for k, v in done[(parameter, side)].items()})
            continue
        scenario = spotsim.load_scenario(CONFIG, BASE + sets)
        e = ensemble(scenario, members, seed=0, workers=workers)
        if e.interrupted:
            raise SystemExit(f"interrupted: {path} keeps the {len(rows)} settings finished")
        rows.append(row(parameter, side, sets, e))
        r = rows[-1]
        print(f"{parameter} ({side}): " + ", ".join(
            f"{label} {r[f'{q}_median']:.4g} {unit}" for q, label, unit in QUANTITIES), flush=True)
        with path.open("w", newline="") as f:  # after every setting: an interruption loses only the running one
            w = csv.DictWriter(f, COLUMNS)
            w.writeheader()
            w.writerows(rows)
    return rows


def tornado(rows: list[dict], path: Path, parameters=PARAMETERS) -> None:
    """Per quantity, each parameter's low and high medians over the default's median (a log
    scale: a factor either way reads alike), the default's sampling error (two standard
    errors) shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    base = next(r for r in rows if r["side"] == "default")
    labels = [p for p, _ in parameters]
    fig, panels = plt.subplots(1, len(QUANTITIES), figsize=(5.2 * len(QUANTITIES), 0.55 * len(labels) + 1.6),
                               sharey=True)
    for ax, (q, name, unit) in zip(panels, QUANTITIES):
        b = base[f"{q}_median"]
        for i, label in enumerate(labels):
            for side, colour, dy in (("low", "tab:blue", -0.2), ("high", "tab:red", 0.2)):
                r = next(x for x in rows if x["parameter"] == label and x["side"] == side)
                ratio = r[f"{q}_median"] / b
                ax.barh(i + dy, ratio - 1.0, left=1.0, height=0.4, color=colour, alpha=0.8,
                        label=side if i == 0 else None)
        noise = 2 * base[f"{q}_median_error"] / b
        if math.isfinite(noise):  # one member has no sampling error
            ax.axvspan(max(1 - noise, 1e-3), 1 + noise, color="0.85", zorder=0, label="default ± 2 sampling errors")
        ax.axvline(1.0, color="k", lw=0.8)
        ax.set_xscale("log")
        ax.set_title(f"{name}: default {b:.3g} {unit}")
        ax.set_xlabel("median / the default's median")
        ax.set_yticks(range(len(labels)), labels)
    panels[0].invert_yaxis()
    handles, names = panels[0].get_legend_handles_labels()
    fig.legend(handles, names, loc="lower center", ncol=3, fontsize=9)
    fig.suptitle(f"Case I, motor drive: one parameter at a time, {int(base['members'])} perturbed starts each")
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", type=int, help="perturbed starts per setting (default 32; --quick: 1)")
    ap.add_argument("--out", type=Path, default=Path("results/sensitivity"))
    ap.add_argument("--workers", type=int)
    ap.add_argument("--figure", type=Path, help="the tornado chart (default OUT/sensitivity.png)")
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    parameters = [p for p in PARAMETERS if p[0] in QUICK] if args.quick else PARAMETERS
    members = args.members or (1 if args.quick else 32)
    rows = run(args.out, members, args.workers, parameters)
    figure = args.figure or args.out / "sensitivity.png"
    tornado(rows, figure, parameters)
    print(f"{args.out / 'sensitivity.csv'}\n{figure}")


if __name__ == "__main__":
    main()
