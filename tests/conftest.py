import os

import can.interfaces.virtual
import numpy as np
import pytest
from hypothesis import settings

import rts_scenario as rs

# CI replays the same examples every run (a new counterexample should come from a developer's
# run, not block a landing at random); locally hypothesis explores freely.
settings.register_profile("ci", derandomize=True, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")


@pytest.fixture(scope="session", autouse=True)
def plan_cache_dir(tmp_path_factory: pytest.TempPathFactory):
    """Keep the solver's disk cache of plans out of the user's cache directory.

    One directory per test session: tests see the same cache whatever their order, and no plan
    from an earlier run (or other code) is ever loaded.
    """
    directory = tmp_path_factory.mktemp("plan-cache")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("RTS_SCENARIO_CACHE_DIR", str(directory))
        yield directory


@pytest.fixture(scope="session")
def kit_rig() -> rs.Rig:
    return rs.Rig.preset("kit-table1")


@pytest.fixture(scope="session", params=["paper", "awr1843boost"])
def array(request: pytest.FixtureRequest) -> rs.VirtualArray:
    return rs.VirtualArray.preset(request.param)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261121)


@pytest.fixture
def no_bus_left_open(monkeypatch):
    """Fail the test if it leaves a CAN bus open (virtual or in-process); yields the buses."""
    from rts_scenario.canbus import ListenerBus

    created = []
    for cls in (can.interfaces.virtual.VirtualBus, ListenerBus):
        def init(self, *args, _original=cls.__init__, **kwargs):
            _original(self, *args, **kwargs)
            created.append(self)

        monkeypatch.setattr(cls, "__init__", init)
    yield created
    left = [b for b in created if not b._is_shutdown]
    for b in left:
        b.shutdown()
    assert not left, f"{len(left)} CAN bus(es) left open"
