"""Studies over many runs of one scenario: accuracy against run time, and numerical stability.

- `accuracy_study`: a reference run at a tight setting, confirmed by its next refinement (no
  reported quantity may change by more than CONFIRM_REL), then a sweep of integrator x step
  (x tolerance for dopri5, x sphere radius if asked). Each setting reports its error against
  the reference in the residual offset, the peak contact force and (dual arm) the robot's
  centroid displacement, its momentum drift, its wall time and its status.
- `stability_study`: stiff and extreme variants of a scenario. Each reports the predicted
  stable step, the verdict (converged / not captured / diverged (detected) / rejected at
  start) and the run's outcome.

Both write their CSV a row at a time as runs finish, so that Ctrl-C keeps what was computed,
then a markdown table (and the accuracy study a work-precision plot). A run may be given a
wall-time budget (the stability study's default): it then runs in a child process, killed
when the budget is spent.
"""

from __future__ import annotations

import csv
import math
import multiprocessing
import textwrap
import traceback
from dataclasses import dataclass, field
from dataclasses import replace as dc_replace
from pathlib import Path

import numpy as np

from .errors import SpotsimError
from .scenario import TOLERANCE_DEG, TOLERANCE_OFFSET_MM, modules_of, replace, to_dict

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
#: A stability case's wall-time budget, s: a hundred times Case I's run at its default step.
STABILITY_WALL_LIMIT_S = 300.0

#: What a run ended as, besides the simulator's statuses.
WALL_LIMIT, REJECTED, EXCEPTION = "wall limit", "rejected", "exception"
#: Statuses whose record may be compared with the reference's.
COMPARABLE = ("completed", "incomplete")


# ----------------------------------------------------------------------------- settings


