"""The pytest plugin, driven through pytester."""

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

# pytester runs pytest in this process and drops the modules a run imported; numpy's and
# scipy's extension modules cannot load twice, so the library is imported here, once.
import rts_scenario.pipeline  # noqa: F401

pytest_plugins = ["pytester"]
ROOT = Path(__file__).resolve().parents[1]


def scene(name: str, *, detection_rate: float = 0.9, extra: str = "") -> str:
    return textwrap.dedent(f"""\
        rts_scenario: 1
        name: {name}
        duration_s: 2.0
        frame_rate_hz: 20.0
        radar: {{profile: awr1843boost, mount: {{x_m: 3.7, z_m: 0.5}}}}
        rig: wide-3x5
        ego:
          motion: {{type: constant_velocity, position_m: [0, 0, 0], speed_mps: 20.0}}
        targets:
          - name: car
            motion: {{type: constant_velocity, position_m: [30, 0, 0.6], speed_mps: 19.0}}
            rcs: {{rcs_dbsm: 10.0}}
        expectations:
          detection_rate: {detection_rate}
        """) + extra


def test_collects_scene_files_and_runs_them(pytester):
    pytester.makefile(".scenario.yaml", follow=scene("follow"))
    pytester.makefile(".yaml", unrelated="a: 1\n")
    result = pytester.runpytest("-v")
    result.stdout.fnmatch_lines(["*follow.scenario.yaml::follow PASSED*"])
    result.assert_outcomes(passed=1)


def test_parametrized_combinations_and_marks(pytester):
    extra = "parametrize:\n  radar.estimator: [bartlett, ti]\nmarks: [slow]\n"
    pytester.makefile(".scenario.yaml", combo=scene("combo", extra=extra))
    result = pytester.runpytest("-v", "-m", "slow")
    result.stdout.fnmatch_lines(["*combo[[]estimator=bartlett[]] PASSED*",
                                 "*combo[[]estimator=ti[]] PASSED*"])
    result.assert_outcomes(passed=2)
    assert pytester.runpytest("-m", "not slow").ret == pytest.ExitCode.NO_TESTS_COLLECTED


def test_a_scene_s_own_marks_pass_strict_markers(pytester):
    pytester.makefile(".scenario.yaml", night=scene("night", extra="marks: [nightly]\n"))
    result = pytester.runpytest("--strict-markers", "-m", "nightly")
    result.assert_outcomes(passed=1)


def test_failure_shows_the_report_and_worst_frames(pytester):
    # A target the rig cannot show (far outside its coverage) never gets detected.
    text = scene("impossible").replace("[30, 0, 0.6]", "[30, 20, 0.6]")
    pytester.makefile(".scenario.yaml", impossible=text)
    result = pytester.runpytest("--junitxml=out.xml")
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(["*FAIL: impossible*nothing to check*"])
    assert "Traceback" not in result.stdout.str()
    # Nothing checkable has no detection rate: null, as the JSON report says (not "nan").
    assert '<property name="detection_rate" value="null"' in (pytester.path / "out.xml").read_text()


def test_failure_summary_starts_with_the_verdict_and_its_reasons(pytester):
    text = scene("impossible").replace("[30, 0, 0.6]", "[30, 20, 0.6]")
    pytester.makefile(".scenario.yaml", impossible=text)
    result = pytester.runpytest()
    lines = result.stdout.lines
    verdict = next(i for i, line in enumerate(lines) if line.startswith("FAIL: impossible - "))
    assert "nothing to check" in lines[verdict]
    assert lines[verdict + 2].startswith("target ")  # then the table
    # Said once: the table under it leaves its own verdict line out.
    assert sum(line.startswith("FAIL: impossible") for line in lines) == 1


def test_bad_rts_output_stops_the_session_once(pytester):
    for name in ("one", "two", "three"):
        pytester.makefile(".scenario.yaml", **{name: scene(name)})
    result = pytester.runpytest("--rts-output", "carrier-pigeon")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    text = result.stderr.str() + result.stdout.str()
    assert text.count("unknown output 'carrier-pigeon'") == 1
    assert "valid outputs: file, udp, simulated-radar" in text
    assert "Traceback" not in text


def test_bad_rts_mapping_or_can_fd_stops_the_session_up_front(pytester):
    pytester.makefile(".scenario.yaml", one=scene("one"))
    result = pytester.runpytest("--rts-mapping", "nowhere.mapping.yaml")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    text = result.stderr.str() + result.stdout.str()
    assert "--rts-mapping nowhere.mapping.yaml" in text and "Traceback" not in text
    mapping = ROOT / "scenarios" / "can" / "cluster_list.mapping.yaml"
    result = pytester.runpytest("--rts-mapping", str(mapping), "--rts-can-fd")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    text = result.stderr.str() + result.stdout.str()
    assert f"--rts-can-fd: the mapping {mapping} has no fd_message" in text

