"""The free-flying dual-arm robot's mass properties against the paper's Tables 5 and 6."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..scenario import TABLE6_ARM1, TABLE6_ARM2
from . import assets

DUAL_ARM_XACRO = assets.URDF_DIR / "dual_arm_scene.urdf.xacro"
ARM = "ur3"
ARM_JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
              "wrist_2_joint", "wrist_3_joint")
FINGERS = ("ee1_finger_upper", "ee1_finger_lower", "ee2_finger_upper", "ee2_finger_lower")
#: Table 6: joint states of the arms during the grasps, rad, by arm prefix.
TABLE6 = {"arm1_": TABLE6_ARM1, "arm2_": TABLE6_ARM2}


#: The robot's layouts (scenario `robot.layout`, `scenario.LAYOUT_TM1_COM_MM`) as XACRO
#: arguments beyond the defaults. table5_body4: the least-change fit of `python
#: benchmarks/table5_composite.py` with TM-1's centroid within 0.2 m (mm, rounded), and its
#: base fitted to Table 5 body 3 (`fit_base`, 6 digits); its mounts reach past the default
#: 400 mm base, which is drawn 500 mm.
LAYOUTS = {
    "compact": {},
    "table5_body4": {"arm1_mount_mm": "-6 213 183", "arm2_mount_mm": "124 -160 218", "base_com_mm": "82 -53 -1",
                     "base_size_mm": 500, "base_mass_kg": 24.977, "base_ixx": 1.23739, "base_iyy": 2.31562,
                     "base_izz": 1.71921, "base_ixy": -0.355998, "base_ixz": -0.0399275, "base_iyz": 0.330329},
}
#: XACRO arguments that leave the base (nearly) massless: the robot's other parts alone.
MASSLESS_BASE = {"base_mass_kg": 1e-9, "base_ixx": 1e-12, "base_iyy": 1e-12, "base_izz": 1e-12,
                 "base_ixy": 0, "base_ixz": 0, "base_iyz": 0}


@dataclass(frozen=True)
class Body:
    """Mass (kg) and principal moments of inertia about the centroid (kg m^2), Table 5."""

    mass: float
    inertia: tuple[float, float, float]


TABLE5 = {1: Body(30.531, (0.533, 0.397, 0.308)), 2: Body(10.567, (0.318, 0.199, 0.190)),
          3: Body(47.037, (3.561, 3.521, 3.450)), 4: Body(77.568, (10.459, 8.039, 13.471))}


def locked_robot(urdf: str, angles=TABLE6) -> tuple[pin.Model, int]:
    """The scene with both arms locked at `angles` and the fingers at opening 0, and the
    FDR's free-flyer joint, whose body is then the whole robot."""
    full = pin.buildModelFromXML(urdf)
    lock = [full.getJointId(prefix + name) for prefix in angles for name in ARM_JOINTS]
    lock += [full.getJointId(name) for name in FINGERS]
    model = pin.buildReducedModel(full, lock, arms_at(full, angles))
    return model, model.getJointId("fdr_free_flyer")


def arms_at(model: pin.Model, angles=TABLE6) -> np.ndarray:
    """The scene's neutral configuration with the arms' joints at `angles` ({prefix: six
    angles}, rad)."""
    q = pin.neutral(model)
    for prefix, values in angles.items():
        for name, value in zip(ARM_JOINTS, values, strict=True):
            q[model.idx_qs[model.getJointId(prefix + name)]] = value
    return q


def parallel_axis(m: float, d: np.ndarray) -> np.ndarray:
    """The inertia (3, 3) a mass m adds about a point at d from it: m (|d|^2 1 - d d^T)."""
    return m * (d @ d * np.eye(3) - np.outer(d, d))


