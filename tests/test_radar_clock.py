"""The radar on its own clock: cycles, counters, the RTS's hold, time-aligned checking."""

import dataclasses
import json
import re
import shutil
import textwrap
from pathlib import Path

import numpy as np
import pytest
import yaml

from rts_scenario.detections import Detections
from rts_scenario.errors import RtsError
from rts_scenario.kinematics import compute_tracks
from rts_scenario.pipeline import Pipeline, RunOptions
from rts_scenario.radar.clock import RadarClock
from rts_scenario.radar.profile import RadarProfile
from rts_scenario.recheck import check_log
from rts_scenario.scenario import load_scenario
from rts_scenario.schedule import held_frames

ROOT = Path(__file__).resolve().parents[1]
AWR = ROOT / "rts_scenario" / "data" / "radars" / "awr1843boost.radar.yaml"


def test_cycles_and_their_times():
    clock = RadarClock(cycle_s=0.072, start_offset_s=0.013, counter_start=4242)
    n, t = clock.cycles_between(0.0, 1.0)
    # 0.013 + 13 * 0.072 = 0.949 < 1 <= 0.013 + 14 * 0.072
    np.testing.assert_array_equal(n, np.arange(14))
    np.testing.assert_allclose(t, 0.013 + 0.072 * np.arange(14))
    np.testing.assert_array_equal(clock.counter_of(n)[:2], [4242, 4243])
    # Consecutive spans share no cycle and lose none.
    a, _ = clock.cycles_between(0.0, 0.5)
    b, _ = clock.cycles_between(0.5, 1.0)
    np.testing.assert_array_equal(np.concatenate([a, b]), n)


def test_a_cycle_at_a_frame_s_time_sees_that_frame():
    frames = np.arange(5) * 0.05
    got = held_frames(frames, np.array([-0.01, 0.0, 0.049, 0.05, 0.05 * 3, 0.3]))
    np.testing.assert_array_equal(got, [-1, 0, 0, 1, 3, 4])
    # Float round-off of equal times does not slip a frame.
    assert held_frames(np.arange(100) / 20.0, np.array([0.1 * 3]))[0] == 6


@pytest.mark.parametrize(("field", "value", "message"), [
    ("cycle_s", 0.0, "cycle_s"), ("latency_s", -1.0, "latency_s"),
    ("counter_start", -3, "counter_start")])
def test_bad_clock_values_are_refused(field, value, message):
    with pytest.raises(ValueError, match=message):
        RadarClock(**{"cycle_s": 0.05, field: value})
    with pytest.raises(ValueError, match="jitter_s"):
        RadarClock(cycle_s=0.05, latency_s=0.01, jitter_s=0.02)


def write_radar(folder: Path, **clock) -> str:
    data = yaml.safe_load(AWR.read_text())
    data["name"] = "own-clock"
    data["clock"] = clock
    (folder / "radars").mkdir(exist_ok=True)
    (folder / "radars" / "own.radar.yaml").write_text(yaml.safe_dump(data))
    return "radars/own.radar.yaml"


def test_profile_clock_key_and_its_located_errors(tmp_path):
    profile = RadarProfile.from_file(tmp_path / write_radar(tmp_path, cycle_s=0.072,
                                                             latency_s=0.13, counter_start=4242))
    assert profile.radar_clock == RadarClock(cycle_s=0.072, latency_s=0.13, counter_start=4242)
    assert RadarProfile.preset("awr1843boost").radar_clock.cycle_s == 0.05  # frame_period_s
    bad = tmp_path / write_radar(tmp_path, cycle_s=0.05, latency_s=0.01, jitter_s=0.5)
    with pytest.raises(RtsError, match=r"own.radar.yaml:\d+:\d+: clock.jitter_s"):
        RadarProfile.from_file(bad)


@pytest.mark.parametrize(("value", "shown"), [("sometimes", "'sometimes'"), (1.5, "1.5"),
                                            ([0], "[0]")])
def test_a_bad_counter_start_names_what_is_allowed(tmp_path, value, shown):
    bad = tmp_path / write_radar(tmp_path, cycle_s=0.05, counter_start=value)
    with pytest.raises(RtsError, match=r"own.radar.yaml:\d+:\d+: clock.counter_start: got "
                                       + re.escape(shown) + r"; allowed: an integer >= 0 or "
                                       r"'auto'$"):
        RadarProfile.from_file(bad)
    negative = tmp_path / write_radar(tmp_path, cycle_s=0.05, counter_start=-3)
    with pytest.raises(RtsError, match=r"clock.counter_start: must be >= 0, got -3$"):
        RadarProfile.from_file(negative)


def scene_with_clock(tmp_path, **clock):
    shutil.copy(ROOT / "scenarios" / "cut_in.scenario.yaml", tmp_path / "cut_in.scenario.yaml")
    for sub in ("rigs",):
        if (ROOT / "scenarios" / sub).exists():
            shutil.copytree(ROOT / "scenarios" / sub, tmp_path / sub, dirs_exist_ok=True)
    radar = write_radar(tmp_path, **clock)
    # The RTS plays 20 frames/s, the radar measures fewer: the scene says it expects that.
    return load_scenario(tmp_path / "cut_in.scenario.yaml",
                         {"radar.profile": radar, "radar.noise": False,
                          "radar.fidelity": "analytic",
                          "expectations.expected_limits": ["frame_rate_above_radar"]})


def rechecked_alike(scene, log, report):
    """The log's re-check by its sidecar passes and counts the cycles as the run did."""
    again = check_log(scene, log).report
    assert again.passed, again.reasons
    assert again.frames == report.frames
    return again


def run(scene, tamper=None):
    with Pipeline.for_scene(scene, RunOptions()) as pipeline:
        if tamper is not None:
            sink = pipeline.output._sink
            pipeline.output._sink = lambda cycles: [tamper(c, sink) for c in cycles]
        return pipeline.run(scene).report


def test_a_radar_on_its_own_clock_is_checked_at_its_measurement_times(tmp_path):
    scene = scene_with_clock(tmp_path, cycle_s=0.072, start_offset_s=0.013, latency_s=0.13,
                             counter_start=4242)
    seen: list[Detections] = []

    def keep(cycle, sink):
        seen.append(cycle)
        sink([cycle])

    report = run(scene, keep)
    assert report.passed, report.reasons
    n = int(np.ceil((scene.duration_s - 0.013) / 0.072))
    assert report.frames["total"] == report.frames["checked"] == n
    assert [c.cycle for c in seen] == list(range(4242, 4242 + n))
    t = np.array([c.t_s for c in seen])
    np.testing.assert_allclose(t, 0.013 + 0.072 * np.arange(n), atol=1e-12)
    # Each cycle measured the frame the RTS held: the range the scene had at that frame's
    # time (20 Hz frames), not at the measurement time.
    held_t = np.floor(t * scene.frame_rate_hz + 1e-9) / scene.frame_rate_hz
    truth = compute_tracks(scene, held_t)
    got = np.array([c.range_m[0] for c in seen])
    np.testing.assert_allclose(got, truth.range_m[:, 0], atol=0.02)
    # ... which differs from the truth at the measurement time by the hold (the scene's motion
    # while the RTS held the frame). The checker judges the radar on what was played: its
    # errors are those against the held frames, not the hold.
    moved = np.abs(compute_tracks(scene, t).range_m[:, 0] - truth.range_m[:, 0])
    assert moved.max() > 0.05
    # (the bus carries range in 5 mm steps: up to 2.5 mm more)
    assert report.errors["range_m"].max == pytest.approx(
        np.max(np.abs(got - truth.range_m[:, 0])), abs=0.0026)
    assert report.errors["range_m"].max < 0.01 < moved.max()


def test_a_radar_slower_than_the_frames_re_checks_to_its_live_counts(tmp_path):
    # 56 cycles of 72 ms over 80 frames of 50 ms: the re-check by the sidecar numbers the
    # run's cycles and finds the frame each one held among all 80, as live.
    scene = scene_with_clock(tmp_path, cycle_s=0.072, latency_s=0.13, counter_start=4242)
    scene = load_scenario(tmp_path / "cut_in.scenario.yaml",
                          {"radar.profile": "radars/own.radar.yaml", "radar.noise": False,
                           "radar.fidelity": "analytic", "duration_s": 4.0,
                           "expectations.expected_limits": ["frame_rate_above_radar"]})
    log = tmp_path / "slow.blf"
    with Pipeline.for_scene(scene, RunOptions(bus_log=str(log))) as pipeline:
        live = pipeline.run(scene).report
    again = check_log(scene, log).report
    assert live.frames["total"] == 56 and live.passed, live.reasons
    assert again.frames == live.frames
    assert again.errors["range_m"].max == pytest.approx(live.errors["range_m"].max)


@pytest.mark.parametrize(("fault", "reason"), [
    ("drop_target", "detection rate"), ("az_bias", "detection rate"),
    ("lose_cycles", "missing")])
def test_faults_of_a_radar_on_its_own_clock_fail_with_their_reason(tmp_path, fault, reason):
    scene = scene_with_clock(tmp_path, cycle_s=0.072, latency_s=0.13, counter_start=4242)
    rng = np.random.default_rng(3)

    def tamper(cycle, sink):
        if fault == "lose_cycles" and rng.random() < 0.3:
            return
        if fault == "drop_target":
            cycle = Detections.empty(cycle.cycle, cycle.t_s)
        if fault == "az_bias" and cycle.az_deg is not None:
            cycle = Detections(cycle=cycle.cycle, t_s=cycle.t_s, range_m=cycle.range_m,
                               radial_velocity_mps=cycle.radial_velocity_mps,
                               az_deg=cycle.az_deg + 1.0, el_deg=cycle.el_deg,
                               snr_db=cycle.snr_db, rcs_dbsm=cycle.rcs_dbsm)
        sink([cycle])

    report = run(scene, tamper)
    assert not report.passed
    assert any(reason in r for r in report.reasons), report.reasons
    if fault == "lose_cycles":
        assert 0.2 < report.frames["missing"] / report.frames["total"] < 0.4


def test_the_cycle_fit_recovers_a_crystal_off_by_1000_ppm_through_jitter():
    from rts_scenario.radar.clock import CycleTimeFit

    rng = np.random.default_rng(1)
    n = np.arange(3600)
    # Epoch timestamps, 130 ms latency, +-4 ms jitter, a 50.05 ms cycle; fed in batches.
    bus_t = 1.7e9 + 0.13 + 0.05005 * n + rng.uniform(-0.004, 0.004, n.size)
    fit = CycleTimeFit()
    for a in range(0, n.size, 500):
        fit.add(n[a:a + 500], bus_t[a:a + 500])
    cycle, error = fit.cycle_s()
    assert cycle == pytest.approx(0.05005, abs=3 * error) and error < 1e-7
    # By cycle 3599 the radar measured 3599 x 0.05 ms = 180 ms later than 50 ms cycles say.
    drift, sigma3 = fit.drift_s(0.05)
    assert drift == pytest.approx(3599 * 0.00005, abs=sigma3) and sigma3 < 1e-3
    advised = fit.drift_reason(0.05, 0.003).split("set clock.cycle_s: ")[1].split()[0]
    assert float(advised) == pytest.approx(0.05005, abs=3 * error)
    assert fit.drift_reason(0.05005, 0.003) is None


def test_a_radar_1_ppm_off_over_an_hour_is_told_the_cycle_to_set():
    from rts_scenario.radar.clock import CycleTimeFit

    # 72,000 cycles of 50.00005 ms: the last 3.6 ms late, beyond 2.88 ms. The advice must
    # differ from the profile's 0.05 (six digits gave 0.05 back).
    n = np.arange(72_000)
    fit = CycleTimeFit()
    fit.add(n, 1.7e9 + 0.05000005 * n + np.random.default_rng(0).uniform(-1e-3, 1e-3, n.size))
    reason = fit.drift_reason(0.05, 0.00288)
    assert "every 50.000050 ms, its profile says 50.000000 ms (+1.0 ppm)" in reason
    assert "set clock.cycle_s: 0.0500000" in reason
    advised = float(reason.split("set clock.cycle_s: ")[1].split()[0])
    # (the fit's standard error: 0.58 ms of jitter over 72,000 cycles, 1e-10 s)
    assert advised == pytest.approx(0.05000005, abs=5e-10)
    assert fit.drift_reason(advised, 0.00288) is None


def test_bus_times_number_a_gap_an_8_bit_counter_cannot():
    from rts_scenario.detections import sequential_numbers

    rng = np.random.default_rng(4)
    n = np.concatenate([np.arange(100), np.arange(250, 600), np.arange(727, 800)])
    # Latency jitter of +-4 ms at both ends of each gap, a crystal 1000 ppm fast.
    bus_t = 1.7e9 + 0.04995 * n + rng.uniform(-0.004, 0.004, n.size)
    by_time = sequential_numbers(n % 256, 256, bus_t, 0.05)
    np.testing.assert_array_equal(by_time, n)
    # Without the times, a gap of 151 reads as 105 back (the one of 128 stays 128).
    by_counter = sequential_numbers(n % 256, 256)
    assert by_counter[100] == 99 - 105 and by_counter[450] - by_counter[449] == 128
    # A time that matches no step the counter allows (stamps 140 cycles apart, counters 60)
    # is not a gap the counter hid: the counter's step stands.
    stamps = 1.7e9 + 0.05 * np.array([0, 1, 141, 142])
    np.testing.assert_array_equal(sequential_numbers(np.array([0, 1, 61, 62]), 256, stamps,
                                                     0.05), [0, 1, 61, 62])


