"""Simulated radar frame rates (run: pytest tests/benchmarks --benchmark-json=...)."""

import numpy as np
import pytest
from scene_helpers import write_scene

from rts_scenario.kinematics import compute_tracks
from rts_scenario.radar.simulate import SimulatedRadar
from rts_scenario.scenario import load_scenario
from rts_scenario.schedule import build_schedule


@pytest.fixture(scope="module")
def eight_targets(tmp_path_factory):
    """60 s at 20 Hz, awr1843boost, 8 targets drifting around the ego over the wide rig."""
    rng = np.random.default_rng(4)
    targets = [{"name": f"car{i}", "frame": "ego", "rcs": {"rcs_dbsm": float(rng.uniform(0, 20))},
                "motion": {"type": "constant_velocity",
                           "position_m": [float(20 + 5 * i), float(rng.uniform(-4, 4)), 0.6],
                           "speed_mps": float(rng.uniform(0.0, 0.3))}} for i in range(8)]
    ego = {"motion": {"type": "constant_velocity", "position_m": [0, 0, 0], "speed_mps": 22.0}}
    path = write_scene(tmp_path_factory.mktemp("radar"), targets, duration_s=60.0,
                       frame_rate_hz=20.0, ego=ego, radar={"profile": "awr1843boost"})
    scene = load_scenario(path)
    schedule = build_schedule(compute_tracks(scene), scene.rig, scene.radar)
    assert schedule.emitted.sum(axis=1).min() == 8
    return scene, schedule


@pytest.mark.parametrize("fidelity, frames", [("adc", 40), ("analytic", 1200)])
def test_radar_frames_per_second(benchmark, eight_targets, fidelity, frames):
    scene, schedule = eight_targets
    part = schedule.frames(0, frames)
    benchmark.group = f"simulated radar, awr1843boost, 8 targets: {fidelity}"

    def run():
        radar = SimulatedRadar(scene.radar, scene.rig, fidelity=fidelity,
                               rng=np.random.default_rng(0))
        return radar.process(part)

    dets = benchmark.pedantic(run, rounds=3, iterations=1, warmup_rounds=1)
    assert len(dets) == frames
    assert np.mean([d.count for d in dets]) >= 7.5
    benchmark.extra_info["frames_per_s"] = frames / benchmark.stats.stats.min


def test_adc_frame_against_its_ffts_alone(benchmark, eight_targets):
    """The adc frame's cost relative to the two windowed FFTs of its cube (same shape, same run).

    ``extra_info["ratio"]`` is the frame's best time over the FFTs' best time.
    """
    scene, schedule = eight_targets
    part = schedule.frames(0, 20)
    radar = SimulatedRadar(scene.radar, scene.rig, fidelity="adc",
                           rng=np.random.default_rng(0))
    p = scene.radar
    shape = (p.chirp_loops, p.array.n_elements, p.adc_samples)
    noise = np.random.default_rng(1).standard_normal((2, *shape))
    cube = noise[0] + 1j * noise[1]
    win_r, win_d = np.hanning(shape[2] + 2)[1:-1], np.hanning(shape[0] + 2)[1:-1]

    def ffts():
        spec = np.fft.ifft(cube * win_r, axis=2)
        return np.fft.fft(spec * win_d[:, None, None], axis=0)

    best_fft = min(_timed(ffts) for _ in range(30))
    benchmark.group = "simulated radar, awr1843boost, 8 targets: adc frame vs its FFTs"
    benchmark.pedantic(radar.process, args=(part,), rounds=3, iterations=1, warmup_rounds=1)
    frame = benchmark.stats.stats.min / part.n_frames
    benchmark.extra_info.update({"frame_ms": frame * 1e3, "ffts_ms": best_fft * 1e3,
                                 "ratio": frame / best_fft})
    print(f"\nadc frame {frame * 1e3:.1f} ms, its FFTs alone {best_fft * 1e3:.1f} ms: "
          f"{frame / best_fft:.1f}x")


def _timed(fn) -> float:
    import time

    start = time.perf_counter()
    fn()
    return time.perf_counter() - start
