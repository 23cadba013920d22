"""Preflight: what the bench and the radar cannot do for a scene, known before anything plays.

Streams the scene's kinematics and schedule in frame batches (bounded memory, no output, no
radar) and counts, per target, the target-frames under each limit of
`rts_scenario.scenario.model.LIMITS`, plus the limits of the whole scene. `validate` prints it;
a run prints it before playing, so an hour on a real bench is not spent to learn that a target
was never played.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from .check import checkable, limit_masks
from .kinematics import Tracks, compute_tracks
from .scenario.model import LIMITS, RadarOptions, Scenario
from .schedule import Schedule, build_schedule

BATCH_FRAMES = 2000
# Target-frames per streamed batch: large enough to amortize per-call costs, small enough that
# memory stays bounded however many targets a scene has.
BATCH_TARGET_FRAMES = 16_384


def frames_per_batch(n_targets: int, most: int = BATCH_FRAMES) -> int:
    """Frames per batch for a scene of ``n_targets``: at most ``most``, `BATCH_TARGET_FRAMES`."""
    return max(1, min(most, BATCH_TARGET_FRAMES // max(1, n_targets)))


@dataclass(frozen=True)
class Preflight:
    """Limits a scene hits, per target and for the whole scene.

    Attributes
    ----------
    scene : str
        Scene name.
    targets : dict of str to dict of str to int
        Per target name: target-frames under each limit it hits.
    scene_limits : dict of str to str
        Limits of the whole scene and why.
    expected : dict of str to frozenset of str
        Per target name: the limits the scene declares expected for it.
    scene_expected : frozenset of str
        Scene-wide limits the scene declares expected.
    checkable_frames : int or None
        Target-frames under no limit, all targets together (None: not counted).
    crowded_analytic_frames : int
        Scene frames in which targets share a range-Doppler neighbourhood where the scene
        forces the built-in simulated radar's analytic fidelity: a run on that radar fails
        with ``crowded_in_analytic`` unless the scene expects it (the run counts the radar's
        cycles, which may be more or fewer than the scene's frames).
    """

    scene: str
    targets: dict[str, dict[str, int]]
    scene_limits: dict[str, str]
    expected: dict[str, frozenset[str]]
    scene_expected: frozenset[str]
    checkable_frames: int | None = None
    crowded_analytic_frames: int = 0

    def unexpected(self) -> list[str]:
        """One line per limit the scene does not declare (these fail a run's verdict).

        Also one where the scene has targets and none is checkable in any frame: whatever it
        expects, a run has nothing to check and fails.
        """
        out = [f"{name}: {why}" for name, why in self.scene_limits.items()
               if name not in self.scene_expected]
        for target, hits in self.targets.items():
            bad = {lim: n for lim, n in hits.items() if lim not in self.expected[target]}
            if bad:
                out.append(f"{target}: " + ", ".join(
                    f"{lim} in {n} frames ({LIMITS[lim]})" for lim, n in bad.items()))
        if self.expected and self.checkable_frames == 0:
            out.append("no target is checkable in any frame (each is under a limit "
                       "throughout): a run has nothing to check and fails")
        return out

    def expected_lines(self) -> list[str]:
        """One line per target whose limits the scene declares (shown, not failing)."""
        out = [f"{name}: {why} (expected)" for name, why in self.scene_limits.items()
               if name in self.scene_expected]
        for target, hits in self.targets.items():
            good = {lim: n for lim, n in hits.items() if lim in self.expected[target]}
            if good:
                out.append(f"{target}: " + ", ".join(f"{lim} in {n} frames"
                                                     for lim, n in good.items()) + " (expected)")
        return out


def scene_limits(scene: Scenario) -> dict[str, str]:
    """Limits the whole scene hits, with why (see `rts_scenario.scenario.model.LIMITS`)."""
    out = {}
    cycle_s = scene.radar.radar_clock.cycle_s
    radar_hz = 1.0 / cycle_s
    if scene.frame_rate_hz > radar_hz * (1.0 + 1e-9):
        out["frame_rate_above_radar"] = (
            f"the scene runs at {scene.frame_rate_hz:g} frames/s but radar "
            f"{scene.radar.name!r} measures {radar_hz:g} cycles/s (cycle {cycle_s:g} s): "
            f"it cannot report every frame")
    staircase = _staircase(scene)
    if staircase is not None:
        out["motion_staircase"] = staircase
    return out


# A frame held over at least this many radar cycles is measured as it stands by all of them.
STAIRCASE_CYCLES = 3.0


def _staircase(scene: Scenario) -> str | None:
    """Why the radar would see a target's motion as a staircase, or None.

    Each frame is held for a frame period; where that spans `STAIRCASE_CYCLES` radar cycles or
    more, every one of them measures (and is judged against) the frame held, while the scene's
    target moves on. Flagged where a target present and in the rig's coverage moves farther
    than the range tolerance
    within one frame period (from its frame's time to the next, the last frame's to the
    scene's end).
    """
    period_s = 1.0 / scene.frame_rate_hz
    cycle_s = scene.radar.radar_clock.cycle_s
    if period_s < STAIRCASE_CYCLES * cycle_s or not scene.targets:
        return None
    tolerance_m = scene.expectations.tolerances["range_m"]
    worst = (0.0, 0, 0)  # distance, frame, target
    step = frames_per_batch(len(scene.targets))
    for first in range(0, scene.n_frames, step):
        frames = np.arange(first, min(first + step, scene.n_frames) + 1)
        tracks = compute_tracks(scene, frames / scene.frame_rate_hz, frames)
        moved = np.linalg.norm(np.diff(tracks.position_m, axis=0), axis=-1)
        # Of what the RTS plays the radar: a target out of the rig's coverage is not played.
        moved = np.where(tracks.present[:-1] & tracks.in_coverage[:-1], moved, 0.0)
        f, k = np.unravel_index(int(np.argmax(moved)), moved.shape)
        if moved[f, k] > worst[0]:
            worst = (float(moved[f, k]), first + int(f), int(k))
    distance_m, frame, target = worst
    if distance_m <= tolerance_m:
        return None
    return (f"the scene holds each frame {period_s:g} s, {period_s / cycle_s:.3g} radar cycles "
            f"(cycle {cycle_s:g} s), while target {scene.targets[target].name!r} moves "
            f"{distance_m:.3g} m in one (from {frame / scene.frame_rate_hz:g} s), more than the "
            f"range tolerance {tolerance_m:g} m: the radar sees its motion as a staircase, each "
            f"cycle judged against the frame held; raise frame_rate_hz")


def track_batches(scene: Scenario, batch_frames: int | None = None
                  ) -> Iterator[tuple[np.ndarray, Tracks]]:
    """Yield the scene batch by batch: frame indices and their tracks.

    ``batch_frames``: frames per batch (default: `frames_per_batch` of the scene's targets).
    """
    t_all = scene.t_s
    if batch_frames is None:
        batch_frames = frames_per_batch(len(scene.targets))
    for first in range(0, scene.n_frames, batch_frames):
        frames = np.arange(first, min(first + batch_frames, scene.n_frames))
        yield frames, compute_tracks(scene, t_all[frames], frames)


def schedule_batches(scene: Scenario, method: str = "exact", batch_frames: int | None = None
                     ) -> Iterator[tuple[np.ndarray, Tracks, Schedule]]:
    """Yield the scene batch by batch: frame indices, their tracks and their schedule.

    ``batch_frames``: frames per batch (default: `frames_per_batch` of the scene's targets).
    """
    for frames, tracks in track_batches(scene, batch_frames):
        yield frames, tracks, build_schedule(tracks, scene.rig, scene.radar, method=method,
                                             estimator=scene.radar_options.estimator,
                                             frame_rate_hz=scene.frame_rate_hz,
                                             angle_tolerance_deg=angle_tolerance_deg(scene))


def angle_tolerance_deg(scene: Scenario) -> tuple[float, float]:
    """Return the scene's azimuth and elevation tolerances (what `build_schedule` flags by)."""
    tol = scene.expectations.tolerances
    return float(tol["az_deg"]), float(tol["el_deg"])


class LimitCounter:
    """Count a scene's limits batch by batch (`add`), as its schedule is built; `result`."""

    def __init__(self, scene: Scenario) -> None:
        self.scene = scene
        self._counts = {lim: np.zeros(len(scene.targets), dtype=np.int64) for lim in LIMITS}
        self._checkable = 0
        self._crowded = 0
        options = scene.radar_options
        # The built-in radar's analytic model reads crowded frames as if alone: counted where
        # the scene forces it (an OS-CFAR runs every frame through the cube).
        self._radar = None
        if options.fidelity == "analytic" and options.cfar == "ca" and scene.targets:
            from .radar.simulate import SimulatedRadar

            self._radar = SimulatedRadar(scene.radar, scene.rig, fidelity="analytic",
                                         noise=False)

    def add(self, tracks: Tracks, schedule: Schedule) -> None:
        """Count one batch's target-frames under each limit, and the checkable ones."""
        for lim, mask in limit_masks(tracks, schedule.status).items():
            self._counts[lim] += mask.sum(axis=0)
        self._checkable += int(checkable(tracks, schedule.status).sum())
        if self._radar is not None:
            echoes = self._radar.echoes(schedule)
            self._crowded += int(self._radar.crowded(echoes, schedule.n_frames).sum())

    def result(self) -> Preflight:
        """Return the `Preflight` of the batches added."""
        scene, counts = self.scene, self._counts
        expected = scene.expectations.expected_limits
        return Preflight(
            scene=scene.name,
            targets={t.name: {lim: int(c[k]) for lim, c in counts.items() if c[k]}
                     for k, t in enumerate(scene.targets)
                     if any(c[k] for c in counts.values())},
            scene_limits=scene_limits(scene),
            expected={t.name: expected | t.expected_limits for t in scene.targets},
            scene_expected=expected, checkable_frames=self._checkable,
            crowded_analytic_frames=self._crowded)


def preflight(scene: Scenario, method: str = "exact",
              batch_frames: int | None = None) -> Preflight:
    """Count the limits ``scene`` hits with the weight solver ``method``."""
    counter = LimitCounter(scene)
    for _, tracks, schedule in schedule_batches(scene, method, batch_frames):
        counter.add(tracks, schedule)
    return counter.result()


# A chance below this that the simulated radar's thermal noise makes more false detections than
# an empty bench allows: its check could not fail (`vacuous_empty_bench`).
VACUOUS_CHANCE = 1e-3


def vacuous_empty_bench(scene: Scenario, radar_options: RadarOptions) -> str | None:
    """Why an empty bench on the built-in simulated radar checks nothing, else None.

    A scene without targets checks only the radar's false detections; the simulated radar
    makes them only from the cube's noise (`adc` fidelity or an OS-CFAR, noise on), as far as
    its CFAR lets thermal noise through (`thermal_false_alarm_chance`, CA-CFAR; an OS-CFAR lets less
    through): where more of them than the scene allows over its cycles (Poisson) have a chance
    below `VACUOUS_CHANCE`, its check could not fail either. Played to an RTS, the radar is the
    bench's, and the check is real.
    """
    ro = radar_options
    if scene.targets:
        return None
    # The cube's frames: every one at fidelity adc, and with an OS-CFAR at any fidelity.
    if (ro.fidelity == "adc" or ro.cfar != "ca") and ro.noise:
        from scipy.special import pdtrc  # scipy when needed: see `check._assign`

        from .radar.simulate import THRESHOLD_DB, thermal_false_alarm_chance

        radar = scene.radar
        chance = thermal_false_alarm_chance(radar)
        cycles = max(1, round(scene.duration_s / radar.radar_clock.cycle_s))
        expected = chance * radar.adc_samples * radar.chirp_loops * cycles
        allowed = math.floor(scene.expectations.max_false_detections_per_frame * cycles + 1e-9)
        beyond = float(pdtrc(allowed, expected))
        if beyond >= VACUOUS_CHANCE:
            return None
        bound = "" if ro.cfar == "ca" else " at most (its OS-CFAR lets less through)"
        return (f"nothing to check: the scene has no targets, and the built-in simulated radar's "
                f"thermal noise crosses its CFAR threshold ({THRESHOLD_DB:g} dB over the noise "
                f"of its {radar.array.n_elements} channels summed) with a chance of "
                f"{chance:.2g} per cell{bound}: {expected:.2g} false detections are to be "
                f"expected in this run's {cycles} radar cycles, more than the {allowed} it "
                f"allows with a chance of {beyond:.2g}, so its one check could not fail; play "
                f"it to a bench (expected where the scene lists nothing_checked in "
                f"expected_limits)")
    why = ("with noise off" if not ro.noise else "at analytic fidelity"
           if ro.fidelity == "analytic" else
           f"at {ro.fidelity} fidelity (the cube only where targets crowd: none here)")
    return (f"nothing to check: the scene has no targets, and the built-in simulated radar "
            f"{why} makes no false detections, so its one check could not fail; play it to a "
            f"bench (expected where the scene lists nothing_checked in expected_limits)")
