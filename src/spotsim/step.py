"""One simulation step as the paper's Fig. 5 reads it.

kinematics -> broad phase -> sphere pairs -> forces -> wrenches -> dynamics -> integrate ->
grasp phase. Each stage is a function of (model, data, ...); `Data` holds all that changes.
The run loop around the step is in `run.py`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from .bodies import body_kinematics
from .contact.forces import body_wrenches, contact_summary, pair_forces
from .contact.search import all_pairs, empty_pair_list, grid_search, listed_search
from .jit import njit, njit_inline
from .grasp import FingerDrive, GraspPhase
from .errors import SimulationError
from .model import Model
from .record import drive_power


class StateOverflow(SimulationError):
    """The state grew past what the broad phase can represent: the run has diverged."""


@dataclass
class Contacts:
    """The sphere pairs in contact at one step, sorted by key (master * |S2| + slave)."""

    master: np.ndarray
    slave: np.ndarray
    key: np.ndarray
    phi: np.ndarray = None
    point_W: np.ndarray = None
    c1_W: np.ndarray = None  # master and slave sphere centres, for the negative control
    c2_W: np.ndarray = None
    force_W: np.ndarray = None  # on the master (finger); the slave gets the opposite
    speed: np.ndarray = None  # |relative velocity| at the contact point, m/s
    state: np.ndarray = None
    memory: tuple = None  # (key, bristle deflection, onset approach speed) after this step


@dataclass
class Data:
    """Everything that changes during a run."""

    t: float
    q: np.ndarray
    v: np.ndarray
    pin_data: pin.Data
    geom_data: pin.GeometryData
    manager: object
    phases: list  # GraspPhase of each grasp, in sequence order
    R_W: np.ndarray  # (njoints, 3, 3) rotation of each contact joint
    p_W: np.ndarray  # (njoints, 3) origin of each contact joint
    w_W: np.ndarray  # (njoints, 3) angular velocity in world
    vo_W: np.ndarray  # (njoints, 3) velocity of the joint origin in world
    mem_key: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    mem_s: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    mem_vminus: np.ndarray = field(default_factory=lambda: np.zeros(0))
    drives: list = None  # FingerDrive of each end-effector
    opening: np.ndarray = None  # (n_fingers,) each finger's opening, m
    opening_rate: np.ndarray = None  # (n_fingers,) its rate during the current step, m/s
    finger_load: np.ndarray = None
    contacts: Contacts = None
    f_ext: pin.StdVec_Force = None  # (njoints,) pin.Force on each body, its joint's frame
    f_views: list = None  # a writable view of each one's 6-vector
    tau: np.ndarray = None  # joint torques: none, every joint is free or reduced away
    summary: np.ndarray = field(default_factory=lambda: np.zeros(8))  # contact_summary of the step
    active: int = 0  # the grasp under way
    joint_force_W: np.ndarray = None  # (njoints, 3) contact force on each body, world
    joint_torque_O_W: np.ndarray = None  # (njoints, 3) its moment about the world origin
    near_pairs: np.ndarray = None  # indices of the face pairs coal kept at its last run
    travel: float = np.inf  # bound on any two spheres' relative motion since then, m
    pair_list: tuple = None  # the search's candidate pairs (contact.search.PairList)
    drive_power: float = 0.0  # the finger drives' power during the last step, W (bound)
    external_force_W: np.ndarray = field(default_factory=lambda: np.zeros(3))
    external_torque_O_W: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def phase(self) -> GraspPhase:
        """The phase of the grasp under way."""
        return self.phases[self.active]


def make_data(model: Model) -> Data:
    m = model.pin_model
    pdata = m.createData()
    gdata = pin.GeometryData(model.geom_model)
    for req in gdata.collisionRequests:
        req.security_margin = model.params.margin
    manager = None
    if model.params.broad_phase == "coal":
        manager = pin.BroadPhaseManager_DynamicAABBTreeCollisionManager(m, model.geom_model, gdata)
    c, ee = model.scenario.completion, model.scenario.end_effector
    phases = [GraspPhase(c.hold_s, c.max_contact_speed_m_s, c.max_net_force_N) for _ in model.grasps]
    nj = m.njoints
    n_f = len(model.fingers)
    f_ext = pin.StdVec_Force()  # ABA takes it as it is; a Python list is converted each call
    for _ in range(nj):
        f_ext.append(pin.Force.Zero())
    return Data(0.0, model.q0.copy(), model.v0.copy(), pdata, gdata, manager, phases,
                np.tile(np.eye(3), (nj, 1, 1)), np.zeros((nj, 3)), np.zeros((nj, 3)),
                np.zeros((nj, 3)), finger_load=np.zeros(n_f),
                drives=[FingerDrive(ee.closing_speed_m_s, ee.grasp_load_N, ee.resume_fraction)
                        for _ in model.end_effectors],
                joint_force_W=np.zeros((nj, 3)), joint_torque_O_W=np.zeros((nj, 3)),
                opening=np.array([f.opening_start for f in model.fingers]),
                opening_rate=np.zeros(n_f), f_ext=f_ext, f_views=[f_ext[j].vector for j in range(nj)],
                tau=np.zeros(m.nv), pair_list=empty_pair_list(len(model.face_pairs)))


# ------------------------------------------------------------------------------ stages


def kinematics(model: Model, data: Data) -> None:
    """Placements and world velocities of the bodies that carry contact faces (all free
    bodies; fixed ones stay at the identity)."""
    body_kinematics(model.bodies, data.q, data.v, data.R_W, data.p_W, data.w_W, data.vo_W)


def finger_centres_J(model: Model, data: Data) -> np.ndarray:
    """(|S1|, 3) the master spheres' centres at the current openings, their joints' frames, m."""
    return model.master.centres_J + data.opening[model.master_finger, None] * model.master_axis_J


def broad_phase(model: Model, data: Data) -> np.ndarray:
    """Indices into model.face_pairs of the face pairs whose patches lie within the security
    margin (coal), or of all of them."""
    if data.manager is None:
        return np.arange(len(model.face_pairs))
    pin.forwardKinematics(model.pin_model, data.pin_data, data.q)
    pin.updateGeometryPlacements(model.pin_model, data.pin_data, model.geom_model, data.geom_data)
    for g, k in model.finger_geoms:  # finger patches slide along their axes by the opening
        f = model.fingers[k]
        M = data.geom_data.oMg[g]
        R = data.pin_data.oMi[f.parent_joint].rotation
        M.translation = M.translation + R @ f.axis_J * data.opening[k]
        data.geom_data.oMg[g] = M
    try:
        data.manager.update(False)
        pin.computeCollisions(data.manager, False)
    except ValueError as e:  # coal rejects bounds that overflowed
        reason = str(e).strip().splitlines()[-1].removeprefix("message: ")
        raise StateOverflow(f"state left the representable range (coal: {reason})") from e
    results = data.geom_data.collisionResults
    return np.array([i for i, fp in enumerate(model.face_pairs) if results[fp.geom_pair].isCollision()],
                    dtype=np.int64)


def refresh_broad_phase(model: Model, data: Data) -> None:
    """Run the broad phase anew: its face pairs start a fresh skin (the search's pair list
    checks itself against the face pairs it was built for)."""
    data.near_pairs, data.travel = broad_phase(model, data), 0.0


def near_face_pairs(model: Model, data: Data) -> np.ndarray:
    """The broad phase's face pairs, reused while they are valid (Verlet skin): a face pair
    coal left out was at least the margin apart, and stays beyond contact reach until the
    spheres have moved the skin relative to each other."""
    if data.travel > model.params.skin:
        refresh_broad_phase(model, data)
    return data.near_pairs


def candidate_pairs(model: Model, data: Data, near) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(master, slave, key) sphere pairs in contact, sorted by key: a local grid search inside
    the face pairs `near` (indices into model.face_pairs)."""
    p = model.params
    M = model.master
    return grid_search(np.asarray(near, dtype=np.int64), model.face_table, M.centres_J, M.normals_J,
                       model.master_finger, model.master_axis_J, data.opening,
                       model.slave_maps, len(model.slave.centres_J), data.R_W, data.p_W, p.r1, p.r2, p.cutoff)


