"""A run: the compiled loop driven through a scenario's grasp sequence, with coal refreshed,
modules welded, the record kept and the outcome reported.

Python does what only Python can (coal's broad phase, building a welded model) and the
reporting; every step and record is the compiled loop's (`loop.run_intervals`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numba
import numpy as np
import pinocchio as pin

from . import instrument, measures
from .assemble.model import Model, build_model, grasp_frame, on_table
from .assemble.weld import weld
from .contact.search import literal_search
from .errors import ScenarioError
from .scenario import in_grooves, modules_of, tolerance_warnings
from .sim.broadphase import BroadPhase, StateOverflow
from .sim.data import ROWS_PER_CALL, make_data
from .sim.events import ENERGY, ENERGY_WORK, NONFINITE, RAN, REFRESH, STOPPED, TOO_DEEP, UNDERFLOW
from .sim.loop import progress_of, run_intervals, skin_used
from .sim.phase import HOLD_ROUND_OFF_S, completion_criteria
from .sim.record import begin_record
from .sim.recorder import Recorder
from .sim.stability import ENERGY_GROWTH, stability_warnings
from .sim.step import step
from .sim.tree import kinematics
from .status import COMPLETED, DIVERGED, INCOMPLETE, INTERRUPTED, NOT_CAPTURED, WALL_LIMIT
from .tables import APPROACH, PHASE_NAMES, SELF_CENTRING, TRANSMISSION_STATES
from .version import __version__

#: The layout of summary.json and timeseries.npz; a reader refuses any other (`results.read_results`).
RESULTS_FORMAT = 1


@dataclass
class Result:
    """What a run produced: `summary` (the summary.json contract) and `timeseries` arrays."""

    scenario: object
    model: Model
    summary: dict
    timeseries: dict[str, np.ndarray] = field(repr=False)
    replay: dict[str, np.ndarray] = field(default_factory=dict, repr=False)  # replay.npz

    @property
    def status(self) -> str:
        return self.summary["status"]

    @property
    def grasp(self) -> dict:
        """The first grasp's entry of the summary (the only one of a single-arm run)."""
        return self.summary["grasps"][0]


def simulate(scenario, *, model: Model | None = None, progress: bool = False,
             source: str = "<scenario>", wall_limit_s: float | None = None) -> Result:
    """Run a scenario's grasps in sequence to completion, divergence or time-out.

    Never raises on physics. progress: a progress bar (tqdm) on stderr. Ctrl-C ends the run
    with status `interrupted` and keeps what was recorded; so does a wall-time budget spent
    (`wall_limit_s`, checked each time the compiled loop returns, about every 0.25 s
    simulated), with status `wall limit`.
    """
    model = model or build_model(scenario, source)
    check_start(model, source)
    n_records = int(round(scenario.simulation.duration_s / scenario.simulation.dt_s))
    data = make_data(model)
    broad = None if model.sim.literal else BroadPhase(model)
    near = np.zeros(0, dtype=np.int64)  # the broad phase's face pairs
    rec = Recorder(model)
    begin_record(model.sim, data)
    out = progress_of(data, RAN)
    rec.collect(model, out, near)
    status, message, welds = INCOMPLETE, "", []
    compile_loop(model, data)  # the run's wall time is the simulation's, not the compiler's
    bar = progress_bar(n_records, progress)
    wall0 = time.perf_counter()
    done = 0  # record intervals taken
    try:
        while done < n_records:
            if skin_used(model.sim, data):
                try:
                    near = broad.refresh(data)  # the Verlet skin is used up
                except StateOverflow as e:
                    status, message = DIVERGED, f"{e} at t = {out.t:.4f} s"
                    break
            out = run_intervals(model.sim, data, min(n_records - done, ROWS_PER_CALL))
            rows = rec.collect(model, out, near)
            done += rows
            bar.update(rows)
            spent = wall_limit_s is not None and time.perf_counter() - wall0 > wall_limit_s
            if out.event == REFRESH and not spent:
                continue
            message = _divergence(model, data, out.event)
            if message:
                status = DIVERGED
                break
            if out.complete and out.event == STOPPED:  # (before: the window after the last grasp)
                if out.active + 1 == len(model.grasps):
                    status = COMPLETED
                    message = _completed(model, data)
                    break
                model, data = weld(model, data, source)
                broad = None if model.sim.literal else BroadPhase(model)
                near = np.zeros(0, dtype=np.int64)
                out = progress_of(data, RAN)
                welds.append(out.t)
            elif not out.complete and out.elapsed > model.sim.completion.phase_timeout:
                message = _why_incomplete(model, data, "the phase time-out")
                break
            if spent:  # checked at every return of the compiled loop, a refresh of the broad phase's too
                status, message = WALL_LIMIT, f"wall-time budget of {wall_limit_s:g} s spent at t = {out.t:.4f} s"
                break
        else:
            if out.complete and out.active + 1 == len(model.grasps):  # the duration ended the window after it
                status, message = COMPLETED, _completed(model, data)
            else:
                message = _why_incomplete(model, data, "the time-out")
    except KeyboardInterrupt:
        status, message = INTERRUPTED, f"interrupted by the user at t = {out.t:.4f} s"
    finally:
        bar.close()
    wall = time.perf_counter() - wall0
    series = rec.arrays()
    summary = _summary(scenario, model, data.view(), rec, series, status, message, wall, welds)
    return Result(scenario, model, summary, series, rec.replay_arrays())