def composite(inertia: pin.Inertia) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass, centroid (in the body frame) and inertia matrix about the centroid of a body."""
    return inertia.mass, inertia.lever.copy(), inertia.inertia.copy()


def fit_base(args: dict | None = None, arm: str = ARM, physical: bool = True) -> dict[str, float]:
    """The base mass and inertia (about its centroid, base axes) that give the locked robot
    Table 5 body 3's mass and inertia about its centroid (products of inertia zero).

    The base's centroid is the XACRO's base_com_mm (in `args`, else its default, the base
    frame's origin). arm: the arms' model (the XACRO's arm_model). Returns the XACRO arguments
    base_mass_kg and base_i**; raises ValueError if no physical base can do it (unless physical
    is False: then the base returned may be unphysical).
    """
    for prefix in TABLE6:
        assets.prefixed_arm(arm, prefix)
    args = args or {}
    com = args.get("base_com_mm", assets.xacro_arg_defaults(DUAL_ARM_XACRO)["base_com_mm"])
    c_b = 1e-3 * np.array([float(x) for x in str(com).split()])
    probe = {**args, "arm_model": arm, **MASSLESS_BASE}
    model, j = locked_robot(assets.compile_xacro(DUAL_ARM_XACRO, probe))
    m_r, c_r, I_r = composite(model.inertias[j])
    target = TABLE5[3]
    m_b = target.mass - m_r
    c = (m_r * c_r + m_b * c_b) / target.mass  # the robot's centroid

    I_b = np.diag(target.inertia) - I_r - parallel_axis(m_r, c_r - c) - parallel_axis(m_b, c_b - c)
    eig = np.linalg.eigvalsh(I_b)
    if physical and (m_b <= 0 or eig.min() <= 0 or 2 * eig.max() > eig.sum()):
        raise ValueError(f"no physical base gives Table 5 body 3: base mass {m_b:.3f} kg, "
                         f"inertia eigenvalues {eig}")
    return {"base_mass_kg": m_b, "base_ixx": I_b[0, 0], "base_iyy": I_b[1, 1], "base_izz": I_b[2, 2],
            "base_ixy": I_b[0, 1], "base_ixz": I_b[0, 2], "base_iyz": I_b[1, 2]}


#: How closely `level_arms` brings each grasp frame's y_a to the table's normal, rad.
LEVEL_TOL_RAD = 1e-9


def grasp_axes(urdf: str, angles) -> list[np.ndarray]:
    """Each end-effector's grasp frame O_a (its rotation in the robot's base frame, columns
    x_a, y_a, z_a) with the arms locked at `angles` ({prefix: six angles})."""
    model, _ = locked_robot(urdf, angles)
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    return [data.oMf[model.getFrameId(f"ee{k}_grasp")].rotation.copy() for k in (1, 2)]


def level_arms(normal=(0.0, 1.0, 0.0), angles=TABLE6) -> dict[str, tuple[float, ...]]:
    """The arms' joint angles nearest `angles` (least squares, rad) at which both grasp frames'
    y_a lie along the table's `normal` (base frame, the robot at its start): their x_a (the
    SPOT offsets' axis) and z_a (the fingers' closing axis) then lie in the table's plane, as
    on the testbed. UR3 at Table 6's own angles tilts them 7.6 and 7.1 deg from world y."""
    from scipy.optimize import least_squares

    for prefix in angles:
        assets.prefixed_arm(ARM, prefix)
    urdf = assets.compile_xacro(DUAL_ARM_XACRO, {})
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    prefixes = list(angles)
    start = np.concatenate([angles[p] for p in prefixes])

    def as_angles(x):
        return {p: tuple(float(a) for a in x[6 * i:6 * i + 6]) for i, p in enumerate(prefixes)}

    def misalignment(x):
        return np.concatenate([np.cross(R[:, 1], n) for R in grasp_axes(urdf, as_angles(x))])

    # the nearest angles: a small weight on the change, then the alignment alone from there
    near = least_squares(lambda x: np.r_[misalignment(x), 1e-2 * (x - start)], start, xtol=1e-12).x
    exact = least_squares(misalignment, near, xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    if np.abs(misalignment(exact)).max() > LEVEL_TOL_RAD:
        raise ValueError(f"no arm angles near {angles} level both grasp frames to the normal {normal}")
    return as_angles(exact)
