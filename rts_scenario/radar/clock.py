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
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

# Times this close count as equal (a cycle measured exactly at a frame's time sees that frame).
TIME_EPS_S = 1e-9


# The shortest radar cycle a profile or a log's sidecar may state (automotive radars measure
# every 10 to 100 ms): shorter ones are typos, and would count millions of cycles into a scene.
# A cycle fitted to a log's stamps is the log's to answer for: any positive one is taken.
MIN_CYCLE_S = 1e-3
# The longest latency a radar's clock may have (s): radars report within a second; beyond
# this, sums with bus times lose their milliseconds.
MAX_LATENCY_S = 600.0


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
        if self.latency_s > MAX_LATENCY_S:
            raise ValueError(f"clock.latency_s: must be <= {MAX_LATENCY_S:g}, got "
                             f"{self.latency_s:g}")
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


# A radar's crystal keeps within about 100 ppm of its nominal frequency over temperature and
# age. A cycle further than this from the profile's is not a crystal: the profile describes
# another radar or another mode (a run fails with `radar_clock: ...`).
CLOCK_TOLERANCE_PPM = 1000.0
# A drift smaller than this over the cycles seen is rounding, not a crystal (s).
DRIFT_FLOOR_S = 1e-5
# Spread of bus times about a radar's line that its profile's jitter need not explain (s): the
# stamping, a thread's wake-up.
STAMP_NOISE_S = 1e-3
# Cycles a free radar's phase is learnt from before it decides which is the scene's first.
START_CYCLES = 8


# Summaries a clock keeps of its cycles' bus times, however long the run (`LineSegments`).
SEGMENTS = 32
# Chance that cycles on one straight line (a crystal off its profile, latency jitter of any
# size) read as bent (`LineSegments.test`): the two-sided tail beyond three sigma, the bar the
# clock's cycle is told off the profile's by.
BENT_P = 0.0027


def _moments(x: FloatArray, y: FloatArray) -> FloatArray:
    """Count, means and centred sums of squares and products of points (k, mx, my, xx, xy, yy)."""
    mx, my = float(x.mean()), float(y.mean())
    dx, dy = x - mx, y - my
    return np.array([x.size, mx, my, dx @ dx, dx @ dy, dy @ dy], dtype=np.float64)


def _spread_about(s: FloatArray, slope: float) -> FloatArray:
    """Return each segment's sum of squares about a line of ``slope`` through its means.

    Rows of `_moments`; not clamped: rounding may leave a hair below 0 where the points lie on it.
    """
    return s[..., 5] - 2.0 * slope * s[..., 4] + slope * slope * s[..., 3]


def _combine(a: FloatArray, b: FloatArray) -> FloatArray:
    """Moments of two groups of points together (rows of `_moments`, or arrays of them)."""
    k = a[..., 0] + b[..., 0]
    w = np.divide(b[..., 0], k, out=np.zeros_like(k), where=k > 0)
    dx, dy = b[..., 1] - a[..., 1], b[..., 2] - a[..., 2]
    ab = a[..., 0] * w  # ka kb / k
    return np.stack([k, a[..., 1] + dx * w, a[..., 2] + dy * w,
                     a[..., 3] + b[..., 3] + ab * dx * dx, a[..., 4] + b[..., 4] + ab * dx * dy,
                     a[..., 5] + b[..., 5] + ab * dy * dy], axis=-1)


