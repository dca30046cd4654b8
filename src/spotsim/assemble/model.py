"""Scenario -> Model: the Pinocchio scene, its contact faces, sphere layers and parameters, and
the compiled Model (`sim.model.SimModel`) a run's compiled code reads.

Everything here is fixed for a run (a weld builds a new Model). The arms are self-locked
during the grasp (paper Sec. 4.1), so their joints are reduced away with
`pin.buildReducedModel`. The fingers stay on their prismatic joints, each a body whose
coordinate is its opening, moved by its end-effector's drive (`sim.actuation`); a welded
module's end-effector's fingers are locked where they hold it. The scene keeps a free-flyer
for each floating body: the module(s) and, on the free-flying robot, the robot, which carries
its fingers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import coal
import numpy as np
import pinocchio as pin

from ..contact.detection import cutoff_distance
from ..contact.forces import ContactLaw
from ..contact.friction import BristleParams
from ..contact.layers import FaceTable, MasterSpheres, SlaveSpheres
from ..contact.normal import damping_factor, hertz_stiffness, indentation
from ..errors import ModelError, ScenarioError
from ..sim.actuation import Actuators, Drives
from ..sim.integrators import tableau
from ..sim.model import (
    CompletionParams,
    Grasps,
    IntegratorParams,
    Limits,
    ModelFields,
    RecordFrames,
    SimModel,
    sim_model,
)
from ..sim.record import REPLAY_RATE_HZ, Layout
from ..sim.tether import Tethers, no_tethers
from ..sim.tree import joint_axis, kinematic_tree
from ..tables import ADAPTIVE, DRIVES, METHODS, MOTOR
from . import assets
from .compliance import MOTOR_SUFFIX, compliance_of, joint_springs, reflected_inertias, servo_urdf, spring_arrays
from .faces import INSET_KINDS, TOUCHING_KINDS, contact_faces, inset, sphere_layer
from .rig import DYNAMOMETER_JOINTS, bungee, dynamometer_springs, mount_on_dynamometer, settle
from .scene import FINGER_NAMES, SceneSpec, check_inertials, check_inertias, frame, lock_joints, scene_spec, weld_urdf
from .table import mount_on_table


@dataclass(frozen=True)
class Finger:
    """A finger: a body on its prismatic joint `joint`, whose coordinate is the finger's
    opening (m), moved by its drive (`drive`, the index of its end-effector).

    opening_touch, opening_start: openings (m) at first touch of a centred groove and at start.
    """

    name: str
    joint: int
    drive: int
    opening_touch: float
    opening_start: float


@dataclass(frozen=True)
class EndEffector:
    """An end-effector's grasp frame O_a: its joint and placement in that joint's frame."""

    name: str
    joint: int
    placement: pin.SE3


@dataclass(frozen=True)
class ModuleBody:
    """A target module: its free-flyer joint (0 once welded) and its groove frame O_b's
    placement in that joint's frame."""

    name: str
    prefix: str
    joint: int
    placement: pin.SE3


@dataclass(frozen=True)
class Model:
    """A scene ready to run: the Pinocchio model and coal geometry, its bodies, fingers and
    contact layers by name, and `sim`, the compiled Model its runs read."""

    scenario: object
    spec: SceneSpec
    urdf: str
    pin_model: pin.Model
    geom_model: pin.GeometryModel
    end_effectors: tuple[EndEffector, ...]
    modules: tuple[ModuleBody, ...]
    grasps: tuple[tuple[int, int], ...]  # (end-effector, module) in the order they are grasped
    robot_joint: int  # the free-flying robot's joint, 0 for a fixed base
    fingers: tuple[Finger, ...]  # the fingers on their joints (a welded end-effector's are locked: not here)
    master_geoms: tuple[int, ...]  # the geometry object (coal patch) of each master face, in layer order
    contact_joints: tuple[int, ...]  # joints carrying contact faces
    q0: np.ndarray
    v0: np.ndarray
    free_joints: tuple[int, ...]  # the floating roots
    faces: tuple  # every contact face of the URDF, active or not (`faces.contact_faces`); a weld keeps them
    layout: Layout  # the time series a run of this scene records (fixed by the unwelded scene)
    sim: SimModel
    springs: dict  # the compliant arm joints' springs, by joint name (`compliance.joint_springs`)

    @property
    def law(self) -> ContactLaw:
        return self.sim.law

    @property
    def master(self) -> MasterSpheres:
        return self.sim.master

    @property
    def slave(self) -> SlaveSpheres:
        return self.sim.slave

    @cached_property
    def face_names(self) -> tuple[list[str], list[str]]:
        """The names of the master and of the slave faces, in the order of their layers' `face`
        index: each face is one coal patch, added in that order (masters are `master_geoms`)."""
        objects = self.geom_model.geometryObjects
        masters = list(self.master_geoms)
        slaves = [g for g in range(len(objects)) if g not in set(masters)]
        return [objects[g].name for g in masters], [objects[g].name for g in slaves]

    @cached_property
    def groove_placements(self) -> list[tuple[int, pin.SE3]]:
        """Each module's groove frame O_b as (joint, placement in it); a welded module's rides
        on its end-effector's joint."""
        return [groove_placement(self.pin_model, m) for m in self.modules]

    @property
    def module_joint(self) -> int:
        """The first grasp's module joint (single-arm scenes have one)."""
        return self.modules[self.grasps[0][1]].joint


