"""The run loop: step the scene, watch the grasp, record, and report."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from .contact.friction import SLIPPING, STICKING
from .grasp import COMPLETE, PHASES, SELF_CENTRING
from .integrators import make_integrator
from .model import Model, build_model
from .scenario import Scenario, tolerance_warnings
from .step import make_data, step

COMPLETED, INCOMPLETE, DIVERGED, INTERRUPTED = "completed", "incomplete", "diverged", "interrupted"


@dataclass
class Result:
    """What a run produced: `summary` (the summary.json contract) and `timeseries` arrays."""

    scenario: Scenario
    model: Model
    summary: dict
    timeseries: dict[str, np.ndarray] = field(repr=False)

    @property
    def status(self) -> str:
        return self.summary["status"]

    @property
    def grasp(self) -> dict:
        """The (single-arm) grasp's entry of the summary."""
        return self.summary["grasps"][0]


def refresh_kinematics(model: Model, data) -> None:
    """Joint placements and velocities of the current (q, v): a step leaves those of its start."""
    pin.forwardKinematics(model.pin_model, data.pin_data, data.q, data.v)


def module_momentum_W(model: Model, data) -> tuple[np.ndarray, np.ndarray]:
    """Linear momentum and angular momentum about the world origin of the module, world frame.

    Reads the kinematics in data.pin_data: call refresh_kinematics first.
    """
    j = model.module_joint
    h_local = model.pin_model.inertias[j] * data.pin_data.v[j]
    h_world = data.pin_data.oMi[j].act(h_local)
    return h_world.linear.copy(), h_world.angular.copy()


class Recorder:
    """Samples the state at every recorded step and keeps per-substep peaks."""

    def __init__(self, model: Model):
        self.model = model
        self.rows: dict[str, list] = {k: [] for k in (
            "t", "module_pos_m", "module_quat_xyzw", "offset_mm", "rpy_deg", "module_vel_m_s",
            "module_omega_rad_s", "force_N", "torque_Nm", "finger_opening_mm", "finger_load_N",
            "pairs_slipping", "pairs_sticking", "phase", "max_penetration_um")}
        self.peak_force = np.zeros(3)
        self.peak_torque = np.zeros(3)
        self.peak_force_norm = 0.0
        self.peak_torque_norm = 0.0
        self.max_pairs = 0
        self.force_a = np.zeros(3)
        self.torque_a = np.zeros(3)

    def wrench_in_a(self, data):
        """Combined contact force on the module and torque about its centroid, in O_a axes."""
        m = self.model
        oMb = data.pin_data.oMi[m.module_joint]
        r_G = oMb.act(m.pin_model.inertias[m.module_joint].lever)
        F_W = data.module_force_W
        tau_G = data.module_torque_O_W - np.cross(r_G, F_W)
        R = m.oMa.rotation
        return R.T @ F_W, R.T @ tau_G

    def substep(self, data, n_pairs):
        if n_pairs == 0:
            self.force_a, self.torque_a = np.zeros(3), np.zeros(3)
            return
        self.force_a, self.torque_a = self.wrench_in_a(data)
        self.peak_force = np.maximum(self.peak_force, np.abs(self.force_a))
        self.peak_torque = np.maximum(self.peak_torque, np.abs(self.torque_a))
        self.peak_force_norm = max(self.peak_force_norm, float(np.linalg.norm(self.force_a)))
        self.peak_torque_norm = max(self.peak_torque_norm, float(np.linalg.norm(self.torque_a)))
        self.max_pairs = max(self.max_pairs, n_pairs)

    def sample(self, data):
        """Record the state; data.pin_data must hold the kinematics of (q, v)."""
        m, r = self.model, self.rows
        oMb = data.pin_data.oMi[m.module_joint]
        aMb = m.oMa.actInv(oMb)
        nu = data.pin_data.v[m.module_joint]
        c = data.contacts
        states = np.bincount(c.state, minlength=3) if c is not None and len(c.key) else np.zeros(3, int)
        r["t"].append(data.t)
        r["module_pos_m"].append(oMb.translation.copy())
        r["module_quat_xyzw"].append(pin.SE3ToXYZQUAT(oMb)[3:])
        r["offset_mm"].append(aMb.translation * 1e3)
        r["rpy_deg"].append(np.degrees(pin.rpy.matrixToRpy(aMb.rotation)))
        r["module_vel_m_s"].append(oMb.rotation @ nu.linear)
        r["module_omega_rad_s"].append(oMb.rotation @ nu.angular)
        r["force_N"].append(self.force_a)
        r["torque_Nm"].append(self.torque_a)
        r["finger_opening_mm"].append(data.opening * 1e3)
        r["finger_load_N"].append(data.finger_load.copy())
        r["pairs_slipping"].append(states[SLIPPING])
        r["pairs_sticking"].append(states[STICKING])
        r["phase"].append(PHASES.index(data.phase.phase))
        r["max_penetration_um"].append(c.phi.max() * 1e6 if c is not None and len(c.key) else 0.0)

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(v) for k, v in self.rows.items()}


