"""The compiled Data: everything that changes during a run, in one mutable structure.

`Data` is a structure of `structs` (a numba structref): compiled code reads and writes its
fields by name (`d.t += h`, `d.contacts = ...`) and passes it as one pointer. Its fields are
those of `DataFields`, one place that names and documents them. From Python a field reads as
an attribute (`data.q`: arrays are the live arrays, numbers a copy), and `data.assign(t=...)`
writes fields.

Arrays of a fixed size (q, v, the kinematics, the per-grasp records) are written in place;
those whose size changes with the contacts (the pairs, their memory, the pair list) are
replaced whole by the stage that makes them.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba.experimental import structref

from ..contact.forces import Contacts, Memory, no_contacts, no_memory
from ..contact.search import Candidates, PairList, empty_pair_list, no_candidates
from ..contact.wrenches import Loads, Summary, no_loads, no_summary
from ..structs import StructProxy, StructType, new_struct, register, view
from .actuation import start_drive
from .dynamics import Articulation, new_articulation
from .integrators import state_size
from .tree import Frames, new_frames

#: Record rows the row buffer holds: the compiled loop returns to Python after at most this
#: many (each return updates the progress bar and lets Ctrl-C in); 250 rows are 0.25 s
#: simulated at the default record interval.
ROWS_PER_CALL = 250


class Snapshots(NamedTuple):
    """The replay's contact snapshots taken during one call of the loop (`sim.record`)."""

    row: np.ndarray  # (cap,) the run's row each is taken at
    pairs: np.ndarray  # (cap,) pairs in contact at it
    force_W: np.ndarray  # (cap, n_modules, 3) each module's combined contact force, world, N
    master: np.ndarray  # (cap_pairs,) the pairs of all snapshots, concatenated
    slave: np.ndarray
    state: np.ndarray