def groove_placement(model: pin.Model, module: ModuleBody) -> tuple[int, pin.SE3]:
    """A module's groove frame O_b as (joint, placement in it): a welded module's rides on its
    end-effector's joint."""
    if module.joint:
        return module.joint, module.placement
    f = frame(model, f"{module.prefix}module")
    return f.parentJoint, f.placement


def contact_law(s) -> ContactLaw:
    """The contact law's constants of a scenario's `contact` and `friction` blocks."""
    c, f = s.contact, s.friction
    r1, r2 = c.sphere_radius_finger_mm * 1e-3, c.sphere_radius_groove_mm * 1e-3
    return ContactLaw(
        r1=r1, r2=r2,
        K=hertz_stiffness(c.youngs_modulus_finger_Pa, c.poisson_finger, c.youngs_modulus_groove_Pa, c.poisson_groove,
                          r1, r2),
        damping=damping_factor(c.restitution),
        # the key bounds the normal approach speed; the law's floor is on delta_dot_minus, the
        # rate of delta = phi / 2 at that speed (the one place the two are converted)
        floor=indentation(c.approach_speed_floor_m_s),
        cutoff=cutoff_distance(r1, r2, min(r1, r2)),
        bristle=BristleParams(mu_k=f.mu_k, mu_s=f.mu_s, k_b=f.bristle_stiffness_N_m, c_b=f.bristle_damping_N_s_m,
                              v_d=f.velocity_deadband_m_s),
        common_point=c.force_point == "common",
        gradient=c.normal_direction == "gradient",
    )


def scene_fingers(spec: SceneSpec) -> list[str]:
    """The finger links of the unwelded scene, in the order its Model lists its fingers."""
    return [f"{prefix}{finger}" for _, prefix in spec.end_effectors for finger in FINGER_NAMES]


