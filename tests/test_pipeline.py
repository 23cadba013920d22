"""The pipeline: batches change nothing, every bus closes, nothing unseen passes."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from rts_scenario import OutputError
from rts_scenario.kinematics import compute_tracks
from rts_scenario.pipeline import Pipeline, RunOptions, run_scene
from rts_scenario.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]
PLATOON = ROOT / "scenarios" / "highway_platoon_60s.scenario.yaml"
CUT_IN = ROOT / "scenarios" / "cut_in.scenario.yaml"


pytestmark = pytest.mark.usefixtures("no_bus_left_open")


def test_tracks_in_batches_equal_the_whole_scene():
    scene = load_scenario(PLATOON)  # Swerling targets: the fluctuation must not restart
    whole = compute_tracks(scene)
    edges = [0, 1, 333, 334, 900, scene.n_frames]
    parts = [compute_tracks(scene, scene.t_s[a:b], np.arange(a, b))
             for a, b in zip(edges, edges[1:], strict=False)]
    for field in dataclasses.fields(whole):
        if not isinstance(getattr(whole, field.name), np.ndarray):  # names, the radar's limits
            assert all(getattr(p, field.name) == getattr(whole, field.name) for p in parts)
            continue
        joined = np.concatenate([getattr(p, field.name) for p in parts])
        np.testing.assert_array_equal(joined, getattr(whole, field.name), err_msg=field.name)
    # The fluctuation is a fluctuation: Swerling 1 power has unit mean and unit variance.
    power = 10.0 ** ((whole.rcs_dbsm[:, 0] - 10.0) / 10.0)
    assert power.mean() == pytest.approx(1.0, abs=0.1)
    assert power.var() == pytest.approx(1.0, abs=0.25)


def test_batch_size_does_not_change_the_verdict(no_bus_left_open):
    scene = load_scenario(CUT_IN, {"radar.noise": False})
    small = run_scene(scene, RunOptions(batch_frames=37)).report
    large = run_scene(scene, RunOptions(batch_frames=1000)).report
    assert small.passed and large.passed
    assert small.frames == large.frames and small.target_frames == large.target_frames
    for q in ("range_m", "az_deg", "el_deg"):
        assert small.errors[q].max == pytest.approx(large.errors[q].max, rel=1e-9)
    assert len(no_bus_left_open) == 4  # a listener and a publisher per run, all closed


def test_an_output_that_plays_to_no_radar_fails_the_run(tmp_path):
    # The schedule goes to a file and no radar answers: every frame is missing, nothing passes.
    options = RunOptions(output=f"file:{tmp_path / 'schedule.npz'}", drain_s=0.3)
    report = run_scene(CUT_IN, options).report
    assert not report.passed
    assert report.frames["missing"] == report.frames["total"] == 240
    assert report.frames["checked"] == 0
    assert any("silent" in r for r in report.reasons)
    assert (tmp_path / "schedule.npz").exists()


def test_unknown_output_lists_the_valid_ones_and_closes_the_bus():
    scene = load_scenario(CUT_IN)
    with pytest.raises(OutputError, match="valid outputs: .*simulated-radar"):
        Pipeline.for_scene(scene, RunOptions(output="carrier-pigeon"))


def test_record_reads_every_frame_back():
    report = run_scene(CUT_IN, RunOptions(record=True, batch_frames=100)).report
    frames = report.per_frame
    np.testing.assert_array_equal(frames["frame"], np.arange(240))
    assert frames["error_az_deg"].shape == (240, 1)
    assert int(frames["detected"].sum()) == report.targets[0].detected_frames
    assert report.to_json()  # the record handle stays out of the JSON


def test_pipeline_plays_a_schedule_for_calibration():
    scene = load_scenario(CUT_IN, {"radar.noise": False})
    from rts_scenario.schedule import build_schedule

    schedule = build_schedule(compute_tracks(scene), scene.rig, scene.radar).frames(0, 5)
    with Pipeline.for_scene(scene) as pipeline:
        cycles = pipeline.play(schedule)
    assert [c.cycle for c in cycles] == [0, 1, 2, 3, 4]
    assert all(c.complete and c.count == 1 for c in cycles)


def test_public_api_names_every_stage():
    import rts_scenario as rs

    assert sorted(rs.__all__) == sorted(rs._EXPORTS)
    for name in rs.__all__:
        assert getattr(rs, name) is not None
    result = rs.run_scene(CUT_IN, rs.RunOptions())
    assert isinstance(result.report, rs.Report) and result.report.passed


def test_detections_csv_has_every_detection_and_its_target():
    import csv
    import io

    from rts_scenario.check import DETECTION_COLUMNS

    out = io.StringIO()
    report = run_scene(CUT_IN, RunOptions(batch_frames=64), detections_out=out).report
    rows = list(csv.reader(io.StringIO(out.getvalue())))
    assert len(rows) == report.targets[0].detected_frames + report.false_detections
    assert all(len(r) == len(DETECTION_COLUMNS) for r in rows)
    record = dict(zip(DETECTION_COLUMNS, rows[0], strict=True))
    assert record["scene"] == "cut-in" and record["cycle"] == "0" and record["t_s"] == "0.0"
    assert record["target"] == "cutting-car" and float(record["range_m"]) > 0
    assert [int(r[1]) for r in rows] == sorted(int(r[1]) for r in rows)
    # Beside each detection its target's ground truth (empty for a false one), within the
    # scene's tolerances of what the radar reported where the run passed.
    tolerance = {"range_m": 0.3, "radial_velocity_mps": 0.3, "az_deg": 0.5, "el_deg": 1.0}
    for row in rows:
        record = dict(zip(DETECTION_COLUMNS, row, strict=True))
        if not record["target"]:
            assert all(record[f"truth_{q}"] == "" for q in (*tolerance, "rcs_dbsm"))
            continue
        for q, tol in tolerance.items():
            assert abs(float(record[q]) - float(record[f"truth_{q}"])) <= tol, (q, record)
        assert abs(float(record["rcs_dbsm"]) - float(record["truth_rcs_dbsm"])) <= 6.0


def test_cycles_at_a_frame_change_are_counted_only_where_they_came_back():
    # Every cycle of the built-in radar falls on a frame change (cycle = frame period); half
    # of them never reach the bus. Only those that came back were measured at a change as far
    # as the report can tell, and those are what its `frame changes` line counts.
    scene = load_scenario(CUT_IN, {"radar.noise": False, "radar.fidelity": "analytic",
                                   "duration_s": 4.0})
    with Pipeline.for_scene(scene) as pipeline:
        sink = pipeline.output._sink
        pipeline.output._sink = lambda cycles: sink([c for c in cycles if c.cycle % 2])
        report = pipeline.run(scene).report
    assert report.frames["missing"] == 40 and report.frames["received"] == 40
    # All received cycles but none of the missing ones (cycle 0 is missing: no change before).
    assert report.frames["ambiguous"] == 40


def test_frames_slower_than_the_radar_stream_in_batches_of_cycles(tmp_path, monkeypatch):
    # Two frames a second for 5 minutes, the radar's cycles every 50 ms: 6000 cycles. A batch
    # of BATCH_FRAMES frames would put 5000 cycles on the bus and in the checker at once (a
    # day of such frames, 1.7 million): the batches hold about BATCH_FRAMES cycles instead, so
    # memory does not grow with the scene's length.
    from rts_scenario.pipeline import BATCH_FRAMES
    from rts_scenario.radar.simulate import SimulatedRadar

    path = tmp_path / "slow.scenario.yaml"
    path.write_text(CUT_IN.read_text().split("parametrize:")[0]
                    .replace("duration_s: 12.0", "duration_s: 300.0")
                    .replace("frame_rate_hz: 20.0", "frame_rate_hz: 2.0")
                    .replace("profile: awr1843boost",
                             "profile: awr1843boost\n  fidelity: analytic"))
    sizes: list[int] = []
    process = SimulatedRadar.process

    def counted(self, schedule):
        sizes.append(schedule.n_frames)
        return process(self, schedule)

    monkeypatch.setattr(SimulatedRadar, "process", counted)
    report = run_scene(path, RunOptions(drain_s=1.0)).report
    assert report.frames["total"] == 6000 and report.frames["missing"] == 0
    assert sum(sizes) == 6000 and max(sizes) <= BATCH_FRAMES


def test_a_run_listens_at_its_end_as_long_as_a_slow_radar_s_last_cycles_take(monkeypatch):
    # A radar on the bus (no simulated radar in process) whose messages come 1.9 s after it
    # measured, cycles of 0.2 s: its last cycle reaches the bus up to latency + cycle + 0.2 s
    # (2.3 s) after the frames ended, beyond the 2 s `drain_s` a quick bus is given. The
    # run's end waits for it, and for the scene time it was asked to listen until.
    from rts_scenario.hostclock import monotonic_s

    scene = load_scenario(CUT_IN)
    with Pipeline.for_scene(scene, RunOptions()) as pipeline:
        clock = pipeline.radar.radar_clock
        pipeline.radar = dataclasses.replace(pipeline.radar, clock=dataclasses.replace(
            clock, cycle_s=0.2, latency_s=1.9, jitter_s=0.0))
        pipeline._publisher = None
        start = monotonic_s()
        pipeline.receive(final=True)
        assert monotonic_s() - start >= 1.9 + 0.2 + 0.2
        start = monotonic_s()
        pipeline.receive(final=True, until_monotonic_s=start + 2.5)
        assert monotonic_s() - start >= 2.5


def test_an_unknown_run_method_lists_every_method_a_run_takes():
    # "estimator" is a run's method (aimed at the radar's estimator), not the solver's.
    from rts_scenario.errors import SolverError

    scene = load_scenario(ROOT / "scenarios" / "approaching_target.scenario.yaml",
                          {"duration_s": 0.2})
    with pytest.raises(SolverError, match="unknown method 'bogus'; valid methods: exact, "
                                          "paper, estimator$"):
        run_scene(scene, RunOptions(method="bogus"))
    assert run_scene(scene, RunOptions(method="estimator")).report.passed
