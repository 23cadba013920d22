"""``rts-scenario sweep``: combinations, verdicts in every place they run, summary, JSON."""

import io
import json
import sys
import textwrap
from collections import Counter
from pathlib import Path

import pytest

# pytester runs pytest in this process and drops the modules a run imported; numpy's and
# scipy's extension modules cannot load twice, so the library is imported here, once.
import rts_scenario.pipeline  # noqa: F401
from rts_scenario.cli import main
from rts_scenario.cli.sweep import SweepProgress
from rts_scenario.sweep import collect_tasks, run_sweep, summarize

pytest_plugins = ["pytester"]
ROOT = Path(__file__).resolve().parents[1]

# Two of the six combinations put the car 20 m to the side, outside the rig's coverage, and the
# scene does not declare that limit: those runs fail by design.
OFFSETS_M = [0.0, 2.0, 20.0]
RCS_DBSM = [5.0, 10.0]


def tiny_scene(name: str, parametrize: str = "") -> str:
    """Half a second at 20 Hz on the analytic simulated radar: a run takes a few 10 ms."""
    return textwrap.dedent(f"""\
        rts_scenario: 1
        name: {name}
        duration_s: 0.5
        frame_rate_hz: 20.0
        radar: {{profile: awr1843boost, mount: {{x_m: 3.7, z_m: 0.5}}, fidelity: analytic}}
        rig: wide-3x5
        ego:
          motion: {{type: constant_velocity, position_m: [0, 0, 0], speed_mps: 20.0}}
        targets:
          - name: car
            motion: {{type: constant_velocity, position_m: [30, 0, 0.6], speed_mps: 19.0}}
            rcs: {{rcs_dbsm: 10.0}}
        """) + parametrize


SWEPT = tiny_scene("swept", "parametrize:\n"
                            f"  targets.0.motion.position_m.1: {OFFSETS_M}\n"
                            f"  targets.0.rcs.rcs_dbsm: {RCS_DBSM}\n")
OFFSET_KEY = "targets.0.motion.position_m.1"
RCS_KEY = "targets.0.rcs.rcs_dbsm"


@pytest.fixture
def scenes(tmp_path):
    """A folder: the swept scene, a plain one in a subfolder and a scene that does not load."""
    (tmp_path / "b_swept.scenario.yaml").write_text(SWEPT)
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "a_plain.scenario.yaml").write_text(tiny_scene("plain"))
    (tmp_path / "c_broken.scenario.yaml").write_text(tiny_scene("broken") + "colour: red\n")
    return tmp_path