def build_model(s, source: str = "<scenario>", welded: dict | None = None, urdf: str | None = None,
                faces: tuple | None = None, held: dict | None = None, springs: dict | None = None) -> Model:
    """Build the immutable Model of a validated scenario (raises ModelError, ScenarioError).

    welded: modules already grasped and welded, and held: the openings their end-effectors'
    fingers are locked at (see `scene.scene_spec`). The fingers of an end-effector whose grasp
    is not under way (the next one's) do not move: they are locked at their start openings
    too, so that each phase's model carries only the joints that move in it. urdf: the scene's compiled URDF
    (`Model.urdf`, any earlier welds in it), to weld into (`scene.weld_urdf`) instead of
    compiling the XACRO again; faces: its contact faces (`Model.faces`), which a weld does not
    change (they are given in their links' frames), instead of parsing them again; springs:
    the compliant joints' (`Model.springs`), which a weld does not change either.
    """
    spec = scene_spec(s, welded, held)
    if urdf is None:
        for arm, prefix in spec.arms:
            assets.prefixed_arm(arm, prefix)
        urdf = assets.compile_xacro(spec.xacro, spec.args)
        if spec.dynamometer:
            urdf = mount_on_dynamometer(urdf, s.dynamometer)
        if spec.servo:
            urdf = servo_urdf(urdf, spec.compliant)
    else:
        urdf = weld_urdf(urdf, spec)
    check_inertials(urdf)
    try:
        full = pin.buildModelFromXML(urdf)
    except Exception as e:
        raise ModelError(f"Pinocchio cannot build the scene: {e}") from e
    check_inertias(full)
    model, problems = lock_joints(full, spec)
    if problems:
        raise ScenarioError([f"{source}: {p}" for p in problems])
    if spec.servo:
        reflected_inertias(model, spec.compliant)
    model.gravity = pin.Motion(np.array(s.simulation.gravity_m_s2), np.zeros(3))
    robot_joint = model.getJointId(spec.robot_joint) if spec.robot_joint else 0

    end_effectors, modules = _scene_frames(model, spec)
    free = tuple(m.joint for m in modules if m.joint) + ((robot_joint,) if robot_joint else ())
    check_inertias(model, joints=set(free))
    q0 = start_configuration(model, spec, end_effectors, modules)
    if on_table(s):
        model, q0 = mount_on_table(model, q0, free, s.testbed.table_normal)
        end_effectors, modules = _scene_frames(model, spec)

    law = contact_law(s)
    active = [k for k in range(len(modules)) if k not in spec.welded_modules]
    finger_links = [f"{prefix}{finger}" for e, (_, prefix) in enumerate(spec.end_effectors)
                    if not any(g == (e, m) for m in spec.welded_modules for g in spec.grasps)
                    for finger in FINGER_NAMES]
    module_prefixes = [modules[k].prefix for k in active]
    faces = tuple(contact_faces(urdf)) if faces is None else faces
    layers = _contact_layers(model, faces, finger_links, module_prefixes, law)

    fingers = []
    for link in finger_links:
        if link in spec.locked:  # held: its faces ride on the body it is locked to
            continue
        j = frame(model, link).parentJoint
        if model.joints[j].shortname() not in ("JointModelPX", "JointModelPY", "JointModelPZ",
                                               "JointModelPrismaticUnaligned"):
            raise ModelError(f"finger {link} is not on a prismatic joint of its own ({model.names[j]})")
        e = next(i for i, (_, prefix) in enumerate(spec.end_effectors) if link.startswith(prefix))
        mod = next(m for (ee, m) in spec.grasps if ee == e)
        touch = _opening_at_touch(model, j, layers, end_effectors[e], modules[mod], law)
        start = touch + s.end_effector.start_gap_mm * 1e-3
        fingers.append(Finger(link, j, e, touch, start))
    active_ee = next(e for e, k in spec.grasps if k not in spec.welded_modules)
    idle = {f.name: f.opening_start for f in fingers if f.drive != active_ee}
    if idle:  # the next grasp's fingers stay at their start until it begins: locked there
        return build_model(s, source, welded, urdf=urdf, faces=faces, held={**(held or {}), **idle}, springs=springs)
    q0 = with_openings(model, q0, fingers)
    if springs is None:  # (a weld keeps those of the scene before it)
        springs = joint_springs(model, q0, spec.compliant, compliance_of(s), not on_table(s))
        if spec.compliant and np.any(model.gravity.linear) and not on_table(s):
            # the arms sag on their gearboxes under gravity: the start is where they hold still,
            # and the modules start from the grasp frames there (on the air-bearing table the
            # bearings carry the weight: `assemble.table`)
            q0 = settle(model, q0, springs, [name for name, _, _, _ in spec.compliant])
            q0 = start_configuration(model, spec, end_effectors, modules, q0)
            if spec.servo:  # the servos hold the settled start
                springs = joint_springs(model, q0, spec.compliant, compliance_of(s))
        if spec.dynamometer:  # its rests hold the (settled) arm
            springs = {**springs, **dynamometer_springs(model, q0, s.dynamometer)}
    tethers = (bungee(model, q0, modules[0].joint, s.suspension, s.module.mass_kg)
               if hasattr(s, "suspension") and modules[0].joint else no_tethers())
    layout = Layout(scene_fingers(spec), bool(robot_joint), [m.name for m in modules], [e.name for e in end_effectors],
                    tuple(name for name, _, _, _ in spec.compliant), spec.dynamometer)
    parts = _Parts(scenario=s, pin_model=model, end_effectors=end_effectors, modules=modules, grasps=spec.grasps,
                   robot_joint=robot_joint, fingers=tuple(fingers), free_joints=free, layers=layers, law=law,
                   layout=layout, held={name: spec.locked[name] for name in scene_fingers(spec) if name in spec.locked},
                   springs=springs, tethers=tethers)
    return Model(scenario=s, spec=spec, urdf=urdf, pin_model=model, geom_model=layers.geom,
                 end_effectors=tuple(end_effectors), modules=tuple(modules), grasps=spec.grasps,
                 robot_joint=robot_joint,
                 fingers=tuple(fingers), master_geoms=layers.master_geoms, contact_joints=layers.contact_joints, q0=q0,
                 v0=np.zeros(model.nv), free_joints=free, faces=faces, layout=layout,
                 sim=sim_model(model_fields(parts)), springs=springs)


def _scene_frames(model: pin.Model, spec: SceneSpec) -> tuple[list[EndEffector], list[ModuleBody]]:
    """The end-effectors' grasp frames and the modules' groove frames of `model`, by the
    spec's link names."""
    end_effectors = []
    for name, prefix in spec.end_effectors:
        f = frame(model, f"{prefix}grasp")
        end_effectors.append(EndEffector(name, f.parentJoint, f.placement))
    modules = []
    for k, (name, prefix, _, _) in enumerate(spec.modules):
        f = frame(model, f"{prefix}module")
        joint = 0 if k in spec.welded_modules else f.parentJoint
        modules.append(ModuleBody(name, prefix, joint, f.placement))
    return end_effectors, modules


def on_table(s) -> bool:
    """The scenario's bodies float on the air-bearing testbed's table (`assemble.table`)."""
    return getattr(getattr(s, "testbed", None), "mount", None) == "air_bearing"


