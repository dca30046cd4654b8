"""The run loop: step the scene through its grasp sequence, weld, record, and report."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from . import compiled
from .contact.forces import raise_peaks
from .contact.friction import SLIPPING, STICKING
from .grasp import COMPLETE, PHASES, SELF_CENTRING
from .contact.search import FacePair
from .integrators import StepSizeUnderflow, make_integrator
from .model import Model, build_model, grasp_frame, groove_frame
from .scenario import tolerance_warnings
from .stability import ENERGY_FLOOR_J, ENERGY_GROWTH, mechanical_energy, stability_warnings
from .step import StateOverflow, completion_inputs, free_flight, make_data, step
from .weld import twist_for_momentum, world_momentum

COMPLETED, INCOMPLETE, DIVERGED, INTERRUPTED = "completed", "incomplete", "diverged", "interrupted"
NO_WRENCH = np.zeros(3)

#: Contact snapshots per simulated second kept for `spotsim replay`: its highest display rate.
#: 100 Hz is ten samples of a 10 ms bounce; a snapshot takes ~50 us, under 0.5 % of a Case I
#: or dual-arm run's wall time with the compiled step.
REPLAY_RATE_HZ = 100.0


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


def refresh_kinematics(model: Model, data) -> None:
    """Joint placements and velocities of the current (q, v): a step leaves those of its start."""
    pin.forwardKinematics(model.pin_model, data.pin_data, data.q, data.v)


def body_momentum_W(model: Model, data, j: int) -> pin.Force:
    """Spatial momentum of the body of joint j, world axes, about the world origin.

    Reads the kinematics in data.pin_data: call refresh_kinematics first.
    """
    return world_momentum(data.pin_data.oMi[j], model.pin_model.inertias[j], data.pin_data.v[j])


def free_momentum_W(model: Model, data) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Total linear and angular momentum (about the world origin) of the free bodies, and the
    largest single body's linear and angular momentum magnitudes. From (q, v) directly."""
    return model.momentum_call(model.bodies, model.all_bodies, data.q, data.v)[:4]


def centroid_W(model: Model, data, joints) -> np.ndarray:
    """Centroid (world) of the free bodies of `joints`, from q."""
    joints = tuple(joints)
    rows = model.row_cache.get(joints)
    if rows is None:
        rows = model.row_cache[joints] = np.array([model.body_row[j] for j in joints], dtype=np.int64)
    return model.momentum_call(model.bodies, rows, data.q, data.v)[4]


