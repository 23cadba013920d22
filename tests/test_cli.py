import json
import os
import re
import shutil
import sys
from pathlib import Path

import pytest

import rts_scenario.cli as cli

ROOT = Path(__file__).resolve().parents[1]


def test_bench_reports_performance_figures_in_text_and_json(tmp_path, capsys, monkeypatch):
    """The performance section: each figure with its comparison, goal and whether it is met."""
    from rts_scenario import perf

    calls = []

    def quick(cut_in, scale_s):  # the real start-up figures only; the others take minutes
        calls.append((cut_in, scale_s))
        return perf.startup(cut_in, rounds=1)

    monkeypatch.setattr(perf, "all_figures", quick)
    out, md = tmp_path / "bench.json", tmp_path / "bench.md"
    code = cli.main(["bench", "--targets", "200", "--repeats", "1", "--scene-s", "0",
                     "--no-honest", "--scale-s", "0", "--json", str(out), "--markdown", str(md)])
    assert code == 0 and calls and calls[0][1] == 0.0
    text = capsys.readouterr().out
    assert "import rts_scenario (fresh interpreter)" in text and "vs import numpy" in text
    figure, runner, repeat = json.loads(out.read_text())["performance"]
    for each in (figure, runner):
        assert each["unit"] == "ms" and each["value"] > 0 and each["comparison_value"] > 0
        assert each["met"] == (each["value"] <= 150.0)
    assert runner["name"] == "start-up of a cut-in run (the command's)"
    assert runner["value"] > figure["value"]  # the package alone loads next to nothing
    assert repeat["name"] == "repeated cut-in run, in process" and repeat["value"] > 0
    # The Markdown file: the same figure in the README's table, the solver table fenced.
    markdown = md.read_text()
    row = next(line for line in markdown.splitlines() if line.startswith("| import"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[0] == figure["name"] and cells[4] == "≤ 150 ms"
    assert float(cells[1].removesuffix(" ms")) == pytest.approx(figure["value"], rel=5e-3)
    assert cells[5] == ("met" if figure["met"] else "**not met**")
    assert "### Speed against error\n\n```\nmethod" in markdown
    assert "### End to end" not in markdown and "### The honest" not in markdown


def test_bench_markdown_and_json_may_not_name_one_file(tmp_path, capsys):
    same = tmp_path / "bench.out"
    assert cli.main(["bench", "--no-performance", "--json", str(same),
                     "--markdown", str(same)]) == 2
    err = capsys.readouterr().err
    assert err.count("error:") == 1 and "--json" in err and "--markdown" in err
    assert not same.exists()


def test_bench_json_has_every_section_when_one_is_skipped(tmp_path):
    """`end_to_end` is null with --scene-s 0, as `honest` and `performance` are [] when skipped."""
    from rts_scenario import bench

    out = tmp_path / "bench.json"
    bench.write_json([], [], out, end=None, honest_rows=None, figures=None)
    data = json.loads(out.read_text())
    assert set(data) == {"solver", "quantization", "honest", "end_to_end", "performance"}
    assert data["end_to_end"] is None and data["honest"] == [] and data["performance"] == []


def test_bench_prints_table_and_writes_json(tmp_path, capsys):
    out = tmp_path / "bench.json"
    code = cli.main(["bench", "--targets", "2000", "--repeats", "1", "--scene-s", "10",
                     "--no-performance", "--json", str(out)])
    assert code == 0
    text = capsys.readouterr().out
    assert "target-frames/s" in text and "exact" in text and "awr1843boost" in text
    data = json.loads(out.read_text())
    rows = data["solver"]
    quantized = {(q["array"], q["mode"]): q for q in data["quantization"]}
    for array in ("paper", "awr1843boost"):
        assert quantized[(array, "aware")]["max_deg"] <= 0.05
        assert quantized[(array, "naive")]["max_deg"] > quantized[(array, "aware")]["max_deg"]
    assert {(r["method"], r["array"]) for r in rows} == {
        (m, a) for m in ("paper", "exact") for a in ("paper", "awr1843boost")
    }
    for row in rows:
        assert row["throughput_per_s"] > 0
        assert row["feasible"] == row["grid_points"] == 30
        if row["method"] == "exact":
            assert row["max_az_deg"] <= 1e-3 and row["max_el_deg"] <= 1e-3
        else:
            assert 0.1 < row["rms_az_deg"] < 0.5
    honest = {(r["method"], r["radar"], r["estimator"], r["fidelity"]): r
              for r in data["honest"]}
    assert len(honest) == 27
    assert all(r["missed"] == 0 for key, r in honest.items() if key[1] != "cascade-12x16")
    # With the FEs' modeled responses the exact method is exact on the honest bench for a
    # Bartlett radar, the estimator-aware one for a TI-style radar too; the paper's is not.
    for radar in ("paper", "awr1843boost"):
        for fidelity in ("analytic", "adc"):
            exact = honest[("exact", radar, "bartlett", fidelity)]
            aware = honest[("estimator", radar, "ti", fidelity)]
            assert max(exact["max_az_deg"], exact["max_el_deg"]) <= 0.002
            assert max(aware["max_az_deg"], aware["max_el_deg"]) <= 0.005
            assert honest[("exact", radar, "ti", fidelity)]["max_az_deg"] > 0.03
            assert honest[("paper", radar, "bartlett", fidelity)]["max_el_deg"] > 0.3
    # The cascade's beams are far narrower than kit-table1's FE spacing: no grid point can be
    # synthesized (NO_SOLUTION or SPLIT), and the table says so instead of an error figure.
    cascade = honest[("exact", "cascade-12x16", "bartlett", "analytic")]
    assert cascade["missed"] == 30 and cascade["max_az_deg"] is None
    end = data["end_to_end"]
    assert end["frames"] == 200 and end["targets"] == 4 and end["passed"]
    assert end["realtime_factor"] == pytest.approx(10.0 / end["wall_s"])
    assert "end to end: motorway-10s" in text


def test_bad_input_is_one_line_and_exit_2(capsys):
    assert cli.main(["bench", "--rig", "nope"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: unknown rig preset 'nope'; valid presets:")
    assert "Traceback" not in err
    assert cli.main(["bench", "--targets", "0"]) == 2
    assert "--targets" in capsys.readouterr().err


def test_run_exit_codes_json_and_plots(tmp_path, capsys):
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    good = root / "scenarios" / "highway_following.scenario.yaml"
    out = tmp_path / "report.json"
    assert cli.main(["run", str(good), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "PASS: highway-following" in text and "timing:" in text
    report = json.loads(out.read_text())
    for key in ("passed", "frames", "targets", "errors", "detection_rate", "timing",
                "false_detections", "bus"):
        assert key in report
    assert report["errors"]["az_deg"]["rms"] < 0.5 and report["errors"]["range_m"]["max"] >= 0
    failing = tmp_path / "fail.scenario.yaml"
    failing.write_text(good.read_text().replace("az_deg: 0.5", "az_deg: 0.000001"))
    assert cli.main(["run", str(failing)]) == 1
    assert "FAIL" in capsys.readouterr().out
    assert cli.main(["run", str(tmp_path / "missing.scenario.yaml")]) == 2
    assert capsys.readouterr().err.startswith("error: ")


def test_a_plot_is_the_png_matplotlib_saves(tmp_path):
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt

    from rts_scenario import plots

    def figure():
        fig, ax = plt.subplots()
        ax.plot([0, 1, 2], [1, 0, 2])
        return fig

    reference = figure()
    reference.tight_layout()
    reference.savefig(tmp_path / "reference.png", dpi=110)
    plt.close(reference)
    plots._save(figure(), tmp_path / "p.png")
    assert (tmp_path / "p.png").read_bytes() == (tmp_path / "reference.png").read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.png", "reference.png"]


@pytest.mark.parametrize("exc", [KeyboardInterrupt(), OSError(28, "No space left on device")],
                         ids=["interrupt", "full-disk"])
def test_plots_written_part_way_leave_the_previous_ones(tmp_path, capsys, cut_short_drafts,
                                                        exc):
    # A run's --plot PNGs over an earlier run's, stopped part way: each stays the earlier
    # whole picture, never half a PNG.
    pytest.importorskip("matplotlib")
    scene = ROOT / "scenarios" / "gantry_stopped_car.scenario.yaml"
    folder = tmp_path / "plots"
    assert cli.main(["run", str(scene), "--plot", str(folder)]) == 0
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    assert len(before) == 3 and all(data.startswith(b"\x89PNG") for data in before.values())
    capsys.readouterr()
    cut_short_drafts(exc)
    try:
        code = cli.main(["run", str(scene), "--plot", str(folder)])
    except KeyboardInterrupt:
        code = None
    assert code != 0
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before  # no draft among them


def test_plots_draw_the_schedule_the_run_played(tmp_path, monkeypatch):
    # --method paper plays the paper's weights: the schedule plot is of those, not the exact
    # solver's, with the statuses the run judged by.
    pytest.importorskip("matplotlib")
    import rts_scenario.pipeline as pipeline

    real, calls = pipeline.build_schedule, []

    def spy(*args, **kwargs):
        calls.append(kwargs)
        return real(*args, **kwargs)

    monkeypatch.setattr(pipeline, "build_schedule", spy)
    import matplotlib.pyplot as plt

    from rts_scenario import plots

    drawn = {}

    def no_drawing(fig, path):  # what is drawn is the question, not the pixels
        drawn[path.name] = [(line.get_label(), line.get_zorder()) for line in fig.axes[-1].lines]
        plt.close(fig)
        return path

    monkeypatch.setattr(plots, "_save", no_drawing)
    scene = tmp_path / "short.scenario.yaml"
    scene.write_text((ROOT / "scenarios" / "approaching_target.scenario.yaml").read_text()
                     .replace("duration_s: 7.5", "duration_s: 0.5"))
    assert cli.main(["run", str(scene), "--method", "paper", "--plot", str(tmp_path / "p")]) == 0
    # The plot draws the schedules the run played, every one built as the run played it.
    assert calls and {(c.get("method"), c.get("angle_tolerance_deg")) for c in calls} == {
        ("paper", (0.5, 1.0))}
    # The car straight ahead sits on the middle FE's direction: its track is drawn over the
    # FE's marker, not hidden under it (the quads' outlines, zorder 0, are the background).
    lines = drawn["approaching-target-scene.png"]
    fe = next(z for label, z in lines if label == "front ends")
    assert fe < min(z for label, z in lines if label != "front ends" and z > 0)


def test_a_can_channel_that_cannot_be_opened_is_bad_input(capsys):
    # The arguments name a CAN channel this machine does not have: exit 2 (as emulate), not
    # a runtime error, with one line naming the interface and the channel.
    scene = str(ROOT / "scenarios" / "cut_in.scenario.yaml")
    code = cli.main(["run", scene, "--can-interface", "socketcan", "--can-channel",
                     "rts-no-such0"])
    assert code == 2
    err = capsys.readouterr().err
    assert "cannot open CAN interface 'socketcan' channel 'rts-no-such0'" in err
    assert "Traceback" not in err


def test_schedule_and_list_outputs(tmp_path, capsys):
    from pathlib import Path

    from rts_scenario.outputs.file import read_schedule

    root = Path(__file__).resolve().parents[1]
    target = tmp_path / "s.npz"
    assert cli.main(["schedule", str(root / "scenarios" / "cut_in.scenario.yaml"), "--output",
                     f"file:{target}", "--variant", "estimator=ti"]) == 0
    assert read_schedule(target).n_frames == 240
    assert cli.main(["list-outputs"]) == 0
    assert set(capsys.readouterr().out.split()) >= {"file", "udp", "simulated-radar"}


SHORT_SCENE = """\
rts_scenario: 1
name: short
duration_s: 1.0
frame_rate_hz: 20.0
radar: {profile: awr1843boost, mount: {x_m: 3.7, z_m: 0.5}}
rig: wide-3x5
targets:
  - name: car
    motion: {type: stationary, position_m: [30.0, 0.0, 0.6]}
    rcs: {rcs_dbsm: 10.0}
"""


def test_schedule_to_udp_fails_when_nothing_received_it(tmp_path, capsys):
    # An export whose datagrams all came back undelivered said "100% of entries emitted" and
    # exited 0, as when an RTS played every frame.
    import socket

    from rts_scenario.outputs.udp import UdpReceiver

    scene = tmp_path / "short.scenario.yaml"
    scene.write_text(SHORT_SCENE)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        closed = sock.getsockname()[1]
    assert cli.main(["schedule", str(scene), "--output", f"udp://127.0.0.1:{closed}"]) == 1
    out, err = capsys.readouterr()
    assert "100% of entries emitted" in out
    assert re.match(rf"error: rts_unreachable: \d+ datagrams to udp://127.0.0.1:{closed} came "
                    rf"back undelivered \(Connection refused\)", err), err
    # As run judges it: a scene that declares frames_lost is told, not failed.
    declared = tmp_path / "declared.scenario.yaml"
    declared.write_text(SHORT_SCENE.replace("name: short", "name: declared")
                        + "expectations: {expected_limits: [frames_lost]}\n")
    assert cli.main(["schedule", str(declared), "--output", f"udp://127.0.0.1:{closed}"]) == 0
    err = capsys.readouterr().err
    assert err.startswith("note: rts_unreachable: ") and err.endswith(
        "(the scene declares frames_lost)\n"), err
    receiver = UdpReceiver().start()
    try:
        assert cli.main(["schedule", str(scene), "--output",
                         f"udp://127.0.0.1:{receiver.address[1]}"]) == 0
    finally:
        stats = receiver.stop()
    assert stats.frames_applied == 20 and capsys.readouterr().err == ""


def test_schedule_fails_where_the_rts_plays_another_rig_or_another_sender_s_stream(
        tmp_path, capsys):
    # An RTS that says it has kit-table1 (4 FEs) plays the wide-3x5 schedule's entries from
    # other directions; one whose stream another sender took over played that sender's. Both
    # exited 0; they fail as run fails them, whatever the scene declares of lost frames.
    import threading

    from rts_scenario.outputs import open_output
    from rts_scenario.outputs.udp import UdpReceiver
    from rts_scenario.rig import Rig

    scene = tmp_path / "short.scenario.yaml"
    scene.write_text(SHORT_SCENE + "expectations: {expected_limits: [frames_lost]}\n")
    kit = Rig.preset("kit-table1")
    receiver = UdpReceiver(n_front_ends=kit.n_front_ends, rig_digest=kit.geometry_digest()
                           ).start()
    try:
        assert cli.main(["schedule", str(scene), "--output",
                         f"udp://127.0.0.1:{receiver.address[1]}"]) == 1
    finally:
        receiver.stop()
    err = capsys.readouterr().err
    assert err.startswith("error: rts_rig: the RTS plays a rig of 4 FEs, not the 15 of the "
                          "schedule's (wide-3x5): "), err
    # Another sender's stream, begun 0.3 s into this one's 3 s.
    from rts_scenario.kinematics import compute_tracks
    from rts_scenario.scenario import load_scenario
    from rts_scenario.schedule import build_schedule

    scene.write_text(scene.read_text().replace("duration_s: 1.0", "duration_s: 3.0"))
    loaded = load_scenario(scene)
    theirs = build_schedule(compute_tracks(loaded), loaded.rig, loaded.radar)
    receiver = UdpReceiver().start()
    address = f"udp://127.0.0.1:{receiver.address[1]}"

    def take_over():
        with open_output(address, pacing="fast") as other:
            other.write(theirs)

    thread = threading.Timer(0.3, take_over)
    thread.start()
    try:
        code = cli.main(["schedule", str(scene), "--output", address])
    finally:
        thread.join()
        receiver.stop()
    err = capsys.readouterr().err
    assert code == 1, err
    assert re.search(r"error: rts_stream: the RTS's counters count \d+ datagrams more than "
                     r"this schedule sent", err), err


def test_unwritable_json_is_one_line_naming_option_and_path(tmp_path, capsys):
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    target = tmp_path / "no-such-folder" / "report.json"
    assert cli.main(["run", str(root / "scenarios" / "cut_in.scenario.yaml"),
                     "--json", str(target)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: --json {target}: cannot write:")
    assert "Traceback" not in err


def test_validate_a_directory_is_a_clear_error(tmp_path, capsys):
    assert cli.main(["validate", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {tmp_path}: cannot read file:")
    assert "Traceback" not in err


def test_validate_notes_the_bench_once_per_scene_file(capsys):
    # Both scenes play on awr1843boost and wide-3x5: each file's lines say its bench whole,
    # once for its variants, whatever file came before it.
    scenes = [str(ROOT / "scenarios" / f"{name}.scenario.yaml")
              for name in ("cut_in", "accelerating_lead")]
    assert cli.main(["validate", *scenes]) == 0
    notes = [line for line in capsys.readouterr().out.splitlines()
             if "Fraunhofer distance" in line]
    assert [line.split(": ", 2)[1] for line in notes] == [f"{scenes[0]}[estimator=bartlett]",
                                                         scenes[1]], notes
    assert len({line.split(": ", 2)[2] for line in notes}) == 1


@pytest.mark.parametrize("command", ["run", "validate"])
def test_a_folder_given_as_a_scene_says_which_commands_take_folders(tmp_path, capsys, command):
    # `sweep scenarios/` and `pytest scenarios/` take a folder; run and validate take files.
    assert cli.main([command, str(tmp_path)]) == 2
    assert capsys.readouterr().err.splitlines()[0] == (
        f"error: {tmp_path}: cannot read file: a folder, where a scene file goes "
        f"({tmp_path}/*.scenario.yaml); rts-scenario sweep and pytest take folders")


def test_run_writes_every_detection_as_csv(tmp_path, capsys):
    import csv

    out = tmp_path / "d.csv"
    scenes = [str(ROOT / "scenarios" / f"{s}.scenario.yaml") for s in ("cut_in", "overtaking")]
    code = cli.main(["run", *scenes, "--detections", str(out), "--json", str(tmp_path / "r.json")])
    assert code == 0
    rows = list(csv.DictReader(out.open()))
    report = json.loads((tmp_path / "r.json").read_text())
    # cut_in runs once per estimator: the variant tells its two runs apart.
    assert [(e["scene"], e["variant"]) for e in report] == [
        ("cut-in", "estimator=bartlett"), ("cut-in", "estimator=ti"), ("overtaking", "")]
    for entry in report:
        mine = [r for r in rows
                if r["scene"] == entry["scene"] and r["variant"] == entry["variant"]]
        detected = sum(t["detected_frames"] + t["out_of_tolerance_frames"]
                       for t in entry["targets"])
        assert len(mine) == detected + entry["false_detections"]
    # The columns outside tools read, in their places; the ground truth after them.
    assert list(rows[0]) == ["scene", "cycle", "t_s", "range_m", "radial_velocity_mps", "az_deg",
                             "el_deg", "snr_db", "rcs_dbsm", "target", "variant", "file",
                             "truth_range_m", "truth_radial_velocity_mps", "truth_az_deg",
                             "truth_el_deg", "truth_rcs_dbsm"]
    assert {r["target"] for r in rows} <= {"cutting-car", "overtaker", ""}
    assert {r["file"] for r in rows} == set(scenes)


def test_detections_of_two_scene_files_of_one_name_are_told_apart(tmp_path):
    # An edited copy of a scene keeps its name: the CSV's file column says which run is which.
    import csv

    text = (ROOT / "scenarios" / "approaching_target.scenario.yaml").read_text()
    text = text.replace("duration_s: 7.5", "duration_s: 0.5")
    first, second = tmp_path / "a.scenario.yaml", tmp_path / "b.scenario.yaml"
    first.write_text(text.replace("rcs_dbsm: 12.0", "rcs_dbsm: 10.0"))
    second.write_text(text)
    out = tmp_path / "d.csv"
    assert cli.main(["run", str(first), str(second), "--detections", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    assert {r["scene"] for r in rows} == {"approaching-target"}
    by_file = {f: {r["rcs_dbsm"] for r in rows if r["file"] == f} for f in (str(first),
                                                                            str(second))}
    assert by_file == {str(first): {"10"}, str(second): {"12"}}


def two_variant_scene(folder: Path) -> Path:
    """cut_in, 4 s long, once in the rig's coverage (passes) and once far outside it (fails)."""
    text = (ROOT / "scenarios" / "cut_in.scenario.yaml").read_text()
    text = text.replace("duration_s: 12.0", "duration_s: 4.0").replace(
        "radar.estimator: [bartlett, ti]", "targets.0.motion.position_m.1: [3.5, 40.0]")
    path = folder / "two.scenario.yaml"
    path.write_text(text)
    return path


def test_run_runs_every_variant_of_a_parametrized_scene(tmp_path, capsys):
    import csv

    scene = two_variant_scene(tmp_path)
    report, detections, log = tmp_path / "r.json", tmp_path / "d.csv", tmp_path / "bus.blf"
    code = cli.main(["run", str(scene), "--json", str(report), "--detections", str(detections),
                     "--record", str(log)])
    assert code == 1  # one variant fails: the run fails, whatever the other does
    captured = capsys.readouterr()
    text = captured.out
    assert "PASS: cut-in[1=3.5]" in text and "FAIL: cut-in[1=40.0] - " in text
    assert f"PASS cut-in[1=3.5] ({scene})" in text and f"FAIL cut-in[1=40.0] ({scene})" in text
    assert f"warning: {scene}[1=40.0]: cutting-car: out_of_coverage" in captured.err
    entries = json.loads(report.read_text())
    assert [(e["scene"], e["variant"], e["parameters"], e["status"], e["passed"])
            for e in entries] == [
        ("cut-in", "1=3.5", {"targets.0.motion.position_m.1": 3.5}, "pass", True),
        ("cut-in", "1=40.0", {"targets.0.motion.position_m.1": 40.0}, "fail", False)]
    assert entries[1]["targets"][0]["limits"] == {"out_of_coverage": 80}
    rows = list(csv.DictReader(detections.open()))
    assert rows and {r["variant"] for r in rows} <= {"1=3.5", "1=40.0"}
    passing = [r for r in rows if r["variant"] == "1=3.5"]
    assert len(passing) == entries[0]["targets"][0]["detected_frames"] + entries[0][
        "targets"][0]["out_of_tolerance_frames"] + entries[0]["false_detections"]
    # One bus log per variant, its sidecar naming the variant; none under the name given.
    assert not log.exists()
    for variant, value in (("1=3.5", 3.5), ("1=40.0", 40.0)):
        sidecar = json.loads((tmp_path / f"bus[{variant}].blf.rts.json").read_text())
        assert sidecar["variant"] == variant
        assert sidecar["parameters"] == {"targets.0.motion.position_m.1": value}
        assert f"wrote {tmp_path / f'bus[{variant}].blf'} and " in text


def test_run_names_each_variant_s_plots_and_logs(tmp_path):
    from rts_scenario.cli.run import variant_logs

    assert variant_logs("d/bus.blf", [""]) == {}
    assert variant_logs("d/bus.blf", ["speed_mps=10.0-1=-0.5", "x=a/b", "x=a:b"]) == {
        "speed_mps=10.0-1=-0.5": "d/bus[speed_mps=10.0-1=-0.5].blf",
        "x=a/b": "d/bus[x=a_b].blf", "x=a:b": "d/bus[x=a_b-2].blf"}
    pytest.importorskip("matplotlib")
    scene = two_variant_scene(tmp_path)
    assert cli.main(["run", str(scene), "--plot", str(tmp_path / "plots")]) == 1
    names = sorted(p.name for p in (tmp_path / "plots").iterdir())
    assert names and len(names) % 2 == 0  # every plot names its run
    assert sum(n.startswith("cut-in[1=3.5]-") for n in names) == len(names) // 2
    assert sum(n.startswith("cut-in[1=40.0]-") for n in names) == len(names) // 2


def test_check_takes_the_variant_from_the_sidecar_or_refuses(tmp_path, capsys):
    import shutil

    scene = two_variant_scene(tmp_path)
    assert cli.main(["run", str(scene), "--record", str(tmp_path / "bus.blf")]) == 1
    capsys.readouterr()
    failing, passing = tmp_path / "bus[1=40.0].blf", tmp_path / "bus[1=3.5].blf"
    out = tmp_path / "c.json"
    # The sidecar says which variant the log is of: the live verdict again, for that variant.
    assert cli.main(["check", str(scene), "--log", str(failing), "--json", str(out)]) == 1
    text = capsys.readouterr().out
    assert "variant cut-in[1=40.0] (from the log's sidecar)" in text
    assert "FAIL: cut-in[1=40.0] - " in text
    data = json.loads(out.read_text())
    assert (data["variant"], data["status"]) == ("1=40.0", "fail")
    # Without a sidecar nothing says which run the log is: refused, naming the choices.
    bare = tmp_path / "bare.blf"
    shutil.copy(passing, bare)
    assert cli.main(["check", str(scene), "--log", str(bare)]) == 2
    err = capsys.readouterr().err
    assert err == (f"error: {scene}: a parametrized scene (2 variants) and no sidecar of the log "
                   f"{bare} names the one it records: choose one with --variant ID: 1=3.5, "
                   f"1=40.0\n")
    assert cli.main(["check", str(scene), "--log", str(bare), "--variant", "1=3.5"]) == 0
    assert "PASS: cut-in[1=3.5]" in capsys.readouterr().out
    assert cli.main(["check", str(scene), "--log", str(bare), "--variant", "1=7"]) == 2
    assert capsys.readouterr().err == (f"error: --variant 1=7: not a variant of {scene}; valid: "
                                       f"1=3.5, 1=40.0\n")
    # --variant and the sidecar disagree: refused, not checked against either.
    assert cli.main(["check", str(scene), "--log", str(passing), "--variant", "1=40.0"]) == 2
    assert capsys.readouterr().err == (f"error: --variant 1=40.0: the log {passing} was recorded "
                                       f"for variant '1=3.5' (its sidecar)\n")
    # A log of a variant is no log of another scene: the scenes are named, the mistake made.
    other = ROOT / "scenarios" / "highway_following.scenario.yaml"
    assert cli.main(["check", str(other), "--log", str(passing)]) == 2
    assert capsys.readouterr().err == (
        f"error: --log {passing}: recorded for scene 'cut-in' (its sidecar), not "
        f"'highway-following': check it against that scene's file\n")


def test_check_log_refuses_a_scene_other_than_the_recorded_variant(tmp_path):
    from rts_scenario.recheck import LogError, check_log
    from rts_scenario.scenario import load_scenario

    scene = two_variant_scene(tmp_path)
    assert cli.main(["run", str(scene), "--record", str(tmp_path / "bus.blf")]) == 1
    log = tmp_path / "bus[1=3.5].blf"
    with pytest.raises(LogError, match=r"recorded for variant '1=3.5' \(its sidecar\), not the "
                                       r"scene without parametrize"):
        check_log(load_scenario(scene), log)
    with pytest.raises(LogError, match="not variant '1=40.0'"):
        check_log(load_scenario(scene, {"targets.0.motion.position_m.1": 40.0}), log)
    assert check_log(load_scenario(scene, {"targets.0.motion.position_m.1": 3.5}),
                     log).report.passed


def test_a_variant_with_a_long_id_records_and_plots_under_a_name_that_fits(tmp_path, capsys):
    # Its log name, LOG[ID].blf, ran past the 255 bytes of a file name: the run stopped with
    # "error: OSError: File name too long", exit 3, no scene run.
    scene = tmp_path / "short.scenario.yaml"
    scene.write_text(SHORT_SCENE + "parametrize:\n  description: ['" + "d" * 300
                     + "', plain]\n")
    assert cli.main(["run", str(scene), "--record", str(tmp_path / "bus.blf"),
                     "--plot", str(tmp_path / "plots")]) == 0
    logs = sorted(p.name for p in tmp_path.glob("bus*.blf"))
    assert len(logs) == 2 and "bus[description=plain].blf" in logs
    assert all(len(name.encode()) < 200 for name in logs)
    assert all(len(p.name) < 200 for p in (tmp_path / "plots").iterdir())
    # The log's variant comes from its sidecar, not its name: the cut one checks.
    (long,) = [name for name in logs if name != "bus[description=plain].blf"]
    capsys.readouterr()
    assert cli.main(["check", str(scene), "--log", str(tmp_path / long)]) == 0


def test_validate_says_which_variants_an_error_is_of(tmp_path, capsys):
    # One line per error; its variants named, not only the first that hit it.
    scene = two_variant_scene(tmp_path)
    scene.write_text(scene.read_text().replace("rig: wide-3x5", "rig: nowhere.rig.yaml"))
    assert cli.main(["validate", str(scene)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {scene}:") and err[0].endswith(
        "nowhere.rig.yaml' (looked in " + str(tmp_path) + ") [every variant]"), err
    scene.write_text(scene.read_text().replace("rig: nowhere.rig.yaml", "rig: wide-3x5")
                     .replace("[3.5, 40.0]", "[3.5, 40.0, 1.0e+6]"))
    assert cli.main(["validate", str(scene)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert [line for line in err if line.startswith("error: ")][0].endswith(" [1=1000000.0]")


def test_list_validate_and_schedule_show_the_variants(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(ROOT)
    assert cli.main(["list"]) == 0
    out = capsys.readouterr().out
    assert ("  scenarios/cut_in.scenario.yaml\n    [estimator=bartlett]\n    [estimator=ti]\n"
            in out)
    scene = two_variant_scene(tmp_path)
    assert cli.main(["validate", str(scene)]) == 0
    out = capsys.readouterr().out
    # Each variant's status line (valid, a run of which fails where warnings say so).
    assert f": {scene}[1=3.5]: " in out and f": {scene}[1=40.0]: " in out
    assert all(line.startswith(("ok: ", "valid, a run fails: ", "note: "))
               for line in out.splitlines()), out
    target = tmp_path / "s.npz"
    assert cli.main(["schedule", str(scene), "--output", f"file:{target}"]) == 2
    assert capsys.readouterr().err == (f"error: {scene}: a parametrized scene (2 variants): "
                                       f"choose one with --variant ID: 1=3.5, 1=40.0\n")
    assert not target.exists()
    assert cli.main(["schedule", str(scene), "--output", f"file:{target}", "--variant",
                     "1=40.0"]) == 0
    assert capsys.readouterr().out.startswith(f"{scene}[1=40.0]: 80 frames")


def test_schedule_warns_of_what_it_does_not_play(tmp_path, capsys):
    # As validate and run say it: a target the export leaves unplayed is named, not only
    # counted in the share of entries emitted.
    scene = two_variant_scene(tmp_path)
    target = tmp_path / "s.npz"
    assert cli.main(["schedule", str(scene), "--output", f"file:{target}", "--variant",
                     "1=40.0"]) == 0
    out, err = capsys.readouterr()
    assert err.startswith(f"warning: {scene}[1=40.0]: cutting-car: out_of_coverage in "), err
    assert out.startswith(f"{scene}[1=40.0]: 80 frames")


def test_a_run_killed_part_way_leaves_no_detections_named_as_the_runs(tmp_path):
    # A process killed (SIGKILL, the machine's memory exhausted, a power cut) runs no handler:
    # its detections were written under their own name and looked like a whole run's.
    import subprocess

    scenes = [str(ROOT / "scenarios" / f"{name}.scenario.yaml")
              for name in ("approaching_target", "cut_out")]
    detections = tmp_path / "d.csv"
    detections.write_text("a previous run's\n")
    script = (
        "import os, sys\n"
        "import rts_scenario.pipeline as pipeline\n"
        "import rts_scenario.cli as cli\n"
        "real, calls = pipeline.run_scene, []\n"
        "def killed(scene, options, **kwargs):\n"
        "    calls.append(scene.name)\n"
        "    if len(calls) == 2:\n"
        "        sys.stdout.flush()\n"
        "        os._exit(137)\n"
        "    return real(scene, options, **kwargs)\n"
        "pipeline.run_scene = killed\n"
        "cli.main(sys.argv[1:])\n"
    )
    done = subprocess.run([sys.executable, "-c", script, "run", *scenes,
                           "--detections", str(detections)], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 137, done.stderr
    # Neither the previous run's file (not this run's) nor a file of this run's name.
    assert not detections.exists()
    drafts = [p for p in tmp_path.iterdir() if p.name != "d.csv"]
    assert len(drafts) == 1 and drafts[0].name.startswith(".d.csv.")
    assert drafts[0].name.endswith(".draft")
    rows = drafts[0].read_text().splitlines()
    assert len(rows) > 100 and all(r.startswith("approaching-target,") for r in rows[1:])


def test_a_sidecar_that_cannot_be_written_keeps_the_verdict(tmp_path, capsys, monkeypatch):
    # A disk that fills while the scene runs: the sidecar's write failed after the check, and
    # the run ended as an error with its verdict lost.
    import rts_scenario.pipeline as pipeline

    def full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(pipeline, "write_log_sidecar", full)
    log, report = tmp_path / "r.blf", tmp_path / "r.json"
    scene = str(ROOT / "scenarios" / "approaching_target.scenario.yaml")
    code = cli.main(["run", scene, "--record", str(log), "--json", str(report)])
    out, err = capsys.readouterr()
    assert code == 3  # a runtime error, as the exit codes say
    assert "PASS: approaching-target" in out
    assert (f"error: --record {log}: {log}.rts.json: cannot write: No space left on device; "
            f"the verdict above stands, but a check of {log} has no sidecar") in err
    entry = json.loads(report.read_text())
    assert entry["status"] == "pass" and entry["passed"] is True
    assert log.exists() and not Path(f"{log}.rts.json").exists()


def test_runs_writing_one_detections_file_at_once_each_write_their_own(tmp_path):
    from rts_scenario.atomic import Draft

    path = tmp_path / "d.csv"
    path.write_text("previous\n")
    os.chmod(path, 0o640)
    first, second = Draft(path), Draft(path)
    assert not path.exists()  # the previous run's rows are not this run's
    for n in range(1000):
        first.file.write(f"first,{n}\n")
        second.file.write(f"second,{n}\n")
    assert first.keep() == path
    assert path.read_text() == "".join(f"first,{n}\n" for n in range(1000))
    assert second.cut_short() == tmp_path / "d.csv.partial"
    assert path.read_text().startswith("first,0\n")
    assert (tmp_path / "d.csv.partial").read_text().startswith("second,0\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.csv", "d.csv.partial"]
    assert path.stat().st_mode & 0o777 == 0o640  # the file's permissions, not the draft's


def test_detections_through_a_link_cut_short_name_the_file_they_became(tmp_path):
    from rts_scenario.atomic import Draft

    (tmp_path / "real").mkdir()
    (tmp_path / "real" / "d.csv").write_text("previous\n")
    link = tmp_path / "link.csv"
    link.symlink_to(tmp_path / "real" / "d.csv")
    draft = Draft(link)
    draft.file.write("rows\n")
    # It named link.csv.partial, which does not exist: the draft was beside the real file.
    assert draft.cut_short() == tmp_path / "real" / "d.csv.partial"
    assert (tmp_path / "real" / "d.csv.partial").read_text() == "rows\n"
    draft = Draft(tmp_path / "plain.csv")
    draft.file.write("rows\n")
    assert draft.cut_short() == tmp_path / "plain.csv.partial"


def test_detections_to_a_device_are_written_into_it(tmp_path):
    from rts_scenario.atomic import Draft

    draft = Draft(os.devnull)
    draft.file.write("rows\n")
    assert draft.cut_short() == Path(os.devnull)
    assert Path(os.devnull).exists() and not Path(os.devnull + ".partial").exists()


@pytest.mark.parametrize("stop", ["ctrl-c", "sigterm"])
def test_an_interrupted_run_keeps_what_finished_and_leaves_nothing_looking_complete(
        tmp_path, capsys, monkeypatch, request, stop):
    # Ctrl-C, or SIGTERM (a CI job's timeout, `kill`): the run keeps what finished, marks the
    # run under way interrupted, leaves its detections as .partial and exits 1.
    import os
    import signal

    import rts_scenario.pipeline as pipeline

    real = pipeline.run_scene
    calls = []
    swallowed = request.getfixturevalue("sigterm_swallowed") if stop == "sigterm" else None

    def second_is_interrupted(scene, options, **kwargs):
        calls.append(scene.name)
        if len(calls) == 2:
            if stop == "sigterm":
                os.kill(os.getpid(), signal.SIGTERM)
            else:
                raise KeyboardInterrupt
        return real(scene, options, **kwargs)

    monkeypatch.setattr(pipeline, "run_scene", second_is_interrupted)
    scenes = [str(ROOT / "scenarios" / f"{name}.scenario.yaml")
              for name in ("approaching_target", "cut_out", "motorcycle")]
    detections, report = tmp_path / "d.csv", tmp_path / "r.json"
    code = cli.main(["run", *scenes, "--detections", str(detections), "--json", str(report)])
    out, err = capsys.readouterr()
    assert code == 1 and calls == ["approaching-target", "cut-out"]
    assert ("cut_out.scenario.yaml: interrupted (Ctrl-C or a stop signal) while running: "
            "no verdict") in err
    entries = json.loads(report.read_text())
    # The scene under way had loaded: its entry names it by the scene's name (docs/cli.md),
    # as the summary line does.
    assert [(e["scene"], e["status"]) for e in entries] == [("approaching-target", "pass"),
                                                            ("cut-out", "error"),
                                                            ("motorcycle", "error")]
    assert "ERROR cut-out (" in out
    # The scene the stop kept from running is not missing: not run, by its file's name.
    assert entries[2]["error"] == "not run: interrupted (Ctrl-C or SIGTERM) before it ran"
    assert "ERROR motorcycle (" in out
    # The detections so far are kept under a name that says they are not the whole run's.
    assert not detections.exists()
    rows = (tmp_path / "d.csv.partial").read_text().splitlines()
    assert len(rows) > 100 and all(r.startswith("approaching-target,") for r in rows[1:])
    assert f"wrote {detections}.partial (cut short: the run was interrupted)" in out
    if swallowed is not None:
        # The handler the command found is back in place.
        assert swallowed == []
        os.kill(os.getpid(), signal.SIGTERM)
        assert swallowed == [signal.SIGTERM]


@pytest.fixture
def sigterm_swallowed():
    """A SIGTERM handler that only counts, in place of the default that would end pytest.

    A command that handles SIGTERM itself replaces it while it runs, and puts it back.
    """
    import signal

    received = []
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: received.append(signum))
    yield received
    signal.signal(signal.SIGTERM, previous)


@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_a_schedule_export_stopped_by_sigterm_leaves_only_its_draft(tmp_path, capsys, monkeypatch,
                                                                     sigterm_swallowed, suffix):
    # The export goes to PATH.partial and is named PATH once whole: one stopped part way (a CI
    # job's timeout) leaves nothing named like a whole schedule, nor the export before it.
    import os
    import signal

    import rts_scenario.preflight as preflight

    real = preflight.schedule_batches

    def terminated_after_the_first_batch(scene, method="exact", batch_frames=None):
        for n, batch in enumerate(real(scene, method, batch_frames=40)):
            if n == 1:
                os.kill(os.getpid(), signal.SIGTERM)
            yield batch

    monkeypatch.setattr(preflight, "schedule_batches", terminated_after_the_first_batch)
    scene = ROOT / "scenarios" / "cut_in.scenario.yaml"
    target = tmp_path / f"s{suffix}"
    target.write_text("an earlier export")
    code = cli.main(["schedule", str(scene), "--output", f"file:{target}", "--variant",
                     "estimator=ti"])
    _, err = capsys.readouterr()
    assert code == 1 and err.endswith("error: interrupted\n"), err
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"s{suffix}.partial"]


@pytest.mark.parametrize("where", ["variants", "import"])
def test_a_run_stopped_before_its_first_scene_leaves_no_earlier_report(tmp_path, capsys,
                                                                        monkeypatch, where):
    # Ctrl-C while the scenes' variants were read: the --json of an earlier run stayed in
    # place, its "pass" to be read as this run's. A stop while the scenes' package was half
    # imported (its yaml not yet whole) made the "not run" --json fail with an error of that
    # import: exit 3, and the earlier report kept.
    import sys

    import rts_scenario.cli.run as run_cli
    import rts_scenario.scenario as scenario

    def stopped(path):
        raise KeyboardInterrupt

    def stopped_while_importing(args, started):
        monkeypatch.setitem(sys.modules, "rts_scenario.scenario", None)  # import fails
        raise KeyboardInterrupt

    if where == "variants":
        monkeypatch.setattr(scenario, "parametrizations", stopped)
    else:
        monkeypatch.setattr(run_cli, "_run", stopped_while_importing)
    report = tmp_path / "r.json"
    report.write_text(json.dumps({"scene": "approaching-target", "status": "pass"}))
    scene = str(ROOT / "scenarios" / "approaching_target.scenario.yaml")
    assert cli.main(["run", scene, "--json", str(report)]) == 1
    assert capsys.readouterr().err == "error: interrupted\n"
    entry = json.loads(report.read_text())
    assert entry["scene"] == "approaching_target" and entry["file"] == scene
    assert entry["status"] == "error"
    assert entry["error"] == "not run: interrupted (Ctrl-C or SIGTERM) before it ran"
    if where == "variants":
        return

    def broken(*args, **kwargs):
        raise RecursionError("maximum recursion depth exceeded")

    monkeypatch.setattr(run_cli, "write_json", broken)
    assert cli.main(["run", scene, "--json", str(report)]) == 1
    err = capsys.readouterr().err
    assert err == (f"error: --json {report}: not replaced after the stop: RecursionError: "
                   f"maximum recursion depth exceeded\nerror: interrupted\n"), err


def _swallowing_a_stop():
    """Send SIGTERM and swallow its interrupt, as a library's bare ``except:`` does (asammdf
    while python-can imports it; numpy inside some of its calls)."""
    import os
    import signal

    try:
        os.kill(os.getpid(), signal.SIGTERM)
    except BaseException:  # noqa: BLE001 - the library's, not ours
        pass


def test_a_stop_a_library_swallowed_still_ends_the_run_as_stopped(capsys, monkeypatch,
                                                                  sigterm_swallowed):
    # The scene ran on to its end and passed: the command exited 0 after Ctrl-C or SIGTERM.
    import rts_scenario.pipeline as pipeline

    real = pipeline.run_scene

    def swallowed(scene, options, **kwargs):
        _swallowing_a_stop()
        return real(scene, options, **kwargs)

    monkeypatch.setattr(pipeline, "run_scene", swallowed)
    scene = ROOT / "scenarios" / "approaching_target.scenario.yaml"
    code = cli.main(["run", str(scene)])
    out, err = capsys.readouterr()
    assert "PASS: approaching-target" in out  # what it printed stands
    assert code == 1 and err.endswith("error: interrupted\n"), err
    # The next command is not stopped by it.
    monkeypatch.setattr(pipeline, "run_scene", real)
    assert cli.main(["run", str(scene)]) == 0


@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_a_schedule_export_whose_stop_numpy_swallowed_leaves_only_its_draft(
        tmp_path, capsys, monkeypatch, sigterm_swallowed, suffix):
    # numpy swallows an interrupt raised inside some of its calls: the export ran on to its
    # end, was named whole and the command exited 0.
    import rts_scenario.preflight as preflight

    real = preflight.schedule_batches

    def swallowed_after_the_first_batch(scene, method="exact", batch_frames=None):
        for n, batch in enumerate(real(scene, method, batch_frames=40)):
            if n == 1:
                _swallowing_a_stop()
            yield batch

    monkeypatch.setattr(preflight, "schedule_batches", swallowed_after_the_first_batch)
    scene = ROOT / "scenarios" / "cut_in.scenario.yaml"
    target = tmp_path / f"s{suffix}"
    code = cli.main(["schedule", str(scene), "--output", f"file:{target}", "--variant",
                     "estimator=ti"])
    _, err = capsys.readouterr()
    assert code == 1 and err.endswith("error: interrupted\n"), err
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"s{suffix}.partial"]


def test_sigterm_before_a_command_runs_anything_exits_as_ctrl_c(tmp_path, capsys, monkeypatch,
                                                                 sigterm_swallowed):
    import os
    import signal

    import rts_scenario.cli.check as check_command

    def terminated(args):
        os.kill(os.getpid(), signal.SIGTERM)
        return 0

    monkeypatch.setattr(check_command, "_do_check", terminated)
    scene = ROOT / "scenarios" / "approaching_target.scenario.yaml"
    code = cli.main(["check", str(scene), "--log", str(tmp_path / "x.blf")])
    _, err = capsys.readouterr()
    assert code == 1 and err == "error: interrupted\n"


@pytest.mark.parametrize("when", ["as the command returns", "as its handler is put back"])
def test_sigterm_as_a_command_ends_exits_as_ctrl_c_without_a_traceback(
        capsys, monkeypatch, sigterm_swallowed, when):
    # Between the command's end and the old handler back in place, a SIGTERM raised out of
    # main() as a traceback; it ends the command as interrupted, and the old handler is back.
    import os
    import signal

    if when == "as the command returns":
        real = cli._handle

        def handle_then_terminated(args):
            code = real(args)
            os.kill(os.getpid(), signal.SIGTERM)
            return code

        monkeypatch.setattr(cli, "_handle", handle_then_terminated)
    else:
        real_signal = signal.signal

        def terminated_first(signum, handler):
            if signum == signal.SIGTERM and not isinstance(handler, cli._SigtermAsInterrupt):
                os.kill(os.getpid(), signal.SIGTERM)  # the command's handler still in place
            return real_signal(signum, handler)

        monkeypatch.setattr(cli.signal, "signal", terminated_first)
    scene = ROOT / "scenarios" / "approaching_target.scenario.yaml"
    code = cli.main(["validate", str(scene)])
    out, err = capsys.readouterr()
    assert code == 1 and err.endswith("error: interrupted\n"), err
    assert "Traceback" not in err and "approaching_target" in out
    assert sigterm_swallowed == []
    os.kill(os.getpid(), signal.SIGTERM)
    assert sigterm_swallowed == [signal.SIGTERM]


@pytest.mark.skipif(sys.platform == "win32", reason="file size limits are POSIX's")
@pytest.mark.parametrize("command", ["run", "sweep"])
def test_a_json_report_that_cannot_be_written_whole_leaves_the_old_one(tmp_path, command):
    # A file system that takes the first 300 bytes only (a full disk, a quota): the report is
    # replaced whole or not at all, so a CI system reading it never gets half a file, neither
    # while it is written nor after a write that failed.
    import os
    import resource
    import signal
    import subprocess

    report = tmp_path / "r.json"
    report.write_text('{"previous": "report"}\n')
    # Named short, from the folder it runs in: the run's placeholder report, which names the
    # scene's file, fits in the 300 bytes wherever the repository lies.
    shutil.copy(ROOT / "scenarios" / "gantry_stopped_car.scenario.yaml",
                tmp_path / "g.scenario.yaml")
    scene = "g.scenario.yaml"

    def limited() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past it fails, EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (300, 300))

    # Out of the repository, and git (which a pytest plugin the sweep loads runs) takes no
    # optional lock: a git command under the limit would leave the repository's index locked.
    env = {**os.environ, "RTS_SCENARIO_CACHE_DIR": "off", "GIT_OPTIONAL_LOCKS": "0",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    extra = ["--workers", "1"] if command == "sweep" else []
    proc = subprocess.run(
        [sys.executable, "-m", "rts_scenario", command, str(scene), "--json", str(report),
         *extra], capture_output=True, text=True, env=env, preexec_fn=limited, timeout=300,
        cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip().endswith(f"error: --json {report}: cannot write: File too large")
    if command == "run":
        # Before the scene ran, the earlier report was replaced by one with no verdict (small
        # enough to be written): whatever stops the run later leaves no earlier pass in place.
        left = json.loads(report.read_text())
        assert left["status"] == "error" and left["error"].startswith("no verdict")
    else:
        assert report.read_text() == '{"previous": "report"}\n'
    # No draft left behind.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.scenario.yaml", "r.json"]


def test_a_json_report_keeps_its_file_s_permissions(tmp_path, capsys):
    scene = ROOT / "scenarios" / "gantry_stopped_car.scenario.yaml"
    report = tmp_path / "r.json"
    report.write_text("{}\n")
    report.chmod(0o640)
    assert cli.main(["run", str(scene), "--json", str(report)]) == 0
    assert json.loads(report.read_text())["status"] == "pass"
    assert report.stat().st_mode & 0o777 == 0o640


@pytest.mark.skipif(sys.platform != "linux", reason="/dev/stdout as a path is Linux's")
def test_a_json_report_to_dev_stdout_is_written_into_the_pipe(tmp_path):
    # `rts-scenario run SCENE --json /dev/stdout | jq ...`: the pipe has no folder to put a
    # draft in (before: exit 2, "cannot write", after the run).
    import os
    import subprocess

    scene = ROOT / "scenarios" / "gantry_stopped_car.scenario.yaml"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT),
                                                        os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-m", "rts_scenario", "run", str(scene), "--json",
                           "/dev/stdout"], capture_output=True, text=True, env=env, timeout=300,
                          cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    report = proc.stdout[proc.stdout.index("{"):proc.stdout.rindex("}") + 1]
    assert json.loads(report)["status"] == "pass"


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0,
                    reason="making a device node takes root")
def test_a_json_report_to_a_device_writes_into_it_and_leaves_the_device(tmp_path, capsys):
    # `--json /dev/null` in a CI job run as root: renamed over, the device node became a
    # regular file holding the report, for every program after it.
    import stat

    null = tmp_path / "null"
    os.mknod(null, 0o666 | stat.S_IFCHR, os.makedev(1, 3))  # /dev/null's numbers
    link = tmp_path / "r.json"
    link.symlink_to(null)
    scene = ROOT / "scenarios" / "gantry_stopped_car.scenario.yaml"
    for path in (null, link):
        assert cli.main(["run", str(scene), "--json", str(path)]) == 0
        assert stat.S_ISCHR(null.stat().st_mode) and link.is_symlink()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["null", "r.json"]  # no draft left


def test_a_reader_that_stops_early_loses_neither_the_verdict_nor_the_report(tmp_path):
    # `rts-scenario run SCENE --json R | head -1`: the reader goes away after one line. The
    # rest of the output has nowhere to go, but every variant still runs, the report is written
    # and the exit code is the verdict's (before: exit 3, the variants after the first line
    # erred, no report).
    import os
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    report = tmp_path / "r.json"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), str(root / "plugins"),
                                                        os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen(
        [sys.executable, "-c", "import sys, rts_scenario.cli as c; sys.exit(c.main())", "run",
         str(root / "scenarios" / "cut_in.scenario.yaml"), "--json", str(report)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    assert proc.stdout is not None and proc.stderr is not None
    first = proc.stdout.readline()
    proc.stdout.close()  # as `head -1` does
    errors = proc.stderr.read().decode()
    assert proc.wait(timeout=300) == 0, errors
    assert first.startswith(b"target ")
    assert "BrokenPipe" not in errors and "Exception ignored" not in errors, errors
    assert [s["status"] for s in json.loads(report.read_text())] == ["pass", "pass"]


def test_a_reader_of_both_outputs_that_stops_early_loses_neither_verdict_nor_report(tmp_path):
    # `rts-scenario run A B --json R 2>&1 | head -1`: standard error goes to the same reader.
    # Its next line (B's warning) met a broken pipe: B did not run, no report was written,
    # and the exit code was 1 from an uncaught BrokenPipeError, whatever the verdicts.
    import os
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    text = (root / "scenarios" / "approaching_target.scenario.yaml").read_text()
    scenes = []
    for name in ("loud-a", "loud-b"):
        # A 60 dBsm car saturates the attenuator near the radar: a warning on stderr, and a
        # verdict of fail (the limit is not declared expected).
        scene = tmp_path / f"{name}.scenario.yaml"
        scene.write_text(text.replace("name: approaching-target", f"name: {name}")
                         .replace("rcs_dbsm: 12.0", "rcs_dbsm: 60.0"))
        scenes.append(str(scene))
    report = tmp_path / "r.json"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), str(root / "plugins"),
                                                        os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen(
        [sys.executable, "-c", "import sys, rts_scenario.cli as c; sys.exit(c.main())", "run",
         *scenes, "--json", str(report)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env)
    assert proc.stdout is not None
    first = proc.stdout.readline()
    proc.stdout.close()  # as `head -1` does
    assert proc.wait(timeout=300) == 1
    assert first.startswith(b"warning: "), first
    entries = json.loads(report.read_text())
    assert [(e["scene"], e["status"]) for e in entries] == [("loud-a", "fail"),
                                                            ("loud-b", "fail")]


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full here")
def test_standard_output_that_cannot_be_written_is_a_runtime_error_not_a_scene_s(tmp_path):
    # `rts-scenario run SCENE --json R > /dev/full`: everything printed is lost. That is exit 3
    # (never the verdict's 0: nobody saw it), said once; the scenes still run and are not
    # blamed for it, and the report holds their verdicts (before: the first variant an error
    # entry for an OSError, the second not run, no report).
    import os
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    report = tmp_path / "r.json"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), str(root / "plugins"),
                                                        os.environ.get("PYTHONPATH", "")])}
    with open("/dev/full", "w") as full:
        proc = subprocess.run(
            [sys.executable, "-c", "import sys, rts_scenario.cli as c; sys.exit(c.main())",
             "run", str(root / "scenarios" / "cut_in.scenario.yaml"), "--json", str(report)],
            stdout=full, stderr=subprocess.PIPE, env=env, timeout=300)
    errors = proc.stderr.decode()
    assert proc.returncode == 3, errors
    assert [s["status"] for s in json.loads(report.read_text())] == ["pass", "pass"]
    lines = [line for line in errors.splitlines() if line.startswith("error:")]
    assert len(lines) == 1 and lines[0].startswith("error: standard output: "), errors
    assert "No space left on device" in lines[0] and "Traceback" not in errors


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full here")
def test_main_called_twice_reports_lost_output_each_time():
    # main() in one process twice (as a program embedding the command line does): the first
    # call's lost output must not leave standard output on the null device, where the second
    # call's output was lost without a word and its exit code 0.
    import os
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), str(root / "plugins"),
                                                        os.environ.get("PYTHONPATH", "")])}
    code = ("import sys, rts_scenario.cli as c\n"
            "codes = [c.main(['list-outputs']), c.main(['list-outputs'])]\n"
            "print('codes', codes, file=sys.stderr)\n")
    with open("/dev/full", "w") as full:
        proc = subprocess.run([sys.executable, "-c", code], stdout=full, stderr=subprocess.PIPE,
                              env=env, timeout=120)
    errors = proc.stderr.decode()
    assert "codes [3, 3]" in errors, errors
    assert errors.count("error: standard output: ") == 2, errors
    # A reader gone stays gone for both calls: each ends with its verdict, nothing on stderr.
    proc2 = subprocess.Popen([sys.executable, "-c", code.replace("list-outputs", "list")],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    assert proc2.stdout is not None and proc2.stderr is not None
    proc2.stdout.readline()
    proc2.stdout.close()
    errors = proc2.stderr.read().decode()
    assert proc2.wait(timeout=120) == 0
    assert errors.strip() == "codes [0, 0]", errors


def test_rts_listen_stops_when_its_reader_has_gone(tmp_path):
    # `rts-scenario rts-listen udp://... | head -1`: printing frames is all it does, so it ends
    # (exit 0) once nobody reads them, rather than listening on for ever.
    import os
    import subprocess
    import sys
    import time

    from rts_scenario.kinematics import compute_tracks
    from rts_scenario.outputs import open_output
    from rts_scenario.scenario import load_scenario
    from rts_scenario.schedule import build_schedule

    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), str(root / "plugins"),
                                                        os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen(
        [sys.executable, "-c", "import sys, rts_scenario.cli as c; sys.exit(c.main())",
         "rts-listen", "udp://127.0.0.1:0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    assert proc.stdout is not None and proc.stderr is not None
    try:
        first = proc.stdout.readline().decode()
        assert first.startswith("listening on udp://127.0.0.1:"), first
        port = int(first.rsplit(":", 1)[1])
        proc.stdout.close()  # as `head -1` does
        scene = load_scenario(root / "scenarios" / "cut_in.scenario.yaml")
        schedule = build_schedule(compute_tracks(scene), scene.rig, scene.radar)
        deadline = time.monotonic() + 60
        while proc.poll() is None and time.monotonic() < deadline:
            with open_output(f"udp://127.0.0.1:{port}", pacing="fast") as out:
                out.write(schedule)
            time.sleep(0.2)
        assert proc.wait(timeout=10) == 0
        errors = proc.stderr.read().decode()
        assert "BrokenPipe" not in errors and "Exception ignored" not in errors, errors
    finally:
        if proc.poll() is None:
            proc.kill()


def test_a_can_interface_that_cannot_be_opened_is_one_error_before_the_first_scene(tmp_path,
                                                                                   capsys):
    """A parametrized scene gave one "cannot open" error per variant, each after loading it;
    the options are checked before the first scene runs, as for the other options."""
    scene = str(ROOT / "scenarios" / "euro-ncap" / "ccrs.scenario.yaml")
    report = tmp_path / "report.json"
    code = cli.main(["run", scene, scene, "--can-interface", "socketcan", "--can-channel",
                     "rts-no-such0", "--json", str(report)])
    out, err = capsys.readouterr()
    assert code == 2
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("error: --can-interface socketcan --can-channel rts-no-such0: "
                               "cannot open CAN interface 'socketcan' channel 'rts-no-such0'")
    assert out == ""
    # Nothing ran: each scene given is an error entry, none a verdict.
    entries = json.loads(report.read_text())
    assert [e["status"] for e in entries] == ["error", "error"]
    assert all(e["error"] == "not run: " + lines[0].removeprefix("error: ") for e in entries)
    # Without --can-channel the run would use a private channel name: said so.
    assert cli.main(["run", scene, "--can-interface", "socketcan"]) == 2
    out, err = capsys.readouterr()
    assert err.startswith("error: --can-interface socketcan (no --can-channel: a private "
                          "channel name): cannot open CAN interface 'socketcan'")
    assert len(err.splitlines()) == 1 and out == ""


def test_the_virtual_interface_is_not_opened_up_front(monkeypatch):
    """Opening a virtual bus has no effect anywhere else, and a check is not a run."""
    import can

    from rts_scenario.cli.common import check_can_opens

    opened = []
    monkeypatch.setattr(can, "Bus", lambda *a, **k: opened.append((a, k)))
    check_can_opens("--can-interface", "virtual", None, "--can-channel")
    check_can_opens("--can-interface", "virtual", "vcan7", "--can-channel")
    assert opened == []


def test_a_can_interface_that_opens_is_opened_once_up_front_and_closed(monkeypatch):
    import can

    from rts_scenario.cli.common import check_can_opens

    events = []

    class Probe:
        def __init__(self, **kwargs):
            events.append(("open", kwargs["interface"], kwargs["channel"], kwargs["fd"]))

        def shutdown(self):
            events.append(("shutdown",))

    monkeypatch.setattr(can, "Bus", Probe)
    check_can_opens("--can-interface", "socketcan", "vcan0", "--can-channel", fd=True)
    assert events == [("open", "socketcan", "vcan0", True), ("shutdown",)]


def test_run_runs_a_marked_scene_as_written_and_says_what_pytest_and_sweep_would_report(
        tmp_path, capsys):
    """run is the direct command: it plays a skip-marked scene and judges an xfail-marked one
    by its check, and says that pytest and sweep judge them by their marks."""
    text = (ROOT / "scenarios" / "cut_in.scenario.yaml").read_text().replace(
        "duration_s: 12.0", "duration_s: 4.0").replace(
        "parametrize:                   # the pytest plugin runs the scene once per estimator\n"
        "  radar.estimator: [bartlett, ti]\n", "")
    known = tmp_path / "known.scenario.yaml"  # its car far outside the rig's coverage: fails
    known.write_text(text.replace("name: cut-in", "name: known").replace(
        "[30.0, 3.5, 0.6]", "[30.0, 40.0, 0.6]") + "marks: [xfail, slow]\n")
    parked = tmp_path / "parked.scenario.yaml"
    parked.write_text(text.replace("name: cut-in", "name: parked") + "marks: [skip]\n")
    out = tmp_path / "r.json"
    assert cli.main(["run", str(known), str(parked), "--json", str(out)]) == 1
    stdout = capsys.readouterr().out
    assert ("note: known is marked xfail: pytest and rts-scenario sweep report its failed "
            "check as XFAIL (a known failure, which fails nothing); run judges the check as "
            "written") in stdout
    assert ("note: parked is marked skip: pytest and rts-scenario sweep skip it; run ran it "
            "as written") in stdout
    assert f"FAIL known ({known}) - marked xfail: XFAIL in pytest and sweep" in stdout
    assert f"PASS parked ({parked}) - marked skip: SKIPPED in pytest and sweep" in stdout
    entries = json.loads(out.read_text())
    assert [(e["scene"], e["status"], e["marks"]) for e in entries] == [
        ("known", "fail", ["xfail", "slow"]), ("parked", "pass", ["skip"])]


def test_a_run_stopped_by_a_bad_option_leaves_no_earlier_report_in_its_json(tmp_path, capsys):
    # A CI job reading the --json of a command that stopped on its options must not read the
    # report an earlier run left there as this one's.
    scene = Path(__file__).resolve().parents[1] / "scenarios" / "cut_in.scenario.yaml"
    out = tmp_path / "report.json"
    out.write_text('{"scene": "cut-in", "status": "pass", "passed": true}\n')
    assert cli.main(["run", str(scene), "--json", str(out), "--can-interface", "nosuch"]) == 2
    assert "unknown python-can interface" in capsys.readouterr().err
    report = json.loads(out.read_text())
    assert report["status"] == "error" and "passed" not in report
    assert report["error"].startswith("not run: --can-interface 'nosuch': unknown python-can")
    assert report["file"] == str(scene) and report["scene"] == "cut_in"
    # An error of --json itself leaves the file alone: it names what cannot be written.
    assert cli.main(["run", str(scene), "--json", str(tmp_path / "no" / "r.json")]) == 2


def usage_error(argv, capsys):
    """Run the CLI on a command line argparse refuses; return its error message."""
    with pytest.raises(SystemExit) as exited:
        cli.main(argv)
    assert exited.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err.splitlines()[-1].split(" error: ", 1)[1]


@pytest.mark.parametrize("bad", [["--method", "nope"], ["--record", "x.blf", "--record", "y.blf"],
                                 ["--workers", "3"], ["--can-fd=1"]])
@pytest.mark.parametrize("json_option", ["--json", "--json="])
def test_a_run_refused_by_the_argument_parser_leaves_no_earlier_report(tmp_path, capsys, bad,
                                                                        json_option):
    # argparse exited before the command's own checks: a passing report of an earlier run stayed
    # in --json, to be read as this one's.
    scene = str(ROOT / "scenarios" / "cut_in.scenario.yaml")
    out = tmp_path / "report.json"
    out.write_text('{"scene": "cut-in", "status": "pass", "passed": true}\n')
    given = [json_option + str(out)] if json_option.endswith("=") else [json_option, str(out)]
    message = usage_error(["run", scene, scene, *given, *bad], capsys)
    entries = json.loads(out.read_text())
    assert entries == [{"scene": "cut_in", "file": scene, "status": "error",
                        "error": f"not run: {message}", "variant": "", "parameters": {}}] * 2


def test_a_run_refused_before_its_scenes_are_told_says_so_in_one_entry(tmp_path, capsys):
    out = tmp_path / "report.json"
    out.write_text('{"scene": "cut-in", "status": "pass", "passed": true}\n')
    message = usage_error(["run", "--json", str(out)], capsys)
    assert message == "the following arguments are required: SCENE"
    assert json.loads(out.read_text()) == {
        "scene": "", "file": "", "status": "error", "error": f"not run: {message}",
        "variant": "", "parameters": {}}


@pytest.mark.parametrize("bad", [["--json", "other.json"], ["--json"], ["--json="],
                                 ["--detections", "{out}", "--method", "nope"],
                                 ["--method", "nope", "--record", "{out}"]])
def test_a_usage_error_writes_no_report_where_json_is_at_fault_or_names_another_file(
        tmp_path, capsys, bad):
    scene = str(ROOT / "scenarios" / "cut_in.scenario.yaml")
    out = tmp_path / "report.json"
    out.write_text("earlier\n")
    usage_error(["run", scene, "--json", str(out), *(b.format(out=out) for b in bad)], capsys)
    assert out.read_text() == "earlier\n"


def test_a_run_stopped_before_its_first_scene_leaves_no_earlier_detections(tmp_path, capsys,
                                                                             monkeypatch):
    # The report said "not run: interrupted", and the detections an earlier run wrote stayed
    # under the name this run was to write them to.
    import rts_scenario.cli.run as run_module

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(run_module, "check_output", stopped)
    scene = str(ROOT / "scenarios" / "cut_in.scenario.yaml")
    report, detections = tmp_path / "report.json", tmp_path / "detections.csv"
    detections.write_text("scene,cycle\nold,1\n")
    assert cli.main(["run", scene, "--json", str(report), "--detections", str(detections)]) == 1
    assert json.loads(report.read_text())["error"] == ("not run: interrupted (Ctrl-C or SIGTERM) "
                                                       "before it ran")
    assert not detections.exists() and not Path(f"{detections}.partial").exists()
    # Never a file the command reads, whose check may not have run.
    mapping = tmp_path / "radar.mapping.yaml"
    mapping.write_text("rts_can_mapping: 1\n")
    assert cli.main(["run", scene, "--mapping", str(mapping), "--detections", str(mapping)]) == 1
    assert mapping.read_text() == "rts_can_mapping: 1\n"
    capsys.readouterr()


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
@pytest.mark.parametrize("signum", ["SIGINT", "SIGTERM"])
def test_a_stop_while_the_process_exits_never_kills_it_without_a_word(signum):
    # After the command printed its verdict, the process exits: it waits for threads, runs
    # its exit hooks, then tears its modules down without Python's signal handlers. A Ctrl-C
    # or SIGTERM there killed it by the signal (exit -2 / -15), silently.
    import subprocess

    def run(body):
        script = ("import os, signal, sys, threading, atexit, time\n"
                  "import rts_scenario.cli as cli\n" + body +
                  "cli.main = main\ncli.console()\n")
        return subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                              timeout=60)

    # While it waits for a thread (one that never ended would hang it): stopped as a command
    # that ends then is, what it printed standing.
    waiting = run(f"def main():\n    print('PASS: scene')\n"
                  f"    threading.Thread(target=lambda: (time.sleep(0.3), os.kill(os.getpid(), "
                  f"signal.{signum}), time.sleep(0.5))).start()\n    return 0\n")
    assert waiting.returncode == 1, waiting
    assert waiting.stdout == "PASS: scene\n" and waiting.stderr == "error: interrupted\n"
    # A bad input's exit code stands (never 0, and not made 1).
    erred = run(f"def main():\n"
                f"    threading.Thread(target=lambda: (time.sleep(0.3), os.kill(os.getpid(), "
                f"signal.{signum}), time.sleep(0.5))).start()\n    return 2\n")
    assert erred.returncode == 2 and erred.stderr == "error: interrupted\n", erred
    # In the last exit hook or after (the modules' teardown): nothing is left to stop; the
    # command's exit code stands.
    tearing = run(f"atexit.register(lambda: os.kill(os.getpid(), signal.{signum}))\n"
                  f"def main():\n    print('FAIL: scene')\n    return 1\n")
    assert tearing.returncode == 1 and tearing.stderr == "", tearing
    passing = run(f"atexit.register(lambda: os.kill(os.getpid(), signal.{signum}))\n"
                  f"def main():\n    return 0\n")
    assert passing.returncode == 0 and passing.stderr == "", passing


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_a_sigterm_as_the_command_hands_back_its_handler_is_acted_on_not_fatal():
    # Between the command putting back the handler it found and the exit's handlers in place,
    # a SIGTERM used to meet the default and kill the process silently: it is noted, then the
    # command stops as interrupted.
    import subprocess

    script = ("import os, signal\nimport rts_scenario.cli as cli\n"
              "def main():\n    print('PASS: scene')\n"
              "    os.kill(os.getpid(), signal.SIGTERM)\n    return 0\n"
              "cli.main = main\ncli.console()\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 1 and done.stdout == "PASS: scene\n", done
    assert done.stderr == "error: interrupted\n", done


def test_run_s_marks_note_says_how_pytest_and_sweep_judge_the_run():
    from rts_scenario.cli.run import marks_note

    assert marks_note((), False) is None
    assert marks_note(("xfail",), False)[1] == "xfail: XFAIL in pytest and sweep"
    assert marks_note(("xfail",), True)[1] == "xfail: XPASS in pytest and sweep"
    # It said XFAIL of a run the bench failed, which pytest and sweep now fail.
    note, line = marks_note(("xfail",), False, ["bus_silent", "rts_unreachable"])
    assert line == "xfail: FAIL in pytest and sweep (the bench failed it)"
    assert note.endswith("not the bench (bus_silent, rts_unreachable)")


def test_a_run_on_a_bench_bus_without_an_rts_says_the_simulated_radar_measured(tmp_path,
                                                                                capsys):
    # A bench script that forgot --output passed on the built-in radar, which put its
    # detections on the bench's bus; neither the text nor the --json said so.
    report = tmp_path / "r.json"
    scene = str(ROOT / "scenarios" / "approaching_target.scenario.yaml")
    code = cli.main(["run", scene, "--can-interface", "udp_multicast", "--can-channel",
                     "239.74.163.117", "--json", str(report)])
    out, err = capsys.readouterr()
    # The verdict itself is the simulated radar's over a real socket: a cycle late on a loaded
    # machine fails it, which is not what this test is about.
    assert code in (0, 1), out + err
    assert err.startswith("warning: --can-interface udp_multicast without --output: the "
                          "built-in simulated radar measures (no RTS plays the scene)")
    assert "playback: 150 frames sent to the built-in simulated radar (no RTS)" in out
    assert json.loads(report.read_text())["playback"]["output"] == "simulated-radar"


def test_a_variant_over_the_simulated_radar_s_options_on_a_bench_is_noted(tmp_path, capsys):
    # cut-in[estimator=ti] got its own PASS on a bench whose radar never ran the ti estimator.
    import socket

    scene = tmp_path / "short.scenario.yaml"
    scene.write_text(SHORT_SCENE + "parametrize:\n  radar.estimator: [ti]\n")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        closed = sock.getsockname()[1]
    cli.main(["run", str(scene), "--output", f"udp://127.0.0.1:{closed}"])
    out = capsys.readouterr().out
    assert (f"note: {scene}[estimator=ti]: radar.estimator set the built-in simulated radar; on "
            f"the bench (udp://127.0.0.1:{closed}) the radar measures as it is set, so this "
            f"variant runs as the others do") in out


@pytest.mark.parametrize("where", ["json", "detections"])
def test_a_stop_after_the_scenes_leaves_no_earlier_pass_report(tmp_path, capsys, monkeypatch,
                                                               where):
    # A stop after the last scene, while the detections were named or the report written,
    # left the earlier run's passing --json in place under an exit code of 1.
    import rts_scenario.cli.run as run_cli

    report, detections = tmp_path / "r.json", tmp_path / "d.csv"
    report.write_text(json.dumps({"scene": "an earlier run", "status": "pass"}))

    def stop(*args, **kwargs):
        raise KeyboardInterrupt

    if where == "json":
        # The first write is the placeholder, before the scene; the second the report.
        monkeypatch.setattr(run_cli, "write_json", _first_call_then(run_cli.write_json, stop))
    else:
        monkeypatch.setattr(run_cli, "_finish_detections", stop)
    scene = str(ROOT / "scenarios" / "cut_out.scenario.yaml")
    code = cli.main(["run", scene, "--json", str(report), "--detections", str(detections)])
    out, err = capsys.readouterr()
    assert code == 1 and "error: interrupted" in err
    written = json.loads(report.read_text())
    if where == "json":
        # The placeholder written before the scene ran: no verdict.
        assert (written["scene"], written["status"]) == ("cut_out", "error")
        assert written["error"].startswith("no verdict: the command stopped before it wrote "
                                           "its report")
    else:
        # The scene's verdict was known: the report is this run's, the stop said apart.
        assert (written["scene"], written["status"]) == ("cut-out", "pass")
        assert written["targets"]
        assert not detections.exists()


def test_a_run_stopped_after_its_verdict_keeps_it_and_its_log(tmp_path, capsys, monkeypatch):
    # A stop after the scene's verdict and its log's sidecar were written (while the timing
    # line was printed) marked the run "no verdict" and said its complete log was cut short.
    import rts_scenario.cli.run as run_cli

    def print_then_stop(*args, **kwargs):
        if args and str(args[0]).startswith("timing: "):
            raise KeyboardInterrupt
        return print(*args, **kwargs)

    monkeypatch.setattr(run_cli, "print", print_then_stop, raising=False)
    log, report = tmp_path / "drive.asc", tmp_path / "r.json"
    scene = str(ROOT / "scenarios" / "cut_out.scenario.yaml")
    code = cli.main(["run", scene, "--record", str(log), "--json", str(report)])
    _, err = capsys.readouterr()
    assert code == 1 and "error: interrupted" in err and "cut short" not in err
    assert json.loads(report.read_text())["status"] == "pass"
    assert log.exists() and Path(f"{log}.rts.json").exists()


def test_a_full_disk_under_the_detections_keeps_the_verdicts(tmp_path, capsys, monkeypatch):
    # A write of the detections that failed (a full disk) failed the scene whose detections
    # it was writing: its verdict lost, the option not named, and the CSV, cut mid-row, named
    # as whole.
    import errno

    from rts_scenario.atomic import Draft

    real_init = Draft.__init__

    class Full:
        def __init__(self, file):
            self.file, self.written = file, 0

        def write(self, text):
            if self.written > 2000:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            self.written += len(text)
            return self.file.write(text)

        def close(self):
            self.file.close()

    def init(self, path, newline=None):
        real_init(self, path, newline)
        self.file = Full(self.file)

    monkeypatch.setattr(Draft, "__init__", init)
    detections, report = tmp_path / "d.csv", tmp_path / "r.json"
    scenes = [str(ROOT / "scenarios" / f"{name}.scenario.yaml")
              for name in ("approaching_target", "cut_out")]
    code = cli.main(["run", *scenes, "--detections", str(detections), "--json", str(report)])
    out, err = capsys.readouterr()
    assert code == 3
    assert [(e["scene"], e["status"]) for e in json.loads(report.read_text())] == [
        ("approaching-target", "pass"), ("cut-out", "pass")]
    assert (f"error: --detections {detections}: cannot write: No space left on device; the "
            f"verdicts stand; the rows written are in {detections}.partial (cut short)") in err
    assert not detections.exists() and f"wrote {detections}" not in out
    rows = Path(f"{detections}.partial").read_text()
    assert 1000 < len(rows) < 2000 + 400  # up to the write that failed (a row)


def _first_call_then(real, then):
    calls = []

    def call(*args, **kwargs):
        calls.append(args)
        return real(*args, **kwargs) if len(calls) == 1 else then(*args, **kwargs)

    return call


def test_a_calibrated_rig_on_the_simulated_radar_is_said_to_play_its_offsets_as_errors(
        tmp_path, capsys):
    # lab-2x3's calibration (12.5, -41 and 77 deg, -0.3 and 0.2 dB) cancels its bench's
    # channel errors; the simulated radar's bench has none, so there the offsets put targets
    # 2-3 deg off and the radar was blamed without a word.
    import shutil

    shutil.copy(ROOT / "scenarios" / "rigs" / "lab-2x3.rig.yaml", tmp_path / "lab.rig.yaml")
    scene = tmp_path / "s.scenario.yaml"
    scene.write_text((ROOT / "scenarios" / "gantry_stopped_car.scenario.yaml").read_text()
                     .replace("rig: wide-3x5", "rig: lab.rig.yaml"))
    cli.main(["run", str(scene)])
    err = capsys.readouterr().err
    assert ("rig 'lab-2x3' carries the calibration of its bench (calibration.phase_deg 0, "
            "12.5, -41, 0, 77, 0; calibration.gain_db 0, -0.3, 0, 0, 0.2, 0; "
            "calibration.delay_s 0, 1.2e-12, 0, 0, 0, 0)") in err
    # A rig without calibration: nothing said.
    cli.main(["run", str(ROOT / "scenarios" / "gantry_stopped_car.scenario.yaml")])
    assert "carries the calibration" not in capsys.readouterr().err


def test_a_json_report_named_like_a_variant_s_log_sidecar_is_refused(tmp_path, capsys):
    # cut_in's variants record to drive[estimator=ti].blf and its sidecar: a --json of that
    # sidecar's name replaced it with the report, and its check then failed.
    scene = str(ROOT / "scenarios" / "cut_in.scenario.yaml")
    log, report = tmp_path / "drive.asc", tmp_path / "drive[estimator=ti].asc.rts.json"
    code = cli.main(["run", scene, "--record", str(log), "--json", str(report)])
    err = capsys.readouterr().err
    assert code == 2
    assert (f"error: --json {report} and --record's sidecar of "
            f"{tmp_path / 'drive[estimator=ti].asc'} {report}: the same file") in err, err
    assert not report.exists() and list(tmp_path.iterdir()) == []


def test_a_png_report_in_the_plot_folder_is_refused(tmp_path, capsys):
    # --plot p with --json p/highway-following-errors.png: the plot replaced the report, or
    # the report a plot, and "wrote" was printed for both.
    pytest.importorskip("matplotlib")
    scene = str(ROOT / "scenarios" / "highway_following.scenario.yaml")
    plots = tmp_path / "p"
    plots.mkdir()
    report = plots / "highway-following-errors.png"
    code = cli.main(["run", scene, "--plot", str(plots), "--json", str(report)])
    err = capsys.readouterr().err
    assert code == 2
    assert f"error: --json {report}: a .png in the --plot folder {plots}" in err
    assert list(plots.iterdir()) == []


def test_a_report_given_as_a_dangling_link_is_written_where_the_link_points(tmp_path, capsys):
    # The up-front probe created the file the link named, then removed the link itself: the
    # report went to a plain file at the link's place and an empty file stayed at its target.
    (tmp_path / "real").mkdir()
    link = tmp_path / "r.json"
    link.symlink_to(tmp_path / "real" / "r.json")
    scene = str(ROOT / "scenarios" / "gantry_stopped_car.scenario.yaml")
    assert cli.main(["run", scene, "--json", str(link)]) == 0
    capsys.readouterr()
    assert link.is_symlink()
    assert json.loads((tmp_path / "real" / "r.json").read_text())["status"] == "pass"


def test_a_run_warns_of_an_if_rts_whose_fes_need_a_phase_calibration(tmp_path, capsys):
    # lab-2x3 without its calibration: an FE at 1.01 m behind an IF RTS turns its echo by 40
    # deg against the others, targets played off their angles with status OK; only validate
    # said so, not the run whose verdict it skews.
    import re as regex

    text = (ROOT / "scenarios" / "rigs" / "lab-2x3.rig.yaml").read_text()
    (tmp_path / "lab.rig.yaml").write_text(regex.sub(r", calibration: \{[^}]*\}", "", text))
    scene = tmp_path / "s.scenario.yaml"
    scene.write_text((ROOT / "scenarios" / "gantry_stopped_car.scenario.yaml").read_text()
                     .replace("rig: wide-3x5", "rig: lab.rig.yaml"))
    cli.main(["run", str(scene)])
    err = capsys.readouterr().err
    assert "carries the calibration" not in err
    assert re.search(r"warning: .*: rig 'lab-2x3': its FEs lie 1 to 1\.01 m from the radar "
                     r"behind an IF RTS .* and it has no phase calibration", err), err


def test_a_stop_while_a_run_s_error_is_said_keeps_one_entry_per_run(tmp_path, capsys,
                                                                    monkeypatch):
    # Stopped while b's error (a parametrize block that does not expand) was printed: the
    # report held a twice (its error, then "interrupted") and b not at all.
    import rts_scenario.cli.run as run_cli

    gantry = (ROOT / "scenarios" / "gantry_stopped_car.scenario.yaml").read_text()
    (tmp_path / "a.scenario.yaml").write_text(gantry.replace("rig: wide-3x5",
                                                             "rig: nowhere.rig.yaml"))
    (tmp_path / "b.scenario.yaml").write_text(gantry + "parametrize: 3\n")

    stops = []

    def stop_at_b(*args, **kwargs):
        if not stops and args and str(args[0]).startswith(f"error: {tmp_path}/b.scenario"):
            stops.append(args[0])  # once, as Ctrl-C pressed once
            raise KeyboardInterrupt
        return print(*args, **kwargs)

    monkeypatch.setattr(run_cli, "print", stop_at_b, raising=False)
    report = tmp_path / "r.json"
    code = cli.main(["run", str(tmp_path / "a.scenario.yaml"), str(tmp_path / "b.scenario.yaml"),
                     str(ROOT / "scenarios" / "cut_out.scenario.yaml"), "--json", str(report)])
    assert code != 0
    entries = json.loads(report.read_text())
    assert [(e["scene"], e["status"]) for e in entries] == [
        ("a", "error"), ("b", "error"), ("cut_out", "error")]
    assert "rig: file not found" in entries[0]["error"]
    assert entries[1]["error"].endswith("interrupted (Ctrl-C or a stop signal) while running: "
                                        "no verdict")
    assert entries[2]["error"] == "not run: interrupted (Ctrl-C or SIGTERM) before it ran"


@pytest.mark.skipif(sys.platform != "linux", reason="/dev/stdout as a path is Linux's")
def test_a_json_report_to_dev_stdout_redirected_to_a_file_is_the_report(tmp_path):
    # `run SCENE --json /dev/stdout > out.txt`: the placeholder was renamed over out.txt, and
    # the report then went to "out.txt (deleted)"; out.txt said "no verdict".
    import subprocess

    scene = ROOT / "scenarios" / "gantry_stopped_car.scenario.yaml"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT),
                                                        os.environ.get("PYTHONPATH", "")])}
    out = tmp_path / "out.txt"
    with out.open("w") as stdout:
        proc = subprocess.run([sys.executable, "-m", "rts_scenario", "run", str(scene),
                               "--json", "/dev/stdout"], stdout=stdout, stderr=subprocess.PIPE,
                              text=True, env=env, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    text = out.read_text()
    assert json.loads(text[text.index("{"):text.rindex("}") + 1])["status"] == "pass"
    assert "no verdict" not in text


def test_a_recording_through_a_link_rewrites_the_file_it_names(tmp_path, capsys):
    # The earlier recording was removed by removing the link: the new log became a plain file
    # at the link's place, the file it named keeping the stale recording.
    (tmp_path / "store").mkdir()
    real = tmp_path / "store" / "real.asc"
    real.write_text("OLD")
    link = tmp_path / "log.asc"
    link.symlink_to(real)
    scene = str(ROOT / "scenarios" / "gantry_stopped_car.scenario.yaml")
    assert cli.main(["run", scene, "--record", str(link)]) == 0
    capsys.readouterr()
    assert link.is_symlink() and real.read_text() != "OLD" and real.stat().st_size > 1000


def test_a_run_stopped_on_an_option_never_writes_its_report_over_a_scene(tmp_path, capsys):
    # --json named like a scene (not one of the run's): the not-run report replaced it when
    # another option stopped the run before the check that refuses such a name.
    other = tmp_path / "other.scenario.yaml"
    other.write_text("kept\n")
    code = cli.main(["run", str(ROOT / "scenarios" / "cut_in.scenario.yaml"), "--json",
                     str(other), "--output", f"file:{tmp_path / 'x.npz'}"])
    assert code == 2
    assert other.read_text() == "kept\n"


@pytest.mark.parametrize("argv", [["run", "--json", "{path}"],
                                  ["run", "--json", "{path}", "--bogus"],
                                  ["sweep", "--json", "{path}", "--bogus"]])
def test_a_refused_command_line_writes_its_report_over_no_file_but_a_report(tmp_path, argv):
    # `run --json plain.yaml` without a scene: read leniently, the scene the user meant is
    # where --json goes; the not-run report replaced it (a scene, a bench recording).
    for name, data in (("plain.yaml", b"rts_scenario: 1\n"), ("bench.blf", b"LOGG\x00\x01"),
                       ("gen.json", b'{"rts_scenario": 1, "name": "a scene as JSON"}'),
                       ("run.blf.rts.json", b'{"rts_scenario_log": 1, "clock": {}}')):
        path = tmp_path / name
        path.write_bytes(data)
        with pytest.raises(SystemExit):
            cli.main([a.format(path=path) for a in argv])
        assert path.read_bytes() == data
    # An earlier report is replaced (it must not be read as this command's).
    report = tmp_path / "report.json"
    report.write_text('{"status": "pass"}')
    with pytest.raises(SystemExit):
        cli.main([a.format(path=report) for a in argv])
    assert json.loads(report.read_text()) != {"status": "pass"}


@pytest.mark.parametrize("stop", ["environment", "usage"])
def test_a_run_stopped_before_it_ran_leaves_no_earlier_report_or_detections(tmp_path,
                                                                             monkeypatch, stop):
    # A bad setting in the environment stopped `run` after argparse and before anything ran:
    # the earlier run's passing report and detections stayed, to be read as this one's (a
    # line argparse refused left the detections).
    scene = str(ROOT / "scenarios" / "cut_in.scenario.yaml")
    report, rows = tmp_path / "r.json", tmp_path / "d.csv"
    assert cli.main(["run", scene, "--json", str(report), "--detections", str(rows)]) == 0
    assert rows.exists() and '"pass"' in report.read_text()
    argv = ["run", scene, "--json", str(report), "--detections", str(rows)]
    if stop == "environment":
        monkeypatch.setenv("RTS_SCENARIO_JIT", "sometimes")
        assert cli.main(argv) == 2
    else:
        with pytest.raises(SystemExit):
            cli.main([*argv, "--bogus"])
    entries = json.loads(report.read_text())
    assert [e["status"] for e in (entries if isinstance(entries, list) else [entries])] == [
        "error"]
    assert not rows.exists()


def test_a_setting_refused_before_a_run_never_writes_over_its_recording_s_sidecar(
        tmp_path, monkeypatch):
    # --json naming --record's sidecar: refused by the run's own checks; a bad setting in the
    # environment stopped it before them and its report replaced the sidecar.
    sidecar = tmp_path / "rec.blf.rts.json"
    sidecar.write_text('{"rts_scenario_log": 1}')
    monkeypatch.setenv("RTS_SCENARIO_JIT", "sometimes")
    assert cli.main(["run", str(ROOT / "scenarios" / "cut_in.scenario.yaml"), "--json",
                     str(sidecar), "--record", str(tmp_path / "rec.blf")]) == 2
    assert sidecar.read_text() == '{"rts_scenario_log": 1}'
