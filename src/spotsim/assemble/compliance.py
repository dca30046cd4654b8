"""Compliant arm joints (`arm.compliance`, `robot.compliance`): each joint a flexible joint.

A "locked" arm joint is held by its brake or its servo through its gearbox (paper Sec. 4.1: the
arms are self-locked during the grasp), and a gearbox is a torsional spring: Spong's flexible
joint. The link turns against -k (q - q_m) - c (q' - q_m'), q_m the motor side's angle, k the
gearbox's torsional stiffness from its catalogue, c the damping that gives `damping_ratio` of
critical on the link-side inertia the joint turns at the start (the mass matrix's diagonal, the
other joints held).

- `compliant`: the brake holds the motor side at the scenario's angle q_b; the rotor and its
  reflected inertia do not move.
- `servo`: the motor side turns, a joint of its own (`<name>_motor`) carrying the rotor's
  reflected inertia J_r as armature (Spong's model: the rotor's energy 1/2 J_r q_m'^2 alone),
  and a PD position servo holds it: -K_p (q_m - q_b) - K_d q_m' plus, fed forward, the torque
  that holds the start still under gravity, clamped to the joint's torque limit (its URDF's
  effort). K_p = J w^2 and K_d = 2 zeta J w, w the servo's bandwidth, J the rotor's and the
  link side's inertia at the start. The gearbox's spring sits between the two joints: joint
  `<name>` is its deflection.

`rigid` locks the joints and reduces them away; a stiffness scaled to infinity is its limit.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from ..errors import ScenarioError
from ..sim.tree import Spring, no_springs


class GearStiffness(NamedTuple):
    """A gearbox's torsional stiffness as its catalogue gives it: K1 up to the limit torque T1,
    K2 up to T2, K3 beyond (N m/rad, N m)."""

    K1: float
    T1: float
    K2: float
    T2: float
    K3: float

    def deflection(self, torque: float) -> float:
        """The twist under |torque| (rad): the catalogue's T/K1, T1/K1 + (T - T1)/K2, ... ."""
        T = abs(torque)
        if T <= self.T1:
            return T / self.K1
        if T <= self.T2:
            return self.T1 / self.K1 + (T - self.T1) / self.K2
        return self.T1 / self.K1 + (self.T2 - self.T1) / self.K2 + (T - self.T2) / self.K3


#: Each arm model's rotors' inertia reflected through their gearboxes, kg m^2, base to wrist
#: (`servo`; docs/model.md's assumptions table gives the sources): UR3, the wave generators of
#: Harmonic Drive sizes 17, 17, 14, 14, 14, 14 at ratio 100 (their motors' rotors not published,
#: so a lower bound); Z1, no published figure: the size-14 value for all six.
REFLECTED_INERTIA_KG_M2 = {
    "ur3": (0.079, 0.079, 0.033, 0.033, 0.033, 0.033),
    "z1": (0.033, 0.033, 0.033, 0.033, 0.033, 0.033),
}
#: The motor side's joint of a servo-held arm joint: its name.
MOTOR_SUFFIX = "_motor"


#: Harmonic Drive's torsional stiffness by size, ratio above 50 (CHA engineering data, doc.
#: 1018854, Tables 50.3/50.4; docs/model.md's assumptions table).
HARMONIC_DRIVE_14 = GearStiffness(K1=4.7e3, T1=2.0, K2=6.1e3, T2=6.9, K3=7.1e3)
HARMONIC_DRIVE_17 = GearStiffness(K1=1.0e4, T1=3.9, K2=1.4e4, T2=12.0, K3=1.6e4)
#: A planetary gearbox of the Z1's 30 N m class: one stiffness, ~1e4 N m/rad.
PLANETARY_30NM = GearStiffness(K1=1.0e4, T1=math.inf, K2=1.0e4, T2=math.inf, K3=1.0e4)
#: Each arm model's joints' gearboxes, base to wrist. UR3: strain-wave gears in UR's joint sizes
#: 2, 2, 1, 0, 0, 0 (56, 56, 28, 12 N m), taken as Harmonic Drive sizes 17, 17, 14, 14, 14, 14
#: (size 14 the smallest the table gives). Z1: Unitree publishes neither reduction nor stiffness.
JOINT_STIFFNESS = {
    "ur3": (HARMONIC_DRIVE_17, HARMONIC_DRIVE_17) + (HARMONIC_DRIVE_14,) * 4,
    "z1": (PLANETARY_30NM,) * 6,
}


def twist(spring: Spring, torque: float) -> float:
    """How far `spring` twists under a torque (or force) of `torque` >= 0: its torsion curve
    inverted (`sim.tree.spring_torque`), the catalogue's T/K1, T1/K1 + (T - T1)/K2, ... ."""
    return GearStiffness(spring.stiffness, spring.knee_1, spring.stiffness_2, spring.knee_2,
                         spring.stiffness_3).deflection(torque)


