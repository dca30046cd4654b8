"""The run loop: step the scene through its grasp sequence, weld, record, and report."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from . import compiled
from .contact.forces import raise_peaks
from .grasp import COMPLETE, PHASES, SELF_CENTRING
from .contact.search import FacePair
from .integrators import StepSizeUnderflow, make_integrator
from .model import Model, build_model, grasp_frame, groove_frame
from .scenario import tolerance_warnings
from .jit import direct
from .record import (DRIFT_ANG, DRIFT_LIN, DRIVE_WORK, E_NOW, E_PASSIVE, E_START, ENERGY, ENERGY_WORK, L_MAX,
                     N_RECORD_STATE, NONFINITE, OK, P_MAX, Layout, close_interval, record_args, sample, start_record)
from .stability import ENERGY_GROWTH, stability_warnings
from .step import StateOverflow, completion_inputs, free_flight, make_data, step
from .weld import twist_for_momentum, world_momentum

COMPLETED, INCOMPLETE, DIVERGED, INTERRUPTED = "completed", "incomplete", "diverged", "interrupted"
NO_PHI = np.zeros(0)
NO_STATES = np.zeros(0, dtype=np.int64)

#: Contact snapshots per simulated second kept for `spotsim replay`: its highest display rate.
#: 100 Hz is ten samples of a 10 ms bounce. The compiled loop copies each snapshot's pairs in
#: place (`compiled.intervals`), so they cost it no return to Python.
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


class Recorder:
    """Records a row at the end of every record interval (`record.close_interval`) and keeps
    per-grasp peaks over every substep and the replay's contact snapshots.

    The model may change (a weld): quantities are recorded by name, per module and per
    end-effector of the first model (`record.Layout`).
    """

    def __init__(self, model: Model):
        self.first = model
        self.layout = Layout(model)
        self.fingers = self.layout.fingers
        self.last_open = np.array([f.opening_start for f in model.fingers], dtype=float)
        self.chunks: list[np.ndarray] = []  # rows, (n, layout.width) each
        self.n_rows = 0
        self.state = np.zeros(N_RECORD_STATE)  # record.close_interval's: energy, momentum balance
        self.buffer = np.empty((1, self.layout.width))
        # norms: the peak |force| and |torque|
        self.peaks = [dict(force=np.zeros(3), torque=np.zeros(3), norms=np.zeros(2), pairs=0) for _ in model.grasps]
        # the replay's contact snapshots, every `replay_every`-th sample, as chunks of samples:
        # spheres by their index in the first model, so that a weld (a new model) does not
        # renumber them
        self.replay_every = max(1, int(round(1.0 / (REPLAY_RATE_HZ * model.scenario.simulation.dt_s))))
        self.face_names = face_names(model)
        self.snapshots: dict[str, list] = {k: [] for k in (
            "row", "pairs", "master", "slave", "state", "faces_in_range", "force_W")}
        self._ids = (None, None)  # (model, its SphereIds in the first model)
        self._args = (None, None)  # (model, its record.record_args)
        self._sample, self._close = direct(sample), direct(close_interval)

    def args(self, model: Model) -> tuple:
        """`record.record_args` of `model` (the current one)."""
        if self._args[0] is not model:
            self._args = (model, record_args(model, self.layout))
        return self._args[1]

    def substep(self, model: Model, data, n_pairs: int) -> None:
        """Raise the active grasp's peaks by a step's contact wrench (step-by-step path)."""
        if n_pairs:
            p = self.peaks[data.active]
            raise_peaks(p["force"], p["torque"], p["norms"], data.summary)
            p["pairs"] = max(p["pairs"], n_pairs)

    def start(self, model: Model, data) -> None:
        """The first row, and the momentum the balance starts from."""
        start_record(self.state, data.q, data.v, self.args(model))
        row = self.buffer[0]
        self._sample(row, float(data.t), data.q, data.v, data.summary, 0, NO_STATES, data.opening,
                     data.finger_load, self.last_open, PHASES.index(data.phase.phase), data.active,
                     *model.grasps[data.active], self.args(model))
        self.add_rows(model, data, self.buffer[:1])

    def close(self, model: Model, data, held: bool, J: np.ndarray, JL: np.ndarray) -> int:
        """`record.close_interval` on data's state: OK, NONFINITE (nothing recorded) or ENERGY."""
        c = data.contacts
        n = len(c.key)
        code = self._close(self.buffer[0], self.state, J, JL, held, float(data.t), data.q, data.v,
                           c.phi if n else NO_PHI, data.mem_s, data.summary, n, c.state if n else NO_STATES,
                           data.opening, data.finger_load, self.last_open, PHASES.index(data.phase.phase),
                           data.active, *model.grasps[data.active], self.args(model))
        if code != NONFINITE:
            self.add_rows(model, data, self.buffer[:1])
        return code

    def add_rows(self, model: Model, data, rows: np.ndarray, snapshots: tuple | None = None) -> None:
        """Keep rows (n, width), the last of them data's state, and the replay's snapshots:
        those the compiled loop took of these rows (`compiled.intervals`), else data's if the
        last row is due for one."""
        if not len(rows):
            return
        self.chunks.append(rows.copy())
        self.n_rows += len(rows)
        if snapshots is not None:
            self.add_snapshots(model, data.near_pairs, *snapshots)
        elif (self.n_rows - 1) % self.replay_every == 0:
            self.snapshot(model, data, self.n_rows - 1)

    @property
    def momentum_drift(self) -> tuple[float, float]:
        """The largest drift of the free bodies' linear and angular momentum, relative to the
        largest single body's (`record.close_interval`)."""
        s = self.state
        return s[DRIFT_LIN] / max(s[P_MAX], 1e-300), s[DRIFT_ANG] / max(s[L_MAX], 1e-300)

    def snapshot(self, model: Model, data, row: int) -> None:
        """Keep what the replay draws at sample `row`, from data's last step (`add_snapshots`)."""
        c = data.contacts
        n = 0 if c is None or c.state is None else len(c.state)
        force_W = np.zeros((1, len(self.first.modules), 3))
        for k, mod in enumerate(model.modules):
            if mod.joint:  # a welded module takes no contact
                force_W[0, k] = data.joint_force_W[mod.joint]
        pairs = (c.master, c.slave, c.state) if n else (NO_STATES,) * 3
        self.add_snapshots(model, data.near_pairs, np.array([row]), np.array([n]), force_W, *pairs)

    def add_snapshots(self, model: Model, near_pairs, rows: np.ndarray, pairs: np.ndarray, force_W: np.ndarray,
                      master: np.ndarray, slave: np.ndarray, state: np.ndarray) -> None:
        """Keep what the replay draws at samples rows (n,): the pairs in contact (pairs (n,)
        of them at each; their master and slave spheres and states, all concatenated), the
        faces in contact range and each module's combined contact force, (n, n_modules, 3),
        world. near_pairs: the broad phase's face pairs, the same at all these samples."""
        if self._ids[0] is not model:
            self._ids = (model, SphereIds(model, self.first, self.face_names))
        ids = self._ids[1]
        s = self.snapshots
        in_range = np.zeros((len(rows), len(self.face_names[0]) + len(self.face_names[1])), dtype=bool)
        # coal's face pairs within the security margin (the last broad phase's)
        in_range[:, ids.pair_faces[ids.near(near_pairs)].ravel()] = True
        sample = np.repeat(np.arange(len(rows)), pairs)
        in_range[sample, ids.master_face[model.master.face[master]]] = True
        in_range[sample, ids.slave_face[model.slave.face[slave]]] = True
        s["master"].append(ids.master[master].astype(np.int32))
        s["slave"].append(ids.slave[slave].astype(np.int32))
        s["state"].append(state.astype(np.int8))
        s["row"].append(np.asarray(rows, dtype=np.int64))
        s["pairs"].append(np.asarray(pairs, dtype=np.int64))
        s["faces_in_range"].append(in_range)
        s["force_W"].append(np.asarray(force_W, dtype=float))

    def arrays(self) -> dict[str, np.ndarray]:
        rows = np.concatenate(self.chunks) if self.chunks else np.zeros((0, self.layout.width))
        return self.layout.split(rows)

    def replay_arrays(self) -> dict[str, np.ndarray]:
        """The snapshots as the arrays of replay.npz (pairs of all snapshots concatenated)."""
        s = self.snapshots
        n_faces = len(self.face_names[0]) + len(self.face_names[1])
        cat = {k: np.concatenate(s[k]) if s[k] else np.zeros(shape, dtype) for k, shape, dtype in (
            ("master", 0, np.int32), ("slave", 0, np.int32), ("state", 0, np.int8), ("row", 0, np.int64),
            ("pairs", 0, np.int64), ("faces_in_range", (0, n_faces), bool),
            ("force_W", (0, len(self.first.modules), 3), float))}
        return {
            "rate_hz": np.float64(REPLAY_RATE_HZ),
            "row": cat["row"],
            "pairs_end": np.cumsum(cat["pairs"], dtype=np.int64),
            **{k: cat[k] for k in ("master", "slave", "state", "faces_in_range", "force_W")},
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
    # the XACRO is not compiled again, nor the contact faces parsed again
    new = build_model(model.scenario, source, welded=welded, urdf=model.urdf, faces=model.faces)
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
    J, JL = np.zeros(3), np.zeros(3)
    fixed_contact = model.fixed_contact
    g_W = np.array(sim.gravity_m_s2)
    gravity = bool(np.any(g_W))
    max_phi = min(model.params.r1, model.params.r2)
    timeout = scenario.completion.phase_timeout_s
    status, message = INCOMPLETE, ""
    starts = [0.0]  # when each grasp's drive started
    welds, retired = [], []  # the integrators' counts of the models before each weld
    rec.start(model, data)
    bar = progress_bar(n_records, progress)
    wall0 = time.perf_counter()
    steps = free_steps = pair_steps = 0
    done = 0  # record intervals taken
    try:
        while done < n_records:
            if compiled.applies(model, integrator):  # many intervals in one call
                event, n_rows, n_steps, n_pairs, n_free, overflow = compiled.run_records(
                    model, data, min(n_records - done, compiled.RECORDS_PER_CALL), rec, J, JL, starts[-1], timeout,
                    max_phi)
                steps += n_steps
                pair_steps += n_pairs
                free_steps += n_free
                code = {compiled.NONFINITE: NONFINITE, compiled.ENERGY: ENERGY,
                        compiled.ENERGY_WORK: ENERGY_WORK}.get(event, OK)
                if event == compiled.TOO_DEEP:
                    status, message = DIVERGED, _too_deep(data, max_phi)
                elif event == compiled.OVERFLOW:  # its broad phase met a state coal cannot bound
                    status, message = DIVERGED, f"{overflow} at t = {data.t:.4f} s"
            else:  # one interval step by step
                # nothing can touch before the next record (zero gravity): one step to it; else
                # the dynamics substeps
                try:
                    flight = not gravity and free_flight(model, data, sim.dt_s)
                except StateOverflow as e:
                    status, message = DIVERGED, f"{e} at t = {data.t:.4f} s"
                    break
                free_steps += flight
                # the active drive held the fingers still through every step of this interval
                held = data.drives[model.grasps[data.active][0]].stalled
                for h in _step_sizes(integrator, data, flight, sim.dt_s, h_contact, sim.substeps):
                    t_start = data.t
                    try:
                        c = step(model, data, h, integrator)
                    except (StateOverflow, StepSizeUnderflow) as e:
                        status, message = DIVERGED, f"{e} at t = {data.t:.4f} s"
                        break
                    if integrator.adaptive:  # its step may be shorter than asked
                        h = data.t - t_start
                    held = held and data.drives[model.grasps[data.active][0]].stalled
                    steps += 1
                    rec.state[DRIVE_WORK] += h * data.drive_power
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
                    if data.phase.phase == COMPLETE or data.t - starts[-1] > timeout:
                        break
                n_rows, code = 0, OK
                if status != DIVERGED:
                    code = rec.close(model, data, held, J, JL)
                    n_rows = code != NONFINITE
            done += n_rows
            bar.update(n_rows)
            if code == NONFINITE:  # a NaN or an infinity anywhere; nothing recorded
                status = DIVERGED
                message = f"state became non-finite by t = {data.t:.4f} s"
            elif code == ENERGY_WORK:  # energy from nowhere; its record is kept
                status = DIVERGED
                message = (f"energy grew to {rec.state[E_NOW]:.3g} J, more than {ENERGY_GROWTH:g} times the "
                           f"{rec.state[E_START]:.3g} J at the start plus the {rec.state[DRIVE_WORK]:.3g} J the finger "
                           f"drives did, at t = {data.t:.4f} s")
            elif code == ENERGY:  # a passive phase gained energy; its record is kept
                status = DIVERGED
                message = (f"energy grew from {rec.state[E_PASSIVE]:.3g} J to {rec.state[E_NOW]:.3g} J while the "
                           f"drive held the fingers (a passive phase) at t = {data.t:.4f} s")
            if status == DIVERGED:
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
                rec.state[E_PASSIVE] = np.nan  # a new passive phase starts with the new model
            elif data.t - starts[-1] > timeout:
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
                       pair_steps, h_contact, starts, welds, *rec.momentum_drift, integrator_stats)
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
