"""The bench calibration workflow: `emulate` as an uncalibrated RTS, `survey` and `calibrate`
over UDP, and what they print and refuse.

The emulated RTS runs in this process on python-can's virtual bus (`Emulator`); each test plays
its test patterns in real time on loopback. The injected channel errors are the known values.
"""

import dataclasses
import itertools
import json
import re
import time

import numpy as np
import pytest

import rts_scenario as rs
import rts_scenario.cli as cli
from rts_scenario import calibration as cal
from rts_scenario.detections import Detections
from rts_scenario.emulator import Emulator
from rts_scenario.errors import MeasurementError
from rts_scenario.radar.profile import RadarProfile
from rts_scenario.radar.simulate import ChannelErrors

# In wall-clock time: run with the session's heap frozen (conftest `frozen_heap`).
REAL_TIME = True

_channels = itertools.count()


def _wrap(deg):
    return (np.asarray(deg) + 180.0) % 360.0 - 180.0


def _table(out: str, n_fe: int) -> np.ndarray:
    """The rows `FE phase gain ...` of calibrate's table, as numbers."""
    rows = [line.split() for line in out.splitlines()
            if re.match(r"^\s*\d+\s+-?\d", line)]
    assert len(rows) == n_fe, out
    return np.array([[float(v) for v in row] for row in rows])


def test_calibrate_prints_each_channel_s_phase_as_its_json_gives_it_on_a_wide_rig(tmp_path,
                                                                                   capsys):
    # 15 FEs, 8 quads: phases relative to FE 0 add up to more than a turn along the grid; the
    # table prints each in [-180, 180), as the JSON, the rig file and `emulate` give them.
    report = tmp_path / "cal.json"
    code = cli.main(["calibrate", "wide-3x5", "--radar", "awr1843boost", "--inject-phase-deg",
                     "180", "--inject-gain-db", "1", "--seed", "4", "--json", str(report)])
    out = capsys.readouterr().out
    assert code == 0, out
    table = _table(out, 15)
    errors = ChannelErrors.random(15, np.random.default_rng(4), phase_deg=180.0, gain_db=1.0)
    injected = _wrap(errors.phase_deg - errors.phase_deg[0])
    assert np.all((table[:, 1] >= -180.0) & (table[:, 1] < 180.0)), table[:, 1]
    # The known injected phases, within the fit's half degree (the table prints 2 decimals).
    np.testing.assert_allclose(_wrap(table[:, 1] - injected), 0.0, atol=0.5)
    np.testing.assert_allclose(table[:, 3], injected, atol=0.006)
    recovered = [c["recovered_phase_deg"] for c in json.loads(report.read_text())["channels"]]
    np.testing.assert_allclose(table[:, 1], recovered, atol=0.006)


def _drop_last_cycle(pair, times):
    """``drop(schedule, cycles)``, which loses the last cycle of FE ``pair``'s sweep the first
    ``times`` times, and the frames it dropped."""
    dropped = []

    def drop(schedule, cycles):
        if schedule.fe[0, 0, :2].tolist() == list(pair) and len(dropped) < times:
            dropped.append(int(schedule.frame_index[-1]))
            last = cycles[-1]
            cycles[-1] = Detections.empty(last.cycle, last.t_s, (), complete=False)
        return cycles

    return drop, dropped


def _dropping(measure, pair, times):
    """``measure`` that loses the last cycle of FE ``pair``'s sweep the first ``times`` times."""
    drop, dropped = _drop_last_cycle(pair, times)
    return (lambda schedule: drop(schedule, measure(schedule))), dropped


def test_a_pair_whose_cycle_did_not_come_back_twice_is_named_as_such():
    # The radar saw the rig, but one cycle of a sweep never arrived (lost, or later than the
    # measurement waited), in the pair's measurement and in its second one: the error says
    # so, not that the radar does not see the rig.
    rig, radar = rs.Rig.preset("kit-table1"), RadarProfile.preset("paper")
    measure, dropped = _dropping(cal.simulated_measure(radar, rig, ChannelErrors.none(4)),
                                 (0, 2), times=2)
    with pytest.raises(MeasurementError) as info:
        cal.calibrate(rig, radar, measure)
    message = str(info.value)
    assert len(dropped) == 2
    assert "FE pair 0-2" in message and "did not come back" in message, message
    assert "measured twice" in message, message
    assert "sees the rig" not in message, message


