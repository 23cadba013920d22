"""Re-check a recorded CAN log against a scene: offline, aligned by time.

A log recorded by ``rts-scenario run --record LOG`` has a sidecar (``LOG.rts.json``,
`rts_scenario.pipeline.write_log_sidecar`) with the radar's clock: its counters name the cycles
exactly as they did live, so the re-check gives the live verdict. A log recorded by any other
tool has only timestamps. Then the cycles are numbered from their counters (gaps are missing
cycles), the radar's cycle time is fitted to the header timestamps, and the scene time of the
log is ``log time - latency - offset``: ``offset`` (the log time of the scene's time 0) is given
(``--time-offset-s``) or estimated by matching the detections to the ground truth over
candidate offsets. The estimate and its uncertainty are reported. Either way the scene's whole
time counts: cycles the radar measured before the log's first one or after its last are
missing.

The ground truth is rebuilt from the scene; a sidecar's checksums of the truth the run played
(`rts_scenario.recording`) fail a re-check against a scene edited since. Which target played in
which frame is the sidecar's record of the statuses the RTS played; without it (a log of another
tool, an older sidecar) the schedule is rebuilt by the same solver as live, and an older
sidecar's digest of the statuses tells whether the rebuilt schedule plays the same.
"""

from __future__ import annotations

import gc
import glob
import hashlib
import io
import json
import locale
import logging
import re
import struct
import sys
from array import array
from collections import Counter
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import can
import jsonschema
import numpy as np
from numpy.typing import NDArray

from . import mf4
from .canbus import DetectionReceiver, channel_label, mapping_reason, with_mapping_hint
from .canbus.mapping import CanMapping
from .check import Checker
from .detections import Detections, sequential_numbers
from .errors import RtsError, ScenarioError
from .file_kinds import identify
from .kinematics import Tracks, compute_tracks
from .located_yaml import load_yaml
from .pipeline import (
    BUS_CLOCK_SLACK_S,
    LOG_SIDECAR_SUFFIX,
    RECEIPT_OFF_S,
    CycleTruth,
    after_scene_until_s,
    ambiguity_window_s,
    judge_crowded_analytic,
    judge_empty_bench,
    lag_dict,
)
from .playback import (
    SEND_LATENESS_ENCODING,
    playback_limits,
    playback_not_hit,
    playback_reasons,
    unpack_send_lateness,
)
from .preflight import preflight, scene_limits, schedule_batches, track_batches
from .radar.clock import (
    CLOCK_TOLERANCE_PPM,
    DRIFT_FLOOR_S,
    MIN_CYCLE_S,
    STAMP_NOISE_S,
    TIME_EPS_S,
    ClockTrack,
    CycleTimeFit,
    RadarClock,
    late_start_reason,
    late_start_s,
)
from .radar.clock import (
    MAX_LATENCY_S as MAX_CLOCK_LATENCY_S,
)
from .recording import STATUS_ENCODING, StatusRecord, TruthChecksums
from .report import FailReason, Report
from .scenario import Scenario, parametrizations, select_variant
from .solver.estimator_aware import SCHEDULE_METHODS

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

# Log formats python-can reads (``can.LogReader``), by extension.
LOG_SUFFIXES = (".asc", ".blf", ".csv", ".db", ".log", ".mf4", ".trc")
# Coarse offset search: step (s), cycles it prices at most; beyond FULL_SEARCH_S of candidate
# offsets, only those within ONSET_WINDOW_S of where the first detections put the scene.
COARSE_STEP_S = 0.01
COARSE_CYCLES = 300
# Cycles an offset is estimated on at most (evenly spread over a longer log): an hour at 20 Hz
# holds 72,000; the fine search's cost is a mean over their detections.
ALIGN_CYCLES = 20_000
FULL_SEARCH_S = 300.0
ONSET_WINDOW_S = 30.0
# Fine search: from this before the coarse minima to this after them, in steps of FINE_STEP_S
# (coarser where the minima span more than MAX_FINE_POINTS steps).
FINE_SPAN_S = 0.05
FINE_STEP_S = 0.001
MAX_FINE_POINTS = 2000
# The edges of the best offsets are found to this (log timestamps carry microseconds) and the
# estimate kept this far inside them, so that no cycle sits on a frame change by rounding.
EDGE_RESOLUTION_S = 1e-6
EDGE_GUARD_S = 1e-5
# Longest latency a given --time-offset-s may imply (s): a radar reports within a cycle or a
# few; seconds mean the offset is in another time base than the log's.
MAX_LATENCY_S = 5.0
# A cycle measured this close before the scene's time 0 counts as measured at it.
START_TOLERANCE_S = 1e-5
# Timestamps of a log that go back this far from one radar cycle to the next are a clock set
# back while it logged: the log cannot be aligned by them (s).
STAMPS_BACK_S = 1.0
# Fitting the radar's cycle time, a stamp this far off the line (or five times the stamps'
# spread, if more) is a cycle held up on the bus and left out.
FIT_OUTLIER_FLOOR_S = 0.001
# Resamplings for the uncertainty of an estimated offset.
BOOTSTRAP_ROUNDS = 30
# A detection farther than this (normalized by the tolerances) from every target counts this.
GATE2 = 9.0
# A second offset matching this share of what the best one matches, a scene's length away: the
# log holds the scene played again (`estimate_offset`).
REPEAT_MATCH = 0.3
# Detections a start must match that the scene's last frame, held, does not, to be a play
# again (`_held_after`): one (a still scene held matches none such; a target crossing for a
# few cycles among parked ones may be seen in one).
HELD_EXTRA = 1


class LogError(RtsError):
    """A log that cannot be read or re-checked."""


@dataclass
class Alignment:
    """How the log's cycles were placed in scene time."""

    source: str  # "sidecar", "given" or "estimated"
    cycle_s: float
    offset_s: float | None = None
    uncertainty_s: float | None = None
    plateau_s: float | None = None  # offsets up to this much earlier fit the data as well
    latency_s: float = 0.0
    # "profile", "sidecar" (the run's, as recorded) or "estimated" (the offset given, the
    # latency not)
    latency_source: str = "profile"
    latency_uncertainty_s: float | None = None
    # Where ``cycle_s`` came from: "sidecar" (the run's), "fitted" (to the log's timestamps)
    # or "profile" (kept: the timestamps could not tell a cycle apart from the profile's).
    cycle_source: str = "sidecar"
    cycles_in_log: int = 0
    cycles_outside_scene: int = 0
    schedule_matches_recording: bool | None = None
    # Whether the scene's ground truth is the one the run played (its sidecar's checksums).
    truth_matches_recording: bool | None = None
    # The statuses judged by: "recorded" (the sidecar's, as played) or "rebuilt".
    statuses: str = "rebuilt"
    notes: list[str] = field(default_factory=list)
    # How the log was cut short, where its format tells (`log_cut_short`); None: it was not.
    log_cut_short: dict[str, Any] | None = None
    # Records of a text log python-can's reader passes over (`_Unread.summary`); None: none.
    log_unread: dict[str, Any] | None = None

    def describe(self) -> str:
        """One line for people."""
        if self.source == "sidecar":
            text = (f"aligned by the recording's sidecar: counters name the cycles "
                    f"({self.cycle_s * 1e3:.1f} ms cycle)")
        else:
            how = "given" if self.source == "given" else "estimated"
            pm = (f" +- {self.uncertainty_s * 1e3:.1f} ms" if self.uncertainty_s is not None
                  else "")
            plateau_s = self.plateau_s or 0.0
            flat = plateau_s >= FINE_STEP_S
            if flat and self.latency_source != "estimated":
                pm += (f"; the data fit as well up to {plateau_s * 1e3:.1f} ms earlier, "
                       f"the latest is taken")
            if self.latency_source == "estimated":
                lat = (f"latency {self.latency_s * 1e3:.1f} ms estimated"
                       + (f" +- {self.latency_uncertainty_s * 1e3:.1f} ms"
                          if self.latency_uncertainty_s is not None else ""))
                if flat:
                    lat += (f" (the data fit as well up to {plateau_s * 1e3:.1f} ms "
                            f"shorter, the longest is taken)")
            else:
                lat = f"latency {self.latency_s * 1e3:.0f} ms (profile)"
            cycle = (f"cycle {self.cycle_s * 1e3:.2f} ms fitted" if self.cycle_source == "fitted"
                     else f"cycle {self.cycle_s * 1e3:.2f} ms (profile; the timestamps cannot "
                     f"tell another)")
            text = (f"aligned by timestamps: scene time 0 at log time {self.offset_s:.6f} s "
                    f"({how}{pm}), {lat}, {cycle}")
        text += f"; {self.cycles_in_log} cycles in the log"
        if self.cycles_outside_scene:
            text += f", {self.cycles_outside_scene} outside the scene"
        return text

    def to_dict(self) -> dict[str, Any]:
        """Plain data for JSON."""
        return {"source": self.source, "cycle_s": self.cycle_s, "offset_s": self.offset_s,
                "uncertainty_s": self.uncertainty_s, "plateau_s": self.plateau_s,
                "latency_s": self.latency_s,
                "latency_source": self.latency_source,
                "latency_uncertainty_s": self.latency_uncertainty_s,
                "cycle_source": self.cycle_source,
                "cycles_in_log": self.cycles_in_log,
                "cycles_outside_scene": self.cycles_outside_scene,
                "schedule_matches_recording": self.schedule_matches_recording,
                "truth_matches_recording": self.truth_matches_recording,
                "statuses": self.statuses,
                "log_cut_short": None if self.log_cut_short is None else {
                    k: v for k, v in self.log_cut_short.items() if k != "why"},
                "log_unread": self.log_unread,
                "notes": list(self.notes)}


@dataclass
class RecheckResult:
    """The verdict on a recorded log and how its cycles were aligned."""

    scene: Scenario
    report: Report
    alignment: Alignment
    mapping: CanMapping | None = None  # the one the log was read with


@dataclass(frozen=True)
class RecordedClock(RadarClock):
    """The radar's clock a recorded run ended with (its sidecar's ``clock``).

    Its cycle 0 is the scene's first as the run took it, measured at ``start_offset_s``:
    negative where the run took a cycle measured within its clock's uncertainty before the
    scene's start as the scene's first (it may have measured at the start itself). Sidecars of
    older versions kept that time clamped at 0.
    """

    def __post_init__(self) -> None:
        if not (np.isfinite(self.start_offset_s) and self.start_offset_s > -self.cycle_s):
            raise ValueError(f"clock.start_offset_s: must lie within a cycle before the scene's "
                             f"start, got {self.start_offset_s!r}")
        RadarClock(cycle_s=self.cycle_s, start_offset_s=max(0.0, self.start_offset_s),
                   latency_s=self.latency_s, jitter_s=self.jitter_s,
                   counter_start=self.counter_start)

    @property
    def start_tolerance_s(self) -> float:
        """How far before the scene's start its first cycle lies: cycle 0 is the first."""
        return max(0.0, -self.start_offset_s)


@dataclass
class _LoggedCycle:
    detections: Detections
    bus_t_s: float


# The largest bus time or clock step a sidecar may hold (s): about 300 years.
_BUS_SPAN_S = 1e10


def _number(**bounds: float) -> dict[str, Any]:
    return {"type": "number", **bounds}


# What `run --record` writes beside a log (`pipeline.write_sidecar`); read back by `check`.
SIDECAR_SCHEMA: dict[str, Any] = {
    "type": "object",
    "required": ["rts_scenario_log", "clock"],
    "properties": {
        "rts_scenario_log": {"const": 1},
        "version": {"type": "string"},
        "scene": {"type": "string"},
        "variant": {"type": ["string", "null"]},
        "parameters": {"type": "object"},
        "frames": {"type": "integer", "minimum": 0},
        "frame_rate_hz": _number(exclusiveMinimum=0),
        "radar": {"type": "string"},
        "rig": {"type": "object", "required": ["name", "sha256"], "properties": {
            "name": {"type": "string"},
            "sha256": {"type": "string", "pattern": "^[0-9a-f]{64}$"}}},
        "clock": {
            "type": "object",
            "required": ["cycle_s", "start_offset_s", "latency_s", "jitter_s", "counter_start"],
            "properties": {
                "cycle_s": _number(minimum=MIN_CYCLE_S),
                # Signed (older versions wrote it clamped at 0): within a cycle of the start.
                "start_offset_s": _number(),
                "latency_s": _number(minimum=0, maximum=MAX_CLOCK_LATENCY_S),
                "jitter_s": _number(minimum=0, maximum=MAX_CLOCK_LATENCY_S),
                "counter_start": {"type": ["integer", "null"], "minimum": 0},
                "cycles": {"type": ["integer", "null"], "minimum": 0},
                # Bus times and clock steps within a few centuries of the epoch (a float's
                # millisecond still counts there).
                "origin_bus_s": {"type": ["number", "null"], "minimum": -_BUS_SPAN_S,
                                 "maximum": _BUS_SPAN_S},
                # A delivery delay: beyond RECEIPT_OFF_S receipts are no deliveries.
                "early_s": _number(minimum=0, maximum=RECEIPT_OFF_S),
                # The host's clock steps the run saw, and where they moved the log's stamps.
                "host_clock_steps": {"type": "array", "items": {
                    "type": "object", "required": ["at_s", "within_s", "size_s", "corrected"],
                    "properties": {"at_s": _number(), "within_s": _number(minimum=0),
                                   "size_s": _number(minimum=-_BUS_SPAN_S,
                                                     maximum=_BUS_SPAN_S),
                                   "corrected": {"type": "string"}}}},
                "bus_time_shifts": {"type": "array", "items": {
                    "type": "object", "required": ["bus_s", "counter", "shift_s"],
                    "properties": {"bus_s": _number(minimum=-_BUS_SPAN_S,
                                                    maximum=_BUS_SPAN_S),
                                   "counter": {"type": "integer", "minimum": 0},
                                   "shift_s": _number(minimum=-_BUS_SPAN_S,
                                                      maximum=_BUS_SPAN_S)}}},
            },
        },
        "mapping": {"type": ["string", "null"]},
        "mapping_sha256": {"type": ["string", "null"], "pattern": "^[0-9a-f]{64}$"},
        # The bus the run listened on (python-can's interface and channel).
        "can_interface": {"type": ["string", "null"]},
        "can_channel": {"type": ["string", "null"]},
        "can_channel_named": {"type": ["boolean", "null"]},
        "radar_channel": {"type": ["string", "null"]},
        "can_fd": {"type": "boolean"},
        "method": {"type": ["string", "null"]},
        "output": {"type": ["string", "null"]},
        "status_sha256": {"type": ["string", "null"]},
        # Per target, a checksum of the ground truth the run judged by (`TruthChecksums`).
        "truth": {
            "type": ["object", "null"],
            "required": ["encoding", "quanta", "targets"],
            "properties": {
                "encoding": {"type": "string"}, "quanta": {"type": "object"},
                "targets": {"type": "object", "additionalProperties": {
                    "type": "string", "pattern": "^[0-9a-f]{16}$"}},
            },
        },
        # The statuses the RTS played (`StatusRecorder`): the re-check judges by them.
        "statuses": {
            "type": ["object", "null"],
            "required": ["frames", "targets", "encoding", "data"],
            "properties": {"frames": {"type": "integer", "minimum": 0},
                           "targets": {"type": "integer", "minimum": 0},
                           "names": {"type": "array", "items": {"type": "string"}},
                           "encoding": {"const": STATUS_ENCODING},
                           "data": {"type": "string"}},
        },
        # The run's playback (`Playback.to_dict`): a re-check fails on it as the run did.
        "playback": {
            "type": ["object", "null"],
            "required": ["frames_sent", "late_frames", "lateness_s", "late_after_s",
                         "ambiguity_window_s"],
            "properties": {
                "frames_sent": {"type": "integer", "minimum": 0},
                "late_frames": {"type": "integer", "minimum": 0},
                "lateness_s": {"type": "object", "required": ["max"],
                               "properties": {k: _number() for k in ("p50", "p95", "max")}},
                "late_after_s": _number(minimum=0), "ambiguity_window_s": _number(minimum=0),
                "rts": {"type": ["object", "null"],
                        "additionalProperties": {"type": "integer", "minimum": 0}},
                "rts_unreachable": {
                    "type": ["object", "null"],
                    "required": ["address", "datagrams", "error", "first_s", "last_s"],
                    "properties": {"address": {"type": "string"}, "error": {"type": "string"},
                                   "datagrams": {"type": "integer", "minimum": 1},
                                   "first_s": _number(), "last_s": _number()}},
            },
        },
        "send_lateness": {
            "type": ["object", "null"],
            "required": ["frames", "encoding", "data"],
            "properties": {"frames": {"type": "integer", "minimum": 0},
                           "encoding": {"const": SEND_LATENESS_ENCODING},
                           "data": {"type": "string"}},
        },
    },
}


