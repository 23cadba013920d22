import os

import can.interfaces.virtual
import numpy as np
import numpy.fft  # noqa: F401  (below)
import pytest
from hypothesis import settings

import rts_scenario as rs

# pytester's in-process runs drop the modules first imported inside them when they end, and
# numpy.fft (numpy loads it on first use) refuses to load a second time: imported here, before
# any, so that a worker whose first FFT came inside a plugin test does not fail every later one.

# CI replays the same examples every run (a new counterexample should come from a developer's
# run, not block a landing at random); locally hypothesis explores freely.
settings.register_profile("ci", derandomize=True, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")

# The slowest tests (`pytest --durations=40` on two workers), slowest first. They run before
# the rest, so that under pytest-xdist no worker is left with a long test when the other has
# run out of work; a test not listed keeps its place after them. (A test using a fixture of
# module scope is not listed: moved away from its module, it would build the fixture again.)
SLOW_FIRST = (
    "tests/test_phase_search.py::test_the_phase_search_chooses_what_the_reference_chooses",
    "tests/test_two_processes.py::test_calibrate_an_emulated_rts_over_the_network_then_run_on",
    "tests/test_plugin.py::test_xdist_gives_the_same_verdicts",
    "tests/test_calibration.py::test_cli_calibrate_fails_when_the_check_grid_cannot_be_played",
    "tests/test_sweep.py::test_the_euro_ncap_catalogue_sweeps_to_the_same_verdicts_everywhere",
    "tests/test_honest_bench.py::test_cascade_sees_each_fe_where_the_reference_says",
    "tests/test_bench_calibration.py::test_a_pair_whose_frame_went_out_late_is_measured_again",
    "tests/test_bench_calibration.py::test_calibrate_recovers_channels_within_6_db_for_every",
    "tests/test_bad_input.py::test_random_command_lines_never_raise",
    "tests/test_radar_clock.py::test_a_free_radar_just_before_the_frames_is_numbered_by_all",
    "tests/test_solver.py::test_plane_waves_leave_no_gap_between_the_slanted_quads_of_lab_2x3",
    "tests/test_globalmax.py::test_feasible_targets_are_the_global_peak_over_the_field_of_view",
    "tests/test_solver.py::test_ten_million_targets",
    "tests/test_bench_calibration.py::test_a_pair_whose_frame_went_out_late_twice_stops_the",
    "tests/test_emulate.py::test_udp_losses_show_in_the_rts_statistics_and_in_the_detections",
    "tests/test_honest_bench.py::test_100_ps_delay_step_keeps_the_angle_on_a_calibrated_rig",
    "tests/test_recheck.py::test_a_damaged_log_is_one_error_line_without_a_traceback",
    "tests/test_radar_clock.py::test_cycles_on_one_line_read_as_bent_as_rarely_as_the_test_says",
    "tests/test_recheck.py::test_a_long_log_is_aligned_by_where_its_detections_begin",
    "tests/test_recheck.py::test_an_8_bit_counter_names_every_cycle_live_and_in_the_re_checks",
    "tests/test_bench_calibration.py::test_a_survey_of_a_rig_the_rts_does_not_have_fails_naming",
    "tests/test_cli.py::test_bench_prints_table_and_writes_json",
    "tests/test_sweep.py::test_relative_paths_reach_dask_workers_started_in_another_folder",
)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    def rank(item: pytest.Item) -> int:
        return next((i for i, prefix in enumerate(SLOW_FIRST) if item.nodeid.startswith(prefix)),
                    len(SLOW_FIRST))

    items.sort(key=rank)  # stable: the rest keep pytest's order


@pytest.fixture(autouse=True)
def frozen_heap(request: pytest.FixtureRequest):
    """In a module that sets ``REAL_TIME = True`` (rehearsals against an emulated bench, in
    wall-clock time), each test runs as the plugin plays a scene to an RTS: the session's heap
    collected, then frozen (`pytest_rts_scenario.frozen_heap`).

    A worker's heap grows over the session: late in a parallel run a full collection of it
    took 200-340 ms (measured), holding every thread, and an emulated radar's thread then
    measured that late.
    """
    from pytest_rts_scenario import frozen_heap as frozen

    with frozen(getattr(request.module, "REAL_TIME", False)):
        yield


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
def unnamed_channel(monkeypatch):
    """Make the run's in-process bus an interface naming no channel on its messages, as
    python-can's ``udp_multicast`` (the two-process rehearsal's bus) gives ``channel`` None."""
    from rts_scenario.canbus import ListenerBus

    class Unnamed(ListenerBus):
        def send(self, msg, timeout=None):
            msg.channel, msg.is_rx = None, True
            for listener in self._listeners:
                listener.on_message_received(msg)

    monkeypatch.setattr("rts_scenario.pipeline.ListenerBus", Unnamed)


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


class _CutShort:
    """A draft whose first write writes half its data, then raises ``exc``."""

    def __init__(self, file, exc):
        self._file, self._exc = file, exc

    def write(self, data):
        self._file.write(data[:len(data) // 2])
        self._file.flush()  # on disk: a file replaced in place would now be half a file
        raise self._exc

    def __getattr__(self, name):
        return getattr(self._file, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc_info):
        self._file.close()


@pytest.fixture
def cut_short_drafts(monkeypatch):
    """``arm(exc)``: from then on, every file replaced whole fails part way with ``exc``.

    A full disk (``OSError(ENOSPC)``) or an interrupt (``KeyboardInterrupt``) while the
    draft is written: what it replaces must stay as it was, and no draft stay behind.
    """
    import rts_scenario.atomic

    opened = rts_scenario.atomic._open_draft

    def arm(exc):
        def open_draft(target, mode, *args):
            file, draft = opened(target, mode, *args)
            return _CutShort(file, exc), draft

        monkeypatch.setattr(rts_scenario.atomic, "_open_draft", open_draft)

    return arm
