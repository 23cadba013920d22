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
        lo = self.first_at(t_start_s)
        hi = max(lo, self.first_at(t_end_s))
        n = np.arange(lo, hi, dtype=np.int64)
        return n, self.time_of(n)

    def time_of(self, n: IntArray) -> FloatArray:
        """Measurement time (scene time) of cycles ``n``."""
        return self.start_offset_s + np.asarray(n, dtype=np.float64) * self.cycle_s

    def counter_of(self, n: IntArray) -> IntArray:
        """Return the counters cycles ``n`` carry (before any wrap of the bus signal)."""
        return (self.counter_start or 0) + np.asarray(n, dtype=np.int64)

    def first_at(self, t_s: float) -> int:
        """Return the first cycle (>= 0) measured at or after scene time ``t_s``."""
        return max(0, int(np.ceil((t_s - self.start_offset_s) / self.cycle_s - TIME_EPS_S)))

    @property
    def start_tolerance_s(self) -> float:
        """How far before the scene's start a cycle may lie and count as its first: 0 (exact)."""
        return 0.0

    def edge_tolerance_s(self, t_s: float) -> float:
        """How far before scene time ``t_s`` a cycle may lie and have measured at it: 0."""
        return 0.0

    def bus_delay(self, n_cycles: int, rng: np.random.Generator) -> FloatArray:
        """Latency of ``n_cycles`` cycles' messages, jitter included (s)."""
        if self.jitter_s == 0.0:
            return np.full(n_cycles, self.latency_s)
        return self.latency_s + rng.uniform(-self.jitter_s, self.jitter_s, n_cycles)


