"""The stability study: stiff and extreme variants of a scenario, each with the predicted
stable step and its verdict: the run's outcome (seated / wedged / not captured / incomplete /
diverged), rejected at start, or a failure of the simulator."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from dataclasses import replace as dc_replace
from pathlib import Path

import numpy as np

from ..errors import SpotsimError
from ..files import prepare
from ..scenario import TOLERANCE_DEG, TOLERANCE_OFFSET_MM, modules_of, replace, to_dict
from ..status import (
    COMPARABLE,
    COMPLETED,
    EXCEPTION,
    NOT_CAPTURED,
    REJECTED,
    WALL_LIMIT,
)
from ..tables import ADAPTIVE
from .runs import (
    RUNS_FILE,
    Outcome,
    Runs,
    StudyRows,
    clearing_gap,
    step_scaled,
    warm_up,
    widened,
)

#: A stability case's wall-time budget, s: a hundred times Case I's run at its default step.
STABILITY_WALL_LIMIT_S = 300.0
#: The study's page (`study_reports`), removed as the study starts.
PAGE = "stability.md"

# ----------------------------------------------------------------------------- stability


@dataclass(frozen=True)
class Case:
    """A variant of a scenario: its name, group (baseline, stiff, extreme), what it changes, and
    the changes as a function of the scenario (the keyword arguments of scenario.replace)."""

    name: str
    group: str
    what: str
    changes: object  # scenario -> dict
    detail: object = None  # the changed scenario -> a value to add to `what` (a computed load)
    misalignment: bool = False  # rejected at start, it is run again with a start gap that clears it

    def apply(self, s):
        return replace(s, **self.changes(s))

    def describe(self, changed) -> str:
        return self.what if self.detail is None else f"{self.what}: {self.detail(changed)}"


def _closing(speed_m_s: float):
    """A closing speed; a slower one gets the time its longer approach and settling take (the
    scenario's times scaled by the speed ratio)."""
    def changes(s):
        slower = s.end_effector.closing_speed_m_s / speed_m_s
        out = {"end_effector": {"closing_speed_m_s": speed_m_s}}
        if slower > 1:
            out["simulation"] = {"duration_s": s.simulation.duration_s * slower}
            out["completion"] = {"phase_timeout_s": s.completion.phase_timeout_s * slower}
        return out
    return changes


def _modules(s, **fields) -> dict:
    """The same changes to every module section of `s`."""
    return {section: dict(fields) for section in modules_of(s)}


def _misaligned(offset=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0)):
    """Every module started centred but for one misalignment (mm, deg)."""
    return lambda s: _modules(s, initial_offset_mm=list(offset), initial_rpy_deg=list(rpy))


def _scaled(section: str, **factors):
    return lambda s: {section: {k: getattr(getattr(s, section), k) * f for k, f in factors.items()}}


def _lighter(factor: float):
    def changes(s):
        out = {}
        for section, m in modules_of(s).items():
            inertia = {k: v * factor for k, v in to_dict(m.inertia_kg_m2).items()}
            out[section] = {"mass_kg": m.mass_kg * factor, "inertia_kg_m2": inertia}
        return out
    return changes


def load_limit(model) -> float:
    """The largest grasp load, N, at which the scenario's dynamics step is still inside its
    integrator's predicted stability region (stability.predict_step; bisection in log load)."""
    import dataclasses

    from ..sim.stability import predict_step

    s = model.scenario

    def stable(load):
        m = dataclasses.replace(model, scenario=replace(s, end_effector={"grasp_load_N": load}))
        return predict_step(m).stable

    lo, hi = 1e-3, 1e7
    if not stable(lo):
        return lo
    if stable(hi):
        return hi
    for _ in range(50):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


def _at_load_limit(s) -> dict:
    from ..assemble.model import build_model

    return {"end_effector": {"grasp_load_N": load_limit(build_model(s))}}


