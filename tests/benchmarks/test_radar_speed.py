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


# Acceptance: the analytic radar's rate with 8 targets; an adc frame against its FFTs alone.
ANALYTIC_FRAMES_PER_S = 5000
ADC_OVER_FFTS = 3.0
ROUNDS = 30


@pytest.mark.parametrize("fidelity, frames", [("adc", 40), ("analytic", 1200)])
def test_radar_frames_per_second(benchmark, eight_targets, fidelity, frames):
    scene, schedule = eight_targets
    part = schedule.frames(0, frames)
    benchmark.group = f"simulated radar, awr1843boost, 8 targets: {fidelity}"

    def run():
        radar = SimulatedRadar(scene.radar, scene.rig, fidelity=fidelity,
                               rng=np.random.default_rng(0))
        return radar.process(part)

    dets = benchmark.pedantic(run, rounds=5, iterations=1, warmup_rounds=1)
    assert len(dets) == frames
    assert np.mean([d.count for d in dets]) >= 7.5
    rate = frames / benchmark.stats.stats.min
    benchmark.extra_info["frames_per_s"] = rate
    print(f"\n{fidelity}: {rate:,.0f} frames/s with 8 targets")
    if fidelity == "analytic":
        assert rate >= ANALYTIC_FRAMES_PER_S


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

    benchmark.group = "simulated radar, awr1843boost, 8 targets: adc frame vs its FFTs"
    # Alternating rounds: both see the same machine; each takes its best.
    radar.process(part.frames(0, 2))  # warm-up
    frame, best_fft = np.inf, np.inf
    for i in range(ROUNDS):
        one = part.frames(i % part.n_frames, i % part.n_frames + 1)
        frame = min(frame, _timed(lambda one=one: radar.process(one)))
        best_fft = min(best_fft, _timed(ffts))
    benchmark.pedantic(radar.process, args=(part.frames(0, 1),), rounds=1, iterations=1)
    benchmark.extra_info.update({"frame_ms": frame * 1e3, "ffts_ms": best_fft * 1e3,
                                 "ratio": frame / best_fft})
    print(f"\nadc frame {frame * 1e3:.1f} ms, its FFTs alone {best_fft * 1e3:.1f} ms: "
          f"{frame / best_fft:.1f}x (best of {ROUNDS} alternating rounds)")
    assert frame / best_fft <= ADC_OVER_FFTS


def _timed(fn) -> float:
    import time

    start = time.perf_counter()
    fn()
    return time.perf_counter() - start
