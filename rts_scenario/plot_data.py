"""What a run's plots draw, gathered as the run goes in memory bounded whatever its length.

`PlotData` takes the scene's frames and the judged radar cycles batch by batch; each series is
an `Envelope`: of each bucket of consecutive samples, two (a bucket's extremes, or its first
and last sample). `rts_scenario.plots` draws them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .arrays import FloatArray

if TYPE_CHECKING:
    from collections.abc import Mapping

    from numpy.typing import ArrayLike, NDArray

    from .kinematics import Tracks
    from .schedule import Schedule

# The errors gathered, by tolerance key (`PlotData.errors`).
ERROR_KEYS = ("range_m", "radial_velocity_mps", "az_deg", "el_deg")

# Buckets of samples a plotted series keeps per target, two samples each: a few thousand points
# per target and series, whatever the scene's length.
PLOT_BUCKETS = 1024

def _extremes(t_s: FloatArray, values: FloatArray, starts: NDArray[np.intp], by_time: bool
              ) -> tuple[FloatArray, FloatArray]:
    """Per segment of rows and per column, the samples of least and of greatest key.

    ``t_s``, ``values``: shape (N, C), NaN where there is no sample (in both); ``starts``: the
    first row of each segment (S,), ascending from 0, none empty. The key is ``t_s`` (the
    segment's first and last sample) or, without ``by_time``, ``values`` (its extremes; of
    equal ones, the first). Returns ``t_s`` and ``values`` of shape (S, 2, C), the least key
    first, NaN where a segment has no sample (the second also where it has only one).
    """
    key = t_s if by_time else values
    rows = np.arange(key.shape[0], dtype=np.float64)[:, None]
    segment = np.repeat(np.arange(starts.size), np.diff(starts, append=key.shape[0]))
    least, greatest = (np.fmin.reduceat(np.where(key == best[segment], rows, np.nan), starts,
                                        axis=0)
                       for best in (np.fmin.reduceat(key, starts, axis=0),
                                    np.fmax.reduceat(key, starts, axis=0)))
    greatest[greatest == least] = np.nan
    row = np.stack([least, greatest], axis=1)
    has = ~np.isnan(row)
    at = np.where(has, row, 0.0).astype(np.intp), np.arange(key.shape[1])
    return np.where(has, t_s[at], np.nan), np.where(has, values[at], np.nan)


class Envelope:
    """A series per column in bounded memory: of each bucket of consecutive samples, two.

    Samples come in order, in batches of any length. Each bucket of `stride` samples keeps,
    per column, its samples of least and of greatest key: the value (the extremes stay drawn,
    an error out of tolerance however long the scene) or, ``by_time``, the time (the bucket's
    first and last sample: a path, events). When the samples would fill more than ``buckets``
    buckets, each two neighbours merge into one and the stride doubles: a series of any length
    holds ``2 * buckets`` samples per column at most.

    Parameters
    ----------
    columns : int
        Columns of the series (C), e.g. targets.
    by_time : bool
        Keep each bucket's first and last sample rather than its extremes.
    buckets : int
        Buckets kept, an even number.
    """

    def __init__(self, columns: int, by_time: bool = False, buckets: int = PLOT_BUCKETS) -> None:
        if buckets < 2 or buckets % 2:
            raise ValueError(f"buckets: must be an even number >= 2, got {buckets}")
        self.by_time = by_time
        self.stride = 1  # samples per bucket
        self.count = 0  # samples taken
        self._t_s = np.full((buckets, 2, columns), np.nan)
        self._values = np.full((buckets, 2, columns), np.nan)

    @property
    def nbytes(self) -> int:
        """Bytes the samples kept take, the same for a series of any length."""
        return self._t_s.nbytes + self._values.nbytes

    def add(self, t_s: ArrayLike, values: ArrayLike) -> None:
        """Take the next samples: at times ``t_s`` (N,) s, ``values`` (N, C), NaN where none."""
        t = np.asarray(t_s, dtype=np.float64)
        v = np.asarray(values, dtype=np.float64).reshape(t.size, -1)
        n = t.size
        if n == 0:
            return
        buckets = self._t_s.shape[0]
        while (self.count + n - 1) // self.stride >= buckets:
            self._merge()
        bucket = (self.count + np.arange(n)) // self.stride
        first, last = int(bucket[0]), int(bucket[-1])
        # The first bucket may hold samples of the batch before: its two join the new ones.
        t_new = np.where(np.isnan(v), np.nan, t[:, None])
        starts = np.concatenate([[0], 3 + np.flatnonzero(np.diff(bucket))]).astype(np.intp)
        picked = _extremes(np.concatenate([self._t_s[first], t_new]),
                           np.concatenate([self._values[first], v]), starts, self.by_time)
        self._t_s[first:last + 1], self._values[first:last + 1] = picked
        self.count += n

    def _merge(self) -> None:
        """Merge each two neighbouring buckets into one; double the stride."""
        buckets, _, columns = self._t_s.shape
        starts = np.arange(0, 2 * buckets, 4, dtype=np.intp)
        t, v = _extremes(self._t_s.reshape(2 * buckets, columns),
                         self._values.reshape(2 * buckets, columns), starts, self.by_time)
        half = buckets // 2
        self._t_s[:half], self._values[:half] = t, v
        self._t_s[half:] = self._values[half:] = np.nan
        self.stride *= 2

    def samples(self) -> tuple[FloatArray, FloatArray]:
        """Return the times (s) and values kept, shape (P, C) in bucket order, NaN where none."""
        used = -(-self.count // self.stride)
        columns = self._t_s.shape[2]
        # (no columns: a scene without targets)
        return (self._t_s[:used].reshape(2 * used, columns),
                self._values[:used].reshape(2 * used, columns))


class PlotData:
    """What a run's plots draw, taken as the run goes in bounded memory (`Envelope`).

    The run gives it the scene's frames as it plays them (`add_frames`: ground truth and the
    schedule played), the checker the radar's cycles as it judges them (`add_cycles`).

    Attributes
    ----------
    x_m, y_m, az_deg, el_deg : Envelope
        Each target's position (radar frame) and direction while present (by time).
    checkable_az_deg, checkable_el_deg : Envelope
        Its direction in the frames where it was checkable (by time).
    attenuation_db : Envelope
        Each channel's attenuation while it plays, column ``4 * target + channel``.
    delay_ns : Envelope
        Each target's RTS delay (the mean over its channels) while it plays.
    errors : dict of str to Envelope
        Per tolerance key (range, radial velocity, azimuth, elevation), each target's error
        per radar cycle.
    missed : Envelope
        Each target's radar cycles where it was checkable and not detected within tolerance
        (value 0, by time).
    """

    def __init__(self, n_targets: int, buckets: int = PLOT_BUCKETS) -> None:
        def series(columns: int = n_targets, by_time: bool = False) -> Envelope:
            return Envelope(columns, by_time, buckets)

        self.x_m, self.y_m, self.az_deg, self.el_deg = (series(by_time=True) for _ in range(4))
        self.checkable_az_deg, self.checkable_el_deg = series(by_time=True), series(by_time=True)
        self.attenuation_db = series(4 * n_targets)
        self.delay_ns = series()
        self.errors = {key: series() for key in ERROR_KEYS}
        self.missed = series(by_time=True)

    @property
    def nbytes(self) -> int:
        """Bytes the samples take, the same for a scene of any length."""
        return sum(e.nbytes for e in (self.x_m, self.y_m, self.az_deg, self.el_deg,
                                      self.checkable_az_deg, self.checkable_el_deg,
                                      self.attenuation_db, self.delay_ns, self.missed,
                                      *self.errors.values()))

    def add_frames(self, tracks: Tracks, schedule: Schedule,
                   judged: NDArray[np.bool_]) -> None:
        """Take a batch of the scene's frames: their ground truth and the schedule played.

        ``judged`` (F, K): each target-frame checkable (`rts_scenario.check.checkable`).
        """
        t = tracks.t_s
        present = tracks.present
        for series, value in ((self.x_m, tracks.position_m[..., 0]),
                              (self.y_m, tracks.position_m[..., 1]),
                              (self.az_deg, tracks.az_deg), (self.el_deg, tracks.el_deg)):
            series.add(t, np.where(present, value, np.nan))
        self.checkable_az_deg.add(t, np.where(judged, tracks.az_deg, np.nan))
        self.checkable_el_deg.add(t, np.where(judged, tracks.el_deg, np.nan))
        self.attenuation_db.add(t, np.where(schedule.active, schedule.attenuation_db, np.nan))
        # The mean over the channels that play (the others' delay is NaN).
        delay = np.where(schedule.active, schedule.delay_s, 0.0)
        playing = schedule.active.sum(axis=2)
        mean_ns = delay.sum(axis=2) / np.maximum(playing, 1) * 1e9
        self.delay_ns.add(t, np.where(playing > 0, mean_ns, np.nan))

    def add_cycles(self, t_s: FloatArray, checkable: NDArray[np.bool_],
                   detected: NDArray[np.bool_], errors: Mapping[str, FloatArray]) -> None:
        """Take a batch of judged radar cycles.

        ``t_s`` (N,): their measurement times; ``checkable``, ``detected`` (N, K): each
        target checkable, detected within tolerance; ``errors``: per tolerance key, the
        errors (N, K), NaN where none was measured.
        """
        for key, series in self.errors.items():
            series.add(t_s, errors[key])
        self.missed.add(t_s, np.where(checkable & ~detected, 0.0, np.nan))
