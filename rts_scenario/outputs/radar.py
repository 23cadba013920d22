"""The built-in simulated radar as an output: schedules reach it like they reach a real RTS."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..detections import Detections
from ..errors import OutputError
from ..radar.clock import RadarClock
from ..radar.profile import RadarProfile
from ..radar.simulate import SimulatedRadar
from ..rig import Rig
from ..schedule import Schedule
from .base import Output, RunContext


class SimulatedRadarOutput(Output):
    """Play each batch on a `SimulatedRadar` on its own clock; hand its cycles to ``sink``.

    The radar measures at its clock's times (`rts_scenario.radar.clock.RadarClock`, the
    profile's unless ``clock`` is given), not at the scene's frames: each cycle sees the frame
    the RTS holds at that time, and carries the radar's counter and measurement time. A batch
    of frames is held from its first frame's time until one frame period after its last (the
    next batch's first frame; `Output.frame_period_s` where a run set it, else the batch's
    spacing). ``sink`` receives each batch's cycles as a list, in order;
    without a sink the cycles collect in `detections`. Keyword
    options go to `SimulatedRadar` (fidelity, estimator, cfar, noise, errors, rng,
    threshold_db).
    """

    name = "simulated-radar"
    applies_frames_on_time = True

    def __init__(self, *, profile: RadarProfile, rig: Rig,
                 sink: Callable[[list[Detections]], None] | None = None,
                 clock: RadarClock | None = None, **options: Any) -> None:
        super().__init__()
        self.radar = SimulatedRadar(profile, rig, **options)
        self.clock = clock or profile.radar_clock
        self.detections: list[Detections] = []
        self._sink = sink or self.detections.extend
        self._spacing_s: float | None = None

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
        if batch.n_frames == 0:
            return
        t = batch.t_s
        if batch.n_frames > 1:
            self._spacing_s = float(np.median(np.diff(t)))
        # The last frame is held one frame period: the run's, else the batches', else a cycle.
        spacing = next(s for s in (self.frame_period_s, self._spacing_s, self.clock.cycle_s)
                       if s is not None)
        n, t_cycles = self.clock.cycles_between(float(t[0]), float(t[-1]) + spacing)
        cycles = batch.held(t_cycles, self.clock.counter_of(n))
        self._sink(list(self.radar.process(cycles)))
