"""The built-in simulated radar as an output: schedules reach it like they reach a real RTS."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ..detections import Detections
from ..errors import OutputError
from ..radar.profile import RadarProfile
from ..radar.simulate import SimulatedRadar
from ..rig import Rig
from ..schedule import Schedule
from .base import Output, RunContext


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

    @classmethod
    def for_run(cls, argument: str, context: RunContext) -> SimulatedRadarOutput:
        """Open the radar of the run's profile behind the run's rig, publishing to its checker."""
        if argument:
            raise OutputError(f"output 'simulated-radar' takes no argument, got {argument!r}")
        opts = context.radar_options
        return cls(profile=context.radar, rig=context.rig, sink=context.open_publisher(),
                   fidelity=opts.fidelity, estimator=opts.estimator, cfar=opts.cfar,
                   noise=opts.noise, errors=context.errors, rng=context.rng)

    def _write(self, batch: Schedule) -> None:
        for frame in self.radar.process(batch):  # frames leave the radar one by one
            self._sink(frame)