def test_rts_radar_channel_reads_the_radar_s_channel_alone(pytester, monkeypatch):
    # The interface hears the radar's messages on channels 0 and 1 (`bridged_twice`): the run
    # refuses to judge the mixed cycles, unless told which channel is the radar's.
    from test_can_bench import bridged_twice

    bridged_twice(monkeypatch)
    pytester.makefile(".scenario.yaml", one=scene("one"))
    result = pytester.runpytest()
    result.assert_outcomes(failed=1)
    # The reason names the plugin's option, not the command's.
    text = result.stdout.str()
    assert "came on 2 channels" in text and "give --rts-radar-channel CH" in text
    assert "give --radar-channel" not in text
    pytester.runpytest("--rts-radar-channel", "0").assert_outcomes(passed=1)
    result = pytester.runpytest("--rts-radar-channel", "7")
    result.assert_outcomes(failed=1)
    assert "--rts-radar-channel 7: none of the radar's messages" in result.stdout.str()
    result = pytester.runpytest("--rts-radar-channel", " ")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    text = result.stderr.str() + result.stdout.str()
    assert "--rts-radar-channel ' ': empty" in text and "Traceback" not in text


def test_a_cache_folder_that_is_not_there_stops_the_session_up_front(pytester, monkeypatch):
    # A mistyped path was made, with every folder above it that was not there.
    pytester.makefile(".scenario.yaml", one=scene("one"))
    missing = pytester.path / "nope" / "deeper"
    monkeypatch.setenv("RTS_SCENARIO_CACHE_DIR", str(missing))
    result = pytester.runpytest()
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    text = result.stderr.str() + result.stdout.str()
    assert text.count(f"RTS_SCENARIO_CACHE_DIR={str(missing)!r}: no such folder; allowed: ") == 1
    assert "Traceback" not in text and not missing.parent.exists()


@pytest.mark.parametrize("option", ["--rts-mapping", "--rts-can-channel", "--rts-output",
                                    "--rts-can-interface"])
def test_an_empty_rts_option_is_a_usage_error(pytester, option):
    # `--rts-mapping=$MAPPING` with MAPPING unset is not the option left out: a radar read with
    # rts-scenario's own DBC instead of its own, or a private channel instead of the bench's.
    pytester.makefile(".scenario.yaml", one=scene("one"))
    result = pytester.runpytest(f"{option}=")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    text = result.stderr.str() + result.stdout.str()
    assert f"{option}: an empty value; give one, or leave the option out" in text
    assert text.count("an empty value") == 1 and "Traceback" not in text

@pytest.mark.parametrize("first, second", [
    (["--rts-mapping", "a.mapping.yaml"], ["--rts-mapping=b.mapping.yaml"]),
    (["--rts-output=udp://127.0.0.1:5999"], ["--rts-output", "simulated-radar"]),
    (["--rts-method", "paper"], ["--rts-method", "exact"])])
def test_an_rts_option_given_twice_is_a_usage_error(pytester, first, second):
    # argparse kept the last: every scene was judged by the second mapping, or played to the
    # simulated radar instead of the bench, without a word (`rts-scenario run` refuses it).
    pytester.makefile(".scenario.yaml", one=scene("one"))
    result = pytester.runpytest(*first, *second)
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    text = result.stderr.str() + result.stdout.str()
    name = second[0].split("=")[0]
    assert f"{name}: given twice (" in text and "give it once" in text
    assert "Traceback" not in text


def test_an_rts_option_from_addopts_is_overridden_on_the_command_line(pytester, monkeypatch):
    # pytest's way to override an option its configuration gives: not a repeat. The values
    # overridden would each stop the session (no such mapping; an output nothing answers).
    pytester.makefile(".scenario.yaml", one=scene("one"))
    own = ROOT / "rts_scenario" / "data" / "can" / "rts_detections.mapping.yaml"
    pytester.makeini("[pytest]\naddopts = --rts-mapping /no/such.mapping.yaml\n")
    assert pytester.runpytest().ret == pytest.ExitCode.USAGE_ERROR
    pytester.runpytest("--rts-mapping", str(own)).assert_outcomes(passed=1)
    monkeypatch.setenv("PYTEST_ADDOPTS", "--rts-output udp://127.0.0.1:9")
    pytester.runpytest("--rts-mapping", str(own), "--rts-output",
                       "simulated-radar").assert_outcomes(passed=1)


def test_an_rts_option_twice_through_an_args_file_is_a_usage_error(pytester):
    # pytest reads arguments from @FILE, one per line: its repeats are the command line's.
    pytester.makefile(".scenario.yaml", one=scene("one"))
    pytester.makefile(".txt", args="--rts-method\npaper\n")
    result = pytester.runpytest("@args.txt", "--rts-method", "exact")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    assert "--rts-method: given twice ('paper', then 'exact')" in (result.stderr.str()
                                                                   + result.stdout.str())


def test_path_arguments_are_read_as_the_command_line(tmp_path):
    # pytest.main([Path(...)]) gives invocation_params.args as os.PathLike: the repeat check
    # took them for strings (INTERNALERROR).
    import pytest_rts_scenario as plugin

    plugin._refuse_repeats([tmp_path / "one.scenario.yaml", "--rts-method", "exact"])
    with pytest.raises(pytest.UsageError, match="--rts-method: given twice"):
        plugin._refuse_repeats([tmp_path, "--rts-method", "exact", "--rts-method=paper"])


