"""A quantity the run's CAN mapping does not carry is not checked, and every run says so.

A scene that wrote the quantity's tolerance means it checked: the run fails with the scene-wide
limit ``quantity_unchecked`` unless the scene declares it expected; a tolerance the scene left
to its default is said, not failed. The expected reasons, lines and fields are written out by
hand from the scene and mapping files, not taken from the code under test.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

import rts_scenario.cli as cli
from rts_scenario.canbus.mapping import CanMapping
from rts_scenario.check import Checker
from rts_scenario.errors import ScenarioError
from rts_scenario.pipeline import RunOptions, run_scene
from rts_scenario.recheck import check_log
from rts_scenario.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]
GANTRY = ROOT / "scenarios" / "gantry_stopped_car.scenario.yaml"
CAN = ROOT / "scenarios" / "can"
CLUSTER = CAN / "cluster_list.mapping.yaml"
OBJECTS = CAN / "object_list.mapping.yaml"
QUIET = {"radar.noise": False, "radar.fidelity": "analytic"}
EXPECTS_IT = {**QUIET, "expectations.expected_limits": ["quantity_unchecked"]}

NO_ELEVATION = "mapping 'cluster-list' carries no elevation, a cartesian one without z_m"
HINT = (" (list quantity_unchecked in expected_limits where the scene means to run on such a "
        "mapping)")
# gantry_stopped_car writes el_deg: 0.5 (elevation tells the car from the gantry).
GANTRY_REASON = ("quantity_unchecked: the scene's el tolerance 0.5 deg is not checked: "
                 + NO_ELEVATION + HINT)


def mapping_without(tmp_path: Path, source: Path, name: str, *keys: str) -> Path:
    """A copy of ``source`` (beside a copy of its DBC) without the detection ``keys``."""
    text = source.read_text()
    for key in keys:
        text, n = re.subn(rf"^  {key}: .*\n", "", text, flags=re.M)
        assert n == 1, key
    text = re.sub(r"^name: .*$", f"name: {name}", text, count=1, flags=re.M)
    dbc = re.search(r"^dbc: (\S+)", text, re.M).group(1)
    (tmp_path / dbc).write_text((CAN / dbc).read_text())
    out = tmp_path / f"{name}.mapping.yaml"
    out.write_text(text)
    return out


def held_to(report) -> str:
    (line,) = [x for x in report.table().splitlines() if x.startswith("held to: ")]
    return line


# --- the scene knows which tolerances it wrote ------------------------------------------------

def test_the_scene_knows_which_tolerances_it_wrote(tmp_path):
    scene = load_scenario(GANTRY)
    assert scene.expectations.tolerances_written == {"range_m", "radial_velocity_mps", "az_deg",
                                                      "el_deg"}
    # The merged tolerances stay as they were: rcs from the defaults.
    assert scene.expectations.tolerances == {"range_m": 0.3, "radial_velocity_mps": 0.3,
                                             "az_deg": 0.5, "el_deg": 0.5, "rcs_db": 6.0}
    bare = tmp_path / "bare.scenario.yaml"
    bare.write_text(GANTRY.read_text().replace(
        "  tolerances: {range_m: 0.3, radial_velocity_mps: 0.3, az_deg: 0.5, el_deg: 0.5}\n", ""))
    assert load_scenario(bare).expectations.tolerances_written == frozenset()
    # A parametrize block that sets one writes it too.
    swept = load_scenario(GANTRY, {"expectations.tolerances.rcs_db": 3.0})
    assert swept.expectations.tolerances_written == {"range_m", "radial_velocity_mps", "az_deg",
                                                     "el_deg", "rcs_db"}
    assert swept.expectations.tolerances["rcs_db"] == 3.0


def test_quantity_unchecked_on_a_target_is_refused(tmp_path):
    bad = tmp_path / "bad.scenario.yaml"
    bad.write_text(GANTRY.read_text().replace(
        "    rcs: {rcs_dbsm: 18.0}\n",
        "    rcs: {rcs_dbsm: 18.0}\n    expected_limits: [quantity_unchecked]\n"))
    with pytest.raises(ScenarioError, match=(
            rf"^{re.escape(str(bad))}:28:\d+: targets\[1\].expected_limits\[0\]: "
            r"'quantity_unchecked' is a limit of the whole scene, not of one target: list it in "
            r"expectations.expected_limits; a target's expected_limits allow 'out_of_coverage', "
            r".*'beyond_radar_velocity'$")):
        load_scenario(bad)


# --- what a mapping carries -------------------------------------------------------------------

def test_what_a_mapping_does_not_carry(tmp_path):
    assert CanMapping.builtin().not_carried() == {}
    assert CanMapping.from_file(OBJECTS).not_carried() == {}
    assert CanMapping.from_file(CLUSTER).not_carried() == {"elevation_deg": NO_ELEVATION}
    # Cartesian: radial velocity is derived only from both velocities.
    one_velocity = mapping_without(tmp_path, CLUSTER, "no-vx", "vx_mps")
    assert CanMapping.from_file(one_velocity).not_carried() == {
        "radial_velocity_mps": "mapping 'no-vx' carries no radial velocity, a cartesian one "
                               "without both vx_mps and vy_mps",
        "elevation_deg": "mapping 'no-vx' carries no elevation, a cartesian one without z_m"}
    polar = mapping_without(tmp_path, OBJECTS, "flat-objects", "elevation_deg", "rcs_dbsm")
    assert CanMapping.from_file(polar).not_carried() == {
        "elevation_deg": "mapping 'flat-objects' carries no elevation",
        "rcs_dbsm": "mapping 'flat-objects' carries no RCS"}


# --- runs -------------------------------------------------------------------------------------

def test_a_written_tolerance_the_mapping_does_not_carry_fails_the_run(tmp_path, capsys):
    out = tmp_path / "run.json"
    code = cli.main(["run", str(GANTRY), "--mapping", str(CLUSTER), "--json", str(out)])
    text = capsys.readouterr().out
    assert code == 1
    entry = json.loads(out.read_text())
    assert entry["passed"] is False
    assert entry["reasons"] == [GANTRY_REASON]
    assert entry["unchecked_quantities"] == {
        "el_deg": {"why": NO_ELEVATION, "tolerance": 0.5, "written": True, "target_cycles": None}}
    assert entry["scene_limits"] == {"quantity_unchecked": {
        "why": GANTRY_REASON.removeprefix("quantity_unchecked: "), "expected": False}}
    assert ("held to: range 0.3 m, radial velocity 0.3 m/s, az 0.5 deg, el not checked ("
            + NO_ELEVATION + "), rcs 6 dB; detection rate >= 90.0% per target; false "
            "detections <= 0.1 per cycle") in text.splitlines()
    assert "el 0.5 deg" not in text


def test_the_reason_code_is_quantity_unchecked():
    report = run_scene(load_scenario(GANTRY, QUIET), RunOptions(mapping=str(CLUSTER))).report
    assert report.reason_codes == ["quantity_unchecked"]
    # Both targets matched within the tolerances checked: the run fails on the elevation alone.
    assert [t.verdict for t in report.targets] == ["pass", "pass"]


def test_a_scene_that_expects_it_passes_and_still_says_it(tmp_path):
    report = run_scene(load_scenario(GANTRY, EXPECTS_IT), RunOptions(mapping=str(CLUSTER))).report
    assert report.passed, report.reasons
    assert report.scene_limits["quantity_unchecked"]["expected"] is True
    assert report.unchecked_quantities == {
        "el_deg": {"why": NO_ELEVATION, "tolerance": 0.5, "written": True, "target_cycles": None}}
    assert "el not checked (" + NO_ELEVATION + ")" in held_to(report)
    assert "quantity_unchecked" not in report.expected_not_hit


def test_a_default_tolerance_not_carried_is_said_not_failed(tmp_path):
    scene = tmp_path / "gantry.scenario.yaml"
    scene.write_text(GANTRY.read_text().replace(", el_deg: 0.5}", "}"))
    report = run_scene(load_scenario(scene, QUIET), RunOptions(mapping=str(CLUSTER))).report
    assert report.passed, report.reasons
    assert report.scene_limits == {}
    assert report.unchecked_quantities == {
        "el_deg": {"why": NO_ELEVATION, "tolerance": 1.0, "written": False, "target_cycles": None}}
    assert held_to(report).startswith("held to: range 0.3 m, radial velocity 0.3 m/s, az 0.5 "
                                      "deg, el not checked (" + NO_ELEVATION + "), rcs 6 dB;")


def test_written_and_default_tolerances_on_a_polar_mapping(tmp_path):
    polar = mapping_without(tmp_path, OBJECTS, "flat-objects", "elevation_deg", "rcs_dbsm")
    report = run_scene(load_scenario(GANTRY, QUIET), RunOptions(mapping=str(polar))).report
    # el written (fails), rcs the default (said only).
    assert report.reasons == [
        "quantity_unchecked: the scene's el tolerance 0.5 deg is not checked: mapping "
        "'flat-objects' carries no elevation" + HINT]
    assert report.unchecked_quantities == {
        "el_deg": {"why": "mapping 'flat-objects' carries no elevation", "tolerance": 0.5,
                   "written": True, "target_cycles": None},
        "rcs_db": {"why": "mapping 'flat-objects' carries no RCS", "tolerance": 6.0,
                   "written": False, "target_cycles": None}}
    assert held_to(report).startswith(
        "held to: range 0.3 m, radial velocity 0.3 m/s, az 0.5 deg, el not checked (mapping "
        "'flat-objects' carries no elevation), rcs not checked (mapping 'flat-objects' carries "
        "no RCS);")


def test_a_cartesian_mapping_with_one_velocity_leaves_radial_velocity_unchecked(tmp_path):
    one_velocity = mapping_without(tmp_path, CLUSTER, "no-vx", "vx_mps")
    report = run_scene(load_scenario(GANTRY, QUIET), RunOptions(mapping=str(one_velocity))).report
    assert report.reasons == [
        "quantity_unchecked: the scene's radial velocity tolerance 0.3 m/s is not checked: "
        "mapping 'no-vx' carries no radial velocity, a cartesian one without both vx_mps and "
        "vy_mps; the scene's el tolerance 0.5 deg is not checked: mapping 'no-vx' carries no "
        "elevation, a cartesian one without z_m" + HINT]
    assert report.errors["radial_velocity_mps"].count == 0


def test_own_mapping_checks_everything_and_an_expectation_not_hit_is_said():
    plain = run_scene(load_scenario(GANTRY, QUIET), RunOptions()).report
    assert plain.passed, plain.reasons
    assert plain.unchecked_quantities == {}
    assert "not checked" not in held_to(plain)
    expects = run_scene(load_scenario(GANTRY, EXPECTS_IT), RunOptions()).report
    assert expects.passed, expects.reasons
    assert expects.expected_not_hit == ["quantity_unchecked"]


# --- a re-check of the log, and the pytest plugin ---------------------------------------------

def test_a_re_check_fails_the_same_way(tmp_path, capsys):
    log = tmp_path / "drive.blf"
    live = run_scene(load_scenario(GANTRY), RunOptions(mapping=str(CLUSTER), bus_log=str(log))
                     ).report
    assert live.reasons == [GANTRY_REASON]
    again = check_log(load_scenario(GANTRY), log).report  # the sidecar names the mapping
    assert again.reasons == [GANTRY_REASON]
    assert again.unchecked_quantities == {
        "el_deg": {"why": NO_ELEVATION, "tolerance": 0.5, "written": True, "target_cycles": None}}
    # The same scene declaring it: the same ground truth, so the same log re-checks.
    expecting = tmp_path / "gantry.scenario.yaml"
    expecting.write_text(GANTRY.read_text().replace(
        "  detection_rate: 0.9\n",
        "  detection_rate: 0.9\n  expected_limits: [quantity_unchecked]\n"))
    expects = check_log(load_scenario(expecting), log).report
    assert expects.passed, expects.reasons
    assert expects.scene_limits["quantity_unchecked"]["expected"] is True
    capsys.readouterr()
    assert cli.main(["check", str(GANTRY), "--log", str(log), "--mapping", str(CLUSTER)]) == 1
    assert ("el not checked (" + NO_ELEVATION + ")") in capsys.readouterr().out


pytest_plugins = ["pytester"]


def test_the_plugin_fails_a_scene_on_it_and_names_the_code(pytester):
    import xml.etree.ElementTree as ET

    pytester.makefile(".scenario.yaml", gantry=GANTRY.read_text())
    result = pytester.runpytest("--rts-mapping", str(CLUSTER), "--junitxml=out.xml")
    result.assert_outcomes(failed=1)
    assert GANTRY_REASON in result.stdout.str()
    (case,) = ET.parse(pytester.path / "out.xml").getroot().iter("testcase")
    assert {p.get("name"): p.get("value") for p in case.iter("property")}["reasons"] == (
        "quantity_unchecked")
    pytester.runpytest().assert_outcomes(passed=1)  # its own mapping carries elevation


def test_an_xfail_mark_does_not_cover_it(pytester):
    # xfail expects the radar's check to fail; an elevation never checked is no such failure.
    pytester.makefile(".scenario.yaml", gantry=GANTRY.read_text() + "marks: [xfail]\n")
    result = pytester.runpytest("--rts-mapping", str(CLUSTER))
    result.assert_outcomes(failed=1)
    assert ("the scene's xfail mark expects the radar's check to fail, not the bench: "
            "quantity_unchecked") in result.stdout.str()


# --- a quantity reported at its signal's end ---------------------------------------------------
# A radar puts a value beyond its signal's range at the signal's end (the simulated radar does
# so with RCS): such a reading says "this much or more", not how much. Against a truth beyond
# the end it is not checked, and the run says so; against a truth within the signal's range it
# is a measurement like any other.

PINNED_DBC = """VERSION ""

