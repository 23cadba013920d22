"""The streaming checker against hand-built truth and cycles (no simulator involved)."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from rts_scenario.check import Checker
from rts_scenario.check import check_cycles as check
from rts_scenario.detections import Detections, unwrap_counter
from rts_scenario.kinematics import Tracks, compute_tracks
from rts_scenario.report import FrameRecord, RunningStats
from rts_scenario.scenario import load_scenario
from rts_scenario.scenario.model import Expectations
from rts_scenario.schedule import Status


def OK(n_frames, n_targets):
    """Schedule status of target-frames played exactly as specified."""
    return np.zeros((n_frames, n_targets), dtype=np.uint16)


EXPECT = Expectations(tolerances={"range_m": 0.3, "radial_velocity_mps": 0.3, "az_deg": 0.5,
                                  "el_deg": 1.0, "rcs_db": 100.0})


def truth(n_frames, n_targets=2, first=0):
    """Targets whose range and angles change every frame (no two frames alike)."""
    f = np.arange(first, first + n_frames, dtype=float)[:, None]
    k = np.arange(n_targets, dtype=float)[None, :]
    shape = (n_frames, n_targets)
    ones = np.ones(shape, dtype=bool)
    return Tracks(names=tuple(f"t{i}" for i in range(n_targets)), t_s=f[:, 0] * 0.05,
                  range_m=20.0 + 10.0 * k + 5.0 * np.sin(f * 0.01),
                  radial_velocity_mps=np.cos(f * 0.01) + k, doppler_hz=np.zeros(shape),
                  rcs_dbsm=np.full(shape, 10.0), az_deg=np.sin(f * 0.003) * 3.0 - 2.0 * k,
                  el_deg=np.zeros(shape) + 0.5 * k, position_m=np.zeros((*shape, 3)),
                  present=ones, in_coverage=ones, in_range=ones, in_velocity=ones)


def cycles_from(tracks, first=0, modulus=65536, drop=None, offset=0.0):
    """One cycle per frame reporting each target's truth (``drop``: (frame, target) pairs)."""
    drop = drop or set()
    out = []
    for f in range(tracks.t_s.size):
        keep = [k for k in range(len(tracks.names)) if (first + f, k) not in drop]
        out.append(Detections(
            cycle=(first + f) % modulus, t_s=float(tracks.t_s[f]),
            range_m=tracks.range_m[f, keep] + offset,
            radial_velocity_mps=tracks.radial_velocity_mps[f, keep],
            az_deg=tracks.az_deg[f, keep], el_deg=tracks.el_deg[f, keep],
            rcs_dbsm=tracks.rcs_dbsm[f, keep], snr_db=np.full(len(keep), 30.0)))
    return out


def block(tracks, a, b):
    return Tracks(**{f.name: (getattr(tracks, f.name) if not isinstance(getattr(tracks, f.name),
                                                                        np.ndarray)
                              else getattr(tracks, f.name)[a:b])
                     for f in dataclasses.fields(Tracks)})


def flat(value, key=""):
    """Nested report data as {path: value} (sums may differ in the last bit by block order)."""
    if isinstance(value, dict):
        return {k2: v2 for k, v in value.items() for k2, v2 in flat(v, f"{key}.{k}").items()}
    if isinstance(value, list):
        return {k2: v2 for i, v in enumerate(value) for k2, v2 in flat(v, f"{key}.{i}").items()}
    return {key: value}


def test_perfect_cycles_pass_with_every_frame_checked():
    tr = truth(300)
    report = check("s", tr, OK(300, 2), cycles_from(tr), EXPECT)
    assert report.passed, report.reasons
    assert report.frames["checked"] == report.frames["received"] == 300
    assert report.target_frames == {"checkable": 600, "matched": 600, "unmatched": 0,
                                    "unchecked": 0, "detected": 600}
    assert report.errors["range_m"].max == 0.0


def test_a_verdict_says_what_it_was_held_to():
    # A reviewer of a pass sees its standard, not only a fail's numbers.
    tr = truth(20)
    held = Expectations(tolerances={"range_m": 0.25, "radial_velocity_mps": 0.1, "az_deg": 0.4,
                                    "el_deg": 1.5, "rcs_db": 8.0},
                        detection_rate=0.97, max_false_detections_per_frame=0.05)
    report = check("s", tr, OK(20, 2), cycles_from(tr), held)
    assert report.passed
    assert ("held to: range 0.25 m, radial velocity 0.1 m/s, az 0.4 deg, el 1.5 deg, rcs 8 dB; "
            "detection rate >= 97.0% per target; false detections <= 0.05 per cycle\n"
            ) in report.table()
    assert report.to_dict()["expectations"] == {
        "tolerances": {"range_m": 0.25, "radial_velocity_mps": 0.1, "az_deg": 0.4,
                       "el_deg": 1.5, "rcs_db": 8.0},
        "detection_rate": 0.97, "max_false_detections_per_frame": 0.05}


def test_streaming_in_blocks_equals_one_shot():
    tr = truth(400)
    played = OK(400, 2)
    drop = {(17, 0), (230, 1)}
    cycles = cycles_from(tr, drop=drop, offset=0.05)
    whole = check("s", tr, played, cycles, EXPECT).to_dict()
    checker = Checker("s", tr.names, EXPECT)
    edges = [0, 37, 150, 151, 399, 400]
    for i, (a, b) in enumerate(zip(edges, edges[1:], strict=False)):
        checker.add_truth(a, block(tr, a, b), played[a:b])
        checker.add_frames(block(tr, a, b), played[a:b])
        if i:  # cycles of a block arrive one block late, as from a radar with latency
            checker.add_cycles(cycles[edges[i - 1]:a])
        checker.settle(before_frame=edges[i - 1] if i else 0)
    checker.add_cycles(cycles[edges[-2]:])
    checker.settle()
    got, want = flat(checker.report().to_dict()), flat(whole)
    assert got.keys() == want.keys()
    numbers = {k for k, v in want.items() if isinstance(v, float)}
    assert {k: got[k] for k in numbers} == pytest.approx({k: want[k] for k in numbers},
                                                         rel=1e-12, nan_ok=True)
    assert {k: got[k] for k in want.keys() - numbers} == {k: want[k] for k in want.keys() - numbers}


def test_unmatched_target_frames_are_never_reported_as_checked():
    tr = truth(100)
    drop = {(10, 0), (11, 0), (50, 1)}
    report = check("s", tr, OK(100, 2), cycles_from(tr, drop=drop), EXPECT)
    assert report.frames["received"] == 100
    assert report.frames["checked"] == 97 and report.frames["unmatched"] == 3
    assert report.target_frames["unmatched"] == 3 and report.target_frames["matched"] == 197
    assert report.targets[0].detected_frames == 98
    missed = [w for w in report.worst_frames if w["missed"]]
    assert {(w["frame"], w["target"]) for w in missed} == {(10, "t0"), (11, "t0"), (50, "t1")}


