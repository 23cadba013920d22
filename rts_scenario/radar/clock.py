"""The radar's own clock: when it measures, what it counts, when it reports.

A real radar does not number its cycles like the scene's frames. It measures every ``cycle_s``
(its frame period, e.g. 72 ms whatever the scene's frame rate), starting ``start_offset_s``
after the scene's time origin, counts its cycles from ``counter_start`` (wrapping where its
DBC's counter signal wraps), and puts a cycle's detections on the bus ``latency_s`` (+- a
uniform ``jitter_s``) after it measured. Cycle ``n`` (0, 1, ...) is measured at scene time
``start_offset_s + n * cycle_s`` and carries the counter ``counter_start + n``.

The RTS holds each schedule frame until the next one: a cycle measures the frame current at its
measurement time (`rts_scenario.schedule.held_frames`). Ground truth is evaluated at the
measurement time itself.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

# Times this close count as equal (a cycle measured exactly at a frame's time sees that frame).
TIME_EPS_S = 1e-9


@dataclass(frozen=True)
class RadarClock:
    """When the radar measures and reports (see the module docstring).

    Attributes
    ----------
    cycle_s : float
        Measurement cycle (> 0).
    start_offset_s : float
        Scene time of cycle 0 (>= 0).
    latency_s : float
        From measurement to the cycle's messages on the bus (>= 0).
    jitter_s : float
        The latency varies uniformly within +- this (>= 0, at most ``latency_s``).
    counter_start : int or None
        Counter of cycle 0 (>= 0); None when it is not known (a real radar counts from when it
        was switched on): a run learns it from the first cycle's bus time, the simulated radar
        starts at 0.
    """

    cycle_s: float
    start_offset_s: float = 0.0
    latency_s: float = 0.0
    jitter_s: float = 0.0
    counter_start: int | None = 0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.cycle_s) and self.cycle_s > 0):
            raise ValueError(f"clock.cycle_s: must be > 0, got {self.cycle_s!r}")
        for name in ("start_offset_s", "latency_s", "jitter_s"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"clock.{name}: must be >= 0, got {value!r}")
        if self.jitter_s > self.latency_s:
            raise ValueError(f"clock.jitter_s: must not exceed latency_s ({self.latency_s:g}), "
                             f"got {self.jitter_s:g}")
        if self.counter_start is not None and self.counter_start < 0:
            raise ValueError(f"clock.counter_start: must be >= 0, got {self.counter_start}")

    def cycles_between(self, t_start_s: float, t_end_s: float) -> tuple[IntArray, FloatArray]:
        """Cycles measured in ``[t_start_s, t_end_s)``: their numbers n and measurement times."""
        lo = max(0, int(np.ceil((t_start_s - self.start_offset_s) / self.cycle_s - TIME_EPS_S)))
        hi = max(lo, int(np.ceil((t_end_s - self.start_offset_s) / self.cycle_s - TIME_EPS_S)))
        n = np.arange(lo, hi, dtype=np.int64)
        return n, self.time_of(n)

    def time_of(self, n: IntArray) -> FloatArray:
        """Measurement time (scene time) of cycles ``n``."""
        return self.start_offset_s + np.asarray(n, dtype=np.float64) * self.cycle_s

    def counter_of(self, n: IntArray) -> IntArray:
        """Return the counters cycles ``n`` carry (before any wrap of the bus signal)."""
        return (self.counter_start or 0) + np.asarray(n, dtype=np.int64)

    def cycle_at(self, measured_s: float) -> int:
        """Return the cycle number measured nearest scene time ``measured_s``."""
        return int(np.round((measured_s - self.start_offset_s) / self.cycle_s))

    def bus_delay(self, n_cycles: int, rng: np.random.Generator) -> FloatArray:
        """Latency of ``n_cycles`` cycles' messages, jitter included (s)."""
        if self.jitter_s == 0.0:
            return np.full(n_cycles, self.latency_s)
        return self.latency_s + rng.uniform(-self.jitter_s, self.jitter_s, n_cycles)


__all__ = ["TIME_EPS_S", "RadarClock"]
