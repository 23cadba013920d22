"""The package's metadata agrees with itself."""

import tomllib
from pathlib import Path

import rts_scenario

ROOT = Path(__file__).resolve().parent.parent


def test_version_matches_pyproject():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert rts_scenario.__version__ == project["version"]