def test_wrapped_counters_are_checked_against_their_own_frames():
    n = 70_000  # beyond one 16-bit wrap
    tr = truth(n, n_targets=1)
    played = OK(n, 1)
    cycles = cycles_from(tr)
    checker = Checker("long", tr.names, EXPECT)
    step = 5000
    for a in range(0, n, step):
        checker.add_truth(a, block(tr, a, a + step), played[a:a + step])
        checker.add_cycles(cycles[a:a + step])
        checker.settle(before_frame=a)
    checker.settle()
    report = checker.report()
    assert report.frames["checked"] == n and report.frames["late"] == 0
    assert report.errors["range_m"].max == 0.0 and report.passed


def test_an_8_bit_counter_names_its_cycles_though_a_batch_holds_more():
    # As a run hands them on: each batch's cycles arrive before its truth (handed on with the
    # next batch), and a batch holds 500 cycles, an 8-bit counter counts 256.
    n, step = 1200, 500
    tr = truth(n, n_targets=1)
    played = OK(n, 1)
    cycles = cycles_from(tr, modulus=256)
    checker = Checker("8-bit", tr.names, EXPECT, counter_modulus=256)
    for a in range(0, n, step):
        if a:
            checker.add_truth(a - step, block(tr, a - step, a), played[a - step:a])
        checker.add_cycles(cycles[a:a + step])
        checker.settle(before_frame=a - step)
    checker.add_truth(a, block(tr, a, n), played[a:])
    checker.settle()
    report = checker.report()
    assert report.frames["checked"] == n
    assert (report.frames["missing"], report.frames["late"], report.frames["repeated"]) == (
        0, 0, 0)
    assert report.errors["range_m"].max == 0.0 and report.passed


def test_a_cycle_checked_against_the_wrong_wrap_fails():
    n = 70_000
    tr = truth(n, n_targets=1)
    cycles = cycles_from(tr)
    # The radar reports frame f - 65536's values under frame f's counter: the truth differs.
    confused = [dataclasses.replace(cycles[f - 65536], cycle=cycles[f].cycle)
                if f >= 65536 else cycles[f] for f in range(n)]
    report = check("s", tr, OK(n, 1), confused, EXPECT)
    assert report.targets[0].detected_frames < n - 4000


def test_missing_and_incomplete_cycles_fail_and_are_counted():
    tr = truth(50)
    cycles = cycles_from(tr)
    cycles[3] = dataclasses.replace(cycles[3], complete=False)
    del cycles[7]
    report = check("s", tr, OK(50, 2), cycles, EXPECT)
    assert report.frames["missing"] == 1 and report.frames["incomplete"] == 1
    assert report.target_frames["unchecked"] == 4
    assert not report.passed and any("could not be checked" in r for r in report.reasons)
    # Their targets are not checked, not missed: the worst frames agree with the table.
    assert sum(t.missed_frames for t in report.targets) == 0
    assert all(not row["missed"] for row in report.worst_frames)
    assert {row["frame"] for row in report.worst_frames}.isdisjoint({3, 7})


def test_no_cycle_at_all_leaves_no_worst_frame():
    # Nothing was judged, nothing is worst (a target-frame never received is not missed).
    report = check("s", truth(50), OK(50, 2), [], EXPECT)
    assert report.target_frames["unchecked"] == 100 and report.worst_frames == []


def test_a_missing_cycle_fails_even_where_no_target_was_checkable():
    tr = truth(50)
    status = OK(50, 2)
    status[7] = Status.OUT_OF_COVERAGE  # nothing to detect in cycle 7, but false detections
    cycles = cycles_from(tr)
    del cycles[7]
    exp = dataclasses.replace(EXPECT, expected_limits=frozenset({"out_of_coverage"}))
    report = check("s", tr, status, cycles, exp)
    assert report.frames["missing"] == 1 and report.target_frames["unchecked"] == 0
    assert not report.passed
    assert report.reasons == ["1 radar cycles missing and 0 incomplete: 0 target-cycles and the "
                              "cycles' false detections could not be checked"]


def test_an_empty_bench_checks_false_detections_only():
    empty = truth(40, n_targets=0)
    quiet = [Detections.empty(f, float(t)) for f, t in enumerate(empty.t_s)]
    strict = dataclasses.replace(EXPECT, max_false_detections_per_frame=0.0)
    report = check("s", empty, OK(40, 0), quiet, strict)
    assert report.passed, report.reasons
    assert report.frames["checked"] == report.frames["received"] == 40
    assert report.targets == [] and report.false_detections == 0
    # One ghost in 40 cycles: 0.025 per cycle, within the default 0.1 but not within 0.
    ghost = dataclasses.replace(
        quiet[5], range_m=np.array([12.0]), radial_velocity_mps=np.array([0.0]),
        az_deg=np.array([1.0]), el_deg=np.array([0.0]), rcs_dbsm=np.array([5.0]),
        snr_db=np.array([20.0]))
    haunted = [*quiet[:5], ghost, *quiet[6:]]
    assert check("s", empty, OK(40, 0), haunted, EXPECT).passed
    report = check("s", empty, OK(40, 0), haunted, strict)
    assert report.false_detections == 1
    assert report.reasons == ["0.025 false detections per radar cycle > 0"]
    # Cycles that never came could not be checked; none at all is nothing to check.
    report = check("s", empty, OK(40, 0), quiet[:30], strict)
    assert not report.passed and report.frames["missing"] == 10
    report = check("s", empty, OK(40, 0), [], strict)
    assert "nothing to check: no radar cycle was received" in report.reasons


def test_absent_quantities_are_not_checked():
    tr = truth(20)
    cycles = [dataclasses.replace(c, el_deg=None, rcs_dbsm=None) for c in cycles_from(tr)]
    report = check("s", tr, OK(20, 2), cycles, EXPECT)
    assert report.passed
    assert report.errors["el_deg"].count == 0 and report.errors["range_m"].count == 40



@pytest.mark.parametrize("quantity", ["range_m", "az_deg", "radial_velocity_mps", "rcs_dbsm"])
def test_a_detection_whose_reported_value_is_not_a_number_matches_nothing_and_fails(quantity):
    # Every cycle: both targets reported correctly, plus one detection equal to target 0 but
    # with one reported quantity NaN (or infinite). It must neither count as target 0's match
    # (zero error) nor hide among the false detections.
    tr = truth(20)
    cycles = []
    for c in cycles_from(tr):
        extra = {q: np.append(getattr(c, q), getattr(c, q)[0])
                 for q in ("range_m", "radial_velocity_mps", "az_deg", "el_deg", "rcs_dbsm",
                           "snr_db")}
        extra[quantity][-1] = np.nan if c.cycle % 2 else np.inf
        cycles.append(dataclasses.replace(c, **extra))
    report = check("s", tr, OK(20, 2), cycles, EXPECT)
    assert not report.passed
    assert report.invalid_detections == 20
    assert report.false_detections == 0
    assert report.target_frames["detected"] == 40  # the real detections still match
    assert any("20 detections with a reported quantity that is not a number" in r
               for r in report.reasons)
    assert "invalid detections (not a number): 20" in report.table()


