"""The schedule's data model: per-frame channel settings and their status flags."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from enum import IntFlag
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import RtsError

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


class ScheduleError(RtsError):
    """A schedule cannot be built (e.g. the scene outpaces the RTS)."""


class Status(IntFlag):
    """Per-entry flags; all but two keep the entry from being emitted.

    ``ATTENUATION_CLIPPED`` and ``ANGLE_QUANTIZED`` entries are played, not as specified.
    """

    OK = 0
    NOT_PRESENT = 1
    OUT_OF_COVERAGE = 2
    NOT_SYNTHESIZABLE = 4
    SPLIT = 8
    TOO_CLOSE = 16
    DOPPLER_OUT_OF_RANGE = 32
    NO_ECHO_SLOT = 64
    ATTENUATION_CLIPPED = 128
    TOO_FAR = 256
    ANGLE_QUANTIZED = 512


BLOCKING = Status(sum(Status) & ~Status.ATTENUATION_CLIPPED & ~Status.ANGLE_QUANTIZED)


@dataclass(frozen=True)
class Schedule:
    """Channel settings per frame (F), target (K) and channel (4, paper order).

    Attributes
    ----------
    t_s : ndarray, shape (F,)
        Frame times.
    frame_index : ndarray, shape (F,)
        Index of each frame in the whole scene (batches keep it).
    names : tuple of str
        Target names (K).
    quad : ndarray, shape (F, K)
        Quad used, -1 when not synthesized.
    fe : ndarray, shape (F, K, 4)
        Rig FE index of each channel, -1 when not synthesized.
    weight : ndarray, shape (F, K, 4)
        Linear amplitude weights after quantization (max 1 per emitted entry).
    attenuation_db, delay_s, doppler_hz, phase_rad : ndarray, shape (F, K, 4)
        The channel settings (NaN where the channel is off).
    active : ndarray of bool, shape (F, K, 4)
        Channels that emit an echo.
    status : ndarray, shape (F, K)
        `Status` flags.
    angle_error_deg : ndarray, shape (F, K, 2)
        Predicted azimuth and elevation error left by the quantization of the attenuations
        and phases.
    """

    t_s: FloatArray
    frame_index: IntArray
    names: tuple[str, ...]
    quad: IntArray
    fe: IntArray
    weight: FloatArray
    attenuation_db: FloatArray
    delay_s: FloatArray
    doppler_hz: FloatArray
    phase_rad: FloatArray
    active: BoolArray
    status: NDArray[np.uint16]
    angle_error_deg: FloatArray

    @property
    def n_frames(self) -> int:
        """Number of frames F."""
        return int(self.t_s.size)

    @property
    def emitted(self) -> BoolArray:
        """Entries (F, K) the RTS plays."""
        return (self.status & BLOCKING) == 0

    def frames(self, start: int, stop: int) -> Schedule:
        """Return the frames ``start:stop`` as a schedule of their own (views, no copy)."""
        part = slice(start, stop)
        return Schedule(**{
            f.name: getattr(self, f.name) if f.name == "names" else getattr(self, f.name)[part]
            for f in fields(self)
        })

    def take(self, index: IntArray) -> Schedule:
        """Return the frames ``index`` (any order, repeats allowed) as a schedule (copies)."""
        return Schedule(**{
            f.name: getattr(self, f.name) if f.name == "names" else getattr(self, f.name)[index]
            for f in fields(self)
        })

    def held(self, clock_t_s: FloatArray, counters: IntArray) -> Schedule:
        """Return what a radar measures at ``clock_t_s``: the frames held then.

        The RTS holds each frame until the next (`held_frames`); each
        row of the result is the frame current at a cycle's time, with that time as ``t_s`` and
        the cycle's counter as ``frame_index``. Cycles before the first frame are left out.
        """
        index = held_frames(self.t_s, clock_t_s)
        keep = index >= 0
        out = self.take(index[keep])
        return replace(out, t_s=np.asarray(clock_t_s, dtype=np.float64)[keep],
                       frame_index=np.asarray(counters, dtype=np.int64)[keep])

    def changed(self, before: Schedule | None = None,
                as_sent: Mapping[str, Any] | None = None) -> BoolArray:
        """Entries (F, K) that differ from the previous frame.

        Frame 0 is compared with ``before``'s last frame (the batch sent before this one, of
        the same targets); without it, all of frame 0 counts as changed. Static targets and
        unchanged entries need not be sent again: an output in delta mode sends only these,
        the same entries however the frames were cut into batches. ``as_sent``: per field,
        the dtype an output sends it as (float32 on the wire): values compared as sent, so
        that rounding differences of batches computed apart (1e-12 dB) are no change.
        """
        out = np.ones(self.status.shape, dtype=bool)
        if self.n_frames > 1:
            out[1:] = ~self._same(slice(1, None), self, slice(None, -1), as_sent)
        if (self.n_frames and before is not None and before.n_frames
                and before.status.shape[1:] == self.status.shape[1:]):
            out[:1] = ~self._same(slice(0, 1), before, slice(-1, None), as_sent)
        return out

    def _same(self, rows: slice, other: Schedule, other_rows: slice,
              as_sent: Mapping[str, Any] | None = None) -> BoolArray:
        """Whether each target's entries in frames ``rows`` equal ``other``'s ``other_rows``."""
        same = self.status[rows] == other.status[other_rows]
        for name in ("fe", "attenuation_db", "delay_s", "doppler_hz", "phase_rad", "active"):
            a, b = getattr(self, name)[rows], getattr(other, name)[other_rows]
            if as_sent and name in as_sent:
                a, b = a.astype(as_sent[name]), b.astype(as_sent[name])
            same &= np.all((a == b) | (np.isnan(a) & np.isnan(b)) if a.dtype.kind == "f"
                           else a == b, axis=-1)
        return same



# Times this close count as equal (a cycle measured exactly at a frame's time sees that frame).
SAME_TIME_S = 1e-9


def held_frames(frame_t_s: FloatArray, t_s: FloatArray) -> IntArray:
    """Return the index of the frame the RTS holds at each time ``t_s`` (-1 before the first).

    The RTS applies frame i at ``frame_t_s[i]`` and holds it until the next one.
    """
    return np.searchsorted(np.asarray(frame_t_s), np.asarray(t_s) + SAME_TIME_S,
                           side="right").astype(np.int64) - 1


__all__ = ["BLOCKING", "SAME_TIME_S", "Schedule", "ScheduleError", "Status", "held_frames"]
