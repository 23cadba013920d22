"""A bench rehearsal: a simulated RTS and radar behind the interfaces of a real bench.

`Emulator` listens for the schedule stream on UDP (`rts_scenario.outputs.udp.UdpReceiver`, the
reference RTS endpoint: frames are applied when complete and held until the next), and runs
the simulated radar on its own clock in wall time: cycle n is measured at the scene-time origin
(fixed by the first frame that arrives) plus ``start_offset_s + n * cycle_s``, sees the frame
the RTS holds at that moment, and its detections go out on CAN ``latency_s`` (+- ``jitter_s``)
later, with the radar's counter. `rts-scenario run SCENE --output udp://HOST:PORT` against it
exercises the path a bench uses: UDP to the RTS, a radar on its own clock, CAN back.
"""

from __future__ import annotations

import heapq
import itertools
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import can
import numpy as np

from .canbus import DetectionPublisher, open_bus
from .canbus.mapping import CanMapping
from .detections import Detections
from .outputs.udp import ReceiverStats, UdpReceiver
from .radar.profile import RadarProfile
from .radar.simulate import ChannelErrors, SimulatedRadar
from .rig import Rig
from .schedule import Schedule, Status

# How often the radar thread looks at the clock while waiting (s).
TICK_S = 0.0005


@dataclass
class EmulatorStats:
    """What the emulated radar did."""

    cycles: int = 0
    published: int = 0
    detections: int = 0
    idle_cycles: int = 0  # measured while the RTS held no frame yet
    late_s: list[float] = field(default_factory=list)  # measurement later than its time

    can_messages: int = 0
    unsendable_detections: int = 0

    @property
    def worst_late_s(self) -> float:
        """Largest delay of a measurement behind its cycle time (s)."""
        return max(self.late_s, default=0.0)

    def to_dict(self) -> dict[str, Any]:
        """Return the radar's counters as `Emulator.stop` gives them."""
        return {"cycles": self.cycles, "published": self.published,
                "detections": self.detections, "idle_cycles": self.idle_cycles,
                "worst_late_ms": round(self.worst_late_s * 1e3, 2)}


def schedule_of_entries(entries: np.ndarray, frame: int, t_s: float) -> Schedule:
    """Return the one-frame `Schedule` an RTS state holds (entries of the UDP protocol)."""
    target = entries["target"].astype(np.int64)
    channel = entries["channel"].astype(np.int64)
    k = int(target.max()) + 1 if target.size else 0
    shape = (1, k, 4)
    active = np.zeros(shape, dtype=bool)
    fe = np.full(shape, -1, dtype=np.int64)
    nan = np.full(shape, np.nan)
    att, delay, doppler, phase = nan.copy(), nan.copy(), nan.copy(), nan.copy()
    active[0, target, channel] = True
    fe[0, target, channel] = entries["fe"].astype(np.int64)
    att[0, target, channel] = entries["attenuation_db"].astype(np.float64)
    delay[0, target, channel] = entries["delay_s"].astype(np.float64)
    doppler[0, target, channel] = entries["doppler_hz"].astype(np.float64)
    phase[0, target, channel] = entries["phase_rad"].astype(np.float64)
    return Schedule(
        t_s=np.array([t_s]), frame_index=np.array([frame]),
        names=tuple(f"target {i}" for i in range(k)), quad=np.full((1, k), -1),
        fe=fe, weight=active.astype(np.float64), attenuation_db=att, delay_s=delay,
        doppler_hz=doppler, phase_rad=phase, active=active,
        status=np.full((1, k), Status.OK, dtype=np.uint16), angle_error_deg=np.zeros((1, k, 2)))


