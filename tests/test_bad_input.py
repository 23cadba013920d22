"""Acceptance test: no input ends in a traceback.

A catalogue of bad scene files and bad command lines. Each ends in exactly one ``error:`` line
that names the file, line and key (YAML) or the argument, and what is allowed, with the
documented exit code; a hypothesis test throws random argument lists at the CLI.
"""

from __future__ import annotations

import json
import math
import os
import re
import stat
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import rts_scenario.cli as cli

ROOT = Path(__file__).resolve().parents[1]

TINY = """\
rts_scenario: 1
name: tiny
duration_s: 0.5
frame_rate_hz: 10.0
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


def alias_bomb() -> str:
    """A "billion laughs" document of about 2 kB: 10^31 nodes once its aliases are expanded."""
    lines = ['l0: &l0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for i in range(1, 31):
        lines.append(f"l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * 10) + "]")
    return "\n".join(lines) + "\n"


def sub(old: str, new: str) -> str:
    assert old in TINY, old
    return TINY.replace(old, new)


TARGET = "  - name: car\n"
MOTION = "    motion: {type: constant_velocity, position_m: [30, 0, 0.6], speed_mps: 19.0}\n"

# (id, scene text (or bytes), regex of the message after "error: "; {f} is the scene's path)
SCENE_CASES: list[tuple[str, str | bytes, str]] = [
    ("alias-bomb", alias_bomb(),
     r"^{f}:\d+:\d+: document expands to more than 1,000,000 YAML nodes"),
    ("recursive-alias", TINY + "description: &d [*d]\n", r"^{f}:15:\d+: alias \*d refers to"),
    # validate said ok and run stopped it with exit 3, naming no key.
    ("estimator-not-for-array",
     TINY.replace("  profile: awr1843boost\n", "  profile: cascade-12x16\n  estimator: ti\n"),
     r"^{f}:7:3: radar.estimator: 'ti' cannot estimate angles on the radar's array: array "
     r"'cascade-12x16': TI-style azimuth needs an evenly spaced row; an estimator that can: "
     r"bartlett$"),
    ("deep-nesting", TINY + "description: " + "[" * 100 + "]" * 100 + "\n",
     r"^{f}:15:\d+: nesting deeper than the limit of 64 levels"),
    ("too-many-nodes", TINY + "marks: [" + ", ".join(["a"] * 1_000_100) + "]\n",
     r"^{f}:15:\d+: document expands to more than 1,000,000 YAML nodes"),
    ("document-too-large", TINY + "description: " + "x" * (4 * 1024 * 1024) + "\n",
     r"^{f}: document larger than the limit of 4 MB"),
    ("invalid-yaml", TINY + "description: [unclosed\n", r"^{f}:\d+:\d+: invalid YAML"),
    ("tab-indent", sub("  profile: awr1843boost", "\tprofile: awr1843boost"),
     r"^{f}:6:1: a tab indents this line; YAML indents with spaces$"),
    ("tab-after-dash", sub(TARGET, "  -\tname: car\n"),
     r"^{f}:12:4: a tab after '-' on this line; YAML separates with spaces$"),
    ("key-indented-between", sub("  mount:", " mount:"),
     r"^{f}:7:2: invalid YAML: this line is indented 1 space, but the mapping from line 1 has "
     r"its keys at 0 spaces and line 6 above it at 2; keys of one mapping line up$"),
    ("duplicate-key", TINY + "name: again\n", r"^{f}:15:1: name: duplicate key"),
    ("non-string-key", TINY + "1: one\n", r"^{f}:\d+:\d+: keys must be strings"),
    ("python-tag", TINY + "description: !!python/object:os.system x\n",
     r"^{f}:15:\d+: .*(tag|constructor)"),
    ("custom-tag", TINY + "seed: !custom 3\n", r"^{f}:\d+:\d+: .*tag"),
    ("top-level-list", "- 1\n- 2\n", r"^{f}:1:1: a scene must be a mapping of keys, got list"),
    ("empty-file", "", r"^{f}: a scene must be a mapping of keys, got an empty file"),
    ("not-utf8", b"name: \xff\xfe\n",
     r"^{f}:1:7: not UTF-8 text: invalid start byte \(byte 0xff\)"),
    # YAML 1.1 (PyYAML) reads 010 as octal 8 and 1:30 as the base-60 number 90; YAML 1.2 (what
    # editors and the schema's users read) as 10 and a string: a number either way is a guess.
    ("leading-zero", sub("speed_mps: 19.0}", "speed_mps: 010}"),
     r"^{f}:13:\d+: targets\[0\].motion.speed_mps: 010: a number with a leading zero reads as "
     r"octal 8 in YAML 1.1 and as 10 in YAML 1.2; write it without the leading zero \(or "
     r"quote it for a string\)$"),
    ("leading-zero-not-octal", sub("duration_s: 0.5", "duration_s: 09"),
     r"^{f}:3:\d+: duration_s: 09: a number with a leading zero reads as a string in YAML 1.1 "
     r"and as 9 in YAML 1.2; write it without the leading zero"),
    ("sexagesimal", sub("duration_s: 0.5", "duration_s: 1:30"),
     r"^{f}:3:\d+: duration_s: 1:30: reads as the base-60 number 90 in YAML 1.1 and as a "
     r"string in YAML 1.2; write the number \(90\), or quote it for a string$"),
    ("underscores", sub("speed_mps: 19.0}", "speed_mps: 1_0.0}"),
     r"^{f}:13:\d+: targets\[0\].motion.speed_mps: 1_0.0: a number with underscores reads as "
     r"10.0 in YAML 1.1 and as a string in YAML 1.2; write it without them \(10.0\), or quote "
     r"it for a string$"),
    ("binary", sub("speed_mps: 19.0}", "speed_mps: 0b1000}"),
     r"^{f}:13:\d+: targets\[0\].motion.speed_mps: 0b1000: reads as the binary number 8 in "
     r"YAML 1.1 and as a string in YAML 1.2; write the number \(8\), or quote it for a string$"),
    ("octal-1.2", sub("duration_s: 0.5", "duration_s: 0o17"),
     r"^{f}:3:\d+: duration_s: 0o17: reads as a string in YAML 1.1 and as the octal number 15 "
     r"in YAML 1.2; write the number \(15\), or quote it for a string$"),
    *((f"bool-{word}", TINY.replace("radar:\n", f"radar:\n  noise: {word}\n"),
       rf"^{{f}}:\d+:10: radar.noise: {word}: reads as {reading} in YAML 1.1 and as the string "
       rf"'{word}' in YAML 1.2; write {reading}, or quote it for a string$")
      for word, reading in (("no", "false"), ("off", "false"), ("yes", "true"), ("On", "true"))),
    ("missing-name", sub("name: tiny\n", ""), r"^{f}.*'name' is required but missing"),
    ("unknown-key", TINY + "colour: red\n", r"^{f}:15:1: colour: unknown key 'colour'; allowed"),
    ("version-2", sub("rts_scenario: 1", "rts_scenario: 2"),
     r"^{f}:1:1: rts_scenario: got 2; allowed values: 1"),
    ("duration-string", sub("duration_s: 0.5", "duration_s: ten"),
     r"^{f}:3:1: duration_s: must be of type number, got 'ten'"),
    ("duration-negative", sub("duration_s: 0.5", "duration_s: -1"),
     r"^{f}:3:1: duration_s: must be > 0, got -1"),
    ("duration-nan", sub("duration_s: 0.5", "duration_s: .nan"),
     r"^{f}:3:1: duration_s: must be a finite number, got nan"),
    ("duration-too-long", sub("duration_s: 0.5", "duration_s: 100000"),
     r"^{f}:3:1: duration_s: must be <= 86400"),
    ("frame-rate-inf", sub("frame_rate_hz: 10.0", "frame_rate_hz: .inf"),
     r"^{f}:4:1: frame_rate_hz: must be a finite number, got inf"),
    ("frame-rate-above-schema", sub("frame_rate_hz: 10.0", "frame_rate_hz: 5000"),
     r"^{f}:4:1: frame_rate_hz: must be <= 1000"),
    # A scene has at least one frame, held for its frame period: here 11 days.
    ("frames-span-too-long", sub("frame_rate_hz: 10.0", "frame_rate_hz: 1e-6"),
     r"^{f}:4:1: frame_rate_hz: duration_s = 0.5 s at frame_rate_hz = 1e-06 Hz is 5e-07 frame "
     r"periods, not a whole number of them: the scene would play 1 frame held 1e\+06 s, "
     r"1e\+06 s in all, not the 0.5 s declared \(frame_rate_hz counts frames per second, the "
     r"inverse of the frame period\); "),
    # A frame period written where the rate goes: one frame frozen for 20 s, none of the 6 s of
    # motion played; 0.05 s is a frame period that covers 6 s.
    ("frames-frozen", sub("duration_s: 0.5", "duration_s: 6.0").replace(
        "frame_rate_hz: 10.0", "frame_rate_hz: 0.05"),
     r"^{f}:4:1: frame_rate_hz: duration_s = 6 s at frame_rate_hz = 0.05 Hz is 0.3 frame "
     r"periods, not a whole number of them: the scene would play 1 frame held 20 s, 20 s in "
     r"all, not the 6 s declared \(frame_rate_hz counts frames per second: if 0.05 s is the "
     r"frame period, frame_rate_hz: 20\); the frames must cover duration_s to within 0.001 of a "
     r"frame period: e.g. duration_s: 20 \(1 frame\) or frame_rate_hz: 0.166667$"),
    # 1.5 frame periods play as 2: 1.33 s of a 1 s scene.
    ("frames-overrun", sub("duration_s: 0.5", "duration_s: 1.0").replace(
        "frame_rate_hz: 10.0", "frame_rate_hz: 1.5"),
     r"^{f}:3:1: duration_s: duration_s = 1 s at frame_rate_hz = 1.5 Hz is 1.5 frame periods, "
     r"not a whole number of them: the scene would play 2 frames held 0.666667 s each, 1.33333 "
     r"s in all, not the 1 s declared; the frames must cover duration_s to within 0.001 of a "
     r"frame period: e.g. duration_s: 0.666667 or 1.33333 \(1 or 2 frames\) or frame_rate_hz: "
     r"1 or 2$"),
    ("frames-short-of-duration", sub("duration_s: 0.5", "duration_s: 0.52"),
     r"^{f}:3:1: duration_s: duration_s = 0.52 s at frame_rate_hz = 10 Hz is 5.2 frame periods"
     r".* would play 5 frames held 0.1 s each, 0.5 s in all, not the 0.52 s declared; .* e.g. "
     r"duration_s: 0.5 or 0.6 \(5 or 6 frames\) or frame_rate_hz: 9.61538 or 11.5385$"),
    ("frame-rate-above-rig", sub("frame_rate_hz: 10.0", "frame_rate_hz: 500"),
     r"^{f}:4:1: frame_rate_hz: the scene runs at 500 Hz but rig 'wide-3x5' updates at most"),
    ("target-frames-too-many", sub("duration_s: 0.5", "duration_s: 86400").replace(
        "frame_rate_hz: 10.0", "frame_rate_hz: 1000"),
     r"^{f}:3:1: duration_s: duration_s x frame_rate_hz = .* the limit is 50,000,000"),
    ("measurement-noise", TINY + "effects:\n  measurement_noise: {range_m: 0.05}\n",
     r"^{f}:16:3: effects.measurement_noise: not supported; the simulated radar's noise comes "
     r"from radar.noise"),
    ("unknown-rig", sub("rig: wide-3x5", "rig: wide-9x9"),
     r"^{f}:8:1: rig: unknown preset 'wide-9x9'; valid presets: .*wide-3x5"),
    ("unknown-radar", sub("profile: awr1843boost", "profile: awr9999"),
     r"^{f}:6:3: radar.profile: unknown preset 'awr9999'; valid presets"),
    # A file of another kind in its place: named as such, not by its every key unknown.
    ("rig-file-as-radar", sub("profile: awr1843boost", "profile: lab.rig.yaml"),
     r"^{f}:6:3: radar.profile: 'lab.rig.yaml' is a rig file \(\*.rig.yaml\); radar.profile "
     r"takes a preset \(awr1843boost, cascade-12x16, paper\) or a \*.radar.yaml file$"),
    ("dbc-as-radar", sub("profile: awr1843boost", "profile: cluster_list.dbc"),
     r"^{f}:6:3: radar.profile: 'cluster_list.dbc' is a DBC file \(\*.dbc\); radar.profile "
     r"takes a preset \(awr1843boost, cascade-12x16, paper\) or a \*.radar.yaml file$"),
    ("radar-file-as-rig", sub("rig: wide-3x5", "rig: long.radar.yaml"),
     r"^{f}:8:1: rig: 'long.radar.yaml' is a radar profile \(\*.radar.yaml\); rig takes a "
     r"preset \(kit-table1, wide-3x5\) or a \*.rig.yaml file$"),
    ("rig-outside-tree", sub("rig: wide-3x5", "rig: ../elsewhere.rig.yaml"),
     r"^{f}:8:1: rig: '../elsewhere.rig.yaml' leaves the scene's folder tree"),
    ("absolute-include", TINY + "include: [/etc/passwd]\n",
     r"^{f}:15:\d+: include\[0\]: must be a path relative to the scene's folder"),
    ("missing-include", TINY + "include: [nothing.yaml]\n",
     r"^{f}:15:\d+: include\[0\]: file not found: 'nothing.yaml'"),
    ("target-without-motion", sub(MOTION, ""),
     r"^{f}:12:\d+: targets\[0\].*'motion' is required but missing"),
    ("bad-target-name", sub("name: car", "name: my car"),
     r"^{f}:12:\d+: targets\[0\].name: .*does not match"),
    ("duplicate-target", TINY + TARGET.replace("targets", "") + MOTION
     + "    rcs: {rcs_dbsm: 10.0}\n",
     r"^{f}:15:\d+: targets\[1\].name: duplicate target name 'car'"),
    ("unknown-motion", sub("type: constant_velocity, position_m: [30",
                           "type: teleport, position_m: [30"),
     r"^{f}:13:\d+: targets\[0\].motion"),
    ("motion-without-type", sub("type: constant_velocity, position_m: [30", "position_m: [30"),
     r"^{f}:13:\d+: targets\[0\].motion: 'type' is required but missing; allowed values: "
     r"'stationary', 'constant_velocity'"),
    ("position-wrong-length", sub("position_m: [30, 0, 0.6]", "position_m: [30, 0]"),
     r"^{f}:13:\d+: targets\[0\].motion.*(position_m|items)"),
    ("speed-profile-not-increasing", sub(
        MOTION, "    motion: {type: speed_profile, position_m: [30, 0, 0.6], profile: "
                "[{t_s: 1, speed_mps: 1}, {t_s: 1, speed_mps: 2}]}\n"),
     r"^{f}:13:\d+: targets\[0\].motion.profile\[1\].t_s: times must increase"),
    ("repeated-waypoint", sub(
        MOTION, "    motion: {type: waypoints, points: [{position_m: [30, 0, 0], speed_mps: 1}, "
                "{position_m: [30, 0, 0], speed_mps: 1}]}\n"),
     r"^{f}:13:\d+: targets\[0\].motion.points\[1\].position_m: repeats waypoint 0"),
    ("disappear-before-appear", TINY + "    appear_s: 2\n    disappear_s: 1\n",
     r"^{f}:16:5: targets\[0\].disappear_s: must be later than appear_s = 2, got 1"),
    ("no-targets", TINY.split(TARGET)[0].replace("targets:", "targets: []"),
     r"^{f}:11:1: targets: the scene has no targets .* it can only test the radar's false "
     r"detections on an empty bench; to mean that, set "
     r"expectations.max_false_detections_per_frame"),
    ("target-never-present", TINY + "    appear_s: 100\n",
     r"^{f}:15:5: targets\[0\].appear_s: the target appears at 100 s, after the scene's last "
     r"frame at 0.4 s"),
    ("lane-change-after-the-end", TINY + "    lane_changes: [{start_s: 300, duration_s: 1, "
     "offset_m: 3}]\n",
     r"^{f}:15:\d+: targets\[0\].lane_changes\[0\].start_s: the lane change starts at 300 s, "
     r"at or after the scene's last frame at 0.4 s"),
    # A limit of the whole scene listed on a target would be ignored: the scene's alone count.
    ("scene-wide-limit-on-target", TINY + "    expected_limits: [out_of_coverage, "
     "frame_rate_above_radar]\n",
     r"^{f}:15:\d+: targets\[0\].expected_limits\[1\]: 'frame_rate_above_radar' is a limit of "
     r"the whole scene, not of one target: list it in expectations.expected_limits; a target's "
     r"expected_limits allow 'out_of_coverage', .*'beyond_radar_velocity'$"),
    ("rcs-table-mismatch", sub("rcs: {rcs_dbsm: 10.0}",
                               "rcs: {aspect_deg: [0, 90], rcs_dbsm: [1, 2, 3]}"),
     r"^{f}:14:\d+: targets\[0\].rcs.rcs_dbsm: needs one value per aspect_deg entry"),
    ("detection-rate-2", TINY + "expectations: {detection_rate: 2}\n",
     r"^{f}:15:\d+: expectations.detection_rate: must be <= 1, got 2"),
    ("tolerance-zero", TINY + "expectations: {tolerances: {az_deg: 0}}\n",
     r"^{f}:15:\d+: expectations.tolerances.az_deg: must be >= 1e-06, got 0"),
    ("seed-negative", TINY + "seed: -4\n", r"^{f}:15:1: seed: must be >= 0, got -4"),
    ("bad-mark", TINY + "marks: [not a mark]\n", r"^{f}:15:\d+: marks\[0\]: .*does not match"),
    ("parametrize-bad-path", TINY + "parametrize: {radar.nothing.here: [1, 2]}\n",
     r"^{f}:15:15: parametrize.radar.nothing.here: radar.nothing.here: no such key path in the "
     r"scene"),
    # A key path the scene does not have is wrong in its entry, not in the whole block.
    ("parametrize-path-past-the-list", TINY + "parametrize:\n  seed: [1]\n"
     "  targets.5.motion.speed_mps: [1]\n",
     r"^{f}:17:3: parametrize.targets.5.motion.speed_mps: targets.5.motion.speed_mps: no such "
     r"key path in the scene \(at targets.5\) \[seed=1-speed_mps=1\]$"),
    ("parametrize-index-past-the-list", TINY + "parametrize:\n  seed: [1]\n"
     "  duration_s, targets.0.motion.position_m.3: [[1.0, 2]]\n",
     r"^{f}:17:3: parametrize.duration_s, targets.0.motion.position_m.3: "
     r"targets.0.motion.position_m.3: no such key path in the scene \["),
    ("parametrize-combination-fails", TINY + "parametrize: {frame_rate_hz: [10, 400]}\n",
     r"^{f}:15:\d+: frame_rate_hz: the scene runs at 400 Hz .*\[frame_rate_hz=400\]$"),
    # A value a combination puts in place is wrong where the parametrize block gives it.
    ("parametrize-bad-value", TINY + "parametrize:\n  targets.0.motion.speed_mps: [19.0, fast]\n",
     r"^{f}:16:3: targets\[0\].motion.speed_mps: must be of type number, got 'fast' "
     r"\[speed_mps=fast\]$"),
    ("parametrize-new-key", TINY + "parametrize:\n  targets.0.motion.sped_mps: [19.0]\n",
     r"^{f}:16:3: targets\[0\].motion.sped_mps: unknown key 'sped_mps'; allowed keys: "
     r"heading_deg, position_m, speed_mps, type \[sped_mps=19.0\]$"),
    ("parametrize-group-bad-value", TINY + "parametrize:\n  duration_s, seed: [[1.0, 2], "
     "[2.0, -3]]\n", r"^{f}:16:3: seed: must be >= 0, got -3 \[duration_s=2.0-seed=-3\]$"),
    ("parametrize-group-short", TINY + "parametrize:\n  duration_s, seed: [[1.0, 2], [2.0]]\n",
     r"^{f}:16:\d+: parametrize.duration_s, seed\[1\]: needs a list of 2 values \(one per "
     r"key path: duration_s, seed\), got \[2.0\]"),
    # A key path given twice: the second took the place of the first's value without a word.
    ("parametrize-group-path-twice", TINY + "parametrize:\n  seed, seed: [[1, 2]]\n",
     r"^{f}:16:3: parametrize.seed, seed: seed: a key path given twice \(in the same entry\); "
     r"each key path takes one value per run$"),
    ("parametrize-path-in-two-entries", TINY + "parametrize:\n  seed: [1, 2]\n"
     "  duration_s, seed: [[1.0, 3]]\n",
     r"^{f}:17:3: parametrize.duration_s, seed: seed: a key path given twice \(first in "
     r"'seed'\); each key path takes one value per run$"),
    # A key path inside another: the runs were named after values they did not play.
    ("parametrize-path-inside-another", TINY + "parametrize:\n  targets.0.motion.speed_mps: "
     "[10.0, 30.0]\n  targets.0.motion: [{type: stationary, position_m: [20, 0, 0]}]\n",
     r"^{f}:16:3: parametrize.targets.0.motion.speed_mps: targets.0.motion.speed_mps lies "
     r"inside the key path 'targets.0.motion' varied too: a run would take one's value in "
     r"place of the other's and be named after both; write the values for "
     r"targets.0.motion.speed_mps into those of targets.0.motion, or vary only key paths "
     r"inside it$"),
    # An index spelled otherwise is the same index (the loader reads 00 as 0).
    ("parametrize-path-inside-another-spelled-otherwise", TINY + "parametrize:\n  "
     "targets.00.motion.speed_mps: [10.0, 30.0]\n  targets.0.motion: [{type: stationary, "
     "position_m: [20, 0, 0]}]\n",
     r"^{f}:16:3: parametrize.targets.00.motion.speed_mps: targets.00.motion.speed_mps lies "
     r"inside the key path 'targets.0.motion' varied too"),
    ("parametrize-path-twice-spelled-otherwise", TINY + "parametrize:\n  seed: [1, 2]\n"
     "  duration_s, seed: [[1.0, 3]]\n  targets.0.name: [a]\n  targets.00.name: [b]\n",
     r"^{f}:17:3: parametrize.duration_s, seed: seed: a key path given twice \(first in "
     r"'seed'\)"),
    ("parametrize-index-twice-spelled-otherwise", TINY + "parametrize:\n  targets.0.name: [a]\n"
     "  targets.00.name: [b]\n",
     r"^{f}:17:3: parametrize.targets.00.name: targets.00.name: a key path given twice \(as "
     r"'targets.0.name'\) \(first in 'targets.0.name'\)"),
    # A superscript two is a digit to str.isdigit, no index: int() of it was a runtime error.
    ("parametrize-superscript-index",
     TINY + "parametrize:\n  targets.\u00b2.rcs.rcs_dbsm: [1, 2]\n",
     r"^{f}:16:3: parametrize.targets.\u00b2.rcs.rcs_dbsm: targets.\u00b2.rcs.rcs_dbsm: no such "
     r"key path in the scene"),
    ("parametrize-path-inside-a-group", TINY + "parametrize:\n  radar: [{profile: "
     "awr1843boost}]\n  seed, radar.estimator: [[1, ti], [2, bartlett]]\n",
     r"^{f}:17:3: parametrize.seed, radar.estimator: radar.estimator lies inside the key path "
     r"'radar' varied too: .*$"),
    ("parametrize-group-empty-path", TINY + "parametrize:\n  'duration_s,': [[1.0, 2]]\n",
     r"^{f}:16:\d+: parametrize.duration_s,: 'duration_s,': an empty key path"),
    ("parametrize-empty-path", TINY + "parametrize:\n  '': [1.0, 2.0]\n",
     r"^{f}:16:\d+: parametrize.*: '': an empty key path, or an empty part between dots; write "
     r"a key path such as 'radar.estimator' or 'targets.0.rcs.rcs_dbsm'$"),
    ("parametrize-empty-part", TINY + "parametrize:\n  targets..name: [a, b]\n",
     r"^{f}:16:\d+: parametrize.targets..name: 'targets..name': an empty key path, or an empty "
     r"part between dots"),
    ("date-for-a-string", TINY + "description: 2024-01-01\n",
     r"^{f}:15:1: description: must be of type string, got a date \(2024-01-01\); quote it "
     r"for a string: '2024-01-01'$"),
    # A YAML date is no value a report can hold (run --json, sweep --json lost every verdict).
    ("parametrize-date", TINY + "parametrize:\n  description: [2024-01-01, plain]\n",
     r"^{f}:16:\d+: parametrize.description\[0\]: got a date \(2024-01-01\); a value must be "
     r"a string, a number, true, false, null, or a list or mapping of them \(quote it: "
     r"'2024-01-01'\)$"),
]


def one_error(err: str) -> str:
    """The message of the only ``error:`` line in ``err`` (argparse's lines included)."""
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if re.search(r"(^|: )error: ", line)]
    assert len(lines) == 1, err
    return lines[0].split("error: ", 1)[1]


