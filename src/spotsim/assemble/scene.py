"""The scene of a scenario: which XACRO, which joints to lock, which bodies take part.

Everything here is by name and fixed for a run (a weld makes a new scene with its module
joined to the robot).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
import pinocchio as pin

from ..errors import ModelError
from ..scenario import DualArmScenario, Geometry, Scenario
from . import assets, robot

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
    # the arms' compliant joints, kept (not locked): (joint name, the brake's angle (rad), arm
    # model, the joint's index in its arm), `compliance.joint_springs`; limit-checked as `checked` says
    compliant: tuple[tuple[str, float, str, int], ...] = ()
    # the arm's base on the dynamometer (`rig.mount_on_dynamometer`)
    dynamometer: bool = False
    # the compliant joints held by servos, each split in a motor side and the gearbox's
    # deflection (`compliance.servo_urdf`)
    servo: bool = False

    @property
    def welded_modules(self) -> set[int]:
        return {k for k, _, _ in self.welded}


def geometry_args(g) -> dict:
    """XACRO arguments of a scenario's `geometry` block (the XACRO's arguments of the same names)."""
    return {f.name: getattr(g, f.name) for f in fields(g)}


def module_args(prefix: str, m) -> dict:
    """XACRO arguments of one module, named with the scene's prefix convention."""
    args = {f"{prefix}mass_kg": m.mass_kg, f"{prefix}com_x_mm": m.com_mm[0],
            f"{prefix}com_y_mm": m.com_mm[1], f"{prefix}com_z_mm": m.com_mm[2]}
    args.update({f"{prefix}{k.name}": getattr(m.inertia_kg_m2, k.name) for k in fields(m.inertia_kg_m2)})
    return args


def scene_spec(s, welded: dict | None = None, held: dict | None = None) -> SceneSpec:
    """The scene of a scenario. welded: module index -> (xyz, rpy) of its O_b in its
    end-effector's grasp frame, for modules already grasped; held: finger joint name -> the
    opening (m) it is locked at: a welded module's end-effector's fingers (0 if not given)
    and any other finger that does not move in the scene. The other fingers stay on their
    prismatic joints."""
    welded, held = welded or {}, held or {}
    if isinstance(s, Scenario):
        args = {**geometry_args(s.geometry), **module_args("module_", s.module)}
        arm = [f"joint{i}" for i in range(1, 7)]
        joints = dict(zip(arm, s.arm.joint_angles_rad, strict=True))
        compliant = s.arm.compliance.joints != "rigid"
        locked = {**({} if compliant else joints), "jointGripper": 0.0, **{name: float(x) for name, x in held.items()}}
        checked = {name: f"arm.joint_angles_rad[{i}]" for i, name in enumerate(arm)}
        return SceneSpec(assets.URDF_DIR / "single_arm_scene.urdf.xacro", args, locked, checked,
                         (("EE", "ee_"),), (("TM", "tm_", s.module, 0),), ((0, 0),),
                         compliant=tuple((name, joints[name], s.arm.model, i) for i, name in enumerate(arm)
                                         if compliant), dynamometer=s.arm.base == "dynamometer",
                         servo=s.arm.compliance.joints == "servo")
    if isinstance(s, DualArmScenario):
        args = {**geometry_args(s.geometry), **module_args("tm1_", s.tm1), **module_args("tm2_", s.tm2),
                **robot.LAYOUTS[s.robot.layout]}
        for k, (xyz, rpy) in welded.items():
            prefix = ("tm1_", "tm2_")[k]
            args.update({f"{prefix}joint_type": "fixed", f"{prefix}parent": f"ee{k + 1}_grasp",
                         f"{prefix}xyz": " ".join(repr(float(x)) for x in xyz),
                         f"{prefix}rpy": " ".join(repr(float(x)) for x in rpy)})
        locked, checked, compliant = {}, {}, []
        for arm, angles in (("arm1_", s.robot.arm1_joint_angles_rad), ("arm2_", s.robot.arm2_joint_angles_rad)):
            for i, (name, angle) in enumerate(zip(robot.ARM_JOINTS, angles, strict=True)):
                if s.robot.compliance.joints != "rigid":
                    compliant.append((arm + name, angle, s.robot.arm_model, i))
                else:
                    locked[arm + name] = angle
                checked[arm + name] = f"robot.{arm}joint_angles_rad[{i}]"
            for finger in FINGER_NAMES:
                name = f"ee{arm[3]}_{finger}"
                if int(arm[3]) - 1 in welded or name in held:  # its fingers hold its module, or stay
                    locked[name] = float(held.get(name, 0.0))
        return SceneSpec(assets.URDF_DIR / "dual_arm_scene.urdf.xacro", args, locked, checked,
                         (("EE-1", "ee1_"), ("EE-2", "ee2_")),
                         (("TM-1", "tm1_", s.tm1, 0), ("TM-2", "tm2_", s.tm2, 1)),
                         ((0, 0), (1, 1)), robot_joint="fdr_free_flyer",
                         welded=tuple((k, tuple(map(float, xyz)), tuple(map(float, rpy)))
                                      for k, (xyz, rpy) in sorted(welded.items())),
                         arms=((s.robot.arm_model, "arm1_"), (s.robot.arm_model, "arm2_")), compliant=tuple(compliant),
                         servo=s.robot.compliance.joints == "servo")
    raise TypeError(f"not a scenario: {type(s).__name__}")


