"""Scenario -> Model: the Pinocchio scene, its contact faces, sphere layers and parameters.

Everything here is fixed for a run. The arm is self-locked during the grasp (paper Sec. 4.1),
so its joints are reduced away with `pin.buildReducedModel`. The fingers' prismatic joints are
reduced away too: their drive prescribes their motion, so they carry no dynamic degree of
freedom. Their mass joins the body they are mounted on, their faces slide along their joint
axes by the drive's opening, and their contact loads act on that body. The scene keeps one
free-flyer per free body: here the module's.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import coal
import numpy as np
import pinocchio as pin

from . import assets
from .contact.detection import cutoff_distance
from .contact.friction import BristleParams
from .contact.normal import damping_factor, hertz_stiffness
from .contact.search import FacePair, LayerSet, SlaveGrid
from .errors import ModelError, ScenarioError
from .scenario import Scenario
from .spheres import contact_faces, sphere_layer

SCENE_XACRO = assets.URDF_DIR / "single_arm_scene.urdf.xacro"
ARM_JOINTS = {"z1": ["joint1", "joint2", "joint3", "joint4", "joint5", "joint6"]}
#: Joints of the arm's own hardware that the grasp never moves (the Z1 stock gripper).
ARM_FIXED_JOINTS = {"z1": {"jointGripper": 0.0}}
GRASP_FRAME = "ee_grasp"
FINGER_JOINTS = ("ee_finger_upper", "ee_finger_lower")
MODULE_JOINT = "tm_free_flyer"
#: Smallest eigenvalue a body's inertia may have, kg m^2, below which it is not positive definite.
MIN_INERTIA_EIGENVALUE = 1e-12


@dataclass(frozen=True)
class ContactParams:
    """Contact law constants: radii (m), Hertz K (N/m^1.5), damping factor, floors."""

    r1: float
    r2: float
    K: float
    damping_factor: float
    approach_speed_floor: float
    cutoff: float
    margin: float
    bristle: BristleParams
    broad_phase: str


@dataclass(frozen=True)
class Finger:
    """A finger moved by its drive along its prismatic axis, on the body of joint `parent_joint`.

    axis_J: (3,) its opening direction in that joint's frame. drive: index of its drive.
    opening_touch, opening_start: openings (m) at first touch of a centred groove and at start;
    the master spheres' centres are given at opening 0.
    """

    name: str
    parent_joint: int
    axis_J: np.ndarray
    drive: int
    opening_touch: float
    opening_start: float


@dataclass(frozen=True)
class Model:
    scenario: Scenario
    urdf: str
    pin_model: pin.Model
    geom_model: pin.GeometryModel
    module_joint: int
    fingers: tuple[Finger, ...]
    master_finger: np.ndarray  # (|S1|,) the finger each master sphere is on
    master_axis_J: np.ndarray  # (|S1|, 3) that finger's opening axis, in the sphere's joint frame
    finger_geoms: tuple[tuple[int, int], ...]  # (geometry object, finger) of each finger patch
    oMa: pin.SE3  # grasp frame O_a in world (the arm is locked and fixed)
    contact_joints: tuple[int, ...]  # joints carrying contact faces
    master: LayerSet
    slave: LayerSet
    face_pairs: tuple[FacePair, ...]
    slave_maps: np.ndarray  # (n_slave_faces, ni, nj) global slave index per grid node, -1 if none
    params: ContactParams
    q0: np.ndarray
    v0: np.ndarray


def xacro_args(s: Scenario) -> dict[str, float]:
    """The scene XACRO's arguments from a scenario's geometry and module sections."""
    args = {f.name: getattr(s.geometry, f.name) for f in fields(s.geometry)}
    m = s.module
    args.update(module_mass_kg=m.mass_kg, module_com_x_mm=m.com_mm[0],
                module_com_y_mm=m.com_mm[1], module_com_z_mm=m.com_mm[2])
    args.update({f"module_{k.name}": getattr(m.inertia_kg_m2, k.name) for k in fields(m.inertia_kg_m2)})
    return args


def check_inertias(model: pin.Model, joints=None) -> None:
    """Reject non-finite values, negative masses and inertias that are not positive definite.

    Pinocchio accepts all of these silently. `joints`: the bodies that must have mass > 0.
    """
    problems = []
    for j in range(1, model.njoints):
        I = model.inertias[j]
        name = model.names[j]
        if not (np.isfinite(I.mass) and np.all(np.isfinite(I.lever)) and np.all(np.isfinite(I.inertia))):
            problems.append(f"body of joint {name}: non-finite mass, centroid or inertia")
            continue
        if I.mass < 0 or (joints is not None and j in joints and I.mass <= 0):
            problems.append(f"body of joint {name}: mass {I.mass} kg must be > 0")
        if I.mass > 0 and np.linalg.eigvalsh(I.inertia).min() < MIN_INERTIA_EIGENVALUE:
            problems.append(f"body of joint {name}: inertia {I.inertia.tolist()} is not positive definite")
    if problems:
        raise ModelError("; ".join(problems))


def _lock_arm(full: pin.Model, s: Scenario) -> tuple[pin.Model, list[str]]:
    """Reduce away the arm's joints (at the scenario's angles) and the fingers' (at opening 0)."""
    names = ARM_JOINTS[s.arm.model]
    q_ref = pin.neutral(full)
    problems = []
    lock = []
    for name, angle in [*zip(names, s.arm.joint_angles_rad), *ARM_FIXED_JOINTS[s.arm.model].items()]:
        j = full.getJointId(name)
        lo, hi = full.lowerPositionLimit[full.idx_qs[j]], full.upperPositionLimit[full.idx_qs[j]]
        if not lo <= angle <= hi and name in names:
            problems.append(f"arm.joint_angles_rad[{names.index(name)}] = {angle}: "
                            f"must be within the {name} limits [{lo:.4f}, {hi:.4f}] rad")
        q_ref[full.idx_qs[j]] = angle
        lock.append(j)
    lock += [full.getJointId(name) for name in FINGER_JOINTS]
    return pin.buildReducedModel(full, lock, q_ref), problems