def test_rts_run_finds_relative_paths_beside_the_test_file(pytester):
    sub = pytester.mkdir("sub")
    (sub / "data").mkdir()
    (sub / "data" / "near.scenario.yaml").write_text(scene("near"))
    (sub / "test_near.py").write_text(textwrap.dedent("""
        def test_relative(rts_run):
            assert rts_run("data/near.scenario.yaml").report.passed
    """))
    # The scene is the test's data, not a test of its own: its folder is not collected.
    pytester.makeini("[pytest]\nnorecursedirs = data\n")
    pytester.runpytest().assert_outcomes(passed=1)


def test_rts_run_of_a_parametrized_scene_needs_its_variant(pytester):
    pytester.mkdir("data")
    (pytester.path / "data" / "two.scenario.yaml").write_text(scene(
        "two", extra="parametrize:\n  radar.estimator: [bartlett, ti]\n"))
    pytester.makepyfile(test_two=textwrap.dedent("""
        import pytest
        from rts_scenario.errors import RtsError

        def test_without_variant(rts_run):
            with pytest.raises(RtsError, match="a parametrized scene [(]2 variants[)]: "
                                               "choose one with variant= ID: "
                                               "estimator=bartlett, estimator=ti"):
                rts_run("data/two.scenario.yaml")

        def test_with_variant(rts_run):
            result = rts_run("data/two.scenario.yaml", variant="estimator=ti")
            assert result.report.passed and result.report.variant == "estimator=ti"
    """))
    pytester.makeini("[pytest]\nnorecursedirs = data\n")
    pytester.runpytest().assert_outcomes(passed=2)

def test_failing_detection_rate_lists_worst_frames(pytester):
    pytester.makefile(".scenario.yaml", strict=scene("strict").replace(
        "detection_rate: 0.9", "detection_rate: 0.9\n  tolerances: {az_deg: 0.00001}"))
    result = pytester.runpytest()
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(["*car*FAIL*", "*worst frames (error / tolerance):*",
                                 "*frame*t_s*target*range*vel*az*el*"])


def test_worst_frames_are_error_over_tolerance_as_their_heading_says():
    """The worst frames' columns are each quantity's error divided by its tolerance."""
    from types import SimpleNamespace

    from pytest_rts_scenario import _render

    scene_ = SimpleNamespace(expectations=SimpleNamespace(tolerances={
        "range_m": 0.3, "radial_velocity_mps": 0.2, "az_deg": 0.004, "el_deg": 1.0,
        "rcs_db": 6.0}))
    row = {"frame": 7, "t_s": 0.35, "target": "car", "missed": False, "range_m": -0.15,
           "radial_velocity_mps": 0.05, "az_deg": -0.005, "el_deg": 0.25, "rcs_dbsm": 0.0}
    report = SimpleNamespace(label="s", reasons=["car: detection rate 0.0% < 90.0%"],
                             verdict_line="FAIL: s - car: detection rate 0.0% < 90.0%",
                             table=lambda verdict=True: "TABLE", worst_frames=[row])
    text = _render(SimpleNamespace(scene=scene_, report=report))
    heading, columns, line = text.splitlines()[4:7]
    assert heading == "worst frames (error / tolerance):"
    assert line.split() == ["7", "0.35", "car", "-0.500", "+0.250", "-1.250", "+0.250"]


def test_no_worst_frames_is_said_not_an_empty_table():
    # Nothing was judged (a target never checkable): no heading over no rows.
    from types import SimpleNamespace

    from pytest_rts_scenario import _render

    scene_ = SimpleNamespace(expectations=SimpleNamespace(tolerances={}))
    report = SimpleNamespace(label="s", reasons=["nothing to check"],
                             verdict_line="FAIL: s - nothing to check",
                             table=lambda verdict=True: "TABLE", worst_frames=[])
    text = _render(SimpleNamespace(scene=scene_, report=report))
    assert text.splitlines()[-1] == "worst frames: none (no target-frame was judged)"


def test_bad_scene_is_one_failing_item_naming_file_and_line(pytester):
    # One scene that does not load fails as one item, named after its file (as
    # `rts-scenario run` names it); the session still runs the others.
    pytester.makefile(".scenario.yaml", broken=scene("cut-in").replace("rig: wide-3x5",
                                                                       "rig: wide-3x9"),
                      fine=scene("fine"))
    result = pytester.runpytest("-rA")
    result.assert_outcomes(failed=1, passed=1)
    result.stdout.fnmatch_lines(["*broken.scenario.yaml:6:*rig: unknown preset 'wide-3x9'*",
                                 "FAILED broken.scenario.yaml::broken - error: *"])
    assert "Traceback" not in result.stdout.str()