def test_a_pair_whose_cycle_did_not_come_back_once_is_measured_again():
    # A bench hiccup: the pair's second measurement comes back whole and is the one fitted.
    rig, radar = rs.Rig.preset("kit-table1"), RadarProfile.preset("paper")
    errors = ChannelErrors.random(4, np.random.default_rng(2), phase_deg=180.0, gain_db=1.0)
    measure, dropped = _dropping(cal.simulated_measure(radar, rig, errors), (0, 2), times=1)
    result = cal.calibrate(rig, radar, measure)
    assert len(dropped) == 1
    assert result.remeasured == ("FE pair 0-2",)
    assert not result.suspects and _recovered(result, errors)


# Pair 0-2's frames are the pattern's 24..47 (pair 0-1 plays 0..23); each is held for two
# radar cycles over UDP, so frame 30's first datagram is the stream's frame 60.
HELD_FRAME = 60


def _held_calibration(monkeypatch, times):
    """Calibrate kit-table1 over UDP to an emulated RTS (no channel errors) whose sender is
    held 60 ms before pair 0-2's frame 30 goes out (after the radar's cycle measuring it, 50
    ms later), the first ``times`` times, as a loaded host may. Return the result (or the
    error), how many frames the bench found sent late, how often the sender was held and how
    many measurements were played."""
    from rts_scenario.outputs.udp import HEADER, UdpOutput
    from rts_scenario.pipeline import Pipeline, RunOptions

    transmit = UdpOutput.transmit
    held = []

    def held_transmit(self, datagram: bytes) -> None:
        if HEADER.unpack_from(datagram)[4] == HELD_FRAME and len(held) < times:
            held.append(HELD_FRAME)
            time.sleep(0.06)
        transmit(self, datagram)

    monkeypatch.setattr(UdpOutput, "transmit", held_transmit)  # each measurement's sender
    rig, radar = rs.Rig.preset("kit-table1"), RadarProfile.preset("awr1843boost")
    channel = f"rts-bench-cal-test-{next(_channels)}"
    with Emulator(rig, radar, can_channel=channel, noise=False) as emulator:
        host, port = emulator.address
        options = RunOptions(output=f"udp://{host}:{port}", can_interface="virtual",
                             can_channel=channel)
        with Pipeline(rig, radar, options) as bench:
            plays = []

            def play(schedule):
                plays.append(schedule.n_frames)
                return bench.play(schedule)

            try:
                outcome = cal.calibrate(rig, radar, play)
            except MeasurementError as exc:
                outcome = exc
    return outcome, bench.measurement_late_frames, len(held), len(plays)


def test_a_pair_whose_frame_went_out_late_is_measured_again(monkeypatch):
    # The frame reached the RTS after the cycle that measures it: not measured. The pair is
    # measured once more, on time, and the calibration finds the emulator's channels as they
    # are (no errors: every offset 0).
    # (A loaded host may hold the sender elsewhere too: other measurements may be played
    # again, pair 0-2 must be.)
    result, late, held, _ = _held_calibration(monkeypatch, times=1)
    assert held == 1 and late >= 1
    assert isinstance(result, cal.CalibrationResult), result
    assert "FE pair 0-2" in result.remeasured
    assert not result.suspects
    np.testing.assert_allclose(_wrap(result.phase_deg), 0.0, atol=0.05)
    np.testing.assert_allclose(result.gain_db, 0.0, atol=0.005)


def test_a_pair_whose_frame_went_out_late_twice_stops_the_calibration(monkeypatch):
    # It stops there: the FEs alone, pair 0-1, pair 0-2 twice; the four pairs after it are not
    # played (a failed calibration, minutes of bench time on a wide rig). A loaded host may
    # hold the sender elsewhere too: each measurement with a frame late for another reason
    # is played once more, at most one play per such frame.
    error, late, held, plays = _held_calibration(monkeypatch, times=2)
    assert held == 2 and late >= 2 and 4 <= plays <= 4 + (late - held), (late, plays)
    assert isinstance(error, MeasurementError), error
    message = str(error)
    assert "FE pair 0-2's frame 30" in message and "measured twice" in message, message


