"""A run's discretisation error, estimated from one companion run with steps twice as long.

The default integrator and the paper's step are first order: a quantity's error falls in
proportion to the step, e(h) ~ C h. A companion run whose steps are twice as long therefore
differs from the run by about e(2h) - e(h) = e(h), and that difference is the estimate
(Richardson). For `adaptive_euler` the companion takes four times the velocity tolerance (its
steps go as tol^(1/2)) and twice the onset depth; for `symplectic_euler` half the substeps.
Its steps are longer, so it costs about half the run.

An estimate from two step sizes is itself uncertain: where a quantity does not yet fall
smoothly with the step, the companion may land nearer the converged value than the run.
Roache's grid convergence index (Roache 1994, J. Fluids Eng. 116:405; ASME V&V 20-2009) turns
a two-step estimate into an uncertainty band with a factor of safety of 3: GCI = 3 |Q(h) -
Q(2h)| / (2^p - 1), here with p = 1. Both are reported; `spotsim study estimate` counts how
often the true error lies within each.

A grasp's residual offset is also a distribution over microscopic start perturbations
(model.md Sec. 9): the companion may seat where the run wedges, so the difference is then
chance, not discretisation. Such quantities are marked `distribution`; their spread over
starts is what `spotsim run --ensemble N` measures.
"""

from __future__ import annotations

import math

from .runs import step_scaled

#: The quantities estimated, per grasp: summary key -> whether it is a distribution over starts.
QUANTITIES = {
    "residual_offset_norm_mm": True,
    "peak_force_norm_N": False,
    "peak_torque_norm_Nm": False,
    "robot_centroid_displacement_norm_mm": False,
}
#: Roache's factor of safety for a grid convergence index from two grids.
GCI_SAFETY = 3.0
METHOD = ("estimate: Richardson, first order: |Q(run) - Q(companion)|, the companion's steps twice as long "
          "(adaptive_euler: velocity_tol_m_s x4, onset_depth_m x2; symplectic_euler: substeps / 2); uncertainty: "
          "Roache's grid convergence index from two steps, 3 x estimate")


def companion(scenario):
    """The scenario with steps twice as long (`runs.step_scaled`), or None when the integrator
    has none to offer: rk4 and dopri5, which are not first order, or symplectic_euler at an odd
    number of substeps."""
    if scenario.simulation.integrator.method not in ("symplectic_euler", "adaptive_euler"):
        return None
    return step_scaled(scenario, 2.0)


def quantities(summary: dict) -> list[dict]:
    """Each grasp's estimated quantities from a summary (None where a grasp did not complete;
    the robot centroid's displacement only on a free-floating robot)."""
    out = []
    for g in summary["grasps"]:
        done = g["completed_s"] is not None
        row = {name: g[name] if done else None for name in QUANTITIES if name in g}
        if "robot_centroid_displacement_mm" in g:
            d = g["robot_centroid_displacement_mm"]
            row["robot_centroid_displacement_norm_mm"] = math.hypot(*d) if done and d is not None else None
        out.append(row)
    return out


def error_estimate(summary: dict, companion_summary: dict | None) -> dict:
    """The `error_estimate` entry of a summary: per grasp and quantity, its value, the
    companion's and the estimate |difference|."""
    if companion_summary is None:
        return {"method": METHOD, "companion": None,
                "note": "no companion with twice the step for this integrator: not estimated"}
    grasps = []
    for mine, theirs in zip(quantities(summary), quantities(companion_summary), strict=True):
        entry = {}
        for name, value in mine.items():
            other = theirs.get(name)
            estimate = None if value is None or other is None else abs(value - other)
            entry[name] = {"value": value, "companion": other, "estimate": estimate,
                           "estimate_rel": None if estimate is None or not value else estimate / abs(value),
                           "uncertainty": None if estimate is None else GCI_SAFETY * estimate,
                           "distribution": QUANTITIES[name]}
        grasps.append(entry)
    c = companion_summary
    return {"method": METHOD,
            "companion": {"status": c["status"], "integrator": c["integrator"], "wall_time_s": c["wall_time_s"]},
            "grasps": grasps,
            "note": ("a residual offset is one sample of a distribution over starts: where the run and its "
                     "companion end in different outcome classes (seated, wedged) the difference is chance; "
                     "`spotsim run --ensemble N` measures the spread")}


def estimate(scenario, summary: dict, source: str = "<scenario>") -> dict:
    """Run the companion of `scenario`, whose run gave `summary`, and return the error
    estimate entry for that summary."""
    from ..sim.run import simulate

    s = companion(scenario)
    return error_estimate(summary, None if s is None else simulate(s, source=source).summary)


# ---------------------------------------------------------------------------- validation


def validate(scenario, reference, n: int = 8, *, seed: int = 0, workers: int | None = None,
             progress: bool = False) -> list[dict]:
    """Check the estimate against a converged reference from n starts (`ensemble`'s, seeded):
    one row per member, grasp and quantity with the run's value, the companion's, the
    estimate and uncertainty, the reference's, the true error |run - reference| and whether it
    lies within each. `reference`: the scenario at a converged setting."""
    from .ensemble import ensemble

    other = companion(scenario)
    if other is None:
        raise ValueError(f"{scenario.simulation.integrator.method}: no companion to estimate with")
    runs = [ensemble(s, n, seed=seed, workers=workers, progress=progress).members
            for s in (scenario, other, reference)]
    rows = []
    for run, comp, ref in zip(*runs, strict=True):
        if not (run.summary and comp.summary and ref.summary):
            continue
        truth = quantities(ref.summary)
        for g, entry in enumerate(error_estimate(run.summary, comp.summary)["grasps"]):
            for name, q in entry.items():
                r = truth[g].get(name) if g < len(truth) else None
                error = None if q["value"] is None or r is None else abs(q["value"] - r)
                known = error is not None and q["estimate"] is not None
                rows.append({"member": run.index, "grasp": g + 1, "quantity": name, "value": q["value"],
                             "companion": q["companion"], "estimate": q["estimate"], "uncertainty": q["uncertainty"],
                             "reference": r, "error": error, "distribution": q["distribution"],
                             "within": known and error <= q["estimate"],
                             "within_uncertainty": known and error <= q["uncertainty"]})
    return rows


def validation_table(rows: list[dict]) -> list[dict]:
    """Per grasp and quantity: how many members' true errors lay within their estimates and
    their uncertainties, and the median estimate and error."""
    import numpy as np

    out = []
    for key in dict.fromkeys((r["grasp"], r["quantity"]) for r in rows):
        group = [r for r in rows if (r["grasp"], r["quantity"]) == key and r["error"] is not None
                 and r["estimate"] is not None]
        if not group:
            continue
        out.append({"grasp": key[0], "quantity": key[1], "members": len(group),
                    "within": sum(r["within"] for r in group),
                    "within_uncertainty": sum(r["within_uncertainty"] for r in group),
                    "median_estimate": float(np.median([r["estimate"] for r in group])),
                    "median_error": float(np.median([r["error"] for r in group])),
                    "distribution": group[0]["distribution"]})
    return out