def test_a_variant_that_does_not_load_fails_alone(pytester):
    # As in `rts-scenario run`: the other variants of the scene, and the other scenes, run.
    extra = "parametrize:\n  rig: [wide-3x5, wide-3x9]\n"
    pytester.makefile(".scenario.yaml", mixed=scene("mixed", extra=extra), fine=scene("fine"))
    result = pytester.runpytest("-rA")
    result.assert_outcomes(failed=1, passed=2)
    text = result.stdout.str()
    result.stdout.fnmatch_lines([
        "PASSED mixed.scenario.yaml::mixed[[]rig=wide-3x5[]]",
        "FAILED mixed.scenario.yaml::mixed[[]rig=wide-3x9[]] - error: *",
    ])
    # Located at the parametrize entry that put the value in place.
    assert ("mixed.scenario.yaml:16:3: rig: unknown preset 'wide-3x9'; valid presets: "
            "kit-table1, wide-3x5, or a relative path to a *.rig.yaml file [rig=wide-3x9]"
            in text)
    assert "Traceback" not in text and "Interrupted" not in text


@pytest.mark.parametrize("stage", ["load_scenario", "parametrizations"])
def test_a_scene_whose_loading_crashes_fails_alone(pytester, monkeypatch, stage):
    # A bug met while loading one scene (not bad input: no located message for it) fails that
    # scene's item with its traceback; it does not stop the session as a collection error,
    # which would run none of the other scenes (`rts-scenario run` and `sweep` run them too).
    import rts_scenario.scenario

    real = getattr(rts_scenario.scenario, stage)

    def crashes_on_buggy(path, *args):
        if Path(path).name.startswith("buggy"):
            raise ZeroDivisionError("a bug in the loader")
        return real(path, *args)

    monkeypatch.setattr(rts_scenario.scenario, stage, crashes_on_buggy)
    pytester.makefile(".scenario.yaml", buggy=scene("buggy"), fine=scene("fine"))
    result = pytester.runpytest("-rA")
    result.assert_outcomes(failed=1, passed=1)
    assert result.ret == pytest.ExitCode.TESTS_FAILED
    result.stdout.fnmatch_lines(["FAILED buggy.scenario.yaml::buggy - ZeroDivisionError: a bug*"])
    assert "Traceback" in result.stdout.str() or "crashes_on_buggy" in result.stdout.str()
    assert "error during collection" not in result.stdout.str()


def test_a_scene_its_rig_cannot_play_names_the_scene_file_and_line(pytester):
    # Frames faster than the rig's update rate: the error names the file, line and key.
    pytester.makefile(".scenario.yaml", fast=scene("fast").replace("frame_rate_hz: 20.0",
                                                                   "frame_rate_hz: 200.0"))
    result = pytester.runpytest()
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines([f"error: {pytester.path / 'fast.scenario.yaml'}:*: frame_rate_hz: "
                                 "the scene runs at 200 Hz but rig 'wide-3x5' updates at most "
                                 "100 Hz*"])
    assert "Traceback" not in result.stdout.str()


def test_a_variant_that_does_not_load_keeps_the_scene_s_marks(pytester):
    # A bench-only scene whose lab rig is missing here: deselected with its marks, not failed.
    extra = "parametrize:\n  rig: [wide-3x5, lab.rig.yaml]\nmarks: [hardware, lab_only]\n"
    pytester.makefile(".scenario.yaml", bench=scene("bench", extra=extra), fine=scene("fine"))
    result = pytester.runpytest("-rA", "-m", "not hardware")
    result.assert_outcomes(passed=1, deselected=2)
    result = pytester.runpytest("-rA", "--strict-markers", "-m", "lab_only")
    result.assert_outcomes(passed=1, failed=1, deselected=1)
    result.stdout.fnmatch_lines(["FAILED bench.scenario.yaml::bench[[]rig=lab.rig.yaml[]] - *"])


def test_a_bad_parametrize_block_is_one_failing_item(pytester):
    extra = "parametrize:\n  radar.estimator: ti\n"
    pytester.makefile(".scenario.yaml", block=scene("block", extra=extra), fine=scene("fine"))
    result = pytester.runpytest("-rA")
    result.assert_outcomes(failed=1, passed=1)
    result.stdout.fnmatch_lines(["*block.scenario.yaml:16:3: parametrize.radar.estimator: "
                                 "must be of type array, got 'ti'*"])
    assert "Traceback" not in result.stdout.str()


def test_an_xfail_scene_expects_its_check_to_fail_not_its_file_to_break(pytester):
    # `marks: [xfail]` declares a known failure of the radar's check: a scene that then does
    # not load, or a variant that does not, is an error of its own and fails the session.
    extra = "marks: [xfail]\nparametrize:\n  rig: [wide-3x5, wide-3x9]\n"
    known = scene("known").replace("[30, 0, 0.6]", "[30, 20, 0.6]")  # never detected
    pytester.makefile(".scenario.yaml", known=known + "marks: [xfail]\n",
                      broken=scene("broken", extra="marks: [xfail]\ncolour: red\n"),
                      mixed=known.replace("name: known", "name: mixed") + extra)
    result = pytester.runpytest("-rA")
    result.assert_outcomes(xfailed=2, failed=2)
    result.stdout.fnmatch_lines(["XFAIL known.scenario.yaml::known*",
                                 "XFAIL mixed.scenario.yaml::mixed[[]rig=wide-3x5[]]*"])
    result.stdout.fnmatch_lines(["FAILED broken.scenario.yaml::broken - error: *",
                                 "FAILED mixed.scenario.yaml::mixed[[]rig=wide-3x9[]] - error: *"])
    result.stdout.fnmatch_lines(["error: *broken.scenario.yaml:*: colour: unknown key*"])
    assert result.ret == pytest.ExitCode.TESTS_FAILED


