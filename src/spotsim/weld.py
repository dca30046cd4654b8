"""Welding a grasped module to the robot: one composite body with the same momentum.

After the first grasp TM-1 and the robot move as one body (paper Sec. 5.1, body 4). The weld
is a model change: the module's free-flyer is replaced by a fixed joint at its pose in the
grasp frame, and the composite gets the velocity that keeps the pair's linear and angular
momentum exactly (a perfectly plastic joining).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin


def world_momentum(M_WB: pin.SE3, inertia: pin.Inertia, v_B: pin.Motion) -> pin.Force:
    """Spatial momentum of a body (inertia and twist in its frame B) in world, about the origin."""
    return M_WB.act(inertia * v_B)


def twist_for_momentum(M_WA: pin.SE3, inertia_A: pin.Inertia, h_W: pin.Force) -> pin.Motion:
    """The twist, in frame A, that gives a body of inertia `inertia_A` (frame A) the world
    momentum h_W: Y^-1 h, both in A."""
    return pin.Motion(np.linalg.solve(inertia_A.matrix(), M_WA.actInv(h_W).vector))


def merged_twist(M_WA: pin.SE3, inertia_A: pin.Inertia, v_A: pin.Motion,
                 M_WB: pin.SE3, inertia_B: pin.Inertia, v_B: pin.Motion) -> tuple[pin.Inertia, pin.Motion]:
    """Composite inertia (in A's frame) and the twist of A's frame that keep A's and B's momentum.

    Y = Y_A + Y_B; the composite twist is Y^-1 (h_A + h_B). Returned in A's frame, the frame
    the composite keeps.
    """
    Y_A = M_WA.actInv(M_WA.act(inertia_A) + M_WB.act(inertia_B))
    h_W = world_momentum(M_WA, inertia_A, v_A) + world_momentum(M_WB, inertia_B, v_B)
    return Y_A, twist_for_momentum(M_WA, Y_A, h_W)