def test_an_all_nan_cycle_does_not_detect_anything():
    tr = truth(10, n_targets=1)
    nan = np.array([np.nan])
    cycles = [Detections(cycle=i, t_s=0.05 * i, range_m=nan, radial_velocity_mps=nan,
                         az_deg=nan, el_deg=nan, rcs_dbsm=nan, snr_db=nan) for i in range(10)]
    report = check("s", tr, OK(10, 1), cycles, EXPECT)
    assert not report.passed
    assert report.detection_rate == 0.0 and report.invalid_detections == 10


def test_cycles_for_frames_the_scene_never_had_are_counted_not_lost():
    tr = truth(10)
    cycles = cycles_from(tr) + cycles_from(truth(3, first=9000), first=9000)
    report = check("s", tr, OK(10, 2), cycles, EXPECT)
    assert report.frames["after_scene"] == 3 and report.frames["checked"] == 10
    assert report.frames["late"] == 0 and report.passed
    # Shown, not only in the JSON.
    assert "0 incomplete, 3 after the scene's end (not checked);" in report.table()


def test_detections_reject_quantities_of_different_lengths():
    from rts_scenario.errors import RtsError
    with pytest.raises(RtsError, match="differ in length"):
        Detections(cycle=1, t_s=0.0, range_m=np.zeros(2), az_deg=np.zeros(3))
    d = Detections(cycle=1, t_s=None, range_m=[1.0, 2.0], snr_db=[3.0, 9.0])
    assert d.count == 2 and d.present == ("range_m", "snr_db") and d.strongest() == 1


@pytest.mark.parametrize("near", [0, 65535, 65536 * 3 + 10])
def test_unwrap_counter_picks_the_nearest_wrap(near):
    frames = near + np.arange(-20000, 20000, 997)
    np.testing.assert_array_equal(unwrap_counter(frames % 65536, near, 65536), frames)


def test_running_stats_match_numpy():
    rng = np.random.default_rng(3)
    x = rng.lognormal(-3.0, 2.0, (5000, 3)) * rng.choice([-1, 1], (5000, 3))
    x[::97, 1] = np.nan
    stats = RunningStats(3)
    for part in np.array_split(x, 7):
        stats.add(part)
    for k in range(3):
        col = np.abs(x[:, k][np.isfinite(x[:, k])])
        got = stats.result(k)
        assert got.count == col.size
        assert got.rms == pytest.approx(np.sqrt(np.mean(col**2)), rel=1e-12)
        assert got.max == col.max()
        # A 1 % histogram bin: the percentile is within half a bin of numpy's.
        for q, value in ((50, got.p50), (95, got.p95)):
            assert value == pytest.approx(np.percentile(col, q), rel=0.006)
    assert stats.result().count == sum(stats.result(k).count for k in range(3))


def test_frame_record_round_trip(tmp_path):
    record = FrameRecord(tmp_path / "rec")
    a = {"t_s": np.arange(3.0), "ok": np.array([[True, False]] * 3)}
    b = {"t_s": np.arange(3.0, 5.0), "ok": np.array([[False, True]] * 2)}
    record.append(a)
    record.append(b)
    back = record.load()
    np.testing.assert_array_equal(back["t_s"], np.arange(5.0))
    assert back["ok"].shape == (5, 2) and record.frames == 5


def test_status_must_be_the_schedules_flags_not_booleans():
    # Schedule.emitted (booleans, per channel) passed for Schedule.status would read as
    # limit flags and turn every played target-frame into "not checked".
    from rts_scenario.errors import CheckError
    tr = truth(5)
    with pytest.raises(CheckError, match=r"status: must be the schedule's Status flags .*"
                                         r"got bool of shape \(5, 2\)"):
        check("s", tr, np.ones((5, 2), dtype=bool), cycles_from(tr), EXPECT)
    with pytest.raises(CheckError, match=r"of shape \(5, 2\): frames x targets\), got uint16 "
                                         r"of shape \(5, 2, 4\)"):
        check("s", tr, np.zeros((5, 2, 4), dtype=np.uint16), cycles_from(tr), EXPECT)


def test_detections_the_radar_could_not_send_fail_the_run():
    # The simulated radar leaves out detections its protocol cannot carry (a range beyond the
    # DBC's); they were never seen by the checker, even if the rate still passes.
    tr = truth(20)
    bus = {"messages": 60, "unsendable_detections": 3}
    report = check("s", tr, OK(20, 2), cycles_from(tr), EXPECT, bus=bus)
    assert not report.passed
    assert any(r.startswith("3 detections the radar could not put on the bus")
               for r in report.reasons)
    assert check("s", tr, OK(20, 2), cycles_from(tr), EXPECT,
                 bus={"messages": 60, "unsendable_detections": 0}).passed


# -- cycles measured at a frame change (`rts_scenario.pipeline.CycleTruth`) ------------------

def _radar_run(scene, clock, window_s, lag_frames, radar_window_s=None, applied_delay_s=0.0,
               expected=(), range_offset_m=0.0):
    """Check a noise-free radar on ``clock`` that shows the frame ``lag_frames`` before the
    one the RTS holds when measured within ``radar_window_s`` (default: the checker's
    ``window_s``) after the change, the held frame otherwise; the RTS applies every frame
    ``applied_delay_s`` after its time, and the checker is told so. ``expected``: limits the
    scene declares besides its own; ``range_offset_m`` added to every reported range."""
    from dataclasses import replace

    from rts_scenario.kinematics import compute_tracks
    from rts_scenario.pipeline import CycleTruth

    radar_window_s = window_s if radar_window_s is None else radar_window_s
    expectations = replace(scene.expectations,
                           expected_limits=scene.expectations.expected_limits | set(expected))
    checker = Checker(scene.name, tuple(t.name for t in scene.targets), expectations)
    truths = CycleTruth(checker, scene, clock, window_s)
    frames = np.arange(scene.n_frames)
    status = np.zeros((scene.n_frames, len(scene.targets)), dtype=np.uint16)
    half = scene.n_frames // 2  # two batches: the window works across a batch's border
    applied = scene.t_s + applied_delay_s
    n = np.concatenate([truths.add(frames[:half], status[:half], applied[:half]),
                        truths.add(frames[half:], status[half:], applied[half:]),
                        truths.finish()])
    t = clock.time_of(n)
    held = np.maximum(np.searchsorted(applied, t + 1e-9, side="right") - 1, 0)
    near = t - applied[held] < radar_window_s
    shown = np.maximum(np.where(near, held - lag_frames, held), 0)
    seen = compute_tracks(scene, scene.t_s[shown], shown)
    checker.add_cycles(
        Detections(cycle=int(c), t_s=float(tc), range_m=seen.range_m[i] + range_offset_m,
                   radial_velocity_mps=seen.radial_velocity_mps[i], az_deg=seen.az_deg[i],
                   el_deg=seen.el_deg[i], rcs_dbsm=seen.rcs_dbsm[i],
                   snr_db=np.full(len(scene.targets), 30.0))
        for i, (c, tc) in enumerate(zip(n, t, strict=True)))
    checker.settle()
    return checker.report(), n.size