def start_configuration(model: pin.Model, spec: SceneSpec, end_effectors, modules, q=None) -> np.ndarray:
    """The configuration at the start (nq,): the robot's joints as q has them (default: the
    compliant arms' joints at their brakes' angles, locked ones reduced away) and each active
    module at its `initial_offset_mm` and `initial_rpy_deg` from its end-effector's grasp frame O_a."""
    if q is None:
        q0 = pin.neutral(model)
        for name, angle, _, _ in spec.compliant:  # a servo holds the motor side there, the gearbox undeflected
            q0[model.idx_qs[model.getJointId(name + MOTOR_SUFFIX if spec.servo else name)]] = angle
    else:
        q0 = np.array(q, dtype=float)
    data = model.createData()
    pin.forwardKinematics(model, data, q0)
    for k, (_, _, m, e) in enumerate(spec.modules):
        if k in spec.welded_modules:
            continue
        ee = end_effectors[e]
        oMa = data.oMi[ee.joint] * ee.placement
        rpy = np.radians(m.initial_rpy_deg)
        oMb = oMa * pin.SE3(pin.rpy.rpyToMatrix(*rpy), np.array(m.initial_offset_mm) * 1e-3)
        j = modules[k].joint
        jMb = model.jointPlacements[j].inverse() * oMb * modules[k].placement.inverse()
        q0[model.idx_qs[j]:model.idx_qs[j] + 7] = pin.SE3ToXYZQUAT(jMb)
    return q0


def with_openings(model: pin.Model, q: np.ndarray, fingers) -> np.ndarray:
    """q (nq,) with each finger's joint at its start opening."""
    q = q.copy()
    for f in fingers:
        q[model.idx_qs[f.joint]] = f.opening_start
    return q


def with_start(model: Model, s) -> Model:
    """`model` with the modules' starts of scenario `s`: a scenario that differs from
    `model.scenario` only in the modules' `initial_offset_mm` and `initial_rpy_deg`.

    Nothing else of a Model depends on those starts (the fingers' openings at touch are
    computed with the module centred, `_opening_at_touch`) but, on the air-bearing testbed,
    the planar joints (built again, from the compiled URDF), so only `q0`, the spec's module
    sections and the scenario change; the Pinocchio model, the sphere layers and the compiled
    Model are shared, not copied. Raises ValueError for any other difference, or a welded model.
    """
    from dataclasses import replace

    from ..scenario import modules_of, to_dict

    if model.spec.welded:
        raise ValueError("with_start: the model has welded modules; restart from the unwelded scene")

    def without_starts(scenario) -> dict:
        raw = to_dict(scenario)
        for k in modules_of(scenario):
            del raw[k]["initial_offset_mm"], raw[k]["initial_rpy_deg"]
        return raw

    if type(s) is not type(model.scenario) or without_starts(s) != without_starts(model.scenario):
        raise ValueError("with_start: the scenarios differ in more than the modules' starts")
    if on_table(s):  # each body's planar joint lies in the plane through its start
        return build_model(s, urdf=model.urdf, faces=model.faces)
    if getattr(s, "suspension", None) is not None and s.suspension.kind != "none":  # hung from above its start
        return build_model(s, urdf=model.urdf, faces=model.faces)
    sections = list(modules_of(s).values())
    spec = replace(model.spec, modules=tuple((name, prefix, sections[k], e)
                                             for k, (name, prefix, _, e) in enumerate(model.spec.modules)))
    q0 = with_openings(model.pin_model, start_configuration(model.pin_model, spec, model.end_effectors,
                                                           model.modules, model.q0), model.fingers)
    return replace(model, scenario=s, spec=spec, q0=q0)


@dataclass(frozen=True)
class _Layers:
    """The contact layers of the active faces, as `_contact_layers` builds them."""

    geom: pin.GeometryModel
    master_centre_J: np.ndarray
    master_normal_J: np.ndarray
    master_joint: np.ndarray
    master_face: np.ndarray
    slave: SlaveSpheres
    faces: FaceTable
    master_geoms: tuple[int, ...]
    contact_joints: tuple[int, ...]
    kinds: tuple[tuple[str, ...], tuple[str, ...]]  # each master face's and each slave face's kind (FACE_KINDS)