def test_a_survey_of_a_rig_the_rts_does_not_have_fails_naming_the_frames_it_refused(tmp_path,
                                                                                    capsys):
    # The RTS (emulate --rig kit-table1) refuses the frames of FEs it lacks and holds the frame
    # before: the radar keeps seeing FE 3 while FEs 4..14 of wide-3x5 are surveyed. A survey
    # that took those cycles would "see" eleven FEs at FE 3's direction.
    rig, radar = rs.Rig.preset("kit-table1"), RadarProfile.preset("awr1843boost")
    channel = f"rts-bench-cal-test-{next(_channels)}"
    written = tmp_path / "seen.rig.yaml"
    with Emulator(rig, radar, can_channel=channel, noise=False) as emulator:
        host, port = emulator.address
        code = cli.main(["survey", "wide-3x5", "--radar", "awr1843boost", "--output",
                         f"udp://{host}:{port}", "--can-channel", channel, "--write",
                         str(written)])
    out = capsys.readouterr()
    assert code == 1, out
    assert "did not apply" in out.err and "malformed" in out.err, out.err
    assert not written.exists()
    assert "3.9" not in out.out  # no table of FEs "seen" where FE 3 was held


def test_a_calibration_against_an_rts_playing_another_rig_s_geometry_fails(tmp_path, capsys):
    # Same layout (one quad), other directions: every frame is valid and played, but the RTS
    # says which rig it plays; a calibration measured on it is not the rig file's.
    rig, radar = rs.Rig.preset("kit-table1"), RadarProfile.preset("awr1843boost")
    other = dataclasses.replace(rig, az_deg=rig.az_deg + np.array([0.0, 0.3, 0.0, 0.3]))
    channel = f"rts-bench-cal-test-{next(_channels)}"
    written = tmp_path / "lab.rig.yaml"
    with Emulator(other, radar, can_channel=channel, noise=False) as emulator:
        host, port = emulator.address
        code = cli.main(["calibrate", "kit-table1", "--radar", "awr1843boost", "--output",
                         f"udp://{host}:{port}", "--can-channel", channel, "--write",
                         str(written)])
        runs = len(emulator.runs)
    out = capsys.readouterr()
    assert code == 1, out
    assert "rts_rig" in out.err and "kit-table1" in out.err, out.err
    assert not written.exists()
    assert runs <= 1  # stopped at the first measurement, not after every pair


def test_udp_multicast_buses_of_two_groups_do_not_hear_each_other():
    # Two rehearsals on one host, each on its own multicast group (docs/cli.md, emulate): a
    # socket bound to python-can's port hears every group joined on the host unless told not
    # to, and one bench's radar cycles would mix into the other's.
    import can

    from rts_scenario.canbus import open_bus

    try:
        a = open_bus("udp_multicast", "239.74.163.221")
    except Exception as exc:  # no msgpack, no multicast route: no such bench here
        pytest.skip(f"udp_multicast unavailable here: {exc}")
    with a, open_bus("udp_multicast", "239.74.163.222") as b, \
            open_bus("udp_multicast", "239.74.163.221") as a2:
        a.send(can.Message(arbitration_id=0x7A, data=b"\x01", is_extended_id=False))
        if a2.recv(1.0) is None:
            pytest.skip("udp_multicast does not loop back on this host")
        assert b.recv(0.3) is None


@pytest.mark.usefixtures("unnamed_channel")
def test_radar_channel_on_an_interface_that_names_no_channel_says_so(capsys):
    # udp_multicast (the two-process rehearsal's bus) gives every message channel None: there
    # is one channel, and --radar-channel cannot pick it. The error says that, not "(none)".
    code = cli.main(["survey", "kit-table1", "--radar-channel", "239.74.163.2"])
    err = capsys.readouterr().err
    assert code == 1, err
    assert "(none)" not in err, err
    assert "names no channel" in err and "leave --radar-channel out" in err, err


