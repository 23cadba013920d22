"""Compare the radar's detections with the scene's ground truth: errors, rates, verdict.

The checker consumes `Detections` (radar cycles) from any source - the simulated radar, the CAN
receiver, a recorded log - and never sees a bus. It streams: ground truth arrives in blocks of
frames, cycles as they come, and `Checker.settle` checks the frames whose cycles are due and
forgets them, keeping running statistics, the worst frames and (on request) a per-frame record
on disk. Memory does not grow with the length of a run.

A cycle belongs to the scene frame its counter names; the counter may wrap (16 bits on
rts-scenario's own messages, 8 or fewer on some radars'), the cycle before it resolves it. A
cycle measured within the ambiguity window of a frame change
(`rts_scenario.pipeline.CycleTruth`) is judged against whichever of the two frames it matches
better, and counted.

Per frame, detections are associated with the targets the RTS played (gated at 3x each
quantity's tolerance, then an optimal assignment on the normalized distance). A checkable
target (present, synthesizable, unambiguous for the radar, played) counts as detected in a
frame when a detection is assigned to it and every checked quantity lies within its tolerance.
A quantity the radar does not report is not checked; where the run knows it from its CAN
mapping (`Checker`'s ``not_carried``), the report says so (``unchecked_quantities``), and a
tolerance the scene wrote for it fails the run (``quantity_unchecked``) unless expected.

Verdict (pass only if all hold): every target's detection rate reaches the scene's
``detection_rate``; false detections per frame stay within ``max_false_detections_per_frame``;
and no radar cycle is missing, incomplete or corrupted - its targets count as unchecked and it
fails the run (a cycle without a checkable target had its false detections to check), so missing
data can never pass. A scene without targets (an empty bench) checks false detections only. A
frame counts as checked only when every checkable target in it was matched to a detection.

A target-frame the bench did not play as the scene specifies it, or that the radar cannot measure
unambiguously (a `LIMITS` entry: outside the rig's coverage, no echo slot, attenuation clipped,
beyond the radar's unambiguous range, ...), is not checkable, and it is not silently dropped
either: it is counted per target and limit, and fails the verdict unless the scene declares the
limit expected (``expectations.expected_limits`` or the target's ``expected_limits``).
"""

from __future__ import annotations

import csv
import heapq
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .detections import Detections, bus_times, sequential_numbers, unwrap_counter
from .errors import CheckError
from .kinematics import Tracks
from .report import FailReason, FrameRecord, Report, RunningStats, TargetResult
from .scenario.model import LIMITS, PLANNED_SCENE_LIMITS, SCENE_LIMITS, Expectations
from .schedule.model import BLOCKING, Status

if TYPE_CHECKING:
    from .plot_data import PlotData

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]

# Checked quantity: (name in Tracks and Detections, tolerance key).
QUANTITIES = (
    ("range_m", "range_m"),
    ("radial_velocity_mps", "radial_velocity_mps"),
    ("az_deg", "az_deg"),
    ("el_deg", "el_deg"),
    ("rcs_dbsm", "rcs_db"),
)
GATE = 3.0
# Detections that fit the scene more than this share of a frame period (three standard errors
# clear) before or after the times the check took for them fail the run (`Checker.lag_reason`):
# most of their cycles were judged against frames the radar had not seen.
LAG_FRAMES = 0.5
# The least matched target-cycles, in cycles judged against one frame, the lag is told from.
LAG_MIN_CYCLES = 10
# Range errors that follow the scene's geometry (the bench's, the radar's) change smoothly: the
# lag's standard error is told from how its fit's residuals add up over each LAG_BIN_S of the
# radar's measurement times, not target-cycle by target-cycle, over LAG_MIN_BINS of them at
# least.
LAG_BIN_S = 0.5
LAG_MIN_BINS = 5
# Range rates whose spread (RMS about their mean) is below this did not vary (m/s): equal rates
# of targets moving along a road that is not along x differ by round-off (1e-16 m/s), and a
# lag would be told from nothing. Far below any radar's velocity resolution (centimetres per
# second).
LAG_RATE_FLOOR_MPS = 1e-6
# Worst target-frames kept for the report.
WORST_FRAMES = 8
# The counter of rts-scenario's own frame header (16 bits).
COUNTER_MODULUS = 65536

_OK, _MISSING, _INCOMPLETE = 0, 1, 2

# Schedule flags behind each limit of the bench.
_LIMIT_FLAGS = {
    "out_of_coverage": Status.OUT_OF_COVERAGE,
    "not_synthesizable": Status.NOT_SYNTHESIZABLE,
    "split": Status.SPLIT,
    "too_close": Status.TOO_CLOSE,
    "too_far": Status.TOO_FAR,
    "doppler_out_of_range": Status.DOPPLER_OUT_OF_RANGE,
    "no_echo_slot": Status.NO_ECHO_SLOT,
    "attenuation_clipped": Status.ATTENUATION_CLIPPED,
    "angle_quantized": Status.ANGLE_QUANTIZED,
}
# Columns of the detections CSV (``run --detections``), in order.
DETECTION_COLUMNS = ("scene", "cycle", "t_s", "range_m", "radial_velocity_mps", "az_deg",
                     "el_deg", "snr_db", "rcs_dbsm", "target", "variant", "file",
                     "truth_range_m", "truth_radial_velocity_mps", "truth_az_deg",
                     "truth_el_deg", "truth_rcs_dbsm")
# The ground truth beside each detection: its target's in the frame the cycle was judged against.
_TRUTH_COLUMNS = ("range_m", "radial_velocity_mps", "az_deg", "el_deg", "rcs_dbsm")


def limit_masks(tracks: Tracks, status: NDArray[np.uint16]) -> dict[str, BoolArray]:
    """Target-frames (F, K) under each limit of `LIMITS` (present targets only).

    ``status`` is the schedule's `Status` per target-frame; the radar's limits come from the
    tracks (unambiguous range and radial velocity).
    """
    present = tracks.present
    out = {name: present & ((status & flag) != 0) for name, flag in _LIMIT_FLAGS.items()}
    out["beyond_radar_range"] = present & ~tracks.in_range
    out["beyond_radar_velocity"] = present & ~tracks.in_velocity
    return out


def checkable(tracks: Tracks, status: NDArray[np.uint16]) -> BoolArray:
    """Target-frames (F, K) played exactly as specified and measurable by the radar."""
    return tracks.present & (status == Status.OK) & tracks.in_range & tracks.in_velocity


@dataclass(frozen=True)
class _Block:
    """Ground truth of consecutive cycles ``first .. first + len(t_s)``.

    ``other`` is the truth of the frame across the nearest frame change, for the cycles
    flagged ``ambiguous`` (measured within the ambiguity window of that change).
    """

    first: int
    tracks: Tracks
    status: NDArray[np.uint16]
    other: tuple[Tracks, NDArray[np.uint16]] | None = None
    ambiguous: BoolArray | None = None

    @property
    def end(self) -> int:
        return self.first + int(self.tracks.t_s.size)


@dataclass(frozen=True)
class _Judged:
    """A block's detections associated with one candidate truth of its cycles.

    Per target-cycle (F, K): ``truth`` (checkable), ``assigned`` (a detection assigned),
    ``within`` (every quantity within tolerance), ``errors`` per quantity, ``limits`` per
    limit; per detection: ``match`` (its target, -1 for none).
    """

    truth: BoolArray
    assigned: BoolArray
    within: BoolArray
    errors: dict[str, FloatArray]
    match: NDArray[np.int64]
    limits: dict[str, BoolArray]

    def better_than(self, other: _Judged) -> BoolArray:
        """Return the cycles in which this candidate detects more targets than ``other``.

        Only targets checkable in both frames count (a target under a limit in the frame held
        is never made checkable by the frame across the change), and only more detections:
        where both detect as many, ``other`` (the frame the run knows was held) stays, so the
        errors reported are against it and a frame across the change never lowers them by
        matching the noise a little better.
        """
        both = self.truth & other.truth
        detected = (self.assigned & self.within & both).sum(axis=1)
        return detected > (other.assigned & other.within & both).sum(axis=1)

    def take(self, rows: NDArray[np.intp], detections: BoolArray) -> _Judged:
        """Return the cycles ``rows`` and the ``detections`` (a mask) that belong to them."""
        return _Judged(self.truth[rows], self.assigned[rows], self.within[rows],
                       {q: e[rows] for q, e in self.errors.items()}, self.match[detections],
                       {name: m[rows] for name, m in self.limits.items()})

    def spread(self, rows: NDArray[np.intp], detections: BoolArray, n_cycles: int) -> _Judged:
        """Return this judgement of cycles ``rows`` placed among ``n_cycles`` (the rest empty).

        ``detections`` (a mask over all of the block's detections) marks this one's.
        """
        def put(a: np.ndarray, fill: Any) -> np.ndarray:
            out = np.full((n_cycles, *a.shape[1:]), fill, dtype=a.dtype)
            out[rows] = a
            return out

        match = np.full(detections.size, -1, dtype=np.int64)
        match[detections] = self.match
        return _Judged(put(self.truth, False), put(self.assigned, False),
                       put(self.within, True), {q: put(e, np.nan) for q, e in self.errors.items()},
                       match, {name: put(m, False) for name, m in self.limits.items()})

    def where(self, cycles: BoolArray, other: _Judged, frame_of: NDArray[np.int64]) -> _Judged:
        """Return this judgement where ``cycles`` is False, ``other``'s where it is True.

        The limits stay this one's (the frame held: what the RTS played), and a target is
        checkable in ``cycles`` only where it is in both.
        """
        rows = cycles[:, None]
        return _Judged(
            np.where(rows, other.truth & self.truth, self.truth),
            np.where(rows, other.assigned, self.assigned),
            np.where(rows, other.within, self.within),
            {q: np.where(rows, other.errors[q], e) for q, e in self.errors.items()},
            np.where(cycles[frame_of], other.match, self.match),
            self.limits)