def _contact_layers(model, faces, finger_links, module_prefixes, law) -> _Layers:
    """Sphere layers of the active contact faces, stacked by role, and the coal face patches.

    Master faces: those on `finger_links`, on each finger's joint. Slave faces: those on links
    of the modules named by `module_prefixes`. Every
    master face may touch every slave face of a kind it can touch (`faces.TOUCHING_KINDS`):
    one coal collision pair (and one FaceTable row) each.
    """
    geom = pin.GeometryModel()
    roles = {"master": [], "slave": []}
    master_geoms = []
    for face in faces:
        if face.link in finger_links:
            role = "master"
        elif any(face.link.startswith(p) for p in module_prefixes):
            role = "slave"
        else:
            continue  # an idle or welded pair of faces: no contact work
        f = frame(model, face.link)
        j, jMl = f.parentJoint, f.placement
        verts_J = face.vertices_L @ jMl.rotation.T + jMl.translation
        radius = law.r1 if role == "master" else law.r2
        if face.kind in INSET_KINDS:
            verts_J = inset(verts_J, radius)
            if verts_J is None:
                continue  # a land narrower than a sphere: no layer
        if role == "master":
            master_geoms.append(len(geom.geometryObjects))
        layer = sphere_layer(verts_J, radius)
        T = face.T_LC
        placement = jMl * pin.SE3(T[:3, :3], T[:3, 3])
        gid = geom.addGeometryObject(pin.GeometryObject(face.name, j, placement, coal.Box(*face.box_size)))
        roles[role].append((gid, j, layer, face.kind))
    if not roles["master"] or not roles["slave"]:
        raise ModelError("the scene needs contact faces on both the fingers and a module")

    def stack(entries):
        centres = np.concatenate([e[2].centres for e in entries])
        normals = np.concatenate([np.tile(e[2].normal, (len(e[2].centres), 1)) for e in entries])
        joint = np.concatenate([np.full(len(e[2].centres), e[1], dtype=np.int64) for e in entries])
        face = np.concatenate([np.full(len(e[2].centres), k, dtype=np.int64) for k, e in enumerate(entries)])
        return centres, normals, joint, face

    m_centres, m_normals, m_joint, m_face = stack(roles["master"])
    s_centres, s_normals, s_joint, s_face = stack(roles["slave"])
    starts_m = np.cumsum([0] + [len(e[2].centres) for e in roles["master"]])
    starts_s = np.cumsum([0] + [len(e[2].centres) for e in roles["slave"]])
    shapes = np.array([e[2].index_map.shape for e in roles["slave"]])
    maps = -np.ones((len(shapes), *shapes.max(axis=0)), dtype=np.int64)
    for b, (_, _, lay, _) in enumerate(roles["slave"]):
        ni, nj = lay.index_map.shape
        maps[b, :ni, :nj] = np.where(lay.index_map >= 0, lay.index_map + starts_s[b], -1)
    rows = []  # one per face pair, in the order of coal's collision pairs
    for a, (gid_m, jm, _, kind_m) in enumerate(roles["master"]):
        centres = m_centres[starts_m[a]:starts_m[a + 1]]
        middle = centres.mean(axis=0)
        for b, (gid_s, js, lay, kind_s) in enumerate(roles["slave"]):
            if (kind_m, kind_s) not in TOUCHING_KINDS:
                continue
            geom.addCollisionPair(pin.CollisionPair(gid_m, gid_s))
            rows.append(dict(master_start=starts_m[a], master_stop=starts_m[a + 1], master_joint=jm, slave_joint=js,
                             slave_face=b, origin_J=lay.origin, t1_J=lay.t1, t2_J=lay.t2, n_J=lay.normal,
                             shape=lay.index_map.shape, master_centre_J=middle,
                             master_radius=np.linalg.norm(centres - middle, axis=1).max()))
    ints = ("master_start", "master_stop", "master_joint", "slave_joint", "slave_face", "shape")
    table = FaceTable(**{name: np.array([r[name] for r in rows], dtype=np.int64 if name in ints else float)
                         for name in FaceTable._fields})
    contact_joints = tuple(sorted({*m_joint.tolist(), *s_joint.tolist()}))
    slave = SlaveSpheres(centre_J=s_centres, normal_J=s_normals, joint=s_joint, face=s_face, maps=maps)
    return _Layers(geom=geom, master_centre_J=m_centres, master_normal_J=m_normals, master_joint=m_joint,
                   master_face=m_face, slave=slave, faces=table, master_geoms=tuple(master_geoms),
                   contact_joints=contact_joints,
                   kinds=tuple(tuple(e[3] for e in roles[r]) for r in ("master", "slave")))


