"""Recording the bus and re-checking logs: the live verdict again, or aligned by timestamps."""

import base64
import dataclasses
import json
import os
import re
import shutil
import subprocess
import sys
import time
import zlib
from dataclasses import replace
from pathlib import Path

import can
import numpy as np
import pytest
import yaml

import rts_scenario.cli as cli
from rts_scenario.canbus import DetectionPublisher
from rts_scenario.detections import Detections
from rts_scenario.kinematics import compute_tracks
from rts_scenario.outputs.radar import SimulatedRadarOutput
from rts_scenario.pipeline import Pipeline, RunOptions, run_scene
from rts_scenario.recheck import LogError, check_log
from rts_scenario.scenario import load_scenario
from rts_scenario.schedule import build_schedule

ROOT = Path(__file__).resolve().parents[1]
CUT_IN = ROOT / "scenarios" / "cut_in.scenario.yaml"
QUIET = {"radar.noise": False, "radar.fidelity": "analytic"}


def biased(cycle: Detections) -> Detections:
    az = None if cycle.az_deg is None else cycle.az_deg + 1.0
    return Detections(cycle=cycle.cycle, t_s=cycle.t_s, range_m=cycle.range_m,
                      radial_velocity_mps=cycle.radial_velocity_mps, az_deg=az,
                      el_deg=cycle.el_deg, snr_db=cycle.snr_db, rcs_dbsm=cycle.rcs_dbsm)


@pytest.mark.parametrize("suffix", [".blf", ".asc", ".csv", ".mf4"])
def test_a_recorded_run_re_checks_to_the_live_verdict(tmp_path, suffix):
    if suffix == ".mf4":
        pytest.importorskip("asammdf")
    scene = load_scenario(CUT_IN, QUIET)
    log = tmp_path / f"run{suffix}"
    live = run_scene(scene, RunOptions(bus_log=str(log))).report
    sidecar = json.loads(Path(str(log) + ".rts.json").read_text())
    assert sidecar["clock"]["counter_start"] == 0 and sidecar["scene"] == scene.name
    again = check_log(scene, log)
    assert again.alignment.source == "sidecar"
    # Judged by the statuses the run played, against the ground truth it played.
    assert again.alignment.statuses == "recorded"
    assert again.alignment.truth_matches_recording is True
    assert again.report.passed == live.passed is True
    assert again.report.frames == live.frames
    for q, stats in live.errors.items():
        assert again.report.errors[q].max == pytest.approx(stats.max, abs=1e-9), q


def test_a_failing_run_re_checks_to_the_same_failure(tmp_path):
    scene = load_scenario(CUT_IN, QUIET)
    log = tmp_path / "biased.blf"
    with Pipeline.for_scene(scene, RunOptions(bus_log=str(log))) as pipeline:
        sink = pipeline.output._sink
        pipeline.output._sink = lambda cycles: sink([biased(c) for c in cycles])
        live = pipeline.run(scene).report
    again = check_log(scene, log).report
    assert not live.passed and not again.passed
    assert again.reasons == live.reasons


def test_a_re_check_judges_cycles_by_the_send_times_of_the_run(tmp_path):
    # Every fourth frame went out 20 ms late, beyond the 5.76 ms ambiguity window: the cycle
    # measured at its time saw the frame before. The sidecar keeps the send times, so the
    # re-check judges each cycle against the frame the run did; without them it could not.
    scene = load_scenario(CUT_IN, QUIET)
    log = tmp_path / "late.blf"
    with Pipeline.for_scene(scene, RunOptions(bus_log=str(log))) as pipeline:
        pipeline.output.sent_t_s = lambda batch: batch.t_s + np.where(
            batch.frame_index % 4 == 1, 0.02, 0.0)
        live = pipeline.run(scene).report
    assert live.playback["lateness_s"]["max"] == pytest.approx(0.02)
    sidecar = json.loads(Path(str(log) + ".rts.json").read_text())
    assert sidecar["send_lateness"]["frames"] == scene.n_frames == 240
    again = check_log(scene, log)
    assert again.report.frames == live.frames and again.report.reasons == live.reasons
    for q, stats in live.errors.items():
        assert again.report.errors[q].max == pytest.approx(stats.max, abs=1e-9), q
    assert not any("nominal times" in note for note in again.alignment.notes)
    # A sidecar without send times (an older version's): judged at the nominal times, and said.
    del sidecar["send_lateness"]
    (tmp_path / "old").mkdir()
    nominal = check_log(scene, _copy(log, tmp_path / "old", json.dumps(sidecar)))
    assert nominal.report.frames["ambiguous"] != live.frames["ambiguous"]
    assert any("judges them at their nominal times" in n for n in nominal.alignment.notes)
    # Send times of another length are not this run's.
    sidecar["send_lateness"] = {**json.loads(Path(str(log) + ".rts.json").read_text())[
        "send_lateness"], "frames": 100}
    with pytest.raises(LogError, match=r"send_lateness: holds 240 frames \(says 100\), the "
                                       r"scene has 240"):
        check_log(scene, _copy(log, tmp_path / "old", json.dumps(sidecar)))
    # A frame sent before its time: the run writes none (its lateness is clipped at 0).
    early = np.zeros(240, dtype="<i4")
    early[7] = -1_000_000_000
    sidecar["send_lateness"] = {**sidecar["send_lateness"], "frames": 240, "data": base64.b64encode(
        zlib.compress(early.tobytes())).decode()}
    with pytest.raises(LogError, match=r"send_lateness: frame 7 went out 1000 s before its "
                                       r"time: a run writes every frame's lateness as 0 or more"):
        check_log(scene, _copy(log, tmp_path / "old", json.dumps(sidecar)))


def test_a_re_check_judges_cycles_against_the_frames_of_a_run_whose_frames_went_out_late_by_ns(
        tmp_path):
    # A paced UDP sender puts every frame out some tens of nanoseconds after its time: a radar
    # in step with the frames measured each cycle just before the frame change, so the run
    # judged it against the frame before. The sidecar's send times must keep that order.
    scene = load_scenario(CUT_IN, QUIET)
    log = tmp_path / "udp.blf"
    with Pipeline.for_scene(scene, RunOptions(bus_log=str(log))) as pipeline:
        pipeline.output.sent_t_s = lambda batch: batch.t_s + 40e-9
        live = pipeline.run(scene).report
    again = check_log(scene, log).report
    assert again.frames == live.frames and again.reasons == live.reasons
    for q, stats in live.errors.items():
        assert again.errors[q].rms == pytest.approx(stats.rms, abs=1e-9), q
        assert again.errors[q].max == pytest.approx(stats.max, abs=1e-9), q


def write_radar(folder: Path, **clock) -> str:
    data = yaml.safe_load((ROOT / "rts_scenario/data/radars/awr1843boost.radar.yaml")
                          .read_text())
    data["name"] = "own-clock"
    data["clock"] = clock
    (folder / "radars").mkdir(exist_ok=True)
    (folder / "radars" / "own.radar.yaml").write_text(yaml.safe_dump(data))
    return "radars/own.radar.yaml"


OWN_CLOCK = {"cycle_s": 0.072, "start_offset_s": 0.013, "latency_s": 0.13, "jitter_s": 0.004,
             "counter_start": 4242}


def foreign_log(tmp_path: Path, origin_s: float, seed: int = 0, tamper=None, suffix=".blf",
                busy=False, lead_s=0.0, clock=None, tail_cycles=0):
    """A log as another tool writes it: the radar on its own clock (``clock``, default
    `OWN_CLOCK`), timestamps in that tool's time base (scene time 0 at ``origin_s``), latency
    and jitter on every cycle, no sidecar; ``tail_cycles`` more cycles after the scene (empty,
    as ``tamper`` makes them)."""
    shutil.copy(CUT_IN, tmp_path / "cut_in.scenario.yaml")
    radar = write_radar(tmp_path, **(clock or OWN_CLOCK))
    scene = load_scenario(tmp_path / "cut_in.scenario.yaml",
                          {"radar.profile": radar, "radar.noise": True,
                           "radar.fidelity": "analytic",
                           "expectations.expected_limits": ["frame_rate_above_radar"]})
    messages: list[can.Message] = []
    stamp = {"t": 0.0}

    class Recorder:  # what a logging tool sees on the bus
        def send(self, msg):
            msg.timestamp = stamp["t"]
            messages.append(msg)

    publisher = DetectionPublisher(Recorder())
    rng = np.random.default_rng(seed)
    clock = scene.radar.radar_clock

    last = []

    def sink(cycles):
        for cycle in cycles:
            stamp["t"] = origin_s + cycle.t_s + clock.latency_s + rng.uniform(-clock.jitter_s,
                                                                              clock.jitter_s)
            publisher.publish(tamper(cycle) if tamper else cycle)
            last[:] = [cycle]

    # The radar ran before the RTS played the scene: empty cycles, counters before 4242.
    for n in range(-int(lead_s / clock.cycle_s), 0):
        t = clock.start_offset_s + n * clock.cycle_s
        stamp["t"] = origin_s + t + clock.latency_s
        publisher.publish(Detections.empty(clock.counter_start + n, t))
    radar = SimulatedRadarOutput(profile=scene.radar, rig=scene.rig, sink=sink,
                                 fidelity="analytic", noise=True, rng=rng)
    radar.write(build_schedule(compute_tracks(scene), scene.rig, scene.radar,
                               frame_rate_hz=scene.frame_rate_hz))
    radar.close()
    for j in range(1, tail_cycles + 1):  # the log goes on after the scene
        t = last[0].t_s + j * clock.cycle_s
        stamp["t"] = origin_s + t + clock.latency_s
        empty = Detections.empty(last[0].cycle + j, t)
        publisher.publish(tamper(empty) if tamper else empty)
    if busy:
        # A real bus: the logger started inside a cycle (detections before the first header)
        # and other ECUs talk in between.
        tail = [can.Message(arbitration_id=m.arbitration_id, data=m.data,
                            timestamp=messages[0].timestamp - 0.01, is_extended_id=False)
                for m in messages[1:4]]
        chatter = [can.Message(arbitration_id=0x3F0 + i % 3, data=bytes([i % 256] * 8),
                               timestamp=messages[0].timestamp + 0.001 * i,
                               is_extended_id=False) for i in range(0, 12000, 7)]
        messages = sorted(tail + messages + chatter, key=lambda m: m.timestamp)
    log = tmp_path / f"other{suffix}"
    with can.Logger(str(log)) as writer:
        for msg in messages:
            writer.on_message_received(msg)
    # Some formats keep times relative to the log's start (ASC): scene time 0 in the log's
    # own time base.
    with can.LogReader(str(log)) as reader:
        first_read = next(iter(reader)).timestamp
    return scene, log, origin_s - messages[0].timestamp + first_read


@pytest.mark.parametrize(("seed", "suffix", "busy"), [(0, ".blf", False), (1, ".asc", True),
                                                     (2, ".csv", False), (3, ".mf4", True)])
def test_a_log_of_another_tool_is_aligned_within_20_ms(tmp_path, seed, suffix, busy):
    if suffix == ".mf4":
        pytest.importorskip("asammdf")
    origin = 1.7e9 + 1000.0 * np.random.default_rng(seed).random()
    scene, log, origin = foreign_log(tmp_path, origin, seed, suffix=suffix, busy=busy)
    result = check_log(scene, log)
    a = result.alignment
    assert a.source == "estimated"
    assert abs(a.offset_s - origin) <= 0.020
    assert a.uncertainty_s is not None and abs(a.offset_s - origin) <= 5 * a.uncertainty_s + 2e-3
    assert a.cycle_s == pytest.approx(0.072, abs=1e-4)
    assert result.report.passed, result.report.reasons
    assert result.report.frames["missing"] == 0
    # That the scene is the one played rests on the estimate alone: said.
    span_ms = (a.plateau_s + a.uncertainty_s) * 1e3
    assert (f"no sidecar ({log.name}.rts.json): scene time 0 is estimated from the detections "
            f"themselves, so a scene that differs from the one played by its targets' motion "
            f"over {span_ms:.1f} ms") in a.notes[0]
    if busy:
        assert result.report.bus["unknown_ids"] > 1000
        assert result.report.bus["before_first_cycle"] >= 2  # the cycle the log began in


@pytest.mark.parametrize("seed", range(3))
def test_a_log_without_sidecar_keeps_the_profile_s_cycle_its_stamps_cannot_tell_from(tmp_path,
                                                                                    seed):
    # A radar on its profile's 72 ms cycle, its stamps +-4 ms about its latency: the cycle
    # fitted to them is off the profile's by noise (a standard error of 4 us over 167
    # cycles), which a check by it would carry into every cycle's time. Within three standard
    # errors, the profile's cycle is kept, exactly; a radar 2000 ppm off it is the stamps'.
    origin = 1.7e9 + 55.5
    scene, log, _ = foreign_log(tmp_path, origin, seed)
    result = check_log(scene, log)
    assert result.alignment.cycle_s == 0.072
    assert result.report.radar_clock["cycle_s"] == 0.072
    assert result.alignment.cycle_source == "profile"
    assert ("cycle 72.00 ms (profile; the timestamps cannot tell another)"
            in result.alignment.describe())
    assert result.report.passed, result.report.reasons
    (tmp_path / "off").mkdir()
    _, log, _ = foreign_log(tmp_path / "off", origin, seed, clock={**OWN_CLOCK,
                                                                   "cycle_s": 0.072144})
    result = check_log(scene, log)
    assert result.alignment.cycle_s == pytest.approx(0.072144, abs=1.5e-5)
    assert result.alignment.cycle_source == "fitted"
    assert "ms fitted" in result.alignment.describe()


def test_a_long_log_is_aligned_by_where_its_detections_begin(tmp_path):
    # Ten minutes of radar cycles before the scene: too long to try every offset, the search
    # starts where the first detections put the scene's first visible target.
    scene, log, origin = foreign_log(tmp_path, 1.7e9 + 77.7, lead_s=600.0)
    result = check_log(scene, log)
    assert abs(result.alignment.offset_s - origin) <= 0.020
    assert result.report.passed, result.report.reasons
    assert result.alignment.cycles_outside_scene >= 8000


def test_a_given_time_offset_tells_the_latency(tmp_path):
    scene, log, origin = foreign_log(tmp_path, 1.7e9 + 55.5)
    right = check_log(scene, log, time_offset_s=origin)
    assert right.alignment.source == "given" and right.report.passed
    # Given the scene's start, the data tell the radar's latency (130 ms +- 4 ms jitter).
    assert right.alignment.latency_source == "estimated"
    assert right.alignment.latency_s == pytest.approx(0.13, abs=0.01)
    assert right.alignment.latency_uncertainty_s is not None
    # An offset too late makes the radar report before it measured: refused.
    with pytest.raises(LogError, match="before the radar measured them"):
        check_log(scene, log, time_offset_s=origin + 0.6)
    # One too early shows as a latency far from the radar's profile: more than half a frame
    # off it, it fails, as live (it passed with a note).
    early = check_log(scene, log, time_offset_s=origin - 0.6)
    assert early.alignment.latency_s == pytest.approx(0.73, abs=0.01)
    assert any("differs from its profile's 130.0 ms" in n for n in early.alignment.notes)
    assert not early.report.passed
    assert "time_alignment" in early.report.reason_codes
    # The threshold it states is the one applied: half a frame beyond what the data leave
    # open (it said "half a frame apart", and passed 31 ms off).
    assert any(re.match(r"time_alignment: given the scene's start, .*, give or take "
                        r"\d+\.\d ms\), its profile's 130\.0 ms: more than half a frame "
                        r"\(25 ms\) beyond that apart", r) for r in early.report.reasons)
    # One in another time base (seconds since the logger started, for epoch timestamps) would
    # make the radar report decades late: refused, naming the log's time base.
    with pytest.raises(LogError, match=r"--time-offset-s 5\.000000: .*\(at most 5 s\); give the "
                                       r"scene's start in the log's time base \(its first cycle "
                                       r"is at 1700000055\.\d+ s\)"):
        check_log(scene, log, time_offset_s=5.0)


