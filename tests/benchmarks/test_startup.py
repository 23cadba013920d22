"""Start-up (run: pytest tests/benchmarks ... -s): importing the package, and a repeated run.

- ``import rts_scenario`` in a fresh interpreter, against ``import numpy`` alone in the same
  run (the floor any numerical package pays).
- A repeated in-process run of the cut-in scene on a rig whose solver plan is cached: the time
  `run_scene` reports (load to verdict).
"""

import subprocess
import sys
from pathlib import Path

from rts_scenario.pipeline import run_scene

ROOT = Path(__file__).resolve().parents[2]


def _import_seconds(module: str) -> float:
    code = (f"import time; t = time.perf_counter(); import {module}; "
            f"print(time.perf_counter() - t)")
    runs = [float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                 check=True, cwd=ROOT).stdout) for _ in range(5)]
    return min(runs)


def test_import_time(benchmark):
    benchmark.group = "start-up: import"
    package = benchmark.pedantic(_import_seconds, args=("rts_scenario",), rounds=1,
                                 iterations=1)
    numpy = _import_seconds("numpy")
    benchmark.extra_info.update({"import_rts_scenario_ms": package * 1e3,
                                 "import_numpy_ms": numpy * 1e3})
    print(f"\nimport rts_scenario {package * 1e3:.1f} ms (import numpy {numpy * 1e3:.1f} ms)")
    assert package <= 0.150


def test_repeated_cut_in_run(benchmark):
    scene = ROOT / "scenarios" / "cut_in.scenario.yaml"
    run_scene(scene)  # the plan is built (or read) once
    benchmark.group = "start-up: repeated cut-in run, cached plan"
    report = benchmark.pedantic(lambda: run_scene(scene).report, rounds=5, iterations=1)
    total = benchmark.stats.stats.min
    benchmark.extra_info.update({"total_s": total, "timing": report.timing})
    print(f"\ncut-in, repeated: {total * 1e3:.0f} ms in process ("
          + ", ".join(f"{k.removesuffix('_s')} {v * 1e3:.0f} ms" for k, v in
                      report.timing.items()) + ")")
    assert report.passed and total <= 0.35
