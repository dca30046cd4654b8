"""The finger actuator and the grasp phases (paper Sec. 2.4 and 3.2 step 3)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

APPROACH, SELF_CENTRING, COMPLETE = "approach", "self_centring", "complete"
PHASES = (APPROACH, SELF_CENTRING, COMPLETE)


@dataclass
class FingerDrive:
    """One self-locking drive closing both fingers symmetrically (a linkage mirrors them).

    The drive closes at `speed` until the grasp force, the mean of the two fingers' contact
    loads (N, along their opening axes), reaches the grasp load; it then holds until the
    grasp force falls below `resume_fraction` of the grasp load. The hysteresis keeps a
    stalled drive from chattering between closing and holding.
    """

    speed: float
    grasp_load: float
    resume_fraction: float
    stalled: bool = False

    def opening_rate(self, load: np.ndarray) -> float:
        """The fingers' common opening rate for the coming step, m/s (closing is negative)."""
        force = sum(load.tolist()) / len(load)
        if force >= self.grasp_load:
            self.stalled = True
        elif force < self.resume_fraction * self.grasp_load:
            self.stalled = False
        return 0.0 if self.stalled else -self.speed


@dataclass
class GraspPhase:
    """Approach (no contact) -> self-centring -> complete, with the time of each change.

    Complete when, for `hold_s` without a break, the finger drive has stalled at the grasp
    load and holds, every active contact's relative speed is below `max_contact_speed`
    (m/s), and the net contact force on the module is below `max_net_force` (N): the paper's
    rule (Sec. 3.2 step 3, Sec. 5.1; model.md Sec. 6).
    """

    hold_s: float
    max_contact_speed: float
    max_net_force: float
    phase: str = APPROACH
    times: dict = field(default_factory=dict)
    _held_since: float | None = None

    def update(self, t: float, n_pairs: int, stalled: bool, contact_speed: float,
               net_force: float) -> None:
        if self.phase == APPROACH and n_pairs > 0:
            self.phase = SELF_CENTRING
            self.times[SELF_CENTRING] = t
        if self.phase != SELF_CENTRING:
            return
        if n_pairs > 0 and all(self.checks(stalled, contact_speed, net_force)):
            if self._held_since is None:
                self._held_since = t
            if t - self._held_since >= self.hold_s - 1e-12:
                self.phase = COMPLETE
                self.times[COMPLETE] = t
        else:
            self._held_since = None

    def checks(self, stalled: bool, contact_speed: float, net_force: float) -> tuple[bool, bool, bool]:
        """Whether each completion criterion holds now (labels: `labels()`)."""
        return (bool(stalled), contact_speed <= self.max_contact_speed, net_force <= self.max_net_force)

    def labels(self) -> tuple[str, str, str]:
        return ("finger drive stalled at the grasp load",
                f"contact speeds <= {self.max_contact_speed:g} m/s",
                f"net contact force <= {self.max_net_force:g} N")

    def criteria(self, stalled: bool, contact_speed: float, net_force: float) -> dict[str, bool]:
        """Each completion criterion, labelled, and whether it holds now (for messages)."""
        return dict(zip(self.labels(), self.checks(stalled, contact_speed, net_force), strict=True))