class Stale:
    """A radar reporting in each cycle what it measured ``k`` cycles before."""

    def __init__(self, k):
        self.k, self.seen = k, []

    def __call__(self, cycle):
        self.seen.append(cycle)
        old = (self.seen[-1 - self.k] if len(self.seen) > self.k
               else Detections.empty(cycle.cycle, cycle.t_s))
        return dataclasses.replace(old, cycle=cycle.cycle, t_s=cycle.t_s)


def test_a_log_without_sidecar_is_judged_from_the_count_the_radar_restarts_at(tmp_path):
    # A radar 10 cycles late (720 ms beyond its profile's latency), its log going on for 10
    # cycles after the scene: without the sidecar the scene's start was estimated from the
    # detections alone, 10 cycles after the radar's count restarted, where everything fitted,
    # and the run passed. Its first cycle carries the count the profile says the radar
    # restarts at with the scene: the cycles are judged from there, and the contradiction fails.
    scene, log, origin = foreign_log(tmp_path, 1.7e9 + 77.0, tamper=Stale(10), tail_cycles=10)
    result = check_log(scene, log)
    assert not result.report.passed
    reasons = " ".join(result.report.reasons)
    assert re.search(r"the log's first cycle carries the count the radar restarts at with the "
                     r"scene \(4242, its profile's\), but the detections fit the scene only 10 "
                     r"cycles \(7[12]\d ms\) later, beyond the estimate's span", reasons), reasons
    assert result.report.radar_clock["counter_start"] == 4242
    assert abs(result.alignment.offset_s - origin) <= 0.02
    assert result.report.frames["missing"] == 0
    # An on-time radar's log with the same tail: no reason of the count's.
    scene, log, origin = foreign_log(tmp_path, 1.7e9 + 77.0, tail_cycles=10)
    result = check_log(scene, log)
    assert result.report.passed, result.report.reasons
    assert abs(result.alignment.offset_s - origin) <= 0.02


def test_a_biased_radar_in_another_tool_s_log_fails(tmp_path):
    scene, log, _ = foreign_log(tmp_path, 1.7e9, tamper=biased)
    result = check_log(scene, log)
    assert not result.report.passed
    assert any("detection rate" in r for r in result.report.reasons)


