"""Scenario -> Model: the Pinocchio scene, its contact faces, sphere layers and parameters.

Everything here is fixed for a run (a weld builds a new Model). The arms are self-locked
during the grasp (paper Sec. 4.1), so their joints are reduced away with
`pin.buildReducedModel`. The fingers' prismatic joints are reduced away too: their drive
prescribes their motion, so they carry no dynamic degree of freedom. Their mass joins the body
they are mounted on, their faces slide along their joint axes by the drive's opening, and
their contact loads act on that body. The scene keeps one free-flyer per free body: the
module(s) and, on the free-flying robot, the robot.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from functools import cached_property

import coal
import numpy as np
import pinocchio as pin

from . import assets
from .contact.detection import cutoff_distance
from .contact.friction import BristleParams
from .contact.normal import damping_factor, hertz_stiffness
from .bodies import FreeBodies, free_bodies
from .contact.search import FacePair, FaceTable, LayerSet, SlaveGrid, face_table
from .errors import ModelError, ScenarioError
from .scenario import DualArmScenario, Scenario
from .spheres import contact_faces, sphere_layer

#: Smallest eigenvalue a body's inertia may have, kg m^2, below which it is not positive definite.
MIN_INERTIA_EIGENVALUE = 1e-12
FINGER_NAMES = ("finger_upper", "finger_lower")


@dataclass(frozen=True)
class SceneSpec:
    """What a scenario's scene is made of, by name: the XACRO, the joints to lock, the
    end-effectors (name, link prefix), the modules (name, link prefix, scenario section, the
    end-effector it starts at) and the grasp sequence (end-effector, module)."""

    xacro: object
    args: dict
    locked: dict  # joint name -> angle, rad; names listed in `checked` are limit-checked
    checked: dict  # joint name -> scenario key path, for limit errors
    end_effectors: tuple[tuple[str, str], ...]
    modules: tuple[tuple[str, str, object, int], ...]
    grasps: tuple[tuple[int, int], ...]
    robot_joint: str | None = None
    # modules fixed to their end-effector (grasp done): (module, xyz, rpy of O_b in O_a)
    welded: tuple[tuple[int, tuple, tuple], ...] = ()
    # the arm fragments the XACRO includes (`assets.prefixed_arm`): (arm model, prefix)
    arms: tuple[tuple[str, str], ...] = ()

    @property
    def welded_modules(self) -> set[int]:
        return {k for k, _, _ in self.welded}


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
    force_point: str = "common"
    skin: float = 0.0  # the margin's extra beyond contact reach, m


@dataclass(frozen=True)
class Finger:
    """A finger moved by its drive along its prismatic axis, on the body of joint `parent_joint`.

    axis_J: (3,) its opening direction in that joint's frame. drive: index of its drive (its
    end-effector). opening_touch, opening_start: openings (m) at first touch of a centred
    groove and at start; the master spheres' centres are given at opening 0.
    """

    name: str
    parent_joint: int
    axis_J: np.ndarray
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
    scenario: object
    spec: SceneSpec
    urdf: str
    pin_model: pin.Model
    geom_model: pin.GeometryModel
    end_effectors: tuple[EndEffector, ...]
    modules: tuple[ModuleBody, ...]
    grasps: tuple[tuple[int, int], ...]  # (end-effector, module) in the order they are grasped
    robot_joint: int  # the free-flying robot's joint, 0 for a fixed base
    fingers: tuple[Finger, ...]
    master_finger: np.ndarray  # (|S1|,) the finger each master sphere is on
    master_axis_J: np.ndarray  # (|S1|, 3) that finger's opening axis, in the sphere's joint frame
    finger_geoms: tuple[tuple[int, int], ...]  # (geometry object, finger) of each finger patch
    contact_joints: tuple[int, ...]  # joints carrying contact faces
    master: LayerSet
    slave: LayerSet
    face_pairs: tuple[FacePair, ...]
    slave_maps: np.ndarray  # (n_slave_faces, ni, nj) global slave index per grid node, -1 if none
    params: ContactParams
    q0: np.ndarray
    v0: np.ndarray
    free_joints: tuple[int, ...] = field(default=())
    # (joint, farthest contact sphere from its origin, m): bounds how far its spheres move
    sphere_reach: tuple[tuple[int, float], ...] = field(default=())
    # the fingers of each end-effector's drive, as index arrays into `fingers`
    drive_fingers: tuple[np.ndarray, ...] = field(default=())
    # every contact face of the URDF, active or not (`spheres.contact_faces`); a weld keeps them
    faces: tuple = field(default=())

    @cached_property
    def face_table(self) -> FaceTable:
        """`face_pairs` stacked as arrays, for the compiled search."""
        return face_table(self.face_pairs, self.master.centres_J)

    @cached_property
    def contact_call(self):
        """`step._contact_kernels`, called directly once compiled (`jit.direct`): its
        arguments' types are fixed by this model."""
        from .jit import direct
        from .step import _contact_kernels

        return direct(_contact_kernels)

    @cached_property
    def contact_kernel_args(self) -> tuple:
        """The model's arguments of the compiled contact stage (`step.contact_kernel_args`)."""
        from .step import contact_kernel_args

        return contact_kernel_args(self)

    @cached_property
    def loop_args(self) -> tuple:
        """The model's constant arguments of the compiled loop (`compiled.loop_args`)."""
        from .compiled import loop_args

        return loop_args(self)

    @cached_property
    def watch_args(self) -> list[tuple]:
        """Per grasp, the end-effector's joint and grasp-frame rotation, the module's joint and
        centroid: the frames `contact.forces.contact_summary` reads."""
        out = []
        for ee, k in self.grasps:
            e, j = self.end_effectors[ee], self.modules[k].joint
            out.append((e.joint, np.ascontiguousarray(e.placement.rotation), j,
                        np.array(self.pin_model.inertias[j].lever)))
        return out

    @cached_property
    def bodies(self) -> FreeBodies:
        """The free bodies as arrays, for the compiled kinematics and integrators."""
        return free_bodies(self.pin_model)

    @cached_property
    def groove_placements(self) -> list[tuple[int, pin.SE3]]:
        """Each module's groove frame O_b as (joint, placement in it); a welded module's rides
        on its end-effector's joint."""
        out = []
        for m in self.modules:
            if m.joint:
                out.append((m.joint, m.placement))
            else:
                f = _frame(self.pin_model, f"{m.prefix}module")
                out.append((f.parentJoint, f.placement))
        return out

    @cached_property
    def fixed_contact(self) -> bool:
        """Whether a fixed body (joint 0) carries contact faces: only then do the contact forces
        exert an external impulse on the free bodies."""
        return bool((self.master.joint == 0).any() or (self.slave.joint == 0).any())

    @cached_property
    def all_bodies(self) -> np.ndarray:
        """Rows of every free body in `bodies`."""
        return np.arange(len(self.bodies.joint), dtype=np.int64)

    @cached_property
    def body_row(self) -> dict[int, int]:
        """Each free joint's row in `bodies`."""
        return {int(j): b for b, j in enumerate(self.bodies.joint)}

    @cached_property
    def finger_parent(self) -> np.ndarray:
        """(n_fingers,) the joint of the body each finger is mounted on."""
        return np.array([f.parent_joint for f in self.fingers], dtype=np.int64)

    @cached_property
    def finger_axis_J(self) -> np.ndarray:
        """(n_fingers, 3) each finger's opening axis in that joint's frame."""
        return np.array([f.axis_J for f in self.fingers], dtype=float).reshape(-1, 3)

    @cached_property
    def reach_table(self) -> tuple[np.ndarray, np.ndarray]:
        """`sphere_reach` of the free bodies as (row in `bodies`, reach in m) arrays."""
        pairs = [(self.body_row[j], r) for j, r in self.sphere_reach if j != 0]
        return (np.array([b for b, _ in pairs], dtype=np.int64), np.array([r for _, r in pairs], dtype=float))

    @property
    def module_joint(self) -> int:
        """The first grasp's module joint (single-arm scenes have one)."""
        return self.modules[self.grasps[0][1]].joint

    @property
    def oMa(self) -> pin.SE3:
        """The first end-effector's grasp frame in world, for a fixed base."""
        ee = self.end_effectors[self.grasps[0][0]]
        assert ee.joint == 0, "the grasp frame moves with a free-flying robot: use grasp_frame()"
        return ee.placement