def test_a_mark_pytest_cannot_take_is_refused_by_the_scene_loader(pytester):
    # pytest refuses marks starting with an underscore: the scene format refuses them first.
    pytester.makefile(".scenario.yaml", under=scene("under", extra="marks: [_private]\n"),
                      fine=scene("fine"))
    result = pytester.runpytest("-rA")
    result.assert_outcomes(failed=1, passed=1)
    result.stdout.fnmatch_lines(["*under.scenario.yaml:15:*marks*_private*"])
    assert "Traceback" not in result.stdout.str()


def test_bad_rts_can_interface_stops_the_session_once(pytester):
    for name in ("one", "two"):
        pytester.makefile(".scenario.yaml", **{name: scene(name)})
    result = pytester.runpytest("--rts-can-interface", "nonsense")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    text = result.stderr.str() + result.stdout.str()
    assert text.count("--rts-can-interface 'nonsense': unknown python-can interface") == 1
    assert "socketcan" in text and "Traceback" not in text
    # udp_multicast needs a multicast group: a private channel name would reach no one.
    result = pytester.runpytest("--rts-can-interface", "udp_multicast")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    text = result.stderr.str() + result.stdout.str()
    assert "--rts-can-interface udp_multicast needs --rts-can-channel" in text
    result = pytester.runpytest("--rts-can-interface", "udp_multicast",
                                "--rts-can-channel", "can0")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    assert "--rts-can-channel 'can0': udp_multicast needs" in (result.stderr.str()
                                                               + result.stdout.str())


def test_a_can_interface_that_cannot_be_opened_stops_the_session_once(pytester):
    """Each scene failed on its own with "cannot open CAN interface"."""
    for name in ("one", "two"):
        pytester.makefile(".scenario.yaml", **{name: scene(name)})
    result = pytester.runpytest("--rts-can-interface", "socketcan", "--rts-can-channel",
                                "rts-no-such0")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    text = result.stderr.str() + result.stdout.str()
    assert text.count("--rts-can-interface socketcan --rts-can-channel rts-no-such0: cannot "
                      "open CAN interface 'socketcan' channel 'rts-no-such0'") == 1
    assert "Traceback" not in text


def test_a_scene_with_a_mistyped_suffix_fails_instead_of_being_left_out(pytester):
    # A file holding a scene (its rts_scenario key) but not named *.scenario.yaml is not run
    # as one: without an item for it, the session would be green with the scene never played.
    # Fragments and other kinds of file are no scenes and stay uncollected.
    pytester.makefile(".scenario.yaml", fine=scene("fine"))
    pytester.makefile(".scenario.yml", typo=scene("typo"))
    pytester.makefile(".yaml", plain=scene("plain"))
    pytester.makefile(".yaml", parked="targets:\n  - name: parked\n")
    pytester.makefile(".rig.yaml", lab=(ROOT / "scenarios" / "rigs" / "lab-2x3.rig.yaml"
                                        ).read_text())
    result = pytester.runpytest("-rA")
    result.assert_outcomes(passed=1, failed=2)
    result.stdout.fnmatch_lines([
        f"*error: {pytester.path / 'plain.yaml'} holds a scene (its rts_scenario key) but is "
        f"not named *.scenario.yaml, so it does not run as one; rename it plain.scenario.yaml",
        f"*error: {pytester.path / 'typo.scenario.yml'} holds a scene (its rts_scenario key) "
        f"but is not named *.scenario.yaml, so it does not run as one; rename it "
        f"typo.scenario.yaml"])
    assert "Traceback" not in result.stdout.str()
    # A pattern of one's own names the scene files; a scene under another name is still no
    # scene left out unseen (scenes are chosen by their marks, -m, or folders, norecursedirs).
    pytester.makeini("[pytest]\nrts_scenario_pattern = fine.*\n")
    result = pytester.runpytest("-rA")
    result.assert_outcomes(passed=1, failed=2)
    result.stdout.fnmatch_lines([
        f"*error: {pytester.path / 'plain.yaml'} holds a scene (its rts_scenario key) but is "
        f"not named fine.* (the project's rts_scenario_pattern), so it does not run as one; "
        f"rename it to match that pattern"])


def test_a_project_s_own_yaml_with_an_rts_scenario_section_is_no_misnamed_scene(pytester):
    # A scene's rts_scenario key is its format version, a number. A project's settings file
    # may keep its own section under that name (a mapping, block or flow), or a list; neither
    # is a scene, and a session with them is as green as without.
    pytester.makefile(".scenario.yaml", fine=scene("fine"))
    pytester.makefile(".yaml", bench="rts_scenario:\n  interface: pcan\n  channel: 1\n",
                      flow="rts_scenario: {interface: pcan}  # the bench's\n",
                      listed="rts_scenario:\n- cut_in\n- cut_out\n",
                      nested="lab:\n  rts_scenario: 1\n")
    pytester.makefile(".yml", commented="rts_scenario:   # our settings\n  seed: 4\n")
    result = pytester.runpytest("-rA")
    result.assert_outcomes(passed=1)
    # A scene's version written as a scene writes it is one, whatever follows it.
    pytester.makefile(".yaml", quoted=scene("quoted").replace("rts_scenario: 1",
                                                              "rts_scenario: '1'  # v1"))
    pytester.runpytest().assert_outcomes(passed=1, failed=1)