def stability_cases() -> list[Case]:
    """The stiff and the extreme cases of the issue, in the order the study runs them."""
    off, deg = TOLERANCE_OFFSET_MM, TOLERANCE_DEG
    E = ("youngs_modulus_finger_Pa", "youngs_modulus_groove_Pa")
    r = ("sphere_radius_finger_mm", "sphere_radius_groove_mm")
    cases = [
        Case("baseline", "baseline", "the scenario as given", lambda s: {}),
        Case("E x10", "stiff", "both Young's moduli x10", _scaled("contact", **{k: 10.0 for k in E})),
        Case("E x100", "stiff", "both Young's moduli x100", _scaled("contact", **{k: 100.0 for k in E})),
        Case("spheres x0.5", "stiff", "both sphere radii x0.5", _scaled("contact", **{k: 0.5 for k in r})),
        Case("restitution 0.3", "stiff", "contact.restitution = 0.3", lambda s: {"contact": {"restitution": 0.3}}),
        Case("k_b x10", "stiff", "bristle stiffness x10", _scaled("friction", bristle_stiffness_N_m=10.0)),
        Case("module /100", "stiff", "module mass and inertia x0.01", _lighter(0.01)),
    ]
    for sign in (1, -1):
        for axis, i in (("x_a", 0), ("y_a", 1)):
            o = [0.0, 0.0, 0.0]
            o[i] = sign * off
            cases.append(Case(f"{axis} {sign * off:+g} mm", "extreme", f"offset {o} mm, at the claimed tolerance",
                              _misaligned(offset=o), misalignment=True))
    for sign in (1, -1):
        for i, name in enumerate(("roll", "pitch", "yaw")):
            a = [0.0, 0.0, 0.0]
            a[i] = sign * deg[name]
            cases.append(Case(f"{name} {sign * deg[name]:+g} deg", "extreme",
                              f"rpy {a} deg, at the claimed tolerance", _misaligned(rpy=a), misalignment=True))
    past = [("x_a", [12.0, 0.0, 0.0], None), ("y_a", [0.0, 12.0, 0.0], None), ("roll", None, [35.0, 0.0, 0.0]),
            ("pitch", None, [0.0, 70.0, 0.0]), ("yaw", None, [0.0, 0.0, 35.0])]
    for name, o, a in past:
        value = f"{o[o.index(max(o))]:+g} mm" if o else f"{max(a):+g} deg"
        what = f"{'offset' if o else 'rpy'} {o or a} {'mm' if o else 'deg'}, past the claimed tolerance"
        cases.append(Case(f"{name} {value}", "extreme", what, _misaligned(offset=o or (0, 0, 0), rpy=a or (0, 0, 0)),
                          misalignment=True))
    def load(s):
        return f"{s.end_effector.grasp_load_N:.4g} N"

    cases += [
        Case("closing 5 mm/s", "extreme", "closing speed 5 mm/s (duration and phase time-out x speed ratio)",
             _closing(0.005)),
        Case("closing 50 mm/s", "extreme", "closing speed 50 mm/s", _closing(0.05)),
        Case("load x10", "extreme", "grasp load x10",
             lambda s: {"end_effector": {"grasp_load_N": 10 * s.end_effector.grasp_load_N}}, load),
        Case("load at limit", "extreme", "grasp load at the largest the step is predicted stable for",
             _at_load_limit, load),
    ]
    return cases


#: The suite's cases: one of each kind of verdict on Case I, each short.
QUICK_CASES = ("baseline", "E x100", "module /100", "y_a +10 mm", "closing 50 mm/s")
#: Long enough for Case I to complete (1.03 s, 1.41 s from a 12 mm gap), short enough for the suite.
QUICK_DURATION_S = 1.5


def _key(name: str) -> str:
    return name.replace(" ", "").lower()


def select_cases(names: list[str]) -> list[Case]:
    """The cases named (spaces and case ignored: `Ex100`, `y_a+10mm`) or of the groups named
    (`stiff`, `extreme`, `baseline`), in the study's order; ValueError lists the valid names."""
    cases = stability_cases()
    wanted = {_key(n) for n in names}
    known = {_key(c.name) for c in cases} | {c.group for c in cases}
    unknown = sorted(wanted - known)
    if unknown:
        raise ValueError(f"unknown case(s) {', '.join(unknown)}; valid: groups stiff, extreme, baseline, or "
                         f"{', '.join(c.name for c in cases)}")
    return [c for c in cases if _key(c.name) in wanted or c.group in wanted]


def verdict(o: Outcome) -> str:
    """The run's outcome (`status.run_outcome`: seated, wedged, not captured, incomplete,
    diverged), or rejected at start, or no verdict (its wall-time budget spent), or a failure
    of the simulator that the study exists to catch (an exception, a silent NaN)."""
    if o.status in COMPARABLE and not o.finite:
        return "FAILED: silent NaN"
    if o.outcome:
        return o.outcome
    return {REJECTED: "rejected at start", WALL_LIMIT: "no verdict: wall limit",
            EXCEPTION: "FAILED: exception"}.get(o.status, o.status)


STABILITY_COLUMNS = ["case", "group", "change", "dynamics_step_ms", "predicted_stable_step_ms", "omega_h",
                     "damping_h", "predicted_stable", "verdict", "prediction_held", "status", "completed_s",
                     "residual_offset_mm", "final_offset_mm", "peak_force_N", "sim_time_s", "wall_time_s",
                     "finite", "message", "finer_verdict", "finer_message", "gradient_verdict", "gradient_message"]
#: A diverged case runs again this many times finer (fixed step; dopri5: rtol / this): if it
#: still diverges, the cause is not the step.
FINER = 4