def compliance_of(s):
    """A scenario's arm compliance block (`scenario.Compliance`)."""
    return s.arm.compliance if hasattr(s, "arm") else s.robot.compliance


def joint_springs(model: pin.Model, q0: np.ndarray, joints, compliance, gravity: bool = True) -> dict[str, Spring]:
    """The springs of a reduced scene's compliant joints, by joint name.

    joints: (joint name, the brake's or the servo's angle, arm model, the joint's index in its
    arm), one per compliant joint (`scene.SceneSpec.compliant`); q0: the start configuration, at
    which each joint's link-side inertia is taken for its damping and, for a servo, the load it
    holds against gravity (unless `gravity` is False: the air-bearing table carries it).
    `compliant`: each joint's gearbox spring to its brake's angle; `servo`: the gearbox spring
    on the deflection (rest 0) and the servo on the motor side (`<name>_motor`). A weld keeps
    the springs of the scene before it (`Model.springs`): a welded module does not change a
    gearbox."""
    if not joints:
        return {}
    M = pin.crba(model, model.createData(), q0)
    servo = compliance.joints == "servo"
    G = np.zeros(model.nv)
    if servo and gravity:
        G = pin.computeGeneralizedGravity(model, model.createData(), q0)
    springs = {}
    for name, angle, arm, i in joints:
        if arm not in JOINT_STIFFNESS:
            raise ScenarioError([f"no joint stiffness known for the {arm} arm"])
        iv = model.idx_vs[model.getJointId(name)]
        gear, scale = JOINT_STIFFNESS[arm][i], compliance.stiffness_scale
        k = scale * gear.K1
        springs[name] = Spring(k, 2.0 * compliance.damping_ratio * math.sqrt(k * M[iv, iv]), 0.0 if servo else angle,
                               knee_1=gear.T1, stiffness_2=scale * gear.K2, knee_2=gear.T2, stiffness_3=scale * gear.K3)
        if servo:
            im = model.idx_vs[model.getJointId(name + MOTOR_SUFFIX)]
            inertia = M[im, im]  # the rotor's armature and the link side
            w = 2.0 * math.pi * compliance.servo_bandwidth_Hz
            kp = inertia * w * w
            springs[name + MOTOR_SUFFIX] = Spring(float(kp), float(2.0 * compliance.servo_damping_ratio * inertia * w),
                                                  float(angle + G[im] / kp), float(model.effortLimit[im]))
    return springs


def reflected_inertias(model: pin.Model, joints) -> None:
    """Put each servo-held joint's rotor's reflected inertia on its motor side's joint as
    armature (`REFLECTED_INERTIA_KG_M2`), in `model`."""
    armature = np.array(model.armature, dtype=float)
    for name, _, arm, i in joints:
        armature[model.idx_vs[model.getJointId(name + MOTOR_SUFFIX)]] = REFLECTED_INERTIA_KG_M2[arm][i]
    model.armature = armature


def spring_arrays(model: pin.Model, springs: dict) -> Spring:
    """The springs by velocity index, each field an array (nv,) (`sim.tree.kinematic_tree`); a
    joint without one has none (zero stiffness, infinite knees and limit) and the model's own
    damping."""
    arrays = no_springs(model)
    for name, spring in springs.items():
        iv = model.idx_vs[model.getJointId(name)]
        for array, value in zip(arrays, spring, strict=True):
            array[iv] = value
    return arrays


def servo_urdf(urdf: str, joints) -> str:
    """A compiled URDF with each of `joints` (joint name, ...) split in two: `<name>_motor`, the
    motor side, where the joint was (its parent, placement, axis and limits), and `<name>`, the
    gearbox's deflection, after a massless link `<name>_rotor` (its rotor is armature)."""
    import re

    for name, *_ in joints:
        found = re.search(rf'<joint\s[^>]*name="{name}".*?</joint>', urdf, re.DOTALL)
        if found is None:
            raise ScenarioError([f"the scene has no joint {name} to hold by a servo"])
        text = found.group(0)
        motor = text.replace(f'name="{name}"', f'name="{name}{MOTOR_SUFFIX}"', 1)
        motor = re.sub(r'<child\s+link="[^"]*"\s*/>', f'<child link="{name}_rotor"/>', motor)
        link = re.sub(r'<parent\s+link="[^"]*"\s*/>', f'<parent link="{name}_rotor"/>', text)
        link = re.sub(r'<origin[^>]*/>', '<origin xyz="0 0 0" rpy="0 0 0"/>', link)
        urdf = urdf[:found.start()] + motor + f'<link name="{name}_rotor"/>' + link + urdf[found.end():]
    return urdf
