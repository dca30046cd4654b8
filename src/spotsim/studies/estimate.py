"""A run's discretisation error, estimated from one companion run with steps twice as long,
and the bound on how far it lies from the converged run from the same start.

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
Q(2h)| / (2^p - 1), here with p = 1.

Neither bounds how far a run lies from the converged run from the same start. A grasp's
bounces decorrelate two runs that start alike, and two runs at different steps alike: its
residual offset is a distribution over microscopic start perturbations (model.md Sec. 9), and
its peak force partly so. That share of a run's error is chance, the difference between two
draws from the distribution over starts, which no companion run can measure. Each quantity's
`spread` over starts says how large it can be, and its `chance` range (largest minus smallest
over those starts) bounds it: the `bound` is the uncertainty plus the chance range. For a
scenario that the ensemble accuracy study ran, the spread is that study's: its members at the
run's own setting and at the converged reference, pooled (TYPICAL_SPREAD, written with its
provenance by `spotsim study spreads`, `spread_from_study`). For another scenario run as an
ensemble (`spotsim run --ensemble N`, whose member 0 is estimated), it is the ensemble's own.
For a lone run of any other scenario whose grasps all closed, it is measured around the run's
own start (`start_spread`): SPREAD_MEMBERS starts within the ensembles' tolerances of it, at its
own setting. A range needs MIN_SPREAD_COUNT runs: a smaller ensemble has no bound. `spotsim study estimate` counts how
often the true error lies within the estimate, the uncertainty and the bound.
"""

from __future__ import annotations

import json
import math
from importlib import resources
from typing import NamedTuple

from ..errors import SpotsimError
from ..scenario import fingerprint, modules_of
from ..status import COMPLETED, NOT_CAPTURED
from .ensemble import grasp_key, headline_statistics
from .runs import companion


class Quantity(NamedTuple):
    column: str  # its members-table column (`ensemble.member_row`), without the grasp prefix
    distribution: bool  # a distribution over starts, not a near-deterministic value


#: The quantities estimated, per grasp, by summary key.
QUANTITIES = {
    "residual_offset_norm_mm": Quantity("residual_norm_mm", True),
    "peak_force_norm_N": Quantity("peak_force_norm_N", False),
    "peak_torque_norm_Nm": Quantity("peak_torque_norm_Nm", False),
    "robot_centroid_displacement_norm_mm": Quantity("centroid_displacement_norm_mm", False),
}
#: The studied scenarios' typical spreads over starts, by `scenario.fingerprint` (package data).
TYPICAL_SPREAD = "typical_spread.json"
#: The fewest runs whose range is taken as a quantity's chance range: fewer give no bound.
MIN_SPREAD_COUNT = 16
#: The seed of `spotsim study estimate`'s starts: not the ensemble accuracy studies' (0), whose
#: spreads the bound uses, nor the one that confirmed the default tolerance (1).
VALIDATION_SEED = 2
#: A lone run's spread over starts (`start_spread`): as many starts as a range needs, drawn with
#: a seed of their own (not the studies' 0, 1 or 2).
SPREAD_MEMBERS, SPREAD_SEED = MIN_SPREAD_COUNT, 3
#: The statuses of a run whose grasps all closed: those that get a spread around their start.
CLOSED = (COMPLETED, NOT_CAPTURED)
#: Why a run has no spread over starts, by default.
NO_SPREAD = ("none: no ensemble and no study of this scenario, and none measured around its start (`spotsim run` "
             "measures one, --spread-members, for a run that completes)")
#: Why a sweep point's error estimate has no spread over starts, and so no bound.
POINT_NO_SPREAD = ("none: a sweep point (its spread would take 16 more runs a point); `spotsim run` of the point's "
                   "scenario measures it and gives the bound")
#: Roache's factor of safety for a grid convergence index from two grids.
GCI_SAFETY = 3.0
METHOD = ("estimate: Richardson, first order: |Q(run) - Q(companion)|, the companion's steps twice as long "
          "(adaptive_euler: velocity_tol_m_s x4, onset_depth_m x2; symplectic_euler: substeps / 2); uncertainty: "
          "Roache's grid convergence index from two steps, 3 x estimate")


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


