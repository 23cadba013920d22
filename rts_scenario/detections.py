"""Detections: one radar cycle, whatever produced it (simulated radar, CAN, a recorded log).

This is the currency between the radar side and the checker. A cycle carries the radar's own
cycle counter (as the radar numbers it: it may start anywhere and wrap), its measurement time on
the radar's clock, and one array per reported quantity. A quantity the radar does not report is
``None`` (absent), never zeros: the checker checks only what is there.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, overload

import numpy as np
from numpy.typing import NDArray

from .errors import RtsError

FloatArray = NDArray[np.float64]

# Quantities a cycle may carry, in the order reports list them.
QUANTITIES = ("range_m", "radial_velocity_mps", "az_deg", "el_deg", "rcs_dbsm", "snr_db")


@dataclass(frozen=True)
class Detections:
    """One radar cycle: its counter, its measurement time and the detections' quantities.

    Attributes
    ----------
    cycle : int
        The radar's cycle counter as reported (no unwrapping; see `unwrap_counter`).
    t_s : float or None
        Measurement time on the radar's clock, seconds (None when the radar does not say).
    range_m, radial_velocity_mps, az_deg, el_deg, rcs_dbsm, snr_db : ndarray, shape (D,), or None
        One value per detection; None when the radar does not report that quantity.
        ``radial_velocity_mps`` > 0 means receding; angles in the radar frame (DESIGN.md 4).
    complete : bool
        False when the cycle arrived damaged (detections lost or corrupted on the way): a
        checker must not take it as the radar's whole answer.
    bus_t_s : float or None
        When the cycle's first message was on the bus (the bus's clock), if it came over one.
    host_t_s : float or None
        When the host received the cycle's first message (the host's wall clock,
        ``time.time()``, whatever clock the interface stamps ``bus_t_s`` with), if it came
        over a bus: at least the radar's latency (less its jitter) after it measured.
    host_step_s : float
        How far the host's wall clock had stepped (the sum of its steps,
        `rts_scenario.hostclock.HostClockWatch`) when the host received the cycle: 0 where
        it never stepped, or where the receiver did not watch it (a log).
    """

    cycle: int
    t_s: float | None
    range_m: FloatArray | None = None
    radial_velocity_mps: FloatArray | None = None
    az_deg: FloatArray | None = None
    el_deg: FloatArray | None = None
    rcs_dbsm: FloatArray | None = None
    snr_db: FloatArray | None = None
    complete: bool = True
    bus_t_s: float | None = None
    host_t_s: float | None = None
    host_step_s: float = 0.0

    def __post_init__(self) -> None:
        sizes = set()
        for name in QUANTITIES:
            value = getattr(self, name)
            if value is None:
                continue
            array = np.asarray(value, dtype=np.float64).reshape(-1)
            object.__setattr__(self, name, array)
            sizes.add(array.size)
        if len(sizes) > 1:
            raise RtsError(f"detections of cycle {self.cycle}: quantities differ in length "
                           f"({', '.join(f'{n} {getattr(self, n).size}' for n in self.present)})")

    @property
    def present(self) -> tuple[str, ...]:
        """Names of the quantities this cycle reports."""
        return tuple(n for n in QUANTITIES if getattr(self, n) is not None)

    @property
    def count(self) -> int:
        """Number of detections D."""
        for name in QUANTITIES:
            value = getattr(self, name)
            if value is not None:
                return int(value.size)
        return 0

    def strongest(self) -> int | None:
        """Index of the strongest detection (SNR, else RCS), None without detections."""
        if self.count == 0:
            return None
        level = self.snr_db if self.snr_db is not None else self.rcs_dbsm
        return 0 if level is None else int(np.argmax(level))

    @classmethod
    def empty(cls, cycle: int, t_s: float | None, quantities: Iterable[str] = QUANTITIES,
              complete: bool = True) -> Detections:
        """Return a cycle without detections that reports ``quantities``."""
        none = np.zeros(0)
        reported: dict[str, Any] = {q: none for q in quantities}
        return cls(cycle=cycle, t_s=t_s, complete=complete, **reported)


def bus_times(cycles: Sequence[Detections]) -> NDArray[np.float64]:
    """When each cycle reached the bus (NaN where it did not say)."""
    return np.array([np.nan if c.bus_t_s is None else c.bus_t_s for c in cycles],
                    dtype=np.float64)


def host_times(cycles: Sequence[Detections]) -> NDArray[np.float64]:
    """When the host received each cycle (NaN where not known; `Detections.host_t_s`)."""
    return np.array([np.nan if c.host_t_s is None else c.host_t_s for c in cycles],
                    dtype=np.float64)


def unwrap_counter(counter: NDArray[np.int64], near: NDArray[np.int64] | int,
                   modulus: int) -> NDArray[np.int64]:
    """Full cycle numbers of wrapped counters: the value ``counter + k * modulus`` nearest ``near``.

    A radar's counter wraps (16 bits on rts-scenario's own messages); over a scene longer than
    one wrap the counter alone is ambiguous, the expected position resolves it.
    """
    counter = np.asarray(counter, dtype=np.int64)
    k = np.round((np.asarray(near, dtype=np.float64) - counter) / modulus).astype(np.int64)
    return counter + k * modulus


@overload
def signed_step(counter: int, reference: int, modulus: int) -> int: ...


@overload
def signed_step(counter: NDArray[np.int64], reference: NDArray[np.int64] | int,
                modulus: int) -> NDArray[np.int64]: ...


def signed_step(counter: Any, reference: Any, modulus: int) -> Any:
    """Return the step from ``reference`` to ``counter``, a counter of ``modulus`` values.

    One of ``-largest_step_back(modulus)`` to ``modulus // 2``: negative where ``counter`` is
    behind ``reference`` (a reordered or repeated cycle), positive where it is ahead (a new
    cycle). A counter of 16 values steps -7..8 (8 on is forward), one of 15 values -7..7.
    Whole numbers or arrays of them.
    """
    step = (counter - reference) % modulus
    return step - modulus * (step > modulus // 2)


def largest_step_back(modulus: int) -> int:
    """Return how far back a counter of ``modulus`` values steps at most (`signed_step`).

    A receiver remembering the latest counter and this many before it knows every counter
    behind the latest, and none ahead of it: (modulus - 1) // 2, 7 for 15 or 16 values.
    """
    return (modulus - 1) // 2


# The fewest values a cycle counter may take. One of 4 steps forward by 2 at most: the header
# after one lost cycle is a new cycle. One of 3 values steps back by 1 there, and one of 2 comes
# back to the same value: the header after one lost cycle cannot be told from a copy of a cycle
# before (a counter of 16 values tells up to 7 lost cycles).
SMALLEST_COUNTER_MODULUS = 4


def long_gap_cycles(modulus: int) -> float:
    """Return how many cycles apart two headers are for their gap's time to tell the step.

    Half the range of a counter of ``modulus`` values, less `GAP_TOLERANCE_CYCLES`: a gap
    that long may be one the counter wrapped in. Never under `SHORTEST_LONG_GAP_CYCLES`, so
    that on a counter of few values (half of 4 or 5 values less the tolerance is none) a
    header on time, late by a cycle or copied is still told by its counter. The receiver
    takes a longer gap for a silence (`DetectionReceiver`), the re-check's numbering reads
    the step from its time (`sequential_numbers`).
    """
    return max(modulus // 2 - GAP_TOLERANCE_CYCLES, SHORTEST_LONG_GAP_CYCLES)


def sequential_numbers(counters: NDArray[np.int64], modulus: int,
                       bus_t_s: NDArray[np.float64] | None = None,
                       cycle_s: float | None = None) -> NDArray[np.int64]:
    """Cycle numbers of counters in arrival order, the first 0: each a step from the one before.

    A step is taken modulo the counter's wrap (`signed_step`): forward by half of it at most,
    back by less (a step back is a reordered cycle). A counter narrower than the cycles in
    flight (an 8-bit one wraps every 256 cycles) names its cycle only this way, never by where
    the cycle is expected.

    With the cycles' bus times (``bus_t_s``, NaN where not known) and the radar's ``cycle_s``,
    a gap longer than half the counter's range (`long_gap_cycles`) is told by the time it
    took: the step is the one
    the counter allows nearest the gap's time in cycles, where it lies within
    `GAP_TOLERANCE_CYCLES` of it (or 0.2 % of the gap: a crystal off its profile); times that
    match no such step (stamps out of step with the cycles) leave the counter's.
    """
    counters = np.asarray(counters, dtype=np.int64)
    if counters.size == 0:
        return counters
    step = signed_step(counters[1:], counters[:-1], modulus)
    if bus_t_s is not None and cycle_s is not None and counters.size > 1:
        elapsed = np.diff(np.asarray(bus_t_s, dtype=np.float64)) / cycle_s
        long = np.isfinite(elapsed) & (elapsed > long_gap_cycles(modulus))
        if long.any():
            timed = step + np.round((elapsed - step) / modulus).astype(np.int64) * modulus
            off = np.abs(elapsed - timed)
            use = long & (off <= np.maximum(GAP_TOLERANCE_CYCLES, 0.002 * elapsed))
            step = np.where(use, timed, step)
    return np.concatenate([[0], np.cumsum(step)]).astype(np.int64)


# How far (cycles) a long gap's time may put it from a step its counters allow: the latency's
# jitter at both ends, and a crystal off its profile over the gap (1000 ppm: 1 cycle in 1000).
GAP_TOLERANCE_CYCLES = 2.0
# The shortest gap (cycles) whose time tells its step (`long_gap_cycles`): up to a cycle late
# with the latency's jitter, a header is told by its counter.
SHORTEST_LONG_GAP_CYCLES = 2.0


__all__ = ["GAP_TOLERANCE_CYCLES", "QUANTITIES", "SHORTEST_LONG_GAP_CYCLES",
           "SMALLEST_COUNTER_MODULUS", "Detections", "bus_times", "host_times",
           "largest_step_back", "long_gap_cycles", "sequential_numbers", "signed_step",
           "unwrap_counter"]
