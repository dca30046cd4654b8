"""The accuracy study over ensembles: each setting run from the same N perturbed starts.

A run's residual offset and tilt are samples of a distribution over microscopic start
perturbations (model.md Sec. 9): one run against one reference run says nothing about them.
Here every setting (the reference, its confirmation, each swept one) is an N-member ensemble
(`spotsim.ensemble`) with the same seed, hence the same starts, and is compared with the
reference's ensemble:

- distributions (each grasp's residual offset norm, and its roll, pitch, yaw): the two-sample
  Kolmogorov-Smirnov p-value (scipy.stats.ks_2samp) and the difference of the medians, and the
  seated / wedged shares;
- near-deterministic quantities (each grasp's peak contact force and torque norms; on the
  free-floating robot its centroid displacement norm): the relative difference of the medians,
  next to each ensemble's p10-p90 spread, which shows how deterministic they are; and member
  by member (`paired_rel`): the median of each member's own relative difference from the
  reference member that started alike, and the 90th percentile of its size.

Each difference comes with its sampling error (`median_rel_error`, `paired_rel`): two
ensembles' medians differ by chance as well as by accuracy, and a difference within about two
of these errors is not resolved by N members.

A setting meets the targets when every deterministic quantity's member-by-member median
difference is within DETERMINISTIC_REL, and every grasp's residual has a KS p-value above
KS_ALPHA and a median within RESIDUAL_MEDIAN_REL of the reference's. Both differences of a
deterministic quantity measure how far its distribution has moved. A peak is reached in the
first impacts, before the bounces decorrelate the members, so a member and its reference stay
correlated, and the median of their own differences resolves a shift that the difference of
two medians of a wide spread across starts cannot. Its bootstrap resamples whole pairs, so
where the members do decorrelate its error grows with their spread and claims no precision
the pairs lack.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..files import atomic_write, prepare
from ..scenario import modules_of
from ..status import SEATED, WEDGED
from .ensemble import (
    EnsembleResult,
    ensemble,
    finite,
    grasp_prefix,
    members_csv,
    statistics,
)
from .runs import StudyRows, warm_up

#: Targets of a setting against the reference (issue 14): the near-deterministic quantities
#: within 2 %, member by member (`paired_rel`); the residual offset's distribution not told
#: apart from the reference's by a KS test at 5 %, and its median within 5 %.
DETERMINISTIC_REL = 0.02
KS_ALPHA = 0.05
RESIDUAL_MEDIAN_REL = 0.05
#: Resamples of the bootstrap that gives a difference of medians its sampling error.
BOOTSTRAP = 2000
#: The study's page (`study_reports`), removed as the study starts.
PAGE = "accuracy_ensemble.md"

#: (members-table column without grasp prefix, CSV name, unit) of the compared quantities.
DISTRIBUTED = (("residual_norm_mm", "residual", "mm"),)
ANGLES = (("residual_roll_deg", "roll", "deg"), ("residual_pitch_deg", "pitch", "deg"),
          ("residual_yaw_deg", "yaw", "deg"))
DETERMINISTIC = (("peak_force_norm_N", "peak_force", "N"), ("peak_torque_norm_Nm", "peak_torque", "Nm"))
CENTROID = (("centroid_displacement_norm_mm", "centroid", "mm"),)


def deterministic_quantities(dual: bool):
    return DETERMINISTIC + (CENTROID if dual else ())


# ----------------------------------------------------------------------------- statistics


def ks_pvalue(a, b) -> float:
    """The two-sample Kolmogorov-Smirnov p-value of samples a and b (nan if either is empty)."""
    from scipy.stats import ks_2samp

    a, b = finite(a), finite(b)
    if not len(a) or not len(b):
        return math.nan
    return float(ks_2samp(a, b).pvalue)


def quantiles(values) -> tuple[float, float, float]:
    """(p10, median, p90) of the finite values (`ensemble.statistics`; nan if none)."""
    st = statistics(values)
    return (math.nan,) * 3 if not st["count"] else (st["p10"], st["median"], st["p90"])


def median_rel(a, b) -> float:
    """The signed relative difference of the median of a from the median of b."""
    ma, mb = quantiles(a)[1], quantiles(b)[1]
    if math.isnan(ma) or math.isnan(mb) or mb == 0:
        return math.nan
    return (ma - mb) / abs(mb)


def median_rel_error(a, b, seed: int = 0) -> float:
    """The sampling error of `median_rel(a, b)`: the standard deviation of the relative
    difference of the medians over BOOTSTRAP resamples, with replacement, of each sample
    (seeded; nan if either has fewer than two finite values). The samples are resampled
    independently, as two medians are taken: the member-by-member difference is
    `paired_rel`'s."""
    a, b = finite(a), finite(b)
    if len(a) < 2 or len(b) < 2:
        return math.nan
    rng = np.random.default_rng(seed)
    ma = np.median(rng.choice(a, (BOOTSTRAP, len(a))), axis=1)
    mb = np.median(rng.choice(b, (BOOTSTRAP, len(b))), axis=1)
    return float(np.std((ma - mb) / np.abs(mb)))


