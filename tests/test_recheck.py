"""Recording the bus and re-checking logs: the live verdict again, or aligned by timestamps."""

import json
import shutil
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
    assert again.alignment.schedule_matches_recording is True
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


def write_radar(folder: Path, **clock) -> str:
    data = yaml.safe_load((ROOT / "rts_scenario/data/radars/awr1843boost.radar.yaml")
                          .read_text())
    data["name"] = "own-clock"
    data["clock"] = clock
    (folder / "radars").mkdir(exist_ok=True)
    (folder / "radars" / "own.radar.yaml").write_text(yaml.safe_dump(data))
    return "radars/own.radar.yaml"


def foreign_log(tmp_path: Path, origin_s: float, seed: int = 0, tamper=None, suffix=".blf",
                busy=False, lead_s=0.0):
    """A log as another tool writes it: the radar on its own clock, timestamps in that tool's
    time base (scene time 0 at ``origin_s``), latency and jitter on every cycle, no sidecar."""
    shutil.copy(CUT_IN, tmp_path / "cut_in.scenario.yaml")
    radar = write_radar(tmp_path, cycle_s=0.072, start_offset_s=0.013, latency_s=0.13,
                        jitter_s=0.004, counter_start=4242)
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

    def sink(cycles):
        for cycle in cycles:
            stamp["t"] = origin_s + cycle.t_s + clock.latency_s + rng.uniform(-0.004, 0.004)
            publisher.publish(tamper(cycle) if tamper else cycle)

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
    if busy:
        assert result.report.bus["unknown_ids"] > 1000
        assert result.report.bus["before_first_cycle"] >= 2  # the cycle the log began in


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
    # One too early shows as a latency far from the radar's profile.
    early = check_log(scene, log, time_offset_s=origin - 0.6)
    assert early.alignment.latency_s == pytest.approx(0.73, abs=0.01)
    assert any("differs from its profile's 130.0 ms" in n for n in early.alignment.notes)


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