NS_ :

BS_:

BU_: RADAR GATEWAY

BO_ 1536 St: 8 RADAR
 SG_ Cnt : 0|8@1+ (1,0) [0|255] "" GATEWAY
 SG_ NObj : 8|8@1+ (1,0) [0|255] "" GATEWAY

BO_ 1537 Obj: 8 RADAR
 SG_ Id : 0|8@1+ (1,0) [0|255] "" GATEWAY
 SG_ Range : 8|14@1+ (0.02,0) [0|327.66] "m" GATEWAY
 SG_ Az : 22|12@1- (0.05,0) [-102.4|102.35] "deg" GATEWAY
 SG_ Vr : 34|14@1- (0.02,0) [-163.84|163.82] "m/s" GATEWAY
 SG_ El : 48|8@1- (0.1,0) [-12.8|12.75] "deg" GATEWAY
 SG_ Rcs : 56|8@1+ (0.5,-64) [-64|2] "dBsm" GATEWAY
"""
PINNED_MAPPING = """rts_can_mapping: 1
name: pinned
dbc: pinned.dbc
header: {message: St, counter: Cnt, count: [NObj]}
detection:
  messages: [Obj]
  index: Id
  form: polar
  range_m: Range
  azimuth_deg: Az
  radial_velocity_mps: Vr
  elevation_deg: El
  rcs_dbsm: Rcs