def paired_rel(rows: list[dict], ref_rows: list[dict], column: str, seed: int = 0) -> tuple[float, float, float]:
    """Member by member: the median over the members of their own relative difference in
    `column` from the reference member of the same index, its sampling error (the standard
    deviation of that median over BOOTSTRAP resamples of the pairs, with replacement; seeded)
    and the 90th percentile of the differences' size. nan where no member has a pair (the
    error: fewer than two)."""
    ref = {r["member"]: r.get(column) for r in ref_rows}
    pairs = [(r.get(column), ref.get(r["member"])) for r in rows]
    d = np.array([a / b - 1.0 for a, b in pairs if finite([a, b]).size == 2 and b != 0.0])
    if not d.size:
        return math.nan, math.nan, math.nan
    error = math.nan
    if d.size > 1:
        rng = np.random.default_rng(seed)
        error = float(np.std(np.median(d[rng.integers(0, d.size, (BOOTSTRAP, d.size))], axis=1)))
    return float(np.median(d)), error, float(np.percentile(np.abs(d), 90))


def class_share(rows: list[dict], p: str, cls: str) -> float:
    """The share of `rows` (members that ran) whose grasp `p` ended as `cls`."""
    ran = [r for r in rows if r["status"] != "interrupted"]
    return sum(r[f"{p}class"] == cls for r in ran) / len(ran) if ran else math.nan


def compare(rows: list[dict], ref_rows: list[dict], n_grasps: int, dual: bool) -> dict:
    """The comparison of an ensemble's member rows with the reference's: per grasp, for the
    residual and its angles the KS p-value and the median difference (relative for the offset
    norm, deg for the angles); for each deterministic quantity the relative difference of the
    medians and the member-by-member one (`paired_rel`: `*_paired_rel`, its error and
    `*_paired_p90_abs`); each relative difference's sampling error (`*_rel_error`); the seated /
    wedged shares; then the targets (`*_ok`, `meets_targets`) and the worst of each measure
    over the grasps (`max_deterministic_rel`, `min_residual_ks_p`, `max_residual_median_rel`).
    The reference is taken over the same members as `rows` (the
    first k of its starts, when the ensemble has fewer members)."""
    members = {r["member"] for r in rows}
    ref_rows = [r for r in ref_rows if r["member"] in members]
    out: dict = {}
    det, ks, med = [], [], []
    for g in range(n_grasps):
        p = grasp_prefix(g, n_grasps)

        def col(rs, q, p=p):
            return [r.get(f"{p}{q}") for r in rs]

        for q, name, unit in DISTRIBUTED:
            a, b = col(rows, q), col(ref_rows, q)
            out[f"{p}{name}_p10_{unit}"], out[f"{p}{name}_median_{unit}"], out[f"{p}{name}_p90_{unit}"] = quantiles(a)
            out[f"{p}{name}_ks_p"] = ks_pvalue(a, b)
            out[f"{p}{name}_median_rel"] = median_rel(a, b)
            out[f"{p}{name}_median_rel_error"] = median_rel_error(a, b)
            ks.append(out[f"{p}{name}_ks_p"])
            med.append(abs(out[f"{p}{name}_median_rel"]))
        for q, name, unit in ANGLES:
            a, b = col(rows, q), col(ref_rows, q)
            out[f"{p}{name}_median_{unit}"] = quantiles(a)[1]
            out[f"{p}{name}_ks_p"] = ks_pvalue(a, b)
            out[f"{p}{name}_median_diff_{unit}"] = quantiles(a)[1] - quantiles(b)[1]
        for q, name, unit in deterministic_quantities(dual):
            a, b = col(rows, q), col(ref_rows, q)
            out[f"{p}{name}_p10_{unit}"], out[f"{p}{name}_median_{unit}"], out[f"{p}{name}_p90_{unit}"] = quantiles(a)
            out[f"{p}{name}_median_rel"] = median_rel(a, b)
            out[f"{p}{name}_median_rel_error"] = median_rel_error(a, b)
            (out[f"{p}{name}_paired_rel"], out[f"{p}{name}_paired_rel_error"],
             out[f"{p}{name}_paired_p90_abs"]) = paired_rel(rows, ref_rows, f"{p}{q}")
            det.append(abs(out[f"{p}{name}_paired_rel"]))
        out[f"{p}completed"] = sum(r[f"{p}class"] in (SEATED, WEDGED) for r in rows)
        out[f"{p}seated"] = class_share(rows, p, SEATED)
        out[f"{p}wedged"] = class_share(rows, p, WEDGED)

    def worst(values, best=max):
        return math.nan if not values or any(math.isnan(v) for v in values) else best(values)

    out["max_deterministic_rel"] = worst(det)
    out["min_residual_ks_p"] = worst(ks, min)
    out["max_residual_median_rel"] = worst(med)
    out["deterministic_ok"] = out["max_deterministic_rel"] <= DETERMINISTIC_REL  # False on nan
    out["residual_ks_ok"] = out["min_residual_ks_p"] > KS_ALPHA
    out["residual_median_ok"] = out["max_residual_median_rel"] <= RESIDUAL_MEDIAN_REL
    out["meets_targets"] = out["deterministic_ok"] and out["residual_ks_ok"] and out["residual_median_ok"]
    return out


