"""The studies' reports in markdown: what a study found, as its .md beside the CSV it wrote.

A study computes and writes its table (`studies`); this module writes its pages from the
report the study returns, as `study_figures` draws its figures from its files. `spotsim
study` writes both after the study ends (or is stopped).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .files import atomic_write
from .scenario import modules_of
from .status import COMPARABLE, WEDGED_OFFSET_MM, WEDGED_TILT_DEG
from .studies import accuracy, accuracy_ensemble, stability
from .studies.accuracy import (
    CONFIRM_REL,
    LADDER_REL,
    PERTURBATION_MM,
    WITHIN_REL,
    AccuracyReport,
)
from .studies.accuracy_ensemble import (
    DETERMINISTIC_REL,
    KS_ALPHA,
    RESIDUAL_MEDIAN_REL,
    EnsembleAccuracyReport,
    deterministic_quantities,
)
from .studies.ensemble import OFFSET_TOL_MM, RPY_TOL_DEG, grasp_names, grasp_prefix
from .studies.runs import free_floating
from .studies.stability import FINER, StabilityReport

# ----------------------------------------------------------------------------- cells and tables


def markdown_table(header: list[str], rows: list[list]) -> str:
    """A markdown table (a pipe in a cell escaped), without a newline after its last row."""
    def line(cells):
        return "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |"
    return "\n".join([line(header), line("---" for _ in header), *map(line, rows)])


def sig(x, digits=3) -> str:
    """A markdown cell: `digits` significant digits, a dash for nan."""
    return "–" if _nan(x) else f"{x:.{digits}g}"


def percent(x, spec: str = ".3g") -> str:
    """A share as a percentage cell, formatted by `spec`; a dash for nan."""
    return "–" if _nan(x) else f"{100 * x:{spec}} %"


def _nan(x) -> bool:
    return isinstance(x, (float, np.floating)) and math.isnan(x)


# ----------------------------------------------------------------------------- the accuracy study


def accuracy_confirmation(report: AccuracyReport) -> str:
    r, c = report.reference.label(report.dt_s), report.confirmation.label(report.dt_s)
    if not report.reference_outcome.comparable:
        return (f"reference not usable: {r} ended {report.reference_outcome.status} "
                f"({report.reference_outcome.message}); no errors computed")
    if report.confirmation_outcome is None:
        return f"reference not confirmed: the study stopped before its confirmation ({c}) ran"
    if math.isnan(report.change_rel):
        text = (f"reference not confirmed: its refinement {c} ended {report.confirmation_outcome.status} "
                f"({report.confirmation_outcome.message})")
        if report.coarser is not None and not math.isnan(report.coarser_change_rel):
            text += (f"; the setting one refinement coarser, {report.coarser.label(report.dt_s)}, differs from "
                     f"it by up to {100 * report.coarser_change_rel:.3g} % ({report.coarser_change_what})")
        return text
    verdict = "confirmed" if report.confirmed else "not confirmed"
    return (f"reference {verdict}: refining {r} to {c} changes the reported quantities by at most "
            f"{100 * report.change_rel:.3g} % ({report.change_what}; the bound is {100 * CONFIRM_REL:g} %)")


def accuracy_sensitivity(report: AccuracyReport) -> str:
    if math.isnan(report.sensitivity_rel):
        return "sensitivity not measured"
    return (f"sensitivity: starting the reference {PERTURBATION_MM * 1e6:g} nm off in y changes the reported "
            f"quantities by at most {100 * report.sensitivity_rel:.3g} % ({report.sensitivity_what}); no setting "
            f"can be expected to agree with the reference more closely than that")


def ladder_table(report: AccuracyReport) -> str:
    """The fastest setting within 1 % and each of LADDER_REL, on every quantity at once and
    on each alone, next to how much refining and perturbing the reference changes each: a
    markdown table."""
    keys = ["max_err_rel"] + [k for k in report.rows[0] if k.endswith("_err_rel") and k != "max_err_rel"]
    bounds = (WITHIN_REL, *LADDER_REL)
    by_role = {r["role"]: r for r in report.rows}
    checks = {"confirmation": "refining the reference changes it by",
              "coarser check": "the coarser check differs by",
              "perturbed": f"a {PERTURBATION_MM * 1e6:g} nm start changes it by"}
    checks = {role: text for role, text in checks.items() if role in by_role}
    rows = []
    for key in keys:
        cells = [percent(by_role[role][key]) for role in checks]
        for rel in bounds:
            best = report.fastest_within(rel, key)
            cells.append("none" if best is None else
                         f"{best['setting']} ({best['wall_time_s']:.3g} s, {100 * best[key]:.2g} %)")
        name = "every quantity" if key == "max_err_rel" else key.removesuffix("_err_rel").replace("_", " ")
        rows.append([name, *cells])
    return markdown_table(["error of", *checks.values(), *(f"fastest within {100 * b:g} %" for b in bounds)],
                          rows)


def accuracy_fastest(report: AccuracyReport) -> str:
    best = report.fastest_within()
    if not report.reference_outcome.comparable:
        return "fastest setting within 1 % of the reference: none (no usable reference)"
    u = report.uncertainty_rel
    resolution = "" if u <= WITHIN_REL else (
        f"; the reference itself is uncertain by {100 * u:.3g} %, more than 1 %, so this is within 1 % "
        f"of the reference, not of the converged answer" if not math.isnan(u) else
        "; how far the reference is from the converged answer is not known")
    if best is None:
        return f"fastest setting within 1 % of the reference: none of the settings swept{resolution}"
    return (f"fastest setting within 1 % of the reference: {best['setting']} ({best['role']}), "
            f"{best['wall_time_s']:.3g} s of wall time, largest error {100 * best['max_err_rel']:.3g} %"
            f"{resolution}")




def accuracy_markdown(scenario, report: AccuracyReport) -> str:
    names, centroid = grasp_names(scenario), free_floating(scenario)
    header = ["setting", "role", "status", "wall (s)", "force evals"]
    for p in names:
        g = f"{p[:-1]} " if p else ""
        header += [f"{g}offset (mm)", f"{g}offset error (mm)", f"{g}offset error", f"{g}peak force (N)",
                   f"{g}peak force error"]
        if centroid:
            header += [f"{g}centroid displ. (mm)", f"{g}centroid error"]
    header += ["within 1 %", "momentum drift lin / ang"]
    rows = []
    for r in report.rows:
        cells = [r["setting"], r["role"], r["status"] if r["status"] in COMPARABLE else
                 f"{r['status']}: {r['message']}", sig(r["wall_time_s"]), sig(r["force_evaluations"], 4)]
        for p in names:
            cells += [sig(r[f"{p}offset_norm_mm"], 4), sig(r[f"{p}offset_err_mm"], 2), percent(r[f"{p}offset_err_rel"]),
                      sig(r[f"{p}peak_force_N"], 4), percent(r[f"{p}peak_force_err_rel"])]
            if centroid:
                cells += [sig(r[f"{p}centroid_norm_mm"], 4), percent(r[f"{p}centroid_err_rel"])]
        cells += ["yes" if r["within_1pct"] else "no",
                  f"{sig(r['linear_drift_rel'], 2)} / {sig(r['angular_drift_rel'], 2)}"]
        rows.append(cells)
    text = [f"# Accuracy study: {report.scenario}", "",
            (f"Errors against the reference, {report.reference.label(report.dt_s)}. The offset is O_b from "
             f"O_a at the end of the run (the residual offset of a completed grasp); its error is the norm "
             f"of the vector difference. Wall time is the simulation loop's."), "",
            *(f"- {line}" for line in findings(report))]
    if report.interrupted:
        text.append("- **interrupted**: the study was stopped; the rows below are the runs that finished")
    ladder = ("\n\nPer quantity: how well the reference is known, and the fastest setting within each "
              "bound of it (wall time, error):\n\n"
              + ladder_table(report)) if report.rows else ""
    return "\n".join(text) + ladder + "\n\nEvery run:\n\n" + markdown_table(header, rows) + "\n"


# ----------------------------------------------------------------------------- the accuracy study over ensembles


def ensemble_confirmation(report: EnsembleAccuracyReport) -> str:
    c = report.row("confirmation")
    ref = report.reference.label(report.dt_s)
    if report.row("reference") is None:
        return "reference not run"
    if c is None:
        return "reference not confirmed: the study stopped before its confirmation ran"
    fewer = (f" ({c['members']} members, against the reference's first {c['members']})"
             if c["members"] < report.members else "")
    return (f"refining the reference {ref} to {report.confirmation.label(report.dt_s)}{fewer} changes the "
            f"deterministic quantities, member by member, by at most {percent(c['max_deterministic_rel'])} "
            f"({c['worst_deterministic']}); the residual's KS p = {sig(c['min_residual_ks_p'], 2)}, its "
            f"median by {percent(c['max_residual_median_rel'])}: "
            f"{'within' if c['meets_targets'] else 'NOT within'} the targets")


def ensemble_fastest(report: EnsembleAccuracyReport) -> str:
    best = report.fastest_meeting()
    text = ("fastest setting meeting every target: none of the settings swept" if best is None else
            f"fastest setting meeting every target: {best['setting']}, {best['wall_per_member_s']:.3g} s "
            f"per member")
    adaptive = report.fastest_meeting("adaptive_euler")
    if adaptive is not None and adaptive is not best:
        text += f"; fastest adaptive_euler: tol {adaptive['tol']:g} m/s, {adaptive['wall_per_member_s']:.3g} s"
    return text




def _yes(x) -> str:
    return "yes" if x else "**no**"


def _error(x) -> str:
    return "" if math.isnan(x) else f"± {percent(x, '.2g')}"


def ensemble_markdown(scenario, report: EnsembleAccuracyReport) -> str:
    """The study's markdown: its findings, then a table of the targets and one of the values."""
    n_grasps, dual = len(modules_of(scenario)), scenario.kind == "dual_arm"
    ref = report.row("reference")
    head = [f"# Accuracy study over ensembles: {report.scenario}", "",
            (f"Every setting run from the same {report.members} starts (seed {report.seed}, each module's start "
             f"moved uniformly within +-{OFFSET_TOL_MM * 1e3:g} um and +-{RPY_TOL_DEG:g} deg; member 0 "
             f"unperturbed), compared with the reference's ensemble, {report.reference.label(report.dt_s)}. "
             f"Targets: the peak force and torque norms"
             f"{' and the robot centroid displacement norm' if dual else ''} within "
             f"{100 * DETERMINISTIC_REL:g} % of the reference's, member by member (the median of each member's own "
             f"difference from the reference member that started alike); the residual offset norm's distribution "
             f"with a two-sample KS p-value above {KS_ALPHA:g} and its median within "
             f"{100 * RESIDUAL_MEDIAN_REL:g} %. Each difference is followed by its sampling error (bootstrap); "
             f"the deterministic quantities' difference of medians and the 90th percentile of the members' own "
             f"differences are shown too. "
             f"Wall time: the simulation loop's, per member, with the members run in parallel."), "",
            *(f"- {line}" for line in findings(report))]
    if report.interrupted:
        head.append("- **interrupted**: the study was stopped; the rows below are the settings that finished")
    targets, values = [], []
    for r in report.rows:
        targets.append([r["setting"], r["role"], str(r["members"]), r["statuses"], sig(r["wall_per_member_s"]),
                        percent(r["max_deterministic_rel"]), _yes(r["deterministic_ok"]),
                        sig(r["min_residual_ks_p"], 2), _yes(r["residual_ks_ok"]),
                        percent(r["max_residual_median_rel"]), _yes(r["residual_median_ok"]),
                        _yes(r["meets_targets"])])
        for g in range(n_grasps):
            p = grasp_prefix(g, n_grasps)
            cells = [r["setting"], f"{p[:-1] or 'grasp'}",
                     f"{sig(r[f'{p}residual_median_mm'], 3)} [{sig(r[f'{p}residual_p10_mm'], 3)}, "
                     f"{sig(r[f'{p}residual_p90_mm'], 3)}]",
                     f"{sig(r[f'{p}residual_ks_p'], 2)} / {percent(r[f'{p}residual_median_rel'], '+.2g')} "
                     f"{_error(r[f'{p}residual_median_rel_error'])}",
                     f"{percent(r[f'{p}seated'], '.0f')} / {percent(r[f'{p}wedged'], '.0f')} "
                     f"({percent(ref[f'{p}seated'], '.0f')} / {percent(ref[f'{p}wedged'], '.0f')})" if ref else "–",
                     f"{sig(r[f'{p}roll_median_deg'], 3)} (p {sig(r[f'{p}roll_ks_p'], 2)}), "
                     f"{sig(r[f'{p}pitch_ks_p'], 2)}, {sig(r[f'{p}yaw_ks_p'], 2)}"]
            for _, name, unit in deterministic_quantities(dual):
                cells.append(f"{sig(r[f'{p}{name}_median_{unit}'], 4)} [{sig(r[f'{p}{name}_p10_{unit}'], 4)}, "
                             f"{sig(r[f'{p}{name}_p90_{unit}'], 4)}] {percent(r[f'{p}{name}_median_rel'], '+.2g')} "
                             f"{_error(r[f'{p}{name}_median_rel_error'])}; member by member "
                             f"{percent(r[f'{p}{name}_paired_rel'], '+.2g')} "
                             f"{_error(r[f'{p}{name}_paired_rel_error'])}, "
                             f"p90 {percent(r[f'{p}{name}_paired_p90_abs'], '.2g')}")
            values.append(cells)
    target_table = markdown_table(
        ["setting", "role", "members", "statuses", "wall per member (s)", "deterministic member by member, worst",
         f"within {100 * DETERMINISTIC_REL:g} %", "residual KS p, least", f"p > {KS_ALPHA:g}",
         "residual median, worst", f"within {100 * RESIDUAL_MEDIAN_REL:g} %", "all targets"], targets)
    det_heads = [f"{name.replace('_', ' ')} ({unit}) median [p10, p90], vs ref; member by member, p90 of |diff|"
                 for _, name, unit in deterministic_quantities(dual)]
    value_table = markdown_table(
        ["setting", "grasp", "residual e (mm) median [p10, p90]", "residual KS p / median vs ref",
         "seated / wedged (ref)", "roll median deg (KS p); pitch, yaw KS p", *det_heads], values)
    return ("\n".join(head) + "\n\nTargets (the worst grasp):\n\n" + target_table
            + "\n\nValues per grasp:\n\n" + value_table + "\n")