@pytest.fixture(scope="module")
def closing_scene():
    from pathlib import Path

    from rts_scenario.scenario import load_scenario
    root = Path(__file__).resolve().parents[1]
    # 3 s at 20 frames/s; the target closes fast enough that one frame's motion is beyond
    # the range tolerance (checked below: a radar one frame behind fails).
    return load_scenario(root / "scenarios" / "approaching_target.scenario.yaml",
                         {"duration_s": 3.0})


def test_a_cycle_measured_at_a_frame_change_may_show_the_frame_before(closing_scene):
    from rts_scenario.radar.clock import RadarClock

    # In step with the frames (every shipped profile): each cycle is measured exactly when
    # the next frame is due, and this radar always shows the frame before. The scene declares
    # that race known (the verdict rests on those cycles: see the test below).
    report, n = _radar_run(closing_scene, RadarClock(cycle_s=0.05), window_s=0.006,
                           lag_frames=1, expected=["adjacent_frame"])
    assert report.passed, report.reasons
    assert report.scene_limits["adjacent_frame"]["expected"]
    assert report.expected_not_hit == []
    assert report.frames["checked"] == report.frames["total"] == n == 60
    # Every cycle but the first (no frame before it) is measured at a change; all of those
    # matched the frame before, and the report says so.
    assert report.frames["ambiguous"] == 59 and report.frames["adjacent_frame"] == 59
    assert ("59 cycles measured within the ambiguity window of a frame change, 59 of them "
            "judged against the frame across it") in report.table()
    # Behind an interface stamping with its own clock, the window after each change is the
    # clocks' tie longer, and the line says so.
    report.radar_clock["early_s"] = 0.011
    assert ("59 cycles measured within the ambiguity window of a frame change (11 ms more "
            "after one: the interface's clock is tied to the host's within that), 59 of them "
            "judged against the frame across it") in report.table()


def test_a_verdict_resting_on_the_frame_across_each_change_fails_unless_declared(closing_scene):
    from rts_scenario.radar.clock import RadarClock

    # The target closes 0.4 m per frame (tolerance 0.3 m). A radar in step with the frames
    # that shows the frame held but reads every range 0.4 m long (a delay on the bench)
    # matches the frame before each change: judged against it, every cycle would pass.
    clock = RadarClock(cycle_s=0.05)
    travel = float(np.abs(np.diff(compute_tracks(closing_scene).range_m[:, 0])).max())
    assert 0.3 < travel < 0.45
    offset, _ = _radar_run(closing_scene, clock, window_s=0.006, lag_frames=0,
                           range_offset_m=travel)
    # Some cycles (the first, none across it) cannot be judged across: out of tolerance.
    assert offset.frames["adjacent_frame"] > 50
    assert not offset.passed
    [reason] = [r for r in offset.reasons if "adjacent_frame" in r.codes]
    assert "against the frames held alone, oncoming-car detection rate" in reason
    assert f"up to {travel:.2f} m here" in reason
    assert offset.scene_limits["adjacent_frame"] == {"why": reason.removeprefix(
        "adjacent_frame: "), "expected": False}
    # A radar that shows the frame before in every cycle is the same verdict: the run cannot
    # tell the two apart; declared, the scene passes.
    before, _ = _radar_run(closing_scene, clock, window_s=0.006, lag_frames=1)
    assert [r.codes for r in before.reasons] == [("adjacent_frame",)]
    # The same radar in step and without an offset: nothing rests on the frame across.
    right, _ = _radar_run(closing_scene, clock, window_s=0.006, lag_frames=0,
                          expected=["adjacent_frame"])
    assert right.passed and right.frames["adjacent_frame"] == 0
    assert right.expected_not_hit == ["adjacent_frame"]
    assert "adjacent_frame" not in right.scene_limits


def test_changes_a_standing_target_makes_do_not_hide_a_radar_a_frame_off(tmp_path):
    from rts_scenario.radar.clock import RadarClock

    # Standing 1.2 s, then closing at 8 m/s (from 1.8 s, 13.3 m/s2 between): at the changes
    # while it stands, the frame held passes whatever the radar showed. A radar always showing
    # the frame before (a delay of a frame on the bench looks the same) must not pass for
    # those: only the changes whose frames differ by more than a tolerance count towards the
    # rule.
    path = tmp_path / "stop_then_close.scenario.yaml"
    path.write_text(STOP_THEN_CLOSE)
    report, _ = _radar_run(load_scenario(path), RadarClock(cycle_s=0.05), window_s=0.006,
                           lag_frames=1)
    assert 25 < report.frames["adjacent_frame"] < report.frames["ambiguous"] - 20
    assert [r.codes for r in report.reasons] == [("adjacent_frame",)], report.reasons
    assert "against the frames held alone, oncoming-car detection rate" in report.reasons[0]


STOP_THEN_CLOSE = """\
rts_scenario: 1
name: stop-then-close
duration_s: 3.0
frame_rate_hz: 20.0
radar:
  profile: awr1843boost
  mount: {x_m: 3.7, z_m: 0.5}
rig: wide-3x5
ego:
  motion: {type: stationary, position_m: [0, 0, 0]}
targets:
  - name: oncoming-car
    kind: car
    motion:
      type: speed_profile
      position_m: [50.0, 0.0, 0.6]
      heading_deg: 180
      profile:
        - {t_s: 0.0, speed_mps: 0.0}
        - {t_s: 1.2, speed_mps: 0.0}
        - {t_s: 1.8, speed_mps: 8.0}
    rcs: {rcs_dbsm: 12.0}
expectations:
  tolerances: {range_m: 0.3, radial_velocity_mps: 0.3, az_deg: 0.5, el_deg: 1.0}
  detection_rate: 0.9
"""


def test_a_range_offset_beyond_tolerance_on_a_slow_target_fails_counting_what_it_rests_on(
        tmp_path):
    import re

    from rts_scenario.radar.clock import RadarClock

    # Closing at 4 m/s: 0.2 m a frame, less than the 0.3 m tolerance, so no change's frames
    # differ by more than it. A radar in step reading every range 0.32 m long (beyond the
    # tolerance) matches the frame before each change: judged against it, every cycle would
    # pass. The run failed, but its reason said "59 of the 0 measured at one whose frames
    # differ by more than a tolerance": the cycles that matched the frame across better now
    # count among those.
    path = tmp_path / "slow.scenario.yaml"
    path.write_text(STOP_THEN_CLOSE.replace("{t_s: 0.0, speed_mps: 0.0}",
                                            "{t_s: 0.0, speed_mps: 4.0}")
                    .replace("{t_s: 1.2, speed_mps: 0.0}", "{t_s: 1.2, speed_mps: 4.0}")
                    .replace("{t_s: 1.8, speed_mps: 8.0}", "{t_s: 1.8, speed_mps: 4.0}"))
    scene = load_scenario(path)
    travel = float(np.abs(np.diff(compute_tracks(scene).range_m[:, 0])).max())
    assert 0.15 < travel < 0.25
    report, _ = _radar_run(scene, RadarClock(cycle_s=0.05), window_s=0.006, lag_frames=0,
                           range_offset_m=0.32)
    assert not report.passed
    [reason] = [r for r in report.reasons if "adjacent_frame" in r.codes]
    across, counted = map(int, re.search(r"\((\d+) of the (\d+) measured", reason).groups())
    assert 0 < across <= counted and across >= 0.9 * counted
    assert "against the frames held alone, oncoming-car detection rate" in reason