def error_estimate(summary: dict, companion_summary: dict | None, spread: dict | None = None,
                   no_spread: str = NO_SPREAD) -> dict:
    """The `error_estimate` entry of a summary: per grasp and quantity, its value, the
    companion's, the estimate |difference| and its uncertainty; with a `spread` over starts
    (`ensemble_spread`, `typical_spread`, `start_spread`), that spread, its chance range and the
    bound; without one, `no_spread` says why."""
    if companion_summary is None:
        return {"method": METHOD, "companion": None,
                "note": "no companion with twice the step for this integrator: not estimated"}
    n = len(summary["grasps"])
    grasps = []
    for g, (mine, theirs) in enumerate(zip(quantities(summary), quantities(companion_summary), strict=True)):
        spreads = spread["grasps"].get(grasp_key(g, n), {}) if spread else {}
        entry = {}
        for name, value in mine.items():
            other = theirs.get(name)
            estimate = None if value is None or other is None else abs(value - other)
            uncertainty = None if estimate is None else GCI_SAFETY * estimate
            st = spreads.get(QUANTITIES[name].column)
            chance = chance_range(st)
            entry[name] = {"value": value, "companion": other, "estimate": estimate,
                           "estimate_rel": None if estimate is None or not value else estimate / abs(value),
                           "uncertainty": uncertainty, "distribution": QUANTITIES[name].distribution,
                           "spread": dict(st) if chance is not None else None,
                           "chance": chance,
                           "bound": None if uncertainty is None or chance is None else uncertainty + chance}
        grasps.append(entry)
    c = companion_summary
    return {"method": METHOD,
            "companion": {"status": c["status"], "integrator": c["integrator"], "wall_time_s": c["wall_time_s"]},
            "spread": ({k: v for k, v in spread.items() if k != "grasps"} if spread else
                       {"source": None, "about": no_spread}),
            "grasps": grasps,
            "note": ("the estimate and its uncertainty say how far the run moves with the step; the bound adds "
                     "the chance range over starts (largest - smallest), since the bounces decorrelate runs that "
                     "start alike: the run lies within the bound of the converged run from its own start")}


def chance_range(stats: dict | None) -> float | None:
    """A quantity's chance range over starts, largest minus smallest, from its `statistics`
    over at least MIN_SPREAD_COUNT runs (else None: too few to say)."""
    return stats["max"] - stats["min"] if stats and stats["count"] >= MIN_SPREAD_COUNT else None


def ensemble_spread(e) -> dict:
    """The spread over an ensemble's own members (`ensemble.EnsembleResult`): its run setting
    only, each quantity over the members whose grasp completed."""
    return {"source": "ensemble", "about": f"this ensemble's {len(e.members)} members (seed {e.seed}), those "
                                           f"whose grasp completed (the bound needs {MIN_SPREAD_COUNT})",
            "grasps": e.statistics}


def start_spread(scenario, members: int = SPREAD_MEMBERS, *, workers: int | None = None, model=None,
                 source: str = "<scenario>", progress: bool = False) -> dict:
    """The spread over `members` starts around the scenario's own (an ensemble, seed SPREAD_SEED:
    its member 0 the start itself, the others within the ensembles' tolerances), at its own
    setting: the chance range of a run of a scenario that no study has seen."""
    from .ensemble import ensemble

    e = ensemble(scenario, members, seed=SPREAD_SEED, workers=workers, model=model, source=source,
                 progress=progress)
    return {"source": "starts", "about": f"{members} starts within +-{e.offset_tol_mm:g} mm and +-{e.rpy_tol_deg:g} "
                                         f"deg of this run's (seed {SPREAD_SEED}), at its own setting, "
                                         f"{e.wall_time_s:.1f} s on {e.workers} workers",
            "members": members, "wall_time_s": e.wall_time_s, "grasps": e.statistics}


def study_spread(scenario, run_rows: list[dict], reference_rows: list[dict], about: str) -> dict:
    """A studied scenario's typical spread: the statistics over its members (members-table
    rows) at its own setting and at the converged reference, pooled."""
    columns = {q.column for q in QUANTITIES.values()}
    stats = headline_statistics(run_rows + reference_rows, len(modules_of(scenario)))
    return {"source": "study", "about": about, "scenario": scenario.name,
            "grasps": {g: {c: st for c, st in by.items() if c in columns} for g, by in stats.items()}}


