"""coal's broad phase over the contact faces' patches: which face pairs lie within the margin.

It runs in Python (Pinocchio's broad-phase manager over coal's dynamic AABB tree), between calls
of the compiled loop: the face pairs it keeps stay valid while the spheres move less than the
skin relative to each other (a Verlet skin), which the loop tracks (`Data.travel`).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..errors import SimulationError
from .loop import set_near


class StateOverflow(SimulationError):
    """The state grew past what the broad phase can represent: the run has diverged."""


class BroadPhase:
    """The broad phase of one Model: its own Pinocchio and coal data."""

    def __init__(self, model):
        self.model = model
        m = model.pin_model
        self.pin_data = m.createData()
        self.geom_data = pin.GeometryData(model.geom_model)
        for req in self.geom_data.collisionRequests:
            req.security_margin = model.sim.limits.margin
        self.manager = pin.BroadPhaseManager_DynamicAABBTreeCollisionManager(m, model.geom_model, self.geom_data)

    def near(self, q: np.ndarray) -> np.ndarray:
        """Indices into the model's face pairs (`SimModel.faces`) of those whose patches lie
        within the security margin at configuration q. Raises StateOverflow when coal rejects
        the state."""
        model, gd = self.model, self.geom_data
        pin.forwardKinematics(model.pin_model, self.pin_data, q)
        pin.updateGeometryPlacements(model.pin_model, self.pin_data, model.geom_model, gd)
        try:
            self.manager.update(False)
            pin.computeCollisions(self.manager, False)
        except ValueError as e:  # coal rejects bounds that overflowed
            reason = str(e).strip().splitlines()[-1].removeprefix("message: ")
            raise StateOverflow(f"state left the representable range (coal: {reason})") from e
        results = gd.collisionResults
        return np.array([i for i in range(len(results)) if results[i].isCollision()], dtype=np.int64)

    def refresh(self, data) -> np.ndarray:
        """Run it anew at data's state: its face pairs start a fresh skin (the search's pair
        list checks itself against the face pairs it was built for). Returns them."""
        near = self.near(data.q)
        set_near(data, near)
        return near