def sweep(capsys, *args):
    code = main(["sweep", *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


def verdicts(payload):
    """What must not depend on where a run ran: all but its duration and its plan's origin."""
    return [{k: v for k, v in run.items() if k not in ("seconds", "solver_plan")}
            for run in payload["runs"]]


def test_verdicts_are_identical_in_process_in_a_pool_and_on_dask(scenes, tmp_path, capsys):
    swept = scenes / "b_swept.scenario.yaml"
    payloads = []
    places = [["--workers", "1"], ["--workers", "2"]]
    try:
        import distributed  # noqa: F401

        # One worker process: the cluster starts in a few seconds and runs the same
        # `run_task` in another process, as a remote worker would.
        places.append(["--scheduler", "local", "--workers", "1"])
    except ImportError:
        pass
    for i, place in enumerate(places):
        out = tmp_path / f"sweep-{i}.json"
        code, _, _ = sweep(capsys, swept, "--json", out, *place)
        assert code == 1  # two runs fail by design
        payloads.append(json.loads(out.read_text()))
    first = verdicts(payloads[0])
    assert [r["status"] for r in first] == ["pass", "pass", "pass", "pass", "fail", "fail"]
    for payload in payloads[1:]:
        assert verdicts(payload) == first
        assert payload["summary"] == payloads[0]["summary"]
    # The plan was built (or read) once before the pool started; forked workers inherit it.
    assert {r["solver_plan"] for r in payloads[1]["runs"]} == {"memory"}
    # A Dask worker reads it from the disk cache once, then keeps it in memory.
    for payload in payloads[2:]:
        assert Counter(r["solver_plan"] for r in payload["runs"]) == {"disk": 1, "memory": 5}


def test_json_layout_and_summary_counted_independently(scenes, tmp_path, capsys):
    out = tmp_path / "sweep.json"
    code, stdout, _ = sweep(capsys, scenes, "--json", out, "--workers", "1")
    assert code == 2  # the broken scene is bad input; the others still ran
    payload = json.loads(out.read_text())
    assert set(payload) == {"runs", "summary", "config"}
    runs = payload["runs"]
    # Folder order: sorted paths, recursively; combinations in parametrize order.
    assert [(Path(r["file"]).name, r["id"]) for r in runs] == (
        [("b_swept.scenario.yaml", f"1={y}-rcs_dbsm={rcs}") for y in OFFSETS_M
         for rcs in RCS_DBSM]
        + [("c_broken.scenario.yaml", ""), ("a_plain.scenario.yaml", "")])
    for run in runs:
        assert {"scene", "file", "parameters", "passed", "status"} <= set(run)
        assert run["status"] in ("pass", "fail", "error")
        assert run["passed"] == (run["status"] == "pass")
    swept = [r for r in runs if r["scene"] == "swept"]
    assert [r["parameters"] for r in swept] == [{OFFSET_KEY: y, RCS_KEY: rcs}
                                                for y in OFFSETS_M for rcs in RCS_DBSM]
    for r in swept:
        assert r["status"] == ("fail" if r["parameters"][OFFSET_KEY] == 20.0 else "pass")
        if r["status"] == "fail":
            assert "out_of_coverage" in r["reason"]
        else:
            assert r["errors"]["az_deg"]["max"] < 0.5
    broken = runs[6]
    assert broken["status"] == "error" and broken["error_type"] == "bad_input"
    assert "c_broken.scenario.yaml:" in broken["reason"] and "colour" in broken["reason"]
    assert "\n" not in broken["reason"]
    assert runs[7]["scene"] == "plain" and runs[7]["status"] == "pass"

    summary = payload["summary"]
    statuses = Counter(r["status"] for r in runs)
    assert (summary["runs"], summary["passed"], summary["failed"], summary["errors"]) == (
        8, statuses["pass"], statuses["fail"], statuses["error"])
    assert summary["pass_rate"] == pytest.approx(5 / 8)
    expected: dict = {}
    for r in runs:
        for key, value in r["parameters"].items():
            counts = expected.setdefault(key, {}).setdefault(str(value), Counter())
            counts["runs"] += 1
            counts[{"pass": "passed", "fail": "failed"}.get(r["status"], "errors")] += 1
    got = {key: {value: Counter({k: v for k, v in c.items() if k != "pass_rate" and v})
                 for value, c in values.items()} for key, values in summary["by_parameter"].items()}
    assert got == expected
    assert summary["by_parameter"][OFFSET_KEY]["20.0"]["pass_rate"] == 0.0
    # The worst runs: the error, then the failures, then the passes by error over tolerance.
    assert [w["status"] for w in summary["worst"][:3]] == ["error", "fail", "fail"]
    ratios = [w["max_error_ratio"] for w in summary["worst"][3:]]
    assert ratios == sorted(ratios, reverse=True)

    assert f"{OFFSET_KEY}=20.0: 0/2" in stdout
    assert "rcs_dbsm=5.0: 2/3" in stdout
    assert "pass rate 62.5%" in stdout
    assert "ERROR broken" not in stdout  # it never loaded: named after its file
    assert "ERROR c_broken (" in stdout


def test_worst_passing_runs_are_those_with_the_largest_error_ratio():
    """A passing run with no error to rate (an empty bench) is not among the worst passes:
    the JSON's worst runs and the printed ones are the same runs."""
    from rts_scenario.cli.sweep import _summary_text

    def run(name, status, ratio):
        return {"scene": name, "file": f"{name}.scenario.yaml", "id": "", "parameters": {},
                "passed": status == "pass", "status": status, "max_error_ratio": ratio,
                "max_error_quantity": "az_deg" if ratio is not None else None,
                **({"reason": "why"} if status != "pass" else {})}

    entries = [run("empty", "pass", None), run("close", "pass", 0.9), run("far", "pass", 0.2),
               run("lost", "fail", None), run("off", "fail", 2.5)]
    three = summarize(entries, worst=3)
    assert [w["scene"] for w in three["worst"]] == ["lost", "off", "close"]
    for summary in (three, summarize(entries)):
        text = _summary_text(summary, 1.0)
        printed = [line.split()[1] for line in text.splitlines()[text.splitlines().index(
            "worst runs:") + 1:]]
        assert printed == [w["scene"] for w in summary["worst"]]
    assert printed == ["lost", "off", "close", "far"]


def test_a_parameter_value_json_cannot_hold_is_bad_input_and_the_json_is_written(scenes,
                                                                                  tmp_path,
                                                                                  capsys):
    # YAML reads 2024-01-01 as a date: writing the JSON failed after every run had finished.
    dated = scenes / "d_dated.scenario.yaml"
    dated.write_text(tiny_scene("dated", "parametrize:\n  description: [2024-01-01, x]\n"))
    out = tmp_path / "dated.json"
    code, stdout, err = sweep(capsys, dated, scenes / "sub", "--workers", "1", "--json", out)
    assert code == 2 and "Traceback" not in err and "TypeError" not in err
    runs = json.loads(out.read_text())["runs"]
    assert [(r["scene"], r["status"]) for r in runs] == [("d_dated", "error"), ("plain", "pass")]
    assert runs[0]["reason"].startswith(f"{dated}:14:")
    assert "parametrize.description[0]: got a date (2024-01-01)" in runs[0]["reason"]


def test_exit_codes(scenes, tmp_path, capsys, monkeypatch):
    plain = scenes / "sub" / "a_plain.scenario.yaml"
    assert sweep(capsys, plain, "--workers", "1")[0] == 0
    assert sweep(capsys, scenes / "b_swept.scenario.yaml", "--workers", "1")[0] == 1
    assert sweep(capsys, scenes / "c_broken.scenario.yaml", plain, "--workers", "1")[0] == 2
    assert sweep(capsys, tmp_path / "missing.scenario.yaml", "--workers", "1")[0] == 2
    code, _, err = sweep(capsys, plain, "--workers", "0")
    assert code == 2 and err.strip() == "error: --workers: must be >= 1, got 0"


    real = rts_scenario.pipeline.run_scene

    def flaky(scene, options):
        if scene.name == "plain":
            raise RuntimeError("the bench fell over")
        return real(scene, options)

    monkeypatch.setattr(rts_scenario.pipeline, "run_scene", flaky)
    out = tmp_path / "flaky.json"
    code, stdout, err = sweep(capsys, scenes, "--workers", "1", "--json", out)
    assert code == 3
    runs = json.loads(out.read_text())["runs"]
    assert len(runs) == 8  # nothing lost
    [crashed] = [r for r in runs if r["scene"] == "plain"]
    assert crashed["status"] == "error" and crashed["error_type"] == "runtime"
    assert "RuntimeError: the bench fell over" in crashed["reason"]
    assert "Traceback" not in stdout + err


def test_an_erred_point_has_every_quantity_null_and_its_error(scenes, tmp_path, capsys,
                                                               monkeypatch):
    """A point that erred measured nothing: its quantities are null, never a number a tool
    would read as a result, and its entry says why (``reason``, ``error_type``)."""
    from rts_scenario.sweep import error_entry

    # The quantities a finished run gives (docs/cli.md, sweep's keys of a run).
    quantities = ("detection_rate", "false_detections", "errors", "max_error_ratio",
                  "max_error_quantity")
    real = rts_scenario.pipeline.run_scene

    def second_point_fails(scene, options):
        if scene.variant.endswith("rcs_dbsm=10.0"):
            raise RuntimeError("the bench fell over")
        return real(scene, options)

    monkeypatch.setattr(rts_scenario.pipeline, "run_scene", second_point_fails)
    out = tmp_path / "sweep.json"
    code, _, _ = sweep(capsys, scenes, "--workers", "1", "--json", out)
    assert code == 3
    runs = json.loads(out.read_text())["runs"]
    erred = [r for r in runs if r["status"] == "error"]
    assert {(r["scene"], r["error_type"]) for r in erred} == {("swept", "runtime"),
                                                               ("c_broken", "bad_input")}
    for run in erred:
        assert {k: run[k] for k in quantities} == dict.fromkeys(quantities), run
        assert run["reason"]
    passed = [r for r in runs if r["status"] == "pass"]
    assert passed and all(isinstance(r["detection_rate"], float) for r in passed)
    # Numbers an entry held before its run erred do not survive into the erred entry.
    stale = {"scene": "s", "file": "s.scenario.yaml", "id": "", "parameters": {}, "marks": [],
             "detection_rate": 1.0, "false_detections": 0, "errors": {"az_deg": {"rms": 0.1,
             "max": 0.2}}, "max_error_ratio": 0.4, "max_error_quantity": "az_deg"}
    entry = error_entry(stale, "s.scenario.yaml: worker failed", "runtime")
    assert {k: entry[k] for k in quantities} == dict.fromkeys(quantities)
    assert entry["reason"] == "s.scenario.yaml: worker failed" and not entry["passed"]


def test_a_scene_whose_combinations_cannot_be_listed_for_a_bug_loses_no_other_run(
        scenes, tmp_path, capsys, monkeypatch):
    # Listing a scene's combinations raised something else than bad input: that scene is a
    # runtime error, and the other scenes still run.
    import rts_scenario.scenario

    real = rts_scenario.scenario.parametrizations

    def crashes_on_swept(path):
        if Path(path).name.startswith("b_swept"):
            raise ZeroDivisionError("a bug in the loader")
        return real(path)

    monkeypatch.setattr(rts_scenario.scenario, "parametrizations", crashes_on_swept)
    out = tmp_path / "bug.json"
    code, stdout, err = sweep(capsys, scenes, "--workers", "1", "--json", out)
    assert code == 3
    runs = json.loads(out.read_text())["runs"]
    assert [(Path(r["file"]).name, r["status"]) for r in runs] == [
        ("b_swept.scenario.yaml", "error"), ("c_broken.scenario.yaml", "error"),
        ("a_plain.scenario.yaml", "pass")]
    assert runs[0]["error_type"] == "runtime" and runs[1]["error_type"] == "bad_input"
    assert "ZeroDivisionError: a bug in the loader" in runs[0]["reason"]
    assert "Traceback" not in stdout + err


def test_a_scene_with_a_mistyped_suffix_in_a_folder_is_an_erred_run(scenes, tmp_path, capsys):
    # Left out, the sweep would not say that the scene it holds never ran.
    (scenes / "sub" / "typo.scenario.yml").write_text(tiny_scene("typo"))
    (scenes / "sub" / "parked.yaml").write_text("targets:\n  - name: parked\n")
    out = tmp_path / "typo.json"
    code, stdout, _ = sweep(capsys, scenes / "sub", "--workers", "1", "--json", out)
    assert code == 2
    runs = json.loads(out.read_text())["runs"]
    assert [(Path(r["file"]).name, r["status"]) for r in runs] == [
        ("a_plain.scenario.yaml", "pass"), ("typo.scenario.yml", "error")]
    typo = scenes / "sub" / "typo.scenario.yml"
    assert runs[1]["reason"] == (f"{typo} holds a scene (its rts_scenario key) but is not named "
                                 f"*.scenario.yaml, so it does not run as one; rename it "
                                 f"typo.scenario.yaml")
    assert runs[1]["error_type"] == "bad_input"


def test_a_misnamed_scene_is_found_as_yaml_reads_it(tmp_path):
    # A byte-order mark before the key, or the key quoted: YAML reads a scene, and the file
    # under another name was left out unseen.
    text = tiny_scene("a")
    assert text.startswith("rts_scenario: 1\n")
    (tmp_path / "bom.yaml").write_bytes(b"\xef\xbb\xbf" + text.encode())
    (tmp_path / "double.yaml").write_text(text.replace("rts_scenario:", '"rts_scenario":', 1))
    (tmp_path / "single.yml").write_text(text.replace("rts_scenario:", "'rts_scenario' :", 1))
    tasks = collect_tasks([tmp_path])
    assert [Path(t.file).name for t in tasks] == ["bom.yaml", "double.yaml", "single.yml"]
    assert all(t.error and "is not named *.scenario.yaml" in t.error for t in tasks)


def test_a_project_s_own_yaml_with_an_rts_scenario_section_is_no_misnamed_scene(tmp_path):
    # A scene's rts_scenario key is its format version, a number; a settings section of that
    # name (a mapping or a list) is none, and the folder's sweep is its scenes alone.
    (tmp_path / "a.scenario.yaml").write_text(tiny_scene("a"))
    (tmp_path / "bench.yaml").write_text("rts_scenario:\n  interface: pcan\n")
    (tmp_path / "flow.yml").write_text("rts_scenario: {interface: pcan}\n")
    (tmp_path / "listed.yaml").write_text("rts_scenario:   # ours\n- cut_in\n")
    tasks = collect_tasks([tmp_path])
    assert [(Path(t.file).name, t.error) for t in tasks] == [("a.scenario.yaml", None)]


@pytest.mark.skipif(sys.platform == "win32", reason="symbolic links")
def test_a_scene_link_that_leads_nowhere_is_an_erred_run(scenes, tmp_path, capsys):
    gone = scenes / "sub" / "gone.scenario.yaml"
    gone.symlink_to("../shared/gone.scenario.yaml")
    out = tmp_path / "gone.json"
    code, _, _ = sweep(capsys, scenes / "sub", "--workers", "1", "--json", out)
    assert code == 2
    runs = json.loads(out.read_text())["runs"]
    assert [(Path(r["file"]).name, r["status"]) for r in runs] == [
        ("a_plain.scenario.yaml", "pass"), ("gone.scenario.yaml", "error")]
    assert runs[1]["reason"] == (f"{gone}: cannot read file: a link to "
                                 f"../shared/gone.scenario.yaml, which does not exist")


def test_progress_lines_without_a_terminal(scenes, capsys):
    _, _, err = sweep(capsys, scenes / "b_swept.scenario.yaml", "--workers", "1")
    lines = err.splitlines()
    assert lines[0] == "sweep: 6 runs on this process"
    assert [line.split(",")[0] for line in lines[1:]] == [f"sweep: {n}/6 runs"
                                                          for n in range(1, 7)]
    assert lines[-1].startswith("sweep: 6/6 runs, 2 failed, 0 errors, ")


def test_progress_bar_on_a_terminal_and_tenths_otherwise():
    class Terminal(io.StringIO):
        def isatty(self):
            return True

    tty = Terminal()
    bar = SweepProgress(4, tty)
    for status in ("pass", "fail", "pass", "error"):
        bar({"status": status})
    assert "\n" not in tty.getvalue()
    assert "sweep [###############...............] 2/4 runs, 1 failed, 0 errors" in tty.getvalue()
    assert tty.getvalue().endswith("\r")  # the bar is wiped when done

    plain = io.StringIO()
    progress = SweepProgress(100, plain)
    for _ in range(100):
        progress({"status": "pass"})
    assert [line.split(",")[0] for line in plain.getvalue().splitlines()] == [
        f"sweep: {n}/100 runs" for n in range(10, 101, 10)]


def test_the_library_runs_the_same_as_the_command_line(scenes):
    tasks = collect_tasks([scenes / "b_swept.scenario.yaml"])
    seen = []
    entries = run_sweep(tasks, workers=1, on_result=seen.append)
    assert len(seen) == len(entries) == 6
    assert summarize(entries)["by_parameter"][RCS_KEY]["10.0"]["passed"] == 2


def test_scheduler_without_dask_is_one_clear_line(scenes, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)
    code, out, err = sweep(capsys, scenes, "--scheduler", "local")
    assert code == 2
    assert err == ("error: --scheduler needs dask.distributed: pip install "
                   "'rts-scenario[sweep]'\n")
    assert out == ""


def test_unreachable_scheduler_is_one_clear_line(scenes, capsys, monkeypatch):
    pytest.importorskip("distributed")
    monkeypatch.setattr("rts_scenario.sweep.CONNECT_TIMEOUT_S", 1.0)
    code, _, err = sweep(capsys, scenes / "sub", "--scheduler", "tcp://127.0.0.1:9")
    assert code == 2
    assert err.count("\n") == 2 and "error: --scheduler tcp://127.0.0.1:9: cannot connect" in err


def test_relative_paths_reach_dask_workers_started_in_another_folder(scenes, tmp_path, capsys,
                                                                    monkeypatch):
    """A cluster's workers run elsewhere (another folder, another machine sharing the files):
    a scene given relative to this folder is still found there, and named as given."""
    distributed = pytest.importorskip("distributed")
    import logging

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=None, silence_logs=logging.ERROR) as cluster:
        monkeypatch.chdir(scenes)  # the workers stay in `elsewhere`
        out = tmp_path / "remote.json"
        code, stdout, _ = sweep(capsys, "sub", "c_broken.scenario.yaml", "--json", out,
                                "--scheduler", cluster.scheduler_address)
    runs = json.loads(out.read_text())["runs"]
    assert [(r["file"], r["status"]) for r in runs] == [
        (str(Path("sub") / "a_plain.scenario.yaml"), "pass"),
        ("c_broken.scenario.yaml", "error")]
    # The error names the file as given, where it is wrong.
    assert runs[1]["reason"].startswith("c_broken.scenario.yaml:")
    assert "colour" in runs[1]["reason"]
    assert code == 2


def test_plot_of_pass_and_fail_over_two_parameters(scenes, tmp_path, capsys):
    png = tmp_path / "sweep.png"
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        code, _, err = sweep(capsys, scenes, "--plot", png)
        assert code == 2 and err == ("error: --plot needs matplotlib: pip install "
                                     "'rts-scenario[plot]'\n")
        return
    code, out, _ = sweep(capsys, scenes / "b_swept.scenario.yaml", "--workers", "1",
                         "--plot", png)
    assert code == 1 and f"wrote {png}" in out
    assert png.read_bytes().startswith(b"\x89PNG")


@pytest.mark.parametrize("stop", ["ctrl-c", "sigterm"])
def test_interrupted_sweep_keeps_the_runs_done(scenes, tmp_path, capsys, monkeypatch, stop):
    """Ctrl-C, or SIGTERM (a CI job's timeout, ``kill``): the runs done are kept."""
    import os
    import signal

    real = rts_scenario.pipeline.run_scene
    calls = []

    def interrupted_at_the_third(scene, options):
        calls.append(scene.name)
        if len(calls) == 3:
            if stop == "sigterm":
                os.kill(os.getpid(), signal.SIGTERM)
            else:
                raise KeyboardInterrupt
        return real(scene, options)

    monkeypatch.setattr(rts_scenario.pipeline, "run_scene", interrupted_at_the_third)
    # Counted, not pytest's end, where the command does not handle it.
    received = []
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: received.append(signum))
    try:
        out = tmp_path / "partial.json"
        code, _, err = sweep(capsys, scenes / "b_swept.scenario.yaml", "--workers", "1",
                             "--json", out)
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert received == [] and code == 1 and err.endswith("error: interrupted\n"), err
    payload = json.loads(out.read_text())
    assert [r["id"] for r in payload["runs"]] == ["1=0.0-rcs_dbsm=5.0", "1=0.0-rcs_dbsm=10.0"]
    assert payload["summary"]["runs"] == 2 and payload["summary"]["interrupted"] is True
    # The runs not run are counted: 2 of the 6 planned.
    assert payload["summary"]["planned"] == 6


