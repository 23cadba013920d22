"""Limits in the verdict: counted in the scene's frames, and their echoes no false alarms.

A target the RTS could not play as the scene says (here: above every quad of the rig) is a
limit in that frame; the verdict fails on it unless the scene expects it, whether the radar
measured that frame or not (a radar slower than the frames, or starting after them), and the
count is of target-frames, not of the cycles that saw them. An echo the RTS played under a
limit the scene expects (clipped, off its angle, folded) is no false detection.
"""

from pathlib import Path

import numpy as np
import pytest
import yaml

from rts_scenario.pipeline import run_scene
from rts_scenario.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]
AWR = ROOT / "rts_scenario" / "data" / "radars" / "awr1843boost.radar.yaml"


def scene(tmp_path, clock, targets, expected=(), rig="wide-3x5", seen_at=20.0):
    profile = yaml.safe_load(AWR.read_text())
    profile["name"] = "own-clock"
    profile["clock"] = clock
    (tmp_path / "own.radar.yaml").write_text(yaml.safe_dump(profile))
    data = {
        "rts_scenario": 1, "name": "limits", "duration_s": 2.0, "frame_rate_hz": 20.0,
        "radar": {"profile": "own.radar.yaml", "fidelity": "analytic", "noise": False},
        "rig": rig,
        "ego": {"motion": {"type": "stationary", "position_m": [0, 0, 0]}},
        "targets": [{"name": "seen", "kind": "car", "rcs": {"rcs_dbsm": 10.0},
                     "motion": {"type": "stationary", "position_m": [seen_at, 0.0, 0.0]}},
                    *targets],
        "expectations": {"tolerances": {"range_m": 0.3, "radial_velocity_mps": 0.3,
                                        "az_deg": 0.5, "el_deg": 1.0},
                         "detection_rate": 0.9, "expected_limits": list(expected)}}
    path = tmp_path / "limits.scenario.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return load_scenario(path)


# 20 m ahead and 30 m up: 56 deg of elevation, above the wide grid's quads (+-8 deg).
ABOVE = {"kind": "car", "rcs": {"rcs_dbsm": 10.0},
         "motion": {"type": "stationary", "position_m": [20.0, 0.0, 30.0]}}


@pytest.mark.parametrize("expected", [False, True])
def test_a_target_not_played_in_a_frame_no_cycle_measured_fails_unless_expected(tmp_path,
                                                                               expected):
    # The radar measures every 100 ms, at 0, 0.1, 0.2 s ...; the frames are 50 ms. The target
    # is there from 0.04 to 0.09 s: in frame 1 (0.05 s) alone, which no cycle measured.
    blip = {"name": "blip", **ABOVE, "appear_s": 0.04, "disappear_s": 0.09}
    limits = ["frame_rate_above_radar"] + (["out_of_coverage"] if expected else [])
    report = run_scene(scene(tmp_path, {"cycle_s": 0.1, "start_offset_s": 0.0}, [blip],
                             limits)).report
    blip_result = next(t for t in report.targets if t.name == "blip")
    assert blip_result.limits == {"out_of_coverage": 1}
    if expected:
        assert report.passed, report.reasons
        assert "out_of_coverage" not in report.expected_not_hit
    else:
        assert not report.passed
        assert any("blip: target-frames not played or not measurable as specified: "
                   "out_of_coverage 1" in str(r) for r in report.reasons)


def test_a_radar_started_late_does_not_hide_what_was_not_played_before(tmp_path):
    # The radar's cycle 0 is at 1 s (the profile says so: a late start on purpose); a target
    # behind it until 0.9 s was not played in those 18 frames.
    early = {"name": "early", "kind": "car", "rcs": {"rcs_dbsm": 10.0}, "disappear_s": 0.9,
             "motion": {"type": "stationary", "position_m": [-20.0, 0.0, 0.0]}}
    report = run_scene(scene(tmp_path, {"cycle_s": 0.05, "start_offset_s": 1.0},
                             [early])).report
    assert not report.passed
    assert next(t for t in report.targets if t.name == "early").limits == {
        "out_of_coverage": 18}


def test_limits_count_target_frames_not_the_cycles_that_saw_them(tmp_path):
    # A radar twice as fast as the frames sees each frame twice: a target above the quads for
    # the whole 2 s scene is 40 target-frames, not 80.
    report = run_scene(scene(tmp_path, {"cycle_s": 0.025, "start_offset_s": 0.0},
                             [{"name": "high", **ABOVE}], ["out_of_coverage"])).report
    assert next(t for t in report.targets if t.name == "high").limits == {
        "out_of_coverage": 40}
    assert report.passed, report.reasons


