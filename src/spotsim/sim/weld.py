"""Welding a grasped module to the robot: one composite body with the same momentum.

After the first grasp TM-1 and the robot move as one body (paper Sec. 5.1, body 4). The weld
is a model change: the module's free-flyer is replaced by a fixed joint at its pose in the
grasp frame, and the composite gets the velocity that keeps the pair's linear and angular
momentum exactly (a perfectly plastic joining).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .drive import start_drive


def world_momentum(M_WB: pin.SE3, inertia: pin.Inertia, v_B: pin.Motion) -> pin.Force:
    """Spatial momentum of a body (inertia and twist in its frame B) in world, about the origin."""
    return M_WB.act(inertia * v_B)


def twist_for_momentum(M_WA: pin.SE3, inertia_A: pin.Inertia, h_W: pin.Force) -> pin.Motion:
    """The twist, in frame A, that gives a body of inertia `inertia_A` (frame A) the world
    momentum h_W: Y^-1 h, both in A."""
    return pin.Motion(np.linalg.solve(inertia_A.matrix(), M_WA.actInv(h_W).vector))




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
    iv = nm.idx_vs[new.robot_joint]
    # the robot's frame is kept by the weld; its new inertia is the composite's
    v[iv:iv + 6] = twist_for_momentum(pd.oMi[r_old], nm.inertias[new.robot_joint], h_W).vector
    names = [f.name for f in model.fingers]
    opening = np.array([old.opening[names.index(f.name)] for f in new.fingers], dtype=float).reshape(-1)
    t_start = old.t_start.copy()
    t_start[old.active + 1] = old.t
    new_data = make_data(new)
    carried = {name: getattr(old, name) for name in (
        "t", "stalled", "drive_stopped", "drive_resumes", "drive_jump", "phase", "t_contact", "t_complete",
        "peak_force", "peak_torque", "peak_force_norm", "peak_torque_norm", "peak_pairs", "impulse_W",
        "impulse_moment_O_W", "drive_work", "steps", "pair_steps", "flights", "evaluations", "accepted", "rejected",
        "energy_start", "energy_now", "momentum_start", "angular_momentum_start", "momentum_max",
        "angular_momentum_max", "momentum_drift", "angular_momentum_drift", "row_index", "last_open")}
    # a new passive phase starts with the new model
    new_data.assign(q=q, v=v, opening=opening, t_start=t_start, active=old.active + 1, **carried)
    start_drive(new.sim, new_data)  # the next grasp's drive closes from the weld on
    return new, new_data