def test_a_race_at_the_frame_changes_that_goes_both_ways_passes(closing_scene):
    from rts_scenario.radar.clock import RadarClock

    # A radar whose cycle drifts 0.1 ms a cycle past the changes, and that shows the frame
    # before only when measured within 1 ms of one: every cycle is measured within the 6 ms
    # window, some show the frame across. Against the frames held alone, more than 5 % of the
    # cycles would miss (the verdict rests on them), but the race went both ways: an offset of
    # one frame's travel would leave the others out of tolerance.
    report, n = _radar_run(closing_scene, RadarClock(cycle_s=0.0501), window_s=0.006,
                           lag_frames=1, radar_window_s=0.001)
    adjacent, ambiguous = report.frames["adjacent_frame"], report.frames["ambiguous"]
    assert adjacent > 0.05 * n and ambiguous > 2 * adjacent
    assert report.passed, report.reasons
    assert "adjacent_frame" not in report.scene_limits


def test_a_radar_two_frames_behind_fails(closing_scene):
    from rts_scenario.radar.clock import RadarClock

    report, n = _radar_run(closing_scene, RadarClock(cycle_s=0.05), window_s=0.006,
                           lag_frames=2)
    assert not report.passed
    # Only cycles 0 and 1 (nothing two frames before them) show a frame the checker accepts.
    assert report.detection_rate == pytest.approx(2 / n)
    assert any("detection rate" in r for r in report.reasons)


def test_a_radar_a_frame_behind_outside_the_window_fails(closing_scene):
    from rts_scenario.radar.clock import RadarClock

    # Measured 20 ms into each frame, far from any change: showing the frame before is an
    # error of the radar, not the bench's race.
    clock = RadarClock(cycle_s=0.05, start_offset_s=0.02)
    report, _ = _radar_run(closing_scene, clock, window_s=0.006, lag_frames=1,
                           radar_window_s=1.0)
    assert not report.passed and report.frames["ambiguous"] == 0
    assert report.detection_rate < 0.05
    right, _ = _radar_run(closing_scene, clock, window_s=0.006, lag_frames=0)
    assert right.passed, right.reasons


def test_frames_applied_late_are_found_by_their_send_times(closing_scene):
    from rts_scenario.radar.clock import RadarClock

    # Every frame reached the RTS 30 ms after its time (beyond the 6 ms window); a radar in
    # step with the frames saw the frame before at each cycle: right, by the send times.
    report, _ = _radar_run(closing_scene, RadarClock(cycle_s=0.05), window_s=0.006,
                           lag_frames=0, applied_delay_s=0.03)
    assert report.passed, report.reasons
    assert report.frames["adjacent_frame"] == 0


def test_a_limit_of_the_frame_held_counts_whatever_frame_across_the_change_is_tried():
    # A clipped echo (a limit that does not block the channel) is not checkable in its frame;
    # the frame before has the target checkable, and a radar reporting it matches that frame
    # too (slow motion). The limit must still count and fail the run, and the cycle must not
    # be judged against the frame before for it.
    from rts_scenario.schedule.model import Status

    tr = truth(20)
    status = OK(20, 2)
    status[10, 1] |= Status.ATTENUATION_CLIPPED
    before = np.maximum(np.arange(20) - 1, 0)
    checker = Checker("s", tr.names, EXPECT, counter_start=0)
    checker.add_truth(0, tr, status, other=(tr.take(before), status[before]),
                      ambiguous=np.arange(20) > 0)
    checker.add_cycles(cycles_from(tr))
    checker.settle()
    report = checker.report()
    assert not report.passed
    assert report.targets[1].limits == {"attenuation_clipped": 1}
    assert report.frames["adjacent_frame"] == 0
    assert report.target_frames["checkable"] == 39


@pytest.mark.parametrize("scene_first", [0, 3])
def test_cycles_measured_before_the_scene_are_counted_as_such_not_late_or_after_it(scene_first):
    # A radar measures before the scene's start (a real one runs before the stream starts):
    # those cycles are neither late (their frame was never settled) nor after the scene's end.
    tr = truth(10)
    checker = Checker("s", tr.names, EXPECT, counter_start=100)
    early = [Detections.empty(100 + scene_first - k, -0.05 * k, ()) for k in (3, 2, 1)]
    checker.add_cycles(early[:2])
    checker.add_truth(scene_first, tr, OK(10, 2))
    checker.add_frames(tr, OK(10, 2))
    checker.add_cycles(early[2:] + cycles_from(tr, first=100 + scene_first))
    checker.settle(before_frame=scene_first + 10)
    checker.add_cycles(cycles_from(truth(2, first=10), first=110 + scene_first))
    checker.settle()
    report = checker.report()
    assert report.frames["checked"] == 10 and report.passed, report.reasons
    assert (report.frames["before_scene"], report.frames["late"],
            report.frames["after_scene"]) == (3, 0, 2)
    assert "3 before the scene's start (not checked)" in report.table()


def test_a_detection_rate_failed_by_detections_off_tolerance_names_the_quantity():
    # Every detection is there, 0.5 m long (within the 3 x 0.3 m gate, beyond the 0.3 m
    # tolerance): the rate fails, and the reason says it was the range, by how much.
    tr = truth(10)
    checker = Checker("s", tr.names, EXPECT, counter_start=0)
    checker.add_truth(0, tr, OK(10, 2))
    checker.add_frames(tr, OK(10, 2))
    checker.add_cycles(cycles_from(tr, offset=0.5))
    checker.settle()
    reasons = checker.report().reasons
    assert reasons[:2] == [f"t{k}: detection rate 0.0% < 90.0% (10 target-cycles out of "
                           f"tolerance: range up to 0.5 m > 0.3 m)" for k in range(2)]
    # Missing detections are no quantity off: the reason says the rate alone.
    checker = Checker("s", tr.names, EXPECT, counter_start=0)
    checker.add_truth(0, tr, OK(10, 2))
    checker.add_frames(tr, OK(10, 2))
    checker.add_cycles(cycles_from(tr, drop={(f, 0) for f in range(10)}))
    checker.settle()
    assert checker.report().reasons[0] == "t0: detection rate 0.0% < 90.0%"


