"""A kinematic tree alone, outside a scene: the compiled Model and Data fields the dynamics
stages read (`tree.kinematics`, `dynamics.accelerations`, the integrators' updates), for
checking them against Pinocchio on any model, and for driving a tree without contact.

    model, data = bare(pin_model)
    data.q[:] = q; data.v[:] = v; data.tau[:] = tau; data.loads.f_local[:] = f
    kinematics(model, data); accelerations(model, data)   # data.a: pin.aba's
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pinocchio as pin

from .actuation import Actuators, Drives
from .dynamics import new_articulation
from .integrators import state_size
from .tree import kinematic_tree, new_frames


class BareModel(NamedTuple):
    """The tree's compiled fields (`tree.Tree`, `tree.Branches`), in space (no table), no
    actuators and no drives."""

    tree: object
    branches: object
    table_normal: np.ndarray  # (3,) zero: no air-bearing table
    actuators: object
    drives: object


class BareLoads(NamedTuple):
    """External wrenches on each joint's body: (force, moment about its origin) in its frame,
    and the force in the world (the integrators' centroids read it)."""

    f_local: np.ndarray  # (nj, 6) N, N m
    force_W: np.ndarray  # (nj, 3) N


class BareData(NamedTuple):
    """The state and scratch the dynamics stages read and write (`data.Data`'s fields of the
    same names)."""

    q: np.ndarray
    v: np.ndarray
    tau: np.ndarray
    loads: BareLoads
    work: object
    a: np.ndarray
    R_W: np.ndarray
    p_W: np.ndarray
    w_W: np.ndarray
    vo_W: np.ndarray
    now: object
    fsal_dy: np.ndarray
    placed: np.ndarray
    placed_q: np.ndarray
    placed_v: np.ndarray
    placed_offset: np.ndarray
    # no motor drives: their fields, empty
    drive_free: np.ndarray
    drive_force: np.ndarray
    response: np.ndarray
    transmission: np.ndarray
    screw_force: np.ndarray
    current: np.ndarray


def bare(model: pin.Model, prescribed=(), springs=None) -> tuple[BareModel, BareData]:
    """The compiled Model and a Data (at the neutral configuration, at rest) of a Pinocchio
    model's tree; `prescribed`, `springs` as `tree.kinematic_tree`. Its gravity is the
    model's. External wrenches go into data.loads.f_local, and their world forces, which the
    integrators' centroids read, into data.loads.force_W."""
    tree, branches = kinematic_tree(model, prescribed, model.gravity.linear, springs=springs)
    nj, nv = model.njoints, model.nv
    frames = new_frames(nj)
    data = BareData(q=pin.neutral(model), v=np.zeros(nv), tau=np.zeros(nv),
                    loads=BareLoads(f_local=np.zeros((nj, 6)), force_W=np.zeros((nj, 3))),
                    work=new_articulation(nj, nv), a=np.zeros(nv), R_W=frames.R_W, p_W=frames.p_W, w_W=frames.w_W,
                    vo_W=frames.vo_W, now=new_frames(nj), fsal_dy=np.zeros(state_size(tree, branches)),
                    placed=np.zeros(1, dtype=np.bool_), placed_q=np.zeros(model.nq), placed_v=np.zeros(nv),
                    placed_offset=np.zeros((len(branches.joint), 6)), drive_free=np.zeros(0), drive_force=np.zeros(0),
                    response=np.zeros((0, nv)), transmission=np.zeros(0, dtype=np.int64), screw_force=np.zeros(0),
                    current=np.zeros(0))
    none = np.zeros(0)
    drives = Drives(law=np.zeros(0, dtype=np.int64), closing_speed=none, grasp_load=none, no_load_speed=none,
                    resume_fraction=none, period=none, ratio=none, forward=none, backward=none, rotor=none,
                    torque_constant=none, resistance=none, voltage=none, current_limit=none, gain=none,
                    integral_time=none, back_calculation=np.zeros(0, dtype=np.bool_))
    actuators = Actuators(joint=np.zeros(0, dtype=np.int64), drive=np.zeros(0, dtype=np.int64))
    return BareModel(tree=tree, branches=branches, table_normal=np.zeros(3), actuators=actuators,
                     drives=drives), data