def geometry_args(s) -> dict:
    return {f.name: getattr(s.geometry, f.name) for f in fields(s.geometry)}


def module_args(prefix: str, m) -> dict:
    """XACRO arguments of one module, named with the scene's prefix convention."""
    args = {f"{prefix}mass_kg": m.mass_kg, f"{prefix}com_x_mm": m.com_mm[0],
            f"{prefix}com_y_mm": m.com_mm[1], f"{prefix}com_z_mm": m.com_mm[2]}
    args.update({f"{prefix}{k.name}": getattr(m.inertia_kg_m2, k.name) for k in fields(m.inertia_kg_m2)})
    return args


def scene_spec(s, welded: dict | None = None) -> SceneSpec:
    """The scene of a scenario. welded: module index -> (xyz, rpy) of its O_b in its
    end-effector's grasp frame, for modules already grasped."""
    welded = welded or {}
    if isinstance(s, Scenario):
        args = {**geometry_args(s), **module_args("module_", s.module)}
        arm = [f"joint{i}" for i in range(1, 7)]
        locked = {**dict(zip(arm, s.arm.joint_angles_rad, strict=True)), "jointGripper": 0.0,
                  "ee_finger_upper": 0.0, "ee_finger_lower": 0.0}
        checked = {name: f"arm.joint_angles_rad[{i}]" for i, name in enumerate(arm)}
        return SceneSpec(assets.URDF_DIR / "single_arm_scene.urdf.xacro", args, locked, checked,
                         (("EE", "ee_"),), (("TM", "tm_", s.module, 0),), ((0, 0),))
    if isinstance(s, DualArmScenario):
        from .robot import ARM_JOINTS

        args = {**geometry_args(s), **module_args("tm1_", s.tm1), **module_args("tm2_", s.tm2)}
        for k, (xyz, rpy) in welded.items():
            prefix = ("tm1_", "tm2_")[k]
            args.update({f"{prefix}joint_type": "fixed", f"{prefix}parent": f"ee{k + 1}_grasp",
                         f"{prefix}xyz": " ".join(repr(float(x)) for x in xyz),
                         f"{prefix}rpy": " ".join(repr(float(x)) for x in rpy)})
        locked, checked = {}, {}
        for arm, angles in (("arm1_", s.robot.arm1_joint_angles_rad), ("arm2_", s.robot.arm2_joint_angles_rad)):
            for i, (name, angle) in enumerate(zip(ARM_JOINTS, angles, strict=True)):
                locked[arm + name] = angle
                checked[arm + name] = f"robot.{arm}joint_angles_rad[{i}]"
            for finger in FINGER_NAMES:
                locked[f"ee{arm[3]}_{finger}"] = 0.0
        return SceneSpec(assets.URDF_DIR / "dual_arm_scene.urdf.xacro", args, locked, checked,
                         (("EE-1", "ee1_"), ("EE-2", "ee2_")),
                         (("TM-1", "tm1_", s.tm1, 0), ("TM-2", "tm2_", s.tm2, 1)),
                         ((0, 0), (1, 1)), robot_joint="fdr_free_flyer",
                         welded=tuple((k, tuple(map(float, xyz)), tuple(map(float, rpy)))
                                      for k, (xyz, rpy) in sorted(welded.items())),
                         arms=((s.robot.arm_model, "arm1_"), (s.robot.arm_model, "arm2_")))
    raise TypeError(f"not a scenario: {type(s).__name__}")


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


