"""One simulation step as the paper's Fig. 5 reads it.

kinematics -> broad phase -> sphere pairs -> forces -> wrenches -> dynamics -> integrate ->
grasp phase. Each stage is a function of (model, data, ...); `Data` holds all that changes.
The run loop around the step is in `run.py`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from .contact.detection import contact_point, penetration
from .contact.friction import bristle_step
from .contact.normal import indentation, normal_force
from .contact.search import all_pairs, grid_search
from .grasp import FingerDrive, GraspPhase
from .errors import SimulationError
from .model import Model


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
    C1_J: np.ndarray = None  # (|S1|, 3) master sphere centres at the current openings
    finger_load: np.ndarray = None
    contacts: Contacts = None
    f_ext: list = None
    active: int = 0  # the grasp under way
    joint_force_W: np.ndarray = None  # (njoints, 3) contact force on each body, world
    joint_torque_O_W: np.ndarray = None  # (njoints, 3) its moment about the world origin
    near_pairs: list = None  # face pairs coal kept at its last run
    travel: float = np.inf  # bound on any two spheres' relative motion since then, m
    external_force_W: np.ndarray = field(default_factory=lambda: np.zeros(3))
    external_torque_O_W: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def phase(self) -> GraspPhase:
        """The phase of the grasp under way."""
        return self.phases[self.active]

    def module_force_W(self, model: Model) -> np.ndarray:
        """Combined contact force on the active grasp's module, world, N."""
        return self.joint_force_W[model.modules[model.grasps[self.active][1]].joint]

    def module_torque_O_W(self, model: Model) -> np.ndarray:
        """Its moment about the world origin, N m."""
        return self.joint_torque_O_W[model.modules[model.grasps[self.active][1]].joint]


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
    return Data(0.0, model.q0.copy(), model.v0.copy(), pdata, gdata, manager, phases,
                np.tile(np.eye(3), (nj, 1, 1)), np.zeros((nj, 3)), np.zeros((nj, 3)),
                np.zeros((nj, 3)), finger_load=np.zeros(n_f),
                drives=[FingerDrive(ee.closing_speed_m_s, ee.grasp_load_N, ee.resume_fraction)
                        for _ in model.end_effectors],
                joint_force_W=np.zeros((nj, 3)), joint_torque_O_W=np.zeros((nj, 3)),
                opening=np.array([f.opening_start for f in model.fingers]),
                opening_rate=np.zeros(n_f))


# ------------------------------------------------------------------------------ stages


def kinematics(model: Model, data: Data) -> None:
    """Placements and world velocities of the bodies that carry contact faces, and the finger
    spheres' centres at the current openings."""
    pin.forwardKinematics(model.pin_model, data.pin_data, data.q, data.v)
    data.C1_J = model.master.centres_J + data.opening[model.master_finger, None] * model.master_axis_J
    for j in model.contact_joints:
        M = data.pin_data.oMi[j]
        nu = data.pin_data.v[j]
        data.R_W[j] = M.rotation
        data.p_W[j] = M.translation
        data.w_W[j] = M.rotation @ nu.angular
        data.vo_W[j] = M.rotation @ nu.linear


def broad_phase(model: Model, data: Data):
    """Face pairs whose patches lie within the security margin (coal), or all of them."""
    if data.manager is None:
        return model.face_pairs
    pin.updateGeometryPlacements(model.pin_model, data.pin_data, model.geom_model, data.geom_data)
    for g, k in model.finger_geoms:  # finger patches slide along their axes by the opening
        f = model.fingers[k]
        M = data.geom_data.oMg[g]
        M.translation = M.translation + data.R_W[f.parent_joint] @ f.axis_J * data.opening[k]
        data.geom_data.oMg[g] = M
    try:
        data.manager.update(False)
        pin.computeCollisions(data.manager, False)
    except ValueError as e:  # coal rejects bounds that overflowed
        reason = str(e).strip().splitlines()[-1].removeprefix("message: ")
        raise StateOverflow(f"state left the representable range (coal: {reason})") from e
    results = data.geom_data.collisionResults
    return [fp for fp in model.face_pairs if results[fp.geom_pair].isCollision()]


def candidate_pairs(model: Model, data: Data, face_pairs) -> tuple[np.ndarray, np.ndarray]:
    """(master, slave) sphere pairs in contact: a local grid search inside each face pair."""
    p = model.params
    return grid_search(face_pairs, data.C1_J, model.master.normals_J, model.slave_maps, data.R_W,
                       data.p_W, p.r1, p.r2, p.cutoff)


def literal_pairs(model: Model, data: Data) -> tuple[np.ndarray, np.ndarray]:
    """The paper's search: every master sphere against every slave sphere (reference)."""
    C1, N1 = model.master.to_world(data.R_W, data.p_W, data.C1_J)
    C2, N2 = model.slave.to_world(data.R_W, data.p_W)
    return all_pairs(model.master, model.slave, C1, N1, C2, N2)