def call(argv: list[str]) -> int:
    """Run the CLI in-process; argparse's usage errors come back as their exit code."""
    try:
        return cli.main(argv)
    except SystemExit as exc:
        assert exc.code == 2, exc.code  # only argparse exits, and only with 2
        return 2


@pytest.mark.parametrize(("text", "pattern"), [c[1:] for c in SCENE_CASES],
                         ids=[c[0] for c in SCENE_CASES])
def test_bad_scene_is_one_located_error_line(tmp_path, capsys, text, pattern):
    path = tmp_path / "bad.scenario.yaml"
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    assert call(["validate", str(path)]) == 2
    message = one_error(capsys.readouterr().err)
    assert re.search(pattern.replace("{f}", re.escape(str(path))), message), message


@pytest.fixture
def places(tmp_path):
    """A good tiny scene, a folder, a plain file and a missing folder to point options at."""
    scene = tmp_path / "tiny.scenario.yaml"
    scene.write_text(TINY)
    folder = tmp_path / "folder"
    folder.mkdir()
    plain = tmp_path / "plain.txt"
    plain.write_text("x")
    (tmp_path / "junk.blf").write_text("not a BLF log")
    (tmp_path / "text.blf").write_text("not a BLF log, longer than its header\n" * 10)
    (tmp_path / "other.blf.rts.json").write_text("{}")
    # rts-scenario's own mapping without its CAN FD message.
    can = ROOT / "rts_scenario" / "data" / "can"
    (tmp_path / "rts_detections.dbc").write_text((can / "rts_detections.dbc").read_text())
    mapping = (can / "rts_detections.mapping.yaml").read_text()
    (tmp_path / "m.mapping.yaml").write_text(re.sub(r"\n *fd_message:.*", "", mapping))
    return {"scene": str(scene), "dir": str(folder), "file": str(plain),
            "missing": str(tmp_path / "missing" / "out.json"), "tmp": str(tmp_path)}