def read_sidecar(log: str | Path) -> dict[str, Any] | None:
    """Return the ``LOG.rts.json`` of a log recorded by rts-scenario, None without one.

    Raises
    ------
    LogError
        The sidecar is not valid JSON, or not what ``run --record`` writes (`SIDECAR_SCHEMA`):
        the message names the file, the key and what is allowed.
    """
    path = Path(str(log) + LOG_SIDECAR_SUFFIX)
    if not path.exists():
        return None

    def finite_only(name: str) -> float:
        raise ValueError(f"{name} is not a number a sidecar holds")

    try:
        data = json.loads(path.read_text(encoding="utf-8"), parse_constant=finite_only)
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise LogError(f"{path}: not an rts-scenario log sidecar: {exc}") from None
    validator = jsonschema.Draft202012Validator(SIDECAR_SCHEMA)
    error = jsonschema.exceptions.best_match(validator.iter_errors(data))
    if error is not None:
        key = ".".join(str(k) for k in error.absolute_path) or "(the document)"
        raise LogError(f"{path}: {key}: {error.message} (not what `rts-scenario run --record` "
                       f"writes; a log without its sidecar is aligned by its timestamps)")
    method = data.get("method")
    if method is not None and method not in SCHEDULE_METHODS:
        raise LogError(f"{path}: method: got {method!r}; allowed values: "
                       f"{', '.join(SCHEDULE_METHODS)}")
    if data.get("statuses") is not None and data.get("truth") is None:
        # Written together: an older version's sidecar keeps neither, and one keeping the
        # statuses alone would leave the scene unchecked.
        raise LogError(f"{path}: truth: missing, but the sidecar keeps the statuses written "
                       f"with it (not what `rts-scenario run --record` writes; a log without "
                       f"its sidecar is aligned by its timestamps)")
    return dict(data)


def _yaml_data(path: Path) -> Any:
    """Return the data of a YAML file given as a log, to tell its kind by (``None``: none)."""
    if path.suffix.lower() not in (".yaml", ".yml"):
        return None
    try:
        return load_yaml(path).data
    except ScenarioError:
        return None


def check_log_file(log: str | Path) -> None:
    """Refuse a log of a format python-can does not read, or one that is not there."""
    path = Path(log)
    if path.is_dir():
        raise LogError(f"--log {log}: a folder, not a log file ({', '.join(LOG_SUFFIXES)})")
    if path.name.endswith(LOG_SIDECAR_SUFFIX) and path.name != LOG_SIDECAR_SUFFIX:
        recorded = str(log).removesuffix(LOG_SIDECAR_SUFFIX)
        raise LogError(f"--log {log} is the sidecar run --record wrote beside its log; give "
                       f"the log: --log {recorded}")
    if path.suffix.lower() not in LOG_SUFFIXES:
        kind = identify(log, _yaml_data(path)) if path.is_file() else None
        if kind is not None:
            what, evidence, _ = kind
            raise LogError(f"--log {log} is {what} ({evidence}), not a CAN log; check takes the "
                           f"scene as SCENE and, as --log, the log rts-scenario run --record "
                           f"wrote ({', '.join(LOG_SUFFIXES)})")
        raise LogError(f"--log {log}: unknown log format {path.suffix!r}; valid: "
                       f"{', '.join(LOG_SUFFIXES)}")
    if not path.is_file():
        # `run --record LOG` of a parametrized scene writes STEM[ID].SUFFIX per variant.
        variants = sorted(str(p) for p in path.parent.glob(
            f"{glob.escape(path.stem)}[[]*[]]{glob.escape(path.suffix)}") if p.is_file())
        beside = (f"; beside it, the logs run --record wrote for each variant of a "
                  f"parametrized scene: {', '.join(variants)}" if variants else "")
        raise LogError(f"--log {log}: no such file{beside}")
    if path.stat().st_size == 0:  # a recorder that never wrote, a copy that did not happen
        raise LogError(f"--log {log}: the file is empty (0 bytes): nothing was recorded in it")


def log_variant(scene: str | Path, log: str | Path,
                variant: str | None = None) -> tuple[str, dict[str, Any]]:
    """Return the combination ``(id, overrides)`` of the scene file that ``log`` records.

    A log records one run. ``variant`` (``--variant``) names it; otherwise the log's sidecar
    does (``run --record`` writes it). Given both, they must agree.

    Raises
    ------
    RtsError
        The scene is parametrized and neither says which variant the log is of, or the
        variant is not one of the scene's; the message lists the scene's variants.
    """
    sidecar = read_sidecar(log) or {}
    recorded = sidecar.get("variant")

    def another_scene() -> None:
        # A log of another scene: that is the mistake to name, not a variant it lacks.
        name = (_yaml_data(Path(scene)) or {}).get("name")
        if isinstance(name, str) and sidecar.get("scene", name) != name:
            raise LogError(f"--log {log}: recorded for scene {sidecar['scene']!r} (its "
                           f"sidecar), not {name!r}: check it against that scene's file")

    if variant is not None and recorded is not None and variant != recorded:
        another_scene()
        raise LogError(f"--variant {variant}: the log {log} was recorded for "
                       f"{_variant_text(recorded)} (its sidecar)")
    if variant is None and recorded is not None:
        combos = dict(parametrizations(scene))
        if recorded in combos:
            return recorded, combos[recorded]
        has = ("it has no parametrize block" if list(combos) == [""]
               else f"its variants: {', '.join(combos)}")
        another_scene()
        raise LogError(f"--log {log}: recorded for {_variant_text(recorded)} (its sidecar), "
                       f"which {scene} does not have; {has}")
    return select_variant(scene, variant, unnamed=f" and no sidecar of the log {log} names the "
                                                  f"one it records")


# The channel python-can's writers give a message that names none, as their readers read it
# back (BLF and ASC number it 1 and read it as 0; canutils writes vcan0).
_UNNAMED_CHANNEL = {".blf": "0", ".asc": "0", ".log": "vcan0"}


def pick_channel(log: str | Path, channel: str | None, channels: Counter[str | None],
                 mapping: CanMapping, sidecar: dict[str, Any] | None,
                 ) -> tuple[str | None, str | None]:
    """Return the log's channel to read (None: all of it) and a note on the choice, if any.

    ``channels``: per channel, the messages of the radar's identifiers the log holds. A
    channel given (``--log-channel``) must hold some. Without one, a log that holds them on
    one channel (or says of no message which channel it came on) is read whole, with a note
    where the sidecar says the run listened on another; on several,
    the channel the run listened on (its sidecar's ``can_channel``) where the log names one
    so, else the log is refused: which one is the radar's is not guessed. Where the sidecar
    says the run's messages named no channel (``can_channel_named`` false), the log names
    theirs as its writer does such a message's (`_UNNAMED_CHANNEL`).

    Raises
    ------
    LogError
        Naming the log, its channels with the radar's messages and how many each holds.
    """
    held = {c: n for c, n in channels.items() if n}

    def listing() -> str:
        return ", ".join(f"{'(none)' if c is None else c} ({n} messages)"
                         for c, n in sorted(held.items(), key=lambda cn: str(cn[0])))

    what = f"the radar's messages (the identifiers of mapping {mapping.name!r})"
    if channel is not None:
        if channel not in held:
            found = (f"its channels with them: {listing()}" if held
                     else "it holds none on any channel")
            raise LogError(f"--log-channel {channel}: the log {log} holds none of {what} on "
                           f"channel {channel}; {found}")
        return channel, None
    recorded = (sidecar or {}).get("can_channel")
    # As the log names the run's channel: python-can's BLF and ASC writers number a channel
    # by the digits its name ends in (can1: 1), else as the first (0, read back).
    names = [str(recorded)]
    suffix = Path(log).suffix.lower()
    if recorded is not None and suffix in (".blf", ".asc"):
        number = can.util.channel2int(recorded)
        names.append(str(0 if number is None else number))
    elif recorded is not None and suffix == ".log" and str(recorded).isdigit():
        names.append(f"can{recorded}")  # python-can's canutils writer: channel 1 as can1
    if (sidecar or {}).get("can_channel_named") is False and suffix in _UNNAMED_CHANNEL:
        # The run's messages named no channel (udp_multicast's): the log's writer put them on
        # its default one.
        names.append(_UNNAMED_CHANNEL[suffix])
    if len(held) <= 1:
        only = next(iter(held), None)
        if recorded is None or only is None or only in names:
            return None, None
        chosen = (sidecar or {}).get("radar_channel")
        if chosen is not None and suffix in (".blf", ".asc", ".log"):
            # The run read that channel alone, as this format names it: none of these.
            raise LogError(f"--log {log}: the run read channel {chosen} alone (run "
                           f"--radar-channel, its sidecar), and the log holds none of {what} "
                           f"there: only on {listing()}; the run judged none of them; give "
                           f"--log-channel {only} to judge those")
        return None, (f"the log holds {what} on channel {only} only, not on the one the run "
                      f"listened on ({recorded!r}, its sidecar): read it")
    if recorded is not None:
        match = next((name for name in names if name in held), None)
        if match is not None:
            return match, (f"the log holds {what} on {len(held)} channels ({listing()}): "
                           f"read channel {match}, the one the run listened on ({recorded!r}, "
                           f"its sidecar)")
    heard = (f"; the run listened on channel {recorded} (its sidecar), which the log does not "
             f"name" if recorded is not None else "")
    raise LogError(f"--log {log}: holds {what} on {len(held)} channels: {listing()}{heard}; "
                   f"which is the radar's is not guessed: give --log-channel CH (the channel "
                   f"as python-can reads it from the log)")


def _counter_words(mapping: CanMapping) -> str:
    """Name the radar's counter by its width, or where it wraps when that is below it."""
    if mapping.counter_min:
        return (f"counter (running {mapping.counter_min} to "
                f"{mapping.counter_min + mapping.counter_modulus - 1}, counted from "
                f"{mapping.counter_min} as 0)")
    if mapping.counter_max is not None:
        return f"counter (wrapping after {mapping.counter_max})"
    return f"{mapping.counter_modulus.bit_length() - 1}-bit counter"


def _variant_text(variant: str) -> str:
    return f"variant {variant!r}" if variant else "the scene without parametrize"


def read_cycles(log: str | Path, mapping: CanMapping | None, cycle_s: float | None = None,
                *, channel: str | None = None,
                restart: int | None = None) -> tuple[list[_LoggedCycle], dict[str, int]]:
    """Decode a log's radar cycles, each with the bus time of its header message.

    ``cycle_s``: the radar's cycle, so that a counter repeated after a long silence is told
    from a copy (`DetectionReceiver`). ``channel``: read only the messages of this channel
    (python-can's ``Message.channel`` as text), None: every message. ``restart``: the counter
    the radar's count starts afresh at with the run's stream, as the run's receiver took it
    (`DetectionReceiver.reset`): the stream before's cycles logged before it are dropped.
    """
    stats: dict[str, int] = {}
    return list(_iter_cycles(log, mapping, stats, cycle_s, channel=channel,
                             restart=restart)), stats


# Detection messages held before a log's first header, waiting for it: more than a cycle's
# worth are a tail of cycles before it whatever comes.
_EARLY_PARTS = 1024


def _iter_cycles(log: str | Path, mapping: CanMapping | None, stats: dict[str, int],
                 cycle_s: float | None = None, *, channel: str | None = None,
                 channels: Counter[str | None] | None = None,
                 last_t_s: list[float] | None = None,
                 restart: int | None = None,
                 unread: list[_Unread] | None = None,
                 headers: list[int] | None = None,
                 starts: list[list[float]] | None = None) -> Iterator[_LoggedCycle]:
    """Yield a log's radar cycles in log order; ``stats`` gets the bus counters at the end.

    ``channel``: read only its messages (the others count as ``other_channels``).
    ``restart``: the counter the run's stream restarted the radar's count at (`read_cycles`).
    ``channels`` gets, per channel, how many messages of the radar's identifiers it holds;
    ``last_t_s`` the timestamp of the log's last message (of any channel), if it has one;
    ``unread`` the records of a text log python-can's reader read no message of (`_Unread`);
    ``headers`` how many messages had the identifier of the mapping's header.
    """
    check_log_file(log)
    path = Path(log)
    receiver = DetectionReceiver(mapping, cycle_s)
    receiver.reset(restart=restart)  # as the run's receiver was, when its stream started
    m = receiver.mapping
    header = m.db.get_message_by_name(m.header)
    header_id = (header.frame_id, bool(header.is_extended_frame))
    radar_ids = {(message.frame_id, bool(message.is_extended_frame))
                 for message in (header, *(message for fd in (False, True)
                                           for message, _ in m.parts(fd)))}

    def take(cycles: list[Detections]) -> Iterator[_LoggedCycle]:
        for cycle in cycles:  # one per radar cycle, with the time of its own header
            t = cycle.bus_t_s
            yield _LoggedCycle(cycle, float("nan") if t is None else t)

    started = False
    skipped = other = 0
    # Detections before the log's first header: where they carry their frame counter, one
    # of the first cycle's own waits for its header (a radar whose detection identifiers are
    # lower than its header's sends them first), the rest are the tail of a cycle before.
    early: list[can.Message] = []
    not_read = None
    if unread is not None:
        not_read = _Unread(path.suffix.lower(), radar_ids)
        unread.append(not_read)
    for msg in _messages(path, not_read):  # one per logged message
        if channels is not None or channel is not None:
            label = channel_label(msg.channel)
            if channels is not None and not (msg.is_error_frame or msg.is_remote_frame) and (
                    msg.arbitration_id, msg.is_extended_id) in radar_ids:
                channels[label] += 1
            if channel is not None and label != channel:
                other += 1  # another bus's
                continue
        if not started:
            data = not (msg.is_error_frame or msg.is_remote_frame)
            ident = (msg.arbitration_id, msg.is_extended_id)
            if data and ident in radar_ids and ident != header_id:
                # The log began inside a cycle, or the first cycle's detections came first.
                if receiver.frame_counted and len(early) < _EARLY_PARTS:
                    early.append(msg)
                else:
                    skipped += 1
                continue
            # Error and remote frames, and identifiers the mapping does not know, count as
            # the run's receiver counts them, wherever they come.
            started = data and ident == header_id
            if started and early:
                orphans = receiver.stats.orphans
                for part in early:
                    receiver.on_message_received(part)
                receiver.on_message_received(msg)
                # Those the first header did not claim: no cycle of the log (not counted as
                # orphans, nor as messages twice).
                unclaimed = receiver.forget_waiting() + receiver.stats.orphans - orphans
                receiver.stats.orphans = orphans
                receiver.stats.messages -= unclaimed
                skipped += unclaimed
                early = []
                yield from take(receiver.pop())
                continue
        receiver.on_message_received(msg)
        yield from take(receiver.pop())
    # Detections held for a first header that never came: the log's, before any cycle.
    skipped += len(early)
    yield from take(receiver.flush())
    if last_t_s is not None and (started or skipped or other or receiver.stats.messages):
        last_t_s.append(float(msg.timestamp))
    stats.update({k: int(v) for k, v in vars(receiver.stats).items()})
    # Messages before the first cycle's header are the log's too (a log the mapping reads no
    # header of is not a silent bus).
    stats["messages"] += skipped
    stats["before_first_cycle"] = skipped
    stats["stale_cycles"] = receiver.stale_cycles
    stats["other_channels"] = other
    if headers is not None:
        headers.append(receiver.headers)
    if starts is not None:
        starts.append(list(receiver.count_starts))


