"""Welding a grasped module to the robot: one composite body with the same momentum.

After the first grasp TM-1 and the robot move as one body (paper Sec. 5.1, body 4). The weld
is a model change: the module's free-flyer is replaced by a fixed joint at its pose in the
grasp frame, and the composite gets the velocity that keeps the pair's linear and angular
momentum exactly (a perfectly plastic joining); on the air-bearing testbed, the in-plane
momentum and the angular momentum about the table's normal.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .bodies import PLANAR
from .drive import start_drive


def world_momentum(M_WB: pin.SE3, inertia: pin.Inertia, v_B: pin.Motion) -> pin.Force:
    """Spatial momentum of a body (inertia and twist in its frame B) in world, about the origin."""
    return M_WB.act(inertia * v_B)


#: A planar joint's velocity components among a twist's (v_O, omega): v_O,x, v_O,y, omega_z.
PLANAR_COMPONENTS = [0, 1, 5]


def joint_velocity_for_momentum(M_WA: pin.SE3, inertia_A: pin.Inertia, h_W: pin.Force, planar: bool) -> np.ndarray:
    """The joint velocity, in frame A, that gives a body of inertia `inertia_A` (frame A) the
    world momentum h_W: the twist Y^-1 h (6,), both in A, on a free-flyer. On a planar joint
    (3,), the one that keeps the momentum's in-plane components and its moment about the
    normal, S^T Y S x = S^T h; the table takes the rest."""
    Y, h_A = inertia_A.matrix(), M_WA.actInv(h_W).vector
    if planar:
        S = PLANAR_COMPONENTS
        return np.linalg.solve(Y[np.ix_(S, S)], h_A[S])
    return np.linalg.solve(Y, h_A)




def weld(model, data, source: str = "<scenario>"):
    """Weld the active grasp's module to its end-effector: the new (Model, Data).

    The module's free-flyer is replaced by a fixed joint at its current pose in the grasp
    frame, and the composite body gets the twist that keeps the pair's linear and angular
    momentum: Y_new^-1 (h_robot + h_module), with Y_new the new model's composite inertia. The
    run's clock, records and bookkeeping carry over; the next grasp's drive starts.
    """
    from ..build.model import build_model, grasp_frame, groove_frame
    from .data import make_data

    old = data.view()
    ee, k = model.grasps[old.active]
    pm = model.pin_model
    pd = pm.createData()
    pin.forwardKinematics(pm, pd, old.q, old.v)
    aMb = grasp_frame(model, pd, ee).actInv(groove_frame(model, pd, k))
    welded = {i: (xyz, rpy) for i, xyz, rpy in model.spec.welded}
    welded[k] = (aMb.translation, pin.rpy.matrixToRpy(aMb.rotation))
    # the XACRO is not compiled again, nor the contact faces parsed again
    new = build_model(model.scenario, source, welded=welded, urdf=model.urdf, faces=model.faces)
    nm = new.pin_model
    q, v = new.q0.copy(), new.v0.copy()
    # configurations by joint name; the robot's twist from the momentum of robot + module
    for j in range(1, nm.njoints):
        o = pm.getJointId(nm.names[j])
        q[nm.idx_qs[j]:nm.idx_qs[j] + nm.nqs[j]] = old.q[pm.idx_qs[o]:pm.idx_qs[o] + pm.nqs[o]]
        v[nm.idx_vs[j]:nm.idx_vs[j] + nm.nvs[j]] = old.v[pm.idx_vs[o]:pm.idx_vs[o] + pm.nvs[o]]
    r_old, m_old = model.robot_joint, model.modules[k].joint
    h_W = (world_momentum(pd.oMi[r_old], pm.inertias[r_old], pd.v[r_old])
           + world_momentum(pd.oMi[m_old], pm.inertias[m_old], pd.v[m_old]))
    r = new.robot_joint
    # the robot's frame is kept by the weld; its new inertia is the composite's
    v[nm.idx_vs[r]:nm.idx_vs[r] + nm.nvs[r]] = joint_velocity_for_momentum(
        pd.oMi[r_old], nm.inertias[r], h_W, nm.joints[r].shortname() == PLANAR)
    names = [f.name for f in model.fingers]
    opening = np.array([old.opening[names.index(f.name)] for f in new.fingers], dtype=float).reshape(-1)
    t_start = old.t_start.copy()
    t_start[old.active + 1] = old.t
    new_data = make_data(new)
    carried = {name: getattr(old, name) for name in (
        "t", "stalled", "drive_stopped", "drive_resumes", "drive_jump", "phase", "t_contact", "t_complete",
        "peak_force", "peak_torque", "peak_force_norm", "peak_torque_norm", "peak_pairs", "peak_table_force",
        "peak_table_moment", "impulse_W",
        "impulse_moment_O_W", "drive_work", "steps", "pair_steps", "flights", "evaluations", "accepted", "rejected",
        "cut", "energy_start", "energy_now", "momentum_start", "angular_momentum_start", "momentum_max",
        "angular_momentum_max", "momentum_drift", "angular_momentum_drift", "row_index", "last_open")}
    # a new passive phase starts with the new model
    new_data.assign(q=q, v=v, opening=opening, t_start=t_start, active=old.active + 1, **carried)
    start_drive(new.sim, new_data)  # the next grasp's drive closes from the weld on
    return new, new_data