def _lock(full: pin.Model, spec: SceneSpec) -> tuple[pin.Model, list[str]]:
    """Reduce away the locked joints (arms at the scenario's angles, fingers at opening 0)."""
    q_ref = pin.neutral(full)
    problems, lock = [], []
    for name, angle in spec.locked.items():
        j = full.getJointId(name)
        lo, hi = full.lowerPositionLimit[full.idx_qs[j]], full.upperPositionLimit[full.idx_qs[j]]
        if name in spec.checked and not lo <= angle <= hi:
            problems.append(f"{spec.checked[name]} = {angle}: must be within the {name} limits "
                            f"[{lo:.4f}, {hi:.4f}] rad")
        q_ref[full.idx_qs[j]] = angle
        lock.append(j)
    return pin.buildReducedModel(full, lock, q_ref), problems


def contact_params(s) -> ContactParams:
    c = s.contact
    r1, r2 = c.sphere_radius_finger_mm * 1e-3, c.sphere_radius_groove_mm * 1e-3
    cutoff = cutoff_distance(r1, r2, min(r1, r2))
    return ContactParams(
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
        force_point=c.force_point,
        skin=c.skin_mm * 1e-3,
    )


def _frame(model: pin.Model, name: str) -> pin.Frame:
    return model.frames[model.getFrameId(name, pin.BODY)]