# ----------------------------------------------------------------------------- the stability study


def stability_markdown(scenario, report: StabilityReport) -> str:
    header = ["case", "change", "predicted stable step (ms)", "ω·h", "verdict", "prediction held",
              "residual offset (mm)", "peak force (N)", "sim / wall (s)", "outcome", f"diverged: at h/{FINER}",
              "diverged: gradient law"]
    rows = [[r["case"], r["change"], sig(r["predicted_stable_step_ms"]), sig(r["omega_h"]), r["verdict"],
             r["prediction_held"],
             sig(r["residual_offset_mm"]), sig(r["peak_force_N"]), f"{sig(r['sim_time_s'])} / {sig(r['wall_time_s'])}",
             r["message"], "" if r["finer_verdict"] == "not run" else f"{r['finer_verdict']}: {r['finer_message']}",
             "" if r["gradient_verdict"] == "not run" else f"{r['gradient_verdict']}: {r['gradient_message']}"]
            for r in report.rows]
    counts = {}
    for r in report.rows:
        counts[r["verdict"]] = counts.get(r["verdict"], 0) + 1
    step = next((r["dynamics_step_ms"] for r in report.rows if not math.isnan(r["dynamics_step_ms"])), math.nan)
    text = [f"# Stability study: {report.scenario}", "",
            (f"Dynamics step {sig(step)} ms ({scenario.simulation.integrator.method}). The predicted stable step "
             f"is stability.predict_step's; ω·h is the stiffest contact mode times the step (the integrator's "
             f"limit on the imaginary axis is 2 for symplectic Euler). A closed grasp is seated or wedged "
             f"by the ensembles' thresholds ({WEDGED_OFFSET_MM:g} mm, {WEDGED_TILT_DEG:g} deg). A diverged case "
             f"runs again with a step {FINER} times smaller: if it still diverges, the step is not the "
             f"cause; and with the energy-consistent pair law (contact.normal_direction: gradient)."), "",
            "- verdicts: " + ", ".join(f"{n} {v}" for v, n in counts.items())]
    if report.failures:
        text.append(f"- **{len(report.failures)} case(s) FAILED** (an exception or a silent NaN): "
                    + ", ".join(r["case"] for r in report.failures))
    if report.interrupted:
        text.append("- **interrupted**: the study was stopped; the rows below are the cases that finished")
    return "\n".join(text) + "\n\n" + markdown_table(header, rows) + "\n"


# ----------------------------------------------------------------------------- every study


def findings(report) -> list[str]:
    """What a study found, a line each (its .md's list; `spotsim study` prints them): the
    reference's confirmation, (a single-run study) the sensitivity to the start, the fastest
    setting within the targets."""
    if isinstance(report, EnsembleAccuracyReport):
        return [ensemble_confirmation(report), ensemble_fastest(report)]
    return [accuracy_confirmation(report), accuracy_sensitivity(report), accuracy_fastest(report)]


def write_markdown(scenario, report, out) -> list:
    """Write the study's .md (accuracy.md, accuracy_ensemble.md or stability.md) into `out`;
    returns its path in a list."""
    name, text = ((accuracy_ensemble.PAGE, ensemble_markdown(scenario, report))
                  if isinstance(report, EnsembleAccuracyReport) else
                  (accuracy.PAGE, accuracy_markdown(scenario, report)) if isinstance(report, AccuracyReport) else
                  (stability.PAGE, stability_markdown(scenario, report)))
    path = Path(out) / name
    atomic_write(path, text)
    return [path]
