"""Schedule building and UDP streaming (run: pytest tests/benchmarks --benchmark-json=...)."""

import dataclasses

import numpy as np
import pytest
from benchmark_rates import record_rate
from scene_helpers import write_scene
from test_kinematics_speed import mixed_targets

from rts_scenario import perf
from rts_scenario.kinematics import compute_tracks
from rts_scenario.outputs import open_output
from rts_scenario.outputs.udp import UdpReceiver
from rts_scenario.scenario import load_scenario
from rts_scenario.schedule import build_schedule


@pytest.fixture(scope="module")
def scene_tracks(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sched")
    ego = {"motion": {"type": "constant_velocity", "position_m": [0, 0, 0], "speed_mps": 22.0}}
    scene = load_scenario(write_scene(folder, mixed_targets(32, np.random.default_rng(3)),
                                      duration_s=60.0, frame_rate_hz=20.0, ego=ego, seed=1))
    return scene, compute_tracks(scene)


def rig_for(scene, step_db, phase_step_deg=0.0):
    limits = dataclasses.replace(scene.rig.limits, attenuation_step_db=step_db,
                                 echoes_per_channel=64, phase_step_deg=phase_step_deg)
    return dataclasses.replace(scene.rig, limits=limits)


@pytest.mark.parametrize("step_db, phase_deg, mode",
                         [(0.0, 0.0, "aware"), (0.5, 0.0, "naive"), (0.5, 0.0, "aware"),
                          (0.5, 5.625, "aware")],
                         ids=["continuous", "0.5dB-naive", "0.5dB-aware", "0.5dB-5.625deg-aware"])
def test_schedule_1200_frames_32_targets(benchmark, scene_tracks, step_db, phase_deg, mode):
    scene, tracks = scene_tracks
    rig = rig_for(scene, step_db, phase_deg)
    build_schedule(tracks, rig, scene.radar, quantization=mode)  # per-rig caches
    benchmark.group = "schedule: 1200 frames x 32 targets"
    sch = benchmark.pedantic(build_schedule, args=(tracks, rig, scene.radar),
                             kwargs={"quantization": mode}, rounds=5, iterations=1)
    assert sch.status.shape == (1200, 32)


@pytest.fixture(scope="module")
def schedule(scene_tracks):
    scene, tracks = scene_tracks
    return build_schedule(tracks, rig_for(scene, 0.0), scene.radar)


def test_udp_loopback_throughput(benchmark, schedule):
    benchmark.group = "udp: loopback, as fast as possible"

    def stream():
        receiver = UdpReceiver().start()
        with open_output(f"udp://127.0.0.1:{receiver.address[1]}", pacing="fast") as out:
            out.write(schedule)
        return out, receiver

    out, receiver = benchmark.pedantic(stream, rounds=3, iterations=1)
    stats = receiver.stop()
    assert stats.clean and stats.frames_applied == schedule.n_frames
    benchmark.extra_info["entries"] = out.entries_sent
    record_rate(benchmark, "entries_per_s", out.entries_sent)


def test_udp_paced_jitter(benchmark, schedule):
    benchmark.group = "udp: paced at 20 Hz, 100 frames"
    part = schedule.frames(0, 100)
    result = {}

    def stream():
        receiver = UdpReceiver(keep_applied=True).start()
        with open_output(f"udp://127.0.0.1:{receiver.address[1]}", pacing="realtime") as out:
            out.write(part)
        result["stats"] = receiver.stop()
        result["late"] = out.sent_t_s(part) - part.t_s
        result["arrival"] = np.array(receiver.arrival_s)

    benchmark.pedantic(stream, rounds=1, iterations=1)
    assert result["stats"].clean
    late = result["late"]
    arrival = result["arrival"]
    # Jitter: deviation of each frame's time from the ideal 50 ms clock.
    sent_jitter = np.abs(late - np.median(late))
    recv_jitter = np.abs((arrival - arrival[0]) - (part.t_s - part.t_s[0]))
    benchmark.extra_info["send_jitter_p99_ms"] = float(np.percentile(sent_jitter, 99) * 1e3)
    benchmark.extra_info["receive_jitter_p99_ms"] = float(np.percentile(recv_jitter, 99) * 1e3)


def test_quantization_aware_against_continuous():
    """The quantization-aware schedule against the continuous one, alternating rounds."""
    figure = perf.quantization_ratio()
    print("\n" + figure.line())
    assert figure.met
