"""A whole run: scene to verdict (run: pytest tests/benchmarks --benchmark-json=...)."""

from pathlib import Path

from rts_scenario.pipeline import run_scene

SCENE = Path(__file__).resolve().parents[2] / "scenarios" / "highway_platoon_60s.scenario.yaml"


def test_run_60s_20hz_8_targets(benchmark):
    benchmark.group = "run: 60 s x 20 Hz x 8 targets, analytic radar, virtual CAN"
    result = benchmark.pedantic(run_scene, args=(SCENE,), rounds=3, iterations=1,
                                warmup_rounds=1)
    assert result.report.passed
    # Every radar cycle arrived and was compared; the scene allows the weak bike a rare miss
    # (a cycle with an unmatched target), which its detection rate counts.
    frames = result.report.frames
    assert frames["total"] == frames["received"] == 1200
    assert frames["checked"] + frames["unmatched"] == 1200
    assert frames["missing"] == frames["incomplete"] == frames["late"] == 0
    for stage, seconds in result.report.timing.items():
        benchmark.extra_info[stage] = seconds
