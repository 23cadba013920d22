"""Per-frame four-channel schedules: what each RTS channel must do for each target.

- `model`: the `Schedule` (per frame, target and channel) and its `Status` flags;
- `build`: `build_schedule`, from tracks to schedule (weights, levels, delays, Doppler, phase);
- `quantization`: attenuator settings that keep the synthesized angle, and the angle error left;
- `echo_slots`: which targets an FE channel plays when it has too few echoes per frame.
"""

from .build import build_schedule
from .model import BLOCKING, Schedule, ScheduleError, Status, held_frames
from .quantization import QUANTIZATION_MODES, predicted_angle_error

__all__ = ["BLOCKING", "QUANTIZATION_MODES", "Schedule", "ScheduleError", "Status",
           "build_schedule", "held_frames", "predicted_angle_error"]