class CycleTimeFit:
    """Running straight-line fit of when a radar's cycles reached the bus against their numbers.

    Its slope is the radar's cycle on the bus's clock. A radar's crystal is not its profile:
    a cycle 0.1 % longer than ``cycle_s`` puts cycle 3,600 (three minutes at 50 ms) 180 ms
    later than a check by the profile assumes, three frames. Latency and its jitter shift the
    points, not the slope. Memory is constant (sums about the first point, which keep the
    precision of epoch timestamps).
    """

    def __init__(self) -> None:
        self.count = 0
        self._origin: tuple[int, float] | None = None
        self._sums = np.zeros(5)  # n, t, n^2, n t, t^2 about the origin
        self._span = [0, 0]  # smallest and largest n about the origin

    def add(self, n: IntArray, bus_t_s: FloatArray) -> None:
        """Take cycles ``n`` and when they reached the bus (NaN: not known, left out)."""
        n = np.asarray(n, dtype=np.int64)
        t = np.asarray(bus_t_s, dtype=np.float64)
        keep = np.isfinite(t)
        n, t = n[keep], t[keep]
        if not n.size:
            return
        if self._origin is None:
            self._origin = (int(n[0]), float(t[0]))
        x = (n - self._origin[0]).astype(np.float64)
        y = t - self._origin[1]
        self._sums += (x.sum(), y.sum(), (x * x).sum(), (x * y).sum(), (y * y).sum())
        self._span = [min(self._span[0], int(x.min())), max(self._span[1], int(x.max()))]
        self.count += int(n.size)

    def cycle_s(self) -> tuple[float, float] | None:
        """Return the fitted cycle (s) and its standard error; None when the bus cannot tell.

        None before three cycles, and where the cycles scatter by more than a quarter of the
        cycle about the line: their numbers do not follow their bus times (a counter that
        jumped, or a gap longer than half of what a narrow counter counts), and a crystal off
        its profile leaves them on a straight line. None too where the times do not advance
        with the numbers (a logger that stamped every message alike, or whose clock went back).
        """
        line = self._line()
        if line is None:
            return None
        slope, scatter, var_x = line
        if not slope > 0.0 or scatter > 0.25 * slope:
            return None
        return float(slope), float(scatter / np.sqrt(var_x))

    def scatter_s(self) -> float | None:
        """Return the cycles' scatter about the fitted line (s); None before three cycles."""
        line = self._line()
        return None if line is None else float(line[1])

    def _line(self) -> tuple[float, float, float] | None:
        """Slope, scatter about the line and the numbers' sum of squares; None before 3."""
        k = self.count
        sx, sy, sxx, sxy, syy = self._sums
        var_x = sxx - sx * sx / k if k else 0.0
        if k < 3 or var_x <= 0.0:
            return None
        slope = (sxy - sx * sy / k) / var_x
        residual = max(syy - sy * sy / k - slope * (sxy - sx * sy / k), 0.0)
        return slope, float(np.sqrt(residual / (k - 2))), var_x

    @property
    def span(self) -> int:
        """Cycles from the first seen to the last (by number)."""
        return self._span[1] - self._span[0]

    def zero_s(self, cycle_s: float) -> float | None:
        """Bus time of cycle 0 on the line of slope ``cycle_s`` through the cycles seen.

        The mean of their bus times less ``cycle_s`` times their numbers (the least-squares
        intercept for that slope); None before the first cycle.
        """
        if self._origin is None:
            return None
        sx, sy = self._sums[0] / self.count, self._sums[1] / self.count
        return self._origin[1] + sy - cycle_s * (self._origin[0] + sx)

    def zero_error_s(self, cycle_s: float) -> float:
        """Return the standard error of `zero_s` for that slope (from the scatter about it)."""
        k = self.count
        if k < 2:
            return np.inf
        sx, sy, sxx, sxy, syy = self._sums / k
        mean = sy - cycle_s * sx
        var = syy - 2.0 * cycle_s * sxy + cycle_s * cycle_s * sxx - mean * mean
        return float(np.sqrt(max(var, 0.0) / (k - 1)))

    def drift_s(self, cycle_s: float) -> tuple[float, float] | None:
        """How far the last cycle lies from where ``cycle_s`` puts it, and 3 sigma of that.

        Over the span of the cycles seen, from the first; None before three cycles.
        """
        fit = self.cycle_s()
        if fit is None:
            return None
        return (fit[0] - cycle_s) * self.span, 3.0 * fit[1] * self.span

    def drift_reason(self, cycle_s: float, tolerance_s: float) -> str | None:
        """Why the radar's clock fails a check that assumed ``cycle_s``; None when it does not.

        It fails where its last cycle lies more than ``tolerance_s`` (beyond 3 sigma of the
        fit) from where ``cycle_s`` puts it: the check judged those cycles at the wrong times.
        """
        drift = self.drift_s(cycle_s)
        fit = self.cycle_s()
        if drift is None or fit is None or abs(drift[0]) - drift[1] <= tolerance_s:
            return None
        # Digits enough for the ppm that fail a long run (1 ppm: 3.6 ms over an hour).
        return (f"radar_clock: the radar's cycles reached the bus every {fit[0] * 1e3:.6f} ms, "
                f"its profile says {cycle_s * 1e3:.6f} ms ({(fit[0] / cycle_s - 1) * 1e6:+.1f}"
                f" ppm): by its last cycle it measured {abs(drift[0]) * 1e3:.1f} ms (+-"
                f"{drift[1] * 1e3:.1f}) {'later' if drift[0] > 0 else 'earlier'} than the "
                f"check took it to, more than {tolerance_s * 1e3:.3g} ms; set clock.cycle_s: "
                f"{fit[0]:.10g} in the radar profile")


# A radar's crystal keeps within about 100 ppm of its nominal frequency over temperature and
# age. A cycle further than this from the profile's is not a crystal: the profile describes
# another radar or another mode (a run fails with `radar_clock: ...`).
CLOCK_TOLERANCE_PPM = 1000.0
# A drift smaller than this over the cycles seen is rounding, not a crystal (s).
DRIFT_FLOOR_S = 1e-5
# Spread of bus times about a radar's line that its profile's jitter need not explain (s): the
# stamping, a thread's wake-up.
STAMP_NOISE_S = 1e-3
# How far a latency that changed on the way tilts the line through the bus times over the
# cycles seen, for the scatter it leaves about it: a step in the middle (the most a change
# of height h can tilt: 1.5 h) scatters the cycles by h / 4.
LATENCY_TILT = 6.0
# Cycles a free radar's phase is learnt from before it decides which is the scene's first.
START_CYCLES = 8


