"""The accuracy study: error against run time over integrators and steps.

A reference run at a tight setting, confirmed by its next refinement (no reported quantity may
change by more than CONFIRM_REL), then a sweep of integrator x step (x tolerance for dopri5, x
sphere radius if asked). Each setting reports its error against the reference in the residual
offset, the peak contact force and (dual arm) the robot's centroid displacement, its momentum
drift, its wall time and its status, a row of accuracy.csv each (its page: `study_reports`, its
figure: `study_figures`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from dataclasses import replace as dc_replace
from pathlib import Path

import numpy as np

from ..files import prepare
from ..scenario import Integrator, modules_of, replace
from ..tables import ADAPTIVE, METHODS
from .ensemble import grasp_names
from .runs import (
    RUNS_FILE,
    Outcome,
    Runs,
    StudyRows,
    errors,
    free_floating,
    warm_up,
    worst,
)

#: The refinement that confirms a reference may change no reported quantity by more than this
#: share of it (the issue's 0.1 %).
CONFIRM_REL = 1e-3
#: "Within 1 % of the reference": every reported quantity within this share of the reference's.
WITHIN_REL = 1e-2
#: Looser bounds whose fastest settings the report names too, on every quantity and on each:
#: 1 % may lie below what the reference can resolve.
LADDER_REL = (0.05, 0.1, 0.2)
#: How far the sensitivity run moves each module's start, mm (1 nm, along y_a): a change of
#: the reported quantities under it is the floor below which no setting can agree.
PERTURBATION_MM = 1e-6
#: dopri5's absolute tolerance is its relative one times this: the state's positions are
#: ~0.1-1 m from the origin and its speeds ~10 mm/s, so atol (m, m/s) must sit well below
#: rtol x position for the speeds to be controlled at all (the scenario default is 1e-6 / 1e-9).
ATOL_PER_RTOL = 1e-3
#: The study's page (`study_reports`), removed as the study starts.
PAGE = "accuracy.md"

# ----------------------------------------------------------------------------- settings


@dataclass(frozen=True)
class Setting:
    """One integrator setting of a sweep.

    method: symplectic_euler, adaptive_euler, rk4 or dopri5. substeps: dynamics steps per
    recorded step (fixed-step methods; the adaptive ones keep the scenario's, their first trial
    step). rtol: dopri5's relative tolerance (atol = ATOL_PER_RTOL rtol). tol: adaptive_euler's
    velocity tolerance, m/s. sphere_scale: both sphere radii times this.
    """

    method: str
    substeps: int = 0
    rtol: float | None = None
    sphere_scale: float = 1.0
    tol: float | None = None

    @property
    def adaptive(self) -> bool:
        return self.method in ADAPTIVE

    @property
    def atol(self) -> float | None:
        return None if self.rtol is None else self.rtol * ATOL_PER_RTOL

    def step_s(self, dt_s: float) -> float:
        """The dynamics step, s (nan for the adaptive method)."""
        return math.nan if self.adaptive else dt_s / self.substeps

    def label(self, dt_s: float) -> str:
        text = (f"dopri5 rtol {self.rtol:g}" if self.method == "dopri5" else
                f"adaptive_euler tol {self.tol:g} m/s" if self.method == "adaptive_euler" else
                f"{self.method} h {self.step_s(dt_s) * 1e3:g} ms")
        return text + (f", spheres x{self.sphere_scale:g}" if self.sphere_scale != 1.0 else "")

    def refined(self) -> Setting:
        """The next refinement: a tenth of dopri5's tolerance, a quarter of adaptive_euler's
        (its steps ~ tol^(1/2): half the step), or half the step."""
        if self.method == "dopri5":
            return dc_replace(self, rtol=self.rtol / 10)
        if self.method == "adaptive_euler":
            return dc_replace(self, tol=self.tol / 4)
        return dc_replace(self, substeps=2 * self.substeps)

    def coarsened(self) -> Setting | None:
        """The setting one refinement coarser (None below one substep)."""
        if self.method == "dopri5":
            return dc_replace(self, rtol=self.rtol * 10) if self.rtol < 0.1 else None
        if self.method == "adaptive_euler":
            return dc_replace(self, tol=self.tol * 4)
        return dc_replace(self, substeps=self.substeps // 2) if self.substeps % 2 == 0 else None

    def apply(self, s):
        """The scenario `s` run at this setting (validated again)."""
        integrator = {"method": self.method}
        simulation = {"integrator": integrator}
        if self.method == "dopri5":
            integrator.update(rtol=self.rtol, atol=self.atol)
        elif self.method == "adaptive_euler":
            integrator.update(velocity_tol_m_s=self.tol)
        else:
            simulation["substeps"] = self.substeps
        changes = {"simulation": simulation}
        if self.sphere_scale != 1.0:
            c = s.contact
            changes["contact"] = {"sphere_radius_finger_mm": c.sphere_radius_finger_mm * self.sphere_scale,
                                  "sphere_radius_groove_mm": c.sphere_radius_groove_mm * self.sphere_scale}
        return replace(s, **changes)


def setting_of(s) -> Setting:
    """The setting a scenario runs at."""
    i = s.simulation.integrator
    if i.method == "dopri5":
        return Setting("dopri5", rtol=i.rtol)
    if i.method == "adaptive_euler":
        return Setting("adaptive_euler", tol=i.velocity_tol_m_s)
    return Setting(i.method, s.simulation.substeps)


def parse_setting(text: str) -> Setting:
    """`METHOD:VALUE`: `symplectic_euler:80`, `rk4:40` (substeps), `dopri5:1e-7` (rtol) or
    `adaptive_euler:1e-6` (velocity tolerance, m/s)."""
    method, _, value = text.partition(":")
    if method not in METHODS or not value:
        raise ValueError(f"{text}: must read METHOD:VALUE with METHOD one of {', '.join(METHODS)} and VALUE its "
                         f"substeps (fixed step), rtol (dopri5) or velocity tolerance in m/s (adaptive_euler), "
                         f"e.g. dopri5:1e-7")
    try:
        if method in ADAPTIVE:
            tol = float(value)
            if not 0 < tol < 1:
                raise ValueError
            return Setting(method, rtol=tol) if method == "dopri5" else Setting(method, tol=tol)
        substeps = int(value)
        if substeps < 1:
            raise ValueError
        return Setting(method, substeps)
    except ValueError:
        rule = "the tolerance must be a number in (0, 1)" if method in ADAPTIVE else "substeps must be an integer >= 1"
        raise ValueError(f"{text}: {rule}") from None


@dataclass(frozen=True)
class Grid:
    """A sweep: substeps per fixed-step method, dopri5's and adaptive_euler's tolerances, the
    sphere scales, the reference."""

    substeps: dict[str, tuple[int, ...]]
    rtols: tuple[float, ...]
    reference: Setting
    sphere_scales: tuple[float, ...] = (1.0,)
    duration_s: float | None = None  # None: the scenario's
    tols: tuple[float, ...] = ()  # adaptive_euler's velocity tolerances, m/s

    def settings(self) -> list[Setting]:
        out = []
        for scale in self.sphere_scales:
            for method, substeps in self.substeps.items():
                out += [Setting(method, n, sphere_scale=scale) for n in substeps]
            out += [Setting("adaptive_euler", tol=t, sphere_scale=scale) for t in self.tols]
            out += [Setting("dopri5", rtol=r, sphere_scale=scale) for r in self.rtols]
        return out


def narrowed(grid: Grid, methods=None, substeps=None, rtols=None, tols=None, sphere_scales=None,
             reference: Setting | None = None) -> Grid:
    """`grid` with the user's choices: only `methods` (a method the grid leaves out is swept too,
    at `substeps`, when named), these `substeps` for every fixed-step method, these `rtols`
    (dopri5), `tols` (adaptive_euler), `sphere_scales` and `reference`. ValueError for an
    unknown method."""
    bad = [m for m in methods or () if m not in METHODS]
    if bad:
        raise ValueError(f"--methods {','.join(methods)}: unknown {', '.join(bad)}; valid: {', '.join(METHODS)}")
    fixed = {m: substeps or n for m, n in grid.substeps.items()}
    if substeps:  # a method the grid leaves out is swept too when asked for by name
        fixed.update({m: substeps for m in methods or () if m not in ADAPTIVE})
    if methods:
        fixed = {m: n for m, n in fixed.items() if m in methods}
    return Grid(fixed, (rtols or grid.rtols) if not methods or "dopri5" in methods else (),
                reference or grid.reference, sphere_scales or grid.sphere_scales, grid.duration_s,
                tols=(tols or grid.tols) if not methods or "adaptive_euler" in methods else ())


#: adaptive_euler's default tolerance, which the quick grid runs as the default setting
DEFAULT_TOL = Integrator().velocity_tol_m_s
#: adaptive_euler's tolerances swept: quarters of the default, from 16 times it down
TOLS = tuple(DEFAULT_TOL * f for f in (16, 4, 1, 1 / 4, 1 / 16))

#: The grids. The references are fine fixed steps of symplectic Euler: on Case I, 12.5 us takes
#: ~5 s and its confirmation at 6.25 us ~10 s, where dopri5 takes ~200 s at rtol 1e-6 and did
#: not finish in 19 min at 1e-7 (every contact onset and stick-slip switch is a kink its error
#: control steps through). Costs on Case I in docs/validation.md.
GRIDS = {
    # the suite's: Case I's first 120 ms of contact, in which the paper's setting diverges (0.49 s)
    "quick": Grid({"symplectic_euler": (1, 5, 10), "rk4": (10,)}, (1e-4,), Setting("symplectic_euler", 40),
                  duration_s=0.55, tols=(DEFAULT_TOL,)),
    "reduced": Grid({"symplectic_euler": (1, 2, 5, 10, 20), "rk4": (10, 20)}, (1e-4, 1e-5),
                    Setting("symplectic_euler", 40), tols=TOLS[:3]),
    "default": Grid({"symplectic_euler": (1, 2, 5, 10, 20, 40), "rk4": (5, 10, 20, 40)},
                    (1e-3, 1e-4, 1e-5, 1e-6), Setting("symplectic_euler", 80),
                    tols=TOLS),
    "full": Grid({"symplectic_euler": (1, 2, 5, 10, 20, 40, 80), "rk4": (2, 5, 10, 20, 40, 80)},
                 (1e-3, 1e-4, 1e-5, 1e-6), Setting("symplectic_euler", 160), sphere_scales=(1.0, 0.75),
                 tols=TOLS),
}


# ----------------------------------------------------------------------------- accuracy


@dataclass
class AccuracyReport:
    """What an accuracy study found; `rows` as written to its CSV."""

    scenario: str
    dt_s: float
    reference: Setting
    reference_outcome: Outcome
    confirmation: Setting
    confirmation_outcome: Outcome | None
    change_rel: float  # the largest relative change of a reported quantity, reference to confirmation
    change_what: str  # which quantity that is
    rows: list[dict]
    sensitivity_rel: float = math.nan  # the same, reference to the reference started PERTURBATION_MM off
    sensitivity_what: str = ""
    # when the confirmation ends with nothing to compare: the setting one refinement coarser
    coarser: Setting | None = None
    coarser_change_rel: float = math.nan
    coarser_change_what: str = ""

    @property
    def uncertainty_rel(self) -> float:
        """How far the reference may be from the converged answer, as far as the study can tell."""
        return self.coarser_change_rel if math.isnan(self.change_rel) else self.change_rel
    interrupted: bool = False
    files: list[Path] = field(default_factory=list)

    @property
    def confirmed(self) -> bool:
        return self.change_rel < CONFIRM_REL

    def fastest_within(self, rel: float = WITHIN_REL, key: str = "max_err_rel") -> dict | None:
        """The row of the fastest setting whose error `key` (by default the largest of every
        reported quantity) is within `rel` of the reference: a swept setting, not the reference,
        its perturbed twin or its confirmation (a finer run, whose difference is the reference's
        own uncertainty, reported as such)."""
        ref = self.reference_outcome.status
        ok = [r for r in self.rows if r["role"] not in ("reference", "perturbed", "confirmation") and r["status"] == ref
              and not math.isnan(r[key]) and r[key] <= rel]
        return min(ok, key=lambda r: r["wall_time_s"]) if ok else None

def accuracy_columns(scenario, sphere_sweep: bool) -> list[str]:
    cols = ["role", "setting", "method", "substeps", "step_ms", "rtol", "atol", "tol"]
    cols += ["sphere_scale"] if sphere_sweep else []
    cols += ["status", "completed_s", "sim_time_s", "wall_time_s", "steps", "force_evaluations", "rejected_steps"]
    for p in grasp_names(scenario):
        cols += [f"{p}offset_x_mm", f"{p}offset_y_mm", f"{p}offset_z_mm", f"{p}offset_norm_mm",
                 f"{p}offset_err_mm", f"{p}offset_err_rel", f"{p}peak_force_N", f"{p}peak_force_err_rel"]
        if free_floating(scenario):
            cols += [f"{p}centroid_norm_mm", f"{p}centroid_err_mm", f"{p}centroid_err_rel"]
    return cols + ["max_err_rel", "within_1pct", "linear_drift_rel", "angular_drift_rel", "message"]


def accuracy_row(scenario, setting: Setting, role: str, o: Outcome, ref: Outcome) -> dict:
    dt = scenario.simulation.dt_s
    names, centroid = grasp_names(scenario), free_floating(scenario)
    row = {"role": role, "setting": setting.label(dt), "method": setting.method,
           "substeps": math.nan if setting.adaptive else setting.substeps,
           "step_ms": setting.step_s(dt) * 1e3, "rtol": setting.rtol or math.nan, "atol": setting.atol or math.nan,
           "tol": setting.tol or math.nan,
           "sphere_scale": setting.sphere_scale, "status": o.status, "completed_s": o.completed_s,
           "sim_time_s": o.sim_time_s, "wall_time_s": o.wall_time_s, "steps": o.steps,
           "force_evaluations": o.force_evaluations, "rejected_steps": o.rejected_steps,
           "linear_drift_rel": o.linear_drift_rel, "angular_drift_rel": o.angular_drift_rel,
           "message": o.message}
    for g, p in enumerate(names):
        off = o.offsets[g] if g < len(o.offsets) and o.offsets[g] is not None else np.full(3, math.nan)
        row.update({f"{p}offset_x_mm": off[0], f"{p}offset_y_mm": off[1], f"{p}offset_z_mm": off[2],
                    f"{p}offset_norm_mm": float(np.linalg.norm(off)),
                    f"{p}peak_force_N": o.peaks[g] if g < len(o.peaks) else math.nan})
        if centroid:
            c = o.centroids[g] if g < len(o.centroids) and o.centroids[g] is not None else np.full(3, math.nan)
            row[f"{p}centroid_norm_mm"] = float(np.linalg.norm(c))
    if not o.offsets:  # rejected or failed before it ran: nothing to compare
        o = dc_replace(o, offsets=[None] * len(names), peaks=[math.nan] * len(names),
                       centroids=[None] * len(names))
    row.update(errors(o, ref, names, centroid))
    row["within_1pct"] = (role not in ("reference", "perturbed") and o.status == ref.status
                          and not math.isnan(row["max_err_rel"]) and row["max_err_rel"] <= WITHIN_REL)
    return row


def perturbed(s, d_mm: float = PERTURBATION_MM):
    """`s` with every module started `d_mm` further along y_a."""
    return replace(s, **{k: {"initial_offset_mm": [m.initial_offset_mm[0], m.initial_offset_mm[1] + d_mm,
                                                   m.initial_offset_mm[2]]}
                         for k, m in modules_of(s).items()})


def accuracy_study(scenario, settings: list[Setting], reference: Setting, out_dir, *,
                   source: str = "<study>", progress: bool = False, wall_limit_s: float | None = None,
                   ensemble: int | None = None, seed: int = 0, workers: int | None = None,
                   confirmation_members: int | None = None):
    """Run the reference and its confirmation, then every setting; write accuracy.csv (a row per
    run as it ends) into `out_dir` (its page: `study_reports`, its figure: `study_figures`).

    With `ensemble` = N, every setting is instead an N-member ensemble from the same starts
    (`seed`), compared with the reference's ensemble (`accuracy_ensemble.accuracy_ensemble_study`,
    which returns an EnsembleAccuracyReport; `wall_limit_s` does not apply).

    Errors are against the reference run. If the confirmation ends with nothing to compare
    (diverged), the setting one refinement coarser is run next (role `coarser check`) and bounds
    the reference's uncertainty instead. A further run, the reference started PERTURBATION_MM
    off, measures how sensitive the reported quantities are to the start. The paper's setting
    (symplectic Euler at dt = 1 ms) and the scenario's own setting are marked in the `role`
    column. Ctrl-C stops the study and keeps the rows written (report.interrupted); every run is
    kept in runs.jsonl as it ends, and a study started again over `out_dir` runs only what it
    lacks (`runs.Runs`).
    """
    if ensemble is not None:
        from .accuracy_ensemble import accuracy_ensemble_study

        return accuracy_ensemble_study(scenario, settings, reference, out_dir, ensemble, default=setting_of(scenario),
                                       seed=seed, workers=workers,
                                       confirmation_members=confirmation_members, source=source,
                                       progress=progress)
    out = Path(out_dir)
    prepare(out, PAGE)
    runs = Runs(source, wall_limit_s, out / RUNS_FILE)
    dt = scenario.simulation.dt_s
    confirmation = reference.refined()
    sphere_sweep = any(s.sphere_scale != 1.0 for s in settings)
    default = setting_of(scenario)
    # the paper's dynamics step is its 1 ms record interval; a scenario recording at another
    # interval has no run with the paper's setting
    paper = Setting("symplectic_euler", 1) if math.isclose(dt, 1e-3) else None
    todo = [s for s in dict.fromkeys(settings) if s not in (reference, confirmation)]

    def role(s: Setting) -> str:
        return "paper" if s == paper else "default" if s == default else "sweep"

    with StudyRows(out / "accuracy.csv", accuracy_columns(scenario, sphere_sweep), len(todo) + 3, progress,
                   f"{scenario.name}: accuracy") as study:
        report = AccuracyReport(scenario.name, dt, reference, Outcome("interrupted", "not run"), confirmation,
                                None, math.nan, "", study.rows)
        warm_up(scenario, sorted({s.method for s in (*settings, reference)}))
        names, centroid = grasp_names(scenario), free_floating(scenario)

        def run(setting: Setting, role: str, s=scenario, label: str | None = None):
            """One run: its row written; its outcome and its largest error against the reference."""
            study.bar.set_postfix_str(label or setting.label(dt))
            o = runs(setting.apply(s))
            ref = o if role == "reference" else report.reference_outcome
            study.write(accuracy_row(scenario, setting, role, o, ref))
            study.bar.update(1)
            change = errors(o, ref, names, centroid)
            return o, change["max_err_rel"], worst(change)

        report.reference_outcome = run(reference, "reference")[0]
        report.confirmation_outcome, report.change_rel, report.change_what = run(confirmation, "confirmation")
        coarser = reference.coarsened()
        if math.isnan(report.change_rel) and report.reference_outcome.comparable and coarser is not None:
            # the refinement gave nothing to compare (it diverged): bound the reference from below
            report.coarser = coarser
            if coarser in todo:  # it runs now instead of among the sweep's
                todo.remove(coarser)
            else:
                study.bar.total += 1
            _, report.coarser_change_rel, report.coarser_change_what = run(coarser, "coarser check")
        off = f"{reference.label(dt)}, started {PERTURBATION_MM * 1e6:g} nm off"
        _, report.sensitivity_rel, report.sensitivity_what = run(reference, "perturbed", perturbed(scenario), off)
        for setting in todo:
            run(setting, role(setting))
    report.interrupted = study.interrupted
    report.files = [study.path]
    return report