def _completed(model: Model, data) -> str:
    """The message of a run whose grasps all completed: when the last did."""
    v = data.view()
    return f"{'all grasps' if len(model.grasps) > 1 else 'grasp'} complete at t = {v.t_complete[v.active]:.4f} s"


def compile_loop(model: Model, data) -> None:
    """Compile the loop for this Model and Data's types (or load it from numba's cache)
    without running it."""
    run_intervals.compile((numba.typeof(model.sim), numba.typeof(data), numba.types.int64))


class Stepper:
    """Step a scene from Python, one compiled step at a time (for inspection and tests).

    Between steps it does what the loop leaves to Python: it refreshes coal's face pairs when
    the skin is used up. Free flight, records and welds are the loop's (`simulate`), and so is
    ending an adaptive step at the drive's next reading: a step here is the integrator's own.
    """

    def __init__(self, model: Model, data=None):
        self.model = model
        self.data = make_data(model) if data is None else data
        self.broad = None if model.sim.literal else BroadPhase(model)

    def step(self, h: float) -> float:
        """One step of at most h (s); returns the step taken (0.0: the adaptive step fell
        below its least size)."""
        if skin_used(self.model.sim, self.data):
            self.broad.refresh(self.data)
        return step(self.model.sim, self.data, h)


def _divergence(model: Model, data, event: int) -> str:
    """Why the run has diverged, from the loop's event and data, or ''."""
    if event not in (TOO_DEEP, NONFINITE, ENERGY_WORK, ENERGY, UNDERFLOW):
        return ""
    v = data.view()
    if event == TOO_DEEP:
        return (f"penetration {v.summary.max_penetration * 1e3:.3f} mm exceeds the sphere radius "
                f"{model.sim.limits.max_penetration * 1e3:.3f} mm at t = {v.t:.4f} s")
    if event == NONFINITE:  # a NaN or an infinity anywhere; nothing recorded
        return f"state became non-finite by t = {v.t:.4f} s"
    if event == ENERGY_WORK:  # energy from nowhere; its record is kept
        return (f"energy grew to {v.energy_now:.3g} J, more than {ENERGY_GROWTH:g} times the "
                f"{v.energy_start:.3g} J at the start plus the {v.drive_work:.3g} J the finger "
                f"drives did, at t = {v.t:.4f} s")
    if event == ENERGY:  # a passive phase gained energy; its record is kept
        return (f"energy grew from {v.energy_passive:.3g} J to {v.energy_now:.3g} J while the "
                f"drive held the fingers (a passive phase) at t = {v.t:.4f} s")
    if event == UNDERFLOW:
        return (f"adaptive step fell below h_min_s = {model.sim.integrator.h_min:g} s at "
                f"t = {v.t:.4f} s")
    return ""


