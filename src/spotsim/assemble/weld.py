"""Welding a grasped module to the robot: a transform of the Model, with the same momentum.

After the first grasp TM-1 and the robot move as one body (paper Sec. 5.1, body 4). The weld
is a model change: the module's free-flyer becomes a fixed joint at its pose in the grasp
frame, and the end-effector's fingers, which hold it, are locked at their openings; the
robot's branch then gets the velocity that keeps the pair's linear and angular momentum
exactly (a perfectly plastic joining); on the air-bearing testbed, the in-plane momentum and
the angular momentum about the table's normal.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..sim.actuation import start_drive
from ..sim.data import make_data
from .model import Model, build_model, grasp_frame, groove_frame

#: A planar joint's velocity components among a twist's (v_O, omega): v_O,x, v_O,y, omega_z.
PLANAR_COMPONENTS = [0, 1, 5]


def world_momentum(M_WB: pin.SE3, inertia: pin.Inertia, v_B: pin.Motion) -> pin.Force:
    """Spatial momentum of a body (inertia and twist in its frame B) in world, about the origin."""
    return M_WB.act(inertia * v_B)


def branch_momentum(model: pin.Model, data: pin.Data, root: int) -> pin.Force:
    """The spatial momentum (world, about the origin) of the bodies of the branch from `root`,
    at the kinematics in `data` (`pin.forwardKinematics` with velocities)."""
    total = pin.Force.Zero()
    for j in range(root, model.njoints):
        k = j
        while k and k != root:
            k = model.parents[k]
        if k == root:
            total += world_momentum(data.oMi[j], model.inertias[j], data.v[j])
    return total


def root_velocity_for_momentum(model: pin.Model, q: np.ndarray, v: np.ndarray, root: int,
                               h_W: pin.Force) -> np.ndarray:
    """The velocity of the floating root `root` (its nv components, its frame) that gives its
    branch the world momentum h_W, the branch's other joints at their velocities in v: the
    branch's momentum in the root's frame is M_rr v_r + M_ri v_i (`pin.crba`), so
    v_r = M_rr^-1 (S^T h - M_ri v_i). On a planar root, S keeps the momentum's in-plane
    components and its moment about the normal; the table takes the rest."""
    data = model.createData()
    M = pin.crba(model, data, q)
    M = np.triu(M) + np.triu(M, 1).T
    pin.forwardKinematics(model, data, q)
    h_A = data.oMi[root].actInv(h_W).vector
    i0, n = model.idx_vs[root], model.nvs[root]
    S = PLANAR_COMPONENTS if n == 3 else list(range(6))
    rest = [i for i in range(model.nv) if not i0 <= i < i0 + n]
    coupling = M[i0:i0 + n][:, rest] @ v[rest]
    return np.linalg.solve(M[i0:i0 + n, i0:i0 + n], h_A[S] - coupling)


def weld(model: Model, data, source: str = "<scenario>") -> tuple[Model, object]:
    """Weld the active grasp's module to its end-effector: the new (Model, Data).

    The module's free-flyer becomes a fixed joint at its current pose in the grasp frame, its
    end-effector's fingers are locked at their current openings, and the robot's root gets
    the velocity that keeps the momentum of robot and module (`root_velocity_for_momentum`).
    The run's clock, records and bookkeeping carry over; the next grasp's drive starts.
    """
    old = data.view()
    ee, k = model.grasps[old.active]
    pm = model.pin_model
    pd = pm.createData()
    pin.forwardKinematics(pm, pd, old.q, old.v)
    aMb = grasp_frame(model, pd, ee).actInv(groove_frame(model, pd, k))
    welded = {i: (xyz, rpy) for i, xyz, rpy in model.spec.welded}
    welded[k] = (aMb.translation, pin.rpy.matrixToRpy(aMb.rotation))
    # the fingers that hold a welded module stay locked where they hold it (the next grasp's,
    # locked at their start in this phase, move in the next)
    holding = {model.spec.end_effectors[e][1] for e, k in model.grasps if k in welded}
    held = {name: model.spec.locked[name] for name in model.layout.fingers
            if name in model.spec.locked and any(name.startswith(prefix) for prefix in holding)}
    held.update({f.name: float(old.q[pm.idx_qs[f.joint]]) for f in model.fingers if f.drive == ee})
    # the XACRO is not compiled again, nor the contact faces parsed again; the joints' springs are kept
    new = build_model(model.scenario, source, welded=welded, urdf=model.urdf, faces=model.faces, held=held,
                      springs=model.springs)
    nm = new.pin_model
    q, v = new.q0.copy(), new.v0.copy()
    # configurations and velocities by joint name (the next grasp's fingers, locked until now,
    # start at rest at their start openings); the robot's from the momentum of robot + module
    for j in range(1, nm.njoints):
        if not pm.existJointName(nm.names[j]):
            continue
        o = pm.getJointId(nm.names[j])
        q[nm.idx_qs[j]:nm.idx_qs[j] + nm.nqs[j]] = old.q[pm.idx_qs[o]:pm.idx_qs[o] + pm.nqs[o]]
        v[nm.idx_vs[j]:nm.idx_vs[j] + nm.nvs[j]] = old.v[pm.idx_vs[o]:pm.idx_vs[o] + pm.nvs[o]]
    h_W = branch_momentum(pm, pd, model.robot_joint) + branch_momentum(pm, pd, model.modules[k].joint)
    r = new.robot_joint
    # the robot's frame is kept by the weld; its branch's inertia is the composite's
    v[nm.idx_vs[r]:nm.idx_vs[r] + nm.nvs[r]] = root_velocity_for_momentum(nm, q, v, r, h_W)
    t_start = old.t_start.copy()
    t_start[old.active + 1] = old.t
    new_data = make_data(new, start=False)
    carried = {name: getattr(old, name) for name in (
        "t", "stalled", "drive_stopped", "drive_resumes", "drive_jump", "peak_current", "transmission_time",
        "transmission_stops", "peak_deceleration", "phase", "t_contact", "t_complete",
        "peak_force", "peak_torque", "peak_force_norm", "peak_torque_norm", "peak_pairs", "peak_table_force",
        "peak_table_moment", "impulse_W",
        "impulse_moment_O_W", "drive_work", "steps", "pair_steps", "flights", "evaluations", "accepted", "rejected",
        "cut", "energy_start", "energy_now", "momentum_start", "angular_momentum_start", "momentum_max",
        "angular_momentum_max", "momentum_drift", "angular_momentum_drift", "row_index")}
    # a new passive phase starts with the new model
    new_data.assign(q=q, v=v, t_start=t_start, active=old.active + 1, **carried)
    start_drive(new.sim, new_data)  # the next grasp's drive closes from the weld on
    return new, new_data

