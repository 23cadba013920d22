"""The host's wall clock stepping while a run plays (an NTP step, a manual change, a VM resuming).

python-can stamps messages with ``time.time()``, the host receives them on it, and the scene's
start is taken on it: a step moves every later time but not the start. A run watches the wall
clock against the monotonic one, brings the times back by the steps and says so.
"""

import json
import shutil
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from free_radar import behind_own_clock
from test_emulate import bench_scene, rehearse
from test_radar_clock import free_radar

from rts_scenario.hostclock import SLEW_PPM, STEP_TOLERANCE_S, HostClockWatch
from rts_scenario.pipeline import Pipeline, RunOptions
from rts_scenario.radar.profile import RadarProfile
from rts_scenario.recheck import check_log

# In wall-clock time: run with the session's heap frozen (conftest `frozen_heap`).
REAL_TIME = True


class SteppedWallClock:
    """``time.time`` as a host's wall clock that steps by ``step`` when told (`step`)."""

    def __init__(self, monkeypatch):
        real = time.time
        self.offset_s = 0.0
        monkeypatch.setattr(time, "time", lambda: real() + self.offset_s)

    def step(self, size_s):
        self.offset_s += size_s



def interface_stamps_unstepped(pipeline, wall):
    """The simulated radar's interface stamps with its own clock, which does not step; the
    host receives its messages on the stepped wall clock."""
    bus = pipeline._publisher.bus
    send = bus.send

    def unstepped(msg, timeout=None):
        msg.timestamp -= wall.offset_s
        send(msg, timeout)

    bus.send = unstepped
    receipt = pipeline.receiver.received_at
    pipeline.receiver.received_at = lambda msg: receipt(msg) + wall.offset_s

def test_the_watch_tells_a_step_from_the_wall_clock_s_slew(monkeypatch):
    wall = SteppedWallClock(monkeypatch)
    watch = HostClockWatch()
    assert watch.sample() == 0.0 and watch.steps == []
    # Below the tolerance: a slew (or a reading's jitter), not a step.
    wall.step(0.5 * STEP_TOLERANCE_S)
    assert watch.sample() == 0.0 and watch.steps == []
    wall.step(0.5)
    # The step is measured from the reading before: a slew before it is not part of it.
    assert watch.sample() == pytest.approx(0.5, abs=1e-4)
    (step,) = watch.steps
    assert step.size_s == pytest.approx(0.5, abs=1e-3) and step.after_s < step.before_s
    wall.step(-0.2)
    assert watch.sample() == pytest.approx(0.3, abs=2e-3)
    assert [round(s.size_s, 3) for s in watch.steps] == [0.5, -0.2]
    assert watch.levels() == [0.0, *(s.level_s for s in watch.steps)]
    # A reading between the two a step fell between is placed by its wall time.
    first = watch.steps[0]
    mid = 0.5 * (first.after_s + first.before_s)
    offset0 = time.time() - time.monotonic() - watch.level_s
    assert watch.level_at(mid, mid + offset0) == 0.0
    assert watch.level_at(mid, mid + offset0 + first.size_s) == first.level_s
    assert watch.level_at(first.before_s) == first.level_s
    assert SLEW_PPM == 500.0  # NTP's limit: 0.5 ms a second at most


def desk_run(monkeypatch, tmp_path, step_s, *, after_batches=2, log=None):
    """A radar running free on the desk (50 ms, 31 ms into its cycle at the scene's start); the
    host's wall clock steps by ``step_s`` after ``after_batches`` batches of 40 frames (2 s)."""
    scene, radar = free_radar(tmp_path)
    wall = SteppedWallClock(monkeypatch)
    batches = []

    def progress(done, total):
        batches.append(done)
        if len(batches) == after_batches:
            wall.step(step_s)

    options = RunOptions(batch_frames=40, bus_log=None if log is None else str(log))
    with Pipeline.for_scene(scene, options) as pipeline:
        pipeline.output.clock = radar
        report = pipeline.run(scene, progress=progress).report
    return scene, report


