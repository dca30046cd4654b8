"""One exception tree for everything spotsim reports to a user."""

from __future__ import annotations


class SpotsimError(Exception):
    """Base class of every error spotsim raises on purpose."""


class ScenarioError(SpotsimError):
    """A scenario failed validation; `problems` holds one line per problem.

    Each line reads `file: key.path = value: rule`, so that a user can fix every
    problem in one pass.
    """

    def __init__(self, problems: list[str]):
        self.problems = list(problems)
        super().__init__("\n".join(self.problems))


class ModelError(SpotsimError):
    """The URDF/XACRO assets or the model built from them are unusable."""


class SimulationError(SpotsimError):
    """A run could not be carried out (not a physics divergence, which is a status)."""