def build_model(s: Scenario, source: str = "<scenario>") -> Model:
    """Build the immutable Model of a validated scenario (raises ModelError, ScenarioError)."""
    urdf = assets.compile_xacro(SCENE_XACRO, xacro_args(s))
    try:
        full = pin.buildModelFromXML(urdf)
    except Exception as e:
        raise ModelError(f"Pinocchio cannot build the scene: {e}") from e
    check_inertias(full)
    model, problems = _lock_arm(full, s)
    if problems:
        raise ScenarioError([f"{source}: {p}" for p in problems])
    model.gravity = pin.Motion(np.array(s.simulation.gravity_m_s2), np.zeros(3))
    module_joint = model.getJointId(MODULE_JOINT)
    check_inertias(model, joints={module_joint})

    c = s.contact
    r1, r2 = c.sphere_radius_finger_mm * 1e-3, c.sphere_radius_groove_mm * 1e-3
    cutoff = cutoff_distance(r1, r2, min(r1, r2))
    params = ContactParams(
        r1=r1, r2=r2,
        K=hertz_stiffness(c.youngs_modulus_finger_Pa, c.poisson_finger,
                          c.youngs_modulus_groove_Pa, c.poisson_groove, r1, r2),
        damping_factor=damping_factor(c.restitution),
        approach_speed_floor=c.approach_speed_floor_m_s,
        cutoff=cutoff,
        # a sphere centre sits r off its face, so faces whose spheres may pair are within
        # r1 + cutoff + r2 of each other; the skin keeps the culling conservative
        margin=r1 + r2 + cutoff + c.skin_mm * 1e-3,
        bristle=BristleParams(s.friction.mu_k, s.friction.mu_s, s.friction.bristle_stiffness_N_m,
                              s.friction.bristle_damping_N_s_m, s.friction.velocity_deadband_m_s),
        broad_phase=c.broad_phase,
    )
    master, master_finger, finger_geoms, slave, pairs, maps, geom, contact_joints = _contact_layers(
        model, urdf, module_joint, params)

    oMa = model.frames[model.getFrameId(GRASP_FRAME, pin.BODY)].placement
    if model.frames[model.getFrameId(GRASP_FRAME, pin.BODY)].parentJoint != 0:
        raise ModelError("the grasp frame must be fixed to the world once the arm is locked")
    rpy = np.radians(s.module.initial_rpy_deg)
    oMb = oMa * pin.SE3(pin.rpy.rpyToMatrix(*rpy), np.array(s.module.initial_offset_mm) * 1e-3)
    q0 = pin.neutral(model)
    jMb = model.jointPlacements[module_joint].inverse() * oMb
    iq = model.idx_qs[module_joint]
    q0[iq:iq + 7] = pin.SE3ToXYZQUAT(jMb)

    fingers = []
    for k, name in enumerate(FINGER_JOINTS):
        frame = model.frames[model.getFrameId(name, pin.BODY)]
        axis_J = frame.placement.rotation[:, 2]  # prismatic finger joints open along their local z
        touch = _opening_at_touch(model, frame.parentJoint, axis_J, master, master_finger == k,
                                  slave, oMa, module_joint, params)
        start = touch + s.end_effector.start_gap_mm * 1e-3
        fingers.append(Finger(name, frame.parentJoint, axis_J, 0, touch, start))
    axes = np.array([f.axis_J for f in fingers])
    return Model(s, urdf, model, geom, module_joint, tuple(fingers), master_finger,
                 axes[master_finger], finger_geoms, oMa,
                 contact_joints, master, slave, tuple(pairs), maps, params, q0, np.zeros(model.nv))


