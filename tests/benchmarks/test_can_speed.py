"""Detections through CAN to the checker (run: pytest tests/benchmarks --benchmark-json=...)."""

import numpy as np
from test_radar_speed import eight_targets  # noqa: F401 - shared fixture

from rts_scenario.canbus import DetectionPublisher, DetectionReceiver, open_bus
from rts_scenario.check import check_cycles as check
from rts_scenario.kinematics import compute_tracks
from rts_scenario.radar.simulate import SimulatedRadar


def test_can_encode_bus_decode_check(benchmark, eight_targets):  # noqa: F811
    scene, schedule = eight_targets
    tracks = compute_tracks(scene)
    frames = SimulatedRadar(scene.radar, scene.rig, fidelity="analytic",
                            rng=np.random.default_rng(0)).process(schedule)
    assert sum(f.count for f in frames) >= 1200 * 8 - 10
    benchmark.group = "CAN: 1200 frames x 8 detections, encode -> virtual bus -> decode -> check"
    result = {}

    def run():
        with open_bus(channel="bench") as listen, open_bus(channel="bench") as talk:
            receiver = DetectionReceiver()
            publisher = DetectionPublisher(talk)
            for frame in frames:  # the radar's frames, as they come
                publisher.publish(frame)
                while (msg := listen.recv(timeout=0)) is not None:
                    receiver.on_message_received(msg)
            while (msg := listen.recv(timeout=0.01)) is not None:
                receiver.on_message_received(msg)
        report = check(scene.name, tracks, schedule.status, receiver.flush(), scene.expectations,
                   bus=vars(receiver.stats))
        result.update(sent=publisher.sent, stats=receiver.stats, report=report)

    benchmark.pedantic(run, rounds=3, iterations=1)
    assert result["stats"].clean and result["stats"].messages == result["sent"]
    assert result["report"].frames["checked"] == 1200
    benchmark.extra_info["messages"] = result["sent"]
    benchmark.extra_info["messages_per_s"] = result["sent"] / benchmark.stats.stats.min
    print(f"\nCAN: {result['sent']} messages, "
          f"{result['sent'] / benchmark.stats.stats.min:,.0f} messages/s")