class Emulator:
    """A simulated RTS (UDP in) and radar on its own clock (CAN out), in wall time.

    Parameters
    ----------
    host, port : str, int
        Where to listen for the schedule stream (port 0: any free port; see `address`).
    rig, radar : Rig, RadarProfile
        The rig the RTS plays through and the radar (its clock: `RadarProfile.clock`).
    bus : can.BusABC, optional
        Where detections go; else ``open_bus(can_interface, can_channel)`` (closed on `stop`).
    fidelity, estimator, cfar, noise, rng :
        The simulated radar's options (`SimulatedRadar`).
    tamper : callable, optional
        Fault injection for tests: maps each cycle's `Detections` to what is published (None
        publishes nothing: a lost cycle).
    mapping, fd : CanMapping, bool, optional
        The radar's protocol (a third-party DBC through its mapping; rts-scenario's messages by
        default) and whether it speaks CAN FD.
    errors : ChannelErrors, optional
        The RTS channels' own phase, gain and delay errors (default none): what a calibration
        measures and the rig's calibration offsets cancel.
    """

    def __init__(self, rig: Rig, radar: RadarProfile, *, host: str = "127.0.0.1",
                 port: int = 0, bus: can.BusABC | None = None,
                 can_interface: str = "virtual", can_channel: str = "rts-emulator",
                 fidelity: str = "analytic", estimator: str = "bartlett", cfar: str = "ca",
                 noise: bool = True, rng: np.random.Generator | None = None,
                 tamper: Callable[[Detections], Detections | None] | None = None,
                 mapping: CanMapping | None = None, fd: bool = False,
                 errors: ChannelErrors | None = None) -> None:
        self.rig, self.radar = rig, radar
        self.clock = radar.radar_clock
        self.rng = rng if rng is not None else np.random.default_rng(0)
        # Frames that name FEs this rig lacks, or FEs that make none of its quads (a run on
        # another rig) are refused as malformed, never played on other FEs; each sender is told
        # the rig's geometry, so a run on a rig of the same layout pointing elsewhere fails.
        self.receiver = UdpReceiver(host, port, n_front_ends=rig.n_front_ends,
                                    quads=rig.quads, rig_digest=rig.geometry_digest())
        self._own_bus = bus is None
        # The radar's messages are stamped when it put them on the bus, its latency after
        # measuring, not when the publishing thread got round to them (a loaded host wakes
        # it late): python-can's virtual bus keeps a sender's stamp when told to. An interface
        # that stamps messages itself, as they pass, stamps them when they were sent.
        options = {"preserve_timestamps": True} if bus is None and \
            can_interface == "virtual" else {}
        try:
            self.bus = bus if bus is not None else open_bus(can_interface, can_channel,
                                                            **options)
        except BaseException:
            self.receiver.stop(drain_s=0.0)
            raise
        self.publisher = DetectionPublisher(self.bus, fd=fd, mapping=mapping)
        self.simulated = SimulatedRadar(radar, rig, fidelity=fidelity, estimator=estimator,
                                        cfar=cfar, noise=noise, errors=errors, rng=self.rng)
        self.tamper = tamper
        # The radar's counters of each stream (a run) by the stream's number; `stats` is the
        # current one's.
        self.stats = EmulatorStats()
        self._radar_runs: dict[int, EmulatorStats] = {}
        # Each finished run's counters (`stop`'s ``runs``), and the RTS's of those not yet
        # taken with their radar's.
        self.runs: list[dict[str, Any]] = []
        self._runs_lock = threading.Lock()
        self.receiver.on_stream_end = self._stream_ended
        self._stop = threading.Event()
        # (publish at, order, cycle, its run's counters)
        self._due: list[tuple[float, int, Detections, EmulatorStats]] = []
        self._order = itertools.count()
        self._due_lock = threading.Condition()
        self._threads: list[threading.Thread] = []

    @property
    def address(self) -> tuple[str, int]:
        """Where the RTS listens."""
        return self.receiver.address

    def start(self) -> Emulator:
        """Start receiving, measuring and publishing in background threads."""
        self.receiver.start()
        for target in (self._measure, self._publish):
            thread = threading.Thread(target=target, daemon=True)
            thread.start()
            self._threads.append(thread)
        return self

    def _radar_of(self, stream: int) -> EmulatorStats:
        """Return the radar's counters of stream ``stream`` (created on first use)."""
        with self._runs_lock:
            return self._radar_runs.setdefault(stream, EmulatorStats())

    def _stream_ended(self, stream: int, udp: ReceiverStats) -> None:
        """Keep a finished stream's counters, the RTS's and its radar's, as a run's."""
        with self._runs_lock:
            radar = self._radar_runs.pop(stream, None) or EmulatorStats()
            self.runs.append(self._run_dict(stream, udp, radar))

    @staticmethod
    def _run_dict(stream: int, udp: ReceiverStats, radar: EmulatorStats) -> dict[str, Any]:
        return {"run": stream, "udp": dict(vars(udp)), "radar": radar.to_dict(),
                "can_messages": radar.can_messages,
                "unsendable_detections": radar.unsendable_detections}

    def stop(self) -> dict[str, Any]:
        """Stop everything (cycles not yet published are dropped); return the statistics.

        ``runs``: each stream's (a run's) counters in turn, ``run`` its number from 1, ``udp``
        the RTS's, ``radar`` the radar's, ``can_messages`` and ``unsendable_detections``. At
        the top: ``udp`` of the last stream, the others summed over the runs.
        """
        self._stop.set()
        with self._due_lock:
            self._due_lock.notify_all()
        for thread in self._threads:
            thread.join()
        self._threads.clear()
        udp = self.receiver.stop(drain_s=0.0)
        if self._own_bus:
            self.bus.shutdown()
        with self._runs_lock:
            if self.receiver.streams and not any(r["run"] == self.receiver.streams
                                                 for r in self.runs):
                radar = self._radar_runs.pop(self.receiver.streams, None) or EmulatorStats()
                self.runs.append(self._run_dict(self.receiver.streams, udp, radar))
            runs = list(self.runs)
        total = {k: sum(r["radar"][k] for r in runs)
                 for k in ("cycles", "published", "detections", "idle_cycles")}
        total["worst_late_ms"] = max((r["radar"]["worst_late_ms"] for r in runs), default=0.0)
        return {"udp": dict(vars(udp)), "radar": total,
                "can_messages": self.publisher.sent,
                "unsendable_detections": self.publisher.unsendable_detections, "runs": runs}

    def __enter__(self) -> Emulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- the radar ---------------------------------------------------------------------------

    def _measure(self) -> None:
        """Measure on the radar's clock from the first frame on; queue each cycle's report.

        The RTS starts the radar: each stream (a run) restarts its clock and counter at the
        stream's first frame, and the reports of the stream before not yet on the bus are
        dropped.
        """
        origin = None
        n = 0
        stream = -1
        while not self._stop.is_set():
            if self.receiver.streams != stream:
                stream, origin, n = self.receiver.streams, None, 0
                with self._due_lock:
                    self._due.clear()
                self.stats = self._radar_of(stream)
            if origin is None:
                self.receiver.poll()
                first = self.receiver.first
                if first is None or self.receiver.streams != stream:
                    time.sleep(TICK_S)
                    continue
                # Scene time 0 in perf_counter time, by the stream's first frame however
                # late this thread looks: the RTS starts the radar as that frame arrives.
                _, t_s, arrival = first
                origin = arrival - t_s
            due = origin + float(self.clock.time_of(np.array([n]))[0])
            while (not self._stop.is_set() and time.perf_counter() < due
                   and self.receiver.streams == stream):
                time.sleep(min(TICK_S, max(due - time.perf_counter(), 0.0)))
            if self._stop.is_set():
                return
            if self.receiver.streams != stream:
                continue
            stats = self.stats
            stats.late_s.append(time.perf_counter() - due)
            if len(stats.late_s) > 10000:  # keep the worst, bounded
                stats.late_s = [max(stats.late_s)]
            self._measure_cycle(n, due)
            n += 1

    def _measure_cycle(self, n: int, due: float) -> None:
        """Measure cycle ``n`` (due at perf_counter time ``due``) and queue its report.

        It sees the frame the RTS held at ``due``, however late the thread got here: a radar
        measures on its own clock, not on its host's (a loaded machine wakes a thread late).
        Datagrams that reached the RTS by then are applied first, as of when they arrived,
        whether or not its receiving thread woke to them yet.
        """
        self.receiver.poll()
        snap = self.receiver.snapshot(at=due)
        if snap is None:  # a new stream began, its first frame not applied yet
            return
        frame, _, _, entries = snap
        stats = self.stats
        t_cycle = float(self.clock.time_of(np.array([n]))[0])
        counter = int(self.clock.counter_of(np.array([n]))[0])
        stats.cycles += 1
        schedule = schedule_of_entries(entries, counter, t_cycle)
        if schedule.active.any():
            cycle = self.simulated.process(schedule)[0]
        else:
            stats.idle_cycles += 1
            cycle = Detections.empty(counter, t_cycle)
        report = self.tamper(cycle) if self.tamper is not None else cycle
        if report is None:
            return
        at = due + float(self.clock.bus_delay(1, self.rng)[0])
        with self._due_lock:
            heapq.heappush(self._due, (at, next(self._order), report, stats))
            self._due_lock.notify()

    def _publish(self) -> None:
        """Put each cycle on the bus when its latency has passed."""
        while not self._stop.is_set():
            with self._due_lock:
                while not self._due and not self._stop.is_set():
                    self._due_lock.wait(0.05)
                if self._stop.is_set():
                    return
                at, _, report, stats = self._due[0]
                wait = at - time.perf_counter()
                if wait > 0:
                    self._due_lock.wait(min(wait, 0.05))
                    continue
                heapq.heappop(self._due)
            sent, unsendable = self.publisher.sent, self.publisher.unsendable_detections
            # When it was due on the bus, on the wall clock python-can stamps with.
            self.publisher.publish(report, time.time() - (time.perf_counter() - at))
            stats.published += 1
            stats.detections += report.count
            stats.can_messages += self.publisher.sent - sent
            stats.unsendable_detections += self.publisher.unsendable_detections - unsendable


__all__ = ["Emulator", "EmulatorStats", "schedule_of_entries"]
