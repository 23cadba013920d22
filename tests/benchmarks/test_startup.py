"""Start-up (run: pytest tests/benchmarks/test_startup.py -s): importing, and a repeated run.

- ``import rts_scenario`` in a fresh interpreter, against ``import numpy`` alone in the same
  run (the floor any numerical package pays).
- What a fresh command spends before its cut-in run goes as fast as a repeated one: the
  imports it makes and what its first run loads on first use, against ``import numpy``.
- A repeated in-process run of the cut-in scene on a rig whose solver plan is cached (load to
  verdict). All from `rts_scenario.perf.startup`.
"""

from pathlib import Path

from benchmark_rates import check_goals

from rts_scenario import perf

ROOT = Path(__file__).resolve().parents[2]


def test_import_time_and_a_repeated_cut_in_run(benchmark):
    benchmark.group = "start-up"
    figures = benchmark.pedantic(perf.startup, args=(ROOT / "scenarios" / "cut_in.scenario.yaml",),
                                 rounds=1, iterations=1)
    print()
    for figure in figures:
        print(figure.line())
        benchmark.extra_info[figure.name] = figure.value
    check_goals(figures, unmet=("start-up of a cut-in run",))
