"""How closely `check --log` places another tool's log in scene time (run: pytest
tests/benchmarks ... -s).

Logs as another tool writes them (tests/test_recheck.py's `foreign_log`): the cut-in scene on a
radar measuring every 72 ms from 13 ms, reporting 130 ms +- 4 ms later, counter from 4242, noise
on; BLF, ASC and CSV, with and without other ECUs' messages and 10 minutes of radar cycles before
the scene. Printed: the estimated offset's error against the truth and its stated uncertainty.
"""

import numpy as np
from test_recheck import foreign_log

from rts_scenario.recheck import check_log

CASES = [(seed, suffix, busy, lead) for seed, (suffix, busy, lead) in enumerate(
    [(".blf", False, 0.0), (".asc", True, 0.0), (".csv", False, 0.0), (".blf", True, 600.0),
     (".blf", False, 0.0), (".asc", False, 0.0), (".csv", True, 0.0), (".blf", False, 600.0)])]


def align_all(tmp_path_factory) -> dict[str, float]:
    errors, spreads, passed = [], [], 0
    for seed, suffix, busy, lead in CASES:
        origin = 1.7e9 + 1000.0 * np.random.default_rng(seed).random()
        scene, log, origin = foreign_log(tmp_path_factory.mktemp("log"), origin, seed,
                                         suffix=suffix, busy=busy, lead_s=lead)
        result = check_log(scene, log)
        errors.append(abs(result.alignment.offset_s - origin))
        spreads.append(result.alignment.uncertainty_s or np.nan)
        passed += result.report.passed
    return {"max_error_ms": 1e3 * max(errors), "median_error_ms": 1e3 * float(np.median(errors)),
            "median_uncertainty_ms": 1e3 * float(np.nanmedian(spreads)),
            "passed": passed, "logs": len(CASES)}


def test_alignment_of_other_tools_logs(benchmark, tmp_path_factory):
    benchmark.group = "check --log: offset of another tool's log"
    out = benchmark.pedantic(align_all, args=(tmp_path_factory,), rounds=1, iterations=1)
    benchmark.extra_info.update(out)
    print(f"\nalignment over {out['logs']} logs: error max {out['max_error_ms']:.2f} ms, median "
          f"{out['median_error_ms']:.2f} ms; stated uncertainty median "
          f"{out['median_uncertainty_ms']:.2f} ms; {out['passed']} passed")
    assert out["max_error_ms"] <= 20.0
    assert out["passed"] == out["logs"]
