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

import pytest

import rts_scenario.cli as cli
from rts_scenario.canbus.mapping import CanMapping
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
        "el_deg": {"why": NO_ELEVATION, "tolerance": 0.5, "written": True}}
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
        "el_deg": {"why": NO_ELEVATION, "tolerance": 0.5, "written": True}}
    assert "el not checked (" + NO_ELEVATION + ")" in held_to(report)
    assert "quantity_unchecked" not in report.expected_not_hit


def test_a_default_tolerance_not_carried_is_said_not_failed(tmp_path):
    scene = tmp_path / "gantry.scenario.yaml"
    scene.write_text(GANTRY.read_text().replace(", el_deg: 0.5}", "}"))
    report = run_scene(load_scenario(scene, QUIET), RunOptions(mapping=str(CLUSTER))).report
    assert report.passed, report.reasons
    assert report.scene_limits == {}
    assert report.unchecked_quantities == {
        "el_deg": {"why": NO_ELEVATION, "tolerance": 1.0, "written": False}}
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
                   "written": True},
        "rcs_db": {"why": "mapping 'flat-objects' carries no RCS", "tolerance": 6.0,
                   "written": False}}
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
        "el_deg": {"why": NO_ELEVATION, "tolerance": 0.5, "written": True}}
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