# Each tolerance key's quantity and unit, as a reason says them.
_SAID = {"range_m": ("range", "m"), "radial_velocity_mps": ("radial velocity", "m/s"),
         "az_deg": ("az", "deg"), "el_deg": ("el", "deg"), "rcs_db": ("rcs", "dB")}


# The unit of each checked quantity (`QUANTITIES`), as reasons say it.
_UNITS = {"range_m": "m", "radial_velocity_mps": "m/s", "az_deg": "deg", "el_deg": "deg",
          "rcs_dbsm": "dBsm"}

# A mapped quantity (`canbus.mapping.QUANTITIES`) per checked tolerance key.
_MAPPED = {"range_m": "range_m", "radial_velocity_mps": "radial_velocity_mps",
           "az_deg": "azimuth_deg", "el_deg": "elevation_deg", "rcs_db": "rcs_dbsm"}


def tolerances_below_bus_steps(exp: Expectations, steps: dict[str, float],
                               mapping_name: str) -> list[str]:
    """Say which tolerances are finer than half the bus's step of their quantity.

    ``steps``: `CanMapping.steps`. A radar exact to its bus still reports such a quantity up
    to half a step off (more where it truncates), so it can fail the check by rounding alone.
    One line per such quantity; none where every tolerance clears half a step.
    """
    out = []
    for key, quantity in _MAPPED.items():
        step = steps.get(quantity)
        if step is None or key not in exp.tolerances or exp.tolerances[key] >= step / 2:
            continue
        said, unit = _SAID[key]
        out.append(f"the {said} tolerance {exp.tolerances[key]:g} {unit} is finer than half "
                   f"the bus's step of {quantity} in mapping {mapping_name!r} ({step:g} {unit}): "
                   f"a radar exact to its bus reports it up to {step / 2:g} {unit} off and can "
                   f"fail the check by rounding alone")
    return out


def unchecked_quantities(not_carried: Mapping[str, str]) -> dict[str, str]:
    """Return the tolerance keys of the checked quantities a mapping does not carry, and why.

    ``not_carried``: `CanMapping.not_carried` (the mapping's quantity names). A detection
    without a quantity is matched and judged on the others: the quantity is not checked, and
    the report says so (`Checker`).
    """
    return {key: not_carried[q] for key, q in _MAPPED.items() if q in not_carried}


def _quantity_unchecked(exp: Expectations, unchecked: Mapping[str, str]) -> str | None:
    """Why the scene's own tolerances of quantities not checked fail the run, or None.

    A tolerance the scene wrote is one it means checked (a scene separating a car from a
    gantry by elevation); a default's is only said (`Report.unchecked_quantities`).
    """
    said = [f"the scene's {_SAID[key][0]} tolerance {exp.tolerances[key]:g} {_SAID[key][1]} "
            f"is not checked: {why}" for key, why in unchecked.items()
            if key in exp.tolerances_written]
    if not said:
        return None
    return ("; ".join(said) + " (list quantity_unchecked in expected_limits where the scene "
            "means to run on such a mapping)")


def _beyond_tolerance(target: TargetResult, exp: Expectations) -> str:
    """Say which quantities kept a target's matched detections from counting as detected.

    ``" (N target-cycles out of tolerance: rcs up to 10.2 dB > 6 dB, ...)"``, or "" where
    none was (the detections were missing, not off).
    """
    if not target.out_of_tolerance_frames:
        return ""
    over = [f"{_SAID[key][0]} up to {err.max:.3g} {_SAID[key][1]} > "
            f"{exp.tolerances[key]:g} {_SAID[key][1]}"
            for q, key in QUANTITIES
            if (err := target.errors[q]).count and err.max > exp.tolerances[key]]
    return (f" ({target.out_of_tolerance_frames} target-cycles out of tolerance"
            + (": " + ", ".join(over) if over else "") + ")")


# A cycle numbered before the scene came on the bus during it (`Checker.out_of_count_reason`)
# where it came later than its number says by more than this: a bus that held one up, or
# a latency's jitter, do not come near (the radar's own cycles before the scene come before
# its first cycle's time).
OUT_OF_COUNT_SLACK_CYCLES = 2
OUT_OF_COUNT_SLACK_S = 0.1