@dataclass(frozen=True)
class _LogIndex:
    """What a first pass over a log keeps of each cycle: 24 bytes, not its detections.

    The checks read the log again for the detections, so memory does not grow with them.
    """

    counters: IntArray
    bus_t_s: FloatArray
    counts: IntArray  # detections per cycle
    bus: dict[str, int]
    # Per channel of the log, the messages of the radar's identifiers it holds.
    channels: Counter[str | None] = field(default_factory=Counter)
    # The timestamp of the log's last message (None: it holds none).
    last_t_s: float | None = None
    # A text log's records python-can's reader read no message of (None: not a text log).
    unread: _Unread | None = None
    # Messages with the identifier of the mapping's header.
    headers: int = 0
    # Bus times of the headers that started the radar's count afresh at its profile's start
    # (`DetectionReceiver.count_starts`).
    count_starts: tuple[float, ...] = ()

    @classmethod
    def scan(cls, log: str | Path, mapping: CanMapping | None,
             cycle_s: float | None = None, *, channel: str | None = None,
             restart: int | None = None) -> _LogIndex:
        stats: dict[str, int] = {}
        channels: Counter[str | None] = Counter()
        last: list[float] = []
        unread: list[_Unread] = []
        headers: list[int] = []
        starts: list[list[float]] = []
        counters, times, counts = array("q"), array("d"), array("l")
        for c in _iter_cycles(log, mapping, stats, cycle_s, channel=channel,
                              channels=channels, last_t_s=last,
                              restart=restart, unread=unread,
                              headers=headers, starts=starts):  # one per radar cycle
            counters.append(c.detections.cycle)
            times.append(c.bus_t_s)
            counts.append(c.detections.count)
        return cls(np.frombuffer(counters, dtype=np.int64).copy(),
                   np.frombuffer(times, dtype=np.float64).copy(),
                   np.asarray(counts, dtype=np.int64), stats, channels,
                   last[0] if last else None, unread[0] if unread else None, headers[0],
                   tuple(starts[0]))

    def __len__(self) -> int:
        return int(self.counters.size)


def _refused_text(bus: dict[str, int]) -> str:
    """Why a log's detections may be missing: its messages the receiver refused, in words."""
    refused = [(bus.get("checksum_errors", 0), "failed their checksum"),
               (bus.get("decode_errors", 0), "could not be decoded")]
    said = [f"{n} messages {why}" for n, why in refused if n]
    if not said:
        return ""
    return (f" ({' and '.join(said)}: is --mapping the radar's, and did the logger keep "
            f"each message whole (its CAN FD flag and length)?)")


def _cycles_at(log: str | Path, mapping: CanMapping | None, positions: IntArray,
               cycle_s: float | None = None, *, channel: str | None = None,
               restart: int | None = None) -> list[Detections]:
    """Read the log again for the cycles at ``positions`` (increasing)."""
    want = set(positions.tolist())
    return [c.detections for i, c in enumerate(_iter_cycles(log, mapping, {}, cycle_s,
                                                            channel=channel, restart=restart))
            if i in want]


class _ReadAhead:
    """Cycles of a log by their position, read once, in order, as far as asked."""

    def __init__(self, log: str | Path, mapping: CanMapping | None,
                 kept: NDArray[np.bool_], cycle_s: float | None = None, *,
                 channel: str | None = None, shifts: FloatArray | None = None,
                 restart: int | None = None) -> None:
        self._log = log
        self._shifts = shifts  # per position, what its bus time is brought back by
        self._cycles = enumerate(_iter_cycles(log, mapping, {}, cycle_s, channel=channel,
                                              restart=restart))
        self._kept = kept  # positions ever asked for: the others are not held
        self._held: dict[int, Detections] = {}
        self._read = -1

    def take(self, positions: IntArray) -> list[Detections]:
        """Return the cycles at ``positions``, each once."""
        if positions.size:
            last = int(positions.max())
            while self._read < last:
                step = next(self._cycles, None)
                if step is None:  # the first pass read more cycles than this one
                    raise LogError(f"--log {self._log}: changed while it was checked (it now "
                                   f"ends after {self._read + 1} radar cycles, not "
                                   f"{self._kept.size}); check it again")
                self._read, cycle = step
                if self._kept[self._read]:
                    held = cycle.detections
                    if (self._shifts is not None and self._shifts[self._read]
                            and held.bus_t_s is not None):
                        held = replace(held, bus_t_s=held.bus_t_s
                                       - float(self._shifts[self._read]))
                    self._held[self._read] = held
        return [self._held.pop(int(i)) for i in positions]


# The header of a BLF python-can wrote and never closed (its size, no object count yet).
_BLF_OPEN_HEADER_BYTES = 144
# What an ASC log's last line is (python-can's writer and Vector's tools end it so).
_ASC_END = b"end triggerblock"
# ... where it opened one: its header's ``Begin Triggerblock`` line, within this many bytes.
_ASC_BEGIN = b"begin triggerblock"
_ASC_HEAD_BYTES = 4096


# Log formats of text lines, one message a line (python-can's readers by extension).
TEXT_LOG_READERS: dict[str, type[can.io.generic.TextIOMessageReader]] = {
    ".asc": can.ASCReader, ".csv": can.CSVReader, ".log": can.CanutilsLogReader,
    ".trc": can.TRCReader}
# How much of a text log's end is read at a time looking for its last line's end (bytes).
_TAIL_CHUNK_BYTES = 65536


@dataclass(frozen=True)
class _TextEnd:
    """Where a text log's complete lines end: a last line without its line end was cut."""

    complete_bytes: int  # the file's bytes up to its last line end
    cut_line: int | None  # the number (from 1) of the line cut in the middle; None: none was
    cut_bytes: int  # the bytes of that line the file holds


def _text_end(path: Path) -> _TextEnd:
    """Find whether a text log's last line lacks its line end (written in part: cut short).

    Every tool ends each line of a log with a line end; python-can's readers take a line
    without one as it is (a data field cut in the middle of a byte as a shorter message, with
    a made-up half byte), or fail on it. A last line of white space alone, or an ASC log's
    ``End TriggerBlock`` without a line end, is complete. Line ends are the ones python-can
    reads a text log by (universal line ends): a line feed, a carriage return and line feed,
    or a carriage return alone, as some loggers write.
    """
    size = path.stat().st_size
    with path.open("rb") as f:
        end = size
        while end > 0:  # back to the last line end, a chunk at a time
            start = max(0, end - _TAIL_CHUNK_BYTES)
            f.seek(start)
            chunk = f.read(end - start)
            at = max(chunk.rfind(b"\n"), chunk.rfind(b"\r"))
            if at >= 0:
                end = start + at + 1
                break
            end = start
        f.seek(end)
        partial = f.read(size - end).strip()
        if not partial or (path.suffix.lower() == ".asc" and partial.lower() == _ASC_END):
            return _TextEnd(size, None, 0)
        f.seek(0)
        lines, left, after_cr = 0, end, False
        while left > 0:  # the line's number: the line ends before it, a chunk at a time
            chunk = f.read(min(left, 1 << 20))
            # A carriage return and line feed end one line, also across two chunks.
            lines += (chunk.count(b"\n") + chunk.count(b"\r") - chunk.count(b"\r\n")
                      - (after_cr and chunk.startswith(b"\n")))
            after_cr = chunk.endswith(b"\r")
            left -= len(chunk)
        return _TextEnd(end, lines + 1, size - end)


class _HeadBytes(io.RawIOBase):
    """The first ``limit`` bytes of a binary file, as a raw stream."""

    def __init__(self, f: io.BufferedReader, limit: int) -> None:
        super().__init__()
        self._f, self._left = f, int(limit)

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: Any) -> int:
        n = min(len(buffer), self._left)
        data = self._f.read(n) if n > 0 else b""
        buffer[:len(data)] = data
        self._left -= len(data)
        return len(data)

    def close(self) -> None:
        self._f.close()
        super().close()


class _CountedLines(io.TextIOWrapper):
    """A text log's complete lines (`_TextEnd`), counting those read (``lines``).

    Lines of white space alone hold no message and are passed over (python-can's CSV reader
    fails on them: an empty line after the last is no damage). ``at``: the number of the line
    being read, or last read: where a reader failed (a line that cannot be decoded in the
    locale's encoding fails as it is read, up to a few kilobytes before the bad byte).
    """

    def __init__(self, path: Path, limit: int,
                 unread: Callable[[int, str], None] | None = None) -> None:
        head = io.BufferedReader(_HeadBytes(path.open("rb"), limit))
        # As python-can opens a text log: the locale's encoding, universal line ends.
        super().__init__(head, encoding=locale.getpreferredencoding(False))
        self.lines = 0
        self.at = 0
        self.last = ""  # the last line given to the reader
        self.given = 0  # ... and its number
        self.answered = 0  # the number of the last line the reader gave a message of
        self._unread = unread  # told each line the reader gave no message of

    def __next__(self) -> str:  # type: ignore[override]  # text lines, as read
        self.passed_over()
        while True:
            self.at = self.lines + 1
            line = super().__next__()
            self.lines += 1
            if line.strip():
                self.last, self.given = line, self.lines
                return line

    def passed_over(self) -> None:
        """Tell ``unread`` of the line last given, where the reader gave no message of it."""
        if self._unread is not None and self.given > self.answered:
            self._unread(self.given, self.last)
            self.answered = self.given


def log_cut_short(log: str | Path, last_t_s: float | None) -> dict[str, Any] | None:
    """Return how a log was cut short, where its format tells; None where it was not.

    python-can's readers read a BLF or an ASC cut short as a shorter log, without a word. A
    BLF's header gives the file's size (python-can's `BLFReader` reads it; a writer that was
    never closed left the 144 bytes of the header alone there); an ASC log that opened a
    trigger block (its header's ``Begin Triggerblock``) ends with an ``End TriggerBlock`` line
    (either in any case; a log that opens none cannot tell). A text log (``.asc``, ``.csv``,
    ``.log``, ``.trc``) whose last line lacks its line end was cut in the middle of writing it
    (`_text_end`): that line is not read. ``last_t_s``: the log's last message's time, where
    it ends.

    Returns ``{"header_bytes", "file_bytes", "line", "last_message_t_s", "why"}``
    (``header_bytes`` None where the format keeps no size; ``line`` the line cut in the
    middle, None where none was; ``why``: one line for people).
    """
    path = Path(log)
    size = path.stat().st_size
    suffix = path.suffix.lower()
    ends = ("it holds no message" if last_t_s is None
            else f"it ends at log time {last_t_s:.6f} s (its last message read)")
    if suffix in TEXT_LOG_READERS:
        text = _text_end(path)
        if text.cut_line is not None:
            lacks = (" (and the 'End TriggerBlock' line an ASC log ends with)"
                     if suffix == ".asc" else "")
            why = (f"the log {log} was cut short: its line {text.cut_line} ends without a "
                   f"line end{lacks}, {text.cut_bytes} bytes of it written: not read; {ends}: "
                   f"what the radar sent after it is not in it")
            return {"header_bytes": None, "file_bytes": size, "line": text.cut_line,
                    "last_message_t_s": last_t_s, "why": why}
    if suffix == ".blf":
        with _quiet_unraisable():
            try:
                with can.BLFReader(str(path)) as reader:
                    stated = int(reader.file_size)
            except Exception:  # noqa: BLE001 - a header python-can cannot read: read as before
                return None
        if stated == size:
            return None
        never = (" (the tool that wrote it never closed it)"
                 if stated == _BLF_OPEN_HEADER_BYTES else "")
        why = (f"the log {log} was cut short: its header says {stated} bytes{never}, the file "
               f"holds {size}; {ends}: what the radar sent after it is not in it")
        return {"header_bytes": stated, "file_bytes": size, "line": None,
                "last_message_t_s": last_t_s, "why": why}
    if suffix == ".asc":
        with path.open("rb") as f:
            head = f.read(_ASC_HEAD_BYTES).lower()
            f.seek(max(0, size - 256))
            tail = f.read().rstrip().lower()
        # Keywords in any case, as python-can reads them; a log that opens no trigger block
        # (can-utils' log2asc writes none) has no end line to miss.
        if tail.endswith(_ASC_END) or _ASC_BEGIN not in head:
            return None
        why = (f"the log {log} was cut short: it lacks the 'End TriggerBlock' line an ASC log "
               f"ends with; {ends}: what the radar sent after it is not in it")
        return {"header_bytes": None, "file_bytes": size, "line": None,
                "last_message_t_s": last_t_s, "why": why}
    return None


def _messages(path: Path, unread: _Unread | None = None) -> Iterator[can.Message]:
    """Yield the log's messages; a file python-can cannot parse is a `LogError`.

    A text log's lines are read up to its last line end: a last line without one was cut in
    the middle of writing it (`log_cut_short` says so), and a line python-can cannot parse is
    named by its number. ``unread`` gets the text log's lines python-can's reader gave no
    message of (`_Unread`).
    """
    problem = None
    text: _CountedLines | None = None
    reader: can.io.generic.MessageReader
    with _quiet_unraisable():
        try:
            suffix = path.suffix.lower()
            if suffix in TEXT_LOG_READERS:
                text = _CountedLines(path, _text_end(path).complete_bytes,
                                     None if unread is None else unread.line)
                reader = TEXT_LOG_READERS[suffix](file=text)
                if unread is not None:
                    unread.reader = reader
            else:
                mf4.ready(path)
                reader = can.LogReader(str(path))
        except ImportError as exc:
            problem = (f"--log {path}: {exc} (.mf4 logs need asammdf: pip install "
                       f"'rts-scenario[mf4]')")
        except Exception as exc:  # noqa: BLE001 - each format fails in its own way
            where = f"line {text.at}: " if text is not None and text.at else ""
            problem = f"--log {path}: {where}cannot read: {_unreadable(path, exc)}"
            if text is not None:
                text.close()
        if problem is not None:
            # The reader it left half made goes now, while its clean-up's errors are held back
            # (asammdf's fails on a file it could not open, with a traceback).
            gc.collect()
    if problem is not None:
        raise LogError(problem)
    with reader, _skipped_lines(text, unread) as skipped:
        iterator = iter(reader)
        while True:
            try:
                msg = next(iterator)
            except StopIteration:
                msg = None
                if text is not None:
                    text.passed_over()
            except Exception as exc:  # noqa: BLE001 - a damaged log, in the format's words
                where = f"line {text.at}: " if text is not None else ""
                raise LogError(f"--log {path}: {where}cannot read: "
                               f"{_unreadable(path, exc)}") from None
            if skipped:
                # A line python-can's reader skipped with a warning (its TRC reader, on a
                # line of too few columns): a message lost, not a shorter log.
                line, said = skipped[0]
                raise LogError(f"--log {path}: line {line}: cannot read: python-can's reader "
                               f"skipped it ({said})")
            if msg is None:
                return
            if text is not None:
                text.answered = text.given
            yield msg


def _unreadable(path: Path, exc: Exception) -> str:
    """Why python-can's reader of ``path``'s format failed: the bytes are not that format's.

    In the reader's words, named by module where its name alone says nothing (``struct.error``,
    not ``error``).
    """
    kind = type(exc)
    name = (kind.__qualname__ if kind.__module__ == "builtins"
            else f"{kind.__module__}.{kind.__qualname__}")
    if isinstance(exc, struct.error | UnicodeDecodeError | can.io.blf.BLFParseError):
        return (f"not a {path.suffix.lower()} log as python-can reads one, or a damaged one "
                f"({name}: {exc})")
    return f"{name}: {exc}"