@pytest.mark.parametrize("step_s", [0.5, -0.2])
def test_a_host_clock_step_mid_run_is_told_and_its_cycles_judged_as_if_it_had_not(
        monkeypatch, tmp_path, step_s):
    log = tmp_path / "stepped.blf"
    scene, report = desk_run(monkeypatch, tmp_path, step_s, log=log)
    assert report.passed, report.reasons
    clock = report.radar_clock
    (step,) = clock["host_clock_steps"]
    assert step["size_s"] == pytest.approx(step_s, abs=2e-3)
    assert step["corrected"] == "bus and receipt times"
    # Told at the batch after the second (4 s of the 12 s scene played on the desk in far
    # less: the scene's time of a reading is the host's since the start, not the scene's).
    assert 0.0 <= step["at_s"] and 0.0 <= step["within_s"]
    # The radar's phase and cycle as if the clock had not stepped.
    assert clock["start_offset_s"] == pytest.approx(0.031, abs=5e-4)
    assert "latency_change_s" not in clock
    assert report.frames["checked"] == report.frames["total"] == 240
    assert "host clock" in report.table() and f"{step_s * 1e3:+.1f} ms" in report.table()
    # Its log's sidecar keeps where the stamps stepped: the re-check judges alike.
    again = check_log(scene, log).report
    assert again.passed, again.reasons
    assert again.frames == report.frames
    (told,) = again.radar_clock["host_clock_steps"]
    assert told["size_s"] == pytest.approx(step_s, abs=2e-3)
    # Without its sidecar nothing says the host's clock stepped: aligned by its timestamps,
    # the re-check says where they jump, and fails rather than judge the cycles after it off.
    bare = tmp_path / "bare.blf"
    shutil.copy(log, bare)
    blind = check_log(scene, bare)
    assert not blind.report.passed
    (reason,) = [r for r in blind.report.reasons if r.startswith("log_stamps:")]
    size = float(reason.split("jump by ")[1].split(" ms")[0]) * 1e-3
    assert size == pytest.approx(step_s, abs=3e-3)
    # Whole cycles of the radar's (0.5 s, 0.2 s of 50 ms), its count contiguous: no skip of
    # its counter is named.
    assert "counter skipped" not in reason and "host's clock stepped" in reason
    # A sidecar naming a cycle the log lacks: its stamps cannot be brought back, it says so.
    sidecar = Path(f"{log}.rts.json")
    data = json.loads(sidecar.read_text())
    data["clock"]["bus_time_shifts"][0]["bus_s"] += 1.0
    sidecar.write_text(json.dumps(data))
    lost = check_log(scene, log).report
    assert not lost.passed
    assert any(r.startswith("host_clock: ") and "not in the log" in r for r in lost.reasons)


@pytest.mark.parametrize("step_s", [-0.5, -0.2, 0.5])
def test_without_bringing_the_times_back_the_same_step_fails_the_run(monkeypatch, tmp_path,
                                                                     step_s):
    # The control: a step back is one a run misjudges when it takes the stamps as they are,
    # and nothing it says names the cause (-0.5 s: the cycles before the step judged against
    # frames 10 away; -0.2 s: cycles taken for missing). A step forward reads as messages
    # held up from then on: the phase is the radar's own (its cycles' lowest level of bus
    # times less their numbers), the cycles are judged at their times, and the run passes.
    monkeypatch.setattr(Pipeline, "_unstep", lambda self, cycles, *args: cycles)
    _, report = desk_run(monkeypatch, tmp_path, step_s)
    if step_s > 0:
        assert report.passed, report.reasons
        return
    assert not report.passed
    assert not any("host" in r for r in report.reasons), report.reasons


def test_no_step_no_key(monkeypatch, tmp_path):
    _, report = desk_run(monkeypatch, tmp_path, 0.0)
    assert report.passed, report.reasons
    assert "host_clock_steps" not in report.radar_clock
    assert np.isfinite(report.radar_clock["start_offset_s"])


