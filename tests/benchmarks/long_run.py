"""A long motorway scene for the streaming benchmarks: duration given on the command line.

Four vehicles drift around the ego for as long as the scene lasts (speed profiles with a 60 s
period), so every frame's ground truth differs from the frames one counter wrap (65,536 frames)
away: a frame checked against the wrong truth would fail.

Run ``python tests/benchmarks/long_run.py DURATION_S``: prints one JSON line with the peak
resident memory and the report's frame counts.
"""

from __future__ import annotations

import json
import resource
import sys
import tempfile
import time
from pathlib import Path

PERIOD_S = 60.0


def scene_text(duration_s: float) -> str:
    """The scene as YAML."""
    cycles = int(duration_s // PERIOD_S) + 2

    def profile(base: float, swing: float, phase: int) -> str:
        points = [f"{{t_s: {i * PERIOD_S / 2:g}, speed_mps: "
                  f"{base + (swing if (i + phase) % 2 else -swing):g}}}"
                  for i in range(2 * cycles)]
        return "[" + ", ".join(points) + "]"

    return f"""rts_scenario: 1
name: long-motorway
duration_s: {duration_s:g}
frame_rate_hz: 20.0
seed: 3
radar:
  profile: awr1843boost
  mount: {{x_m: 3.7, z_m: 0.5}}
  fidelity: analytic
rig: wide-3x5
ego:
  motion: {{type: constant_velocity, position_m: [0, 0, 0], speed_mps: 25.0}}
targets:
  - {{name: lead, rcs: {{rcs_dbsm: 10.0, fluctuation: swerling1}},
     motion: {{type: speed_profile, position_m: [35, 0, 0.6], profile: {profile(25.0, 0.4, 0)}}}}}
  - {{name: left, rcs: {{rcs_dbsm: 9.0}},
     motion: {{type: speed_profile, position_m: [22, 3.5, 0.6], profile: {profile(25.0, 0.3, 1)}}}}}
  - {{name: right, rcs: {{rcs_dbsm: 12.0}},
     motion: {{type: speed_profile, position_m: [50, -3.5, 1.0],
              profile: {profile(25.0, 0.5, 0)}}}}}
  - {{name: far, rcs: {{rcs_dbsm: 15.0, fluctuation: swerling3}},
     motion: {{type: speed_profile, position_m: [70, 0.3, 1.2], profile: {profile(25.0, 0.6, 1)}}}}}
expectations:
  tolerances: {{range_m: 0.3, radial_velocity_mps: 0.3, az_deg: 0.5, el_deg: 1.0}}
  detection_rate: 0.9
"""


def main(duration_s: float) -> dict[str, object]:
    """Run the scene end to end; return peak RSS and the report's counts."""
    from rts_scenario.pipeline import run_scene

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "long.scenario.yaml"
        path.write_text(scene_text(duration_s))
        start = time.perf_counter()
        report = run_scene(path).report
        wall = time.perf_counter() - start
    return {"duration_s": duration_s, "wall_s": round(wall, 2),
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            "passed": report.passed, "reasons": report.reasons, "frames": report.frames,
            "target_frames": report.target_frames, "detection_rate": report.detection_rate,
            "range_max_m": report.errors["range_m"].max, "timing": report.timing}


if __name__ == "__main__":
    print(json.dumps(main(float(sys.argv[1]))))