# Lines of an ASC log that hold no message: its header, comments, its trigger block's begin and
# end, the start of the measurement (python-can's ASC reader passes over them).
_ASC_NO_MESSAGE = re.compile(
    r"(//|date\s|base\s|(no\s+)?internal\s+events\s+logged|begin\s+triggerblock|"
    r"end\s+triggerblock|\d+\.\d+\s+start\s+of\s+measurement)", re.IGNORECASE)
# A word of a TRC record that is an identifier as TRC writes them: 4 hex digits (11 bits),
# 8 (29 bits).
_TRC_IDENTIFIER = re.compile(r"[0-9A-Fa-f]{4}|[0-9A-Fa-f]{8}")


def _trc_identifier_column(reader: object) -> int | None:
    """Return the word of a TRC record holding its identifier, as python-can's reader reads it.

    Versions 1.1 and 1.3 put it at a fixed place; 2.x names it in the header's ``$COLUMNS``
    (``I``). None where the reader read no version or columns that place it.
    """
    version = getattr(reader, "file_version", None)
    name = getattr(version, "name", "")
    if name == "V1_1":
        return 3
    if name == "V1_3":
        return 4
    if name in ("V2_0", "V2_1"):
        column = (getattr(reader, "columns", None) or {}).get("I")
        return column if isinstance(column, int) else None
    return None


class _Unread:
    """The records of a text log python-can's reader gave no message of, by type.

    python-can's TRC reader drops a record of a type it does not read with an info line of
    its logger (its type, told in ``kinds`` by line); its ASC reader passes over every line
    that is not a CAN frame (error and remote frames it reads) without a word. Either way the
    log would be judged shorter than it is: `check_log` fails where such a record holds one
    of the radar's identifiers, and notes the others.
    """

    def __init__(self, suffix: str, radar_ids: set[tuple[int, bool]]) -> None:
        self.suffix = suffix
        self.radar_ids = radar_ids
        self.kinds: dict[int, str] = {}  # by line: the type python-can's TRC reader named
        self.counts: Counter[str] = Counter()  # records not read, by type
        self.radar = 0  # ... of them holding one of the radar's identifiers
        self.first_radar_line: int | None = None
        self._base = 16  # an ASC log's numbers' (its header's ``base``)
        # The text log's reader: a TRC reader knows, once it has read the header, which of a
        # record's words holds its identifier.
        self.reader: object = None

    def line(self, number: int, text: str) -> None:
        """Take the line ``number`` (from 1) the reader gave no message of."""
        kind = self.kinds.pop(number, None)
        words = text.split()
        if kind is None and self._holds_no_message(number, text):
            return
        if kind is None:  # a line of an ASC log: its first word after the time
            kind = next((w.rstrip(":") for w in words[1:] if w[:1].isalpha()), "line")
        self.counts[kind] += 1
        if self._holds_radar_id(words):
            self.radar += 1
            if self.first_radar_line is None:
                self.first_radar_line = number

    def _holds_no_message(self, number: int, text: str) -> bool:
        line = text.strip()
        if self.suffix == ".trc":
            return line.startswith(";")
        if self.suffix == ".asc":
            if line.lower().startswith("base "):
                self._base = 10 if line.split()[1].lower() == "dec" else 16
            return _ASC_NO_MESSAGE.match(line) is not None
        return self.suffix == ".csv" and number == 1  # its header

    def _holds_radar_id(self, words: list[str]) -> bool:
        if self.suffix == ".trc":
            at = _trc_identifier_column(self.reader)
            if at is not None:  # the word python-can reads the identifier of a frame from
                candidates = words[at:at + 1]
            else:  # a version it names no column for: any word written as an identifier
                candidates = words
            return any((int(w, 16), len(w) == 8) in self.radar_ids for w in candidates
                       if _TRC_IDENTIFIER.fullmatch(w))
        if self.suffix == ".asc":
            # Where an ASC frame line holds its identifier: after its time and channel, or
            # after ``CANFD``, its channel and direction; an ``x`` ends an extended one.
            at = 4 if len(words) > 1 and words[1].upper() == "CANFD" else 2
            if len(words) <= at:
                return False
            word = words[at]
            extended = word[-1:].lower() == "x"
            try:
                number = int(word[:-1] if extended else word, self._base)
            except ValueError:
                return False
            return (number, extended) in self.radar_ids
        return True  # a format whose reader gives a message of each line or fails

    def summary(self) -> dict[str, Any] | None:
        """Plain data for JSON: the records not read, by type; None where there were none."""
        total = sum(self.counts.values())
        if not total:
            return None
        return {"records": total, "by_type": dict(self.counts.most_common()),
                "with_radar_identifiers": self.radar, "first_radar_line": self.first_radar_line}

    def verdict(self, log: str | Path) -> tuple[str | None, str | None]:
        """Return ``(reason, note)``: a reason where a record not read may be the radar's."""
        total = sum(self.counts.values())
        if not total:
            return None, None
        kinds = ", ".join(f"{n} of type {kind!r}" for kind, n in self.counts.most_common())
        said = (f"the log {log} holds {total} record{'s' if total != 1 else ''} python-can's "
                f"reader does not read ({kinds}), ")
        if self.radar:
            return (said + f"{self.radar} of them with the radar's identifiers (the first at "
                    f"line {self.first_radar_line}): the cycles they belong to are judged "
                    f"without them"), None
        return None, said + "none of them with the radar's identifiers"


class _SkippedLines(logging.Handler):
    """Collects the lines python-can's TRC reader skips (``(line, its words)``).

    It tells ``unread`` the type of each record the reader drops as one it does not read.
    """

    def __init__(self, text: _CountedLines, unread: _Unread | None) -> None:
        super().__init__(logging.INFO)
        self.text, self.unread = text, unread
        self.lines: list[tuple[int, str]] = []

    def emit(self, record: logging.LogRecord) -> None:
        said = record.getMessage()
        if record.levelno >= logging.WARNING and said.startswith("TRCReader: Failed to parse"):
            self.lines.append((self.text.lines, said))
        elif self.unread is not None and said.startswith("TRCReader: Unsupported type"):
            args = record.args if isinstance(record.args, tuple) else ()
            self.unread.kinds[self.text.given] = str(args[0] if args else "")
        elif self.unread is not None and said.startswith("TRCReader: Dropping bus info"):
            self.unread.kinds[self.text.given] = "FFFFFFFF"  # a bus's state, no message


@contextmanager
def _skipped_lines(text: _CountedLines | None,
                   unread: _Unread | None = None) -> Iterator[list[tuple[int, str]]]:
    """Collect, while reading ``text``, the lines python-can's TRC reader skips."""
    if text is None:
        yield []
        return
    logger = logging.getLogger("can.io.trc")
    handler, level = _SkippedLines(text, unread), logger.level
    logger.addHandler(handler)
    wanted = logging.WARNING if unread is None else logging.INFO
    if not logger.isEnabledFor(wanted):
        logger.setLevel(wanted)
    try:
        yield handler.lines
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)


@contextmanager
def _quiet_unraisable() -> Iterator[None]:
    """Hold back what Python prints of errors raised while objects are collected."""
    hook = sys.unraisablehook
    sys.unraisablehook = lambda _: None
    try:
        yield
    finally:
        sys.unraisablehook = hook


class _Detected:
    """A log's detections as flat arrays, each with the cycle (row) it came in."""

    def __init__(self, dets: list[Detections], quantities: tuple[str, ...]) -> None:
        counts = np.array([d.count for d in dets], dtype=np.int64)
        self.owner = np.repeat(np.arange(len(dets)), counts)  # detection -> cycle

        def column(q: str) -> FloatArray:
            parts = [getattr(d, q) if getattr(d, q) is not None else np.full(d.count, np.nan)
                     for d in dets]
            return np.concatenate(parts) if parts else np.zeros(0)

        self.values = {q: column(q) for q in quantities}


class _TruthTable:
    """What the RTS plays, on a fine time grid, read at any time by linear interpolation.

    Built once, it prices an offset in a few array operations (every candidate of the search
    reads it instead of evaluating the scene again).
    """

    QUANTITIES = (("range_m", "range_m"), ("radial_velocity_mps", "radial_velocity_mps"),
                  ("az_deg", "az_deg"))

    def __init__(self, scene: Scenario) -> None:
        self.frame_s = 1.0 / scene.frame_rate_hz
        self.step = max(0.002, scene.duration_s / 20000.0)
        self.t = np.arange(0.0, scene.duration_s + self.step, self.step)
        tracks = compute_tracks(scene, self.t)
        # What the radar can see: present and played (inside the rig's coverage).
        self.visible = tracks.present & tracks.in_coverage
        self.values = {q: getattr(tracks, q) for q, _ in self.QUANTITIES}
        self.tol = scene.expectations.tolerances

    def detected(self, dets: list[Detections]) -> _Detected:
        """Return the detections ``dets`` in the form `cost` reads."""
        return _Detected(dets, tuple(q for q, _ in self.QUANTITIES))

    @property
    def first_visible_s(self) -> float | None:
        """Scene time at which the radar can first see a target (None: never)."""
        rows = np.flatnonzero(self.visible.any(axis=1))
        return float(self.t[rows[0]]) if rows.size else None

    def at(self, t_s: FloatArray) -> tuple[dict[str, FloatArray], NDArray[np.bool_]]:
        """Truth (C, K) the RTS plays at times ``t_s``: the frame it holds then.

        Targets are absent outside the scene.
        """
        held = np.floor(np.asarray(t_s) / self.frame_s + TIME_EPS_S) * self.frame_s
        x = (held - self.t[0]) / self.step
        inside = (x >= 0) & (x <= self.t.size - 1)
        i0 = np.clip(np.floor(x).astype(np.int64), 0, self.t.size - 2)
        w = np.clip(x - i0, 0.0, 1.0)[:, None]
        values = {q: v[i0] * (1 - w) + v[i0 + 1] * w for q, v in self.values.items()}
        visible = self.visible[i0] & self.visible[i0 + 1] & inside[:, None]
        return values, visible

    def cost(self, t_s: FloatArray, det: _Detected, weight: FloatArray | None = None,
             angles: bool = True) -> float:
        """Mean over detections of the normalized distance to the nearest visible target.

        ``t_s`` are the cycles' scene times; ``weight`` (per detection) weighs the mean (a
        bootstrap's resampled cycles); without ``angles``, by range and range rate alone (the
        scene's motion, whatever the radar's angles).
        """
        if det.owner.size == 0:
            return float("inf")
        return float(np.average(np.minimum(self.nearest(t_s, det, angles), GATE2),
                                weights=weight))

    def nearest(self, t_s: FloatArray, det: _Detected, angles: bool = True) -> FloatArray:
        """Return each detection's normalized squared distance to its nearest visible target."""
        values, visible = self.at(t_s)
        total = np.zeros((det.owner.size, visible.shape[1]))
        for q, key in self.QUANTITIES[: None if angles else 2]:
            diff = (det.values[q][:, None] - values[q][det.owner]) / self.tol[key]
            total += np.nan_to_num(diff, nan=0.0) ** 2
        total = np.where(visible[det.owner], total, np.inf)
        return np.asarray(total.min(axis=1, initial=np.inf), dtype=np.float64)


@dataclass(frozen=True)
class OffsetEstimate:
    """Log time of the scene's time 0 that matches the detections to the truth best.

    Attributes
    ----------
    offset_s : float
        The latest of the best offsets (see `estimate_offset`).
    plateau_s : float
        Offsets up to this much earlier match the detections as well (>= 0).
    spread_s : float or None
        Spread of ``offset_s`` over resampled cycles (None: too few cycles to tell).
    others_s : tuple of float
        Offsets a scene's length or more away that match a good part as many detections
        (`REPEAT_MATCH`): the log holds the scene played again there.
    """

    offset_s: float
    plateau_s: float
    spread_s: float | None
    others_s: tuple[float, ...] = ()

    @property
    def uncertainty_s(self) -> float:
        """The plateau and the spread together (the true offset lies within this)."""
        return float(np.hypot(self.plateau_s, self.spread_s or 0.0))


def estimate_offset(scene: Scenario, bus_t_s: FloatArray, dets: list[Detections],
                    latency_s: float, within_s: tuple[float, float] | None = None
                    ) -> OffsetEstimate:
    """Log time of scene time 0 that best matches detections to the truth, and its uncertainty.

    A coarse search (10 ms steps, on at most `COARSE_CYCLES` cycles with detections) over every
    offset that puts the log inside the scene - or, for a log much longer than `FULL_SEARCH_S`,
    within `ONSET_WINDOW_S` of where the first detections put the scene's first visible
    target - then a fine one (1 ms, every cycle) over the coarse minima and `FINE_SPAN_S` on
    either side, and the edges of the best offsets to `EDGE_RESOLUTION_S`. ``within_s``: the
    offsets searched are kept within these bounds too, where any of them lies within the log.

    The cost is flat between frame changes: a radar sees the frame the RTS holds, so moving
    the offset changes nothing until some cycle crosses into another frame. A radar whose cycle
    is the frame period, in step with the frames, crosses with all its cycles at once: every
    offset over a whole frame fits equally (a plateau). The data cannot tell where in the hold
    the radar measured; causality bounds it: a cycle cannot measure a frame before the RTS
    applies it, so the latest offset of the plateau is the latest possible one. That one is
    taken: the radar measured each frame as it was applied, so the detections are checked
    against the state the RTS played and the hold (the bench's frame rate, not the radar) adds
    no error. The plateau's width is reported with it (`OffsetEstimate.plateau_s`): the true
    offset may be that much earlier. A radar on its own cycle time measures at shifting
    points of the frames and narrows the plateau to a sliver. The spread over resampled cycles
    (`_offset_uncertainty`) adds what noise and jitter leave uncertain.
    """
    ok = np.isfinite(bus_t_s)
    bus, usable = bus_t_s[ok], [d for d, k in zip(dets, ok, strict=True) if k]
    if bus.size == 0:
        raise LogError("the log has no radar cycle with a timestamp to align")
    table = _TruthTable(scene)
    every = table.detected(usable)
    with_detections = np.flatnonzero([d.count > 0 for d in usable])
    if with_detections.size == 0:
        raise LogError("the log has no detection to align the scene with; give "
                       "--time-offset-s")
    pick = with_detections[np.unique(np.linspace(0, with_detections.size - 1, min(
        COARSE_CYCLES, with_detections.size)).astype(np.int64))]
    some = table.detected([usable[i] for i in pick])
    t_log = bus - latency_s
    lo, hi = bus.min() - latency_s - scene.duration_s, bus.max() - latency_s
    if within_s is not None and max(lo, within_s[0]) <= min(hi, within_s[1]):
        lo, hi = max(lo, within_s[0]), min(hi, within_s[1])
    whole = (lo, hi)
    first_seen = table.first_visible_s
    # The first detections from where the search begins on.
    onwards = with_detections[t_log[with_detections] >= lo + (first_seen or 0.0)]
    if hi - lo > FULL_SEARCH_S and first_seen is not None and onwards.size:
        onset = float(t_log[onwards[0]]) - first_seen
        lo, hi = max(lo, onset - ONSET_WINDOW_S), min(hi, onset + ONSET_WINDOW_S)
    grid = np.arange(lo, hi + COARSE_STEP_S, COARSE_STEP_S)
    coarse = np.array([table.cost(t_log[pick] - s, some) for s in grid])
    best = grid[_best(coarse)]
    # The scene played again in the log: looked for over all of it, a frame at a time, by the
    # scene's motion alone (a play whose angles are off is a play all the same).
    scan = np.arange(whole[0], whole[1] + table.frame_s, max(COARSE_STEP_S, table.frame_s))
    plays = _repeats(scan, np.array([table.cost(t_log[pick] - s, some, angles=False)
                                     for s in scan]), scene.duration_s)
    others = tuple(s for s in plays if abs(s - float(best[-1])) >= scene.duration_s + 1.0
                   and not _held_after(table, scene.duration_s, max(s, float(best[-1])),
                                       t_log, usable))
    span = float(best[-1] - best[0]) + 2 * FINE_SPAN_S
    step = max(FINE_STEP_S, span / MAX_FINE_POINTS)
    fine = best[0] - FINE_SPAN_S + step * np.arange(int(np.ceil(span / step)) + 1)
    costs = np.array([table.cost(t_log - s, every) for s in fine])
    tied = _best(costs)
    least = float(costs.min())

    def fits(s: float) -> bool:
        return bool(np.isclose(table.cost(t_log - s, every), least, rtol=1e-9, atol=0.0))

    first, last = int(tied[0]), int(tied[-1])
    top = _edge(fits, float(fine[last]), float(fine[last + 1])) if last + 1 < fine.size \
        else float(fine[last])
    bottom = _edge(fits, float(fine[first]), float(fine[first - 1])) if first > 0 \
        else float(fine[first])
    plateau = top - bottom
    offset = top - min(EDGE_GUARD_S, plateau / 2)
    return OffsetEstimate(offset, plateau, _offset_uncertainty(table, every, t_log, fine),
                          others)