@dataclass(frozen=True)
class Setting:
    """One integrator setting of a sweep.

    method: symplectic_euler, rk4 or dopri5. substeps: dynamics steps per recorded step
    (fixed-step methods; dopri5 keeps the scenario's, its first trial step). rtol: dopri5's
    relative tolerance (atol = ATOL_PER_RTOL rtol). sphere_scale: both sphere radii times this.
    """

    method: str
    substeps: int = 0
    rtol: float | None = None
    sphere_scale: float = 1.0

    @property
    def adaptive(self) -> bool:
        return self.method == "dopri5"

    @property
    def atol(self) -> float | None:
        return None if self.rtol is None else self.rtol * ATOL_PER_RTOL

    def step_s(self, dt_s: float) -> float:
        """The dynamics step, s (nan for the adaptive method)."""
        return math.nan if self.adaptive else dt_s / self.substeps

    def label(self, dt_s: float) -> str:
        text = (f"dopri5 rtol {self.rtol:g}" if self.adaptive else
                f"{self.method} h {self.step_s(dt_s) * 1e3:g} ms")
        return text + (f", spheres x{self.sphere_scale:g}" if self.sphere_scale != 1.0 else "")

    def refined(self) -> Setting:
        """The next refinement: a tenth of the tolerance, or half the step."""
        return dc_replace(self, rtol=self.rtol / 10) if self.adaptive else dc_replace(self, substeps=2 * self.substeps)

    def coarsened(self) -> Setting | None:
        """The setting one refinement coarser (None below one substep)."""
        if self.adaptive:
            return dc_replace(self, rtol=self.rtol * 10) if self.rtol < 0.1 else None
        return dc_replace(self, substeps=self.substeps // 2) if self.substeps % 2 == 0 else None

    def apply(self, s):
        """The scenario `s` run at this setting (validated again)."""
        integrator = {**to_dict(s.simulation.integrator), "method": self.method}
        simulation = {"integrator": integrator}
        if self.adaptive:
            integrator.update(rtol=self.rtol, atol=self.atol)
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
    return Setting(i.method, s.simulation.substeps)


def parse_setting(text: str) -> Setting:
    """`METHOD:VALUE`: `symplectic_euler:80`, `rk4:40` (substeps) or `dopri5:1e-7` (rtol)."""
    method, _, value = text.partition(":")
    if method not in ("symplectic_euler", "rk4", "dopri5") or not value:
        raise ValueError(f"{text}: must read METHOD:VALUE with METHOD one of symplectic_euler, rk4, "
                         f"dopri5 and VALUE its substeps (fixed step) or rtol (dopri5), e.g. dopri5:1e-7")
    try:
        if method == "dopri5":
            rtol = float(value)
            if not 0 < rtol < 1:
                raise ValueError
            return Setting(method, rtol=rtol)
        substeps = int(value)
        if substeps < 1:
            raise ValueError
        return Setting(method, substeps)
    except ValueError:
        rule = "rtol must be a number in (0, 1)" if method == "dopri5" else "substeps must be an integer >= 1"
        raise ValueError(f"{text}: {rule}") from None


@dataclass(frozen=True)
class Grid:
    """A sweep: substeps per fixed-step method, dopri5's tolerances, the sphere scales, the reference."""

    substeps: dict[str, tuple[int, ...]]
    rtols: tuple[float, ...]
    reference: Setting
    sphere_scales: tuple[float, ...] = (1.0,)
    duration_s: float | None = None  # None: the scenario's

    def settings(self) -> list[Setting]:
        out = []
        for scale in self.sphere_scales:
            for method, substeps in self.substeps.items():
                out += [Setting(method, n, sphere_scale=scale) for n in substeps]
            out += [Setting("dopri5", rtol=r, sphere_scale=scale) for r in self.rtols]
        return out


#: The grids. The references are fine fixed steps of symplectic Euler: on Case I, 12.5 us takes
#: ~5 s and its confirmation at 6.25 us ~10 s, where dopri5 takes ~200 s at rtol 1e-6 and did
#: not finish in 19 min at 1e-7 (every contact onset and stick-slip switch is a kink its error
#: control steps through). Costs on Case I in the README.
GRIDS = {
    # the suite's: Case I's first 120 ms of contact, in which the paper's setting diverges (0.49 s)
    "quick": Grid({"symplectic_euler": (1, 5, 10), "rk4": (10,)}, (1e-4,), Setting("symplectic_euler", 40),
                  duration_s=0.55),
    "reduced": Grid({"symplectic_euler": (1, 2, 5, 10, 20), "rk4": (10, 20)}, (1e-4, 1e-5),
                    Setting("symplectic_euler", 40)),
    "default": Grid({"symplectic_euler": (1, 2, 5, 10, 20, 40), "rk4": (5, 10, 20, 40)},
                    (1e-3, 1e-4, 1e-5, 1e-6), Setting("symplectic_euler", 80)),
    "full": Grid({"symplectic_euler": (1, 2, 5, 10, 20, 40, 80), "rk4": (2, 5, 10, 20, 40, 80)},
                 (1e-3, 1e-4, 1e-5, 1e-6), Setting("symplectic_euler", 160), sphere_scales=(1.0, 0.75)),
}


# ----------------------------------------------------------------------------- one run


@dataclass
class Outcome:
    """What a study keeps of one run. Per grasp: the offset of O_b from O_a at the end (the
    residual offset of a completed grasp, mm), the peak contact force norm (N) and, on a
    free-floating robot, the centroid displacement (mm); None where the grasp never ran."""

    status: str
    message: str
    wall_time_s: float = math.nan
    sim_time_s: float = math.nan
    completed_s: float = math.nan
    steps: float = math.nan
    force_evaluations: float = math.nan
    rejected_steps: float = math.nan
    offsets: list = field(default_factory=list)
    peaks: list = field(default_factory=list)
    centroids: list = field(default_factory=list)
    linear_drift_rel: float = math.nan
    angular_drift_rel: float = math.nan
    finite: bool = True  # every recorded number finite
    prediction: object = None  # stability.StepPrediction of the run's model

    @property
    def comparable(self) -> bool:
        return self.status in COMPARABLE


def run_once(scenario, source: str = "<study>", wall_limit_s: float | None = None) -> Outcome:
    """Build, check and simulate `scenario`; never raises but on the user's Ctrl-C.

    A scenario the model or the start check rejects is status `rejected`; any exception out
    of `simulate` is status `exception` (it must never raise: a bug the study reports).

    With `wall_limit_s`, the run goes on in a forked child process, which is killed once the
    budget is spent (status `wall limit`; what it recorded is lost with it). A signal raised
    into the run instead would land inside numba's callbacks, which turn it into a SystemError;
    and a child also survives what the simulator must never do, a crash in compiled code.
    """
    if not wall_limit_s:
        return _run_once(scenario, source)
    ctx = multiprocessing.get_context("fork")  # the child inherits the loaded kernels
    receive, send = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_child, args=(send, scenario, source), daemon=True)
    child.start()
    send.close()
    try:
        if receive.poll(wall_limit_s):
            o = receive.recv()
        else:
            o = Outcome(WALL_LIMIT, f"wall limit of {wall_limit_s:g} s reached: the run was stopped")
    except EOFError:  # the child died without a word
        child.join()
        o = Outcome(EXCEPTION, f"the run's process died (exit code {child.exitcode})")
    finally:
        if child.is_alive():
            child.kill()
        child.join()
        receive.close()
    if o.status == "interrupted":
        raise KeyboardInterrupt  # the user's Ctrl-C reached the child too: the study stops
    if o.prediction is None and o.status in (WALL_LIMIT, EXCEPTION):
        o.prediction = _prediction(scenario, source)
    return o


def _child(send, scenario, source) -> None:
    try:
        o = _run_once(scenario, source)
    except KeyboardInterrupt:
        o = Outcome("interrupted", "interrupted by the user")
    send.send(o)
    send.close()


def _prediction(scenario, source):
    """stability.predict_step of the scenario's model, or None if it cannot be built."""
    from .model import build_model
    from .stability import predict_step

    try:
        return predict_step(build_model(scenario, source))
    except SpotsimError:
        return None


