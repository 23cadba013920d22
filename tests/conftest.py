import os

import numpy as np
import pytest
from hypothesis import settings

import rts_scenario as rs

# CI replays the same examples every run (a new counterexample should come from a developer's
# run, not block a landing at random); locally hypothesis explores freely.
settings.register_profile("ci", derandomize=True, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")


@pytest.fixture(scope="session")
def kit_rig() -> rs.Rig:
    return rs.Rig.preset("kit-table1")


@pytest.fixture(scope="session", params=["paper", "awr1843boost"])
def array(request: pytest.FixtureRequest) -> rs.VirtualArray:
    return rs.VirtualArray.preset(request.param)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261121)
