"""Where a played test pattern shows in the radar's detections: the gate a measurement reads.

A bench stands in a room: a wall, the RTS's housing, the coupling path between the FEs and the
radar return static echoes (0 m/s, at a fixed range) that the radar reports every cycle
alongside the played target, and may report stronger than a weak FE's echo. Taking a cycle's
strongest detection would then measure the room. A measurement (`rts_scenario.calibration`,
`rts_scenario.survey`) takes the strongest detection within a gate about where the pattern's
echo shows:

- in range, where its total delay puts it: the RTS's delay as played (a delay sweep's steps
  included), the FE's distance there and back and the RTS's latency, read where the radar's
  range spectrum shows it (the range-Doppler coupling of its chirps, unless the radar corrects
  it; folded into its unambiguous range), plus or minus `GATE_BINS` range bins, widened by
  half the spread of the played channels' ranges;
- in radial velocity, where its Doppler puts it (folded into the unambiguous velocities), plus
  or minus `GATE_BINS` velocity bins.

A quantity the radar does not report does not gate. A cycle with detections but none in the
gate is a missing measurement; `Gate.miss` says what was looked for where, and what the radar
reported strongest instead.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .detections import Detections
from .propagation import C0_MPS
from .radar.profile import RadarProfile
from .rig import Rig
from .schedule import Schedule

FloatArray = NDArray[np.float64]

# Half the gate's width in the radar's range and velocity bins: the radar's sub-bin estimate,
# the bus's steps and a bench's few centimetres of unmodelled delay stay well within it; a
# static reflection of the room at another range, or at the pattern's range standing still
# (the pattern approaches at 1 m/s: 3 velocity bins of the awr1843boost), stays out.
GATE_BINS = 2.0


def echo_delays_s(rig: Rig, schedule: Schedule) -> FloatArray:
    """Total delay of each channel's echo, (frames, targets, 4) s, NaN where it is off.

    The RTS's delay as scheduled, the FE's distance there and back and the RTS's latency, less
    the FE's ``calibration.delay_s``: the schedule adds that to make up for the channel's own
    delay, which takes it off again on the way (where the rig's calibration is right).
    """
    fe = np.maximum(schedule.fe, 0)
    delay: FloatArray = (schedule.delay_s - rig.cal_delay_s[fe]
                         + 2.0 * rig.distance_m[fe] / C0_MPS + rig.limits.latency_s)
    return delay


def _folded(value: FloatArray, period: float) -> FloatArray:
    """``value`` less the nearest multiple of ``period`` (a difference on a circular axis)."""
    out: FloatArray = value - period * np.round(value / period)
    return out


@dataclass(frozen=True)
class Gate:
    """Where each frame of a played schedule shows in the radar's detections.

    ``range_m`` and ``radial_velocity_mps`` (F,) are the gate's centre in each frame (NaN
    where the frame plays nothing), ``range_half_m`` (F,) and ``velocity_half_mps`` its half
    widths; ``range_period_m`` and ``velocity_period_mps`` the radar's unambiguous spans,
    over which its reports fold.
    """

    range_m: FloatArray
    range_half_m: FloatArray
    radial_velocity_mps: FloatArray
    velocity_half_mps: float
    range_period_m: float
    velocity_period_mps: float

    @classmethod
    def of(cls, rig: Rig, radar: RadarProfile, schedule: Schedule) -> Gate:
        """Return the gate of every frame of ``schedule`` played on ``rig`` for ``radar``."""
        n = schedule.n_frames
        delay = echo_delays_s(rig, schedule).reshape(n, -1)
        doppler = schedule.doppler_hz.reshape(n, -1)
        coupled = doppler if radar.range_doppler_coupling == "kept" else 0.0
        ranges = radar.range_bin(delay, coupled) * radar.range_bin_m
        # A frame that plays nothing gets NaN: no detection lies in its gate.
        on = np.isfinite(ranges)
        count = on.sum(axis=1)
        played = count > 0
        low = np.where(played, np.where(on, ranges, np.inf).min(axis=1), np.nan)
        high = np.where(played, np.where(on, ranges, -np.inf).max(axis=1), np.nan)
        mean_doppler = np.where(on, doppler, 0.0).sum(axis=1) / np.maximum(count, 1)
        velocity = np.where(played, -mean_doppler * radar.wavelength_m / 2.0, np.nan)
        return cls(range_m=np.mod(0.5 * (low + high), radar.max_range_m),
                   range_half_m=0.5 * (high - low) + GATE_BINS * radar.range_bin_m,
                   radial_velocity_mps=velocity,
                   velocity_half_mps=GATE_BINS * radar.velocity_resolution_mps,
                   range_period_m=radar.max_range_m,
                   velocity_period_mps=2.0 * radar.max_radial_velocity_mps)

    def inside(self, cycle: Detections, frame: int) -> NDArray[np.bool_]:
        """Which of ``cycle``'s detections lie in frame ``frame``'s gate, (D,) bool."""
        ok = np.ones(cycle.count, dtype=bool)
        if cycle.range_m is not None:
            ok &= (np.abs(_folded(cycle.range_m - self.range_m[frame], self.range_period_m))
                   <= self.range_half_m[frame])
        if cycle.radial_velocity_mps is not None:
            ok &= (np.abs(_folded(cycle.radial_velocity_mps - self.radial_velocity_mps[frame],
                                  self.velocity_period_mps)) <= self.velocity_half_mps)
        return ok

    def strongest(self, cycle: Detections, frame: int) -> int | None:
        """Index of the strongest detection (SNR, else RCS) in the gate, None if none is."""
        inside = np.flatnonzero(self.inside(cycle, frame))
        if inside.size == 0:
            return None
        level = cycle.snr_db if cycle.snr_db is not None else cycle.rcs_dbsm
        return int(inside[0] if level is None else inside[np.argmax(level[inside])])

    def miss(self, what: str, cycle: Detections, frame: int) -> str | None:
        """Why ``cycle`` measured nothing of ``what``: detections, none in the gate; or None.

        None where it has no detection at all (the radar does not see the pattern, or reports
        elsewhere), or one in the gate.
        """
        k = cycle.strongest()
        if k is None or self.strongest(cycle, frame) is not None:
            return None
        where, width = [], []
        if cycle.range_m is not None:
            where.append(f"{self.range_m[frame]:.2f} m")
            width.append(f"+-{self.range_half_m[frame]:.2f} m")
        if cycle.radial_velocity_mps is not None:
            where.append(f"{self.radial_velocity_mps[frame]:.2f} m/s")
            width.append(f"+-{self.velocity_half_mps:.2f} m/s")
        seen = [f"{values[k]:.{digits}f} {unit}" for values, digits, unit in (
            (cycle.range_m, 2, "m"), (cycle.radial_velocity_mps, 2, "m/s"),
            (cycle.rcs_dbsm, 1, "dBsm")) if values is not None]
        return (f"{what} not seen at {' / '.join(where)} in cycle {cycle.cycle} (gate "
                f"{', '.join(width)}); strongest detection at {', '.join(seen)}: a reflection "
                f"in the room? (at every FE about the same offset: the rig's "
                f"limits.latency_s or its FEs' calibration.delay_s)")


__all__ = ["GATE_BINS", "Gate", "echo_delays_s"]
