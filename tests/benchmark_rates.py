"""Record a benchmark's rate in its JSON ``extra_info`` when it was timed.

With ``--benchmark-disable`` pytest-benchmark runs the function once and keeps no statistics;
the benchmarks then still run (as tests of what they call) without recording a rate.
"""


def record_rate(benchmark, key, count, stat="min"):
    """Set ``extra_info[key]`` to ``count`` per second of the run's ``stat`` time, if timed."""
    stats = benchmark.stats
    if stats is None:
        return None
    rate = count / getattr(stats.stats, stat)
    benchmark.extra_info[key] = rate
    return rate