def emulated_run(monkeypatch, tmp_path, step_s, log=None):
    """A 4 s scene over UDP to the emulated RTS, its radar running free on a virtual CAN bus
    (python-can stamps every message with ``time.time()``); the host's wall clock steps by
    ``step_s`` 2 s into the scene, in real time (timed from its first frame: setting the run
    up takes a second or two where the solver's plans are not cached yet, more on a loaded
    machine)."""
    from rts_scenario.outputs.udp import UdpOutput

    scene = bench_scene(tmp_path, duration_s=4.0, counter_start="auto")
    radar = RadarProfile.from_file(tmp_path / "radars" / "bench.radar.yaml")
    wall = SteppedWallClock(monkeypatch)
    timer = threading.Timer(2.0, wall.step, [step_s])
    wait = UdpOutput._wait_for

    def first_frame_starts_the_timer(self, t_s):
        if self._start is None:
            timer.start()
        return wait(self, t_s)

    monkeypatch.setattr(UdpOutput, "_wait_for", first_frame_starts_the_timer)
    try:
        report, _ = rehearse(scene, radar=radar, mapping=None,
                             bus_log=None if log is None else str(log))
    finally:
        timer.cancel()
    return scene, report


@pytest.mark.parametrize("step_s", [0.5, -0.2])
def test_a_host_clock_step_on_the_emulated_bench_is_told_and_corrected(monkeypatch, tmp_path,
                                                                        step_s):
    log = tmp_path / "bench.blf"
    scene, report = emulated_run(monkeypatch, tmp_path, step_s, log=log)
    assert report.passed, report.reasons
    (step,) = report.radar_clock["host_clock_steps"]
    assert step["size_s"] == pytest.approx(step_s, abs=2e-3)
    assert step["corrected"] == "bus and receipt times"
    # 2 s into the run, the scene's start a transport's delay in: wide for a loaded machine.
    assert 1.0 < step["at_s"] < 3.5
    assert report.frames["checked"] == report.frames["total"]
    again = check_log(scene, log).report
    assert again.passed, again.reasons
    assert {k: v for k, v in again.frames.items() if k != "after_scene"} == {
        k: v for k, v in report.frames.items() if k != "after_scene"}


def test_without_bringing_the_times_back_the_emulated_bench_fails(monkeypatch, tmp_path):
    monkeypatch.setattr(Pipeline, "_unstep", lambda self, cycles, *args: cycles)
    _, report = emulated_run(monkeypatch, tmp_path, -0.5)
    assert not report.passed
    assert not any("host" in r for r in report.reasons), report.reasons


@pytest.mark.parametrize("step_s", [0.5, -0.2])
def test_behind_an_interface_with_its_own_clock_only_the_receipts_are_brought_back(
        monkeypatch, tmp_path, step_s):
    # The interface stamps with its own clock (seconds since it was plugged in), which the
    # host's step does not move; the host receives on its wall clock, which it does. The
    # receipts tie the interface's clock to the host's: brought back, the tie holds.
    scene, radar = free_radar(tmp_path)
    wall = SteppedWallClock(monkeypatch)
    batches = []

    def progress(done, total):
        batches.append(done)
        if len(batches) == 2:
            wall.step(step_s)

    with Pipeline.for_scene(scene, RunOptions(batch_frames=40)) as pipeline:
        behind_own_clock(pipeline, 0.031, early=0)
        pipeline.output.clock = radar
        interface_stamps_unstepped(pipeline, wall)
        report = pipeline.run(scene, progress=progress).report
    assert report.passed, report.reasons
    clock = report.radar_clock
    assert clock["bus_clock"] == "interface"
    (step,) = clock["host_clock_steps"]
    assert step["size_s"] == pytest.approx(step_s, abs=2e-3)
    assert step["corrected"] == "receipt times (the interface stamps with its own clock)"
    # Tied within the fastest delivery (3 ms) and the line's 1 ms.
    assert clock["start_offset_s"] == pytest.approx(0.031, abs=0.005)
    assert report.frames["checked"] == report.frames["total"]


