"""Detections through CAN to the checker: messages per second, encode -> bus -> decode -> check.

Run: ``pytest tests/benchmarks/test_can_speed.py -s``. The in-process path (what a run with the
simulated radar uses: cycles published in batches on a `ListenerBus`, straight to the
receiver) is measured beside python-can's virtual bus with a reader, as before (a copy of each
message and a queue), in the same run.
"""

import time

import numpy as np
from test_radar_speed import eight_targets  # noqa: F401 - shared fixture

from rts_scenario.canbus import DetectionPublisher, DetectionReceiver, ListenerBus, open_bus
from rts_scenario.check import check_cycles as check
from rts_scenario.kinematics import compute_tracks
from rts_scenario.radar.simulate import SimulatedRadar

ROUNDS = 5
TARGET_MESSAGES_PER_S = 100_000


def _in_process(frames):
    receiver = DetectionReceiver()
    with ListenerBus([receiver]) as bus:
        publisher = DetectionPublisher(bus)
        publisher.publish_many(frames)
    return publisher, receiver


def _virtual_bus(frames):
    receiver = DetectionReceiver()
    with open_bus(channel="bench") as listen, open_bus(channel="bench") as talk:
        publisher = DetectionPublisher(talk)
        for frame in frames:  # the radar's frames, as they come
            publisher.publish(frame)
            while (msg := listen.recv(timeout=0)) is not None:
                receiver.on_message_received(msg)
        while (msg := listen.recv(timeout=0.01)) is not None:
            receiver.on_message_received(msg)
    return publisher, receiver


def _best(path, frames, scene, tracks, schedule):
    best, result = np.inf, None
    for _ in range(ROUNDS):
        start = time.perf_counter()
        publisher, receiver = path(frames)
        report = check(scene.name, tracks, schedule.status, receiver.flush(),
                       scene.expectations, bus=vars(receiver.stats))
        best = min(best, time.perf_counter() - start)
        result = publisher, receiver, report
    return best, result


def test_can_encode_bus_decode_check(benchmark, eight_targets):  # noqa: F811
    scene, schedule = eight_targets
    tracks = compute_tracks(scene)
    frames = SimulatedRadar(scene.radar, scene.rig, fidelity="analytic",
                            rng=np.random.default_rng(0)).process(schedule)
    assert sum(f.count for f in frames) >= 1200 * 8 - 10
    benchmark.group = "CAN: 1200 frames x 8 detections, encode -> bus -> decode -> check"
    fast_s, (publisher, receiver, report) = _best(_in_process, frames, scene, tracks, schedule)
    slow_s, (slow_pub, slow_rec, slow_report) = _best(_virtual_bus, frames, scene, tracks,
                                                      schedule)
    for pub, rec, rep in ((publisher, receiver, report), (slow_pub, slow_rec, slow_report)):
        assert rec.stats.clean and rec.stats.messages == pub.sent
        assert rep.frames["checked"] == 1200
    sent = publisher.sent
    print(f"\nCAN: {sent} messages; in process {sent / fast_s:,.0f} messages/s; "
          f"python-can virtual bus {sent / slow_s:,.0f} messages/s (same run); "
          f"ratio {slow_s / fast_s:.1f}x")
    benchmark.extra_info.update(messages=sent, messages_per_s=sent / fast_s,
                                virtual_bus_messages_per_s=sent / slow_s)
    benchmark.pedantic(lambda: _in_process(frames), rounds=1, iterations=1)
    assert sent / fast_s >= TARGET_MESSAGES_PER_S