def test_check_command_writes_the_report_and_the_alignment(tmp_path, capsys):
    scene = ROOT / "scenarios" / "highway_following.scenario.yaml"
    log = tmp_path / "run.blf"
    assert cli.main(["run", str(scene), "--record", str(log)]) == 0
    out = tmp_path / "check.json"
    assert cli.main(["check", str(scene), "--log", str(log), "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["status"] == "pass" and data["alignment"]["source"] == "sidecar"
    assert data["log"] == str(log) and data["variant"] == "" and data["parameters"] == {}
    text = capsys.readouterr().out
    assert "aligned by the recording's sidecar" in text and "PASS" in text



def test_a_recording_s_sidecar_is_whole_or_absent(tmp_path, capsys, cut_short_drafts):
    scene = ROOT / "scenarios" / "gantry_stopped_car.scenario.yaml"
    log = tmp_path / "run.blf"
    sidecar = Path(f"{log}.rts.json")
    assert cli.main(["run", str(scene), "--record", str(log)]) == 0
    text = sidecar.read_text()
    assert text == json.dumps(json.loads(text), indent=2, allow_nan=False) + "\n"
    # A disk that fills as the sidecar is written: no half sidecar beside the log, which a
    # re-check would take for a damaged one (the earlier recording's goes as the run starts).
    cut_short_drafts(OSError(28, "No space left on device"))
    assert cli.main(["run", str(scene), "--record", str(log)]) == 3
    assert "No space left on device" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.blf"]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A recording of the highway-following scene by `run --record`, with its sidecar."""
    folder = tmp_path_factory.mktemp("recorded")
    log = folder / "run.blf"
    assert cli.main(["run", str(ROOT / "scenarios" / "highway_following.scenario.yaml"),
                     "--record", str(log)]) == 0
    return log


def _copy(log: Path, folder: Path, sidecar: str | None = None) -> Path:
    copy = folder / log.name
    shutil.copy(log, copy)
    text = Path(str(log) + ".rts.json").read_text() if sidecar is None else sidecar
    Path(str(copy) + ".rts.json").write_text(text)
    return copy


@pytest.mark.parametrize("edit, message", [
    (lambda d: [], r"\(the document\): \[\] is not of type 'object'"),
    (lambda d: {**d, "clock": {**d["clock"], "cycle_s": 0}},
     r"clock\.cycle_s: 0 is less than the minimum of 0\.001"),
    (lambda d: {**d, "clock": {**d["clock"], "cycle_s": "x"}},
     r"clock\.cycle_s: 'x' is not of type 'number'"),
    (lambda d: {**d, "clock": {**d["clock"], "latency_s": -0.05}},
     r"clock\.latency_s: -0\.05 is less than the minimum of 0"),
    (lambda d: {k: v for k, v in d.items() if k != "clock"}, r"\(the document\): 'clock' is a"),
    (lambda d: {**d, "clock": {**d["clock"], "start_offset_s": -1.0}},
     r"clock\.start_offset_s: -1 s, a cycle or more before the scene's start \(allowed: "
     r"above -0\.05"),
    (lambda d: {**d, "clock": {**d["clock"], "jitter_s": 5.0}},
     r"clock\.jitter_s: must not exceed latency_s \(0\), got 5"),
    (lambda d: {**d, "method": "bogus"},
     r"method: got 'bogus'; allowed values: exact, paper, estimator"),
    # The run judged 400 cycles of 50 ms in 20 s: 3 would pass on 150 ms of the scene, and
    # 10**30 is a runtime error.
    (lambda d: {**d, "clock": {**d["clock"], "cycles": 3}},
     r"clock\.cycles: 3, but cycles of 50 ms from 0 s put 400 in the scene's 20 s \(allowed: "
     r"399 to 401\)"),
    (lambda d: {**d, "clock": {**d["clock"], "cycles": 10**30}}, r"clock\.cycles: 10+, but"),
    # A cycle of a nanosecond counted billions of cycles into the scene: a MemoryError.
    (lambda d: {**d, "clock": {**d["clock"], "cycle_s": 1e-9}},
     r"clock\.cycle_s: 1e-09 is less than the minimum of 0\.001"),
    # Beyond what the 16-bit counter counts: 10**30 was a runtime error.
    (lambda d: {**d, "clock": {**d["clock"], "counter_start": 10**30}},
     r"clock\.counter_start: 10+, beyond what the radar's 16-bit counter counts \(allowed: 0 "
     r"to 65535, or null\)"),
    (lambda d: {**d, "clock": {**d["clock"], "counter_start": 65536}},
     r"clock\.counter_start: 65536, beyond"),
    # How much earlier than the clock's times the cycles may have been measured: a delivery
    # delay, at most the 0.25 s beyond which receipts are not deliveries; 1e300 was a runtime
    # error, 5 s moved the scene's first cycle 100 cycles on.
    (lambda d: {**d, "clock": {**d["clock"], "early_s": -0.01}},
     r"clock\.early_s: -0\.01 is less than the minimum of 0"),
    (lambda d: {**d, "clock": {**d["clock"], "early_s": 1e300}},
     r"clock\.early_s: 1e\+300 is greater than the maximum of 0\.25"),
    (lambda d: {**d, "clock": {**d["clock"], "early_s": 5.0}},
     r"clock\.early_s: 5\.0 is greater than the maximum of 0\.25"),
    (lambda d: {**d, "clock": {**d["clock"], "early_s": "x"}},
     r"clock\.early_s: 'x' is not of type 'number'"),
    # The run's playback, which the re-check fails on as the run did: each was a runtime error.
    (lambda d: {**d, "playback": {"lateness_s": 5}},
     r"playback: 'frames_sent' is a required property"),
    (lambda d: {**d, "playback": {**d["playback"], "late_frames": "x"}},
     r"playback\.late_frames: 'x' is not of type 'integer'"),
    (lambda d: {**d, "playback": {**d["playback"], "rts": {"lost_frames": "a"}}},
     r"playback\.rts\.lost_frames: 'a' is not of type 'integer'"),
    (lambda d: {**d, "playback": {**d["playback"], "ambiguity_window_s": "x"}},
     r"playback\.ambiguity_window_s: 'x' is not of type 'number'"),
    # What the run played: each would have judged another scene, or raised.
    (lambda d: {**d, "statuses": {**d["statuses"], "frames": 399}},
     r"statuses: holds 399 frames of 2 targets, the scene has 400 of 2"),
    (lambda d: {**d, "statuses": {**d["statuses"], "data": "AAAA"}},
     r"statuses: data: not zlib-compressed"),
    (lambda d: {**d, "statuses": {**d["statuses"], "data": "%%"}}, r"statuses: data: not base64"),
    (lambda d: {**d, "statuses": {**d["statuses"], "encoding": "raw"}},
     r"statuses\.encoding: 'uint16 little-endian .*' was expected"),
    (lambda d: {**d, "truth": {**d["truth"], "targets": {"lead-car": "12"}}},
     r"truth\.targets\.lead-car: '12' does not match"),
    # Written together: statuses without the truth's checksums is a damaged sidecar, not an
    # older one (which keeps neither); judged, the scene would go unchecked with a note.
    (lambda d: {k: v for k, v in d.items() if k != "truth"},
     r"truth: missing, but the sidecar keeps the statuses written with it"),
    (lambda d: {**d, "truth": None},
     r"truth: missing, but the sidecar keeps the statuses written with it"),
    # Bus times and clock steps of 10**300 s: a numpy overflow on standard error and a reason
    # printing a 300-digit number; the check that refuses another run's log was skipped.
    (lambda d: {**d, "clock": {**d["clock"], "origin_bus_s": 1e308}},
     r"clock\.origin_bus_s: 1e\+308 is greater than the maximum of 10000000000"),
    (lambda d: {**d, "clock": {**d["clock"], "bus_time_shifts": [
        {"bus_s": 1.0, "counter": 3, "shift_s": 1e300}]}},
     r"clock\.bus_time_shifts\.0\.shift_s: 1e\+300 is greater than the maximum"),
])
def test_a_malformed_sidecar_is_bad_input_naming_the_key(recorded, tmp_path, capsys, edit,
                                                         message):
    data = json.loads(Path(str(recorded) + ".rts.json").read_text())
    log = _copy(recorded, tmp_path, json.dumps(edit(data)))
    scene = str(ROOT / "scenarios" / "highway_following.scenario.yaml")
    assert cli.main(["check", scene, "--log", str(log)]) == 2
    err = capsys.readouterr().err
    assert err.count("error:") == 1 and "Traceback" not in err
    assert f"{log}.rts.json: " in err
    assert re.search(message, err), err


def test_a_sidecar_without_playback_says_what_is_not_judged(recorded, tmp_path):
    # Frames sent late, or lost by the RTS, fail a re-check as they failed the run: a sidecar
    # without the run's playback passed without a word that none of it was judged.
    data = json.loads(Path(str(recorded) + ".rts.json").read_text())
    scene = load_scenario(ROOT / "scenarios" / "highway_following.scenario.yaml")
    assert not any("no playback" in n for n in check_log(scene, recorded).alignment.notes)
    log = _copy(recorded, tmp_path, json.dumps({**data, "playback": None}))
    assert ("the sidecar records no playback: frames the run sent late, or the RTS lost, are "
            "not judged") in check_log(scene, log).alignment.notes


def test_a_log_recorded_with_another_radar_is_refused(recorded, tmp_path, capsys):
    # Another radar's array, field of view and clock: it re-checked silently.
    data = json.loads(Path(str(recorded) + ".rts.json").read_text())
    log = _copy(recorded, tmp_path, json.dumps({**data, "radar": "another-radar"}))
    scene = str(ROOT / "scenarios" / "highway_following.scenario.yaml")
    assert cli.main(["check", scene, "--log", str(log)]) == 2
    err = capsys.readouterr().err
    assert err == (f"error: --log {log}: recorded with radar 'another-radar' (its sidecar), not "
                   f"the scene's '{data['radar']}': another radar's array, field of view and "
                   f"clock judge other detections; check the log against the scene file and "
                   f"radar profile it was played with\n")


def test_a_sidecar_with_nan_is_bad_input(recorded, tmp_path, capsys):
    text = Path(str(recorded) + ".rts.json").read_text()
    log = _copy(recorded, tmp_path, text.replace('"jitter_s": 0.0', '"jitter_s": NaN'))
    scene = str(ROOT / "scenarios" / "highway_following.scenario.yaml")
    assert cli.main(["check", scene, "--log", str(log)]) == 2
    assert "NaN is not a number a sidecar holds" in capsys.readouterr().err


def test_a_log_of_another_scene_or_a_time_offset_beside_the_sidecar_is_refused(recorded,
                                                                               capsys):
    other = str(ROOT / "scenarios" / "cut_out.scenario.yaml")
    assert cli.main(["check", other, "--log", str(recorded)]) == 2
    assert "recorded for scene 'highway-following' (its sidecar), not 'cut-out'" in \
        capsys.readouterr().err
    scene = str(ROOT / "scenarios" / "highway_following.scenario.yaml")
    assert cli.main(["check", scene, "--log", str(recorded), "--time-offset-s", "1e9"]) == 2
    assert "the log's sidecar aligns it by the radar's counters" in capsys.readouterr().err


@pytest.mark.parametrize("variant", [None, "estimator=ti"])
def test_a_log_of_another_scene_is_refused_naming_the_scenes_not_the_variants(recorded, capsys,
                                                                             variant):
    # A parametrized scene given a log of a scene without parametrize (the wrong scene file
    # on the command line): the sidecar names the scene it was recorded for, and that is the
    # mistake to name, not a variant the scene lacks.
    cut_in = str(CUT_IN)
    assert cli.main(["check", cut_in, "--log", str(recorded),
                     *(["--variant", variant] if variant else [])]) == 2
    assert capsys.readouterr().err == (
        f"error: --log {recorded}: recorded for scene 'highway-following' (its sidecar), not "
        f"'cut-in': check it against that scene's file\n")


@pytest.mark.parametrize("send_times", [True, False], ids=["sidecar", "older-sidecar"])
def test_a_scene_of_other_frames_than_the_recording_is_refused(recorded, tmp_path, capsys,
                                                               send_times):
    # The scene file was edited since the recording (here 20 s -> 15 s): it is not the scene
    # that was played, with or without the send times in the sidecar.
    data = json.loads(Path(str(recorded) + ".rts.json").read_text())
    if not send_times:
        del data["send_lateness"]
    log = _copy(recorded, tmp_path, json.dumps(data))
    text = (ROOT / "scenarios" / "highway_following.scenario.yaml").read_text()
    shorter = tmp_path / "highway_following.scenario.yaml"
    shorter.write_text(re.sub(r"(?m)^duration_s: .*$", "duration_s: 15.0", text))
    assert cli.main(["check", str(shorter), "--log", str(log)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"error: {log}.rts.json: frames: the recording played {data['frames']} "
                   f"frames, the scene {shorter} has 300: not the scene file that was "
                   f"recorded (edited since?)")


def test_a_re_check_fails_on_the_playback_the_run_failed_on(recorded, tmp_path, capsys):
    # The run's playback (frames the RTS reported lost, frames sent late) is in the sidecar:
    # the re-check of its log fails on it as the run would have.
    data = json.loads(Path(str(recorded) + ".rts.json").read_text())
    assert data["playback"]["frames_sent"] == 400 and data["playback"]["late_frames"] == 0
    data["playback"]["rts"] = {"lost_frames": 3, "unsynced_frames": 0, "corrupted": 0}
    log = _copy(recorded, tmp_path, json.dumps(data))
    scene = str(ROOT / "scenarios" / "highway_following.scenario.yaml")
    assert cli.main(["check", scene, "--log", str(log)]) == 1
    assert "frames_lost: the RTS reports 3 schedule frames it did not apply" in \
        capsys.readouterr().out
    assert cli.main(["check", scene, "--log", str(recorded)]) == 0
    # Datagrams that came back undelivered: frames the RTS never played.
    data["playback"]["rts"] = None
    data["playback"]["rts_unreachable"] = {"address": "127.0.0.1:5006", "datagrams": 40,
                                           "error": "Connection refused", "first_s": 0.0,
                                           "last_s": 1.95}
    log = _copy(recorded, tmp_path, json.dumps(data))
    assert cli.main(["check", scene, "--log", str(log)]) == 1
    assert ("rts_unreachable: 40 datagrams to udp://127.0.0.1:5006 came back undelivered "
            "(Connection refused) from 0.00 s to 1.95 s of the scene") in capsys.readouterr().out
    del data["playback"]["rts_unreachable"]["address"]  # not one a run writes
    log = _copy(recorded, tmp_path, json.dumps(data))
    assert cli.main(["check", scene, "--log", str(log)]) == 2
    assert "rts_unreachable" in capsys.readouterr().err

def test_a_re_check_says_the_playback_limits_the_run_did_not_hit(tmp_path):
    # The scene expects frames sent late and frames lost; the run (in-process, every frame at
    # its time) sent none late: the re-check says so, as the run did. Where the sidecar holds
    # an RTS's counters with nothing lost, frames_lost is said not hit too.
    data = yaml.safe_load(CUT_IN.read_text())
    data["expectations"]["expected_limits"] = sorted(
        {*data["expectations"].get("expected_limits", []), "frames_sent_late", "frames_lost"})
    shutil.copy(CUT_IN, tmp_path / "scene.scenario.yaml")
    (tmp_path / "scene.scenario.yaml").write_text(yaml.safe_dump(data))
    scene = load_scenario(tmp_path / "scene.scenario.yaml", QUIET)
    log = tmp_path / "run.blf"
    live = run_scene(scene, RunOptions(bus_log=str(log))).report
    assert "frames_sent_late" in live.expected_not_hit
    assert "frames_lost" not in live.expected_not_hit  # no RTS counters: not told
    again = check_log(scene, log).report
    assert again.expected_not_hit == live.expected_not_hit
    sidecar = json.loads(Path(str(log) + ".rts.json").read_text())
    sidecar["playback"]["rts"] = {"lost_frames": 0, "unsynced_frames": 0, "corrupted": 0}
    Path(str(log) + ".rts.json").write_text(json.dumps(sidecar))
    again = check_log(scene, log).report
    assert again.passed
    assert {"frames_lost", "frames_sent_late"} <= set(again.expected_not_hit)


@pytest.mark.parametrize("edit, target", [
    # 2 cm further ahead: within every tolerance, so the log would pass against it.
    (("position_m: [50.0, 3.5, 1.2]", "position_m: [50.02, 3.5, 1.2]"), "'truck-left'"),
    (("rcs_dbsm: 10.0, fluctuation", "rcs_dbsm: 10.5, fluctuation"), "'lead-car'"),
    (("name: lead-car", "name: leading-car"),
     "'leading-car' (not in the recording) and 'lead-car' (not in the scene)"),
])
def test_a_scene_edited_since_the_recording_fails_its_re_check_naming_the_target(
        recorded, tmp_path, capsys, edit, target):
    # The RTS played the scene as it was; judged against the edited file, the log would be
    # judged against a scene that never played.
    text = (ROOT / "scenarios" / "highway_following.scenario.yaml").read_text()
    edited = tmp_path / "highway_following.scenario.yaml"
    assert edit[0] in text
    edited.write_text(text.replace(*edit))
    out = tmp_path / "r.json"
    assert cli.main(["check", str(edited), "--log", str(recorded), "--json", str(out)]) == 1
    assert (f"scene: the ground truth of {target} differs from the one the recorded run "
            f"played") in capsys.readouterr().out
    data = json.loads(out.read_text())
    assert data["status"] == "fail" and data["alignment"]["truth_matches_recording"] is False


def test_an_edit_that_leaves_the_ground_truth_alone_re_checks_as_recorded(recorded, tmp_path):
    # New expectations judge the same log again: the truth is the one that played.
    text = (ROOT / "scenarios" / "highway_following.scenario.yaml").read_text()
    edited = tmp_path / "highway_following.scenario.yaml"
    edited.write_text(text.replace("detection_rate: 0.9", "detection_rate: 0.8")
                      .replace("slowly closes the gap", "closes the gap slowly"))
    again = check_log(load_scenario(edited), recorded)
    assert again.report.passed and again.alignment.truth_matches_recording is True
    assert not again.alignment.notes


def test_a_re_check_judges_by_the_statuses_the_run_played_not_a_rebuilt_schedule(
        recorded, tmp_path, monkeypatch):
    import rts_scenario.preflight as preflight
    from rts_scenario.schedule.model import Status

    scene_file = ROOT / "scenarios" / "highway_following.scenario.yaml"
    before = check_log(load_scenario(scene_file), recorded).report
    assert before.passed and before.frames["checked"] == 400

    # A version whose schedule would keep every target out (as a coverage edge moved by a
    # rounding does to a few target-frames): the run's statuses still say what played.
    build = preflight.build_schedule

    def out_of_coverage(*args, **kwargs):
        schedule = build(*args, **kwargs)
        return replace(schedule, status=schedule.status | np.uint16(Status.OUT_OF_COVERAGE))

    monkeypatch.setattr(preflight, "build_schedule", out_of_coverage)
    again = check_log(load_scenario(scene_file), recorded)
    assert again.alignment.statuses == "recorded"
    assert again.report.passed and again.report.frames == before.frames

    # A sidecar of an older version keeps no statuses: the rebuilt schedule judges, and the
    # re-check says it differs from the one recorded.
    data = json.loads(Path(str(recorded) + ".rts.json").read_text())
    del data["statuses"], data["truth"]
    older = check_log(load_scenario(scene_file), _copy(recorded, tmp_path, json.dumps(data)))
    assert older.alignment.statuses == "rebuilt"
    assert older.alignment.schedule_matches_recording is False
    assert not older.report.passed
    assert any("keeps no checksum of the ground truth" in n for n in older.alignment.notes)


def test_a_simulated_run_stamps_its_messages_on_the_radar_s_clock(tmp_path):
    # The in-process radar's messages carry when the radar would have sent them, so a
    # recording of it is a realistic log even without its sidecar.
    shutil.copy(CUT_IN, tmp_path / "cut_in.scenario.yaml")
    radar = write_radar(tmp_path, cycle_s=0.072, start_offset_s=0.013, latency_s=0.13,
                        jitter_s=0.004, counter_start=4242)
    scene = load_scenario(tmp_path / "cut_in.scenario.yaml", {
        "radar.profile": radar, "radar.noise": True,
        "expectations.expected_limits": ["frame_rate_above_radar"]})
    log = tmp_path / "sim.blf"
    assert run_scene(scene, RunOptions(bus_log=str(log))).report.passed
    Path(str(log) + ".rts.json").unlink()
    with can.LogReader(str(log)) as reader:
        headers = [m.timestamp for m in reader if m.arbitration_id == 256]
    gaps = np.diff(headers)
    assert np.median(gaps) == pytest.approx(0.072, abs=0.001)
    assert np.all(np.abs(gaps - 0.072) <= 0.008 + 1e-6)  # +-4 ms of jitter on each
    result = check_log(scene, log)
    origin = headers[0] - 0.013 - 0.13  # within the first cycle's jitter
    assert abs(result.alignment.offset_s - origin) <= 0.020
    assert result.report.passed


def radar_cycles(log: Path) -> list[list[can.Message]]:
    """The log's messages, one list per radar cycle (its header first)."""
    with can.LogReader(str(log)) as reader:
        messages = list(reader)
    cycles: list[list[can.Message]] = []
    for msg in messages:
        if msg.arbitration_id == 256:
            cycles.append([msg])
        elif cycles:
            cycles[-1].append(msg)
    return cycles


def write_log(path: Path, cycles: list[list[can.Message]]) -> Path:
    with can.Logger(str(path)) as writer:
        for cycle in cycles:
            for msg in cycle:
                writer.on_message_received(msg)
    return path


@pytest.fixture(scope="module")
def desk_log(tmp_path_factory) -> tuple[object, Path, float]:
    """A desk recording of the cut-in scene without its sidecar, and its scene start.

    The built-in radar measures every 50 ms from the scene's start, in step with the frames,
    and reports at once: the first header's stamp is the log time of scene time 0. Tests only
    read it (what they change, they write to a log of their own).
    """
    scene = load_scenario(CUT_IN, QUIET)
    log = tmp_path_factory.mktemp("desk") / "desk.blf"
    assert run_scene(scene, RunOptions(bus_log=str(log))).report.passed
    Path(str(log) + ".rts.json").unlink()
    return scene, log, radar_cycles(log)[0][0].timestamp


def test_a_log_holding_two_runs_is_refused_naming_where_each_starts(tmp_path):
    # A logger left running over two runs of the scene: the radar's count starts at its
    # profile's 4242 twice. Judged as one run, its reasons were about the other's cycles.
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    scene, first, _ = foreign_log(tmp_path / "a", 1.7e9 + 100.0)
    _, second, _ = foreign_log(tmp_path / "b", 1.7e9 + 120.0, seed=1)
    messages = []
    for log in (first, second):
        with can.LogReader(str(log)) as reader:
            messages += list(reader)
    both = write_log(tmp_path / "both.blf", [messages])
    assert check_log(scene, first).report.passed
    starts = [m.timestamp for m in messages if m.arbitration_id == 256
              and int.from_bytes(m.data[:2], "little") == 4242]
    assert len(starts) == 2
    with pytest.raises(LogError, match=rf"the radar's count starts at its profile's "
                                       rf"counter_start \(4242\) 2 times \(log times "
                                       rf"{starts[0]:.3f}, {starts[1]:.3f} s\): the log holds 2 "
                                       rf"runs"):
        check_log(scene, both)


@pytest.mark.parametrize(("gap", "az_off_deg"), [(972, 0.0), (5556, 2.0)])
def test_a_log_holding_two_plays_for_a_free_radar_is_refused_naming_where_each_starts(
        tmp_path, gap, az_off_deg):
    # A logger left running over two plays of the scene, the radar counting on (free, no
    # count start to tell runs by), 70 s apart (or 400 s, the second play's angles 2 deg off:
    # a log that long is aligned about its first detections, and a play whose angles are off
    # fits the scene by its motion all the same). Aligned by its detections, the check took
    # the better of the two and judged it alone: a failing play passed unseen.
    free = {**OWN_CLOCK, "counter_start": "auto"}
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    origins = (1.7e9 + 100.0, 1.7e9 + 100.0 + gap * OWN_CLOCK["cycle_s"])
    scene, first, _ = foreign_log(tmp_path / "a", origins[0], clock=free)
    _, second, _ = foreign_log(
        tmp_path / "b", origins[1], seed=1, clock=free,
        tamper=lambda c: replace(c, cycle=c.cycle + gap,
                                 az_deg=None if c.az_deg is None else c.az_deg + az_off_deg))
    assert check_log(scene, first).report.passed
    messages = []
    for log in (first, second):
        with can.LogReader(str(log)) as reader:
            messages += list(reader)
    both = write_log(tmp_path / "both.blf", [messages])
    with pytest.raises(LogError, match=r"the detections fit the scene at 2 times in the log "
                                       r"\(scene time 0 at log times ([\d.]+), ([\d.]+) s\): "
                                       r"the log holds 2 plays") as refused:
        check_log(scene, both)
    times = re.search(r"log times ([\d.]+), ([\d.]+) s", str(refused.value)).groups()
    np.testing.assert_allclose([float(t) for t in times], origins, atol=0.05)
    # Told which play to check, it checks that one.
    report = check_log(scene, both, time_offset_s=origins[1]).report
    if az_off_deg:
        assert not report.passed and report.errors["az_deg"].max > 1.0
    else:
        assert report.passed and report.frames["checked"] == report.frames["total"]


@pytest.mark.parametrize(("start_offset_s", "jitter_s"), [(0.0, 0.0), (0.0, 0.004),
                                                          (0.02, 0.0)])
def test_a_radar_in_step_with_the_frames_is_aligned_to_the_frame_it_saw(tmp_path, start_offset_s,
                                                                         jitter_s):
    # Cycle = frame period: every offset over a frame fits the detections equally. The latest
    # (each frame measured as it was applied) is taken; the rest of the frame is the stated
    # uncertainty, never +- 0.
    clock = {"cycle_s": 0.05, "start_offset_s": start_offset_s, "latency_s": 0.03,
             "jitter_s": jitter_s, "counter_start": 7}
    scene, log, origin = foreign_log(tmp_path, 1.7e9 + 321.0, seed=5, clock=clock)
    result = check_log(scene, log)
    a = result.alignment
    assert a.source == "estimated"
    # Measured start_offset_s into each frame, reported 30 +- jitter ms later: every offset
    # up to origin + start_offset_s fits (the plateau). The log's first cycle carries the
    # count the profile restarts at with the scene (7): measured at the profile's
    # start_offset_s, it puts the scene's start at the origin, within the jitter.
    assert abs(a.offset_s - origin) <= jitter_s + 2e-4
    assert a.plateau_s == pytest.approx(0.05 - 2 * jitter_s, abs=0.002)
    assert a.uncertainty_s is not None and a.uncertainty_s >= a.plateau_s
    assert abs(a.offset_s - origin) <= a.uncertainty_s
    assert "+- 0.0 ms" not in a.describe()
    assert result.report.passed, result.report.reasons
    assert result.report.frames["missing"] == 0
    assert result.report.frames["total"] == 240
    # The true start given: the delay from each frame to its report is the latency plus
    # start_offset_s; as long as it, or shorter (not below 0), fits as well.
    given = check_log(scene, log, time_offset_s=origin).alignment
    assert given.latency_s == pytest.approx(0.03 + start_offset_s, abs=jitter_s + 2e-4)
    assert given.plateau_s == pytest.approx(min(given.latency_s, 0.05 - 2 * jitter_s),
                                            abs=0.002)
    assert given.notes == []


def test_a_desk_recording_without_sidecar_re_checks_like_live(desk_log):
    scene, log, origin = desk_log
    estimated = check_log(scene, log)
    assert abs(estimated.alignment.offset_s - origin) <= 2e-4
    assert estimated.alignment.uncertainty_s >= 0.045
    assert estimated.report.passed and estimated.report.frames["total"] == 240
    # The true start given: accepted, and the data tell the radar reports at once.
    given = check_log(scene, log, time_offset_s=origin)
    assert given.alignment.source == "given" and given.report.passed
    assert given.alignment.latency_s == pytest.approx(0.0, abs=2e-4)
    assert given.alignment.notes == []
    # A start later than the first cycle is refused, the value in full.
    with pytest.raises(LogError, match=rf"--time-offset-s {origin + 0.06:.6f}: .* 60\.0 ms "
                                       rf"before"):
        check_log(scene, log, time_offset_s=origin + 0.06)


@pytest.mark.parametrize("desk", [True, False])
def test_a_log_cut_at_the_start_misses_the_cycles_before_it(tmp_path, desk, request):
    if desk:
        scene, log, origin = request.getfixturevalue("desk_log")
    else:
        scene, log, origin = foreign_log(tmp_path, 1.7e9 + 12.3)
    cycles = radar_cycles(log)
    cut = len(cycles) // 2
    late = write_log(tmp_path / "late.blf", cycles[cut:])
    for offset in (None, origin):
        report = check_log(scene, late, time_offset_s=offset).report
        assert not report.passed
        assert report.frames["total"] == len(cycles)
        assert report.frames["missing"] == cut
        assert report.frames["checked"] == len(cycles) - cut


def test_a_first_cycle_held_up_on_the_bus_is_still_the_scene_s_first(tmp_path, desk_log):
    # The first cycle reaches the bus after the second (50 ms late): all 240 cycles are still
    # the scene's, none missing, none outside.
    scene, log, _ = desk_log
    cycles = radar_cycles(log)
    second_t = cycles[1][0].timestamp
    held = [can.Message(arbitration_id=m.arbitration_id, data=m.data, is_extended_id=False,
                        timestamp=second_t + 0.001 * (i + 1)) for i, m in enumerate(cycles[0])]
    result = check_log(scene, write_log(tmp_path / "held.blf", [cycles[1], held, *cycles[2:]]))
    assert result.alignment.cycles_outside_scene == 0
    assert result.report.frames["total"] == 240
    assert result.report.frames["missing"] == 0
    assert result.report.passed, result.report.reasons


def test_the_first_cycle_s_detections_before_its_header_wait_for_it(tmp_path, desk_log):
    # A radar whose detection identifiers are lower than its header's sends them first (CAN
    # arbitration): every cycle, the log's first too, is whole; the detections come before
    # their header (reordered messages), no cycle came late.
    scene, log, origin = desk_log
    cycles = radar_cycles(log)
    assert len(cycles[0]) > 1  # the first cycle has detections
    swapped = write_log(tmp_path / "swapped.blf", [c[1:] + c[:1] for c in cycles])
    for offset in (None, origin):
        report = check_log(scene, swapped, time_offset_s=offset).report
        assert report.passed, report.reasons
        assert (report.frames["total"], report.frames["checked"]) == (240, 240)
        assert (report.frames["incomplete"], report.frames["late"]) == (0, 0)
        assert report.bus["before_first_cycle"] == report.bus["orphans"] == 0
        assert report.bus["reordered"] == sum(len(c) - 1 for c in cycles)
        assert report.bus["messages"] == sum(len(c) for c in cycles)
    # A log that began inside a cycle: that cycle's tail is no cycle of the log (not an
    # orphan, nor a part of a later cycle with the same low counter bits).
    tail = write_log(tmp_path / "tail.blf", [cycles[0][1:], *cycles[1:]])
    report = check_log(scene, tail, time_offset_s=origin).report
    assert report.bus["before_first_cycle"] == len(cycles[0]) - 1
    assert (report.bus["orphans"], report.bus["reordered"], report.bus["conflicts"]) == (0, 0, 0)
    assert report.bus["messages"] == sum(len(c) for c in cycles) - 1
    assert report.frames["missing"] == 1 and report.frames["checked"] == 239


def test_a_log_whose_detections_all_fail_their_checksum_says_so(tmp_path, desk_log):
    # A logger that cut CAN FD messages short, or another radar's checksums: no detection
    # to align the scene by, and the message says why.
    scene, log, _ = desk_log
    broken = [[c[0], *(can.Message(arbitration_id=m.arbitration_id, is_extended_id=False,
                                   data=bytes(m.data[:-1]) + bytes([m.data[-1] ^ 0xFF]),
                                   timestamp=m.timestamp) for m in c[1:])]
              for c in radar_cycles(log)]
    n_detections = sum(len(c) - 1 for c in broken)
    with pytest.raises(LogError, match=rf"no detection to align the scene with \({n_detections} "
                                       rf"messages failed their checksum: is --mapping the "
                                       rf"radar's, .*\); give --time-offset-s"):
        check_log(scene, write_log(tmp_path / "broken.blf", broken))


def test_a_log_of_detections_without_any_header_counts_them(tmp_path, desk_log):
    # Detections held for a first header that never comes are the log's messages still:
    # not a silent bus.
    scene, log, _ = desk_log
    parts = [m for c in radar_cycles(log) for m in c[1:]]
    headless = write_log(tmp_path / "headless.blf", [parts])
    with pytest.raises(LogError, match=rf"no radar cycle in it \({len(parts)} messages, none a "):
        check_log(scene, headless)


@pytest.mark.parametrize("kept", [1, 2, 3])
def test_a_log_with_detections_in_a_few_cycles_fails_without_a_runtime_error(tmp_path,
                                                                              desk_log, kept):
    # A radar that lost its target: the other cycles announce detections that never came.
    # The offset's uncertainty (a bootstrap over the cycles with detections) has too few to
    # draw from, or draws all of them again: the check fails on the detection rate.
    scene, log, _ = desk_log
    cycles = radar_cycles(log)
    few = [c if 80 <= i < 80 + kept else c[:1] for i, c in enumerate(cycles)]
    report = check_log(scene, write_log(tmp_path / "few.blf", few)).report
    assert not report.passed
    assert report.frames["incomplete"] == len(cycles) - kept


def test_an_8_bit_counter_names_every_cycle_live_and_in_the_re_checks(tmp_path):
    # rts-scenario's own messages with an 8-bit cycle counter: 600 cycles wrap it twice and
    # more, and a batch of 200 frames holds more cycles than it counts.
    from importlib import resources
    dbc = resources.files("rts_scenario").joinpath("data/can/rts_detections.dbc").read_text()
    wide = 'SG_ FrameCounter : 0|16@1+ (1,0) [0|65535] ""'
    assert wide in dbc
    (tmp_path / "c8.dbc").write_text(dbc.replace(wide, 'SG_ FrameCounter : 0|8@1+ (1,0) '
                                                       '[0|255] ""'))
    mapping = resources.files("rts_scenario").joinpath(
        "data/can/rts_detections.mapping.yaml").read_text()
    (tmp_path / "c8.mapping.yaml").write_text(mapping.replace("rts_detections.dbc", "c8.dbc"))
    scene = load_scenario(CUT_IN, {**QUIET, "duration_s": 30.0,
                                   "targets.0.motion.speed_mps": 22.0})
    log = tmp_path / "c8.blf"
    options = RunOptions(mapping=str(tmp_path / "c8.mapping.yaml"), bus_log=str(log),
                         batch_frames=200)
    live = run_scene(scene, options).report
    copy = shutil.copy(log, tmp_path / "copy.blf")
    for report in (live, check_log(scene, log, batch_frames=200).report,
                   check_log(scene, copy, mapping=options.mapping, batch_frames=200).report):
        assert report.frames["total"] == report.frames["checked"] == 600
        assert (report.frames["missing"], report.frames["late"], report.frames["repeated"],
                report.frames["after_scene"]) == (0, 0, 0, 0)
        assert report.passed, report.reasons


def eight_bit_mapping(tmp_path):
    """rts-scenario's own messages with an 8-bit cycle counter (a mapping file's path)."""
    from importlib import resources
    dbc = resources.files("rts_scenario").joinpath("data/can/rts_detections.dbc").read_text()
    wide = 'SG_ FrameCounter : 0|16@1+ (1,0) [0|65535] ""'
    (tmp_path / "c8.dbc").write_text(dbc.replace(wide, 'SG_ FrameCounter : 0|8@1+ (1,0) '
                                                       '[0|255] ""'))
    mapping = resources.files("rts_scenario").joinpath(
        "data/can/rts_detections.mapping.yaml").read_text()
    (tmp_path / "c8.mapping.yaml").write_text(mapping.replace("rts_detections.dbc", "c8.dbc"))
    return str(tmp_path / "c8.mapping.yaml")


def test_a_gap_longer_than_half_an_8_bit_counter_is_told_by_bus_time(tmp_path):
    # 150 cycles lost (7.5 s): an 8-bit counter reads the gap as 106 cycles back. Numbered by
    # the counter alone, the 290 cycles after it landed 256 early, on cycles already settled
    # (late) or on others' (repeated), and 256 cycles at the scene's end were missing. The bus
    # times say how long the gap took: exactly the lost cycles are missing, live and re-checked.
    scene = load_scenario(CUT_IN, {**QUIET, "duration_s": 30.0,
                                   "targets.0.motion.speed_mps": 22.0})
    log = tmp_path / "gap.blf"
    options = RunOptions(mapping=eight_bit_mapping(tmp_path), bus_log=str(log),
                         batch_frames=200)
    lost = range(160, 310)
    with Pipeline.for_scene(scene, options) as pipeline:
        sink = pipeline.output._sink
        pipeline.output._sink = lambda cycles: sink([c for c in cycles if c.cycle not in lost])
        live = pipeline.run(scene).report
    copy = shutil.copy(log, tmp_path / "copy.blf")
    for report in (live, check_log(scene, log, batch_frames=200).report,
                   check_log(scene, copy, mapping=options.mapping, time_offset_s=None,
                             batch_frames=200).report):
        assert report.frames["total"] == 600
        assert report.frames["checked"] == 450 and report.frames["missing"] == 150
        assert (report.frames["late"], report.frames["repeated"],
                report.frames["after_scene"]) == (0, 0, 0)
        assert not report.passed
        assert report.errors["range_m"].max < 0.01  # every cycle against its own frame


def test_a_re_check_holds_a_few_cycles_at_a_time_not_the_log(tmp_path, monkeypatch):
    # The log is read ahead only as far as the batch being checked needs: memory does not grow
    # with its length (the first pass keeps 24 bytes per cycle).
    import rts_scenario.recheck as recheck

    scene = load_scenario(CUT_IN, QUIET)
    log = tmp_path / "run.blf"
    live = run_scene(scene, RunOptions(bus_log=str(log), batch_frames=40)).report
    most = []
    take = recheck._ReadAhead.take

    def counting(self, positions):
        out = take(self, positions)
        most.append(len(self._held) + len(out))
        return out

    monkeypatch.setattr(recheck._ReadAhead, "take", counting)
    again = check_log(scene, log, batch_frames=40)
    assert again.report.frames == live.frames and again.report.passed
    assert again.alignment.cycles_in_log == 240 and max(most) <= 45


def test_a_log_without_detections_to_align_by_is_checked_at_a_given_offset(tmp_path):
    # An empty bench's log, without its sidecar: no target to align it by, so the scene's
    # start must be given, and the latency is the profile's (0 ms: the first of the 60 cycles,
    # 3 s at 20 Hz, reached the bus at the scene's time 0).
    scene = load_scenario(ROOT / "scenarios" / "empty_bench.scenario.yaml")
    (tmp_path / "run").mkdir()
    log = tmp_path / "run" / "bench.blf"
    assert run_scene(scene, RunOptions(bus_log=str(log))).report.passed
    copy = Path(shutil.copy(log, tmp_path / "bench.blf"))
    with can.BLFReader(str(copy)) as reader:
        origin = next(iter(reader)).timestamp
    with pytest.raises(LogError, match="has no targets, so its log's detections cannot tell "
                                       "when the scene started; give --time-offset-s"):
        check_log(scene, copy)
    result = check_log(scene, copy, time_offset_s=origin)
    assert (result.alignment.latency_source, result.alignment.latency_s) == ("profile", 0.0)
    assert any("its profile's is taken" in n for n in result.alignment.notes)
    assert result.report.frames["checked"] == result.report.frames["total"] == 60
    assert result.report.passed, result.report.reasons
    # Half a second later: the log's first 10 cycles come before the scene, its last 10 lack.
    late = check_log(scene, copy, time_offset_s=origin + 0.5).report
    assert late.frames["missing"] == 10 and not late.passed
    # A scene with a target whose radar reported nothing fails on it, no longer refused.
    target = check_log(load_scenario(CUT_IN, QUIET), copy, time_offset_s=origin).report
    assert target.detection_rate == 0.0 and not target.passed


def test_a_recording_cut_short_keeps_no_sidecar_of_an_earlier_one(tmp_path):
    # A first recording to the name leaves its sidecar; a second one stopped by Ctrl-C after 50
    # cycles writes none, and must not be re-checked by the first one's.
    scene = load_scenario(CUT_IN, QUIET)
    log = tmp_path / "run.blf"
    run_scene(scene, RunOptions(bus_log=str(log), batch_frames=40))
    assert Path(str(log) + ".rts.json").exists()
    with pytest.raises(KeyboardInterrupt), \
            Pipeline.for_scene(scene, RunOptions(bus_log=str(log), batch_frames=40)) as pipeline:
        sink, sent = pipeline.output._sink, []

        def stop(cycles):
            sent.extend(cycles)
            if len(sent) > 50:
                raise KeyboardInterrupt
            sink(cycles)

        pipeline.output._sink = stop
        pipeline.run(scene)
    assert not Path(str(log) + ".rts.json").exists()
    again = check_log(scene, log)
    assert again.alignment.source == "estimated" and again.alignment.cycles_in_log <= 50


def test_a_log_that_shrinks_between_the_passes_is_one_clear_error(tmp_path):
    import rts_scenario.recheck as recheck

    scene = load_scenario(CUT_IN, QUIET)
    log = tmp_path / "run.asc"
    run_scene(scene, RunOptions(bus_log=str(log)))
    reader = recheck._ReadAhead(log, None, np.ones(300, dtype=bool))  # as if it had held 300
    assert len(reader.take(np.arange(240))) == 240
    with pytest.raises(LogError, match=r"run.asc: changed while it was checked \(it now ends "
                                       r"after 240 radar cycles, not 300\)"):
        reader.take(np.array([250]))


@pytest.mark.parametrize(("stamps", "told"), [
    ("equal", "all 240 of them within"), ("back", "go back"),
    ("reversed", "(go back|do not advance)")])
def test_a_log_whose_timestamps_do_not_advance_re_checks_by_its_sidecar_only(
        tmp_path, stamps, told):
    # A logger that wrote one time for every message, or whose clock went back 30 s midway
    # (or ran backwards): its sidecar numbers the cycles by their counters, to the live
    # verdict; without it, one clear error naming the log, not a traceback.
    scene = load_scenario(CUT_IN, QUIET)
    log = tmp_path / "run.blf"
    live = run_scene(scene, RunOptions(bus_log=str(log))).report
    messages = list(can.LogReader(str(log)))
    t0 = messages[0].timestamp
    restamp = {"equal": lambda t: t0, "back": lambda t: t - 30.0 * (t - t0 > 6.0),
               "reversed": lambda t: 2 * t0 - t}[stamps]
    odd = tmp_path / f"{stamps}.blf"
    with can.Logger(str(odd)) as writer:
        for m in messages:
            writer.on_message_received(can.Message(
                arbitration_id=m.arbitration_id, data=m.data, is_extended_id=False,
                timestamp=restamp(m.timestamp)))
    shutil.copy(str(log) + ".rts.json", str(odd) + ".rts.json")
    again = check_log(scene, odd).report
    assert again.passed == live.passed is True, again.reasons
    assert again.frames == live.frames
    Path(str(odd) + ".rts.json").unlink()
    with pytest.raises(LogError, match=rf"--log {re.escape(str(odd))}: its radar cycles' "
                                       rf"timestamps .*{told}"):
        check_log(scene, odd)


@pytest.mark.parametrize("free", [True, False])
def test_an_8_bit_radar_silent_for_its_first_seven_seconds_misses_them(tmp_path, free):
    # Its first 140 cycles (7 s, more than half of what an 8-bit counter counts) never reached
    # the bus. Numbered by the counter from the scene's start, the first received read as 116
    # cycles before it: the run judged the radar from 12.8 s on and passed with 344 cycles of
    # 600. The bus time from the scene's start tells the 140: they are missing, live and
    # re-checked by the sidecar.
    from test_radar_clock import write_radar

    from rts_scenario.radar.clock import RadarClock

    shutil.copy(CUT_IN, tmp_path / "cut_in.scenario.yaml")
    shutil.copytree(CUT_IN.parent / "rigs", tmp_path / "rigs", dirs_exist_ok=True)
    radar = write_radar(tmp_path, cycle_s=0.05, start_offset_s=0.01, latency_s=0.13,
                        jitter_s=0.004, counter_start="auto" if free else 100)
    scene = load_scenario(tmp_path / "cut_in.scenario.yaml",
                          {**QUIET, "radar.profile": radar, "duration_s": 30.0,
                           "targets.0.motion.speed_mps": 22.0})
    log = tmp_path / "silent.blf"
    options = RunOptions(mapping=eight_bit_mapping(tmp_path), bus_log=str(log),
                         batch_frames=200)
    with Pipeline.for_scene(scene, options) as pipeline:
        pipeline.output.clock = RadarClock(cycle_s=0.05, start_offset_s=0.01, latency_s=0.13,
                                           jitter_s=0.004, counter_start=100)
        sink = pipeline.output._sink
        pipeline.output._sink = lambda cycles: sink([c for c in cycles if c.cycle >= 240])
        live = pipeline.run(scene).report
    assert live.radar_clock["counter_start"] == 100
    for report in (live, check_log(scene, log, batch_frames=200).report):
        assert not report.passed
        assert report.frames["total"] == 600
        assert report.frames["checked"] == 460 and report.frames["missing"] == 140
        assert (report.frames["late"], report.frames["repeated"]) == (0, 0)


@pytest.mark.parametrize("free", [False, True])
def test_a_log_without_sidecar_begun_over_half_an_8_bit_count_into_the_scene_misses_those(
        tmp_path, free):
    # The logger started 150 cycles (7.5 s) into the scene. Numbered by the counter from the
    # profile's start alone, the log's first cycle read as 106 before the scene: every cycle
    # 256 early, none of them the scene's (a counter counting from "auto", by the fitted
    # clock, likewise). The stamps, aligned to the scene by the detections, tell the 150.
    from test_radar_clock import write_radar

    from rts_scenario.radar.clock import RadarClock

    shutil.copy(CUT_IN, tmp_path / "cut_in.scenario.yaml")
    shutil.copytree(CUT_IN.parent / "rigs", tmp_path / "rigs", dirs_exist_ok=True)
    radar = write_radar(tmp_path, cycle_s=0.05, start_offset_s=0.01, latency_s=0.13,
                        jitter_s=0.004, counter_start="auto" if free else 100)
    scene = load_scenario(tmp_path / "cut_in.scenario.yaml",
                          {**QUIET, "radar.profile": radar, "duration_s": 20.0})
    log = tmp_path / "late.blf"
    options = RunOptions(mapping=eight_bit_mapping(tmp_path), bus_log=str(log))
    with Pipeline.for_scene(scene, options) as pipeline:
        pipeline.output.clock = RadarClock(cycle_s=0.05, start_offset_s=0.01, latency_s=0.13,
                                           jitter_s=0.004, counter_start=100)
        pipeline.run(scene)
    copy = write_log(tmp_path / "copy.blf", radar_cycles(log)[150:])
    report = check_log(scene, copy, mapping=options.mapping).report
    assert report.frames["total"] == 400
    assert report.frames["checked"] == 250 and report.frames["missing"] == 150
    assert (report.frames["late"], report.frames["repeated"]) == (0, 0)
    assert report.errors["range_m"].max < 0.05  # every cycle against its own frame


def test_a_log_whose_clock_moved_an_hour_re_checks_by_its_sidecar_to_the_live_verdict(tmp_path):
    # A copy of the log whose timestamps a tool moved by an hour (a time zone): its first
    # cycle is not an hour of cycles after the scene's start the sidecar keeps; an 8-bit
    # counter numbers the cycles, to the live verdict.
    scene = load_scenario(CUT_IN, QUIET)
    log = tmp_path / "run.blf"
    live = run_scene(scene, RunOptions(bus_log=str(log), mapping=eight_bit_mapping(tmp_path))
                     ).report
    moved = tmp_path / "moved.blf"
    with can.Logger(str(moved)) as writer:
        for m in can.LogReader(str(log)):
            writer.on_message_received(can.Message(
                arbitration_id=m.arbitration_id, data=m.data, is_extended_id=False,
                timestamp=m.timestamp + 3600.0))
    shutil.copy(str(log) + ".rts.json", str(moved) + ".rts.json")
    again = check_log(scene, moved).report
    assert live.passed and again.passed, again.reasons
    assert again.frames == live.frames


@pytest.mark.parametrize("free", [True, False])
def test_cycles_from_before_the_scene_are_counted_alike_live_and_re_checked(tmp_path, free):
    # A real radar measures before the stream starts the scene: three of its cycles from
    # before the scene's start reach the bus. Live and re-checked by the sidecar they are
    # the same count: measured before the scene, neither late nor after its end.
    from rts_scenario.radar.clock import RadarClock

    shutil.copy(CUT_IN, tmp_path / "cut_in.scenario.yaml")
    shutil.copytree(CUT_IN.parent / "rigs", tmp_path / "rigs", dirs_exist_ok=True)
    radar = write_radar(tmp_path, cycle_s=0.05, start_offset_s=0.01, latency_s=0.13,
                        jitter_s=0.0, counter_start="auto" if free else 100)
    scene = load_scenario(tmp_path / "cut_in.scenario.yaml", {**QUIET, "radar.profile": radar})
    log = tmp_path / "early.blf"
    with Pipeline.for_scene(scene, RunOptions(bus_log=str(log))) as pipeline:
        pipeline.output.clock = RadarClock(cycle_s=0.05, start_offset_s=0.01, latency_s=0.13,
                                           jitter_s=0.0, counter_start=100)
        sink, sent = pipeline.output._sink, []

        def with_early(cycles):
            if not sent:
                early = [Detections.empty(100 - k, 0.01 - 0.05 * k, ()) for k in (3, 2, 1)]
                cycles = early + list(cycles)
            sent.append(len(cycles))
            sink(cycles)

        pipeline.output._sink = with_early
        live = pipeline.run(scene).report
    again = check_log(scene, log)
    assert live.passed and again.report.passed, (live.reasons, again.report.reasons)
    assert live.frames["before_scene"] == 3 and live.frames["total"] == 240
    assert (live.frames["late"], live.frames["after_scene"]) == (0, 0)
    assert again.report.frames == live.frames


def test_a_free_radar_whose_first_cycle_measured_just_before_the_scene_re_checks_on_its_clock(
        tmp_path):
    # A radar running free whose messages reach the bus 0.2 ms sooner after it measured than
    # its profile's latency says: its phase from the bus puts the scene's first cycle 0.2 ms
    # before the scene's start, within three standard errors of the phase (0.45 ms): it is
    # the scene's first, measured at -0.2 ms. The sidecar keeps that phase, signed, so the
    # re-check times every cycle where the run did.
    from rts_scenario.radar.clock import RadarClock

    shutil.copy(CUT_IN, tmp_path / "cut_in.scenario.yaml")
    shutil.copytree(CUT_IN.parent / "rigs", tmp_path / "rigs", dirs_exist_ok=True)
    radar = write_radar(tmp_path, cycle_s=0.05, latency_s=0.13, jitter_s=0.004,
                        counter_start="auto")
    scene = load_scenario(tmp_path / "cut_in.scenario.yaml", {**QUIET, "radar.profile": radar})
    log = tmp_path / "free.blf"
    with Pipeline.for_scene(scene, RunOptions(bus_log=str(log))) as pipeline:
        pipeline.output.clock = RadarClock(cycle_s=0.05, latency_s=0.13, counter_start=100)
        publisher = pipeline._publisher

        def stamp(cycles):
            t = np.array([c.t_s for c in cycles])
            publisher.publish_many(cycles, pipeline._bus_origin_s + t + 0.13 - 0.0002)

        pipeline.output._sink = stamp
        live = pipeline.run(scene).report
    assert live.radar_clock["start_from"] == "bus"
    assert live.radar_clock["start_offset_s"] == pytest.approx(-0.0002, abs=2e-5)
    assert live.frames["total"] == 240 and live.frames["before_scene"] == 0
    sidecar = json.loads(Path(str(log) + ".rts.json").read_text())
    assert sidecar["clock"]["start_offset_s"] == pytest.approx(-0.0002, abs=2e-5)
    again = check_log(scene, log).report
    for key in ("counter_start", "cycle_s", "start_offset_s"):
        assert again.radar_clock[key] == pytest.approx(live.radar_clock[key], abs=1e-6), key
    assert again.frames == live.frames and again.reasons == live.reasons
    # A sidecar of an older version kept the phase clamped at the scene's start: read as before.
    sidecar["clock"]["start_offset_s"] = 0.0
    (tmp_path / "old").mkdir()
    old = check_log(scene, _copy(log, tmp_path / "old", json.dumps(sidecar))).report
    assert old.radar_clock["start_offset_s"] == 0.0
    assert old.frames["total"] == 240 and old.passed == live.passed
    # A phase more than a cycle before the scene's start is no scene's first cycle's.
    sidecar["clock"]["start_offset_s"] = -0.06
    with pytest.raises(LogError, match=r"clock.start_offset_s: -0.06 s, a cycle or more before "
                                       r"the scene's start \(allowed: above -0.05: "):
        check_log(scene, _copy(log, tmp_path / "old", json.dumps(sidecar)))


def run_scattered(tmp_path, radar_cycle_s, step_s, spread_s=0.012):
    """Run the cut-in scene with a radar of ``radar_cycle_s`` whose latency jitters
    +-``spread_s`` (default 12 ms; its profile: 50 ms, +-4 ms), ``step_s`` longer from cycle
    120 on; its log re-checked."""
    from rts_scenario.radar.clock import RadarClock

    shutil.copy(CUT_IN, tmp_path / "cut_in.scenario.yaml")
    shutil.copytree(CUT_IN.parent / "rigs", tmp_path / "rigs", dirs_exist_ok=True)
    radar = write_radar(tmp_path, cycle_s=0.05, latency_s=0.13, jitter_s=0.004, counter_start=0)
    scene = load_scenario(tmp_path / "cut_in.scenario.yaml", {**QUIET, "radar.profile": radar})
    log = tmp_path / "scattered.blf"
    rng = np.random.default_rng(1)
    with Pipeline.for_scene(scene, RunOptions(bus_log=str(log))) as pipeline:
        pipeline.output.clock = RadarClock(cycle_s=radar_cycle_s, latency_s=0.13,
                                           jitter_s=0.004)
        publisher = pipeline._publisher

        def stamp(cycles):
            t = np.array([c.t_s for c in cycles])
            counter = np.array([c.cycle for c in cycles])
            publisher.publish_many(cycles, pipeline._bus_origin_s + t + 0.13
                                   + rng.uniform(-spread_s, spread_s, t.size)
                                   + step_s * (counter >= 120))

        pipeline.output._sink = stamp
        live = pipeline.run(scene).report
    return live, check_log(scene, log)


def test_a_radar_5_percent_off_its_profile_s_cycle_is_no_jump_in_a_log_without_sidecar(
        tmp_path):
    # Checked without its sidecar, the log's cycle is fitted (52.5 ms against the profile's
    # 50): the radar_clock reason says so. Its stamps, within the profile's jitter around
    # that cycle, do not jump: measured against the profile's cycle they drifted 2.5 ms a
    # cycle, which read as a jump of the stamps and failed the check as log_stamps.
    _, with_sidecar = run_scattered(tmp_path, 0.0525, 0.0, spread_s=0.002)
    log = tmp_path / "scattered.blf"
    Path(str(log) + ".rts.json").unlink()
    again = check_log(with_sidecar.scene, log)
    assert again.alignment.cycle_s == pytest.approx(0.0525, rel=1e-3)
    codes = [c for r in again.report.reasons for c in r.codes]
    assert "radar_clock" in codes and "log_stamps" not in codes, again.report.reasons
    assert not any("stamps jump" in note for note in again.alignment.notes)


def test_a_radar_2000_ppm_off_with_more_jitter_than_its_profile_says_fails_live_and_again(
        tmp_path):
    # Its cycles on one line through +-12 ms of jitter: the run follows the bus's cycle and
    # fails, 2000 ppm being no crystal; the sidecar's re-check judges where the run did, to
    # the same verdict.
    live, again = run_scattered(tmp_path, 0.0501, 0.0)
    assert live.radar_clock["cycle_from"] == "bus"
    assert live.radar_clock["cycle_s"] == pytest.approx(0.0501, rel=1e-4)
    assert not live.passed and len(live.reasons) == 1
    assert "more than a crystal's 1000 ppm" in live.reasons[0]
    assert again.alignment.cycle_s == live.radar_clock["cycle_s"]
    assert again.report.frames == live.frames
    assert again.report.reasons == live.reasons


def test_a_re_check_by_the_sidecar_judges_at_the_clock_the_run_took_and_notes_the_bus_s(
        tmp_path):
    # A radar on its profile's cycle whose messages reach the bus 30 ms later from cycle 120
    # on, through +-12 ms of jitter: the line through the bus times tilts by 45 ms, and the
    # run keeps the profile's cycle (the segments' means do not keep to one line), saying the
    # latency changed. A crystal could have drawn little of a step: the verdict stands. The
    # sidecar's re-check judges the cycles where the run did, to the live counts, and its
    # notes say what the bus times show.
    live, again = run_scattered(tmp_path, 0.05, 0.03)
    assert live.radar_clock["cycle_from"] == "profile"
    assert live.radar_clock["latency_change_s"] == pytest.approx(0.03, abs=0.01)
    assert live.passed, live.reasons
    assert again.alignment.cycle_s == live.radar_clock["cycle_s"] == 0.05
    assert again.report.frames == live.frames
    assert again.report.passed == live.passed
    assert again.report.radar_clock["latency_change_s"] == pytest.approx(
        live.radar_clock["latency_change_s"], abs=0.002)
    assert any(re.match(r"the radar.s cycles reached the bus every 50\.1\d+ ms, the run took "
                        r"50\.000000 ms", n)
               for n in again.alignment.notes), again.alignment.notes


def test_a_method_the_recorded_statuses_make_unused_is_noted(recorded):
    scene = load_scenario(ROOT / "scenarios" / "highway_following.scenario.yaml")
    again = check_log(scene, recorded, method="paper")
    assert again.report.passed and again.alignment.statuses == "recorded"
    assert again.alignment.notes == ["--method paper is not used: the sidecar keeps the statuses "
                                     "the RTS played (with exact)"]
    assert check_log(scene, recorded, method="exact").alignment.notes == []


def test_targets_listed_in_another_order_are_judged_by_their_own_recorded_statuses(tmp_path):
    # The truck stands 30 m to the left, beyond the rig's coverage: the RTS never played it.
    # Listed after the car in the scene file the run played, before it in the one re-checked
    # (no other change: the same ground truth per target), the truck is still the one not
    # played and the car the one played.
    text = (ROOT / "scenarios" / "highway_following.scenario.yaml").read_text()
    text = (text.replace("duration_s: 20.0", "duration_s: 5.0")
            .replace(", fluctuation: swerling1", "")
            .replace("position_m: [50.0, 3.5, 1.2]", "position_m: [20.0, 30.0, 1.2]")
            .replace("../rts_scenario", str(ROOT / "rts_scenario")))
    head, rest = text.split("targets:\n", 1)
    body, tail = rest.split("expectations:", 1)
    car, truck = ("  - name: " + b for b in body.split("  - name: ")[1:])
    played, reordered = tmp_path / "played.scenario.yaml", tmp_path / "reordered.scenario.yaml"
    played.write_text(head + "targets:\n" + car + truck + "expectations:" + tail)
    reordered.write_text(head + "targets:\n" + truck + car + "expectations:" + tail)
    log = tmp_path / "run.blf"
    live = run_scene(load_scenario(played), RunOptions(bus_log=str(log))).report
    targets = {t.name: t for t in live.targets}
    assert targets["truck-left"].limits == {"out_of_coverage": 100}
    assert targets["lead-car"].detection_rate == 1.0 and not targets["lead-car"].limits
    again = check_log(load_scenario(reordered), log)
    assert again.alignment.truth_matches_recording is True
    targets = {t.name: t for t in again.report.targets}
    assert targets["truck-left"].limits == {"out_of_coverage": 100}
    assert targets["lead-car"].detection_rate == 1.0 and not targets["lead-car"].limits
    assert again.report.passed == live.passed and again.report.reasons == live.reasons


def test_a_log_the_mapping_reads_no_cycle_of_counts_its_messages(recorded, tmp_path, capsys):
    # Checked with a third-party radar's mapping, rts-scenario's own messages hold no header
    # of it: the log is not silent, it holds every message the run recorded, each of an
    # identifier the mapping does not know (as a run given that mapping counts them).
    with can.LogReader(str(recorded)) as reader:
        n_messages = sum(1 for _ in reader)
    assert n_messages > 400
    scene = str(ROOT / "scenarios" / "highway_following.scenario.yaml")
    mapping = str(ROOT / "scenarios" / "can" / "cluster_list.mapping.yaml")
    again = check_log(load_scenario(scene), recorded, mapping=mapping)
    assert not again.report.passed and again.report.frames["missing"] == 400
    assert again.report.bus["messages"] == again.report.bus["unknown_ids"] == n_messages
    assert again.report.bus["before_first_cycle"] == 0
    assert not any("silent" in r for r in again.report.reasons)
    assert (f"no message matched the mapping's header (Cluster_Status of mapping "
            f"'cluster-list'); {n_messages} messages with identifiers the mapping does not "
            f"know: is --mapping the radar's?") in again.report.reasons
    bare = _copy(recorded, tmp_path)
    Path(str(bare) + ".rts.json").unlink()
    assert cli.main(["check", scene, "--log", str(bare), "--mapping", mapping]) == 2
    assert (f"no radar cycle in it ({n_messages} messages, none a Cluster_Status header of "
            f"mapping 'cluster-list')") in capsys.readouterr().err


def with_a_second_radar(recorded: Path, log: Path, first_counter: int) -> Path:
    """``recorded`` with another radar's cycles, counting from ``first_counter``, during it."""
    with can.LogReader(str(recorded)) as reader:
        messages = list(reader)
    first = messages[0].timestamp
    extra: list[can.Message] = []
    stamp = {"t": 0.0}

    class Recorder:
        def send(self, msg):
            msg.timestamp = stamp["t"]
            extra.append(msg)

    publisher = DetectionPublisher(Recorder())
    for k in range(40):  # 2 s of a 50 ms radar, from 1 s into the scene
        stamp["t"] = first + 1.0 + 0.05 * k + 0.021
        publisher.publish(Detections.empty(first_counter + k, 1.0 + 0.05 * k))
    log = write_log(log, [sorted(messages + extra, key=lambda m: m.timestamp)])
    shutil.copy(str(recorded) + ".rts.json", str(log) + ".rts.json")
    return log


def test_a_second_radar_on_the_recorded_bus_fails_the_re_check(recorded, tmp_path):
    # Another radar with the same identifiers on the bus, counting from 60000: its cycles are
    # numbered before the scene (60000 on a 16-bit count from 0), yet came on the bus during
    # it. Counted as before_scene alone, the re-check passed; they are no cycles of this
    # radar, and fail it.
    log = with_a_second_radar(recorded, tmp_path / "two.blf", 60000)
    scene = load_scenario(ROOT / "scenarios" / "highway_following.scenario.yaml")
    assert check_log(scene, recorded).report.passed
    report = check_log(scene, log).report
    assert not report.passed
    [foreign] = [r for r in report.reasons if "foreign_cycles" in r.codes]
    assert foreign.startswith("40 radar cycles numbered before the scene came on the bus 1.0")
    assert report.frames["before_scene"] == 40


def test_a_second_radar_counting_ahead_on_the_recorded_bus_fails_the_re_check(recorded,
                                                                              tmp_path):
    # Another radar with the same identifiers, counting from 30000 (after the scene on a
    # 16-bit count from 0), during the scene: its cycles were said to be "measured after the
    # scene's end ... the recorder went on", and counted nowhere. They fail the re-check.
    log = with_a_second_radar(recorded, tmp_path / "ahead.blf", 30000)
    scene = load_scenario(ROOT / "scenarios" / "highway_following.scenario.yaml")
    result = check_log(scene, log)
    report = result.report
    assert not report.passed
    [foreign] = [r for r in report.reasons if "foreign_cycles" in r.codes]
    assert foreign.startswith("40 radar cycles numbered after the scene (cycle 30000 on, "
                              "counted from the profile's counter_start 0) came on the bus 1.0")
    assert not any("recorder went on" in note for note in result.alignment.notes)


def test_a_mapping_or_dbc_edited_since_the_recording_is_refused_and_a_copy_is_the_same(
        tmp_path):
    # A run recorded with a copy of rts-scenario's mapping and DBC. Its DBC edited since
    # would read the log otherwise (a signal's scale changes every RCS): refused, not a
    # verdict; a copy of the run's mapping and DBC elsewhere (a log moved to another machine)
    # reads it as the run did, without a note.
    builtin = ROOT / "rts_scenario" / "data" / "can"
    dbc = (builtin / "rts_detections.dbc").read_text()
    rcs = re.search(r"SG_ RCS : .*", dbc)
    assert rcs is not None and "(0.5," in rcs.group(0)
    folder = tmp_path / "can"
    folder.mkdir()
    (folder / "rts_detections.mapping.yaml").write_text(
        (builtin / "rts_detections.mapping.yaml").read_text())
    (folder / "rts_detections.dbc").write_text(dbc)
    mapping = folder / "rts_detections.mapping.yaml"
    scene = load_scenario(CUT_IN, QUIET)
    log = tmp_path / "run.blf"
    live = run_scene(scene, RunOptions(mapping=str(mapping), bus_log=str(log))).report
    sidecar = json.loads(Path(str(log) + ".rts.json").read_text())
    digest = sidecar["mapping_sha256"]
    assert re.fullmatch("[0-9a-f]{64}", digest)
    assert check_log(scene, log).report.frames == live.frames
    # Moved: the sidecar's path names no file; a copy given with --mapping is the run's.
    moved = tmp_path / "moved"
    shutil.copytree(folder, moved)
    shutil.rmtree(folder)
    with pytest.raises(LogError, match=r"\.rts\.json: mapping: .*rts_detections\.mapping\.yaml: "
                                       r"no such file \(the mapping the run spoke.*give "
                                       r"--mapping with a copy of it"):
        check_log(scene, log)
    again = check_log(scene, log, mapping=str(moved / "rts_detections.mapping.yaml"))
    assert again.alignment.notes == [] and again.report.frames == live.frames
    # Edited in place (a signal's offset): refused, naming the digest.
    shutil.copytree(moved, folder)
    (folder / "rts_detections.dbc").write_text(dbc.replace(rcs.group(0), rcs.group(0).replace(
        "(0.5,", "(0.25,", 1)))
    with pytest.raises(LogError, match=r"mapping .* is not what the run decoded the bus with: "
                                       r"its text or its DBC's changed since the recording"):
        check_log(scene, log)
    with pytest.raises(LogError, match="mapping_sha256 differs"):
        check_log(scene, log, mapping=str(mapping))


def test_a_mapping_other_than_the_run_s_is_noted_and_a_changed_target_list_named(recorded,
                                                                                tmp_path):
    scene_file = ROOT / "scenarios" / "highway_following.scenario.yaml"
    scene = load_scenario(scene_file)
    builtin = ROOT / "rts_scenario" / "data" / "can" / "rts_detections.mapping.yaml"
    # rts-scenario's own mapping named explicitly is the one the run spoke: no note.
    assert check_log(scene, recorded, mapping=str(builtin)).alignment.notes == []
    other = tmp_path / "other.mapping.yaml"
    other.write_text(builtin.read_text().replace(
        "rts_detections.dbc", str(builtin.parent / "rts_detections.dbc")))
    notes = check_log(scene, recorded, mapping=str(other)).alignment.notes
    assert notes == [f"--mapping {other} is not the one the run spoke (rts-scenario's messages, "
                     f"its sidecar): the log is read as this one says"]
    # A target added since the recording: refused, naming it.
    text = scene_file.read_text()
    added = tmp_path / "highway_following.scenario.yaml"
    added.write_text(text.replace("expectations:", """  - name: bus
    kind: truck
    motion: {type: constant_velocity, position_m: [70.0, -3.5, 1.2], speed_mps: 23.0}
    rcs: {rcs_dbsm: 20.0}
expectations:"""))
    with pytest.raises(LogError, match=r"statuses: holds 400 frames of 2 targets, the scene has "
                                       r"400 of 3; not in the recording: 'bus': not the scene "
                                       r"file that was recorded \(edited since\?\)"):
        check_log(load_scenario(added), recorded)


@pytest.mark.parametrize("suffix", [".mf4", ".blf", ".csv"])
def test_a_damaged_log_is_one_error_line_without_a_traceback(tmp_path, suffix):
    # A log cut short by a full disk or a pulled cable: the format's reader fails. One error
    # line names the log, with no traceback from the reader cleaning up after itself (asammdf
    # does, on an MF4 it could not open).
    if suffix == ".mf4":
        pytest.importorskip("asammdf")
    whole = tmp_path / f"whole{suffix}"
    with can.Logger(str(whole)) as logger:
        for i in range(2000):
            logger.on_message_received(can.Message(arbitration_id=0x200 + i % 5,
                                                   is_extended_id=False, timestamp=0.001 * i,
                                                   data=bytes([i % 256] * 8)))
    data = whole.read_bytes()
    damaged = tmp_path / f"cut{suffix}"
    damaged.write_bytes(data[: len(data) // 3] + b"\xff" * 7)
    scene = str(ROOT / "scenarios" / "approaching_target.scenario.yaml")
    # In a process of its own, as a user runs it (pytest takes over what Python prints of an
    # exception raised while an object is collected).
    done = subprocess.run([sys.executable, "-m", "rts_scenario.cli", "check", scene, "--log",
                           str(damaged)], capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    err = done.stderr
    assert done.returncode == 2, err
    assert "Traceback" not in err and "Exception ignored" not in err, err
    (line,) = err.strip().splitlines()
    assert line.startswith(f"error: --log {damaged}: ")


def _mid_line_cut(log: Path, fraction: float) -> tuple[bytes, int]:
    """The log's bytes cut in the middle of the line at ``fraction`` of it (not its last), and
    that line's number (from 1)."""
    data = log.read_bytes()
    lines = data.splitlines(keepends=True)
    at = min(int(len(lines) * fraction), len(lines) - 2)
    start = sum(len(line) for line in lines[:at])
    return data[:start + len(lines[at].rstrip()) // 2], at + 1


@pytest.mark.parametrize("suffix", [".log", ".trc", ".asc", ".csv"])
def test_a_text_log_cut_in_the_middle_of_a_line_fails_its_re_check_naming_the_line(
        tmp_path, capsys, suffix):
    # A recorder killed mid-write, a copy cut short: the last line is written in part.
    # python-can reads it as it is (a data field cut short, its half byte made up), fails on
    # it, or skips it; the re-check reads the complete lines and fails naming the line.
    scene = ROOT / "scenarios" / "approaching_target.scenario.yaml"  # 7.5 s: 150 cycles
    log = tmp_path / f"run{suffix}"
    assert cli.main(["run", str(scene), "--record", str(log)]) == 0
    capsys.readouterr()
    data, line = _mid_line_cut(log, 0.6)
    cut = tmp_path / f"cut{suffix}"
    cut.write_bytes(data)
    shutil.copy(str(log) + ".rts.json", str(cut) + ".rts.json")
    # The reference: the complete lines alone, as python-can reads them.
    whole = tmp_path / f"whole{suffix}"
    whole.write_bytes(data[:data.rfind(b"\n") + 1])
    kept = list(can.LogReader(str(whole)))
    headers = sum(1 for m in kept if m.arbitration_id == 0x100)
    assert 0 < headers < 150
    out_json = tmp_path / "check.json"
    code = cli.main(["check", str(scene), "--log", str(cut), "--json", str(out_json)])
    out, err = capsys.readouterr()
    assert code == 1 and "Traceback" not in err, out + err
    report = json.loads(out_json.read_text())
    lacks = " (and the 'End TriggerBlock' line an ASC log ends with)" if suffix == ".asc" else ""
    expected = (f"the log {cut} was cut short: its line {line} ends without a line end{lacks}, "
                f"{len(data) - len(whole.read_bytes())} bytes of it written: not read; it ends at "
                f"log time {kept[-1].timestamp:.6f} s (its last message read): what the radar "
                f"sent after it is not in it")
    assert expected in report["reasons"], report["reasons"]
    assert expected in out
    assert report["alignment"]["log_cut_short"] == {
        "header_bytes": None, "file_bytes": len(data), "line": line,
        "last_message_t_s": kept[-1].timestamp}
    # The cycles the complete lines hold are judged, the rest missing: none read from half a
    # line.
    frames = report["frames"]
    assert frames["total"] == 150 and frames["missing"] == 150 - headers
    assert frames["received"] + frames["incomplete"] == headers
    assert report["bus"]["messages"] == len(kept)
    # The whole log has nothing of the kind.
    assert cli.main(["check", str(scene), "--log", str(log), "--json", str(out_json)]) == 0
    capsys.readouterr()
    assert json.loads(out_json.read_text())["alignment"]["log_cut_short"] is None


@pytest.mark.parametrize("suffix", [".log", ".trc"])
def test_a_text_log_cut_after_the_cycles_counted_is_noted_and_re_checks_to_the_live_verdict(
        tmp_path, suffix):
    # The radar went on for 10 cycles after the scene's end (12 s, cycles of 50 ms from 0):
    # 5 of them (12.00 s to 12.20 s) within a cycle and 0.2 s of the end are counted, live
    # and re-checked. A log cut in its last line, after those, lacks nothing counted: noted.
    scene = load_scenario(CUT_IN, QUIET)
    log = tmp_path / f"run{suffix}"
    with Pipeline.for_scene(scene, RunOptions(bus_log=str(log))) as pipeline:
        sink = pipeline.output._sink

        def going_on(cycles):
            if cycles and cycles[-1].cycle == 239:
                cycles = list(cycles) + [Detections.empty(240 + k, 12.0 + 0.05 * k, ())
                                         for k in range(10)]
            sink(cycles)

        pipeline.output._sink = going_on
        live = pipeline.run(scene).report
    assert live.passed and live.frames["after_scene"] == 5
    again = check_log(scene, log)
    assert again.report.frames == live.frames and again.report.passed
    data = log.read_bytes()
    cut = tmp_path / f"cut{suffix}"
    cut.write_bytes(data[:len(data.rstrip()) - 3])
    shutil.copy(str(log) + ".rts.json", str(cut) + ".rts.json")
    line = data.rstrip().count(b"\n") + 1
    result = check_log(scene, cut)
    assert result.report.passed, result.report.reasons
    assert result.report.frames == live.frames
    assert result.alignment.log_cut_short["line"] == line
    assert any(note.startswith(f"the log {cut} was cut short: its line {line} ends without a "
                               f"line end") and note.endswith("nothing counted is lost")
               for note in result.alignment.notes), result.alignment.notes


@pytest.mark.parametrize("suffix", [".log", ".csv", ".trc"])
def test_a_damaged_line_inside_a_text_log_is_one_error_naming_it(tmp_path, capsys, suffix):
    # python-can's readers fail on it, or skip it with a warning (TRC): either way a message
    # is lost in the middle of the log, which is not read as a shorter one.
    scene = ROOT / "scenarios" / "approaching_target.scenario.yaml"
    log = tmp_path / f"run{suffix}"
    assert cli.main(["run", str(scene), "--record", str(log)]) == 0
    capsys.readouterr()
    lines = log.read_bytes().splitlines(keepends=True)
    lines[99] = b"(garbage\n"
    log.write_bytes(b"".join(lines))
    assert cli.main(["check", str(scene), "--log", str(log)]) == 2
    err = capsys.readouterr().err
    (said,) = err.strip().splitlines()
    assert said.startswith(f"error: --log {log}: line 100: cannot read: "), said


def _stale_cycle(k, t_s):
    """A cycle of the stream before, as the radar sent it (one detection 30 m ahead)."""
    return Detections(cycle=k, t_s=t_s, range_m=np.array([30.0]),
                      radial_velocity_mps=np.array([0.0]), az_deg=np.array([0.0]),
                      el_deg=np.array([0.0]))


def _live_and_re_checked(tmp_path, first_batch):
    """Run the quiet cut-in recording its bus, the radar's first batch of cycles given by
    ``first_batch(cycles)``; return the live report and that of the recording's re-check."""
    scene = load_scenario(CUT_IN, QUIET)
    log = tmp_path / "run.blf"
    with Pipeline.for_scene(scene, RunOptions(bus_log=str(log))) as pipeline:
        sink = pipeline.output._sink
        first = [True]

        def tampered(cycles):
            if first[0]:
                first[0] = False
                cycles = first_batch(cycles)
            sink(cycles)

        pipeline.output._sink = tampered
        live = pipeline.run(scene).report
    return live, check_log(scene, log).report


def test_a_recording_opening_with_the_stream_before_s_last_cycles_re_checks_to_the_live_verdict(
        tmp_path):
    # A radar counting from its profile's counter start (0) with each stream: the stream
    # before's last two cycles (counters 238, 239) reach the bus after this run's receiver was
    # reset, before this stream's cycle 0. The run drops them at the restart of the count and
    # says how many; the recording holds them, and its re-check drops the same ones: the same
    # counts and verdict, not 224 cycles taken for late ones.
    live, again = _live_and_re_checked(tmp_path, lambda cycles: [
        _stale_cycle(238, -0.02), _stale_cycle(239, -0.01), *cycles])
    assert live.passed, live.reasons
    assert live.frames["total"] == live.frames["checked"] == 240
    assert live.bus["stale_cycles"] == 2
    assert again.frames == live.frames
    assert again.passed and again.reasons == []
    assert again.bus["stale_cycles"] == 2


def test_a_stream_s_first_cycle_held_up_behind_its_second_after_the_stale_tail_re_checks_alike(
        tmp_path):
    # The stream before's last two cycles (238, 239) come after the reset, and this stream's
    # cycle 0 is held up behind its cycle 1. The run keeps cycles 0 and 1 (its own: 1 counts on
    # from the restart) and drops the stale two; the re-check of its recording keeps and drops
    # the same ones: every cycle of the scene checked, in both.
    def stale_and_held_up(cycles):
        assert [c.cycle for c in cycles[:2]] == [0, 1]
        return [_stale_cycle(238, -0.02), _stale_cycle(239, -0.01), cycles[1], cycles[0],
                *cycles[2:]]

    live, again = _live_and_re_checked(tmp_path, stale_and_held_up)
    assert live.passed, live.reasons
    assert live.frames["total"] == live.frames["checked"] == 240
    assert live.frames["missing"] == 0
    assert live.bus["stale_cycles"] == 2 and live.bus["reordered"] == 1
    assert again.frames == live.frames
    assert again.passed and again.reasons == []
    assert again.bus["stale_cycles"] == 2 and again.bus["reordered"] == 1


@pytest.mark.parametrize("suffix", [".log", ".trc", ".asc", ".csv"])
def test_a_text_log_ending_in_an_empty_line_re_checks_to_the_live_verdict(tmp_path, capsys,
                                                                          suffix):
    # An editor, or a tool joining logs, leaves an empty line (or one of blanks) after the
    # last: no message is lost, and none is cut short.
    scene = ROOT / "scenarios" / "approaching_target.scenario.yaml"
    log = tmp_path / f"run{suffix}"
    assert cli.main(["run", str(scene), "--record", str(log)]) == 0
    capsys.readouterr()
    for n, tail in enumerate((b"\n", b"  \r\n\n")):
        padded = tmp_path / f"padded{n}{suffix}"
        padded.write_bytes(log.read_bytes() + tail)
        shutil.copy(str(log) + ".rts.json", str(padded) + ".rts.json")
        result = check_log(load_scenario(scene), padded)
        assert result.report.passed, result.report.reasons
        assert result.report.frames["checked"] == result.report.frames["total"] == 150
        assert result.alignment.log_cut_short is None


@pytest.mark.parametrize("suffix", [".log", ".csv"])
def test_a_text_log_that_is_no_text_is_one_error_naming_its_first_line(tmp_path, capsys,
                                                                       suffix):
    # A compressed log named as a text one: its first line cannot be decoded.
    import gzip

    scene = ROOT / "scenarios" / "approaching_target.scenario.yaml"
    log = tmp_path / f"run{suffix}"
    assert cli.main(["run", str(scene), "--record", str(log)]) == 0
    capsys.readouterr()
    packed = tmp_path / f"packed{suffix}"
    packed.write_bytes(gzip.compress(log.read_bytes()))
    assert cli.main(["check", str(scene), "--log", str(packed)]) == 2
    err = capsys.readouterr().err
    (said,) = err.strip().splitlines()
    assert said.startswith(f"error: --log {packed}: line 1: cannot read: "), said


def _carriage_returns_only(data: bytes) -> bytes:
    """A text log's bytes with each line ended by a carriage return alone (old Mac style)."""
    return data.replace(b"\r\n", b"\n").replace(b"\n", b"\r")


@pytest.mark.parametrize("suffix", [".log", ".trc", ".asc", ".csv"])
def test_a_text_log_with_carriage_returns_alone_re_checks_to_the_live_verdict(tmp_path, capsys,
                                                                              suffix):
    # Some loggers end each line with a carriage return alone. python-can opens a text log
    # with universal line ends and reads every message of it; so does the re-check, which
    # neither takes the log for one cut line nor misses a cycle.
    scene = ROOT / "scenarios" / "approaching_target.scenario.yaml"  # 7.5 s: 150 cycles
    log = tmp_path / f"run{suffix}"
    assert cli.main(["run", str(scene), "--record", str(log)]) == 0
    capsys.readouterr()
    old_mac = tmp_path / f"mac{suffix}"
    old_mac.write_bytes(_carriage_returns_only(log.read_bytes()))
    assert b"\n" not in old_mac.read_bytes()
    shutil.copy(str(log) + ".rts.json", str(old_mac) + ".rts.json")
    assert len(list(can.LogReader(str(old_mac)))) == len(list(can.LogReader(str(log))))
    whole = check_log(load_scenario(scene), log)
    result = check_log(load_scenario(scene), old_mac)
    assert result.alignment.log_cut_short is None
    assert result.report.passed, result.report.reasons
    assert result.report.frames == whole.report.frames
    assert result.report.frames["checked"] == result.report.frames["total"] == 150
    assert result.report.bus == whole.report.bus
    # Cut in the middle of a line, it names that line, counted as python-can reads its lines.
    data, line = _mid_line_cut(log, 0.6)
    cut = tmp_path / f"cut{suffix}"
    cut.write_bytes(_carriage_returns_only(data))
    shutil.copy(str(log) + ".rts.json", str(cut) + ".rts.json")
    result = check_log(load_scenario(scene), cut)
    assert not result.report.passed
    assert result.alignment.log_cut_short["line"] == line
    assert result.alignment.log_cut_short["file_bytes"] == len(cut.read_bytes())


def test_a_cut_line_is_numbered_as_python_can_counts_lines_across_any_read_size(tmp_path):
    # Line ends of every kind in one log (a line feed, a carriage return and line feed, a
    # carriage return alone), one of them split across 1 MiB of the file: the cut line's
    # number is the one python-can's universal line ends give it.
    from rts_scenario.recheck import log_cut_short

    line = b"(1.000000) can0 100#0011223344556677\r\n"  # 38 bytes
    # A first line of a length that puts one of the carriage returns at the 1 MiB mark.
    lead = 30 + ((1 << 20) - 37 - 30) % len(line)
    first = b"(0.500000) can0 100#" + b"0" * (lead - 21) + b"\r"
    count = (1 << 20) // len(line) + 1
    data = (first + line * count + b"\n(2.000000) can0 100#00\r(3.0000")
    assert len(first) == lead
    assert data[(1 << 20) - 1:(1 << 20) + 1] == b"\r\n"
    log = tmp_path / "mixed.log"
    log.write_bytes(data)
    lines = data.decode().splitlines()
    assert len(lines) == count + 4  # with the empty line after the last CR LF
    cut = log_cut_short(log, 2.0)
    assert cut is not None and cut["line"] == count + 4


def _radar_line_numbers(lines: list[bytes], identifier: bytes) -> list[int]:
    """The indexes of a text log's lines whose words include ``identifier``."""
    return [i for i, line in enumerate(lines) if identifier in line.split()]


def _recorded_lines(tmp_path, suffix, identifier):
    """Record a quiet approaching-target run as ``run{suffix}``: the scene, the log, the live
    report, the log's lines and the indexes of those holding ``identifier``."""
    scene = load_scenario(ROOT / "scenarios" / "approaching_target.scenario.yaml", QUIET)
    log = tmp_path / f"run{suffix}"
    live = run_scene(scene, RunOptions(bus_log=str(log))).report
    assert live.passed
    lines = log.read_bytes().splitlines(keepends=True)
    detections = _radar_line_numbers(lines, identifier)
    assert len(detections) > 40
    return scene, log, live, lines, detections


def _re_checked_as(scene, log, lines, path):
    """Write ``lines`` to ``path`` with ``log``'s sidecar; return its re-check."""
    path.write_bytes(b"".join(lines))
    shutil.copy(str(log) + ".rts.json", str(path) + ".rts.json")
    return check_log(scene, path)


def test_trc_records_python_can_does_not_read_fail_a_re_check_where_they_may_be_the_radar_s(
        tmp_path):
    # python-can's TRC reader drops a record of a type it has no parser for with an info line
    # of its logger alone. Status records (ST, EC, EV) hold no identifier: noted, the verdict
    # the live one. Records of such a type holding the radar's detection identifier (0101,
    # rts-scenario's first detection message) may be its detections: the re-check fails.
    scene, log, live, lines, detections = _recorded_lines(tmp_path, ".trc", b"0101")
    status = [b"      9      1500.000 ST  1     -    Rx -  4    00 00 00 08\r\n",
              b"      9      1500.000 EC  1     -    Rx -  2    80 00\r\n",
              b"      9      1500.000 ST  1     -    Rx -  4    00 00 00 04\r\n"]
    noted = tmp_path / "status.trc"
    result = _re_checked_as(scene, log, lines[:detections[10]] + status + lines[detections[10]:],
                            noted)
    assert result.report.passed, result.report.reasons
    assert result.report.frames == live.frames
    assert (f"the log {noted} holds 3 records python-can's reader does not read (2 of type "
            f"'ST', 1 of type 'EC'), none of them with the radar's identifiers"
            in result.alignment.notes), result.alignment.notes
    assert result.alignment.to_dict()["log_unread"] == {
        "records": 3, "by_type": {"ST": 2, "EC": 1}, "with_radar_identifiers": 0,
        "first_radar_line": None}
    # A word elsewhere in a record that reads as the radar's identifier (a record number
    # written with leading zeros) is not its identifier: the header's $COLUMNS places that.
    numbered = tmp_path / "numbered.trc"
    padded = [b"   0101      1500.000 ST  1     -    Rx -  4    00 00 00 08\r\n"]
    result = _re_checked_as(scene, log, lines[:detections[10]] + padded + lines[detections[10]:],
                            numbered)
    assert result.report.passed, result.report.reasons
    assert result.alignment.to_dict()["log_unread"]["with_radar_identifiers"] == 0
    # Four of the radar's detections in records of a type python-can has no parser for.
    for i in detections[20:24]:
        lines[i] = lines[i].replace(b" DT ", b" XD ")
    dropped = tmp_path / "dropped.trc"
    result = _re_checked_as(scene, log, lines, dropped)
    assert not result.report.passed
    assert (f"the log {dropped} holds 4 records python-can's reader does not read (4 of type "
            f"'XD'), 4 of them with the radar's identifiers (the first at line "
            f"{detections[20] + 1}): the cycles they belong to are judged without them"
            in result.report.reasons), result.report.reasons
    assert result.alignment.to_dict()["log_unread"] == {
        "records": 4, "by_type": {"XD": 4}, "with_radar_identifiers": 4,
        "first_radar_line": detections[20] + 1}
    assert check_log(scene, log).alignment.to_dict()["log_unread"] is None  # all read


def test_asc_lines_python_can_does_not_read_fail_a_re_check_where_they_may_be_the_radar_s(
        tmp_path):
    # python-can's ASC reader reads error and remote frames (counted in the report's bus) and
    # passes over every other line without a word. Lines of other events (a CAN controller's
    # status, bus statistics) hold no radar message: noted. A radar frame's line it does not
    # read (its time written without a fraction) is one lost: the re-check fails.
    scene, log, live, lines, detections = _recorded_lines(tmp_path, ".asc", b"101")
    events = [b"   1.500000 CAN 1 Status:chip status error active\n",
              b"   1.500000 1 Statistic: D 257 R 0 XD 0 XR 0 E 0 O 0 B 3.21%\n"]
    noted = tmp_path / "events.asc"
    result = _re_checked_as(scene, log, lines[:detections[10]] + events + lines[detections[10]:],
                            noted)
    assert result.report.passed, result.report.reasons
    assert result.report.frames == live.frames
    assert (f"the log {noted} holds 2 records python-can's reader does not read (1 of type "
            f"'CAN', 1 of type 'Statistic'), none of them with the radar's identifiers"
            in result.alignment.notes), result.alignment.notes
    assert result.alignment.to_dict()["log_unread"] == {
        "records": 2, "by_type": {"CAN": 1, "Statistic": 1}, "with_radar_identifiers": 0,
        "first_radar_line": None}
    at = detections[20]
    time_s, rest = lines[at].split(None, 1)
    lines[at] = b"   " + str(round(float(time_s))).encode() + b" " + rest
    dropped = tmp_path / "dropped.asc"
    result = _re_checked_as(scene, log, lines, dropped)
    assert not result.report.passed
    assert (f"the log {dropped} holds 1 record python-can's reader does not read (1 of type "
            f"'Rx'), 1 of them with the radar's identifiers (the first at line {at + 1}): the "
            f"cycles they belong to are judged without them"
            in result.report.reasons), result.report.reasons
    assert result.alignment.to_dict()["log_unread"] == {
        "records": 1, "by_type": {"Rx": 1}, "with_radar_identifiers": 1,
        "first_radar_line": at + 1}


@pytest.mark.parametrize("suffix", [".blf", ".asc", ".trc", ".log", ".csv", ".mf4"])
def test_an_empty_log_is_said_to_be_empty(tmp_path, capsys, suffix):
    # A recorder that never wrote leaves a file of 0 bytes: said so, not in a reader's words
    # ("unpack requires a buffer of 72 bytes") or as a log holding no radar cycle.
    log = tmp_path / f"empty{suffix}"
    log.write_bytes(b"")
    scene = str(ROOT / "scenarios" / "approaching_target.scenario.yaml")
    assert cli.main(["check", scene, "--log", str(log)]) == 2
    assert capsys.readouterr().err == (f"error: --log {log}: the file is empty (0 bytes): "
                                       f"nothing was recorded in it\n")


@pytest.mark.parametrize("name, limits", [
    ("wide-3x5", "limits: {attenuation_step_db: 0.5}\n"),  # the rig file edited since the run
    ("lab", "limits: {attenuation_step_db: 0.5}\n"),  # another rig of the same FEs
    ("lab", ""),  # the same rig under another name: it plays the same
])
def test_a_log_re_checked_on_another_rig_than_it_was_played_on_is_refused(
        recorded, tmp_path, capsys, name, limits):
    # The sidecar keeps the rig the run played on (its name and a digest of its FEs,
    # calibration and limits): another rig would have played other levels and statuses, so
    # a re-check on it would judge a run that never happened.
    text = (ROOT / "rts_scenario" / "data" / "rigs" / "wide-3x5.rig.yaml").read_text()
    rig = tmp_path / "edited.rig.yaml"
    rig.write_text(text.replace("name: wide-3x5\n", f"name: {name}\n") + limits)
    scene = tmp_path / "highway_following.scenario.yaml"
    scene.write_text(re.sub(r"(?m)^rig: .*$", f"rig: {rig.name}",
                            (ROOT / "scenarios" / "highway_following.scenario.yaml").read_text()))
    code = cli.main(["check", str(scene), "--log", str(recorded)])
    err = capsys.readouterr().err
    if not limits:
        assert code == 0, err
        return
    assert code == 2
    assert err == (
        f"error: --log {recorded}: played on rig 'wide-3x5' (its sidecar), not on the scene's "
        f"{name!r}" + (" as it is now (its FEs, calibration or limits were edited since)"
                       if name == "wide-3x5" else "")
        + ": another rig plays other levels and statuses; check the log against the scene "
        "file and rig it was played with\n")


def test_a_recording_ends_with_the_last_message_the_run_counted(tmp_path):
    # The bus stays open after the run has taken its counts, until the pipeline closes: what
    # arrives then (a radar that keeps measuring, another node) is neither counted by the run
    # nor recorded, so a re-check of the log counts what the run did.
    scene = load_scenario(CUT_IN, QUIET)
    log = tmp_path / "run.blf"
    with Pipeline.for_scene(scene, RunOptions(bus_log=str(log))) as pipeline:
        live = pipeline.run(scene).report
        counted = pipeline.receiver.stats.messages
        with can.Bus(interface="virtual", channel=pipeline.channel) as other:
            for n in range(3):
                other.send(can.Message(arbitration_id=0x7F0 + n, data=bytes(8),
                                       is_extended_id=False))
            deadline = time.monotonic() + 5.0
            while pipeline.receiver.stats.messages < counted + 3 and time.monotonic() < deadline:
                time.sleep(0.01)
        assert pipeline.receiver.stats.messages == counted + 3  # received, after the counts
    again = check_log(scene, log).report
    assert live.passed and again.passed
    assert again.bus["messages"] == live.bus["messages"]
    assert again.bus["unknown_ids"] == live.bus["unknown_ids"] == 0


@pytest.mark.parametrize("shift_s, code", [(5.7, 2), (-2.0, 2), (-300.0, 2), (86400.0 + 7.3, 2),
                                           (3600.0, 0), (-1800.0, 0), (0.0, 0)])
def test_a_log_beside_the_sidecar_of_another_run_is_refused(recorded, tmp_path, capsys,
                                                            shift_s, code):
    # The sidecar of a run whose scene started shift_s later on the bus's clock than this
    # log's (a log copied over another run's, a logger of its own writing to the same name):
    # its counters name the cycles as that run's, and a log of a passing run re-checked as a
    # failing one passed. Its cycles lie seconds off where the run timed them: refused. A
    # whole number of quarter hours is a tool or another machine's time zone moving the
    # stamps: judged by the counters, as before.
    data = json.loads(Path(str(recorded) + ".rts.json").read_text())
    data["clock"]["origin_bus_s"] += shift_s
    log = _copy(recorded, tmp_path, json.dumps(data))
    scene = str(ROOT / "scenarios" / "highway_following.scenario.yaml")
    assert cli.main(["check", scene, "--log", str(log)]) == code
    err = capsys.readouterr().err
    if code == 0:
        assert "error:" not in err
        return
    when = "before" if shift_s > 0 else "after"
    off = abs(shift_s) % 900.0 if shift_s > 0 else abs(shift_s)
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith(f"error: --log {log}: its radar cycles were stamped {off:.1f} s {when} "
                          f"the times the run its sidecar ({log}.rts.json) records timed them"), err
    assert "a log of another run" in err


def test_a_log_named_as_given_to_record_for_a_parametrized_scene_names_the_variants_logs(
        tmp_path, capsys):
    # `run cut_in --record drive.blf` writes drive[estimator=bartlett].blf and
    # drive[estimator=ti].blf; `check cut_in --log drive.blf` said only "no such file".
    for variant in ("estimator=bartlett", "estimator=ti"):
        (tmp_path / f"drive[{variant}].blf").write_bytes(b"x")
    log = tmp_path / "drive.blf"
    assert cli.main(["check", str(CUT_IN), "--log", str(log)]) == 2
    assert capsys.readouterr().err == (
        f"error: --log {log}: no such file; beside it, the logs run --record wrote for each "
        f"variant of a parametrized scene: {tmp_path}/drive[estimator=bartlett].blf, "
        f"{tmp_path}/drive[estimator=ti].blf\n")
    assert cli.main(["check", str(CUT_IN), "--log", str(tmp_path / "other.blf")]) == 2
    assert capsys.readouterr().err == f"error: --log {tmp_path / 'other.blf'}: no such file\n"


def test_a_sidecar_with_host_clock_steps_the_log_lacks_fails_on_them_not_as_another_run(
        recorded, tmp_path, capsys):
    # Stamps the run brought back from a cycle the log lacks are judged as they are: the
    # re-check fails with host_clock, whatever the stamps' offset from the sidecar's start.
    data = json.loads(Path(str(recorded) + ".rts.json").read_text())
    data["clock"]["origin_bus_s"] += 5.7
    data["clock"]["bus_time_shifts"] = [{"bus_s": 1.0, "counter": 5, "shift_s": 0.5}]
    log = _copy(recorded, tmp_path, json.dumps(data))
    scene = str(ROOT / "scenarios" / "highway_following.scenario.yaml")
    assert cli.main(["check", scene, "--log", str(log)]) == 1
    out = capsys.readouterr().out
    assert "host_clock: the host's wall clock stepped while the run recorded" in out


@pytest.mark.parametrize("suffix", [".blf", ".asc"])
def test_a_log_cut_short_before_any_message_is_not_a_silent_bus(tmp_path, capsys, suffix):
    # A recorder killed before it wrote a message: the log holds its header alone. That says
    # nothing of the bus: the log's fault comes first, and the bus is not called silent.
    scene = ROOT / "scenarios" / "approaching_target.scenario.yaml"
    log = tmp_path / f"run{suffix}"
    assert cli.main(["run", str(scene), "--record", str(log)]) == 0
    capsys.readouterr()
    data = log.read_bytes()
    cut = tmp_path / f"cut{suffix}"
    if suffix == ".blf":
        cut.write_bytes(data[:144])  # the file header alone
    else:
        head = data.index(b"Start of measurement")  # its header and first line
        cut.write_bytes(data[:data.index(b"\n", head) + 1])
    shutil.copy(str(log) + ".rts.json", str(cut) + ".rts.json")
    out_json = tmp_path / "check.json"
    assert cli.main(["check", str(scene), "--log", str(cut), "--json", str(out_json)]) == 1
    capsys.readouterr()
    report = json.loads(out_json.read_text())
    assert report["reasons"][0].startswith(f"the log {cut} was cut short"), report["reasons"]
    assert not any("silent" in r for r in report["reasons"]), report["reasons"]
    assert report["bus"]["messages"] == 0


@pytest.mark.parametrize("declared", [False, True])
def test_an_empty_bench_the_simulated_radar_played_re_checks_to_the_live_verdict(tmp_path,
                                                                                 declared):
    # The simulated radar's empty bench checks nothing: the run fails with nothing_checked
    # unless the scene declares it, and the re-check of its log (the sidecar says what played
    # it) does the same, where it passed with nothing said.
    scene = load_scenario(ROOT / "scenarios" / "empty_bench.scenario.yaml", {
        "duration_s": 1.0,
        "expectations.expected_limits": ["nothing_checked"] if declared else []})
    log = tmp_path / "bench.blf"
    live = run_scene(scene, RunOptions(bus_log=str(log))).report
    again = check_log(scene, log).report
    assert (live.passed, again.passed) == (declared, declared)
    assert again.reason_codes == live.reason_codes == ([] if declared else ["nothing_checked"])
    assert again.scene_limits == live.scene_limits
    assert ("nothing_checked" in again.scene_limits) == declared


def test_a_counter_skipping_ahead_in_a_log_without_sidecar_is_named_as_such(tmp_path):
    # The radar's counter steps by 1001 at cycle 100, its timing unchanged. The re-check
    # called it a jump of the log's stamps by -72 s, a host clock's step or a latency change
    # alone: whole cycles are as well a count that skipped.
    scene, log, _ = foreign_log(
        tmp_path, 1.7e9 + 10.0,
        tamper=lambda c: replace(c, cycle=c.cycle + (1000 if c.cycle >= 4242 + 100 else 0)))
    report = check_log(scene, log).report
    assert not report.passed and "log_stamps" in report.reason_codes
    (reason,) = [r for r in report.reasons if r.startswith("log_stamps:")]
    assert re.search(r"stamps jump by -720\d\d\.\d ms from its cycle 10[01] on, .*\(1000 whole "
                     r"cycles: the radar's counter skipped 1000 cycles ahead \(the cycles after "
                     r"it are named by their counter\), or the host's clock stepped by as much",
                     reason), reason


def test_a_re_check_by_the_sidecar_names_the_sidecar_as_the_latency_s_source(recorded):
    scene = load_scenario(ROOT / "scenarios" / "highway_following.scenario.yaml")
    alignment = check_log(scene, recorded).alignment
    assert alignment.source == "sidecar" and alignment.latency_source == "sidecar"
    assert alignment.to_dict()["latency_source"] == "sidecar"


PARKED = """\
rts_scenario: 1
name: parked
duration_s: 10.0
frame_rate_hz: 20.0
radar: {profile: awr1843boost, mount: {x_m: 3.7, z_m: 0.5}, fidelity: analytic}
rig: wide-3x5
ego:
  motion: {type: stationary, position_m: [0, 0, 0]}
targets:
  - {name: parked-car, kind: car, rcs: {rcs_dbsm: 10.0},
     motion: {type: stationary, position_m: [30.0, 1.0, 0.6]}}
"""


def test_a_still_scene_held_after_its_play_is_one_play_not_two(tmp_path):
    # The RTS holds the last frame after the play; the logger ran on for 6 s. The held
    # detections fit a still scene a scene's length later as well: "the log holds 2 plays",
    # refused. They are the last frame held, which fits them as well.
    path = tmp_path / "parked.scenario.yaml"
    path.write_text(PARKED)
    log = tmp_path / "held.blf"
    run_scene(load_scenario(path, {"duration_s": 16.0}), RunOptions(bus_log=str(log)))
    Path(f"{log}.rts.json").unlink()
    report = check_log(load_scenario(path), log).report
    assert report.frames["checked"] == report.frames["total"] == 200
