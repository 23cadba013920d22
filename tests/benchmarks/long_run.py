"""Run the bench's motorway scene of a given length end to end; print peak RSS and counts.

``python tests/benchmarks/long_run.py DURATION_S`` prints one JSON line. Each run is its own
process so its peak resident memory is its own.
"""

from __future__ import annotations

import json
import resource
import sys
import tempfile
import time
from pathlib import Path


def peak_rss_mb() -> float:
    """This process's peak resident memory (MB).

    Linux's VmHWM starts afresh at exec; ``ru_maxrss`` may carry the peak of the process that
    forked this one, so it is only the fallback.
    """
    try:
        with open("/proc/self/status") as status:
            return next(int(line.split()[1]) for line in status
                        if line.startswith("VmHWM")) / 1024.0
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main(duration_s: float) -> dict[str, object]:
    """Run the scene end to end; return peak RSS and the report's counts."""
    from rts_scenario.bench import motorway_scene
    from rts_scenario.pipeline import run_scene

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "long.scenario.yaml"
        path.write_text(motorway_scene(duration_s))
        start = time.perf_counter()
        report = run_scene(path).report
        wall = time.perf_counter() - start
    return {"duration_s": duration_s, "wall_s": round(wall, 2),
            "peak_rss_mb": peak_rss_mb(),
            "passed": report.passed, "reasons": report.reasons, "frames": report.frames,
            "target_frames": report.target_frames, "detection_rate": report.detection_rate,
            "range_max_m": report.errors["range_m"].max, "timing": report.timing}


if __name__ == "__main__":
    print(json.dumps(main(float(sys.argv[1]))))