@pytest.mark.parametrize("foreign", [0, 2])
def test_cycles_numbered_before_the_scene_that_come_during_it_are_no_cycles_of_this_radar(
        foreign):
    # One radar's cycles before the scene come on the bus before its first cycle's time (the
    # anchor: cycle 0 at 1000 s, one every 50 ms). A second radar with the same identifiers,
    # counting elsewhere, puts cycles numbered before the scene on the bus during it: they
    # fail the verdict (foreign_cycles), not silently counted as before_scene.
    import dataclasses

    tr = truth(10)
    checker = Checker("s", tr.names, EXPECT, counter_start=100, cycle_s=0.05)
    checker.anchor(0, 1000.0)

    def on_bus(cycles, first_s):
        return [dataclasses.replace(c, bus_t_s=first_s + 0.05 * i) for i, c in enumerate(cycles)]

    early = on_bus([Detections.empty(100 - k, -0.05 * k, ()) for k in (3, 2, 1)], 999.85)
    scene = on_bus(cycles_from(tr, first=100), 1000.0)
    other = on_bus([Detections.empty(50 + k, None, ()) for k in range(foreign)], 1000.2)
    checker.add_truth(0, tr, OK(10, 2))
    checker.add_frames(tr, OK(10, 2))
    checker.add_cycles(early + scene[:5] + other + scene[5:])
    checker.settle()
    report = checker.report()
    assert report.frames["checked"] == 10
    assert report.frames["before_scene"] == 3 + foreign
    if not foreign:
        assert report.passed, report.reasons
        return
    assert not report.passed
    [reason] = report.reasons
    assert reason.codes == ("foreign_cycles",)
    assert reason.startswith("2 radar cycles numbered before the scene came on the bus 0.200 "
                             "to 0.250 s after its first cycle's time, later than their numbers "
                             "allow: not this radar's count")


def test_cycles_numbered_after_the_scene_that_come_during_it_are_no_cycles_of_this_radar():
    # A radar counting from 4242 where its profile says 0: every cycle it sent during the
    # scene is numbered far after it. They were counted nowhere (neither received nor
    # after_scene), and the verdict blamed missing cycles alone.
    import dataclasses

    tr = truth(10)
    checker = Checker("s", tr.names, EXPECT, counter_start=0, cycle_s=0.05)
    checker.anchor(0, 1000.0)
    checker.after_scene_end = 14  # the run counts 4 cycles after the scene's 10
    cycles = [dataclasses.replace(c, bus_t_s=1000.0 + 0.05 * i)
              for i, c in enumerate(cycles_from(tr, first=4242))]
    # The radar's own cycles after the window, measured after the scene: not the reason.
    late = [dataclasses.replace(Detections.empty(20 + k, None, ()), bus_t_s=1001.0 + 0.05 * k)
            for k in range(3)]
    checker.add_truth(0, tr, OK(10, 2))
    checker.add_frames(tr, OK(10, 2))
    checker.add_cycles(cycles + late)
    checker.settle()
    report = checker.report()
    assert report.frames["missing"] == 10 and report.frames["received"] == 0
    foreign = [r for r in report.reasons if "foreign_cycles" in r.codes]
    assert foreign == [
        "10 radar cycles numbered after the scene (cycle 4242 on, counted from the profile's "
        "counter_start 0) came on the bus 0.000 to 0.450 s after its first cycle's time, "
        "earlier than their numbers allow: not this radar's count (another radar with the same "
        "identifiers on the bus, or a count that does not start where the radar's profile "
        "says); not checked"]


@pytest.mark.parametrize("jitter_s, early_s, drift", [
    (0.3, 0.25, 0.0),   # within the profile's jitter
    (0.0, 0.0, 5e-4),   # a clock 500 ppm fast over 500 s
])
def test_a_radars_own_cycles_after_the_scene_are_not_taken_for_anothers(jitter_s, early_s,
                                                                        drift):
    # A radar whose latency jitters by 0.3 s, or whose clock runs fast, puts its own cycles
    # after the scene on the bus earlier than their numbers say, but after the scene's last:
    # not another radar's (foreign_cycles failed such a run).
    import dataclasses

    n = 10_000 if drift else 10
    tr = truth(n)
    checker = Checker("s", tr.names, EXPECT, counter_start=0, cycle_s=0.05, jitter_s=jitter_s)
    checker.anchor(0, 1000.0)
    checker.after_scene_end = n + 5
    cycles = [dataclasses.replace(c, bus_t_s=1000.0 + 0.05 * i * (1 - drift))
              for i, c in enumerate(cycles_from(tr))]
    after = [dataclasses.replace(Detections.empty(n + 5 + k, None, ()),
                                 bus_t_s=1000.0 + 0.05 * (n + 5 + k) * (1 - drift) - early_s)
             for k in range(5)]
    checker.add_truth(0, tr, OK(n, 2))
    checker.add_frames(tr, OK(n, 2))
    checker.add_cycles(cycles + after)
    checker.settle()
    report = checker.report()
    assert report.passed, report.reasons


def test_limits_a_scene_expects_but_never_hits_are_said(tmp_path):
    # The scene expects its car to leave the rig's coverage and the radar to be slower than
    # the frames, and the car to come too close: none of it happens in its 3 s. The run
    # passes (nothing unchecked), and says which expectations it did not meet.
    import yaml

    from rts_scenario.pipeline import Pipeline, RunOptions

    root = Path(__file__).resolve().parents[1]
    data = yaml.safe_load((root / "scenarios" / "approaching_target.scenario.yaml").read_text())
    data["duration_s"] = 3.0
    data["radar"]["noise"] = False
    data["expectations"]["expected_limits"] = ["out_of_coverage", "frame_rate_above_radar",
                                               "frames_lost"]
    data["targets"][0]["expected_limits"] = ["too_close"]
    (tmp_path / "s.scenario.yaml").write_text(yaml.safe_dump(data))
    scene = load_scenario(tmp_path / "s.scenario.yaml")
    with Pipeline.for_scene(scene, RunOptions()) as pipeline:
        report = pipeline.run(scene).report
    assert report.passed, report.reasons
    assert report.expected_not_hit == ["frame_rate_above_radar", "out_of_coverage",
                                       "oncoming-car: too_close"]
    assert ("expected limits not hit: frame_rate_above_radar; out_of_coverage; "
            "oncoming-car: too_close") in report.table()
    assert report.to_dict()["expected_not_hit"] == report.expected_not_hit


def test_playback_limits_a_scene_expects_but_never_hits_are_said(tmp_path):
    # frames_sent_late and frames_lost are judged from the playback, not by the checker: a
    # scene that expects them is told when they did not happen, as for the other limits.
    # The in-process radar output applies every frame at its time (none late) and reports
    # no RTS counters: whether frames were lost is not told, so it is not said.
    import yaml

    from rts_scenario.pipeline import Pipeline, RunOptions

    root = Path(__file__).resolve().parents[1]
    data = yaml.safe_load((root / "scenarios" / "approaching_target.scenario.yaml").read_text())
    data["duration_s"] = 1.0
    data["radar"]["noise"] = False
    data["expectations"]["expected_limits"] = ["out_of_coverage", "frames_sent_late",
                                               "frames_lost"]
    (tmp_path / "s.scenario.yaml").write_text(yaml.safe_dump(data))
    scene = load_scenario(tmp_path / "s.scenario.yaml")
    with Pipeline.for_scene(scene, RunOptions()) as pipeline:
        report = pipeline.run(scene).report
    assert report.passed, report.reasons
    assert report.playback["late_frames"] == 0 and report.playback["rts"] is None
    assert report.expected_not_hit == ["frames_sent_late", "out_of_coverage"]
    assert "expected limits not hit: frames_sent_late; out_of_coverage" in report.table()