def own_spread(scenario, summary: dict, spread_members: int, **options) -> dict | None:
    """The spread around the start of a run (`start_spread`, `options` passed on) whose grasps
    all closed, if `spread_members` asks for one; else None."""
    if not spread_members or summary["status"] not in CLOSED:
        return None
    return start_spread(scenario, spread_members, **options)


def read_members(path) -> list[dict]:
    """A members table written by an ensemble (members.csv, or a study's members/<setting>.csv)
    read back: numbers as floats, empty cells None."""
    import csv

    def value(text: str):
        if text == "":
            return None
        try:
            return float(text)
        except ValueError:
            return text

    with open(path, newline="") as f:
        return [{k: value(v) for k, v in row.items()} for row in csv.DictReader(f)]


def spread_from_study(scenario, study_dir, source: str | None = None) -> dict:
    """`scenario`'s typical spread from the directory of its ensemble accuracy study (`spotsim
    study accuracy --ensemble N`): the members at the scenario's own setting and at the study's
    reference (its `accuracy_ensemble.csv`'s reference row), pooled (`study_spread`), with its
    provenance: the study's directory (or `source`), the two settings, the members per setting,
    the scenario's fingerprint and the spotsim that collected it."""
    from pathlib import Path

    from ..version import __version__
    from .accuracy import setting_of
    from .accuracy_ensemble import slug

    d = Path(study_dir)
    try:
        table = read_members(d / "accuracy_ensemble.csv")
        reference = next(str(r["setting"]) for r in table if r["role"] == "reference")
    except (OSError, StopIteration, KeyError) as e:
        raise SpotsimError(f"{d}: not an ensemble accuracy study's directory (its accuracy_ensemble.csv with a "
                           f"reference row): {e}") from None
    own = setting_of(scenario).label(scenario.simulation.dt_s)
    rows = []
    for label in (own, reference):
        path = d / "members" / f"{slug(label)}.csv"
        if not path.is_file():
            raise SpotsimError(f"{d}: the study has no members at {label} ({path.name}): the scenario's own setting "
                               "must be among the study's")
        rows.append(read_members(path))
    seeds = sorted({int(r["seed"]) for r in table if r.get("seed") is not None})
    about = (f"the ensemble accuracy study's {len(rows[0])} starts (seed {', '.join(map(str, seeds))}) at {own} and "
             f"at the converged {reference}, pooled ({source or d})")
    return {**study_spread(scenario, *rows, about),
            "provenance": {"study": str(source or d), "settings": [own, reference],
                           "members": [len(rows[0]), len(rows[1])], "fingerprint": fingerprint(scenario),
                           "collected_by": f"spotsim {__version__} (spotsim study spreads)"}}


def write_spreads(entries: list[dict], path) -> dict:
    """The typical-spreads file (the format `typical_spreads` reads) of `entries`
    (`spread_from_study`), keyed by each scenario's fingerprint, written whole to `path`."""
    from pathlib import Path

    from ..files import atomic_write

    doc = {"about": "written by `spotsim study spreads`; read by spotsim.studies.estimate.typical_spread",
           "scenarios": {e["provenance"]["fingerprint"]: e for e in entries}}
    atomic_write(Path(path), json.dumps(doc, indent=2) + "\n")
    return doc


def typical_spreads() -> dict:
    """The shipped typical spreads: `scenario.fingerprint` -> `study_spread` entry."""
    return json.loads(resources.files(__package__).joinpath(TYPICAL_SPREAD).read_text())["scenarios"]


def typical_spread(scenario) -> dict | None:
    """The study's spread for exactly this scenario (the same `fingerprint`), or None."""
    return typical_spreads().get(fingerprint(scenario))