def test_cycles_numbered_off_their_bus_times_tell_no_cycle():
    from rts_scenario.radar.clock import CycleTimeFit

    # 50 ms cycles, +-4 ms jitter; a 150-cycle gap an 8-bit counter reads as 106 back, so the
    # cycles after it are numbered 256 short: the bus times show no steady cycle to advise.
    rng = np.random.default_rng(2)
    n = np.concatenate([np.arange(100), np.arange(250, 600)])
    bus_t = 0.05 * n + rng.uniform(-0.004, 0.004, n.size)
    fit = CycleTimeFit()
    fit.add(np.where(n < 250, n, n - 256), bus_t)
    assert fit.cycle_s() is None and fit.drift_reason(0.05, 0.003) is None
    # Numbered right, the same times give the cycle.
    fit = CycleTimeFit()
    fit.add(n, bus_t)
    assert fit.cycle_s()[0] == pytest.approx(0.05, abs=1e-5)


@pytest.mark.parametrize(("cycle_s", "ppm"), [(0.05, 0.0), (0.0500005, 10.0), (0.050025, 500.0),
                                            (0.0501, 2000.0)])
def test_a_run_follows_a_radar_whose_crystal_runs_off_its_profile(tmp_path, cycle_s, ppm):
    # 500 ppm: cycle 239 is measured 6 ms later than the profile's 50 ms cycles put it, beyond
    # half the 5.76 ms window in which the check takes either frame (those cycles were judged
    # against the wrong frame); the run takes the cycle from the bus. 2000 ppm is no crystal:
    # the profile is another radar's, and the run fails saying so (the cycles judged right).
    scene = load_scenario(ROOT / "scenarios" / "cut_in.scenario.yaml",
                          {"radar.noise": False, "radar.fidelity": "analytic",
                           "radar.estimator": "bartlett"})
    profile = scene.radar.radar_clock
    log = tmp_path / "drift.blf"
    with Pipeline.for_scene(scene, RunOptions(bus_log=str(log))) as pipeline:
        pipeline.output.clock = dataclasses.replace(profile, cycle_s=cycle_s)
        report = pipeline.run(scene).report
    clock = report.radar_clock
    assert clock["bus_cycle_s"] == pytest.approx(cycle_s, rel=1e-9)
    assert clock["cycle_s"] == (profile.cycle_s if ppm == 0 else pytest.approx(cycle_s,
                                                                                 rel=1e-9))
    assert clock["cycle_from"] == ("profile" if ppm == 0 else "bus")
    assert clock["start_offset_s"] == profile.start_offset_s
    assert clock["start_from"] == "profile"  # the profile gives the counter: started with it
    assert report.frames["checked"] == report.frames["total"] == 240
    drifted = [r for r in report.reasons if r.startswith("radar_clock:")]
    assert report.reasons == drifted
    assert report.passed == (ppm < 1000)
    if ppm > 1000:
        assert f"every 50.100000 ms, its profile says 50.000000 ms (+{ppm:.1f} ppm)" in drifted[0]
        assert "set clock.cycle_s: 0.0501 " in drifted[0]
    # A re-check of the log judges the cycles at the cycle the run followed, to the same verdict.
    again = check_log(scene, log)
    assert again.report.reasons == report.reasons
    assert again.report.frames["checked"] == again.report.frames["total"] == 240
    assert again.alignment.cycle_s == pytest.approx(cycle_s, rel=1e-9)
    assert again.report.errors["range_m"].max == pytest.approx(report.errors["range_m"].max)
    # Its report says which clock it judged by: the run's, from the sidecar.
    rechecked = again.report.radar_clock
    assert rechecked["source"] == "sidecar"
    assert rechecked["counter_start"] == clock["counter_start"]
    assert rechecked["cycle_s"] == pytest.approx(clock["cycle_s"], rel=1e-12)
    assert rechecked["bus_cycle_s"] == pytest.approx(cycle_s, rel=1e-9)


@pytest.mark.parametrize("seed", range(4))
def test_a_radar_of_another_cycle_is_told_through_more_jitter_than_its_profile_says(
        tmp_path, seed):
    # The profile says 50 ms cycles and no jitter; the radar measures every 60 ms and its
    # messages wobble by +-4 ms on the bus (2.3 ms rms): 25 cycles over a 1.5 s scene, too few
    # for the lack-of-fit test on segments of one cycle each. Whatever the jitter draws, the
    # run names the profile's cycle as not the radar's and judges the cycles at its own,
    # live and re-checked.
    scene = scene_with_clock(tmp_path, cycle_s=0.05, latency_s=0.13, counter_start=4242)
    scene = load_scenario(tmp_path / "cut_in.scenario.yaml",
                          {"radar.profile": "radars/own.radar.yaml", "radar.noise": False,
                           "radar.fidelity": "analytic", "duration_s": 1.5,
                           "targets.0.lane_changes.0.start_s": 0.375,
                           "expectations.expected_limits": ["frame_rate_above_radar"]})
    rng = np.random.default_rng(seed)
    log = tmp_path / "other.blf"
    radar = dataclasses.replace(scene.radar.radar_clock, cycle_s=0.06)
    report = run_stamped(scene, lambda n: 0.13 + rng.uniform(-0.004, 0.004, n.size), log,
                         radar)
    assert report.radar_clock["cycle_from"] == "bus"
    assert report.radar_clock["cycle_s"] == pytest.approx(0.06, abs=2e-4)
    assert report.frames["total"] == report.frames["checked"] == 25
    assert len(report.reasons) == 1, report.reasons
    assert "its profile says 50.000000 ms" in report.reasons[0]
    assert report.reasons[0].startswith("radar_clock: the radar's cycles reached the bus every")
    again = check_log(scene, log).report
    assert again.reasons == report.reasons and again.frames == report.frames


@pytest.mark.parametrize("late_s", [0.3, 0.335])
def test_a_radar_started_after_the_scene_is_checked_from_its_first_cycle_not_missing(tmp_path,
                                                                                   late_s):
    # The profile says the radar counts from 4242 at the scene's start; it was switched on
    # late, its count's cycle 0 measured 300 (or 335) ms into the scene, its messages 130 ms
    # +- 3 ms later. Its bus times less its latency say when: the cycles are judged at their
    # times, none missing (the profile's first six were never measured), and the report says
    # when cycle 0 was measured, live, re-checked by the sidecar and without it. The scene's
    # first 300 ms were not seen: the run fails for that alone, and says so.
    scene = scene_with_clock(tmp_path, cycle_s=0.05, latency_s=0.13, jitter_s=0.003,
                             counter_start=4242)
    log = tmp_path / "late.blf"
    with Pipeline.for_scene(scene, RunOptions(bus_log=str(log))) as pipeline:
        pipeline.output.clock = dataclasses.replace(scene.radar.radar_clock,
                                                    start_offset_s=late_s)
        live = pipeline.run(scene).report
    cycles = int(np.ceil((scene.duration_s - late_s) / 0.05))
    sidecar = check_log(scene, log).report
    Path(str(log) + ".rts.json").unlink()
    blind = check_log(scene, log).report
    # (without the sidecar, the phase within a frame is the plateau's: a radar in step with
    # the frames fits as well anywhere in the frame, docs/bench.md section 4)
    for report, within_s in ((live, 0.004), (sidecar, 0.004), (blind, 0.05)):
        assert not report.passed
        (late,) = [r for r in report.reasons if r.startswith("radar_clock: ")]
        assert late in report.reasons and len(report.reasons) == 1, report.reasons
        assert re.fullmatch(
            r"radar_clock: the radar measured its cycle 0 at scene time ([\d.]+) s, ([\d.]+) s "
            r"later than its profile says \(0\.000 s\): it started after the scene began, and "
            r"the scene's frames before that were not measured \(about (\d+) cycles\); start "
            r"the radar before the scene, or set clock.start_offset_s in its profile where it "
            r"starts late on purpose", late)
        assert late.codes == ("radar_clock",)
        assert report.frames["total"] == report.frames["checked"] == cycles
        assert report.frames["missing"] == 0
        clock = report.radar_clock
        assert clock["counter_start"] == 4242
        assert clock["start_offset_s"] == pytest.approx(late_s, abs=within_s)
        assert clock["late_start_s"] == clock["start_offset_s"]
    assert live.radar_clock["start_from"] == "bus"
    json.dumps(live.to_dict(), allow_nan=False)


def test_a_radar_reporting_cycles_late_is_told_from_one_started_late(tmp_path):
    # 100 ms (two cycles) later than its profile's latency: its cycles reach the bus as a
    # radar's started two cycles late would, but its detections fit the scene earlier than
    # the times that gives, by more than half a frame. It measured on time: the reason said
    # it "started after the scene began".
    scene = scene_with_clock(tmp_path, cycle_s=0.05, latency_s=0.13, counter_start=4242)
    report = run_stamped(scene, lambda n: np.full(n.size, 0.23), tmp_path / "slower.blf")
    assert not report.passed
    (clock_reason,) = [r for r in report.reasons if r.codes == ("radar_clock",)]
    assert re.match(r"radar_clock: the radar's cycles reached the bus 0\.1\d\d s later than "
                    r"its profile's latency and start say, but its detections fit the scene "
                    r"0\.\d+ s \(\+-0\.\d+ s\) earlier than the times that gives, more than "
                    r"half a frame: it measured earlier than a radar started late would have, so "
                    r"its latency is longer than its profile's \(0\.130 s\) rather than its "
                    r"start late", clock_reason), clock_reason
    assert "started after the scene began" not in " ".join(report.reasons)
    assert "time_alignment" in report.reason_codes


def test_a_radar_reporting_less_than_a_cycle_late_is_no_late_start(tmp_path):
    # 40 ms later than its profile's latency: a latency not the profile's, which the
    # detections' lag tells (`test_a_radar_whose_latency_is_not_its_profile_s_fails_...`).
    scene = scene_with_clock(tmp_path, cycle_s=0.05, latency_s=0.13, counter_start=4242)
    report = run_stamped(scene, lambda n: np.full(n.size, 0.17), tmp_path / "slow.blf")
    assert "late_start_s" not in report.radar_clock
    assert report.radar_clock["start_from"] == "profile"


def test_a_radar_running_free_is_checked_at_the_phase_its_bus_times_show(tmp_path):
    # The profile knows the radar's cycle and latency, not when it was switched on: it measures
    # 31 ms into each 50 ms frame (and runs 300 ppm slow). Its bus times less its latency give
    # the phase; each cycle is judged against the frame the radar really saw.
    scene = scene_with_clock(tmp_path, cycle_s=0.05, latency_s=0.13, jitter_s=0.004,
                             counter_start="auto")
    radar = RadarClock(cycle_s=0.050015, start_offset_s=0.031, latency_s=0.13, jitter_s=0.004,
                       counter_start=4242)
    seen: list[Detections] = []
    log = tmp_path / "free.blf"
    with Pipeline.for_scene(scene, RunOptions(bus_log=str(log))) as pipeline:
        pipeline.output.clock = radar
        sink = pipeline.output._sink
        pipeline.output._sink = lambda cycles: (seen.extend(cycles), sink(cycles))
        report = pipeline.run(scene).report
    assert report.passed, report.reasons
    clock = report.radar_clock
    assert clock["counter_start"] == 4242 and clock["start_from"] == "bus"
    # +-4 ms of jitter on 240 cycles: the phase to a fraction of a millisecond, the cycle to
    # a few microseconds (3 sigma: 2.3 ms / sqrt(240^3 / 12) = 2.6 us).
    assert clock["start_offset_s"] == pytest.approx(0.031, abs=5e-4)
    assert clock["cycle_s"] == pytest.approx(0.050015, abs=8e-6)
    assert clock["cycle_from"] == "bus"
    # The radar saw the frame held 31 ms into each hold; the check compared it with that frame:
    # its errors are the bus's 5 mm steps, not the target's motion over a frame.
    t = np.array([c.t_s for c in seen])
    held_t = np.floor(t * scene.frame_rate_hz + 1e-9) / scene.frame_rate_hz
    truth = compute_tracks(scene, held_t)
    got = np.array([c.range_m[0] for c in seen])
    np.testing.assert_allclose(got, truth.range_m[:, 0], atol=0.02)
    moved = np.abs(compute_tracks(scene, held_t + 0.05).range_m[:, 0] - truth.range_m[:, 0])
    assert report.errors["range_m"].max < 0.01 < moved.max()
    assert report.frames["checked"] == report.frames["total"] == len(seen)
    # Measured mid-frame, no cycle lies near a frame change: each is judged against one frame
    # (taken at the profile's phase, every cycle sat on a change and could match either).
    assert report.frames["ambiguous"] == 0
    # Its log re-checked by the sidecar: the same cycles, judged at the same times.
    again = check_log(scene, log)
    assert again.report.passed, again.report.reasons
    assert again.report.frames["checked"] == len(seen)
    assert again.report.errors["range_m"].max == pytest.approx(report.errors["range_m"].max)