def _contact_layers(model, urdf, module_joint, params):
    """Sphere layers of every contact face, stacked by role, and the coal face patches.

    Finger faces are placed at opening 0 on the joint the finger is mounted on.
    """
    faces = contact_faces(urdf)
    geom = pin.GeometryModel()
    roles = {"master": [], "slave": []}
    finger_of_face, finger_geoms = [], []
    for face in faces:
        frame = model.frames[model.getFrameId(face.link, pin.BODY)]
        j, jMl = frame.parentJoint, frame.placement
        role = "master" if face.link in FINGER_JOINTS else "slave" if j == module_joint else None
        if role is None:
            raise ModelError(f"contact face {face.name} is on {face.link}, neither a finger nor the module")
        if role == "master":
            finger_of_face.append(FINGER_JOINTS.index(face.link))
            finger_geoms.append((len(geom.geometryObjects), finger_of_face[-1]))
        verts_J = face.vertices_L @ jMl.rotation.T + jMl.translation
        layer = sphere_layer(verts_J, params.r1 if role == "master" else params.r2)
        T = face.T_LC
        placement = jMl * pin.SE3(T[:3, :3], T[:3, 3])
        gid = geom.addGeometryObject(pin.GeometryObject(face.name, j, placement, coal.Box(*face.box_size)))
        roles[role].append((gid, j, layer))
    if not roles["master"] or not roles["slave"]:
        raise ModelError("the scene needs contact faces on both the fingers and the module")

    def stack(entries, radius):
        centres = np.concatenate([e[2].centres for e in entries])
        normals = np.concatenate([np.tile(e[2].normal, (len(e[2].centres), 1)) for e in entries])
        joint = np.concatenate([np.full(len(e[2].centres), e[1]) for e in entries])
        face = np.concatenate([np.full(len(e[2].centres), k) for k, e in enumerate(entries)])
        return LayerSet(radius, centres, normals, joint, face)

    master, slave = stack(roles["master"], params.r1), stack(roles["slave"], params.r2)
    master_finger = np.asarray(finger_of_face)[master.face]
    starts_m = np.cumsum([0] + [len(e[2].centres) for e in roles["master"]])
    starts_s = np.cumsum([0] + [len(e[2].centres) for e in roles["slave"]])
    shapes = np.array([e[2].index_map.shape for e in roles["slave"]])
    maps = -np.ones((len(shapes), *shapes.max(axis=0)), dtype=np.int64)
    grids = []
    for b, (_, js, lay) in enumerate(roles["slave"]):
        ni, nj = lay.index_map.shape
        maps[b, :ni, :nj] = np.where(lay.index_map >= 0, lay.index_map + starts_s[b], -1)
        grids.append(SlaveGrid(js, b, lay.origin, lay.t1, lay.t2, lay.normal, (ni, nj)))
    pairs = []
    for a, (gid_m, jm, _) in enumerate(roles["master"]):
        for b, (gid_s, _, _) in enumerate(roles["slave"]):
            geom.addCollisionPair(pin.CollisionPair(gid_m, gid_s))
            pairs.append(FacePair(slice(starts_m[a], starts_m[a + 1]), jm, grids[b], len(pairs)))
    contact_joints = tuple(sorted({*master.joint.tolist(), *slave.joint.tolist()}))
    return master, master_finger, tuple(finger_geoms), slave, pairs, maps, geom, contact_joints


def _opening_at_touch(model, parent_joint, axis_J, master, on_finger, slave, oMa, module_joint, params):
    """The finger opening (m) at which its sphere layer first touches a centred groove's.

    For each of the finger's faces opposed to a groove face (normals anti-parallel), the
    sphere envelopes touch when the face planes are 2 (r1 + r2) apart; the finger moves
    along its axis, so that distance is linear in the opening.
    on_finger: (|S1|,) bool, the master spheres of this finger (given at opening 0).
    """
    q = pin.neutral(model)
    jMb = model.jointPlacements[module_joint].inverse() * oMa
    iq = model.idx_qs[module_joint]
    q[iq:iq + 7] = pin.SE3ToXYZQUAT(jMb)
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    oMf, oMm = data.oMi[parent_joint], data.oMi[module_joint]
    axis_W = oMf.rotation @ axis_J
    best = None
    for fm in np.unique(master.face[on_finger]):
        k = np.flatnonzero(master.face == fm)[0]
        n_f = oMf.rotation @ master.normals_J[k]
        x_f = oMf.act(master.centres_J[k] - params.r1 * master.normals_J[k])
        for fs in np.unique(slave.face):
            i = np.flatnonzero(slave.face == fs)[0]
            n_g = oMm.rotation @ slave.normals_J[i]
            if n_f @ n_g > -1 + 1e-9 or abs(axis_W @ n_g) < 1e-9:
                continue
            x_g = oMm.act(slave.centres_J[i] - params.r2 * slave.normals_J[i])
            dist0 = (x_f - x_g) @ n_g
            opening = (2 * (params.r1 + params.r2) - dist0) / (axis_W @ n_g)
            best = opening if best is None else max(best, opening)
    if best is None:
        raise ModelError("a finger has no face opposed to a groove face")
    return best