class Recorder:
    """Samples the state at every recorded step and keeps per-grasp peaks over every substep.

    The model may change (a weld): quantities are recorded by name, per module and per
    end-effector of the first model.
    """

    def __init__(self, model: Model):
        self.first = model
        self.fingers = [f.name for f in model.fingers]
        self.last_opening = {f.name: f.opening_start for f in model.fingers}
        self.rows: dict[str, list] = {k: [] for k in (
            "t", "module_pos_m", "module_quat_xyzw", "offset_mm", "rpy_deg", "module_vel_m_s",
            "module_omega_rad_s", "force_N", "torque_Nm", "finger_opening_mm", "finger_load_N",
            "pairs_slipping", "pairs_sticking", "phase", "grasp", "max_penetration_um")}
        if model.robot_joint:
            for k in ("robot_centroid_m", "base_pos_m", "base_quat_xyzw", "system_centroid_m"):
                self.rows[k] = []
            for mod in model.modules:
                self.rows[f"{mod.name}_pos_m"] = []
                self.rows[f"{mod.name}_quat_xyzw"] = []
            for ee in model.end_effectors:
                self.rows[f"{ee.name}_pos_m"] = []
        # norms: the peak |force| and |torque|
        self.peaks = [dict(force=np.zeros(3), torque=np.zeros(3), norms=np.zeros(2), pairs=0) for _ in model.grasps]
        self.force_a = np.zeros(3)
        self.torque_a = np.zeros(3)
        # the replay's contact snapshots, every `replay_every`-th sample: spheres by their index
        # in the first model, so that a weld (a new model) does not renumber them
        self.replay_every = max(1, int(round(1.0 / (REPLAY_RATE_HZ * model.scenario.simulation.dt_s))))
        self.face_names = face_names(model)
        self.snapshots: dict[str, list] = {k: [] for k in (
            "row", "pairs", "master", "slave", "state", "faces_in_range", "force_W")}
        self._ids = (None, None)  # (model, its SphereIds in the first model)

    def substep(self, model: Model, data, n_pairs: int) -> None:
        if n_pairs == 0:
            self.force_a = self.torque_a = NO_WRENCH  # never written to
            return
        # the combined wrench on the active module, in O_a: force, and moment about its centroid
        self.force_a, self.torque_a = data.summary[:3], data.summary[3:6]
        p = self.peaks[data.active]
        raise_peaks(p["force"], p["torque"], p["norms"], data.summary)
        p["pairs"] = max(p["pairs"], n_pairs)

    def sample(self, model: Model, data) -> None:
        """Record the state; data.pin_data must hold the kinematics of (q, v)."""
        r = self.rows
        ee, k = model.grasps[data.active]
        grooves = [groove_frame(model, data.pin_data, i) for i in range(len(model.modules))]
        grasps = [grasp_frame(model, data.pin_data, i) for i in range(len(model.end_effectors))]
        oMa, oMb = grasps[ee], grooves[k]
        aMb = oMa.actInv(oMb)
        j = model.modules[k].joint
        nu = data.pin_data.v[j]
        R_j = data.pin_data.oMi[j].rotation
        c = data.contacts
        states = np.bincount(c.state, minlength=3) if c is not None and len(c.key) else np.zeros(3, int)
        names = [f.name for f in model.fingers]
        for i, name in enumerate(names):
            self.last_opening[name] = data.opening[i]
        r["t"].append(data.t)
        r["module_pos_m"].append(oMb.translation.copy())
        r["module_quat_xyzw"].append(pin.SE3ToXYZQUAT(oMb)[3:])
        r["offset_mm"].append(aMb.translation * 1e3)
        r["rpy_deg"].append(np.degrees(pin.rpy.matrixToRpy(aMb.rotation)))
        r["module_vel_m_s"].append(R_j @ nu.linear)
        r["module_omega_rad_s"].append(R_j @ nu.angular)
        r["force_N"].append(self.force_a)
        r["torque_Nm"].append(self.torque_a)
        r["finger_opening_mm"].append([self.last_opening[n] * 1e3 for n in self.fingers])
        r["finger_load_N"].append([data.finger_load[names.index(n)] if n in names else 0.0 for n in self.fingers])
        r["pairs_slipping"].append(states[SLIPPING])
        r["pairs_sticking"].append(states[STICKING])
        r["phase"].append(PHASES.index(data.phase.phase))
        r["grasp"].append(data.active)
        r["max_penetration_um"].append(data.summary[7] * 1e6 if c is not None and len(c.key) else 0.0)
        if model.robot_joint:
            base = data.pin_data.oMi[model.robot_joint]
            r["robot_centroid_m"].append(centroid_W(model, data, [model.robot_joint]))
            r["base_pos_m"].append(base.translation.copy())
            r["base_quat_xyzw"].append(pin.SE3ToXYZQUAT(base)[3:])
            r["system_centroid_m"].append(centroid_W(model, data, model.free_joints))
            for mod, M in zip(model.modules, grooves, strict=True):
                r[f"{mod.name}_pos_m"].append(M.translation.copy())
                r[f"{mod.name}_quat_xyzw"].append(pin.SE3ToXYZQUAT(M)[3:])
            for e, M in zip(model.end_effectors, grasps, strict=True):
                r[f"{e.name}_pos_m"].append(M.translation.copy())
        if (len(r["t"]) - 1) % self.replay_every == 0:
            self.snapshot(model, data, len(r["t"]) - 1)

    def snapshot(self, model: Model, data, row: int) -> None:
        """Keep what the replay draws at sample `row`: the pairs in contact (their spheres and
        states), the faces in contact range and each module's combined contact force (world)."""
        if self._ids[0] is not model:
            self._ids = (model, SphereIds(model, self.first, self.face_names))
        ids = self._ids[1]
        s, c = self.snapshots, data.contacts
        n = 0 if c is None or c.state is None else len(c.state)
        in_range = np.zeros(len(self.face_names[0]) + len(self.face_names[1]), dtype=bool)
        if n:
            s["master"].append(ids.master[c.master].astype(np.int32))
            s["slave"].append(ids.slave[c.slave].astype(np.int32))
            s["state"].append(c.state.astype(np.int8))
            in_range[ids.master_face[model.master.face[c.master]]] = True
            in_range[ids.slave_face[model.slave.face[c.slave]]] = True
        # coal's face pairs within the security margin (the last broad phase's)
        near = ids.near(data.near_pairs)
        in_range[ids.pair_faces[near]] = True
        F = np.zeros((len(self.first.modules), 3))
        for k, mod in enumerate(model.modules):
            if mod.joint:  # a welded module takes no contact
                F[k] = data.joint_force_W[mod.joint]
        s["row"].append(row)
        s["pairs"].append(n)
        s["faces_in_range"].append(in_range)
        s["force_W"].append(F)

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(v) for k, v in self.rows.items()}

    def replay_arrays(self) -> dict[str, np.ndarray]:
        """The snapshots as the arrays of replay.npz (pairs of all snapshots concatenated)."""
        s = self.snapshots
        cat = {k: np.concatenate(s[k]) if s[k] else np.zeros(0, dtype) for k, dtype in
               (("master", np.int32), ("slave", np.int32), ("state", np.int8))}
        return {
            "rate_hz": np.float64(REPLAY_RATE_HZ),
            "row": np.asarray(s["row"], dtype=np.int64),
            "pairs_end": np.cumsum(s["pairs"], dtype=np.int64),
            **cat,
            "faces_in_range": np.asarray(s["faces_in_range"], dtype=bool).reshape(len(s["row"]), -1),
            "force_W": np.asarray(s["force_W"], dtype=float).reshape(len(s["row"]), -1, 3),
            "master_faces": np.asarray(self.face_names[0]),
            "slave_faces": np.asarray(self.face_names[1]),
        }