@pytest.mark.skipif(sys.platform == "win32", reason="symbolic links")
def test_a_scene_link_that_leads_nowhere_fails_instead_of_being_left_out(pytester):
    # A scene linked from elsewhere (a shared folder, a checkout not made): pytest walks past a
    # link to nothing, and the session would be green with that scene never played.
    pytester.makefile(".scenario.yaml", fine=scene("fine"))
    (pytester.path / "sub").mkdir()
    (pytester.path / "sub" / "gone.scenario.yaml").symlink_to("../shared/gone.scenario.yaml")
    result = pytester.runpytest("-rA")
    result.assert_outcomes(passed=1, failed=1)
    gone = pytester.path / "sub" / "gone.scenario.yaml"
    result.stdout.fnmatch_lines([f"error: {gone}: cannot read file: a link to "
                                 f"../shared/gone.scenario.yaml, which does not exist"])


def test_pattern_is_configurable(pytester):
    pytester.makefile(".yml", odd=scene("odd"))
    pytester.makeini("[pytest]\nrts_scenario_pattern = *.yml\n")
    pytester.runpytest().assert_outcomes(passed=1)


def test_junit_properties_and_rts_run_fixture(pytester):
    pytester.makefile(".scenario.yaml", follow=scene("follow"))
    pytester.makepyfile(test_api="""
        def test_fixture(rts_run, pytestconfig):
            import pathlib
            result = rts_run(pathlib.Path(str(pytestconfig.rootpath)) / "follow.scenario.yaml")
            assert result.report.passed
            assert result.report.frames["checked"] == 40
    """)
    result = pytester.runpytest("--junitxml=out.xml")
    result.assert_outcomes(passed=2)
    xml = (pytester.path / "out.xml").read_text()
    assert 'name="detection_rate"' in xml and 'name="az_deg_rms"' in xml


def test_junit_says_why_a_scene_failed_or_was_skipped(pytester):
    """Each failed or skipped scene's testcase has a ``reasons`` property, the reason codes
    (docs/report.md), comma-separated; a skipped scene's <skipped> gives its reason."""
    import xml.etree.ElementTree as ET

    pytester.makefile(".scenario.yaml", **{
        "a_pass": scene("a-pass"),
        # Far outside the rig's coverage: never played, nothing checkable.
        "b_fail": scene("b-fail").replace("[30, 0, 0.6]", "[30, 20, 0.6]"),
        "c_parked": scene("c-parked", extra="marks: [skip]\n"),
        "d_shelved": scene("d-shelved", extra="marks: [skipif]\n"),
        # The radar's check fails (an azimuth tolerance no radar meets): what xfail expects.
        "e_known": scene("e-known", extra="marks: [xfail]\n").replace(
            "  detection_rate: 0.9\n", "  detection_rate: 0.9\n  tolerances: {az_deg: 1.0e-6}\n"),
        "f_broken": scene("f-broken", extra="colour: red\n"),
        # Its check passes under xfail, with xfail_strict: pytest fails it.
        "g_strict": scene("g-strict", extra="marks: [xfail]\n"),
    })
    result = pytester.runpytest("--junitxml=out.xml", "-o", "xfail_strict=true")
    result.assert_outcomes(passed=1, failed=3, skipped=2, xfailed=1)
    cases = {case.get("name"): case
             for case in ET.parse(pytester.path / "out.xml").getroot().iter("testcase")}

    def properties(name):
        return {p.get("name"): p.get("value") for p in cases[name].iter("property")}

    assert "reasons" not in properties("a-pass")
    assert properties("b-fail")["reasons"] == "out_of_coverage,nothing_checked"
    assert properties("e-known")["reasons"] == "detection_rate,false_detections"
    assert properties("f_broken")["reasons"] == "bad_input"
    assert properties("g-strict")["reasons"] == "xpass_strict"
    for name, mark in (("c-parked", "skip"), ("d-shelved", "skipif")):
        assert properties(name) == {"reasons": mark}
        assert cases[name].find("skipped").get("message") == f"the scene's marks: {mark}"


def test_xdist_gives_the_same_verdicts(pytester):
    for name in ("cut_in", "highway_following", "hard_quad_sweep", "overtaking"):
        shutil.copy(ROOT / "scenarios" / f"{name}.scenario.yaml", pytester.path)
    pytester.makefile(".scenario.yaml", impossible=scene("impossible").replace(
        "[30, 0, 0.6]", "[30, 20, 0.6]"))
    # (pytest-benchmark has nothing to measure here and warns under xdist: keep it out.)
    serial = pytester.runpytest("-n", "0", "-q", "-rA", "-p", "no:benchmark")
    parallel = pytester.runpytest("-n", "2", "-q", "-rA", "-p", "no:benchmark")

    def verdicts(result):
        return sorted(line.split(" ", 1) for line in result.stdout.lines
                      if line.startswith(("PASSED ", "FAILED ")))

    assert verdicts(serial) == verdicts(parallel)
    parallel.assert_outcomes(passed=5, failed=1)