@dataclass(frozen=True)
class Bend:
    """How a radar's cycles lie about the straight line through their bus times.

    Attributes
    ----------
    slope_s : float
        The line's slope (the cycle on the bus's clock).
    f : float
        Spread of the segments' mean residuals about the line over the spread of the cycles
        within the segments (each per its degrees of freedom): near 1 where they keep to it.
    dof : tuple of float
        ``f``'s degrees of freedom: between the segments and within them.
    departure_s : float
        The largest distance of a segment's mean from the line.
    scatter_s : float
        The cycles' scatter within their segments (the measured one: latency jitter, stamping).
    segments : numpy.ndarray
        The segments' moments (rows of count, mean number, mean bus time, centred sums).
    """

    slope_s: float
    f: float
    dof: tuple[float, float]
    departure_s: float
    scatter_s: float
    segments: FloatArray

    @cached_property
    def p(self) -> float:
        """Chance of an ``f`` this large from cycles on one line (Fisher's F, `dof`)."""
        if self.f == np.inf or self.f == 0.0:  # no scatter within the segments
            return 0.0 if self.f else 1.0
        from scipy.special import fdtrc  # scipy when needed: see `check._assign`

        return float(fdtrc(*self.dof, self.f))

    @property
    def bent(self) -> bool:
        """Whether the cycles depart from one line: by more than rounding, and beyond `BENT_P`.

        The departure is asked first: cycles within rounding of a line need no F distribution.
        """
        return self.departure_s > DRIFT_FLOOR_S and self.p < BENT_P


