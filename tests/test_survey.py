"""Survey: each front end alone, where the radar sees it and how strong."""

import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from free_radar import behind_own_clock, free_profile

import rts_scenario.cli as cli
from rts_scenario import RadarProfile, Rig, RtsError
from rts_scenario.pipeline import Pipeline
from rts_scenario.radar.simulate import ChannelErrors
from rts_scenario.scenario.model import RadarOptions
from rts_scenario.survey import survey

# In wall-clock time: run with the session's heap frozen (conftest `frozen_heap`).
REAL_TIME = True

OBJECT_LIST = (Path(__file__).resolve().parents[1] / "scenarios" / "can"
               / "object_list.mapping.yaml")
# The object list's angle signals: 0.05 deg a step (object_list.dbc), against 0.005 deg on
# rts-scenario's own classic CAN messages.
OBJECT_LIST_STEP_DEG = 0.05


def test_survey_finds_moved_front_ends_and_their_levels():
    rig, radar = Rig.preset("kit-table1"), RadarProfile.preset("paper")
    moved = ChannelErrors(gain_db=np.array([0.0, -1.5, 0.0, 2.0]), phase_deg=np.zeros(4),
                          delay_s=np.zeros(4), az_deg=np.array([0.3, 0.0, -0.2, 0.0]),
                          el_deg=np.array([0.0, 0.25, 0.0, -0.1]), distance_m=np.zeros(4))
    with Pipeline(rig, radar, radar_options=RadarOptions(fidelity="analytic", noise=False),
                  errors=moved) as bench:
        result = survey(rig, radar, bench.play)
    # The FE stands where the error put it; classic CAN carries angles at 0.005 deg.
    np.testing.assert_allclose(result.seen_az_deg, rig.az_deg + moved.az_deg, atol=0.006)
    np.testing.assert_allclose(result.seen_el_deg, rig.el_deg + moved.el_deg, atol=0.006)
    # Levels travel at 0.5 dB steps on classic CAN.
    np.testing.assert_allclose(result.level_db, moved.gain_db, atol=0.26)


