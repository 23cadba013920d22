"""The compiled quantization-aware search chooses as the numpy search does.

Reference: the numpy search (`quantization._search_grid`), on the same entries; and the
independent peak search (`rts_scenario.peak_search`) for the angle the chosen settings give.
"""

import threading
import time

import numpy as np
import pytest
from test_schedule import RADAR, rig_with, tracks

from rts_scenario import workers
from rts_scenario.peak_search import find_peak, snapshot
from rts_scenario.radar import RadarProfile
from rts_scenario.rig import Rig
from rts_scenario.schedule import build as schedule_build
from rts_scenario.schedule import build_schedule, quantization

pytest.importorskip("numba", reason="the compiled search needs numba (pip install numba)")


@pytest.mark.parametrize("profile", ["paper", "awr1843boost"])
def test_compiled_search_matches_the_numpy_search(profile, monkeypatch):
    radar = RadarProfile.preset(profile) if profile != "paper" else RADAR
    rig = rig_with(attenuation_step_db=0.5, echoes_per_channel=64)
    rng = np.random.default_rng(11)
    az, el = rng.uniform(-2.9, 2.9, 300), rng.uniform(-5.9, 5.9, 300)

    def schedule(compiled):
        monkeypatch.setenv("RTS_SCENARIO_JIT", "on" if compiled else "off")
        return build_schedule(tracks(az[:, None], el[:, None]), rig, radar,
                              quantization="aware",
                              fe_responses="plane-wave")

    assert quantization.compiled_search() is not None
    fast, slow = schedule(True), schedule(False)
    err_fast = np.hypot(*fast.angle_error_deg[:, 0].T)
    err_slow = np.hypot(*slow.angle_error_deg[:, 0].T)
    assert np.isfinite(err_fast).all()
    # The same choice (its prunings skip only work whose outcome is known): a difference is
    # allowed only where rounding breaks a tie of the linear model, and is never worse.
    same = np.all(np.isclose(fast.attenuation_db[:, 0], slow.attenuation_db[:, 0],
                             equal_nan=True), axis=1)
    assert same.mean() >= 0.995
    assert np.all(err_fast <= err_slow + 1e-9)
    # What the radar sees (independent peak search, on a sample) is what was predicted.
    pick = rng.choice(az.size, 20, replace=False)
    w, fes = fast.weight[pick, 0], fast.fe[pick, 0]
    x = snapshot(radar.array, w, rig.az_deg[np.maximum(fes, 0)],
                 rig.el_deg[np.maximum(fes, 0)])
    p_az, p_el = find_peak(radar.array, x)
    np.testing.assert_allclose(np.hypot(p_az - az[pick], p_el - el[pick]), err_fast[pick],
                               atol=2e-3)


def test_compiled_search_matches_with_a_phase_shifter(monkeypatch):
    # With a 6-bit phase shifter both searches fit the attenuators to the channels as their
    # phase steps play them, and choose the same settings (phases included).
    import dataclasses

    kit = Rig.preset("kit-table1")
    rig = rig_with(dataclasses.replace(kit, cal_phase_deg=[10.0, -47.0, 100.3, 2.0]),
                   attenuation_step_db=0.5, phase_step_deg=5.625, echoes_per_channel=64)
    rng = np.random.default_rng(12)
    az, el = rng.uniform(-2.9, 2.9, 300), rng.uniform(-5.9, 5.9, 300)

    def schedule(compiled):
        monkeypatch.setenv("RTS_SCENARIO_JIT", "on" if compiled else "off")
        return build_schedule(tracks(az[:, None], el[:, None]), rig, RADAR,
                              quantization="aware", fe_responses="plane-wave")

    fast, slow = schedule(True), schedule(False)
    err_fast = np.hypot(*fast.angle_error_deg[:, 0].T)
    err_slow = np.hypot(*slow.angle_error_deg[:, 0].T)
    assert np.isfinite(err_fast).all()
    same = np.all(np.isclose(fast.attenuation_db[:, 0], slow.attenuation_db[:, 0],
                             equal_nan=True)
                  & np.isclose(fast.phase_rad[:, 0], slow.phase_rad[:, 0], equal_nan=True),
                  axis=1)
    assert same.mean() >= 0.995
    assert np.all(err_fast <= err_slow + 1e-9)


def test_compiled_search_matches_with_channels_off_on_a_grid_rig(monkeypatch):
    # Weak targets on the wide grid: channels that would need more attenuation than the
    # attenuator has are off, so the searches take their one-candidate and idle-channel paths.
    radar = RadarProfile.preset("awr1843boost")
    rig = rig_with(Rig.preset("wide-3x5"), attenuation_step_db=0.5, echoes_per_channel=64,
                   attenuation_max_db=75.0)
    rng = np.random.default_rng(5)
    n = 600
    az, el = rng.uniform(-19, 19, n), rng.uniform(-7.5, 7.5, n)
    ranges = rng.uniform(5.0, 120.0, n)

    def schedule(compiled):
        monkeypatch.setenv("RTS_SCENARIO_JIT", "on" if compiled else "off")
        return build_schedule(tracks(az[None, :], el[None, :], range_m=ranges[None, :]), rig,
                              radar, quantization="aware")

    fast, slow = schedule(True), schedule(False)
    played = fast.active[0].any(-1)
    some_off = played & (fast.active[0].sum(-1) < 4)
    assert some_off.mean() > 0.2  # the paths this test is for are taken
    err_fast = np.hypot(*fast.angle_error_deg[0].T)[played]
    err_slow = np.hypot(*slow.angle_error_deg[0].T)[played]
    same = np.all(np.isclose(fast.attenuation_db[0], slow.attenuation_db[0], equal_nan=True),
                  axis=1)[played]
    assert same.mean() >= 0.995
    assert np.all(err_fast <= err_slow + 1e-9)