def test_a_reading_another_thread_overtook_keeps_the_level_it_was_read_at(monkeypatch):
    import rts_scenario.hostclock as hostclock

    readings = iter([])

    def feed(*pairs):  # (monotonic, wall) readings, each read as m0, wall, m1
        nonlocal readings
        readings = iter([v for m, w in pairs for v in (m, w, m)])

    monkeypatch.setattr(hostclock, "monotonic_s", lambda: next(readings))
    monkeypatch.setattr(hostclock, "wall_s", lambda: next(readings))
    feed((0.0, 100.0))
    watch = HostClockWatch()
    feed((9.0, 109.0), (10.0, 110.5), (9.5, 109.5), (9.6, 110.1))
    assert watch.read() == (109.0, 0.0)
    assert watch.read() == (110.5, 0.5)  # the step, between 9 s and 10 s
    # Read before the watch took the step, handed in after: at the level it was read at.
    assert watch.read() == (109.5, 0.0)
    assert watch.read() == (110.1, 0.5)
    assert len(watch.steps) == 1


# --- a step during a measurement (survey, calibrate: `Pipeline.play`) -----------------------

def step_during(monkeypatch, wall, step_s, measurement=0):
    """Step the host's wall clock by ``step_s`` as the ``measurement``-th pattern (from 0)
    goes out to the RTS: after the measurement's start was taken, before any cycle."""
    write, calls = Pipeline.write, []

    def stepped(self, schedule):
        if len(calls) == measurement:
            wall.step(step_s)
        calls.append(schedule.n_frames)
        write(self, schedule)

    monkeypatch.setattr(Pipeline, "write", stepped)


def surveyed(radar, errors):
    from rts_scenario import Rig
    from rts_scenario.scenario.model import RadarOptions
    from rts_scenario.survey import survey

    rig = Rig.preset("kit-table1")
    with Pipeline(rig, radar, radar_options=RadarOptions(fidelity="analytic", noise=False),
                  errors=errors) as bench:
        result = survey(rig, radar, bench.play)
    return rig, result, bench.measurement_steps


def moved_front_ends():
    from rts_scenario.radar.simulate import ChannelErrors

    return ChannelErrors(gain_db=np.array([0.0, -1.5, 0.0, 2.0]), phase_deg=np.zeros(4),
                         delay_s=np.zeros(4), az_deg=np.array([0.3, 0.0, -0.2, 0.0]),
                         el_deg=np.array([0.0, 0.25, 0.0, -0.1]), distance_m=np.zeros(4))


def free_paper_radar():
    from free_radar import free_profile

    return free_profile(RadarProfile.preset("paper"), 1.5)


@pytest.mark.parametrize("step_s", [0.5, -0.2])
def test_a_host_clock_step_during_a_survey_is_told_and_its_cycles_placed_as_if_it_had_not(
        monkeypatch, step_s):
    # A radar running free: its cycles are placed in the measurement by their bus times less
    # its latency, against the measurement's start taken before the step.
    radar, moved = free_paper_radar(), moved_front_ends()
    wall = SteppedWallClock(monkeypatch)
    step_during(monkeypatch, wall, step_s)
    rig, result, steps = surveyed(radar, moved)
    # Where each FE stands (classic CAN: 0.005 deg), as without the step.
    np.testing.assert_allclose(result.seen_az_deg, rig.az_deg + moved.az_deg, atol=0.006)
    np.testing.assert_allclose(result.seen_el_deg, rig.el_deg + moved.el_deg, atol=0.006)
    np.testing.assert_allclose(result.level_db, moved.gain_db, atol=0.26)
    (step,) = steps
    assert step["measurement"] == 0
    assert step["size_s"] == pytest.approx(step_s, abs=2e-3)
    assert step["corrected"] == "bus and receipt times"
    assert 0.0 <= step["at_s"] < 30.0 and 0.0 <= step["within_s"] < 30.0


@pytest.mark.parametrize("step_s", [0.5, -0.2])
def test_without_bringing_the_times_back_the_survey_sees_other_front_ends(monkeypatch,
                                                                          step_s):
    # The control: taken as they are, the stepped stamps place every cycle 10 (4) cycles off:
    # each FE is surveyed by another FE's cycles, or by none.
    monkeypatch.setattr(Pipeline, "_unstep", lambda self, cycles, *args: cycles)
    radar, moved = free_paper_radar(), moved_front_ends()
    wall = SteppedWallClock(monkeypatch)
    step_during(monkeypatch, wall, step_s)
    rig, result, _ = surveyed(radar, moved)
    seen = rig.az_deg + moved.az_deg
    assert not np.all(np.abs(result.seen_az_deg - seen) < 0.006), result.seen_az_deg