def estimate(scenario, summary: dict, source: str = "<scenario>", ensemble=None, *,
             spread_members: int = SPREAD_MEMBERS, workers: int | None = None, model=None,
             progress: bool = False) -> dict:
    """Run the companion of `scenario`, whose run gave `summary`, and return the error
    estimate entry for that summary. Its spread: the study's (`typical_spread`) where the
    scenario was studied, else that of the `ensemble` the run belongs to, else, for a run that
    completed, `spread_members` starts around its own (`start_spread`, in `workers` processes;
    0: none, and no bound)."""
    from ..run import simulate

    s = companion(scenario)
    spread = typical_spread(scenario) or (ensemble_spread(ensemble) if ensemble is not None else None)
    if spread is None and s is not None:
        spread = own_spread(scenario, summary, spread_members, workers=workers, model=model, source=source,
                            progress=progress)
    why = NO_SPREAD if spread_members else "none: --spread-members 0"
    if summary["status"] not in CLOSED:
        why = f"none: the run ended {summary['status']} (a run whose grasps all close gets one)"
    return error_estimate(summary, None if s is None else simulate(s, source=source).summary, spread, why)


# ---------------------------------------------------------------------------- validation


def validate(scenario, reference, n: int = 8, *, seed: int = VALIDATION_SEED, workers: int | None = None,
             progress: bool = False, spread_members: int = SPREAD_MEMBERS) -> list[dict]:
    """Check the estimate against a converged reference from n perturbed starts (members 1..n
    of `ensemble`'s, seeded; member 0, the unperturbed start, is every seed's, so it is among
    the study's behind `typical_spread`): one row per member, grasp and quantity with the
    run's value, the companion's, the estimate, uncertainty and bound, the reference's, the
    true error |run - reference| and whether it lies within each. `reference`: the scenario
    at a converged setting. The spread is the study's for a studied scenario; for another,
    each member's own, measured around its start as `spotsim run` measures it (`start_spread`,
    `spread_members` starts; 0: none)."""
    from .ensemble import ensemble, member_scenario, start_of

    other = companion(scenario)
    if other is None:
        raise ValueError(f"{scenario.simulation.integrator.method}: no companion to estimate with")
    spread = typical_spread(scenario)
    runs = [ensemble(s, n + 1, seed=seed, workers=workers, progress=progress).members[1:]
            for s in (scenario, other, reference)]
    rows = []
    for run, comp, ref in zip(*runs, strict=True):
        if not (run.summary and comp.summary and ref.summary):
            continue
        own = spread or own_spread(member_scenario(scenario, start_of(run)), run.summary, spread_members,
                                   workers=workers)
        truth = quantities(ref.summary)
        for g, entry in enumerate(error_estimate(run.summary, comp.summary, own)["grasps"]):
            for name, q in entry.items():
                r = truth[g].get(name) if g < len(truth) else None
                error = None if q["value"] is None or r is None else abs(q["value"] - r)
                known = error is not None and q["estimate"] is not None
                rows.append({"member": run.index, "spread": None if own is None else own["source"],
                             "grasp": g + 1, "quantity": name, "value": q["value"],
                             "companion": q["companion"], "estimate": q["estimate"], "uncertainty": q["uncertainty"],
                             "chance": q["chance"], "bound": q["bound"], "reference": r, "error": error,
                             "distribution": q["distribution"],
                             "within": known and error <= q["estimate"],
                             "within_uncertainty": known and error <= q["uncertainty"],
                             "within_bound": None if not known or q["bound"] is None else error <= q["bound"]})
    return rows


def validation_table(rows: list[dict]) -> list[dict]:
    """Per grasp and quantity: how many members' true errors lay within their estimates, their
    uncertainties and their bounds (None without a spread), and the median estimate, bound
    and true error."""
    import numpy as np

    out = []
    for key in dict.fromkeys((r["grasp"], r["quantity"]) for r in rows):
        group = [r for r in rows if (r["grasp"], r["quantity"]) == key and r["error"] is not None
                 and r["estimate"] is not None]
        if not group:
            continue
        bounded = [r for r in group if r["within_bound"] is not None]
        out.append({"grasp": key[0], "quantity": key[1], "members": len(group), "bounded": len(bounded),
                    "within": sum(r["within"] for r in group),
                    "within_uncertainty": sum(r["within_uncertainty"] for r in group),
                    "within_bound": sum(r["within_bound"] for r in bounded) if bounded else None,
                    "median_estimate": float(np.median([r["estimate"] for r in group])),
                    "median_bound": float(np.median([r["bound"] for r in bounded])) if bounded else None,
                    "median_error": float(np.median([r["error"] for r in group])),
                    "distribution": group[0]["distribution"]})
    return out