def test_calibrate_shows_its_progress_by_fe_pairs_on_a_terminal(monkeypatch, capsys):
    # A calibration over UDP takes minutes on a wide rig (38 pairs): on a terminal it shows
    # how many FE pairs it measured (it counted pairs against a 200-frame minimum: never).
    import io
    import sys

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    assert cli.main(["calibrate", "kit-table1"]) == 0
    shown = terminal.getvalue()
    assert "1/6 FE pairs measured" in shown and "6/6 FE pairs measured" in shown, shown


@pytest.mark.parametrize("gain_db", [10.0, 20.0])
def test_calibrate_recovers_channels_many_db_apart(gain_db):
    # --inject-gain-db allows up to 20 dB: channels up to 40 dB apart. Each pair's fit started
    # at equal gains and settled in a wrong minimum from about 6 dB apart (every pair suspect,
    # the grid worse after than before); the single levels each pair plays first put it near.
    rig, radar = rs.Rig.preset("kit-table1"), RadarProfile.preset("awr1843boost")
    errors = ChannelErrors.random(4, np.random.default_rng(3), phase_deg=180.0, gain_db=gain_db)
    result = cal.calibrate(rig, radar, cal.simulated_measure(radar, rig, errors))
    assert not result.suspects
    np.testing.assert_allclose(_wrap(result.phase_deg - (errors.phase_deg - errors.phase_deg[0])),
                               0.0, atol=0.5)
    np.testing.assert_allclose(result.gain_db, errors.gain_db - errors.gain_db[0], atol=0.05)


def _recovered(result, errors, phase_deg=0.5, gain_db=0.05):
    """The injected offsets relative to FE 0 recovered within ``phase_deg`` and ``gain_db``."""
    phase = _wrap(result.phase_deg - (errors.phase_deg - errors.phase_deg[0]))
    gain = result.gain_db - (errors.gain_db - errors.gain_db[0])
    return np.abs(phase).max() <= phase_deg and np.abs(gain).max() <= gain_db


def test_calibrate_recovers_a_pair_whose_swept_channel_is_6_db_stronger():
    # At weight 0.5 a swept channel about 6 dB stronger than the reference arrives as strong
    # as it: the sweep passes through cancellation, where the angle tells little. Played at
    # weights set from the single channels' levels, it arrives at half the reference's.
    rig, radar = rs.Rig.preset("kit-table1"), RadarProfile.preset("awr1843boost")
    errors = ChannelErrors.random(4, np.random.default_rng(3), phase_deg=180.0, gain_db=6.0)
    result = cal.calibrate(rig, radar, cal.simulated_measure(radar, rig, errors))
    assert not result.suspects
    assert _recovered(result, errors)


@pytest.mark.parametrize("estimator", ["bartlett", "ti"])
def test_calibrate_recovers_channels_within_6_db_for_every_seed(estimator):
    # +-6 dB puts some pairs' channels about 6 dB apart, in either order: 24 seeds, every
    # injected phase within 0.5 deg and gain within 0.05 dB, no pair suspect.
    rig, radar = rs.Rig.preset("kit-table1"), RadarProfile.preset("awr1843boost")
    failed = []
    for seed in range(24):
        errors = ChannelErrors.random(4, np.random.default_rng(seed), phase_deg=180.0,
                                      gain_db=6.0)
        measure = cal.simulated_measure(radar, rig, errors, estimator=estimator)
        result = cal.calibrate(rig, radar, measure, estimator=estimator)
        if result.suspects or not _recovered(result, errors):
            failed.append((seed, result.suspects))
    assert failed == []


def test_calibrate_says_which_measurements_it_played_again(tmp_path, capsys, monkeypatch):
    # A cycle of pair 0-2 lost the first time: the pair is measured again and the calibration
    # passes; the printout and --json say which measurement was played twice.
    from rts_scenario.pipeline import Pipeline

    play = Pipeline.play
    drop, dropped = _drop_last_cycle((0, 2), times=1)
    monkeypatch.setattr(Pipeline, "play", lambda self, schedule: drop(schedule,
                                                                     play(self, schedule)))
    report = tmp_path / "cal.json"
    code = cli.main(["calibrate", "kit-table1", "--json", str(report)])
    out = capsys.readouterr().out
    assert code == 0, out
    assert dropped == [47]
    assert "note: measured again, some cycles missing the first time: FE pair 0-2" in out, out
    assert json.loads(report.read_text())["remeasured"] == ["FE pair 0-2"]
