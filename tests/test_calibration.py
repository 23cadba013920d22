import dataclasses
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from free_radar import behind_own_clock, free_profile

import rts_scenario as rs
import rts_scenario.cli as cli
from rts_scenario.calibration import (
    calibrate,
    check_grid,
    grid_errors,
    pairs_of,
    simulated_measure,
)
from rts_scenario.detections import Detections
from rts_scenario.radar import RadarProfile
from rts_scenario.radar.simulate import ChannelErrors

PAPER = RadarProfile.preset("paper")
KIT = rs.Rig.preset("kit-table1")


def relative(errors: ChannelErrors):
    phase = np.mod(errors.phase_deg - errors.phase_deg[0] + 180.0, 360.0) - 180.0
    return phase, errors.gain_db - errors.gain_db[0]


def wrapped(deg):
    return np.mod(np.asarray(deg) + 180.0, 360.0) - 180.0


def test_pairs_of_a_quad_and_a_grid():
    assert pairs_of(KIT) == [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    wide = rs.Rig.preset("wide-3x5")
    assert len(pairs_of(wide)) == 8 * 6 - 10  # shared edges of neighbouring quads count once


AWR = RadarProfile.preset("awr1843boost")


def recovered_within(result, errors, phase_deg, gain_db):
    phase, gain = relative(errors)
    assert np.abs(wrapped(result.phase_deg - phase)).max() <= phase_deg
    assert np.abs(result.gain_db - gain).max() <= gain_db


@pytest.mark.parametrize("estimator", ["bartlett", "ti"])
@pytest.mark.parametrize("seed", range(5))
def test_recovers_injected_offsets_on_the_awr1843boost_for_its_estimator(seed, estimator):
    # The honest bench: physical antennas 1 m away, near field, IF delay model. The acceptance
    # figures over 20 seeds and both fidelities: tests/benchmarks/calibration_accuracy.py.
    errors = ChannelErrors.random(4, np.random.default_rng(seed), phase_deg=180.0, gain_db=1.0)
    method = "exact" if estimator == "bartlett" else "estimator"
    measure = simulated_measure(AWR, KIT, errors, estimator=estimator)
    before = grid_errors(KIT, AWR, measure, method, estimator)
    result = calibrate(KIT, AWR, measure, estimator=estimator)
    recovered_within(result, errors, 0.5, 0.05)
    assert not result.suspects
    calibrated = result.apply(KIT)
    after = grid_errors(calibrated, AWR, simulated_measure(AWR, calibrated, errors,
                                                            estimator=estimator),
                        method, estimator)
    assert np.nanmax(np.abs(after)) <= 0.01 < np.nanmax(np.abs(before))


@pytest.mark.parametrize("seed", range(3))
def test_a_stepped_attenuator_s_rounding_is_not_taken_for_a_channel_gain(seed):
    # The RTS sets the nearest of its 0.5 dB attenuator steps. Calibrating channels with
    # gain errors (and a calibration already holding fractions of a dB) plays each pair's
    # swept channel up to a quarter step off what it asked: that rounding is the pattern's,
    # not the channel's, and the gains come out within the 0.05 dB of a continuous one.
    import dataclasses

    rig = dataclasses.replace(KIT, limits=dataclasses.replace(KIT.limits,
                                                              attenuation_step_db=0.5),
                              cal_gain_db=np.array([0.0, 0.13, -0.21, 0.37]))
    errors = ChannelErrors.random(4, np.random.default_rng(seed), phase_deg=180.0, gain_db=1.0)
    result = calibrate(rig, PAPER, simulated_measure(PAPER, rig, errors))
    phase, gain = relative(errors)
    assert np.abs(wrapped(result.phase_deg - phase)).max() <= 0.5
    # The channels' gains relative to the calibration the rig already has.
    assert np.abs(result.gain_db - (gain - (rig.cal_gain_db - rig.cal_gain_db[0]))).max() \
        <= 0.05
    # What the pattern asked for lies on the attenuator's steps.
    from rts_scenario.calibration import pattern_schedule

    pattern = pattern_schedule(rig, PAPER, [[(0, 1.0, 0.0), (1, 0.5, 0.0)]], 10.0, 40.0)
    att = pattern.attenuation_db[0, 0, :2]
    np.testing.assert_allclose(att / 0.5, np.round(att / 0.5), atol=1e-9)


# Calibration phases off a 6-bit phase shifter's 5.625 deg steps: the RTS plays 0, 11.25,
# -39.375 and 95.625 deg, turning channels 1-3 by -2.45, +1.825 and -2.275 deg against 0.
STEPPED_CAL_PHASE_DEG = np.array([0.0, 13.7, -41.2, 97.9])


@pytest.mark.parametrize("seed", range(3))
def test_a_phase_shifter_s_rounding_is_not_taken_for_a_channel_phase(seed):
    # The pairs are measured through the rig's calibration as the shifter plays it: the fit
    # takes each channel's rounding back, so the offsets are those of a continuous shifter,
    # the channels' own relative phases plus the calibration's, within 0.05 deg (without it,
    # off by the roundings above).
    import dataclasses

    rig = dataclasses.replace(KIT, cal_phase_deg=STEPPED_CAL_PHASE_DEG,
                              limits=dataclasses.replace(KIT.limits, phase_step_deg=5.625))
    errors = ChannelErrors.random(4, np.random.default_rng(seed), phase_deg=180.0, gain_db=1.0)
    result = calibrate(rig, PAPER, simulated_measure(PAPER, rig, errors))
    phase, gain = relative(errors)
    expected = wrapped(phase + STEPPED_CAL_PHASE_DEG - STEPPED_CAL_PHASE_DEG[0])
    assert np.abs(wrapped(result.phase_deg - expected)).max() <= 0.05
    assert np.abs(result.gain_db - gain).max() <= 0.05
    assert not result.suspects
    # What the pattern asked for lies on the shifter's steps.
    from rts_scenario.calibration import pattern_schedule

    pattern = pattern_schedule(rig, PAPER, [[(0, 1.0, 0.0), (1, 0.5, 0.0), (2, 0.5, 7.0)]],
                               10.0, 40.0)
    sent = np.degrees(pattern.phase_rad[0, 0, :3])
    np.testing.assert_allclose(sent / 5.625, np.round(sent / 5.625), atol=1e-9)


def test_a_check_grid_some_of_whose_cycles_did_not_come_back_is_measured_again():
    # A bench's hiccup (a cycle lost, a frame the host sent late) on the check grid must not
    # fail a calibration that passed: the grid is played once more, as a pair would be, and
    # said to be. Where the second play misses the cycle too, the point stays missed.
    errors = ChannelErrors.random(4, np.random.default_rng(0), phase_deg=0.0, gain_db=0.0)
    measure = simulated_measure(AWR, KIT, errors)
    plays = []

    def hiccup(schedule, lost_on=(0,)):
        cycles = measure(schedule)
        if len(plays) in lost_on:
            cycles[7] = Detections.empty(cycles[7].cycle, cycles[7].t_s, complete=False)
        plays.append(schedule.n_frames)
        return cycles

    again: list[str] = []
    grid = check_grid(KIT, AWR, hiccup, remeasured=again, what="check grid after calibration")
    assert len(plays) == 2 and again == ["check grid after calibration"]
    assert grid.summary()["missed"] == 0
    plays.clear()
    grid = check_grid(KIT, AWR, lambda s: hiccup(s, (0, 1)))
    assert len(plays) == 2 and grid.summary()["missed"] == 1


def test_after_calibration_with_a_phase_shifter_the_radar_sees_the_predicted_angle():
    # On the awr1843boost a 6-bit shifter's rounding moves kit-table1's targets by up to
    # 0.017 deg; the calibrated rig's check grid is seen where the schedule predicts, its
    # phase rounding included, within 0.002 deg (0.0003 deg measured).
    import dataclasses

    from rts_scenario.calibration import check_grid

    rig = dataclasses.replace(KIT, cal_phase_deg=STEPPED_CAL_PHASE_DEG,
                              limits=dataclasses.replace(KIT.limits, phase_step_deg=5.625))
    errors = ChannelErrors.random(4, np.random.default_rng(0), phase_deg=180.0, gain_db=1.0)
    after = calibrate(rig, AWR, simulated_measure(AWR, rig, errors)).apply(rig)
    grid = check_grid(after, AWR, simulated_measure(AWR, after, errors))
    stats = grid.summary()
    assert stats["missed"] == 0 and stats["not_played"] == 0
    assert stats["max_excess_error_deg"] <= 0.002
    assert np.nanmax(np.abs(grid.predicted_deg)) > 0.005  # the rounding is there to predict


@pytest.mark.parametrize("seed", range(3))
def test_recovers_injected_offsets_on_the_paper_radar(seed):
    errors = ChannelErrors.random(4, np.random.default_rng(seed), phase_deg=180.0, gain_db=1.0)
    result = calibrate(KIT, PAPER, simulated_measure(PAPER, KIT, errors))
    recovered_within(result, errors, 0.5, 0.05)
    calibrated = result.apply(KIT)
    after = grid_errors(calibrated, PAPER, simulated_measure(PAPER, calibrated, errors))
    assert np.nanmax(np.abs(after)) <= 0.01


@pytest.mark.parametrize("latency_cycles, offset_s", [(1.5, 0.049), (2.5, 0.0), (3.0, 0.02)])
def test_a_free_radar_on_an_interface_with_its_own_clock_is_calibrated(latency_cycles, offset_s):
    # A real radar runs free, one and a half to three cycles late, behind an interface that
    # stamps with its own clock: each pair's sweep is measured where the radar saw each of its
    # frames (its cycles placed by when the host received them), not from its first cycle
    # received, which it measured before the sweep began.
    from rts_scenario.pipeline import Pipeline
    from rts_scenario.scenario.model import RadarOptions

    errors = ChannelErrors.random(4, np.random.default_rng(1), phase_deg=180.0, gain_db=1.0)
    free = free_profile(PAPER, latency_cycles)
    with Pipeline(KIT, free, errors=errors,
                  radar_options=RadarOptions(fidelity="analytic", noise=False)) as bench:
        behind_own_clock(bench, offset_s)
        result = calibrate(KIT, free, bench.play)
    recovered_within(result, errors, 0.5, 0.05)


def test_the_fit_uses_the_radar_s_estimator():
    # A TI-style radar fitted as if it were Bartlett: the model no longer fits the sweeps.
    errors = ChannelErrors.random(4, np.random.default_rng(4), phase_deg=180.0, gain_db=1.0)
    measure = simulated_measure(AWR, KIT, errors, estimator="ti")
    right = calibrate(KIT, AWR, measure, estimator="ti")
    wrong = calibrate(KIT, AWR, measure, estimator="bartlett")
    assert max(p.fit_rms_deg for p in right.pairs) < 0.01
    assert max(p.fit_rms_deg for p in wrong.pairs) > 5 * max(p.fit_rms_deg
                                                              for p in right.pairs)


@pytest.mark.parametrize(("model", "step"), [("if", 0.0), ("if", 1e-10), ("rf", 1e-10)])
def test_sweeps_delay_on_the_rts_grid_converted_by_its_delay_model(model, step):
    import dataclasses

    from rts_scenario.calibration import delayed_frequency_hz, sweep_delays
    from rts_scenario.rig import RtsDelayModel

    rig = dataclasses.replace(KIT, limits=dataclasses.replace(KIT.limits, delay_step_s=step),
                              rts=RtsDelayModel(model))
    delays, phases = sweep_delays(rig, AWR, 24, 10.0)
    if step:
        np.testing.assert_allclose(delays / step, np.round(delays / step), atol=1e-6)
    # The phase a delay gives: 2 pi f tau at the IF (500 MHz) or the carrier, where the radar
    # reads it (centre of the sampled sweep, less the sweep over the echo's lateness).
    f = (500e6 if model == "if" else AWR.fc_hz) + AWR.slope_hz_per_s * (
        AWR.adc_start_s + (AWR.adc_samples - 1) / (2 * AWR.sample_rate_hz)
        - 2 * 10.0 / 299792458.0)
    assert delayed_frequency_hz(rig, AWR, 10.0) == pytest.approx(f, rel=1e-12)
    np.testing.assert_allclose(wrapped(phases + 360.0 * f * delays), 0.0, atol=1e-6)
    assert len(np.unique(np.round(phases))) >= 5  # the sweep turns the phase around
    errors = ChannelErrors.random(4, np.random.default_rng(3), phase_deg=180.0, gain_db=1.0)
    fidelity = "adc" if (model, step) == ("if", 1e-10) else "analytic"
    result = calibrate(rig, AWR, simulated_measure(AWR, rig, errors, fidelity=fidelity))
    recovered_within(result, errors, 0.5, 0.05)


@pytest.mark.parametrize("name", ["awr1843boost", "cascade-12x16"])
def test_range_response_of_the_radar_is_its_hann_window_s_dft(name):
    # What calibration and the analytic radar weigh an echo with, off the range cell: the DFT
    # of the windowed samples of a tone, from first principles.
    radar = RadarProfile.preset(name)
    n = radar.adc_samples
    w = np.hanning(n + 2)[1:-1]
    for offset in (0.0, 0.013, 0.25, 0.5, 0.77, 1.0, 1.4):
        x = np.fft.fft(np.exp(2j * np.pi * (3.0 + offset) * np.arange(n) / n) * w)
        want = abs(x[3]) / w.sum()  # at bin 3, relative to a tone on the bin
        got = radar.range_response(np.array([offset]))[0]
        assert abs(got) == pytest.approx(want, rel=1e-9, abs=1e-12)
        assert got > 0.0  # the main lobe: no sign flip between channels
    # Along slow time likewise, over its chirp loops (the analytic radar's straddle loss).
    n = radar.chirp_loops
    w = np.hanning(n + 2)[1:-1]
    for offset in (0.0, 0.25, 0.5):
        x = np.fft.fft(np.exp(2j * np.pi * (3.0 + offset) * np.arange(n) / n) * w)
        assert radar.doppler_response(np.array([offset]))[0] == pytest.approx(
            abs(x[3]) / w.sum(), rel=1e-9)


def test_noisy_adc_radar():
    errors = ChannelErrors.random(4, np.random.default_rng(5), phase_deg=180.0, gain_db=1.0)
    measure = simulated_measure(AWR, KIT, errors, fidelity="adc", noise=True,
                                rng=np.random.default_rng(1))
    result = calibrate(KIT, AWR, measure)
    recovered_within(result, errors, 1.0, 0.1)


def test_a_moved_front_end_shows_in_the_residuals():
    base = ChannelErrors.random(4, np.random.default_rng(5), phase_deg=180.0, gain_db=1.0)
    moved = ChannelErrors(base.gain_db, base.phase_deg, base.delay_s,
                          az_deg=np.array([0.0, 0.0, 0.6, 0.0]),
                          el_deg=np.array([0.0, 0.0, 0.6, 0.0]), distance_m=base.distance_m)
    result = calibrate(KIT, PAPER, simulated_measure(PAPER, KIT, moved))
    assert result.suspects
    assert all("2" in s.split(":")[0] or "3" in s.split(":")[0] for s in result.suspects)


def test_calibrated_rig_file_round_trip(tmp_path):
    errors = ChannelErrors.random(4, np.random.default_rng(2), phase_deg=180.0, gain_db=1.0)
    result = calibrate(KIT, PAPER, simulated_measure(PAPER, KIT, errors))
    path = tmp_path / "lab.rig.yaml"
    result.apply(KIT).write(path)
    back = rs.Rig.from_file(path)
    np.testing.assert_allclose(back.cal_phase_deg, wrapped(-result.phase_deg), atol=1e-3)
    np.testing.assert_allclose(back.cal_gain_db, result.gain_db, atol=1e-3)
    np.testing.assert_array_equal(back.az_deg, KIT.az_deg)
    # The schedule uses the file's offsets: the radar with those errors sees the set angles.
    after = grid_errors(back, PAPER, simulated_measure(PAPER, back, errors))
    assert np.nanmax(np.abs(after)) <= 0.02


def test_cli_calibrate_over_can(tmp_path, capsys):
    out = tmp_path / "cal.rig.yaml"
    code = cli.main(["calibrate", "kit-table1", "--inject-phase-deg", "180", "--inject-gain-db",
                     "1", "--seed", "4", "--write", str(out)])
    assert code == 0
    text = capsys.readouterr().out
    assert "injected phase" in text and "angle error after" in text
    after = float(text.split("angle error after:")[1].split("max")[1].split("deg")[0])
    assert after <= 0.02
    assert rs.Rig.from_file(out).cal_phase_deg.any()


def test_calibration_patterns_play_on_the_rts_delay_grid_with_the_rig_s_delay_model():
    import dataclasses

    from rts_scenario.calibration import pattern_schedule
    from rts_scenario.rig import RtsDelayModel

    step = 1e-10
    rig = dataclasses.replace(KIT, limits=dataclasses.replace(KIT.limits, delay_step_s=step),
                              distance_m=np.array([1.0, 1.013, 0.991, 1.004]))
    rows = [[(q, 1.0, 0.0)] for q in range(4)]
    phases = {}
    for model in ("if", "rf"):
        on = dataclasses.replace(rig, rts=RtsDelayModel(model))
        sch = pattern_schedule(on, PAPER, rows, 10.0, 40.0)
        delay = sch.delay_s[:, 0, 0]
        np.testing.assert_allclose(delay / step, np.round(delay / step), atol=1e-6)
        phases[model] = sch.phase_rad[:, 0, 0]
    # The rounding is given back at the frequency the RTS delays: an IF (500 MHz) or the carrier.
    exact = 2 * 10.0 / 299792458.0 - 2 * rig.distance_m / 299792458.0
    quantum = delay - exact
    turn = np.angle(np.exp(1j * (phases["rf"] - phases["if"])))
    want = np.angle(np.exp(2j * np.pi * (PAPER.fc_hz - 500e6) * quantum))
    np.testing.assert_allclose(turn, want, atol=1e-6)
    assert np.abs(want).max() > 0.1  # the two models really differ here


@pytest.mark.parametrize("estimator", ["bartlett", "ti"])
def test_cli_calibrate_passes_and_reports_its_verdict_in_the_json(tmp_path, capsys, estimator):
    # For the TI-style radar the grid's reference is the set angle (the schedule predicts the
    # beamformer's peak, 0.1 deg off what `method: estimator` weights make a TI radar see).
    import json

    out, report = tmp_path / "cal.rig.yaml", tmp_path / "cal.json"
    code = cli.main(["calibrate", "kit-table1", "--radar", "awr1843boost", "--estimator",
                     estimator, "--inject-phase-deg", "180", "--inject-gain-db", "1", "--seed",
                     "1", "--json", str(report), "--write", str(out)])
    assert code == 0
    captured = capsys.readouterr()
    assert "calibration passed" in captured.out and "error" not in captured.err
    assert out.exists()
    data = json.loads(report.read_text())
    assert data["passed"] is True and data["reasons"] == []
    assert set(data["after"]) == {"max_error_deg", "rms_error_deg", "max_excess_error_deg",
                                  "points", "missed", "not_played"}
    assert data["after"]["max_excess_error_deg"] <= 0.01  # classic CAN: 0.005 deg steps
    assert data["after"]["missed"] == data["after"]["not_played"] == 0


def test_cli_calibrate_fails_when_the_check_grid_cannot_be_played(tmp_path, capsys):
    # The cascade radar resolves the kit-table1 FEs (9 deg apart) as separate targets: no grid
    # point can be synthesized, so nothing verifies the calibration.
    import json

    out, report = tmp_path / "casc.rig.yaml", tmp_path / "casc.json"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy RuntimeWarning on all-NaN statistics
        code = cli.main(["calibrate", "kit-table1", "--radar", "cascade-12x16", "--json",
                         str(report), "--write", str(out)])
    assert code == 1
    captured = capsys.readouterr()
    assert "nan" not in captured.out
    assert "angle error after:  none measured, 30 missed (30 not played)" in captured.out
    assert ("error: calibration failed: 30 of 30 check-grid points could not be played on this "
            "rig for this radar (not synthesizable, split)") in captured.err
    assert f"--write {out}: not written" in captured.err
    assert "calibration passed" not in captured.out
    assert not out.exists()
    data = json.loads(report.read_text())
    assert data["passed"] is False and len(data["reasons"]) == 1
    assert data["after"] == {"max_error_deg": None, "rms_error_deg": None,
                             "max_excess_error_deg": None, "points": 30, "missed": 30,
                             "not_played": 30}


def test_cli_calibrate_fails_on_suspect_pairs_and_a_grid_beyond_tolerance(tmp_path, capsys,
                                                                          monkeypatch):
    # FEs mounted up to 2 deg off where the rig file has them (the channel errors drawn with
    # moved FEs): no pair's sweep fits the model, the pairs contradict each other and the
    # "calibrated" rig misses the grid by far more than the tolerance.
    import json

    draw = ChannelErrors.random
    monkeypatch.setattr(ChannelErrors, "random", lambda n, rng, **kw: draw(
        n, rng, **kw, position_deg=2.0))
    out, report = tmp_path / "bad.rig.yaml", tmp_path / "bad.json"
    code = cli.main(["calibrate", "kit-table1", "--radar", "awr1843boost", "--inject-phase-deg",
                     "180", "--inject-gain-db", "1", "--seed", "3", "--json", str(report),
                     "--write", str(out)])
    assert code == 1
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("error: calibration failed: 6 of 6 FE pairs are suspect")
    # The radar and estimator the pairs were fitted with are named: on a bench, calibrate's
    # default radar (paper) where another measures fails so.
    assert err[0].endswith("a bad channel, a moved FE or the wrong estimator (--estimator "
                           "bartlett) or radar profile (--radar awr1843boost): name the radar "
                           "under test"), err[0]
    assert err[1].startswith("error: calibration failed: after calibration the radar sees the "
                             "check grid up to ")
    assert "(tolerance 0.1 deg); max angle error" in err[1]
    assert err[2].startswith(f"error: --write {out}: not written")
    assert not out.exists()
    data = json.loads(report.read_text())
    assert data["passed"] is False and len(data["reasons"]) == 2 and len(data["suspects"]) == 6
    assert data["after"]["max_excess_error_deg"] > 0.5


def test_a_calibration_that_leaves_a_channel_off_fails_the_tolerance(tmp_path):
    # The verdict from a pair sweep that did its job, against a grid after calibration on a
    # bench whose channel 2 is left 0.3 dB off: the grid shows it, the calibration fails.
    from rts_scenario.calibration import MAX_EXCESS_ERROR_DEG, check_grid, failures

    errors = ChannelErrors.random(4, np.random.default_rng(0), phase_deg=180.0, gain_db=1.0)
    result = calibrate(KIT, AWR, simulated_measure(AWR, KIT, errors))
    calibrated = result.apply(KIT)
    before = check_grid(KIT, AWR, simulated_measure(AWR, KIT, errors))
    after = check_grid(calibrated, AWR, simulated_measure(AWR, calibrated, errors))
    assert failures(result, before, after) == []
    off = ChannelErrors(errors.gain_db + np.array([0.0, 0.0, 0.3, 0.0]), errors.phase_deg,
                        errors.delay_s, errors.az_deg, errors.el_deg, errors.distance_m)
    left = check_grid(calibrated, AWR, simulated_measure(AWR, calibrated, off))
    reasons = failures(result, before, left)
    assert len(reasons) == 1 and f"(tolerance {MAX_EXCESS_ERROR_DEG:g} deg)" in reasons[0]
    assert failures(result, before, left, max_excess_deg=0.2) == []


def test_the_check_grid_subtracts_the_error_the_attenuator_steps_predict():
    # lab-2x3 has a 0.5 dB attenuator: a perfect calibration still leaves ~0.05 deg, which the
    # schedule predicts; what the calibration must answer for is the rest.
    from rts_scenario.calibration import check_grid

    lab = rs.Rig.from_file(Path(__file__).parents[1] / "scenarios/rigs/lab-2x3.rig.yaml")
    errors = ChannelErrors.random(6, np.random.default_rng(0), phase_deg=180.0, gain_db=1.0)
    calibrated = calibrate(lab, AWR, simulated_measure(AWR, lab, errors)).apply(lab)
    stats = check_grid(calibrated, AWR, simulated_measure(AWR, calibrated, errors)).summary()
    assert stats["max_error_deg"] > 0.02
    assert stats["max_excess_error_deg"] < 0.002


def test_cli_calibrate_tolerance_must_be_positive(capsys):
    from rts_scenario.calibration import MAX_EXCESS_ERROR_DEG
    from rts_scenario.cli.calibrate import MAX_EXCESS_ERROR_DEG as CLI_DEFAULT

    assert CLI_DEFAULT == MAX_EXCESS_ERROR_DEG
    assert cli.main(["calibrate", "kit-table1", "--max-error-deg", "0"]) == 2
    assert "--max-error-deg: must be a finite number > 0, got 0.0" in capsys.readouterr().err
    # NaN named the bound 0 allows (">= 0"), which 0 itself then failed.
    assert cli.main(["calibrate", "kit-table1", "--max-error-deg", "nan"]) == 2
    assert "--max-error-deg: must be a finite number > 0, got nan" in capsys.readouterr().err


OBJECT_LIST = Path(__file__).resolve().parents[1] / "scenarios" / "can" / "object_list.mapping.yaml"


@pytest.mark.parametrize("mapping", [None, OBJECT_LIST])
def test_cli_calibrate_through_a_third_party_mapping_recovers_the_injected_errors(tmp_path,
                                                                                   mapping):
    # The simulated radar speaks the mapping's DBC (the object list: angles at 0.05 deg steps)
    # and the calibration decodes it: the same offsets as through rts-scenario's own messages,
    # within the tolerance the injected errors are recovered to on the awr1843boost.
    import json

    report = tmp_path / "cal.json"
    code = cli.main(["calibrate", "kit-table1", "--radar", "awr1843boost", "--inject-phase-deg",
                     "180", "--inject-gain-db", "1", "--seed", "4", "--json", str(report),
                     *(["--mapping", str(mapping)] if mapping else [])])
    assert code == 0
    data = json.loads(report.read_text())
    assert data["mapping"] == (str(mapping.resolve()) if mapping else None)
    assert data["can_fd"] is False
    assert data["passed"] and not data["suspects"]
    errors = ChannelErrors.random(4, np.random.default_rng(4), phase_deg=180.0, gain_db=1.0)
    phase, gain = relative(errors)
    recovered_phase = [c["recovered_phase_deg"] for c in data["channels"]]
    recovered_gain = [c["recovered_gain_db"] for c in data["channels"]]
    assert np.abs(wrapped(np.array(recovered_phase) - phase)).max() <= 0.5
    assert np.abs(np.array(recovered_gain) - gain).max() <= 0.05
    assert data["after"]["max_excess_error_deg"] <= 0.05


def test_cli_calibrate_of_a_silent_radar_is_a_failed_measurement(tmp_path, capsys, monkeypatch):
    # No cycle comes back (the radar reports on another bus): a measurement that failed (exit
    # 1, as a survey that saw nothing), not bad input; one line, nothing written.
    monkeypatch.setattr("rts_scenario.pipeline.DetectionPublisher.publish_many",
                        lambda self, cycles, times: None)
    out_json, rig_out = tmp_path / "cal.json", tmp_path / "cal.rig.yaml"
    code = cli.main(["calibrate", "kit-table1", "--json", str(out_json), "--write",
                     str(rig_out)])
    assert code == 1
    err = capsys.readouterr().err
    assert err == ("error: calibrate: no detection with rcs_dbsm of FE 0, 1, 2, 3 played alone "
                   "(cycles 0, 1, 2, 3): its level at the radar sets the weights of its pairs; "
                   "check that the radar sees the rig; nothing written\n")
    assert not out_json.exists() and not rig_out.exists()


def _spied(measure):
    """``measure`` that keeps every schedule it plays."""
    played = []

    def spy(schedule):
        played.append(schedule)
        return measure(schedule)

    return spy, played


def test_each_pair_plays_its_swept_channel_at_half_the_reference_s_level_at_the_radar():
    # Channels up to 6 dB off: each FE is measured alone first (one frame each), then each
    # pair is played so that the swept channel's echo arrives at half the reference's
    # amplitude (-6.02 dB), its weight making up for the channels' gains.
    errors = ChannelErrors.random(4, np.random.default_rng(3), phase_deg=180.0, gain_db=6.0)
    spy, played = _spied(simulated_measure(AWR, KIT, errors))
    result = calibrate(KIT, AWR, spy)
    singles = played[0]
    assert singles.active[:, 0].sum(axis=1).tolist() == [1, 1, 1, 1]
    assert singles.fe[:, 0, 0].tolist() == [0, 1, 2, 3]
    assert len(played) == 1 + len(pairs_of(KIT))
    for schedule, (a, b), pair in zip(played[1:], pairs_of(KIT), result.pairs, strict=True):
        assert schedule.fe[0, 0, :2].tolist() == [a, b]
        att = schedule.attenuation_db[:, 0, :2]
        # b's echo over a's at the radar: the attenuation played less the channels' gains.
        arrives_db = -(att[:, 1] - att[:, 0]) + errors.gain_db[b] - errors.gain_db[a]
        # The single levels are the radar's RCS (unrounded in process: no bus): kit-table1's
        # FEs, all 1 m away, differ by 4e-5 dB in it beyond their injected gains.
        np.testing.assert_allclose(arrives_db, 20.0 * np.log10(0.5), atol=0.001)
        assert min(att[0]) == pytest.approx(40.0)  # the stronger at the pattern's level
        np.testing.assert_allclose(pair.weight_db, -(att[0, 1] - att[0, 0]), atol=1e-9)
    recovered_within(result, errors, 0.5, 0.05)


def test_a_swept_channel_s_weight_stops_at_the_attenuator_s_range_and_is_fitted_as_played():
    # FE 1 is 4 dB stronger than FE 0: pair 0-1 wants FE 1 10 dB below FE 0's 40 dB, beyond
    # the attenuator's 48 dB. It plays at 48 dB and FE 0 2 dB stronger than at weight 1
    # (arriving 6 dB below FE 0, within the rig's limits), and the fit takes the weights
    # played: the offsets are recovered.
    import dataclasses

    rig = dataclasses.replace(KIT, limits=dataclasses.replace(KIT.limits,
                                                              attenuation_max_db=48.0))
    errors = ChannelErrors(gain_db=np.array([0.0, 4.0, 0.0, -4.0]),
                           phase_deg=np.array([0.0, 120.0, -70.0, 160.0]),
                           delay_s=np.zeros(4), az_deg=np.zeros(4), el_deg=np.zeros(4),
                           distance_m=np.zeros(4))
    spy, played = _spied(simulated_measure(AWR, rig, errors))
    result = calibrate(rig, AWR, spy)
    for schedule in played:
        assert np.nanmax(schedule.attenuation_db) <= 48.0
    first = played[1]
    assert first.fe[0, 0, :2].tolist() == [0, 1]
    want_db = 20.0 * np.log10(0.5)
    # Within the FEs' 4e-5 dB level difference beyond the injected gains (1 m away each).
    np.testing.assert_allclose(first.attenuation_db[:, 0, :2],
                               [[48.0 - 4.0 + want_db, 48.0]] * 24, atol=0.001)
    assert result.pairs[0].weight_db == pytest.approx(want_db - 4.0, abs=0.001)
    recovered_within(result, errors, 0.5, 0.05)
    assert not result.suspects


def _blank_fe_alone(measure, fe, complete):
    """``measure`` whose cycle of ``fe`` played alone has no detection (or did not come)."""
    def blanked(schedule):
        cycles = measure(schedule)
        alone = schedule.active[:, 0].sum(axis=1) == 1
        for i in np.flatnonzero(alone & (schedule.fe[:, 0, 0] == fe)):
            cycles[i] = Detections.empty(cycles[i].cycle, cycles[i].t_s, complete=complete)
        return cycles

    return blanked


def test_a_channel_the_radar_does_not_see_alone_fails_naming_its_fe():
    # FE 2's level cannot be measured: the pairs' weights cannot be set from it, and the
    # calibration stops there rather than play its pairs at a guessed level.
    from rts_scenario.errors import MeasurementError

    spy, played = _spied(_blank_fe_alone(simulated_measure(AWR, KIT, ChannelErrors.none(4)),
                                         2, complete=True))
    with pytest.raises(MeasurementError) as info:
        calibrate(KIT, AWR, spy)
    message = str(info.value)
    assert "FE 2 played alone" in message and "sees FE 2" in message, message
    assert "FE 0" not in message and "FE 1" not in message, message
    assert len(played) == 1  # no pair played


def test_a_channel_alone_whose_cycle_did_not_come_back_fails_naming_its_fe():
    from rts_scenario.errors import MeasurementError

    measure = _blank_fe_alone(simulated_measure(AWR, KIT, ChannelErrors.none(4)), 3,
                              complete=False)
    with pytest.raises(MeasurementError) as info:
        calibrate(KIT, AWR, measure)
    message = str(info.value)
    assert "FE 3 played alone" in message and "did not come back" in message, message


@pytest.mark.parametrize("ratio", [0.0, 1.0, 1.5, float("nan")])
def test_a_weight_ratio_outside_0_to_1_is_refused(ratio):
    # At 1 the pair's echoes arrive equally strong: the sweep passes through cancellation.
    from rts_scenario.errors import RtsError

    with pytest.raises(RtsError, match=r"weight_ratio must be within 0 and 1 \(exclusive\)"):
        calibrate(KIT, PAPER, simulated_measure(PAPER, KIT, ChannelErrors.none(4)),
                  weight_ratio=ratio)


def _arrival_db(schedule, errors, a, b):
    """FE b's echo over FE a's at the radar (dB) in each frame of a pair's pattern.

    kit-table1's FEs all sit 1 m away: their echoes differ by the attenuators' settings and
    the injected channel gains alone (4e-5 dB apart beyond them).
    """
    att = schedule.attenuation_db[:, 0, :2]
    return -(att[:, 1] - att[:, 0]) + errors.gain_db[b] - errors.gain_db[a]


def test_a_swept_weight_beyond_the_attenuator_s_range_raises_the_reference_instead():
    # FE 1 is 6 dB stronger than the others: pair 0-1 wants FE 1 12 dB below FE 0's 40 dB,
    # beyond the attenuator's 46 dB. Stopping FE 1 at 46 dB would play both echoes equally
    # strong at the radar, the cancellation the single levels are measured to avoid; FE 0 is
    # played 6 dB stronger instead (about 34 dB: the attenuator goes down to 0 dB).
    import dataclasses

    rig = dataclasses.replace(KIT, limits=dataclasses.replace(KIT.limits,
                                                              attenuation_max_db=46.0))
    errors = ChannelErrors(gain_db=np.array([0.0, 6.0, 0.0, 0.0]),
                           phase_deg=np.array([0.0, 120.0, -70.0, 160.0]),
                           delay_s=np.zeros(4), az_deg=np.zeros(4), el_deg=np.zeros(4),
                           distance_m=np.zeros(4))
    spy, played = _spied(simulated_measure(AWR, rig, errors))
    result = calibrate(rig, AWR, spy)
    for schedule, (a, b) in zip(played[1:], pairs_of(rig), strict=True):
        assert np.nanmax(schedule.attenuation_db) <= 46.0
        np.testing.assert_allclose(_arrival_db(schedule, errors, a, b), 20.0 * np.log10(0.5),
                                   atol=0.001, err_msg=f"pair {a}-{b}")
    np.testing.assert_allclose(played[1].attenuation_db[0, 0, :2],
                               [46.0 - 6.0 + 20.0 * np.log10(0.5), 46.0], atol=0.001)
    recovered_within(result, errors, 0.5, 0.05)


def test_a_coarse_attenuator_never_rounds_a_pair_into_equal_echoes():
    # 12 dB steps (4, 16, 28, 40, 52 dB): FE 1 is 0.5 dB weaker than FE 0, so pair 0-1 wants
    # FE 1 at 45.5 dB. The nearest step, 40 dB, plays it 0.5 dB below FE 0 (close to
    # cancellation); 52 dB plays it 12.5 dB below, far from it.
    import dataclasses

    rig = dataclasses.replace(KIT, limits=dataclasses.replace(
        KIT.limits, attenuation_min_db=4.0, attenuation_step_db=12.0))
    errors = ChannelErrors(gain_db=np.array([0.0, -0.5, 0.0, 0.0]),
                           phase_deg=np.array([0.0, 120.0, -70.0, 160.0]),
                           delay_s=np.zeros(4), az_deg=np.zeros(4), el_deg=np.zeros(4),
                           distance_m=np.zeros(4))
    spy, played = _spied(simulated_measure(AWR, rig, errors))
    result = calibrate(rig, AWR, spy)
    for schedule, (a, b), pair in zip(played[1:], pairs_of(rig), result.pairs, strict=True):
        arrival = _arrival_db(schedule, errors, a, b)
        assert np.all(np.abs(arrival) >= 3.0), (a, b, arrival[0])
        np.testing.assert_allclose(pair.weight_db, -np.diff(schedule.attenuation_db[0, 0, :2]),
                                   atol=1e-9)
    recovered_within(result, errors, 0.5, 0.05)


def test_a_pair_the_attenuator_cannot_play_apart_is_refused_naming_it():
    # A 2 dB attenuator range cannot put FE 1's echo (as strong as FE 0's) 6 dB below it:
    # the sweep would pass near cancellation. The calibration stops before playing the pair.
    import dataclasses

    from rts_scenario.errors import RtsError

    rig = dataclasses.replace(KIT, limits=dataclasses.replace(
        KIT.limits, attenuation_min_db=39.0, attenuation_max_db=41.0))
    spy, played = _spied(simulated_measure(AWR, rig, ChannelErrors.none(4)))
    with pytest.raises(RtsError) as info:
        calibrate(rig, AWR, spy)
    message = str(info.value)
    assert "FE pair 0-1" in message and "limits.attenuation_min_db = 39" in message, message
    assert "limits.attenuation_max_db = 41" in message, message
    assert len(played) == 1  # the FEs alone only


# The awr1843boost's range bin (c0 fs / (2 S N): 20 MHz, 40 MHz/us, 256 samples) and velocity
# bin (lambda / (2 N_tx L T_slot): 3 TX, 64 loops, 30 us slots at 77.5 GHz), two of each: the
# gate about the pattern's echo.
AWR_GATE = "+-0.59 m, +-0.67 m/s"
# kit-table1 with FE 3 12 dB weaker than FE 0 (FEs 1 and 2 within a dB of it).
WEAK_FE_3 = ChannelErrors(gain_db=np.array([0.0, 0.6, -0.4, -12.0]),
                          phase_deg=np.array([0.0, 120.0, -70.0, 160.0]),
                          delay_s=np.zeros(4), az_deg=np.zeros(4), el_deg=np.zeros(4),
                          distance_m=np.zeros(4))


@pytest.mark.parametrize("where", [(4.0, -10.0), (10.0, 6.0)], ids=["wall", "same-range"])
def test_a_room_reflector_stronger_than_a_weak_fe_is_not_taken_for_its_echo(where):
    # A static reflector (-10 dBsm at 4 m, or 6 dBsm at the pattern's 10 m but standing still)
    # the radar reports stronger than FE 3 alone (12 dB weak: about -2 dBsm at 10 m) and than
    # the pairs' sums at their dips, weaker than FEs 0 to 2 alone (about 10 dBsm at 10 m). Each
    # measurement reads the strongest detection where the pattern's echo shows (10 m,
    # approaching at 1 m/s): the calibration is the one without the room.
    from room import with_reflector

    range_m, rcs_dbsm = where
    clean = calibrate(KIT, AWR, simulated_measure(AWR, KIT, WEAK_FE_3))
    room = calibrate(KIT, AWR, with_reflector(simulated_measure(AWR, KIT, WEAK_FE_3), range_m,
                                              0.0, rcs_dbsm, az_deg=1.0, el_deg=2.0))
    recovered_within(room, WEAK_FE_3, 0.5, 0.05)
    assert not room.suspects
    # FE 3's level alone is FE 0's less its 12 dB, not the reflector's RCS (all FEs 1 m away).
    assert room.single_rcs_dbsm[3] == pytest.approx(room.single_rcs_dbsm[0] - 12.0, abs=0.01)
    np.testing.assert_array_equal(room.phase_deg, clean.phase_deg)
    np.testing.assert_array_equal(room.gain_db, clean.gain_db)


def test_the_check_grid_is_read_where_its_target_shows_not_at_a_stronger_reflector():
    # A static reflector at 4 m the radar reports stronger than every grid point's target
    # (10 dBsm at 10 m): each point is read where its echo shows (10 m, approaching at 1 m/s).
    from room import with_reflector

    clean = check_grid(KIT, AWR, simulated_measure(AWR, KIT, WEAK_FE_3))
    room = check_grid(KIT, AWR, with_reflector(simulated_measure(AWR, KIT, WEAK_FE_3), 4.0, 0.0,
                                               10.0, az_deg=1.0, el_deg=2.0))
    assert np.isfinite(room.error_deg).all()
    np.testing.assert_array_equal(room.error_deg, clean.error_deg)


def test_a_reflector_where_an_fe_alone_is_not_seen_fails_naming_the_fe_gate_and_reflector():
    # The radar does not see FE 2 alone; a reflector is there all the same. Its RCS is not FE
    # 2's level: the calibration stops before any pair is played, naming the FE, where its
    # echo was looked for and the detection outside that.
    from room import with_reflector

    from rts_scenario.errors import MeasurementError

    spy, played = _spied(with_reflector(
        _blank_fe_alone(simulated_measure(AWR, KIT, WEAK_FE_3), 2, complete=True),
        4.0, 0.0, -10.0))
    with pytest.raises(MeasurementError) as info:
        calibrate(KIT, AWR, spy)
    assert str(info.value) == (
        f"FE 2 played alone not seen at 10.00 m / -1.00 m/s in cycle 2 (gate {AWR_GATE}); "
        f"strongest detection at 4.00 m, 0.00 m/s, -10.0 dBsm: a reflection in the room? (at "
        f"every FE about the same offset: the rig's limits.latency_s or its FEs' "
        f"calibration.delay_s)")
    assert len(played) == 1  # no pair played


def test_a_reflector_where_a_pair_is_not_seen_fails_naming_the_pair_gate_and_reflector():
    from room import with_reflector

    from rts_scenario.errors import MeasurementError

    def blank_pair_frame(schedule):
        cycles = simulated_measure(AWR, KIT, WEAK_FE_3)(schedule)
        if schedule.fe[0, 0, :2].tolist() == [0, 2]:
            cycles[5] = Detections.empty(cycles[5].cycle, cycles[5].t_s)
        return cycles

    with pytest.raises(MeasurementError) as info:
        calibrate(KIT, AWR, with_reflector(blank_pair_frame, 4.0, 0.0, -10.0))
    message = str(info.value)
    # Pair 0-2 plays the pattern's frames 24 to 47 (the simulated radar numbers its cycles by
    # them). Its swept echo lies up to half a turn of the RTS's IF delay (500 MHz or more: 1 ns,
    # 0.15 m) from 10 m: the gate is centred between the two echoes' ranges and widened by
    # half their spread.
    assert re.fullmatch(
        r"FE pair 0-2 not seen at (9\.9\d|10\.0\d) m / -1\.00 m/s in cycle 29 \(gate "
        r"\+-0\.(59|6\d) m, "
        r"\+-0\.67 m/s\); strongest detection at 4\.00 m, 0\.00 m/s, -10\.0 dBsm: a "
        r"reflection in the room\? \(at every FE about the same offset: the rig's "
        r"limits\.latency_s or its FEs' calibration\.delay_s\)", message), message


def test_cli_calibrate_in_a_room_where_an_fe_alone_is_not_seen_fails_naming_it(
        tmp_path, capsys, monkeypatch):
    # Through the CAN bus (classic: RCS in 0.5 dB steps) and the command's error path: a
    # failed measurement, exit 1, one line, nothing written.
    from room import in_room

    from rts_scenario.radar.simulate import SimulatedRadar

    process = SimulatedRadar.process

    def fe_3_unseen_in_room(self, schedule):
        cycles = process(self, schedule)
        alone = schedule.active[:, 0].sum(axis=1) == 1
        for i in np.flatnonzero(alone & (schedule.fe[:, 0, 0] == 3)):
            cycles[i] = Detections.empty(cycles[i].cycle, cycles[i].t_s)
        return in_room(cycles, 4.0, 0.0, -10.0)

    monkeypatch.setattr(SimulatedRadar, "process", fe_3_unseen_in_room)
    out_json, rig_out = tmp_path / "cal.json", tmp_path / "cal.rig.yaml"
    code = cli.main(["calibrate", "kit-table1", "--radar", "awr1843boost", "--json",
                     str(out_json), "--write", str(rig_out)])
    assert code == 1
    assert capsys.readouterr().err == (
        f"error: calibrate: FE 3 played alone not seen at 10.00 m / -1.00 m/s in cycle 3 "
        f"(gate {AWR_GATE}); strongest detection at 4.00 m, 0.00 m/s, -10.0 dBsm: a "
        f"reflection in the room? (at every FE about the same offset: the rig's "
        f"limits.latency_s or its FEs' calibration.delay_s); nothing written\n")
    assert not out_json.exists() and not rig_out.exists()


def _threshold(measure, rcs_dbsm):
    """``measure`` of a radar that reports no detection weaker than ``rcs_dbsm`` at 10 m.

    Its detection threshold (a fixed SNR) is reached by that RCS at the patterns' range.
    """
    def thresholded(schedule):
        out = []
        for d in measure(schedule):
            keep = d.rcs_dbsm >= rcs_dbsm
            out.append(dataclasses.replace(d, **{q: getattr(d, q)[keep] for q in d.present}))
        return out

    return thresholded


def test_a_pair_whose_sum_dips_below_the_radar_s_threshold_names_the_levels_alone_and_played():
    # Every FE alone comes back at about 10 dBsm, 4 dB above the radar's threshold; a pair
    # plays the swept echo at half the other's amplitude, so their sum dips to about 4 dBsm
    # where the sweep turns them against each other: the radar loses those cycles. The
    # message gives the levels alone and as the pair played them.
    from rts_scenario.errors import MeasurementError

    with pytest.raises(MeasurementError) as info:
        calibrate(KIT, AWR, _threshold(simulated_measure(AWR, KIT, ChannelErrors.none(4)), 6.0))
    message = str(info.value)
    # FE 0 at weight 1 (40 dB: 10 dBsm at 10 m, the rig's reference), FE 2 6.02 dB below it:
    # their sum falls towards 6.02 dB below FE 0's where they meet in antiphase (the radar's
    # array tells pair 0-1's directions apart better, in azimuth: its dip is shallower).
    # Pair 0-2 plays frames 24 to 47 (the simulated radar numbers its cycles by them).
    assert re.fullmatch(
        r"no detection for FE pair 0-2 in cycle 2\d: FE 0 seen alone at (9\.99|10\.00) dBsm "
        r"and played in the pair at (9\.99|10\.00) dBsm, FE 2 seen alone at (9\.99|10\.00) "
        r"dBsm and played at 3\.9\d dBsm: as the sweep turns their echoes against each other "
        r"their sum falls towards 3\.9\d dBsm; below the radar's detection threshold\?",
        message), message


def test_a_channel_whose_delay_the_rig_calibrates_is_read_where_its_echo_lands():
    # FE 2's channel is 5 ns longer than the others (a metre of cable), and the rig file says
    # so (calibration.delay_s): the schedule plays its delay 5 ns shorter and its echo lands at
    # the pattern's 10 m like the others'. The gate must look there, not 0.75 m farther (the
    # delay as scheduled), where it saw nothing of FE 2 and stopped: "a reflection in the room?"
    # The gains and phases found are the channel's errors, none but the delay.
    delay = np.array([0.0, 0.0, 5e-9, 0.0])
    rig = dataclasses.replace(KIT, cal_delay_s=delay)
    errors = dataclasses.replace(ChannelErrors.none(4), delay_s=-delay)
    result = calibrate(rig, AWR, simulated_measure(AWR, rig, errors))
    np.testing.assert_allclose(wrapped(result.phase_deg), 0.0, atol=0.05)
    np.testing.assert_allclose(result.gain_db, 0.0, atol=0.005)


def test_a_stopped_calibration_leaves_no_earlier_report(tmp_path, capsys, monkeypatch):
    # Ctrl-C during the measurement left the earlier --json (a pass, say) to be read as this
    # calibration's; the one the command line names for another option is never written.
    import json

    import rts_scenario.calibration as calibration

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(calibration, "check_grid", stopped)
    report = tmp_path / "cal.json"
    report.write_text(json.dumps({"passed": True}))
    argv = ["calibrate", "kit-table1", "--radar", "awr1843boost", "--json", str(report)]
    assert cli.main(argv) == 1
    assert capsys.readouterr().err.endswith("error: interrupted\n")
    assert json.loads(report.read_text()) == {
        "command": "calibrate", "passed": False, "interrupted": True,
        "error": "interrupted (Ctrl-C or SIGTERM) before the command wrote its report: no "
                 "verdict"}
    mapping = tmp_path / "m.mapping.yaml"
    mapping.write_text("not read: the stop comes first")
    argv = ["calibrate", "kit-table1", "--radar", "awr1843boost", "--json", str(mapping)]
    monkeypatch.setattr("rts_scenario.cli.calibrate.bench_of", stopped)  # before any check
    assert cli.main([*argv, "--mapping", str(mapping)]) == 1
    assert mapping.read_text() == "not read: the stop comes first"


def test_a_stopped_command_whose_report_cannot_be_replaced_says_so(tmp_path, capsys,
                                                                    monkeypatch):
    def stopped(*args, **kwargs):
        raise KeyboardInterrupt

    def broken(*args, **kwargs):
        raise RecursionError("maximum recursion depth exceeded")

    monkeypatch.setattr("rts_scenario.cli.calibrate.bench_of", stopped)
    monkeypatch.setattr("rts_scenario.cli.common.write_json", broken)
    report = tmp_path / "cal.json"
    argv = ["calibrate", "kit-table1", "--radar", "awr1843boost", "--json", str(report)]
    assert cli.main(argv) == 1
    assert capsys.readouterr().err == (f"error: --json {report}: not replaced after the stop: "
                                       f"RecursionError: maximum recursion depth exceeded\n"
                                       f"error: interrupted\n")