def face_names(model: Model) -> tuple[list[str], list[str]]:
    """The names of the master and of the slave faces, in the order of their layers' `face`
    index: each face is one coal patch, added in that order (masters are `finger_geoms`)."""
    objects = model.geom_model.geometryObjects
    masters = [g for g, _ in model.finger_geoms]
    slaves = [g for g in range(len(objects)) if g not in set(masters)]
    return [objects[g].name for g in masters], [objects[g].name for g in slaves]


class SphereIds:
    """Where a model's spheres and faces sit in the first model's layers (found by face name).

    A weld rebuilds the scene without the welded pair's faces; the faces left keep their
    spheres, in the same order on the same joint frames.
    master, slave: (n,) first-model index of each sphere. master_face, slave_face: first-model
    face index of each face, the slave faces numbered after the master ones. pair_faces:
    (n_face_pairs, 2) the two faces of each of the model's face pairs, so numbered.
    """

    def __init__(self, model: Model, first: Model, first_names: tuple[list[str], list[str]]):
        names = face_names(model)
        offsets = (0, len(first_names[0]))
        maps = []
        for role, layers, first_layers in ((0, model.master, first.master), (1, model.slave, first.slave)):
            face = np.array([first_names[role].index(n) for n in names[role]], dtype=np.int64)
            start = np.searchsorted(layers.face, np.arange(len(names[role])))
            first_start = np.searchsorted(first_layers.face, np.arange(len(first_names[role])))
            local = np.arange(len(layers.face)) - start[layers.face]
            maps.append((first_start[face[layers.face]] + local, face + offsets[role]))
        (self.master, self.master_face), (self.slave, self.slave_face) = maps
        self.pair_faces = np.array([[self.master_face[model.master.face[fp.master_slice.start]],
                                     self.slave_face[fp.slave.face]] for fp in model.face_pairs],
                                   dtype=np.int64).reshape(-1, 2)

    @staticmethod
    def near(near_pairs) -> np.ndarray:
        """Indices into model.face_pairs of the broad phase's face pairs (none before its first
        run, or with the all-pairs search)."""
        if near_pairs is None or len(near_pairs) == 0:
            return np.zeros(0, dtype=np.int64)
        if isinstance(near_pairs[0], FacePair):
            return np.array([fp.geom_pair for fp in near_pairs], dtype=np.int64)  # its index
        return np.asarray(near_pairs, dtype=np.int64)


