import numpy as np
import pytest

import rts_scenario as rs


@pytest.fixture(scope="session")
def kit_rig() -> rs.Rig:
    return rs.Rig.preset("kit-table1")


@pytest.fixture(scope="session", params=["paper", "awr1843boost"])
def array(request: pytest.FixtureRequest) -> rs.VirtualArray:
    return rs.VirtualArray.preset(request.param)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261121)


# CI replays the same examples every run (a new counterexample should come from a developer's
# run, not block a landing at random); locally hypothesis explores freely.
import os  # noqa: E402

from hypothesis import settings  # noqa: E402

settings.register_profile("ci", derandomize=True, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")