def test_survey_command_writes_the_front_ends_as_json(tmp_path, capsys):
    out = tmp_path / "survey.json"
    assert cli.main(["survey", "kit-table1", "--radar", "paper", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert [fe["index"] for fe in data["front_ends"]] == [0, 1, 2, 3]
    first = data["front_ends"][0]
    assert set(first) == {"index", "az_deg", "el_deg", "seen_az_deg", "seen_el_deg", "level_db"}
    assert first["seen_az_deg"] == pytest.approx(first["az_deg"], abs=0.006)
    assert "seen az" in capsys.readouterr().out


@pytest.mark.parametrize("fidelity", ["analytic", "adc"])
def test_survey_sees_the_near_field_direction_of_the_independent_reference(fidelity):
    from nearfield_reference import FmcwChirp, seen_direction_of_fe

    from rts_scenario.calibration import pattern_schedule

    rig, radar = Rig.preset("kit-table1"), RadarProfile.preset("awr1843boost")
    with Pipeline(rig, radar, radar_options=RadarOptions(fidelity=fidelity, noise=False)) as b:
        result = survey(rig, radar, b.play, repeats=1)
    ref = rig.reference
    tau = pattern_schedule(rig, radar, [[(q, 1.0, 0.0)] for q in range(4)], ref.range_m,
                           ref.attenuation_db).delay_s[:, 0, 0]
    slot = {t: i for i, t in enumerate(radar.tx_order)}
    chirp = FmcwChirp(fc_hz=radar.fc_hz, bandwidth_hz=radar.bandwidth_hz,
                      ramp_time_s=radar.ramp_time_s, sample_rate_hz=radar.sample_rate_hz,
                      n_samples=radar.adc_samples, adc_start_s=radar.adc_start_s,
                      idle_time_s=radar.idle_time_s,
                      tx_slot=tuple(slot[t] for t in range(len(radar.tx_order))))
    a = radar.antennas
    want = np.array([seen_direction_of_fe(rig.az_deg[q], rig.el_deg[q], rig.distance_m[q],
                                          a.tx_y_m, a.tx_z_m, a.rx_y_m, a.rx_z_m, chirp=chirp,
                                          tau_s=tau[q]) for q in range(4)])
    # Through CAN: angles travel at 0.005 deg steps.
    np.testing.assert_allclose(result.seen_az_deg, want[:, 0], atol=0.005)
    np.testing.assert_allclose(result.seen_el_deg, want[:, 1], atol=0.005)
    # ... and the near field is visible: ~0.2 deg off the mechanical elevation.
    assert np.all(np.abs(result.seen_el_deg - rig.el_deg) > 0.1)


def test_survey_write_stores_the_seen_directions_in_the_rig_file(tmp_path):
    out = tmp_path / "surveyed.rig.yaml"
    assert cli.main(["survey", "kit-table1", "--radar", "awr1843boost", "--write", str(out),
                     "--json", str(tmp_path / "s.json")]) == 0
    rig = Rig.from_file(out)
    fes = json.loads((tmp_path / "s.json").read_text())["front_ends"]
    np.testing.assert_allclose(rig.seen[:, 0], [fe["seen_az_deg"] for fe in fes], atol=1e-5)
    np.testing.assert_allclose(rig.seen[:, 1], [fe["seen_el_deg"] for fe in fes], atol=1e-5)
    np.testing.assert_allclose(rig.seen[:, 2], [fe["level_db"] for fe in fes], atol=1e-5)
    # Everything else of the rig comes back as it was.
    kit = Rig.preset("kit-table1")
    np.testing.assert_array_equal(rig.az_deg, kit.az_deg)
    assert rig.limits == kit.limits and rig.rts == kit.rts


def test_a_survey_whose_rig_file_is_cut_short_leaves_the_previous_one(tmp_path, capsys,
                                                                      cut_short_drafts):
    # A disk that fills while --write writes: the rig file the bench ran on stays whole.
    out = tmp_path / "surveyed.rig.yaml"
    Rig.preset("wide-3x5").write(out)
    before = out.read_bytes()
    cut_short_drafts(OSError(28, "No space left on device"))
    assert cli.main(["survey", "kit-table1", "--write", str(out)]) == 2
    assert capsys.readouterr().err == (f"error: --write {out}: cannot write: No space left on "
                                       f"device\n")
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["surveyed.rig.yaml"]


@pytest.mark.parametrize("fidelity", ["analytic", "adc"])
def test_placing_misplaced_front_ends_by_the_survey_restores_exact_synthesis(fidelity):
    # FEs mounted a few tenths of a degree off the rig file, on the honest bench (1 m, near
    # field): the radar sees them there, exact weights from the file miss by as much; placed by
    # the survey, the model's FE responses are the bench's again.
    from rts_scenario.calibration import grid_errors, simulated_measure
    from rts_scenario.survey import modeled_directions, placed_by_survey

    rig, radar = Rig.preset("kit-table1"), RadarProfile.preset("awr1843boost")
    zero = np.zeros(4)
    moved = ChannelErrors(gain_db=zero, phase_deg=zero, delay_s=zero,
                          az_deg=np.array([0.3, -0.2, 0.0, 0.25]),
                          el_deg=np.array([0.0, 0.2, -0.3, 0.1]), distance_m=zero)
    bench = simulated_measure(radar, rig, moved, fidelity=fidelity)
    before = grid_errors(rig, radar, bench)
    placed = placed_by_survey(rig, radar, survey(rig, radar, bench, repeats=1))
    np.testing.assert_allclose(placed.az_deg - rig.az_deg, moved.az_deg, atol=0.002)
    np.testing.assert_allclose(placed.el_deg - rig.el_deg, moved.el_deg, atol=0.002)
    # The model of the placed rig shows each FE where the radar saw it.
    seen_az, seen_el = modeled_directions(placed, radar)
    np.testing.assert_allclose(seen_az, placed.seen[:, 0], atol=1e-4)
    np.testing.assert_allclose(seen_el, placed.seen[:, 1], atol=1e-4)
    after = grid_errors(placed, radar, bench)  # the same physical bench
    assert np.nanmax(np.hypot(*before.T)) > 0.2
    assert np.nanmax(np.hypot(*after.T)) <= (0.0005 if fidelity == "analytic" else 0.002)


def test_survey_place_writes_the_placed_rig(tmp_path, capsys):
    out = tmp_path / "placed.rig.yaml"
    assert cli.main(["survey", "kit-table1", "--place", "--write", str(out)]) == 0
    placed = Rig.from_file(out)
    kit = Rig.preset("kit-table1")
    # The simulated bench is where the file says: the placement moves the FEs by no more
    # than what classic CAN's angle resolution leaves.
    assert np.abs(placed.az_deg - kit.az_deg).max() <= 0.01
    assert placed.seen is not None
    assert "placed at" in capsys.readouterr().out


@pytest.mark.parametrize("rts", [
    pytest.param(True, id="rts-listening"),
    pytest.param(False, id="nothing-listening", marks=pytest.mark.skipif(
        sys.platform != "linux", reason="ICMP errors reach an unconnected socket on Linux only")),
])
def test_survey_that_sees_nothing_fails_and_writes_nothing(tmp_path, capsys, rts):
    # No radar reports on the bus; an RTS listens on the UDP port, or nothing does (a mistyped
    # port: the host answers every datagram "port unreachable", and the survey says so rather
    # than what a silent radar would suggest).
    import socket

    from rts_scenario.outputs.udp import UdpReceiver

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    receiver = UdpReceiver(port=port).start() if rts else None
    json_out, rig_out = tmp_path / "sv.json", tmp_path / "placed.rig.yaml"
    try:
        code = cli.main(["survey", "kit-table1", "--radar", "awr1843boost", "--output",
                         f"udp://127.0.0.1:{port}", "--json", str(json_out), "--place",
                         "--write", str(rig_out)])
    finally:
        if receiver is not None:
            receiver.stop()
    # A measurement that failed (exit 1, as one missing an FE), not bad input.
    assert code == 1
    err = capsys.readouterr().err
    if rts:
        assert err.startswith("error: survey: the radar saw none of the 4 front ends")
    else:
        assert re.match(rf"error: survey: rts_unreachable: \d+ datagrams to "
                        rf"udp://127\.0\.0\.1:{port} came back undelivered \(Connection "
                        r"refused\) from 0\.00 s to [\d.]+ s of measurement 0: .*nothing "
                        r"listened on that port", err), err
    assert err.count("\n") == 1 and "nothing written" in err
    assert not json_out.exists() and not rig_out.exists()


def test_survey_that_misses_a_front_end_reports_it_and_writes_no_rig(tmp_path, capsys,
                                                                       monkeypatch):
    import dataclasses

    import rts_scenario.survey as survey_module

    real = survey_module.survey

    def one_unseen(*args, **kwargs):
        result = real(*args, **kwargs)
        az = result.seen_az_deg.copy()
        az[2] = np.nan
        return dataclasses.replace(result, seen_az_deg=az)

    monkeypatch.setattr(survey_module, "survey", one_unseen)
    json_out, rig_out = tmp_path / "sv.json", tmp_path / "placed.rig.yaml"
    code = cli.main(["survey", "kit-table1", "--radar", "paper", "--json", str(json_out),
                     "--place", "--write", str(rig_out)])
    assert code == 1
    err = capsys.readouterr().err
    assert err == (f"error: the radar did not see FE 2; --write {rig_out}: not written (a rig "
                   f"is written only from a survey that saw every front end)\n")
    assert json.loads(json_out.read_text())["front_ends"][2]["seen_az_deg"] is None
    assert not rig_out.exists()


@pytest.mark.parametrize("offset_s", [0.031, 0.0499])
def test_a_radar_running_free_is_surveyed_by_when_it_measured_not_by_its_first_cycle(offset_s):
    # A radar on the bench runs free: it measured before the survey's first frame (nothing
    # played yet: an empty cycle) and is anywhere in its cycle when the frames start. Its
    # first cycle received is not the first frame's: each FE is where the radar saw it while
    # that FE alone was played (the paper profile's own latency and jitter).
    rig, result = _survey_free_radar(offset_s, None, latency_s=None)
    np.testing.assert_allclose(result.seen_az_deg, rig.az_deg, atol=0.006)
    np.testing.assert_allclose(result.seen_el_deg, rig.el_deg, atol=0.006)


def _survey_free_radar(offset_s, jitter_s, bus_times=True, latency_s=0.05):
    """Survey kit-table1 with a radar running free: ``offset_s`` into its cycle when the
    frames start, ``latency_s`` and ``jitter_s`` on its messages (None: the paper profile's),
    one cycle measured before the first frame; ``bus_times``: whether the bench knows the
    scene's start on the bus's (and the host's) clock."""
    from dataclasses import replace

    from rts_scenario.detections import Detections
    from rts_scenario.radar.clock import RadarClock

    rig, radar = Rig.preset("kit-table1"), RadarProfile.preset("paper")
    profile = radar.radar_clock
    free = replace(radar, clock=replace(
        profile, counter_start=None,
        latency_s=profile.latency_s if latency_s is None else latency_s,
        jitter_s=profile.jitter_s if jitter_s is None else jitter_s))
    clock = free.radar_clock
    own = RadarClock(cycle_s=clock.cycle_s, start_offset_s=offset_s, latency_s=clock.latency_s,
                     jitter_s=clock.jitter_s, counter_start=811)
    with Pipeline(rig, free, radar_options=RadarOptions(fidelity="analytic", noise=False)
                  ) as bench:
        bench.output.clock = own
        sink = bench.output._sink
        if not bus_times:
            bench._scene_origin_s = lambda: None
            bench._host_origin_s = lambda: None

        early: list[int] = []

        def switched_on_before(cycles):
            if cycles and cycles[0].cycle == 811:
                first = cycles[0]
                early.append(810)
                cycles = [Detections.empty(810, first.t_s - own.cycle_s), *cycles]
            sink(cycles)

        bench.output._sink = switched_on_before
        result = survey(rig, free, bench.play)
    assert early == [810]  # the cycle measured before the first frame was sent
    return rig, result


@pytest.mark.parametrize("offset_s, jitter_s", [
    (0.049, 0.005), (0.045, 0.02), (0.0, 0.02), (0.025, 0.005), (0.001, 0.02)])
def test_a_free_radar_measuring_near_the_frame_changes_is_surveyed_by_the_frame_it_saw(
        offset_s, jitter_s):
    # A radar measuring 1 ms before each frame change, its messages' latency jittering by
    # +-5 ms: four frames' bus times put its phase within a few ms, on either side of the
    # change. Each FE is still where the radar saw it while that FE alone was played.
    rig, result = _survey_free_radar(offset_s, jitter_s)
    np.testing.assert_allclose(result.seen_az_deg, rig.az_deg, atol=0.006)
    np.testing.assert_allclose(result.seen_el_deg, rig.el_deg, atol=0.006)


@pytest.mark.parametrize("offset_s", [0.0, 0.025, 0.049])
def test_a_free_radar_on_a_bench_without_bus_times_is_surveyed_by_the_frame_it_saw(offset_s):
    # The first cycle received, measured before any FE played, is not the first FE's.
    rig, result = _survey_free_radar(offset_s, 0.0, bus_times=False)
    np.testing.assert_allclose(result.seen_az_deg, rig.az_deg, atol=0.006)
    np.testing.assert_allclose(result.seen_el_deg, rig.el_deg, atol=0.006)


@pytest.mark.parametrize("counter_start", [0, None], ids=["started", "free"])
def test_a_silent_radar_is_surveyed_as_seeing_nothing(counter_start):
    # No cycle came back (the radar reports on another bus): nothing seen, for a radar
    # started with the frames and for one running free alike.
    from dataclasses import replace

    rig, radar = Rig.preset("kit-table1"), RadarProfile.preset("paper")
    radar = replace(radar, clock=replace(radar.radar_clock, counter_start=counter_start))
    with Pipeline(rig, radar, radar_options=RadarOptions(fidelity="analytic", noise=False)
                  ) as bench:
        bench.output._sink = lambda cycles: None
        result = survey(rig, radar, bench.play)
    assert np.isnan(result.seen_az_deg).all() and np.isnan(result.seen_el_deg).all()


@pytest.mark.parametrize("clock_off_s", [-3600.0, 1234.5])
def test_a_free_radar_on_an_interface_with_its_own_clock_is_surveyed(clock_off_s):
    # The interface stamps the messages with its own clock (seconds since it was plugged in),
    # not the one the frames' start is known on: the first cycle lies far outside the frames,
    # and the bus times only time the cycles against each other, as in a run.
    from dataclasses import replace

    rig, radar = Rig.preset("kit-table1"), RadarProfile.preset("paper")
    free = replace(radar, clock=replace(radar.radar_clock, counter_start=None))
    with Pipeline(rig, free, radar_options=RadarOptions(fidelity="analytic", noise=False)
                  ) as bench:
        start = bench._scene_origin_s
        bench._scene_origin_s = lambda: start() + clock_off_s
        result = survey(rig, free, bench.play)
    np.testing.assert_allclose(result.seen_az_deg, rig.az_deg, atol=0.006)
    np.testing.assert_allclose(result.seen_el_deg, rig.el_deg, atol=0.006)


def _survey_free_radar_on_its_own_clock(latency_cycles, offset_s, ahead_s=None):
    """Survey kit-table1 with a radar running free ``latency_cycles`` late behind an interface
    stamping with its own clock, ``offset_s`` into its cycle when the frames start, its three
    cycles measured before the first frame arriving after it (`free_radar.behind_own_clock`)."""
    rig = Rig.preset("kit-table1")
    free = free_profile(RadarProfile.preset("paper"), latency_cycles)
    with Pipeline(rig, free, radar_options=RadarOptions(fidelity="analytic", noise=False)
                  ) as bench:
        behind_own_clock(bench, offset_s, ahead_s=ahead_s)
        return rig, survey(rig, free, bench.play)


@pytest.mark.parametrize("latency_cycles, offset_s", [
    (1.5, 0.0), (1.5, 0.049), (2.0, 0.001), (2.2, 0.025), (2.7, 0.0499), (3.0, 0.012)])
def test_a_free_radar_on_an_interface_with_its_own_clock_is_surveyed_by_when_it_measured(
        latency_cycles, offset_s):
    # A real radar runs free and reports one and a half to three cycles after it measured:
    # the cycles it measured before the first frame (nothing played) arrive after the
    # measurement started, so the first cycle received is not the first frame's. The
    # interface stamps with its own clock; when the host received each cycle places it. Each
    # FE is where the radar saw it while that FE alone was played.
    rig, result = _survey_free_radar_on_its_own_clock(latency_cycles, offset_s)
    np.testing.assert_allclose(result.seen_az_deg, rig.az_deg, atol=0.006)
    np.testing.assert_allclose(result.seen_el_deg, rig.el_deg, atol=0.006)


@pytest.mark.parametrize("ahead_s", [0.3, -1.5])
def test_a_free_radar_behind_an_interface_clock_near_the_host_s_is_surveyed(ahead_s):
    # The interface's clock was set from the host's once and has run off it since: its stamps
    # lie within seconds of the host's, where they passed for the host's and numbered the
    # cycles by a start off by that much. No message is received before it was stamped, nor
    # all of them long after: the receipts tell, and place the cycles.
    rig, result = _survey_free_radar_on_its_own_clock(2.2, 0.025, ahead_s=ahead_s)
    np.testing.assert_allclose(result.seen_az_deg, rig.az_deg, atol=0.006)
    np.testing.assert_allclose(result.seen_el_deg, rig.el_deg, atol=0.006)


def test_a_free_radar_whose_cycles_arrival_cannot_place_is_not_surveyed_by_a_guess(
        monkeypatch):
    # An interface that may deliver a message 120 ms after it was on the bus: with 50 ms
    # cycles, a cycle numbered the last of a frame's two-cycle hold may be the last of the
    # frame before's. No frame's measurement is taken (nothing seen, never a neighbour's FE).
    import rts_scenario.pipeline as pipeline

    monkeypatch.setattr(pipeline, "HOST_DELIVERY_S", 0.12)
    rig, result = _survey_free_radar_on_its_own_clock(2.0, 0.03)
    assert np.isnan(result.seen_az_deg).all() and np.isnan(result.seen_el_deg).all()
    # Within 60 ms (a cycle numbered at most one too late: still the frame's own hold), each
    # FE is where the radar saw it.
    monkeypatch.setattr(pipeline, "HOST_DELIVERY_S", 0.06)
    rig, result = _survey_free_radar_on_its_own_clock(2.0, 0.03)
    np.testing.assert_allclose(result.seen_az_deg, rig.az_deg, atol=0.006)


@pytest.mark.parametrize("limits, reference, key", [
    # The FEs' delay at a 1.2 m reference: 2 (1.2 - 1) m / c0 - 4 ns latency, below zero.
    ({"latency_s": 4e-9, "delay_min_s": 4e-9}, {"range_m": 1.2}, "limits.delay_min_s"),
    # At a 10 m reference: 2 (10 - 1) m / c0 = 60 ns, beyond an RTS whose delay reaches 50 ns.
    ({"delay_max_s": 50e-9}, {"range_m": 10.0}, "limits.delay_max_s"),
    # The pattern's target approaches at 1 m/s: 2 / lambda = 513 Hz on a 77 GHz radar.
    ({"doppler_min_hz": 1000.0, "doppler_max_hz": 60000.0}, {}, "limits.doppler_min_hz"),
    ({"doppler_min_hz": -60000.0, "doppler_max_hz": 100.0}, {}, "limits.doppler_max_hz"),
], ids=["delay", "delay-max", "doppler-min", "doppler-max"])
def test_a_survey_the_rts_cannot_play_is_refused_naming_the_limit(tmp_path, capsys, limits,
                                                                  reference, key):
    # A test pattern beyond the rig's limits would go to the RTS as if it could play it
    # (status OK), and its measurement would look like one.
    doc = Rig.preset("kit-table1").to_document()
    doc["limits"].update(limits)
    doc["reference"].update(reference)
    path = tmp_path / "near.rig.yaml"
    import yaml
    path.write_text(yaml.safe_dump(doc))
    rig, radar = Rig.from_file(path), RadarProfile.preset("awr1843boost")
    with Pipeline(rig, radar, radar_options=RadarOptions(fidelity="analytic", noise=False)) as b, \
            pytest.raises(RtsError, match=key.replace(".", r"\.")):
        survey(rig, radar, b.play, repeats=1)
    assert cli.main(["survey", str(path), "--radar", "awr1843boost"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and key in err[0] and "FE 0" in err[0], err


def test_a_front_end_the_radar_never_saw_is_null_without_a_numpy_warning():
    # No cycle of FE 2's frames held a detection: its direction and level are NaN (null in
    # the JSON), the others as measured; nothing else is printed (a RuntimeWarning of
    # numpy's empty mean would reach the user's terminal).
    from rts_scenario.detections import Detections
    from rts_scenario.survey import REPEATS

    rig, radar = Rig.preset("kit-table1"), RadarProfile.preset("paper")
    with Pipeline(rig, radar, radar_options=RadarOptions(fidelity="analytic", noise=False)) as b:
        def blind_to_fe_2(schedule):
            return [Detections.empty(c.cycle, c.t_s, ()) if i // REPEATS == 2 else c
                    for i, c in enumerate(b.play(schedule))]

        result = survey(rig, radar, blind_to_fe_2)
    for seen in (result.seen_az_deg, result.seen_el_deg, result.level_db):
        assert np.isnan(seen[2]) and np.isfinite(np.delete(seen, 2)).all()
    np.testing.assert_allclose(np.delete(result.seen_az_deg, 2), np.delete(rig.az_deg, 2),
                               atol=0.006)


def surveyed_json(tmp_path, name, *argv):
    out = tmp_path / f"{name}.json"
    assert cli.main(["survey", "kit-table1", *argv, "--json", str(out)]) == 0
    return json.loads(out.read_text())


def test_survey_through_a_third_party_mapping_sees_the_rig_s_front_ends(tmp_path):
    # The paper radar sees each kit-table1 FE at its mechanical direction (far field, on the
    # rig's axis): through the object list's DBC as through rts-scenario's own.
    rig = Rig.preset("kit-table1")
    data = surveyed_json(tmp_path, "objects", "--radar", "paper", "--mapping", str(OBJECT_LIST))
    assert data["mapping"] == str(OBJECT_LIST.resolve())
    fes = data["front_ends"]
    np.testing.assert_allclose([fe["seen_az_deg"] for fe in fes], rig.az_deg,
                               atol=OBJECT_LIST_STEP_DEG / 2 + 1e-9)
    np.testing.assert_allclose([fe["seen_el_deg"] for fe in fes], rig.el_deg,
                               atol=OBJECT_LIST_STEP_DEG / 2 + 1e-9)
    assert surveyed_json(tmp_path, "own", "--radar", "paper")["mapping"] is None


def test_survey_through_a_third_party_mapping_decodes_the_radar_speaking_it(tmp_path):
    # The awr1843boost sees the FEs 1 m away in its near field, off any 0.05 deg step: through
    # the mapping the radar speaks the object list and the survey decodes it (every seen angle
    # on its 0.05 deg steps), the same directions as through the built-in DBC within a step.
    own = surveyed_json(tmp_path, "own", "--radar", "awr1843boost")["front_ends"]
    objects = surveyed_json(tmp_path, "objects", "--radar", "awr1843boost", "--mapping",
                            str(OBJECT_LIST))["front_ends"]
    for key in ("seen_az_deg", "seen_el_deg"):
        seen_own = np.array([fe[key] for fe in own])
        seen = np.array([fe[key] for fe in objects])
        steps = seen / OBJECT_LIST_STEP_DEG
        np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)
        np.testing.assert_allclose(seen, seen_own, atol=OBJECT_LIST_STEP_DEG / 2 + 0.0051)
    # The built-in DBC's steps are finer: the near field's directions are off the object list's.
    el_own = np.array([fe["seen_el_deg"] for fe in own]) / OBJECT_LIST_STEP_DEG
    assert np.abs(el_own - np.round(el_own)).max() > 0.05


def test_a_room_reflector_stronger_than_a_weak_front_end_is_not_taken_for_it():
    # A static reflector (-10 dBsm at 4 m, 0 m/s) the radar reports stronger than FE 3 alone
    # (12 dB weak: about -2 dBsm at the reference's 10 m), weaker than the others. The survey
    # reads each cycle where the pattern's echo shows (10 m, approaching at 1 m/s): FE 3 is
    # seen where it is seen without the room, at its own level.
    from room import with_reflector

    from rts_scenario.calibration import simulated_measure

    rig, radar = Rig.preset("kit-table1"), RadarProfile.preset("awr1843boost")
    weak = ChannelErrors(gain_db=np.array([0.0, 0.6, -0.4, -12.0]), phase_deg=np.zeros(4),
                         delay_s=np.zeros(4), az_deg=np.zeros(4), el_deg=np.zeros(4),
                         distance_m=np.zeros(4))
    clean = survey(rig, radar, simulated_measure(radar, rig, weak), repeats=1)
    room = survey(rig, radar, with_reflector(simulated_measure(radar, rig, weak), 4.0, 0.0,
                                             -10.0, az_deg=1.0, el_deg=2.0), repeats=1)
    # The injected gains (kit-table1's FEs all 1 m away: 4e-5 dB apart beyond them).
    np.testing.assert_allclose(room.level_db, weak.gain_db, atol=0.01)
    np.testing.assert_array_equal(room.seen_az_deg, clean.seen_az_deg)
    np.testing.assert_array_equal(room.seen_el_deg, clean.seen_el_deg)