# ----------------------------------------------------------------------------- the study


@dataclass
class EnsembleAccuracyReport:
    """What an ensemble accuracy study found: `rows` as written to its CSV (one per setting),
    `ensembles` each setting's EnsembleResult by its label."""

    scenario: str
    dt_s: float
    members: int
    seed: int
    reference: object  # accuracy.Setting
    confirmation: object
    confirmation_members: int
    rows: list[dict]
    ensembles: dict[str, EnsembleResult] = field(default_factory=dict)
    interrupted: bool = False
    files: list[Path] = field(default_factory=list)

    def row(self, role: str) -> dict | None:
        return next((r for r in self.rows if r["role"] == role), None)

    def fastest_meeting(self, method: str | None = None) -> dict | None:
        """The swept setting (of `method`, if given) with the least wall time per member that
        meets every target."""
        ok = [r for r in self.rows if r["role"] not in ("reference", "confirmation") and r["meets_targets"]
              and (method is None or r["method"] == method)]
        return min(ok, key=lambda r: r["wall_per_member_s"]) if ok else None

def columns(n_grasps: int, dual: bool) -> list[str]:
    cols = ["role", "setting", "method", "substeps", "step_ms", "tol", "members", "seed", "statuses",
            "wall_per_member_s", "wall_time_s", "steps_per_member", "force_evaluations_per_member"]
    for g in range(n_grasps):
        p = grasp_prefix(g, n_grasps)
        cols += [f"{p}completed", f"{p}seated", f"{p}wedged"]
        for _, name, unit in DISTRIBUTED:
            cols += [f"{p}{name}_median_{unit}", f"{p}{name}_p10_{unit}", f"{p}{name}_p90_{unit}",
                     f"{p}{name}_ks_p", f"{p}{name}_median_rel", f"{p}{name}_median_rel_error"]
        for _, name, unit in ANGLES:
            cols += [f"{p}{name}_median_{unit}", f"{p}{name}_ks_p", f"{p}{name}_median_diff_{unit}"]
        for _, name, unit in deterministic_quantities(dual):
            cols += [f"{p}{name}_median_{unit}", f"{p}{name}_p10_{unit}", f"{p}{name}_p90_{unit}",
                     f"{p}{name}_median_rel", f"{p}{name}_median_rel_error", f"{p}{name}_paired_rel",
                     f"{p}{name}_paired_rel_error", f"{p}{name}_paired_p90_abs"]
    return cols + ["max_deterministic_rel", "worst_deterministic", "min_residual_ks_p", "max_residual_median_rel",
                   "deterministic_ok", "residual_ks_ok", "residual_median_ok", "meets_targets"]