def test_a_sweep_killed_or_failing_after_its_runs_leaves_no_earlier_report(
        scenes, tmp_path, capsys, monkeypatch):
    # Its report was written only at the end: a sweep killed outright, or stopped as it wrote
    # its report, left an earlier sweep's passing report in place.
    import rts_scenario.cli.sweep as sweep_cli

    out = tmp_path / "s.json"
    out.write_text(json.dumps({"runs": [], "summary": {"runs": 9, "passed": 9}}))
    real, calls = sweep_cli.write_json, []

    def stop_at_the_report(*args, **kwargs):
        calls.append(args)
        if len(calls) > 1:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(sweep_cli, "write_json", stop_at_the_report)
    code, _, err = sweep(capsys, scenes / "b_swept.scenario.yaml", "--workers", "1",
                         "--json", out)
    assert code == 1 and "error: interrupted" in err
    left = json.loads(out.read_text())
    assert left["runs"] == [] and left["summary"]["interrupted"] is True
    assert left["summary"]["planned"] == 6 and left["error"].startswith("no verdict")


# A sweep whose runs each take two minutes, its first run's flag written as it starts.
LONG_RUNS = """\
import sys, time
from pathlib import Path
import rts_scenario.pipeline
from rts_scenario.cli import main

def long_run(scene, options):
    Path(sys.argv[1]).touch()
    time.sleep(120)

rts_scenario.pipeline.run_scene = long_run
sys.exit(main(sys.argv[2:]))
"""


def test_sigterm_stops_a_sweep_s_pool_without_waiting_for_its_runs(scenes, tmp_path):
    """SIGTERM reaches the sweep's process alone, not its workers (Ctrl-C reaches all of them):
    the sweep stops the runs under way and exits, instead of waiting for them to end, which a
    CI job's timeout would not (it kills the sweep a few seconds after its SIGTERM, and its
    exit code with it)."""
    import signal
    import subprocess
    import time

    flag, out = tmp_path / "started", tmp_path / "partial.json"
    command = [sys.executable, "-c", LONG_RUNS, str(flag), "sweep",
               str(scenes / "b_swept.scenario.yaml"), "--workers", "2", "--json", str(out)]
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                          text=True) as sweeping:
        deadline = time.monotonic() + 60.0
        while not flag.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert flag.exists(), "no run started"
        sweeping.send_signal(signal.SIGTERM)
        start = time.monotonic()
        try:
            _, err = sweeping.communicate(timeout=60.0)
        except subprocess.TimeoutExpired:
            sweeping.kill()
            raise
        elapsed = time.monotonic() - start
    assert sweeping.returncode == 1 and err.endswith("error: interrupted\n"), err
    assert elapsed < 30.0
    payload = json.loads(out.read_text())
    assert payload["runs"] == [] and payload["summary"]["interrupted"] is True


def test_interrupted_sweep_prints_the_runs_done(scenes, tmp_path, capsys, monkeypatch):
    """Without --json too: the verdicts that finished are printed, as `run` prints them, and a
    run that erred at run time before Ctrl-C keeps its exit code."""

    real = rts_scenario.pipeline.run_scene
    calls = []

    def crash_then_interrupt(scene, options):
        calls.append(scene.name)
        if len(calls) == 2:
            raise RuntimeError("the bench fell over")
        if len(calls) == 4:
            raise KeyboardInterrupt
        return real(scene, options)

    monkeypatch.setattr(rts_scenario.pipeline, "run_scene", crash_then_interrupt)
    code, stdout, err = sweep(capsys, scenes / "b_swept.scenario.yaml", "--workers", "1")
    assert code == 3 and err.endswith("error: interrupted\n")
    lines = [line for line in stdout.splitlines() if line.split(" ")[0] in ("PASS", "FAIL",
                                                                            "ERROR")]
    assert [line.split(" (")[0] for line in lines] == [
        "PASS swept[1=0.0-rcs_dbsm=5.0]", "ERROR swept[1=0.0-rcs_dbsm=10.0]",
        "PASS swept[1=2.0-rcs_dbsm=5.0]"]
    assert "RuntimeError: the bench fell over" in lines[1]
    assert "sweep: 3 of 6 runs (interrupted), 2 passed, 0 failed, 1 errors" in stdout


@pytest.mark.skipif(sys.platform == "win32", reason="the pool's workers are forked")
def test_a_worker_that_dies_loses_no_run(scenes, tmp_path, capsys, monkeypatch):
    import os


    real = rts_scenario.pipeline.run_scene

    def dies_on_plain(scene, options):  # forked workers inherit the patch
        if scene.name == "plain":
            os._exit(7)
        return real(scene, options)

    monkeypatch.setattr(rts_scenario.pipeline, "run_scene", dies_on_plain)
    out = tmp_path / "died.json"
    code, stdout, err = sweep(capsys, scenes, "--workers", "2", "--json", out)
    assert code == 3
    runs = json.loads(out.read_text())["runs"]
    assert len(runs) == 8
    [plain] = [r for r in runs if r["file"].endswith("a_plain.scenario.yaml")]
    assert plain["status"] == "error" and plain["error_type"] == "runtime"
    assert "worker failed: BrokenProcessPool" in plain["reason"]
    # Named as any run that did not report its scene: after its file, as in the listing.
    assert plain["scene"] == "a_plain"
    assert f"ERROR a_plain ({plain['file']}): " in stdout
    assert "Traceback" not in stdout + err