def sphere_pairs(model: Model, data: Data) -> Contacts:
    """The pairs in contact (Eq. 6-10), found by the configured search, sorted by key."""
    if model.params.broad_phase == "none":
        m_idx, s_idx = literal_pairs(model, data)
    else:
        # Verlet skin: a face pair coal left out was at least the margin apart, and stays
        # beyond contact reach until the spheres have moved the skin relative to each other
        if data.travel > model.params.skin:
            data.near_pairs, data.travel = broad_phase(model, data), 0.0
        m_idx, s_idx = candidate_pairs(model, data, data.near_pairs)
    key = m_idx * len(model.slave.centres_J) + s_idx
    order = np.argsort(key, kind="stable")
    return Contacts(m_idx[order], s_idx[order], key[order])


def contact_forces(model: Model, data: Data, c: Contacts, h: float) -> Contacts:
    """Normal (Eq. 11-13) and bristle friction (Eq. 14-17) force of each pair, on the master.

    Pairs that are not in contact are dropped; each remaining pair's bristle deflection and
    onset approach speed carry over from the last step (new pairs start from zero).
    """
    M, S, p = model.master, model.slave, model.params
    if len(c.key) == 0:  # nothing touches: every pair's memory ends
        data.mem_key, data.mem_s, data.mem_vminus = c.key, np.zeros((0, 3)), np.zeros(0)
        c.phi, c.point_W, c.force_W, c.speed = np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
        c.state = np.zeros(0, dtype=np.int64)
        return c
    jm, js = M.joint[c.master], S.joint[c.slave]
    Rm, Rs = data.R_W[jm], data.R_W[js]
    c1 = np.einsum("kij,kj->ki", Rm, data.C1_J[c.master]) + data.p_W[jm]
    c2 = np.einsum("kij,kj->ki", Rs, S.centres_J[c.slave]) + data.p_W[js]
    n1 = np.einsum("kij,kj->ki", Rm, M.normals_J[c.master])
    n2 = np.einsum("kij,kj->ki", Rs, S.normals_J[c.slave])
    n_c, phi, hit = penetration(c1, n1, p.r1, c2, n2, p.r2)
    if not hit.all():
        keep = np.flatnonzero(hit)
        c = Contacts(c.master[keep], c.slave[keep], c.key[keep])
        jm, js, c1, c2, n_c, phi = jm[keep], js[keep], c1[keep], c2[keep], n_c[keep], phi[keep]
        Rm = Rm[keep]
    point = contact_point(c1, c2, p.r1, p.r2, n_c, phi)
    finger = model.master_finger[c.master]
    slide_W = np.einsum("kij,kj->ki", Rm, model.master_axis_J[c.master]) * data.opening_rate[finger, None]
    v_A = data.vo_W[jm] + np.cross(data.w_W[jm], point - data.p_W[jm]) + slide_W
    v_B = data.vo_W[js] + np.cross(data.w_W[js], point - data.p_W[js])
    v_rel = v_A - v_B
    delta = indentation(phi)
    delta_dot = -0.5 * np.einsum("ij,ij->i", v_rel, n_c)  # rate of delta = phi/2

    pos = np.searchsorted(data.mem_key, c.key)
    pos_ok = np.minimum(pos, max(len(data.mem_key) - 1, 0))
    known = (pos < len(data.mem_key)) & (data.mem_key[pos_ok] == c.key) if len(data.mem_key) else \
        np.zeros(len(c.key), dtype=bool)
    onset_speed = np.maximum(delta_dot, p.approach_speed_floor)
    v_minus = np.where(known, data.mem_vminus[pos_ok] if len(data.mem_key) else 0.0, onset_speed)
    s_prev = np.where(known[:, None], data.mem_s[pos_ok] if len(data.mem_key) else 0.0, 0.0)

    F_n = normal_force(delta, delta_dot, v_minus, p.K, p.damping_factor)
    s, F_f, state = bristle_step(s_prev, v_rel, n_c, F_n, h, p.bristle)
    data.mem_key, data.mem_s, data.mem_vminus = c.key, s, v_minus
    c.phi, c.point_W, c.state, c.c1_W, c.c2_W = phi, point, state, c1, c2
    c.force_W = F_n[:, None] * n_c + F_f  # Eq. (18): f_i = F_n,i + F_f,i, on the master
    c.speed = np.linalg.norm(v_rel, axis=1)
    return c