def _caused_by_ctrl_c(e: BaseException) -> bool:
    """Whether a KeyboardInterrupt lies in `e`'s chain of causes: Ctrl-C landing inside one of
    numba's callbacks comes out as a SystemError."""
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False


def _run_once(scenario, source: str) -> Outcome:
    from .model import build_model
    from .run import check_start, simulate
    from .stability import predict_step

    prediction = None
    try:
        model = build_model(scenario, source)
        prediction = predict_step(model)
        check_start(model, source)
    except SpotsimError as e:  # the scenario's own problem, found before anything ran
        return Outcome(REJECTED, str(e).replace("\n", "; "), prediction=prediction)
    try:
        result = simulate(scenario, model=model, source=source)
    except Exception as e:  # simulate must never raise: the study reports it rather than dies of it
        if _caused_by_ctrl_c(e):
            raise KeyboardInterrupt from e
        where = traceback.extract_tb(e.__traceback__)[-1]
        return Outcome(EXCEPTION, f"{type(e).__name__} raised by simulate: {e} "
                                  f"({Path(where.filename).name}:{where.lineno})", prediction=prediction)
    s = result.summary
    if s["status"] == "interrupted":
        raise KeyboardInterrupt  # the user's Ctrl-C: the study stops
    integrator = s["integrator"]
    done = [g["completed_s"] for g in s["grasps"]]
    return Outcome(
        s["status"], s["message"], s["wall_time_s"], s["sim_time_s"],
        done[-1] if s["status"] == "completed" else math.nan,
        s["steps"], integrator.get("force_evaluations", s["steps"]), integrator.get("rejected_steps", 0),
        [None if g["final_offset_mm"] is None else np.array(g["final_offset_mm"]) for g in s["grasps"]],
        [g["peak_force_norm_N"] for g in s["grasps"]],
        [np.array(g["robot_centroid_displacement_mm"]) if "robot_centroid_displacement_mm" in g else None
         for g in s["grasps"]],
        s["momentum"]["linear_drift_rel"], s["momentum"]["angular_drift_rel"],
        all(bool(np.all(np.isfinite(a))) for a in result.timeseries.values()
            if np.issubdtype(np.asarray(a).dtype, np.floating)),
        prediction)


# ----------------------------------------------------------------------------- comparing


def grasp_names(scenario) -> list[str]:
    """Column prefixes of the grasps: none for one grasp, `g1_`, `g2_`... for several."""
    n = len(modules_of(scenario))
    return [""] if n == 1 else [f"g{i + 1}_" for i in range(n)]


def free_floating(scenario) -> bool:
    return scenario.kind == "dual_arm"


def errors(o: Outcome, ref: Outcome, names: list[str], centroid: bool) -> dict[str, float]:
    """The errors of `o` against `ref`, per grasp: offset (norm of the vector difference, mm,
    and relative to the reference's norm), peak force (relative) and centroid displacement
    (mm, relative); and `max_err_rel`, the largest relative one. nan where either run has
    nothing comparable (diverged, rejected, a grasp that never ran)."""
    out = {}
    ok = o.comparable and ref.comparable
    for g, p in enumerate(names):
        def diff(a, b):
            if not ok or a is None or b is None:
                return math.nan, math.nan
            d = float(np.linalg.norm(np.asarray(a) - np.asarray(b)))
            return d, d / max(float(np.linalg.norm(b)), 1e-300)

        out[f"{p}offset_err_mm"], out[f"{p}offset_err_rel"] = diff(o.offsets[g], ref.offsets[g])
        out[f"{p}peak_force_err_rel"] = diff(o.peaks[g], ref.peaks[g])[1]
        if centroid:
            out[f"{p}centroid_err_mm"], out[f"{p}centroid_err_rel"] = diff(o.centroids[g], ref.centroids[g])
    rel = [v for k, v in out.items() if k.endswith("_rel")]
    out["max_err_rel"] = math.nan if any(math.isnan(v) for v in rel) else max(rel)
    return out


def worst(errs: dict[str, float]) -> str:
    """The name of the largest relative error."""
    rel = {k: v for k, v in errs.items() if k.endswith("_rel") and k != "max_err_rel"}
    return max(rel, key=lambda k: -1.0 if math.isnan(rel[k]) else rel[k])


# ----------------------------------------------------------------------------- output


def fmt(x) -> str:
    """A CSV cell: numbers to 6 significant digits, nan spelt out."""
    if isinstance(x, (bool, np.bool_)):
        return "yes" if x else "no"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    if isinstance(x, (float, np.floating)):
        return "nan" if math.isnan(x) else f"{x:.6g}"
    return str(x)


class RowWriter:
    """A CSV written and flushed a row at a time."""

    def __init__(self, path: Path, columns: list[str]):
        self.path, self.columns = path, columns
        self._file = open(path, "w", newline="")  # noqa: SIM115 - open across rows, closed by close()
        self._csv = csv.writer(self._file)
        self._csv.writerow(columns)
        self._file.flush()
        self.rows: list[dict] = []

    def write(self, row: dict) -> None:
        missing = [c for c in self.columns if c not in row]
        if missing:
            raise KeyError(f"row lacks {missing}")
        self._csv.writerow([fmt(row[c]) for c in self.columns])
        self._file.flush()
        self.rows.append(row)

    def close(self) -> None:
        self._file.close()


