"""Former home of `run_scene`; the run now lives in `rts_scenario.pipeline`."""

from .pipeline import RunOptions, RunResult, run_scene

__all__ = ["RunOptions", "RunResult", "run_scene"]