class DataFields(NamedTuple):
    """The fields of Data: the state of a run, its bookkeeping and its scratch buffers."""

    # the state
    t: float  # s
    q: np.ndarray  # (nq,) configuration over the tree's joints (`tree`: free-flyers xyz, quaternion xyzw)
    v: np.ndarray  # (nv,) velocity (free-flyers: v_O, omega in the body frame)
    a: np.ndarray  # (nv,) acceleration at the last force evaluation
    tau: np.ndarray  # (nv,) the actuators' joint forces (`actuation`), N or N m
    load: np.ndarray  # (n_a,) each actuated joint's contact load at the last evaluation, N (`actuation`)
    # the motor drives (`dynamics.transmissions`, `actuation`): per actuated joint
    drive_force: np.ndarray  # (n_a,) the joint force its drive's screw and linkage put on it, N
    drive_free: np.ndarray  # (n_a,) its acceleration without that force, m/s^2
    response: np.ndarray  # (n_a, nv) the accelerations a unit force on it gives (`dynamics.joint_response`)
    # ... per end-effector
    transmission: np.ndarray  # (n_ee,) its transmission's state, tables.TRANSMISSION_STATES
    screw_force: np.ndarray  # (n_ee,) the screw's total closing force on the fingers, N
    current: np.ndarray  # (n_ee,) the motor's current, A (the speed loop's last reading)
    integral: np.ndarray  # (n_ee,) the speed loop's integral, A
    encoder_opening: np.ndarray  # (n_ee,) the fingers' mean opening at the speed loop's last reading, m
    encoder_t: np.ndarray  # (n_ee,) the time of that reading, s (nan: none yet)
    saturated: np.ndarray  # (n_ee,) bool: the speed loop's last reading asked for its upper clamp or more
    direction: np.ndarray  # (n_ee,) the way its transmission slides: +1 closing, -1 opening (0: stuck)
    # the kinematics of the last force evaluation, rows by joint (the universe: identity)
    R_W: np.ndarray  # (njoints, 3, 3)
    p_W: np.ndarray  # (njoints, 3) m
    w_W: np.ndarray  # (njoints, 3) angular velocity, world, rad/s
    vo_W: np.ndarray  # (njoints, 3) the joint origin's velocity, world, m/s
    now: Frames  # scratch: the kinematics at the state as it is (`tree.current_frames`, the integrators' centroids)
    work: Articulation  # scratch of the articulated-body algorithm (`dynamics`)
    # the broad phase (coal, refreshed from Python) and the search
    near: np.ndarray  # (k,) the face pairs coal kept within its margin
    travel: float  # bound on any two spheres' relative motion since coal's last run, m
    pair_list: PairList
    candidates: Candidates
    # the contact of the last force evaluation
    contacts: Contacts
    memory: Memory  # what the pairs carry into the next evaluation (the last committed one)
    loads: Loads
    summary: Summary
    external_force_W: np.ndarray  # (3,) the external force on the floating branches, mean over the last step, N
    external_torque_O_W: np.ndarray  # (3,) its moment about the world origin, N m
    # the grasps: the active one's drive and phase, and each one's record
    active: int  # the grasp under way
    stalled: np.ndarray  # (n_ee,) the relay: each end-effector's drive holds at the grasp load
    sample_t: float  # when the active drive's controller next reads the load and sets the speed, s
    jumped: bool  # a controller changed a prescribed speed since the last force evaluation
    drive_stopped: np.ndarray  # (n_g,) each grasp's drive has stopped since it last closed at over half speed
    drive_resumes: np.ndarray  # (n_g,) ... the times it closed again at over half its closing speed after it stopped
    drive_jump: np.ndarray  # (n_g,) ... its largest change of speed from one reading to the next, m/s
    peak_current: np.ndarray  # (n_g,) a motor drive's largest |current|, A
    transmission_time: np.ndarray  # (n_g, 3) ... the time its transmission spent in each state, s
    transmission_stops: np.ndarray  # (n_g,) ... the times its sliding fingers were stopped (stuck)
    peak_deceleration: np.ndarray  # (n_g,) ... its closing fingers' largest deceleration between stops, m/s^2
    phase: np.ndarray  # (n_g,) APPROACH, SELF_CENTRING or COMPLETE
    held_since: float  # since when the completion criteria hold, s (nan: they do not)
    t_start: np.ndarray  # (n_g,) when each grasp's drive started, s (nan: not yet)
    t_contact: np.ndarray  # (n_g,) its first contact, s (nan: none yet)
    t_complete: np.ndarray  # (n_g,) its completion, s (nan: not complete)
    peak_force: np.ndarray  # (n_g, 3) per axis of O_a, the largest |contact force| on the module, N
    peak_torque: np.ndarray  # (n_g, 3) ... and |moment about its centroid|, N m
    peak_force_norm: np.ndarray  # (n_g,) N
    peak_torque_norm: np.ndarray  # (n_g,) N m
    peak_pairs: np.ndarray  # (n_g,) most pairs in contact at once
    # (n_g,) on the air-bearing table, the most any floating branch's contact wrench pressed into it:
    # the force along its normal, N, and the moment about the body's centroid in its plane, N m
    peak_table_force: np.ndarray
    peak_table_moment: np.ndarray
    # the run's bookkeeping
    impulse_W: np.ndarray  # (3,) external impulse on the floating branches (contacts from outside, gravity), N s
    impulse_moment_O_W: np.ndarray  # (3,) its moment about the world origin, N m s
    drive_power: float  # the finger drives' power during the last step (a bound), W
    drive_work: float  # the work they did since the start (a bound), J
    steps: int  # dynamics steps taken
    pair_steps: int  # pairs in contact summed over the steps
    flights: int  # record intervals taken as one free-flight step
    evaluations: int  # force evaluations
    accepted: int  # steps accepted (all but an adaptive integrator's rejected tries)
    rejected: int  # adaptive steps rejected
    cut: int  # adaptive_euler's tries cut to end just past a bristle's switch
    energy_start: float  # mechanical energy at the start, J
    energy_now: float  # ... at the last record, J
    energy_passive: float  # ... when the current passive phase began, J (nan: not in one)
    gravity_datum: float  # the bodies' potential in gravity at the start (`tree.gravity_energy`), J
    momentum_start: np.ndarray  # (3,) the floating branches' linear momentum at the start, kg m/s
    angular_momentum_start: np.ndarray  # (3,) their angular momentum about the world origin
    momentum_max: float  # the largest single body's linear momentum, kg m/s
    angular_momentum_max: float  # ... angular momentum, kg m^2/s
    momentum_drift: float  # the largest |momentum - start - external impulse| recorded
    angular_momentum_drift: float
    # the record interval under way (`sim.loop`)
    left: int  # steps left in it
    h: float  # its dynamics step, s
    t_end: float  # its end, s
    flight: bool  # taken as one free-flight step
    held: bool  # the active drive held the fingers through all of it so far
    # the integrator
    h_next: float  # the step an adaptive integrator tries next, s (0: none yet)
    h_last: float  # adaptive Euler's last accepted step, s (0.0: none yet)
    # s: how far the rate the contacts' normal damping reads leads the state's velocities (staggered
    # kicks' `integrators.end_forces`; d.now then holds the kinematics at that rate), 0.0 otherwise
    lead: float
    kick: float  # how long adaptive Euler's last velocity update applied its forces, s (`kick_of`: its impulse's span)
    fsal: bool  # the last committed evaluation can be the next step's first stage
    fsal_t: float  # ... at this time,
    fsal_dy: np.ndarray  # (`integrators.state_size`,) its state derivative
    # the last symplectic Euler update's (q, v), and each floating branch's offset from its root
    # then (`integrators.root_offset`: r, u), to start the next from if nothing moved since
    placed: np.ndarray  # (1,) bool: they are set
    placed_q: np.ndarray  # (nq,)
    placed_v: np.ndarray  # (nv,)
    placed_offset: np.ndarray  # (nb, 6)
    fsal_external: np.ndarray  # (6,) its external wrench (force, moment about the origin)
    # an adaptive Euler step's start, put back after a rejected try, and its tries' rates
    # (`integrators.adaptive_euler`): kept here, not allocated at every step
    start_q: np.ndarray  # (nq,)
    start_v: np.ndarray  # (nv,)
    start_a: np.ndarray  # (nv,)
    start_external: np.ndarray  # (6,) the start's external wrench (force, moment about the origin)
    rates: np.ndarray  # (2, rows of `integrators.error_rates`, 6) at a try's start and end
    # the record rows and replay snapshots of one call of the loop
    rows: np.ndarray  # (ROWS_PER_CALL, width)
    n_rows: int
    row_index: int  # the run's index of the next row
    snapshots: Snapshots
    n_snapshots: int
    n_snapshot_pairs: int