def stability_row(case: Case, o: Outcome, changed=None, fine: Outcome | None = None,
                  gradient: Outcome | None = None) -> dict:
    """A stability CSV row: the case, its prediction, verdict and outcome, and, when it
    diverged ("not run" otherwise), the verdicts of the same case FINER times finer (`fine`)
    and with the energy-consistent pair law (`gradient`)."""
    p = o.prediction
    v = verdict(o)
    if p is None or o.status not in (*COMPARABLE, "diverged"):
        held = "n/a"
    elif p.integrator in ADAPTIVE:
        held = "n/a (adaptive step)"  # the prediction bounds a fixed step; an adaptive one finds its own
    elif p.stable and o.status == "diverged" and fine is not None and fine.status == "diverged":
        held = "yes (not the step's divergence)"  # the step was not the cause: nothing to predict
    else:
        held = "yes" if p.stable == (o.status != "diverged") else "no"
    finals = [float(np.linalg.norm(x)) for x in o.offsets if x is not None]
    return {"case": case.name, "group": case.group,
            "change": case.what if changed is None else case.describe(changed),
            "dynamics_step_ms": math.nan if p is None else p.step_s * 1e3,
            "predicted_stable_step_ms": math.nan if p is None else p.stable_step_s * 1e3,
            "omega_h": math.nan if p is None else p.omega_h,
            "damping_h": math.nan if p is None else p.damping_rate_1_s * p.step_s,
            "predicted_stable": "n/a" if p is None else ("yes" if p.stable else "no"),
            "verdict": v, "prediction_held": held, "status": o.status, "completed_s": o.completed_s,
            "residual_offset_mm": max(finals) if o.status in (COMPLETED, NOT_CAPTURED) else math.nan,
            "final_offset_mm": max(finals, default=math.nan), "peak_force_N": max(o.peaks, default=math.nan),
            "sim_time_s": o.sim_time_s, "wall_time_s": o.wall_time_s,
            "finite": "n/a" if o.status not in COMPARABLE else ("yes" if o.finite else "no"),
            "message": o.message, "finer_verdict": "not run" if fine is None else verdict(fine),
            "finer_message": "not run" if fine is None else fine.message,
            "gradient_verdict": "not run" if gradient is None else verdict(gradient),
            "gradient_message": "not run" if gradient is None else gradient.message}


@dataclass
class StabilityReport:
    scenario: str
    rows: list[dict]
    interrupted: bool = False
    files: list[Path] = field(default_factory=list)

    @property
    def failures(self) -> list[dict]:
        """Cases that ended in what the simulator must never do: an exception or a silent NaN."""
        return [r for r in self.rows if r["verdict"].startswith("FAILED")]


def checked_row(case: Case, o: Outcome, s, runs: Runs) -> dict:
    """The row of a case's run. A diverged one runs again FINER times finer (`step_scaled`) and,
    under the paper's pair law, with the energy-consistent one (`contact.normal_direction:
    gradient`): the paper's law gains energy on strongly tilted faces, which the run's energy
    check stops as diverged."""
    diverged = o.status == "diverged"
    fine = runs(step_scaled(s, 1 / FINER)) if diverged else None
    gradient = (runs(replace(s, contact={"normal_direction": "gradient"}))
                if diverged and s.contact.normal_direction != "gradient" else None)
    return stability_row(case, o, s, fine, gradient)


def stability_study(scenario, cases: list[Case], out_dir, *, source: str = "<study>", progress: bool = False,
                    wall_limit_s: float | None = STABILITY_WALL_LIMIT_S) -> StabilityReport:
    """Run every case of `scenario`; write stability.csv (a row per case as it ends)
    into `out_dir` (its page: `study_reports`). A misaligned start rejected for interpenetrating is run once
    more with the start gap that clears it (a second row). A diverged case runs again FINER
    times finer (`finer_verdict`): one that still diverges does not diverge for its step.
    Ctrl-C stops the study and keeps the rows written; every run is kept in runs.jsonl as it
    ends, and a study started again over `out_dir` runs only what it lacks (`runs.Runs`)."""
    out = Path(out_dir)
    prepare(out, PAGE)
    runs = Runs(source, wall_limit_s, out / RUNS_FILE)
    with StudyRows(out / "stability.csv", STABILITY_COLUMNS, len(cases), progress,
                   f"{scenario.name}: stability") as study:
        report = StabilityReport(scenario.name, study.rows)
        warm_up(scenario, [scenario.simulation.integrator.method])
        for case in cases:
            study.bar.set_postfix_str(case.name)
            try:
                s = case.apply(scenario)
            except SpotsimError as e:
                s, o = None, Outcome(REJECTED, str(e).replace("\n", "; "))
            else:
                o = runs(s)
            study.write(checked_row(case, o, s, runs))
            gap = clearing_gap(s) if case.misalignment and o.status == REJECTED and s is not None else None
            if gap is not None:  # the same start, with fingers opened wide enough to clear it
                wide = dc_replace(case, name=f"{case.name}, gap {gap:g} mm",
                                  what=f"{case.what}; start gap {s.end_effector.start_gap_mm:g} -> {gap:g} mm")
                s = widened(s, gap)
                o = runs(s)
                study.write(checked_row(wide, o, s, runs))
            study.bar.update(1)
    report.interrupted = study.interrupted
    report.files = [study.path]
    return report
