"""A sweep of the shipped scenes in this process and on two worker processes (runs per second).

Run: pytest tests/benchmarks/test_sweep_speed.py --benchmark-json=sweep.json; each round sweeps
every combination of scenarios/*.scenario.yaml with warm solver plans (the warm-up round builds
them), so the figure is the runs themselves plus the pool's start.
"""

import glob
from pathlib import Path

import pytest
from benchmark_rates import record_rate

from rts_scenario.sweep import collect_tasks, run_sweep

SCENES = sorted(glob.glob(str(Path(__file__).resolve().parents[2] / "scenarios"
                              / "*.scenario.yaml")))


@pytest.mark.parametrize("workers", [1, 2])
def test_sweep_shipped_scenes(benchmark, workers):
    benchmark.group = "sweep: shipped scenes, every combination"
    tasks = collect_tasks(SCENES)
    entries = benchmark.pedantic(run_sweep, args=(tasks,), kwargs={"workers": workers},
                                 rounds=3, iterations=1, warmup_rounds=1)
    assert all(e["status"] == "pass" for e in entries)
    benchmark.extra_info["runs"] = len(entries)
    record_rate(benchmark, "runs_per_s", len(entries), stat="median")
