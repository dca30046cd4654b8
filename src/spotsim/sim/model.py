"""The compiled Model: everything a run's compiled code reads and never changes.

A structure of `structs` (a numba structref, passed to compiled code as one pointer) whose
fields, `ModelFields`, are arrays, numbers and named tuples of them, built once per scene by
`build.model.build_model` (a weld builds a new one). The stages read it by name (`m.law.K`,
`m.grasps.ee_joint[g]`), never by position.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba.experimental import structref

from ..contact.forces import ContactLaw
from ..contact.layers import FaceTable, MasterSpheres, SlaveSpheres
from ..structs import StructProxy, StructType, new_struct, register
from .bodies import FreeBodies


class Fingers(NamedTuple):
    """The fingers, one row each: moved by their drive along their prismatic axes."""

    parent_joint: np.ndarray  # (n_f,) the joint of the body the finger is mounted on
    axis_J: np.ndarray  # (n_f, 3) its opening direction in that joint's frame
    drive: np.ndarray  # (n_f,) its drive: the end-effector it belongs to


class Grasps(NamedTuple):
    """The grasps in sequence order, one row each, with the frames a step watches."""

    ee: np.ndarray  # (n_g,) the end-effector
    module: np.ndarray  # (n_g,) the module
    ee_joint: np.ndarray  # (n_g,) the end-effector's joint
    R_ee: np.ndarray  # (n_g, 3, 3) its grasp frame O_a's rotation in that joint's frame
    module_joint: np.ndarray  # (n_g,) the module's joint (0 once welded)
    module_lever: np.ndarray  # (n_g, 3) the module's centroid in its joint's frame, m


class DriveParams(NamedTuple):
    """The finger drive (`sim.drive`)."""

    law: int  # `drive.DRIVES`
    closing_speed: float  # the speed limit, m/s
    grasp_load: float  # the stall force, N
    no_load_speed: float  # the actuator's torque-speed line at zero load, m/s
    resume_fraction: float  # the relay: a stalled drive closes again below this share of the grasp load
    period: float  # the controller's period: it reads the load and sets the speed this often, s


class CompletionParams(NamedTuple):
    """The grasp phase's completion rule (`sim.phase`)."""

    hold_s: float  # how long every criterion must hold, s
    max_contact_speed: float  # m/s
    max_net_force: float  # N
    phase_timeout: float  # a grasp not complete this long after its drive started is incomplete, s


class Limits(NamedTuple):
    """What bounds a step: divergence, the broad phase's skin and the motion bound."""

    max_penetration: float  # a pair deeper than this (the smaller sphere radius) has diverged, m
    skin: float  # coal's margin beyond contact reach: the travel allowed before a refresh, m
    margin: float  # coal's security margin: contact reach plus the skin, m
    fixed_contact: bool  # a fixed body carries contact faces (contact impulses are external)
    reach_rows: np.ndarray  # (n,) rows of `bodies` carrying contact spheres
    reach: np.ndarray  # (n,) the farthest of their spheres from their joint's origin, m


class RecordFrames(NamedTuple):
    """What a record row reads (`sim.record`): frames, bodies and the energy constants.

    Frames (rows of row, R, p): each module's groove frame, then each end-effector's grasp
    frame, then the robot's base (its joint frame); `row` is the row in `bodies` of the body
    each rides on, -1 for a fixed one.
    """

    row: np.ndarray  # (n_frames,)
    R: np.ndarray  # (n_frames, 3, 3) placement in that body's joint frame
    p: np.ndarray  # (n_frames, 3)
    module_row: np.ndarray  # (n_modules,) each module's row in `bodies`, -1 once welded
    finger_map: np.ndarray  # (n_f,) each finger among the first model's fingers
    all_rows: np.ndarray  # every free body's row
    robot_rows: np.ndarray  # the robot's rows (none on a fixed base)
    system_rows: np.ndarray  # the free bodies the system centroid is taken over
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
    locate_switches: bool  # adaptive_euler: a step ends where a bristle saturates or lets go
    lever: np.ndarray  # (n_bodies,) each free body's farthest contact sphere from its centroid, m


class ModelFields(NamedTuple):
    """The fields of the compiled Model of a scene."""

    bodies: FreeBodies
    gravity_W: np.ndarray  # (3,) m/s^2
    # (3,) the air-bearing table's unit normal in world, which every free body's planar joint
    # turns about; zero in space (`build.table`)
    table_normal: np.ndarray
    master: MasterSpheres
    slave: SlaveSpheres
    faces: FaceTable
    law: ContactLaw
    literal: bool  # the paper's all-pairs search instead of the culled one
    fingers: Fingers
    grasps: Grasps
    drive: DriveParams
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