def _held_after(table: _TruthTable, duration_s: float, later_s: float, t_log: FloatArray,
                dets: list[Detections]) -> bool:
    """Whether the later of two starts that fit matches the RTS holding the earlier's last frame.

    Its detections are matched as well by the scene's last frame, which the RTS holds after
    its play until it is told otherwise: no play again. A scene whose targets stand still
    matches wherever they are held.
    """
    picked = np.flatnonzero((t_log - later_s >= 0.0) & (t_log - later_s <= duration_s))
    if picked.size == 0:
        return True
    det = table.detected([dets[i] for i in picked])
    played = table.nearest(t_log[picked] - later_s, det, angles=False) <= 1.0
    held = table.nearest(np.full(picked.size, duration_s - 0.5 * table.frame_s), det,
                         angles=False) <= 1.0
    # A play again matches detections the held frame does not: a target that moves, even
    # for a few cycles among many that stand still.
    return int((played & ~held).sum()) < HELD_EXTRA


def _repeats(grid: FloatArray, costs: FloatArray, duration_s: float) -> tuple[float, ...]:
    """Offsets of ``grid`` a scene's length or more apart that match as the best nearly does.

    The best among them (all in order of offset); each other matches at least `REPEAT_MATCH`
    of what the best matches: the scene played again.

    A detection matched costs little, one unmatched `GATE2`: ``GATE2 - cost`` grows with the
    detections an offset matches. Offsets less than a scene's length apart share cycles.
    """
    matched = GATE2 - costs
    top = float(matched.max(initial=0.0))
    if not top > 0.0:
        return ()
    found: list[float] = []
    free = np.ones(grid.size, dtype=bool)
    away = duration_s + 1.0
    while free.any():
        at = int(np.flatnonzero(free)[np.argmax(matched[free])])
        if found and matched[at] < REPEAT_MATCH * top:
            break
        found.append(float(grid[at]))
        free &= np.abs(grid - grid[at]) >= away
    return tuple(sorted(found))


def _best(costs: FloatArray) -> IntArray:
    """Return the indices of the least cost and of every cost tied with it (same frames matched)."""
    return np.flatnonzero(np.isclose(costs, costs.min(), rtol=1e-9, atol=0.0))


def _edge(fits: Callable[[float], bool], inside_s: float, outside_s: float) -> float:
    """Offset where ``fits`` ends between ``inside_s`` (fits) and ``outside_s`` (does not).

    Bisection to `EDGE_RESOLUTION_S`; returns the last offset found to fit.
    """
    while abs(outside_s - inside_s) > EDGE_RESOLUTION_S:
        middle = 0.5 * (inside_s + outside_s)
        if fits(middle):
            inside_s = middle
        else:
            outside_s = middle
    return inside_s


def _offset_uncertainty(table: _TruthTable, det: _Detected, t_log: FloatArray,
                        fine: FloatArray, rounds: int = BOOTSTRAP_ROUNDS) -> float | None:
    """Spread of the offset found again on cycles drawn with replacement (a bootstrap).

    It covers what noise leaves uncertain: the latency's jitter, the measurement noise and,
    for a slow scene, which frame fits best. Each round takes the latest of its best offsets
    on the grid ``fine``, as `estimate_offset` does.
    """
    # Cycles with detections drawn (the others weigh nothing in the cost): a draw of only
    # cycles without any would leave nothing to weigh.
    owners = np.unique(det.owner)
    if owners.size < 3:
        return None
    rng = np.random.default_rng(0)
    found = []
    for _ in range(rounds):  # a few dozen resamplings, each a vectorized search
        pick = np.zeros(t_log.size, dtype=np.int64)
        np.add.at(pick, owners[rng.integers(0, owners.size, owners.size)], 1)
        weight = pick[det.owner].astype(np.float64)
        costs = np.array([table.cost(t_log - s, det, weight) for s in fine])
        found.append(float(fine[_best(costs)[-1]]))
    return float(np.std(found, ddof=1))


