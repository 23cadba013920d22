"""Scene to per-frame time series (run: pytest tests/benchmarks --benchmark-json=...)."""

import numpy as np
import pytest
from scene_helpers import write_scene

from rts_scenario.kinematics import compute_tracks
from rts_scenario.scenario import load_scenario


def mixed_targets(n: int, rng: np.random.Generator) -> list[dict]:
    """n targets cycling through every motion type, lane changes and RCS model."""
    targets = []
    for i in range(n):
        x, y = float(rng.uniform(10, 60)), float(rng.uniform(-6, 6))
        kind = i % 6
        if kind == 0:
            motion = {"type": "constant_velocity", "position_m": [x, y, 0.6], "speed_mps": 22.0}
        elif kind == 1:
            motion = {"type": "constant_acceleration", "position_m": [x, y, 0.6],
                      "speed_mps": 25.0, "acceleration_mps2": -0.5}
        elif kind == 2:
            motion = {"type": "speed_profile", "position_m": [x, y, 0.6], "profile": [
                {"t_s": 0, "speed_mps": 20}, {"t_s": 20, "speed_mps": 26},
                {"t_s": 40, "speed_mps": 18}, {"t_s": 60, "speed_mps": 24}]}
        else:
            points = [{"position_m": [x + 25 * k, y + float(rng.uniform(-2, 2)), 0.6],
                       "speed_mps": float(rng.uniform(18, 26))} for k in range(60)]
            motion = {"type": "waypoints", "path": "spline" if kind == 3 else "polyline",
                      "points": points}
        target = {"name": f"t{i}", "motion": motion,
                  "rcs": {"rcs_dbsm": 10.0} if i % 2 else
                         {"aspect_deg": [0, 90, 180, 270], "rcs_dbsm": [10, 15, 12, 15],
                          "fluctuation": "swerling1"}}
        if i % 4 == 0 and motion.get("path") != "polyline":  # no offset at a polyline's corner
            target["lane_changes"] = [{"start_s": 10.0 + i, "duration_s": 4.0, "offset_m": 3.5}]
        targets.append(target)
    return targets


@pytest.fixture(scope="module")
def scene_60s_32_targets(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bench")
    ego = {"motion": {"type": "constant_velocity", "position_m": [0, 0, 0], "speed_mps": 22.0}}
    path = write_scene(folder, mixed_targets(32, np.random.default_rng(3)), duration_s=60.0,
                       frame_rate_hz=20.0, ego=ego, seed=1)
    return load_scenario(path)


def test_tracks_60s_20hz_32_targets(benchmark, scene_60s_32_targets):
    benchmark.group = "kinematics: 60 s x 20 Hz x 32 targets"
    tracks = benchmark(compute_tracks, scene_60s_32_targets)
    assert tracks.range_m.shape == (1200, 32)
    benchmark.extra_info["budget_s"] = 0.050


def test_load_60s_32_targets(benchmark, tmp_path):
    benchmark.group = "scene loading: 32 targets"
    path = write_scene(tmp_path, mixed_targets(32, np.random.default_rng(3)), duration_s=60.0)
    scene = benchmark(load_scenario, path)
    assert len(scene.targets) == 32
