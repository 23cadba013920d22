"""The built-in simulated radar as an output: schedules reach it like they reach a real RTS."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ..radar.profile import RadarProfile
from ..radar.simulate import Detections, SimulatedRadar
from ..rig import Rig
from ..schedule import Schedule
from .base import Output


class SimulatedRadarOutput(Output):
    """Play each batch on a `SimulatedRadar`; hand every frame's detections to ``sink``.

    Without a sink the detections collect in `detections`. Keyword options go to
    `SimulatedRadar` (fidelity, estimator, cfar, noise, errors, rng, threshold_db).
    """

    name = "simulated-radar"

    def __init__(self, *, profile: RadarProfile, rig: Rig,
                 sink: Callable[[Detections], None] | None = None, **options: Any) -> None:
        super().__init__()
        self.radar = SimulatedRadar(profile, rig, **options)
        self.detections: list[Detections] = []
        self._sink = sink or self.detections.append

    def _write(self, batch: Schedule) -> None:
        for frame in self.radar.process(batch):  # frames leave the radar one by one
            self._sink(frame)