def weld(model: Model, data, source: str):
    """Weld the active grasp's module to its end-effector and return the new (model, data).

    The module's free-flyer is replaced by a fixed joint at its current pose in the grasp
    frame, and the composite body gets the twist that keeps the pair's linear and angular
    momentum: Y_new^-1 (h_robot + h_module), with Y_new the new model's composite inertia.
    """
    ee, k = model.grasps[data.active]
    refresh_kinematics(model, data)
    aMb = grasp_frame(model, data.pin_data, ee).actInv(groove_frame(model, data.pin_data, k))
    welded = {i: (xyz, rpy) for i, xyz, rpy in model.spec.welded}
    welded[k] = (aMb.translation, pin.rpy.matrixToRpy(aMb.rotation))
    new = build_model(model.scenario, source, welded=welded)
    new_data = make_data(new)
    pm, nm = model.pin_model, new.pin_model
    # configurations by joint name; the robot's twist from the momentum of robot + module
    for j in range(1, nm.njoints):
        old = pm.getJointId(nm.names[j])
        new_data.q[nm.idx_qs[j]:nm.idx_qs[j] + nm.nqs[j]] = data.q[pm.idx_qs[old]:pm.idx_qs[old] + pm.nqs[old]]
        new_data.v[nm.idx_vs[j]:nm.idx_vs[j] + nm.nvs[j]] = data.v[pm.idx_vs[old]:pm.idx_vs[old] + pm.nvs[old]]
    r_old, m_old = model.robot_joint, model.modules[k].joint
    h_W = body_momentum_W(model, data, r_old) + body_momentum_W(model, data, m_old)
    r_new = new.robot_joint
    iv = nm.idx_vs[r_new]
    # the robot's frame is kept by the weld; its new inertia is the composite's
    new_data.v[iv:iv + 6] = twist_for_momentum(data.pin_data.oMi[r_old], nm.inertias[r_new], h_W).vector
    new_data.t = data.t
    new_data.phases, new_data.active = data.phases, data.active + 1
    new_data.drives = data.drives
    names = [f.name for f in model.fingers]
    for i, f in enumerate(new.fingers):
        new_data.opening[i] = data.opening[names.index(f.name)]
        new_data.opening_rate[i] = 0.0
    return new, new_data