def progress_bar(total: int, enabled: bool, what: str = "simulating", unit: str = "ms"):
    """A progress bar on stderr; when not enabled, or stderr is not a terminal (CI logs,
    pipes), a disabled one whose calls do nothing."""
    from tqdm import tqdm

    return tqdm(total=total, unit=unit, desc=what, leave=False, disable=None if enabled else True)


def _why_incomplete(model: Model, data, limit: str) -> str:
    v = data.view()
    ee, k = model.grasps[v.active]
    who = f"{model.end_effectors[ee].name} on {model.modules[k].name}"
    if v.phase[v.active] != SELF_CENTRING:
        return f"{who}: no contact by {limit} t = {v.t:.3f} s: the fingers never reached the groove"
    unmet = [name for name, ok in completion_criteria(model, data).items() if not ok]
    if not len(v.contacts.key):
        unmet.insert(0, "contact lost")
    return (f"{who}: self-centring did not complete by {limit} t = {v.t:.3f} s; "
            f"unmet at the end: {'; '.join(unmet) or 'criteria not held for hold_s'}")


def _time(x: float) -> float | None:
    return None if math.isnan(x) else float(x)


def _summary(s, model, v, rec, series, status, message, wall, welds) -> dict:
    """The summary.json of a run from its last model, its Data's fields v and its record."""
    grasps, phases = [], []
    starts = [m.initial_offset_mm for m in modules_of(s).values()]  # in the order of model.modules
    for g, (ee, k) in enumerate(model.grasps):
        completed = _time(v.t_complete[g])
        rows = np.flatnonzero(series["grasp"] == g)
        if completed is not None:  # not the rows recorded after it (`completion.record_after_s`)
            rows = rows[series["t"][rows] <= v.t_complete[g] + HOLD_ROUND_OFF_S]
        last = rows[-1] if len(rows) else None
        done = completed is not None and last is not None
        offset = series["offset_mm"][last] if done else None
        # when each phase began: the approach always (None if the grasp never started), the
        # others once reached
        began = dict(zip(PHASE_NAMES, (_time(v.t_start[g]), _time(v.t_contact[g]), completed), strict=True))
        phases.append({name: t for name, t in began.items() if t is not None or name == PHASE_NAMES[APPROACH]})
        entry = {
            "end_effector": model.end_effectors[ee].name,
            "module": model.modules[k].name,
            "started_s": _time(v.t_start[g]),
            "contact_onset_s": _time(v.t_contact[g]),
            "completed_s": completed,
            "residual_offset_mm": None if offset is None else [float(x) for x in offset],
            "residual_offset_norm_mm": None if offset is None else float(np.linalg.norm(offset)),
            "residual_rpy_deg": None if not done else [float(x) for x in series["rpy_deg"][last]],
            # both fingers' flat tips ended within their grooves' mouths: captured (False: a
            # finger rests on a land or a mouth's edge beside its groove)
            "in_grooves": None if offset is None else in_grooves(s.geometry, offset),
            # the offset of O_b from O_a at the grasp's first record, and how far the earlier
            # grasps moved it from the module's configured start (the second grasp's: what the
            # first did to EE-2's offset to TM-2, the paper's Sec. 5.2 explanation)
            "start_offset_mm": None if not len(rows) else [float(x) for x in series["offset_mm"][rows[0]]],
            "start_offset_change_mm": None if not len(rows) else
            [float(x) for x in series["offset_mm"][rows[0]] - np.asarray(starts[k])],
            "peak_force_N": [float(x) for x in v.peak_force[g]],
            "peak_torque_Nm": [float(x) for x in v.peak_torque[g]],
            "peak_force_norm_N": float(v.peak_force_norm[g]),
            "peak_torque_norm_Nm": float(v.peak_torque_norm[g]),
            "max_active_pairs": int(v.peak_pairs[g]),
            # the drive: how often it closed again at over half its closing speed after it had
            # stopped, and its largest change of speed from one reading to the next
            "drive_resumes": int(v.drive_resumes[g]),
            "drive_largest_speed_step_mm_s": float(v.drive_jump[g] * 1e3),
            "final_offset_mm": None if last is None else [float(x) for x in series["offset_mm"][last]],
        }
        if "robot_centroid_m" in series and len(rows):
            # the FDR centroid's displacement over this grasp: from its drive's start to its
            # completion (or the end of the record), taken within one body (the FDR in the
            # first grasp, the FDR + TM-1 composite after the weld)
            d = series["robot_centroid_m"][last] - series["robot_centroid_m"][rows[0]]
            entry["robot_centroid_displacement_mm"] = [float(x) for x in d * 1e3]
        if s.end_effector.drive == "motor":
            # the motor: its largest current, its transmission's time in each state and how often
            # it stopped sliding fingers, their largest deceleration between stops
            entry["motor_peak_current_A"] = float(v.peak_current[g])
            entry["transmission_time_s"] = {name: float(x) for name, x in
                                            zip(TRANSMISSION_STATES, v.transmission_time[g], strict=True)}
            entry["transmission_stops"] = int(v.transmission_stops[g])
            entry["finger_peak_deceleration_m_s2"] = float(v.peak_deceleration[g])
        if on_table(s):
            # what the grasp pressed into the air-bearing table: the largest contact force along
            # its normal and moment about a branch's centroid in its plane, over the floating branches
            entry["table_force_peak_N"] = float(v.peak_table_force[g])
            entry["table_moment_peak_Nm"] = float(v.peak_table_moment[g])
        grasps.append(entry)
    if "base_pos_m" in series and len(series["t"]):
        # the SPOT experiment's measures: each body's displacement in the table's plane and
        # its turn about the normal, their amplitudes within each grasp (`measures`)
        moved = measures.displacements(series, s.testbed.table_normal)
        started = [entry for entry in grasps if entry["started_s"] is not None]
        windows = measures.grasp_windows({"grasps": grasps}, float(series["t"][-1]))
        for entry, (start, end) in zip(started, windows, strict=True):
            entry["displacements"] = measures.amplitudes(series["t"], moved, start, end)
    free = bool(model.robot_joint)
    sim = s.simulation
    testbed = {}
    if hasattr(s, "testbed"):
        # the mount, and the table's normal the displacements are measured about (`measures`;
        # a free-floating run is measured in the testbed's axes too)
        n = np.asarray(s.testbed.table_normal, dtype=float) / np.linalg.norm(s.testbed.table_normal)
        testbed = {"testbed": {"mount": s.testbed.mount, "table_normal": [float(x) for x in n]}}
        if on_table(s) and "base_pos_m" in series and len(series["t"]):
            # each body's height above the table's plane through the world origin: its
            # recorded frame's (the base's joint frame, each module's groove frame O_b)
            heights = {"base": series["base_pos_m"][0]}
            heights.update({m.name: series[f"{m.name}_pos_m"][0] for m in model.modules})
            testbed["testbed"]["heights_mm"] = {k: float(p @ n * 1e3) for k, p in heights.items()}
    # the momentum the floating bodies' weight alone would give them over the run: a scale of
    # the balance where gravity is on and what it holds up stays still (a module on a bungee)
    br = model.sim.branches
    weight_impulse = v.t * sum(br.mass[b] * np.linalg.norm(br.gravity_W[b]) for b in range(len(br.joint))
                               if br.floating[b])
    rig = {}
    if model.spec.dynamometer:
        # what the plate under the arm reads, beside the contact force (`instrument`)
        data = model.pin_model.createData()
        pin.forwardKinematics(model.pin_model, data, model.q0)
        setting = instrument.settings(s, grasp_frame(model, data, 0).rotation)
        samples = instrument.reading(series, setting) if len(series["t"]) > 1 else None
        rig["dynamometer"] = {**setting, **(instrument.peaks(samples) if samples is not None else {})}
        done = _time(v.t_complete[len(model.grasps) - 1])
        if samples is not None and done is not None:
            rig["dynamometer"]["after_grasp"] = instrument.after_grasp(samples, done)
    outside = [g + 1 for g, entry in enumerate(grasps) if entry["in_grooves"] is False]
    if status == COMPLETED and outside:
        status = NOT_CAPTURED
        message = "; ".join(f"grasp {g} closed at t = {grasps[g - 1]['completed_s']:.4f} s with a finger outside "
                            f"its groove, e = {grasps[g - 1]['residual_offset_norm_mm']:.3f} mm" for g in outside)
    return {
        "scenario": s.name,
        "spotsim_version": __version__,
        "results_format": RESULTS_FORMAT,
        "status": status,
        "message": message,
        "wall_time_s": wall,
        "sim_time_s": v.t,
        "steps": v.steps,
        "pair_steps": v.pair_steps,  # sphere pairs in contact, summed over the steps
        "dt_s": sim.dt_s,
        "substeps": sim.substeps,
        "dynamics_dt_s": model.sim.h,
        # steps of a whole record interval, taken where no contact could start within it
        "free_flight_steps": v.flights,
        "integrator": {"method": sim.integrator.method, "accepted_steps": v.accepted, "rejected_steps": v.rejected,
                       "switch_cuts": v.cut, "force_evaluations": v.evaluations},
        "broad_phase": s.contact.broad_phase,
        "drive": s.end_effector.drive,
        "phases": phases[0] if len(phases) == 1 else phases,
        "welds_s": welds,
        "grasps": grasps,
        **testbed,
        **rig,
        "momentum": {
            "linear_drift_rel": v.momentum_drift / max(v.momentum_max, weight_impulse, 1e-300),
            "angular_drift_rel": v.angular_momentum_drift / max(v.angular_momentum_max, 1e-300),
            "definition": (
                "max over the run of |total momentum of the floating bodies - initial|, relative to "
                "the largest single body's momentum (angular about the world origin); the robot "
                "floats freely, so momentum is conserved" if free and not on_table(s) else
                "max over the run of |in-plane momentum of the floating bodies - initial| and of |their "
                "angular momentum about the table's normal - initial|, relative to the largest single "
                "body's momentum (angular about the world origin); the bodies float on the air-bearing "
                "table, which reacts the rest, so these are conserved" if free else
                "max over the run of |momentum - initial - impulse of the contact forces, the "
                "bungee's pull and gravity| of the module, relative to its largest momentum (angular "
                "about the world origin) or, if larger, the linear momentum its weight alone would give "
                "it over the run; the base is fixed, so momentum is not conserved"),
        },
        "spheres": {"finger": int(len(model.master.centre_J)), "groove": int(len(model.slave.centre_J))},
        "fingers": rec.layout.fingers,
        "warnings": tolerance_warnings(s) + stability_warnings(model),
    }


def initial_contacts(model: Model) -> int:
    """Sphere pairs already in contact at the start, by the literal all-pairs search (which
    finds pairs at any depth, where the culled search only looks as deep as a run may go
    before it is declared diverged)."""
    data = make_data(model)
    kinematics(model.sim, data)
    # spheres of faces whose patches coal finds apart by more than the margin do not touch
    if not model.sim.literal and not len(BroadPhase(model).near(data.q)):
        return 0
    return len(literal_search(model.sim, data).key)


def check_start(model: Model, source: str) -> None:
    """Reject a scenario whose fingers and groove interpenetrate at the start."""
    n = initial_contacts(model)
    if n:
        s = model.scenario
        offsets = "; ".join(f"{k}.initial_offset_mm = {list(m.initial_offset_mm)}"
                            for k, m in modules_of(s).items())
        raise ScenarioError([
            f"{source}: {offsets}: fingers and groove interpenetrate at the start ({n} sphere "
            f"pairs); widen end_effector.start_gap_mm = {s.end_effector.start_gap_mm} or move "
            f"the module"])