def check_inertials(urdf: str) -> None:
    """Reject a URDF whose <inertial> values are not finite numbers, whose mass is negative or
    whose inertia is not positive semi-definite, naming the link: Pinocchio's URDF parser drops
    an inertial it cannot read (a massless link) with only a log line, and takes the rest as
    they are."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.fromstring(urdf)
    except ET.ParseError as e:
        raise ModelError(f"not a URDF: {e}") from None
    problems = []
    for link in root.iter("link"):
        inertial = link.find("inertial")
        if inertial is None:
            continue
        name = link.get("name")
        values = {}
        for tag, attrs in (("mass", ("value",)), ("inertia", ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")),
                           ("origin", ("xyz", "rpy"))):
            element = inertial.find(tag)
            for attr in attrs:
                text = element.get(attr) if element is not None else None
                if text is None:
                    continue
                try:
                    numbers = [float(x) for x in text.split()]
                except ValueError:
                    numbers = [math.nan]
                if not numbers or not all(math.isfinite(x) for x in numbers):
                    problems.append(f"link {name}: inertial {tag} {attr}={text!r} must be finite numbers")
                values[attr] = numbers[0] if numbers else math.nan
        if not all(math.isfinite(v) for v in values.values()):
            continue
        if values.get("value", 0.0) < 0:
            problems.append(f"link {name}: mass {values['value']} kg must be >= 0")
        I = np.array([[values.get("ixx", 0.0), values.get("ixy", 0.0), values.get("ixz", 0.0)],
                      [values.get("ixy", 0.0), values.get("iyy", 0.0), values.get("iyz", 0.0)],
                      [values.get("ixz", 0.0), values.get("iyz", 0.0), values.get("izz", 0.0)]])
        if np.linalg.eigvalsh(I).min() < -MIN_INERTIA_EIGENVALUE:
            problems.append(f"link {name}: inertia {I.tolist()} is not positive semi-definite")
    if problems:
        raise ModelError("; ".join(problems))


def check_inertias(model: pin.Model, joints=None) -> None:
    """Reject non-finite values, negative masses and inertias that are not positive definite.

    Pinocchio accepts all of these silently. `joints`: the bodies that must have mass > 0.
    """
    problems = []
    for j in range(1, model.njoints):
        I = model.inertias[j]
        links = [f.name for f in model.frames if f.type == pin.BODY and f.parentJoint == j]
        name = f"link {links[0]} (joint {model.names[j]})" if links else f"body of joint {model.names[j]}"
        if not (np.isfinite(I.mass) and np.all(np.isfinite(I.lever)) and np.all(np.isfinite(I.inertia))):
            problems.append(f"{name}: non-finite mass, centroid or inertia")
            continue
        if I.mass < 0 or (joints is not None and j in joints and I.mass <= 0):
            problems.append(f"{name}: mass {I.mass} kg must be > 0")
        if I.mass > 0 and np.linalg.eigvalsh(I.inertia).min() < MIN_INERTIA_EIGENVALUE:
            problems.append(f"{name}: inertia {I.inertia.tolist()} is not positive definite")
    if problems:
        raise ModelError("; ".join(problems))


def lock_joints(full: pin.Model, spec: SceneSpec) -> tuple[pin.Model, list[str]]:
    """Reduce away the locked joints (arms at the scenario's angles, a welded end-effector's
    fingers at their openings); the compliant arms' joints stay. Every arm joint's angle is
    checked against its limits."""
    q_ref = pin.neutral(full)
    problems, lock = [], []
    held = [(name, angle, True) for name, angle in spec.locked.items()]
    held += [(name, angle, False) for name, angle, _, _ in spec.compliant]
    for name, angle, locked in held:
        j = full.getJointId(name)
        lo, hi = full.lowerPositionLimit[full.idx_qs[j]], full.upperPositionLimit[full.idx_qs[j]]
        if name in spec.checked and not lo <= angle <= hi:
            problems.append(f"{spec.checked[name]} = {angle}: must be within the {name} limits "
                            f"[{lo:.4f}, {hi:.4f}] rad")
        if locked:
            q_ref[full.idx_qs[j]] = angle
            lock.append(j)
    return pin.buildReducedModel(full, lock, q_ref), problems


def frame(model: pin.Model, name: str) -> pin.Frame:
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


def fdr_inertia(s, with_tm1: bool = False) -> pin.Inertia:
    """The free-flying robot of a dual-arm scenario as one body (Table 5 body 3), or with TM-1
    welded to EE-1 at the grasp frame (body 4): its scene (`scene.scene_spec`, the robot's
    layout included) with the arms locked at the scenario's angles."""
    spec = scene_spec(s, {0: ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))} if with_tm1 else None)
    for arm, prefix in spec.arms:
        assets.prefixed_arm(arm, prefix)
    angles = {"arm1_": s.robot.arm1_joint_angles_rad, "arm2_": s.robot.arm2_joint_angles_rad}
    model, j = robot.locked_robot(assets.compile_xacro(spec.xacro, spec.args), angles)
    return model.inertias[j]


def xacro_defaults_agree() -> list[str]:
    """Differences between the scene XACRO's argument defaults and Geometry's defaults."""
    xacro = assets.xacro_arg_defaults(assets.URDF_DIR / "single_arm_scene.urdf.xacro")
    return [f"{f.name}: XACRO {xacro.get(f.name)} != scenario {f.default}"
            for f in fields(Geometry) if xacro.get(f.name) != f.default]