def _closed_udp_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@pytest.mark.parametrize("declared", ["", "  expected_limits: [frames_lost]\n"])
def test_an_xfail_scene_the_bench_never_played_fails(pytester, monkeypatch, declared):
    # `xfail` expects the radar's check to fail; a run whose datagrams reached no RTS and whose
    # radar said nothing checked no radar, and was an expected failure with the bench unplugged.
    # The session under test runs in this process: not as a worker of this run's own xdist
    # (which refuses a bench output).
    for name in ("PYTEST_XDIST_WORKER", "PYTEST_XDIST_WORKER_COUNT"):
        monkeypatch.delenv(name, raising=False)
    # A scene that declares frames_lost (an RTS that drops some) has no rts_unreachable
    # reason: nothing listening is no RTS all the same.
    text = scene("known", extra="marks: [xfail]\n").replace("  detection_rate: 0.9\n",
                                                             "  detection_rate: 0.9\n" + declared)
    pytester.makefile(".scenario.yaml", known=text)
    result = pytester.runpytest("-rA", "--rts-output", f"udp://127.0.0.1:{_closed_udp_port()}")
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(["the scene's xfail mark expects the radar's check to fail, not "
                                 "the bench: bus_silent, rts_unreachable",
                                 "FAILED known.scenario.yaml::known - the scene's xfail mark*"])


@pytest.mark.parametrize("filters", [(), ("-W", "error")])
def test_a_combination_over_the_simulated_radar_s_options_on_a_bench_is_warned(pytester,
                                                                              monkeypatch,
                                                                              filters):
    # cut-in[estimator=ti] got its own verdict on a bench whose radar never ran ti. Under
    # `-W error` the note was raised in the item: a long traceback, the scene never played.
    for name in ("PYTEST_XDIST_WORKER", "PYTEST_XDIST_WORKER_COUNT"):
        monkeypatch.delenv(name, raising=False)
    extra = "parametrize:\n  radar.estimator: [ti]\n"
    pytester.makefile(".scenario.yaml", known=scene("known", extra=extra))
    port = _closed_udp_port()
    result = pytester.runpytest("-rA", "--rts-output", f"udp://127.0.0.1:{port}", *filters)
    result.assert_outcomes(failed=1, warnings=1)
    # Played, and failed as the bench failed it (no RTS listening), not on the note.
    result.stdout.fnmatch_lines(["*rts_unreachable*"])
    assert "Traceback" not in result.stdout.str()
    result.stdout.fnmatch_lines([f"*BenchSettingWarning: known[[]estimator=ti[]]: "
                                 f"radar.estimator set the built-in simulated radar; on the "
                                 f"bench (udp://127.0.0.1:{port}) the radar measures as it is "
                                 f"set, so this combination runs as the others do*"])


@pytest.mark.parametrize("workers", [("-n", "2"), ("-d", "--tx", "2*popen")])
@pytest.mark.parametrize("options", [
    ("--rts-can-interface", "udp_multicast", "--rts-can-channel", "239.74.163.2"),
    ("--rts-output", "udp://127.0.0.1:45871"),
])
def test_xdist_workers_sharing_one_bench_are_refused(pytester, monkeypatch, options, workers):
    # One bench (an RTS on UDP, a bus other processes hear) driven by two workers at once
    # would mix their frames and their radars' detections: each verdict judged the other's.
    # Two workers as -n 2 or xdist's --tx 2*popen (which each worker refused with a traceback).
    # The session under test runs in this process: not as a worker of this run's own xdist.
    for name in ("PYTEST_XDIST_WORKER", "PYTEST_XDIST_WORKER_COUNT"):
        monkeypatch.delenv(name, raising=False)
    pytester.makefile(".scenario.yaml", one=scene("one"), two=scene("two"))
    result = pytester.runpytest(*workers, "-p", "no:benchmark", *options)
    text = result.stderr.str() + result.stdout.str()
    assert result.ret == pytest.ExitCode.USAGE_ERROR, text
    assert f"{options[0]} {options[1]} with 2 xdist workers" in text
    assert "one bench" in text and "-n 0" in text and "Traceback" not in text


def test_importing_the_plugin_leaves_the_library_alone():
    import pytest_rts_scenario

    # The same plugin and library as this test run, whatever is installed.
    path = [str(Path(pytest_rts_scenario.__file__).parents[1]), str(ROOT),
            os.environ.get("PYTHONPATH", "")]
    heavy = ("rts_scenario.pipeline", "scipy", "can", "cantools")
    code = f"import sys, pytest_rts_scenario; print([m for m in {heavy!r} if m in sys.modules])"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            env={**os.environ, "PYTHONPATH": os.pathsep.join(path)}, check=True)
    assert result.stdout.strip() == "[]"


