"""One pipeline for every run: scene -> tracks -> schedule -> output -> radar -> CAN -> check.

`Pipeline` wires a bench once - the CAN bus the checker listens on, the receiver, the output
(from the registry: a file, the RTS over UDP, the simulated radar, a plugin) and, when the output
is the simulated radar, the bus it publishes its detections on - and closes all of it. A scene
runs as a stream of frame batches: kinematics, schedule, playback, reception and checking per
batch, so memory does not grow with the length of the scene. The CLI, the pytest plugin and
calibration all run through it.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import TracebackType
from typing import Any, TextIO

import can
import numpy as np

from . import mf4
from .atomic import write_atomic
from .canbus import (
    DetectionPublisher,
    DetectionReceiver,
    ListenerBus,
    mapping_reason,
    open_bus,
    with_mapping_hint,
)
from .canbus.mapping import CanMapping
from .check import Checker, checkable
from .detections import Detections, bus_times, host_times, sequential_numbers, unwrap_counter
from .errors import MeasurementError
from .hostclock import HostClockWatch, monotonic_s, wall_s
from .kinematics import compute_tracks
from .outputs import Output, output_class, split_spec
from .outputs.base import RunContext
from .playback import (
    LOST_COUNTERS,
    Playback,
    lost_frames,
    playback_limits,
    rig_difference,
    rts_rig_record,
    unreachable_reason,
)
from .plot_data import PlotData
from .preflight import (
    Preflight,
    angle_tolerance_deg,
    frames_per_batch,
    preflight,
    scene_limits,
    vacuous_empty_bench,
)
from .radar.clock import TIME_EPS_S, ClockTrack, RadarClock, latency_not_late_start_reason
from .radar.profile import RadarProfile
from .radar.simulate import ChannelErrors
from .recording import PlayedRecord
from .report import FailReason, FrameRecord, Report, strict
from .rig import Rig
from .scenario import Scenario, load_scenario
from .scenario.model import RadarOptions
from .schedule import Schedule, build_schedule, held_frames
from .schedule.build import FE_RESPONSES, solver_inputs
from .solver import solver_plan
from .solver.estimator_aware import plan_method
from .suffixes import LOG_SIDECAR_SUFFIX

# Frames per batch: large enough to amortize per-call costs, small enough for bounded memory.
BATCH_FRAMES = 500
# Without a known message count (a real radar), the bus is drained this long after the radar's
# latency, jitter and one cycle.
QUIET_S = 0.2
# At the end of a stream, how long to wait for the RTS's report of its last frames (s).
RTS_SETTLE_S = 0.2
# How far outside the scene (plus the radar's latency) the first cycle's bus time may lie and
# still be on the clock the scene's start was taken on (s): a radar's cycles from just before
# the stream started, or one silent for a while. Farther, the interface stamps with its own.
BUS_CLOCK_SLACK_S = 10.0
# How long the host may take to receive a radar's message once it was on the bus, at the
# fastest of a measurement's cycles (the interface's buffering, its driver, the notifier's
# thread) (s). Where the interface stamps with its own clock, when the host received the
# cycles places them against a measurement's frames (`Pipeline.play`) within this.
HOST_DELIVERY_S = 0.01
# How fast an interface's clock may run against the host's (two crystals' tolerance).
HOST_DRIFT = 2e-4
# Stamps whose fastest receipt over seconds lies further than this after them are on another
# clock than the host's (s): a loaded host holds some messages up, never every one that long.
# (A stamp received before it was made, by more than HOST_DELIVERY_S, is another clock's too.)
RECEIPT_OFF_S = 0.25
# A run ties an interface's own clock to the host's by the fastest delivery over the last
# LINK_BLOCKS blocks of LINK_BLOCK_S of the interface's time (`ClockLink`).
LINK_BLOCK_S = 1.0
LINK_BLOCKS = 5


def stamped_on_another_clock(least_delay_s: float) -> bool:
    """Whether stamps whose least receipt-less-stamp is ``least_delay_s`` are another clock's.

    No message reaches the host before it was stamped (by more than `HOST_DELIVERY_S`), nor
    every one of seconds of them more than `RECEIPT_OFF_S` after: stamps that say otherwise
    are on another clock than the host's, though within the scene's reach (an interface's, set
    from the host's once and run off since). One less than `RECEIPT_OFF_S` behind the host's
    shows as the detections' lag (`Checker.lag_reason`).
    """
    return not -HOST_DELIVERY_S <= least_delay_s <= RECEIPT_OFF_S


class ClockLink:
    """An interface's own clock tied to the host's, by when the host received its messages.

    A message reached the host a delivery delay (not negative) after the interface stamped it,
    so the least ``host - bus`` time over many is the offset between the two clocks, late by
    the fastest delivery (at most `HOST_DELIVERY_S`). It is kept per block of `LINK_BLOCK_S`
    of the interface's time: the least over the last `LINK_BLOCKS` blocks (`offset_s`) follows
    two crystals running apart (`HOST_DRIFT`) as a run goes on, and the line below every
    block's least and nearest them (`line`: on the lower convex hull of the blocks' least, a
    few points) gives their rate over the whole run. A block whose messages were all held up
    (an interface's start-up, a loaded host) lies above that line and does not tilt it. A time
    on the interface's clock plus either offset is on the host's, at most `error_s` late.
    """

    error_s = HOST_DELIVERY_S + HOST_DRIFT * LINK_BLOCK_S * LINK_BLOCKS

    def __init__(self) -> None:
        # Set where the receipts turned out not to be deliveries: the clocks are not tied.
        self.broken = False
        self._least: dict[int, tuple[float, float]] = {}  # block: least delay, its bus time
        self._ref: float | None = None
        # The blocks that left the window: how many, the sum of their bus times (from
        # ``_ref``), and the lower convex hull of their (bus time, least delay).
        self._count, self._sum_x = 0, 0.0
        self._hull: list[tuple[float, float]] = []

    def add(self, bus_t_s: np.ndarray, host_t_s: np.ndarray) -> None:
        """Take messages stamped ``bus_t_s`` by the interface and received at ``host_t_s``."""
        ok = np.isfinite(bus_t_s) & np.isfinite(host_t_s)
        if not ok.any():
            return
        bus, delay = bus_t_s[ok], host_t_s[ok] - bus_t_s[ok]
        if self._ref is None:
            self._ref = float(bus[0])
        block = np.floor(bus / LINK_BLOCK_S).astype(np.int64)
        order = np.lexsort((delay, block))  # by block, then the least delay first
        blocks, first = np.unique(block[order], return_index=True)
        for b, i in zip(blocks.tolist(), order[first].tolist(), strict=True):
            old = self._least.get(b)  # a batch spans a few blocks
            if old is None or delay[i] < old[0]:
                self._least[b] = (float(delay[i]), float(bus[i]))
        for b in sorted(self._least)[:-LINK_BLOCKS]:
            y, x = self._least.pop(b)
            x -= self._ref
            self._count, self._sum_x = self._count + 1, self._sum_x + x
            self._hull = _lower_hull(self._hull + [(x, y)])

    @property
    def offset_s(self) -> float | None:
        """The host's time less the interface's now (the recent blocks'); None before any."""
        return min(y for y, _ in self._least.values()) if self._least else None

    def line(self) -> tuple[float, float, float] | None:
        """Return the host's time less the interface's over the run: ``(offset, rate, at)``.

        ``offset + rate * (t - at)`` at interface time ``t``; the line below every block's
        least delay (a delay is not negative: each lies above the clocks' true line by its
        fastest delivery) that lies highest at the blocks' mean time: the edge of their lower
        convex hull across it. Blocks held up (a start-up's) lie above it and leave it be. The
        rate is 0 over less than `LINK_BLOCKS` blocks and held to `HOST_DRIFT` (the line then
        the highest below every block with that rate). None before any message.
        """
        if self._ref is None:
            return None
        recent = sorted((x - self._ref, y) for y, x in self._least.values())
        points = _lower_hull(self._hull + recent) if self._hull else _lower_hull(recent)
        n = self._count + len(recent)
        mean = (self._sum_x + sum(x for x, _ in recent)) / n
        rate = 0.0
        if n > LINK_BLOCKS and len(points) > 1:
            xs = np.array([x for x, _ in points])
            i = int(np.clip(np.searchsorted(xs, mean), 1, len(points) - 1))
            (x0, y0), (x1, y1) = points[i - 1], points[i]
            rate = float(np.clip((y1 - y0) / (x1 - x0), -HOST_DRIFT, HOST_DRIFT))
        offset = min(y - rate * (x - mean) for x, y in points)
        return float(offset - rate * mean), rate, self._ref


def _lower_hull(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """Return the lower convex hull of ``points``, sorted by x (Andrew's monotone chain)."""
    hull: list[tuple[float, float]] = []
    for p in sorted(points):
        while len(hull) >= 2 and ((hull[-1][0] - hull[-2][0]) * (p[1] - hull[-2][1])
                                  - (hull[-1][1] - hull[-2][1]) * (p[0] - hull[-2][0])) <= 0.0:
            hull.pop()
        if hull and hull[-1][0] == p[0]:
            continue  # the same time again, not lower (sorted): the lower one stays
        hull.append(p)
    return hull


@dataclass(frozen=True)
class RunOptions:
    """How to run a scene.

    Attributes
    ----------
    output : str
        Output spec: ``simulated-radar`` (default), ``udp://HOST:PORT``, ``file:PATH`` or any
        registered ``NAME[:ARGUMENT]``.
    can_interface, can_channel, can_fd : str, str or None, bool
        The bus the radar's detections come on (python-can); a private virtual channel by
        default.
    radar_channel : str, optional
        On an interface listening on several channels, the one the radar's messages come on
        (``Message.channel`` as text, `rts_scenario.canbus.channel_label`): the others are
        not read (``other_channels`` in the report's bus). Without it, radar identifiers
        heard on several channels fail the verdict (`DetectionReceiver.channel_reason`).
    option_prefix : str
        What comes after the dashes of an option a reason names (``--radar-channel``,
        ``--mapping``): none for the command's, ``rts-`` for the pytest plugin's
        (``--rts-radar-channel``, ``--rts-mapping``).
    mapping : str, optional
        ``*.mapping.yaml`` of a third-party radar's DBC.
    method : {"exact", "paper", "estimator"}
        Weight solver.
    drain_s : float
        Longest wait for the simulated radar's last detections after the last frame (a radar
        on the bus is waited for as long as its clock's latency, jitter and cycle say).
    batch_frames : int, optional
        Frames per streamed batch; default `BATCH_FRAMES`, fewer for scenes with many targets
        (`rts_scenario.preflight.frames_per_batch`: memory stays bounded).
    record : bool
        Keep every frame's check arrays (on disk) for post-processing (`Report.per_frame`).
    plot : bool
        Gather what `rts_scenario.plots.write_plots` draws (`RunResult.plot`), in memory that
        does not grow with the scene's length (`rts_scenario.plot_data.PlotData`).
    bus_log : str, optional
        Record the detection bus to this file with python-can's ``Logger`` (format by
        extension: .blf, .asc, .csv, .log, .trc, .mf4 with asammdf), plus ``LOG.rts.json``
        (`write_log_sidecar`) for ``rts-scenario check --log``.
    """

    output: str = "simulated-radar"
    can_interface: str = "virtual"
    can_channel: str | None = None
    can_fd: bool = False
    radar_channel: str | None = None
    option_prefix: str = ""
    mapping: str | None = None
    method: str = "exact"
    drain_s: float = 2.0
    batch_frames: int | None = None
    record: bool = False
    plot: bool = False
    bus_log: str | None = None

    def option(self, name: str) -> str:
        """Return option ``name`` (the command's, without dashes) as the caller spells it."""
        return f"--{self.option_prefix}{name}"


@dataclass
class RunResult:
    """What a run produced: the scene and its report (per-frame arrays in ``report.record``)."""

    scene: Scenario
    report: Report
    # What the plots draw, gathered as the run went (`RunOptions.plot`), else None.
    plot: PlotData | None = None
    # Why the recorded log's sidecar (``LOG.rts.json``) could not be written, else None: the
    # verdict stands, but a check of the log then aligns it by its data alone.
    sidecar_error: str | None = None


@dataclass
class _Timing:
    """Seconds per stage, summed over batches."""

    stages: dict[str, float] = field(default_factory=dict)

    def add(self, stage: str, since: float) -> float:
        now = time.perf_counter()
        self.stages[stage] = self.stages.get(stage, 0.0) + now - since
        return now


class Pipeline:
    """A wired bench: output, detection bus, receiver; closes everything it opened.

    Parameters
    ----------
    rig : Rig
        The RTS rig.
    radar : RadarProfile
        The radar under test (the simulated radar's profile; the array the solver uses).
    options : RunOptions, optional
        Output, bus and solver choices.
    radar_options : RadarOptions, optional
        How the simulated radar runs (fidelity, estimator, CFAR, noise).
    errors : ChannelErrors, optional
        Channel errors injected into the simulated bench (calibration studies).
    rng : numpy.random.Generator, optional
        Noise source of the simulated radar.
    """

    def __init__(self, rig: Rig, radar: RadarProfile, options: RunOptions | None = None, *,
                 radar_options: RadarOptions | None = None, errors: ChannelErrors | None = None,
                 rng: np.random.Generator | None = None) -> None:
        self.rig = rig
        self.radar = radar
        self.options = options = options or RunOptions()
        self._buses: list[can.BusABC] = []
        self._publisher: DetectionPublisher | None = None
        self._notifier: can.Notifier | None = None
        self._logger: can.Listener | None = None
        self._recording: _Recording | None = None
        self.counter_start_learnt: tuple[int, str] | None = None
        # The scene's start on the bus's clock where the simulated radar stamps its messages.
        self._bus_origin_s: float | None = None
        # Whether the cycles' bus times were found on another clock than the scene's start,
        # and that clock tied to the host's in a run (`ClockLink`).
        self._bus_clock_checked = self._bus_clock_foreign = False
        self._link = ClockLink()
        # The host's wall clock, watched for steps against its monotonic clock from here on
        # (`HostClockWatch`): the receiver reads it at every cycle, a run at every batch.
        self.host_clock = HostClockWatch()
        # How the simulated radar runs, where it is the output (`_vacuous_empty_bench`).
        self._radar_options = radar_options or RadarOptions()
        # The level of the host's clock (`HostClockWatch.level_s`) the scene's start was taken
        # at, by the simulated radar in process; and the monotonic time of that start.
        self._bus_origin_level_s = 0.0
        self._bus_origin_monotonic_s: float | None = None
        # A run's corrections of host clock steps (`_unstep`): the monotonic time it began,
        # the level of its stamps' last cycle, and where that level changed (for the sidecar).
        self._run_monotonic_s = monotonic_s()
        self._run_level_s = 0.0
        self._stamp_shift_s = 0.0
        self._bus_shifts: list[dict[str, float | int]] = []
        # Whether `_unstep` found the cycles' receipts on another clock than their stamps.
        self._stamps_foreign = False
        # The measurements made (`play`) and the steps of the host's clock seen during them
        # (`host_clock_steps`, each with the ``measurement``'s number, from 0).
        self.measurements = 0
        self.measurement_steps: list[dict[str, float | str | int]] = []
        # The messages of other channels than ``radar_channel`` the measurements skipped.
        self.measurement_other_channels = 0
        # Frames of the measurements that went out too late for the cycle that measures them
        # (`play`): not measured.
        self.measurement_late_frames = 0
        self.output: Output | None = None
        self._new_output: Callable[[], Output] | None = None
        # Whether a measurement (`play`) was made: the next starts a stream of its own.
        self._measured = False
        # A private name that does not end in digits (MF4 logs read those as a channel number).
        self.channel = options.can_channel or f"rts-scenario-{id(self):x}-detections"
        try:
            self.mapping = CanMapping.from_file(options.mapping) if options.mapping else None
            self.receiver = DetectionReceiver(self.mapping, radar.radar_clock.cycle_s,
                                              channel=options.radar_channel,
                                              host_clock=self.host_clock,
                                              channel_option=options.option("radar-channel"))
            listen = self._open_bus()
            self._listeners: list[can.Listener] = [self.receiver]
            if options.bus_log:
                # An earlier recording's sidecar must not pass for this one's, should this one
                # stop before its own is written (Ctrl-C, an error).
                Path(str(options.bus_log) + LOG_SIDECAR_SUFFIX).unlink(missing_ok=True)
                mf4.ready(options.bus_log)
                self._logger = can.Logger(options.bus_log)
                self._recording = _Recording(self.receiver, self._logger)
                self._listeners = [self._recording]
            self._notifier = can.Notifier(listen, self._listeners, timeout=0.01)
            name, argument = split_spec(options.output)
            context = RunContext(rig=rig, radar=radar, radar_options=self._radar_options,
                                 open_publisher=self._open_publisher,
                                 rng=rng if rng is not None else np.random.default_rng(0),
                                 errors=errors)
            self._new_output = lambda: output_class(name).for_run(argument, context)
            self.output = self._new_output()
        except BaseException:
            self.close()
            raise

    @classmethod
    def for_scene(cls, scene: Scenario, options: RunOptions | None = None) -> Pipeline:
        """Wire the bench a scene asks for: its rig, radar, simulated-radar options and seed."""
        return cls(scene.rig, scene.radar, options, radar_options=scene.radar_options,
                   rng=np.random.default_rng(scene.seed))

    def _radar_channel(self) -> str | None:
        """Return the channel the radar's messages were read from, as a log names it.

        ``--radar-channel`` where given; else the one channel the interface said they came
        on (socketcan bound to every device names each message's), or the channel listened
        on where it said none. None where they came on several: which is the radar's is not
        known (the run failed), and a re-check must not pick one.
        """
        if self.options.radar_channel is not None:
            return self.options.radar_channel
        held = self._radar_channels()
        if len(held) > 1:
            return None
        return held[0] if held and held[0] is not None else self.channel

    def _radar_channel_named(self) -> bool | None:
        """Whether the radar's messages named the channel they came on (``Message.channel``).

        False where they named none (python-can's ``udp_multicast``): a log file gives them
        its format's default channel, not the one listened on. None where none came.
        """
        held = self._radar_channels()
        return None if not held else None not in held

    def _radar_channels(self) -> list[str | None]:
        """Return the channels the radar's messages came on (None: a message named none)."""
        return [c for c, n in self.receiver.channels.items() if n]

    def _open_bus(self) -> can.BusABC:
        o = self.options
        bus = open_bus(o.can_interface, self.channel, fd=o.can_fd)
        self._buses.append(bus)
        return bus

    def _open_publisher(self) -> Callable[[list[Detections]], None]:
        if self._publisher is None:
            o = self.options
            if o.can_interface == "virtual":
                # In process, the simulated radar's messages go straight to the run's listeners
                # (no copy, no thread) and keep the time the radar would have sent them: its
                # measurement time after the run's start, plus its latency and jitter. That
                # is when the host receives them, on its wall clock.
                bus: can.BusABC = ListenerBus(self._listeners, self.channel)
                self.receiver.received_at = _stamped
            else:
                bus = open_bus(o.can_interface, self.channel, fd=o.can_fd)
            self._buses.append(bus)
            # The run's mapping (a third-party radar's DBC) makes the simulated radar speak it.
            self._publisher = DetectionPublisher(bus, fd=o.can_fd, mapping=self.mapping)
        publisher, clock = self._publisher, self.radar.radar_clock
        watch = self.host_clock
        level = watch.sample()
        origin, rng = wall_s(), np.random.default_rng(0)
        in_process = self.options.can_interface == "virtual"
        if in_process:
            # The messages keep the times given them: the scene's start on the bus's clock.
            self._bus_origin_s = origin
            self._bus_origin_level_s = level
            self._bus_origin_monotonic_s = monotonic_s()

        def publish(cycles: list[Detections]) -> None:
            t = np.array([c.t_s or 0.0 for c in cycles], dtype=np.float64)
            # Stamped as the host's wall clock reads them, as python-can would: where it
            # stepped since the scene's start (`HostClockWatch`), by the step (its slow
            # slew, within a step's tolerance, left out: a desk run's stamps stay exact).
            stepped = watch.sample() - level if in_process else 0.0
            publisher.publish_many(cycles,
                                   origin + stepped + t + clock.bus_delay(len(cycles), rng))

        return publish

    @property
    def counter_modulus(self) -> int:
        """Where the radar's cycle counter wraps (the mapping's `CanMapping.counter_modulus`)."""
        return self.receiver.mapping.counter_modulus

    # -- playing ---------------------------------------------------------------------------

    def write(self, schedule: Schedule) -> None:
        """Send a batch of frames to the output."""
        assert self.output is not None
        self.output.write(schedule)

    def receive(self, *, final: bool = False,
                until_monotonic_s: float | None = None) -> list[Detections]:
        """Return the radar cycles received so far.

        With the simulated radar, waits until every message it published has arrived. For a
        real radar, returns what is there, except at the end (``final``): then waits the radar
        clock's latency, jitter and one cycle plus `QUIET_S`, and until ``until_monotonic_s``
        on the host's monotonic clock where given (however much longer than ``drain_s``, the
        most the simulated radar's messages are waited for, that is), and hands on the cycles
        still being assembled, as incomplete where parts are missing.
        """
        start = time.perf_counter()
        deadline = start + self.options.drain_s
        expected = self._publisher.sent if self._publisher is not None else None
        # A real radar's last cycles come one latency (and its jitter) after they were measured,
        # and it may never fall quiet (it keeps measuring what the RTS holds): wait that long.
        clock = self.radar.radar_clock
        settle_s = clock.latency_s + clock.jitter_s + clock.cycle_s + QUIET_S
        if expected is None and final:
            # However slow the radar: its cycles do not come sooner for a shorter wait.
            wait_s = max(settle_s, 0.0 if until_monotonic_s is None
                         else until_monotonic_s - monotonic_s())
            deadline = max(deadline, start + wait_s + 0.05)
        stats = self.receiver.stats
        while time.perf_counter() < deadline:
            count = stats.messages
            if expected is not None and count >= expected:
                break
            if expected is None and not final:
                break
            if expected is None and time.perf_counter() - start > settle_s and (
                    until_monotonic_s is None or monotonic_s() >= until_monotonic_s):
                break
            time.sleep(0.002)
        return self.receiver.flush() if final else self.receiver.pop()

    def play(self, schedule: Schedule) -> list[Detections]:
        """Play a schedule; return one cycle per frame, in frame order (a measurement).

        A frame whose cycle did not come back, or came back damaged, gets an empty cycle marked
        incomplete.
        """
        assert self.output is not None
        # The host's clock is watched from here on (`HostClockWatch`): a step during the
        # measurement is told and its times brought back (`_unstep`), as in a run.
        self._run_level_s = self.host_clock.sample()
        self._run_monotonic_s = monotonic_s()
        self._stamp_shift_s, self._bus_shifts, self._stamps_foreign = 0.0, [], False
        if self._measured:
            # Each measurement is a stream of its own, as each run is: its frames paced from
            # its own start and its cycles numbered from it (an RTS, and `emulate`, start a
            # stream per sender). A stream that went on would have sent this one's frames at
            # the first's times, all at once.
            self.output.close()
            self.output = None
            assert self._new_output is not None
            self.output = self._new_output()
        self._measured = True
        # Each frame is held for a cycle (or two, below): never a run's frame period.
        self.output.frame_period_s = None
        self.receiver.reset(restart=self._counter_restart())
        unknown_before = self.receiver.stats.unknown_ids
        # A measurement places its cycles itself (`_cycle_numbers`): no run's clock link holds.
        self._bus_clock_checked = self._bus_clock_foreign = False
        self._link = ClockLink()
        # Each frame is held for one cycle of the radar's clock and measured in it, where the
        # output applies frames exactly at their times. An RTS applies a frame after its time
        # (transport, its own update): a cycle measured as the frame is due may still show the
        # frame before, so there each frame is held for two cycles and measured in the second,
        # a whole cycle after it was due. So is it for a radar running free: where in its
        # cycle it measures is known only to its messages' jitter (`_cycle_numbers`), or,
        # behind an interface stamping with its own clock, to when the host received them
        # (within `HOST_DELIVERY_S`), and a radar measuring just before the frame changes
        # would be taken for one measuring just after them (each frame judged by the cycle of
        # the frame before); held for two cycles, either cycle numbered lies within the
        # frame's hold. A frame whose cycle may lie further off is not taken. Frame numbers
        # keep increasing (an RTS applies only a frame newer than the last).
        clock = self.radar.radar_clock
        hold = 1 if self.output.applies_frames_on_time and clock.counter_start is not None else 2
        n = np.arange(schedule.n_frames, dtype=np.int64)
        played = schedule if hold == 1 else replace(
            schedule.take(np.repeat(n, hold)),
            frame_index=(np.repeat(schedule.frame_index, hold) * hold
                         + np.tile(np.arange(hold), schedule.n_frames)))
        played = replace(played, t_s=clock.time_of(np.arange(played.n_frames)))
        self.write(played)
        received = self.receive(final=True)
        self.measurement_other_channels += self.receiver.other_channels
        # The radar's identifiers on several channels (or none on --radar-channel): the
        # cycles would mix another bus's in; nothing is measured from them.
        # So does a radar speaking another protocol than the mapping's: no header of it came,
        # messages of identifiers it does not know did.
        reason = (self.receiver.channel_reason() or self._rts_refusal(played.n_frames)
                  or mapping_reason(self.receiver.mapping, self.receiver.headers,
                                    self.receiver.stats.unknown_ids - unknown_before,
                                    option=self.options.option("mapping")))
        if reason:
            raise MeasurementError(reason)
        self.host_clock.sample()  # a step is told by the measurement, if no cycle told it
        duration_s = float(played.n_frames) * clock.cycle_s
        cycles = [c for c in self._unstep(received, duration_s) if c.complete]
        self.measurement_steps += [{"measurement": self.measurements, **step}
                                   for step in self.host_clock_steps()]
        self.measurements += 1
        numbers, spread = self._cycle_numbers(cycles, duration_s)
        found = dict(zip(numbers.tolist(), cycles, strict=True))
        if spread >= hold:
            # Each cycle may be up to ``spread`` cycles earlier than numbered: the last of a
            # frame's hold may be one of the frame before's. None is taken for a frame.
            found = {}
        if not self.output.applies_frames_on_time:
            # A frame that went out later than its measuring cycle (the last of its hold)
            # less the ambiguity window may not have been played yet when that cycle measured:
            # it may show the frame before. Such a frame is not measured, never taken from
            # the frame before.
            late_s = self.output.sent_t_s(played) - played.t_s
            allowed_s = (hold - 1) * clock.cycle_s - ambiguity_window_s(self.radar, self.rig)
            for i in np.flatnonzero(late_s[n * hold] > allowed_s):
                found.pop(int(i) * hold + hold - 1, None)
                self.measurement_late_frames += 1
        return [found.get(int(i) * hold + hold - 1,
                          Detections.empty(int(f), float(t), (), complete=False))
                for i, f, t in zip(n, schedule.frame_index, schedule.t_s, strict=True)]

    def _rts_refusal(self, frames: int) -> str | None:
        """Say why the RTS's own word on a measurement's stream makes its cycles untrustworthy.

        An RTS that reports its counters (docs/udp-protocol.md, status replies) and did not
        apply some frames held the frame before instead: the cycles measured then show that
        one, and would be taken for the frames it refused. An RTS that says its rig (rig
        replies) and plays another geometry than the measured rig's played the pattern from
        other directions. None where neither happened, or the RTS says nothing.
        """
        assert self.output is not None
        rts = self.output.rts_status(settle_s=RTS_SETTLE_S)
        rig = rts_rig_record(self.output.rts_rig(), self.rig)
        which = f"measurement {self.measurements}"
        gone = self.output.rts_unreachable()
        if gone is not None:
            return unreachable_reason(gone, f"of {which}")
        if rts is not None and (lost := lost_frames(rts)):
            counts = ", ".join(f"{k.replace('_', ' ')} {rts[k]}" for k in LOST_COUNTERS
                               if rts.get(k))
            why = (f"; malformed frames: the RTS's rig lacks FEs of rig {self.rig.name!r}, or "
                   f"lays them out in other rows and columns: measure the rig the RTS has"
                   if rts.get("malformed") else "")
            return (f"the RTS did not apply {lost} of the {frames} frames of {which} "
                    f"({counts}): it held the frame before, and what the radar measured then "
                    f"is not the frame's{why}")
        if rig is not None and not rig["matches_run"]:
            differs = rig_difference(rig, "the measured rig's")
            return (f"rts_rig: the RTS plays a rig of {differs}, in {which}: its echoes came "
                    f"from other directions than the pattern put them in; measure the rig the "
                    f"RTS has (emulate: --rig the measured rig's)")
        return None

    def _counter_restart(self) -> int | None:
        """Return the counter a run's or measurement's stream restarts the radar's count at.

        The profile's counter start: a radar numbered from it starts counting with each
        stream (`emulate` restarts its radar so), and the stream before's last cycles may
        still come after the reset (`DetectionReceiver.reset`). None for a radar running free.
        """
        start = self.radar.radar_clock.counter_start
        return None if start is None else start % self.counter_modulus

    def _cycle_numbers(self, cycles: list[Detections],
                       duration_s: float) -> tuple[np.ndarray, int]:
        """Return the radar's cycle numbers (0 at its clock's start) of received cycles.

        Each is a step from the cycle before (`sequential_numbers`), the first nearest 0 for a
        profile's counter start. A radar running free (no counter start) measured before the
        first frame too, at any point of its cycle: where the measurement's start is known on
        the bus's clock, cycle n is the one measured while frame n was held, told by the
        cycles' bus times less the latency (on the line of the profile's cycle through them,
        which averages the jitter out; a cycle within three standard errors of the line's
        phase after a frame change counts as measured at it, as a run's first cycle does).
        With times on another clock (an interface stamping with its own: the first cycle far
        outside the ``duration_s`` played, `BUS_CLOCK_SLACK_S`, or the receipts telling them
        apart as in `_follow_bus_clock`), or none, when the host
        received the cycles places them (`_host_phase_s`), within the host's delivery delay:
        each cycle is numbered as the latest it may be. Without those either, the first cycle
        received is taken as cycle 0.

        Returns the numbers and how many cycles earlier any of them may be (0: as numbered).
        """
        clock = self.radar.radar_clock
        counters = np.array([c.cycle for c in cycles], dtype=np.int64)
        if not counters.size:  # a radar silent throughout: no phase to number by
            return counters, 0
        start = clock.counter_start if clock.counter_start is not None else (
            int(counters[0]) if counters.size else 0)
        counters = (counters - start) % self.counter_modulus
        bus_t = bus_times(cycles)
        steps = sequential_numbers(counters, self.counter_modulus, bus_t, clock.cycle_s)
        if clock.counter_start is not None:
            return unwrap_counter(counters[:1], 0, self.counter_modulus) + steps, 0
        origin = self._scene_origin_s()
        late_s = duration_s + clock.latency_s + clock.jitter_s + BUS_CLOCK_SLACK_S
        if origin is not None and np.isfinite(bus_t[0]) and not (
                -BUS_CLOCK_SLACK_S <= float(bus_t[0]) - origin <= late_s):
            origin = None
        delay = host_times(cycles) - bus_t
        delay = delay[np.isfinite(delay)]
        if origin is not None and delay.size and stamped_on_another_clock(float(delay.min())):
            origin = None
        if origin is None or not np.isfinite(bus_t).all():
            bounds = self._host_phase_s(cycles, steps)
            if bounds is None:
                return steps, 0
            lo, hi = (int(np.floor((b + TIME_EPS_S) / clock.cycle_s)) for b in bounds)
            return steps + hi, hi - lo
        measured = bus_t - clock.latency_s - origin - clock.start_offset_s
        phase = float(np.mean(measured - steps * clock.cycle_s))
        # The spread of the mean of uniform jitter over +- jitter_s.
        stderr = clock.jitter_s / np.sqrt(3.0 * max(1, steps.size))
        return steps + int(np.floor((phase + 3.0 * stderr + TIME_EPS_S) / clock.cycle_s)), 0

    def _host_phase_s(self, cycles: list[Detections],
                      steps: np.ndarray) -> tuple[float, float] | None:
        """Return bounds of when a free radar measured its first cycle received (``steps`` 0).

        Measured against the measurement's start (and the profile's start offset), from when
        the host received the cycles (`Detections.host_t_s`, on the clock the start is known
        on): each arrived the radar's latency (within its jitter) and the delivery delay
        after it was measured. The delay is unknown but not negative, and that of the fastest
        cycle at most `HOST_DELIVERY_S`. Where the interface stamped the cycles on its own
        clock, those stamps time them against each other without the delivery delay (their
        mean averages the jitter out) and the fastest delivery ties that clock to the host's
        (within `HOST_DRIFT`). None where the start or a cycle's receipt is not known.
        """
        clock = self.radar.radar_clock
        origin = self._host_origin_s()
        host_t = host_times(cycles)
        if origin is None or not np.isfinite(host_t).all():
            return None
        # A cycle's arrival on the bus, on the host's clock, had it measured at phase 0.
        due = origin + clock.start_offset_s + clock.latency_s + steps * clock.cycle_s
        bus_t = bus_times(cycles)
        if np.isfinite(bus_t).all():
            fastest = float(np.min(host_t - bus_t))
            phase = float(np.mean(bus_t - due)) + fastest
            spread = (3.0 * clock.jitter_s / np.sqrt(3.0 * max(1, steps.size))
                      + HOST_DRIFT * float(bus_t.max() - bus_t.min()))
            return phase - HOST_DELIVERY_S - spread, phase + spread
        first = float(np.min(host_t - due))
        return first - clock.jitter_s - HOST_DELIVERY_S, first + clock.jitter_s

    def _host_origin_s(self) -> float | None:
        """Return the measurement's time 0 on the host's wall clock, where the run knows it.

        What `_scene_origin_s` gives, whatever clock the interface stamps the bus times with.
        """
        origin = getattr(self.output, "scene_origin_wall_s", None)
        return origin if origin is not None else self._bus_origin_s

    def _origin_level_s(self) -> float:
        """Return the level of the host's clock (`HostClockWatch.level_s`) the start was taken at.

        The start `_host_origin_s` gives: a paced stream's (read with the monotonic clock: a
        step between the watch's readings around it is placed by its wall time), the simulated
        radar's in process; else the level when the run began.
        """
        wall = getattr(self.output, "scene_origin_wall_s", None)
        mono = getattr(self.output, "scene_origin_monotonic_s", None)
        if wall is not None and mono is not None:
            return self.host_clock.level_at(mono, wall)
        if wall is None and self._bus_origin_s is not None:
            return self._bus_origin_level_s
        return self._run_level_s

    def _origin_monotonic_s(self) -> float | None:
        """Return the scene's start on the host's monotonic clock, where the run knows it."""
        if getattr(self.output, "scene_origin_wall_s", None) is not None:
            return getattr(self.output, "scene_origin_monotonic_s", None)
        return self._bus_origin_monotonic_s if self._bus_origin_s is not None else None

    def _unstep(self, cycles: list[Detections], duration_s: float,
                track: ClockTrack | None = None) -> list[Detections]:
        """Return the cycles with their times on the host's clock as it read at the start.

        The host's wall clock may step while a run plays (`HostClockWatch`): every time read on
        it after the step is off by it, while the scene's start was taken before. Each cycle
        says how far it had stepped when the host received it (`Detections.host_step_s`): its
        receipt time is brought back by the steps since the start (`_origin_level_s`), and so
        is its bus time where the bus stamps with the host's clock (python-can's stamps, the
        simulated radar's). A cycle stamped just before a step and received just after it
        keeps the level before: the one that leaves its delivery (receipt less stamp) nearer
        0. Bus times an interface stamps with its own clock do not step; only their receipts
        are brought back (they tie that clock to the host's, `ClockLink`). ``track``: a run's
        clock (None for a measurement, `play`, which places its cycles itself).
        """
        ref = self._origin_level_s()
        if not cycles or (all(c.host_step_s == ref for c in cycles)
                          and self._stamp_shift_s == 0.0):
            return cycles
        self._check_bus_clock(cycles, duration_s, track)
        foreign = self._bus_clock_foreign
        if not foreign and self._link.offset_s is None:
            # The first cycles: their receipts tell an interface's clock (`_follow_bus_clock`).
            delay = np.array([c.host_t_s - c.bus_t_s for c in cycles
                              if c.host_step_s == ref and c.host_t_s is not None
                              and c.bus_t_s is not None])
            foreign = bool(delay.size) and stamped_on_another_clock(float(delay.min()))
        self._stamps_foreign = self._stamps_foreign or foreign
        levels = self.host_clock.levels()
        out = []
        for c in cycles:
            shift = c.host_step_s - ref
            host_t = None if c.host_t_s is None else c.host_t_s - shift
            bus_t = c.bus_t_s
            if bus_t is not None and not foreign:
                stamp = c.host_step_s
                i = levels.index(stamp) if stamp in levels else 0
                if i > 0 and c.host_t_s is not None:
                    delivery = c.host_t_s - bus_t
                    if abs(delivery - (stamp - levels[i - 1])) < abs(delivery):
                        stamp = levels[i - 1]  # stamped before the step, received after it
                if stamp - ref != self._stamp_shift_s:
                    self._stamp_shift_s = stamp - ref
                    self._bus_shifts.append({"bus_s": bus_t, "counter": c.cycle,
                                             "shift_s": stamp - ref})
                bus_t -= stamp - ref
            out.append(replace(c, bus_t_s=bus_t, host_t_s=host_t, host_step_s=ref))
        return out

    def host_clock_steps(self) -> list[dict[str, float | str]]:
        """Return the steps of the host's clock since the scene's start (or the run's).

        Each: ``at_s`` the scene time of the first reading after it (the host's monotonic clock
        from the scene's start), ``within_s`` how long before that it may have come (since the
        reading before), ``size_s`` and what was ``corrected`` (`_unstep`).
        """
        origin = self._origin_monotonic_s()
        zero = self._run_monotonic_s if origin is None else origin
        since = min(zero, self._run_monotonic_s)
        corrected = ("receipt times (the interface stamps with its own clock)"
                     if self._bus_clock_foreign or self._stamps_foreign
                     else "bus and receipt times")
        return [{"at_s": s.before_s - zero, "within_s": s.before_s - s.after_s,
                 "size_s": s.size_s, "corrected": corrected}
                for s in self.host_clock.steps if s.before_s > since]

    def _scene_origin_s(self) -> float | None:
        """Return the scene's time 0 on the bus's clock, where the run knows it.

        A stream paced in real time knows when it started the scene; the simulated radar in
        process stamps its messages from the run's start. On an interface stamping with its
        own clock, a run ties that clock to the host's (`ClockLink`, from the cycles it
        received so far): the start is then on the interface's clock, at most
        `ClockLink.error_s` late. None otherwise.
        """
        if not self._bus_clock_foreign:
            return self._host_origin_s()
        host, line = self._host_origin_s(), self._link.line()
        if host is None or line is None or self._link.broken:
            return None
        offset, rate, at = line
        # The interface's time at the scene's start: where its time plus the line is ``host``.
        return at + (host - offset - at) / (1.0 + rate)

    def _check_bus_clock(self, cycles: list[Detections], duration_s: float,
                         track: ClockTrack | None) -> None:
        """Forget the scene's start on the bus's clock where the cycles are not on that clock.

        python-can stamps messages with the wall clock, the one the scene's start is taken
        on; an interface that stamps them with its own (seconds since it was plugged in) puts
        the first cycle received far outside the scene (`BUS_CLOCK_SLACK_S`). Its bus times
        then number and time the cycles only relative to each other: the counters and the
        profile's phase place them in the scene.
        """
        origin = self._scene_origin_s()
        t = bus_times(cycles)
        t = t[np.isfinite(t)]
        if self._bus_clock_checked or origin is None or not t.size:
            return
        self._bus_clock_checked = True  # by the first cycle received with a bus time
        clock = self.radar.radar_clock
        late_s = duration_s + clock.latency_s + clock.jitter_s + BUS_CLOCK_SLACK_S
        if not -BUS_CLOCK_SLACK_S <= float(t[0]) - origin <= late_s:
            self._bus_clock_foreign = True
            if track is not None:
                track.origin_s = None

    def _follow_bus_clock(self, cycles: list[Detections], duration_s: float, track: ClockTrack,
                          truths: CycleTruth) -> None:
        """Tie a bus stamped on an interface's own clock to the host's, batch by batch.

        Where the cycles' bus times are on another clock than the scene's start
        (`_check_bus_clock`, or their receipts say so: a message received before it was
        stamped, or the fastest of seconds of them more than `RECEIPT_OFF_S` after), when the
        host received them ties that clock to its own
        (`ClockLink`): the scene's start on the interface's clock follows, at most
        `ClockLink.error_s` late, and so the cycles' measurement times, which may then lie that
        much earlier than they seem: a cycle just after a frame change may have seen the frame
        before, and the ambiguity window after each change grows by that much
        (`CycleTruth.early_s`).
        """
        self._check_bus_clock(cycles, duration_s, track)
        if self._link.broken:
            return
        bus_t = bus_times(cycles)
        self._link.add(bus_t, host_times(cycles))
        if not self._bus_clock_foreign:
            offset = self._link.offset_s
            if offset is None or not stamped_on_another_clock(offset):
                return
            # The receipts tie that clock to the host's.
            self._bus_clock_foreign = True
        origin = self._scene_origin_s()
        t = bus_t[np.isfinite(bus_t)]
        clock = self.radar.radar_clock
        if origin is not None and t.size and not (
                -BUS_CLOCK_SLACK_S <= float(t[0]) - origin
                <= duration_s + clock.latency_s + clock.jitter_s + BUS_CLOCK_SLACK_S):
            # Receipt times that do not put the cycles in the scene are not the host's
            # deliveries of them (a tool's replay, a stamp taken for a receipt).
            self._link.broken = True
            origin = None
        track.origin_s = origin
        if origin is not None:
            line = self._link.line()
            assert line is not None
            # The cycles handed on are a batch older than the latest: the line times them
            # through the crystals' drift since (`ClockLink.line`).
            track.scale = 1.0 + line[1]
            truths.early_s = ClockLink.error_s

    def _link_over_the_run(self, track: ClockTrack) -> None:
        """Tie an interface's clock to the host's over the whole run (`ClockLink.line`).

        Batch by batch, the deliveries so far tied the clocks; the report and the log's
        sidecar describe the radar's clock over the run by all of them, on the host's
        seconds: its cycle less the interface's crystal's error, and its phase.
        """
        line = self._link.line()
        host = self._host_origin_s()
        if not self._bus_clock_foreign or line is None or host is None or self._link.broken:
            return
        offset, rate, at = line
        track.scale = 1.0 + rate
        # The interface's time at the scene's start: where its time plus the line is ``host``.
        track.origin_s = at + (host - offset - at) / (1.0 + rate)

    def _learn_counter_start(self, checker: Checker, cycles: list[Detections]) -> None:
        """Find where the radar's counter starts when its profile does not say.

        A radar whose profile gives no counter start runs free: it was switched on before the
        scene, at any point of its frames. Where the scene's start is known on the bus's
        clock, the first cycles' bus times less the radar's latency tell roughly how many
        cycles it measured in the scene before the earliest received (those lost are
        missing); cycle 0 is numbered a cycle earlier still, and the clock track
        (`ClockTrack`, from all the cycles' bus times) tells which cycle is the scene's first
        (`CycleTruth.first_cycle`): a few cycles' jitter decides nothing. The report gives
        that cycle's counter. Without those times, the first cycle received is taken as the
        scene's first.
        """
        clock = self.radar.radar_clock
        origin = self._scene_origin_s()
        timed = [c for c in cycles if c.bus_t_s is not None]
        if timed and origin is not None:
            counters = np.array([c.cycle for c in timed], dtype=np.int64)
            m = sequential_numbers((counters - counters[0]) % self.counter_modulus,
                                   self.counter_modulus, bus_times(timed), clock.cycle_s)
            measured = bus_times(timed) - clock.latency_s - origin
            # Scene time of the earliest received, on the line of the profile's cycle.
            earliest = float(np.mean(measured - m * clock.cycle_s)) + m.min() * clock.cycle_s
            before = max(0, int(np.floor(earliest / clock.cycle_s))) + 1
            checker.counter_start = int(counters[0] + m.min() - before) % self.counter_modulus
            # Cycle 0's bus time on that line: the earliest received is `before` cycles on,
            # however many an 8-bit counter would read.
            checker.anchor(0, origin + clock.latency_s + earliest - before * clock.cycle_s)
            source = "learnt from the cycles' bus times"
        else:
            checker.counter_start = cycles[0].cycle % self.counter_modulus
            source = "assumed: the first cycle received is the scene's first"
        self.counter_start_learnt = (checker.counter_start, source)

    def _anchor(self, checker: Checker, cycles: list[Detections]) -> None:
        """Tell the checker when a profile's radar's cycle 0 reached the bus (`Checker.anchor`).

        Its cycle 0 reaches the bus its latency after the profile's start offset, from the
        scene's start on the bus's clock (where the run knows it): the first cycle received
        is numbered on from there (`Checker.anchor`).
        """
        clock = self.radar.radar_clock
        origin = self._scene_origin_s()
        if cycles and clock.counter_start is not None and origin is not None:
            checker.anchor(0, origin + clock.latency_s + clock.start_offset_s)

    def run(self, scene: Scenario, progress: Callable[[int, int], None] | None = None,
            timing: dict[str, float] | None = None,
            detections_out: TextIO | None = None,
            on_preflight: Callable[[Preflight], None] | None = None) -> RunResult:
        """Run a scene batch by batch and check the radar's detections.

        ``progress(done, total)`` is called after each batch; ``timing`` holds seconds already
        spent before the run (e.g. loading) and is reported with the run's own;
        ``detections_out`` receives every detection as a CSV row
        (`rts_scenario.check.DETECTION_COLUMNS`); ``on_preflight``, when given, receives the
        scene's `Preflight` before anything plays.
        """
        options = self.options
        timer = _Timing(dict(timing or {}))
        start = mark = time.perf_counter()
        record = FrameRecord() if options.record else None
        plot = PlotData(len(scene.targets)) if options.plot else None
        clock = self.radar.radar_clock
        checker = Checker(scene.name, tuple(t.name for t in scene.targets), scene.expectations,
                          counter_modulus=self.counter_modulus,
                          counter_start=clock.counter_start, record=record, plot=plot,
                          expected_limits=[t.expected_limits for t in scene.targets],
                          scene_limits=scene_limits(scene), detections_out=detections_out,
                          variant=scene.variant, parameters=scene.parameters,
                          cycle_s=clock.cycle_s, file=scene.file,
                          not_carried=self.receiver.mapping.not_carried(),
                          limits=self.receiver.mapping.limits(options.can_fd),
                          mapping_name=self.receiver.mapping.name, jitter_s=clock.jitter_s)
        n_frames = scene.n_frames
        t_all = scene.t_s
        # What the run played, for a re-check of its log (`rts_scenario.recording`).
        played = PlayedRecord(t.name for t in scene.targets) if options.bus_log else None
        # The per-rig set-up, once (every batch then finds it in memory); a cached plan is
        # read from disk instead of being built again.
        array, model = solver_inputs(scene.radar, FE_RESPONSES[0])
        plan = solver_plan(scene.rig, array, plan_method(options.method), model)
        mark = timer.add("plan_s", mark)
        if on_preflight is not None:
            on_preflight(preflight(scene, options.method))
            mark = timer.add("preflight_s", mark)
        with self._recorded(True):
            self.receiver.reset(restart=self._counter_restart())
        self._bus_clock_checked = self._bus_clock_foreign = False
        self._link = ClockLink()
        self._run_level_s = self.host_clock.sample()
        self._run_monotonic_s = monotonic_s()
        self._stamp_shift_s, self._bus_shifts, self._stamps_foreign = 0.0, [], False
        window_s = ambiguity_window_s(self.radar, self.rig)
        # When the radar measures: its profile's clock, corrected by its cycles' bus times.
        track = ClockTrack(clock, self._scene_origin_s(),
                           free=clock.counter_start is None)
        truths = CycleTruth(checker, scene, track, window_s)
        playback = Playback(1.0 / scene.frame_rate_hz, window_s)
        batch = options.batch_frames or frames_per_batch(len(scene.targets), BATCH_FRAMES)
        per_frame = 1.0 / (scene.frame_rate_hz * clock.cycle_s)  # the radar's cycles a frame
        if options.batch_frames is None and per_frame > 1.0:
            # Frames slower than the radar's cycles: each batch's cycles go on the bus and to
            # the checker together, so a batch holds about as many cycles as it would frames.
            batch = max(1, int(batch / per_frame))
        assert self.output is not None
        # The RTS holds each frame for a frame period, the last one of a batch too.
        self.output.frame_period_s = 1.0 / scene.frame_rate_hz
        for first in range(0, n_frames, batch):
            frames = np.arange(first, min(first + batch, n_frames))
            tracks = compute_tracks(scene, t_all[frames], frames)
            mark = timer.add("kinematics_s", mark)
            schedule = build_schedule(tracks, scene.rig, scene.radar, method=options.method,
                                      estimator=scene.radar_options.estimator,
                                      frame_rate_hz=scene.frame_rate_hz,
                                      angle_tolerance_deg=angle_tolerance_deg(scene))
            schedule = replace(schedule, frame_index=frames)
            checker.add_frames(tracks, schedule.status)
            if plot is not None:
                plot.add_frames(tracks, schedule, checkable(tracks, schedule.status))
            if played is not None:
                played.add(frames, tracks, schedule.status)
            mark = timer.add("schedule_s", mark)
            self.write(schedule)
            if track.origin_s is None:  # a stream knows the scene's start once it started it
                track.origin_s = self._scene_origin_s()
            assert self.output is not None
            sent_s = self.output.sent_t_s(schedule)
            playback.add(schedule.t_s, sent_s)
            mark = timer.add("play_s", mark)
            # The cycles first, so that the clock knows them before it times the truth.
            cycles = self.receive()
            self.host_clock.sample()  # a step is told by the batch, if no cycle told it
            cycles = self._unstep(cycles, scene.duration_s, track)
            mark = timer.add("receive_s", mark)
            self._follow_bus_clock(cycles, scene.duration_s, track, truths)
            if checker.counter_start is None and cycles:
                self._learn_counter_start(checker, cycles)
            self._anchor(checker, cycles)
            track.add(checker.add_cycles(cycles), bus_times(cycles))
            mark = timer.add("check_s", mark)
            # The radar's cycles while the RTS held the batch before: it was held until this
            # batch's first frame went out.
            n = truths.add(frames, schedule.status, sent_s)
            mark = timer.add("kinematics_s", mark)
            # The batch before that one is due: its cycles had a whole batch to arrive.
            if n.size:
                checker.settle(before_frame=int(n[0]))
            mark = timer.add("check_s", mark)
            if progress is not None:
                progress(int(frames[-1]) + 1, n_frames)
        # The radar's cycles after the scene's end, as far as they are counted
        # (`after_scene_until_s`), reach the host by its latency, jitter and `QUIET_S` later.
        origin_mono = self._origin_monotonic_s()
        until = None if origin_mono is None else (
            origin_mono + after_scene_until_s(scene.duration_s, track.cycle_s)
            + clock.latency_s + clock.jitter_s + QUIET_S)
        last = self._unstep(self.receive(final=True, until_monotonic_s=until), scene.duration_s,
                            track)
        self._follow_bus_clock(last, scene.duration_s, track, truths)
        if checker.counter_start is None and last:
            self._learn_counter_start(checker, last)
        self._anchor(checker, last)
        track.add(checker.add_cycles(last), bus_times(last))
        mark = timer.add("receive_s", mark)
        truths.finish()
        self._link_over_the_run(track)
        # The scene's first cycle as the clock ended up taking it, and how many it had.
        scene_first = truths.first_cycle or 0
        n_cycles = (truths.end_cycle or scene_first) - scene_first
        mark = timer.add("kinematics_s", mark)
        # Cycles after the scene are counted as far as a re-check of the log counts them.
        checker.after_scene_end = max(
            scene_first + n_cycles,
            track.first_at(after_scene_until_s(scene.duration_s, track.cycle_s)))
        checker.settle()
        # The log ends with the last message counted: a re-check counts what the run did.
        with self._recorded(False):
            bus = {k: int(v) for k, v in vars(self.receiver.stats).items()}
        # Cycles of the stream before, dropped at the restart of the radar's count.
        bus["stale_cycles"] = self.receiver.stale_cycles
        if self._publisher is not None:
            # Detections the simulated radar made that the bus could not carry (out of a
            # signal's range): the checker never saw them.
            bus["unsendable_detections"] = self._publisher.unsendable_detections
        if options.radar_channel is not None:
            bus["other_channels"] = self.receiver.other_channels
        report = checker.report(bus, self._publisher.unsendable_reason
                                if self._publisher is not None else None)
        late_reason = track.late_start_reason()
        late, lag = track.late_start_s(), checker.detection_lag_s(scene.radar.coupling_lag_s)
        if late_reason and late is not None and lag is not None:
            # Late on the bus, and the detections as early: a latency, not a late start.
            late_reason = latency_not_late_start_reason(
                clock, late, lag[0], lag[1], 1.0 / scene.frame_rate_hz) or late_reason
        for code, drifted in (
                ("radar_channel", self.receiver.channel_reason()),
                ("mapping", mapping_reason(self.receiver.mapping, self.receiver.headers,
                                           bus["unknown_ids"], report.frames,
                                           option=options.option("mapping"))),
                ("radar_clock", track.off_profile_reason(0.5 * window_s)),
                ("radar_clock", track.latency_change_reason(0.5 * window_s)),
                ("radar_clock", late_reason),
                ("time_alignment", checker.lag_reason(1.0 / scene.frame_rate_hz,
                                                      scene.radar.coupling_lag_s))):
            if drifted:
                if code == "radar_clock":
                    drifted = with_mapping_hint(drifted, self.receiver.mapping,
                                                bus["unknown_ids"],
                                                option=options.option("mapping"))
                report.reasons.append(FailReason(drifted, code))
                report.passed = False
        assert self.output is not None
        # The stream has ended: its last frames' report may still be on the way.
        playback.rts = self.output.rts_status(settle_s=RTS_SETTLE_S)
        playback.rts_rig = rts_rig_record(self.output.rts_rig(), scene.rig)
        playback.rts_unreachable = self.output.rts_unreachable()
        # Which output played the scene: "simulated-radar" is no bench (docs/report.md).
        report.playback = {**playback.to_dict(), "output": options.output}
        judge_empty_bench(report, scene, self._radar_options, options.output)
        judge_crowded_analytic(report, scene, getattr(getattr(self.output, "radar", None),
                                                      "frames_crowded_analytic", 0))
        failures = playback.reasons(scene.expectations.expected_limits)
        report.add_playback_limits(playback_limits(report.playback),
                                   scene.expectations.expected_limits)
        report.add_expected_not_hit(playback.not_hit(scene.expectations.expected_limits))
        if failures:
            report.reasons += failures
            report.passed = False
        sidecar_error = None
        if options.bus_log and played is not None:
            try:
                self._write_sidecar(options, scene, played, checker, scene_first, report,
                                    playback, track, n_cycles, truths)
            except OSError as exc:  # a disk filled while the scene ran: the verdict is kept
                sidecar_error = (f"{options.bus_log}{LOG_SIDECAR_SUFFIX}: cannot write: "
                                 f"{exc.strerror or exc}")
        timer.add("check_s", mark)
        timer.stages["total_s"] = timer.stages.get("load_s", 0.0) + time.perf_counter() - start
        report.timing = timer.stages
        report.solver_plan = plan.origin
        if clock.counter_start is not None:
            report.radar_clock = {"counter_start": clock.counter_start, "source": "profile"}
        elif self.counter_start_learnt is not None:
            start, source = self.counter_start_learnt
            report.radar_clock = {"counter_start": (start + scene_first) % self.counter_modulus,
                                  "source": source}
        measured = track.fit.cycle_s()
        if measured is not None:
            report.radar_clock["bus_cycle_s"] = measured[0]
        report.radar_clock.update(track.to_dict(scene_first))
        # Whose clock the bus times are on: the host's, or an interface's own (`ClockLink`);
        # not said where no cycle came with a bus time.
        if track.fit.count:
            report.radar_clock["bus_clock"] = "interface" if self._bus_clock_foreign else "host"
        report.radar_clock.update(lag_dict(checker, scene.radar.coupling_lag_s,
                                           truths.early_s))
        steps = self.host_clock_steps()
        if steps:
            # Said where the host's clock stepped: the times were brought back (`_unstep`).
            report.radar_clock["host_clock_steps"] = steps
        return RunResult(scene=scene, report=report, plot=plot, sidecar_error=sidecar_error)

    def _write_sidecar(self, options: RunOptions, scene: Scenario, played: PlayedRecord,
                       checker: Checker, scene_first: int, report: Report, playback: Playback,
                       track: ClockTrack, n_cycles: int, truths: CycleTruth) -> None:
        """Write the recorded log's sidecar (`write_log_sidecar`) from the run's state."""
        assert options.bus_log is not None
        write_log_sidecar(options.bus_log, scene, self.radar, options, played,
                          counter_start=None if checker.counter_start is None
                          else (checker.counter_start + scene_first) % self.counter_modulus,
                          playback=report.playback,
                          send_lateness=playback.send_lateness(), clock=track,
                          first_cycle=scene_first, cycles=n_cycles,
                          origin_bus_s=self._scene_origin_s() if track.origin_s is None
                          else track.origin_s, early_s=truths.early_s,
                          channel=self._radar_channel(),
                          channel_unknown=self._radar_channel() is None,
                          channel_named=self._radar_channel_named(),
                          host_clock_steps=self.host_clock_steps(),
                          bus_time_shifts=self._bus_shifts,
                          mapping_sha256=self.receiver.mapping.sha256)

    def _recorded(self, on: bool) -> contextlib.AbstractContextManager[None]:
        """Hold the bus's messages back while the block runs; the log records after it or not.

        With no log: nothing to hold back.
        """
        if self._recording is None:
            return contextlib.nullcontext()
        return self._recording.switched(on)

    # -- closing ---------------------------------------------------------------------------

    def close(self) -> None:
        """Close the output, stop the listener and shut every bus down (safe to call twice)."""
        try:
            if self.output is not None:
                self.output.close()
        finally:
            if self._notifier is not None:
                self._notifier.stop()  # stops its listeners too: the log is complete
                self._notifier = None
            elif self._logger is not None:
                self._logger.stop()
            self._logger = None
            while self._buses:
                self._buses.pop().shutdown()

    def __enter__(self) -> Pipeline:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


class CycleTruth:
    """Give a `Checker` the ground truth of the radar's cycles, batch of frames by batch.

    Each cycle is compared with the frame the RTS held at its measurement time, as the scene
    has it at that frame's time, and with that frame's limits (the schedule's statuses): the
    radar is judged on what was played, not on the scene's motion during the hold, which the
    bench's frame rate decides (the truth's ``t_s`` stay the measurement times).

    The RTS holds a frame from when it was applied, not from its nominal time: the frame
    cannot be applied before the sender put it out (`Output.sent_t_s`: nominal for the
    simulated radar, the real send times of a paced UDP stream), so a batch's cycles are
    known only once the next batch's first frame went out, and each batch's truth is handed
    on one batch later (`add` returns the cycles of the batch before; `finish` the last's).

    Even then a cycle measured just after a frame change may legitimately show the frame
    before: the radar's chirp sequence (`RadarProfile.measurement_s`; its measurement time
    marks the end of the chirps) can straddle the change, and the RTS may apply a frame up
    to ``limits.update_latency_s`` after it arrives. Cycles measured within ``window_s``
    (those two together) of a frame change are judged against the frame across it where
    that one detects more of their targets, and counted (`Checker.add_truth`).
    A radar one frame behind outside the window, or two frames behind, still fails.

    Parameters
    ----------
    checker : Checker
        Receives the truth.
    scene : Scenario
        The scene (frame times, targets).
    clock : RadarClock or ClockTrack
        When the radar measures: its profile's clock, or the clock the run learns from the
        bus (asked again for every batch).
    window_s : float
        The ambiguity window after a frame change (s); `ambiguity_window_s` gives it.
    cycles : int, optional
        How many cycles the scene has, from its first: a re-check gives the run's (its
        sidecar's); by default those the clock puts in the scene.

    The scene's cycles are those measured in it, as far as the clock knows: its first is the
    first at or after its start less the clock's `start_tolerance_s` (it may have measured at
    the start itself; the first batches wait until the clock knows which, within a batch of
    frames) plus ``early_s`` (one that seems measured less than that after the start may have
    measured before it, when nothing was played yet), its last the last before its end less
    that tolerance (the one after it may have measured at the end itself, after the scene).
    `first_cycle` and `end_cycle` say which they were.
    """

    def __init__(self, checker: Checker, scene: Scenario, clock: RadarClock | ClockTrack,
                 window_s: float, cycles: int | None = None) -> None:
        self.checker, self.scene, self.clock = checker, scene, clock
        self.window_s = float(window_s)
        # How much earlier than the clock says a cycle may have been measured (`ClockLink`).
        self.early_s = 0.0
        self.cycles = cycles
        # The scene's first cycle (None until the first batch's truth is handed on).
        self.first_cycle: int | None = None
        # The batch whose truth waits for the next one's first send time.
        self._pending: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        # The last frame of the batch before the pending one: (frame, status row, applied s).
        self._before: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        # The first cycle not handed on yet (None: the scene's first, found by its time).
        self._next_n: int | None = None

    @property
    def end_cycle(self) -> int | None:
        """The first cycle not handed on (after `finish`: one past the scene's last)."""
        return self._next_n

    def add(self, frames: np.ndarray, status: np.ndarray,
            applied_s: np.ndarray | None = None) -> np.ndarray:
        """Take a batch: its frames, their statuses and when they went out (nominal if None).

        Returns the numbers of the cycles whose truth the checker got: the batch before's
        (empty for the first batch).
        """
        t_all = self.scene.t_s
        applied = t_all[frames] if applied_s is None else np.asarray(applied_s, dtype=np.float64)
        # A frame is never applied before its time, nor before the frame ahead of it.
        applied = np.maximum.accumulate(np.maximum(applied, t_all[frames]))
        batch = (np.asarray(frames)[:], np.asarray(status), applied)
        done = np.zeros(0, dtype=np.int64)
        if self._pending is not None and self._await_start(batch[0].size):
            # The scene's first cycle is not known yet: the batch joins the pending one.
            pending = self._pending
            self._pending = (np.concatenate([pending[0], batch[0]]),
                             np.concatenate([pending[1], batch[1]]),
                             np.maximum.accumulate(np.concatenate([pending[2], applied])))
            return done
        if self._pending is not None:
            done = self._give(float(applied[0]), (batch[0][:1], batch[1][:1], applied[:1]))
        self._pending = batch
        return done

    def _await_start(self, more: int) -> bool:
        """Whether to hold the first batches until the clock knows the scene's first cycle.

        A clock learnt from the bus (a radar running free) may not tell it from a few cycles
        (`ClockTrack.start_known`): its first batches wait for more, as long as they and
        ``more`` frames stay within one batch of the scene's size (`frames_per_batch`).
        """
        assert self._pending is not None
        known = getattr(self.clock, "start_known", None)
        if self._next_n is not None or known is None:
            return False
        if known(float(self.scene.t_s[self._pending[0][0]]) + self.early_s):
            return False
        return self._pending[0].size + more <= frames_per_batch(len(self.scene.targets))

    def finish(self) -> np.ndarray:
        """Hand on the last batch (held until the scene's end); return its cycles' numbers."""
        if self._pending is None:
            return np.zeros(0, dtype=np.int64)
        scene = self.scene
        return self._give(float(scene.t_s[-1]) + 1.0 / scene.frame_rate_hz, None)

    def _give(self, end_s: float,
              after: tuple[np.ndarray, np.ndarray, np.ndarray] | None) -> np.ndarray:
        """Hand on the pending batch's cycles, measured until ``end_s``.

        ``after`` is the next batch's first frame (frame, status row, applied), None at the
        scene's end.
        """
        assert self._pending is not None
        parts = [p for p in (self._before, self._pending, after) if p is not None]
        frames, status, applied = (np.concatenate([p[i] for p in parts]) for i in range(3))
        first = 0 if self._before is None else 1
        last = first + self._pending[0].size - 1
        # The scene's first cycle may come before its first frame reached the RTS: it counts.
        start_s = float(applied[first]) if self._before is not None else float(
            self.scene.t_s[self._pending[0][0]])
        self._before = tuple(p[-1:] for p in self._pending)  # type: ignore[assignment]
        self._pending = None
        # Cycle numbers follow on from the batch before's, whatever the clock now says: a
        # clock learnt from the bus (`ClockTrack`) may have moved a cycle across the batches'
        # boundary since (judged against the frame before, then).
        # A cycle that seems measured within ``early_s`` after the scene's start may have
        # measured before it (nothing played yet): the scene's first is the one after.
        tolerance_s = self.clock.start_tolerance_s - self.early_s
        lo = (self.clock.first_at(start_s - tolerance_s)
              if self._next_n is None else self._next_n)
        if self.first_cycle is None:
            self.first_cycle = lo
        # The scene's end: a cycle that may have measured at it is after the scene.
        end_s = (max(end_s, start_s) if after is not None
                 else max(end_s - self.clock.edge_tolerance_s(end_s), start_s))
        hi = max(lo, self.clock.first_at(end_s))
        if self.cycles is not None:
            end_n = self.first_cycle + self.cycles
            hi = max(lo, end_n if after is None else min(hi, end_n))
        self._next_n = hi
        n = np.arange(lo, hi, dtype=np.int64)
        if not n.size:
            return n
        t_cycles = self.clock.time_of(n)
        held = np.clip(held_frames(applied, t_cycles), 0, last)
        # The frame change nearest each cycle, and whether it lies within the window.
        since = t_cycles - applied[held]
        has_next = held + 1 < frames.size
        until = np.where(has_next, applied[np.minimum(held + 1, frames.size - 1)] - t_cycles,
                         np.inf)
        to_before = (since < self.window_s + self.early_s) & (held > 0) & (since <= until)
        to_after = (until <= self.window_s) & has_next & ~to_before
        ambiguous = to_before | to_after
        t_all, scene = self.scene.t_s, self.scene
        # The scene once at every frame a cycle may be judged against: a radar in step with
        # the frames has the frame across each change as its neighbour's held one.
        alt = held - to_before + to_after
        need = np.union1d(held, alt[ambiguous])
        base = compute_tracks(scene, t_all[frames[need]], frames[need])
        truth = base.take(np.searchsorted(need, held), t_cycles)
        other = None
        if ambiguous.any():
            other = (base.take(np.searchsorted(need, alt), t_cycles), status[alt])
        self.checker.add_truth(int(n[0]), truth, status[held], other=other,
                               ambiguous=ambiguous)
        return n


def judge_empty_bench(report: Report, scene: Scenario, radar_options: RadarOptions,
                      output: str | None) -> None:
    """Fail an empty bench the built-in simulated radar played, whose check could not fail.

    `vacuous_empty_bench` says why, where ``output`` (the run's, or a re-checked log's from
    its sidecar) is ``simulated-radar``; played to an RTS, the radar is the bench's and the
    check is real. A scene that declares ``nothing_checked`` passes with the limit said
    (``scene_limits``), or, where the check was real, said as not hit.
    """
    vacuous = (vacuous_empty_bench(scene, radar_options) if output == "simulated-radar"
               else None)
    expected = scene.expectations.expected_limits
    if vacuous and "nothing_checked" in expected:
        # Declared: said beside the verdict, as the other limits of the whole scene.
        report.scene_limits["nothing_checked"] = {"why": vacuous, "expected": True}
    elif vacuous:
        report.reasons.append(FailReason(vacuous, "nothing_checked"))
        report.passed = False
    elif "nothing_checked" in expected and "nothing_checked" not in report.reason_codes:
        report.add_expected_not_hit(["nothing_checked"])


def judge_crowded_analytic(report: Report, scene: Scenario, frames: int,
                           what: str = "radar cycles") -> None:
    """Fail a run whose built-in radar read crowded frames in analytic fidelity, unless expected.

    ``frames``: how many ``what`` (`SimulatedRadar.frames_crowded_analytic`, which counts the
    frames it processed: its radar cycles; a re-check counts the scene's frames,
    `rts_scenario.preflight.Preflight.crowded_analytic_frames`). The analytic model reports
    targets that share a range-Doppler neighbourhood each as if alone, where a radar (and the
    cube of fidelity ``auto`` or ``adc``) merges or loses them: what passed there is not what
    a radar does. Said in ``scene_limits`` (``crowded_in_analytic``).
    """
    expected = "crowded_in_analytic" in scene.expectations.expected_limits
    if not frames:
        if expected:  # declared, not hit (another fidelity, no crowding, a bench's radar)
            report.add_expected_not_hit(["crowded_in_analytic"])
        return
    why = (f"in {frames} {what} targets shared a range-Doppler neighbourhood (within 2.5 "
           f"range and Doppler bins) where the built-in simulated radar, in analytic fidelity, "
           f"read each as if alone: a radar merges or loses them; fidelity auto or adc runs "
           f"such {what} through the beat-signal cube")
    report.scene_limits["crowded_in_analytic"] = {"why": why, "expected": expected}
    if not expected:
        report.reasons.append(FailReason(f"crowded_in_analytic: {why}", "crowded_in_analytic"))
        report.passed = False


def _stamped(message: can.Message) -> float:
    """When the host received a message the simulated radar sent in process: its stamp."""
    return float(message.timestamp)


def lag_dict(checker: Checker, coupling_s: float, early_s: float) -> dict[str, float | str]:
    """Return the report's ``radar_clock`` entries of the detections' timing.

    ``coupling_s``: the lag the radar's range-Doppler coupling gives (`Checker.lag_reason`);
    ``early_s``: how much earlier than their times the cycles may have been measured
    (`CycleTruth.early_s`), said where not 0.
    """
    out: dict[str, float | str] = {"early_s": early_s} if early_s else {}
    lag = checker.detection_lag_s(coupling_s)
    if lag is None:
        untold = checker.lag_untold()
        return out if untold is None else {**out, "detection_lag_untold": untold}
    return {**out, "detection_lag_s": lag[0], "detection_lag_error_s": lag[1],
            "detection_lag_coupling_s": coupling_s}


def after_scene_until_s(duration_s: float, cycle_s: float) -> float:
    """Return the scene time up to which cycles after the scene are counted (``after_scene``).

    A radar keeps measuring what the RTS holds after the scene's end, as long as it runs: how
    many of those cycles a run receives depends on how long it listens, and a recorder may go
    on after it stopped. Counted are those measured within one cycle (``cycle_s``, the
    radar's) and `QUIET_S` after the end, by the radar's clock: the run listens until they are
    in, and a re-check of its log counts the same ones.
    """
    return float(duration_s) + float(cycle_s) + QUIET_S


def ambiguity_window_s(radar: RadarProfile, rig: Rig) -> float:
    """Return how long after a frame change a radar cycle may still show the frame before.

    The radar's chirp sequence (its measurement time marks their end) plus the RTS's stated
    update latency (`HardwareLimits.update_latency_s`); see `CycleTruth`.
    """
    return radar.measurement_s + rig.limits.update_latency_s


def write_log_sidecar(log: str | Path, scene: Scenario, radar: RadarProfile,
                      options: RunOptions, played: PlayedRecord,
                      counter_start: int | None = None,
                      playback: dict[str, Any] | None = None,
                      send_lateness: dict[str, Any] | None = None,
                      clock: ClockTrack | None = None, first_cycle: int = 0,
                      cycles: int | None = None, origin_bus_s: float | None = None,
                      early_s: float = 0.0, channel: str | None = None,
                      channel_unknown: bool = False,
                      channel_named: bool | None = None,
                      host_clock_steps: list[dict[str, float | str]] | None = None,
                      bus_time_shifts: list[dict[str, float | int]] | None = None,
                      mapping_sha256: str | None = None) -> Path:
    """Write what re-checking a recorded bus log needs next to it (``LOG.rts.json``).

    The variant of the scene that played (`Scenario.variant`, its ``parametrize``
    combination), the radar's clock (which counter is which cycle, measured when), the mapping
    the bus speaks,
    the solver method, and what the run played (``played``, `PlayedRecord`: the statuses the
    RTS played and their digest, and checksums of the ground truth, so that a re-check judges
    the same target-frames against the same truth). ``counter_start`` is the one the
    run used (learnt, where the profile does not give it); ``playback`` the run's
    (`Playback.to_dict`) and ``send_lateness`` when each frame went out
    (`Playback.send_lateness`). ``clock`` is the clock the run ended with (`ClockTrack`): its
    cycle and phase are written, cycle 0 renumbered to the scene's first as the run took it
    (``first_cycle`` of the clock's numbers; ``counter_start`` is its counter; its time, the
    ``start_offset_s`` written, negative where it measured just before the scene's start), and
    ``cycles`` the number of cycles the run judged, so that a re-check judges the same ones;
    ``origin_bus_s`` the scene's start on the bus's clock, where the run knew it: the log's
    first cycles are numbered from it by their bus times, as live (`Checker.anchor`);
    ``early_s`` how much earlier than the clock's times the cycles may have been measured
    (`CycleTruth.early_s`: an interface's clock tied to the host's by deliveries);
    ``channel`` the CAN channel the radar's messages were read from (``options.can_channel``
    when not given; `Pipeline._radar_channel`), kept with the interface so that a re-check of
    a log holding several channels reads the radar's; ``channel_unknown``: they came on
    several and none was chosen (``can_channel`` null: a re-check does not pick one);
    ``channel_named``: whether the messages named their channel (`Pipeline._radar_channel_named`;
    a log file gives those that name none its format's default channel);
    ``host_clock_steps`` the steps of the host's clock the run saw (`Pipeline.host_clock_steps`)
    and ``bus_time_shifts`` where they moved the log's stamps: from the cycle of that counter
    stamped ``bus_s`` on (in log order), its bus times less ``shift_s`` are on the clock the
    scene's start (``origin_bus_s``) was taken on (`Pipeline._unstep`).
    """
    import json

    from ._version import __version__

    c = radar.radar_clock
    start_offset_s = c.start_offset_s
    if clock is not None:
        c = replace(c, cycle_s=clock.cycle_s)
        # Signed: the scene's first cycle may lie within the clock's uncertainty before its
        # start (it may have measured at it), and a re-check times the cycles from there too.
        start_offset_s = float(clock.time_of(np.array([first_cycle]))[0])
    path = Path(str(log) + LOG_SIDECAR_SUFFIX)
    data = {
        "rts_scenario_log": 1, "version": __version__, "scene": scene.name,
        "variant": scene.variant, "parameters": scene.parameters,
        "frames": scene.n_frames, "frame_rate_hz": scene.frame_rate_hz,
        "radar": radar.name,
        # The rig the run played on (`Rig.played_digest`): a re-check on another is refused.
        "rig": {"name": scene.rig.name, "sha256": scene.rig.played_digest()},
        "clock": {"cycle_s": c.cycle_s, "start_offset_s": start_offset_s,
                  "latency_s": c.latency_s, "jitter_s": c.jitter_s,
                  "counter_start": c.counter_start if counter_start is None
                  else counter_start, "cycles": cycles, "origin_bus_s": origin_bus_s,
                  "early_s": early_s, "host_clock_steps": host_clock_steps or [],
                  "bus_time_shifts": bus_time_shifts or []},
        "can_interface": options.can_interface,
        "can_channel": None if channel_unknown else (
            channel if channel is not None else options.can_channel),
        # False: the radar's messages named no channel, and a log file gives them its
        # format's default one (a re-check reads that as the run's).
        "can_channel_named": channel_named,
        # The channel ``run --radar-channel`` read alone (null: not given): a re-check reads
        # no other in its place.
        "radar_channel": options.radar_channel,
        "mapping": str(Path(options.mapping).resolve()) if options.mapping else None,
        # The mapping's and its DBC's text (`CanMapping.sha256`): a re-check by one edited
        # since decodes the log otherwise than the run did, and is refused.
        "mapping_sha256": mapping_sha256 or None,
        "can_fd": options.can_fd, "method": options.method, "output": options.output,
        # The statuses the RTS played (a re-check judges by them) and their digest, and per
        # target a checksum of the ground truth the run judged by (`PlayedRecord`).
        **played.sidecar_fields(),
        # How the schedule went out and what the RTS said it applied (`Playback.to_dict`):
        # a re-check fails on it as the run did.
        "playback": strict(playback) if playback is not None else None,
        # When each frame went out (`Playback.send_lateness`): a re-check judges the radar's
        # cycles by the frames the RTS held, as the run did.
        "send_lateness": send_lateness,
    }
    write_atomic(path, json.dumps(data, indent=2, allow_nan=False) + "\n")
    return path


def run_scene(scene: Scenario | str | Path, options: RunOptions | None = None,
              progress: Callable[[int, int], None] | None = None,
              detections_out: TextIO | None = None,
              on_preflight: Callable[[Preflight], None] | None = None,
              timing: dict[str, float] | None = None) -> RunResult:
    """Load (if given a path) and run a scene on the bench ``options`` describe.

    ``progress(done, total)`` is called after each batch of frames; ``detections_out`` gets
    every detection as a CSV row; ``on_preflight`` the scene's `Preflight` before it plays;
    ``timing`` holds seconds spent before (e.g. loading a scene passed in loaded).
    """
    start = time.perf_counter()
    timing = dict(timing or {})
    if not isinstance(scene, Scenario):
        scene = load_scenario(scene)
        timing["load_s"] = timing.get("load_s", 0.0) + time.perf_counter() - start
    with Pipeline.for_scene(scene, options) as pipeline:
        return pipeline.run(scene, progress, timing, detections_out, on_preflight)



class _Recording(can.Listener):
    """The run's receiver and its bus log as one listener: the log holds what the run counted.

    A message reaches both, or the receiver alone while the log is not recording. While a run
    resets the receiver or takes its counts (`switched`), messages are held back; the log then
    records from the next message on, or stops: its messages are the ones the run counted,
    however many more arrive before the bus is shut.
    """

    def __init__(self, receiver: DetectionReceiver, logger: can.Listener) -> None:
        self.receiver, self.logger = receiver, logger
        self.recording = True
        self._lock = threading.Lock()

    def on_message_received(self, msg: can.Message) -> None:
        with self._lock:
            self.receiver.on_message_received(msg)
            if self.recording:
                self.logger.on_message_received(msg)

    def on_error(self, exc: Exception) -> None:
        self.receiver.on_error(exc)

    def stop(self) -> None:
        try:
            self.receiver.stop()
        finally:
            self.logger.stop()

    @contextlib.contextmanager
    def switched(self, on: bool) -> Iterator[None]:
        """Hold messages back while the block runs; then record them (``on``) or not."""
        with self._lock:
            yield
            self.recording = on


__all__ = ["BATCH_FRAMES", "LOG_SIDECAR_SUFFIX", "Pipeline", "RunOptions", "RunResult",
           "CycleTruth", "after_scene_until_s", "ambiguity_window_s", "run_scene",
           "write_log_sidecar"]