def check_log(scene: Scenario, log: str | Path, *, mapping: str | None = None,
              time_offset_s: float | None = None, method: str | None = None,
              batch_frames: int | None = None, channel: str | None = None) -> RecheckResult:
    """Check a recorded log's detections against ``scene``.

    Parameters
    ----------
    scene : Scenario
        The scene that was played.
    log : str or Path
        A CAN log python-can reads (.blf, .asc, .csv, .log, .trc, .mf4 with asammdf).
    mapping : str, optional
        ``*.mapping.yaml`` of the radar's DBC (default: the sidecar's, else rts-scenario's).
    time_offset_s : float, optional
        Log time of the scene's time 0 (a log without a sidecar); estimated when not given.
    method : str, optional
        Solver method of the played schedule (default: the sidecar's, else ``exact``); not
        used where the sidecar keeps the statuses the RTS played.
    channel : str, optional
        The log's channel the radar's messages are on (``--log-channel``; python-can's
        ``Message.channel`` as text). Without it, a log holding the radar's identifiers on
        one channel is read whole; on several, the sidecar's ``can_channel`` where the log
        names it so, else it is refused (`pick_channel`).
    """
    sidecar = read_sidecar(log)
    recorded_mapping = (sidecar or {}).get("mapping")
    # The mapping the run spoke: its sidecar's, else rts-scenario's own messages.
    builtin = Path(__file__).resolve().parent / "data" / "can" / "rts_detections.mapping.yaml"
    other_mapping = (mapping is not None and sidecar is not None
                     and Path(mapping).resolve() != Path(recorded_mapping or builtin).resolve())
    from_sidecar = mapping is None and bool(recorded_mapping)
    if from_sidecar:
        mapping = recorded_mapping
        if not Path(str(mapping)).is_file():
            raise LogError(f"{log}{LOG_SIDECAR_SUFFIX}: mapping: {mapping}: no such file (the "
                           f"mapping the run spoke, as the sidecar names it; a log moved from "
                           f"another machine?); give --mapping with a copy of it")
    can_mapping = CanMapping.from_file(mapping) if mapping else None
    recorded_digest = (sidecar or {}).get("mapping_sha256")
    digest = (can_mapping or CanMapping.builtin()).sha256
    if recorded_digest and digest == recorded_digest:
        other_mapping = False  # the run's mapping and DBC, wherever they are now
    elif recorded_digest and not other_mapping:
        which = (f"mapping {mapping}" if mapping else "rts-scenario's own mapping")
        raise LogError(f"--log {log}: {which} is not what the run decoded the bus with: its "
                       f"text or its DBC's changed since the recording (its sidecar's "
                       f"mapping_sha256 differs), so the log's messages would read otherwise "
                       f"than the run read them; check with the mapping and DBC the run spoke"
                       + ("" if mapping is None else ", or copy the edited one to another "
                          "file and give it as --mapping to read the log as it says"))
    unused_method = (method is not None and sidecar is not None
                     and sidecar.get("statuses") is not None
                     and method != sidecar.get("method"))
    method = method or (sidecar or {}).get("method") or "exact"
    # The profile's cycle: a radar silent for half its counter's range is told by its bus time.
    restart = _counter_restart(scene, can_mapping)
    # Without a sidecar: where the log's timing contradicts the radar's profile (fails).
    count_reason: str | None = None
    latency_reason: str | None = None
    index = _LogIndex.scan(log, can_mapping, scene.radar.radar_clock.cycle_s, channel=channel,
                           restart=restart)
    receiver_mapping = (can_mapping or CanMapping.builtin())
    picked, channel_note = pick_channel(log, channel, index.channels, receiver_mapping, sidecar)
    if picked != channel:  # the sidecar's: read again, that channel alone
        channel = picked
        index = _LogIndex.scan(log, can_mapping, scene.radar.radar_clock.cycle_s,
                               channel=channel, restart=restart)
    bus = index.bus
    # Where the host's clock stepped while the run recorded (its sidecar): the stamps after it
    # are brought back onto the clock the scene's start was taken on, as live.
    shifts, unplaced = _bus_time_shifts(index, sidecar)
    if shifts is not None:
        index = replace(index, bus_t_s=index.bus_t_s - shifts)
    cut_short = log_cut_short(log, index.last_t_s)
    modulus = receiver_mapping.counter_modulus
    profile_clock = scene.radar.radar_clock
    counters = index.counters
    numbers = sequential_numbers(counters, modulus, index.bus_t_s, profile_clock.cycle_s)
    if sidecar is not None:
        c = sidecar["clock"]
        if c["counter_start"] is not None and not c["counter_start"] < modulus:
            raise LogError(f"{log}{LOG_SIDECAR_SUFFIX}: clock.counter_start: "
                           f"{c['counter_start']}, beyond what the radar's "
                           f"{_counter_words(receiver_mapping)} counts (allowed: 0 to "
                           f"{modulus - 1}, or null); not what `rts-scenario run --record` "
                           f"writes for this mapping")
        if not float(c["start_offset_s"]) > -float(c["cycle_s"]):
            raise LogError(f"{log}{LOG_SIDECAR_SUFFIX}: clock.start_offset_s: "
                           f"{c['start_offset_s']:g} s, a cycle or more before the scene's start "
                           f"(allowed: above -{c['cycle_s']:g}: the scene's first cycle, measured "
                           f"at most within the run's tolerance before it); not what "
                           f"`rts-scenario run --record` writes")
        try:
            clock: RadarClock = RecordedClock(
                cycle_s=float(c["cycle_s"]), start_offset_s=float(c["start_offset_s"]),
                latency_s=float(c["latency_s"]), jitter_s=float(c["jitter_s"]),
                counter_start=None if c["counter_start"] is None else int(c["counter_start"]))
        except ValueError as exc:  # values the schema allows one by one, not together
            raise LogError(f"{log}{LOG_SIDECAR_SUFFIX}: {exc} (not what `rts-scenario run "
                           f"--record` writes)") from None
        if clock.counter_start is None:  # the run saw no cycle: count from the log's first
            clock = replace(clock, counter_start=int(counters[0]) if len(index) else 0)
        # The sidecar keeps the cycle the run followed, and the re-check judges the cycles
        # where the run did. Where the bus times show another (bus times that did not keep
        # to one line, which the run did not follow), the notes say so.
        fit = CycleTimeFit()
        fit.add(numbers, index.bus_t_s)
        drifted = fit.drift_reason(clock.cycle_s, 0.5 * ambiguity_window_s(scene.radar,
                                                                            scene.rig))
        alignment = Alignment("sidecar", clock.cycle_s, latency_s=clock.latency_s,
                              latency_source="sidecar")
        if drifted:
            alignment.notes.append(drifted.removeprefix("radar_clock: ").replace(
                "its profile says", "the run took").replace(
                "than the check took it to", "than the run and this re-check took it to"))
        recorded = sidecar.get("variant")
        if recorded is not None and recorded != scene.variant:
            raise LogError(f"--log {log}: recorded for {_variant_text(recorded)} (its "
                           f"sidecar), not {_variant_text(scene.variant)}")
        if sidecar.get("scene", scene.name) != scene.name:
            raise LogError(f"--log {log}: recorded for scene {sidecar.get('scene')!r} (its "
                           f"sidecar), not {scene.name!r}: check it against that scene's file")
        played_rig = sidecar.get("rig")  # absent in sidecars of older versions
        if played_rig is not None and played_rig["sha256"] != scene.rig.played_digest():
            same = played_rig["name"] == scene.rig.name
            raise LogError(f"--log {log}: played on rig {played_rig['name']!r} (its sidecar), "
                           f"not on the scene's {scene.rig.name!r}"
                           + (" as it is now (its FEs, calibration or limits were edited since)"
                              if same else "")
                           + ": another rig plays other levels and statuses; check the log "
                           "against the scene file and rig it was played with")
        played_radar = sidecar.get("radar")
        if played_radar is not None and played_radar != scene.radar.name:
            # Its antennas, coverage and clock are what the run solved and judged for.
            raise LogError(f"--log {log}: recorded with radar {played_radar!r} (its sidecar), "
                           f"not the scene's {scene.radar.name!r}: another radar's "
                           f"array, field of view and clock judge other detections; check the "
                           f"log against the scene file and radar profile it was played with")
        if sidecar.get("frames", scene.n_frames) != scene.n_frames:
            raise LogError(f"{log}{LOG_SIDECAR_SUFFIX}: frames: the recording played "
                           f"{sidecar['frames']} frames, the scene {scene.file} has "
                           f"{scene.n_frames}: not the scene file that was recorded (edited "
                           f"since?)")
        if time_offset_s is not None:
            raise LogError(f"--time-offset-s {time_offset_s!r}: the log's sidecar aligns it by "
                           f"the radar's counters, so a time offset would not be used; leave "
                           f"it out, or check a copy of the log without its sidecar")
        _check_sidecar_cycles(scene, log, clock, c.get("cycles"))
    else:
        if not len(index):
            raise LogError(f"--log {log}: no radar cycle in it ({bus['messages']} messages, "
                           f"none a {receiver_mapping.header} header of mapping "
                           f"{receiver_mapping.name!r}); "
                           + ("is --mapping the radar's?" if cut_short is None
                              else cut_short["why"].removeprefix(f"the log {log} ")))
        latency = profile_clock.latency_s
        bus_t = index.bus_t_s
        _check_timestamps(log, bus_t, profile_clock.cycle_s, numbers)
        _refuse_runs(log, index.count_starts, restart)
        # The cycles the offset is estimated on, read again (at most `ALIGN_CYCLES`).
        chosen = _alignment_cycles(index)
        dets = _cycles_at(log, can_mapping, chosen, profile_clock.cycle_s, channel=channel,
                          restart=restart)
        # Detections of targets are what the data align by: an empty bench has none to match.
        aligned_by_data = bool(scene.targets) and any(d.count for d in dets)
        if time_offset_s is None and not scene.targets:
            raise LogError(f"--log {log}: scene {scene.name!r} has no targets, so its log's "
                           f"detections cannot tell when the scene started; give "
                           f"--time-offset-s (the log time of the scene's time 0)")
        span_s = 0.0
        # How far before the scene's start as the estimate puts it a cycle may lie and be its
        # first: the estimate's error is no such allowance (a cycle measured before the scene
        # saw the RTS idle: judged as its first, a miss), so none beyond rounding.
        start_tolerance_s = START_TOLERANCE_S
        if time_offset_s is None:
            if not aligned_by_data:
                raise LogError(f"--log {log}: no detection to align the scene with"
                               + _refused_text(bus) + "; give --time-offset-s")
            # The profile's latency, the offset from the data.
            found = estimate_offset(scene, bus_t[chosen], dets, latency)
            offset = found.offset_s
            if found.others_s:
                starts = sorted((offset, *found.others_s))
                times = ", ".join(f"{t:.3f}" for t in starts[:5]) + (
                    ", ..." if len(starts) > 5 else "")
                raise LogError(
                    f"--log {log}: the detections fit the scene at {len(starts)} times in the "
                    f"log (scene time 0 at log times {times} s): the log holds {len(starts)} "
                    f"plays of the scene, and a scene is checked against one; check a log of "
                    f"one run (`run --record` writes one, with the sidecar that aligns it), or "
                    f"give --time-offset-s (the log time of the play's scene time 0)")
            alignment = Alignment("estimated", 0.0, offset, found.uncertainty_s,
                                  found.plateau_s, latency)
            span_s = (found.plateau_s or 0.0) + (found.uncertainty_s or 0.0)
            alignment.notes.append(
                f"no sidecar ({Path(log).name}{LOG_SIDECAR_SUFFIX}): scene time 0 is estimated "
                f"from the detections themselves, so a scene that differs from the one played by "
                f"its targets' motion over {span_s * 1e3:.1f} ms (the estimate's span) fits "
                f"the log as well, and is not told (with --time-offset-s, the latency estimated "
                f"from the data takes it up); a log checked with the sidecar its recording "
                f"wrote is aligned by the run's own record")
        elif not aligned_by_data:
            # The scene's start given, nothing to estimate the latency on: the profile's.
            offset = float(time_offset_s)
            alignment = Alignment("given", 0.0, offset, latency_s=latency)
            alignment.notes.append("the radar's latency cannot be estimated (the scene has no "
                                   "targets, or the log no detection): its profile's is taken")
        else:
            # With the scene's start known in the log's time, the data tell the latency: the
            # same search, over latency + offset. Its latest fit is the longest latency the
            # data allow (the radar measuring each frame as it was applied); a shorter one by
            # up to the plateau fits as well (measuring later in each frame).
            offset = float(time_offset_s)
            # Plays of the scene the log holds from the given start on: the first is checked
            # (one before it lies a scene's length or more earlier: outside).
            plays_note = None
            within = (offset - 0.5 * scene.duration_s, offset + MAX_LATENCY_S)
            found = estimate_offset(scene, bus_t[chosen], dets, 0.0, within)
            plays = sorted((found.offset_s, *found.others_s))
            if len(plays) > 1:
                within = (within[0], 0.5 * (plays[0] + plays[1]))
                found = estimate_offset(scene, bus_t[chosen], dets, 0.0, within)
                plays_note = (
                    f"the detections fit the scene at {len(plays)} times in the log from "
                    f"--time-offset-s on (scene time 0 at log times "
                    f"{', '.join(f'{t:.3f}' for t in plays[:5])} s, the latency taken out): "
                    f"the play from {plays[0]:.3f} s is checked; the cycles after it are not "
                    f"the scene's")
            latency = found.offset_s - offset
            slack = 3 * (found.spread_s or 0.0) + 0.005
            if latency < -slack:
                raise LogError(f"--time-offset-s {offset:.6f}: the log's cycles would reach the "
                               f"bus {-latency * 1e3:.1f} ms before the radar measured them; "
                               f"the scene starts at log time {found.offset_s:.6f} s or "
                               f"earlier")
            if latency > MAX_LATENCY_S:
                first_t = float(bus_t[np.isfinite(bus_t)][0])
                raise LogError(f"--time-offset-s {offset:.6f}: the log's detections match the "
                               f"scene from log time {found.offset_s:.6f} s on, which would "
                               f"make the radar report {latency:.3g} s after measuring (at "
                               f"most {MAX_LATENCY_S:g} s); give the scene's start in the "
                               f"log's time base (its first cycle is at {first_t:.6f} s), or "
                               f"leave the option out to estimate it")
            latency = max(latency, 0.0)
            # Shorter by the plateau, but never below 0: a latency the data put at 0 is 0.
            plateau = min(found.plateau_s, latency)
            alignment = Alignment("given", 0.0, offset, None, plateau, latency,
                                  latency_source="estimated",
                                  latency_uncertainty_s=replace(
                                      found, plateau_s=plateau).uncertainty_s)
            if plays_note:
                alignment.notes.append(plays_note)
            if not (latency - plateau - slack <= profile_clock.latency_s <= latency + slack):
                alignment.notes.append(
                    f"the radar's latency from the data, {latency * 1e3:.1f} ms, differs from "
                    f"its profile's {profile_clock.latency_s * 1e3:.1f} ms")
                half_frame = 0.5 / scene.frame_rate_hz
                if not (latency - plateau - slack - half_frame <= profile_clock.latency_s
                        <= latency + slack + half_frame):
                    # As live (`time_alignment`): more than half a frame off, the detections
                    # were judged against frames the radar had not seen.
                    latency_reason = (
                        f"time_alignment: given the scene's start, the radar's latency from "
                        f"the data is {latency * 1e3:.1f} ms (the data fit as well down to "
                        f"{(latency - plateau) * 1e3:.1f} ms, give or take "
                        f"{slack * 1e3:.1f} ms), its profile's "
                        f"{profile_clock.latency_s * 1e3:.1f} ms: more than half a frame "
                        f"({half_frame * 1e3:.0f} ms) beyond that apart, the radar reports at "
                        f"other times than its profile says (or --time-offset-s is not the "
                        f"scene's start)")
        clock, kept = _fitted_clock(numbers, bus_t, counters, latency, offset, modulus,
                                    profile_clock.cycle_s, restart, start_tolerance_s)
        if (time_offset_s is None and restart is not None and counters.size
                and int(counters[0]) == restart):
            # The log's first cycle carries the count the radar restarts at with the scene
            # (its profile's): the scene's first cycle, measured at the profile's start, unless
            # the detections say otherwise beyond what they leave open. Under the estimate it
            # was measured at `first_s` (its cycle `after` counts from the scene's first).
            after = ((clock.counter_start or 0) - restart) % modulus
            first_s = clock.start_offset_s - after * clock.cycle_s
            later_s = profile_clock.start_offset_s - first_s  # the estimate's scene, later
            if later_s >= -span_s - START_TOLERANCE_S:  # else a radar started late
                offset -= later_s  # the count decides
                alignment.offset_s = offset
                clock, kept = _fitted_clock(numbers, bus_t, counters, latency, offset,
                                            modulus, profile_clock.cycle_s, restart,
                                            start_tolerance_s)
            later_cycles = later_s / clock.cycle_s
            # Beyond the estimate's span and half a cycle (the span is no hard bound: noise
            # moves the estimate by a millisecond or two beyond it); less is the estimate's
            # noise, and the detections' lag (`time_alignment`) judges what the count leaves.
            if later_s > span_s + 0.5 * clock.cycle_s:
                count_reason = (
                    f"radar_clock: the log's first cycle carries the count the radar "
                    f"restarts at with the scene ({restart}, its profile's), but the "
                    f"detections fit the scene only {later_cycles:.0f} cycles "
                    f"({later_s * 1e3:.0f} ms) later, beyond the estimate's span "
                    f"({span_s * 1e3:.0f} ms) and half a cycle: the radar reported "
                    f"{later_s * 1e3:.0f} ms later than its profile's latency, or missed the "
                    f"scene's start and saw targets after its end; a check without the "
                    f"recording's sidecar cannot tell which (check the log with its sidecar, "
                    f"or give --time-offset-s); the cycles are judged from the count's start")
            elif later_cycles >= 0.5:
                alignment.notes.append(
                    f"the detections fit as well a scene {later_s * 1e3:.0f} ms later, within "
                    f"the estimate's span; the log's first cycle carries the count the radar "
                    f"restarts at with the scene ({restart}, its profile's), so the scene is "
                    f"taken to start there")
        alignment.cycle_s = clock.cycle_s
        alignment.cycle_source = "profile" if kept else "fitted"
    alignment.cycles_in_log = len(index)
    jump = None
    if "bus_time_shifts" not in ((sidecar or {}).get("clock") or {}):
        # Nothing tells whether the host's clock stepped while the log was recorded.
        jump = stamp_jump(numbers, index.bus_t_s, profile_clock)
    skipped = None
    if jump is not None and 0 < jump[0] < counters.size:
        # Only where the counter itself stepped by other than one there: a contiguous count
        # with stamps that jump by whole cycles is a step of the host's clock (whole seconds).
        if (int(counters[jump[0]]) - int(counters[jump[0] - 1])) % modulus != 1:
            skipped = counter_skip(jump[1], profile_clock, modulus)
    why = ("the host's clock stepped while it was recorded (no sidecar of this version says "
           "so), or the radar's latency changed")
    if skipped is not None:
        # Whole cycles: as well the radar's count stepping beyond its stamps.
        why = (f"{abs(skipped)} whole cycles: the radar's counter skipped {abs(skipped)} "
               f"cycles {'ahead' if skipped > 0 else 'back'} (the cycles after it are named "
               f"by their counter), or the host's clock stepped by as much while it was "
               f"recorded")
    if jump is not None:
        at, size = jump
        alignment.notes.append(
            f"the log's stamps jump by {size * 1e3:+.1f} ms from its cycle {at + 1} on "
            f"(stamped {index.bus_t_s[at]:.6f} s), beyond the radar's jitter: {why}; the "
            f"stamps are taken as they are")
    alignment.log_cut_short = cut_short
    if channel_note:
        alignment.notes.append(channel_note)
    result, ends_early = _check(scene, log, can_mapping, counters, index.bus_t_s, clock,
                                modulus, method, batch_frames, bus, alignment, sidecar, channel,
                                shifts)
    half_window_s = 0.5 * ambiguity_window_s(scene.radar, scene.rig)
    if jump is not None and sidecar is None and abs(jump[1]) > half_window_s:
        # Aligned by its timestamps, the cycles after the jump are judged that far off.
        result.reasons.append(FailReason(
            f"log_stamps: the log's stamps jump by {jump[1] * 1e3:+.1f} ms from its cycle "
            f"{jump[0] + 1} on, more than half the ambiguity window ({half_window_s * 1e3:.3g}"
            f" ms): aligned by its timestamps, the cycles after it may be judged against the "
            f"wrong frames ({why}); a recording's sidecar says where the host's clock stepped",
            "log_stamps"))
        result.passed = False
    if unplaced:
        # Stamps the run brought back that this check cannot find: judged as they are, they
        # may put cycles against the wrong frames.
        result.reasons.append(FailReason(unplaced, "host_clock"))
        result.passed = False
    if other_mapping:
        spoken = recorded_mapping or "rts-scenario's messages"
        alignment.notes.append(f"--mapping {mapping} is not the one the run spoke ({spoken}, "
                               f"its sidecar): the log is read as this one says")
    if unused_method:
        alignment.notes.append(f"--method {method} is not used: the sidecar keeps the statuses "
                               f"the RTS played (with {(sidecar or {}).get('method')})")
    unread_reason, unread_note = (index.unread.verdict(log) if index.unread is not None
                                  else (None, None))
    alignment.log_unread = index.unread.summary() if index.unread is not None else None
    if unread_reason:
        # Records that may be the radar's, which python-can does not read: judged without
        # them, its cycles would be judged by what the log does not hold.
        result.reasons.append(FailReason(unread_reason, "log_unread"))
        result.passed = False
    elif unread_note:
        alignment.notes.append(unread_note)
    if cut_short is not None and ends_early:
        # Its missing cycles may not all show (a cycle's tail, those after the scene counted
        # as the run counts them): the log itself fails, first. A log cut short before any
        # message tells nothing of the bus: not said to have been silent.
        result.reasons[:] = [FailReason(cut_short["why"], "log_cut_short"),
                             *(r for r in result.reasons
                               if "bus_silent" not in getattr(r, "codes", ()))]
        result.passed = False
    elif cut_short is not None:
        # Its last cycle read was measured after every cycle counted: what it lacks counts
        # for nothing.
        alignment.notes.append(f"{cut_short['why']}; its last cycle read was measured after "
                               f"the scene and the cycles counted after it, so nothing counted "
                               f"is lost")
    # Messages none of which is the mapping's header (or headers of no cycle that came
    # whole), of identifiers it does not know: the radar spoke another protocol than the one
    # given, as live.
    spoken = mapping_reason(receiver_mapping, index.headers, bus.get("unknown_ids", 0),
                            result.frames)
    if spoken:
        result.reasons.append(FailReason(spoken, "mapping"))
        result.passed = False
    # A radar whose cycle is further from its profile's than a crystal strays fails, as live.
    track = ClockTrack(profile_clock)
    track.add(numbers, index.bus_t_s)
    late_reason = (late_start_reason(profile_clock, clock.start_offset_s)
                   if profile_clock.counter_start is not None else None)
    for off_profile in (track.off_profile_reason(half_window_s),
                        track.latency_change_reason(half_window_s), late_reason, count_reason):
        if off_profile:
            off_profile = with_mapping_hint(off_profile, receiver_mapping,
                                            bus.get("unknown_ids", 0))
            result.reasons.append(FailReason(off_profile, "radar_clock"))
            result.passed = False
    if latency_reason:
        result.reasons.append(FailReason(latency_reason, "time_alignment"))
        result.passed = False
    # When the radar measured, as this check took it (the run's clock from the sidecar, or the
    # one fitted to the log's timestamps), in the live report's terms.
    lag = result.radar_clock  # the detections' lag (`_check`)
    result.radar_clock = {
        "counter_start": clock.counter_start,
        "source": "sidecar" if sidecar is not None else "fitted to the log's timestamps",
        "cycle_s": clock.cycle_s, "start_offset_s": clock.start_offset_s}
    measured = track.fit.cycle_s()
    if measured is not None:
        result.radar_clock["bus_cycle_s"] = measured[0]
    change = track.latency_change_s()
    if change is not None:
        result.radar_clock["latency_change_s"] = change[0]
    late = (late_start_s(profile_clock, clock.start_offset_s)
            if profile_clock.counter_start is not None else None)
    if late is not None:
        result.radar_clock["late_start_s"] = late
    result.radar_clock.update(lag)
    steps = ((sidecar or {}).get("clock") or {}).get("host_clock_steps") or []
    if steps:
        # The run's, as it said them: the log's stamps were brought back as it did.
        result.radar_clock["host_clock_steps"] = steps
    playback = (sidecar or {}).get("playback")
    if sidecar is not None and not playback:
        alignment.notes.append("the sidecar records no playback: frames the run sent late, "
                               "or the RTS lost, are not judged")
    if playback:
        # The run's playback, as its sidecar recorded it: the re-check fails on it as the run
        # did.
        result.playback = {**playback, "output": playback.get("output",
                                                             (sidecar or {}).get("output"))}
        failures = playback_reasons(playback, scene.expectations.expected_limits)
        result.add_playback_limits(playback_limits(playback),
                                   scene.expectations.expected_limits)
        result.add_expected_not_hit(playback_not_hit(playback, scene.expectations.expected_limits))
        if failures:
            result.reasons += failures
            result.passed = False
        # An empty bench the simulated radar played: judged as the run judged it.
        judge_empty_bench(result, scene, scene.radar_options, result.playback["output"])
        # Crowded frames the simulated radar read alone: judged again from the schedule.
        options = scene.radar_options
        if (result.playback["output"] == "simulated-radar" and options.fidelity == "analytic"
                and options.cfar == "ca"):
            crowded = preflight(scene, method).crowded_analytic_frames
            judge_crowded_analytic(result, scene, crowded, "frames of the scene")
        worst = (playback.get("lateness_s") or {}).get("max")
        if (worst is not None and worst > float(playback.get("ambiguity_window_s") or 0.0)
                and not (sidecar or {}).get("send_lateness")):
            alignment.notes.append(
                f"frames went out up to {worst * 1e3:.1f} ms late in the run; the re-check "
                f"judges them at their nominal times (the sidecar, from an older version, "
                f"keeps no send times)")
    return RecheckResult(scene=scene, report=result, alignment=alignment,
                         mapping=receiver_mapping)


