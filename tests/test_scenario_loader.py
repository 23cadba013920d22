import json
import re
import shutil
import textwrap
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scene_helpers import write_scene

import rts_scenario.cli as cli
from rts_scenario import ScenarioError
from rts_scenario.kinematics import compute_tracks
from rts_scenario.scenario import load_scenario, parametrizations

ROOT = Path(__file__).resolve().parents[1]
SCENES = sorted((ROOT / "scenarios").glob("*.scenario.yaml"))

GOOD = """\
rts_scenario: 1
name: good
duration_s: 5.0
frame_rate_hz: 20.0
radar:
  profile: awr1843boost
  mount: {x_m: 3.7, z_m: 0.5}
rig: wide-3x5
ego:
  motion: {type: constant_velocity, position_m: [0, 0, 0], speed_mps: 20.0}
targets:
  - name: car
    motion: {type: constant_velocity, position_m: [30, 0, 0.6], speed_mps: 19.0}
    rcs: {rcs_dbsm: 10.0}
"""


def test_at_least_ten_realistic_and_four_hard_scenes():
    names = {p.name.removesuffix(".scenario.yaml") for p in SCENES}
    hard = {n for n in names if n.startswith("hard_")}
    assert len(names - hard) >= 10
    assert hard >= {"hard_quad_sweep", "hard_coverage_edges", "hard_too_close",
                    "hard_same_range_doppler"}


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.name)
def test_shipped_scenes_validate(path):
    scene = load_scenario(path)
    tracks = compute_tracks(scene)
    assert tracks.range_m.shape == (scene.n_frames, len(scene.targets))
    # A scene's targets are checkable somewhere; an empty bench checks false detections only.
    assert tracks.checkable.any() or (not scene.targets and scene.radar_options.fidelity == "adc")


def test_dense_scene_has_at_least_eight_simultaneous_targets():
    tracks = compute_tracks(load_scenario(ROOT / "scenarios" / "dense_traffic.scenario.yaml"))
    assert tracks.checkable.sum(axis=1).max() >= 8


def test_readme_example_is_a_valid_scene(tmp_path):
    text = (ROOT / "scenarios" / "README.md").read_text()
    example = re.search(r"## A complete, annotated scene\n\n```yaml\n(.*?)```", text, re.S)
    assert example
    shutil.copytree(ROOT / "scenarios" / "fragments", tmp_path / "fragments")
    path = tmp_path / "example.scenario.yaml"
    path.write_text(example.group(1))
    scene = load_scenario(path)
    assert [t.name for t in scene.targets][:3] == ["parked-1", "parked-2", "parked-3"]
    assert scene.marks == ("slow",)


def test_good_scene_loads(tmp_path):
    path = tmp_path / "good.scenario.yaml"
    path.write_text(GOOD)
    scene = load_scenario(path)
    assert scene.n_frames == 100 and scene.targets[0].name == "car"


@pytest.mark.parametrize("fidelity, runs", [("", "adc"), ("  fidelity: auto\n", "adc"),
                                             ("  fidelity: analytic\n", "analytic")])
def test_an_empty_bench_loads_when_it_says_how_many_false_detections_it_allows(
        tmp_path, fidelity, runs):
    text = GOOD.split("  - name: car")[0].replace("targets:", "targets: []")
    text = text.replace("radar:\n", "radar:\n" + fidelity)
    path = tmp_path / "empty.scenario.yaml"
    path.write_text(text + "expectations: {max_false_detections_per_frame: 0}\n")
    scene = load_scenario(path)
    assert scene.targets == () and scene.n_frames == 100
    assert scene.expectations.max_false_detections_per_frame == 0.0
    # Only the simulated radar's cube has false detections; a forced choice is kept.
    assert scene.radar_options.fidelity == runs


def edit(replace: str, by: str) -> str:
    assert replace in GOOD
    return GOOD.replace(replace, by)