class ClockTrack:
    """When a radar measures, as a run learns it from the times its cycles reached the bus.

    It starts as the profile's clock and follows the radar's as its cycles arrive
    (`add`; constant memory):

    - **Cycle.** A crystal is not its profile: 50 ppm is 90 ms after half an hour of 50 ms
      cycles, nearly two frames. Once the bus tells a cycle off the profile's beyond three
      standard errors (`CycleTimeFit`), that cycle is taken. A radar on its profile's cycle
      keeps it exactly.
    - **Phase.** A radar that runs free (``counter_start: auto``: switched on before the
      scene, not started by it) measures at any point of the scene's frames. Where the scene's
      start is known on the bus's clock (``origin_s``: a paced stream, or the simulated radar
      in process), cycle ``n`` is measured at its bus time less the profile's latency less
      ``origin_s``, on the fitted line. Otherwise the profile's ``start_offset_s`` holds.

    ``time_of`` and ``first_at`` answer as `RadarClock`'s do, by the current estimate.
    """

    def __init__(self, profile: RadarClock, origin_s: float | None = None,
                 free: bool = False) -> None:
        self.profile = profile
        self.origin_s = origin_s  # may be set later: a stream knows it once it has started
        self.free = free
        self.fit = CycleTimeFit()

    @property
    def phase_from_bus(self) -> bool:
        """Whether the phase comes from the bus (a radar running free, the origin known)."""
        return self.free and self.origin_s is not None

    def add(self, n: IntArray, bus_t_s: FloatArray) -> None:
        """Take cycles ``n`` and when they reached the bus (NaN: not known, left out)."""
        self.fit.add(n, bus_t_s)

    @property
    def cycle_from_bus(self) -> bool:
        """Whether the bus told a cycle off the profile's.

        Beyond three standard errors, and by more than `DRIFT_FLOOR_S` over the cycles seen
        (timestamps rounded to a microsecond, or epoch times in a float, are not a drift);
        and only where the cycles keep to the line as the profile's jitter lets them (1.5
        times its spread, at least `STAMP_NOISE_S`): a latency that changed on the way
        (messages held up by a loaded bus or machine from some cycle on) tilts the line
        without the radar's clock running off, and is not followed. The standard errors
        take the scatter for independent from cycle to cycle, as the profile's jitter is;
        what the cycles scatter beyond it (the host's stamping, a loaded machine's delays)
        need not be, and a change of it tilts the line by up to `LATENCY_TILT` times that
        excess over the cycles seen: a drift no larger is not told from it (bus times that
        scatter as the profile's jitter lets them lose nothing to this).
        """
        fit = self.fit.cycle_s()
        scatter = self.fit.scatter_s()
        if fit is None or scatter is None:
            return False
        jitter = self.profile.jitter_s / np.sqrt(3.0)
        spread = max(jitter, STAMP_NOISE_S)
        # The jitter's own share, up to 3 standard deviations of the variance of k uniform
        # draws (sigma^2 sqrt(0.8 / k): a uniform's fourth moment is 1.8 sigma^4).
        jitter_var = jitter * jitter * (1.0 + 3.0 * np.sqrt(0.8 / self.fit.count))
        excess = np.sqrt(max(scatter * scatter - jitter_var, 0.0))
        off = abs(fit[0] - self.profile.cycle_s)
        return bool(off > 3.0 * fit[1]
                    and off * self.fit.span > max(DRIFT_FLOOR_S, LATENCY_TILT * excess)
                    and scatter <= 1.5 * spread)

    @property
    def cycle_s(self) -> float:
        """The radar's cycle: the bus's where it tells one off the profile's, else the profile's."""
        fit = self.fit.cycle_s()
        return fit[0] if fit is not None and self.cycle_from_bus else self.profile.cycle_s

    @property
    def start_offset_s(self) -> float:
        """Scene time of cycle 0 (negative where it was measured before the scene began)."""
        zero = self.fit.zero_s(self.cycle_s) if self.phase_from_bus else None
        if zero is None:
            return self.profile.start_offset_s
        assert self.origin_s is not None
        return zero - self.profile.latency_s - self.origin_s

    def time_of(self, n: IntArray) -> FloatArray:
        """Measurement time (scene time) of cycles ``n``."""
        return self.start_offset_s + np.asarray(n, dtype=np.float64) * self.cycle_s

    def first_at(self, t_s: float) -> int:
        """Return the first cycle (>= 0) measured at or after scene time ``t_s``."""
        return max(0, int(np.ceil((t_s - self.start_offset_s) / self.cycle_s - TIME_EPS_S)))

    @property
    def start_tolerance_s(self) -> float:
        """How far before the scene's start a cycle may lie and count as its first.

        Three standard errors of the phase from the bus (the radar may have measured at the
        start itself), from the cycles' scatter and no less than the profile's jitter gives;
        0 where the phase is the profile's.
        """
        if not self.phase_from_bus or self.fit.count < 2:
            return 0.0
        return 3.0 * max(self.fit.zero_error_s(self.cycle_s),
                         self.profile.jitter_s / np.sqrt(3.0 * self.fit.count))

    def edge_tolerance_s(self, t_s: float) -> float:
        """How far before scene time ``t_s`` a cycle may lie and have measured at it itself.

        `start_tolerance_s`, and where the cycle comes from the bus three standard errors of
        it times the cycles from cycle 0 to ``t_s``: the scene's last cycle may be the one
        after it (measured at the end itself, on a radar in step with the frames).
        """
        tolerance = self.start_tolerance_s
        fit = self.fit.cycle_s()
        if fit is not None and self.cycle_from_bus:
            tolerance += 3.0 * fit[1] * abs(t_s - self.start_offset_s) / self.cycle_s
        return tolerance

    def start_known(self, t_s: float) -> bool:
        """Whether the clock tells which is the first cycle at or after scene time ``t_s``.

        It does where its phase is the profile's. From the bus, once `START_CYCLES` cycles
        are in and the cycle nearest ``t_s`` lies further from it than `start_tolerance_s`
        (more cycles will not move it across); a radar that measures at ``t_s`` itself never
        tells, and the first cycle is then the one within the tolerance before it.
        """
        if not self.phase_from_bus:
            return True
        if self.fit.count < START_CYCLES:
            return False
        nearest = self.time_of(np.array([self.cycle_at(t_s)]))[0]
        return bool(abs(nearest - t_s) > self.start_tolerance_s)

    def cycle_at(self, measured_s: float) -> int:
        """Return the cycle number measured nearest scene time ``measured_s``."""
        return int(np.round((measured_s - self.start_offset_s) / self.cycle_s))

    def off_profile_reason(self, tolerance_s: float) -> str | None:
        """Why the radar's clock fails the run (its cycle too far from the profile's), or None.

        Beyond `CLOCK_TOLERANCE_PPM` (and three standard errors), and by more than
        ``tolerance_s`` over the cycles seen: on a short run a latency that changed on the way
        tilts the line as much.
        """
        fit = self.fit.cycle_s()
        if fit is None or not self.cycle_from_bus:
            return None
        ppm = (fit[0] / self.profile.cycle_s - 1.0) * 1e6
        if (abs(ppm) - 3e6 * fit[1] / self.profile.cycle_s <= CLOCK_TOLERANCE_PPM
                or abs(fit[0] - self.profile.cycle_s) * self.fit.span <= tolerance_s):
            return None
        return (f"radar_clock: the radar's cycles reached the bus every {fit[0] * 1e3:.6f} ms, "
                f"its profile says {self.profile.cycle_s * 1e3:.6f} ms ({ppm:+.1f} ppm), more "
                f"than a crystal's {CLOCK_TOLERANCE_PPM:.0f} ppm: the profile is not this "
                f"radar's clock (another radar or mode?); the check followed the bus's cycle; "
                f"set clock.cycle_s: {fit[0]:.10g} in the radar profile")

    def to_dict(self, first: int = 0) -> dict[str, float | str]:
        """Return the clock the check ended with, for the report's ``radar_clock``.

        ``start_offset_s`` is the scene time of cycle ``first``: the scene's first.
        """
        return {"cycle_s": self.cycle_s, "cycle_from": "bus" if self.cycle_from_bus
                else "profile", "start_offset_s": float(self.time_of(np.array([first]))[0]),
                "start_from": "bus" if self.phase_from_bus and self.fit.count else "profile"}


__all__ = ["CLOCK_TOLERANCE_PPM", "TIME_EPS_S", "ClockTrack", "CycleTimeFit", "RadarClock"]