# How near a log's stamp must lie to the one the sidecar gives of the cycle a step of the
# host's clock moved the stamps from (s): a log's time resolution (ASC: 1 us).
SHIFT_MATCH_S = 1e-4


def _bus_time_shifts(index: _LogIndex,
                     sidecar: dict[str, Any] | None) -> tuple[FloatArray | None, str | None]:
    """Return what each of the log's cycles' bus time is brought back by, and any step not found.

    The sidecar's ``clock.bus_time_shifts``: from the cycle of that counter stamped ``bus_s``
    on (in log order), the stamps are ``shift_s`` off the clock the scene's start was taken
    on (the host's wall clock stepped, `rts_scenario.pipeline.Pipeline._unstep`). None where
    there are none; the reason where a cycle named is not in the log.
    """
    entries = ((sidecar or {}).get("clock") or {}).get("bus_time_shifts") or []
    if not entries:
        return None, None
    shifts = np.zeros(len(index))
    start = 0
    for entry in entries:
        found = np.flatnonzero((index.counters[start:] == int(entry["counter"]))
                               & (np.abs(index.bus_t_s[start:] - float(entry["bus_s"]))
                                  <= SHIFT_MATCH_S))
        if not found.size:
            return shifts, (f"host_clock: the host's wall clock stepped while the run recorded "
                            f"(its sidecar), its stamps moved by "
                            f"{float(entry['shift_s']) * 1e3:+.1f} ms from the cycle of counter "
                            f"{entry['counter']} stamped {float(entry['bus_s']):.6f} s, which "
                            f"is not in the log: the stamps from there on were not brought "
                            f"back, and cycles may be judged against the wrong frames")
        start += int(found[0])
        shifts[start:] = float(entry["shift_s"])
    return shifts, None


# Cycles on either side of a jump in a log's stamps whose medians are compared (`stamp_jump`),
# and at most as many on either side that confirm it (the stamps' scatter, which may be more
# than the profile's jitter, averages out over them: a jump is a step for good).
JUMP_CYCLES = 8
JUMP_CONFIRM_CYCLES = 64