class LineSegments:
    """Moments of consecutive runs of a radar's cycles (in the order they arrived).

    At most ``cap`` segments of ``length`` cycles each, and one filling: when ``cap`` are full,
    neighbours merge in pairs and ``length`` doubles. Memory is constant; the segments depend on
    the order of the cycles, not on how they were handed over (moments merged exactly, the
    sums centred on each segment's means, which keeps them precise over long runs).
    """

    def __init__(self, cap: int = SEGMENTS) -> None:
        if cap < 4 or cap % 2:
            raise ValueError(f"segments: an even number >= 4, got {cap}")
        self.cap = cap
        self.length = 1
        self._full = np.zeros((0, 6))
        self._open = np.zeros(6)

    def add(self, x: FloatArray, y: FloatArray) -> None:
        """Take points ``(x, y)`` in order."""
        i = 0
        while i < x.size:
            room = self.length - int(self._open[0])
            part = slice(i, i + room)
            self._open = _combine(self._open, _moments(x[part], y[part]))
            i += room
            if int(self._open[0]) == self.length:
                self._full = np.vstack([self._full, self._open])
                self._open = np.zeros(6)
                if len(self._full) == self.cap:
                    self._full = _combine(self._full[0::2], self._full[1::2])
                    self.length *= 2

    @property
    def segments(self) -> FloatArray:
        """Moments of the segments with cycles (one row each, in order)."""
        return self._full if self._open[0] == 0 else np.vstack([self._full, self._open])

    def test(self) -> Bend | None:
        """Whether the points keep to one straight line (lack of fit); None where it cannot tell.

        The line through all points leaves each segment a mean residual; on one line (whatever
        the points' scatter) these scatter as the points within the segments about it do,
        divided by the root of the segment's count. Their ratio ``f`` (each sum of squares by its
        degrees of freedom: ``K - 1 - rho`` between K segments, ``N - K - 1 + rho`` within,
        ``rho`` the share of the numbers' spread that lies between the segments) follows
        Fisher's F distribution there; a step or a bend in the points adds to the segments'
        residuals alone. Where the segments are too short to measure the points' scatter within
        them (fewer degrees of freedom within than between: a short run's first cycles, one a
        segment), neighbours are taken in pairs until they are not: the test does not depend on
        what scatter anyone expected. None with fewer than four segments left.
        """
        s = self.segments
        if len(s) < 4:
            return None
        total = s[0]
        for row in s[1:]:
            total = _combine(total, row)
        k, mx, my, sxx, sxy, _ = total
        if sxx <= 0.0:
            return None
        slope = sxy / sxx
        while True:
            n_seg = len(s)
            rho = float(s[:, 0] @ (s[:, 1] - mx) ** 2) / sxx
            df_between, df_within = n_seg - 1.0 - rho, k - n_seg - 1.0 + rho
            if df_within >= df_between and df_between > 0.0:
                break
            if n_seg < 8:
                return None
            even = n_seg - n_seg % 2
            s = np.vstack([_combine(s[0:even:2], s[1:even:2]), s[even:]])
        residual = (s[:, 2] - my) - slope * (s[:, 1] - mx)
        between = float(s[:, 0] @ (residual * residual))
        within = float(np.sum(_spread_about(s, slope)))
        scatter = np.sqrt(max(within, 0.0) / df_within)
        if scatter > 0.0:
            f = (between / df_between) / scatter ** 2
        else:
            f = np.inf if between > 0.0 else 0.0
        return Bend(float(slope), float(f), (float(df_between), float(df_within)),
                    float(np.abs(residual).max()), float(scatter), s.copy())


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
        self.segments = LineSegments()
        self._bend: tuple[int, Bend | None] | None = None

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
        self.segments.add(x, y)

    def bend(self) -> Bend | None:
        """Whether the cycles keep to one line (`LineSegments.test`); None where it cannot tell."""
        if self._bend is None or self._bend[0] != self.count:
            self._bend = (self.count, self.segments.test())
        return self._bend[1]

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
        intercept for that slope). Where they bend away from one line (`bend`: a latency that
        changed on the way), the mean of the two sides of a step is the phase of neither: the
        radar's own level instead, the lowest (`_level`). None before the first cycle.
        """
        if self._origin is None:
            return None
        level = self._level(cycle_s)
        if level is not None:
            return self._origin[1] + level[0] - cycle_s * self._origin[0]
        sx, sy = self._sums[0] / self.count, self._sums[1] / self.count
        return self._origin[1] + sy - cycle_s * (self._origin[0] + sx)

    def zero_error_s(self, cycle_s: float) -> float:
        """Return the standard error of `zero_s` for that slope (from the scatter about it)."""
        level = self._level(cycle_s)
        if level is not None:
            return level[1]
        k = self.count
        if k < 2:
            return np.inf
        sx, sy, sxx, sxy, syy = self._sums / k
        mean = sy - cycle_s * sx
        var = syy - 2.0 * cycle_s * sxy + cycle_s * cycle_s * sxx - mean * mean
        return float(np.sqrt(max(var, 0.0) / (k - 1)))

    def _level(self, cycle_s: float) -> tuple[float, float] | None:
        """Return the radar's own level of offsets where they bend, and its error; None unbent.

        Offsets (mean bus time less ``cycle_s`` times the mean number, about the origin) of the
        segments that keep to one level: a segment across a step scatters within by far more
        than the others (more than nine times their median variance about that slope) and is
        left out. A message held up only adds to its latency: the lowest level is the radar's
        (a latency that rose later, or a start-up's messages held up, lie above it), whether
        or not most cycles keep it. The level is the segments within four standard errors of
        the lowest of the full-length ones, their offsets' mean weighted by their cycles (its
        error from the scatter within them).
        """
        bend = self.bend()
        if bend is None or not bend.bent:
            return None
        s = bend.segments
        offset = s[:, 2] - cycle_s * s[:, 1]
        # Centred sums about each segment's own means: >= 0 but for rounding (exact stamps).
        spread = np.maximum(_spread_about(s, cycle_s), 0.0)
        within = spread / np.maximum(s[:, 0] - 1.0, 1.0)
        several = s[:, 0] > 1.0  # one cycle alone cannot tell
        level = ~several
        if several.any():
            level |= within <= 9.0 * np.median(within[several])
        count, offset, spread = s[level, 0], offset[level], spread[level]
        full = np.flatnonzero(count >= np.median(count))
        lowest = full[int(np.argmin(offset[full]))]
        dof = float(np.sum(count - 1.0))
        scatter = float(np.sqrt(np.sum(spread) / dof)) if dof > 0 else bend.scatter_s
        same = np.abs(offset - offset[lowest]) <= 4.0 * scatter * np.sqrt(
            1.0 / count + 1.0 / count[lowest])
        same[lowest] = True
        cycles = float(count[same].sum())
        return (float(np.sum(count[same] * offset[same]) / cycles),
                scatter / float(np.sqrt(cycles)))

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


def late_start_s(profile: RadarClock, zero_s: float) -> float | None:
    """How much later than ``profile`` says cycle 0 was measured, at scene time ``zero_s``.

    None unless a cycle or more later, beyond the profile's jitter and the stamps' noise
    (`ClockTrack.late_start_s`).
    """
    late = float(zero_s - profile.start_offset_s)
    spread = max(profile.jitter_s / np.sqrt(3.0), STAMP_NOISE_S)
    return late if late > profile.cycle_s + 3.0 * spread else None


def late_start_reason(profile: RadarClock, zero_s: float) -> str | None:
    """Why a radar whose cycle 0 was measured at scene time ``zero_s`` fails the run, or None.

    A radar that started its count after the scene began (`late_start_s`) measured nothing of
    the scene before: those frames were not seen, whatever the cycles after them show.
    """
    late = late_start_s(profile, zero_s)
    if late is None:
        return None
    return (f"radar_clock: the radar measured its cycle 0 at scene time {zero_s:.3f} s, "
            f"{late:.3f} s later than its profile says ({profile.start_offset_s:.3f} s): it "
            f"started after the scene began, and the scene's frames before that were not "
            f"measured (about {int(late / profile.cycle_s)} cycles); start the radar before "
            f"the scene, or set clock.start_offset_s in its profile where it starts late on "
            f"purpose")


def latency_not_late_start_reason(profile: RadarClock, late_s: float, lag_s: float,
                                  lag_error_s: float, frame_s: float) -> str | None:
    """Why a radar that seems to have started ``late_s`` late fails, where its latency may.

    Its cycles reached the bus ``late_s`` later than the profile's latency and start say, as
    a radar started late would; but a radar started late measured at the times that gives,
    and its detections fit them. Where they fit the scene ``lag_s`` (``+- lag_error_s``)
    earlier, by more than half a frame beyond three standard errors (`Checker.lag_reason`'s
    bound), it measured earlier than a late start puts it: a latency longer than its profile's
    explains both. None otherwise.
    """
    if not lag_s - 3.0 * lag_error_s > 0.5 * frame_s:
        return None
    return (f"radar_clock: the radar's cycles reached the bus {late_s:.3f} s later than its "
            f"profile's latency and start say, but its detections fit the scene {lag_s:.3f} s "
            f"(+-{3.0 * lag_error_s:.3f} s) earlier than the times that gives, more than half "
            f"a frame: it measured earlier than a radar started late would have, so its "
            f"latency is longer than its profile's ({profile.latency_s:.3f} s) rather than "
            f"its start late; set clock.latency_s in its profile to the radar's (the cycles "
            f"before the one taken as its first were not counted)")


class ClockTrack:
    """When a radar measures, as a run learns it from the times its cycles reached the bus.

    It starts as the profile's clock and follows the radar's as its cycles arrive
    (`add`; constant memory):

    - **Cycle.** A crystal is not its profile: 50 ppm is 90 ms after half an hour of 50 ms
      cycles, nearly two frames. Once the bus tells a cycle off the profile's beyond three
      standard errors (`CycleTimeFit`), the cycles keeping to that line (`cycle_from_bus`),
      that cycle is taken. A radar on its profile's cycle keeps it exactly. Cycles that bend
      away from one line (a latency that changed) keep the profile's, and fail the run where a
      crystal could have bent them so far (`latency_change_reason`).
    - **Phase.** A radar that runs free (``counter_start: auto``: switched on before the
      scene, not started by it) measures at any point of the scene's frames. Where the scene's
      start is known on the bus's clock (``origin_s``: a paced stream, or the simulated radar
      in process), cycle ``n`` is measured at its bus time less the profile's latency less
      ``origin_s``, on the fitted line (where the cycles bend, their lowest level: held-up
      messages only add latency, `CycleTimeFit.zero_s`). Otherwise the profile's
      ``start_offset_s`` holds.

    A bus stamped by an interface's own clock may run off the host's: ``scale`` is the host's
    seconds per second of the bus's clock (1: the same clock), and scene times are the bus's
    times less ``origin_s`` times it.

    ``time_of`` and ``first_at`` answer as `RadarClock`'s do, by the current estimate.
    """

    def __init__(self, profile: RadarClock, origin_s: float | None = None,
                 free: bool = False) -> None:
        self.profile = profile
        self.origin_s = origin_s  # may be set later: a stream knows it once it has started
        self.free = free
        self.scale = 1.0
        self.fit = CycleTimeFit()

    def _fit_s(self) -> tuple[float, float] | None:
        """Return the fitted cycle and its standard error on the host's clock (s)."""
        fit = self.fit.cycle_s()
        return None if fit is None else (fit[0] * self.scale, fit[1] * self.scale)

    @property
    def phase_from_bus(self) -> bool:
        """Whether the phase comes from the bus (the scene's start known on its clock).

        For a radar running free, and for one whose count began later than its profile says
        (`late_start_s`).
        """
        return self.origin_s is not None and (self.free or self.late_start_s() is not None)

    def _bus_zero_s(self) -> float | None:
        """Scene time of cycle 0 by the bus times (less the profile's latency); None unknown."""
        zero = self.fit.zero_s(self.cycle_s / self.scale) if self.origin_s is not None else None
        if zero is None:
            return None
        assert self.origin_s is not None
        return (zero - self.origin_s) * self.scale - self.profile.latency_s

    def late_start_s(self) -> float | None:
        """How much later than its profile says a radar with a known count measured cycle 0.

        A radar started after the scene began (powered or triggered late) counts from its
        profile's ``counter_start`` all the same: its cycle 0 lies a cycle or more (beyond its
        jitter and the stamps' noise) after the profile's ``start_offset_s``, and the cycles
        the profile puts before it were never measured, not lost. Less than a cycle is a
        latency or phase not the profile's, which the detections' lag tells. None where the
        radar runs free, the scene's start is not known on the bus's clock, or it is not late.
        """
        if self.free or self.origin_s is None or not self.fit.count:
            return None
        zero = self._bus_zero_s()
        return None if zero is None else late_start_s(self.profile, zero)

    def late_start_reason(self) -> str | None:
        """Why a radar that started its count late fails the run (`late_start_reason`)."""
        late = self.late_start_s()
        return None if late is None else late_start_reason(
            self.profile, self.profile.start_offset_s + late)

    def add(self, n: IntArray, bus_t_s: FloatArray) -> None:
        """Take cycles ``n`` and when they reached the bus (NaN: not known, left out)."""
        self.fit.add(n, bus_t_s)

    @property
    def cycle_from_bus(self) -> bool:
        """Whether the bus told a cycle off the profile's.

        Beyond three standard errors, and by more than `DRIFT_FLOOR_S` over the cycles seen
        (timestamps rounded to a microsecond, or epoch times in a float, are not a drift);
        and only where the cycles keep to that straight line (`CycleTimeFit.bend`): a crystal
        off its profile leaves them on one, however large their latency's jitter, while a
        latency that changed on the way (messages held up by a loaded bus or machine from some
        cycle on) bends them, tilting the line without the radar's clock running off, and is
        not followed (`latency_change_s`). Where the cycles are too few to tell (fewer than
        eight: `LineSegments.test` has no four segments of two), they must keep to the line as
        the profile's jitter lets them (1.5 times its spread, at least `STAMP_NOISE_S`).
        """
        fit = self._fit_s()
        if fit is None:
            return False
        off = abs(fit[0] - self.profile.cycle_s)
        if not (off > 3.0 * fit[1] and off * self.fit.span > DRIFT_FLOOR_S):
            return False
        bend = self.fit.bend()
        if bend is not None:
            return not bend.bent
        scatter = self.fit.scatter_s()
        spread = max(self.profile.jitter_s / np.sqrt(3.0), STAMP_NOISE_S)
        return scatter is not None and scatter <= 1.5 * spread

    def latency_change_s(self) -> tuple[float, float, float] | None:
        """How far the cycles strayed from the profile's cycle where they bent (s, three values).

        Where the cycles' bus times do not keep to one straight line (`CycleTimeFit.bend`),
        the check keeps the profile's cycle. The segments' mean bus times, less the profile's
        cycle times their numbers, then lie the first value apart (highest to lowest): the
        latency changed by as much, or the radar's clock did not run steady. A clock moves
        against the profile's no faster than `CLOCK_TOLERANCE_PPM` (beyond, the run fails as
        another radar's): the second is the spread of the path that follows the segments'
        means from the first as far as such a clock can between each two (a start-up's
        messages held up by tens of milliseconds, or a step, are latency; a drift or a bend a
        crystal can draw is taken whole). The third is how far apart the cycles' scatter
        within the segments could put two of K segments' means, at the chance of 3 sigma for
        all K at once. None where they keep to one line, or where the bus times do not follow
        the cycles' numbers (`CycleTimeFit.cycle_s`).
        """
        bend = self.fit.bend()
        if bend is None or not bend.bent or self.fit.cycle_s() is None:
            return None
        s = bend.segments
        offset = s[:, 2] - self.profile.cycle_s / self.scale * s[:, 1]
        rate = CLOCK_TOLERANCE_PPM * 1e-6 * self.profile.cycle_s * np.diff(s[:, 1])
        path = offset[:1] + np.concatenate(
            [[0.0], np.cumsum(np.clip(np.diff(offset), -rate, rate))])
        # Each of K segments' means within z of its standard error of where it would lie
        # without the scatter, all at once with the chance of 3 sigma (Bonferroni).
        from statistics import NormalDist  # when needed: it imports fractions and random

        z = NormalDist().inv_cdf(1.0 - BENT_P / (2.0 * len(s)))
        error = bend.scatter_s / np.sqrt(s[:, 0])
        margin = 0.0
        for line in (offset, path):
            hi, lo = int(np.argmax(line)), int(np.argmin(line))
            margin = max(margin, z * float(error[hi] + error[lo]))
        return float(offset.max() - offset.min()), float(path.max() - path.min()), margin

    def latency_change_reason(self, tolerance_s: float) -> str | None:
        """Why the cycles' bent bus times fail the run, or None.

        Where the part of their stray from the profile's cycle a crystal could have drawn
        exceeds ``tolerance_s`` beyond what the scatter could (`latency_change_s`): the bus
        cannot tell a latency that changed from a clock that did not run steady, and in the
        latter the cycles were judged against the wrong frames.
        """
        change = self.latency_change_s()
        if change is None or change[1] - change[2] <= tolerance_s:
            return None
        return (f"radar_clock: the radar's cycles reached the bus up to {change[0] * 1e3:.1f} "
                f"ms apart from its profile's cycle of {self.profile.cycle_s * 1e3:.6f} ms, not "
                f"along one straight line, {change[1] * 1e3:.1f} ms (+-{change[2] * 1e3:.1f}) "
                f"of it as a clock within {CLOCK_TOLERANCE_PPM:.0f} ppm could have: their "
                f"latency changed during the run (messages held up), or the radar's clock did "
                f"not run steady; the check kept the profile's cycle, and by more than "
                f"{tolerance_s * 1e3:.3g} ms it may have judged cycles against the wrong frames")

    @property
    def cycle_s(self) -> float:
        """The radar's cycle: the bus's where it tells one off the profile's, else the profile's."""
        fit = self._fit_s()
        return fit[0] if fit is not None and self.cycle_from_bus else self.profile.cycle_s

    @property
    def start_offset_s(self) -> float:
        """Scene time of cycle 0 (negative where it was measured before the scene began)."""
        zero = self._bus_zero_s() if self.phase_from_bus else None
        return self.profile.start_offset_s if zero is None else zero

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
        return 3.0 * max(self.fit.zero_error_s(self.cycle_s / self.scale) * self.scale,
                         self.profile.jitter_s / np.sqrt(3.0 * self.fit.count))

    def edge_tolerance_s(self, t_s: float) -> float:
        """How far before scene time ``t_s`` a cycle may lie and have measured at it itself.

        `start_tolerance_s`, and where the cycle comes from the bus three standard errors of
        it times the cycles from cycle 0 to ``t_s``: the scene's last cycle may be the one
        after it (measured at the end itself, on a radar in step with the frames).
        """
        tolerance = self.start_tolerance_s
        fit = self._fit_s()
        if fit is not None and self.cycle_from_bus:
            tolerance += 3.0 * fit[1] * abs(t_s - self.start_offset_s) / self.cycle_s
        return tolerance

    def start_known(self, t_s: float) -> bool:
        """Whether the clock tells which is the first cycle at or after scene time ``t_s``.

        It does where its phase is the profile's, once a radar whose count is known sent a
        cycle (it may have started late: `late_start_s`). From the bus, once `START_CYCLES` cycles
        are in and the cycle nearest ``t_s`` lies further from it than `start_tolerance_s`
        (more cycles will not move it across); a radar that measures at ``t_s`` itself never
        tells, and the first cycle is then the one within the tolerance before it.
        """
        if not self.free and self.origin_s is not None and not self.fit.count:
            return False  # a radar whose count is known may yet have started late
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
        ``tolerance_s`` over the cycles seen beyond three standard errors of that drift (as
        `CycleTimeFit.drift_reason`): on a short run (a radar reporting for a second or two,
        its RTS up late) a latency that changed on the way, a few milliseconds while it had
        targets to process, tilts the line as much.
        """
        fit = self._fit_s()
        if fit is None or not self.cycle_from_bus:
            return None
        ppm = (fit[0] / self.profile.cycle_s - 1.0) * 1e6
        if (abs(ppm) - 3e6 * fit[1] / self.profile.cycle_s <= CLOCK_TOLERANCE_PPM
                or (abs(fit[0] - self.profile.cycle_s) - 3.0 * fit[1]) * self.fit.span
                <= tolerance_s):
            return None
        return (f"radar_clock: the radar's cycles reached the bus every {fit[0] * 1e3:.6f} ms, "
                f"its profile says {self.profile.cycle_s * 1e3:.6f} ms ({ppm:+.1f} ppm), more "
                f"than a crystal's {CLOCK_TOLERANCE_PPM:.0f} ppm: the profile is not this "
                f"radar's clock (another radar or mode?); the check followed the bus's cycle; "
                f"set clock.cycle_s: {fit[0]:.10g} in the radar profile")

    def to_dict(self, first: int = 0) -> dict[str, float | str]:
        """Return the clock the check ended with, for the report's ``radar_clock``.

        ``start_offset_s`` is the scene time of cycle ``first``: the scene's first;
        ``latency_change_s`` where the cycles' bus times bent (`latency_change_s`).
        """
        clock: dict[str, float | str] = {
            "cycle_s": self.cycle_s, "cycle_from": "bus" if self.cycle_from_bus else "profile",
            "start_offset_s": float(self.time_of(np.array([first]))[0]),
            "start_from": "bus" if self.phase_from_bus and self.fit.count else "profile"}
        change = self.latency_change_s()
        if change is not None:
            clock["latency_change_s"] = change[0]
        late = self.late_start_s()
        if late is not None:
            clock["late_start_s"] = float(late)
        return clock


__all__ = ["CLOCK_TOLERANCE_PPM", "MIN_CYCLE_S", "SEGMENTS", "TIME_EPS_S", "Bend", "ClockTrack",
           "CycleTimeFit", "LineSegments", "RadarClock", "late_start_reason", "late_start_s",
           "latency_not_late_start_reason"]