def test_the_euro_ncap_catalogue_sweeps_to_the_same_verdicts_everywhere(tmp_path, capsys):
    """More than 100 combinations of the shipped catalogue in process, every one a pass; two of
    its scenes again in a pool of two and on a local Dask cluster: the same verdicts run by run
    (a third pass over all of it would only take longer)."""
    catalogue = Path(__file__).resolve().parents[1] / "scenarios" / "euro-ncap"
    scenes = [catalogue / f"{name}.scenario.yaml" for name in ("ccrs", "ccrb", "cpna-25",
                                                                "cmrs")]
    again = [scenes[0], scenes[2]]
    places = [["--workers", "2"]]
    try:
        import distributed  # noqa: F401

        places.append(["--scheduler", "local", "--workers", "2"])
    except ImportError:
        pass

    def swept(paths, place, i):
        out = tmp_path / f"catalogue-{i}.json"
        code, _, _ = sweep(capsys, *paths, "--json", out, *place)
        payload = json.loads(out.read_text())
        assert code == 0, [(r["file"], r["id"], r["status"], r.get("reason"))
                           for r in payload["runs"] if r["status"] != "pass"][:3]
        return verdicts(payload)

    first = swept(scenes, ["--workers", "1"], 0)
    assert len(first) >= 100 and all(r["passed"] for r in first)
    assert len({(r["file"], json.dumps(r["parameters"], sort_keys=True)) for r in first}) == \
        len(first)
    subset = [r for r in first if r["file"] in {str(p) for p in again}]
    assert len(subset) >= 40 and {r["file"] for r in subset} == {str(p) for p in again}
    for i, place in enumerate(places, start=1):
        assert swept(again, place, i) == subset


def test_equal_numbers_are_one_parameter_value_however_a_scene_writes_them():
    """ccrs and ccrb in the Euro NCAP catalogue write the same lateral offset as 0 and 0.0:
    one value in the summary (named as a decimal number), as in the plot; 12 and 12.0 alike,
    -0.0 is 0.0, and text stays text."""
    from rts_scenario.cli.sweep import _summary_text
    from rts_scenario.sweep import value_name

    key = "targets.0.motion.position_m.1"

    def run(value, status):
        return {"scene": "s", "file": "s.scenario.yaml", "id": "", "parameters": {key: value},
                "passed": status == "pass", "status": status, "max_error_ratio": 0.1,
                "max_error_quantity": "az_deg", **({"reason": "why"} if status != "pass" else {})}

    entries = [run(0, "pass"), run(0.0, "fail"), run(-0.0, "pass"), run(0.45, "pass"),
               run(12, "pass"), run(12.0, "pass"), run("0", "pass"), run(True, "pass"),
               run(1, "fail")]
    values = summarize(entries)["by_parameter"][key]
    assert list(values) == ["0.0", "0.45", "12.0", "0", "True", "1.0"]
    assert {v: (c["runs"], c["passed"]) for v, c in values.items()} == {
        "0.0": (3, 2), "0.45": (1, 1), "12.0": (2, 2), "0": (1, 1), "True": (1, 1),
        "1.0": (1, 0)}
    assert "position_m.1=0.0: 2/3" in _summary_text(summarize(entries), 1.0)
    # Integers a float cannot hold exactly keep their digits (and stay apart).
    assert value_name(2 ** 64 + 1) == str(2 ** 64 + 1) != value_name(2 ** 64)
    assert value_name(2 ** 64) == value_name(float(2 ** 64))


def test_the_euro_ncap_scenes_write_one_offset_two_ways():
    """The case above is real: the shipped catalogue writes the 100 % overlap as 0 and 0.0."""
    import yaml

    folder = Path(__file__).resolve().parent.parent / "scenarios" / "euro-ncap"
    offsets = [yaml.safe_load((folder / f"{n}.scenario.yaml").read_text())["parametrize"][
        "targets.0.motion.position_m.1"] for n in ("ccrs", "ccrb")]
    zeros = [next(v for v in values if v == 0) for values in offsets]
    assert {type(z) for z in zeros} == {int, float}


def test_a_scene_given_twice_runs_once_and_the_sweep_says_so(scenes, tmp_path, capsys):
    # `sweep DIR DIR/sub/a_plain.scenario.yaml ./DIR`: each scene once (its variants counted
    # once in the pass rate), with a note naming the repeats.
    report = tmp_path / "s.json"
    code, out, err = sweep(capsys, scenes, scenes / "sub" / "a_plain.scenario.yaml",
                           f"{scenes}/./sub/../sub/a_plain.scenario.yaml", "--json", report)
    runs = json.loads(report.read_text())["runs"]
    # The folder holds 6 swept variants, the plain scene and the broken one: 8 runs.
    assert len(runs) == 8
    assert sum(run["file"].endswith("a_plain.scenario.yaml") for run in runs) == 1
    assert err.count("note: ") == 2
    assert f"note: {scenes / 'sub' / 'a_plain.scenario.yaml'}: given again (as " in err
    assert "run once" in err
    # The same path twice, in library use.
    path = scenes / "sub" / "a_plain.scenario.yaml"
    notes = []
    assert len(collect_tasks([path, path], notes)) == 1
    assert notes == [f"{path}: given again (as {path} first): run once"]


# --- the pytest plugin's verdicts for the same scenes ---------------------------------------

def missed(name: str, extra: str = "") -> str:
    """A scene whose check fails: its car is 20 m to the side, outside the rig's coverage."""
    return tiny_scene(name).replace("[30, 0, 0.6]", "[30, 20, 0.6]") + extra


# What pytest -v prints after an item's id, and the status sweep gives the same run.
PLUGIN_STATUS = {"PASSED": "pass", "FAILED": "fail", "XFAIL": "xfail", "XPASS": "xpass",
                 "SKIPPED": "skipped", "ERROR": "error"}


def plugin_verdicts(pytester, *args):
    """Run pytest over the pytester folder: ``{item name: sweep's status for it}``, exit code.

    A scene that does not load is a failed item in pytest and an erred run in the sweep.
    """
    result = pytester.runpytest("-v", "-p", "no:cacheprovider", *args)
    verdicts = {}
    for line in result.stdout.lines:
        head, sep, rest = line.partition("::")
        words = rest.split()
        if sep and head.endswith(".yaml") and len(words) >= 2 and words[1] in PLUGIN_STATUS:
            verdicts[words[0]] = PLUGIN_STATUS[words[1]]
    return verdicts, result.ret


def sweep_verdicts(capsys, tmp_path, *args):
    """Sweep ``args`` in this process: ``{run label: status}``, exit code, the JSON."""
    from rts_scenario.sweep import run_label

    out = tmp_path / "verdicts.json"
    code, stdout, err = sweep(capsys, *args, "--workers", "1", "--json", out)
    assert "Traceback" not in stdout + err
    payload = json.loads(out.read_text())
    return {run_label(r): r["status"] for r in payload["runs"]}, code, payload, stdout


def as_plugin_sees_it(verdicts):
    # The plugin has no erred item of its own: a scene that does not load fails.
    return {name: "fail" if status == "error" else status for name, status in verdicts.items()}


def test_marks_give_the_verdicts_the_pytest_plugin_gives(pytester, capsys, tmp_path):
    """xfail expects the check to fail (a pass is an xpass, not a failure, as pytest's default
    xfail_strict says), skip and skipif skip, and a scene that does not load is an error even
    when marked xfail; a skip mark skips a variant that does not load, as in pytest, but a
    broken parametrize block is selected by its marks (-m) but not skipped by them."""
    pytester.makefile(".scenario.yaml", **{
        "a_plain": tiny_scene("plain"),
        "b_known": missed("known", "marks: [xfail, slow]\n"),
        "c_fixed": tiny_scene("fixed") + "marks: [xfail]\n",
        "d_parked": missed("parked", "marks: [skip]\n"),
        "e_later": missed("later", "marks: [skipif]\n"),
        "f_broken": tiny_scene("broken") + "marks: [xfail]\ncolour: red\n",
        "g_mixed": missed("mixed", "marks: [xfail]\nparametrize:\n  rig: [wide-3x5, "
                                   "lab.rig.yaml]\n"),
        "h_shelved": tiny_scene("shelved") + "marks: [skip]\nparametrize:\n  rig: "
                                             "[lab.rig.yaml]\n",
        "i_block": tiny_scene("block") + "marks: [skip]\nparametrize:\n  radar.estimator: ti\n",
    })
    expected = {"plain": "pass", "known": "xfail", "fixed": "xpass", "parked": "skipped",
                "later": "skipped", "f_broken": "error", "mixed[rig=wide-3x5]": "xfail",
                "g_mixed[rig=lab.rig.yaml]": "error", "h_shelved[rig=lab.rig.yaml]": "skipped",
                "i_block": "error"}
    plugin, plugin_code = plugin_verdicts(pytester)
    assert plugin == as_plugin_sees_it(expected)
    assert plugin_code == pytest.ExitCode.TESTS_FAILED
    swept, code, payload, stdout = sweep_verdicts(capsys, tmp_path, pytester.path)
    assert swept == expected
    assert code == 2  # bad input, as the scenes that do not load are
    runs = {r["scene"] + (f"[{r['id']}]" if r["id"] else ""): r for r in payload["runs"]}
    assert runs["known"]["passed"] is False and "out_of_coverage" in runs["known"]["reason"]
    assert runs["fixed"]["passed"] is True
    assert runs["parked"]["passed"] is False and "detection_rate" not in runs["parked"]
    assert runs["known"]["marks"] == ["xfail", "slow"] and runs["plain"]["marks"] == []
    assert runs["i_block"]["reason"].startswith(
        f"{pytester.path / 'i_block.scenario.yaml'}:15:3: parametrize.radar.estimator: must be "
        f"of type array, got 'ti'")
    # Counted, each under its own name, never as passed or failed.
    summary = payload["summary"]
    assert {k: summary[k] for k in ("runs", "passed", "failed", "errors", "xfailed", "xpassed",
                                    "skipped", "deselected")} == {
        "runs": 10, "passed": 1, "failed": 0, "errors": 3, "xfailed": 2, "xpassed": 1,
        "skipped": 3, "deselected": 0}
    # The pass rate is over the runs that ran: 1 of 7.
    assert summary["pass_rate"] == pytest.approx(1 / 7)
    assert "sweep: 10 runs, 1 passed, 0 failed, 3 errors, 2 xfailed, 1 xpassed, 3 skipped; " \
           "pass rate 14.3%" in stdout
    assert f"XFAIL known ({pytester.path / 'b_known.scenario.yaml'}): " in stdout
    assert f"SKIPPED parked ({pytester.path / 'd_parked.scenario.yaml'}): the scene's marks: " \
           f"skip" in stdout
    rig = summary["by_parameter"]["rig"]
    assert {v: (c["runs"], c["passed"], c["xfailed"], c["errors"], c["skipped"])
            for v, c in rig.items()} == {"wide-3x5": (1, 0, 1, 0, 0),
                                         "lab.rig.yaml": (2, 0, 0, 1, 1)}