class Checker:
    """Streaming check of radar cycles against ground truth.

    Parameters
    ----------
    scene : str
        Scene name, for the report.
    names : tuple of str
        Target names (K).
    expectations : Expectations
        Tolerances and required rates.
    counter_modulus : int
        The radar's cycle counter wraps at this value.
    counter_start : int or None
        The counter of the radar's cycle 0 (`rts_scenario.radar.clock.RadarClock`): truth
        blocks are numbered by cycle (0 at the radar clock's start), cycles by their counter.
        None until the caller knows it (set the attribute before the first `add_cycles`).
    record : FrameRecord, optional
        Where per-frame arrays go (none kept without it).
    plot : PlotData, optional
        Takes each judged cycle's errors and misses for the plots (`PlotData.add_cycles`).
    expected_limits : sequence of frozenset of str, optional
        Per target, limits the scene expects besides ``expectations.expected_limits``.
    scene_limits : mapping of str to str, optional
        Limits the whole scene hits (e.g. ``frame_rate_above_radar``) and why.
    detections_out : text file, optional
        Every detection is written there as a CSV row (`DETECTION_COLUMNS`, no header).
    variant, parameters : str, mapping of str to any, optional
        The combination of the scene's ``parametrize`` block that runs (`Scenario.variant`,
        `Scenario.parameters`): the report and every detection row name it.
    file : str, optional
        The scene's file (`Scenario.file`): every detection row names it, so that two scene
        files of one name are told apart.
    cycle_s : float, optional
        The radar's cycle: a gap in its counters longer than half their range is told by the
        cycles' bus times (`sequential_numbers`). Without it, by the counters alone.
    not_carried : mapping of str to str, optional
        The checked quantities the run's CAN mapping does not carry, and why
        (`CanMapping.not_carried`): not checked, said in the report, and failing the run
        where the scene wrote their tolerance (``quantity_unchecked``). None: not known (the
        cycles' source is no bus), nothing said.
    limits : mapping of str to tuple, optional
        The ends of what the mapping's signals carry of the quantities read as they are
        (`CanMapping.limits`: ``(low, high, step, signal)`` by `Detections` quantity name): a
        detection reporting one at an end, where the target's truth lies beyond it by more
        than half a step, reported all its signal could; that quantity of that target-cycle
        is not checked, and the report says how many (``unchecked_quantities``, failing the
        run where the scene wrote its tolerance). None: no signal ends.
    mapping_name : str, optional
        The mapping's name, for the reasons ``limits`` give.
    jitter_s : float, optional
        The radar's latency jitter (its profile's ``clock.jitter_s``): a cycle may reach the
        bus this much off its time without being another radar's (`tally_out_of_count`).
    """

    def __init__(self, scene: str, names: tuple[str, ...], expectations: Expectations, *,
                 counter_modulus: int = COUNTER_MODULUS, counter_start: int | None = 0,
                 record: FrameRecord | None = None, plot: PlotData | None = None,
                 expected_limits: Sequence[frozenset[str]] | None = None,
                 scene_limits: Mapping[str, str] | None = None,
                 detections_out: TextIO | None = None, variant: str = "",
                 parameters: Mapping[str, Any] | None = None,
                 cycle_s: float | None = None, file: str = "",
                 not_carried: Mapping[str, str] | None = None,
                 limits: Mapping[str, tuple[float, float, float, str]] | None = None,
                 mapping_name: str = "", jitter_s: float = 0.0) -> None:
        self.scene = scene
        self.jitter_s = jitter_s
        self.variant = variant
        self.file = file
        self.parameters = dict(parameters or {})
        self.names = names
        self.expectations = expectations
        self.modulus = counter_modulus
        self.counter_start = counter_start
        self._started = False
        self._scene_first = 0  # the scene's first cycle: those before it were measured before
        # Where the run knows when cycle ``n`` reached the bus (`anchor`): cycles numbered
        # before the scene that came on the bus during it, long after their numbers say (not
        # this radar's count: another radar's with the same identifiers, or a counter gone
        # back), by number (those that may be the scene's first: few) and the rest.
        self._anchor: tuple[int, float] | None = None
        self._out_of_count: dict[int, int] = {}
        self._out_of_count_before = 0
        self._out_of_count_span: tuple[float, float] | None = None
        # Cycles numbered after the scene (beyond those counted) that came on the bus during
        # it, far earlier than their numbers say (`tally_ahead`): how many, the first number,
        # and when they came (after the anchor).
        self._ahead = 0
        self._ahead_first: int | None = None
        self._ahead_span: tuple[float, float] | None = None
        # The first cycle after the scene not counted in ``frames["after_scene"]`` (None: all
        # are): those measured later than the window after the scene's end
        # (`rts_scenario.pipeline.after_scene_until_s`) depend on how long a bus was listened to.
        self.after_scene_end: int | None = None
        self.record = record
        self.plot = plot
        n = len(names)
        self._expected = [expectations.expected_limits | (expected_limits[k] if expected_limits
                                                           else frozenset()) for k in range(n)]
        self._scene_limits = dict(scene_limits or {})
        # Whether the scene-wide limits were judged at all (a run's are; `check_cycles` has none).
        self._scene_limits_known = scene_limits is not None
        # Tolerance key -> why it is not checked (None: the mapping is not known).
        self._not_checked = (None if not_carried is None
                             else unchecked_quantities(not_carried))
        # Quantities a signal carries within ends (`limits`), and per quantity how many
        # matched target-cycles reported it at an end with the truth beyond it (not checked).
        ends = limits or {}
        self._ends: dict[str, tuple[float, float, float, str]] = {
            q: (float(ends[q][0]), float(ends[q][1]), float(ends[q][2]), str(ends[q][3]))
            for q, _ in QUANTITIES if q in ends}
        self._at_end = dict.fromkeys(self._ends, 0)
        self._mapping_name = mapping_name
        self._csv = csv.writer(detections_out) if detections_out is not None else None
        # Target-frames under each limit: of the scene's frames (`add_frames`), or, where a
        # caller gives none, of the frames its cycles saw.
        self._limits = {name: np.zeros(n, dtype=np.int64) for name in LIMITS}
        self._limits_seen = {name: np.zeros(n, dtype=np.int64) for name in LIMITS}
        self._frames_given = False
        self._out_of_tolerance = np.zeros(n, dtype=np.int64)
        self._missed = np.zeros(n, dtype=np.int64)
        self._unchecked_k = np.zeros(n, dtype=np.int64)
        self._blocks: list[_Block] = []
        self._cycles: dict[int, Detections] = {}
        # Per cycle number in `_cycles`, the further cycles received with it: counted as
        # repeated when it is settled, or, after the scene, where it counts as after_scene.
        self._copies: Counter[int] = Counter()
        self._settled = 0  # frames before this one are done
        self._last_cycle: int | None = None  # the number of the last cycle taken
        self._last_bus_t = np.nan  # and when it reached the bus
        self.cycle_s = cycle_s
        # Sums of range error, range rate, their product, their squares and their count over
        # matched targets (`detection_lag_s`), twice: the cycles near a frame change taken
        # as having seen the frame they were judged by the clock to see (row 0), or the one
        # across the change (row 1).
        self._lag = np.zeros((2, 6))
        # Per LAG_BIN_S of measurement time, the sums of count, range error, range rate, their
        # product and range rate^2: the span being filled (its number, its sums), and the
        # outer products of the closed spans' sums summed, and their number (constant memory).
        self._lag_span: tuple[int, FloatArray] | None = None
        self._lag_outer = np.zeros((2, 5, 5))
        self._lag_spans = 0
        self._stats = {q: RunningStats(n) for q, _ in QUANTITIES}
        self._checkable = np.zeros(n, dtype=np.int64)
        self._played = np.zeros(n, dtype=np.int64)
        self._detected = np.zeros(n, dtype=np.int64)
        # The same judged against the frames held alone (no cycle against the frame across a
        # change), and the largest range between the two frames of a cycle judged across one:
        # whether the verdict rests on those cycles (the ``adjacent_frame`` limit).
        self._checkable_held = np.zeros(n, dtype=np.int64)
        self._detected_held = np.zeros(n, dtype=np.int64)
        self._false_held = 0
        self._adjacent_travel_m = 0.0
        # Cycles at a change (received) whose two frames differ by more than a tolerance, or
        # judged against the frame across (it matched better: the frames told apart).
        self._ambiguous_apart = 0
        self._matched = 0
        self._unchecked = 0
        self._false = 0
        self._folded = 0
        self._invalid = 0
        self._worst: list[tuple[float, int, int, dict[str, Any]]] = []
        self.frames = {"total": 0, "checked": 0, "received": 0, "unmatched": 0, "missing": 0,
                       "incomplete": 0, "late": 0, "repeated": 0, "before_scene": 0,
                       "after_scene": 0,
                       "ambiguous": 0, "adjacent_frame": 0}

    def add_truth(self, first_frame: int, tracks: Tracks, status: NDArray[np.uint16], *,
                  other: tuple[Tracks, NDArray[np.uint16]] | None = None,
                  ambiguous: ArrayLike | None = None) -> None:
        """Ground truth of frames ``first_frame ..`` and the schedule's `Status` of each.

        Blocks must follow each other without a gap. A cycle measured close to a frame change
        may show the frame on the other side of it (the radar's chirps straddle the change, or
        the RTS applied it a little earlier or later than the run knows): ``ambiguous`` (one
        bool per cycle) flags those cycles and ``other`` (tracks and status, like ``tracks``
        and ``status``) gives that other frame for each; such a cycle is judged against
        whichever of the two it matches better, and both counts are reported
        (``frames["ambiguous"]``, ``frames["adjacent_frame"]``).
        """
        if not self._started:  # the radar's first cycle in the scene may be any
            self._started = True
            self._settled = self._scene_first = first_frame
        expected = self._blocks[-1].end if self._blocks else self._settled
        if first_frame != expected:
            raise ValueError(f"truth block starts at frame {first_frame}, expected {expected}")
        window = None
        if other is not None and ambiguous is not None:
            window = np.asarray(ambiguous, dtype=bool)
            if window.shape != tracks.t_s.shape:
                raise ValueError(f"ambiguous: one flag per cycle {tracks.t_s.shape}, "
                                 f"got {window.shape}")
            other = (other[0], _status_flags(other[1], other[0]))
        self._blocks.append(_Block(first_frame, tracks, _status_flags(status, tracks),
                                   other if window is not None else None, window))

    def add_frames(self, tracks: Tracks, status: ArrayLike) -> None:
        """Take the scene's frames: their ground truth and the schedule's `Status` flags.

        In any batches, each frame once. Where each target was checkable (played exactly as
        specified and measurable: `checkable`), and each target-frame under a limit
        (`limit_masks`), counted here whether or not a radar cycle measured the frame: the
        truth of the radar's cycles says only what the cycles measured. A target played in
        frames that no cycle measured (a radar slower than the frames, or starting after
        them) was never checked, and fails the verdict; one not played as the scene says
        there fails unless the scene expects that limit, as where a cycle saw it.
        """
        flags = _status_flags(status, tracks)
        self._frames_given = True
        self._played += checkable(tracks, flags).sum(axis=0)
        for name, mask in limit_masks(tracks, flags).items():
            self._limits[name] += mask.sum(axis=0)

    def anchor(self, number: int, bus_t_s: float) -> None:
        """Take cycle ``number``, on the bus at ``bus_t_s``, as the one before the first to come.

        Where the run knows when a cycle reached the bus (or would have: the scene's first,
        from the scene's start on the bus's clock), the first cycles received are a step
        from it told by their bus times too: a radar silent for longer than half of what an
        8-bit counter counts from the scene's start is numbered by how long it was silent.
        """
        if self._last_cycle is None:
            self._last_cycle, self._last_bus_t = int(number), float(bus_t_s)
        if self._anchor is None:
            self._anchor = (int(number), float(bus_t_s))

    def add_cycles(self, cycles: Iterable[Detections]) -> IntArray:
        """Take radar cycles, in the order they arrived; each is filed under its counter's frame.

        Returns the cycle number each was filed under.
        """
        cycles = list(cycles)
        if not cycles:
            return np.zeros(0, dtype=np.int64)
        counters = np.array([c.cycle for c in cycles], dtype=np.int64)
        if self.counter_start is None:
            raise ValueError("the radar's counter start is not known yet (set counter_start)")
        counters = (counters - self.counter_start) % self.modulus
        # Cycles come in order, give or take a reordered one: each is a step from the one
        # before (the first of all from the first frame not settled). Where a frame is
        # expected is no guide: a batch holds more cycles than an 8-bit counter counts. A gap
        # longer than half the counter's range is told by its bus time (`cycle_s`).
        bus_t = bus_times(cycles)
        if self._last_cycle is None:
            frames = (unwrap_counter(counters[:1], self._settled, self.modulus)
                      + sequential_numbers(counters, self.modulus, bus_t, self.cycle_s))
        else:
            frames = self._last_cycle + sequential_numbers(
                np.r_[self._last_cycle % self.modulus, counters], self.modulus,
                np.r_[self._last_bus_t, bus_t], self.cycle_s)[1:]
        self._last_cycle = int(frames[-1])
        self._last_bus_t = float(bus_t[-1])
        self.tally_out_of_count(frames, bus_t)
        for frame, cycle in zip(frames.tolist(), cycles, strict=True):  # one per radar cycle
            if frame < self._scene_first:  # measured before the scene's start: not checked
                self.frames["before_scene"] += 1
            elif frame < self._settled:
                self.frames["late"] += 1
            elif frame in self._cycles:
                self._copies[frame] += 1
            else:
                self._cycles[frame] = cycle
        return frames

    def tally_out_of_count(self, frames: IntArray, bus_t: FloatArray) -> None:
        """Count cycles numbered before cycle 2 that came far later than their numbers say.

        ``frames``: the cycles' numbers, ``bus_t``: their bus times (NaN: none). Called for
        every cycle taken (`add_cycles`), and by a re-check for those it does not hand on
        (numbered before the scene). Without `anchor` or a cycle time: nothing to tell by.
        """
        if self._anchor is None or self.cycle_s is None:
            return
        number, at = self._anchor
        cycle_s = self.cycle_s
        came_after_s = bus_t - at
        late_s = came_after_s - (frames - number) * cycle_s
        odd = (frames < number + 2) & (late_s > self._out_of_count_slack_s())
        if not odd.any():
            return
        for f in frames[odd & (frames >= number)].tolist():
            self._out_of_count[f] = self._out_of_count.get(f, 0) + 1
        self._out_of_count_before += int((odd & (frames < number)).sum())
        span = came_after_s[odd]
        lo, hi = float(span.min()), float(span.max())
        if self._out_of_count_span is not None:
            lo, hi = min(lo, self._out_of_count_span[0]), max(hi, self._out_of_count_span[1])
        self._out_of_count_span = (lo, hi)

    def _out_of_count_slack_s(self) -> float:
        """How far off its number's time a cycle may reach the bus and be this radar's."""
        assert self.cycle_s is not None
        return (OUT_OF_COUNT_SLACK_CYCLES * self.cycle_s + OUT_OF_COUNT_SLACK_S
                + 2.0 * self.jitter_s)

    def tally_ahead(self, frames: IntArray, bus_t: FloatArray) -> BoolArray:
        """Count cycles numbered after the scene that came far earlier than their numbers say.

        ``frames``: numbers of cycles not counted (beyond `after_scene_end`), ``bus_t`` their
        bus times (NaN: none). A radar's own cycles after the scene come after its end; these
        came on the bus while the scene's cycles did, earlier than their numbers allow by more
        than `OUT_OF_COUNT_SLACK_CYCLES` cycles, `OUT_OF_COUNT_SLACK_S`, twice the jitter and
        1 % of the time to their number: another radar's, or a count that does not start where
        the profile says (`out_of_count_reason`). Returns which. Without `anchor` or a cycle
        time: none.
        """
        frames = np.asarray(frames, dtype=np.int64)
        if self._anchor is None or self.cycle_s is None or not frames.size:
            return np.zeros(frames.size, dtype=bool)
        number, at = self._anchor
        came_after_s = np.asarray(bus_t, dtype=np.float64) - at
        since_s = (frames - number) * self.cycle_s
        early_s = since_s - came_after_s
        # Came while the scene's cycles did (by the time its last one was due), earlier than
        # the number allows beyond a latency's jitter and a clock 1 % fast: a radar's own
        # cycles after the scene come after the window counted after its end.
        during = came_after_s <= (self._settled - number) * self.cycle_s
        odd = during & (early_s > self._out_of_count_slack_s() + 0.01 * since_s)
        if odd.any():
            self._ahead += int(odd.sum())
            first = int(frames[odd].min())
            self._ahead_first = first if self._ahead_first is None else min(
                first, self._ahead_first)
            lo, hi = float(came_after_s[odd].min()), float(came_after_s[odd].max())
            if self._ahead_span is not None:
                lo, hi = min(lo, self._ahead_span[0]), max(hi, self._ahead_span[1])
            self._ahead_span = (lo, hi)
        return odd

    def out_of_count_reason(self) -> str | None:
        """Say which cycles numbered outside the scene came on the bus during it: not its radar's.

        One radar's cycles before the scene (measured before it began) come before its first
        cycle's, not seconds after, and its cycles after the scene after its last: those are
        another radar's with the same identifiers on the bus (a second radar, a recording
        replayed onto it), or a counter that went back or starts elsewhere than the profile
        says (`tally_out_of_count`, `tally_ahead`); they were not checked, and the verdict
        cannot rest on a bus that carries them. Needs the bus time of a cycle (`anchor`); else
        None.
        """
        n = self._out_of_count_before + sum(c for f, c in self._out_of_count.items()
                                            if f < self._scene_first)
        said = []
        if n and self._out_of_count_span is not None:
            lo, hi = self._out_of_count_span
            said.append(f"{n} radar cycles numbered before the scene came on the bus {lo:.3f} "
                        f"to {hi:.3f} s after its first cycle's time, later than their numbers "
                        f"allow: not this radar's count (another radar with the same "
                        f"identifiers on the bus, or a counter that went back); counted as "
                        f"before_scene, not checked")
        if self._ahead and self._ahead_span is not None:
            lo, hi = self._ahead_span
            said.append(f"{self._ahead} radar cycles numbered after the scene (cycle "
                        f"{self._ahead_first} on, counted from the profile's counter_start "
                        f"{self.counter_start}) came on the bus {lo:.3f} to {hi:.3f} s after "
                        f"its first cycle's time, earlier than their numbers allow: not this "
                        f"radar's count (another radar with the same identifiers on the bus, or "
                        f"a count that does not start where the radar's profile says); not "
                        f"checked")
        return "; ".join(said) or None

    def settle(self, before_frame: int | None = None) -> None:
        """Check every truth block that ends at or before ``before_frame`` (all if None)."""
        while self._blocks and (before_frame is None or self._blocks[0].end <= before_frame):
            block = self._blocks.pop(0)
            self._check_block(block)
            self._settled = block.end
        if before_frame is None:
            # Every cycle of the scene is settled: the rest were measured before its start
            # (taken before the scene's first cycle was known), after its end (a radar keeps
            # measuring what the RTS holds) or carry a counter the scene does not have. Of
            # those after it, the ones within the window after its end (`after_scene_end`).
            # A second cycle with the number of one after the scene is repeated where that one
            # counts; those before the scene all count as before_scene, as a re-check does.
            end = self.after_scene_end
            beyond: list[tuple[int, float]] = []
            for f, cycle in self._cycles.items():
                copies = self._copies.pop(f, 0)
                if f < self._scene_first:
                    self.frames["before_scene"] += 1 + copies
                elif end is None or f < end:
                    self.frames["after_scene"] += 1
                    self.frames["repeated"] += copies
                else:  # not counted: unless it came during the scene (`tally_ahead`)
                    beyond.append((f, np.nan if cycle.bus_t_s is None else cycle.bus_t_s))
            if beyond:
                numbers, times = zip(*beyond, strict=True)
                self.tally_ahead(np.array(numbers), np.array(times, dtype=np.float64))
            self._cycles.clear()
            self._copies.clear()

    def _check_block(self, block: _Block) -> None:
        n_frames = block.end - block.first
        status = np.full(n_frames, _MISSING, dtype=np.int8)
        got: list[Detections] = []
        rows: list[int] = []
        for f in range(block.first, block.end):  # pick this block's cycles out of the queue
            cycle = self._cycles.pop(f, None)
            if cycle is None:
                continue
            self.frames["repeated"] += self._copies.pop(f, 0)
            if not cycle.complete:
                status[f - block.first] = _INCOMPLETE
                continue
            status[f - block.first] = _OK
            got.append(cycle)
            rows.append(f - block.first)
        counts = [c.count for c in got]
        frame_of = np.repeat(np.array(rows, dtype=np.int64), counts).astype(np.int64)
        n_det = frame_of.size

        values = {q: np.concatenate(
            [getattr(c, q) if getattr(c, q) is not None else np.full(c.count, np.nan)
             for c in got]) if got else np.zeros(0) for q, _ in QUANTITIES}
        # A reported quantity that is not a number (NaN, infinite) is no measurement: such a
        # detection matches no target, and the run fails (absent quantities are not checked).
        invalid = np.zeros(n_det, dtype=bool)
        for q, _ in QUANTITIES:
            reported = np.repeat(np.array([getattr(c, q) is not None for c in got], dtype=bool),
                                 counts)
            invalid |= reported & ~np.isfinite(values[q])
        if invalid.any():  # out of the search and the costs (an infinite value overflows)
            for q, _ in QUANTITIES:
                values[q][invalid] = np.nan
        judged = held = self._judge(block.tracks, block.status, frame_of, values, invalid)
        ok = status == _OK
        use_other = np.zeros(n_frames, dtype=bool)
        if block.other is not None and block.ambiguous is not None:
            # Counted where the cycle came back: of a missing one, nothing was measured.
            self.frames["ambiguous"] += int((block.ambiguous & ok).sum())
            # Only cycles with a target checkable in both frames and not detected in this one
            # can be judged better against the frame across the change: those alone are judged
            # again.
            o_tracks, o_flags = block.other
            both = checkable(o_tracks, o_flags) & judged.truth
            # Those at a change whose two frames differ by more than a tolerance for some
            # target: where they do not, the frame held passes whichever the radar showed.
            apart = np.zeros(both.shape, dtype=bool)
            tol = self.expectations.tolerances
            for q, key in QUANTITIES[:4]:
                apart |= np.abs(getattr(o_tracks, q) - getattr(block.tracks, q)) > tol[key]
            apart_rows = block.ambiguous & ok & (both & apart).any(axis=1)
            undetected = both & ~(judged.assigned & judged.within)
            again = np.flatnonzero(block.ambiguous & ok & undetected.any(axis=1))
            if again.size:
                keep = np.isin(frame_of, again)
                other = self._judge(o_tracks.take(again), o_flags[again],
                                    np.searchsorted(again, frame_of[keep]),
                                    {q: v[keep] for q, v in values.items()}, invalid[keep])
                use_other[again] = other.better_than(judged.take(again, keep))
                if use_other.any():
                    across = np.flatnonzero(use_other)
                    travel = np.abs(o_tracks.range_m[across] - block.tracks.range_m[across])
                    travel = travel[judged.truth[across] & np.isfinite(travel)]
                    if travel.size:
                        self._adjacent_travel_m = max(self._adjacent_travel_m,
                                                      float(travel.max()))
                    judged = judged.where(use_other, other.spread(again, keep, n_frames),
                                          frame_of)
            self.frames["adjacent_frame"] += int(use_other.sum())
            # A cycle judged across told its frames apart, whatever they differ by (a range
            # offset makes less than a tolerance tell): it counts among those that tell.
            self._ambiguous_apart += int((apart_rows | use_other).sum())
        self._add_held(held, invalid)
        truth, assigned, within = judged.truth, judged.assigned, judged.within
        errors, match = judged.errors, judged.match
        matched = match >= 0
        self._add_lag(self._lag_errors(block, errors["range_m"], use_other),
                      block.tracks.radial_velocity_mps, assigned & truth, block.tracks.t_s)
        for q, _ in QUANTITIES:
            self._stats[q].add(errors[q], truth)
        for q in self._ends:  # a matched pair's error is NaN only where it was at an end
            self._at_end[q] += int((assigned & truth & np.isnan(errors[q])).sum())
        detected = assigned & within & truth
        for name, mask in judged.limits.items():
            self._limits_seen[name] += mask.sum(axis=0)

        self._out_of_tolerance += (assigned & ~within & truth).sum(axis=0)
        self._missed += (ok[:, None] & truth & ~assigned).sum(axis=0)
        self._unchecked_k += ((~ok)[:, None] & truth).sum(axis=0)
        if self._csv is not None and n_det:
            self._write_detections(got, counts, block, frame_of, match, use_other)
        whole = ok & ~(truth & ~assigned).any(axis=1)
        self._checkable += truth.sum(axis=0)
        self._detected += detected.sum(axis=0)
        self._matched += int((assigned & truth).sum())
        self._unchecked += int(((~ok)[:, None] & truth).sum())
        self._false += int((~matched & ~invalid).sum())
        if matched.any():  # detections of echoes beyond the radar's limits, where it folds them
            unambiguous = block.tracks.in_range & block.tracks.in_velocity
            self._folded += int((~unambiguous[frame_of[matched], match[matched]]).sum())
        self._invalid += int(invalid.sum())
        tally = self.frames
        tally["total"] += n_frames
        tally["received"] += int(ok.sum())
        tally["checked"] += int(whole.sum())
        tally["unmatched"] += int((ok & ~whole).sum())
        tally["missing"] += int((status == _MISSING).sum())
        tally["incomplete"] += int((status == _INCOMPLETE).sum())
        # Of the cycles that came back: one never received was not judged (frames["missing"]).
        self._keep_worst(block, truth & ok[:, None], assigned, errors)
        if self.record is not None:
            self.record.append({"frame": np.arange(block.first, block.end),
                                "t_s": block.tracks.t_s, "detected": detected,
                                "checkable": truth, "frame_status": status,
                                "adjacent_frame": use_other,
                                **{f"error_{q}": e for q, e in errors.items()}})
        if self.plot is not None:
            self.plot.add_cycles(block.tracks.t_s, truth, detected, errors)

    def _judge(self, tracks: Tracks, flags: NDArray[np.uint16], frame_of: NDArray[np.int64],
               values: dict[str, FloatArray], invalid: BoolArray) -> _Judged:
        """Associate a block's detections with one candidate truth of its cycles."""
        n_frames, n_targets = tracks.range_m.shape
        tol = self.expectations.tolerances
        n_det = frame_of.size
        truth = checkable(tracks, flags)
        # Echoes the RTS sent (a clipped one too, distorted): detections of them are no false
        # alarms, whether or not the target-frame can be checked.
        played = (flags & BLOCKING) == 0
        # Candidate pairs (detection, target): only targets within the gate in range, found by
        # a sorted search per frame (no detections x targets arrays).
        det, target = _range_candidates(frame_of, values["range_m"], tracks.range_m,
                                        GATE * tol["range_m"])
        # An echo the RTS's steps played off its angle (ANGLE_QUANTIZED, not checkable) is
        # matched on range and radial velocity only: its detections are no false alarms. So is
        # a clipped one (ATTENUATION_CLIPPED): each channel clamped at the attenuator's end on
        # its own changes the channels' ratios, and with them the angle the radar sees.
        on_angle = (flags & (Status.ANGLE_QUANTIZED | Status.ATTENUATION_CLIPPED)) == 0
        inside, cost, diffs = self._gate(det, target, frame_of, values, invalid, played,
                                         {q: getattr(tracks, q) for q, _ in QUANTITIES},
                                         angles=on_angle[frame_of[det], target])
        det, target, cost = det[inside], target[inside], cost[inside]
        diffs = {q: d[inside] for q, d in diffs.items()}
        pair = _assign(frame_of, det, target, cost, n_targets)
        match = np.full(n_det, -1, dtype=np.int64)
        match[det[pair]] = target[pair]
        self._match_folded(match, tracks, played, on_angle, frame_of, values, invalid)
        self._match_off_angle(match, tracks, played & ~on_angle, frame_of, values, invalid)
        matched = match >= 0
        assigned = np.zeros((n_frames, n_targets), dtype=bool)
        assigned[frame_of[matched], match[matched]] = True
        within = np.ones((n_frames, n_targets), dtype=bool)
        errors = {}
        for q, key in QUANTITIES:
            err = np.full((n_frames, n_targets), np.nan)
            err[frame_of[det[pair]], target[pair]] = diffs[q][pair]
            errors[q] = err
            within &= ~(np.abs(err) > tol[key])
        return _Judged(truth, assigned, within, errors, match, limit_masks(tracks, flags))

    def _gate(self, det: NDArray[np.int64], target: NDArray[np.int64],
              frame_of: NDArray[np.int64], values: dict[str, FloatArray], invalid: BoolArray,
              played: BoolArray, seen: dict[str, FloatArray], angles: BoolArray | None = None
              ) -> tuple[BoolArray, FloatArray, dict[str, FloatArray]]:
        """Which candidate pairs lie within the gate of a played echo, their costs and errors.

        ``seen``: each quantity's truth where the radar shows it; ``angles`` (per pair): where
        its angles are compared (default: every pair). A pair whose angles are not compared
        costs as much for them as the gate's edge: an echo played off its angle never takes a
        detection from a target that is within the gate on its angles too.
        """
        tol = self.expectations.tolerances
        cost = np.zeros(det.size)
        inside = played[frame_of[det], target] & ~invalid[det]
        diffs: dict[str, FloatArray] = {}
        for q, key in QUANTITIES:
            diff = values[q][det] - seen[q][frame_of[det], target]
            if q == "az_deg":
                diff = (diff + 180.0) % 360.0 - 180.0
            if q in self._ends:
                # A reading at its signal's end with the truth beyond it: not a measurement.
                low, high, step, _ = self._ends[q]
                value, truth = values[q][det], seen[q][frame_of[det], target]
                beyond = (((value >= high - step / 2) & (truth > high + step / 2))
                          | ((value <= low + step / 2) & (truth < low - step / 2)))
                diff = np.where(beyond, np.nan, diff)
            diffs[q] = diff
            if q != "rcs_dbsm":  # RCS fluctuates: it does not decide who is who
                norm = np.nan_to_num(diff / tol[key], nan=0.0)  # absent: not checked
                if angles is not None and q in ("az_deg", "el_deg"):
                    norm = np.where(angles, norm, GATE)
                cost += norm * norm
                inside &= np.abs(norm) <= GATE
        return inside, cost, diffs

    def _match_folded(self, match: NDArray[np.int64], tracks: Tracks, played: BoolArray,
                      on_angle: BoolArray, frame_of: NDArray[np.int64],
                      values: dict[str, FloatArray], invalid: BoolArray) -> None:
        """Give detections left unmatched to the echoes beyond the radar's limits they show.

        A played echo beyond the radar's unambiguous range or velocity shows where the radar's
        FFTs fold it (`Tracks.folded`). Folded in velocity, its angles are not compared: the
        radar's TDM-MIMO compensation used the folded Doppler, so its angles are wrong, and it
        may report the echo at several of them. Nor where the RTS played it off its angle
        (``on_angle`` False: quantized or clipped). Every unmatched detection within the gate
        of such an echo is that echo's (the nearest one's), not a false alarm; the target-frame
        stays under its limit (not checkable), so none of this decides a detection rate.
        """
        beyond = played & tracks.present & ~(tracks.in_range & tracks.in_velocity)
        if beyond.any():
            range_m, velocity = tracks.folded()
            self._match_rest(match, tracks, beyond, frame_of, values, invalid,
                             {"range_m": range_m, "radial_velocity_mps": velocity},
                             tracks.in_velocity & on_angle)

    def _match_off_angle(self, match: NDArray[np.int64], tracks: Tracks, off: BoolArray,
                         frame_of: NDArray[np.int64], values: dict[str, FloatArray],
                         invalid: BoolArray) -> None:
        """Give detections left unmatched to the echoes the RTS's steps played off their angle.

        Settings that move a target's angle (``ANGLE_QUANTIZED``, or channels clipped at the
        attenuator's end one by one: ``ATTENUATION_CLIPPED``) may play more than one peak
        at its range and velocity (a split beam), which the radar reports as several
        detections. Every unmatched detection within the range and velocity gate of such an
        echo is that echo's (the nearest one's), not a false alarm; the target-frame is not
        checkable, so none of this decides a detection rate.
        """
        if off.any():
            self._match_rest(match, tracks, off, frame_of, values, invalid, {},
                             np.zeros(off.shape, dtype=bool))

    def _match_rest(self, match: NDArray[np.int64], tracks: Tracks, echoes: BoolArray,
                    frame_of: NDArray[np.int64], values: dict[str, FloatArray],
                    invalid: BoolArray, seen: dict[str, FloatArray], angles: BoolArray) -> None:
        """Give each unmatched detection to the nearest of ``echoes`` (F, K) whose gate it is in.

        ``seen``: quantities where the radar shows those echoes other than their truth;
        ``angles`` (F, K): whose angles are compared. Many detections may go to one echo.
        """
        free = np.flatnonzero(match < 0)
        if free.size == 0:
            return
        truth = {q: getattr(tracks, q) for q, _ in QUANTITIES} | seen
        det, target = _range_candidates(frame_of[free], values["range_m"][free],
                                        np.where(echoes, truth["range_m"], np.nan),
                                        GATE * self.expectations.tolerances["range_m"])
        det = free[det]
        inside, cost, _ = self._gate(det, target, frame_of, values, invalid, echoes, truth,
                                     angles=angles[frame_of[det], target])
        det, target, cost = det[inside], target[inside], cost[inside]
        nearest = np.lexsort((cost, det))
        first = np.unique(det[nearest], return_index=True)[1]
        match[det[nearest][first]] = target[nearest][first]

    @staticmethod
    def _lag_errors(block: _Block, error: FloatArray, use_other: BoolArray) -> FloatArray:
        """Return the range errors for the lag, shape ``(2, F, K)``, read two ways.

        An ambiguous cycle's error against the frame the clock says it saw (row 0) and
        against the one across the change (row 1).

        A cycle near a frame change may show either frame (`CycleTruth`); it is judged against
        the one it was measured in unless the other detects more, but a target within
        tolerance of both was judged against the first. A radar sees a frame change at one
        phase of its cycle: in step with the frames, all its cycles near a change saw the
        same side of it. The lag is fitted both ways and `detection_lag_s` keeps the one
        nearer the radar's range-Doppler coupling: choosing target by target the frame whose
        error is smaller would let a range offset common to all targets (an RTS's delay
        calibration) choose, and tilt the lag by up to a frame.
        """
        if block.other is None or block.ambiguous is None:
            return np.stack([error, error])
        held, other = block.tracks.range_m, block.other[0].range_m
        turned = use_other[:, None]
        judged_r = np.where(turned, other, held)
        near = block.ambiguous[:, None]
        return np.stack([np.where(near, error + judged_r - held, error),
                         np.where(near, error + judged_r - other, error)])

    def _add_lag(self, error: FloatArray, rate: FloatArray, use: BoolArray,
                 t_s: FloatArray) -> None:
        """Add target-cycles (rows: cycles measured at ``t_s``) to the lag's sums.

        ``error``: ``(F, K)``, or ``(2, F, K)`` for both readings of the cycles near a frame
        change (`_lag_errors`).
        """
        error = np.broadcast_to(error, (2, *np.shape(rate)))
        use = use & np.isfinite(error).all(axis=0) & np.isfinite(rate)
        e, v = error[:, use], rate[use]
        self._lag += np.stack([e.sum(axis=1), np.full(2, v.sum()), e @ v, np.full(2, v @ v),
                               (e * e).sum(axis=1), np.full(2, float(v.size))], axis=1)
        if not v.size:
            return
        bins = np.floor(np.asarray(t_s, dtype=np.float64)[np.nonzero(use)[0]] / LAG_BIN_S)
        keys, of = np.unique(bins.astype(np.int64), return_inverse=True)
        sums = np.stack([np.stack([np.bincount(of, w, minlength=keys.size)
                                   for w in (np.ones(v.size), e[h], v, e[h] * v, v * v)],
                                  axis=1) for h in range(2)], axis=1)  # (spans, 2, 5)
        for key, row in zip(keys.tolist(), sums, strict=True):  # a block spans a few
            if self._lag_span is not None and key == self._lag_span[0]:
                self._lag_span[1][:] += row
            elif self._lag_span is None or key > self._lag_span[0]:
                self._close_lag_span()
                self._lag_span = (key, row.copy())
            else:  # a span closed already (cycles settle in order): a span of its own
                self._lag_outer += np.einsum("hi,hj->hij", row, row)
                self._lag_spans += 1

    def _close_lag_span(self) -> None:
        if self._lag_span is not None:
            row = self._lag_span[1]
            self._lag_outer += np.einsum("hi,hj->hij", row, row)
            self._lag_spans += 1
            self._lag_span = None

    def detection_lag_s(self, coupling_s: float = 0.0) -> tuple[float, float] | None:
        """How much earlier than the check's times the detections fit the scene, and its error.

        A radar that measured ``L`` seconds earlier than the check took it (its latency longer
        than its profile's, its phase or the RTS's timing not what the run knows) ranged each
        target ``L`` times its range rate short: the least-squares slope ``-L`` of the matched
        targets' range errors on their range rates, over cycles judged against one frame (s).
        The fit has a range offset of its own: a radar ranging every target alike long or
        short (its range offset, the RTS's delay calibration) is not out of time. Its standard
        error is the larger of the least-squares one and the one the residuals give summed
        per `LAG_BIN_S` of measurement time (range errors that follow the scene's geometry
        change smoothly, and do not average out cycle by cycle). None over fewer than
        `LAG_MIN_CYCLES` target-cycles or `LAG_MIN_BINS` such spans, or where the range rates
        did not vary (a lag could not be told from a range offset), or varied so little that
        the lag fits only with a range offset beyond the gate of the detections it is told
        from (`GATE` times the range tolerance; a lag of seconds and a range offset of metres
        fit a target whose range rate drifts by a millimetre per second as well as no lag).

        Cycles near a frame change are read both ways (`_lag_errors`): as having seen the
        frame the clock says, or the one across the change; the reading whose lag is nearer
        ``coupling_s``, the lag the radar's range-Doppler coupling gives
        (`RadarProfile.coupling_lag_s`), is kept. A radar in step with the frames fits one of
        them; one whose cycles saw either side at random gives a lag within half a frame.
        """
        fits = [fit[:2] for fit in self._lag_fits() if fit is not None and self._plausible(fit)]
        return min(fits, key=lambda lag: abs(lag[0] - coupling_s), default=None)

    def _lag_fits(self) -> list[tuple[float, float, float] | None]:
        """Return the lag, its standard error and its fit's range offset, of both readings."""
        outer, spans = self._lag_outer, self._lag_spans
        if self._lag_span is not None:  # the span being filled, as if closed
            outer = outer + np.einsum("hi,hj->hij", self._lag_span[1], self._lag_span[1])
            spans += 1
        return [self._lag_of(self._lag[h], outer[h], spans) for h in range(2)]

    def _plausible(self, fit: tuple[float, float, float]) -> bool:
        """Whether the range offset a lag fits with could be the radar's (`detection_lag_s`)."""
        return abs(fit[2]) <= GATE * self.expectations.tolerances["range_m"]

    @staticmethod
    def _lag_of(sums: FloatArray, outer: FloatArray, spans: int
                ) -> tuple[float, float, float] | None:
        """Return the lag, its standard error and its fit's range offset, of one reading."""
        s_e, s_v, s_ev, s_vv, s_ee, n = sums
        if n < LAG_MIN_CYCLES or spans < LAG_MIN_BINS:
            return None
        # About the means: the range offset out.
        mean_e, mean_v = s_e / n, s_v / n
        vv = s_vv - s_v * mean_v
        ev = s_ev - s_e * mean_v
        ee = s_ee - s_e * mean_e
        if not vv > max(1e-9 * s_vv, n * LAG_RATE_FLOOR_MPS ** 2):  # equal but for round-off
            return None
        lag = -ev / vv
        residual = max(ee - lag * lag * vv, 0.0)
        error = np.sqrt(residual / (n - 2.0) / vv)
        # Each span's sum of centred range rate x residual, (v - mean_v) (e - mean_e + L (v -
        # mean_v)), is c . (count, e, v, e v, v v) of its sums: the sum of their squares is
        # c' (sum of the spans' outer products) c.
        c = np.array([mean_v * mean_e + lag * mean_v * mean_v, -mean_v,
                      -mean_e - 2.0 * lag * mean_v, 1.0, lag])
        squares = max(float(c @ outer @ c), 0.0)
        error = max(error, float(np.sqrt(spans / (spans - 1.0) * squares)) / vv)
        return float(lag), float(error), float(mean_e + lag * mean_v)

    def lag_untold(self) -> str | None:
        """Why `detection_lag_s` tells no lag, or None where it tells one or nothing matched."""
        n = self._lag[0, 5]
        if n == 0 or self.detection_lag_s() is not None:
            return None
        spans = self._lag_spans + (self._lag_span is not None)
        if n < LAG_MIN_CYCLES:
            return (f"{int(n)} matched target-cycles judged against one frame, fewer than "
                    f"{LAG_MIN_CYCLES}")
        if spans < LAG_MIN_BINS:
            return (f"the matched target-cycles span {spans} of {LAG_BIN_S:g} s, fewer than "
                    f"{LAG_MIN_BINS}")
        fits = [fit for fit in self._lag_fits() if fit is not None]
        if fits:
            lag, _, offset = min(fits, key=lambda fit: abs(fit[2]))
            return (f"the targets' range rates varied too little: the lag that fits, "
                    f"{lag * 1e3:.1f} ms, needs a range offset of {offset:.3g} m, beyond "
                    f"the {GATE:g} x {self.expectations.tolerances['range_m']:g} m range gate "
                    f"of the detections it was told from")
        return "the targets' range rates did not vary: a lag would look like a range offset"

    def lag_reason(self, frame_s: float, coupling_s: float = 0.0) -> str | None:
        """Why the detections' lag fails the run (`detection_lag_s`), or None.

        Judged about ``coupling_s``, the lag the radar's range-Doppler coupling gives its
        ranges (`RadarProfile.coupling_lag_s`): beyond `LAG_FRAMES` of the scene's frame
        period ``frame_s``, three standard errors clear, most cycles were judged against
        frames the radar had not seen.
        """
        lag = self.detection_lag_s(coupling_s)
        if lag is None:
            return None
        off = lag[0] - coupling_s
        if abs(off) - 3.0 * lag[1] <= LAG_FRAMES * frame_s:
            return None
        when = "before" if lag[0] > 0 else "after"
        coupling = (f", {abs(off) * 1e3:.1f} ms {'before' if off > 0 else 'after'} beyond the "
                    f"{coupling_s * 1e3:+.1f} ms its range-Doppler coupling gives"
                    if coupling_s else "")
        return (f"time_alignment: the detections fit the scene {abs(lag[0]) * 1e3:.1f} ms "
                f"(+-{3e3 * lag[1]:.1f} ms) {when} the times the check took for the radar's "
                f"cycles{coupling}, more than {LAG_FRAMES:g} of a {frame_s * 1e3:g} ms frame: "
                f"most cycles were judged against frames the radar had not seen; the radar's "
                f"latency or phase is not its profile's (clock.latency_s, start_offset_s), or "
                f"the RTS applied frames {'later' if off > 0 else 'earlier'} than the run "
                f"knows")

    def _write_detections(self, got: list[Detections], counts: list[int], block: _Block,
                          frame_of: NDArray[np.int64], match: NDArray[np.int64],
                          use_other: BoolArray) -> None:
        """One CSV row per detection (`DETECTION_COLUMNS`); the target it was assigned to.

        Beside it the target's ground truth in the frame its cycle was judged against (the
        frame across a change where ``use_other`` says so); empty for a false detection.
        """
        assert self._csv is not None
        cycle = np.repeat([c.cycle for c in got], counts)
        # The radar's measurement time; the frame's time where the radar gives none.
        t_s = np.repeat([np.nan if c.t_s is None else c.t_s for c in got], counts)
        t_s = np.where(np.isnan(t_s), block.tracks.t_s[frame_of], t_s)
        columns: list[Any] = [[self.scene] * frame_of.size, cycle.tolist(),
                              np.round(t_s, 6).tolist()]
        for q in ("range_m", "radial_velocity_mps", "az_deg", "el_deg", "snr_db", "rcs_dbsm"):
            values = np.concatenate([getattr(c, q) if getattr(c, q) is not None
                                     else np.full(c.count, np.nan) for c in got])
            columns.append(["" if np.isnan(v) else f"{v:.6g}" for v in values.tolist()])
        names = np.array(("", *self.names), dtype=object)
        columns.append(names[match + 1].tolist())
        columns.append([self.variant] * frame_of.size)
        columns.append([self.file] * frame_of.size)
        assigned = match >= 0
        k = np.where(assigned, match, 0)
        across = use_other[frame_of] if block.other is not None else np.zeros(k.size, bool)
        for q in _TRUTH_COLUMNS:
            values = getattr(block.tracks, q)[frame_of, k]
            if block.other is not None:
                values = np.where(across, getattr(block.other[0], q)[frame_of, k], values)
            columns.append(["" if not a or np.isnan(v) else f"{v:.6g}"
                            for a, v in zip(assigned.tolist(), values.tolist(), strict=True)])
        self._csv.writerows(zip(*columns, strict=True))

    def _keep_worst(self, block: _Block, truth: BoolArray, assigned: BoolArray,
                    errors: dict[str, FloatArray]) -> None:
        """Keep the `WORST_FRAMES` worst target-frames: misses first, then error/tolerance.

        ``truth``: the target-frames judged (checkable, and their cycle received).
        """
        tol = self.expectations.tolerances
        score = np.zeros(truth.shape)
        for q, key in QUANTITIES[:4]:
            score = np.fmax(score, np.abs(errors[q]) / tol[key])
        score = np.where(truth & ~assigned, np.inf, score)
        score = np.where(truth, score, -1.0)
        top = np.argsort(-score, axis=None)[:WORST_FRAMES]
        for flat in top:  # at most WORST_FRAMES per block
            f, k = np.unravel_index(flat, score.shape)
            if score[f, k] < 0:
                break
            entry = {"frame": block.first + int(f), "t_s": float(block.tracks.t_s[f]),
                     "target": self.names[k], "missed": bool(not assigned[f, k]),
                     **{q: float(errors[q][f, k]) for q, _ in QUANTITIES}}
            item = (float(score[f, k]), -(block.first + int(f)), -int(k), entry)
            if len(self._worst) < WORST_FRAMES:
                heapq.heappush(self._worst, item)
            elif item[:3] > self._worst[0][:3]:
                heapq.heapreplace(self._worst, item)

    def _add_held(self, judged: _Judged, invalid: BoolArray) -> None:
        """Count a block judged against the frames held alone (see ``_checkable_held``)."""
        self._checkable_held += judged.truth.sum(axis=0)
        self._detected_held += (judged.assigned & judged.within & judged.truth).sum(axis=0)
        self._false_held += int(((judged.match < 0) & ~invalid).sum())

    def _adjacent_frame(self, targets: list[TargetResult], per_frame: float) -> str | None:
        """Why the verdict rests on cycles judged against the frame across a change, or None.

        Where no target's detection rate nor the false detections would fail against the
        frames held alone, it does not; nor where the cycles at a change went both ways (a
        race: fewer than the detection rate's share of them across). Only the changes whose
        two frames differ by more than a tolerance count there, and those judged across
        (`_ambiguous_apart`): where neither (a target standing, or slow), the frame held
        passes whatever the radar showed. Otherwise the radar showed the frame across (nearly)
        every change that tells, and cannot be told from one whose ranges are off by the
        targets' travel in a frame (a delay, an RTS latency): with such an offset, the cycles
        at those changes that stay with the frame held are out of tolerance, so a pass needs
        about the detection rate's share of them across. The run then passes only where the
        scene declares it.
        """
        adjacent, apart = self.frames["adjacent_frame"], self._ambiguous_apart
        exp = self.expectations
        if not adjacent or adjacent < exp.detection_rate * apart:
            return None
        fails = []
        for k, t in enumerate(targets):
            n_check, n_det = int(self._checkable_held[k]), int(self._detected_held[k])
            if t.passed and n_check and n_det / n_check < exp.detection_rate - 1e-12:
                fails.append(f"{t.name} detection rate {n_det / n_check:.1%}")
        held_per_frame = self._false_held / max(self.frames["received"], 1)
        if (per_frame <= exp.max_false_detections_per_frame
                < held_per_frame):
            fails.append(f"{held_per_frame:.3f} false detections per radar cycle")
        if not fails:
            return None
        return (f"the verdict rests on radar cycles judged against the frame across a change "
                f"({adjacent} of the {apart} measured at one whose frames differ by more than "
                f"a tolerance or matched the frame across better): against the frames held "
                f"alone, "
                + ", ".join(fails) + "; a radar that shows the frame across each change and "
                f"one whose ranges are off by the targets' travel in a frame (up to "
                f"{self._adjacent_travel_m:.2f} m here: a delay, an RTS latency) look alike "
                f"(list adjacent_frame in expected_limits where the bench's race between a "
                f"frame change and the radar's measurement is known)")

    def report(self, bus: dict[str, int] | None = None,
               unsendable_reason: str | None = None) -> Report:
        """Return the verdict so far (call `settle` first); ``bus``: the transport's counters.

        ``unsendable_reason``: why the simulated radar left detections out
        (`DetectionPublisher.unsendable_reason`), said with ``bus["unsendable_detections"]``.
        """
        exp = self.expectations
        limits = self._limits if self._frames_given else self._limits_seen
        targets = []
        limit_reasons = []
        for k, name in enumerate(self.names):  # one summary row per target
            n_check, n_det = int(self._checkable[k]), int(self._detected[k])
            rate = n_det / n_check if n_check else float("nan")
            unmeasured = n_check == 0 and self._played[k] > 0
            hit = {lim: int(c[k]) for lim, c in limits.items() if c[k]}
            unexpected = [lim for lim in hit if lim not in self._expected[k]]
            if unexpected:
                limit_reasons.append(FailReason(
                    f"{name}: target-frames not played or not measurable as specified: "
                    + ", ".join(f"{lim} {hit[lim]}" for lim in unexpected)
                    + " (list them in expected_limits if the scene means it)", *unexpected))
            targets.append(TargetResult(
                name=name, checkable_frames=n_check, detected_frames=n_det, detection_rate=rate,
                errors={q: self._stats[q].result(k) for q, _ in QUANTITIES},
                passed=((n_check == 0 or rate >= exp.detection_rate - 1e-12) and not unexpected
                        and not unmeasured),
                out_of_tolerance_frames=int(self._out_of_tolerance[k]),
                missed_frames=int(self._missed[k]), unchecked_frames=int(self._unchecked_k[k]),
                limits=hit, unexpected_limits=unexpected, played_frames=int(self._played[k])))
        frames = self.frames
        per_frame = self._false / max(frames["received"], 1)
        scene_limits = dict(self._scene_limits)
        adjacent = self._adjacent_frame(targets, per_frame)
        if adjacent is not None:
            scene_limits["adjacent_frame"] = adjacent
        not_checked = dict(self._not_checked or {})
        at_end = self._quantities_at_end()
        not_checked.update({key: why for key, (_, why) in at_end.items()})
        # An empty bench checks false detections alone: no tolerance of it is meant checked.
        unchecked_why = _quantity_unchecked(exp, not_checked) if self.names else None
        if unchecked_why is not None:
            scene_limits["quantity_unchecked"] = unchecked_why
        reasons: list[str] = [FailReason(f"{lim}: {why}", lim)
                              for lim, why in scene_limits.items()
                              if lim not in exp.expected_limits]
        reasons += [FailReason(f"{t.name}: detection rate {t.detection_rate:.1%} < "
                               f"{exp.detection_rate:.1%}" + _beyond_tolerance(t, exp),
                               "detection_rate") for t in targets
                    if t.checkable_frames and t.detection_rate < exp.detection_rate - 1e-12]
        reasons += limit_reasons
        reasons += [FailReason(f"{t.name}: never checked: no radar cycle measured the "
                               + (f"{t.played_frames} frames" if t.played_frames > 1
                                  else "frame")
                               + " it was played in", "never_checked") for t in targets
                    if t.played_frames and not t.checkable_frames]
        if per_frame > exp.max_false_detections_per_frame:
            reasons.append(FailReason(f"{per_frame:.3f} false detections per radar cycle > "
                                      f"{exp.max_false_detections_per_frame:g}",
                                      "false_detections"))
        if self._invalid:
            reasons.append(FailReason(f"{self._invalid} detections with a reported quantity "
                                      f"that is not a number (NaN or infinite): they match no "
                                      f"target", "invalid_detections"))
        out_of_count = self.out_of_count_reason()
        if out_of_count:
            reasons.append(FailReason(out_of_count, "foreign_cycles"))
        if frames["missing"] or frames["incomplete"]:
            # A cycle with no checkable target still had its false detections to check.
            reasons.append(FailReason(f"{frames['missing']} radar cycles missing and "
                                      f"{frames['incomplete']} incomplete: {self._unchecked} "
                                      f"target-cycles and the cycles' false detections could "
                                      f"not be checked", "missing_cycles"))
        if bus is not None:
            if bus.get("messages", 0) == 0:
                reasons.append(FailReason("the bus was silent: no message received",
                                          "bus_silent"))
            # Each with its code: the bus counter's name.
            lost = {"checksum_errors": "checksum errors",
                    "decode_errors": "undecodable messages",
                    "orphans": "detections without a frame header",
                    "conflicts": "conflicting messages (a cycle's header or detections came "
                                 "again with other values, or beyond the count its header "
                                 "announced)",
                    "unsendable_detections": "detections the radar could not put on the bus"
                                             + (f": {unsendable_reason}" if unsendable_reason
                                                else " (a value its protocol's signals cannot "
                                                     "carry, or past the detections per cycle "
                                                     "its index or count numbers)")}
            reasons += [FailReason(f"{bus[key]} {what}", key) for key, what in lost.items()
                        if bus.get(key, 0)]
        n_truth = int(self._checkable.sum())
        if not self.names:  # an empty bench: only false detections are checked
            if frames["received"] == 0:
                reasons.append(FailReason("nothing to check: no radar cycle was received",
                                          "nothing_checked"))
        elif n_truth == 0:
            reasons.append(FailReason("nothing to check: no target was checkable in any frame",
                                      "nothing_checked"))
        worst = [entry for *_, entry in sorted(self._worst, key=lambda w: w[:3], reverse=True)]
        # Limits the scene declares for its targets that none hit (a scene meant to test an
        # edge of the bench may not reach it): said, not failed.
        declared = [lim for lim in exp.expected_limits if lim not in SCENE_LIMITS
                    and not any(lim in t.limits for t in targets)]
        if self._scene_limits_known:
            declared += [lim for lim in PLANNED_SCENE_LIMITS
                         if lim in exp.expected_limits and lim not in self._scene_limits]
        if "adjacent_frame" in exp.expected_limits and adjacent is None:
            declared.append("adjacent_frame")
        if (self._not_checked is not None and "quantity_unchecked" in exp.expected_limits
                and unchecked_why is None):
            declared.append("quantity_unchecked")
        own = [f"{t.name}: {lim}" for k, t in enumerate(targets)
               for lim in sorted(self._expected[k] - exp.expected_limits)
               if lim not in t.limits]
        return Report(
            scene=self.scene, passed=not reasons, reasons=reasons,
            frames=dict(frames),
            targets=targets, errors={q: self._stats[q].result() for q, _ in QUANTITIES},
            detection_rate=float(self._detected.sum() / n_truth) if n_truth else float("nan"),
            false_detections=self._false, false_detections_per_frame=per_frame,
            invalid_detections=self._invalid, folded_detections=self._folded,
            bus=dict(bus or {}),
            target_frames={"checkable": n_truth, "matched": self._matched,
                           "unmatched": n_truth - self._matched - self._unchecked,
                           "unchecked": self._unchecked, "detected": int(self._detected.sum())},
            scene_limits={name: {"why": why, "expected": name in exp.expected_limits}
                          for name, why in scene_limits.items()},
            variant=self.variant, parameters=dict(self.parameters),
            expected_not_hit=sorted(declared) + own, worst_frames=worst, record=self.record,
            expectations={"tolerances": dict(exp.tolerances),
                          "detection_rate": exp.detection_rate,
                          "max_false_detections_per_frame":
                              exp.max_false_detections_per_frame},
            unchecked_quantities={key: {"why": why, "tolerance": exp.tolerances[key],
                                        "written": key in exp.tolerances_written,
                                        "target_cycles": at_end[key][0] if key in at_end
                                        else None}
                                  for key, why in not_checked.items()})

    def _quantities_at_end(self) -> dict[str, tuple[int, str]]:
        """Tolerance key -> (target-cycles, why) of quantities reported at a signal's end.

        Those matched target-cycles whose detection reported the quantity at its signal's
        end, the truth beyond it (`limits`): not checked.
        """
        out = {}
        for q, key in QUANTITIES:
            n = self._at_end.get(q, 0)
            if n:
                low, high, _, signal = self._ends[q]
                unit = _UNITS[q]
                out[key] = (n, f"in {n} of {self._matched} matched target-cycles, reported "
                               f"at the end of signal {signal!r} of mapping "
                               f"{self._mapping_name!r} ({low:g} to {high:g} {unit}) with the "
                               f"truth beyond it")
        return out