def markdown_table(header: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
    lines += ["| " + " | ".join(str(c).replace("|", "\\|") for c in r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def _g(x, digits=3) -> str:
    """A markdown cell: `digits` significant digits, a dash for nan."""
    if isinstance(x, (float, np.floating)) and math.isnan(x):
        return "–"
    return f"{x:.{digits}g}"


def _pct(x) -> str:
    if isinstance(x, (float, np.floating)) and math.isnan(x):
        return "–"
    return f"{100 * x:.3g} %"


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

    def confirmation_text(self) -> str:
        r, c = self.reference.label(self.dt_s), self.confirmation.label(self.dt_s)
        if not self.reference_outcome.comparable:
            return (f"reference not usable: {r} ended {self.reference_outcome.status} "
                    f"({self.reference_outcome.message}); no errors computed")
        if self.confirmation_outcome is None:
            return f"reference not confirmed: the study stopped before its confirmation ({c}) ran"
        if math.isnan(self.change_rel):
            text = (f"reference not confirmed: its refinement {c} ended {self.confirmation_outcome.status} "
                    f"({self.confirmation_outcome.message})")
            if self.coarser is not None and not math.isnan(self.coarser_change_rel):
                text += (f"; the setting one refinement coarser, {self.coarser.label(self.dt_s)}, differs from "
                         f"it by up to {100 * self.coarser_change_rel:.3g} % ({self.coarser_change_what})")
            return text
        verdict = "confirmed" if self.confirmed else "not confirmed"
        return (f"reference {verdict}: refining {r} to {c} changes the reported quantities by at most "
                f"{100 * self.change_rel:.3g} % ({self.change_what}; the bound is {100 * CONFIRM_REL:g} %)")

    def sensitivity_text(self) -> str:
        if math.isnan(self.sensitivity_rel):
            return "sensitivity not measured"
        return (f"sensitivity: starting the reference {PERTURBATION_MM * 1e6:g} nm off in y changes the reported "
                f"quantities by at most {100 * self.sensitivity_rel:.3g} % ({self.sensitivity_what}); no setting "
                f"can be expected to agree with the reference more closely than that")

    def fastest_within(self, rel: float = WITHIN_REL, key: str = "max_err_rel") -> dict | None:
        """The row of the fastest setting whose error `key` (by default the largest of every
        reported quantity) is within `rel` of the reference: a swept setting, not the reference,
        its perturbed twin or its confirmation (a finer run, whose difference is the reference's
        own uncertainty, reported as such)."""
        ref = self.reference_outcome.status
        ok = [r for r in self.rows if r["role"] not in ("reference", "perturbed", "confirmation") and r["status"] == ref
              and not math.isnan(r[key]) and r[key] <= rel]
        return min(ok, key=lambda r: r["wall_time_s"]) if ok else None

    def ladder_table(self) -> str:
        """The fastest setting within 1 % and each of LADDER_REL, on every quantity at once and
        on each alone, next to how much refining and perturbing the reference changes each: a
        markdown table."""
        keys = ["max_err_rel"] + [k for k in self.rows[0] if k.endswith("_err_rel") and k != "max_err_rel"]
        bounds = (WITHIN_REL, *LADDER_REL)
        by_role = {r["role"]: r for r in self.rows}
        checks = {"confirmation": "refining the reference changes it by",
                  "coarser check": "the coarser check differs by",
                  "perturbed": f"a {PERTURBATION_MM * 1e6:g} nm start changes it by"}
        checks = {role: text for role, text in checks.items() if role in by_role}
        rows = []
        for key in keys:
            cells = [_pct(by_role[role][key]) for role in checks]
            for rel in bounds:
                best = self.fastest_within(rel, key)
                cells.append("none" if best is None else
                             f"{best['setting']} ({best['wall_time_s']:.3g} s, {100 * best[key]:.2g} %)")
            name = "every quantity" if key == "max_err_rel" else key.removesuffix("_err_rel").replace("_", " ")
            rows.append([name, *cells])
        return markdown_table(["error of", *checks.values(), *(f"fastest within {100 * b:g} %" for b in bounds)],
                              rows)

    def fastest_text(self) -> str:
        best = self.fastest_within()
        if not self.reference_outcome.comparable:
            return "fastest setting within 1 % of the reference: none (no usable reference)"
        u = self.uncertainty_rel
        resolution = "" if u <= WITHIN_REL else (
            f"; the reference itself is uncertain by {100 * u:.3g} %, more than 1 %, so this is within 1 % "
            f"of the reference, not of the converged answer" if not math.isnan(u) else
            "; how far the reference is from the converged answer is not known")
        if best is None:
            return f"fastest setting within 1 % of the reference: none of the settings swept{resolution}"
        return (f"fastest setting within 1 % of the reference: {best['setting']} ({best['role']}), "
                f"{best['wall_time_s']:.3g} s of wall time, largest error {100 * best['max_err_rel']:.3g} %"
                f"{resolution}")


def accuracy_columns(scenario, sphere_sweep: bool) -> list[str]:
    cols = ["role", "setting", "method", "substeps", "step_ms", "rtol", "atol"]
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


def warm_up(scenario, methods, duration_s: float = 0.5) -> None:
    """Run each method briefly (dopri5 at a loose tolerance), so that no timed run pays for
    loading its compiled kernels."""
    for method in methods:
        integrator = {**to_dict(scenario.simulation.integrator), "method": method}
        if method == "dopri5":
            integrator.update(rtol=1e-3, atol=1e-6)
        run_once(replace(scenario, simulation={"duration_s": min(duration_s, scenario.simulation.duration_s),
                                               "integrator": integrator}))


def accuracy_study(scenario, settings: list[Setting], reference: Setting, out_dir, *,
                   source: str = "<study>", progress: bool = False, wall_limit_s: float | None = None,
                   plot: bool = True) -> AccuracyReport:
    """Run the reference and its confirmation, then every setting; write accuracy.csv (a row per
    run as it ends), accuracy.md and work_precision.png into `out_dir`.

    Errors are against the reference run. If the confirmation ends with nothing to compare
    (diverged), the setting one refinement coarser is run next (role `coarser check`) and bounds
    the reference's uncertainty instead. A further run, the reference started PERTURBATION_MM
    off, measures how sensitive the reported quantities are to the start. The paper's setting
    (symplectic Euler at dt = 1 ms) and the scenario's own setting are marked in the `role`
    column. Ctrl-C stops the study and keeps the rows written (report.interrupted).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    dt = scenario.simulation.dt_s
    confirmation = reference.refined()
    sphere_sweep = any(s.sphere_scale != 1.0 for s in settings)
    writer = RowWriter(out / "accuracy.csv", accuracy_columns(scenario, sphere_sweep))
    default = setting_of(scenario)
    # the paper's dynamics step is its 1 ms record interval; a scenario recording at another
    # interval has no run with the paper's setting
    paper = Setting("symplectic_euler", 1) if math.isclose(dt, 1e-3) else None
    todo = [s for s in dict.fromkeys(settings) if s not in (reference, confirmation)]
    report = AccuracyReport(scenario.name, dt, reference, Outcome("interrupted", "not run"), confirmation,
                            None, math.nan, "", writer.rows)
    from .run import progress_bar

    bar = progress_bar(len(todo) + 3, progress, f"{scenario.name}: accuracy", "run")

    def role(s: Setting) -> str:
        return "paper" if s == paper else "default" if s == default else "sweep"

    try:
        warm_up(scenario, sorted({s.method for s in (*settings, reference)}))
        for setting, name in ((reference, "reference"), (confirmation, "confirmation")):
            bar.set_postfix_str(setting.label(dt))
            o = run_once(setting.apply(scenario), source, wall_limit_s)
            if name == "reference":
                report.reference_outcome = o
            else:
                report.confirmation_outcome = o
            row = accuracy_row(scenario, setting, name, o, report.reference_outcome)
            writer.write(row)
            bar.update(1)
        names, centroid = grasp_names(scenario), free_floating(scenario)
        change = errors(report.confirmation_outcome, report.reference_outcome, names, centroid)
        report.change_rel, report.change_what = change["max_err_rel"], worst(change)
        coarser = reference.coarsened()
        if math.isnan(report.change_rel) and report.reference_outcome.comparable and coarser is not None:
            # the refinement gave nothing to compare (it diverged): bound the reference from below
            bar.set_postfix_str(coarser.label(dt))
            o = run_once(coarser.apply(scenario), source, wall_limit_s)
            writer.write(accuracy_row(scenario, coarser, "coarser check", o, report.reference_outcome))
            change = errors(o, report.reference_outcome, names, centroid)
            report.coarser, report.coarser_change_rel, report.coarser_change_what = coarser, change["max_err_rel"], \
                worst(change)
            todo = [s for s in todo if s != coarser]
        bar.set_postfix_str(f"{reference.label(dt)}, started {PERTURBATION_MM * 1e6:g} nm off")
        o = run_once(reference.apply(perturbed(scenario)), source, wall_limit_s)
        writer.write(accuracy_row(scenario, reference, "perturbed", o, report.reference_outcome))
        change = errors(o, report.reference_outcome, names, centroid)
        report.sensitivity_rel, report.sensitivity_what = change["max_err_rel"], worst(change)
        bar.update(1)
        for setting in todo:
            bar.set_postfix_str(setting.label(dt))
            o = run_once(setting.apply(scenario), source, wall_limit_s)
            writer.write(accuracy_row(scenario, setting, role(setting), o, report.reference_outcome))
            bar.update(1)
    except KeyboardInterrupt:
        report.interrupted = True
    finally:
        bar.close()
        writer.close()
    report.files = [writer.path, out / "accuracy.md"]
    (out / "accuracy.md").write_text(accuracy_markdown(scenario, report))
    if plot and report.rows:
        work_precision_plot(scenario, report, out / "work_precision.png")
        report.files.append(out / "work_precision.png")
    return report


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
                 f"{r['status']}: {r['message']}", _g(r["wall_time_s"]), _g(r["force_evaluations"], 4)]
        for p in names:
            cells += [_g(r[f"{p}offset_norm_mm"], 4), _g(r[f"{p}offset_err_mm"], 2), _pct(r[f"{p}offset_err_rel"]),
                      _g(r[f"{p}peak_force_N"], 4), _pct(r[f"{p}peak_force_err_rel"])]
            if centroid:
                cells += [_g(r[f"{p}centroid_norm_mm"], 4), _pct(r[f"{p}centroid_err_rel"])]
        cells += ["yes" if r["within_1pct"] else "no",
                  f"{_g(r['linear_drift_rel'], 2)} / {_g(r['angular_drift_rel'], 2)}"]
        rows.append(cells)
    text = [f"# Accuracy study: {report.scenario}", "",
            (f"Errors against the reference, {report.reference.label(report.dt_s)}. The offset is O_b from "
             f"O_a at the end of the run (the residual offset of a completed grasp); its error is the norm "
             f"of the vector difference. Wall time is the simulation loop's."), "",
            f"- {report.confirmation_text()}",
            f"- {report.sensitivity_text()}",
            f"- {report.fastest_text()}"]
    if report.interrupted:
        text.append("- **interrupted**: the study was stopped; the rows below are the runs that finished")
    ladder = ("\n\nPer quantity: how well the reference is known, and the fastest setting within each "
              "bound of it (wall time, error):\n\n"
              + report.ladder_table().rstrip()) if report.rows else ""
    return "\n".join(text) + ladder + "\n\nEvery run:\n\n" + markdown_table(header, rows)


def work_precision_plot(scenario, report: AccuracyReport, path: Path) -> None:
    """Error against wall time, log-log, one line per integrator (and sphere scale): the offset
    error (mm), the peak force's relative error and, on a free-floating robot, the centroid
    displacement's. The worst grasp's error where there are several. Runs with no error (diverged,
    stopped) are drawn as crosses on the top edge; the paper's setting is circled."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    names = grasp_names(scenario)
    panels = [("offset_err_mm", "residual offset error (mm)"), ("peak_force_err_rel", "peak force error (relative)")]
    if free_floating(scenario):
        panels.append(("centroid_err_rel", "centroid displacement error (relative)"))
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 5.2), squeeze=False)
    rows = [r for r in report.rows if r["role"] not in ("reference", "perturbed") and not math.isnan(r["wall_time_s"])]
    ref = next((r for r in report.rows if r["role"] == "reference"), None)
    moved = next((r for r in report.rows if r["role"] == "perturbed"), None)
    for ax, (key, label) in zip(axes[0], panels):
        def err(r, key=key):
            return max((r[f"{p}{key}"] for p in names), default=math.nan)

        good = [err(r) for r in rows if not math.isnan(err(r))]
        floor = min([e for e in good if e > 0], default=1e-6) / 3
        top = max(good, default=1.0) * 3
        lines = {}
        for r in rows:
            lines.setdefault((r["method"], r.get("sphere_scale", 1.0)), []).append(r)
        for (method, scale), group in lines.items():
            group.sort(key=lambda r: r["rtol"] if method == "dopri5" else -r["substeps"], reverse=True)
            xs = [r["wall_time_s"] for r in group if not math.isnan(err(r))]
            ys = [max(err(r), floor) for r in group if not math.isnan(err(r))]
            name = method + (f", spheres x{scale:g}" if scale != 1.0 else "")
            (line,) = ax.loglog(xs, ys, "o-", lw=1.2, ms=4, label=name)
            for r in group:
                short = f"rtol {r['rtol']:g}" if method == "dopri5" else f"{r['step_ms']:g} ms"
                if math.isnan(err(r)):
                    ax.plot(r["wall_time_s"], top, "x", color=line.get_color(), ms=8, mew=2)
                    ax.annotate(f"{short}: {r['status']}", (r["wall_time_s"], top), fontsize=7,
                                rotation=90, va="top", ha="right", color=line.get_color())
                else:
                    ax.annotate(short, (r["wall_time_s"], max(err(r), floor)), fontsize=6,
                                xytext=(3, 3), textcoords="offset points", color=line.get_color())
        for r in rows:
            if r["role"] == "paper":
                y = top if math.isnan(err(r)) else max(err(r), floor)
                ax.plot(r["wall_time_s"], y, "o", ms=14, mfc="none", mec="black", mew=1.5,
                        label=f"paper's setting (symplectic Euler, 1 ms): {r['status']}")
            if r["role"] == "default":
                ax.plot(r["wall_time_s"], max(err(r), floor) if not math.isnan(err(r)) else top, "s", ms=11,
                        mfc="none", mec="tab:gray", mew=1.5, label="the scenario's setting")
        if ref is not None and not math.isnan(ref["wall_time_s"]):
            ax.axvline(ref["wall_time_s"], ls=":", color="black", lw=1,
                       label=f"reference: {ref['setting']}")
        if moved is not None and not math.isnan(err(moved)) and err(moved) > 0:
            ax.axhline(err(moved), ls="-.", color="tab:purple", lw=1,
                       label=f"the reference started {PERTURBATION_MM * 1e6:g} nm off")
        if key.endswith("_rel"):
            ax.axhline(WITHIN_REL, ls="--", color="tab:green", lw=1, label="1 %")
        elif ref is not None:
            one = max((WITHIN_REL * ref[f"{p}offset_norm_mm"] for p in names), default=math.nan)
            if not math.isnan(one):
                ax.axhline(one, ls="--", color="tab:green", lw=1, label="1 % of the reference's offset")
        ax.set_xlabel("wall time (s)")
        ax.set_ylabel(label)
        ax.xaxis.set_minor_formatter(NullFormatter())  # the decades alone: minor labels collide
        ax.grid(alpha=0.3, which="both")
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=7, frameon=False)
    fig.suptitle(f"{report.scenario}: error against wall time\n{textwrap.shorten(report.confirmation_text(), 150)}",
                 fontsize=9)
    fig.tight_layout(rect=(0, 0.14, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)


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


#: The start gaps tried, mm, for a misaligned start that interpenetrates at the scenario's.
START_GAPS_MM = (12.0, 15.0, 20.0, 25.0, 30.0, 40.0)


def _travel_time(s, gap_mm: float) -> float:
    """The time the fingers take to close `gap_mm`, s."""
    return gap_mm * 1e-3 / s.end_effector.closing_speed_m_s


def _later(s, dt_s: float) -> dict:
    """Changes that give every grasp phase and the run `dt_s` more time."""
    return {"simulation": {"duration_s": s.simulation.duration_s + dt_s},
            "completion": {"phase_timeout_s": s.completion.phase_timeout_s + dt_s}}


def clearing_gap(s) -> float | None:
    """The smallest of START_GAPS_MM at which `s`'s fingers and groove do not interpenetrate at
    the start, mm (None if none does)."""
    from .model import build_model
    from .run import initial_contacts

    for gap in START_GAPS_MM:
        if gap > s.end_effector.start_gap_mm:
            wider = replace(s, end_effector={"start_gap_mm": gap})
            if not initial_contacts(build_model(wider)):
                return gap
    return None


def widened(s, gap_mm: float):
    """`s` with its fingers starting `gap_mm` from a centred groove, and as much more time as
    the longer travel takes."""
    extra = _travel_time(s, gap_mm - s.end_effector.start_gap_mm)
    return replace(s, end_effector={"start_gap_mm": gap_mm}, **_later(s, extra))


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

    from .stability import predict_step

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
    from .model import build_model

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


#: A completed grasp left farther off than this, mm, is "converged, off centre": the suite's
#: bound on Case I, a tenfold reduction of its 3 mm start.
CENTRED_MM = 0.3


def verdict(o: Outcome) -> str:
    """converged (or converged, off centre) / not captured / diverged (detected) / rejected at
    start, or a failure of the simulator that the study exists to catch (an exception, a
    silent NaN)."""
    if o.status in COMPARABLE and not o.finite:
        return "FAILED: silent NaN"
    if o.status == "completed" and max(float(np.linalg.norm(x)) for x in o.offsets if x is not None) > CENTRED_MM:
        return "converged, off centre"
    return {"completed": "converged", "incomplete": "not captured", "diverged": "diverged (detected)",
            REJECTED: "rejected at start", WALL_LIMIT: "no verdict: wall limit",
            EXCEPTION: "FAILED: exception"}.get(o.status, o.status)


STABILITY_COLUMNS = ["case", "group", "change", "dynamics_step_ms", "predicted_stable_step_ms", "omega_h",
                     "damping_h", "predicted_stable", "verdict", "prediction_held", "status", "completed_s",
                     "residual_offset_mm", "final_offset_mm", "peak_force_N", "sim_time_s", "wall_time_s",
                     "finite", "message", "finer_verdict", "finer_message"]
#: A diverged case runs again this many times finer (fixed step; dopri5: rtol / this): if it
#: still diverges, the cause is not the step.
FINER = 4


def finer(s):
    """`s` with its dynamics step FINER times smaller (dopri5: its rtol and atol)."""
    i = s.simulation.integrator
    if i.method == "dopri5":
        return replace(s, simulation={"integrator": {**to_dict(i), "rtol": i.rtol / FINER, "atol": i.atol / FINER}})
    return replace(s, simulation={"substeps": s.simulation.substeps * FINER})


def stability_row(case: Case, o: Outcome, changed=None, fine: Outcome | None = None) -> dict:
    """A stability CSV row: the case, its prediction, verdict and outcome, and (`fine`) the
    verdict of the same case FINER times finer when it diverged ("not run" otherwise)."""
    p = o.prediction
    v = verdict(o)
    if p is None or o.status not in (*COMPARABLE, "diverged"):
        held = "n/a"
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
            "residual_offset_mm": max(finals) if o.status == "completed" else math.nan,
            "final_offset_mm": max(finals, default=math.nan), "peak_force_N": max(o.peaks, default=math.nan),
            "sim_time_s": o.sim_time_s, "wall_time_s": o.wall_time_s,
            "finite": "n/a" if o.status not in COMPARABLE else ("yes" if o.finite else "no"),
            "message": o.message, "finer_verdict": "not run" if fine is None else verdict(fine),
            "finer_message": "not run" if fine is None else fine.message}


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


