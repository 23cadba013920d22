"""Traffic scenes: the ``*.scenario.yaml`` format, its loader and the typed model."""

from .loader import (
    SCENE_SUFFIX,
    load_scenario,
    parametrizations,
    scenario_schema,
    scene_files,
    select_variant,
    variant_id,
    written_marks,
)
from .model import Effects, Expectations, Mount, RcsModel, Scenario, TargetSpec, run_label

__all__ = [
    "SCENE_SUFFIX",
    "Effects",
    "Expectations",
    "Mount",
    "RcsModel",
    "Scenario",
    "TargetSpec",
    "load_scenario",
    "parametrizations",
    "run_label",
    "scenario_schema",
    "scene_files",
    "select_variant",
    "variant_id",
    "written_marks",
]
