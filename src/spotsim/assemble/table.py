"""The air-bearing testbed (paper Sec. 5.2): floating bodies on planar joints over a table.

On the SPOT testbed the floating base, TM-1 and TM-2 float on air bearings over a granite
table: each moves in the table's plane and turns about its normal, and gravity, along the
normal, is carried by the bearings. `mount_on_table` turns a scene's free-flyers into
Pinocchio planar joints, each in the plane through its body's start: its joint frame is the
start pose turned so that its z is the table's normal, and the body's inertia and frames are
given in that frame, so that at q = (0, 0, 1, 0) every body is where the free-flyer scene
starts it. Each body's height along the normal, its roll and its pitch are then fixed by the
model, not by the integrator.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

#: A planar joint's configuration at its start: x, y, cos(theta), sin(theta).
PLANAR_START = (0.0, 0.0, 1.0, 0.0)


def table_frame(R_WB: np.ndarray, normal_W) -> np.ndarray:
    """A rotation A, in the body frame B, whose z is the table's normal and whose x is B's x
    in the table's plane (B's y where B's x is the normal)."""
    z = R_WB.T @ (np.asarray(normal_W, dtype=float) / np.linalg.norm(normal_W))
    x = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = x - (x @ z) * z
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def mount_on_table(model: pin.Model, q0: np.ndarray, joints, normal_W) -> tuple[pin.Model, np.ndarray]:
    """The model with the free-flyers `joints` (children of the world) on planar joints in
    the planes through their poses at q0, normal to `normal_W`; and its start configuration.

    The other joints are copied as they are. Frames, inertias and child joints on a mounted
    joint are given in its new joint frame (the old one turned by `table_frame`).
    """
    data = model.createData()
    pin.forwardKinematics(model, data, q0)
    turn = {}  # joint -> A, the new joint frame in the old
    for j in joints:
        if model.joints[j].shortname() != "JointModelFreeFlyer" or model.parents[j] != 0:
            raise ValueError(f"joint {model.names[j]} is not a free-flyer on the world")
        turn[j] = pin.SE3(table_frame(data.oMi[j].rotation, normal_W), np.zeros(3))
    new = pin.Model()
    new.name, new.gravity = model.name, model.gravity
    q = []
    for j in range(1, model.njoints):
        if j in turn:
            jid = new.addJoint(model.parents[j], pin.JointModelPlanar(), data.oMi[j] * turn[j], model.names[j])
            new.appendBodyToJoint(jid, turn[j].actInv(model.inertias[j]), pin.SE3.Identity())
            q.extend(PLANAR_START)
        else:  # a joint on a mounted body: its placement in that body's new frame
            placement = model.jointPlacements[j]
            if model.parents[j] in turn:
                placement = turn[model.parents[j]].actInv(placement)
            jid = new.addJoint(model.parents[j], model.joints[j], placement, model.names[j])
            new.appendBodyToJoint(jid, model.inertias[j], pin.SE3.Identity())
            q.extend(q0[model.idx_qs[j]:model.idx_qs[j] + model.nqs[j]])
    # the joints' rotors, dampers and torque limits carried over (a mounted joint's are the
    # table's: none)
    armature, damping, effort = np.array(new.armature), np.array(new.damping), np.array(new.effortLimit)
    for j in range(1, model.njoints):
        if j not in turn:
            src = slice(model.idx_vs[j], model.idx_vs[j] + model.nvs[j])
            dst = slice(new.idx_vs[j], new.idx_vs[j] + new.nvs[j])
            armature[dst], damping[dst], effort[dst] = model.armature[src], model.damping[src], model.effortLimit[src]
    new.armature, new.damping, new.effortLimit = armature, damping, effort
    for f in list(model.frames)[1:]:  # the first is the universe, which every model has
        g = pin.Frame(f)
        if f.parentJoint in turn:
            A = turn[f.parentJoint]
            g.placement = A.actInv(f.placement)
            g.inertia = A.actInv(f.inertia)
        new.addFrame(g, False)
    return new, np.array(q, dtype=float)