def free_radar(tmp_path, cycle_s=0.05, offset_s=0.031, counter_start=4242):
    """A scene whose radar runs free (profile: ``cycle_s``, 130 ms latency, 4 ms jitter,
    ``counter_start: auto``), and that radar's own clock: ``offset_s`` into its cycle at the
    scene's start, its counter from ``counter_start``."""
    scene = scene_with_clock(tmp_path, cycle_s=cycle_s, latency_s=0.13, jitter_s=0.004,
                             counter_start="auto")
    return scene, RadarClock(cycle_s=cycle_s, start_offset_s=offset_s, latency_s=0.13,
                             jitter_s=0.004, counter_start=counter_start)


def run_behind_own_clock(scene, radar, *, ppm=0.0, log=None, late=False, seed=3,
                         delays=(0.0, 0.003), start_up_s=0.0, record=False, ahead_s=None):
    """Run ``scene`` with ``radar``'s cycles stamped by an interface's own clock.

    Seconds since it was plugged in (1234.5 s at the scene's start; ``ahead_s``: the host's
    time at the scene's start plus that, a clock set from the host's long ago), its crystal
    ``ppm`` off
    the host's; the host receives each message ``delays`` (lowest, highest; up to 3 ms by
    default) after it was stamped, and those stamped in the first ``start_up_s`` of the scene
    50 to 200 ms later still (an interface's start-up). ``late``: the radar reports each
    cycle's detections one cycle late (the frame before). ``record``: keep the check's
    per-cycle arrays. Returns the report and the cycles the radar measured.
    """
    seen: list[Detections] = []
    measured: list[Detections] = []
    rng = np.random.default_rng(seed)
    rate = 1.0 + ppm * 1e-6
    with Pipeline.for_scene(scene, RunOptions(bus_log=None if log is None else str(log),
                                              record=record)) as pipeline:
        pipeline.output.clock = radar
        publisher = pipeline._publisher
        origin = pipeline._bus_origin_s
        zero = 1234.5 if ahead_s is None else origin + ahead_s

        def stamp(cycles):
            if late:  # each cycle carries the detections of the one before (none first)
                before = (measured[-1:] or [Detections.empty(0, None)]) + cycles[:-1]
                measured.extend(cycles)
                cycles = [dataclasses.replace(b, cycle=c.cycle, t_s=c.t_s)
                          for b, c in zip(before, cycles, strict=True)]
            seen.extend(cycles)
            t = np.array([c.t_s for c in cycles])
            jitter = rng.uniform(-radar.jitter_s, radar.jitter_s, t.size)
            publisher.publish_many(cycles, zero + (t + radar.latency_s + jitter) * rate)

        pipeline.output._sink = stamp

        def received_at(msg):
            host = origin + (msg.timestamp - zero) / rate
            start_up = rng.uniform(0.05, 0.2) if host - origin < start_up_s else 0.0
            return host + rng.uniform(*delays) + start_up

        pipeline.receiver.received_at = received_at
        return pipeline.run(scene).report, seen


@pytest.mark.parametrize("interface_ppm", [0.0, 150.0, -150.0])
def test_a_free_radar_behind_an_interface_with_its_own_clock_is_checked_at_its_phase(
        tmp_path, interface_ppm):
    # The radar of the test above, behind an interface that stamps messages with its own clock
    # (seconds since it was plugged in, its crystal off the host's by ``interface_ppm``), as
    # PCAN, Vector and Kvaser interfaces do. The bus times cannot say where the scene started;
    # when the host received the messages (up to 3 ms later) ties that clock to the host's:
    # the phase within the delivery, each cycle judged against the frame it saw.
    scene = scene_with_clock(tmp_path, cycle_s=0.05, latency_s=0.13, jitter_s=0.004,
                             counter_start="auto")
    radar = RadarClock(cycle_s=0.050015, start_offset_s=0.031, latency_s=0.13, jitter_s=0.004,
                       counter_start=4242)
    log = tmp_path / "free.blf"
    report, seen = run_behind_own_clock(scene, radar, ppm=interface_ppm, log=log)
    assert report.passed, report.reasons
    clock = report.radar_clock
    assert clock["start_from"] == "bus" and clock["bus_clock"] == "interface"
    assert clock["early_s"] == 0.011  # `ClockLink.error_s`: delivery within 10 ms, and 1 more
    # Placed by the fastest deliveries: late by up to their 3 ms, not earlier (and the
    # phase's own 0.6 ms of jitter); the cycle on the host's clock, the interface's crystal
    # taken out.
    assert 0.031 - 6e-4 <= clock["start_offset_s"] <= 0.031 + 0.0036
    assert clock["cycle_s"] == pytest.approx(0.050015, abs=8e-6)
    t = np.array([c.t_s for c in seen])
    held_t = np.floor(t * scene.frame_rate_hz + 1e-9) / scene.frame_rate_hz
    truth = compute_tracks(scene, held_t)
    moved = np.abs(compute_tracks(scene, held_t + 0.05).range_m[:, 0] - truth.range_m[:, 0])
    assert report.errors["range_m"].max < 0.01 < moved.max()
    assert report.frames["checked"] == report.frames["total"] == len(seen)
    # Mid-frame, 19 ms from the next change and 31 ms after one: no cycle may have seen
    # another frame (at the profile's phase every cycle sat on a change: 239 of 240 were).
    assert report.frames["ambiguous"] == 0
    # Its log (the interface's times only) re-checked by the sidecar: the same verdict.
    again = check_log(scene, log)
    assert again.report.passed, again.report.reasons
    assert again.report.frames["checked"] == len(seen)
    assert again.report.frames["ambiguous"] == 0
    assert again.report.radar_clock["early_s"] == 0.011
    assert again.report.radar_clock["start_offset_s"] == pytest.approx(
        clock["start_offset_s"], abs=1e-9)


@pytest.mark.parametrize("ahead_s", [0.02, 0.5, -0.3, -2.0, 7.0])
def test_an_interface_clock_near_the_host_s_is_told_by_the_receipts(tmp_path, ahead_s):
    # An interface whose clock was set from the host's once and has run off it since (or a
    # driver's own epoch close to it): its stamps lie within the 10 s that a first cycle's bus
    # time may lie outside the scene, so they passed for the host's, and the radar's phase was
    # off by that much (frames judged seconds away). No message reaches the host before it
    # was stamped, nor all of seconds of them 0.25 s late: the receipts tell the clocks apart,
    # and tie them.
    scene, radar = free_radar(tmp_path)
    log = tmp_path / "near.blf"
    report, seen = run_behind_own_clock(scene, radar, log=log, ahead_s=ahead_s)
    assert report.passed, report.reasons
    clock = report.radar_clock
    assert clock["bus_clock"] == "interface" and clock["start_from"] == "bus"
    assert 0.031 - 6e-4 <= clock["start_offset_s"] <= 0.031 + 0.0036
    assert report.frames["checked"] == report.frames["total"] == len(seen)
    assert report.frames["ambiguous"] == 0
    rechecked_alike(scene, log, report)


def test_an_interface_clock_a_little_behind_the_host_s_fails_on_the_detections_lag(tmp_path):
    # 100 ms behind the host's: every receipt seems 100 ms after its stamp, which a loaded
    # host could do to some messages; the stamps pass for the host's, the radar's phase is
    # taken 100 ms early, and each cycle is judged against the frame two before the one it
    # saw. The detections' lag tells, and the run fails.
    scene, radar = free_radar(tmp_path)
    report, _ = run_behind_own_clock(scene, radar, ahead_s=-0.1)
    assert report.radar_clock["bus_clock"] == "host" and "early_s" not in report.radar_clock
    assert report.radar_clock["detection_lag_s"] == pytest.approx(-0.1, abs=0.015)
    assert not report.passed
    assert [r for r in report.reasons if r.startswith("time_alignment:")], report.reasons


def test_a_free_radar_one_frame_late_behind_an_interface_with_its_own_clock_is_seen(tmp_path):
    # The same radar reporting each cycle's detections a cycle late: it showed the frame
    # before. At the profile's phase every cycle sat on a frame change and was judged against
    # whichever frame matched (errors of 4 mm, as on time); tied to the host's clock the check
    # knows where it measured: each cycle's error is the target's motion over a frame.
    scene, radar = free_radar(tmp_path)
    report, _ = run_behind_own_clock(scene, radar, late=True)
    assert report.frames["ambiguous"] == 0
    assert report.errors["range_m"].p50 > 0.04, report.errors["range_m"]
    # The detections fit the scene a frame (50 ms) before the cycles' times, less the radar's
    # range-Doppler coupling (`_coupling_lag_s`; 3 ms more for the bench's own range errors,
    # which follow the target's angle as its range rate does): the run fails.
    lag = report.radar_clock["detection_lag_s"]
    assert lag == pytest.approx(0.05 + _coupling_lag_s(scene),
                                abs=3 * report.radar_clock["detection_lag_error_s"] + 3e-3)
    assert not report.passed
    assert [r for r in report.reasons if r.startswith("time_alignment: the detections fit the "
                                                     "scene 4")], report.reasons


def receding_scene(tmp_path, duration_s, **clock):
    """``scene_with_clock``'s scene ``duration_s`` long, its car straight ahead from 16 m,
    receding 0.5 m/s: measurable for minutes, 2.5 cm further each frame."""
    scene_with_clock(tmp_path, **clock)
    return load_scenario(tmp_path / "cut_in.scenario.yaml",
                         {"radar.profile": "radars/own.radar.yaml", "radar.noise": False,
                          "radar.fidelity": "analytic", "duration_s": duration_s,
                          "targets.0.motion.speed_mps": 22.5, "targets.0.lane_changes": [],
                          "targets.0.motion.position_m": [20.0, 0.0, 0.6],
                          "expectations.expected_limits": ["frame_rate_above_radar"]})


def assert_measured_where_it_did(scene, report, seen, late_s):
    """Each cycle's measurement time as the check took it lies at most ``late_s`` after the
    radar's (and no earlier than the phase's jitter), and its truth is the frame it saw."""
    t = np.array([c.t_s for c in seen])
    got = report.record.load()["t_s"]
    assert got.size == t.size
    assert -6e-4 <= float((got - t).min()) and float((got - t).max()) <= late_s
    held_t = np.floor(t * scene.frame_rate_hz + 1e-9) / scene.frame_rate_hz
    truth = compute_tracks(scene, held_t)
    moved = np.abs(compute_tracks(scene, held_t + 0.05).range_m[:, 0] - truth.range_m[:, 0])
    assert report.errors["range_m"].max < 0.01 < moved.min()


@pytest.mark.parametrize(("interface_ppm", "phase_s"), [(-200.0, 0.038), (200.0, 0.022)])
def test_an_interface_drifting_over_a_long_run_keeps_each_cycle_at_its_phase(
        tmp_path, interface_ppm, phase_s):
    # 90 s in batches of 500 frames (25 s): each batch's cycles are judged once the next
    # batch's came in, up to 50 s later, when the interface's crystal had drifted 10 ms
    # against the host's. Each cycle is placed within its deliveries (3 ms) and the drift
    # over the link's 5 s, as documented: 12 ms from a frame change either way, none is in an
    # ambiguity window (5.8 ms each side, 11 ms more after a change), and the log's re-check
    # judges alike.
    scene = receding_scene(tmp_path, 90.0, cycle_s=0.05, latency_s=0.13, jitter_s=0.004,
                           counter_start="auto")
    radar = RadarClock(cycle_s=0.05, start_offset_s=phase_s, latency_s=0.13, jitter_s=0.004,
                       counter_start=4242)
    log = tmp_path / "long.blf"
    report, seen = run_behind_own_clock(scene, radar, ppm=interface_ppm, log=log, record=True)
    assert report.passed, report.reasons
    assert report.frames["checked"] == report.frames["total"] == len(seen) == 1800
    assert_measured_where_it_did(scene, report, seen, 0.003 + 0.001 + 6e-4)
    assert report.frames["ambiguous"] == 0
    clock = report.radar_clock
    assert phase_s - 6e-4 <= clock["start_offset_s"] <= phase_s + 0.0036
    assert clock["cycle_s"] == 0.05 and clock["cycle_from"] == "profile"
    rechecked_alike(scene, log, report)