def _opening_at_touch(model, joint, layers, ee, module, law):
    """The opening (m) of the finger on prismatic joint `joint` at which its flanks' sphere
    layers first touch its groove's, centred.

    For each of the finger's flanks opposed to a groove face (normals anti-parallel), the
    sphere envelopes touch when the face planes are 2 (r1 + r2) apart; the finger moves
    along its joint's axis, so that distance is linear in the opening.
    """
    q = pin.neutral(model)  # every finger at opening 0
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    oMa = data.oMi[ee.joint] * ee.placement
    if model.nqs[module.joint] == 7:  # a free-flyer: the module placed by its configuration
        jMb = model.jointPlacements[module.joint].inverse() * oMa * module.placement.inverse()
        iq = model.idx_qs[module.joint]
        q[iq:iq + 7] = pin.SE3ToXYZQUAT(jMb)
        pin.forwardKinematics(model, data, q)
        oMm = data.oMi[module.joint]
    else:  # a planar joint cannot leave its plane: the centred pose is taken as it is
        oMm = oMa * module.placement.inverse()
    oMf = data.oMi[joint]
    axis_W = oMf.rotation @ joint_axis(model, joint)
    slave = layers.slave
    on_module = slave.joint == module.joint
    best = None
    master_kind, slave_kind = layers.kinds
    for fm in np.unique(layers.master_face[layers.master_joint == joint]):
        if master_kind[fm] != "flank":
            continue
        k = np.flatnonzero(layers.master_face == fm)[0]
        n_f = oMf.rotation @ layers.master_normal_J[k]
        x_f = oMf.act(layers.master_centre_J[k] - law.r1 * layers.master_normal_J[k])
        for fs in np.unique(slave.face[on_module]):
            if slave_kind[fs] != "flank":
                continue
            i = np.flatnonzero(slave.face == fs)[0]
            n_g = oMm.rotation @ slave.normal_J[i]
            if n_f @ n_g > -1 + 1e-9 or abs(axis_W @ n_g) < 1e-9:
                continue
            x_g = oMm.act(slave.centre_J[i] - law.r2 * slave.normal_J[i])
            dist0 = (x_f - x_g) @ n_g
            opening = (2 * (law.r1 + law.r2) - dist0) / (axis_W @ n_g)
            best = opening if best is None else max(best, opening)
    if best is None:
        raise ModelError("a finger has no face opposed to a groove face")
    return best


# ------------------------------------------------------------------------ the compiled Model


@dataclass(frozen=True)
class _Parts:
    """What `model_fields` assembles the compiled Model from."""

    scenario: object
    pin_model: pin.Model
    end_effectors: list
    modules: list
    grasps: tuple
    robot_joint: int
    fingers: tuple
    free_joints: tuple
    layers: _Layers
    law: ContactLaw
    layout: Layout
    held: dict  # the locked fingers' openings, by name (`scene.scene_spec`)
    springs: dict  # the compliant arm joints' springs, by name (`compliance.joint_springs`)
    tethers: Tethers  # the bungee the module hangs on, if it does (`rig.bungee`)


def model_fields(p: _Parts) -> ModelFields:
    """The fields of a scene's compiled Model."""
    s, model, layers, law = p.scenario, p.pin_model, p.layers, p.law
    master = MasterSpheres(centre_J=layers.master_centre_J, normal_J=layers.master_normal_J, joint=layers.master_joint,
                           face=layers.master_face)
    table = np.array(s.testbed.table_normal, dtype=float) if on_table(s) else np.zeros(3)
    if table.any():
        table /= np.linalg.norm(table)
    # each contact layer with the travel of the fingers above it, for the levers and the
    # motion bound (fingers anywhere between closed and their start opening)
    travel = max((f.opening_start for f in p.fingers), default=0.0)
    finger_joints = {f.joint for f in p.fingers}
    spheres = [(j, master.centre_J[master.joint == j], travel if j in finger_joints else 0.0)
               for j in np.unique(master.joint)]
    spheres += [(j, layers.slave.centre_J[layers.slave.joint == j], 0.0) for j in np.unique(layers.slave.joint)]
    # a kinematic or relay drive prescribes its fingers' motion; a motor pushes them
    prescribed = [] if s.end_effector.drive == "motor" else [f.joint for f in p.fingers]
    tree, branches = kinematic_tree(model, prescribed=prescribed, gravity_W=model.gravity.linear,
                                    table_normal=table if table.any() else None,
                                    springs=spring_arrays(model, p.springs), spheres=spheres)
    ees, mods = [ee for ee, _ in p.grasps], [k for _, k in p.grasps]
    grasps = Grasps(ee=np.array(ees, dtype=np.int64), module=np.array(mods, dtype=np.int64),
                    ee_joint=np.array([p.end_effectors[e].joint for e in ees], dtype=np.int64),
                    R_ee=np.array([p.end_effectors[e].placement.rotation for e in ees]).reshape(-1, 3, 3),
                    module_joint=np.array([p.modules[k].joint for k in mods], dtype=np.int64),
                    module_lever=np.array([model.inertias[p.modules[k].joint].lever for k in mods]).reshape(-1, 3))
    skin = s.contact.skin_mm * 1e-3
    # a sphere centre sits r off its face, so faces whose spheres may pair are within
    # r1 + cutoff + r2 of each other; the skin keeps the culling conservative
    limits = Limits(max_penetration=min(law.r1, law.r2), skin=skin, margin=law.r1 + law.r2 + law.cutoff + skin,
                    external_contact=bool((~tree.free[master.joint]).any() or (~tree.free[layers.slave.joint]).any()
                                          or len(p.tethers.joint)))
    c, sim = s.completion, s.simulation
    i = sim.integrator
    A, b, c_nodes, e = tableau(i.method)
    floating = branches.mass[branches.floating]
    integrator = IntegratorParams(
        method=METHODS.index(i.method), adaptive=i.method in ADAPTIVE, A=A, b=b, c=c_nodes, e=e, rtol=i.rtol,
        atol=i.atol, h_min=i.h_min_s, h_max=i.h_max_s, velocity_tol=i.velocity_tol_m_s, onset_depth=i.onset_depth_m,
        onset_clearance=i.onset_guard == "clearance", locate_switches=i.bristle_switches == "located",
        staggered=i.method == "adaptive_euler" and i.kick == "staggered",
        pass_quiet=i.method in ADAPTIVE and i.drive_readings == "pass_quiet",
        lever=np.concatenate([branches.lever, tree.reach[tree.internal]]),
        lightest=float(floating.min()) if len(floating) else float(tree.mass[1:].max()))
    return ModelFields(
        tree=tree, branches=branches, gravity_W=np.array(model.gravity.linear), table_normal=table, master=master,
        slave=layers.slave, faces=layers.faces, law=law, literal=s.contact.broad_phase == "none",
        actuators=Actuators(joint=np.array([f.joint for f in p.fingers], dtype=np.int64),
                            drive=np.array([f.drive for f in p.fingers], dtype=np.int64)),
        drives=drives(s.end_effector, len(p.end_effectors),
                      max((model.inertias[f.joint].mass for f in p.fingers), default=0.0)), grasps=grasps,
        completion=CompletionParams(hold_s=c.hold_s, max_contact_speed=c.max_contact_speed_m_s,
                                    max_net_force=c.max_net_force_N, phase_timeout=c.phase_timeout_s,
                                    record_after=c.record_after_s),
        tethers=p.tethers, limits=limits, record=_record_frames(p, tree, branches), integrator=integrator, dt=sim.dt_s,
        substeps=sim.substeps, h=sim.dt_s / sim.substeps)