@pytest.mark.parametrize("late, rts, not_hit", [
    (0, None, ["frames_sent_late"]),
    (2, None, []),
    (0, {"lost_frames": 0, "unsynced_frames": 0, "malformed": 0}, ["frames_lost",
                                                                   "frames_sent_late"]),
    (0, {"lost_frames": 0, "unsynced_frames": 1}, ["frames_sent_late"]),
    (0, {"lost_frames": 3, "unsynced_frames": 0}, ["frames_sent_late"]),
])
def test_playback_limits_not_hit_follow_the_playback(late, rts, not_hit):
    from rts_scenario.playback import playback_not_hit

    playback = {"frames_sent": 10, "late_frames": late, "rts": rts}
    assert playback_not_hit(playback, {"frames_sent_late", "frames_lost"}) == not_hit
    # Only what the scene expects is said.
    assert playback_not_hit(playback, set()) == []


@pytest.mark.parametrize("late, rts, gone, hit", [
    (0, None, None, set()),
    (2, None, None, {"frames_sent_late"}),
    (0, {"lost_frames": 3, "unsynced_frames": 0}, None, {"frames_lost"}),
    # Datagrams back undelivered: no RTS played them, no limit of one (rts_unreachable).
    (0, None, {"address": "udp://192.0.2.1:5005", "datagrams": 4, "error": "No route to host",
               "first_s": 0.0, "last_s": 0.2}, set()),
    (1, {"lost_frames": 0, "unsynced_frames": 1}, None, {"frames_sent_late", "frames_lost"}),
])
def test_the_playback_s_limits_hit_join_the_scene_limits(late, rts, gone, hit):
    # A run failed with frames_lost while its JSON's scene_limits, "limits the whole scene
    # hits", listed none of them.
    from rts_scenario.playback import playback_limits
    from rts_scenario.report import Report

    playback = {"frames_sent": 10, "late_frames": late, "rts": rts, "rts_unreachable": gone,
                "lateness_s": {"max": 0.2}, "late_after_s": 0.05}
    limits = playback_limits(playback)
    assert set(limits) == hit
    if "frames_sent_late" in hit:
        assert limits["frames_sent_late"].startswith(f"{late} of 10 frames went out more than")
    report = Report(scene="s", passed=False, reasons=[], frames={}, targets=[], errors={},
                    detection_rate=1.0, false_detections=0, false_detections_per_frame=0.0,
                    bus={})
    report.add_playback_limits(limits, {"frames_lost"})
    assert report.scene_limits == {name: {"why": limits[name],
                                          "expected": name == "frames_lost"} for name in hit}


def test_a_scene_wide_limit_is_said_not_hit_only_where_scene_limits_were_judged():
    from rts_scenario.check import Checker

    # check_cycles judges no scene-wide limits: it cannot tell that the radar kept up.
    expect = Expectations(expected_limits=frozenset({"frame_rate_above_radar",
                                                     "motion_staircase"}))
    assert Checker("s", ("a",), expect).report().expected_not_hit == []
    judged = Checker("s", ("a",), expect, scene_limits={})
    assert judged.report().expected_not_hit == ["frame_rate_above_radar", "motion_staircase"]


# -- echoes beyond the radar's unambiguous range or velocity: where the radar folds them --------

V_MAX, R_MAX = 10.0, 75.0


def beyond(velocity_mps, range_m=40.0, frames=20):
    """A target at ``velocity_mps`` and ``range_m``, and a checkable one at 20 m, 3 m/s, az
    -2 deg, before a radar that folds beyond 10 m/s and 75 m (its unambiguous limits)."""
    shape = (frames, 2)
    ones = np.ones(shape, dtype=bool)
    range_m = np.broadcast_to([range_m, 20.0], shape)
    velocity = np.broadcast_to([velocity_mps, 3.0], shape)
    return Tracks(names=("fast", "steady"), t_s=np.arange(frames) * 0.05, range_m=range_m,
                  radial_velocity_mps=velocity, doppler_hz=np.zeros(shape),
                  rcs_dbsm=np.full(shape, 10.0), az_deg=np.broadcast_to([2.0, -2.0], shape),
                  el_deg=np.ones(shape), position_m=np.zeros((*shape, 3)), present=ones,
                  in_coverage=ones, in_range=range_m < R_MAX, in_velocity=abs(velocity) < V_MAX,
                  max_range_m=R_MAX, max_radial_velocity_mps=V_MAX)


def reported(tracks, range_m, velocity_mps, angles):
    """Each cycle: the steady target's detection, and one per (az, el) in ``angles`` at
    ``range_m``, ``velocity_mps``."""
    az, el = np.array([(-2.0, 1.0), *angles], dtype=float).T
    n = az.size
    return [Detections(cycle=f, t_s=float(t), range_m=np.array([20.0] + [range_m] * (n - 1)),
                       radial_velocity_mps=np.array([3.0] + [velocity_mps] * (n - 1)),
                       az_deg=az, el_deg=el, rcs_dbsm=np.full(n, 10.0), snr_db=np.full(n, 30.0))
            for f, t in enumerate(tracks.t_s)]


@pytest.mark.parametrize("velocity, folded", [(12.0, -8.0), (-12.0, 8.0), (31.0, -9.0),
                                              (5.0, 5.0)])
def test_tracks_fold_the_radial_velocity_into_the_radar_s_unambiguous_interval(velocity, folded):
    assert beyond(velocity).folded()[1][0, 0] == pytest.approx(folded)


def test_tracks_fold_the_range_into_the_radar_s_unambiguous_range():
    assert beyond(5.0, range_m=80.0).folded()[0][0, 0] == pytest.approx(5.0)
    assert beyond(5.0, range_m=40.0).folded()[0][0, 0] == pytest.approx(40.0)


EDGE_SCENE = """rts_scenario: 1
name: edge
duration_s: 0.5
frame_rate_hz: 10.0
radar: {profile: awr1843boost, fidelity: analytic, noise: false}
rig: wide-3x5
ego: {motion: {type: stationary, position_m: [0, 0, 0]}}
targets:
  - name: edge
    motion: {type: constant_velocity, position_m: [RANGE, 0.0, 0.0], heading_deg: 0,
             speed_mps: SPEED}
    rcs: {rcs_dbsm: 25.0}
  - name: near
    motion: {type: stationary, position_m: [30.0, 2.0, 0.0]}
    rcs: {rcs_dbsm: 10.0}
expectations: {expected_limits: [beyond_radar_range]}
"""