def weld_urdf(urdf: str, spec: SceneSpec) -> str:
    """The compiled scene `urdf` with the modules of `spec.welded` fixed to their end-effectors:
    each module's floating joint `<prefix>free_flyer` becomes a fixed joint in its
    end-effector's `<prefix>grasp` link at the welded pose, as the scene's XACRO compiles it
    with `<prefix>joint_type:=fixed` (`scene_spec`). Editing that one joint costs milliseconds;
    compiling the XACRO again costs ~0.1 s of a run."""
    import re
    import xml.etree.ElementTree as ET

    for k, xyz, rpy in spec.welded:
        prefix = spec.modules[k][1]
        ee = next(e for e, m in spec.grasps if m == k)
        # that one element is parsed and rewritten; the rest of the text is kept as it is
        found = re.search(rf'<joint\s[^>]*name="{prefix}free_flyer".*?</joint>', urdf, re.DOTALL)
        if found is None:
            raise ModelError(f"the scene has no joint {prefix}free_flyer to weld module {spec.modules[k][0]} by")
        joint = ET.fromstring(found.group(0))
        joint.set("type", "fixed")
        joint.find("parent").set("link", f"{spec.end_effectors[ee][1]}grasp")
        joint.find("origin").set("xyz", " ".join(repr(float(x)) for x in xyz))
        joint.find("origin").set("rpy", " ".join(repr(float(x)) for x in rpy))
        urdf = urdf[:found.start()] + ET.tostring(joint, encoding="unicode") + urdf[found.end():]
    return urdf