def check_finer(o: Outcome, s, source: str, wall_limit_s) -> Outcome | None:
    """A diverged run's case again, FINER times finer; None for any other outcome."""
    return run_once(finer(s), source, wall_limit_s) if o.status == "diverged" else None


def stability_study(scenario, cases: list[Case], out_dir, *, source: str = "<study>", progress: bool = False,
                    wall_limit_s: float | None = STABILITY_WALL_LIMIT_S) -> StabilityReport:
    """Run every case of `scenario`; write stability.csv (a row per case as it ends) and
    stability.md into `out_dir`. A misaligned start rejected for interpenetrating is run once
    more with the start gap that clears it (a second row). A diverged case runs again FINER
    times finer (`finer_verdict`): one that still diverges does not diverge for its step.
    Ctrl-C stops the study and keeps the rows written."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    writer = RowWriter(out / "stability.csv", STABILITY_COLUMNS)
    report = StabilityReport(scenario.name, writer.rows)
    from .run import progress_bar

    bar = progress_bar(len(cases), progress, f"{scenario.name}: stability", "run")
    try:
        warm_up(scenario, [scenario.simulation.integrator.method])
        for case in cases:
            bar.set_postfix_str(case.name)
            try:
                s = case.apply(scenario)
            except SpotsimError as e:
                s, o = None, Outcome(REJECTED, str(e).replace("\n", "; "))
            else:
                o = run_once(s, source, wall_limit_s)
            writer.write(stability_row(case, o, s, check_finer(o, s, source, wall_limit_s)))
            gap = clearing_gap(s) if case.misalignment and o.status == REJECTED and s is not None else None
            if gap is not None:  # the same start, with fingers opened wide enough to clear it
                wide = dc_replace(case, name=f"{case.name}, gap {gap:g} mm",
                                  what=f"{case.what}; start gap {s.end_effector.start_gap_mm:g} -> {gap:g} mm")
                s = widened(s, gap)
                o = run_once(s, source, wall_limit_s)
                writer.write(stability_row(wide, o, s, check_finer(o, s, source, wall_limit_s)))
            bar.update(1)
    except KeyboardInterrupt:
        report.interrupted = True
    finally:
        bar.close()
        writer.close()
    (out / "stability.md").write_text(stability_markdown(scenario, report))
    report.files = [writer.path, out / "stability.md"]
    return report


def stability_markdown(scenario, report: StabilityReport) -> str:
    header = ["case", "change", "predicted stable step (ms)", "ω·h", "verdict", "prediction held",
              "residual offset (mm)", "peak force (N)", "sim / wall (s)", "outcome", f"diverged: at h/{FINER}"]
    rows = [[r["case"], r["change"], _g(r["predicted_stable_step_ms"]), _g(r["omega_h"]), r["verdict"],
             r["prediction_held"],
             _g(r["residual_offset_mm"]), _g(r["peak_force_N"]), f"{_g(r['sim_time_s'])} / {_g(r['wall_time_s'])}",
             r["message"], "" if r["finer_verdict"] == "not run" else f"{r['finer_verdict']}: {r['finer_message']}"]
            for r in report.rows]
    counts = {}
    for r in report.rows:
        counts[r["verdict"]] = counts.get(r["verdict"], 0) + 1
    step = next((r["dynamics_step_ms"] for r in report.rows if not math.isnan(r["dynamics_step_ms"])), math.nan)
    text = [f"# Stability study: {report.scenario}", "",
            (f"Dynamics step {_g(step)} ms ({scenario.simulation.integrator.method}). The predicted stable step "
             f"is stability.predict_step's; ω·h is the stiffest contact mode times the step (the integrator's "
             f"limit on the imaginary axis is 2 for symplectic Euler). A converged grasp left more than "
             f"{CENTRED_MM:g} mm off is \"converged, off centre\". A diverged case runs again with a step "
             f"{FINER} times smaller: if it still diverges, the step is not the cause."), "",
            "- verdicts: " + ", ".join(f"{n} {v}" for v, n in counts.items())]
    if report.failures:
        text.append(f"- **{len(report.failures)} case(s) FAILED** (an exception or a silent NaN): "
                    + ", ".join(r["case"] for r in report.failures))
    if report.interrupted:
        text.append("- **interrupted**: the study was stopped; the rows below are the cases that finished")
    return "\n".join(text) + "\n\n" + markdown_table(header, rows)