EVERY_50_MS = {"cycle_s": 0.05, "start_offset_s": 0.0}


def test_an_echo_clipped_at_the_attenuator_s_end_is_no_false_detection(tmp_path):
    # 60 dBsm at 3 m needs less attenuation than the RTS has: each channel is clamped at 0 dB
    # on its own, which changes their ratios and moves the angle the radar sees by about 2
    # deg. The scene expects the clipping: its detections are that echo's, not false alarms.
    strong = {"name": "strong", "kind": "car", "rcs": {"rcs_dbsm": 60.0},
              "motion": {"type": "stationary", "position_m": [3.0, 0.0, 0.0]}}
    report = run_scene(scene(tmp_path, EVERY_50_MS, [strong], ["attenuation_clipped"])).report
    assert next(t for t in report.targets if t.name == "strong").limits == {
        "attenuation_clipped": 40}
    assert report.false_detections == 0
    assert report.passed, report.reasons


def test_an_echo_folded_in_range_and_played_off_its_angle_is_no_false_detection(tmp_path):
    # 300 m on the lab's 2 x 3 grid (its channel calibration left out: the simulated radar has
    # none of those errors): so weak an echo is played on one FE (the others need more than
    # the attenuator has), off its angle, and the radar sees it folded to 0.2 m. Expected by
    # the scene, its detection is that echo's, compared in range and velocity only.
    rig = yaml.safe_load((ROOT / "scenarios" / "rigs" / "lab-2x3.rig.yaml").read_text())
    rig["name"] = "lab-uncalibrated"
    for fe in rig["front_ends"]:
        fe.pop("calibration", None)
        fe.pop("distance_m", None)
    (tmp_path / "lab.rig.yaml").write_text(yaml.safe_dump(rig))
    far = {"name": "far", "kind": "car", "rcs": {"rcs_dbsm": 10.0},
           "motion": {"type": "stationary", "position_m": [300.0, 0.0, 0.0]}}
    report = run_scene(scene(tmp_path, EVERY_50_MS, [far], [
        "attenuation_clipped", "angle_quantized", "beyond_radar_range"],
        rig="lab.rig.yaml")).report
    limits = next(t for t in report.targets if t.name == "far").limits
    assert limits.get("angle_quantized") == 40 and limits.get("beyond_radar_range") == 40
    assert report.folded_detections == 40 and report.false_detections == 0
    assert report.passed, report.reasons



def test_an_echo_off_its_angle_takes_no_detection_from_a_checkable_target():
    # Two targets at the same range and radial velocity, one played off its angle (not
    # compared in angle), one checkable; the radar reports one detection, on the checkable
    # target's angles. It is that target's: the off-angle echo costs the gate's edge in angle.
    from rts_scenario.check import Checker
    from rts_scenario.detections import Detections
    from rts_scenario.kinematics import Tracks
    from rts_scenario.scenario.model import Expectations
    from rts_scenario.schedule import Status

    expect = Expectations(tolerances={"range_m": 0.3, "radial_velocity_mps": 0.3,
                                      "az_deg": 0.5, "el_deg": 1.0, "rcs_db": 100.0})
    shape = (10, 2)
    ones = np.ones(shape, dtype=bool)
    tracks = Tracks(names=("clipped", "clear"), t_s=np.arange(10) * 0.05,
                    range_m=np.full(shape, 20.0), radial_velocity_mps=np.zeros(shape),
                    doppler_hz=np.zeros(shape), rcs_dbsm=np.full(shape, 10.0),
                    az_deg=np.tile([0.4, 0.0], (10, 1)), el_deg=np.zeros(shape),
                    position_m=np.zeros((*shape, 3)), present=ones, in_coverage=ones,
                    in_range=ones, in_velocity=ones)
    status = np.zeros(shape, dtype=np.uint16)
    status[:, 0] = Status.ATTENUATION_CLIPPED
    cycles = [Detections(cycle=f, t_s=0.05 * f, range_m=np.array([20.0]),
                         radial_velocity_mps=np.array([0.0]), az_deg=np.array([0.05]),
                         el_deg=np.array([0.0]), rcs_dbsm=np.array([10.0]),
                         snr_db=np.array([30.0])) for f in range(10)]
    checker = Checker("s", tracks.names, expect, counter_start=0,
                      expected_limits=[frozenset({"attenuation_clipped"}), frozenset()])
    checker.add_truth(0, tracks, status)
    checker.add_frames(tracks, status)
    checker.add_cycles(cycles)
    checker.settle()
    report = checker.report()
    clear = next(t for t in report.targets if t.name == "clear")
    assert clear.detection_rate == 1.0 and report.false_detections == 0
    assert report.passed, report.reasons