def test_exit_code_is_pytest_s_for_known_failures_and_skips(pytester, capsys, tmp_path):
    pytester.makefile(".scenario.yaml", known=missed("known", "marks: [xfail]\n"),
                      fixed=tiny_scene("fixed") + "marks: [xfail]\n",
                      parked=missed("parked", "marks: [skip]\n"), plain=tiny_scene("plain"))
    plugin, plugin_code = plugin_verdicts(pytester)
    swept, code, _, _ = sweep_verdicts(capsys, tmp_path, pytester.path)
    assert swept == plugin == {"known": "xfail", "fixed": "xpass", "parked": "skipped",
                               "plain": "pass"}
    assert plugin_code == code == 0
    # A failure beside them fails both.
    pytester.makefile(".scenario.yaml", lost=missed("lost"))
    plugin, plugin_code = plugin_verdicts(pytester)
    swept, code, _, _ = sweep_verdicts(capsys, tmp_path, pytester.path)
    assert swept == plugin and swept["lost"] == "fail"
    assert plugin_code == code == 1


def documented_exit_codes() -> dict[int, tuple[str, str]]:
    """docs/cli.md's table of sweep's exit codes: ``{code: (sweep's cell, pytest's cell)}``."""
    text = (ROOT / "docs" / "cli.md").read_text(encoding="utf-8")
    lines = text[text.index("| code | `sweep` | `pytest`, for the same scenes |"):].splitlines()
    rows = {}
    for line in lines[2:]:
        if not line.startswith("|"):
            break
        code, swept, by_pytest = (cell.strip() for cell in line.strip().strip("|").split("|"))
        rows[int(code)] = swept, by_pytest
    return rows


def test_a_scene_that_does_not_load_exits_as_the_docs_say_for_sweep_and_pytest(pytester, capsys,
                                                                              tmp_path):
    """sweep exits 2, bad input as for run; pytest fails the scene's item, exit 1. The docs
    said both gave the same exit code for the same scenes."""
    pytester.makefile(".scenario.yaml", plain=tiny_scene("plain"),
                      broken=tiny_scene("broken") + "colour: red\n")
    plugin, plugin_code = plugin_verdicts(pytester)
    swept, code, _, _ = sweep_verdicts(capsys, tmp_path, pytester.path)
    assert swept == {"plain": "pass", "broken": "error"}
    assert plugin == as_plugin_sees_it(swept)
    assert (code, plugin_code) == (2, pytest.ExitCode.TESTS_FAILED)
    swept_cell, pytest_cell = documented_exit_codes()[code]
    assert "its scene did not load" in swept_cell
    assert pytest_cell.startswith(f"{plugin_code:d} for a scene or combination that does not "
                                  f"load")
    readme = " ".join((ROOT / "README.md").read_text(encoding="utf-8").split())
    assert ("the same exit code where no run erred (a run that erred, a scene that does not "
            "load or a run that raised, exits 2 or 3 as for `run`, where `pytest` fails its "
            "item, exit 1)") in readme


def test_a_sweep_whose_runs_were_all_skipped_has_no_pass_rate(pytester, capsys, tmp_path):
    # As pytest: nothing failed, exit 0; but no run ran, so there is no rate to give (0 % would
    # read as every run failed, 100 % as every run passed).
    pytester.makefile(".scenario.yaml", parked=missed("parked", "marks: [skip]\n"),
                      shelved=tiny_scene("shelved") + "marks: [skip]\nparametrize:\n  "
                                                      "radar.estimator: [bartlett, ti]\n")
    plugin, plugin_code = plugin_verdicts(pytester)
    swept, code, payload, stdout = sweep_verdicts(capsys, tmp_path, pytester.path)
    assert swept == plugin and set(swept.values()) == {"skipped"}
    assert plugin_code == code == 0
    assert payload["summary"]["pass_rate"] is None
    assert payload["summary"]["by_parameter"]["radar.estimator"]["ti"]["pass_rate"] is None
    assert "3 skipped; no run ran, no pass rate (" in stdout
    assert "  estimator=ti: 0/0 (1 skipped)" in stdout


def test_marks_expression_selects_the_runs_pytest_selects(pytester, capsys, tmp_path):
    pytester.makefile(".scenario.yaml", **{
        "a_plain": tiny_scene("plain"),
        "b_slow": tiny_scene("slow_one") + "marks: [slow]\n",
        "c_bench": tiny_scene("bench") + "marks: [hardware, slow]\nparametrize:\n  rig: "
                                         "[wide-3x5, lab.rig.yaml]\n",
    })
    for expression, expected in [
            ("slow", {"slow_one", "bench[rig=wide-3x5]", "c_bench[rig=lab.rig.yaml]"}),
            ("slow and not hardware", {"slow_one"}),
            ("not slow", {"plain"})]:
        plugin, _ = plugin_verdicts(pytester, "-m", expression)
        swept, code, payload, stdout = sweep_verdicts(capsys, tmp_path, pytester.path,
                                                      "-m", expression)
        assert set(swept) == set(plugin) == expected, expression
        assert as_plugin_sees_it(swept) == plugin
        assert payload["summary"]["deselected"] == 4 - len(expected)
        assert f"{4 - len(expected)} deselected" in stdout
    _, _, payload, _ = sweep_verdicts(capsys, tmp_path, pytester.path, "--marks", "slow")
    assert len(payload["runs"]) == 3


def test_a_bad_or_empty_marks_selection_is_one_line(scenes, capsys):
    code, out, err = sweep(capsys, scenes, "-m", "slow and", "--workers", "1")
    assert code == 2 and out == ""
    assert err.startswith("error: -m/--marks 'slow and': ") and err.count("\n") == 1
    # Selecting none of the runs would be a pass of nothing: pytest's "no tests ran".
    code, out, err = sweep(capsys, scenes, "-m", "nightly", "--workers", "1")
    assert code == 5
    assert err.strip().splitlines()[-1] == (
        "error: -m/--marks 'nightly': selects none of the 8 runs (their marks: none)")


# --- which folders a folder's sweep walks -----------------------------------------------------

def test_a_folder_s_sweep_leaves_out_the_folders_pytest_leaves_out(pytester, capsys, tmp_path):
    """Hidden folders, virtual environments, __pycache__, build output, node_modules: not
    walked, as pytest's default norecursedirs; a file or folder named on the command line
    always runs, as in pytest."""
    root = pytester.path
    for folder in (".venv", ".git", ".hidden/deep", "node_modules/pkg", "__pycache__", "build",
                   "dist", "venv", "CVS", "_darcs", "{arch}", "thing.egg", "env", "kept/sub",
                   "kept/.tox"):
        (root / folder).mkdir(parents=True)
        name = folder.replace("/", "_").strip("._{}") or "x"
        (root / folder / f"{name}.scenario.yaml").write_text(tiny_scene(name))
    (root / "env" / "pyvenv.cfg").write_text("home = /usr/bin\n")
    (root / "top.scenario.yaml").write_text(tiny_scene("top"))
    plugin, _ = plugin_verdicts(pytester, str(root))
    swept, code, _, _ = sweep_verdicts(capsys, tmp_path, root)
    assert set(swept) == set(plugin) == {"top", "kept_sub"}
    assert code == 0
    hidden = root / ".hidden"
    named = root / ".venv" / "venv.scenario.yaml"
    plugin, _ = plugin_verdicts(pytester, str(hidden), str(named))
    swept, code, _, _ = sweep_verdicts(capsys, tmp_path, hidden, named)
    assert set(swept) == set(plugin) == {"hidden_deep", "venv"}
    # A misnamed scene in a folder left out is no erred run either.
    (root / ".git" / "typo.scenario.yml").write_text(tiny_scene("typo"))
    swept, code, _, _ = sweep_verdicts(capsys, tmp_path, root)
    assert set(swept) == {"top", "kept_sub"} and code == 0