@pytest.mark.parametrize("interface_ppm", [0.0, 150.0])
def test_an_interface_s_slow_start_up_does_not_tilt_its_clock(tmp_path, interface_ppm):
    # The interface delivers its first second's messages 50 to 200 ms late (USB start-up):
    # those receipts are no clue to its clock, which the later ones tie to the host's. The
    # report's clock is the radar's on the host's seconds: its profile's cycle, its phase
    # within the deliveries' 3 ms; the sidecar keeps it, and the re-check judges alike.
    scene, radar = free_radar(tmp_path)
    log = tmp_path / "start-up.blf"
    report, seen = run_behind_own_clock(scene, radar, ppm=interface_ppm, log=log,
                                        start_up_s=1.0, record=True)
    assert report.passed, report.reasons
    clock = report.radar_clock
    assert clock["cycle_s"] == 0.05 and clock["cycle_from"] == "profile", clock
    assert 0.031 - 6e-4 <= clock["start_offset_s"] <= 0.031 + 0.0036, clock
    assert_measured_where_it_did(scene, report, seen, 0.003 + 0.001 + 6e-4)
    rechecked_alike(scene, log, report)


def test_a_free_radar_measuring_just_before_the_scene_s_start_misses_no_cycle(tmp_path):
    # Every delivery takes 2 to 10 ms: the cycles seem measured 2 ms (and up to 11) after
    # they were. This radar measures 1 ms before each frame change, so its cycle before the
    # first it sent seems measured 1 ms into the scene; it may as well have measured before
    # the scene (it did, and was not played to): the scene's first cycle is the one after,
    # and no cycle is missing. Its cycles 1 ms before a change are ambiguous (their window
    # after the change grows by the 11 ms); its last, 1 ms before the scene's end, seems
    # measured after it and is not judged (counted after the scene).
    scene, radar = free_radar(tmp_path, 0.05, 0.049, 4242)
    log = tmp_path / "edge.blf"
    report, seen = run_behind_own_clock(scene, radar, log=log, delays=(0.002, 0.01))
    assert report.passed, report.reasons
    assert report.frames["missing"] == report.frames["before_scene"] == 0
    assert report.frames["after_scene"] == 1
    assert report.frames["checked"] == report.frames["total"] == len(seen) - 1
    assert report.radar_clock["counter_start"] == 4242
    rechecked_alike(scene, log, report)


def test_a_72_ms_radar_behind_a_drifting_interface_is_re_checked_alike(tmp_path):
    # A 72 ms radar on 50 ms frames, behind an interface 200 ppm slow delivering in 2 to
    # 10 ms: every cycle is judged against the frame it saw (or counted ambiguous), and the
    # log's re-check by the sidecar counts the same cycles ambiguous.
    scene, radar = free_radar(tmp_path, 0.072, 0.02, 7)
    log = tmp_path / "72.blf"
    report, seen = run_behind_own_clock(scene, radar, ppm=-200.0, log=log,
                                        delays=(0.002, 0.01), record=True)
    assert report.passed, report.reasons
    assert report.frames["checked"] == report.frames["total"] == len(seen)
    t = np.array([c.t_s for c in seen])
    got = report.record.load()["t_s"]
    assert 0.002 - 6e-4 <= float((got - t).min()) and float((got - t).max()) <= 0.011 + 6e-4
    rechecked_alike(scene, log, report)


def test_the_clock_track_keeps_the_profile_until_the_bus_tells_otherwise():
    from rts_scenario.radar.clock import ClockTrack

    rng = np.random.default_rng(5)
    profile = RadarClock(cycle_s=0.05, start_offset_s=0.01, latency_s=0.13, jitter_s=0.004)
    origin = 1.7e9
    n = np.arange(2000)
    on_profile = origin + 0.01 + 0.05 * n + 0.13 + rng.uniform(-0.004, 0.004, n.size)
    track = ClockTrack(profile, origin, free=False)
    track.add(n, on_profile)
    assert track.cycle_s == 0.05 and track.start_offset_s == 0.01
    assert track.to_dict()["cycle_from"] == "profile"
    assert track.off_profile_reason(0.003) is None
    # 100 ppm off, 7 ms into the frames, running free: both from the bus.
    true_t = 0.007 + 0.050005 * n
    track = ClockTrack(profile, origin, free=True)
    track.add(n[:1000], origin + true_t[:1000] + 0.13 + rng.uniform(-0.004, 0.004, 1000))
    track.add(n[1000:], origin + true_t[1000:] + 0.13 + rng.uniform(-0.004, 0.004, 1000))
    assert track.cycle_s == pytest.approx(0.050005, rel=2e-6)
    assert np.abs(track.time_of(n) - true_t).max() < 5e-4
    assert track.first_at(0.0) == 0 and track.first_at(0.008) == 1
    assert track.off_profile_reason(0.003) is None  # 100 ppm: a crystal
    # A latency that rose by 20 ms halfway (a loaded bus) tilts the line: not followed.
    held_up = origin + true_t + 0.13 + rng.uniform(-0.004, 0.004, n.size) + 0.02 * (n > 1000)
    track = ClockTrack(profile, origin, free=False)
    track.add(n, held_up)
    assert track.cycle_s == 0.05 and track.off_profile_reason(0.003) is None
    # Without the scene's start on the bus's clock, the phase stays the profile's.
    blind = ClockTrack(profile, None, free=True)
    blind.add(n, origin + true_t + 0.13)
    assert blind.start_offset_s == 0.01 and blind.to_dict()["start_from"] == "profile"


def run_stamped(scene, delay, log, radar=None, batch_frames=None, keep=None):
    """Run ``scene`` with its cycles on the bus at measurement + ``delay(counters)`` (s).

    ``keep(cycle)``: whether a cycle reaches the bus (all by default).
    """
    with Pipeline.for_scene(scene, RunOptions(bus_log=str(log),
                                              batch_frames=batch_frames)) as pipeline:
        if radar is not None:
            pipeline.output.clock = radar
        publisher = pipeline._publisher

        def stamp(cycles):
            cycles = [c for c in cycles if keep is None or keep(c)]
            if not cycles:
                return
            t = np.array([c.t_s for c in cycles])
            counter = np.array([c.cycle for c in cycles])
            publisher.publish_many(cycles, pipeline._bus_origin_s + t + delay(counter))

        pipeline.output._sink = stamp
        return pipeline.run(scene).report


def test_a_free_radar_in_step_with_the_scene_misses_no_cycle_at_its_end(tmp_path):
    # The profile's radar runs free and measures exactly at the frames' times, 0 to 11.95 s,
    # its messages 130 ms later +- 3 ms. The bus times put its phase 0.2 ms early (the jitter
    # has that mean here): the cycle it measured at the scene's end (12 s, not sent) lies within
    # three standard errors of it, and may be after the scene: it is not missing. Re-checked by
    # the sidecar and without it, the same 240 cycles pass.
    scene = scene_with_clock(tmp_path, cycle_s=0.05, latency_s=0.13, jitter_s=0.004,
                             counter_start="auto")
    log = tmp_path / "free.blf"
    report = run_stamped(scene, lambda n: 0.13 - 0.0002 + np.where(n % 2, 0.003, -0.003), log)
    assert report.radar_clock["start_offset_s"] == pytest.approx(-0.0002, abs=1e-6)
    assert report.passed, report.reasons
    assert report.frames["total"] == report.frames["checked"] == 240
    rechecked_alike(scene, log, report)
    Path(str(log) + ".rts.json").unlink()
    blind = check_log(scene, log).report
    assert blind.passed and blind.frames["total"] == blind.frames["checked"] == 240


@pytest.mark.parametrize("batch_frames", [1, 3])
def test_a_free_radar_just_before_the_frames_is_numbered_by_all_its_cycles(tmp_path,
                                                                            batch_frames):
    # Switched on at 49 ms, the radar measures 1 ms before each frame change, its messages
    # +-3 ms about its latency (the first 3.5 ms late). With a batch of one or three frames
    # the first batch holds one or three cycles, whose times put the cycle before the first
    # (at -1 ms, never measured) in the scene: the scene's first is decided once the bus
    # times tell it (three standard errors of the phase over 240 cycles: 0.6 ms), the same
    # 240 cycles live and re-checked.
    scene, radar = free_radar(tmp_path, 0.05, 0.049, 4242)
    log = tmp_path / "free.blf"
    report = run_stamped(scene, lambda n: 0.13 + np.where(
        n == 4242, 0.0035, np.where(n % 2, 0.003, -0.003)), log, radar, batch_frames)
    assert report.passed, report.reasons
    assert report.radar_clock["counter_start"] == 4242
    assert report.radar_clock["start_offset_s"] == pytest.approx(0.049, abs=5e-4)
    assert report.frames["total"] == report.frames["checked"] == 240
    assert report.frames["after_scene"] == report.frames["missing"] == 0
    again = check_log(scene, log, batch_frames=batch_frames).report
    assert again.passed, again.reasons
    assert again.frames == report.frames


@pytest.mark.parametrize("batch_frames", [None, 3])
def test_a_free_radar_that_lost_its_first_cycles_fails_with_them_missing(tmp_path,
                                                                         batch_frames):
    # The radar measured from the scene's start (25 ms into each frame), but its first ten
    # cycles never reached the bus: they are missing, not a later start of the scene's cycles.
    scene, radar = free_radar(tmp_path, 0.05, 0.025, 4242)
    report = run_stamped(scene, lambda n: 0.13 + np.where(n % 2, 0.003, -0.003),
                         tmp_path / "lost.blf", radar, batch_frames,
                         keep=lambda c: c.cycle >= 4252)
    assert not report.passed
    assert report.frames["total"] == 240 and report.frames["missing"] == 10
    assert report.radar_clock["counter_start"] == 4242
    assert report.radar_clock["start_offset_s"] == pytest.approx(0.025, abs=5e-4)


def test_a_crystal_off_its_profile_with_more_jitter_than_it_says_is_followed_or_failed():
    from rts_scenario.radar.clock import ClockTrack

    # 300 ppm over 1200 cycles of 50 ms: the last cycle measured 18 ms later than the
    # profile's cycle puts it, beyond half the 5.76 ms ambiguity window; the latency's jitter
    # is +-12 ms where the profile says +-4 ms.
    rng = np.random.default_rng(7)
    profile = RadarClock(cycle_s=0.05, latency_s=0.13, jitter_s=0.004)
    n = np.arange(1200)
    track = ClockTrack(profile, 1.7e9)
    track.add(n, 1.7e9 + 0.13 + 0.050015 * n + rng.uniform(-0.012, 0.012, n.size))
    assert track.fit.drift_s(0.05)[0] == pytest.approx(0.018, abs=0.002)
    assert track.cycle_from_bus or track.off_profile_reason(0.00288) is not None