@structref.register
class DataType(StructType):
    pass


class Data(StructProxy):
    """A run's compiled Data (see `DataFields` for its fields)."""

    def copy(self) -> Data:
        """A deep copy: no array shared."""
        return new_struct(_copied(view(self)))


register(DataType, DataFields, Data)


def _copied(x):
    if isinstance(x, np.ndarray):
        return x.copy()
    if isinstance(x, StructProxy):
        return new_struct(_copied(view(x)))
    if isinstance(x, tuple) and hasattr(x, "_fields"):
        return type(x)(*(_copied(v) for v in x))
    return x


def make_data(model, rows: int = ROWS_PER_CALL, start: bool = True) -> Data:
    """The Data of a run's start on `model` (an `assemble.model.Model`): at rest in q0 (the
    fingers at their start openings), the first grasp's drive closing (unless not `start`: a
    weld starts the next grasp's itself), no contact, every grasp still to come."""
    sim = model.sim
    nj, nv = model.pin_model.njoints, model.pin_model.nv
    n_g, n_ee, n_mod = len(model.grasps), len(model.end_effectors), len(model.modules)
    nan = lambda n: np.full(n, np.nan)
    snap_cap = rows // sim.record.replay_every + 1
    ints = lambda n: np.zeros(n, dtype=np.int64)
    frames = new_frames(nj)
    f = DataFields(
        t=0.0, q=model.q0.copy(), v=model.v0.copy(), a=np.zeros(nv), tau=np.zeros(nv),
        load=np.zeros(len(sim.actuators.joint)),
        drive_force=np.zeros(len(sim.actuators.joint)), drive_free=np.zeros(len(sim.actuators.joint)),
        response=np.zeros((len(sim.actuators.joint), nv)), transmission=ints(n_ee), screw_force=np.zeros(n_ee),
        current=np.zeros(n_ee), integral=np.zeros(n_ee), encoder_opening=np.zeros(n_ee),
        encoder_t=np.full(n_ee, np.nan), saturated=np.zeros(n_ee, dtype=np.bool_), direction=np.zeros(n_ee),
        R_W=frames.R_W, p_W=frames.p_W, w_W=frames.w_W, vo_W=frames.vo_W, now=new_frames(nj),
        work=new_articulation(nj, nv),
        near=ints(0), travel=math.inf, pair_list=empty_pair_list(len(sim.faces.master_start)),
        candidates=no_candidates(), contacts=no_contacts(), memory=no_memory(), loads=no_loads(nj),
        summary=no_summary(), external_force_W=np.zeros(3), external_torque_O_W=np.zeros(3),
        active=0, stalled=np.zeros(n_ee, dtype=np.bool_), sample_t=0.0, jumped=False,
        drive_stopped=np.zeros(n_g, dtype=np.bool_),
        drive_resumes=ints(n_g), drive_jump=np.zeros(n_g), peak_current=np.zeros(n_g),
        transmission_time=np.zeros((n_g, 3)), transmission_stops=ints(n_g), peak_deceleration=np.zeros(n_g),
        phase=ints(n_g), held_since=math.nan,
        t_start=np.r_[0.0, nan(n_g - 1)], t_contact=nan(n_g), t_complete=nan(n_g),
        peak_force=np.zeros((n_g, 3)), peak_torque=np.zeros((n_g, 3)), peak_force_norm=np.zeros(n_g),
        peak_torque_norm=np.zeros(n_g), peak_pairs=ints(n_g), peak_table_force=np.zeros(n_g),
        peak_table_moment=np.zeros(n_g),
        impulse_W=np.zeros(3), impulse_moment_O_W=np.zeros(3), drive_power=0.0, drive_work=0.0,
        steps=0, pair_steps=0, flights=0, evaluations=0, accepted=0, rejected=0, cut=0,
        energy_start=0.0, energy_now=0.0, energy_passive=math.nan, gravity_datum=0.0, momentum_start=np.zeros(3),
        angular_momentum_start=np.zeros(3), momentum_max=0.0, angular_momentum_max=0.0, momentum_drift=0.0,
        angular_momentum_drift=0.0,
        left=0, h=sim.h, t_end=0.0, flight=False, held=False,
        h_next=0.0, fsal=False, fsal_t=0.0, h_last=0.0, lead=0.0, kick=0.0,
        fsal_dy=np.zeros(state_size(sim.tree, sim.branches)), fsal_external=np.zeros(6),
        placed=np.zeros(1, dtype=np.bool_), placed_q=np.zeros(model.pin_model.nq), placed_v=np.zeros(nv),
        placed_offset=np.zeros((len(sim.branches.joint), 6)),
        start_q=np.zeros(model.pin_model.nq), start_v=np.zeros(nv), start_a=np.zeros(nv), start_external=np.zeros(6),
        rates=np.zeros((2, len(sim.integrator.lever), 6)),
        rows=np.zeros((rows, sim.record.width)), n_rows=0, row_index=0,
        snapshots=Snapshots(row=ints(snap_cap), pairs=ints(snap_cap), force_W=np.zeros((snap_cap, n_mod, 3)),
                            master=ints(64), slave=ints(64), state=ints(64)),
        n_snapshots=0, n_snapshot_pairs=0)
    data = new_struct(f)
    if start:
        start_drive(sim, data)  # the first grasp's drive closes from the start (no load yet)
    return data