def test_a_folder_whose_scenes_are_all_in_folders_left_out_says_so(tmp_path, capsys):
    (tmp_path / "scenes" / ".drafts").mkdir(parents=True)
    (tmp_path / "scenes" / ".drafts" / "a.scenario.yaml").write_text(tiny_scene("a"))
    (tmp_path / "scenes" / "build").mkdir()
    code, out, _ = sweep(capsys, tmp_path / "scenes", "--workers", "1")
    assert code == 2
    assert f"{tmp_path / 'scenes'}: no *.scenario.yaml files in this folder (2 folders in it " \
           f"left out, as pytest leaves them out: .drafts, build; name one to sweep it)" in out


def test_the_plot_shows_every_status_and_rates_the_runs_that_ran(monkeypatch, tmp_path):
    pytest.importorskip("matplotlib")
    import rts_scenario.plots

    figures = []
    monkeypatch.setattr(rts_scenario.plots, "_save", lambda fig, path: figures.append(fig))

    def run(status, **parameters):
        return {"scene": "s", "file": "s.scenario.yaml", "id": "", "parameters": parameters,
                "status": status}

    statuses = ["pass", "fail", "error", "xfail", "xpass", "skipped"]
    rts_scenario.plots.write_sweep_plot([run(s, a=i) for i, s in enumerate(statuses)],
                                        tmp_path / "one.png")
    legend = [t.get_text() for t in figures[0].axes[0].get_legend().get_texts()]
    assert legend == statuses
    # Two parameters: the cell's skipped run is not one that failed to pass.
    rts_scenario.plots.write_sweep_plot([run("pass", a=1, b=1), run("skipped", a=1, b=1)],
                                        tmp_path / "two.png")
    assert [t.get_text() for t in figures[1].axes[0].texts] == ["1/1"]
    # Three: a value whose runs were all skipped has no pass rate to draw (and no division).
    rts_scenario.plots.write_sweep_plot([run("pass", a=1, b=1, c=1),
                                         run("skipped", a=2, b=2, c=2)], tmp_path / "three.png")
    assert [t.get_text() for t in figures[2].axes[0].texts] == ["1/1", "0/0"]
    # Two scenes over different keys: no grid of combinations no run has; every run is in
    # each key's panel, those without the key as "(not set)".
    figures.clear()
    rts_scenario.plots.write_sweep_plot([run("pass", a=1), run("fail", a=2),
                                         run("pass", b=1), run("fail", b=2)], tmp_path / "ab.png")
    panels = figures[0].axes
    assert [t.get_text() for t in panels[0].get_xticklabels()] == ["1.0", "2.0", "(not set)"]
    assert [t.get_text() for t in panels[0].texts] == ["1/1", "0/1", "1/2"]
    assert [t.get_text() for t in panels[1].texts] == ["1/2", "1/1", "0/1"]
    # One key that one scene lacks: its runs are not dropped from the verdict plot.
    rts_scenario.plots.write_sweep_plot([run("pass", a=1), run("fail")], tmp_path / "a.png")
    assert [t.get_text() for t in figures[1].axes[0].texts] == ["1/1", "0/1"]


def test_a_combination_s_marks_are_the_scene_s_with_its_overrides():
    from rts_scenario.scenario import written_marks

    data = {"marks": ["slow", "hard"], "name": "x"}
    assert written_marks(data, {}) == ("slow", "hard")
    assert written_marks(data, {"marks": ["nightly"], "name": "y"}) == ("nightly",)
    assert written_marks(data, {"marks.1": "bench"}) == ("slow", "bench")
    assert data == {"marks": ["slow", "hard"], "name": "x"}  # the scene itself is left alone
    assert written_marks(data, {"marks.5": "bench"}) == ()  # no such mark: its load says so
    assert written_marks({"marks": ["ok", "_private", 3]}, {}) == ("ok",)
    assert written_marks(["not", "a", "scene"], {}) == ()


def test_a_path_that_is_not_there_is_bad_input_whatever_the_marks_selection(pytester, capsys,
                                                                           tmp_path):
    """A mark expression selects runs of scenes, not the paths given: a path that does not
    exist, or a folder with no scene, is no run it could leave out. pytest stops with a usage
    error for a path that is not there, -m or not; the sweep never passes such a command."""
    pytester.makefile(".scenario.yaml", slow=tiny_scene("slow_one") + "marks: [slow]\n")
    (pytester.path / "empty").mkdir()
    missing = pytester.path / "nothere.scenario.yaml"
    result = pytester.runpytest("-p", "no:cacheprovider", str(missing), str(pytester.path),
                                "-m", "slow")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    for given in (missing, pytester.path / "empty"):
        code, out, _ = sweep(capsys, given, pytester.path, "-m", "slow", "--workers", "1")
        assert code == 2, out
        assert f"ERROR {given.name.removesuffix('.scenario.yaml')} ({given}): {given}: " in out
        assert "PASS slow_one" in out


# --- the project's pytest settings --------------------------------------------------------------

DEFAULT_NORECURSE = ["*.egg", ".*", "_darcs", "build", "CVS", "dist", "node_modules", "venv",
                     "{arch}"]
# One scene whose check fails and one that passes, both marked xfail, and a plain one.
MARKED = {"known": missed("known", "marks: [xfail]\n"),
          "fixed": tiny_scene("fixed") + "marks: [xfail]\n", "plain": tiny_scene("plain")}


@pytest.mark.parametrize("name, text", [
    ("pytest.ini", "[pytest]\nxfail_strict = true\n"),
    ("pyproject.toml", "[tool.pytest.ini_options]\nxfail_strict = true\n"),
    ("tox.ini", "[pytest]\nxfail_strict = yes\n"),
    ("setup.cfg", "[tool:pytest]\nxfail_strict = 1\n"),
    pytest.param("pytest.ini", "[pytest]\nstrict = true\n", id="strict",
                 marks=pytest.mark.skipif(pytest.version_tuple < (9,),
                                          reason="pytest 9 added the strict option")),
])
def test_xfail_strict_in_the_project_s_config_fails_an_xpass_as_pytest_does(
        pytester, capsys, tmp_path, name, text):
    (pytester.path / name).write_text(text)
    pytester.makefile(".scenario.yaml", **MARKED)
    plugin, plugin_code = plugin_verdicts(pytester)
    capsys.readouterr()  # pytest's own report
    swept, code, payload, stdout = sweep_verdicts(capsys, tmp_path, pytester.path)
    assert swept == plugin == {"known": "xfail", "fixed": "fail", "plain": "pass"}
    assert plugin_code == code == 1
    fixed = next(r for r in payload["runs"] if r["scene"] == "fixed")
    assert fixed["passed"] is True  # its check passed; the mark said it would not
    assert fixed["reason"] == "[XPASS(strict)] the scene's marks: xfail"
    assert payload["summary"]["failed"] == 1 and payload["summary"]["xpassed"] == 0
    assert payload["config"] == {"inifile": str(pytester.path / name),
                                 "rootdir": str(pytester.path), "xfail_strict": True,
                                 "norecursedirs": DEFAULT_NORECURSE,
                                 "rts_scenario_pattern": "*.scenario.yaml"}
    assert stdout.splitlines()[0] == (
        f"pytest settings: configfile {name} (rootdir {pytester.path}): xfail_strict = true, "
        f"norecursedirs = *.egg .* _darcs build CVS dist node_modules venv {{arch}}, "
        f"rts_scenario_pattern = *.scenario.yaml")


def test_without_a_config_file_the_sweep_says_it_takes_pytest_s_defaults(scenes, capsys,
                                                                         tmp_path):
    report = tmp_path / "s.json"
    _, out, _ = sweep(capsys, scenes / "sub", "--json", report, "--workers", "1")
    assert json.loads(report.read_text())["config"] == {
        "inifile": None, "rootdir": None, "xfail_strict": False,
        "norecursedirs": DEFAULT_NORECURSE, "rts_scenario_pattern": "*.scenario.yaml"}
    assert out.splitlines()[0] == (
        "pytest settings: none found, pytest's defaults: xfail_strict = false, "
        "norecursedirs = *.egg .* _darcs build CVS dist node_modules venv {arch}, "
        "rts_scenario_pattern = *.scenario.yaml")


def test_pytest_is_not_imported_for_scenes_without_a_config_file(tmp_path):
    """A folder with no config file around it needs nothing from pytest (it takes a while to
    import); a project's config file does."""
    import subprocess

    code = ("import sys; from rts_scenario.sweep import pytest_settings; "
            "s = pytest_settings([sys.argv[1]]); "
            "print(s.inifile, s.xfail_strict, 'pytest' in sys.modules, '_pytest' in sys.modules)")
    env = {**__import__("os").environ, "PYTHONPATH": str(Path(__file__).parents[1])}

    def settings_in(folder):
        done = subprocess.run([sys.executable, "-c", code, str(folder)], env=env, text=True,
                              capture_output=True, check=True)
        return done.stdout.split()

    (tmp_path / "bare").mkdir()
    assert settings_in(tmp_path / "bare") == ["None", "False", "False", "False"]
    (tmp_path / "project" / "scenes").mkdir(parents=True)
    (tmp_path / "project" / "tox.ini").write_text("[pytest]\nxfail_strict = true\n")
    assert settings_in(tmp_path / "project" / "scenes") == [
        str(tmp_path / "project" / "tox.ini"), "True", "True", "True"]