def screw_efficiencies(lead_m: float, diameter_m: float, half_angle_rad: float, friction: float):
    """A lead screw's forward and backward efficiencies (Shigley; Simscape Driveline's
    Leadscrew): lead angle lambda = atan(L / (pi d)), thread half-angle alpha, friction k:
    eta_f = (cos a - k tan l) / (cos a + k / tan l), eta_b = (cos a - k / tan l) / (cos a + k tan l).
    eta_b <= 0: self-locking."""
    lam = math.atan(lead_m / (math.pi * diameter_m))
    ca, tl = math.cos(half_angle_rad), math.tan(lam)
    return (ca - friction * tl) / (ca + friction / tl), (ca - friction / tl) / (ca + friction * tl)


@dataclass(frozen=True)
class MotorDrive:
    """A motor drive's derived quantities, SI (`sim.actuation`, `sim.dynamics.transmissions`)."""

    ratio: float  # rho, rad of rotor per m of each finger's travel
    forward: float  # the transmission's efficiency, motor to fingers (gearhead x screw)
    backward: float  # ... fingers to motor (<= 0: self-locking)
    rotor: float  # kg m^2
    torque_constant: float  # N m/A
    reflected_inertia: float  # J rho^2 on the fingers' common coordinate, kg
    stall_force: float  # the screw's closing force on the pair at the current limit, forward, N


def motor_drive(mo) -> MotorDrive:
    """The derived quantities of a scenario's end_effector.motor block."""
    lead = mo.screw_lead_mm * 1e-3
    ratio = mo.gear_ratio * 2.0 * math.pi / lead
    eta_f, eta_b = screw_efficiencies(lead, mo.screw_diameter_mm * 1e-3, math.radians(mo.thread_half_angle_deg),
                                      mo.screw_friction)
    rotor, kt = mo.rotor_inertia_g_cm2 * 1e-7, mo.torque_constant_mNm_A * 1e-3
    forward = mo.gear_efficiency * eta_f
    return MotorDrive(ratio=ratio, forward=forward, backward=mo.gear_efficiency * eta_b, rotor=rotor,
                      torque_constant=kt, reflected_inertia=rotor * ratio * ratio,  # inf, not OverflowError
                      stall_force=forward * ratio * kt * mo.current_limit_A)