def wrenches(model: Model, data: Data, c: Contacts) -> list:
    """One wrench per body (Eq. 18-21): +f_i on the finger, -f_i on the module, at p_i.

    A finger's wrench acts on the body it is mounted on. Returned as Pinocchio external forces,
    each in its joint's local frame. Also sets each finger's load along its opening axis.
    """
    nj = model.pin_model.njoints
    if len(c.key) == 0:
        data.joint_force_W = np.zeros((nj, 3))
        data.joint_torque_O_W = np.zeros((nj, 3))
        data.external_force_W, data.external_torque_O_W = np.zeros(3), np.zeros(3)
        data.finger_load[:] = 0.0
        return [pin.Force.Zero() for _ in range(nj)]
    joint = np.concatenate([model.master.joint[c.master], model.slave.joint[c.slave]])
    f = np.concatenate([c.force_W, -c.force_W])
    if model.params.force_point == "common":
        points = np.concatenate([c.point_W, c.point_W])
    else:  # negative control: each body's force at its own sphere's centre
        points = np.concatenate([c.c1_W, c.c2_W])
    arm = points - data.p_W[joint]
    tau = np.cross(arm, f)
    F = np.stack([np.bincount(joint, f[:, i], nj) for i in range(3)], axis=1)
    T = np.stack([np.bincount(joint, tau[:, i], nj) for i in range(3)], axis=1)
    f_ext = [pin.Force.Zero() for _ in range(nj)]
    for j in model.contact_joints:
        R = data.R_W[j]
        f_ext[j] = pin.Force(R.T @ F[j], R.T @ T[j])
    data.joint_force_W = F
    data.joint_torque_O_W = T + np.cross(data.p_W, F)
    # the free bodies' external load: what a fixed body (joint 0) exerts on them; forces
    # between two free bodies are internal and are left out
    n = len(c.key)  # rows [0, n) are the masters' sides of the pairs, [n, 2n) the slaves'
    partner = np.concatenate([joint[n:], joint[:n]])
    ext = (partner == 0) & (joint != 0)
    data.external_force_W = f[ext].sum(axis=0)
    data.external_torque_O_W = np.cross(points[ext], f[ext]).sum(axis=0)
    finger = model.master_finger[c.master]
    for k, fg in enumerate(model.fingers):
        on_k = finger == k
        axis_W = data.R_W[fg.parent_joint] @ fg.axis_J
        data.finger_load[k] = max(float(c.force_W[on_k].sum(axis=0) @ axis_W), 0.0)
    return f_ext


# -------------------------------------------------------------------------------- step


def step(model: Model, data: Data, h: float, integrator) -> Contacts:
    """Advance the scene by h seconds; returns the contacts that acted during the step."""
    kinematics(model, data)
    contacts = contact_forces(model, data, sphere_pairs(model, data), h)
    data.f_ext = wrenches(model, data, contacts)
    m = model.pin_model
    a = pin.aba(m, data.pin_data, data.q, data.v, np.zeros(m.nv), data.f_ext)
    data.q, data.v = integrator.step(m, data.q, data.v, a, h)
    # the active grasp's drive sets its fingers' rate for the coming step from this step's
    # loads; the other end-effectors hold
    active_ee = model.grasps[data.active][0]
    for e, (drive, mine) in enumerate(zip(data.drives, model.drive_fingers, strict=True)):
        if len(mine):
            data.opening_rate[mine] = drive.opening_rate(data.finger_load[mine]) if e == active_ee else 0.0
    data.opening += h * data.opening_rate
    data.t += h
    data.travel += h * travel_rate(model, data)
    data.contacts = contacts
    grasp_phase(model, data, contacts)
    return contacts


def travel_rate(model: Model, data: Data) -> float:
    """A bound on how fast any two contact spheres approach each other, m/s: the sum over the
    contact bodies of |v_O| + |omega| reach, plus the fastest finger slide. Uses the
    velocities of the step just taken (R_W, vo_W, w_W from its kinematics)."""
    rate = float(np.abs(data.opening_rate).max()) if len(data.opening_rate) else 0.0
    nu = data.v
    m = model.pin_model
    for j, reach in model.sphere_reach:
        if j == 0:
            continue
        iv = m.idx_vs[j]
        if m.nvs[j] == 6:  # free-flyer: v = (v_O, omega) in its frame; norms are frame-free
            rate += float(np.linalg.norm(nu[iv:iv + 3]) + np.linalg.norm(nu[iv + 3:iv + 6]) * reach)
        else:
            rate += float(np.linalg.norm(data.vo_W[j]) + np.linalg.norm(data.w_W[j]) * reach)
    return rate


def grasp_phase(model: Model, data: Data, c: Contacts) -> None:
    """Advance the active grasp's phase on this step's contacts (approach -> self-centring ->
    complete)."""
    speed = float(c.speed.max()) if len(c.key) else 0.0
    data.phase.update(data.t, len(c.key), data.drives[model.grasps[data.active][0]].stalled, speed,
                      float(np.linalg.norm(data.module_force_W(model))))
