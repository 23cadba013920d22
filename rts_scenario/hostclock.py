"""The host's wall clock, watched for steps against its monotonic clock.

python-can stamps messages with the wall clock (``time.time()``) on the virtual bus and on
interfaces without stamps of their own, the host receives them on it, and a paced stream ties
the scene's start to it. That clock can step while a run plays (an NTP step, someone setting
the time, a virtual machine resuming): every later stamp and receipt jumps by the step, while
the scene's start stays where it was taken. The monotonic clock never steps, so the wall
clock less the monotonic one stays put but for the slow slew of a time daemon (at most
`SLEW_PPM`); a change beyond `STEP_TOLERANCE_S` more than that is a step (`HostClockWatch`).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

# A change of the wall clock against the monotonic one beyond this (plus `SLEW_PPM` of the
# time between two readings, plus how long a reading took) is a step, not a slew (s).
STEP_TOLERANCE_S = 1e-3
# How fast a time daemon may slew the wall clock against the monotonic one (NTP's limit).
SLEW_PPM = 500.0


def wall_s() -> float:
    """Read the host's wall clock (what python-can stamps with), through `time.time`."""
    return time.time()


def monotonic_s() -> float:
    """Read the host's monotonic clock (it never steps)."""
    return time.monotonic()


@dataclass(frozen=True)
class HostClockStep:
    """One step of the host's wall clock.

    Attributes
    ----------
    after_s, before_s : float
        Monotonic times of the readings it fell between: the last one before it and the first
        after it.
    size_s : float
        How far the wall clock jumped (positive: forward).
    level_s : float
        The sum of every step so far, this one included (`HostClockWatch.level_s`).
    """

    after_s: float
    before_s: float
    size_s: float
    level_s: float


class HostClockWatch:
    """Readings of the wall clock less the monotonic one; a change beyond a slew is a step.

    `sample` reads both clocks (thread-safe: the CAN listener's thread samples at each cycle it
    receives, the run's thread at each batch) and returns the level: the sum of the steps seen
    so far. A wall-clock time read at a level is on the clock of level 0 less that level.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.steps: list[HostClockStep] = []
        self._last: tuple[float, float, float] | None = None  # offset, monotonic, its error
        self.sample()

    @property
    def level_s(self) -> float:
        """The sum of the steps seen so far (0 before any)."""
        return self.steps[-1].level_s if self.steps else 0.0

    def sample(self) -> float:
        """Read the clocks; record a step where they moved apart; return the level."""
        return self.read()[1]

    def read(self) -> tuple[float, float]:
        """Read the clocks as `sample` does; return the wall clock's time and its level.

        The level is the one that time was read at: a reading another thread overtook (the
        clocks read before, the watch taken after) is placed by its own times.
        """
        m0 = monotonic_s()
        wall = wall_s()
        m1 = monotonic_s()
        mono, error = 0.5 * (m0 + m1), 0.5 * (m1 - m0)
        offset = wall - mono
        with self._lock:
            last = self._last
            if last is not None and mono < last[1]:  # overtaken: no news, but its own level
                return wall, self._level_at(mono, wall)
            if last is not None:
                change = offset - last[0]
                allowed = (STEP_TOLERANCE_S + SLEW_PPM * 1e-6 * (mono - last[1])
                           + error + last[2])
                if abs(change) > allowed:
                    self.steps.append(HostClockStep(last[1], mono, change,
                                                    self.level_s + change))
            self._last = (offset, mono, error)
            return wall, self.level_s

    def level_at(self, monotonic: float, wall: float | None = None) -> float:
        """Return the level at a monotonic time; ``wall``, read then, decides within a step.

        A reading between the two a step fell between is at the level before it or after it:
        the one its wall time less its monotonic time lies nearer (without ``wall``: after).
        """
        with self._lock:
            return self._level_at(monotonic, wall)

    def _level_at(self, monotonic: float, wall: float | None) -> float:
        level = 0.0
        last = self._last
        for step in self.steps:
            if monotonic >= step.before_s:
                level = step.level_s
            elif monotonic > step.after_s and wall is not None and last is not None:
                # Offsets: the last reading's less the levels after it gives level 0's.
                zero = last[0] - self.level_s
                before, after = step.level_s - step.size_s, step.level_s
                offset = wall - monotonic - zero
                level = after if abs(offset - after) < abs(offset - before) else before
                break
            elif monotonic > step.after_s:
                level = step.level_s
                break
            else:
                break
        return level

    def levels(self) -> list[float]:
        """Return the levels the wall clock has been at: 0, then after each step."""
        return [0.0, *(s.level_s for s in self.steps)]


__all__ = ["SLEW_PPM", "STEP_TOLERANCE_S", "HostClockStep", "HostClockWatch", "monotonic_s",
           "wall_s"]