# (id, argv ({scene}, {dir}, {file}, {missing}, {tmp} filled in), exit code, message regex)
CLI_CASES: list[tuple[str, list[str], int, str]] = [
    ("run-json-folder", ["run", "{scene}", "--json", "{dir}"], 2,
     r"^--json {dir}: cannot write: is a folder"),
    # pathlib drops a trailing slash: the folder name was written as a file.
    ("run-json-trailing-slash", ["run", "{scene}", "--json", "{tmp}/r.json/"], 2,
     r"^--json {tmp}/r.json/: names a folder \(it ends in a slash\); give a file path"),
    ("sweep-json-trailing-slash", ["sweep", "{scene}", "--json", "{tmp}/s.json/"], 2,
     r"^--json {tmp}/s.json/: names a folder \(it ends in a slash\); give a file path"),
    ("schedule-file-trailing-slash", ["schedule", "{scene}", "--output", "file:{tmp}/s.csv/"],
     2, r"^--output file:{tmp}/s.csv/: names a folder \(it ends in a slash\); give a file "
        r"path"),
    ("survey-estimator-not-for-array", ["survey", "wide-3x5", "--radar", "cascade-12x16",
                                        "--estimator", "ti"], 2,
     r"^--estimator ti: 'ti' cannot estimate angles on the radar's array: array "
     r"'cascade-12x16': TI-style azimuth needs"),
    ("emulate-estimator-not-for-array", ["emulate", "--listen", "udp://127.0.0.1:0", "--rig",
                                         "wide-3x5", "--radar", "cascade-12x16",
                                         "--estimator", "ti"], 2,
     r"^--estimator ti: 'ti' cannot estimate angles on the radar's array"),
    ("run-json-under-file", ["run", "{scene}", "--json", "{file}/r.json"], 2,
     r"^--json {file}/r.json: cannot write: folder {file} is not a folder"),
    ("run-json-missing-folder", ["run", "{scene}", "--json", "{missing}"], 2,
     r"^--json {missing}: cannot write: folder .* does not exist"),
    ("run-plot-on-file", ["run", "{scene}", "--plot", "{file}"], 2,
     r"^--plot (needs matplotlib|{file}: cannot write: not a folder)"),
    # A .png name was made a folder of that name; a mistyped parent a tree of new folders.
    ("run-plot-png-name", ["run", "{scene}", "--plot", "{tmp}/plots.png"], 2,
     r"^--plot (needs matplotlib|{tmp}/plots.png: names a file \(.png\); --plot takes the "
     r"folder its .png files go into \(made if missing\))"),
    ("run-plot-missing-parent", ["run", "{scene}", "--plot", "{tmp}/no/such/plots"], 2,
     r"^--plot (needs matplotlib|{tmp}/no/such/plots: cannot write: folder {tmp}/no/such does "
     r"not exist)"),
    # A generated name too long for the file system (a variant's id with a long value) was a
    # runtime error, exit 3; a name too long given is refused up front, naming the option.
    ("run-json-name-too-long", ["run", "{scene}", "--json", "{tmp}/" + "j" * 300 + ".json"], 2,
     r"^--json {tmp}/j+.json: cannot write: File name too long$"),
    ("run-output-unknown", ["run", "{scene}", "--output", "carrier-pigeon"], 2,
     r"^--output 'carrier-pigeon': unknown output 'carrier-pigeon'; valid outputs: .*udp"),
    ("run-output-file", ["run", "{scene}", "--output", "file:{tmp}/x.npz"], 2,
     r"^--output file:{tmp}/x.npz: a file output only stores the schedule, .* no radar sees it "
     r".*; valid here: simulated-radar, udp://HOST:PORT"),
    ("run-output-udp-no-port", ["run", "{scene}", "--output", "udp://localhost"], 2,
     r"^--output udp://localhost: expected udp://HOST:PORT"),
    ("run-output-simulated-radar-argument", ["run", "{scene}", "--output", "simulated-radar:x"],
     2, r"^--output 'simulated-radar:x': simulated-radar takes no argument"),
    ("run-can-interface", ["run", "{scene}", "--can-interface", "carrier-pigeon"], 2,
     r"^--can-interface 'carrier-pigeon': unknown python-can interface; valid: .*virtual"),
    # udp_multicast's channel is the multicast group both processes join: without it (a
    # private channel name) python-can fails deep down with "Name or service not known".
    ("run-udp-multicast-no-channel", ["run", "{scene}", "--can-interface", "udp_multicast"], 2,
     r"^--can-interface udp_multicast needs --can-channel: a multicast group address both "
     r"processes join \(e\.g\. 239\.74\.163\.2, "),
    ("run-udp-multicast-name", ["run", "{scene}", "--can-interface", "udp_multicast",
                                "--can-channel", "can0"], 2,
     r"^--can-channel 'can0': udp_multicast needs a multicast group address"),
    ("emulate-udp-multicast-no-channel", ["emulate", "--listen", "udp://127.0.0.1:0", "--rig",
                                          "wide-3x5", "--radar", "awr1843boost",
                                          "--can-interface", "udp_multicast"], 2,
     r"^--can-interface udp_multicast needs --can-channel: a multicast group address"),
    ("survey-udp-multicast-unicast", ["survey", "kit-table1", "--can-interface",
                                      "udp_multicast", "--can-channel", "127.0.0.1"], 2,
     r"^--can-channel '127.0.0.1': udp_multicast needs a multicast group address"),
    ("run-mapping-missing", ["run", "{scene}", "--mapping", "{tmp}/none.mapping.yaml"], 2,
     r"^--mapping {tmp}/none.mapping.yaml: cannot read file"),
    ("run-missing-scene", ["run", "{tmp}/none.scenario.yaml"], 2,
     r"^{tmp}/none.scenario.yaml: cannot read file"),
    ("run-scene-is-folder", ["run", "{dir}"], 2, r"^{dir}: cannot read file"),
    ("run-method", ["run", "{scene}", "--method", "guess"], 2, r"argument --method"),
    ("run-no-scene", ["run"], 2, r"the following arguments are required: SCENE"),
    ("schedule-simulated-radar", ["schedule", "{scene}", "--output", "simulated-radar"], 2,
     r"^--output simulated-radar: the simulated radar needs a run"),
    ("schedule-file-empty", ["schedule", "{scene}", "--output", "file:"], 2,
     r"^--output 'file:': file needs a path: file:PATH \(.npz or .csv\)"),
    ("schedule-file-format", ["schedule", "{scene}", "--output", "file:{tmp}/s.txt"], 2,
     r"^--output file:{tmp}/s.txt: unknown file format '.txt'; valid: .npz, .csv"),
    ("schedule-file-folder", ["schedule", "{scene}", "--output", "file:{dir}/"], 2,
     r"^--output file:{dir}/: names a folder \(it ends in a slash\)"),
    ("schedule-file-missing-folder", ["schedule", "{scene}", "--output",
                                      "file:{tmp}/missing/s.npz"], 2,
     r"^--output {tmp}/missing/s.npz: cannot write: folder .* does not exist"),
    ("schedule-no-output", ["schedule", "{scene}"], 2, r"required: --output"),
    ("schedule-bad-scene", ["schedule", "{file}", "--output", "file:{tmp}/s.npz"], 2,
     r"^{file}:1:1: a scene must be a mapping of keys, got str"),
    ("calibrate-gain-nan", ["calibrate", "kit-table1", "--inject-gain-db", "nan"], 2,
     r"^--inject-gain-db: must be within 0..20, got nan"),
    ("calibrate-gain-negative", ["calibrate", "kit-table1", "--inject-gain-db", "-1"], 2,
     r"^--inject-gain-db: must be within 0..20, got -1"),
    ("calibrate-phase-negative", ["calibrate", "kit-table1", "--inject-phase-deg", "-5"], 2,
     r"^--inject-phase-deg: must be within 0..180, got -5"),
    ("calibrate-phase-inf", ["calibrate", "kit-table1", "--inject-phase-deg", "inf"], 2,
     r"^--inject-phase-deg: must be within 0..180, got inf"),
    # Options of the built-in simulated radar mean nothing for a radar on the bench.
    ("calibrate-fidelity-over-udp", ["calibrate", "kit-table1", "--output",
                                     "udp://127.0.0.1:45990", "--fidelity", "adc"], 2,
     r"^--fidelity: an option of the built-in simulated radar; with --output "
     r"udp://127.0.0.1:45990 the radar on the bench measures"),
    ("survey-noise-over-udp", ["survey", "kit-table1", "--output", "udp://127.0.0.1:45990",
                               "--noise"], 2,
     r"^--noise: an option of the built-in simulated radar; with --output "
     r"udp://127.0.0.1:45990"),
    ("calibrate-seed-negative", ["calibrate", "kit-table1", "--seed", "-1"], 2,
     r"^--seed: must be >= 0, got -1"),
    ("calibrate-write-folder", ["calibrate", "kit-table1", "--write", "{dir}"], 2,
     r"^--write {dir}: cannot write: is a folder"),
    ("calibrate-write-missing-folder", ["calibrate", "kit-table1", "--write",
                                        "{tmp}/missing/c.rig.yaml"], 2,
     r"^--write {tmp}/missing/c.rig.yaml: cannot write: folder .* does not exist"),
    ("calibrate-write-not-a-rig", ["calibrate", "kit-table1", "--write", "{tmp}/cal.txt"], 2,
     r"^--write {tmp}/cal.txt: a rig file's name ends in .rig.yaml"),
    ("calibrate-output-file", ["calibrate", "kit-table1", "--output", "file:{tmp}/x.npz"], 2,
     r"^--output file:{tmp}/x.npz: a file output only stores the schedule"),
    ("calibrate-json-is-write", ["calibrate", "kit-table1", "--json", "{tmp}/c.rig.yaml",
                                 "--write", "{tmp}/c.rig.yaml"], 2,
     r"^--json {tmp}/c.rig.yaml and --write {tmp}/c.rig.yaml: the same file"),
    ("calibrate-plot-file", ["calibrate", "kit-table1", "--plot", "{file}"], 2,
     r"^--plot (needs matplotlib|{file}: cannot write: not a folder)"),
    ("calibrate-unknown-rig", ["calibrate", "kit-table9"], 2,
     r"^RIG 'kit-table9': unknown preset and no such file; valid presets: .*kit-table1"),
    ("calibrate-rig-not-a-rig", ["calibrate", "{file}"], 2, r"^RIG {file}"),
    ("calibrate-unknown-radar", ["calibrate", "kit-table1", "--radar", "x"], 2,
     r"^--radar 'x': unknown preset and no such file; valid presets: .*paper"),
    ("calibrate-output", ["calibrate", "kit-table1", "--output", "nowhere"], 2,
     r"^--output 'nowhere': unknown output 'nowhere'"),
    ("calibrate-fidelity", ["calibrate", "kit-table1", "--fidelity", "best"], 2,
     r"argument --fidelity"),
    ("sweep-json-folder", ["sweep", "{scene}", "--json", "{dir}"], 2,
     r"^--json {dir}: cannot write: is a folder"),
    ("sweep-workers-zero", ["sweep", "{scene}", "--workers", "0"], 2,
     r"^--workers: must be >= 1, got 0"),
    ("sweep-workers-text", ["sweep", "{scene}", "--workers", "all"], 2, r"argument --workers"),
    ("sweep-plot-not-png", ["sweep", "{scene}", "--plot", "{tmp}/p.svg"], 2,
     r"^--plot (needs matplotlib|{tmp}/p.svg: must name a .png file)"),
    ("sweep-plot-folder", ["sweep", "{scene}", "--plot", "{dir}/x/p.png"], 2,
     r"^--plot (needs matplotlib|{dir}/x/p.png: cannot write)"),
    ("bench-json-folder", ["bench", "--targets", "10", "--scene-s", "0", "--json", "{dir}"], 2,
     r"^--json {dir}: cannot write: is a folder"),
    ("bench-json-under-file", ["bench", "--targets", "10", "--scene-s", "0", "--json",
                               "{file}/b.json"], 2, r"^--json {file}/b.json: cannot write"),
    ("check-log-missing", ["check", "{scene}", "--log", "{tmp}/none.blf"], 2,
     r"^--log {tmp}/none.blf: no such file"),
    ("check-log-format", ["check", "{scene}", "--log", "{file}"], 2,
     r"^--log {file}: unknown log format '.*'; valid: .asc, .blf"),
    ("check-log-not-a-log", ["check", "{scene}", "--log", "{tmp}/junk.blf"], 2,
     r"^--log {tmp}/junk.blf: cannot read: not a \.blf log as python-can reads one, or a "
     r"damaged one \(struct\.error: "),
    ("check-log-text", ["check", "{scene}", "--log", "{tmp}/text.blf"], 2,
     r"^--log {tmp}/text.blf: cannot read: not a \.blf log as python-can reads one, or a "
     r"damaged one \(can\.io\.blf\.BLFParseError: "),
    ("check-log-folder", ["check", "{scene}", "--log", "{dir}"], 2,
     r"^--log {dir}: a folder, not a log file \(\.asc, \.blf"),
    ("check-log-sidecar", ["check", "{scene}", "--log", "{tmp}/other.blf.rts.json"], 2,
     r"^--log {tmp}/other.blf.rts.json is the sidecar run --record wrote beside its log; give "
     r"the log: --log {tmp}/other.blf$"),
    ("check-offset-nan", ["check", "{scene}", "--log", "{tmp}/none.blf", "--time-offset-s",
                          "nan"], 2,
     r"^--time-offset-s: must be within -1e\+10\.\.1e\+10, got nan$"),
    ("check-offset-huge", ["check", "{scene}", "--log", "{tmp}/none.blf", "--time-offset-s",
                           "1e308"], 2, r"^--time-offset-s: must be within -1e\+10\.\.1e\+10, "
                                        r"got 1e\+308$"),
    ("check-without-log", ["check", "{scene}"], 2, r"--log"),
    # A negative number argparse did not take for one ("-inf", "-1e3") was "expected one
    # argument"; the option's own check refuses those it does not allow.
    ("check-offset-minus-inf", ["check", "{scene}", "--log", "{tmp}/none.blf",
                                "--time-offset-s", "-inf"], 2,
     r"^--time-offset-s: must be within -1e\+10\.\.1e\+10, got -inf$"),
    ("check-offset-minus-infinity", ["check", "{scene}", "--log", "{tmp}/none.blf",
                                     "--time-offset-s", "-Infinity"], 2,
     r"^--time-offset-s: must be within -1e\+10\.\.1e\+10, got -inf$"),
    ("check-offset-minus-nan", ["check", "{scene}", "--log", "{tmp}/none.blf",
                                "--time-offset-s", "-nan"], 2,
     r"^--time-offset-s: must be within -1e\+10\.\.1e\+10, got nan$"),
    ("check-offset-exponent", ["check", "{scene}", "--log", "{tmp}/none.blf",
                               "--time-offset-s", "-1e3"], 2,
     r"^--log {tmp}/none.blf: no such file"),
    ("check-offset-not-a-number", ["check", "{scene}", "--log", "{tmp}/none.blf",
                                   "--time-offset-s", "-x"], 2,
     r"argument --time-offset-s: expected one argument"),
    ("calibrate-gain-minus-exponent", ["calibrate", "kit-table1", "--inject-gain-db", "-1e3"],
     2, r"^--inject-gain-db: must be within 0..20, got -1000.0$"),
    ("calibrate-phase-minus-inf", ["calibrate", "kit-table1", "--inject-phase-deg", "-inf"],
     2, r"^--inject-phase-deg: must be within 0..180, got -inf$"),
    ("bench-scene-minus-exponent", ["bench", "--scene-s", "-2E+1"], 2,
     r"^--scene-s: must be within .*, got -20.0$"),
    ("listen-seconds-minus-inf", ["rts-listen", "udp://127.0.0.1:0", "--seconds", "-inf"], 2,
     r"^--seconds: must be within .*, got -inf$"),
    ("import-lane-minus-half", ["import", "{tmp}/none.xosc", "--radar", "paper", "--rig",
                                "kit-table1", "--output", "{tmp}/x.scenario.yaml",
                                "--lane-width-m", "-.5"], 2, r"--lane-width-m.*-0.5"),
    ("run-record-two-scenes", ["run", "{scene}", "{scene}", "--record", "{tmp}/r.blf"], 2,
     r"^--record: records the bus of one scene, got 2 scenes"),
    ("run-record-format", ["run", "{scene}", "--record", "{tmp}/r.txtx"], 2,
     r"^--record {tmp}/r.txtx: unknown log format '.txtx'; valid"),
    ("run-record-folder", ["run", "{scene}", "--record", "{dir}/x/r.blf"], 2,
     r"^--record {dir}/x/r.blf: cannot write"),
    ("survey-place-without-write", ["survey", "kit-table1", "--place"], 2,
     r"^--place: needs --write RIG_OUT"),
    ("survey-write-not-a-rig", ["survey", "kit-table1", "--write", "{scene}"], 2,
     r"^--write {scene}: a rig file's name ends in .rig.yaml"),
    ("survey-output-file", ["survey", "kit-table1", "--output", "file:{tmp}/x.npz"], 2,
     r"^--output file:{tmp}/x.npz: a file output only stores the schedule"),
    ("survey-json-is-write", ["survey", "kit-table1", "--json", "{tmp}/s.rig.yaml", "--write",
                              "{tmp}/s.rig.yaml"], 2,
     r"^--json {tmp}/s.rig.yaml and --write {tmp}/s.rig.yaml: the same file"),
    ("run-detections-is-scene", ["run", "{scene}", "--detections", "{scene}"], 2,
     r"^--detections {scene}: the same file as SCENE {scene}, which this command reads; "
     r"writing it would destroy the input"),
    ("run-json-is-scene", ["run", "{scene}", "--json", "{tmp}/./tiny.scenario.yaml"], 2,
     r"^--json {tmp}/./tiny.scenario.yaml: the same file as SCENE {scene}"),
    ("run-json-is-detections", ["run", "{scene}", "--json", "{tmp}/x", "--detections",
                                "{tmp}/x"], 2,
     r"^--json {tmp}/x and --detections {tmp}/x: the same file; one would overwrite the other"),
    ("run-json-is-record", ["run", "{scene}", "--record", "{tmp}/x.csv", "--json",
                            "{tmp}/x.csv"], 2, r"^--json {tmp}/x.csv and --record {tmp}/x.csv"),
    # An option given twice: argparse kept the last, and the first report was never written.
    ("run-json-twice", ["run", "{scene}", "--json", "{tmp}/a.json", "--json", "{tmp}/b.json"],
     2, r"^argument --json: given twice \('{tmp}/a.json', then '{tmp}/b.json'\); give it once$"),
    ("check-mapping-twice", ["check", "{scene}", "--log", "{tmp}/x.blf", "--mapping", "a",
                             "--mapping", "b"], 2,
     r"^argument --mapping: given twice \('a', then 'b'\); give it once$"),
    ("run-json-is-record-sidecar", ["run", "{scene}", "--record", "{tmp}/x.blf", "--json",
                                    "{tmp}/x.blf.rts.json"], 2,
     r"^--json {tmp}/x.blf.rts.json and --record's sidecar {tmp}/x.blf.rts.json"),
    ("run-json-named-like-a-scene", ["run", "{scene}", "--json", "{tmp}/other.scenario.yaml"],
     2, r"^--json {tmp}/other.scenario.yaml: named like a scene \(.scenario.yaml\), which "
        r"--json would overwrite"),
    ("run-detections-named-like-a-dbc", ["run", "{scene}", "--detections", "{tmp}/radar.DBC"],
     2, r"^--detections {tmp}/radar.DBC: named like a DBC file \(.dbc\)"),
    ("run-json-named-like-a-can-database", ["run", "{scene}", "--json", "{tmp}/radar.arxml"],
     2, r"^--json {tmp}/radar.arxml: named like an AUTOSAR CAN database \(.arxml\), which "
        r"--json would overwrite"),
    ("run-json-is-mapping", ["run", "{scene}", "--mapping", "{tmp}/m.mapping.yaml", "--json",
                             "{tmp}/m.mapping.yaml"], 2,
     r"^--json {tmp}/m.mapping.yaml: the same file as --mapping {tmp}/m.mapping.yaml"),
    ("run-can-fd-without-fd-message", ["run", "{scene}", "--can-fd", "--mapping",
                                       "{tmp}/m.mapping.yaml"], 2,
     r"^--can-fd: the mapping {tmp}/m.mapping.yaml has no fd_message"),
    ("emulate-can-fd-without-fd-message", ["emulate", "--listen", "udp://127.0.0.1:0", "--rig",
                                           "kit-table1", "--radar", "paper", "--can-fd",
                                           "--mapping", "{tmp}/m.mapping.yaml"], 2,
     r"^--can-fd: the mapping {tmp}/m.mapping.yaml has no fd_message"),
    ("check-json-is-log", ["check", "{scene}", "--log", "{tmp}/junk.blf", "--json",
                           "{tmp}/junk.blf"], 2,
     r"^--json {tmp}/junk.blf: the same file as --log {tmp}/junk.blf"),
    ("check-json-is-scene", ["check", "{scene}", "--log", "{tmp}/junk.blf", "--json",
                             "{scene}"], 2, r"^--json {scene}: the same file as SCENE {scene}"),
    ("sweep-json-is-scene-in-folder", ["sweep", "{tmp}", "--json", "{scene}"], 2,
     r"^--json {scene}: the same file as SCENE {scene}"),
    ("schedule-output-is-scene", ["schedule", "{tmp}/s.csv", "--output", "file:{tmp}/s.csv"], 2,
     r"^--output {tmp}/s.csv: the same file as SCENE {tmp}/s.csv"),
    ("survey-estimator", ["survey", "kit-table1", "--estimator", "music"], 2,
     r"^--estimator: unknown estimator 'music'; valid: bartlett, ti"),
    ("calibrate-estimator", ["calibrate", "kit-table1", "--estimator", "music"], 2,
     r"^--estimator: unknown estimator 'music'; valid: bartlett, ti"),
    ("bench-targets-zero", ["bench", "--targets", "0"], 2,
     r"^--targets: must be within 1..10000000, got 0"),
    ("bench-targets-huge", ["bench", "--targets", "100000000000"], 2,
     r"^--targets: must be within 1..10000000"),
    ("bench-repeats", ["bench", "--repeats", "0"], 2, r"^--repeats: must be within 1..100"),
    ("bench-scene-nan", ["bench", "--scene-s", "nan"], 2, r"^--scene-s: must be within 0..86400"),
    ("bench-scene-negative", ["bench", "--scene-s", "-3"], 2, r"^--scene-s: must be within"),
    ("bench-rig", ["bench", "--rig", "nope"], 2, r"^unknown rig preset 'nope'; valid presets"),
    ("bench-targets-text", ["bench", "--targets", "many"], 2, r"argument --targets"),
    ("listen-scheme", ["rts-listen", "tcp://127.0.0.1:5005"], 2,
     r"^ADDRESS 'tcp://127.0.0.1:5005': expected udp://HOST:PORT"),
    ("listen-port", ["rts-listen", "udp://127.0.0.1:70000"], 2,
     r"^ADDRESS 'udp://127.0.0.1:70000': expected udp://HOST:PORT with a port 0..65535"),
    ("emulate-listen-no-port", ["emulate", "--listen", "udp://", "--rig", "kit-table1",
                                "--radar", "paper"], 2,
     r"^--listen 'udp://': expected udp://HOST:PORT with a port 0..65535"),
    ("run-output-udp-no-address", ["run", "{scene}", "--output", "udp://"], 2,
     r"^--output udp://: expected udp://HOST:PORT with a port 1..65535"),
    ("schedule-output-udp-no-address", ["schedule", "{scene}", "--output", "udp:"], 2,
     r"^--output udp://: expected udp://HOST:PORT with a port 1..65535"),
    ("survey-output-udp-no-address", ["survey", "kit-table1", "--output", "udp://"], 2,
     r"^--output udp://: expected udp://HOST:PORT with a port 1..65535"),
    ("run-output-udp-port-not-ascii", ["run", "{scene}", "--output", "udp://127.0.0.1:\u00b2"],
     2, r"^--output udp://127.0.0.1:\u00b2: expected udp://HOST:PORT with a port 1..65535"),
    ("run-output-udp-unknown-host", ["run", "{scene}", "--output",
                                     "udp://no.such.host.invalid:5005"], 2,
     r"^--output udp://no.such.host.invalid:5005: unknown host"),
    ("schedule-output-udp-unknown-host", ["schedule", "{scene}", "--output",
                                          "udp://no.such.host.invalid:5005"], 2,
     r"^--output udp://no.such.host.invalid:5005: unknown host"),
    ("emulate-listen-port-not-ascii", ["emulate", "--listen", "udp://127.0.0.1:\u00b2", "--rig",
                                       "kit-table1", "--radar", "paper"], 2,
     r"^--listen 'udp://127.0.0.1:\u00b2': expected udp://HOST:PORT with a port 0..65535"),
    ("listen-count", ["rts-listen", "udp://127.0.0.1:0", "--count", "0"], 2,
     r"^--count: must be >= 1, got 0"),
    ("listen-seconds", ["rts-listen", "udp://127.0.0.1:0", "--seconds", "nan"], 2,
     r"^--seconds: must be within"),
    ("listen-host", ["rts-listen", "udp://no.such.host.invalid:5005", "--seconds", "0.1"], 2,
     r"^udp://no.such.host.invalid:5005: cannot listen"),
    ("validate-missing", ["validate", "{tmp}/none.scenario.yaml"], 2,
     r"^{tmp}/none.scenario.yaml: cannot read file"),
    ("validate-dev-zero", ["validate", "/dev/zero"], 2,
     r"^/dev/zero: document larger than the limit of 4 MB"),
    ("unknown-command", ["fly"], 2, r"invalid choice: 'fly'"),
    # An empty value (an unset shell variable) was taken as no option: the run passed and
    # wrote no report; `sweep ""` swept the current folder.
    ("run-json-empty", ["run", "{scene}", "--json", ""], 2,
     r"argument --json: an empty value"),
    ("run-detections-empty", ["run", "{scene}", "--detections", ""], 2,
     r"argument --detections: an empty value"),
    ("run-record-empty", ["run", "{scene}", "--record", ""], 2,
     r"argument --record: an empty value"),
    ("sweep-scene-empty", ["sweep", ""], 2, r"argument SCENE: an empty value"),
    ("check-json-empty", ["check", "{scene}", "--log", "{tmp}/junk.blf", "--json", ""], 2,
     r"argument --json: an empty value"),
]