def test_no_step_during_a_survey_no_step_told(monkeypatch):
    radar, moved = free_paper_radar(), moved_front_ends()
    rig, result, steps = surveyed(radar, moved)
    np.testing.assert_allclose(result.seen_az_deg, rig.az_deg + moved.az_deg, atol=0.006)
    assert steps == []


@pytest.mark.parametrize("command, measurement", [
    (["survey", "kit-table1", "--radar", "paper"], 0),
    (["calibrate", "kit-table1", "--inject-phase-deg", "30", "--seed", "1"], 3)])
def test_survey_and_calibrate_say_a_host_clock_step_in_their_text_and_json(
        command, measurement, monkeypatch, tmp_path, capsys):
    import rts_scenario.cli as cli

    wall = SteppedWallClock(monkeypatch)
    step_during(monkeypatch, wall, 0.5, measurement)
    out_json = tmp_path / "out.json"
    code = cli.main([*command, "--json", str(out_json)])
    out, err = capsys.readouterr()
    assert code == 0, out + err
    (step,) = json.loads(out_json.read_text())["host_clock_steps"]
    assert set(step) == {"measurement", "at_s", "within_s", "size_s", "corrected"}
    assert step["measurement"] == measurement
    assert step["size_s"] == pytest.approx(0.5, abs=2e-3)
    assert step["corrected"] == "bus and receipt times"
    (line,) = [x for x in out.splitlines() if x.startswith("host clock:")]
    assert line.startswith("host clock: the wall clock stepped +500.")
    assert f"after measurement {measurement}'s start" in line
    assert line.endswith("corrected: bus and receipt times")


def survey_behind_own_clock(monkeypatch, step_s):
    """Survey a free radar behind an interface stamping with its own clock (which the host's
    step does not move; the host's receipts it does), the host's clock stepping by
    ``step_s`` as the pattern goes out."""
    from rts_scenario import Rig
    from rts_scenario.scenario.model import RadarOptions
    from rts_scenario.survey import survey

    radar, moved, rig = free_paper_radar(), moved_front_ends(), Rig.preset("kit-table1")
    wall = SteppedWallClock(monkeypatch)
    step_during(monkeypatch, wall, step_s)
    with Pipeline(rig, radar, radar_options=RadarOptions(fidelity="analytic", noise=False),
                  errors=moved) as bench:
        behind_own_clock(bench, 0.031)
        interface_stamps_unstepped(bench, wall)
        result = survey(rig, radar, bench.play)
    return rig, moved, result, bench.measurement_steps


@pytest.mark.parametrize("step_s", [0.5, -0.2])
def test_a_survey_behind_an_interface_with_its_own_clock_brings_the_receipts_back(
        monkeypatch, step_s):
    rig, moved, result, steps = survey_behind_own_clock(monkeypatch, step_s)
    np.testing.assert_allclose(result.seen_az_deg, rig.az_deg + moved.az_deg, atol=0.006)
    np.testing.assert_allclose(result.seen_el_deg, rig.el_deg + moved.el_deg, atol=0.006)
    (step,) = steps
    assert step["size_s"] == pytest.approx(step_s, abs=2e-3)
    assert step["corrected"] == "receipt times (the interface stamps with its own clock)"


def test_without_bringing_the_receipts_back_the_survey_behind_an_interface_is_off(
        monkeypatch):
    monkeypatch.setattr(Pipeline, "_unstep", lambda self, cycles, *args: cycles)
    rig, moved, result, _ = survey_behind_own_clock(monkeypatch, 0.5)
    seen = rig.az_deg + moved.az_deg
    assert not np.all(np.abs(result.seen_az_deg - seen) < 0.006), result.seen_az_deg