# (scene text, expected line, expected key path, expected message fragment)
BAD = [
    (edit("rts_scenario: 1", "rts_scenario: 2"), 1, "rts_scenario", "allowed values: 1"),
    # A rate of 0 would pass a radar that detects nothing.
    (GOOD + "expectations: {detection_rate: 0}\n", 15, "expectations.detection_rate",
     "must be > 0, got 0"),
    (edit("name: good", "name: good\ncolour: red"), 3, "colour", "unknown key 'colour'"),
    (edit("duration_s: 5.0", "duration_s: -1"), 3, "duration_s", "must be > 0"),
    (edit("duration_s: 5.0", "duration_s: five"), 3, "duration_s", "must be of type number"),
    (edit("frame_rate_hz: 20.0\n", ""), 1, "", "'frame_rate_hz' is required"),
    (edit("profile: awr1843boost", "profile: awr9999"), 6, "radar.profile",
     "unknown preset 'awr9999'; valid presets: awr1843boost, cascade-12x16, paper"),
    (edit("mount: {x_m: 3.7, z_m: 0.5}", "mount: {x_m: 3.7, yaw_deg: 270}"), 7,
     "radar.mount.yaw_deg", "must be <= 180"),
    (edit("rig: wide-3x5", "rig: narrow"), 8, "rig", "valid presets: kit-table1, wide-3x5"),
    (edit("rig: wide-3x5", "rig: ../../etc/x.rig.yaml"), 8, "rig",
     "leaves the scene's folder tree"),
    (edit("rig: wide-3x5", "rig: /etc/x.rig.yaml"), 8, "rig", "must be a path relative"),
    (edit("rig: wide-3x5", "rig: rigs/missing.rig.yaml"), 8, "rig", "file not found"),
    (edit("type: constant_velocity, position_m: [0, 0, 0]",
          "type: teleport, position_m: [0, 0, 0]"), 10, "ego.motion.type",
     "allowed values: 'stationary', 'constant_velocity'"),
    (edit("position_m: [0, 0, 0]", "position_m: [0, 0]"), 10, "ego.motion.position_m",
     "must have at least 3 items"),
    (edit("speed_mps: 20.0}", "speed_mps: 20.0, acceleration_mps2: 1}"), 10,
     "ego.motion.acceleration_mps2", "unknown key 'acceleration_mps2'"),
    (edit("speed_mps: 20.0}", "speed_mps: -200.0}"), 10, "ego.motion.speed_mps",
     "must be >= -150"),
    (edit("  motion: {type: constant_velocity, position_m: [0, 0, 0], speed_mps: 20.0}",
          "  motion:\n    type: waypoints\n    points:\n"
          "      - {position_m: [0, 0, 0], speed_mps: 20}\n"
          "      - {position_m: [50, 0, 0], speed_mps: 20}\n"
          "      - {position_m: [100, 8.8, 0], speed_mps: 20}"), 14,
     "ego.motion.points[1].position_m",
     "the ego's path turns 9.98 deg at this waypoint: a polyline turns in no time, and the "
     "radar with it, so every target's azimuth would jump 9.98 deg between two frames and the "
     "radar (3.7 m from the ego's reference point) 0.644 m sideways; use path: spline"),
    # A piece straight up or down gives the ego no heading (its radar faced the world's x
    # axis there) and hid a turn across it from the corner's check.
    (edit("  motion: {type: constant_velocity, position_m: [0, 0, 0], speed_mps: 20.0}",
          "  motion:\n    type: waypoints\n    points:\n"
          "      - {position_m: [0, 0, 0], speed_mps: 20}\n"
          "      - {position_m: [50, 0, 0], speed_mps: 20}\n"
          "      - {position_m: [50, 0, 1], speed_mps: 20}\n"
          "      - {position_m: [50, 50, 1], speed_mps: 20}"), 15,
     "ego.motion.points[2].position_m",
     "the ego's path runs straight up or down from the waypoint before: it has no heading "
     "there"),
    (edit("  motion: {type: constant_velocity, position_m: [0, 0, 0], speed_mps: 20.0}",
          "  motion:\n    type: waypoints\n    points:\n"
          "      - {position_m: [0, 0, 0], speed_mps: 20}\n"
          "      - {position_m: [-50, 0, 0], speed_mps: 20}\n"
          "      - {position_m: [-50, 0, 1], speed_mps: 20}\n"
          "      - {position_m: [-100, 0, 1], speed_mps: 20}"), 15,
     "ego.motion.points[2].position_m",
     "the ego's path runs straight up or down from the waypoint before: it has no heading "
     "there"),
    (edit("    motion: {type: constant_velocity, position_m: [30, 0, 0.6], speed_mps: 19.0}",
          "    motion:\n      type: waypoints\n      points:\n"
          "        - {position_m: [30, 0, 0], speed_mps: 3}\n"
          "        - {position_m: [40, 0, 0], speed_mps: -3}"), 17,
     "targets[0].motion.points[1].speed_mps", "must be >= 0"),
    (edit("{type: constant_velocity, position_m: [30, 0, 0.6], speed_mps: 19.0}",
          "{position_m: [30, 0, 0.6]}"), 13, "targets[0].motion",
     "'type' is required but missing; allowed values: 'stationary', 'constant_velocity', "
     "'constant_acceleration', 'speed_profile', 'waypoints'"),
    (edit("{type: constant_velocity, position_m: [30, 0, 0.6], speed_mps: 19.0}",
          "{position_m: [30, 0, 0.6], speed_mps: 22}"), 13, "targets[0].motion",
     "'type' is required but missing; allowed values: 'stationary'"),
    (edit("  - name: car\n", "  - name: car!\n"), 12, "targets[0].name", "does not match"),
    (edit("    rcs: {rcs_dbsm: 10.0}", "    rcs: {rcs_dbsm: 10.0, fluctuation: swerling2}"),
     14, "targets[0].rcs.fluctuation", "allowed values: 'none', 'swerling1', 'swerling3'"),
    (edit("    rcs: {rcs_dbsm: 10.0}", "    rcs: {rcs_dbsm: [1, 2]}"), 14, "targets[0].rcs",
     "an RCS table needs both aspect_deg"),
    (edit("    rcs: {rcs_dbsm: 10.0}", "    rcs: {aspect_deg: [0, 90, 180], rcs_dbsm: [1, 2]}"),
     14, "targets[0].rcs.rcs_dbsm", "needs one value per aspect_deg entry (3), got 2"),
    (edit("    rcs: {rcs_dbsm: 10.0}", "    rcs: {aspect_deg: [0, 360], rcs_dbsm: [1, 2]}"),
     14, "targets[0].rcs.aspect_deg", "distinct modulo 360"),
    (edit("    rcs: {rcs_dbsm: 10.0}", "    rcs: {rcs_dbsm: 10.0}\n    appear_s: 4\n"
          "    disappear_s: 2"), 16, "targets[0].disappear_s", "must be later than appear_s"),
    ("", None, "", "a scene must be a mapping of keys, got an empty file"),
    (GOOD.split("  - name: car")[0].replace("targets:", "targets: []"), 11, "targets",
     "the scene has no targets (none here and none in an included fragment): it can only test "
     "the radar's false detections on an empty bench; to mean that, set "
     "expectations.max_false_detections_per_frame (e.g. 0), else give at least one target"),
    (edit("    rcs: {rcs_dbsm: 10.0}", "    rcs: {rcs_dbsm: 10.0}\n    appear_s: 100"), 15,
     "targets[0].appear_s", "the target appears at 100 s, after the scene's last frame at "
     "4.95 s (duration_s = 5 s at 20 Hz): it would be present in no frame"),
    (edit("    rcs: {rcs_dbsm: 10.0}", "    rcs: {rcs_dbsm: 10.0}\n    appear_s: 1.01\n"
          "    disappear_s: 1.04"), 16, "targets[0].disappear_s",
     "no frame falls between appear_s = 1.01 s and disappear_s = 1.04 s (frames every 0.05 s"),
    (edit("    rcs: {rcs_dbsm: 10.0}", "    rcs: {rcs_dbsm: 10.0}\n    lane_changes:\n"
          "      - {start_s: 300, duration_s: 2, offset_m: 3}"), 16,
     "targets[0].lane_changes[0].start_s", "the lane change starts at 300 s, at or after the "
     "scene's last frame at 4.95 s (duration_s = 5 s at 20 Hz): it would never happen"),
    (edit("speed_mps: 20.0}\n", "speed_mps: 20.0}\n  lane_changes: [{start_s: 5, duration_s: 1, "
          "offset_m: 3}]\n"), 11, "ego.lane_changes[0].start_s", "start_s must be < 4.95"),
    (edit("    rcs: {rcs_dbsm: 10.0}\n",
          "    rcs: {rcs_dbsm: 10.0}\n" + GOOD.split("targets:\n")[1]),
     15, "targets[1].name", "duplicate target name 'car'"),
    (edit("    motion: {type: constant_velocity, position_m: [30, 0, 0.6], speed_mps: 19.0}",
          "    motion:\n      type: speed_profile\n      position_m: [30, 0, 0]\n      profile:\n"
          "        - {t_s: 2, speed_mps: 3}\n        - {t_s: 1, speed_mps: 4}"), 18,
     "targets[0].motion.profile[1].t_s", "times must increase, got 1 after 2"),
    (edit("    motion: {type: constant_velocity, position_m: [30, 0, 0.6], speed_mps: 19.0}",
          "    motion:\n      type: waypoints\n      start_s: 4.97\n      points:\n"
          "        - {position_m: [30, 0, 0], speed_mps: 3}\n"
          "        - {position_m: [40, 0, 0], speed_mps: 3}"), 15,
     "targets[0].motion.start_s", "at or after the scene's last frame at 4.95 s (duration_s = 5 "
     "s at 20 Hz): it would stand at its first waypoint throughout; start_s must be < 4.95"),
    (edit("    motion: {type: constant_velocity, position_m: [30, 0, 0.6], speed_mps: 19.0}",
          "    motion:\n      type: waypoints\n      points:\n"
          "        - {position_m: [30, 0, 0], speed_mps: 3}\n"
          "        - {position_m: [30, 0, 0], speed_mps: 3}"), 17,
     "targets[0].motion.points[1].position_m", "consecutive waypoints must differ"),
    (edit("    motion: {type: constant_velocity, position_m: [30, 0, 0.6], speed_mps: 19.0}",
          "    motion:\n      type: waypoints\n      points:\n"
          "        - {position_m: [30, 0, 0], speed_mps: 0}\n"
          "        - {position_m: [40, 0, 0], speed_mps: 0}"), 17,
     "targets[0].motion.points[1].speed_mps", "both have speed 0"),
    (edit("    motion: {type: constant_velocity, position_m: [30, 0, 0.6], speed_mps: 19.0}",
          "    motion:\n      type: waypoints\n      points:\n"
          "        - {position_m: [30, 0, 0], speed_mps: 3}"), 15, "targets[0].motion.points",
     "must have at least 2 items"),
    (edit("    rcs: {rcs_dbsm: 10.0}", "    rcs: {rcs_dbsm: 10.0}\n    lane_changes:\n"
          "      - {start_s: 1, duration_s: 0, offset_m: 3}"), 16,
     "targets[0].lane_changes[0].duration_s", "must be >= 0.001"),
    # 1e-300 s: the lateral acceleration's duration**2 underflowed to 0 (numpy's "invalid value
    # encountered in divide" printed by validate and run). The schema's floor: 1 ms.
    (edit("    rcs: {rcs_dbsm: 10.0}", "    rcs: {rcs_dbsm: 10.0}\n    lane_changes:\n"
          "      - {start_s: 1, duration_s: 1.0e-300, offset_m: 3}"), 16,
     "targets[0].lane_changes[0].duration_s", "must be >= 0.001, got 1e-300"),
    # Sideways as along the path: at most 15 m/s2 (a 3.5 m change in 1 s peaks at 20.2).
    (edit("    rcs: {rcs_dbsm: 10.0}", "    rcs: {rcs_dbsm: 10.0}\n    lane_changes:\n"
          "      - {start_s: 1, duration_s: 1.0, offset_m: 3.5}"), 16,
     "targets[0].lane_changes[0].duration_s",
     "a lane change of 3.5 m in 1 s is a sideways acceleration of up to 20.2073 m/s2; "
     "accelerations run from -15 to 15 m/s2 (as acceleration_mps2 of constant_acceleration): "
     "give duration_s >= 1.161 s, or a smaller offset_m"),
    (edit("    rcs: {rcs_dbsm: 10.0}", "    rcs: {rcs_dbsm: 10.0}\n    lane_changes:\n"
          "      - {start_s: 1, duration_s: 0.001, offset_m: -3}"), 16,
     "targets[0].lane_changes[0].duration_s", "give duration_s >= 1.075 s"),
    # A tolerance of 1e-300 overflowed the checker's gate (numpy's "overflow encountered in
    # multiply" printed by run); a micrometre, a micro-degree is below any radar's resolution.
    (GOOD + "expectations: {tolerances: {az_deg: 1.0e-300}}\n", 15,
     "expectations.tolerances.az_deg", "must be >= 1e-06, got 1e-300"),
    (edit("targets:", "include: [../outside.yaml]\ntargets:"), 11, "include[0]",
     "leaves the scene's folder tree"),
    (edit("name: good", "name: good\nname: again"), 3, "name", "duplicate key"),
    # An unclosed bracket the parser read on past: placed at the line that opened it.
    (edit("rig: wide-3x5", "rig: [wide"), 8, "", "invalid YAML: did not find expected ',' or "
     "']' at line 9, column 4 (while parsing a flow sequence from line 8, column 6): a comma "
     "left out at the end of this line, or that bracket left open?"),
    (edit("name: good", "name: !!python/object/apply:os.system [echo]"), 2, "name",
     "invalid YAML"),
    ("- just\n- a list\n", 1, "", "a scene must be a mapping"),
    ("", None, "", "a scene must be a mapping"),
    (edit("rig: wide-3x5", "rig: wide-3x5\nexpectations: {detection_rate: 1.5}"), 9,
     "expectations.detection_rate", "must be <= 1"),
]