@pytest.mark.parametrize(("argv", "code", "pattern"), [c[1:] for c in CLI_CASES],
                         ids=[c[0] for c in CLI_CASES])
def test_bad_arguments_are_one_error_line(places, capsys, argv, code, pattern):
    argv = [a.format(**places) for a in argv]
    assert call(argv) == code
    out, err = capsys.readouterr()
    message = one_error(err)
    expected = pattern
    for key, value in places.items():
        expected = expected.replace("{" + key + "}", re.escape(value))
    assert re.search(expected, message), message
    assert "timing:" not in out  # checked before anything ran


@pytest.mark.parametrize("argv", [["run", "{scene}", "--json", "-"],
                                  ["run", "{scene}", "--detections", "-"],
                                  ["sweep", "{scene}", "--json", "-"]],
                         ids=["run-json", "run-detections", "sweep-json"])
def test_a_dash_for_an_output_file_is_refused_not_written_as_a_file(places, capsys, monkeypatch,
                                                                     tmp_path, argv):
    # "-" reads as standard output, where the text report goes: not a file named "-".
    monkeypatch.chdir(tmp_path)
    argv = [a.format(**places) for a in argv]
    assert call(argv) == 2
    out, err = capsys.readouterr()
    assert one_error(err) == (f"{argv[2]} -: a file path, not standard output (which carries "
                              f"the text report); to name a file '-', write ./-")
    assert "timing:" not in out and not (tmp_path / "-").exists()