def test_the_config_files_looked_for_are_those_pytest_reads():
    """pytest is imported only where one of these files could hold its settings; a name pytest
    adds to its list must be added here too."""
    import inspect
    import re

    from _pytest.config import findpaths

    from rts_scenario.sweep import PYTEST_CONFIG_NAMES

    names = re.findall(r'"(\.?[\w.]+\.(?:toml|ini|cfg))"', inspect.getsource(findpaths))
    assert names and set(names) <= set(PYTEST_CONFIG_NAMES)


def test_a_folder_s_sweep_leaves_out_the_folders_the_project_s_norecursedirs_names(
        pytester, capsys, tmp_path):
    """The project's norecursedirs replaces pytest's default list: a hidden folder or build is
    walked unless it names them; a pattern with a slash matches the folder's path; virtual
    environments and __pycache__ stay out whatever it says."""
    root = pytester.path
    (root / "pyproject.toml").write_text(
        '[tool.pytest.ini_options]\nnorecursedirs = ["drafts", "*-ncap", "kept/sub"]\n')
    for folder in ("drafts", "euro-ncap", ".hidden", "build", "kept/sub", "kept/other", "env",
                   "__pycache__"):
        (root / folder).mkdir(parents=True)
        name = folder.replace("/", "_").replace("-", "_").strip("._")
        (root / folder / f"{name}.scenario.yaml").write_text(tiny_scene(name))
    (root / "env" / "pyvenv.cfg").write_text("home = /usr/bin\n")
    plugin, _ = plugin_verdicts(pytester, str(root))
    swept, code, payload, _ = sweep_verdicts(capsys, tmp_path, root)
    assert set(swept) == set(plugin) == {"hidden", "build", "kept_other"}
    assert code == 0
    assert payload["config"]["norecursedirs"] == ["drafts", "*-ncap", "kept/sub"]
    # A folder named on the command line is swept whatever the setting says.
    swept, _, _, _ = sweep_verdicts(capsys, tmp_path, root / "euro-ncap")
    assert set(swept) == {"euro_ncap"}


def test_this_project_s_sweep_of_its_scenes_leaves_out_the_euro_ncap_catalogue():
    # pyproject.toml leaves scenarios/euro-ncap out of pytest's run of scenarios/.
    scenarios = Path(__file__).resolve().parents[1] / "scenarios"
    files = {Path(t.file).parent.name for t in collect_tasks([scenarios])}
    assert files == {"scenarios"}
    assert {Path(t.file).parent.name for t in collect_tasks([scenarios / "euro-ncap"])} == {
        "euro-ncap"}


def test_a_marks_selection_of_no_run_exits_as_pytest_does(pytester, capsys, tmp_path):
    pytester.makefile(".scenario.yaml", slow=tiny_scene("slow_one") + "marks: [slow]\n")
    result = pytester.runpytest("-p", "no:cacheprovider", "-m", "nightly")
    capsys.readouterr()
    code, out, err = sweep(capsys, pytester.path, "-m", "nightly", "--workers", "1")
    assert result.ret == code == pytest.ExitCode.NO_TESTS_COLLECTED
    assert out == ""
    assert err.strip().splitlines()[-1] == (
        "error: -m/--marks 'nightly': selects none of the 1 run (their marks: slow)")


def pytest_collected(pytester, *args):
    """The item names pytest collects (``--collect-only``), each once."""
    result = pytester.runpytest("--collect-only", "-q", "-p", "no:cacheprovider", *args)
    return {line.split("::")[1] for line in result.stdout.lines if "::" in line}


def test_a_folder_s_sweep_follows_linked_folders_as_pytest_does_and_stops_at_loops(
        pytester, capsys, tmp_path):
    root = pytester.path
    elsewhere = tmp_path / "elsewhere"
    (elsewhere / "more").mkdir(parents=True)
    (elsewhere / "more" / "away.scenario.yaml").write_text(tiny_scene("away"))
    (root / "real" / "deep").mkdir(parents=True)
    (root / "real" / "deep" / "home.scenario.yaml").write_text(tiny_scene("home"))
    (root / "linked").symlink_to(elsewhere)
    (root / "real" / "deep" / "loop").symlink_to(root)  # pytest walks it 40 deep
    (root / "gone").symlink_to(tmp_path / "nothing")
    assert pytest_collected(pytester, str(root)) == {"home", "away"}
    swept, code, payload, _ = sweep_verdicts(capsys, tmp_path, root)
    assert swept == {"home": "pass", "away": "pass"} and code == 0
    assert {r["file"] for r in payload["runs"]} == {
        str(root / "real" / "deep" / "home.scenario.yaml"),
        str(root / "linked" / "more" / "away.scenario.yaml")}
    # The linked folder is left out by its own name, as pytest matches it.
    (root / "pytest.ini").write_text("[pytest]\nnorecursedirs = linked\n")
    assert pytest_collected(pytester, str(root)) == {"home"}
    swept, code, _, _ = sweep_verdicts(capsys, tmp_path, root)
    assert swept == {"home": "pass"}


def test_a_sweep_of_a_folder_whose_link_leads_back_above_it_runs(pytester, capsys, tmp_path):
    # sweep sub, sub/back -> ..: the walk meets sub/back/sub, no link itself but sub again.
    # Its note read the link of it: OSError, exit 3, no run and no report.
    root = pytester.path
    (root / "good.scenario.yaml").write_text(tiny_scene("good"))
    (root / "sub").mkdir()
    (root / "sub" / "back").symlink_to("..")
    out = tmp_path / "verdicts.json"
    code, stdout, err = sweep(capsys, root / "sub", "--workers", "1", "--json", out)
    assert code == 0 and "Traceback" not in stdout + err and "error:" not in err
    assert [r["status"] for r in json.loads(out.read_text())["runs"]] == ["pass"]
    assert (f"note: {root / 'sub' / 'back' / 'sub'}: {(root / 'sub').resolve()} again (through "
            f"a link above it), a folder that holds it: not walked again") in err


@pytest.mark.parametrize("bad, code, why", [
    (["-m", "nightly"], 5, "-m/--marks 'nightly': selects none of the 1 run (their marks: "
                              "none)"),
    (["-m", "fast and"], 2, "-m/--marks 'fast and': not a mark expression"),
    (["--workers", "0"], 2, "--workers: must be >= 1, got 0"),
    (["--plot", "sweep.jpg"], 2, "--plot sweep.jpg: must name a .png file")])
def test_a_sweep_stopped_by_bad_input_leaves_no_earlier_report(pytester, capsys, bad, code,
                                                                why):
    # Each printed its error and left an earlier sweep's --json in place, to be read by CI as
    # this sweep's verdicts.
    pytester.makefile(".scenario.yaml", plain=tiny_scene("plain"))
    out = pytester.path / "verdicts.json"
    out.write_text('{"runs": [{"status": "pass"}]}')
    got, _, err = sweep(capsys, pytester.path, "--json", out, *bad)
    assert got == code and f"error: {why}" in err
    payload = json.loads(out.read_text())
    assert payload["runs"] == [] and payload["error"].startswith(why)
    assert payload["summary"]["runs"] == 0


def test_a_sweep_selecting_no_run_counts_them_as_a_sweep_does(pytester, capsys, tmp_path):
    # Its summary had "deselected": 0 and no "planned": the runs -m left out were not counted.
    pytester.makefile(".scenario.yaml", plain=tiny_scene("plain") + "parametrize:\n"
                                                  "  targets.0.rcs.rcs_dbsm: [5.0, 10.0]\n")
    _, code, payload, _ = sweep_verdicts(capsys, tmp_path, pytester.path, "-m", "nightly")
    assert code == 5
    summary = payload["summary"]
    assert summary["runs"] == summary["planned"] == 0 and summary["deselected"] == 2
    _, _, normal, _ = sweep_verdicts(capsys, tmp_path, pytester.path)
    assert set(summary) == set(normal["summary"])
    assert normal["summary"]["planned"] == 2 and normal["summary"]["deselected"] == 0


@pytest.mark.parametrize("address", ["bogus://x", "tcp://127.0.0.1:9"])
def test_a_sweep_whose_scheduler_cannot_be_reached_leaves_no_report_of_a_sweep_under_way(
        scenes, capsys, monkeypatch, address):
    # Its --json kept the placeholder: "interrupted ... or it is still running".
    pytest.importorskip("distributed")
    monkeypatch.setattr("rts_scenario.sweep.CONNECT_TIMEOUT_S", 1.0)
    out = scenes / "verdicts.json"
    code, _, err = sweep(capsys, scenes / "sub", "--scheduler", address, "--json", out)
    assert code == 2
    why = err.splitlines()[-1].removeprefix("error: ")
    assert why.startswith(f"--scheduler {address}: cannot connect")
    payload = json.loads(out.read_text())
    assert payload["runs"] == [] and payload["error"] == why
    assert "interrupted" not in payload["summary"] and payload["summary"]["planned"] == 1


@pytest.mark.parametrize("bad", [["--workers", "abc"], ["--method", "nope"], ["--bogus"],
                                 ["--plot", "a.png", "--plot", "b.png"]])
def test_a_sweep_refused_by_the_argument_parser_leaves_no_earlier_report(pytester, capsys, bad):
    pytester.makefile(".scenario.yaml", plain=tiny_scene("plain"))
    out = pytester.path / "verdicts.json"
    out.write_text('{"runs": [{"status": "pass"}]}')
    with pytest.raises(SystemExit) as exited:
        main(["sweep", str(pytester.path), "--json", str(out), *bad])
    assert exited.value.code == 2
    why = capsys.readouterr().err.splitlines()[-1].split(" error: ", 1)[1]
    payload = json.loads(out.read_text())
    assert payload["runs"] == [] and payload["error"] == why
    assert payload["summary"]["runs"] == payload["summary"]["planned"] == 0
    assert "interrupted" not in payload["summary"]


