"""rts-scenario: traffic scenes replayed on a radar target simulator with 2-D angle of arrival."""

from .arrays import VirtualArray
from .errors import (
    ArrayError,
    CheckError,
    OutputError,
    RigError,
    RtsError,
    ScenarioError,
    SolverError,
)
from .rig import HardwareLimits, Reference, Rig

__all__ = [
    "ArrayError",
    "CheckError",
    "HardwareLimits",
    "OutputError",
    "Reference",
    "Rig",
    "RigError",
    "RtsError",
    "ScenarioError",
    "SolverError",
    "VirtualArray",
]

from .solver import Reason, WeightSolution, solve_weights  # noqa: E402

__all__ += ["Reason", "WeightSolution", "solve_weights"]