def setting_row(setting, role: str, e: EnsembleResult, ref: EnsembleResult, dt_s: float) -> dict:
    """The CSV row of one setting's ensemble compared with the reference's."""
    n_grasps = len(e.statistics)
    dual = e.scenario.kind == "dual_arm"
    rows, ref_rows = e.summary["rows"], ref.summary["rows"]
    ran = [m for m in e.members if m.summary]

    def mean(key):
        values = [m.summary[key] if key in m.summary else m.summary["integrator"].get(key, m.summary["steps"])
                  for m in ran]
        return float(np.mean(values)) if values else math.nan

    row = {"role": role, "setting": setting.label(dt_s), "method": setting.method,
           "substeps": math.nan if setting.adaptive else setting.substeps, "step_ms": setting.step_s(dt_s) * 1e3,
           "tol": setting.tol or math.nan, "members": len(e.members), "seed": e.seed,
           "statuses": " ".join(f"{k}:{v}" for k, v in sorted(e.statuses.items())),
           "wall_per_member_s": mean("wall_time_s"), "wall_time_s": e.wall_time_s,
           "steps_per_member": mean("steps"), "force_evaluations_per_member": mean("force_evaluations")}
    c = compare(rows, ref_rows, n_grasps, dual)
    if role == "reference":  # the same members on both sides: the difference is exactly 0
        c.update({k: math.nan for k in c if k.endswith("_rel_error")})
    det = {f"{grasp_prefix(g, n_grasps)}{name}": abs(c[f"{grasp_prefix(g, n_grasps)}{name}_paired_rel"])
           for g in range(n_grasps) for _, name, _ in deterministic_quantities(dual)}
    row.update(c)
    row["worst_deterministic"] = max(det, key=lambda k: -1.0 if math.isnan(det[k]) else det[k]) if det else ""
    return row


def accuracy_ensemble_study(scenario, settings: list, reference, out_dir, n: int, *, default, seed: int = 0,
                            workers: int | None = None, confirmation_members: int | None = None,
                            source: str = "<study>", progress: bool = False) -> EnsembleAccuracyReport:
    """Run the reference, its confirmation (its refinement; `confirmation_members`, by default
    n, of the same starts) and every setting as an n-member ensemble from the same seeded
    starts; write accuracy_ensemble.csv (a row per setting as it ends), members/<setting>.csv
    (each ensemble's members table) into `out_dir` (its page: `study_reports`, its figure:
    `study_figures`); `default`: the scenario's own setting
    (`accuracy.setting_of`). Ctrl-C stops the study and keeps the rows written
    (report.interrupted); every member's run is kept in members/members.jsonl as it ends, and a
    study started again over `out_dir` runs only the members it lacks (`ensemble.ensemble`'s
    out_dir)."""
    out = Path(out_dir)
    prepare(out, PAGE)
    (out / "members").mkdir(exist_ok=True)
    dt = scenario.simulation.dt_s
    confirmation = reference.refined()
    k = min(confirmation_members or n, n)
    n_grasps, dual = len(modules_of(scenario)), scenario.kind == "dual_arm"
    todo = [(reference, "reference", n), (confirmation, "confirmation", k)]
    todo += [(s, "default" if s == default else "sweep", n) for s in dict.fromkeys(settings)
             if s not in (reference, confirmation)]
    ref = None
    with StudyRows(out / "accuracy_ensemble.csv", columns(n_grasps, dual)) as writer:
        report = EnsembleAccuracyReport(scenario.name, dt, n, seed, reference, confirmation, k, writer.rows)
        warm_up(scenario, sorted({s.method for s, _, _ in todo}))
        for setting, role, size in todo:
            label = setting.label(dt)
            if progress:
                print(f"{scenario.name}: {label} ({role}), {size} members", flush=True)
            e = ensemble(setting.apply(scenario), size, seed=seed, workers=workers, progress=progress,
                         source=source, out_dir=out / "members")
            report.ensembles[label] = e
            atomic_write(out / "members" / f"{slug(label)}.csv", members_csv(e))
            if e.interrupted:
                report.interrupted = True
                break
            ref = ref or e
            writer.write(setting_row(setting, role, e, ref, dt))
    report.interrupted = report.interrupted or writer.interrupted
    report.files = [writer.path]
    return report


def slug(label: str) -> str:
    """A file name for a setting's label: `symplectic_euler h 0.0125 ms` -> `symplectic_euler_h_0.0125_ms`."""
    return re.sub(r"[^A-Za-z0-9.+-]+", "_", label).strip("_")


# ----------------------------------------------------------------------------- convergence checks