def jittery_track(seed, ppm=0.0, step_s=0.0, ramp_s=0.0, cycles=1200, batches=(None,)):
    """A track of cycles of 50 ms (+ ``ppm``), latency 130 ms +- 12 ms (its profile: +- 4 ms).

    From cycle ``cycles // 2`` on the latency is ``step_s`` longer, and grows by ``ramp_s``
    more to the last cycle. ``batches``: where the cycles are split to be handed over.
    """
    from rts_scenario.radar.clock import ClockTrack

    rng = np.random.default_rng(seed)
    profile = RadarClock(cycle_s=0.05, latency_s=0.13, jitter_s=0.004)
    n = np.arange(cycles)
    later = np.clip((n - cycles // 2) / (cycles - 1 - cycles // 2), 0.0, None)
    bus_t = (1.7e9 + 0.13 + 0.05 * (1 + ppm * 1e-6) * n + rng.uniform(-0.012, 0.012, n.size)
             + step_s * (n >= cycles // 2) + ramp_s * later)
    track = ClockTrack(profile, 1.7e9)
    edges = [0, *[b for b in batches if b is not None], cycles]
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        track.add(n[a:b], bus_t[a:b])
    return track


@pytest.mark.parametrize("seed", range(5))
def test_a_crystal_300_ppm_off_with_3x_its_profile_s_jitter_is_followed(seed):
    # Cycles on one line (15 us longer than the profile's) with +-12 ms of jitter: the
    # segments' means keep to it within their scatter, the cycle is the bus's.
    track = jittery_track(seed, ppm=300.0)
    fit = track.fit.cycle_s()
    # (the cycle's standard error: 6.9 ms / sqrt(1200^3 / 12) = 0.58 us)
    assert fit[1] < 6.5e-7
    assert track.cycle_from_bus and track.cycle_s == pytest.approx(0.050015, abs=3 * fit[1])
    assert track.latency_change_s() is None and track.latency_change_reason(0.00288) is None
    assert track.off_profile_reason(0.00288) is None  # 300 ppm: a crystal
    assert "latency_change_s" not in track.to_dict()
    # The scatter within the segments is the jitter's: 24 ms / sqrt(12).
    assert track.fit.bend().scatter_s == pytest.approx(0.024 / np.sqrt(12), rel=0.1)


@pytest.mark.parametrize(("ppm", "step_s", "ramp_s"), [(0.0, 0.015, 0.0), (300.0, 0.015, 0.0),
                                                       (0.0, 0.0, 0.015)])
def test_a_latency_that_changed_mid_run_through_large_jitter_is_not_followed(ppm, step_s,
                                                                            ramp_s):
    # The latency 15 ms longer from the middle on (a step), or growing to 15 ms more by the
    # end (a bend), through +-12 ms of jitter: the line through the bus times tilts by 22 or
    # 15 ms over the run (a step at the middle tilts it by 1.5 times its height, a ramp over
    # the second half by its height: cov(x, ramp) / var(x) on [0, 1]), which a radar 300 ppm
    # off adds to. The segments' means do not keep to one line: not followed.
    track = jittery_track(11, ppm=ppm, step_s=step_s, ramp_s=ramp_s)
    tilt = track.fit.drift_s(0.05)
    assert tilt[0] == pytest.approx(1.5 * step_s + ramp_s + 0.018 * ppm / 300.0,
                                    abs=tilt[1]) and tilt[0] > tilt[1]
    assert not track.cycle_from_bus and track.cycle_s == 0.05
    assert track.to_dict()["cycle_from"] == "profile"
    assert track.fit.bend().p < 1e-6
    assert track.off_profile_reason(0.00288) is None
    # Highest segment to lowest, about the profile's cycle: the change plus the crystal's
    # drift over the run (18 ms at 300 ppm), within what the scatter could put between two
    # of the segments' means and the drift within a segment (1200 cycles: 18 segments of 64
    # and one of 48).
    change, crystal, margin = track.latency_change_s()
    assert track.fit.segments.length == 64
    segment = 64 * 0.05 * 300e-6 * (ppm > 0)
    assert change == pytest.approx(0.015 + 0.018 * ppm / 300.0, abs=margin + segment)
    assert track.to_dict()["latency_change_s"] == change
    # A crystal within 1000 ppm moves 3.2 ms against the profile over a segment of 64 cycles:
    # of a step it draws at most that across the two segments the step may fall between,
    # of a drift (300 ppm) or a bend (500 ppm over the second half) all.
    cap = 1e-3 * 0.05 * 64
    drift = 0.018 * ppm / 300.0
    if step_s:
        assert drift - margin < crystal < drift + 2 * cap + margin
    else:
        assert crystal == pytest.approx(change, abs=margin)
    if drift or ramp_s:
        reason = track.latency_change_reason(0.00288)
        assert reason.startswith("radar_clock: the radar's cycles reached the bus up to ")
        assert "not along one straight line" in reason and "50.000000 ms" in reason
    # Within what the window allows, the report says so without failing.
    assert track.latency_change_reason(0.1) is None


def test_latency_held_up_at_the_start_is_a_change_no_crystal_could_make():
    # The first 16 of 400 cycles reached the bus 30 ms to 0 late (a machine starting up),
    # then +-1 ms: bent, not followed, a change of 30 ms; a crystal within 1000 ppm moves
    # 0.4 ms against the profile over a segment of 8 cycles, so it could have drawn two
    # segments' worth of it: the run does not fail.
    from rts_scenario.radar.clock import ClockTrack

    rng = np.random.default_rng(16)
    profile = RadarClock(cycle_s=0.05, latency_s=0.13, jitter_s=0.004)
    n = np.arange(400)
    track = ClockTrack(profile, 1.7e9)
    track.add(n, 1.7e9 + 0.13 + 0.0500025 * n + rng.uniform(-0.001, 0.001, n.size)
              + np.clip(0.03 * (1 - n / 16), 0.0, None))
    assert track.fit.segments.length == 16
    assert not track.cycle_from_bus
    change, crystal, margin = track.latency_change_s()
    # (the first segment's mean is 30 ms x 17 / 32 late)
    assert change == pytest.approx(0.03 * 17 / 32, abs=margin + 0.001)
    assert crystal < 0.001 + margin
    assert track.latency_change_reason(0.00288) is None


def test_a_small_latency_change_is_reported_without_failing():
    # 2 ms longer from the middle on, through +-1 ms (the profile's +-4 ms: on its cycle the
    # former guard followed the 3 ms tilt): bent, not followed, under the 2.88 ms.
    from rts_scenario.radar.clock import ClockTrack

    rng = np.random.default_rng(12)
    profile = RadarClock(cycle_s=0.05, latency_s=0.13, jitter_s=0.004)
    n = np.arange(2000)
    track = ClockTrack(profile, 1.7e9)
    track.add(n, 1.7e9 + 0.13 + 0.05 * n + rng.uniform(-0.001, 0.001, n.size)
              + 0.002 * (n >= 1000))
    assert not track.cycle_from_bus
    change, crystal, margin = track.latency_change_s()
    assert change == pytest.approx(0.002, abs=margin) and margin < 1e-3
    assert crystal <= change + margin
    assert track.latency_change_reason(0.00288) is None


def test_cycles_on_one_line_read_as_bent_as_rarely_as_the_test_says():
    # The lack-of-fit test's chance: cycles on one line give p uniform on [0, 1] (Fisher's F
    # with the segments' degrees of freedom); 400 runs, their p below 0.1 and 0.5 as often
    # as that within 4 binomial sigma.
    from rts_scenario.radar.clock import CycleTimeFit

    rng = np.random.default_rng(13)
    p = []
    for _ in range(400):
        cycles = int(rng.integers(100, 3000))
        n = np.arange(cycles)
        fit = CycleTimeFit()
        fit.add(n, 1.7e9 + 0.0500123 * n + rng.normal(0.0, rng.uniform(1e-4, 0.02), n.size))
        p.append(fit.bend().p)
    p = np.array(p)
    for level in (0.1, 0.5):
        assert abs(np.mean(p < level) - level) < 4 * np.sqrt(level * (1 - level) / p.size)


def test_the_segments_stay_bounded_over_a_million_cycles():
    from rts_scenario.radar.clock import SEGMENTS, CycleTimeFit

    rng = np.random.default_rng(14)
    fit = CycleTimeFit()
    n = np.arange(1_000_000)
    bus_t = 1.7e9 + 0.13 + 0.0500025 * n + rng.uniform(-0.012, 0.012, n.size)
    most = 0
    for a in range(0, n.size, 7919):
        fit.add(n[a:a + 7919], bus_t[a:a + 7919])
        most = max(most, len(fit.segments.segments))
    assert most <= SEGMENTS
    # 2^15 cycles a segment: 30 full ones and one filling.
    assert fit.segments.length == 2 ** 15 and len(fit.segments.segments) == 31
    assert int(fit.segments.segments[:, 0].sum()) == n.size
    bend = fit.bend()
    # Moments centred on each segment keep the scatter precise a day's run from the origin.
    assert bend.scatter_s == pytest.approx(0.024 / np.sqrt(12), rel=0.01)
    assert bend.slope_s == pytest.approx(0.0500025, abs=1e-10)
    assert bend.p > 1e-3 and not bend.bent


def test_the_segments_do_not_depend_on_how_the_cycles_are_handed_over():
    whole = jittery_track(15, ppm=300.0, step_s=0.004)
    for batches in [(1, 2, 3, 500, 777), tuple(range(7, 1200, 13)), (600,)]:
        split = jittery_track(15, ppm=300.0, step_s=0.004, batches=batches)
        assert split.fit.segments.length == whole.fit.segments.length
        np.testing.assert_allclose(split.fit.segments.segments, whole.fit.segments.segments,
                                   rtol=1e-9, atol=1e-12)
        a, b = split.fit.bend(), whole.fit.bend()
        assert a.f == pytest.approx(b.f, rel=1e-9) and a.p == pytest.approx(b.p, rel=1e-6)
        assert split.cycle_from_bus == whole.cycle_from_bus
        assert split.latency_change_s() == pytest.approx(whole.latency_change_s(), rel=1e-9)


@pytest.mark.parametrize("counter_start", ["auto", 4242])
@pytest.mark.parametrize("ahead_s", [None, 86_400.0])
def test_a_bus_stamped_on_its_own_clock_is_numbered_by_the_counters(tmp_path, counter_start,
                                                                   ahead_s):
    # An interface that stamps messages with its own clock (seconds since it was plugged in,
    # or a day ahead), not the wall clock the scene's start was taken on: the bus times cannot
    # place the cycles in the scene. The radar's counters number them: the first received is
    # the scene's first for a radar running free, the profile's counter start for the other,
    # and all 240 pass.
    scene = scene_with_clock(tmp_path, cycle_s=0.05, latency_s=0.13, jitter_s=0.004,
                             counter_start=counter_start)
    radar = RadarClock(cycle_s=0.05, latency_s=0.13, jitter_s=0.004, counter_start=4242)
    with Pipeline.for_scene(scene, RunOptions()) as pipeline:
        pipeline.output.clock = radar
        publisher = pipeline._publisher

        def stamp(cycles):
            t = np.array([c.t_s for c in cycles])
            zero = 3456.7 if ahead_s is None else pipeline._bus_origin_s + ahead_s
            publisher.publish_many(cycles, zero + t + 0.13)

        pipeline.output._sink = stamp
        report = pipeline.run(scene).report
    assert report.passed, report.reasons
    assert report.frames["total"] == report.frames["checked"] == 240
    assert report.radar_clock["counter_start"] == 4242
    assert report.radar_clock["start_from"] == "profile"


# -- the end-of-scene tolerance of a bus-fitted cycle (`ClockTrack.edge_tolerance_s`) --------

def _on_a_line(cycle_s, d, n_cycles=100, phase_s=0.0, origin=1000.0):
    """Bus times of cycles 0..n_cycles-1 on a line of slope ``cycle_s`` through ``phase_s``
    (latency 0), off it by +d, -d, -d, +d in turn: a pattern with no slope and no mean, so
    the least-squares line is that line and the scatter about it d * sqrt(N / (N - 2))."""
    n = np.arange(n_cycles)
    r = d * np.tile([1.0, -1.0, -1.0, 1.0], n_cycles // 4)
    return n, origin + phase_s + cycle_s * n + r


def _slope_error(d, n_cycles):
    """Standard error of a least-squares slope: scatter / sqrt(sum (n - mean n)^2)."""
    scatter = d * np.sqrt(n_cycles / (n_cycles - 2))
    return scatter / np.sqrt(n_cycles * (n_cycles ** 2 - 1) / 12.0)


def test_the_edge_tolerance_of_a_bus_cycle_is_three_standard_errors_per_cycle_from_zero():
    from rts_scenario.radar.clock import ClockTrack

    # 100 cycles 2000 ppm longer than the profile's, 1 ms off the line: the slope's standard
    # error is 1.0102 ms / sqrt(83325) = 3.4994 us, and the bus's cycle is followed.
    profile = RadarClock(cycle_s=0.05, counter_start=0)
    track = ClockTrack(profile, 1000.0, free=False)
    track.add(*_on_a_line(0.0501, 1e-3))
    se = _slope_error(1e-3, 100)
    assert se == pytest.approx(3.4994e-6, rel=1e-4)
    assert track.cycle_from_bus and track.cycle_s == pytest.approx(0.0501, rel=1e-12)
    # The phase is the profile's (0, exact): the tolerance at scene time t is 3 standard
    # errors of the cycle times the cycles from cycle 0 to t.
    assert track.start_tolerance_s == 0.0
    for t in (0.0, 1.0, 5.01):
        assert track.edge_tolerance_s(t) == pytest.approx(3 * se * t / 0.0501, rel=1e-9)
    assert track.edge_tolerance_s(5.01) == pytest.approx(1.0498e-3, rel=1e-4)
    # A cycle the bus does not tell off the profile's (on it, or within three standard
    # errors of it) keeps the profile's exact cycle: no tolerance.
    near = ClockTrack(profile, 1000.0, free=False)
    near.add(*_on_a_line(0.05 + 2.9 * se, 1e-3))
    assert not near.cycle_from_bus and near.edge_tolerance_s(5.0) == 0.0
    assert profile.edge_tolerance_s(5.0) == 0.0


def test_the_edge_tolerance_of_a_free_radar_adds_the_phase_s_own():
    from rts_scenario.radar.clock import ClockTrack

    # Running free, 10 ms into the frames: the phase's standard error is the scatter of the
    # bus times less the line, d / sqrt(N - 1) (its floor from the profile's jitter is 0).
    free = RadarClock(cycle_s=0.05, counter_start=None)
    track = ClockTrack(free, 1000.0, free=True)
    track.add(*_on_a_line(0.0501, 1e-3, phase_s=0.01))
    se = _slope_error(1e-3, 100)
    assert track.start_offset_s == pytest.approx(0.01, abs=1e-9)
    phase = 3 * 1e-3 / np.sqrt(99)
    assert track.start_tolerance_s == pytest.approx(phase, rel=1e-6)
    assert track.edge_tolerance_s(5.01) == pytest.approx(phase + 3 * se * 5.0 / 0.0501,
                                                         rel=1e-6)
    # The profile's jitter (4 ms, uniform: 2.31 ms standard deviation) is more than the bus
    # times show: the phase's error is no less than it gives over 100 cycles, 0.231 ms.
    jittery = ClockTrack(RadarClock(cycle_s=0.05, latency_s=0.004, jitter_s=0.004,
                                    counter_start=None), 1000.0, free=True)
    jittery.add(*_on_a_line(0.0501, 1e-3, phase_s=0.014))
    floor = 3 * 0.004 / np.sqrt(3 * 100)
    assert jittery.start_tolerance_s == pytest.approx(floor, rel=1e-9)
    assert jittery.edge_tolerance_s(5.01) == pytest.approx(floor + 3 * se * 5.0 / 0.0501,
                                                           rel=1e-6)


@pytest.mark.parametrize(("inside", "scene_cycles"), [(0.9, 59), (1.1, 60)])
def test_a_last_cycle_within_the_edge_tolerance_of_the_scene_end_is_after_it(inside,
                                                                           scene_cycles):
    # A 3 s scene; the bus's cycle (1 ms scatter over 100 cycles, profile's phase 0) puts
    # cycle 59 a fraction ``inside`` of the edge tolerance before the scene's end: within it
    # (0.9), it may have measured at the end itself and is after the scene (59 cycles); just
    # beyond it (1.1), it measured in the scene and is judged (60).
    from rts_scenario.check import Checker
    from rts_scenario.pipeline import CycleTruth
    from rts_scenario.radar.clock import ClockTrack

    scene = load_scenario(ROOT / "scenarios" / "approaching_target.scenario.yaml",
                          {"duration_s": 3.0, "radar.noise": False})
    end, se, k = 3.0, _slope_error(1e-3, 100), 59
    # Cycle k at end - f * tol(end), tol(end) = 3 se end / c: k c^2 - end c + 3 f se end = 0.
    c = (end + np.sqrt(end ** 2 - 12 * k * inside * se * end)) / (2 * k)
    track = ClockTrack(RadarClock(cycle_s=0.05, counter_start=0), 1000.0, free=False)
    track.add(*_on_a_line(c, 1e-3))
    assert track.cycle_from_bus and track.cycle_s == pytest.approx(c, rel=1e-12)
    tolerance = track.edge_tolerance_s(end)
    assert end - k * c == pytest.approx(inside * tolerance, rel=1e-6)
    checker = Checker(scene.name, tuple(t.name for t in scene.targets), scene.expectations)
    truths = CycleTruth(checker, scene, track, 0.005)
    frames = np.arange(scene.n_frames)
    truths.add(frames, np.zeros((scene.n_frames, 1), dtype=np.uint16))
    judged = truths.finish()
    assert truths.first_cycle == 0 and truths.end_cycle == scene_cycles
    np.testing.assert_array_equal(judged, np.arange(scene_cycles))


@pytest.mark.parametrize("seed", range(4))
def test_host_delays_that_fade_after_the_first_cycles_are_not_a_crystal(seed):
    from rts_scenario.radar.clock import ClockTrack

    # A radar on its profile's 50 ms cycle, in step with a 3 s scene (cycle 60 measured at
    # its end). A loaded host stamps its first cycles late, 1.5 ms fading to none by cycle
    # 15, and every one up to 0.5 ms late: the line through the bus times tilts by about
    # 0.9 ms over the 66 cycles, beyond three standard errors of a fit that takes the delays
    # for independent (the cycles keep within 0.35 ms of it). A crystal is not told from that:
    # the profile's cycle stays, and cycle 60 is the one after the scene.
    rng = np.random.default_rng(seed)
    n = np.arange(66)
    host = np.clip(1.5e-3 * (1 - n / 15), 0, None) + rng.uniform(0, 0.5e-3, n.size)
    track = ClockTrack(RadarClock(cycle_s=0.05, counter_start=0), 1000.0)
    track.add(n, 1000.0 + 0.05 * n + host)
    slope, se = track.fit.cycle_s()
    assert 0.05 - slope > 3 * se and (0.05 - slope) * 65 > 7e-4
    assert not track.cycle_from_bus and track.cycle_s == 0.05
    assert track.first_at(3.0 - track.edge_tolerance_s(3.0)) == 60
    # A crystal 100 ppm short under the same start-up delays, over half an hour (180 ms of
    # drift by the end), handed over batch by batch: the start-up's cycles do not bend the
    # line of 36,000, and the crystal is followed to within a nanosecond a cycle.
    n = np.arange(36_000)
    host = np.clip(1.5e-3 * (1 - n / 15), 0, None) + rng.uniform(0, 0.5e-3, n.size)
    off = ClockTrack(RadarClock(cycle_s=0.05, counter_start=0), 1000.0)
    for part in np.array_split(n, 90):
        off.add(part, 1000.0 + 0.049995 * part + host[part])
    assert off.cycle_from_bus and off.cycle_s == pytest.approx(0.049995, abs=1e-9)
    assert off.latency_change_reason(0.00288) is None


def test_a_short_run_s_latency_that_fell_is_not_told_for_a_radar_off_its_profile():
    from rts_scenario.radar.clock import ClockTrack

    # A radar on its profile's 50 ms cycle, reported from cycle 57 on (its RTS came up late
    # in a 4 s scene): 38 cycles, 1.85 s. Its cycles reached the bus 1.5 to 5.8 ms late while
    # it had a target to process and 0.1 ms late once the scene had ended (bus times of a
    # bench). Their line tilts by 3.9 ms over the cycles (-2088 ppm), more than half the
    # check's 5.76 ms window, but within 3 sigma of the fit (1.3 ms) of it: not beyond what
    # the bus tells, so no other radar's clock to advise.
    late_ms = [5.82, 3.01, 3.43, 2.88, 2.56, 3.37, 1.79, 1.88, 1.64, 1.82, 1.65, 2.31, 1.62,
               1.69, 2.68, 1.56, 3.8, 2.3, 2.49, 1.85, 1.43, 0.51, 1.33, 0.04, 0.13, 0.07,
               0.08, 0.17, 0.12, 0.11, 0.08, 0.29, 0.2, 0.26, 0.0, 0.08, 0.02, 0.04]
    n = np.arange(57, 57 + len(late_ms))
    track = ClockTrack(RadarClock(cycle_s=0.05, counter_start=0))
    track.add(n, 1.8e9 + 0.05 * n + np.array(late_ms) * 1e-3)
    slope, se = track.fit.cycle_s()
    assert (0.05 - slope) * track.fit.span > 0.00288 > (0.05 - slope - 3 * se) * track.fit.span
    assert track.off_profile_reason(0.00288) is None
    # A radar 2000 ppm slow, its cycles late by those delays drawn at random, over 8 s: 16 ms
    # by its last cycle, beyond doubt.
    n = np.arange(57, 217)
    late = np.random.default_rng(1).choice(late_ms, n.size) * 1e-3
    slow = ClockTrack(RadarClock(cycle_s=0.05, counter_start=0))
    slow.add(n, 1.8e9 + 0.0501 * n + late)
    reason = slow.off_profile_reason(0.00288)
    assert reason is not None and "more than a crystal's 1000 ppm" in reason
    assert slow.cycle_s == pytest.approx(0.0501, abs=1e-5)


# -- the detections' lag: a radar whose latency is not its profile's ---------------------------

@pytest.mark.parametrize("true_latency_s, lag_s", [(0.13, 0.0), (0.17, 0.05), (0.09, -0.05)])
def test_a_radar_whose_latency_is_not_its_profile_s_fails_on_the_detections_lag(
        tmp_path, true_latency_s, lag_s):
    # The profile says 130 ms; the radar (running free) reports 170 or 90 ms after it measured.
    # Its phase, taken as its bus times less the profile's latency, is 40 ms off: measured 31
    # ms into each 50 ms frame, it is taken for one measuring 21 ms into the next (or 41 ms
    # into the one before), and every cycle is judged against a frame it did not see. Its
    # range errors against the targets' range rates tell by how much: a whole frame (the RTS
    # plays whole frames), and the run fails, live and re-checked. On its profile's latency
    # the lag is the radar's range-Doppler coupling (its range shifts by its range rate times
    # a millisecond or two), far below the half frame that fails.
    scene, radar = free_radar(tmp_path)
    rng = np.random.default_rng(4)
    log = tmp_path / "lag.blf"
    report = run_stamped(scene, lambda n: true_latency_s + rng.uniform(-0.004, 0.004, n.size),
                         log, radar=radar)
    clock = report.radar_clock
    lag, error = clock["detection_lag_s"], clock["detection_lag_error_s"]
    # The target's range rate varies by 0.2 m/s only: the lag and a range offset share that.
    assert 0.0 < error < 3e-3
    assert lag == pytest.approx(lag_s + _coupling_lag_s(scene), abs=3.0 * error + 3e-3)
    failed = [r for r in report.reasons if r.startswith("time_alignment:")]
    assert bool(failed) == (lag_s != 0.0) and report.passed == (lag_s == 0.0), report.reasons
    if lag_s:
        when = "before" if lag_s > 0 else "after"
        assert f"ms (+-{3e3 * error:.1f} ms) {when} the times the check took" in failed[0]
    again = check_log(scene, log).report
    assert again.radar_clock["detection_lag_s"] == pytest.approx(lag, abs=1e-9)
    assert again.passed == report.passed


def test_the_detections_lag_is_the_least_squares_one_of_range_errors_on_range_rates():
    from rts_scenario.check import LAG_BIN_S, LAG_MIN_BINS, LAG_MIN_CYCLES, Checker
    from rts_scenario.scenario.model import Expectations

    def lag_of(error, rate, use, t_s):
        checker = Checker("s", ("a", "b"), Expectations())
        checker._add_lag(error, rate, use, t_s)
        return checker.detection_lag_s()

    # Range errors b - L * rate + noise, in cycles 0.4 s apart; by hand, about the means (the
    # range offset b out): L = -sum(e v) / sum(v v), its standard error the larger of
    # sqrt(sum(r^2) / (n - 2) / sum(v v)), r = e + L v, and sqrt(G / (G - 1) sum_g (sum_g v
    # r)^2) / sum(v v) over the G spans of LAG_BIN_S the cycles fall in.
    rate = np.array([[10.0, -4.0], [12.0, np.nan], [-3.0, 5.0], [8.0, 0.0]] * 4)
    noise = np.array([[0.01, -0.02], [0.0, 0.3], [0.02, 0.01], [-0.01, 0.0]] * 4)
    noise[8:] *= -1.0
    error = 0.25 - 0.02 * rate + noise
    use = np.ones(rate.shape, dtype=bool)
    use[1, 1] = use[3, 0] = False
    t_s = 0.4 * np.arange(rate.shape[0])
    ok = use & np.isfinite(rate)
    e, v = error[ok] - error[ok].mean(), rate[ok] - rate[ok].mean()
    lag = -(e @ v) / (v @ v)
    r = e + lag * v
    span = np.floor(np.repeat(t_s[:, None], 2, axis=1)[ok] / LAG_BIN_S)
    sums = np.array([(v * r)[span == g].sum() for g in np.unique(span)])
    assert e.size >= LAG_MIN_CYCLES and sums.size >= LAG_MIN_BINS
    se = max(np.sqrt((r @ r) / (e.size - 2) / (v @ v)),
             np.sqrt(sums.size / (sums.size - 1) * (sums @ sums)) / (v @ v))
    got = lag_of(error, rate, use, t_s)
    assert got == pytest.approx((lag, se), rel=1e-9)
    assert lag == pytest.approx(0.02, abs=3 * se)
    # The same errors less their range offset: the same lag.
    assert lag_of(error - 0.25, rate, use, t_s) == pytest.approx(got, rel=1e-9)
    # Added cycle by cycle, the same sums.
    checker = Checker("s", ("a", "b"), Expectations())
    for i in range(rate.shape[0]):
        checker._add_lag(error[i:i + 1], rate[i:i + 1], use[i:i + 1], t_s[i:i + 1])
    assert checker.detection_lag_s() == pytest.approx(got, rel=1e-9)
    # Cycles within fewer spans than LAG_MIN_BINS: no lag.
    assert lag_of(error, rate, use, t_s * 0.1) is None
    # Too few target-cycles, or no target moving in range: no lag.
    few = Checker("s", ("a",), Expectations())
    few._add_lag(np.ones((3, 1)), np.ones((3, 1)), np.ones((3, 1), dtype=bool), np.arange(3.0))
    assert few.detection_lag_s() is None
    assert few.lag_untold() == "3 matched target-cycles judged against one frame, fewer than 10"
    assert lag_of(error, rate, use, t_s * 0.1) is None
    brief = Checker("s", ("a", "b"), Expectations())
    brief._add_lag(error, rate, use, t_s * 0.1)
    assert brief.lag_untold() == "the matched target-cycles span 2 of 0.5 s, fewer than 5"
    assert Checker("s", ("a",), Expectations()).lag_untold() is None  # nothing matched
    told = Checker("s", ("a", "b"), Expectations())
    told._add_lag(error, rate, use, t_s)
    assert told.lag_untold() is None
    still = Checker("s", ("a",), Expectations())
    still._add_lag(np.ones((20, 1)), np.zeros((20, 1)), np.ones((20, 1), dtype=bool),
                   np.arange(20.0))
    assert still.detection_lag_s() is None and still.lag_reason(0.05) is None
    # One range rate throughout (a target closing at 8 m/s): a lag is a range offset then.
    steady = Checker("s", ("a",), Expectations())
    steady._add_lag(np.full((20, 1), 0.4), np.full((20, 1), -8.0), np.ones((20, 1), dtype=bool),
                    np.arange(20.0))
    assert steady.detection_lag_s() is None and steady.lag_reason(0.05) is None
    assert steady.lag_untold() == ("the targets' range rates did not vary: a lag would look "
                                   "like a range offset")
    # Equal rates but for round-off (two cars side by side on a road at 30 deg to x: their
    # range rates are 1e-16 m/s, not 0): no lag either, whatever the errors' scatter.
    rng = np.random.default_rng(31)
    level = Checker("s", ("a", "b"), Expectations())
    level._add_lag(rng.normal(0.0, 0.05, (40, 2)), rng.normal(0.0, 2e-16, (40, 2)),
                   np.ones((40, 2), dtype=bool), np.arange(40.0) * 0.1)
    assert level.detection_lag_s() is None and level.lag_reason(0.05) is None
    assert level.lag_untold() == ("the targets' range rates did not vary: a lag would look "
                                  "like a range offset")


def test_a_lag_that_needs_a_range_offset_beyond_the_gate_is_not_told():
    from rts_scenario.check import Checker
    from rts_scenario.scenario.model import Expectations

    # A car receding at 3 m/s whose range rate drifts by 0.4 mm/s over 3 s (the geometry), its
    # range errors 5 mm and a 1.6 mm trend (the bench's): the least-squares lag is 4 s, and it
    # fits only with a range offset of 12 m (a radar measuring 4 s early ranges a receding
    # target 12 m short: the offset would give that back). The detections it is told from
    # lie within 0.9 m (3 x 0.3 m) of their targets: no such offset; a lag cannot be told
    # from the bench's range errors.
    t_s = np.arange(60) * 0.05
    rate = (3.0 - 4e-4 * t_s / 3.0)[:, None]
    error = 0.005 - 4.0 * (rate - rate.mean())
    checker = Checker("s", ("a",), Expectations(tolerances={"range_m": 0.3}))
    checker._add_lag(error, rate, np.ones(rate.shape, dtype=bool), t_s)
    lag, _, offset = checker._lag_fits()[0]
    assert (lag, offset) == pytest.approx((4.0, 0.005 + 4.0 * rate.mean()), rel=1e-6)
    assert checker.detection_lag_s() is None and checker.lag_reason(0.05) is None
    assert checker.lag_untold() == (
        "the targets' range rates varied too little: the lag that fits, 4000.0 ms, needs a "
        "range offset of 12 m, beyond the 3 x 0.3 m range gate of the detections it was told "
        "from")
    # A lag of a frame with the same drift fits with an offset of -15 cm: told.
    late = 0.005 + 0.05 * (rate - rate.mean())
    told = Checker("s", ("a",), Expectations(tolerances={"range_m": 0.3}))
    told._add_lag(late, rate, np.ones(rate.shape, dtype=bool), t_s)
    assert told.detection_lag_s()[0] == pytest.approx(-0.05, rel=1e-6)
    assert told.lag_untold() is None


def test_a_lag_that_cannot_be_told_is_said(tmp_path):
    # One car closing at a constant speed straight ahead: its range rate does not vary, and a
    # lag of the detections would be a range offset. The timing is not checked, and the
    # report says so.
    scene = load_scenario(ROOT / "scenarios" / "approaching_target.scenario.yaml",
                          {"duration_s": 4.0, "radar.noise": False})
    report = run(scene)
    assert report.passed, report.reasons
    assert "detection_lag_s" not in report.radar_clock
    untold = report.radar_clock["detection_lag_untold"]
    assert untold.startswith("the targets' range rates did not vary")
    assert f"time alignment: not told ({untold})" in report.table()


def test_the_detections_lag_is_judged_about_the_radar_s_range_doppler_coupling():
    from rts_scenario.check import Checker
    from rts_scenario.scenario.model import Expectations

    # A radar ranging each target 30.8 ms times its range rate farther (a slow chirp's
    # coupling): its lag is -30.8 ms, more than half a 50 ms frame off none, within its
    # standard error of the coupling its profile gives, and beyond half a frame of the
    # opposite one.
    t = 0.05 * np.arange(120)
    rate = np.stack([-8.0 + 0.5 * np.sin(t), -1.0 + 0.1 * t, 3.0 - 0.2 * t], axis=1)
    checker = Checker("s", ("a", "b", "c"), Expectations())
    checker._add_lag(0.0308 * rate, rate, np.ones(rate.shape, dtype=bool), t)
    lag, error = checker.detection_lag_s()
    assert lag == pytest.approx(-0.0308, abs=1e-12)
    assert checker.lag_reason(0.05, -0.0308) is None
    failed = checker.lag_reason(0.05)
    assert failed.startswith("time_alignment: the detections fit the scene 30.8 ms (+-0.0 ms) "
                             "after the times the check took for the radar's cycles, more than "
                             "0.5 of a 50 ms frame"), failed
    assert "the RTS applied frames earlier than the run knows" in failed
    opposite = checker.lag_reason(0.05, 0.0308)
    assert (", 61.6 ms after beyond the +30.8 ms its range-Doppler coupling gives, more than "
            "0.5 of a 50 ms frame") in opposite, opposite


def slow_chirp_scene(folder: Path, **profile) -> object:
    """A radar with a slow chirp (150 MHz in 60 us at 77 GHz: f / S about 31 ms, beyond half
    a 20 Hz frame) and two cars 2.5 m/s faster and slower than the ego, 22 and 50 m ahead."""
    data = yaml.safe_load(AWR.read_text())
    data.update(name="slow-chirp", bandwidth_hz=150e6, ramp_time_s=60e-6, idle_time_s=5e-6,
                adc_samples=128, sample_rate_hz=2.5e6, **profile)
    folder.mkdir(exist_ok=True)
    (folder / "slow.radar.yaml").write_text(yaml.safe_dump(data))
    (folder / "s.scenario.yaml").write_text(textwrap.dedent("""\
        rts_scenario: 1
        name: two-speeds
        duration_s: 8.0
        frame_rate_hz: 20.0
        radar:
          profile: slow.radar.yaml
          mount: {x_m: 3.7, z_m: 0.5}
          noise: false
          fidelity: analytic
        rig: wide-3x5
        ego:
          motion: {type: constant_velocity, position_m: [0, 0, 0], speed_mps: 20.0}
        targets:
          - name: away
            kind: car
            motion: {type: constant_velocity, position_m: [22.0, 1.0, 0.6], speed_mps: 22.5}
            rcs: {rcs_dbsm: 10.0}
          - name: near
            kind: car
            motion: {type: constant_velocity, position_m: [50.0, -1.0, 0.6], speed_mps: 17.5}
            rcs: {rcs_dbsm: 10.0}
        expectations:
          tolerances: {range_m: 0.3, radial_velocity_mps: 0.3, az_deg: 0.5, el_deg: 1.0}
          detection_rate: 0.9
        """))
    return load_scenario(folder / "s.scenario.yaml")


@pytest.mark.parametrize("coupling", ["kept", "corrected"])
def test_a_slow_chirp_s_range_doppler_coupling_is_not_taken_for_a_late_radar(tmp_path, coupling):
    # An up-chirp's beat is S tau - fD, fD = -2 v f / c at the sampled sweep's centre f: a
    # target of range rate v is ranged v f / S farther, where the scene has it f / S later.
    # By hand for this profile: f = 77 GHz + S (127 / 2) / 2.5 MHz, S = 150 MHz / 60 us.
    slope = 150e6 / 60e-6
    by_hand = -(77e9 + slope * 63.5 / 2.5e6) / slope
    assert by_hand == pytest.approx(-0.030825, abs=1e-6)
    scene = slow_chirp_scene(tmp_path, **({} if coupling == "kept" else
                                          {"range_doppler_coupling": "corrected"}))
    report = run(scene)
    clock = report.radar_clock
    expected = by_hand if coupling == "kept" else 0.0
    assert clock["detection_lag_coupling_s"] == pytest.approx(expected, rel=1e-9)
    # The simulated radar's ranges keep the coupling of its exact beat phases, or take the
    # measured Doppler's share back out: its lag is the coupling (31 ms, more than half a
    # frame: judged about none, the run would fail), or none.
    assert clock["detection_lag_s"] == pytest.approx(expected, abs=1e-3)
    assert 0.0 < clock["detection_lag_error_s"] < 1e-3
    assert report.passed, report.reasons
    coupled = "(the radar's range-Doppler coupling: 30.8 ms after)"
    assert (coupled in report.table()) == (coupling == "kept"), report.table()


def test_range_doppler_coupling_key_names_what_is_allowed(tmp_path):
    data = yaml.safe_load(AWR.read_text())
    data["range_doppler_coupling"] = "compensated"
    (tmp_path / "bad.radar.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(RtsError, match=r"bad.radar.yaml:\d+:\d+: range_doppler_coupling: got "
                                       r"'compensated'; allowed values: 'kept', 'corrected'"):
        RadarProfile.from_file(tmp_path / "bad.radar.yaml")
    assert RadarProfile.preset("awr1843boost").range_doppler_coupling == "kept"


def test_the_detections_lag_s_standard_error_holds_where_its_model_does():
    from rts_scenario.check import Checker
    from rts_scenario.scenario.model import Expectations

    # Three targets' range errors 5 cm + 2 ms x range rate + 2 cm of white noise, 120 cycles
    # of 50 ms added in blocks of 20, a tenth of the target-cycles unmatched: over 1000 runs,
    # the lag lies within three standard errors of -2 ms in 99.7 % of them (a normal's), and
    # its deviations in standard errors spread by about one.
    rng = np.random.default_rng(1)
    t = 0.05 * np.arange(120)
    rate = np.stack([-8.0 + 0.5 * np.sin(t), -1.0 + 0.1 * t, 3.0 - 0.2 * t], axis=1)
    z = []
    for _ in range(1000):
        checker = Checker("s", ("a", "b", "c"), Expectations())
        error = 0.05 + 0.002 * rate + rng.normal(0.0, 0.02, rate.shape)
        use = rng.random(rate.shape) > 0.1
        for i in range(0, t.size, 20):
            checker._add_lag(error[i:i + 20], rate[i:i + 20], use[i:i + 20], t[i:i + 20])
        lag, error_s = checker.detection_lag_s()
        z.append((lag + 0.002) / error_s)
    z = np.abs(np.array(z))
    assert 0.99 <= np.mean(z < 3.0) and np.mean(z < 1.0) == pytest.approx(0.683, abs=0.06)


def _coupling_lag_s(scene) -> float:
    """The lag a radar's range-Doppler coupling shows, from its profile alone.

    An up-chirp's beat is ``S tau - fD`` with ``fD = -2 v / lambda``: it ranges a target
    ``v f / S`` farther (``f = c / lambda``), where the scene has it ``f / S`` later.
    """
    radar = scene.radar
    return -(radar.fc_hz + radar.bandwidth_hz / 2.0) / radar.slope_hz_per_s


def test_a_radar_ranging_a_few_cm_long_is_not_a_radar_out_of_time(tmp_path):
    # The radar measures mid-frame on its profile's clock (no cycle near a frame change) and
    # ranges every target 3 cm long (a tenth of the scene's range tolerance: an RTS's delay
    # calibration, a radar's range offset). The scene's targets close at about 1 m/s: without
    # a range offset in the fit, 3 cm read as a 30 ms lag, more than half a 50 ms frame. The
    # lag is the range errors' slope on the range rates: an offset does not move it.
    scene = scene_with_clock(tmp_path, cycle_s=0.05, start_offset_s=0.025, latency_s=0.13,
                             counter_start=0)
    clean = run(scene)
    report = run(scene, lambda c, sink: sink([dataclasses.replace(c, range_m=c.range_m + 0.03)]))
    assert report.frames["ambiguous"] == 0
    assert report.errors["range_m"].p50 == pytest.approx(0.03, abs=0.01)
    assert report.passed, report.reasons
    lag = report.radar_clock["detection_lag_s"]
    assert lag == pytest.approx(clean.radar_clock["detection_lag_s"], abs=1e-9)
    error = report.radar_clock["detection_lag_error_s"]
    assert lag == pytest.approx(_coupling_lag_s(scene), abs=3.0 * error + 3e-3)


def test_a_radar_in_step_with_the_frames_two_frames_late_fails_on_its_lag(tmp_path):
    # The shipped profiles' radar measures at every frame change (cycle 50 ms, phase 0): each
    # cycle may show the frame before, and is judged against either; for the lag each takes
    # the frame that fits it better. One reporting the detections of two cycles before under
    # each counter saw a frame neither of those: its detections fit the scene a frame or more
    # before, and the run fails on it; on time, the lag is the radar's coupling.
    scene = scene_with_clock(tmp_path, cycle_s=0.05, start_offset_s=0.0, latency_s=0.13,
                             counter_start=0)
    measured: list[Detections] = []

    def two_late(cycle, sink):
        measured.append(cycle)
        stale = measured[-3] if len(measured) > 2 else Detections.empty(0, None)
        sink([dataclasses.replace(stale, cycle=cycle.cycle, t_s=cycle.t_s)])

    report = run(scene, two_late)
    assert not report.passed
    assert [r for r in report.reasons if r.startswith("time_alignment:")], report.reasons
    assert report.radar_clock["detection_lag_s"] > 0.025
    on_time = run(scene).radar_clock
    assert on_time["detection_lag_s"] == pytest.approx(
        _coupling_lag_s(scene), abs=3.0 * on_time["detection_lag_error_s"] + 3e-3)


# -- an interface's own clock tied to the host's (`ClockLink`) --------------------------------

def _deliveries(bus_t, host_of, rng, fastest_every=10):
    """Receipt times of messages stamped ``bus_t``: ``host_of(bus_t)`` plus up to 3 ms, every
    ``fastest_every``-th message received at once (a zero delay, so the least is exact)."""
    delay = rng.uniform(0.0, 0.003, bus_t.size)
    delay[::fastest_every] = 0.0
    return host_of(bus_t) + delay


def test_a_clock_link_is_the_least_delivery_and_the_line_through_each_block_s_least():
    from rts_scenario.pipeline import ClockLink

    rng = np.random.default_rng(11)
    link = ClockLink()
    assert link.offset_s is None and link.line() is None
    # The interface's clock 1234.5 s behind the host's, the same rate: 20 messages a second
    # for 30 s, in batches of a second; every tenth delivered at once.
    bus = 1000.0 + 0.05 * np.arange(600)
    host = _deliveries(bus, lambda t: t + 1234.5, rng)
    for i in range(0, 600, 20):
        link.add(bus[i:i + 20], host[i:i + 20])
    assert link.offset_s == pytest.approx(1234.5, abs=1e-9)
    offset, rate, at = link.line()
    assert rate == pytest.approx(0.0, abs=1e-12) and offset == pytest.approx(1234.5, abs=1e-9)
    assert at == 1000.0
    # Receipts without a time, and none at all, change nothing.
    link.add(np.array([1030.0, np.nan]), np.array([np.nan, 5.0]))
    assert link.offset_s == pytest.approx(1234.5, abs=1e-9)


def test_a_clock_link_follows_two_crystals_running_apart():
    from rts_scenario.pipeline import HOST_DRIFT, LINK_BLOCK_S, LINK_BLOCKS, ClockLink

    rng = np.random.default_rng(12)
    # The host's clock runs 150 ppm faster than the interface's: the offset grows 150 us a
    # second. Each block's least lies on that line (its fastest delivery is immediate):
    # the line through them is it, whatever the batches.
    def host_of(t):
        return 7.0 + (t - 500.0) * (1.0 + 150e-6)

    bus = 500.0 + 0.05 * np.arange(1200)  # 60 s
    host = _deliveries(bus, host_of, rng)
    link = ClockLink()
    for i in range(0, 1200, 37):
        link.add(bus[i:i + 37], host[i:i + 37])
    offset, rate, at = link.line()
    assert rate == pytest.approx(150e-6, rel=1e-6)
    assert offset + rate * (bus - at) == pytest.approx(host_of(bus) - bus, abs=1e-9)
    # The recent blocks' least is the offset now, within the drift over the window.
    now = host_of(bus[-1]) - bus[-1]
    assert now - 150e-6 * LINK_BLOCK_S * LINK_BLOCKS <= link.offset_s <= now
    assert ClockLink.error_s == pytest.approx(0.01 + HOST_DRIFT * LINK_BLOCK_S * LINK_BLOCKS)
    # A rate beyond two crystals' tolerance is held to it; over too few blocks there is none.
    fast = ClockLink()
    fast.add(bus, bus + 3.0 + 0.01 * (bus - 500.0))
    assert fast.line()[1] == HOST_DRIFT
    short = ClockLink()
    short.add(bus[:60], host[:60])  # 3 s
    assert short.line()[1] == 0.0


def test_the_report_table_says_how_the_detections_fit_the_cycles_times(tmp_path):
    scene = scene_with_clock(tmp_path, cycle_s=0.05, start_offset_s=0.025, latency_s=0.13,
                             counter_start=0)
    report = run(scene)
    report.radar_clock.update(detection_lag_s=-0.0086, detection_lag_error_s=0.00233)
    assert ("time alignment: the detections fit the scene 8.6 ms (+-7.0 ms) after the cycles' "
            "times") in report.table()
    report.radar_clock.update(detection_lag_s=0.05, detection_lag_error_s=0.001)
    assert "fit the scene 50.0 ms (+-3.0 ms) before" in report.table()
    del report.radar_clock["detection_lag_s"]
    assert "time alignment" not in report.table()


@pytest.mark.parametrize("offset_m", [-0.1, 0.1])
def test_a_range_offset_common_to_all_targets_is_not_taken_for_a_lag(tmp_path, offset_m):
    # A radar in step with the frames (every cycle within the ambiguity window), correcting
    # its range-Doppler coupling, ranging every target 10 cm long or short (the RTS's delay
    # calibration 0.67 ns off): its detections fit the scene at the cycles' times, and the
    # lag's fit has a range offset of its own for just this. Two cars, 2.5 m/s faster and
    # 0.5 m/s slower than the ego: 12.5 cm and 2.5 cm apart between two 50 ms frames.
    scene = slow_chirp_scene(tmp_path, range_doppler_coupling="corrected")
    path = tmp_path / "s.scenario.yaml"
    path.write_text(path.read_text().replace("speed_mps: 17.5", "speed_mps: 19.5"))
    scene = load_scenario(path)

    def shifted(cycle, sink):
        return sink([dataclasses.replace(cycle, range_m=cycle.range_m + offset_m)])

    report = run(scene, tamper=shifted)
    assert report.frames["ambiguous"] > 0.9 * report.frames["checked"]
    lag = report.radar_clock["detection_lag_s"]
    assert abs(lag) < 3.0 * report.radar_clock["detection_lag_error_s"] + 1e-3, lag
    assert report.passed, report.reasons


def test_a_profile_s_cycle_below_a_millisecond_is_bad_input_not_a_log_s(tmp_path):
    # A profile stating a 0.1 ms cycle counted millions of cycles into a scene; a log whose
    # stamps fit a cycle that short is the log's (it fails its check as a clock off its
    # profile), not a crash of a floor meant for profiles.
    from rts_scenario.errors import RtsError
    from rts_scenario.radar import RadarProfile

    data = yaml.safe_load((ROOT / "rts_scenario/data/radars/awr1843boost.radar.yaml")
                          .read_text())
    data["clock"] = {"cycle_s": 0.0001}
    path = tmp_path / "fast.radar.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(RtsError, match=r"clock.cycle_s: .*0\.0001 is less than the minimum of "
                                       r"0\.001|clock\.cycle_s: must be >= 0\.001"):
        RadarProfile.from_file(path)
    assert RadarClock(cycle_s=0.0007).cycle_s == 0.0007  # a fitted cycle is taken


# -- a latency step: the phase is the one most cycles keep ------------------------------------

@pytest.mark.parametrize(("at", "rise"), [(0.3, 0.12), (0.5, 0.12), (0.7, 0.12), (0.3, -0.12),
                                          (0.7, -0.12)])
def test_a_latency_step_leaves_the_phase_of_the_radar_s_own_latency(at, rise):
    # 150 cycles of exactly 50 ms, their messages 100 ms +- 1 ms (uniform) after each (or 220
    # ms, held up), 120 ms later (earlier) from some cycle on. The mean of the bus times less
    # the cycles lies between the two latencies, the phase of no cycle. A message held up
    # only adds latency: the fit takes the lower level, however many cycles keep either, and
    # its error is that of the jitter (0.58 ms / root of that level's cycles), not the step's.
    from rts_scenario.radar.clock import CycleTimeFit

    n = np.arange(4242, 4392)
    rng = np.random.default_rng(1)
    first = int(at * n.size)
    base = 0.1 if rise > 0 else 0.22
    step = rise * (n >= 4242 + first)
    bus = 100.0 + 0.05 * n + base + rng.uniform(-0.001, 0.001, n.size) + step
    fit = CycleTimeFit()
    fit.add(n[:40], bus[:40])
    fit.add(n[40:], bus[40:])
    assert fit.bend().bent
    zero = fit.zero_s(0.05) - 100.0
    assert zero == pytest.approx(0.1, abs=4 * fit.zero_error_s(0.05))
    lower = first if rise > 0 else n.size - first  # the cycles at the lower latency
    assert fit.zero_error_s(0.05) == pytest.approx(
        0.001 / np.sqrt(3) / np.sqrt(lower), rel=0.35)
    flat = CycleTimeFit()
    flat.add(n, bus - step)  # no step: the least-squares intercept, as before
    assert not flat.bend().bent
    assert flat.zero_s(0.05) - 100.0 == pytest.approx(np.mean(bus - step - 0.05 * n) - 100.0,
                                                     abs=1e-9)


def test_a_free_radar_whose_latency_steps_is_checked_at_its_phase(tmp_path):
    # Switched on at 49 ms, the radar measures 1 ms before each frame change; its messages
    # reach the bus 130 ms +- 1 ms later (its profile's latency), 16 ms more from half-way.
    # Its phase (49 ms) is the one most cycles keep: every cycle is judged against the frame
    # it saw, none missing, and the change is reported; the mean of both latencies put it 8 ms
    # late (past the frame change: every cycle judged against the next frame).
    scene, radar = free_radar(tmp_path, 0.05, 0.049, 4242)
    log = tmp_path / "free.blf"
    rng = np.random.default_rng(1)
    report = run_stamped(scene, lambda n: 0.13 + rng.uniform(-0.001, 0.001, n.size)
                         + 0.016 * (n >= 4242 + 120), log, radar)
    assert report.passed, report.reasons
    assert report.radar_clock["start_offset_s"] == pytest.approx(0.049, abs=1e-3)
    assert report.radar_clock["latency_change_s"] == pytest.approx(0.016, abs=2e-3)
    assert report.frames["total"] == report.frames["checked"] == 240
    assert report.frames["missing"] == report.frames["after_scene"] == 0


@pytest.mark.parametrize("from_cycle", [72, 120, 200])
def test_a_radar_whose_latency_rises_by_more_than_a_cycle_did_not_start_late(tmp_path,
                                                                             from_cycle):
    # The radar's count starts with the scene (4242 at 0 s); from some cycle on its messages
    # take 120 ms more. The mean of its bus times lies up to 120 ms late, more than a cycle:
    # a late start by the mean, which it is not; by its own (lowest) latency it started on
    # time, whether the rise came before or after the middle of the run.
    scene = scene_with_clock(tmp_path, cycle_s=0.05, latency_s=0.1, jitter_s=0.002,
                             counter_start=4242)
    rng = np.random.default_rng(1)
    report = run_stamped(scene, lambda n: 0.1 + rng.uniform(-0.001, 0.001, n.size)
                         + 0.12 * (n >= 4242 + from_cycle), tmp_path / "late.blf")
    assert report.passed, report.reasons
    assert report.radar_clock["start_from"] == "profile"
    assert report.frames["total"] == report.frames["checked"] == 240


def test_a_log_whose_latency_steps_is_re_checked_on_the_profile_s_cycle(tmp_path):
    # Without a sidecar the re-check fits a clock to the log's stamps. A latency 11 ms longer
    # from half-way (within the stamps' jumps the profile's 5 ms jitter allows) tilts that
    # fit 0.14 % off the profile, which would judge cycles against the wrong frames; the stamps
    # bend, so the profile's cycle is kept, as live, and its phase is the one most keep.
    scene = scene_with_clock(tmp_path, cycle_s=0.05, latency_s=0.13, jitter_s=0.005,
                             counter_start=4242)
    log = tmp_path / "step.blf"
    rng = np.random.default_rng(2)
    live = run_stamped(scene, lambda n: 0.13 + rng.uniform(-0.001, 0.001, n.size)
                       + 0.011 * (n >= 4242 + 120), log)
    assert live.passed, live.reasons
    Path(str(log) + ".rts.json").unlink()
    result = check_log(scene, log)
    again = result.report
    assert again.passed, again.reasons
    assert result.alignment.cycle_s == 0.05 and result.alignment.cycle_source == "profile"
    assert again.frames["total"] == again.frames["checked"] == 240
    assert again.frames["missing"] == again.frames["after_scene"] == 0
    assert again.radar_clock["latency_change_s"] == pytest.approx(0.011, abs=2e-3)


def test_exact_stamps_with_a_latency_step_give_a_verdict(tmp_path):
    # Stamps exactly on a 40 ms grid (a logger stamping by a cycle counter), 16 ms later from
    # cycle 500: the segments' scatter within is 0 but for rounding (a hair below 0), which
    # must neither empty the level nor divide by zero: the phase is the lower level's.
    from rts_scenario.radar.clock import CycleTimeFit
    from rts_scenario.recheck import _fitted_clock

    n = np.arange(1000)
    bus = 1000.0 + 0.1 + 0.04 * n + 0.016 * (n >= 500)
    fit = CycleTimeFit()
    fit.add(n, bus)
    assert fit.bend().bent
    assert fit.zero_s(0.04) == pytest.approx(1000.1, abs=1e-9)
    assert np.isfinite(fit.zero_error_s(0.04))
    clock, kept = _fitted_clock(n, bus, n % 65536, 0.1, 1000.0, 65536, 0.04)
    assert kept and clock.cycle_s == 0.04
    assert clock.start_offset_s == pytest.approx(0.0, abs=1e-9)
