"""Build scene files for tests."""

from pathlib import Path

import yaml

BASE = {
    "rts_scenario": 1,
    "name": "test",
    "duration_s": 10.0,
    "frame_rate_hz": 20.0,
    "radar": {"profile": "awr1843boost"},
    "rig": "wide-3x5",
}


def write_scene(folder: Path, targets: list, name: str = "t.scenario.yaml", **extra) -> Path:
    data = {**BASE, **extra, "targets": targets}
    path = folder / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path