def _status_flags(status: ArrayLike, tracks: Tracks) -> NDArray[np.uint16]:
    """Return the `Status` flags of a truth block, checked: (frames, targets) integers.

    Booleans (e.g. ``Schedule.emitted``) or another shape would silently read as other flags.
    """
    out = np.asarray(status)
    shape = tracks.range_m.shape
    if out.dtype.kind not in "ui" or out.shape != shape:
        raise CheckError(
            f"status: must be the schedule's Status flags (Schedule.status, unsigned integers "
            f"of shape {shape}: frames x targets), got {out.dtype} of shape {out.shape}"
        )
    return out.astype(np.uint16, copy=False)


def check_cycles(scene: str, tracks: Tracks, status: NDArray[np.uint16],
                 cycles: Iterable[Detections], expectations: Expectations, *,
                 bus: dict[str, int] | None = None, counter_modulus: int = COUNTER_MODULUS,
                 expected_limits: Sequence[frozenset[str]] | None = None) -> Report:
    """Check radar cycles against the ground truth of a whole scene at once.

    Parameters
    ----------
    scene : str
        Scene name, for the report.
    tracks : Tracks
        Ground truth, (F, K), frame 0 first.
    status : ndarray of uint16, shape (F, K)
        The schedule's `rts_scenario.schedule.Status` of every target-frame (what the RTS
        played, and every limit it hit).
    cycles : iterable of Detections
        The radar's cycles (counter = scene frame index, possibly wrapped).
    expectations : Expectations
        Tolerances and required rates.
    bus : dict, optional
        The transport's counters (`rts_scenario.canbus.BusStats` as a dict).
    expected_limits : sequence of frozenset, optional
        Per target, limits expected besides the scene's.
    """
    checker = Checker(scene, tracks.names, expectations, counter_modulus=counter_modulus,
                      expected_limits=expected_limits)
    checker.add_truth(0, tracks, status)
    checker.add_frames(tracks, status)
    checker.add_cycles(cycles)
    checker.settle()
    return checker.report(bus)


