"""Simulated radar frame rates (run: pytest tests/benchmarks --benchmark-json=...)."""

import numpy as np
import pytest
from benchmark_rates import check_goals, record_rate

from rts_scenario import perf
from rts_scenario.kinematics import compute_tracks
from rts_scenario.radar.simulate import SimulatedRadar
from rts_scenario.scenario import load_scenario
from rts_scenario.schedule import build_schedule


@pytest.fixture(scope="module")
def eight_targets(tmp_path_factory):
    """60 s at 20 Hz, awr1843boost, 8 targets drifting around the ego over the wide rig."""
    path = perf.eight_target_scene(tmp_path_factory.mktemp("radar"))
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

    dets = benchmark.pedantic(run, rounds=5, iterations=1, warmup_rounds=1)
    assert len(dets) == frames
    assert np.mean([d.count for d in dets]) >= 7.5
    rate = record_rate(benchmark, "frames_per_s", frames)
    if rate is not None:
        print(f"\n{fidelity}: {rate:,.0f} frames/s with 8 targets")


def test_adc_frame_against_its_ffts_alone_and_the_analytic_rate(benchmark):
    """adc frames in a row against their two FFTs alone (same cube shape, no noise drawn
    beside them), and the analytic radar's frames per second (`rts_scenario.perf.radar_rates`).
    The adc goal is not met yet: it xfails with its figure."""
    benchmark.group = "simulated radar, awr1843boost, 8 targets: adc frame vs its FFTs"
    figures = benchmark.pedantic(perf.radar_rates, rounds=1, iterations=1)
    print()
    for figure in figures:
        print(figure.line())
        benchmark.extra_info[figure.name] = figure.value
    check_goals(figures, unmet=("adc frame",))