def test_a_config_file_pytest_cannot_read_stops_the_sweep_as_it_stops_pytest(pytester, capsys):
    pytester.makefile(".scenario.yaml", plain=tiny_scene("plain"))
    (pytester.path / "pyproject.toml").write_text("[tool.pytest.ini_options\n")
    assert pytester.runpytest("-p", "no:cacheprovider").ret == pytest.ExitCode.USAGE_ERROR
    capsys.readouterr()
    code, out, err = sweep(capsys, pytester.path, "--workers", "1")
    assert code == 2 and out == ""
    assert err.startswith(f"error: cannot read pytest's settings: "
                          f"{pytester.path / 'pyproject.toml'}: ") and err.count("\n") == 1


def test_the_project_s_scene_pattern_chooses_the_scenes_and_reports_those_it_leaves_out(
        pytester, capsys, tmp_path):
    """A scene under the project's rts_scenario_pattern runs; one under another name, the
    default's among them, is reported, in pytest and in the sweep alike, never left out."""
    root = pytester.path
    pytester.makeini("[pytest]\nrts_scenario_pattern = *.scn.yaml\n")
    (root / "a.scn.yaml").write_text(tiny_scene("ped-a"))
    (root / "b.scenario.yaml").write_text(tiny_scene("ped-b"))
    (root / "lab.yaml").write_text("rts_scenario:\n  interface: pcan\n")  # no scene
    expected = {"ped-a": "pass", "b.scenario.yaml": "error"}
    plugin, plugin_code = plugin_verdicts(pytester)
    assert plugin == as_plugin_sees_it(expected)
    assert plugin_code == pytest.ExitCode.TESTS_FAILED
    capsys.readouterr()  # pytest's own report
    swept, code, payload, stdout = sweep_verdicts(capsys, tmp_path, root)
    assert swept == expected
    assert code == 2  # bad input, as for a scene misnamed under the default pattern
    message = (f"{root / 'b.scenario.yaml'} holds a scene (its rts_scenario key) but is not "
               f"named *.scn.yaml (the project's rts_scenario_pattern), so it does not run as "
               f"one; rename it b.scn.yaml")
    assert payload["runs"][1]["reason"] == message
    result = pytester.runpytest("-p", "no:cacheprovider", "-rA")
    result.stdout.fnmatch_lines([f"*error: {message}"])
    assert payload["config"]["rts_scenario_pattern"] == "*.scn.yaml"
    assert "rts_scenario_pattern = *.scn.yaml" in stdout.splitlines()[0]


def test_a_pattern_without_a_plain_suffix_asks_for_a_name_that_matches_it(pytester, capsys,
                                                                          tmp_path):
    root = pytester.path
    pytester.makeini("[pytest]\nrts_scenario_pattern = scene_*.yaml\n")
    (root / "scene_a.yaml").write_text(tiny_scene("a"))
    (root / "b.scenario.yaml").write_text(tiny_scene("b"))
    _, _, payload, _ = sweep_verdicts(capsys, tmp_path, root)
    assert [r["status"] for r in payload["runs"]] == ["error", "pass"]
    assert payload["runs"][0]["reason"].endswith(
        "but is not named scene_*.yaml (the project's rts_scenario_pattern), so it does not "
        "run as one; rename it to match that pattern")


def test_the_scene_pattern_is_read_where_plugins_are_not_loaded_on_their_own(tmp_path,
                                                                             monkeypatch):
    from rts_scenario.sweep import pytest_settings

    (tmp_path / "pytest.ini").write_text("[pytest]\nrts_scenario_pattern = *.scn.yaml\n")
    monkeypatch.setenv("PYTEST_DISABLE_PLUGIN_AUTOLOAD", "1")
    assert pytest_settings([tmp_path]).rts_scenario_pattern == "*.scn.yaml"


@pytest.mark.parametrize(("marks", "passed", "codes", "playback", "status"), [
    ((), False, ("detection_rate",), {}, "fail"),
    (("xfail",), False, ("detection_rate",), {}, "xfail"),
    (("xfail",), True, (), {}, "xpass"),
    # The bench failed the run (nothing played, nothing heard): not the radar's known failure.
    (("xfail",), False, ("detection_rate", "rts_unreachable"), {}, "fail"),
    (("xfail",), False, ("bus_silent",), {}, "fail"),
    (("xfail",), False, ("mapping",), {}, "fail"),
    (("xfail",), False, ("frames_sent_late",), {}, "fail"),
    # A scene that declares frames_lost drops the undelivered datagrams' reason; nothing
    # listening is no RTS all the same.
    (("xfail",), False, ("detection_rate",), {"rts_unreachable": {"datagrams": 40}}, "fail"),
])
def test_an_xfail_mark_covers_the_radar_s_check_not_the_bench(marks, passed, codes, playback,
                                                              status):
    from rts_scenario.report import bench_failures
    from rts_scenario.sweep import marked_status

    assert marked_status(marks, passed, False, bench_failures(codes, playback)) == status


@pytest.mark.parametrize("step", ["pytest_settings", "collect_tasks"])
def test_a_sweep_stopped_before_its_runs_leaves_no_earlier_report(tmp_path, capsys,
                                                                   monkeypatch, step):
    # Ctrl-C while the sweep collected its runs: the earlier sweep's --json stayed in place.
    import rts_scenario.sweep as sweep

    real, calls = getattr(sweep, step), []

    def stopped_once(*args, **kwargs):
        calls.append(1)
        if len(calls) == 1:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(sweep, step, stopped_once)
    report = tmp_path / "sweep.json"
    report.write_text(json.dumps({"runs": [{"status": "pass"}], "summary": {"runs": 1}}))
    scene = str(Path(__file__).resolve().parents[1] / "scenarios"
                / "approaching_target.scenario.yaml")
    assert main(["sweep", scene, "--workers", "1", "--json", str(report)]) == 1
    assert capsys.readouterr().err.endswith("error: interrupted\n")
    written = json.loads(report.read_text())
    assert written["runs"] == [] and written["summary"]["interrupted"] is True
    assert written["summary"]["runs"] == 0


def test_a_sweep_stopped_in_an_import_still_replaces_its_report(tmp_path, capsys, monkeypatch):
    # The stop left a module half imported: the outputs' check could not run again, and the
    # earlier report stayed ("not replaced after the stop").
    import rts_scenario.cli.sweep as sweep_cli

    calls = []

    def broken(args):
        calls.append(1)
        if len(calls) == 1:
            raise KeyboardInterrupt
        raise AttributeError("partially initialized module 'yaml' has no attribute 'error'")

    monkeypatch.setattr(sweep_cli, "_outputs_checked", broken)
    report = tmp_path / "sweep.json"
    report.write_text(json.dumps({"runs": [{"status": "pass"}], "summary": {"runs": 1}}))
    scene = str(Path(__file__).resolve().parents[1] / "scenarios"
                / "approaching_target.scenario.yaml")
    assert main(["sweep", scene, "--workers", "1", "--json", str(report)]) == 1
    assert capsys.readouterr().err == "error: interrupted\n"
    assert json.loads(report.read_text()) == {
        "runs": [], "summary": {"runs": 0, "interrupted": True}, "config": None}


def test_a_misnamed_scene_in_a_folder_is_no_place_for_the_report(tmp_path, capsys):
    # Reported as an erred run, the file was then written over by --json.
    (tmp_path / "a.scenario.yaml").write_text(tiny_scene("a"))
    misnamed = tmp_path / "b.yaml"
    misnamed.write_text(tiny_scene("b"))
    code = main(["sweep", str(tmp_path), "--workers", "1", "--json", str(misnamed)])
    assert code == 2
    assert f"--json {misnamed}: the same file as SCENE {misnamed}" in capsys.readouterr().err
    assert misnamed.read_text() == tiny_scene("b")


def test_a_marked_scene_whose_parametrize_block_is_broken_is_selected_by_its_marks(tmp_path,
                                                                                    capsys):
    # `sweep -m slow` left out a slow scene whose parametrize block did not expand.
    (tmp_path / "ok.scenario.yaml").write_text(tiny_scene("ok") + "marks: [slow]\n")
    (tmp_path / "empty_list.scenario.yaml").write_text(
        tiny_scene("empty-list") + "marks: [slow]\nparametrize:\n  targets.0.rcs.rcs_dbsm: []\n")
    (tmp_path / "fast.scenario.yaml").write_text(
        tiny_scene("fast") + "parametrize:\n  targets.0.rcs.rcs_dbsm: []\n")
    got, code, payload, _ = sweep_verdicts(capsys, tmp_path, tmp_path, "-m", "slow")
    assert got == {"ok": "pass", "empty_list": "error"} and code == 2
    assert payload["summary"]["deselected"] == 1


def test_a_scene_pattern_that_names_no_scene_files_stops_the_sweep(tmp_path, capsys):
    # As in the plugin: an empty pattern made every scene an erred run, misnamed.
    (tmp_path / "ok.scenario.yaml").write_text(tiny_scene("ok"))
    (tmp_path / "pytest.ini").write_text("[pytest]\nrts_scenario_pattern = *.py\n")
    code, out, err = sweep(capsys, tmp_path)
    assert code == 2 and out == ""
    assert err.strip() == (f"error: {tmp_path / 'pytest.ini'}: rts_scenario_pattern = '*.py': "
                           f"must be a glob of scene file names that can end in .yaml or .yml, "
                           f"without a folder (default *.scenario.yaml)")