def stamp_jump(numbers: IntArray, bus_t_s: FloatArray,
               clock: RadarClock) -> tuple[int, float] | None:
    """Return where a log's stamps jump (log position of the first cycle after it) and by how much.

    The stamps less a cycle times their numbers, in log order: the median of the
    `JUMP_CYCLES` after each cycle against that of those up to it. The cycle is the median of
    the stamps' steps per cycle over a quarter of the log, which a jump (within a third of
    them) leaves as it is: not the profile's,
    against which a radar off it would drift by a cycle's difference per cycle and read as a
    jump (its `radar_clock` reason tells that), nor a line fitted to the stamps, which a jump
    tilts. Each lies within the
    radar's jitter of the latency, so the two differ by at most twice its jitter, plus the
    stamping's noise and what a crystal within `CLOCK_TOLERANCE_PPM` draws over the windows;
    beyond that the stamps moved for good from there on (a cycle held up moves one). A jump
    found so is measured again over up to `JUMP_CONFIRM_CYCLES` on either side: stamps that
    scatter more than the profile's jitter (a busy host's stamping delays) move the median of
    8 by more than the bound now and then, not that of 64. The largest such jump; None where
    there is none.
    """
    t = np.asarray(bus_t_s, dtype=np.float64)
    ok = np.isfinite(t)
    k = JUMP_CYCLES
    if ok.sum() < 2 * k:
        return None
    positions = np.flatnonzero(ok)
    n = numbers[ok]
    # Steps over a quarter of the log: jitter shrinks by the lag, and a jump lies within a
    # third of them at most, which their median leaves out.
    lag = max(1, n.size // 4)
    steps, counted = t[ok][lag:] - t[ok][:-lag], n[lag:] - n[:-lag]
    cycle_s = float(np.median(steps[counted > 0] / counted[counted > 0])) \
        if (counted > 0).any() else clock.cycle_s
    r = t[ok] - t[ok][0] - (n - n[0]) * cycle_s
    windows = np.lib.stride_tricks.sliding_window_view(r, k)
    medians = np.median(windows, axis=1)  # of r[i:i + k]
    jumps = medians[k:] - medians[:-k]  # after cycle i + k - 1 against up to it
    bound = (2.0 * clock.jitter_s + STAMP_NOISE_S
             + CLOCK_TOLERANCE_PPM * 1e-6 * 2 * k * clock.cycle_s)
    if not jumps.size or np.abs(jumps).max() <= bound:
        return None
    # The strongest candidates (a step shows at up to k positions about it), each measured over
    # as many cycles on either side as the log and `JUMP_CONFIRM_CYCLES` allow, with a cycle
    # from the steps that do not cross it (those across tilt the stamps by the jump over the
    # lag: over 64 cycles, as much again as a jump's tenth).
    tn, nn = t[ok] - t[ok][0], (n - n[0]).astype(np.float64)
    candidates = np.flatnonzero(np.abs(jumps) > bound)
    candidates = candidates[np.argsort(-np.abs(jumps[candidates]), kind="stable")][:64]
    best: tuple[float, int, FloatArray] | None = None
    for i in candidates:  # a few dozen at most: not a loop over the log
        after = int(i) + k  # the first cycle after the jump
        same = ((np.arange(counted.size) + lag < after) | (np.arange(counted.size) >= after)) \
            & (counted > 0)
        c = float(np.median(steps[same] / counted[same])) if same.any() else cycle_s
        rr = tn - nn * c
        w = min(JUMP_CONFIRM_CYCLES, after, rr.size - after)
        wide = float(np.median(rr[after : after + w]) - np.median(rr[after - w : after]))
        if abs(wide) > bound and (best is None or abs(wide) > abs(best[0])):
            best = (wide, after, rr)
    if best is None:
        return None
    # Where it lies: the split about it that leaves the least deviation from the medians on
    # either side (a median moves with a few cycles on the wrong side, the deviations do not).
    _, after, rr = best
    lo, hi = max(1, after - k), min(rr.size - 1, after + k)
    region = rr[max(0, lo - JUMP_CONFIRM_CYCLES) : hi + JUMP_CONFIRM_CYCLES]
    base = max(0, lo - JUMP_CONFIRM_CYCLES)
    splits = np.arange(lo, hi + 1)
    cost = [np.abs(region[: q - base] - np.median(region[: q - base])).sum()
            + np.abs(region[q - base :] - np.median(region[q - base :])).sum() for q in splits]
    after = int(splits[int(np.argmin(cost))])
    w = min(JUMP_CONFIRM_CYCLES, after, rr.size - after)
    size = float(np.median(rr[after : after + w]) - np.median(rr[after - w : after]))
    return int(positions[after]), size


def counter_skip(jump_s: float, clock: RadarClock, modulus: int) -> int | None:
    """Cycles a radar's counter stepped beyond its stamps, where a jump of ``jump_s`` is that.

    Stamps that keep their pace while the counter steps ahead by ``m`` cycles more than they
    do read, less a cycle times their numbers, as a jump of ``-m`` cycles (`stamp_jump`):
    whole cycles, within twice the jitter and the stamping's noise (the jump is measured with
    the cycle of its own stamps, `stamp_jump`: no crystal's drift adds). None for a jump of
    no whole number of cycles, of more than half of what the counter counts (a step of the
    host's clock: an hour is whole cycles of many radars), or where that tolerance is a
    quarter of a cycle or more (whole cycles cannot be told).
    """
    cycles = -jump_s / clock.cycle_s
    m = int(round(cycles))
    tolerance_s = 2.0 * clock.jitter_s + STAMP_NOISE_S
    if (m == 0 or abs(m) >= modulus // 2 or tolerance_s >= 0.25 * clock.cycle_s
            or abs(cycles - m) * clock.cycle_s > tolerance_s):
        return None
    return m


def _check_sidecar_cycles(scene: Scenario, log: str | Path, clock: RadarClock,
                          cycles: int | None) -> None:
    """Refuse a sidecar whose ``clock.cycles`` its own clock does not put in the scene.

    The run judged the cycles its clock put in the scene: as many as the sidecar's cycle and
    phase give over the scene's duration, give or take the one at either edge (a radar that
    measured at the scene's start or end itself). Another number would judge other cycles
    than the run did (a few of them: a pass on a fraction of the scene).
    """
    if cycles is None:  # a sidecar from a version that did not keep it
        return
    expected = (len(clock.cycles_between(min(0.0, clock.start_offset_s), scene.duration_s)[0])
                if scene.n_frames else 0)
    if abs(cycles - expected) > 1:
        raise LogError(f"{log}{LOG_SIDECAR_SUFFIX}: clock.cycles: {cycles}, but cycles of "
                       f"{clock.cycle_s * 1e3:.6g} ms from {clock.start_offset_s:.6g} s put "
                       f"{expected} in the scene's {scene.duration_s:g} s (allowed: "
                       f"{max(expected - 1, 0)} to {expected + 1}); not what `rts-scenario run "
                       f"--record` writes for this scene")


def _check_timestamps(log: str | Path, bus_t: FloatArray, cycle_s: float,
                      numbers: IntArray) -> None:
    """Refuse to align a log by timestamps that do not advance with its cycles.

    All alike or nearly (a logger that wrote one time for every message: distinct cycles
    span at least a cycle each, a tenth of the profile's for a radar far off it), or going back
    by more than `STAMPS_BACK_S` from one cycle to the next in the radar's order (``numbers``:
    a clock set back while it logged; a cycle held up on the bus comes later, not earlier, and
    an incomplete one handed on after those that followed it is still in its place).
    """
    ordered = bus_t[np.argsort(numbers, kind="stable")]
    timed = ordered[np.isfinite(ordered)]
    advice = ("it cannot be aligned by them; the sidecar `run --record` writes aligns a log by "
              "the radar's counters")
    span = float(np.ptp(timed)) if timed.size else 0.0
    if timed.size >= 2 and not span >= 0.1 * cycle_s * (timed.size - 1):
        raise LogError(f"--log {log}: its radar cycles' timestamps do not advance: all "
                       f"{timed.size} of them within {span:.6f} s (cycles of "
                       f"{cycle_s * 1e3:g} ms take {cycle_s * (timed.size - 1):.3f} s); {advice}")
    step = np.diff(timed)
    back = np.flatnonzero(step < -STAMPS_BACK_S)
    if back.size:
        i = int(back[0])
        raise LogError(f"--log {log}: its radar cycles' timestamps go back: by "
                       f"{-step[i]:.6f} s from cycle {i + 1} to {i + 2} of the {timed.size} "
                       f"with a timestamp, in the order of the radar's counter "
                       f"({back.size} such steps): the logger's clock was set back, or the "
                       f"radar's counter restarted (switched off and on: a log of two runs, "
                       f"cut it to one); {advice}")


def _fitted_clock(numbers: IntArray, bus_t: FloatArray, counters: IntArray, latency_s: float,
                  offset_s: float, modulus: int, nominal_cycle_s: float,
                  restart: int | None = None, start_tolerance_s: float = START_TOLERANCE_S
                  ) -> tuple[RadarClock, bool]:
    """Return the radar's clock in scene time fitted to the header timestamps.

    And whether its cycle is the profile's (``nominal_cycle_s``), kept where the timestamps
    cannot tell the fitted one apart from it or cannot give one.

    Its cycle 0 is the first one measured at or after the scene's time 0, whether the log
    holds it or not: a log that begins after the scene did lacks the cycles before, and those
    are missing. Unless the log's first cycle carries the counter the radar's count starts at
    (``restart``, its profile's): a radar started after the scene began measured none
    before it. A cycle up to ``start_tolerance_s`` before the scene's start (the offset's
    uncertainty) is its first.
    """
    ok = np.isfinite(bus_t)
    if not ok.any():
        raise LogError("the log has no radar cycle with a timestamp to align")
    # Relative to the log's own first stamp: a log time of 1.7e9 s keeps only 0.2 us in a
    # float, and the fit's intercept less.
    t0 = float(bus_t[ok][0])
    if ok.sum() >= 2 and np.ptp(numbers[ok]) > 0:
        n, t = numbers[ok].astype(float), bus_t[ok] - t0
        cycle_s, first_s = np.polyfit(n, t, 1)
        # A cycle held up on the bus (one late stamp) must not tilt the cycle time: fit again
        # without the stamps far outside the others' spread.
        residual = t - (first_s + cycle_s * n)
        spread = 1.4826 * np.median(np.abs(residual - np.median(residual)))
        keep = np.abs(residual) <= max(5.0 * spread, FIT_OUTLIER_FLOOR_S)
        if not keep.all() and np.ptp(n[keep]) > 0:
            n, t = n[keep], t[keep]
            cycle_s, first_s = np.polyfit(n, t, 1)
        if not cycle_s > 0:
            raise LogError(f"the log's timestamps go back as its radar cycles go on (a cycle of "
                           f"{cycle_s:.6g} s fits them); it cannot be aligned by them")
        # A cycle the stamps cannot tell from the profile's (within three standard errors, or
        # by less than rounding over the cycles), as live (`ClockTrack.cycle_from_bus`): the
        # profile's, not the fit's noise. So too where they bend away from one line (a
        # latency that changed on the way tilts the fit, the radar's clock running on), with
        # the phase of their lowest level (`CycleTimeFit.zero_s`); the check's `ClockTrack`
        # then judges the bend (`ClockTrack.latency_change_reason`).
        fit = CycleTimeFit()
        fit.add(n.astype(np.int64), t)
        bend = fit.bend()
        kept = (bend is not None and bend.bent) or _indistinguishable(
            n, t, float(cycle_s), nominal_cycle_s)
        if kept:
            zero = fit.zero_s(nominal_cycle_s)
            assert zero is not None  # cycles were added
            cycle_s, first_s = nominal_cycle_s, zero
    else:
        kept = True
        cycle_s, first_s = nominal_cycle_s, float(bus_t[ok][0] - t0 - numbers[ok][0]
                                                  * nominal_cycle_s)
    start = (t0 - offset_s) - latency_s + first_s  # scene time of the log's cycle number 0
    shift = int(np.ceil((-start - start_tolerance_s) / cycle_s))
    if restart is not None and counters.size and int(counters[0]) == restart:
        shift = max(shift, 0)
    return RadarClock(cycle_s=float(cycle_s),
                      start_offset_s=max(0.0, float(start + shift * cycle_s)),
                      latency_s=latency_s,
                      counter_start=int((counters[0] + shift) % modulus) if counters.size
                      else 0), kept


def _indistinguishable(n: FloatArray, t: FloatArray, cycle_s: float,
                       nominal_cycle_s: float) -> bool:
    """Whether the cycle fitted to stamps ``t`` of cycles ``n`` may be ``nominal_cycle_s``.

    Within three standard errors of the fit, or by less than `DRIFT_FLOOR_S` over the cycles'
    span (stamps rounded to a microsecond).
    """
    off = abs(cycle_s - nominal_cycle_s)
    if off * float(np.ptp(n)) <= DRIFT_FLOOR_S:
        return True
    if n.size < 3:
        return False
    dn = n - n.mean()
    residual = t - t.mean() - cycle_s * dn
    error = float(np.sqrt(residual @ residual / (n.size - 2) / (dn @ dn)))
    return off <= 3.0 * error


def _refuse_runs(log: str | Path, starts: tuple[float, ...], restart: int | None) -> None:
    """Refuse a log without a sidecar whose radar count starts at ``restart`` twice or more.

    The profile's counter start begins each run's count (the RTS's stream restarts it): a
    log whose headers come back to it from another count holds several runs (a logger left
    running), and would be judged as one, its reasons about cycles of the other run. A start
    is a header with that count further back than `OPEN_CYCLES` from the header before (the
    first header too): a wrap round to it, a reordered header or a copy is none; a count back
    by more than half the counter's range reads as a step forward and is not told
    (`DetectionReceiver.count_starts`).
    """
    if restart is None or len(starts) < 2:
        return
    times = ", ".join(f"{t:.3f}" for t in starts[:5]) + (", ..." if len(starts) > 5 else "")
    raise LogError(f"--log {log}: the radar's count starts at its profile's counter_start "
                   f"({restart}) {len(starts)} times (log times {times} s): the log holds "
                   f"{len(starts)} runs of the radar, and a scene is checked against one; "
                   f"check a log of one run (`run --record` writes one, with the sidecar "
                   f"that aligns it)")


def _counter_restart(scene: Scenario, mapping: CanMapping | None) -> int | None:
    """Return the counter the run's stream restarted the radar's count at, as live.

    The profile's counter start (`rts_scenario.pipeline.Pipeline`, its receiver's reset): the
    cycles the log holds before it, of the stream before, are dropped as the run dropped
    them. None for a radar running free.
    """
    start = scene.radar.radar_clock.counter_start
    return None if start is None else start % (mapping or CanMapping.builtin()).counter_modulus


# Stamps of a wall clock, seconds since 1970 (2001 on): a host's, a recorder's. A log whose
# reader gives times from its start (python-can's ASC reader), or an interface's own clock
# (seconds since it was plugged in), is on another time base than its sidecar's scene start.
WALL_CLOCK_STAMP_S = 1e9
# A time zone moves a log's wall-clock stamps by whole quarter hours (a tool converting it,
# another machine reading it).
TIME_ZONE_STEP_S = 900.0


def _refuse_another_run(log: str | Path, origin_bus_s: float | None, clock: RadarClock,
                        bus_t_s: FloatArray, rel: IntArray, inside: BoolArray) -> None:
    """Refuse a log whose cycles were stamped elsewhere than its sidecar's run timed them.

    The sidecar keeps the scene's start on the bus's clock (``origin_bus_s``): the run's
    cycles reached the bus at that start, plus the clock's latency and phase, plus their
    number of cycles, within the jitter. Where the log's stamps keep to that cycle but lie
    seconds off (less whole quarter hours: a time zone), the log is another run's beside this
    sidecar (a log copied over the run's, a recorder of its own writing to its name), and its
    counters would name its cycles as the run's. Stamps on another time base, or that keep to
    no cycle (a logger writing one time for all), are left to the counters, as before.
    """
    sel = inside & np.isfinite(bus_t_s)
    if origin_bus_s is None or not sel.any():
        return
    if not min(float(origin_bus_s), float(np.min(bus_t_s[sel]))) > WALL_CLOCK_STAMP_S:
        return
    zero_bus_s = float(origin_bus_s) + clock.latency_s + clock.start_offset_s
    off = bus_t_s[sel] - (zero_bus_s + rel[sel] * clock.cycle_s)
    mid = float(np.median(off))
    tolerance_s = max(0.5, 2.0 * clock.cycle_s + 3.0 * clock.jitter_s)
    if float(np.median(np.abs(off - mid))) > tolerance_s:
        return  # stamps that keep to no cycle: the counters tell
    miss = mid - round(mid / TIME_ZONE_STEP_S) * TIME_ZONE_STEP_S
    if abs(miss) <= tolerance_s:
        return
    raise LogError(f"--log {log}: its radar cycles were stamped {abs(miss):.1f} s "
                   f"{'before' if miss < 0 else 'after'} the times the run its sidecar "
                   f"({log}{LOG_SIDECAR_SUFFIX}) records timed them (its scene's start at bus "
                   f"time {float(origin_bus_s):.6f} s, clock.origin_bus_s): a log of another run "
                   f"beside this sidecar (copied over the run's log, or written by another "
                   f"recorder?); check it with the sidecar its run wrote, or a copy of it "
                   f"without one to align it by its timestamps")


def _check(scene: Scenario, log: str | Path, mapping: CanMapping | None, counters: IntArray,
           bus_t_s: FloatArray, clock: RadarClock,
           modulus: int, method: str, batch_frames: int | None, bus: dict[str, int],
           alignment: Alignment, sidecar: dict[str, Any] | None,
           channel: str | None = None, shifts: FloatArray | None = None
           ) -> tuple[Report, bool]:
    """Check the log's cycles (``counters`` in log order, their bus times) batch by batch.

    Returns the report and whether the log ends before the cycles counted end (the scene's
    and those after it counted as ``after_scene``): what a log cut short lacks may count.
    """
    # The bus the run sent on (its sidecar), else not known: both ends of a signal count.
    fd = (sidecar or {}).get("can_fd")
    read_with = mapping or CanMapping.builtin()
    checker = Checker(scene.name, tuple(t.name for t in scene.targets), scene.expectations,
                      counter_modulus=modulus, counter_start=clock.counter_start,
                      expected_limits=[t.expected_limits for t in scene.targets],
                      scene_limits=scene_limits(scene), variant=scene.variant,
                      parameters=scene.parameters, cycle_s=clock.cycle_s,
                      not_carried=read_with.not_carried(), limits=read_with.limits(fd),
                      mapping_name=read_with.name,
                      jitter_s=clock.jitter_s)
    # The cycles the run judged (its sidecar), else those the clock puts in the scene.
    cycles = (sidecar or {}).get("clock", {}).get("cycles")
    total = cycles if cycles is not None else len(
        clock.cycles_between(0.0, scene.duration_s)[0]) if scene.n_frames else 0
    # Cycle numbers in the clock's terms, in log order (the counter wraps with the signal).
    origin = (sidecar or {}).get("clock", {}).get("origin_bus_s")
    first_t = bus_t_s[np.isfinite(bus_t_s)][:1]
    late_s = scene.duration_s + clock.latency_s + clock.jitter_s + BUS_CLOCK_SLACK_S
    if origin is not None and first_t.size and not (
            -BUS_CLOCK_SLACK_S <= float(first_t[0]) - float(origin) <= late_s):
        origin = None  # the log's times moved since (a tool, a time zone): the counters tell
    if origin is not None and counters.size:
        # The scene's start on the bus's clock (the run's): the first cycle is a step from
        # cycle 0 told by its bus time too, as live (`Checker.anchor`).
        zero_bus_s = float(origin) + clock.latency_s + clock.start_offset_s
        rel = sequential_numbers(
            np.r_[0, (counters - (clock.counter_start or 0)) % modulus], modulus,
            np.r_[zero_bus_s, bus_t_s], clock.cycle_s)[1:]
        checker.anchor(0, zero_bus_s)
    else:
        first = int(np.mod(counters[0] - clock.counter_start + modulus // 2, modulus)
                    - modulus // 2) if counters.size else 0
        if (sidecar is None and alignment.offset_s is not None and counters.size
                and np.isfinite(bus_t_s[0])):
            # Aligned by its stamps: they tell how many cycles from the scene's first the log's
            # first was measured, the counter which of those its wrap allows (a logger started
            # long before the scene, or after it began, beyond half the counter's range).
            zero_s = alignment.offset_s + clock.latency_s + clock.start_offset_s
            timed = (float(bus_t_s[0]) - zero_s) / clock.cycle_s
            first += int(np.round((timed - first) / modulus)) * modulus
            checker.anchor(0, zero_s)  # the checker numbers its first cycle alike
        rel = sequential_numbers(counters, modulus, bus_t_s, clock.cycle_s) + first
    inside = (rel >= 0) & (rel < total)
    recorded_clock = (sidecar or {}).get("clock") or {}
    if not recorded_clock.get("bus_time_shifts"):
        # (Where the host's clock stepped, its stamps are brought back from the cycle the
        # sidecar names, which another run's log lacks: `host_clock` fails it.)
        _refuse_another_run(log, recorded_clock.get("origin_bus_s"), clock, bus_t_s, rel,
                            inside)
    alignment.cycles_outside_scene = int((~inside).sum())
    logged = _ReadAhead(log, mapping, inside, scene.radar.radar_clock.cycle_s, channel=channel,
                        shifts=shifts, restart=_counter_restart(scene, mapping))
    digest = hashlib.sha256()
    order = np.argsort(rel, kind="stable")
    rel_sorted = rel[order]
    # Frames as the run sent them (the sidecar's send times), else as applied at their times:
    # the ambiguity window around each change covers the transport, as it does live.
    late = _send_lateness(scene, sidecar, log)
    truths = CycleTruth(checker, scene, clock, ambiguity_window_s(scene.radar, scene.rig),
                        cycles)
    truths.early_s = float((sidecar or {}).get("clock", {}).get("early_s") or 0.0)

    def check_cycles(n: IntArray) -> None:
        if n.size:
            lo, hi = np.searchsorted(rel_sorted, [n[0], n[-1] + 1])
            checker.add_cycles(logged.take(order[lo:hi]))
            checker.settle(before_frame=int(n[-1]) + 1)

    played = _status_record(scene, sidecar, log)
    truth_sums = TruthChecksums(t.name for t in scene.targets)
    for frames, tracks, status in _batches(scene, method, batch_frames, played, log):
        if played is None:
            digest.update(status.tobytes())
        truth_sums.add(tracks, frames)
        checker.add_frames(tracks, status)
        sent = None if late is None else scene.t_s[frames] + late[frames]
        check_cycles(truths.add(frames, status, sent))
    check_cycles(truths.finish())
    checker.settle()
    # Cycles measured after the scene's last (a radar keeps measuring what the RTS holds) or
    # before its first are counted as the run counted them; they were never handed to the
    # checker. After it, those within the window the run counts (`after_scene_until_s`): a
    # recorder goes on after the run stopped listening. A second cycle with the number of one
    # of those is repeated, as live.
    until_s = after_scene_until_s(scene.duration_s, clock.cycle_s)
    end = max(total, clock.first_at(until_s))
    after = rel[(rel >= total) & (rel < end)]
    distinct = int(np.unique(after).size)
    checker.frames["after_scene"] += distinct
    checker.frames["repeated"] += int(after.size) - distinct
    checker.frames["before_scene"] += int((rel < 0).sum())
    checker.tally_out_of_count(rel[rel < 0], bus_t_s[rel < 0])
    # Those that came while the scene played are not the radar's own after it (`tally_ahead`).
    later = int((~checker.tally_ahead(rel[rel >= end], bus_t_s[rel >= end])).sum())
    if later:
        alignment.notes.append(
            f"{later} cycles in the log were measured after the scene's end and the "
            f"{(until_s - scene.duration_s) * 1e3:.0f} ms after it in which cycles are counted "
            f"(after_scene; the recorder went on after the run stopped listening): not counted")
    if played is not None:
        alignment.statuses = "recorded"
    elif sidecar is not None and sidecar.get("status_sha256"):
        alignment.schedule_matches_recording = digest.hexdigest() == sidecar["status_sha256"]
        if not alignment.schedule_matches_recording:
            alignment.notes.append("the rebuilt schedule differs from the one recorded (another "
                                   "version, rig or radar file): limits are those rebuilt")
    report = checker.report(bus)
    _compare_truth(truth_sums, sidecar, alignment, report)
    lagged = checker.lag_reason(1.0 / scene.frame_rate_hz, scene.radar.coupling_lag_s)
    if lagged:
        report.reasons.append(FailReason(lagged, "time_alignment"))
        report.passed = False
    report.radar_clock.update(lag_dict(checker, scene.radar.coupling_lag_s, truths.early_s))
    return report, not (rel.size and rel[-1] >= end)


def _status_record(scene: Scenario, sidecar: dict[str, Any] | None,
                   log: str | Path) -> StatusRecord | None:
    """Return the statuses the run played (its sidecar's), or None (rebuilt from the scene)."""
    record = (sidecar or {}).get("statuses")
    if record is None:
        return None
    try:
        return StatusRecord(record, scene.n_frames, len(scene.targets),
                            (t.name for t in scene.targets))
    except ValueError as exc:
        raise _sidecar_error(log, "statuses", exc) from None


def _batches(scene: Scenario, method: str, batch_frames: int | None,
             played: StatusRecord | None, log: str | Path
             ) -> Iterator[tuple[IntArray, Tracks, NDArray[np.uint16]]]:
    """Yield the scene's frames, tracks and statuses batch by batch.

    The statuses the run played when its sidecar keeps them, else a rebuilt schedule's.
    """
    if played is None:
        for frames, tracks, schedule in schedule_batches(scene, method, batch_frames):
            yield frames, tracks, schedule.status
        return
    try:
        for frames, tracks in track_batches(scene, batch_frames):
            yield frames, tracks, played.take(frames.size)
        played.finish()
    except ValueError as exc:
        raise _sidecar_error(log, "statuses", exc) from None


def _compare_truth(truth_sums: TruthChecksums, sidecar: dict[str, Any] | None,
                   alignment: Alignment, report: Report) -> None:
    """Fail a report whose scene's ground truth is not the one the recorded run played."""
    record = (sidecar or {}).get("truth")
    if sidecar is None:
        return
    if record is None:
        alignment.notes.append("the sidecar keeps no checksum of the ground truth (an older "
                               "version wrote it): the scene is taken to be the one that played")
        return
    differing = truth_sums.differing(record)
    if differing is None:
        alignment.notes.append("the sidecar's checksum of the ground truth was made another "
                               "way (another version): the scene is taken to be the one that "
                               "played")
        return
    alignment.truth_matches_recording = not differing
    if differing:
        recorded, mine = set(record["targets"]), set(truth_sums.names)
        named = [f"{name!r}" + (" (not in the recording)" if name not in recorded else
                                " (not in the scene)" if name not in mine else "")
                 for name in differing[:5]]
        if len(differing) > 5:
            named[-1:] = [named[-1], f"{len(differing) - 5} more"]
        shown = named[0] if len(named) == 1 else ", ".join(named[:-1]) + " and " + named[-1]
        report.reasons.append(FailReason(
            f"scene: the ground truth of {shown} differs from the one the recorded run "
            f"played (the scene file, its radar profile or the version computing it changed "
            f"since): the log "
            f"is judged against a scene that did not play; check it against the scene file "
            f"as it was", "ground_truth"))
        report.passed = False


def _alignment_cycles(index: _LogIndex) -> IntArray:
    """Return the positions of the cycles an offset is estimated on.

    Those with a bus time; of a longer log, `ALIGN_CYCLES` spread evenly over the ones with
    detections, the first kept.
    """
    timed = np.flatnonzero(np.isfinite(index.bus_t_s))
    if timed.size <= ALIGN_CYCLES:
        return timed
    seen = timed[index.counts[timed] > 0]
    if seen.size <= ALIGN_CYCLES:
        return seen
    return seen[np.unique(np.linspace(0, seen.size - 1, ALIGN_CYCLES).astype(np.int64))]


def _sidecar_error(log: str | Path, key: str, exc: ValueError) -> LogError:
    """Return the error for a sidecar's ``key`` that is not what ``run --record`` writes."""
    return LogError(f"{log}{LOG_SIDECAR_SUFFIX}: {key}: {exc} (not what "
                    f"`rts-scenario run --record` wrote for this scene)")


def _send_lateness(scene: Scenario, sidecar: dict[str, Any] | None,
                   log: str | Path) -> FloatArray | None:
    """Each frame's lateness as the run's sidecar recorded it; None without (nominal times)."""
    record = (sidecar or {}).get("send_lateness")
    if record is None:
        return None
    try:
        return unpack_send_lateness(record, scene.n_frames)
    except ValueError as exc:
        raise _sidecar_error(log, "send_lateness", exc) from None


__all__ = ["LOG_SUFFIXES", "Alignment", "LogError", "OffsetEstimate", "RecheckResult",
           "RecordedClock",
           "check_log", "check_log_file", "estimate_offset", "log_variant", "read_cycles",
           "read_sidecar"]