def build_model(s, source: str = "<scenario>", welded: dict | None = None, urdf: str | None = None,
                faces: tuple | None = None) -> Model:
    """Build the immutable Model of a validated scenario (raises ModelError, ScenarioError).

    welded: modules already grasped and welded (see `scene_spec`). urdf: the scene's compiled
    URDF (`Model.urdf`, any earlier welds in it), to weld into (`weld_urdf`) instead of
    compiling the XACRO again; faces: its contact faces (`Model.faces`), which a weld does not
    change (they are given in their links' frames), instead of parsing them again.
    """
    spec = scene_spec(s, welded)
    if urdf is None:
        for arm, prefix in spec.arms:
            assets.prefixed_arm(arm, prefix)
        urdf = assets.compile_xacro(spec.xacro, spec.args)
    else:
        urdf = weld_urdf(urdf, spec)
    try:
        full = pin.buildModelFromXML(urdf)
    except Exception as e:
        raise ModelError(f"Pinocchio cannot build the scene: {e}") from e
    check_inertias(full)
    model, problems = _lock(full, spec)
    if problems:
        raise ScenarioError([f"{source}: {p}" for p in problems])
    model.gravity = pin.Motion(np.array(s.simulation.gravity_m_s2), np.zeros(3))
    robot_joint = model.getJointId(spec.robot_joint) if spec.robot_joint else 0

    end_effectors = []
    for name, prefix in spec.end_effectors:
        f = _frame(model, f"{prefix}grasp")
        end_effectors.append(EndEffector(name, f.parentJoint, f.placement))
    modules = []
    for k, (name, prefix, _, _) in enumerate(spec.modules):
        f = _frame(model, f"{prefix}module")
        joint = 0 if k in spec.welded_modules else f.parentJoint
        modules.append(ModuleBody(name, prefix, joint, f.placement))
    free = tuple(m.joint for m in modules if m.joint) + ((robot_joint,) if robot_joint else ())
    check_inertias(model, joints=set(free))

    params = contact_params(s)
    active = [k for k in range(len(modules)) if k not in spec.welded_modules]
    finger_links = [f"{prefix}{finger}" for e, (_, prefix) in enumerate(spec.end_effectors)
                    if not any(g == (e, m) for m in spec.welded_modules for g in spec.grasps)
                    for finger in FINGER_NAMES]
    module_prefixes = [modules[k].prefix for k in active]
    faces = tuple(contact_faces(urdf)) if faces is None else faces
    layers = _contact_layers(model, faces, finger_links, module_prefixes, params)
    master, master_finger, finger_geoms, slave, pairs, maps, geom, contact_joints = layers
    movable = [j for j in contact_joints if j and model.joints[j].shortname() != "JointModelFreeFlyer"]
    if movable:  # the compiled kinematics reads contact bodies' poses from free-flyers only
        raise ModelError(f"contact faces on joints {[model.names[j] for j in movable]}, which are neither "
                         "fixed nor free-flyers: lock them (reduced away) or make them free")

    q0 = pin.neutral(model)
    data = model.createData()
    pin.forwardKinematics(model, data, q0)
    for k in active:
        _, _, m, e = spec.modules[k]
        ee = end_effectors[e]
        oMa = data.oMi[ee.joint] * ee.placement
        rpy = np.radians(m.initial_rpy_deg)
        oMb = oMa * pin.SE3(pin.rpy.rpyToMatrix(*rpy), np.array(m.initial_offset_mm) * 1e-3)
        j = modules[k].joint
        jMb = model.jointPlacements[j].inverse() * oMb * modules[k].placement.inverse()
        q0[model.idx_qs[j]:model.idx_qs[j] + 7] = pin.SE3ToXYZQUAT(jMb)

    fingers = []
    for link in finger_links:
        f = _frame(model, link)
        e = next(i for i, (_, prefix) in enumerate(spec.end_effectors) if link.startswith(prefix))
        mod = next(m for (ee, m) in spec.grasps if ee == e)
        axis_J = f.placement.rotation[:, 2]  # prismatic finger joints open along their local z
        touch = _opening_at_touch(model, f.parentJoint, axis_J, master, master_finger == len(fingers),
                                  slave, end_effectors[e], modules[mod], params)
        start = touch + s.end_effector.start_gap_mm * 1e-3
        fingers.append(Finger(link, f.parentJoint, axis_J, e, touch, start))
    axes = np.array([f.axis_J for f in fingers]) if fingers else np.zeros((0, 3))
    return Model(s, spec, urdf, model, geom, tuple(end_effectors), tuple(modules), spec.grasps,
                 robot_joint, tuple(fingers), master_finger, axes[master_finger] if len(master_finger)
                 else np.zeros((0, 3)), finger_geoms, contact_joints, master, slave, tuple(pairs), maps,
                 params, q0, np.zeros(model.nv), free, _sphere_reach(master, slave, fingers),
                 tuple(np.array([i for i, f in enumerate(fingers) if f.drive == e], dtype=int)
                       for e in range(len(end_effectors))), faces)