def _range_candidates(frame_of: NDArray[np.int64], range_m: FloatArray, truth_range: FloatArray,
                      gate_m: float) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Pairs (detection, target) of one frame whose ranges are at most ``gate_m`` apart.

    The targets of each frame are sorted by range once; each detection takes the run of them
    within its gate (a detection without a range takes every target of its frame). The cost is
    the detections and targets times a logarithm, plus the pairs found.
    """
    n_frames, n_targets = truth_range.shape
    if frame_of.size == 0 or n_targets == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    order = np.argsort(truth_range, axis=1, kind="stable")  # targets by range, per frame
    ranges = np.take_along_axis(truth_range, order, axis=1)
    # One sorted key over all frames: frame f's ranges shifted past every earlier frame's.
    finite = np.isfinite(ranges)
    span = float(np.abs(ranges[finite]).max() if finite.any() else 0.0) + gate_m + 1.0
    key = (np.arange(n_frames)[:, None] * (4.0 * span) + np.where(finite, ranges, 2.0 * span)
           ).ravel()
    base = frame_of * (4.0 * span)
    slack = 1e-9 * span  # rounding of the key; the gate itself is checked exactly after
    has = np.isfinite(range_m)
    low = np.where(has, base + range_m - gate_m - slack, base - span)
    high = np.where(has, base + range_m + gate_m + slack, base + 3.0 * span)
    lo = np.searchsorted(key, low, side="left")
    hi = np.searchsorted(key, high, side="right")
    n = hi - lo
    det = np.repeat(np.arange(frame_of.size), n)
    pos = np.repeat(lo - np.cumsum(n) + n, n) + np.arange(n.sum())
    return det, order.reshape(-1)[pos]


def _assign(frame_of: NDArray[np.int64], det: NDArray[np.int64], target: NDArray[np.int64],
            cost: FloatArray, n_targets: int) -> NDArray[np.int64]:
    """Pairs kept by the optimal assignment per frame (indices into the candidate pairs).

    Where a detection has one candidate and that target-frame one detection (the usual case),
    that pair is the answer; groups with a choice (connected detections and targets) go to the
    Hungarian method, each on its own small matrix.
    """
    keep = np.zeros(det.size, dtype=bool)
    if det.size == 0:
        return np.flatnonzero(keep)
    slot = frame_of[det] * n_targets + target  # the target-frame of each pair
    per_det = np.bincount(det, minlength=frame_of.size)
    _, slot_of, per_slot = np.unique(slot, return_inverse=True, return_counts=True)
    simple = (per_det[det] == 1) & (per_slot[slot_of] == 1)
    keep[simple] = True
    hard = np.flatnonzero(~simple)
    if hard.size:
        # scipy only here: any of its modules costs a command about a quarter of a second
        # to import (tests/test_startup.py), and most runs have no choice to make.
        from scipy.optimize import linear_sum_assignment
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        # Connected groups of detections and target-frames among the pairs with a choice.
        dets, d_of = np.unique(det[hard], return_inverse=True)
        slots, s_of = np.unique(slot_of[hard], return_inverse=True)
        graph = coo_matrix((np.ones(hard.size), (d_of, dets.size + s_of)),
                           shape=(dets.size + slots.size,) * 2)
        _, group = connected_components(graph, directed=False)
        by_group = np.argsort(group[d_of], kind="stable")
        bounds = np.flatnonzero(np.diff(group[d_of][by_group])) + 1
        for members in np.split(hard[by_group], bounds):  # a few small groups
            rows, r_of = np.unique(det[members], return_inverse=True)
            cols, c_of = np.unique(slot[members], return_inverse=True)
            c = np.full((rows.size, cols.size), 1e9)
            c[r_of, c_of] = cost[members]
            where = np.full((rows.size, cols.size), -1)
            where[r_of, c_of] = members
            r, k = linear_sum_assignment(c)
            chosen = where[r, k]
            keep[chosen[chosen >= 0]] = True
    return np.flatnonzero(keep)