def simulate(scenario, *, model: Model | None = None, progress: bool = False,
             source: str = "<scenario>") -> Result:
    """Run a scenario's grasps in sequence to completion, divergence or time-out.

    Never raises on physics. progress: a progress bar (tqdm) on stderr. Ctrl-C ends the run
    with status `interrupted` and keeps what was recorded.
    """
    model = model or build_model(scenario, source)
    check_start(model, source)
    sim = scenario.simulation
    h_contact = sim.dt_s / sim.substeps
    n_records = int(round(sim.duration_s / sim.dt_s))
    integrator = make_integrator(sim.integrator, model.pin_model)
    data = make_data(model)
    rec = Recorder(model)
    refresh_kinematics(model, data)
    P0, L0, p_max, l_max = free_momentum_W(model, data)
    J, JL = np.zeros(3), np.zeros(3)
    fixed_contact = model.fixed_contact
    g_W = np.array(sim.gravity_m_s2)
    gravity = bool(np.any(g_W))
    drift_lin = drift_ang = 0.0
    max_phi = min(model.params.r1, model.params.r2)
    status, message = INCOMPLETE, ""
    starts = [0.0]  # when each grasp's drive started
    welds, retired = [], []  # the integrators' counts of the models before each weld
    e_passive = None  # mechanical energy when the current passive phase began, J
    rec.sample(model, data)
    bar = progress_bar(n_records, progress)
    wall0 = time.perf_counter()
    steps = free_steps = pair_steps = 0
    try:
        for _ in range(n_records):
            # nothing can touch before the next record (zero gravity): one step to it; else
            # the dynamics substeps
            try:
                flight = not gravity and free_flight(model, data, sim.dt_s)
            except StateOverflow as e:  # its broad phase met a state coal cannot bound
                status, message = DIVERGED, f"{e} at t = {data.t:.4f} s"
                break
            free_steps += flight
            # the active drive held the fingers still through every step of this interval
            held = data.drives[model.grasps[data.active][0]].stalled
            if compiled.applies(model, integrator):  # the interval's steps in one compiled call
                n, h = (1, sim.dt_s) if flight else (sim.substeps, h_contact)
                try:
                    n_steps, n_pairs, event, held = compiled.run_substeps(
                        model, data, n, h, rec.peaks[data.active], J, JL, starts[-1],
                        scenario.completion.phase_timeout_s, max_phi, held)
                except StateOverflow as e:
                    status, message = DIVERGED, f"{e} at t = {data.t:.4f} s"
                    break
                steps += n_steps
                pair_steps += n_pairs
                rec.substep(model, data, len(data.contacts.key))
                if event == compiled.TOO_DEEP:
                    status, message = DIVERGED, _too_deep(data, max_phi)
            else:  # step by step
                for h in _step_sizes(integrator, data, flight, sim.dt_s, h_contact, sim.substeps):
                    t_start = data.t
                    try:
                        c = step(model, data, h, integrator)
                    except (StateOverflow, StepSizeUnderflow) as e:
                        status, message = DIVERGED, f"{e} at t = {data.t:.4f} s"
                        break
                    h = data.t - t_start  # an adaptive step may be shorter than asked
                    held = held and data.drives[model.grasps[data.active][0]].stalled
                    steps += 1
                    n = len(c.key)
                    pair_steps += n
                    rec.substep(model, data, n)
                    # impulse of the external forces on the free bodies: the contact forces from
                    # fixed bodies (a fixed base) and gravity
                    if fixed_contact:  # between free bodies every contact force is internal
                        J += h * data.external_force_W
                        JL += h * data.external_torque_O_W
                    if gravity:
                        for j in model.free_joints:
                            m_j = model.pin_model.inertias[j].mass
                            r_G = data.p_W[j] + data.R_W[j] @ model.pin_model.inertias[j].lever
                            J += h * m_j * g_W
                            JL += h * np.cross(r_G, m_j * g_W)
                    if n and data.summary[7] > max_phi:
                        status, message = DIVERGED, _too_deep(data, max_phi)
                        break
                    if data.phase.phase == COMPLETE or data.t - starts[-1] > scenario.completion.phase_timeout_s:
                        break
            # a NaN or an infinity anywhere makes the sum non-finite; checked once a record
            if status != DIVERGED and not math.isfinite(data.q.sum() + data.v.sum()):
                status = DIVERGED
                message = f"state became non-finite by t = {data.t:.4f} s"
            if status == DIVERGED:
                break
            # a passive phase (the drive holding the fingers through the whole interval) may
            # not gain energy
            if held:
                E = mechanical_energy(model, data)
                if e_passive is None:
                    e_passive = E
                elif E > ENERGY_GROWTH * e_passive + ENERGY_FLOOR_J:
                    status = DIVERGED
                    message = (f"energy grew from {e_passive:.3g} J to {E:.3g} J while the drive held "
                               f"the fingers (a passive phase) at t = {data.t:.4f} s")
            else:
                e_passive = None
            refresh_kinematics(model, data)
            rec.sample(model, data)
            P, L, p_b, l_b = free_momentum_W(model, data)
            p_max, l_max = max(p_max, p_b), max(l_max, l_b)
            drift_lin = max(drift_lin, math.hypot(*(P - P0 - J)))
            drift_ang = max(drift_ang, math.hypot(*(L - L0 - JL)))
            bar.update(1)
            if status == DIVERGED:  # the energy check; the record above is kept
                break
            if data.phase.phase == COMPLETE:
                if data.active + 1 == len(model.grasps):
                    status = COMPLETED
                    message = f"{'all grasps' if len(model.grasps) > 1 else 'grasp'} complete at t = {data.t:.4f} s"
                    break
                model, data = weld(model, data, source)
                welds.append(data.t)
                retired.append(integrator.stats())
                integrator = make_integrator(sim.integrator, model.pin_model)
                fixed_contact = model.fixed_contact
                starts.append(data.t)
                e_passive = None
                refresh_kinematics(model, data)
            elif data.t - starts[-1] > scenario.completion.phase_timeout_s:
                message = _why_incomplete(model, data, "the phase time-out")
                break
        else:
            message = _why_incomplete(model, data, "the time-out")
    except KeyboardInterrupt:
        status, message = INTERRUPTED, f"interrupted by the user at t = {data.t:.4f} s"
    finally:
        bar.close()
    wall = time.perf_counter() - wall0
    series = rec.arrays()
    integrator_stats = integrator.stats()
    for old in retired:
        for k, value in old.items():
            if k != "method":
                integrator_stats[k] += value
    summary = _summary(scenario, model, data, rec, series, status, message, wall, steps, free_steps,
                       pair_steps, h_contact, starts, welds, drift_lin / max(p_max, 1e-300),
                       drift_ang / max(l_max, 1e-300), integrator_stats)
    return Result(scenario, model, summary, series, rec.replay_arrays())


