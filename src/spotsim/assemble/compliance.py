"""Compliant arm joints (`arm.compliance`, `robot.compliance`): each joint a flexible joint.

A "locked" arm joint is held by its brake through its gearbox (paper Sec. 4.1: the arms are
self-locked during the grasp), and a gearbox is a torsional spring: Spong's flexible joint
with its motor side held still. The link turns against -k (q - q_b) - c q', q_b the angle the
brake holds (the scenario's), k the gearbox's torsional stiffness from its catalogue, c the
damping that gives `damping_ratio` of critical on the link-side inertia the joint turns at the
start (the mass matrix's diagonal, the other joints held). The rotor and its reflected inertia
sit on the braked motor side: they do not move. `rigid` locks the joints and reduces them
away; a stiffness scaled to infinity is its limit.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from ..errors import ScenarioError

#: Each arm model's joints' torsional stiffness, N m/rad, base to wrist: the gearbox catalogue's
#: stiffness below its first limit torque (K1) for each joint's size, the softest of its three
#: (docs/model.md's assumptions table gives the sources). UR3: strain-wave gears in UR's joint
#: sizes 2, 2, 1, 0, 0, 0 (56, 56, 28, 12 N m), taken as Harmonic Drive sizes 17, 17, 14, 14, 14,
#: 14 (size 14 the smallest the table gives). Z1: planetary gearboxes of its 30 N m class.
JOINT_STIFFNESS_NM_RAD = {
    "ur3": (1.0e4, 1.0e4, 4.7e3, 4.7e3, 4.7e3, 4.7e3),
    "z1": (1.0e4, 1.0e4, 1.0e4, 1.0e4, 1.0e4, 1.0e4),
}


def compliance_of(s):
    """A scenario's arm compliance block (`scenario.Compliance`)."""
    return s.arm.compliance if hasattr(s, "arm") else s.robot.compliance


def joint_springs(model: pin.Model, q0: np.ndarray, joints, compliance) -> dict[str, tuple[float, float, float]]:
    """The springs of a reduced scene's compliant joints: {joint name: (stiffness (N m/rad),
    damping (N m s/rad), the brake's angle (rad))}.

    joints: (joint name, the brake's angle, arm model, the joint's index in its arm), one per
    compliant joint (`scene.SceneSpec.compliant`); q0: the start configuration, at which each
    joint's link-side inertia is taken for its damping. A weld keeps the springs of the scene
    before it (`Model.springs`): a welded module does not change a gearbox."""
    if not joints:
        return {}
    M = pin.crba(model, model.createData(), q0)
    springs = {}
    for name, angle, arm, i in joints:
        if arm not in JOINT_STIFFNESS_NM_RAD:
            raise ScenarioError([f"no joint stiffness known for the {arm} arm"])
        iv = model.idx_vs[model.getJointId(name)]
        k = compliance.stiffness_scale * JOINT_STIFFNESS_NM_RAD[arm][i]
        springs[name] = (k, 2.0 * compliance.damping_ratio * math.sqrt(k * M[iv, iv]), angle)
    return springs


def spring_arrays(model: pin.Model, springs: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The springs by velocity index (nv,): stiffness, damping and rest (`sim.tree.kinematic_tree`);
    the other joints' damping is the model's own."""
    stiffness, damping, rest = np.zeros(model.nv), np.array(model.damping, dtype=float), np.zeros(model.nv)
    for name, (k, c, angle) in springs.items():
        iv = model.idx_vs[model.getJointId(name)]
        stiffness[iv], damping[iv], rest[iv] = k, c, angle
    return stiffness, damping, rest
