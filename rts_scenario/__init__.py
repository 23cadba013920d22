"""rts-scenario: traffic scenes replayed on a radar target simulator with 2-D angle of arrival.

The stages a user scripts against, each a function over typed values::

    import rts_scenario as rs
    scene = rs.load_scenario("scenarios/cut_in.scenario.yaml")    # Scenario
    tracks = rs.compute_tracks(scene)                              # Tracks (F, K)
    schedule = rs.build_schedule(tracks, scene.rig, scene.radar)   # Schedule (F, K, 4)
    with rs.open_output("file:cut_in.npz") as out:                 # any registered output
        out.write(schedule)
    result = rs.run_scene(scene, rs.RunOptions(output="simulated-radar"))
    print(result.report.table())                                   # Report

    array = rs.VirtualArray.preset("paper")
    rig = rs.Rig.preset("kit-table1")
    sol = rs.solve_weights(az_deg, el_deg, rig=rig, array=array, method="exact")
    sol.weights, sol.quad, sol.feasible, sol.reason

A run streams: `Pipeline` wires the output, the detection bus and the checker, and plays the
scene in frame batches; radar cycles travel as `Detections` and `Checker` compares them
with the ground truth (`check_cycles`: a whole scene at once). Names are imported on first use,
so ``import rts_scenario`` stays cheap.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

from ._version import __version__ as __version__

# Public name -> module that defines it (imported when the name is first used).
_EXPORTS = {
    "ArrayError": "errors", "CheckError": "errors", "OutputError": "errors",
    "RigError": "errors", "RtsError": "errors", "ScenarioError": "errors",
    "SolverError": "errors", "SettingError": "errors",
    "VirtualArray": "arrays",
    "HardwareLimits": "rig", "Reference": "rig", "Rig": "rig",
    "Reason": "solver", "WeightSolution": "solver", "solve_weights": "solver",
    "SolverPlan": "solver", "solver_plan": "solver",
    "Scenario": "scenario", "load_scenario": "scenario",
    "Tracks": "kinematics", "compute_tracks": "kinematics",
    "Schedule": "schedule", "Status": "schedule", "build_schedule": "schedule",
    "Output": "outputs", "available_outputs": "outputs", "open_output": "outputs",
    "RadarProfile": "radar.profile",
    "Detections": "detections",
    "Checker": "check", "check_cycles": "check",
    "ErrorStats": "report", "Report": "report",
    "Pipeline": "pipeline", "RunOptions": "pipeline", "RunResult": "pipeline",
    "run_scene": "pipeline",
}

__all__ = [
    "ArrayError",
    "CheckError",
    "Checker",
    "Detections",
    "ErrorStats",
    "HardwareLimits",
    "Output",
    "OutputError",
    "Pipeline",
    "RadarProfile",
    "Reason",
    "Reference",
    "Report",
    "Rig",
    "RigError",
    "RtsError",
    "RunOptions",
    "RunResult",
    "Scenario",
    "ScenarioError",
    "Schedule",
    "SettingError",
    "SolverError",
    "SolverPlan",
    "Status",
    "Tracks",
    "VirtualArray",
    "WeightSolution",
    "available_outputs",
    "build_schedule",
    "check_cycles",
    "compute_tracks",
    "load_scenario",
    "open_output",
    "run_scene",
    "solve_weights",
    "solver_plan",
]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'rts_scenario' has no attribute {name!r}")
    value = getattr(import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})


if TYPE_CHECKING:
    from .arrays import VirtualArray
    from .check import Checker, check_cycles
    from .detections import Detections
    from .errors import (
        ArrayError,
        CheckError,
        OutputError,
        RigError,
        RtsError,
        ScenarioError,
        SettingError,
        SolverError,
    )
    from .kinematics import Tracks, compute_tracks
    from .outputs import Output, available_outputs, open_output
    from .pipeline import Pipeline, RunOptions, RunResult, run_scene
    from .radar.profile import RadarProfile
    from .report import ErrorStats, Report
    from .rig import HardwareLimits, Reference, Rig
    from .scenario import Scenario, load_scenario
    from .schedule import Schedule, Status, build_schedule
    from .solver import Reason, SolverPlan, WeightSolution, solve_weights, solver_plan