#: A numerical parameter refined (a controller's period divided by ten) moves no median by more
#: than this (peak force, residual, completion time, the robot's centroid displacement), nor a
#: seated share out of the other's 90 % interval (`check_rows`, `period_verdict`).
PERIOD_MEDIAN_REL = 0.03


def share_interval(k: int, n: int, level: float = 0.9) -> tuple[float, float]:
    """The Clopper-Pearson interval of a share k/n at `level`."""
    from scipy.stats import beta

    a = (1.0 - level) / 2
    return (0.0 if k == 0 else float(beta.ppf(a, k, n - k + 1)),
            1.0 if k == n else float(beta.ppf(1.0 - a, k + 1, n - k)))


def check_rows(rows: list[dict], ref_rows: list[dict], dual: bool) -> list[dict]:
    """Per grasp, a tested ensemble (member rows) against a reference ensemble from the same
    starts: `compare` with the completion time's median difference, the
    peak force's KS p-value and the seated share's 90 % interval of the reference, and the
    period check's verdicts."""
    n_grasps = 2 if dual else 1
    c = compare(rows, ref_rows, n_grasps, dual)
    members = {row["member"] for row in rows}
    ref = [row for row in ref_rows if row["member"] in members]  # the same starts, as `compare` takes them
    out = []
    for g in range(n_grasps):
        p = grasp_prefix(g, n_grasps)
        x = {k[len(p):]: v for k, v in c.items() if k.startswith(p)} if p else dict(c)
        x["completion_median_rel"] = median_rel([row[f"{p}completed_s"] for row in rows],
                                                [row[f"{p}completed_s"] for row in ref])
        x["completion_median_rel_error"] = median_rel_error([row[f"{p}completed_s"] for row in rows],
                                                            [row[f"{p}completed_s"] for row in ref])
        x["peak_force_ks_p"] = ks_pvalue([row[f"{p}peak_force_norm_N"] for row in rows],
                                         [row[f"{p}peak_force_norm_N"] for row in ref])
        ran = [row for row in ref if row["status"] != "interrupted"]
        k = sum(row[f"{p}class"] == "seated" for row in ran)
        x["seated_interval"] = share_interval(k, len(ran)) if ran else (math.nan, math.nan)
        # the period check: each median moved by more than PERIOD_MEDIAN_REL, and whether by more
        # than two of its sampling errors (resolved by the members)
        medians = [("peak force", "peak_force_median_rel"), ("residual", "residual_median_rel"),
                   ("completion", "completion_median_rel")] + ([("centroid", "centroid_median_rel")] if dual else [])
        x["medians_beyond"] = [(name, abs(x[key]) > 2 * x[f"{key}_error"]) for name, key in medians
                               if not abs(x[key]) <= PERIOD_MEDIAN_REL]
        lo, hi = x["seated_interval"]
        x["seated_within"] = lo <= x["seated"] <= hi
        x["grasp"] = g + 1
        out.append(x)
    return out


def _resolved(flag: bool) -> str:
    return "resolved" if flag else "within 2 sampling errors"


def period_verdict(x: dict) -> str:
    """The period check's verdict on one grasp (`check_rows`)."""
    beyond = "; ".join(f"{name} ({_resolved(flag)})" for name, flag in x["medians_beyond"])
    medians = f"medians beyond {PERIOD_MEDIAN_REL * 100:.0f} %: {beyond}" if beyond else \
        f"medians within {PERIOD_MEDIAN_REL * 100:.0f} %"
    return f"{medians}; seated share {'within' if x['seated_within'] else 'NOT within'} the other's 90 % interval"


def reference_verdict(x: dict) -> str:
    """A check against a finer step's verdict on one grasp (`check_rows`): the ensemble
    accuracy studies' targets it misses, and whether the members resolve each miss."""
    missed = []
    for q in ("peak_force", "peak_torque", "centroid"):
        d = x.get(f"{q}_paired_rel")
        if d is not None and not abs(d) <= DETERMINISTIC_REL:
            flag = abs(d) > 2 * x[f"{q}_paired_rel_error"]
            missed.append(f"{q.replace('_', ' ')} member by member ({_resolved(flag)})")
    if not abs(x["residual_median_rel"]) <= RESIDUAL_MEDIAN_REL:
        flag = abs(x["residual_median_rel"]) > 2 * x["residual_median_rel_error"]
        missed.append(f"residual median ({_resolved(flag)})")
    if not x["residual_ks_p"] > KS_ALPHA:
        missed.append("residual KS")
    return "meets the targets" if not missed else "misses: " + "; ".join(missed)
