"""The typed scene: what a loaded, checked ``*.scenario.yaml`` holds."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..radar.profile import RadarProfile
from ..rig import Rig
from .trajectory import Trajectory

FloatArray = NDArray[np.float64]

FLUCTUATIONS = ("none", "swerling1", "swerling3")

# What the bench or the radar may fail to do for a target-frame. A target-frame under a limit is
# not played (or not measurable) as the scene specifies it: it fails the verdict unless the scene
# lists the limit in ``expectations.expected_limits`` (or the target in its own
# ``expected_limits``).
LIMITS = {
    "out_of_coverage": "outside every quad of the rig",
    "not_synthesizable": "inside the rig, but no weights put the target there",
    "split": "the echoes would split into several targets",
    "too_close": "nearer than the RTS's shortest delay",
    "too_far": "farther than the RTS's longest delay",
    "doppler_out_of_range": "Doppler shift beyond the RTS's range",
    "no_echo_slot": "no echo slot left on a front end it needs",
    "attenuation_clipped": "level beyond the attenuator's range (played distorted)",
    "angle_quantized": "the RTS's steps, or a channel switched off beyond the attenuator's "
                       "range, move the synthesized angle by more than a third of the angle "
                       "tolerance (played off its angle)",
    "beyond_radar_range": "beyond the radar's unambiguous range",
    "beyond_radar_velocity": "beyond the radar's unambiguous radial velocity",
    "frame_rate_above_radar": "the scene's frames come faster than the radar's cycles",
    "motion_staircase": "a frame is held over several radar cycles while a target moves more "
                        "than the range tolerance: the radar sees its motion as a staircase",
    "frames_sent_late": "schedule frames went out more than a frame period late",
    "frames_lost": "the RTS reports schedule frames it lost or could not apply",
    "adjacent_frame": "the verdict rests on radar cycles judged against the frame across a "
                      "frame change, not the frame held (a radar showing that frame and a "
                      "range offset of the targets' travel in one frame look alike)",
    "quantity_unchecked": "the scene writes a tolerance for a quantity the run's CAN mapping "
                          "does not carry: it is not checked",
    "crowded_in_analytic": "targets shared a range-Doppler neighbourhood in frames the built-in "
                           "simulated radar read in analytic fidelity, which reports each as if "
                           "alone where a radar merges or loses them",
    "nothing_checked": "a scene without targets (an empty bench) played to the built-in "
                       "simulated radar, whose false detections it checks, which makes none "
                       "(no noise, or a CFAR that thermal noise does not cross)",
}

# Limits of the whole scene, not of a target-frame: only ``expectations.expected_limits``
# declares them.
SCENE_LIMITS = ("frame_rate_above_radar", "motion_staircase", "frames_sent_late", "frames_lost",
                "adjacent_frame", "quantity_unchecked", "crowded_in_analytic",
                "nothing_checked")
# Those known from the scene before anything plays (`rts_scenario.preflight.scene_limits`).
PLANNED_SCENE_LIMITS = ("frame_rate_above_radar", "motion_staircase")

DEFAULT_TOLERANCES = {
    "range_m": 0.3,
    "radial_velocity_mps": 0.3,
    "az_deg": 0.5,
    "el_deg": 1.0,
    "rcs_db": 6.0,
}


@dataclass(frozen=True)
class Mount:
    """Radar pose on the ego: position in the ego frame (m) and yaw/pitch/roll (deg).

    Angles follow ISO 8855 (x forward, y left, z up): yaw positive to the left, pitch positive
    nose down, roll positive right side down; applied as yaw, then pitch, then roll.
    """

    x_m: float = 0.0
    y_m: float = 0.0
    z_m: float = 0.0
    yaw_deg: float = 0.0
    pitch_deg: float = 0.0
    roll_deg: float = 0.0

    @property
    def position_m(self) -> FloatArray:
        """Mount position in the ego frame, shape (3,)."""
        return np.array([self.x_m, self.y_m, self.z_m])

    @property
    def rotation(self) -> FloatArray:
        """Rotation from the radar frame to the ego frame, shape (3, 3)."""
        y, p, r = np.radians([self.yaw_deg, self.pitch_deg, self.roll_deg])
        rz = np.array([[np.cos(y), -np.sin(y), 0.0], [np.sin(y), np.cos(y), 0.0], [0, 0, 1.0]])
        ry = np.array([[np.cos(p), 0.0, np.sin(p)], [0, 1.0, 0], [-np.sin(p), 0.0, np.cos(p)]])
        rx = np.array([[1.0, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
        return rz @ ry @ rx


@dataclass(frozen=True)
class RadarOptions:
    """How the built-in simulated radar runs this scene."""

    fidelity: str = "auto"
    estimator: str = "bartlett"
    cfar: str = "ca"
    noise: bool = True


def simulated_radar_parameters(parameters: dict[str, Any]) -> list[str]:
    """Return a variant's parameters (key paths) that only the built-in simulated radar takes.

    Played to an RTS, a combination over them runs as the others do: the radar on the bench
    measures as it is set (`rts-scenario run` and the pytest plugin say so).
    """
    from dataclasses import fields

    keys = {f"radar.{f.name}" for f in fields(RadarOptions)}
    return [key for key in parameters if key in keys]


@dataclass(frozen=True)
class RcsModel:
    """Radar cross section of a target.

    ``rcs_dbsm`` is a constant, or a table over ``aspect_deg`` (0: the radar sees the target's
    front, 180: its back), interpolated linearly and periodically. ``fluctuation`` draws
    Swerling 1 or 3 factors per frame around that mean.
    """

    rcs_dbsm: FloatArray
    aspect_deg: FloatArray | None = None
    fluctuation: str = "none"


@dataclass(frozen=True)
class TargetSpec:
    """One target of the scene."""

    name: str
    kind: str
    frame: str
    trajectory: Trajectory
    rcs: RcsModel
    appear_s: float = 0.0
    disappear_s: float = np.inf
    expected_limits: frozenset[str] = frozenset()


@dataclass(frozen=True)
class Expectations:
    """What the checker demands: error tolerances per quantity and rates.

    ``tolerances`` holds every quantity's (`DEFAULT_TOLERANCES` for those the scene leaves
    out); ``tolerances_written`` names those the scene file wrote in
    ``expectations.tolerances``. A quantity the run's CAN mapping does not carry is not
    checked: where the scene wrote its tolerance, the scene means it checked and the run fails
    (``quantity_unchecked``) unless the scene expects that; a default's is only said.
    Expectations built in code write none unless they say so.
    """

    tolerances: dict[str, float] = field(default_factory=lambda: dict(DEFAULT_TOLERANCES))
    detection_rate: float = 0.9
    max_false_detections_per_frame: float = 0.1
    expected_limits: frozenset[str] = frozenset()
    tolerances_written: frozenset[str] = frozenset()


@dataclass(frozen=True)
class Effects:
    """Optional effects; each costs nothing when absent."""

    rcs_fluctuation: str = "none"


@dataclass(frozen=True, eq=False)
class Scenario:
    """A loaded scene.

    ``variant`` names the combination of the file's ``parametrize`` block it was loaded with,
    as the pytest plugin names its item (``estimator=ti``; ``""`` for the file as written), and
    ``parameters`` holds that combination (key path to value).
    """

    name: str
    description: str
    file: str
    duration_s: float
    frame_rate_hz: float
    seed: int
    radar: RadarProfile
    mount: Mount
    rig: Rig
    ego: Trajectory
    targets: tuple[TargetSpec, ...]
    expectations: Expectations = Expectations()
    effects: Effects = Effects()
    marks: tuple[str, ...] = ()
    radar_options: RadarOptions = RadarOptions()
    variant: str = ""
    parameters: dict[str, Any] = field(default_factory=dict)

    @property
    def label(self) -> str:
        """``name[variant]``, the pytest plugin's name for this run (``name`` without one)."""
        return run_label(self.name, self.variant)

    @property
    def n_frames(self) -> int:
        """Number of frames: ``round(duration_s * frame_rate_hz)``, at least 1."""
        return max(1, int(round(self.duration_s * self.frame_rate_hz)))

    @property
    def t_s(self) -> FloatArray:
        """Frame times from 0, shape (F,)."""
        return np.arange(self.n_frames) / self.frame_rate_hz


def run_label(scene: str, variant: str) -> str:
    """``scene[variant]`` as pytest names a parametrized item; ``scene`` without a variant."""
    return f"{scene}[{variant}]" if variant else scene
