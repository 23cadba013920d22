"""A whole run: scene to verdict (run: pytest tests/benchmarks --benchmark-json=...)."""

from pathlib import Path

from rts_scenario.pipeline import run_scene

SCENE = Path(__file__).resolve().parents[2] / "scenarios" / "highway_platoon_60s.scenario.yaml"


def test_run_60s_20hz_8_targets(benchmark):
    benchmark.group = "run: 60 s x 20 Hz x 8 targets, analytic radar, virtual CAN"
    result = benchmark.pedantic(run_scene, args=(SCENE,), rounds=3, iterations=1,
                                warmup_rounds=1)
    assert result.report.passed
    assert result.report.frames["checked"] == 1200
    for stage, seconds in result.report.timing.items():
        benchmark.extra_info[stage] = seconds