def test_catalogue_is_complete():
    assert len(SCENE_CASES) + len(CLI_CASES) >= 50


def test_alias_bomb_fails_fast_in_little_memory(tmp_path):
    path = tmp_path / "bomb.scenario.yaml"
    path.write_text(alias_bomb())
    assert 1500 < path.stat().st_size < 2500
    code = textwrap.dedent(f"""
        import resource, time
        from rts_scenario.errors import ScenarioError
        from rts_scenario.scenario import load_scenario
        start = time.perf_counter()
        try:
            load_scenario({str(path)!r})
        except ScenarioError as exc:
            message = str(exc)
        print(time.perf_counter() - start)
        # Peak RSS of this process: VmHWM resets at exec (ru_maxrss may carry the peak of
        # the parent that forked it).
        try:
            with open("/proc/self/status") as status:
                print(next(line.split()[1] for line in status if line.startswith("VmHWM")))
        except OSError:
            print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
        print(message)
    """)
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True, env={**os.environ, "PYTHONPATH": os.pathsep.join(
                                [str(ROOT), os.environ.get("PYTHONPATH", "")])})
    seconds, max_rss_kb, message = result.stdout.strip().split("\n")
    assert float(seconds) < 1.0
    assert int(max_rss_kb) < 200 * 1024  # the whole interpreter, libraries included
    assert re.match(re.escape(str(path)) + r":\d+:\d+: document expands", message)


def test_validate_builds_every_combination_and_strict_turns_warnings_into_errors(tmp_path,
                                                                                capsys):
    path = tmp_path / "edge.scenario.yaml"
    # A second target far to the side: out of the rig's coverage in every frame.
    path.write_text(TINY + "  - name: aside\n"
                    "    motion: {type: stationary, position_m: [30, 40, 0.6]}\n"
                    "    rcs: {rcs_dbsm: 10.0}\n"
                    "parametrize: {radar.estimator: [bartlett, ti]}\n")
    assert call(["validate", str(path)]) == 0
    out, err = capsys.readouterr()
    assert "ok: " not in out and "[estimator=ti]" in out
    # Valid, and a run of it fails: its status line says so, not "ok".
    assert out.count("valid, a run fails: ") == 2, out
    assert out.count(", 2 targets, schedule built; the 1 warning says why "
                     "(--strict: errors)\n") == 2, out
    warnings = [line for line in err.splitlines() if line.startswith("warning: ")]
    assert len(warnings) == 2 and all(": aside: out_of_coverage in 5 frames" in w
                                      for w in warnings)
    assert "car" not in err
    assert call(["validate", "--strict", str(path)]) == 2
    out, err = capsys.readouterr()
    assert "ok: " not in out and "valid, a run fails" not in out
    assert [line.split(": ", 1)[0] for line in err.splitlines()] == ["error", "error"]
    # A limit the scene declares is shown, and is no error even with --strict.
    path.write_text(path.read_text().replace("    rcs: {rcs_dbsm: 10.0}\nparametrize",
                                             "    rcs: {rcs_dbsm: 10.0}\n"
                                             "    expected_limits: [out_of_coverage, "
                                             "beyond_radar_velocity]\n"
                                             "parametrize"))
    assert call(["validate", "--strict", str(path)]) == 0
    out, err = capsys.readouterr()
    assert out.count("ok: ") == 2 and out.count(", 2 targets, schedule built\n") == 2, out
    assert out.count("aside: out_of_coverage in 5 frames, beyond_radar_velocity in 1 frames "
                     "(expected)") == 2
    assert err == ""


def test_validate_accepts_exactly_what_run_accepts(tmp_path, capsys):
    fast = tmp_path / "fast.scenario.yaml"
    fast.write_text(sub("frame_rate_hz: 10.0", "frame_rate_hz: 400"))
    assert call(["validate", str(fast)]) == 2
    validate_message = one_error(capsys.readouterr().err)
    assert call(["run", str(fast)]) == 2
    assert one_error(capsys.readouterr().err) == validate_message


def write_scene(folder: Path, file: str, name: str, extra: str = "") -> str:
    path = folder / file
    path.write_text(sub("name: tiny", f"name: {name!r}") + extra)
    return str(path)


def test_batch_runs_every_scene_and_reports_each(tmp_path, capsys):
    good = write_scene(tmp_path, "a.scenario.yaml", "alpha")
    broken = tmp_path / "b.scenario.yaml"
    broken.write_text(TINY + "colour: red\n")
    failing = write_scene(tmp_path, "c.scenario.yaml", "gamma",
                          "expectations: {tolerances: {az_deg: 0.000001}}\n")
    report = tmp_path / "report.json"
    code = call(["run", good, str(broken), failing, "--json", str(report)])
    out, err = capsys.readouterr()
    assert code == 2  # a scene that does not load is bad input
    assert one_error(err).startswith(f"{broken}:15:1: colour: unknown key")
    entries = json.loads(report.read_text())
    assert [(e["scene"], e["file"], e["status"]) for e in entries] == [
        ("alpha", good, "pass"), ("b", str(broken), "error"), ("gamma", failing, "fail")]
    assert entries[1]["error"].startswith(f"{broken}:15:1: colour: unknown key")
    assert entries[0]["passed"] is True and "errors" in entries[0]
    summary = out.strip().splitlines()[-4:-1]
    assert summary == [f"PASS alpha ({good})",
                       f"ERROR b ({broken}): {entries[1]['error']}",
                       f"FAIL gamma ({failing})"]
    assert call(["run", good, failing]) == 1
    capsys.readouterr()