def drives(ee, n: int, finger_mass: float) -> Drives:
    """The compiled finger drives of n end-effectors, each from a scenario's end_effector block
    (`sim.actuation`); finger_mass: one finger's, kg. A motor drive's grasp load is its stall
    force's share per finger; its speed loop's gain puts its crossover at the design bandwidth
    on the fingers' inertia with the rotor's (forward), and its integral time is four times
    that crossover's period over 2 pi (the PI's corner a fourth of it)."""
    row = lambda x, dtype=float: np.full(n, x, dtype=dtype)
    mo, law = ee.motor, DRIVES.index(ee.drive)
    md = motor_drive(mo)
    omega = 2.0 * math.pi * mo.speed_loop_bandwidth_Hz
    inertia = md.forward * md.reflected_inertia + 2.0 * finger_mass
    with np.errstate(all="ignore"):  # extreme keys give inf or nan here, which a run reports, not an exception
        gain = np.divide(inertia * omega, md.forward * md.ratio * md.torque_constant)
    motor = law == MOTOR
    return Drives(law=row(law, np.int64), closing_speed=row(ee.closing_speed_m_s),
                  grasp_load=row(0.5 * md.stall_force if motor else ee.grasp_load_N),
                  no_load_speed=row(ee.closing_speed_m_s / (1.0 - ee.slowdown_fraction)),
                  resume_fraction=row(ee.resume_fraction),
                  period=row(mo.speed_loop_period_s if motor else ee.control_period_s),
                  ratio=row(md.ratio), forward=row(md.forward), backward=row(md.backward), rotor=row(md.rotor),
                  torque_constant=row(md.torque_constant), resistance=row(mo.terminal_resistance_ohm),
                  voltage=row(mo.supply_voltage_V), current_limit=row(mo.current_limit_A),
                  gain=row(gain),
                  integral_time=row(4.0 / omega),
                  back_calculation=row(mo.anti_windup == "back_calculation", np.bool_))


def _record_frames(p: _Parts, tree, branches) -> RecordFrames:
    """What a record row reads: the modules' groove frames, the end-effectors' grasp frames and
    the robot's base, each on its joint (0: fixed); the fingers' openings and loads; the compliant
    arms' joint angles."""
    frames = [groove_placement(p.pin_model, m) for m in p.modules]
    frames += [(e.joint, e.placement) for e in p.end_effectors]
    frames.append((p.robot_joint, None))
    of = lambda joints: np.array([tree.branch[j] for j in joints], dtype=np.int64)
    model = p.pin_model
    names = [f.name for f in p.fingers]
    finger_q, locked, actuator = [], [], []
    for name in p.layout.fingers:
        if name in names:
            k = names.index(name)
            finger_q.append(model.idx_qs[p.fingers[k].joint])
            locked.append(0.0)  # not read: its joint gives its opening
            actuator.append(k)
        else:  # a weld locked it: its opening is the one its spec holds it at
            finger_q.append(-1)
            locked.append(p.held.get(name, 0.0))
            actuator.append(-1)
    dt = p.scenario.simulation.dt_s
    mount = DYNAMOMETER_JOINTS if p.layout.dynamometer else ()
    return RecordFrames(
        joint=np.array([j for j, _ in frames], dtype=np.int64),
        R=np.array([np.eye(3) if M is None else M.rotation for _, M in frames]).reshape(-1, 3, 3),
        p=np.array([np.zeros(3) if M is None else M.translation for _, M in frames]).reshape(-1, 3),
        module_joint=np.array([m.joint for m in p.modules], dtype=np.int64),
        finger_q=np.array(finger_q, dtype=np.int64), locked_opening=np.array(locked, dtype=float),
        finger_actuator=np.array(actuator, dtype=np.int64),
        arm_q=np.array([model.idx_qs[model.getJointId(name)] for name in p.layout.arm_joints], dtype=np.int64),
        arm_motor_q=np.array([model.idx_qs[model.getJointId(name + MOTOR_SUFFIX)] if model.existJointName(
            name + MOTOR_SUFFIX) else -1 for name in p.layout.arm_joints], dtype=np.int64),
        mount_q=np.array([model.idx_qs[model.getJointId(name)] for name in mount], dtype=np.int64),
        mount_v=np.array([model.idx_vs[model.getJointId(name)] for name in mount], dtype=np.int64),
        all_branches=np.flatnonzero(branches.floating).astype(np.int64),
        robot_branches=of([p.robot_joint] if p.robot_joint else []),
        system_branches=of(p.free_joints),
        free_robot=p.layout.free_robot,
        # the drives' work bounds the energy only without gravity (which does work of its own)
        energy_bound=not np.any(model.gravity.linear),
        width=p.layout.width,
        replay_every=max(1, int(round(1.0 / (REPLAY_RATE_HZ * dt)))))


def grasp_frame(model: Model, data: pin.Data, ee: int) -> pin.SE3:
    """End-effector `ee`'s grasp frame O_a in world, from the kinematics in `data`."""
    e = model.end_effectors[ee]
    return data.oMi[e.joint] * e.placement


def groove_frame(model: Model, data: pin.Data, k: int) -> pin.SE3:
    """Module `k`'s groove frame O_b in world (a welded module rides on its end-effector)."""
    joint, placement = model.groove_placements[k]
    return data.oMi[joint] * placement