@pytest.mark.parametrize("speed", [10.0, -10.0])
def test_the_range_folds_where_the_beat_frequency_reaches_the_sample_rate(tmp_path, speed):
    # An up-chirp's beat frequency is 2 S R / c + 2 v / lambda (v > 0 receding): the range
    # FFT folds where it reaches the sample rate, R = (fs - 2 v / lambda) c / (2 S), 19 mm
    # short of fs c / (2 S) for a target receding at 10 m/s (beyond it, approaching). A target
    # between the two was taken as checkable: its detection near 0 m counted as false, and the
    # target as missed.
    from rts_scenario.kinematics import compute_tracks
    from rts_scenario.pipeline import RunOptions, run_scene

    c0 = 299_792_458.0
    scene_file = tmp_path / "edge.scenario.yaml"

    def tracks_at(range_m):
        scene_file.write_text(EDGE_SCENE.replace("RANGE", repr(float(range_m)))
                              .replace("SPEED", repr(speed)))
        scene = load_scenario(scene_file)
        p = scene.radar
        fold_m = (p.sample_rate_hz - 2.0 * speed / p.wavelength_m) * c0 / (2.0 * p.slope_hz_per_s)
        return scene, compute_tracks(scene), fold_m

    _, probe, fold_m = tracks_at(70.0)
    offset = probe.range_m[0, 0] - 70.0  # the radar's mount: range less the position's x
    plain_m = 74.948  # fs c / (2 S) of the awr1843boost profile
    assert abs(fold_m - plain_m) == pytest.approx(0.0193, abs=3e-4)
    # The first frame (t = 0) at 2 mm either side of the fold.
    for range_m, inside in ((fold_m - 0.002, True), (fold_m + 0.002, False)):
        scene, tracks, _ = tracks_at(range_m - offset)
        assert tracks.range_m[0, 0] == pytest.approx(range_m, abs=1e-9)
        assert bool(tracks.in_range[0, 0]) is inside, (range_m, fold_m)
    # Receding between the fold and fs c / (2 S): not checkable, and its detection, folded to
    # near 0 m, is the folded echo's, not a false one.
    if speed > 0:
        scene, tracks, _ = tracks_at(fold_m + 0.001 - offset)
        assert not tracks.in_range[:, 0].any() and tracks.range_m[0, 0] < plain_m
        report = run_scene(scene, RunOptions()).report
        assert report.passed, report.reasons
        assert report.false_detections == 0 and report.folded_detections > 0


def test_detections_of_an_echo_folded_in_velocity_are_not_false():
    # 12 m/s beyond a radar's 10: it shows at -8 m/s, at two wrong angles (its TDM-MIMO
    # compensation used the folded Doppler). Expected, the run passes; its detections are the
    # folded echo's, none false.
    tracks = beyond(12.0)
    expect = dataclasses.replace(EXPECT, expected_limits=frozenset({"beyond_radar_velocity"}),
                                 max_false_detections_per_frame=0.0)
    report = check("s", tracks, OK(20, 2), reported(tracks, 40.0, -8.0, [(90, -90), (90, 90)]),
                   expect)
    assert report.passed, report.reasons
    assert report.false_detections == 0 and report.folded_detections == 40
    assert "folded detections (echoes beyond the radar's unambiguous range or velocity, not " \
           "false): 40" in report.table()
    # Not expected: the limit fails the run, and the detections are still no false alarms.
    report = check("s", tracks, OK(20, 2), reported(tracks, 40.0, -8.0, [(2, 1)]),
                   dataclasses.replace(EXPECT, max_false_detections_per_frame=0.0))
    assert not report.passed and report.false_detections == 0
    assert any("beyond_radar_velocity 20" in r for r in report.reasons), report.reasons
    # Elsewhere in velocity (or range), or of an echo the RTS did not play: false.
    unplayed = OK(20, 2)
    unplayed[:, 0] = Status.NO_ECHO_SLOT
    for det, status in (((40.0, 5.0), OK(20, 2)), ((42.0, -8.0), OK(20, 2)),
                        ((40.0, -8.0), unplayed)):
        report = check("s", tracks, status, reported(tracks, *det, [(2, 1)]), expect)
        assert report.false_detections == 20 and report.folded_detections == 0, det
        assert not report.passed
    # A radar that resolves the ambiguity reports the true velocity: not false either.
    report = check("s", tracks, OK(20, 2), reported(tracks, 40.0, 12.0, [(2, 1)]), expect)
    assert report.false_detections == 0 and report.passed, report.reasons


def test_an_echo_folded_in_range_only_is_looked_for_at_its_angles():
    # 80 m beyond a radar's 75 m, at 5 m/s: it shows at 5 m, and its angles are right.
    tracks = beyond(5.0, range_m=80.0)
    expect = dataclasses.replace(EXPECT, expected_limits=frozenset({"beyond_radar_range"}),
                                 max_false_detections_per_frame=0.0)
    report = check("s", tracks, OK(20, 2), reported(tracks, 5.0, 5.0, [(2, 1)]), expect)
    assert report.passed and report.folded_detections == 20, report.reasons
    report = check("s", tracks, OK(20, 2), reported(tracks, 5.0, 5.0, [(12, 1)]), expect)
    assert report.false_detections == 20 and not report.passed


def test_a_folded_echo_never_takes_a_checkable_target_s_detection():
    # An echo at 20 m and 23 m/s folds onto the steady target (20 m, 3 m/s). The one
    # detection there is the steady target's, and it is detected.
    tracks = beyond(23.0, range_m=20.0)
    assert tracks.folded()[1][0, 0] == pytest.approx(3.0)
    expect = dataclasses.replace(EXPECT, expected_limits=frozenset({"beyond_radar_velocity"}),
                                 max_false_detections_per_frame=0.0)
    report = check("s", tracks, OK(20, 2), reported(tracks, 20.0, 3.0, []), expect)
    assert report.passed, report.reasons
    assert report.targets[1].detected_frames == 20 and report.folded_detections == 0


def test_every_detection_of_an_echo_played_off_its_angle_is_its_own():
    # The RTS's steps played the target at 40 m, 5 m/s off its angle (ANGLE_QUANTIZED, not
    # checkable): the radar reports it twice, 6 deg apart, both away from the set angle. Both
    # are the echo's, no false alarm; elsewhere in range they are false.
    tracks = beyond(5.0)
    status = OK(20, 2)
    status[:, 0] = Status.ANGLE_QUANTIZED
    expect = dataclasses.replace(EXPECT, expected_limits=frozenset({"angle_quantized"}),
                                 max_false_detections_per_frame=0.0)
    report = check("s", tracks, status, reported(tracks, 40.0, 5.0, [(5, 1), (-1, 1)]), expect)
    assert report.passed, report.reasons
    assert report.false_detections == 0 and report.targets[0].limits == {"angle_quantized": 20}
    report = check("s", tracks, status, reported(tracks, 43.0, 5.0, [(5, 1), (-1, 1)]), expect)
    assert report.false_detections == 40 and not report.passed


def test_a_fail_reason_is_its_sentence_with_codes():
    """Reasons read, print and serialize as the sentences they are; their codes survive a copy
    and a pickle (a report crossing to another process); a plain sentence's code is other."""
    import copy
    import json
    import pickle

    from rts_scenario.report import FailReason, reason_codes

    reason = FailReason("car: target-frames ...: too_close 3, split 1", "too_close", "split")
    assert reason == "car: target-frames ...: too_close 3, split 1"
    assert json.dumps([reason]) == json.dumps([str(reason)])
    for copied in (copy.deepcopy(reason), pickle.loads(pickle.dumps(reason))):
        assert copied == reason and copied.codes == ("too_close", "split")
    assert reason_codes([reason, FailReason("x", "split"), FailReason("y", "bus_silent"),
                         "an uncoded sentence"]) == ["too_close", "split", "bus_silent", "other"]