def test_runtime_error_does_not_stop_the_batch(tmp_path, capsys, monkeypatch):
    import rts_scenario.pipeline as pipeline

    first = write_scene(tmp_path, "a.scenario.yaml", "alpha")
    second = write_scene(tmp_path, "b.scenario.yaml", "beta")
    real = pipeline.run_scene

    def flaky(scene, *args, **kwargs):
        if scene.name == "alpha":
            raise RuntimeError("the bench caught fire")
        return real(scene, *args, **kwargs)

    monkeypatch.setattr(pipeline, "run_scene", flaky)
    report = tmp_path / "r.json"
    assert call(["run", first, second, "--json", str(report)]) == 3
    out, err = capsys.readouterr()
    assert "RuntimeError: the bench caught fire" in one_error(err)
    assert [e["status"] for e in json.loads(report.read_text())] == ["error", "pass"]
    assert f"PASS beta ({second})" in out
    # --debug adds the traceback; the batch goes on and the exit code stays the same.
    for argv in (["--debug", "run", first, second], ["run", first, second, "--debug"]):
        assert call(argv) == 3
        out, err = capsys.readouterr()
        assert "Traceback (most recent call last)" in err
        errors = [line for line in err.splitlines() if line.startswith("error: ")]
        assert len(errors) == 1 and "RuntimeError: the bench caught fire" in errors[0], err
        assert f"PASS beta ({second})" in out


def test_plot_file_names_are_safe_and_unique():
    from rts_scenario.cli.run import _unique
    from rts_scenario.plots import safe_stem

    assert safe_stem("../../etc/passwd") == "_.._etc_passwd"
    assert safe_stem("...hidden") == "hidden"
    assert safe_stem("cut in: A/B") == "cut_in_A_B"
    assert safe_stem("///") == "_" and safe_stem("..") == "scene"
    # A long name is cut to MAX_STEM characters with a digest of the whole: two that differ
    # only past the cut stay apart, and a file name holds the stem with room to spare.
    from rts_scenario.plots import MAX_STEM

    long_a, long_b = "v" * 300 + "a", "v" * 300 + "b"
    assert len(safe_stem(long_a)) == MAX_STEM <= 150
    assert safe_stem(long_a) != safe_stem(long_b)
    assert safe_stem(long_a).startswith("v" * 100) and safe_stem("v" * MAX_STEM) == "v" * MAX_STEM
    taken: set[str] = set()
    assert [_unique(s, taken) for s in ("a", "a", "b", "a")] == ["a", "a-2", "b", "a-3"]


def test_version_and_list(capsys, monkeypatch):
    with pytest.raises(SystemExit) as exc:
        cli.main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == "rts-scenario 0.1.0"
    monkeypatch.chdir(ROOT)
    assert call(["list"]) == 0
    out = capsys.readouterr().out
    for name in ("scenarios/cut_in.scenario.yaml", "kit-table1", "wide-3x5", "awr1843boost",
                 "paper"):
        assert name in out


def test_rts_listen_prints_each_applied_frame(tmp_path, capsys):
    import socket
    import threading
    import time

    from rts_scenario.kinematics import compute_tracks
    from rts_scenario.outputs import open_output
    from rts_scenario.scenario import load_scenario
    from rts_scenario.schedule import build_schedule

    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    codes: list[int] = []
    listener = threading.Thread(target=lambda: codes.append(cli.main(
        ["rts-listen", f"udp://127.0.0.1:{port}", "--count", "3", "--seconds", "10"])))
    listener.start()
    path = tmp_path / "tiny.scenario.yaml"
    path.write_text(TINY)
    scene = load_scenario(path)
    schedule = build_schedule(compute_tracks(scene), scene.rig, scene.radar)
    deadline = time.monotonic() + 10
    while listener.is_alive() and time.monotonic() < deadline:
        with open_output(f"udp://127.0.0.1:{port}", pacing="fast") as out:
            out.write(schedule)
        listener.join(0.3)
    listener.join(5)
    assert codes == [0]
    lines = capsys.readouterr().out.splitlines()
    frames = [line for line in lines if line.startswith("frame ")]
    assert len(frames) == 3
    parsed = [re.fullmatch(r"frame (\d+) t ([\d.]+) s: (\d+) entries, (\d+) active", f)
              for f in frames]
    assert all(parsed), frames
    # Consecutive frames of one stream, at their times (the listener may have bound its
    # socket part way through the first stream sent).
    numbers = [int(m[1]) for m in parsed if m]
    assert numbers == list(range(numbers[0], numbers[0] + 3)), frames
    assert [m[2] for m in parsed if m] == [f"{schedule.t_s[n]:.3f}" for n in numbers]


# A pool of good and bad values per option; the CLI may exit 0..3, never raise.
_SCENE_ARGS = ["{scene}", "{file}", "{dir}", "{tmp}/none.scenario.yaml", "", "-"]
_OPTIONS = {
    "validate": [[], ["--strict"], ["--method", "paper"], ["--method", "x"]],
    "schedule": [["--output", "file:{tmp}/s.npz"], ["--output", "file:{tmp}/s.csv"],
                 ["--output", "file:"], ["--output", "simulated-radar"], ["--output", "x:y"],
                 ["--output", "file:{dir}"], ["--method", "paper", "--output", "udp://h"]],
    "list": [[], ["--debug"]],
    "list-outputs": [[], ["extra"]],
    "bench": [["--targets", "5", "--repeats", "1", "--scene-s", "0"],
              ["--targets", "5", "--scene-s", "nan"], ["--targets", "-1"],
              ["--targets", "5", "--scene-s", "0", "--json", "{dir}"],
              ["--targets", "5", "--scene-s", "0", "--rig", "wide-3x5"],
              ["--targets", "5", "--scene-s", "0", "--rig", "{file}"]],
    "run": [[], ["--json", "{tmp}/r.json"], ["--json", "{dir}"], ["--plot", "{file}"],
            ["--output", "file:"], ["--method", "paper"], ["--can-interface", "x"],
            ["--mapping", "{file}"]],
}


