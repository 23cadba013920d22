"""rts-scenario: traffic scenes replayed on a radar target simulator with 2-D angle of arrival.

The core API::

    import rts_scenario as rs
    array = rs.VirtualArray.preset("paper")
    rig = rs.Rig.preset("kit-table1")
    sol = rs.solve_weights(az_deg, el_deg, rig=rig, array=array, method="exact")
    sol.weights, sol.quad, sol.feasible, sol.reason
"""

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
from .solver import Reason, WeightSolution, solve_weights

__version__ = "0.1.0"

__all__ = [
    "ArrayError",
    "CheckError",
    "HardwareLimits",
    "OutputError",
    "Reason",
    "Reference",
    "Rig",
    "RigError",
    "RtsError",
    "ScenarioError",
    "SolverError",
    "VirtualArray",
    "WeightSolution",
    "solve_weights",
]