@pytest.mark.parametrize("profile, rig_name, az_max, el_max", [
    ("paper", "kit-table1", 2.9, 5.9), ("awr1843boost", "kit-table1", 2.9, 5.9),
    ("awr1843boost", "wide-3x5", 19.0, 7.5)])
def test_the_shortlist_chooses_as_well_as_a_longer_one(profile, rig_name, az_max, el_max,
                                                       monkeypatch):
    # The exact prediction is what costs; `SHORTLIST` candidates of the linear model get it.
    # A longer shortlist must not find noticeably better settings.
    monkeypatch.setenv("RTS_SCENARIO_JIT", "on")
    radar = RadarProfile.preset(profile)
    rig = rig_with(Rig.preset(rig_name), attenuation_step_db=0.5, echoes_per_channel=4096)
    rng = np.random.default_rng(3)
    n = 3000
    az, el = rng.uniform(-az_max, az_max, n), rng.uniform(-el_max, el_max, n)
    trk = tracks(az[None], el[None], range_m=rng.uniform(3.0, 60.0, n)[None])

    def errors(shortlist):
        monkeypatch.setattr(quantization, "SHORTLIST", shortlist)
        e = np.hypot(*build_schedule(trk, rig, radar, quantization="aware").angle_error_deg[0].T)
        return e[np.isfinite(e)]

    short, long = errors(quantization.SHORTLIST), errors(8)
    assert short.size == long.size > 0.9 * n
    assert np.sqrt(np.mean(short**2)) <= np.sqrt(np.mean(long**2)) + 1e-4
    for q in (90, 99, 100):
        assert np.percentile(short, q) <= np.percentile(long, q) + 2e-4


def test_the_shortlist_selection_puts_nan_last_as_numpy_does():
    from rts_scenario.schedule._search_kernel import _kth_smallest

    rng = np.random.default_rng(3)
    for _ in range(200):
        n, k = int(rng.integers(1, 12)), int(rng.integers(1, 5))
        cost = rng.choice([0.5, 1.0, 2.0, 3.0, np.nan, np.inf], n) + rng.uniform(0, 1e-3, n) * (
            rng.random(n) < 0.5)
        top = np.full(k, -1, dtype=np.int64)
        kth = _kth_smallest(cost, n, k, top)
        ranked = np.argsort(np.where(np.isnan(cost), np.inf, cost), kind="stable")
        if n >= k:
            np.testing.assert_array_equal(top, ranked[:k])
            expected = cost[ranked[k - 1]]
            assert kth == (np.inf if np.isnan(expected) else expected)
        else:
            np.testing.assert_array_equal(top[:n], ranked)
            assert kth == np.inf


def _grid_scene(n, seed):
    radar = RadarProfile.preset("awr1843boost")
    rig = rig_with(Rig.preset("wide-3x5"), attenuation_step_db=0.5, echoes_per_channel=n)
    rng = np.random.default_rng(seed)
    return tracks(rng.uniform(-19, 19, n)[None], rng.uniform(-7.5, 7.5, n)[None]), rig, radar


@pytest.mark.skipif(workers.THREADS < 2, reason="one core: every search runs on this thread")
def test_searches_in_the_background_give_what_searching_here_gives(monkeypatch):
    # Parts small enough that every quad's search runs in several parts on the worker threads
    # while the next quad is prepared; against the same searches run here, one by one.
    trk, rig, radar = _grid_scene(1500, 8)
    monkeypatch.setenv("RTS_SCENARIO_JIT", "on")
    monkeypatch.setattr(quantization, "COMPILED_PART", 64)
    started = []
    real_start = quantization.start_parts

    def spy(fn, parts):
        parts = list(parts)
        started.append(len(parts))
        return real_start(fn, parts)

    monkeypatch.setattr(quantization, "start_parts", spy)
    background = build_schedule(trk, rig, radar, quantization="aware")
    assert sum(n > 1 for n in started) >= 2  # several quads, each in several parts
    monkeypatch.setattr(workers, "THREADS", 1)
    here = build_schedule(trk, rig, radar, quantization="aware")
    for field in ("attenuation_db", "weight", "angle_error_deg", "status", "active"):
        np.testing.assert_array_equal(getattr(background, field), getattr(here, field))


@pytest.mark.skipif(workers.THREADS < 2, reason="one core: every search runs on this thread")
def test_an_error_while_a_search_runs_leaves_no_part_running(monkeypatch):
    # The second quad fails while the first quad's search still runs: the caller hears of the
    # error only once that search is over.
    trk, rig, radar = _grid_scene(1500, 9)
    monkeypatch.setenv("RTS_SCENARIO_JIT", "on")
    monkeypatch.setattr(quantization, "COMPILED_PART", 64)
    kernel = quantization.compiled_search()
    running = []
    lock = threading.Lock()

    def slow(*args):
        with lock:
            running.append(True)
        time.sleep(0.02)
        kernel(*args)
        with lock:
            running.pop()

    monkeypatch.setattr(quantization, "compiled_search", lambda: slow)
    real_levels = schedule_build._start_levels
    calls = []

    def failing_second(*args):
        calls.append(True)
        if len(calls) == 2:
            raise RuntimeError("the second quad failed")
        return real_levels(*args)

    monkeypatch.setattr(schedule_build, "_start_levels", failing_second)
    with pytest.raises(RuntimeError, match="second quad"):
        build_schedule(trk, rig, radar, quantization="aware")
    with lock:
        assert running == []