def literal_pairs(model: Model, data: Data) -> tuple[np.ndarray, np.ndarray]:
    """The paper's search: every master sphere against every slave sphere (reference)."""
    C1, N1 = model.master.to_world(data.R_W, data.p_W, finger_centres_J(model, data))
    C2, N2 = model.slave.to_world(data.R_W, data.p_W)
    return all_pairs(model.master, model.slave, C1, N1, C2, N2)


def sphere_pairs(model: Model, data: Data) -> Contacts:
    """The pairs in contact (Eq. 6-10), found by the configured search, sorted by key."""
    if model.params.broad_phase == "none":
        m_idx, s_idx = literal_pairs(model, data)
        key = m_idx * len(model.slave.centres_J) + s_idx
        order = np.argsort(key, kind="stable")
        return Contacts(m_idx[order], s_idx[order], key[order])
    return Contacts(*candidate_pairs(model, data, near_face_pairs(model, data)))


def contact_forces(model: Model, data: Data, c: Contacts, h: float, commit: bool = True) -> Contacts:
    """Normal (Eq. 11-13) and bristle friction (Eq. 14-17) force of each pair, on the master.

    Pairs that are not in contact are dropped; each remaining pair's bristle deflection and
    onset approach speed carry over from the last step (new pairs start from zero). The new
    memory is the contacts' `memory`, and with commit, data's.
    """
    M, S, p = model.master, model.slave, model.params
    out = pair_forces(c.master, c.slave, c.key, M.centres_J, M.normals_J, M.joint, model.master_finger,
                      model.master_axis_J, S.centres_J, S.normals_J, S.joint, data.R_W, data.p_W,
                      data.w_W, data.vo_W, data.opening, data.opening_rate, data.mem_key, data.mem_s, data.mem_vminus,
                      p.r1, p.r2, p.K, p.damping_factor, p.approach_speed_floor, h, p.bristle)
    c = Contacts(*out[:10])
    c.memory = (c.key, out[10], out[11])
    if commit:
        data.mem_key, data.mem_s, data.mem_vminus = c.memory
    return c