def _too_deep(data, max_phi: float) -> str:
    return (f"penetration {data.summary[7] * 1e3:.3f} mm exceeds the sphere radius {max_phi * 1e3:.3f} mm "
            f"at t = {data.t:.4f} s")


def _step_sizes(integrator, data, flight: bool, dt: float, h: float, substeps: int):
    """The steps to try over one record interval of dt: one (free flight), `substeps` of h, or
    an adaptive integrator's own until the interval is covered."""
    if flight:
        yield dt
    elif not integrator.adaptive:
        yield from (h,) * substeps
    else:
        t_end = data.t + dt
        while t_end - data.t > 1e-9 * dt:
            yield min(integrator.h or h, t_end - data.t)


def progress_bar(total: int, enabled: bool, what: str = "simulating", unit: str = "ms"):
    """A progress bar on stderr; when not enabled, or stderr is not a terminal (CI logs,
    pipes), a disabled one whose calls do nothing."""
    from tqdm import tqdm

    return tqdm(total=total, unit=unit, desc=what, leave=False, disable=None if enabled else True)


def _why_incomplete(model: Model, data, limit: str) -> str:
    t = data.t
    ee, k = model.grasps[data.active]
    who = f"{model.end_effectors[ee].name} on {model.modules[k].name}"
    if data.phase.phase != SELF_CENTRING:
        return f"{who}: no contact by {limit} t = {t:.3f} s: the fingers never reached the groove"
    c = data.contacts
    criteria = data.phase.criteria(*completion_inputs(model, data))
    unmet = [name for name, ok in criteria.items() if not ok]
    if not len(c.key):
        unmet.insert(0, "contact lost")
    return (f"{who}: self-centring did not complete by {limit} t = {t:.3f} s; "
            f"unmet at the end: {'; '.join(unmet) or 'criteria not held for hold_s'}")