"""
# One car of 7.5 dBsm: beyond the 2 dBsm the mapping's RCS signal carries.
PINNED_SCENE = """rts_scenario: 1
name: pinned
duration_s: 2.0
frame_rate_hz: 20.0
radar: {profile: awr1843boost, mount: {x_m: 3.7, z_m: 0.5}}
rig: wide-3x5
ego: {motion: {type: stationary, position_m: [0, 0, 0]}}
targets:
  - name: car
    kind: car
    motion: {type: constant_velocity, position_m: [60.0, 4.0, 0.6], heading_deg: 180,
             speed_mps: 8.0}
    rcs: {rcs_dbsm: RCS}
expectations:
  tolerances: {range_m: 0.3, radial_velocity_mps: 0.3, az_deg: 0.5, el_deg: 1.0TOL}
"""
PINNED_WHY = ("in {n} of {n} matched target-cycles, reported at the end of signal 'Rcs' of "
              "mapping 'pinned' (-64 to 2 dBsm) with the truth beyond it")


def pinned(tmp_path: Path, rcs_dbsm: float = 7.5, written: bool = False):
    (tmp_path / "pinned.dbc").write_text(PINNED_DBC)
    mapping = tmp_path / "pinned.mapping.yaml"
    mapping.write_text(PINNED_MAPPING)
    scene = tmp_path / "pinned.scenario.yaml"
    scene.write_text(PINNED_SCENE.replace("RCS", str(rcs_dbsm))
                     .replace("TOL", ", rcs_db: 6" if written else ""))
    return scene, mapping


def test_the_ends_a_mapping_carries(tmp_path):
    _, mapping = pinned(tmp_path)
    ends = CanMapping.from_file(mapping).limits()
    # The raw values' ends within the DBC range: El's 12.75 is not on its 0.1 grid, 12.7 is.
    assert ends["rcs_dbsm"] == (-64.0, 2.0, 0.5, "Rcs")
    assert ends["el_deg"][:3] == pytest.approx((-12.8, 12.7, 0.1))
    assert ends["range_m"][:3] == pytest.approx((0.0, 327.66, 0.02))
    # rts-scenario's own: classic RCS in 0.5 dB steps from -64 to 63.5 dBsm, CAN FD wider.
    own = CanMapping.builtin()
    assert own.limits(False)["rcs_dbsm"][:2] == (-64.0, 63.5)
    assert own.limits(True)["rcs_dbsm"][:2] == pytest.approx((-327.68, 327.67))
    assert own.limits(None)["rcs_dbsm"][:2] == (-64.0, 63.5)  # a bus not known: the narrower
    # A cartesian mapping derives range and angles from several signals: RCS alone.
    assert set(CanMapping.from_file(CLUSTER).limits()) == {"rcs_dbsm"}
    # Two messages carrying the range, one to 100 m: the widest (a reading of 100 m in the
    # other is a measurement, not its end).
    (tmp_path / "pinned.dbc").write_text(
        PINNED_DBC + '\nBO_ 1538 Near: 8 RADAR\n SG_ Id : 0|8@1+ (1,0) [0|255] "" GATEWAY\n'
        ' SG_ Range : 8|14@1+ (0.02,0) [0|100] "m" GATEWAY\n')
    mapping.write_text(PINNED_MAPPING.replace("messages: [Obj]", "messages: [Obj, Near]"))
    assert CanMapping.from_file(mapping).limits()["range_m"][:2] == pytest.approx((0.0, 327.66))


def test_a_float_signal_is_at_its_end_only_at_its_end(tmp_path):
    # A float signal's step is 0: a reading of 49.6 in a [-50|50] float signal is a reading,
    # 10.4 dB off a 60 dBsm truth, not "this much or more".
    text = (PINNED_DBC + "\nBO_ 1538 Extra: 8 RADAR\n SG_ Id : 0|8@1+ (1,0) [0|255] \"\" "
            "GATEWAY\n SG_ Ext : 8|32@1- (1,0) [-50|50] \"dBsm\" GATEWAY\n\n"
            "SIG_VALTYPE_ 1538 Ext : 1;\n")
    (tmp_path / "pinned.dbc").write_text(text)
    mapping = tmp_path / "pinned.mapping.yaml"
    mapping.write_text(PINNED_MAPPING.replace("messages: [Obj]", "messages: [Obj, Extra]")
                       .replace("rcs_dbsm: Rcs", "rcs_dbsm: Ext"))
    ends = CanMapping.from_file(mapping).limits()
    # Two units in the last place of 50 in single precision: 2 * 2**-18.
    assert ends["rcs_dbsm"] == (-50.0, 50.0, 2.0**-17, "Ext")
    report = _pinned_checker(60.0, 49.6, ends["rcs_dbsm"])
    assert report.unchecked_quantities == {}
    assert report.errors["rcs_dbsm"].max == pytest.approx(10.4)
    assert not report.passed
    # At its very end, against a truth beyond it: not checked.
    assert _pinned_checker(60.0, 50.0, ends["rcs_dbsm"]).errors["rcs_dbsm"].count == 0
    # An end single precision cannot hold: 2.3 is stored as 2.29999995, still its end.
    (tmp_path / "pinned.dbc").write_text(text.replace("[-50|50]", "[-50|2.3]"))
    ends = CanMapping.from_file(mapping).limits()
    stored = float(np.float32(2.3))
    assert stored < 2.3 and ends["rcs_dbsm"][1] == 2.3
    assert _pinned_checker(12.0, stored, ends["rcs_dbsm"]).errors["rcs_dbsm"].count == 0
    assert _pinned_checker(12.0, 2.29, ends["rcs_dbsm"]).errors["rcs_dbsm"].count == 1


def test_an_rcs_pinned_at_its_signals_end_is_not_checked_and_said(tmp_path, capsys):
    scene, mapping = pinned(tmp_path)
    out = tmp_path / "run.json"
    code = cli.main(["run", str(scene), "--mapping", str(mapping), "--json", str(out)])
    text = capsys.readouterr().out
    entry = json.loads(out.read_text())
    # The default's tolerance: said, not failed.
    assert code == 0 and entry["passed"] is True, entry["reasons"]
    n = entry["target_frames"]["matched"]
    assert n == 40
    assert entry["unchecked_quantities"] == {"rcs_db": {
        "why": PINNED_WHY.format(n=n), "tolerance": 6.0, "written": False, "target_cycles": n}}
    # No RCS error is counted: the 2 dBsm read against 7.5 is no 5.5 dB error.
    assert entry["errors"]["rcs_dbsm"]["count"] == 0
    assert ("held to: range 0.3 m, radial velocity 0.3 m/s, az 0.5 deg, el 1 deg, rcs 6 dB "
            "(not checked " + PINNED_WHY.format(n=n) + "); detection rate >= 90.0% per "
            "target; false detections <= 0.1 per cycle") in text.splitlines()


def test_a_written_rcs_tolerance_pinned_at_its_signals_end_fails_the_run(tmp_path):
    scene, mapping = pinned(tmp_path, written=True)
    report = run_scene(load_scenario(scene, QUIET), RunOptions(mapping=str(mapping))).report
    n = report.target_frames["matched"]
    assert report.reasons == ["quantity_unchecked: the scene's rcs tolerance 6 dB is not "
                              "checked: " + PINNED_WHY.format(n=n) + HINT]
    assert report.unchecked_quantities["rcs_db"]["written"] is True
    expects = load_scenario(scene, EXPECTS_IT)
    assert run_scene(expects, RunOptions(mapping=str(mapping))).report.passed


def test_an_rcs_within_its_signals_range_is_checked(tmp_path):
    # -10 dBsm: well inside -64..2; the quiet radar reports it within a step.
    scene, mapping = pinned(tmp_path, rcs_dbsm=-10.0, written=True)
    report = run_scene(load_scenario(scene, QUIET), RunOptions(mapping=str(mapping))).report
    assert report.passed, report.reasons
    assert report.unchecked_quantities == {}
    assert report.errors["rcs_dbsm"].count == report.target_frames["matched"] == 40


def _pinned_checker(truth_rcs, reported_rcs, ends=(-64.0, 2.0, 0.5, "Rcs")):
    """A checker with the pinned mapping's RCS ends, one target-frame, one detection."""
    from rts_scenario.detections import Detections
    from rts_scenario.kinematics import Tracks
    from rts_scenario.scenario.model import Expectations
    ones = np.ones((1, 1), dtype=bool)
    tracks = Tracks(names=("car",), t_s=np.zeros(1), range_m=np.full((1, 1), 20.0),
                    radial_velocity_mps=np.zeros((1, 1)), doppler_hz=np.zeros((1, 1)),
                    rcs_dbsm=np.full((1, 1), truth_rcs), az_deg=np.zeros((1, 1)),
                    el_deg=np.zeros((1, 1)), position_m=np.zeros((1, 1, 3)), present=ones,
                    in_coverage=ones, in_range=ones, in_velocity=ones)
    tolerances = {"range_m": 0.3, "radial_velocity_mps": 0.3, "az_deg": 0.5, "el_deg": 1.0,
                  "rcs_db": 6.0}
    exp = Expectations(tolerances=tolerances, tolerances_written=frozenset(tolerances))
    checker = Checker("pinned", ("car",), exp, limits={"rcs_dbsm": ends},
                      mapping_name="pinned")
    status = np.zeros((1, 1), dtype=np.uint16)
    checker.add_truth(0, tracks, status)
    checker.add_frames(tracks, status)
    one = np.zeros(1)
    checker.add_cycles([Detections(cycle=0, t_s=0.0, range_m=one + 20.0,
                                   radial_velocity_mps=one, az_deg=one, el_deg=one,
                                   rcs_dbsm=one + reported_rcs)])
    checker.settle()
    return checker.report()


@pytest.mark.parametrize("truth_rcs, reported, checked, error", [
    (7.5, 2.0, False, None),     # pinned, the truth beyond: not checked
    (2.2, 2.0, True, 0.2),       # within half a step of the end: the end is its reading
    (-10.0, 2.0, True, 12.0),    # pinned, the truth far below: a real error of 12 dB
    (-70.0, -64.0, False, None),  # pinned at the low end, the truth below it
    (7.5, 1.5, True, 6.0),       # a step below the end: a reading, 6 dB off
])
def test_a_reading_at_the_end_is_judged_by_where_the_truth_lies(truth_rcs, reported, checked,
                                                                error):
    report = _pinned_checker(truth_rcs, reported)
    stats = report.errors["rcs_dbsm"]
    if checked:
        assert report.unchecked_quantities == {}
        assert stats.count == 1 and stats.max == pytest.approx(error)
        assert report.passed is (error <= 6.0)
    else:
        assert stats.count == 0
        assert report.unchecked_quantities["rcs_db"]["target_cycles"] == 1
        # The scene wrote the tolerance: not checked fails the run.
        assert report.reason_codes == ["quantity_unchecked"]