def test_html_report_embeds_a_failed_scene_s_plots_and_table(pytester):
    pytest.importorskip("pytest_html")
    try:
        # Imported here, once, for the same reason as the library (extension modules).
        import matplotlib.pyplot  # noqa: F401
        plots = True
    except ImportError:
        plots = False
    text = scene("strict").replace("detection_rate: 0.9",
                                   "detection_rate: 0.9\n  tolerances: {az_deg: 0.00001}")
    pytester.makefile(".scenario.yaml", strict=text, follow=scene("follow"))
    result = pytester.runpytest("--html", "report.html", "--self-contained-html")
    result.assert_outcomes(failed=1, passed=1)
    html = (pytester.path / "report.html").read_text()
    # The table `rts-scenario run` prints, with the failing target's row.
    assert html.count("rts-scenario-report") == 1  # the passing scene carries none
    assert "det. rate" in html and "radar cycles: " in html
    assert "FAIL: strict" in html
    if plots:
        # scene, schedule and errors over time, as base64 PNG inside the page
        assert html.count("data:image/png;base64,iVBORw0KGgo") == 3
    else:
        assert "No plots: they need matplotlib" in html


def test_without_an_html_report_nothing_is_recorded_or_added(pytester):
    pytester.makefile(".scenario.yaml", impossible=scene("impossible").replace(
        "[30, 0, 0.6]", "[30, 20, 0.6]"))
    pytester.makeconftest("""
        import pytest

        @pytest.hookimpl(trylast=True)
        def pytest_runtest_logreport(report):
            if report.when == "call":
                assert not getattr(report, "extras", [])
    """)
    result = pytester.runpytest()
    result.assert_outcomes(failed=1)
    assert not pytester.parseconfig().pluginmanager.hasplugin("rts-scenario-html")


def test_an_unknown_jit_setting_stops_the_session_once(pytester, monkeypatch):
    """Each scene failed on its own with the same message."""
    for name in ("one", "two"):
        pytester.makefile(".scenario.yaml", **{name: scene(name)})
    monkeypatch.setenv("RTS_SCENARIO_JIT", "onn")
    result = pytester.runpytest()
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    text = result.stderr.str() + result.stdout.str()
    assert text.count("RTS_SCENARIO_JIT='onn': unknown value; allowed: auto, on, off") == 1


def test_a_marked_scene_whose_parametrize_block_is_broken_is_selected_by_its_marks(pytester):
    # `-m slow` deselected a slow scene whose parametrize block did not expand (its item had
    # no marks), so a nightly `-m slow` job never saw it fail.
    pytester.makefile(".scenario.yaml", **{
        "ok": scene("ok", extra="marks: [slow]\n"),
        "empty_list": scene("empty-list", extra="marks: [slow]\nparametrize:\n"
                                                "  targets.0.rcs.rcs_dbsm: []\n"),
        "fast": scene("fast", extra="parametrize:\n  targets.0.rcs.rcs_dbsm: []\n"),
    })
    result = pytester.runpytest("-m", "slow", "-p", "no:cacheprovider")
    result.assert_outcomes(passed=1, failed=1, deselected=1)
    result.stdout.fnmatch_lines(["FAILED empty_list.scenario.yaml::empty_list*"])


@pytest.mark.parametrize("pattern", ["", "[", "*.py", "scenes/*.yaml"])
def test_a_scene_pattern_that_names_no_scene_files_is_refused_up_front(pytester, pattern):
    # Empty, every scene failed as misnamed "not named  (the project's ...)"; *.py took test
    # modules for scenes and told the scenes to be renamed .py.
    pytester.makefile(".scenario.yaml", fine=scene("fine"))
    pytester.makeini(f"[pytest]\nrts_scenario_pattern = {pattern}\n")
    result = pytester.runpytest()
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    result.stderr.fnmatch_lines([f"*: rts_scenario_pattern = {pattern.strip()!r}: must be a glob "
                                 f"of scene file names that can end in .yaml or .yml, without "
                                 f"a folder (default *.scenario.yaml)"])


def test_a_scene_played_to_an_rts_plays_with_the_session_s_heap_frozen(pytester, monkeypatch):
    # As a command plays it (`rts_scenario.startup`): no full collection of a long session's
    # objects holds the frame sender mid-scene; they are collected again after it. The
    # built-in simulated radar keeps no wall-clock time: its scenes play as they are.
    import gc

    real, seen = rts_scenario.pipeline.run_scene, []

    def recording(*args, **kwargs):
        seen.append(gc.get_freeze_count())
        return real(*args, **kwargs)

    monkeypatch.setattr(rts_scenario.pipeline, "run_scene", recording)
    pytester.makefile(".scenario.yaml", one=scene("one"))
    pytester.makepyfile(test_fixture="""
        def test_it(rts_run):
            rts_run("one.scenario.yaml")
    """)
    pytester.runpytest()
    assert seen == [0, 0]
    # No RTS listens there (the runs fail on it): what matters is how they were played. The
    # session under test is not one of this run's xdist workers (which refuse a bench output).
    for name in ("PYTEST_XDIST_WORKER", "PYTEST_XDIST_WORKER_COUNT"):
        monkeypatch.delenv(name, raising=False)
    result = pytester.runpytest("--rts-output", f"udp://127.0.0.1:{_closed_udp_port()}")
    assert len(seen) == 4, result.stdout.str()
    assert all(count > 1000 for count in seen[2:])
    assert gc.get_freeze_count() == 0