def _summary(s, model, data, rec, series, status, message, wall, steps, free_steps, pair_steps, h, starts,
             welds, drift_lin, drift_ang, integrator_stats):
    grasps = []
    for g, (ee, k) in enumerate(model.grasps):
        times = data.phases[g].times
        completed = times.get(COMPLETE)
        rows = np.flatnonzero(series["grasp"] == g)
        last = rows[-1] if len(rows) else None
        done = completed is not None and last is not None
        offset = series["offset_mm"][last] if done else None
        peak = rec.peaks[g]
        entry = {
            "end_effector": model.end_effectors[ee].name,
            "module": model.modules[k].name,
            "started_s": starts[g] if g < len(starts) else None,
            "contact_onset_s": times.get(SELF_CENTRING),
            "completed_s": completed,
            "residual_offset_mm": None if offset is None else [float(x) for x in offset],
            "residual_offset_norm_mm": None if offset is None else float(np.linalg.norm(offset)),
            "residual_rpy_deg": None if not done else [float(x) for x in series["rpy_deg"][last]],
            "peak_force_N": [float(x) for x in peak["force"]],
            "peak_torque_Nm": [float(x) for x in peak["torque"]],
            "peak_force_norm_N": float(peak["norms"][0]),
            "peak_torque_norm_Nm": float(peak["norms"][1]),
            "max_active_pairs": int(peak["pairs"]),
            "final_offset_mm": None if last is None else [float(x) for x in series["offset_mm"][last]],
        }
        if "robot_centroid_m" in series and len(rows):
            # the FDR centroid's displacement over this grasp: from its drive's start to its
            # completion (or the end of the record), taken within one body (the FDR in the
            # first grasp, the FDR + TM-1 composite after the weld)
            d = series["robot_centroid_m"][last] - series["robot_centroid_m"][rows[0]]
            entry["robot_centroid_displacement_mm"] = [float(x) for x in d * 1e3]
        grasps.append(entry)
    free = bool(model.robot_joint)
    return {
        "scenario": s.name,
        "status": status,
        "message": message,
        "wall_time_s": wall,
        "sim_time_s": data.t,
        "steps": steps,
        "pair_steps": pair_steps,  # sphere pairs in contact, summed over the steps
        "dt_s": s.simulation.dt_s,
        "substeps": s.simulation.substeps,
        "dynamics_dt_s": h,
        # steps of a whole record interval, taken where no contact could start within it
        "free_flight_steps": free_steps,
        "integrator": integrator_stats,
        "broad_phase": s.contact.broad_phase,
        "phases": {"approach": 0.0, **data.phases[0].times} if len(model.grasps) == 1 else
        [{"approach": starts[g] if g < len(starts) else None, **data.phases[g].times}
         for g in range(len(model.grasps))],
        "welds_s": welds,
        "grasps": grasps,
        "momentum": {
            "linear_drift_rel": drift_lin,
            "angular_drift_rel": drift_ang,
            "definition": (
                "max over the run of |total momentum of the free bodies - initial|, relative to "
                "the largest single body's momentum (angular about the world origin); the robot "
                "floats freely, so momentum is conserved" if free else
                "max over the run of |momentum - initial - impulse of the contact forces and "
                "gravity| of the module, relative to its largest momentum (angular about the "
                "world origin); the base is fixed, so momentum is not conserved"),
        },
        "spheres": {"finger": int(len(model.master.centres_J)), "groove": int(len(model.slave.centres_J))},
        "fingers": rec.fingers,
        "warnings": tolerance_warnings(s) + stability_warnings(model),
    }


def initial_contacts(model: Model) -> int:
    """Sphere pairs already in contact at the start, by the literal all-pairs search.

    The literal search finds pairs at any depth, where the grid search only looks as deep
    as a run may go before it is declared diverged.
    """
    from .step import broad_phase, kinematics, literal_pairs

    data = make_data(model)
    kinematics(model, data)
    # spheres of faces whose patches coal finds apart by more than the margin do not touch
    if model.params.broad_phase == "coal" and not len(broad_phase(model, data)):
        return 0
    return len(literal_pairs(model, data)[0])


def check_start(model: Model, source: str) -> None:
    """Reject a scenario whose fingers and groove interpenetrate at the start."""
    from .errors import ScenarioError
    from .scenario import modules_of

    n = initial_contacts(model)
    if n:
        s = model.scenario
        offsets = "; ".join(f"{k}.initial_offset_mm = {list(m.initial_offset_mm)}"
                            for k, m in modules_of(s).items())
        raise ScenarioError([
            f"{source}: {offsets}: fingers and groove interpenetrate at the start ({n} sphere "
            f"pairs); widen end_effector.start_gap_mm = {s.end_effector.start_gap_mm} or move "
            f"the module"])