def simulate(scenario: Scenario, *, model: Model | None = None, progress: bool = False,
             source: str = "<scenario>") -> Result:
    """Run a scenario to completion, divergence or its time-out; never raises on physics.

    progress: show a progress bar (tqdm) on stderr. Ctrl-C ends the run with status
    `interrupted` and keeps what was recorded.
    """
    model = model or build_model(scenario, source)
    check_start(model, source)
    sim = scenario.simulation
    h = sim.dt_s / sim.substeps
    n_records = int(round(sim.duration_s / sim.dt_s))
    integrator = make_integrator(sim.integrator, model.pin_model)
    data = make_data(model)
    rec = Recorder(model)
    refresh_kinematics(model, data)
    p0, L0 = module_momentum_W(model, data)
    J, JL = np.zeros(3), np.zeros(3)
    mass = model.pin_model.inertias[model.module_joint].mass
    g_W = np.array(sim.gravity_m_s2)
    gravity = bool(np.any(g_W))
    drift_lin = drift_ang = 0.0
    p_max, L_max = np.linalg.norm(p0), np.linalg.norm(L0)
    max_phi = min(model.params.r1, model.params.r2)
    status, message = INCOMPLETE, ""
    rec.sample(data)
    bar = _progress(n_records, progress)
    wall0 = time.perf_counter()
    steps = 0
    try:
        for _ in range(n_records):
            for _ in range(sim.substeps):
                try:
                    c = step(model, data, h, integrator)
                except ValueError as e:  # coal rejects bounds that overflowed
                    status = DIVERGED
                    reason = str(e).strip().splitlines()[-1].removeprefix("message: ")
                    message = f"state left the representable range at t = {data.t:.4f} s (coal: {reason})"
                    break
                steps += 1
                n = len(c.key)
                rec.substep(data, n)
                # momentum balance of the module: the impulse of the contact forces and gravity
                if n or gravity:
                    r_G = data.pin_data.oMi[model.module_joint].act(
                        model.pin_model.inertias[model.module_joint].lever)
                    J += h * (data.module_force_W + mass * g_W)
                    JL += h * (data.module_torque_O_W + np.cross(r_G, mass * g_W))
                if n and c.phi.max() > max_phi:
                    status = DIVERGED
                    message = (f"penetration {c.phi.max() * 1e3:.3f} mm exceeds the sphere radius "
                               f"{max_phi * 1e3:.3f} mm at t = {data.t:.4f} s")
                    break
                if not (np.all(np.isfinite(data.q)) and np.all(np.isfinite(data.v))):
                    status = DIVERGED
                    message = f"state became non-finite at t = {data.t:.4f} s"
                    break
                if data.phase.phase == COMPLETE:
                    break
            if status == DIVERGED:
                break
            refresh_kinematics(model, data)
            rec.sample(data)
            p, L = module_momentum_W(model, data)
            p_max, L_max = max(p_max, np.linalg.norm(p)), max(L_max, np.linalg.norm(L))
            drift_lin = max(drift_lin, np.linalg.norm(p - p0 - J))
            drift_ang = max(drift_ang, np.linalg.norm(L - L0 - JL))
            if bar is not None:
                bar.update(1)
            if data.phase.phase == COMPLETE:
                status = COMPLETED
                message = f"grasp complete at t = {data.t:.4f} s"
                break
        else:
            message = _why_incomplete(data)
    except KeyboardInterrupt:
        status, message = INTERRUPTED, f"interrupted by the user at t = {data.t:.4f} s"
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - wall0
    series = rec.arrays()
    summary = _summary(scenario, model, data, rec, series, status, message, wall, steps, h,
                       drift_lin / max(p_max, 1e-300), drift_ang / max(L_max, 1e-300))
    return Result(scenario, model, summary, series)