def _sphere_reach(master, slave, fingers) -> tuple[tuple[int, float], ...]:
    """The farthest contact sphere from each contact joint's origin, fingers at any opening
    within their travel (start opening), m."""
    travel = max((f.opening_start for f in fingers), default=0.0)
    reach = {}
    for layers, extra in ((master, travel), (slave, 0.0)):
        for j in np.unique(layers.joint):
            r = np.linalg.norm(layers.centres_J[layers.joint == j], axis=1).max() + extra
            reach[int(j)] = max(reach.get(int(j), 0.0), float(r))
    return tuple(sorted(reach.items()))


def _contact_layers(model, faces, finger_links, module_prefixes, params):
    """Sphere layers of the active contact faces, stacked by role, and the coal face patches.

    Master faces: those on `finger_links`, placed at opening 0 on the joint the finger is
    mounted on. Slave faces: those on links of the modules named by `module_prefixes`.
    """
    geom = pin.GeometryModel()
    roles = {"master": [], "slave": []}
    finger_of_face, finger_geoms = [], []
    for face in faces:
        if face.link in finger_links:
            role = "master"
        elif any(face.link.startswith(p) for p in module_prefixes):
            role = "slave"
        else:
            continue  # an idle or welded pair of faces: no contact work
        frame = _frame(model, face.link)
        j, jMl = frame.parentJoint, frame.placement
        if role == "master":
            finger_of_face.append(finger_links.index(face.link))
            finger_geoms.append((len(geom.geometryObjects), finger_of_face[-1]))
        verts_J = face.vertices_L @ jMl.rotation.T + jMl.translation
        layer = sphere_layer(verts_J, params.r1 if role == "master" else params.r2)
        T = face.T_LC
        placement = jMl * pin.SE3(T[:3, :3], T[:3, 3])
        gid = geom.addGeometryObject(pin.GeometryObject(face.name, j, placement, coal.Box(*face.box_size)))
        roles[role].append((gid, j, layer))
    if not roles["master"] or not roles["slave"]:
        raise ModelError("the scene needs contact faces on both the fingers and a module")

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


def _opening_at_touch(model, parent_joint, axis_J, master, on_finger, slave, ee, module, params):
    """The finger opening (m) at which its sphere layer first touches its groove, centred.

    For each of the finger's faces opposed to a groove face (normals anti-parallel), the
    sphere envelopes touch when the face planes are 2 (r1 + r2) apart; the finger moves
    along its axis, so that distance is linear in the opening.
    on_finger: (|S1|,) bool, the master spheres of this finger (given at opening 0).
    """
    q = pin.neutral(model)
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    oMa = data.oMi[ee.joint] * ee.placement
    jMb = model.jointPlacements[module.joint].inverse() * oMa * module.placement.inverse()
    iq = model.idx_qs[module.joint]
    q[iq:iq + 7] = pin.SE3ToXYZQUAT(jMb)
    pin.forwardKinematics(model, data, q)
    oMf, oMm = data.oMi[parent_joint], data.oMi[module.joint]
    axis_W = oMf.rotation @ axis_J
    on_module = slave.joint == module.joint
    best = None
    for fm in np.unique(master.face[on_finger]):
        k = np.flatnonzero(master.face == fm)[0]
        n_f = oMf.rotation @ master.normals_J[k]
        x_f = oMf.act(master.centres_J[k] - params.r1 * master.normals_J[k])
        for fs in np.unique(slave.face[on_module]):
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


def grasp_frame(model: Model, data: pin.Data, ee: int) -> pin.SE3:
    """End-effector `ee`'s grasp frame O_a in world, from the kinematics in `data`."""
    e = model.end_effectors[ee]
    return data.oMi[e.joint] * e.placement


def groove_frame(model: Model, data: pin.Data, k: int) -> pin.SE3:
    """Module `k`'s groove frame O_b in world (a welded module rides on its end-effector)."""
    joint, placement = model.groove_placements[k]
    return data.oMi[joint] * placement