def wrenches(model: Model, data: Data, c: Contacts) -> list:
    """One wrench per body (Eq. 18-21): +f_i on the finger, -f_i on the module, at p_i.

    A finger's wrench acts on the body it is mounted on. Returned as Pinocchio external forces,
    each in its joint's local frame. Also sets each finger's load along its opening axis.
    """
    local, data.joint_force_W, data.joint_torque_O_W, data.external_force_W, data.external_torque_O_W, \
        data.finger_load = body_wrenches(c.master, c.slave, c.force_W, c.point_W, c.c1_W, c.c2_W,
                                         model.params.force_point == "common", model.master.joint,
                                         model.slave.joint, model.master_finger, model.finger_parent,
                                         model.finger_axis_J, data.R_W, data.p_W, model.pin_model.njoints)
    for view, w in zip(data.f_views, local):  # written into the Force objects ABA reads
        view[:] = w
    return data.f_ext


def contact_stage(model: Model, data: Data, h: float, commit: bool = True) -> Contacts:
    """kinematics -> broad phase -> sphere pairs -> forces -> wrenches, for one step of h.

    The culled search runs the stages' kernels in one compiled call; the literal search
    (the reference) runs them one by one. commit=False leaves the pair memory as it was (a
    Runge-Kutta stage); the new memory is then in the contacts' `memory`.
    """
    if model.params.broad_phase == "none":
        kinematics(model, data)
        c = contact_forces(model, data, sphere_pairs(model, data), h, commit)
        wrenches(model, data, c)
        data.summary = contact_summary(data.joint_force_W, data.joint_torque_O_W, data.R_W, data.p_W,
                                       *model.watch_args[data.active], c.speed, c.phi)
        return c
    near = near_face_pairs(model, data)
    # the pair list checks itself against the state it is used at, so a Runge-Kutta stage
    # may use and rebuild it too
    pairs, (local, data.joint_force_W, data.joint_torque_O_W, data.external_force_W, data.external_torque_O_W,
            data.finger_load), data.summary, data.pair_list = model.contact_call(
        data.q, data.v, data.R_W, data.p_W, data.w_W, data.vo_W, near, data.opening,
        data.opening_rate, data.mem_key, data.mem_s, data.mem_vminus, h, data.pair_list,
        *model.watch_args[data.active], *model.contact_kernel_args)
    c = Contacts(*pairs[:10])
    c.memory = (c.key, pairs[10], pairs[11])
    if commit:
        data.mem_key, data.mem_s, data.mem_vminus = c.memory
    for view, w in zip(data.f_views, local):  # written into the Force objects ABA reads
        view[:] = w
    return c


def contact_kernel_args(model: Model) -> tuple:
    """The model's part of `_contact_kernels`' arguments, in its order."""
    M, S, p = model.master, model.slave, model.params
    return (model.bodies, model.face_table, model.slave_maps, M.centres_J, M.normals_J, M.joint,
            model.master_finger, model.master_axis_J, S.centres_J, S.normals_J, S.joint, p.r1, p.r2, p.K,
            p.damping_factor, p.approach_speed_floor, p.cutoff, p.bristle, p.force_point == "common",
            model.finger_parent, model.finger_axis_J)


