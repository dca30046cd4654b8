"""A results directory as the replay reads it: the run, its display frames and recorded poses."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..errors import ScenarioError, SpotsimError

# ------------------------------------------------------------------------------ the run


@dataclass
class Run:
    """A results directory as the replay reads it."""

    path: Path
    summary: dict
    ts: dict[str, np.ndarray]
    snapshots: dict[str, np.ndarray] | None  # replay.npz, None for runs recorded before it
    model: object  # the first (unwelded) Model of the run's scenario


def load_run(result_dir: str | Path) -> Run:
    """Read a results directory (raises SpotsimError with what is missing or wrong)."""
    from ..assemble.model import build_model
    from ..results import REPLAY, read_arrays, read_results
    from ..scenario import load_scenario

    d = Path(result_dir)
    summary, ts = read_results(d)
    try:
        scenario = load_scenario(d / "scenario.yaml")
    except ScenarioError as e:
        raise SpotsimError(f"{d}: not a spotsim results directory (needs scenario.yaml): "
                           f"{'; '.join(e.problems)}") from e
    if len(ts.get("t", ())) < 2:
        raise SpotsimError(f"{d}: the run recorded fewer than two samples; nothing to replay")
    model = build_model(scenario, str(d / "scenario.yaml"))
    snapshots = None
    if (d / REPLAY).exists():
        try:
            snapshots = read_arrays(d / REPLAY)
        except (OSError, ValueError) as e:
            raise SpotsimError(f"{d}: {e}") from e
        names = model.face_names
        if not {"master_faces", "slave_faces"} <= set(snapshots):
            raise SpotsimError(f"{d / REPLAY}: not a replay file (no contact faces); was it written by another "
                               "spotsim version?")
        if [list(snapshots["master_faces"]), list(snapshots["slave_faces"])] != [names[0], names[1]]:
            raise SpotsimError(f"{d / REPLAY}: its contact faces are not those of the scene of "
                               f"{d / 'scenario.yaml'}; was it written by another spotsim version?")
    return Run(d, summary, ts, snapshots, model)


@dataclass
class Frames:
    """The display frames: timeseries rows, their simulated times and contact snapshots."""

    rate_hz: float
    rows: np.ndarray
    t: np.ndarray
    snapshot: np.ndarray  # index into replay.npz's snapshots, -1 before the first
    keys: np.ndarray  # animation key times, in frames: 0, 1, 2, ... (the last may fall between)


def display_frames(run: Run, rate_hz: float) -> Frames:
    """Every timeseries row at `rate_hz` of simulated time, and the last row."""
    dt = float(run.summary["dt_s"])
    top = float(run.snapshots["rate_hz"]) if run.snapshots is not None else 1.0 / dt
    if not 0 < rate_hz <= top * (1 + 1e-9):
        raise SpotsimError(f"--rate {rate_hz:g}: must be in (0, {top:g}] Hz, the rate at which the run "
                           f"recorded {'contacts' if run.snapshots is not None else 'poses'}")
    stride = max(1, int(round(1.0 / (rate_hz * dt))))
    n = len(run.ts["t"])
    rows = np.arange(0, n, stride)
    if rows[-1] != n - 1:
        rows = np.append(rows, n - 1)
    snap = np.full(len(rows), -1)
    if run.snapshots is not None and len(run.snapshots["row"]):
        snap = np.searchsorted(run.snapshots["row"], rows, side="right") - 1
    return Frames(1.0 / (stride * dt), rows, run.ts["t"][rows], snap, rows / stride)


# ------------------------------------------------------------------------------ poses


def _se3(pos, quat_xyzw) -> pin.SE3:
    return pin.XYZQUATToSE3(np.concatenate([pos, quat_xyzw]))


def module_pose_keys(run: Run) -> list[tuple[str, str]]:
    """The timeseries keys of each module's groove frame O_b (position, quaternion x y z w)."""
    mods = run.model.modules
    if len(mods) == 1:
        return [("module_pos_m", "module_quat_xyzw")]
    return [(f"{m.name}_pos_m", f"{m.name}_quat_xyzw") for m in mods]


class Kinematics:
    """Places a scene's joints from recorded poses: the free-flyers (robot base, modules), or
    their planar joints on the air-bearing table, from their world poses, the fingers at their
    openings, the locked arm joints at their angles and the compliant ones at theirs."""

    def __init__(self, run: Run, pin_model: pin.Model):
        m, model = pin_model, run.model
        self.pin_model, self.data = m, m.createData()
        self.q_ref = pin.neutral(m)
        for name, angle in model.spec.locked.items():
            if m.existJointName(name):
                self.q_ref[m.idx_qs[m.getJointId(name)]] = angle
        self.fingers = [(m.idx_qs[m.getJointId(f)], i) for i, f in enumerate(run.summary["fingers"])
                        if m.existJointName(f)]
        self.arm = [(m.idx_qs[m.getJointId(name)], i) for i, (name, _, _, _) in enumerate(model.spec.compliant)]
        self.free = []  # (joint, placement^-1 of the recorded frame in it, ("module", k) or ("base", 0))
        for k, (_, prefix, _, _) in enumerate(model.spec.modules):
            f = m.frames[m.getFrameId(f"{prefix}module", pin.BODY)]
            self.free.append((f.parentJoint, f.placement.inverse(), ("module", k)))
        if model.spec.robot_joint:
            self.free.append((m.getJointId(model.spec.robot_joint), pin.SE3.Identity(), ("base", 0)))
        for j, _, _ in self.free:
            if m.parents[j] != 0 or m.nqs[j] not in (7, 4):
                raise SpotsimError(f"joint {m.names[j]} is neither a free-flyer nor a planar joint on the world")

    def q(self, modules_W, base_W, opening_m, arm_rad=None) -> np.ndarray:
        m, q = self.pin_model, self.q_ref.copy()
        for j, frame_inv, (kind, k) in self.free:
            oMi = (modules_W[k] if kind == "module" else base_W) * frame_inv
            M = m.jointPlacements[j].inverse() * oMi
            if m.nqs[j] == 7:
                q[m.idx_qs[j]:m.idx_qs[j] + 7] = pin.SE3ToXYZQUAT(M)
            else:  # planar (the air-bearing table): x, y in its plane, the turn about its normal
                theta = np.arctan2(M.rotation[1, 0], M.rotation[0, 0])
                q[m.idx_qs[j]:m.idx_qs[j] + 4] = (M.translation[0], M.translation[1], np.cos(theta), np.sin(theta))
        for iq, i in self.fingers:
            q[iq] = opening_m[i]
        for iq, i in self.arm:
            q[iq] = arm_rad[i]
        return q

    def place(self, modules_W, base_W, opening_m, arm_rad=None) -> pin.Data:
        pin.forwardKinematics(self.pin_model, self.data, self.q(modules_W, base_W, opening_m, arm_rad))
        return self.data


def recorded_state(run: Run, row: int):
    """World poses of the modules' groove frames and of the robot base, finger openings (m) and
    the compliant arms' joint angles (rad; None for rigid arms)."""
    ts = run.ts
    modules = [_se3(ts[p][row], ts[q][row]) for p, q in module_pose_keys(run)]
    base = _se3(ts["base_pos_m"][row], ts["base_quat_xyzw"][row]) if "base_pos_m" in ts else None
    arm = np.atleast_1d(ts["arm_joint_angles_rad"][row]) if "arm_joint_angles_rad" in ts else None
    return modules, base, ts["finger_opening_mm"][row] * 1e-3, arm
