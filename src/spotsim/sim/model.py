"""The compiled Model: everything a run's compiled code reads and never changes.

A structure of `structs` (a numba structref, passed to compiled code as one pointer) whose
fields, `ModelFields`, are arrays, numbers and named tuples of them, built once per scene by
`assemble.model.build_model` (a weld builds a new one). The stages read it by name (`m.law.K`,
`m.grasps.ee_joint[g]`), never by position.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba.experimental import structref

from ..contact.forces import ContactLaw
from ..contact.layers import FaceTable, MasterSpheres, SlaveSpheres
from ..structs import StructProxy, StructType, new_struct, register
from .actuation import Actuators, Drives
from .tether import Tethers
from .tree import Branches, Tree


class Grasps(NamedTuple):
    """The grasps in sequence order, one row each, with the frames a step watches."""

    ee: np.ndarray  # (n_g,) the end-effector
    module: np.ndarray  # (n_g,) the module
    ee_joint: np.ndarray  # (n_g,) the end-effector's joint
    R_ee: np.ndarray  # (n_g, 3, 3) its grasp frame O_a's rotation in that joint's frame
    module_joint: np.ndarray  # (n_g,) the module's joint (0 once welded)
    module_lever: np.ndarray  # (n_g, 3) the module's centroid in its joint's frame, m


class CompletionParams(NamedTuple):
    """The grasp phase's completion rule (`sim.phase`)."""

    hold_s: float  # how long every criterion must hold, s
    max_contact_speed: float  # m/s
    max_net_force: float  # N
    phase_timeout: float  # a grasp not complete this long after its drive started is incomplete, s
    record_after: float  # the last grasp complete, the run records this long more, s


class Limits(NamedTuple):
    """What bounds a step: divergence, the broad phase's skin and the motion bound."""

    max_penetration: float  # a pair deeper than this (the smaller sphere radius) has diverged, m
    skin: float  # coal's margin beyond contact reach: the travel allowed before a refresh, m
    margin: float  # coal's security margin: contact reach plus the skin, m
    external_contact: bool  # a body that does not float carries contact faces (contact impulses are external)


class RecordFrames(NamedTuple):
    """What a record row reads (`sim.record`): frames, bodies and the energy constants.

    Frames (rows of joint, R, p): each module's groove frame, then each end-effector's grasp
    frame, then the robot's base (its joint frame); `joint` is the joint each rides on (0: the
    fixed world).
    """

    joint: np.ndarray  # (n_frames,)
    R: np.ndarray  # (n_frames, 3, 3) placement in that joint's frame
    p: np.ndarray  # (n_frames, 3)
    module_joint: np.ndarray  # (n_modules,) each module's floating joint, 0 once welded
    # each finger of the unwelded scene (`Layout.fingers`): the index in q of its joint's
    # coordinate, its opening (-1: a weld locked it, at `locked_opening`, m), and its actuator
    # (-1: none, its load is zero)
    finger_q: np.ndarray  # (n_f,)
    locked_opening: np.ndarray  # (n_f,)
    finger_actuator: np.ndarray  # (n_f,)
    arm_q: np.ndarray  # (n_arm,) the index in q of each compliant arm joint (`Layout.arm_joints`)
    # (n_arm,) ... of its motor side's joint, whose angle adds to it (-1: braked, none)
    arm_motor_q: np.ndarray
    # the dynamometer's six joints (`assemble.rig`; none without it): their indices in q and v
    mount_q: np.ndarray
    mount_v: np.ndarray
    all_branches: np.ndarray  # every floating branch
    robot_branches: np.ndarray  # the robot's branch (none on a fixed base)
    system_branches: np.ndarray  # the floating branches the system centroid is taken over
    free_robot: bool
    energy_bound: bool  # the finger drives' work bounds the energy (no gravity doing work)
    width: int  # columns of a row
    replay_every: int  # a contact snapshot every this many rows


class IntegratorParams(NamedTuple):
    """The time integrator (`sim.integrators`) and its tableau (explicit Runge-Kutta)."""

    method: int  # its index in integrators.METHODS
    adaptive: bool  # error-controlled (integrators.ADAPTIVE)
    A: np.ndarray  # (s, s) Runge-Kutta matrix (empty for symplectic Euler)
    b: np.ndarray  # (s,) weights
    c: np.ndarray  # (s,) nodes
    e: np.ndarray  # (s,) weights of the embedded error estimate (empty unless adaptive)
    rtol: float
    atol: float
    h_min: float  # s
    h_max: float  # s
    velocity_tol: float  # adaptive_euler: a step's error in any contact sphere's velocity, m/s
    onset_depth: float  # adaptive_euler: how far a step may move two spheres closer while pairs may start, m
    onset_clearance: bool  # adaptive_euler: ... beyond the clearance of the pairs not in contact (`onset_step`)
    locate_switches: bool  # adaptive_euler: a step ends where a bristle saturates or lets go
    staggered: bool  # adaptive_euler: a velocity update spans the mean of the last step and its own (`kick_of`)
    pass_quiet: bool  # adaptive methods: a step may pass a motor drive's quiet readings (`actuation.quiet_readings`)
    # (n_branches + n_internal,) adaptive_euler's lever of each error row (`integrators.error_rates`):
    # a floating branch's farthest contact sphere from its centroid, m; a joint's motion of the
    # spheres it carries per unit of its coordinate (`tree.Tree.reach`)
    lever: np.ndarray
    lightest: float  # the lightest floating branch's mass, kg (adaptive_euler's switch threshold)


class ModelFields(NamedTuple):
    """The fields of the compiled Model of a scene."""

    tree: Tree
    branches: Branches
    gravity_W: np.ndarray  # (3,) m/s^2
    # (3,) the air-bearing table's unit normal in world, which every floating root's planar
    # joint turns about; zero in space (`assemble.table`)
    table_normal: np.ndarray
    master: MasterSpheres
    slave: SlaveSpheres
    faces: FaceTable
    law: ContactLaw
    tethers: Tethers  # cords from fixed points to bodies (`sim.tether`)
    literal: bool  # the paper's all-pairs search instead of the culled one
    actuators: Actuators
    drives: Drives
    grasps: Grasps
    completion: CompletionParams
    limits: Limits
    record: RecordFrames
    integrator: IntegratorParams
    dt: float  # the record interval, s
    substeps: int  # dynamics steps per record interval
    h: float  # the dynamics step, dt / substeps, s


@structref.register
class SimModelType(StructType):
    pass


class SimModel(StructProxy):
    """The compiled Model of a scene (see `ModelFields` for its fields). It never changes:
    Python reads its fields from the named tuple it was built from (`fields`)."""

    def __getattr__(self, name):
        fields = self.__dict__.get("fields")
        if fields is not None and name in ModelFields._fields:
            return getattr(fields, name)
        return super().__getattr__(name)


register(SimModelType, ModelFields, SimModel)


def sim_model(fields: ModelFields) -> SimModel:
    """The compiled Model holding `fields` (arrays shared)."""
    model = new_struct(fields)
    model.fields = fields
    return model
