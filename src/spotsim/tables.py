"""The names every layer shares: the joint kinds, the integrators, the finger drives and the
grasp phases, each a tuple whose index is the code the compiled Model and Data store.

One place for each table: the scenarios validate their choices against them, the assembly
writes their codes into the compiled Model, and the compiled core reads the codes. This module
imports nothing of spotsim, so every package may import it.
"""

from __future__ import annotations

#: The joint kinds of the compiled core, by Pinocchio's joint short names. `FIXED` is the
#: universe (joint 0); a free-flyer or a planar joint must be a child of the universe (a
#: floating root); revolute and prismatic joints may hang anywhere, about or along any axis.
JOINT_KINDS = ("fixed", "free_flyer", "planar", "revolute", "prismatic")
FIXED, FREE_FLYER, PLANAR, REVOLUTE, PRISMATIC = range(len(JOINT_KINDS))
#: Pinocchio's joint models by kind (`JointModel.shortname()`).
PINOCCHIO_JOINTS = {
    "JointModelFreeFlyer": FREE_FLYER,
    "JointModelPlanar": PLANAR,
    "JointModelRX": REVOLUTE, "JointModelRY": REVOLUTE, "JointModelRZ": REVOLUTE,
    "JointModelRevoluteUnaligned": REVOLUTE,
    "JointModelPX": PRISMATIC, "JointModelPY": PRISMATIC, "JointModelPZ": PRISMATIC,
    "JointModelPrismaticUnaligned": PRISMATIC,
}

#: The integrators, by their scenario names; a Model names its own by its index here.
METHODS = ("symplectic_euler", "rk4", "dopri5", "adaptive_euler")
SYMPLECTIC_EULER, RK4, DOPRI5, ADAPTIVE_EULER = range(len(METHODS))
#: The error-controlled methods.
ADAPTIVE = ("dopri5", "adaptive_euler")

#: The finger drives, by their scenario names (`sim.actuation`): `kinematic` and `relay`
#: prescribe the finger joints' motion at the speed their law sets at each controller sample;
#: `motor` pushes them with a motor's torque through a gearhead and a lead screw.
DRIVES = ("kinematic", "relay", "motor")
KINEMATIC, RELAY, MOTOR = range(len(DRIVES))
#: adaptive_euler's velocity kicks (`simulation.integrator.kick`).
KICKS = ("step", "staggered")
#: The states of a motor drive's transmission (a stick-slip element, as Modelica's
#: `LossyGear`): stuck; sliding with the power flowing from the motor to the fingers
#: (forward efficiency); sliding with it flowing back (backward efficiency).
TRANSMISSION_STATES = ("stuck", "forward", "backward")
STUCK, FORWARD, BACKWARD = range(len(TRANSMISSION_STATES))

#: The grasp phases, in order.
PHASE_NAMES = ("approach", "self_centring", "complete")
APPROACH, SELF_CENTRING, COMPLETE = range(len(PHASE_NAMES))