@njit
def _contact_kernels(q, v, R_W, p_W, w_W, vo_W, near, opening, opening_rate, mem_key, mem_s, mem_vminus, h,
                     pair_list, ee_joint, R_ee, module_joint, lever, bodies, table, maps, C1_J, N1_J, joint1, finger1, axis1_J, C2_J, N2_J, joint2,
                     r1, r2, K, damping, floor, cutoff, bristle, common_point, finger_parent, finger_axis_J):
    """The kernels of `kinematics`, `candidate_pairs` (from the pair list), `contact_forces` and
    `wrenches`, chained, and the `contact_summary` of the step; then the pair list."""
    body_kinematics(bodies, q, v, R_W, p_W, w_W, vo_W)
    (master, slave, key), pair_list = listed_search(
        near, table, C1_J, N1_J, finger1, axis1_J, opening, maps, C2_J.shape[0], R_W, p_W, r1, r2, cutoff,
        pair_list)
    pairs = pair_forces(master, slave, key, C1_J, N1_J, joint1, finger1, axis1_J, C2_J, N2_J, joint2,
                        R_W, p_W, w_W, vo_W, opening, opening_rate, mem_key, mem_s, mem_vminus,
                        r1, r2, K, damping, floor, h, bristle)
    loads = body_wrenches(pairs[0], pairs[1], pairs[7], pairs[4], pairs[5], pairs[6], common_point,
                          joint1, joint2, finger1, finger_parent, finger_axis_J, R_W, p_W, R_W.shape[0])
    summary = contact_summary(loads[1], loads[2], R_W, p_W, ee_joint, R_ee, module_joint, lever, pairs[8],
                              pairs[3])
    return pairs, loads, summary, pair_list


# -------------------------------------------------------------------------------- step


def step(model: Model, data: Data, h: float, integrator) -> Contacts:
    """Advance the scene by h seconds (an adaptive integrator may take less: data.t tells);
    returns the contacts that acted during the step."""
    contacts, h = integrator.advance(model, data, h)  # forces -> dynamics -> integrate
    data.drive_power = drive_power(data.finger_load, data.opening_rate)  # at this step's rate
    # the active grasp's drive sets its fingers' rate for the coming step from this step's
    # loads; the other end-effectors hold (their rates stay zero)
    active_ee = model.grasps[data.active][0]
    mine = model.drive_fingers[active_ee]
    if len(mine):
        data.opening_rate[mine] = data.drives[active_ee].opening_rate(data.finger_load[mine])
    if not integrator.moves_fingers:
        data.opening += h * data.opening_rate
    data.t += h
    data.travel += h * travel_rate(model, data)
    data.contacts = contacts
    grasp_phase(model, data, contacts)
    return contacts


#: Free flight takes the travel bound at the start of a step times this for the whole step: in
#: zero gravity and without contact the centroid velocities are constant and the fingers close
#: at their set speed; only the spin's direction changes, and bodies are barely moving then.
FREE_FLIGHT_SAFETY = 2.0


def free_flight(model: Model, data: Data, H: float) -> bool:
    """Whether no sphere pair can come into contact within the next H seconds, so that a step
    of H (no contact forces, zero gravity) is exact for the centroids.

    True when coal's face pairs (refreshed if the skin is used up) are all beyond the margin
    and the travel bound over H keeps within the skin. Never with the literal search.
    """
    if model.params.broad_phase == "none":
        return False
    return len(near_face_pairs(model, data)) == 0 and \
        data.travel + FREE_FLIGHT_SAFETY * H * travel_rate(model, data) <= model.params.skin


def travel_rate(model: Model, data: Data) -> float:
    """A bound on how fast any two contact spheres approach each other, m/s: the sum over the
    free contact bodies of |v_O| + |omega| reach, plus the fastest finger slide."""
    rows, reach = model.reach_table
    return _travel_rate(model.bodies.idx_v, rows, reach, data.v, data.opening_rate)


@njit_inline
def _travel_rate(idx_v, rows, reach, v, opening_rate):
    rate = 0.0
    for x in opening_rate:
        rate = max(rate, abs(x))
    for b, r in zip(rows, reach):
        iv = idx_v[b]  # a free-flyer's v = (v_O, omega) in its frame; norms are frame-free
        rate += math.sqrt(v[iv] ** 2 + v[iv + 1] ** 2 + v[iv + 2] ** 2) + \
            math.sqrt(v[iv + 3] ** 2 + v[iv + 4] ** 2 + v[iv + 5] ** 2) * r
    return rate


def completion_inputs(model: Model, data: Data) -> tuple[bool, float, float]:
    """What the completion criteria read from the last step: whether the active drive has
    stalled, the fastest relative speed at a contact (m/s) and the net contact force on the
    module (N)."""
    w = data.summary
    return (data.drives[model.grasps[data.active][0]].stalled, float(w[6]),
            math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]))


def grasp_phase(model: Model, data: Data, c: Contacts) -> None:
    """Advance the active grasp's phase on this step's contacts (approach -> self-centring ->
    complete)."""
    data.phase.update(data.t, len(c.key), *completion_inputs(model, data))
