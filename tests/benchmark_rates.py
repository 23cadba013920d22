"""Record a benchmark's rate in its JSON ``extra_info`` when it was timed.

With ``--benchmark-disable`` pytest-benchmark runs the function once and keeps no statistics;
the benchmarks then still run (as tests of what they call) without recording a rate.
"""

import pytest


def record_rate(benchmark, key, count, stat="min"):
    """Set ``extra_info[key]`` to ``count`` per second of the run's ``stat`` time, if timed."""
    stats = benchmark.stats
    if stats is None:
        return None
    rate = count / getattr(stats.stats, stat)
    benchmark.extra_info[key] = rate
    return rate


def check_goals(figures, unmet=()):
    """Assert every figure's goal, but those of ``unmet`` (names' parts: goals the README says
    are not met yet), which xfail with their lines where they miss."""
    missed = [f for f in figures if not f.met]
    hard = [f.line() for f in missed if not any(part in f.name for part in unmet)]
    assert not hard, hard
    if missed:
        pytest.xfail("goals not met yet: " + "; ".join(f.line() for f in missed))
