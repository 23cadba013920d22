"""Run one scene end to end: load, kinematics, schedule, output, detections over CAN, check.

With the default output, the schedule plays on the built-in simulated radar, whose detections
travel over a python-can bus (``virtual`` unless configured) to the checker - all in one
process. With ``udp://HOST:PORT`` or ``file:PATH`` the schedule goes to a real RTS (or a file)
and the checker listens for the real radar's detections on the configured CAN interface.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import can
import numpy as np

from .canbus import DetectionPublisher, DetectionReceiver, open_bus
from .canbus.mapping import CanMapping
from .check import check
from .kinematics import Tracks, compute_tracks
from .outputs import Output, open_output
from .outputs.radar import SimulatedRadarOutput
from .report import Report
from .scenario import Scenario, load_scenario
from .schedule import Schedule, build_schedule

BATCH_FRAMES = 100


@dataclass(frozen=True)
class RunOptions:
    """How to run a scene."""

    output: str = "simulated-radar"
    can_interface: str = "virtual"
    can_channel: str | None = None
    can_fd: bool = False
    mapping: str | None = None
    method: str = "exact"
    drain_s: float = 2.0


@dataclass
class RunResult:
    """Everything a run produced."""

    scene: Scenario
    tracks: Tracks
    schedule: Schedule
    report: Report


def run_scene(scene: Scenario | str | Path, options: RunOptions | None = None,
              progress: Callable[[int, int], None] | None = None) -> RunResult:
    """Run a scene and check the radar's detections.

    ``progress(done, total)`` is called after each batch of frames.
    """
    options = options or RunOptions()
    timing: dict[str, float] = {}
    start = time.perf_counter()
    if not isinstance(scene, Scenario):
        scene = load_scenario(scene)
    timing["load_s"] = time.perf_counter() - start

    mark = time.perf_counter()
    tracks = compute_tracks(scene)
    timing["kinematics_s"] = time.perf_counter() - mark
    mark = time.perf_counter()
    schedule = build_schedule(tracks, scene.rig, scene.radar, method=options.method,
                              frame_rate_hz=scene.frame_rate_hz)
    timing["schedule_s"] = time.perf_counter() - mark

    channel = options.can_channel or f"rts-scenario-{id(schedule):x}"
    mapping = CanMapping.from_file(options.mapping) if options.mapping else None
    listen = open_bus(options.can_interface, channel, fd=options.can_fd)
    receiver = DetectionReceiver(mapping)
    notifier = can.Notifier(listen, [receiver], timeout=0.05)
    talk = None
    try:
        mark = time.perf_counter()
        output: Output
        publisher: DetectionPublisher | None = None
        if options.output == "simulated-radar":
            talk = open_bus(options.can_interface, channel, fd=options.can_fd)
            publisher = DetectionPublisher(talk, fd=options.can_fd)
            radar_opts = scene.radar_options
            output = SimulatedRadarOutput(
                profile=scene.radar, rig=scene.rig, sink=publisher.publish,
                fidelity=radar_opts.fidelity, estimator=radar_opts.estimator,
                cfar=radar_opts.cfar, noise=radar_opts.noise,
                rng=np.random.default_rng(scene.seed))
        else:
            output = open_output(options.output)
        with output:
            for begin in range(0, schedule.n_frames, BATCH_FRAMES):
                output.write(schedule.frames(begin, begin + BATCH_FRAMES))
                if progress is not None:
                    progress(min(begin + BATCH_FRAMES, schedule.n_frames), schedule.n_frames)
        timing["play_s"] = time.perf_counter() - mark
        mark = time.perf_counter()
        expected = publisher.sent if publisher is not None else None
        _drain(receiver, expected, options.drain_s)
        timing["receive_s"] = time.perf_counter() - mark
    finally:
        notifier.stop()
        listen.shutdown()
        if talk is not None:
            talk.shutdown()
    mark = time.perf_counter()
    report = check(scene.name, tracks, schedule.emitted, receiver, scene.expectations)
    timing["check_s"] = time.perf_counter() - mark
    timing["total_s"] = time.perf_counter() - start
    report.timing = timing
    return RunResult(scene=scene, tracks=tracks, schedule=schedule, report=report)


def _drain(receiver: DetectionReceiver, expected: int | None, limit_s: float) -> None:
    """Wait until every sent message arrived (or, for a real radar, the bus went quiet)."""
    deadline = time.perf_counter() + limit_s
    seen = -1
    quiet_since = time.perf_counter()
    while time.perf_counter() < deadline:
        count = receiver.stats.messages
        if expected is not None and count >= expected:
            return
        if count != seen:
            seen, quiet_since = count, time.perf_counter()
        elif expected is None and time.perf_counter() - quiet_since > 0.2:
            return
        time.sleep(0.005)
