"""The package's metadata agrees with itself."""

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import rts_scenario

ROOT = Path(__file__).resolve().parent.parent


def test_version_matches_pyproject():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert rts_scenario.__version__ == project["version"]



def test_the_cli_s_methods_are_the_schedule_s():
    # The CLI spells them out so that building its parser imports no solver code.
    from rts_scenario.cli.common import METHODS
    from rts_scenario.solver.estimator_aware import SCHEDULE_METHODS

    assert METHODS == SCHEDULE_METHODS


@pytest.mark.parametrize("module", ["rts_scenario.cli", "rts_scenario"])
def test_the_cli_runs_as_a_module(module):
    # `python -m rts_scenario` (as `python -m pytest` runs pytest) or `python -m
    # rts_scenario.cli`, where the console script is not on PATH.
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-m", module, "--version"],
                          capture_output=True, text=True, env=env, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == f"rts-scenario {rts_scenario.__version__}"