@settings(max_examples=40, deadline=None, suppress_health_check=[
    HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(data=st.data())
def test_random_command_lines_never_raise(places, capsys, data):
    command = data.draw(st.sampled_from(sorted(_OPTIONS)))
    argv = [command]
    if command in ("validate", "schedule", "run"):
        argv.append(data.draw(st.sampled_from(_SCENE_ARGS)))
        if command == "run":
            # Only the tiny scene runs; everything else fails before a run.
            argv[-1] = data.draw(st.sampled_from(["{scene}", "{file}", "{dir}"]))
    if command == "bench":  # a small bench; the options below may override these
        argv += ["--targets", "5", "--repeats", "1", "--scene-s", "0", "--no-honest",
                 "--no-performance"]
    for _ in range(data.draw(st.integers(0, 2))):
        argv += data.draw(st.sampled_from(_OPTIONS[command]))
    argv = [a.format(**places) for a in argv]
    code = call(argv)
    assert code in (0, 1, 2, 3)
    err = capsys.readouterr().err
    assert "Traceback" not in err
    if code == 2:
        assert one_error(err)


@pytest.mark.parametrize(("argv", "code", "pattern"), [
    (["run", "{scene}", "--output", "bogus"], 2, r"^--output 'bogus': unknown output"),
    (["run", "{tmp}/none.scenario.yaml"], 2, r"^{tmp}/none.scenario.yaml: cannot read file"),
    (["check", "{scene}", "--log", "{tmp}/none.blf"], 2, r"^--log {tmp}/none.blf: no such file"),
    (["validate", "{tmp}/none.scenario.yaml"], 2, r"^{tmp}/none.scenario.yaml: cannot read file"),
], ids=["run-output", "run-missing-scene", "check-missing-log", "validate-missing-scene"])
@pytest.mark.parametrize("where", ["before", "after"])
def test_debug_adds_the_traceback_and_keeps_the_exit_code(places, capsys, argv, code, pattern,
                                                          where):
    argv = [a.format(**places) for a in argv]
    argv = ["--debug", *argv] if where == "before" else [argv[0], "--debug", *argv[1:]]
    assert call(argv) == code
    err = capsys.readouterr().err
    assert "Traceback (most recent call last)" in err
    errors = [line for line in err.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1, err
    expected = pattern
    for key, value in places.items():
        expected = expected.replace("{" + key + "}", re.escape(value))
    assert re.search(expected, errors[0].removeprefix("error: ")), errors[0]


def test_an_output_that_clashes_leaves_every_file_as_it_was(tmp_path, capsys):
    scene = Path(write_scene(tmp_path, "v.scenario.yaml", "victim"))
    text = scene.read_text()
    report = tmp_path / "r.json"
    report.write_text("{}")
    for extra in (["--detections", str(scene)], ["--json", str(scene)],
                  ["--json", str(report), "--detections", str(report)],
                  ["--record", str(report), "--json", str(report)]):
        assert call(["run", str(scene), *extra]) == 2
        assert "the same file" in one_error(capsys.readouterr().err)
        assert scene.read_text() == text and report.read_text() == "{}"
    link = tmp_path / "link.scenario.yaml"
    link.symlink_to(scene)
    assert call(["run", str(scene), "--json", str(link)]) == 2
    assert f"the same file as SCENE {scene}" in one_error(capsys.readouterr().err)
    assert scene.read_text() == text


# Outputs replaced whole, through a draft beside them: (id, argv, the option and file the
# error names).
DRAFTED_CASES = [
    ("run-json", ["run", "{scene}", "--json", "{tmp}/out.json"], "--json {tmp}/out.json"),
    ("run-record", ["run", "{scene}", "--record", "{tmp}/r.blf"], "--record {tmp}/r.blf.rts.json"),
    ("run-plot", ["run", "{scene}", "--plot", "{dir}"], "--plot {dir}"),
    ("sweep-json", ["sweep", "{scene}", "--json", "{tmp}/out.json"], "--json {tmp}/out.json"),
    ("sweep-plot", ["sweep", "{scene}", "--plot", "{tmp}/out.png"], "--plot {tmp}/out.png"),
    ("check-json", ["check", "{scene}", "--log", "{tmp}/junk.blf", "--json", "{tmp}/out.json"],
     "--json {tmp}/out.json"),
    ("survey-json", ["survey", "kit-table1", "--json", "{tmp}/out.json"],
     "--json {tmp}/out.json"),
    ("survey-write", ["survey", "kit-table1", "--write", "{tmp}/out.rig.yaml"],
     "--write {tmp}/out.rig.yaml"),
    ("calibrate-json", ["calibrate", "kit-table1", "--json", "{tmp}/out.json"],
     "--json {tmp}/out.json"),
    ("calibrate-write", ["calibrate", "kit-table1", "--write", "{tmp}/out.rig.yaml"],
     "--write {tmp}/out.rig.yaml"),
    ("calibrate-plot", ["calibrate", "kit-table1", "--plot", "{dir}"], "--plot {dir}"),
    ("bench-json", ["bench", "--targets", "10", "--scene-s", "0", "--json", "{tmp}/out.json"],
     "--json {tmp}/out.json"),
]


@pytest.mark.parametrize(("argv", "named"), [c[1:] for c in DRAFTED_CASES],
                         ids=[c[0] for c in DRAFTED_CASES])
def test_a_folder_that_takes_no_draft_stops_the_command_before_it_runs(places, capsys,
                                                                       monkeypatch, argv, named):
    # A read-only folder holding a writable file: the file opens for appending, but the draft
    # that replaces it cannot be made. Found after the run, its result was lost. (Tests run as
    # root, whom permissions do not stop: the draft's creation is made to fail as they would.)
    import rts_scenario.atomic
    import rts_scenario.pipeline

    if "--plot" in argv:
        pytest.importorskip("matplotlib")
    for name in ("out.json", "out.png", "out.rig.yaml", "r.blf", "r.blf.rts.json"):
        Path(places["tmp"], name).write_text("previous\n")

    def refused(target, mode, *args):
        raise PermissionError(13, "Permission denied")

    def ran(*args, **kwargs):
        raise AssertionError("the command ran")

    monkeypatch.setattr(rts_scenario.atomic, "_open_draft", refused)
    monkeypatch.setattr(rts_scenario.pipeline.Pipeline, "__init__", ran)
    assert call([a.format(**places) for a in argv]) == 2
    out, err = capsys.readouterr()
    assert one_error(err) == f"{named.format(**places)}: cannot write: Permission denied"
    assert out == ""
    for name in ("out.json", "out.png", "out.rig.yaml", "r.blf", "r.blf.rts.json"):
        assert Path(places["tmp"], name).read_text() == "previous\n"


def test_detections_written_as_they_come_need_no_draft(places, capsys, monkeypatch):
    # --detections is written in place, row by row: a folder that takes no new file but holds
    # a writable one is no reason to refuse it.
    import rts_scenario.atomic

    def refused(target, mode, *args):
        raise PermissionError(13, "Permission denied")

    detections = Path(places["tmp"], "d.csv")
    detections.write_text("previous\n")
    monkeypatch.setattr(rts_scenario.atomic, "_open_draft", refused)
    assert call(["run", places["scene"], "--detections", str(detections)]) == 0
    assert detections.read_text().startswith("scene,cycle,t_s,")


JIT_MESSAGE = (r"^RTS_SCENARIO_JIT='onn': unknown value; allowed: auto, on, off \(also 1/0, "
               r"yes/no, true/false; unset or empty is auto\)$")


@pytest.mark.parametrize("argv", [["run", "{scene}", "--json", "{tmp}/out.json"],
                                  ["sweep", "{scene}"], ["validate", "{scene}"],
                                  ["list"]])
def test_an_unknown_jit_setting_is_refused_before_anything_runs(places, capsys, monkeypatch,
                                                                argv):
    """A typo in RTS_SCENARIO_JIT was taken as "auto" without a word."""
    monkeypatch.setenv("RTS_SCENARIO_JIT", "onn")
    assert call([a.format(**places) for a in argv]) == 2
    out, err = capsys.readouterr()
    assert re.search(JIT_MESSAGE, one_error(err)), err
    assert out == ""
    # `run --json` says that nothing ran (an earlier run's report is not left to be read).
    report = Path(places["tmp"], "out.json")
    if "--json" in argv:
        assert json.loads(report.read_text())["error"].startswith("not run: RTS_SCENARIO_JIT")
    else:
        assert not report.exists()


CACHE_ALLOWED = "allowed: an existing folder, or off (or empty) for no disk cache"


@pytest.mark.parametrize(("value", "why"), [
    ("~no-such-user-here/plans", "Could not determine home directory"),
    ("{tmp}/a-file", "not a folder"), (os.devnull, "not a folder"),
    ("{tmp}/nope/deeper", "no such folder"), ("{tmp}/a-file/cache", "no such folder")])
@pytest.mark.parametrize("command", ["run", "validate"])
def test_a_cache_folder_setting_that_names_no_folder_is_refused_before_anything_runs(
        places, capsys, monkeypatch, value, why, command):
    """A ~user that does not exist was a runtime error per scene without the variable named;
    a file or a device was ignored without a word, every plan rebuilt; a mistyped path was
    made, with every folder above it that was not there."""
    Path(places["tmp"], "a-file").write_text("not a folder")
    value = value.format(**places)
    monkeypatch.setenv("RTS_SCENARIO_CACHE_DIR", value)
    assert call([command, places["scene"]]) == 2
    out, err = capsys.readouterr()
    assert one_error(err).startswith(f"RTS_SCENARIO_CACHE_DIR={value!r}: {why}")
    assert one_error(err).endswith(CACHE_ALLOWED)
    assert out == ""
    assert not Path(places["tmp"], "nope").exists()


def test_a_cache_folder_that_is_not_there_is_an_error_in_library_use(monkeypatch, tmp_path):
    """The solver refuses it as the command does, and makes no folder."""
    import numpy as np

    import rts_scenario as rs
    from rts_scenario.solver.plan import clear_memory_cache

    missing = tmp_path / "nope" / "deeper"
    monkeypatch.setenv("RTS_SCENARIO_CACHE_DIR", str(missing))
    clear_memory_cache()
    with pytest.raises(rs.SettingError, match=re.escape(
            f"RTS_SCENARIO_CACHE_DIR={str(missing)!r}: no such folder; {CACHE_ALLOWED}")):
        rs.solve_weights(np.array([0.0]), np.array([0.0]), rig=rs.Rig.preset("wide-3x5"),
                         array=rs.VirtualArray.preset("awr1843boost"))
    assert not (tmp_path / "nope").exists()


@pytest.mark.parametrize("value", ["OFF", " Off "])
def test_the_cache_folder_setting_off_in_any_case(monkeypatch, tmp_path, value):
    """"OFF" made a folder called OFF in the current folder."""
    from rts_scenario.solver import plan_cache_dir

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("RTS_SCENARIO_CACHE_DIR", value)
    assert plan_cache_dir() is None


@pytest.mark.parametrize(("value", "expected"), [
    ("", "auto"), ("auto", "auto"), (" ON ", "on"), ("1", "on"), ("yes", "on"), ("true", "on"),
    ("off", "off"), ("0", "off"), ("No", "off"), ("false", "off")])
def test_the_known_jit_settings(monkeypatch, value, expected):
    from rts_scenario.solver import compiled

    monkeypatch.setenv("RTS_SCENARIO_JIT", value)
    assert compiled.mode() == expected


def test_an_unknown_jit_setting_is_an_error_in_library_use(monkeypatch):
    """The solver and the quantization search ask the same setting: both refuse a typo."""
    import numpy as np

    import rts_scenario as rs
    from rts_scenario.errors import RtsError
    from rts_scenario.schedule import quantization
    from rts_scenario.solver import compiled

    monkeypatch.setenv("RTS_SCENARIO_JIT", "onn")
    with pytest.raises(RtsError, match=JIT_MESSAGE):
        compiled.mode()
    rig = rs.Rig.preset("wide-3x5")
    with pytest.raises(ValueError, match=JIT_MESSAGE):
        rs.solve_weights(np.array([0.0]), np.array([0.0]), rig=rig,
                         array=rs.VirtualArray.preset("awr1843boost"))
    with pytest.raises(RtsError, match=JIT_MESSAGE):
        quantization._compile(1)


RIG_FILE = str(ROOT / "scenarios" / "rigs" / "lab-2x3.rig.yaml")
DBC_FILE = str(ROOT / "scenarios" / "can" / "cluster_list.dbc")
XOSC_FILE = str(ROOT / "tests" / "data" / "xosc" / "cut_in.xosc")
FRAGMENT_FILE = str(ROOT / "scenarios" / "fragments" / "parked_cars.yaml")
RADAR_FILE = str(ROOT / "rts_scenario" / "data" / "radars" / "paper.radar.yaml")
MAPPING_FILE = str(ROOT / "rts_scenario" / "data" / "can" / "rts_detections.mapping.yaml")


@pytest.fixture
def disguised(tmp_path):
    """The shipped rig, radar profile, mapping, a DBC and an OpenSCENARIO file under names that
    do not say what they are."""
    names = {}
    for kind, source in (("rig", RIG_FILE), ("radar", RADAR_FILE), ("mapping", MAPPING_FILE),
                         ("dbc", DBC_FILE), ("xosc", XOSC_FILE)):
        path = tmp_path / f"{kind}-copy.yaml"
        path.write_text(Path(source).read_text())
        names[kind] = str(path)
    return names


# (argv, the message after "error: "): {scene} is a good scene; {rig}, {radar}, {mapping} are
# the copies with plain .yaml names.
WRONG_KIND_CASES = [
    (["run", RIG_FILE],
     rf"^{re.escape(RIG_FILE)} is a rig file \(\*\.rig\.yaml\), not a scene "
     r"\(\*\.scenario\.yaml\); a scene names its rig under rig:"),
    (["validate", MAPPING_FILE],
     rf"^{re.escape(MAPPING_FILE)} is a CAN mapping \(\*\.mapping\.yaml\), not a scene "
     r"\(\*\.scenario\.yaml\); run and check take it as --mapping"),
    (["validate", RADAR_FILE],
     rf"^{re.escape(RADAR_FILE)} is a radar profile \(\*\.radar\.yaml\), not a scene "
     r"\(\*\.scenario\.yaml\); a scene names its radar under radar.profile"),
    (["validate", "{rig}"], r"^{rig} is a rig file \(its rts_rig key\), not a scene"),
    (["run", "{radar}"], r"^{radar} is a radar profile \(its rts_radar key\), not a scene"),
    (["run", "{mapping}"], r"^{mapping} is a CAN mapping \(its rts_can_mapping key\), not a "
                           r"scene"),
    (["run", "{scene}", "--mapping", "{scene}"],
     r"^--mapping {scene} is a scene file \(\*\.scenario\.yaml\), not a CAN mapping "
     r"\(\*\.mapping\.yaml\)"),
    (["check", "{scene}", "--log", "{tmp}/junk.blf", "--mapping", RIG_FILE],
     rf"^--mapping {re.escape(RIG_FILE)} is a rig file \(\*\.rig\.yaml\), not a CAN mapping"),
    (["run", "{scene}", "--mapping", "{rig}"],
     r"^--mapping {rig} is a rig file \(its rts_rig key\), not a CAN mapping"),
    (["survey", "{scene}"],
     r"^RIG {scene} is a scene file \(\*\.scenario\.yaml\), not a rig file \(\*\.rig\.yaml\)"),
    (["calibrate", MAPPING_FILE],
     rf"^RIG {re.escape(MAPPING_FILE)} is a CAN mapping \(\*\.mapping\.yaml\), not a rig file"),
    (["survey", "{radar}"], r"^RIG {radar} is a radar profile \(its rts_radar key\), not a rig "
                            r"file"),
    (["emulate", "--listen", "udp://127.0.0.1:0", "--rig", "kit-table1", "--radar", RIG_FILE],
     rf"^--radar {re.escape(RIG_FILE)} is a rig file \(\*\.rig\.yaml\), not a radar profile "
     r"\(\*\.radar\.yaml\)"),
    (["emulate", "--listen", "udp://127.0.0.1:0", "--rig", "{scene}", "--radar", "paper"],
     r"^--rig {scene} is a scene file \(\*\.scenario\.yaml\), not a rig file"),
    (["import", str(ROOT / "tests" / "data" / "xosc" / "cut_in.xosc"), "--radar", "paper",
      "--rig", RADAR_FILE, "--output", "{tmp}/x.scenario.yaml"],
     rf"^--rig {re.escape(RADAR_FILE)} is a radar profile \(\*\.radar\.yaml\), not a rig "
     r"file"),
    # Files of other formats: a CAN database, an OpenSCENARIO file, a scene fragment, a scene
    # as a log.
    (["run", "{scene}", "--mapping", DBC_FILE],
     rf"^--mapping {re.escape(DBC_FILE)} is a DBC file \(\*\.dbc\), not a CAN mapping "
     r"\(\*\.mapping\.yaml\); --mapping takes a CAN mapping that names a DBC and which of its "
     r"signals carry what \(docs/can-mapping\.md\): "
     rf"{re.escape(str(Path(DBC_FILE).with_name('cluster_list.mapping.yaml')))} names this one$"),
    (["check", "{scene}", "--log", "{tmp}/junk.blf", "--mapping", "{dbc}"],
     r"^--mapping {dbc} is a DBC file \(by its content\), not a CAN mapping "
     r"\(\*\.mapping\.yaml\); --mapping takes a CAN mapping that names a DBC and which of its "
     r"signals carry what \(docs/can-mapping\.md\)$"),
    (["emulate", "--listen", "udp://127.0.0.1:0", "--rig", "kit-table1", "--radar", DBC_FILE],
     rf"^--radar {re.escape(DBC_FILE)} is a DBC file \(\*\.dbc\), not a radar profile"),
    (["import", str(ROOT / "tests" / "data" / "xosc" / "cut_in.xosc"), "--radar", "{dbc}",
      "--rig", "wide-3x5", "--output", "{tmp}/x.scenario.yaml"],
     r"^--radar {dbc} is a DBC file \(by its content\), not a radar profile"),
    (["run", XOSC_FILE],
     rf"^{re.escape(XOSC_FILE)} is an OpenSCENARIO file \(\*\.xosc\), not a scene "
     rf"\(\*\.scenario\.yaml\); rts-scenario import {re.escape(XOSC_FILE)} --radar P --rig R "
     r"--output cut_in\.scenario\.yaml converts it to a scene \(docs/import\.md\)$"),
    (["validate", "{xosc}"], r"^{xosc} is an OpenSCENARIO file \(by its content\), not a scene"),
    (["validate", FRAGMENT_FILE],
     rf"^{re.escape(FRAGMENT_FILE)} is a scene fragment \(only targets and a description\), "
     r"not a scene \(\*\.scenario\.yaml\); a scene lists it under include: "
     r"\(scenarios/README\.md, Fragments\)$"),
    (["survey", FRAGMENT_FILE],
     rf"^RIG {re.escape(FRAGMENT_FILE)} is a scene fragment \(only targets and a description\), "
     r"not a rig file"),
    (["check", "{scene}", "--log", "{scene}"],
     r"^--log {scene} is a scene file \(\*\.scenario\.yaml\), not a CAN log; check takes the "
     r"scene as SCENE and, as --log, the log rts-scenario run --record wrote \(\.asc, \.blf, "
     r"\.csv, \.db, \.log, \.mf4, \.trc\)$"),
    (["check", "{scene}", "--log", FRAGMENT_FILE],
     rf"^--log {re.escape(FRAGMENT_FILE)} is a scene fragment \(only targets and a "
     r"description\), not a CAN log"),
    (["validate", "{tmp}/junk.blf"],
     r"^{tmp}/junk.blf is a CAN log \(\*\.blf\), not a scene \(\*\.scenario\.yaml\); "
     r"rts-scenario check SCENE --log LOG checks it against its scene$"),
]


@pytest.mark.parametrize(("argv", "pattern"), WRONG_KIND_CASES,
                         ids=[f"{c[0][0]}-{i}" for i, c in enumerate(WRONG_KIND_CASES)])
def test_a_file_of_another_kind_says_what_it_is(places, disguised, capsys, argv, pattern):
    """A rig, radar profile or mapping given as a scene (or a scene as a mapping or a rig) said
    "unknown key 'columns' ...; allowed keys ...": true, but not what went wrong."""
    names = {**places, **disguised}
    assert call([a.format(**names) for a in argv]) == 2
    message = one_error(capsys.readouterr().err)
    expected = pattern
    for key, value in names.items():
        expected = expected.replace("{" + key + "}", re.escape(value))
    assert re.search(expected, message), message


def test_a_scene_without_its_version_key_is_no_fragment(tmp_path, capsys):
    """Only a file holding nothing but targets (and a description) is named a fragment."""
    path = tmp_path / "tiny.yaml"
    path.write_text(sub("rts_scenario: 1\n", ""))
    assert call(["validate", str(path)]) == 2
    message = one_error(capsys.readouterr().err)
    assert message == f"{path}:1:1: 'rts_scenario' is required but missing; allowed values: 1"


def test_a_sweep_of_a_rig_file_says_what_it_is(capsys):
    assert call(["sweep", RIG_FILE, "--workers", "1"]) == 2
    out = capsys.readouterr().out
    assert f"{RIG_FILE} is a rig file (*.rig.yaml), not a scene" in out
    assert "unknown key" not in out


@pytest.mark.parametrize("value", ["-inf", "-Infinity", "-1e3", "-1E-3", "-.5", "-5.", "-1_000",
                                   "-0", "-nan"])
def test_negative_numbers_are_values_of_number_options(value):
    """argparse took "-inf" and "-1e3" for options (only "-5" and "-.5" passed as values)."""
    args = cli.build_parser().parse_args(["check", "s.scenario.yaml", "--log", "x.blf",
                                          "--time-offset-s", value])
    expected = float(value)
    assert (math.isnan(args.time_offset_s) if math.isnan(expected)
            else args.time_offset_s == expected)


def test_emulate_names_its_options_when_it_cannot_listen_or_open_the_bus(capsys):
    # A second emulate on the port the first listens on, or a CAN interface this machine cannot
    # open: the line named neither --listen nor --can-interface (a CAN error read "cannot
    # open CAN interface 'socketcan' channel 'rts-emulator'": a name the user never gave).
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        assert call(["emulate", "--listen", f"udp://127.0.0.1:{port}", "--rig", "kit-table1",
                     "--radar", "paper", "--wait", "0.01"]) == 2
    message = one_error(capsys.readouterr().err)
    assert message.startswith(f"--listen udp://127.0.0.1:{port}: cannot listen: "), message
    assert message.endswith("another emulate or RTS receiver listening on that port? stop it, "
                            "or give another"), message
    assert call(["emulate", "--listen", "udp://127.0.0.1:0", "--rig", "kit-table1", "--radar",
                 "paper", "--can-interface", "socketcan", "--can-channel", "nosuchcan9",
                 "--wait", "0.01"]) == 2
    message = one_error(capsys.readouterr().err)
    assert message.startswith("--can-interface socketcan --can-channel nosuchcan9: cannot open "
                              "CAN interface 'socketcan' channel 'nosuchcan9'"), message


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")
def test_an_output_named_pipe_is_not_opened_by_the_early_check(tmp_path):
    # Opening a named pipe for writing waits for a reader: the check before a run must not
    # hang the command there (the result is written into the pipe at the end, as to any pipe).
    import threading

    from rts_scenario.cli.common import check_writable_file

    fifo = tmp_path / "report.fifo"
    os.mkfifo(fifo)
    done = threading.Event()
    probe = threading.Thread(target=lambda: (check_writable_file("--json", fifo), done.set()),
                             daemon=True)
    probe.start()
    try:
        assert done.wait(10.0), "the check waited for a reader of the pipe"
    finally:
        if not done.is_set():  # release the blocked probe: a reader comes and goes
            os.close(os.open(fifo, os.O_RDONLY | os.O_NONBLOCK))
        probe.join(10.0)
    assert stat.S_ISFIFO(fifo.stat().st_mode)  # still the pipe, not replaced by a file


@pytest.mark.parametrize(("argv", "linked"), [
    (["run", "{scene}", "--json", "{tmp}/out.json"], "radar"),
    (["run", "{scene}", "--detections", "{tmp}/out.csv"], "fragment"),
    (["run", "{scene}", "--record", "{tmp}/out.asc"], "rig"),
    (["schedule", "{scene}", "--output", "file:{tmp}/out.csv"], "fragment"),
    (["sweep", "{scene}", "--json", "{tmp}/out.json"], "rig"),
], ids=["json-radar", "detections-fragment", "record-rig", "schedule-fragment", "sweep-rig"])
@pytest.mark.parametrize("link", ["symbolic", "hard"])
def test_an_output_that_is_a_file_the_scene_reads_is_refused(tmp_path, capsys, argv, linked,
                                                              link):
    # A link (or a hard link) named as an output to the radar profile, rig or fragment the
    # scene reads: the command wrote through it, destroying the scene's own files. The
    # same-file check knew only the scene file itself.
    folder = tmp_path / "scene"
    (folder / "frag").mkdir(parents=True)
    files = {
        "radar": folder / "own.radar.yaml",
        "rig": folder / "own.rig.yaml",
        "fragment": folder / "frag" / "parked.yaml",
    }
    files["radar"].write_text((ROOT / "rts_scenario/data/radars/awr1843boost.radar.yaml")
                              .read_text())
    files["rig"].write_text((ROOT / "rts_scenario/data/rigs/wide-3x5.rig.yaml").read_text())
    files["fragment"].write_text("targets:\n  - name: parked\n    motion: {type: stationary, "
                                 "position_m: [40, 2, 0.6]}\n    rcs: {rcs_dbsm: 10.0}\n")
    scene = folder / "s.scenario.yaml"
    scene.write_text(TINY.replace("profile: awr1843boost", "profile: own.radar.yaml")
                     .replace("rig: wide-3x5", "rig: own.rig.yaml")
                     .replace("name: tiny\n", "name: tiny\ninclude: [frag/parked.yaml]\n"))
    assert call(["validate", str(scene)]) == 0
    capsys.readouterr()
    before = {name: path.read_bytes() for name, path in files.items()}
    out = Path(argv[-1].split(":", 1)[-1].format(tmp=tmp_path))
    if link == "symbolic":
        out.symlink_to(files[linked])
    else:
        os.link(files[linked], out)
    code = call([a.format(scene=scene, tmp=tmp_path) for a in argv])
    err = capsys.readouterr().err
    assert code == 2
    assert one_error(err).endswith(f"the same file as the scene's {files[linked]}, which this "
                                   f"command reads; writing it would destroy the input; give "
                                   f"{argv[-2]} another file")
    assert {name: path.read_bytes() for name, path in files.items()} == before


def test_a_command_with_its_standard_output_closed_is_refused(places):
    # Started with '>&-', Python drops what is printed: the run passed, exit 0, its verdict
    # printed nowhere and nothing said.
    done = subprocess.run(
        [sys.executable, "-m", "rts_scenario", "run", places["scene"]],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, timeout=300,
        preexec_fn=lambda: os.close(1))
    assert done.returncode == 2
    assert done.stderr == ("error: standard output is closed: what the command prints (its "
                           "verdict among it) would be lost; give it a file, or /dev/null to "
                           "discard it\n")


def test_a_folder_named_as_a_fragment_says_so(tmp_path, capsys):
    # It said "file not found: 'sub'" of a folder that is there.
    (tmp_path / "sub").mkdir()
    path = tmp_path / "s.scenario.yaml"
    path.write_text(TINY.replace("name: tiny\n", "name: tiny\ninclude: [sub]\n"))
    assert call(["validate", str(path)]) == 2
    assert re.fullmatch(rf"{re.escape(str(path))}:3:\d+: include\[0\]: 'sub' is a folder; "
                        rf"name a file in it", one_error(capsys.readouterr().err))


@pytest.mark.parametrize("data", [bytes(range(256)) * 4, bytes(range(1, 256)) * 4],
                         ids=["with-nul", "without-nul"])
def test_a_binary_dbc_is_one_readable_error_line(tmp_path, data):
    # cantools' error quoted the file's first bytes: raw binary on the terminal.
    from rts_scenario.canbus.mapping import CanMapping
    from rts_scenario.errors import RtsError

    mapping = (ROOT / "scenarios" / "can" / "object_list.mapping.yaml").read_text()
    (tmp_path / "object_list.dbc").write_bytes(data)
    path = tmp_path / "object_list.mapping.yaml"
    path.write_text(mapping)
    with pytest.raises(RtsError) as caught:
        CanMapping.from_file(path)
    message = str(caught.value)
    assert "cannot load DBC" in message and message.isprintable(), message
    assert len(message) < 600


def test_a_cache_folder_out_of_reach_is_no_disk_cache_not_a_crash(monkeypatch, tmp_path):
    """A folder below one without permission: looking at it raised PermissionError, a
    traceback in every command and an internal error in pytest."""
    from rts_scenario import settings

    def denied(self):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setenv("RTS_SCENARIO_CACHE_DIR", str(tmp_path / "priv" / "cache"))
    monkeypatch.setattr(Path, "exists", denied)
    settings.check_environment()
    assert settings.cache_dir_setting() == tmp_path / "priv" / "cache"