def _progress(total: int, enabled: bool):
    if not enabled:
        return None
    from tqdm import tqdm

    # disable=None: no bar when stderr is not a terminal (CI logs, pipes)
    return tqdm(total=total, unit="ms", desc="simulating", leave=False, disable=None)


def _why_incomplete(data) -> str:
    t = data.t
    if data.phase.phase != SELF_CENTRING:
        return f"no contact by the time-out t = {t:.3f} s: the fingers never reached the groove"
    c = data.contacts
    speed = float(c.speed.max()) if len(c.key) else 0.0
    unmet = [k for k, ok in data.phase.criteria(data.drives[0].stalled, speed,
                                                float(np.linalg.norm(data.module_force_W))).items() if not ok]
    if not len(c.key):
        unmet.insert(0, "contact lost")
    return (f"self-centring did not complete by the time-out t = {t:.3f} s; "
            f"unmet at the end: {'; '.join(unmet) or 'criteria not held for hold_s'}")


def _summary(s, model, data, rec, series, status, message, wall, steps, h, drift_lin, drift_ang):
    times = data.phase.times
    completed = times.get(COMPLETE)
    offset = series["offset_mm"][-1] if completed is not None else None
    grasp = {
        "end_effector": "EE",
        "module": "TM",
        "contact_onset_s": times.get(SELF_CENTRING),
        "completed_s": completed,
        "residual_offset_mm": None if offset is None else [float(x) for x in offset],
        "residual_offset_norm_mm": None if offset is None else float(np.linalg.norm(offset)),
        "residual_rpy_deg": None if completed is None else [float(x) for x in series["rpy_deg"][-1]],
        "peak_force_N": [float(x) for x in rec.peak_force],
        "peak_torque_Nm": [float(x) for x in rec.peak_torque],
        "peak_force_norm_N": rec.peak_force_norm,
        "peak_torque_norm_Nm": rec.peak_torque_norm,
        "max_active_pairs": int(rec.max_pairs),
        "final_offset_mm": [float(x) for x in series["offset_mm"][-1]],
    }
    return {
        "scenario": s.name,
        "status": status,
        "message": message,
        "wall_time_s": wall,
        "sim_time_s": data.t,
        "steps": steps,
        "dt_s": s.simulation.dt_s,
        "substeps": s.simulation.substeps,
        "dynamics_dt_s": h,
        "integrator": s.simulation.integrator,
        "broad_phase": s.contact.broad_phase,
        "phases": {"approach": 0.0, **{k: v for k, v in times.items()}},
        "grasps": [grasp],
        "momentum": {
            "linear_drift_rel": drift_lin,
            "angular_drift_rel": drift_ang,
            "definition": "max over the run of |momentum - initial - impulse of the contact forces "
                          "and gravity| of the module, relative to its largest momentum (angular "
                          "about the world origin); the base is fixed, so momentum is not conserved",
        },
        "spheres": {"finger": int(len(model.master.centres_J)), "groove": int(len(model.slave.centres_J))},
        "warnings": tolerance_warnings(s),
    }


def initial_contacts(model: Model) -> int:
    """Sphere pairs already in contact at the start, by the literal all-pairs search.

    The literal search finds pairs at any depth, where the grid search only looks as deep
    as a run may go before it is declared diverged.
    """
    from .step import kinematics, literal_pairs

    data = make_data(model)
    kinematics(model, data)
    return len(literal_pairs(model, data)[0])


def check_start(model: Model, source: str) -> None:
    """Reject a scenario whose fingers and groove interpenetrate at the start."""
    from .errors import ScenarioError

    n = initial_contacts(model)
    if n:
        s = model.scenario
        raise ScenarioError([
            f"{source}: module.initial_offset_mm = {list(s.module.initial_offset_mm)}: fingers and "
            f"groove interpenetrate at the start ({n} sphere pairs); widen end_effector.start_gap_mm "
            f"= {s.end_effector.start_gap_mm} or move the module"])
