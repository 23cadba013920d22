"""The package's metadata agrees with itself."""

import tomllib
from pathlib import Path

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