def test_the_shortest_lane_change_moves_the_target_by_its_offset_without_numpy_warnings(
        tmp_path):
    # The shortest lane change of 3 m (sqrt(10 / sqrt(3) * 3 / 15) = 1.0746 s, its sideways
    # acceleration then peaks at 15 m/s2): every frame is finite, and the target ends the
    # offset away from where it would be without it.
    path = tmp_path / "s.scenario.yaml"
    path.write_text(edit("    rcs: {rcs_dbsm: 10.0}", "    rcs: {rcs_dbsm: 10.0}\n"
                         "    lane_changes:\n      - {start_s: 1, duration_s: 1.0746, "
                         "offset_m: 3}"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tracks = compute_tracks(load_scenario(path))
    assert all(np.all(np.isfinite(np.asarray(v, dtype=float)))
               for v in (tracks.range_m, tracks.radial_velocity_mps, tracks.az_deg))
    # The target is 1 m/s slower than the ego: at the last frame (t = 4.95 s) it is
    # 30 - 4.95 - 3.7 m ahead of the radar and 3 m to its left.
    assert tracks.az_deg[0, 0] == pytest.approx(0.0, abs=1e-9)
    assert tracks.az_deg[-1, 0] == pytest.approx(np.degrees(np.arctan2(3.0, 30 - 4.95 - 3.7)),
                                                 abs=1e-6)


@pytest.mark.parametrize("text, line, key, message", BAD)
def test_bad_scenes_name_file_line_key_and_what_is_allowed(tmp_path, text, line, key, message):
    path = tmp_path / "bad.scenario.yaml"
    path.write_text(text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    err = info.value
    assert err.file == str(path)
    assert message in str(err), str(err)
    if line is not None:
        assert err.line == line, str(err)
        assert str(err).startswith(f"{path}:{line}:")
    if key:
        assert err.key_path == key, str(err)
        assert f": {key}: " in str(err)


def test_twenty_distinct_bad_inputs():
    assert len({message for *_, message in BAD}) >= 20


def test_errors_in_included_and_referenced_files_point_into_them(tmp_path):
    (tmp_path / "frag").mkdir()
    (tmp_path / "frag" / "more.yaml").write_text(textwrap.dedent("""\
        targets:
          - name: extra
            motion: {type: stationary, position_m: [20, 0, 0]}
            rcs: {rcs_dbsm: 10, colour: red}
        """))
    scene = tmp_path / "s.scenario.yaml"
    scene.write_text(edit("targets:", "include: [frag/more.yaml]\ntargets:"))
    with pytest.raises(ScenarioError) as info:
        load_scenario(scene)
    assert info.value.file.endswith("more.yaml") and info.value.line == 4
    assert info.value.key_path == "targets[0].rcs.colour"

    (tmp_path / "rigs").mkdir()
    (tmp_path / "rigs" / "bad.rig.yaml").write_text("rts_rig: 1\nname: r\nlayout: {az_deg: [1]}\n")
    scene.write_text(edit("rig: wide-3x5", "rig: rigs/bad.rig.yaml"))
    with pytest.raises(ScenarioError) as info:
        load_scenario(scene)
    assert info.value.file.endswith("bad.rig.yaml") and info.value.line == 3


def test_a_fragment_included_twice_is_named_once(tmp_path):
    (tmp_path / "fr").mkdir()
    (tmp_path / "fr" / "ok.yaml").write_text(
        "targets:\n  - {name: p1, motion: {type: stationary, position_m: [20, 0, 0]}, "
        "rcs: {rcs_dbsm: 10}}\n")
    scene = tmp_path / "s.scenario.yaml"
    scene.write_text(edit("targets:", "include:\n  - fr/ok.yaml\n  - ./fr/../fr/ok.yaml\n"
                                      "targets:"))
    with pytest.raises(ScenarioError) as info:
        load_scenario(scene)
    err = info.value
    assert (err.file, err.line, err.key_path) == (str(scene), 13, "include[1]")
    assert str(err).endswith("include[1]: './fr/../fr/ok.yaml' is included twice (first as "
                             "include[0] 'fr/ok.yaml'); include each fragment once")


@pytest.mark.parametrize("name, text, what", [
    ("other.scenario.yaml", GOOD, "a scene file (*.scenario.yaml)"),
    ("lab.yaml", "rts_rig: 1\nname: r\nlayout: {az_deg: [-5, 5], el_deg: [-5, 5]}\n",
     "a rig file (its rts_rig key)"),
])
def test_a_file_of_another_kind_under_include_is_named_as_what_it_is(tmp_path, name, text,
                                                                      what):
    # Not its keys listed as unknown to a fragment: what it is, where the scene lists it.
    (tmp_path / name).write_text(text)
    scene = tmp_path / "s.scenario.yaml"
    scene.write_text(edit("targets:", f"include: [{name}]\ntargets:"))
    with pytest.raises(ScenarioError) as info:
        load_scenario(scene)
    err = info.value
    assert (err.file, err.line, err.key_path) == (str(scene), 11, "include[0]")
    assert str(err).split(": ", 2)[2].startswith(
        f"{name!r} is {what}, not a scene fragment (only targets and a description); ")


FRAGMENT = ("targets:\n  - {name: p, motion: {type: stationary, position_m: [9, 0, 0]}, "
            "rcs: {rcs_dbsm: 0}}\n")


@pytest.mark.parametrize("replace, by, line, key, what", [
    ("rig: wide-3x5", "rig: fr/parked.yaml", 8, "rig", "a rig file (*.rig.yaml)"),
    ("profile: awr1843boost", "profile: fr/parked.yaml", 6, "radar.profile",
     "a radar profile (*.radar.yaml)"),
])
def test_a_fragment_named_as_rig_or_radar_profile_is_located_at_the_scene_s_key(
        tmp_path, replace, by, line, key, what):
    (tmp_path / "fr").mkdir()
    (tmp_path / "fr" / "parked.yaml").write_text(FRAGMENT)
    scene = tmp_path / "s.scenario.yaml"
    scene.write_text(edit(replace, by))
    with pytest.raises(ScenarioError) as info:
        load_scenario(scene)
    err = info.value
    assert (err.file, err.line, err.key_path) == (str(scene), line, key)
    assert err.detail.startswith(
        f"'fr/parked.yaml' is a scene fragment (only targets and a description), not {what}; "
        f"a scene lists it under include:")


def test_relative_rig_and_profile_files_inside_the_tree(tmp_path):
    (tmp_path / "rigs").mkdir()
    shutil.copy(ROOT / "scenarios" / "rigs" / "lab-2x3.rig.yaml", tmp_path / "rigs")
    scene = tmp_path / "s.scenario.yaml"
    scene.write_text(edit("rig: wide-3x5", "rig: rigs/lab-2x3.rig.yaml"))
    assert load_scenario(scene).rig.name == "lab-2x3"

    # A file not named *.rig.yaml is a file, not an unknown preset; so is a bare name that exists.
    shutil.copy(tmp_path / "rigs" / "lab-2x3.rig.yaml", tmp_path / "rigs" / "x.yaml")
    shutil.copy(tmp_path / "rigs" / "lab-2x3.rig.yaml", tmp_path / "lab")
    for name in ("rigs/x.yaml", "lab"):
        scene.write_text(edit("rig: wide-3x5", f"rig: {name}"))
        assert load_scenario(scene).rig.name == "lab-2x3"
    scene.write_text(edit("rig: wide-3x5", "rig: rigs/y.yaml"))
    with pytest.raises(ScenarioError, match=r":8:1: rig: file not found: 'rigs/y.yaml'"):
        load_scenario(scene)


def test_an_inconsistent_rig_is_reported_in_the_rig_file_not_as_the_scene(tmp_path):
    (tmp_path / "rigs").mkdir()
    rig = (ROOT / "scenarios" / "rigs" / "lab-2x3.rig.yaml").read_text()
    bad = tmp_path / "rigs" / "bad.rig.yaml"
    scene = tmp_path / "s.scenario.yaml"
    scene.write_text(edit("rig: wide-3x5", "rig: rigs/bad.rig.yaml"))
    for old, new, key in [("update_rate_hz: 50.0", "update_rate_hz: 0", "limits.update_rate_hz"),
                          ("{az_deg: 0.1, el_deg: -7.9,", "{az_deg: -10.2, el_deg: -8.1,",
                           "front_ends[1]")]:
        assert old in rig
        bad.write_text(rig.replace(old, new))
        with pytest.raises(ScenarioError) as info:
            load_scenario(scene)
        assert info.value.file == str(bad) and info.value.key_path == key, str(info.value)


def test_cli_validate_exit_codes(tmp_path, capsys):
    good = tmp_path / "good.scenario.yaml"
    good.write_text(GOOD)
    bad = tmp_path / "bad.scenario.yaml"
    bad.write_text(edit("rts_scenario: 1", "rts_scenario: 3"))
    assert cli.main(["validate", str(good)]) == 0
    assert "ok:" in capsys.readouterr().out
    assert cli.main(["validate", str(good), str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {bad}:1:") and "Traceback" not in err


@pytest.mark.parametrize("kind", ["scene", "rig"])
def test_a_file_of_another_format_version_is_told_so_before_its_keys(tmp_path, kind):
    # A file a later format wrote has keys this one does not know: its version is the error,
    # not the first key it does not know.
    scene = tmp_path / "later.scenario.yaml"
    if kind == "scene":
        scene.write_text(GOOD.replace("rts_scenario: 1", "rts_scenario: 2")
                         + "weather: {rain_mm_per_h: 5}\n")
        where = f"{scene}:1:1: rts_scenario"
    else:
        rig = tmp_path / "later.rig.yaml"
        rig.write_text("rts_rig: 2\nname: later\nmirrors: 3\n"
                       "layout: {az_deg: [-10, 10], el_deg: [-5, 5]}\n")
        scene.write_text(GOOD.replace("rig: wide-3x5", "rig: later.rig.yaml"))
        where = f"{rig}:1:1: rts_rig"
    with pytest.raises(ScenarioError) as info:
        load_scenario(scene)
    assert str(info.value) == (f"{where}: got 2; allowed values: 1 (the file's format version: "
                               f"this version of rts-scenario reads no other)")


# --- fuzzing: only ScenarioError may escape the loader ---------------------------------------

# Each example writes its own file into tmp_path, so sharing the fixture is intended.
FUZZ_CHECKS = [HealthCheck.too_slow, HealthCheck.function_scoped_fixture]

scalars = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6),
                    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12))
documents = st.recursive(
    scalars,
    lambda children: st.lists(children, max_size=4)
    | st.dictionaries(st.sampled_from(["rts_scenario", "name", "duration_s", "frame_rate_hz",
                                       "radar", "rig", "ego", "targets", "motion", "type",
                                       "position_m", "speed_mps", "rcs", "rcs_dbsm", "profile",
                                       "points", "include", "x"]) | st.text(max_size=6),
                      children, max_size=6),
    max_leaves=25,
)


@settings(max_examples=150, deadline=None, suppress_health_check=FUZZ_CHECKS)
@given(doc=documents)
def test_fuzz_random_documents(tmp_path, doc):
    path = tmp_path / "fuzz.scenario.yaml"
    path.write_text(yaml.safe_dump(doc))
    try:
        load_scenario(path)
    except ScenarioError:
        pass


def _mutations(good: dict):
    """Valid scene with one value replaced somewhere."""
    paths = []

    def walk(node, prefix):
        if isinstance(node, dict):
            for k, v in node.items():
                paths.append((*prefix, k))
                walk(v, (*prefix, k))
        elif isinstance(node, list):
            for i, v in enumerate(node):
                paths.append((*prefix, i))
                walk(v, (*prefix, i))

    walk(good, ())
    return st.tuples(st.sampled_from(paths), scalars | st.lists(scalars, max_size=3))


GOOD_DATA = yaml.safe_load(GOOD)


@settings(max_examples=200, deadline=None, suppress_health_check=FUZZ_CHECKS)
@given(change=_mutations(GOOD_DATA))
def test_fuzz_mutated_scenes(tmp_path, change):
    import copy
    path_keys, value = change
    data = copy.deepcopy(GOOD_DATA)
    node = data
    for k in path_keys[:-1]:
        node = node[k]
    node[path_keys[-1]] = value
    path = tmp_path / "fuzz.scenario.yaml"
    path.write_text(yaml.safe_dump(data))
    try:
        scene = load_scenario(path)
        compute_tracks(scene)
    except ScenarioError:
        pass


@settings(max_examples=100, deadline=None, suppress_health_check=FUZZ_CHECKS)
@given(text=st.text(max_size=200))
def test_fuzz_raw_text(tmp_path, text):
    path = tmp_path / "raw.scenario.yaml"
    path.write_text(text, encoding="utf-8", errors="surrogatepass")
    try:
        load_scenario(path)
    except ScenarioError:
        pass


def test_key_paths_joined_by_commas_vary_together(tmp_path):
    text = (ROOT / "scenarios" / "approaching_target.scenario.yaml").read_text()
    path = tmp_path / "grouped.scenario.yaml"
    path.write_text(text + "parametrize:\n"
                    "  ego.motion.position_m.0, duration_s: [[0.0, 7.5], [-10.0, 8.0]]\n"
                    "  radar.estimator: [bartlett, ti]\n")
    combos = parametrizations(path)
    assert [overrides for _, overrides in combos] == [
        {"ego.motion.position_m.0": 0.0, "duration_s": 7.5, "radar.estimator": "bartlett"},
        {"ego.motion.position_m.0": 0.0, "duration_s": 7.5, "radar.estimator": "ti"},
        {"ego.motion.position_m.0": -10.0, "duration_s": 8.0, "radar.estimator": "bartlett"},
        {"ego.motion.position_m.0": -10.0, "duration_s": 8.0, "radar.estimator": "ti"},
    ]
    assert combos[2][0] == "0=-10.0-duration_s=8.0-estimator=bartlett"
    scene = load_scenario(path, combos[2][1])
    assert scene.duration_s == 8.0
    assert scene.radar_options.estimator == "bartlett"


def test_a_value_the_parametrize_block_puts_in_place_may_be_a_placeholder(tmp_path):
    # The file as written is none of the runs: each combination is validated, with its values
    # in place, not the placeholder.
    path = tmp_path / "placeholder.scenario.yaml"
    path.write_text(GOOD.replace("speed_mps: 19.0}", "speed_mps: null}")
                    + "parametrize:\n  targets.0.motion.speed_mps: [18.0, 19.0]\n")
    combos = parametrizations(path)
    assert [ident for ident, _ in combos] == ["speed_mps=18.0", "speed_mps=19.0"]
    assert load_scenario(path, combos[1][1]).name == "good"
    # Or left out: the block puts it in place.
    path.write_text(GOOD.replace(", speed_mps: 19.0}", "}")
                    + "parametrize:\n  targets.0.motion.speed_mps: [18.0, 19.0]\n")
    assert [ident for ident, _ in parametrizations(path)] == ["speed_mps=18.0", "speed_mps=19.0"]
    # Any other bad value of the file is still one error naming it.
    path.write_text(GOOD.replace("speed_mps: 19.0}", "speed_mps: null}")
                    + "parametrize:\n  targets.0.rcs.rcs_dbsm: [8.0, 10.0]\n")
    with pytest.raises(ScenarioError, match=r"placeholder.scenario.yaml:13:\d+: "
                                            r"targets\[0\]\.motion\.speed_mps: must be of type "
                                            r"number, got None"):
        parametrizations(path)


def test_combinations_with_the_same_id_are_refused(tmp_path):
    # Runs are told apart by their id: two alike would share a pytest item, a report entry
    # and a recorded log.
    path = tmp_path / "twice.scenario.yaml"
    path.write_text(GOOD + "parametrize:\n  targets.0.rcs.rcs_dbsm: [10, 12, 10]\n")
    with pytest.raises(ScenarioError, match=r"twice.scenario.yaml:15:\d+: parametrize: "
                                            r"combinations 1 and 3 have the same id "
                                            r"'rcs_dbsm=10'"):
        parametrizations(path)


@pytest.mark.parametrize("values, first, second, ids", [
    ("[10, 12, 10.0]", 1, 3, "'rcs_dbsm=10' and 'rcs_dbsm=10.0'"),
    ("[1.0e+1, 10]", 1, 2, "'rcs_dbsm=10.0' and 'rcs_dbsm=10'"),
])
def test_combinations_playing_equal_values_are_refused(tmp_path, values, first, second, ids):
    # 10 and 10.0 are one value under two ids: the same run twice, counted twice in a sweep's
    # pass rate.
    path = tmp_path / "twice.scenario.yaml"
    path.write_text(GOOD + f"parametrize:\n  targets.0.rcs.rcs_dbsm: {values}\n")
    with pytest.raises(ScenarioError, match=rf"twice.scenario.yaml:15:\d+: parametrize: "
                                            rf"combinations {first} and {second} \({ids}\) "
                                            rf"play the same values"):
        parametrizations(path)
    # A bool is no number here: true and 1 stay two values.
    path.write_text(GOOD + "parametrize:\n  radar.noise: [true, false]\n")
    assert len(parametrizations(path)) == 2


@pytest.mark.parametrize("fc", ["1.0e+15", "5.0e+8"])
def test_a_carrier_outside_the_radar_bands_is_a_located_error(tmp_path, fc):
    # 1e15 Hz made the estimator's angle grid 349 GiB (MemoryError, exit 3).
    from rts_scenario.radar.profile import RadarProfile

    radar = (ROOT / "scenarios" / "radars" / "awr1843boost-long.radar.yaml").read_text()
    path = tmp_path / "r.radar.yaml"
    path.write_text(radar.replace("fc_hz: 76.5e+9", f"fc_hz: {fc}"))
    line = next(i for i, text in enumerate(path.read_text().splitlines(), 1)
                if text.startswith("fc_hz"))
    with pytest.raises(ScenarioError, match=rf"r.radar.yaml:{line}:\d+: fc_hz: must be "
                                            rf"(<= 300000000000|>= 1000000000)"):
        RadarProfile.from_file(path)


@pytest.mark.parametrize("position", ["2.0", "1.0e+6", "1.0e+200", "1.0e+308"])
def test_an_array_wider_than_the_angle_grids_allow_is_a_located_error(tmp_path, position):
    # An RX antenna 1e6 m out made the global-maximum check's grid 34 GiB (MemoryError, exit 3);
    # 1e200 m an OverflowError, 1e308 m numpy's overflow warning and an error naming no key.
    from rts_scenario.radar.profile import MAX_APERTURE_WAVELENGTHS, RadarProfile

    radar = (ROOT / "scenarios" / "radars" / "awr1843boost-long.radar.yaml").read_text()
    path = tmp_path / "r.radar.yaml"
    path.write_text(radar.replace("rx_y_m: [0.002075,", f"rx_y_m: [{position},"))
    line = next(i for i, text in enumerate(path.read_text().splitlines(), 1)
                if text.strip().startswith("rx_y_m"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ScenarioError, match=rf"r.radar.yaml:{line}:\d+: array.rx_y_m: "
                                                rf".* at most {MAX_APERTURE_WAVELENGTHS} "
                                                rf"wavelengths"):
            RadarProfile.from_file(path)


@pytest.mark.parametrize("edits, axis", [
    ({"tx_z_m: [-0.000325, 0.001625, -0.000325]": "tx_z_m: [-0.000325, -0.000325, -0.000325]"},
     "z"),
    ({"tx_y_m: [-0.0089, -0.0050, -0.0011]": "tx_y_m: [0.0, 0.0, 0.0]",
      "rx_y_m: [0.002075, 0.004025, 0.005975, 0.007925]": "rx_y_m: [0.002, 0.002, 0.002, 0.002]"},
     "y"),
])
def test_an_array_on_a_line_is_a_located_error(tmp_path, edits, axis):
    # Every TX and RX at one height (or one y): the virtual array measures one angle only, and
    # no weight method can synthesize both. The profile loaded; run then failed with exit 3
    # and a message naming no line or key (validate: exit 2).
    from rts_scenario.radar.profile import RadarProfile

    radar = (ROOT / "scenarios" / "radars" / "awr1843boost-long.radar.yaml").read_text()
    for old, new in edits.items():
        assert old in radar
        radar = radar.replace(old, new)
    path = tmp_path / "r.radar.yaml"
    path.write_text(radar)
    line = next(i for i, text in enumerate(radar.splitlines(), 1) if text.startswith("array"))
    with pytest.raises(ScenarioError, match=rf"r.radar.yaml:{line}:\d+: array: the virtual "
                                            rf"array is a line: every element at one {axis}"):
        RadarProfile.from_file(path)


@pytest.mark.parametrize("edits, key", [
    ({"chirp_loops: 64": "chirp_loops: 100000000", "frame_period_s: 0.05":
      "frame_period_s: 1.0e+6"}, "chirp_loops"),
    ({"adc_samples: 256": "adc_samples: 100000000", "sample_rate_hz: 20.0e+6":
      "sample_rate_hz: 1.0e+20"}, "adc_samples"),
])
def test_a_cube_larger_than_the_simulated_radar_can_hold_is_a_located_error(tmp_path, edits,
                                                                             key):
    # 10^8 chirp loops (or ADC samples) made run allocate 191 GiB (47.7 GiB): MemoryError,
    # exit 3.
    from rts_scenario.radar.profile import MAX_CUBE_SAMPLES, RadarProfile

    radar = (ROOT / "scenarios" / "radars" / "awr1843boost-long.radar.yaml").read_text()
    for old, new in edits.items():
        assert old in radar
        radar = radar.replace(old, new)
    path = tmp_path / "r.radar.yaml"
    path.write_text(radar)
    line = next(i for i, text in enumerate(radar.splitlines(), 1) if text.startswith(key))
    with pytest.raises(ScenarioError, match=rf"r.radar.yaml:{line}:\d+: {key}: .* at most "
                                            rf"{MAX_CUBE_SAMPLES:,}"):
        RadarProfile.from_file(path)


@pytest.mark.parametrize("bandwidth, allowed", [("1.0e+30", "<= 300000000000"),
                                                 ("1.0e-300", ">= 1000000")])
def test_a_sweep_beyond_the_radar_bands_is_a_located_error(tmp_path, bandwidth, allowed):
    # A bandwidth of 1e30 Hz was refused as an array 2.28e19 wavelengths wide; 1e-300 Hz made
    # range bins of 1.5e308 m (numpy's "overflow encountered in multiply" printed by run).
    from rts_scenario.radar.profile import RadarProfile

    radar = (ROOT / "scenarios" / "radars" / "awr1843boost-long.radar.yaml").read_text()
    path = tmp_path / "r.radar.yaml"
    path.write_text(radar.replace("bandwidth_hz: 0.6e+9", f"bandwidth_hz: {bandwidth}"))
    line = next(i for i, text in enumerate(path.read_text().splitlines(), 1)
                if text.startswith("bandwidth_hz"))
    with pytest.raises(ScenarioError, match=rf"r.radar.yaml:{line}:\d+: bandwidth_hz: must be "
                                            rf"{allowed}"):
        RadarProfile.from_file(path)


def test_an_integer_beyond_64_bits_is_a_located_error_in_every_file_type(tmp_path):
    # clock.counter_start: 10**20 reached numpy: OverflowError ("Python int too large to
    # convert to C long"), exit 3.
    from rts_scenario.radar.profile import RadarProfile

    radar = (ROOT / "scenarios" / "radars" / "awr1843boost-long.radar.yaml").read_text()
    path = tmp_path / "r.radar.yaml"
    path.write_text(radar + "clock: {counter_start: 100000000000000000000}\n")
    line = len(radar.splitlines()) + 1
    with pytest.raises(ScenarioError, match=rf"r.radar.yaml:{line}:\d+: clock.counter_start: "
                                            rf"an integer beyond 64 bits"):
        RadarProfile.from_file(path)
    scene = tmp_path / "s.scenario.yaml"
    scene.write_text(GOOD + "seed: 100000000000000000000\n")
    with pytest.raises(ScenarioError, match=r"s.scenario.yaml:15:\d+: seed: an integer beyond "
                                            r"64 bits"):
        load_scenario(scene)


def test_the_64_bit_bound_message_gives_the_range_of_integers_accepted(tmp_path):
    # 2^63 was refused with "numbers must lie within +-9,223,372,036,854,775,808": the bound
    # itself, read as allowed. The largest accepted integer is 2^63 - 1.
    scene = tmp_path / "s.scenario.yaml"
    scene.write_text(GOOD + f"seed: {2**63 - 1}\n")
    assert load_scenario(scene).seed == 2**63 - 1
    scene.write_text(GOOD + f"seed: {2**63}\n")
    with pytest.raises(ScenarioError, match=r"s.scenario.yaml:15:\d+: seed: an integer beyond "
                                            r"64 bits, got 9223372036854775808; integers must "
                                            r"lie from -9,223,372,036,854,775,808 to "
                                            r"9,223,372,036,854,775,807$"):
        load_scenario(scene)


def test_exponent_numbers_are_floats_in_every_file_type(tmp_path):
    # YAML 1.1 reads 76.5e9 and 1e6 as strings; YAML 1.2 (and engineers) as numbers.
    from rts_scenario.canbus.mapping import CanMapping
    from rts_scenario.located_yaml import load_yaml
    from rts_scenario.radar.profile import RadarProfile
    from rts_scenario.rig import Rig

    assert load_yaml("x.yaml", "[1e6, 76.5e9, -2.5E-3, .5e1, 7.65e+10, 10, 1.5, '1e6', 1e]\n"
                     ).data == [1e6, 76.5e9, -2.5e-3, 5.0, 7.65e10, 10, 1.5, "1e6", "1e"]
    radar = (ROOT / "scenarios" / "radars" / "awr1843boost-long.radar.yaml").read_text()
    assert "fc_hz: 76.5e+9" in radar
    (tmp_path / "r.radar.yaml").write_text(radar.replace("fc_hz: 76.5e+9", "fc_hz: 76.5e9"))
    assert RadarProfile.from_file(tmp_path / "r.radar.yaml").fc_hz == 76.5e9
    rig = (ROOT / "scenarios" / "rigs" / "lab-2x3.rig.yaml").read_text()
    (tmp_path / "r.rig.yaml").write_text(rig.replace("delay_step_s: 1.0e-10",
                                                     "delay_step_s: 1e-10"))
    assert Rig.from_file(tmp_path / "r.rig.yaml").limits.delay_step_s == 1e-10
    can = ROOT / "scenarios" / "can"
    shutil.copy(can / "cluster_list.dbc", tmp_path)
    (tmp_path / "m.mapping.yaml").write_text((can / "cluster_list.mapping.yaml").read_text()
                                             .replace("rcs_dbsm: RCS",
                                                      "rcs_dbsm: {signal: RCS, scale: 1e0}"))
    assert CanMapping.from_file(tmp_path / "m.mapping.yaml").fields["rcs_dbsm"].scale == 1.0
    scene = tmp_path / "s.scenario.yaml"
    scene.write_text(edit("speed_mps: 19.0", "speed_mps: 1.9e1").replace(
        "duration_s: 5.0", "duration_s: 5e0"))
    loaded = load_scenario(scene)
    assert loaded.duration_s == 5.0


CORNER = """\
    motion:
      type: waypoints
      path: {path}
      points:
        - {{position_m: [30, -10, 0.5], speed_mps: 5}}
        - {{position_m: [30, 5, 0.5], speed_mps: 5}}
        - {{position_m: [50, 5, 0.5], speed_mps: 5}}
    lane_changes: [{{start_s: {start_s}, duration_s: 1.5, offset_m: 3}}]
"""


@pytest.mark.parametrize("path, start_s, refused", [
    ("polyline", 0.0, True),     # 3 m left of the path when it turns right at 3 s
    ("polyline", 3.5, False),    # the lane change starts after the corner
    ("spline", 0.0, False),      # a spline turns smoothly
])
def test_a_lateral_offset_at_a_polyline_corner_is_refused(tmp_path, path, start_s, refused):
    # At a corner of a polyline the object turns in no time: a point 3 m to the left of it
    # would jump 2 x 3 m x sin(90 deg / 2) = 4.24 m between two instants.
    text = GOOD.replace("    motion: {type: constant_velocity, position_m: [30, 0, 0.6], "
                        "speed_mps: 19.0}\n", CORNER.format(path=path, start_s=start_s))
    scene = tmp_path / "corner.scenario.yaml"
    scene.write_text(text)
    if not refused:
        tracks = compute_tracks(load_scenario(scene), np.linspace(0.0, 4.95, 991))
        step = np.linalg.norm(np.diff(tracks.position_m[:, 0], axis=0), axis=1)
        assert step.max() < 0.2  # 5 ms apart at some 20-30 m/s: no jump of metres
        return
    with pytest.raises(ScenarioError) as info:
        load_scenario(scene)
    err = info.value
    assert (err.line, err.key_path) == (18, "targets[0].motion.points[1].position_m")
    assert ("the path turns 90 deg at this waypoint (at 3 s) while the object is 3 m to the "
            "left of it (lane_changes): a polyline turns in no time, so the object would jump "
            "4.24 m; use path: spline, or end the lateral offset before the corner") in str(err)


def test_yaml_merge_keys_take_the_keys_written_beside_them(tmp_path):
    # YAML's merge key: the second target is the first, with its own name and motion. Keys
    # written beside a merge override the merged ones; a key written twice is still an error.
    text = GOOD.split("targets:\n")[0] + textwrap.dedent("""\
        targets:
          - &car {name: a, kind: car, motion: {type: stationary, position_m: [30, 1, 0.6]},
                  rcs: {rcs_dbsm: 10}}
          - <<: *car
            name: b
            motion:
              type: stationary
              position_m: [35, -1, 0.6]
        """)
    path = tmp_path / "merge.scenario.yaml"
    path.write_text(text)
    scene = load_scenario(path)
    assert [t.name for t in scene.targets] == ["a", "b"]
    assert [t.kind for t in scene.targets] == ["car", "car"]
    tracks = compute_tracks(scene)
    np.testing.assert_allclose(tracks.range_m[0], [np.hypot(30 - 3.7, np.hypot(1, 0.1)),
                                                   np.hypot(35 - 3.7, np.hypot(1, 0.1))])
    # An error in the merged-over value points at the line written, not at the anchor's.
    path.write_text(text.replace("position_m: [35, -1, 0.6]", "position_m: [35, -1]"))
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert (info.value.line, info.value.key_path) == (18, "targets[1].motion.position_m")
    path.write_text(text.replace("    name: b\n", "    name: b\n    name: c\n"))
    with pytest.raises(ScenarioError, match="targets\\[1\\].name: duplicate key"):
        load_scenario(path)


REVERSAL = """\
    motion:
      type: waypoints
      path: {path}
      points:
        - {{position_m: [20, 0, 0.6], speed_mps: 3}}
        - {{position_m: [30, 0, 0.6], speed_mps: {speed}}}
        - {{position_m: [24, 2, 0.6], speed_mps: 2}}
"""


def _with_target_motion(tmp_path, name, motion, refused):
    """Load GOOD with its target's motion replaced by ``motion`` (YAML lines): the error where
    ``refused`` (it must be), else None (it must load)."""
    scene = tmp_path / f"{name}.scenario.yaml"
    scene.write_text(GOOD.replace("    motion: {type: constant_velocity, position_m: [30, 0, "
                                  "0.6], speed_mps: 19.0}\n", motion))
    if not refused:
        load_scenario(scene)
        return None
    with pytest.raises(ScenarioError) as info:
        load_scenario(scene)
    return info.value


@pytest.mark.parametrize("path, speed, refused", [
    ("spline", 1.5, True),       # a reversal passed at 1.5 m/s: impossible
    ("spline", 0, False),        # stops at the cusp, then backs out
    ("polyline", 1.5, False),    # a polyline turns in no time at any corner
])
def test_a_spline_reversal_passed_at_speed_is_refused(tmp_path, path, speed, refused):
    # The path turns 161.6 deg at the second waypoint: a spline path reverses there (a cusp),
    # where the object must stand for an instant.
    err = _with_target_motion(tmp_path, "reversal", REVERSAL.format(path=path, speed=speed),
                              refused)
    if err is None:
        return
    assert err.file.endswith("reversal.scenario.yaml")
    assert (err.line, err.key_path) == (18, "targets[0].motion.points[1].speed_mps")
    assert ("the path reverses at this waypoint (it turns 162 deg, more than 90 deg): a spline "
            "path has a cusp there, where the object stops and backs out; speed_mps must be 0 "
            "here, got 1.5") in str(err)


def test_a_spline_reversal_just_beyond_a_right_angle_says_by_how_much(tmp_path):
    # The path turns 90.000001 deg at the second waypoint: a reversal (more than 90 deg), and
    # the refusal says the angle to the digit that makes it one.
    import math

    a = math.radians(90.000001)
    third = f"[{30 + 6 * math.cos(a)!r}, {6 * math.sin(a)!r}, 0.6]"
    motion = REVERSAL.format(path="spline", speed=1.5).replace("[24, 2, 0.6]", third)
    text = GOOD.replace("    motion: {type: constant_velocity, position_m: [30, 0, 0.6], "
                        "speed_mps: 19.0}\n", motion)
    scene = tmp_path / "right.scenario.yaml"
    scene.write_text(text)
    with pytest.raises(ScenarioError, match=r"\(it turns 90\.000001 deg, more than 90 deg\)"):
        load_scenario(scene)


def test_two_spline_reversals_in_a_row_say_how_to_write_them(tmp_path):
    # Forward to 40 m, back to 25 m, forward again: both turns are reversals (speed 0 at each),
    # and a piece from standstill to standstill never moves: the refusal says what to add.
    motion = """\
    motion:
      type: waypoints
      path: spline
      points:
        - {position_m: [20, 0, 0.6], speed_mps: 4}
        - {position_m: [40, 0, 0.6], speed_mps: 0}
        - {position_m: [25, 0, 0.6], speed_mps: 0}
        - {position_m: [35, 0, 0.6], speed_mps: 2}
"""
    text = GOOD.replace("    motion: {type: constant_velocity, position_m: [30, 0, 0.6], "
                        "speed_mps: 19.0}\n", motion)
    scene = tmp_path / "twice.scenario.yaml"
    scene.write_text(text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(scene)
    assert info.value.key_path == "targets[0].motion.points[2].speed_mps"
    assert ("waypoints 1 and 2 both have speed 0: the object would never get from one to the "
            "other (to stop at both, add a waypoint between them with a speed above 0)"
            ) in str(info.value)


@pytest.mark.parametrize("duration_s, frame_rate_hz, n_frames", [
    (7.35, 20.0, 147),  # 147.00000000000003 frame periods in floating point
    (7.333333, 30.0, 220),  # a duration written to six decimals: 220 - 1e-5 frame periods
    (1.0 + 0.9e-3 / 20.0, 20.0, 20),  # 0.9 thousandths of a frame period too long
    (2.0, 0.5, 1),  # one frame held its whole 2 s period
])
def test_frames_that_cover_the_duration_load(tmp_path, duration_s, frame_rate_hz, n_frames):
    scene = load_scenario(write_scene(tmp_path, [{
        "name": "car", "rcs": {"rcs_dbsm": 10},
        "motion": {"type": "stationary", "position_m": [20, 0, 0.5]}}],
        duration_s=duration_s, frame_rate_hz=frame_rate_hz))
    assert scene.n_frames == n_frames
    assert abs(n_frames / frame_rate_hz - duration_s) <= 1e-3 / frame_rate_hz


@pytest.mark.parametrize("duration_s, frame_rate_hz, key", [
    (1.0 + 1.1e-3 / 20.0, 20.0, "duration_s"),  # 1.1 thousandths of a frame period too long
    (1.0 - 1.1e-3 / 20.0, 20.0, "duration_s"),
    (6.0, 0.05, "frame_rate_hz"),  # under one frame period: the rate is the suspect
    (1.0, 1.5, "duration_s"),
    (0.02, 20.0, "duration_s"),  # under one frame of a usual rate: the duration is the suspect
])
def test_frames_that_do_not_cover_the_duration_are_refused(tmp_path, duration_s,
                                                            frame_rate_hz, key):
    with pytest.raises(ScenarioError, match=rf":\d+:\d+: {key}: duration_s = .* frame periods, "
                                            rf"not a whole number of them"):
        load_scenario(write_scene(tmp_path, [{
            "name": "car", "rcs": {"rcs_dbsm": 10},
            "motion": {"type": "stationary", "position_m": [20, 0, 0.5]}}],
            duration_s=duration_s, frame_rate_hz=frame_rate_hz))


def accelerating(speed_mps, acceleration_mps2):
    return {"type": "constant_acceleration", "position_m": [20, 0, 0.5],
            "speed_mps": speed_mps, "acceleration_mps2": acceleration_mps2}


@pytest.mark.parametrize("speed_mps, acceleration_mps2, reaches_s", [
    (0.0, 15.0, 10.0),  # 150 m/s after 150 / 15 s
    (15.0, 15.0, 9.0),
    (-30.0, -12.0, 10.0),  # backwards, faster and faster: -150 m/s after 120 / 12 s
])
def test_a_motion_whose_speed_leaves_the_limit_within_the_scene_is_refused(
        tmp_path, speed_mps, acceleration_mps2, reaches_s):
    limit = 150.0 if acceleration_mps2 > 0 else -150.0
    path = write_scene(tmp_path, [{"name": "rocket", "rcs": {"rcs_dbsm": 10},
                                   "motion": accelerating(speed_mps, acceleration_mps2)}],
                       duration_s=20.0)
    with pytest.raises(ScenarioError, match=(
            rf":\d+:\d+: targets\[0\]\.motion\.acceleration_mps2: target 'rocket' reaches "
            rf"{limit:g} m/s at {reaches_s:g} s \({acceleration_mps2:g} m/s2 from "
            rf"{speed_mps:g} m/s\), before the scene's last frame at 19.95 s .*speeds run from "
            rf"-150 to 150 m/s")):
        load_scenario(path)


def test_the_ego_s_speed_is_held_to_the_same_limit(tmp_path):
    path = write_scene(tmp_path, [{"name": "car", "rcs": {"rcs_dbsm": 10},
                                   "motion": accelerating(0.0, 0.0)}],
                       duration_s=20.0, ego={"motion": accelerating(100.0, 10.0)})
    with pytest.raises(ScenarioError, match=r":\d+:\d+: ego\.motion\.acceleration_mps2: the ego "
                                            r"reaches 150 m/s at 5 s "):
        load_scenario(path)


@pytest.mark.parametrize("speed_mps, acceleration_mps2", [
    (100.0, 2.5),  # 150 m/s at exactly 20 s: after the last frame (19.95 s)
    (150.0, -15.0),  # braking from the limit: it stops at 10 s and stands
    (-150.0, 15.0),
    (150.0, 0.0),
])
def test_a_motion_within_the_speed_limit_loads(tmp_path, speed_mps, acceleration_mps2):
    scene = load_scenario(write_scene(tmp_path, [{
        "name": "car", "rcs": {"rcs_dbsm": 10},
        "motion": accelerating(speed_mps, acceleration_mps2)}], duration_s=20.0))
    # Radial speed is at most the speed: at most the limit in every frame.
    assert np.abs(compute_tracks(scene).radial_velocity_mps).max() <= 150.0 + 1e-9


def test_a_target_is_held_to_the_speed_limit_while_it_is_present(tmp_path):
    # 100 m/s, 10 m/s2: 150 m/s at 5 s. Gone at 4 s (its last frame 3.95 s, at 139.5 m/s) it
    # never plays faster than the limit; gone at 6 s, it does, and the error says when it goes.
    def bike(disappear_s):
        return write_scene(tmp_path, [{"name": "bike", "rcs": {"rcs_dbsm": 0},
                                       "disappear_s": disappear_s,
                                       "motion": accelerating(100.0, 10.0)}], duration_s=12.0)

    scene = load_scenario(bike(4.0))
    assert np.abs(compute_tracks(scene).radial_velocity_mps[scene.t_s < 4.0]).max() <= 150.0
    with pytest.raises(ScenarioError, match=(
            r"target 'bike' reaches 150 m/s at 5 s \(10 m/s2 from 100 m/s\), before its last "
            r"frame at 5.95 s \(disappear_s; duration_s = 12 s at 20 Hz\): .* accelerate less, "
            r"or let it disappear before the speed leaves them")):
        load_scenario(bike(6.0))


def profile(*points):
    return {"type": "speed_profile", "position_m": [20, 0, 0.5],
            "profile": [{"t_s": t, "speed_mps": v} for t, v in points]}


def waypoints(*points):
    return {"type": "waypoints",
            "points": [{"position_m": [x, 0, 0.5], "speed_mps": v} for x, v in points]}


@pytest.mark.parametrize("motion, key, message", [
    # 0 to 10 m/s in 1 ms: 10 / 0.001.
    (profile((0, 0), (1, 0), (1.001, 10)), r"profile\[2\]",
     r"from profile\[1\] to profile\[2\] the speed goes from 0 to 10 m/s in 0.001 s: that is an "
     r"acceleration of 10000 m/s2"),
    # Braking from 20 m/s to 0 in 1 s.
    (profile((0, 20), (1, 0)), r"profile\[1\]", r"an acceleration of -20 m/s2"),
    # 0 to 150 m/s over 1 m: 150^2 / (2 x 1).
    (waypoints((20, 0), (21, 150)), r"points\[1\]",
     r"from waypoint 0 to waypoint 1 the speed goes from 0 to 150 m/s over 1 m of path: that is "
     r"an acceleration of 11250 m/s2"),
    # 30 m/s to standstill over 20 m: -900 / 40.
    (waypoints((20, 30), (40, 0), (60, 10)), r"points\[1\]", r"an acceleration of -22.5 m/s2"),
])
def test_an_acceleration_a_motion_implies_beyond_the_bound_is_refused(tmp_path, motion, key,
                                                                      message):
    path = write_scene(tmp_path, [{"name": "car", "rcs": {"rcs_dbsm": 10}, "motion": motion}])
    with pytest.raises(ScenarioError, match=(
            rf":\d+:\d+: targets\[0\]\.motion\.{key}: .*{message}; accelerations run from -15 to "
            rf"15 m/s2")):
        load_scenario(path)


@pytest.mark.parametrize("motion", [
    profile((0, 0), (1, 15)),  # 15 m/s2, the bound
    profile((0, 20), (2, -10)),  # -15 m/s2
    waypoints((20, 0), (50, 30)),  # 900 / 60 = 15 m/s2
])
def test_an_acceleration_a_motion_implies_at_the_bound_loads(tmp_path, motion):
    scene = load_scenario(write_scene(tmp_path, [{"name": "car", "rcs": {"rcs_dbsm": 10},
                                                  "motion": motion}]))
    assert np.abs(scene.targets[0].trajectory.law.a_mps2).max() == pytest.approx(15.0)


def test_the_acceleration_bound_is_the_schema_s():
    from rts_scenario.scenario.loader import MAX_ACCELERATION_MPS2, scenario_schema
    motions = scenario_schema()["$defs"]["motion"]["allOf"]
    bound = next(m["then"]["properties"]["acceleration_mps2"] for m in motions
                 if m["if"]["properties"]["type"]["const"] == "constant_acceleration")
    assert (bound["minimum"], bound["maximum"]) == (-MAX_ACCELERATION_MPS2, MAX_ACCELERATION_MPS2)


@pytest.mark.parametrize("name, message", [
    ("x\nPASS approaching-target (a.scenario.yaml)",
     r"the control character '\\n' at position 1;"),
    ("a\x1b[31mred", r"the control character '\\x1b' at position 1;"),
    ("a\u2028b", r"the control character '\\u2028' at position 1;"),  # a line separator
    ("left\u202eright", r"the control character '\\u202e' at position 4;"),  # bidi override
    ("   ", r"got '   ', a blank name;"),
    ("", r"should be non-empty|a blank name"),
])
def test_a_scene_name_that_is_not_one_line_of_printable_text_is_refused(tmp_path, name,
                                                                          message):
    path = write_scene(tmp_path, [{"name": "car", "rcs": {"rcs_dbsm": 10},
                                   "motion": {"type": "stationary", "position_m": [20, 0, 0]}}],
                       name="t.scenario.yaml")
    # JSON's string escapes are YAML's double-quoted ones.
    path.write_text(path.read_text().replace("name: test\n", f"name: {json.dumps(name)}\n"))
    with pytest.raises(ScenarioError, match=rf"t\.scenario\.yaml:2:1: name: .*(?:{message})"):
        load_scenario(path)


@pytest.mark.parametrize("name", ["cut-in", "CCRs 50 km/h, 75% overlap", "Überholen ü"])
def test_a_scene_name_of_printable_text_loads(tmp_path, name):
    path = write_scene(tmp_path, [{"name": "car", "rcs": {"rcs_dbsm": 10},
                                   "motion": {"type": "stationary", "position_m": [20, 0, 0]}}])
    path.write_text(path.read_text().replace("name: test\n", f"name: '{name}'\n"))
    assert load_scenario(path).name == name


@pytest.mark.parametrize("mark, message", [
    ("skp", "'skp' looks like a misspelt 'skip'"),
    ("xfial", "'xfial' looks like a misspelt 'xfail'"),  # two letters swapped
    ("Skip", "'Skip' looks like a misspelt 'skip'"),
    ("skipiff", "'skipiff' looks like a misspelt 'skipif'"),
    ("parametrize", "'parametrize' is a pytest mark that needs arguments"),
    ("usefixtures", "'usefixtures' is a pytest mark that needs arguments"),
    ("filterwarnings", "'filterwarnings' is a pytest mark that needs arguments"),
])
def test_a_mark_that_would_silently_not_apply_is_refused(tmp_path, mark, message):
    path = tmp_path / "s.scenario.yaml"
    path.write_text(GOOD + f"marks: [slow, {mark}]\n")
    with pytest.raises(ScenarioError, match=rf"s\.scenario\.yaml:15:\d+: marks\[1\]: "
                                            rf"{re.escape(message)}"):
        load_scenario(path)


@pytest.mark.parametrize("marks", [["skip"], ["skipif"], ["xfail", "slow"],
                                   ["nightly", "hardware", "ship_lab"],
                                   ["skid", "ship", "slip"]])  # words, one letter apart
def test_verdict_marks_and_labels_load(tmp_path, marks):
    path = tmp_path / "s.scenario.yaml"
    path.write_text(GOOD + f"marks: [{', '.join(marks)}]\n")
    assert load_scenario(path).marks == tuple(marks)


def test_a_duration_no_frame_rate_can_play_suggests_no_rate_beyond_the_schema_s(tmp_path):
    path = write_scene(tmp_path, [{"name": "car", "rcs": {"rcs_dbsm": 10},
                                   "motion": {"type": "stationary", "position_m": [20, 0, 0]}}],
                       duration_s=1e-300)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert "frame_rate_hz: 1e+300" not in str(info.value)
    assert str(info.value).endswith(
        "e.g. duration_s: 0.05 (1 frame) (no frame rate up to 1000 Hz plays 1e-300 s in whole "
        "frames)")


@pytest.mark.parametrize("replace, by, key, preset, suffix", [
    ("rig: wide-3x5", "rig: wide-3x5.rig.yaml", "rig", "wide-3x5", ".rig.yaml"),
    ("profile: awr1843boost", "profile: awr1843boost.radar.yaml", "radar.profile",
     "awr1843boost", ".radar.yaml"),
])
def test_a_preset_named_as_a_file_that_does_not_exist_suggests_the_preset(
        tmp_path, replace, by, key, preset, suffix):
    path = tmp_path / "s.scenario.yaml"
    path.write_text(edit(replace, by))
    with pytest.raises(ScenarioError, match=rf": {re.escape(key)}: file not found: "
                                            rf"'{preset}{re.escape(suffix)}' .*; the preset "
                                            rf"'{preset}' is named without "
                                            rf"{re.escape(suffix)}: {re.escape(key)}: {preset}$"):
        load_scenario(path)


def test_a_mapping_where_a_list_goes_is_quoted_short(tmp_path):
    targets = "".join(f"  car{i}: {{name: car{i}, kind: car}}\n" for i in range(50))
    path = tmp_path / "s.scenario.yaml"
    path.write_text(GOOD.split("targets:")[0] + "targets:\n" + targets)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    message = str(info.value).split("targets: ", 1)[1]
    assert message.startswith("must be of type array, got {'car0': {'name': 'car0'")
    assert message.endswith(" ...}") and len(message) < 120


def test_the_shortest_lane_change_peaks_at_the_acceleration_bound(tmp_path):
    # The bound's constant against the motion itself: the lateral position's second difference
    # over 1 ms steps peaks at 15 m/s2 for the shortest 3 m change, within the differences'
    # error (~1e-5 relative).
    from rts_scenario.scenario.loader import MAX_ACCELERATION_MPS2, lane_change_seconds

    shortest = lane_change_seconds(3.0)
    path = tmp_path / "s.scenario.yaml"
    path.write_text(edit("    rcs: {rcs_dbsm: 10.0}", "    rcs: {rcs_dbsm: 10.0}\n"
                         "    lane_changes:\n      - {start_s: 1, duration_s: "
                         f"{shortest!r}, offset_m: 3}}"))
    from rts_scenario.scenario.trajectory import TrajectorySet

    motion = TrajectorySet([load_scenario(path).targets[0].trajectory])
    h = 1e-3
    t = np.arange(0.5, 1.5 + shortest, h)
    lateral = motion.evaluate(t).position_m[:, 0, 1]
    peak = np.abs(np.diff(lateral, 2)).max() / h**2
    assert peak == pytest.approx(MAX_ACCELERATION_MPS2, rel=1e-4)
    assert lateral[-1] - lateral[0] == pytest.approx(3.0, abs=1e-9)


def _quintic_accel(t, start, duration, offset):
    """The lane change's sideways acceleration, from its position's second difference."""
    h = 1e-4
    pos = [offset * np.clip((t + k * h - start) / duration, 0, 1) ** 3
           * (10 - 15 * np.clip((t + k * h - start) / duration, 0, 1)
              + 6 * np.clip((t + k * h - start) / duration, 0, 1) ** 2) for k in (-1, 0, 1)]
    return (pos[0] - 2 * pos[1] + pos[2]) / h**2


@pytest.mark.parametrize("changes", [
    [(1.0, 1.2, 3.5), (1.0, 1.2, 3.5)],        # the same change twice: 2 x 14.03 m/s2
    [(0.5, 1.3, 3.0), (0.9, 1.3, 3.0)],        # shifted: their peaks add in part (12.4)
    [(0.5, 1.5, 3.5), (1.4, 1.5, -3.5)],       # a return before the change ends: the
                                               # change's braking and the return's start add
                                               # (17.9)
    [(0.5, 1.2, 3.5), (1.7, 1.2, -3.5)],       # one after the other: each alone (14.03)
])
def test_overlapping_lane_changes_are_held_to_the_bound_together(tmp_path, changes):
    # The loader's peak (exact, piecewise cubic) against the second difference of the summed
    # quintics on a 0.1 ms grid: refused exactly where the sum exceeds 15 m/s2.
    t = np.arange(0.0, 4.0, 1e-4)
    numeric = np.abs(sum(_quintic_accel(t, *c) for c in changes)).max()
    items = "".join(f"\n      - {{start_s: {s}, duration_s: {d}, offset_m: {o}}}"
                    for s, d, o in changes)
    path = tmp_path / "s.scenario.yaml"
    path.write_text(edit("    rcs: {rcs_dbsm: 10.0}", "    rcs: {rcs_dbsm: 10.0}\n"
                         "    lane_changes:" + items))
    if numeric <= 15.0:
        load_scenario(path)
        return
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    err = info.value
    assert err.key_path == "targets[0].lane_changes"
    peak = float(str(err).split("sideways up to ")[1].split(" m/s2")[0])
    assert peak == pytest.approx(numeric, rel=1e-4)
    assert "lane_changes[0] and lane_changes[1] overlap in time" in str(err)
    assert "start one after the other ends, or make them longer" in str(err)


EGO_LANE_CHANGE = "\n  lane_changes: [{start_s: 1.0, duration_s: 2.0, offset_m: 3.5}]"


@pytest.mark.parametrize("motion, zero_at", [
    # Standing: its body would face sideways, the radar with it.
    ("{type: stationary, position_m: [0, 0, 0]}", 1.0),
    # Braking from 10 m/s at 5 m/s2: stands from 2 s, within the change (1 to 3 s).
    ("{type: constant_acceleration, position_m: [0, 0, 0], speed_mps: 10.0, "
     "acceleration_mps2: -5.0}", 2.0),
    # Backing out and driving off: speed 0 at 1.5 s (-2 m/s at 0.5 s, +2 m/s at 2.5 s).
    ("{type: speed_profile, position_m: [0, 0, 0], profile: [{t_s: 0.5, speed_mps: -2}, "
     "{t_s: 2.5, speed_mps: 2}]}", 1.5),
    # Backwards throughout, or forwards throughout: the body faces one way, as in a run.
    ("{type: constant_velocity, position_m: [0, 0, 0], speed_mps: -5.0}", None),
    ("{type: constant_acceleration, position_m: [0, 0, 0], speed_mps: 10.0, "
     "acceleration_mps2: -3.0}", None),
])
def test_an_ego_lane_change_while_it_stands_is_refused(tmp_path, motion, zero_at):
    # The reviewer's scene: a standing ego changing lanes turned the radar by +-90 deg, and
    # flipped it 180 deg between frames on rounding (azimuth -98.4, then +95.3, then -99.1).
    path = tmp_path / "s.scenario.yaml"
    path.write_text(GOOD.replace(
        "  motion: {type: constant_velocity, position_m: [0, 0, 0], speed_mps: 20.0}",
        f"  motion: {motion}{EGO_LANE_CHANGE}"))
    if zero_at is None:
        tracks = compute_tracks(load_scenario(path), np.arange(0.0, 4.0, 0.01))
        assert np.abs(np.diff(tracks.az_deg[:, 0])).max() < 5.0  # no jump of the radar
        return
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    err = info.value
    assert err.key_path == "ego.lane_changes[0]" and err.line == 11
    assert (f"the ego's speed along its path is 0 at {zero_at:g} s, during this lane change "
            f"(1 to 3 s)") in str(err)


@pytest.mark.parametrize("speed_mps, refused", [(12.0, False), (25.0, True)])
def test_a_spline_that_turns_too_hard_for_its_speed_is_refused(tmp_path, speed_mps, refused):
    # Waypoints on a circle of 30 m radius, a quarter of it, driven at a constant speed: the
    # sideways acceleration is about v^2 / R (12 m/s: 4.8 m/s2; 25 m/s: 21 m/s2, beyond the
    # 15 m/s2 a scene allows along a path and for lane changes).
    angles = np.radians([0.0, 22.5, 45.0, 67.5, 90.0])
    points = "".join(f"        - {{position_m: [{40 + 30 * np.sin(a):.6f}, "
                     f"{30 - 30 * np.cos(a):.6f}, 0.6], speed_mps: {speed_mps}}}\n"
                     for a in angles)
    motion = f"    motion:\n      type: waypoints\n      path: spline\n      points:\n{points}"
    err = _with_target_motion(tmp_path, "turn", motion, refused)
    if err is None:
        return
    message = str(err)
    assert "targets[0].motion.points[" in message and "the spline path turns" in message
    across = float(re.search(r"a sideways acceleration of ([0-9.]+) m/s2", message).group(1))
    radius = float(re.search(r"with a radius of ([0-9.]+) m", message).group(1))
    # The reference: the natural cubic spline through the points (chord-length parameter),
    # its curvature on a fine grid: it bends more than the circle (21 m/s2) in its middle, its
    # curvature being 0 at its ends.
    from scipy.interpolate import CubicSpline

    xy = np.stack([40 + 30 * np.sin(angles), 30 - 30 * np.cos(angles)], axis=1)
    u = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    spline = CubicSpline(u, xy, bc_type="natural")
    fine = np.linspace(0.0, u[-1], 20001)
    d1, d2 = spline(fine, 1), spline(fine, 2)
    curvature = np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / np.linalg.norm(d1, axis=1) ** 3
    assert across == pytest.approx(speed_mps ** 2 * curvature.max(), rel=0.01)
    assert radius == pytest.approx(1.0 / curvature.max(), rel=0.01)
    assert across > speed_mps ** 2 / 30.0


def test_a_parametrize_block_of_too_many_combinations_is_refused_before_expanding(tmp_path):
    # 8 keys x 10 values: 10^8 combinations, each loaded where pytest collects it; collection
    # hung for ever without a word.
    import time

    keys = ["targets.0.rcs.rcs_dbsm", "targets.0.motion.speed_mps", "ego.motion.speed_mps",
            "duration_s", "frame_rate_hz", "targets.0.motion.position_m.0",
            "targets.0.motion.position_m.1", "radar.mount.x_m"]
    block = "".join(f"  {key}: [{', '.join(str(1.0 + i) for i in range(10))}]\n"
                    for key in keys)
    path = tmp_path / "many.scenario.yaml"
    path.write_text(GOOD + "parametrize:\n" + block)
    start = time.perf_counter()
    with pytest.raises(ScenarioError, match=r"many.scenario.yaml:15:\d+: parametrize: "
                                            r"100,000,000 combinations \(10 x 10 x 10 x 10 x 10 "
                                            r"x 10 x 10 x 10\); at most 100,000 in one scene "
                                            r"file: split it"):
        parametrizations(path)
    assert time.perf_counter() - start < 30.0  # refused before expanding (a wide margin)


def test_a_parametrize_block_of_as_many_combinations_as_allowed_expands(tmp_path, monkeypatch):
    import rts_scenario.scenario.loader as loader

    monkeypatch.setattr(loader, "MAX_COMBINATIONS", 6)
    path = tmp_path / "six.scenario.yaml"
    path.write_text(GOOD + "parametrize:\n  targets.0.rcs.rcs_dbsm: [1, 2, 3]\n"
                           "  radar.noise: [true, false]\n")
    assert len(parametrizations(path)) == 6
    path.write_text(GOOD + "parametrize:\n  targets.0.rcs.rcs_dbsm: [1, 2, 3, 4]\n"
                           "  radar.noise: [true, false]\n")
    with pytest.raises(ScenarioError, match=r"8 combinations \(4 x 2\); at most 6 in one"):
        parametrizations(path)
