"""The CFAR's view of other targets: a strong target masks a weak one, its sidelobes bound its SNR.

References: the CA-CFAR estimate computed from the windowed DFTs of each target's tone (numpy's
FFT of the window times the tone, every cell), padded and averaged over the training cells as
the CFAR defines them; and the beat-signal cube (`adc`), which the analytic model must agree
with.
"""

import numpy as np
import pytest
from scipy import ndimage
from test_radar import scene_tracks

import rts_scenario as rs
from rts_scenario.radar import RadarProfile
from rts_scenario.radar.simulate import CFAR_GUARD, CFAR_TRAIN, SimulatedRadar
from rts_scenario.schedule import build_schedule

AWR = RadarProfile.preset("awr1843boost")
KIT = rs.Rig.preset("kit-table1")


def tone_power(n, position):
    """|DFT|^2 of hanning(n + 2)[1:-1] times a tone at ``position`` bins, 1 at the tone."""
    window = np.hanning(n + 2)[1:-1]
    spectrum = np.fft.fft(window * np.exp(2j * np.pi * position * np.arange(n) / n))
    return np.abs(spectrum) ** 2 / window.sum() ** 2


def brute_force_estimate(profile, ranges, dopplers, powers):
    """CA-CFAR training mean at each target's peak cell, from the frame's whole spectrum."""
    n, loops = profile.adc_samples, profile.chirp_loops
    # Power over (Doppler index, range bin), Doppler index = centred bin + loops // 2.
    spectrum = sum(p * np.outer(np.roll(tone_power(loops, d), loops // 2), tone_power(n, r))
                   for r, d, p in zip(ranges, dopplers, powers, strict=True))
    half = CFAR_GUARD + CFAR_TRAIN
    padded = np.pad(np.pad(spectrum, ((half, half), (0, 0)), mode="wrap"),
                    ((0, 0), (half, half)), mode="reflect")
    ring = np.ones((2 * half + 1, 2 * half + 1), bool)
    ring[CFAR_TRAIN:-CFAR_TRAIN, CFAR_TRAIN:-CFAR_TRAIN] = False
    out = []
    for r, d in zip(ranges, dopplers, strict=True):
        row = (int(np.round(d)) + loops // 2) % loops
        col = int(np.round(r)) % n
        out.append(padded[row : row + 2 * half + 1, col : col + 2 * half + 1][ring].mean())
    return np.array(out)


TINY = """\
rts_radar: 1
name: tiny
fc_hz: 77.0e+9
bandwidth_hz: 1.0e+9
ramp_time_s: 25.0e-6
idle_time_s: 5.0e-6
adc_samples: 8
sample_rate_hz: 0.625e+6
chirp_loops: 8
tx_order: [0, 1, 2]
frame_period_s: 0.05
noise_level_db: -75.0
array: awr1843boost
"""


@pytest.mark.parametrize(("seed", "decades"), [(0, 6), (1, 6), (2, 6), (3, 6), (4, 12),
                                               (5, 12), (6, 12)])
def test_leakage_is_the_ca_cfar_mean_of_every_targets_window_response(seed, decades):
    # Powers over 60 dB, or 120 dB: a target that strong masks others 40 bins away (beyond
    # the pairs `_near_pairs` finds).
    rng = np.random.default_rng(seed)
    radar = SimulatedRadar(AWR, KIT, fidelity="analytic", noise=False)
    n, loops = AWR.adc_samples, AWR.chirp_loops
    frames, ranges, dopplers, powers = [], [], [], []
    for frame in range(3):
        k = int(rng.integers(1, 12))
        # Clusters (masking), targets at the range ends (the mirrored window) and at the
        # Doppler ends (the wrapped one), powers over 60 dB.
        r = np.mod(rng.choice([rng.uniform(0, n, k), rng.normal(40.0, 6.0, k),
                               rng.choice([0.3, 2.6, n - 0.4, n - 4.2], k)], axis=0), n)
        d = np.mod(rng.choice([rng.uniform(-loops / 2, loops / 2, k),
                               rng.normal(-loops / 2 + 1.0, 3.0, k)], axis=0)
                   + loops / 2, loops) - loops / 2
        frames += [frame] * k
        ranges += list(r)
        dopplers += list(d)
        powers += list(10.0 ** rng.uniform(0.0, decades, k))
    frames, ranges, dopplers, powers = map(np.array, (frames, ranges, dopplers, powers))
    got = radar._leakage(frames, ranges, dopplers, powers)
    want = np.concatenate([
        brute_force_estimate(AWR, ranges[frames == f], dopplers[frames == f],
                             powers[frames == f]) for f in range(3)])
    # What is left out: targets whose far sidelobes stay below a thousandth of a twentieth of
    # the frame's weakest.
    np.testing.assert_allclose(got, want, rtol=2e-3, atol=1e-3 * powers.min())


def test_leakage_on_an_axis_shorter_than_the_cfar_window_mirrors_it_again(tmp_path):
    # 8 range bins: numpy's "reflect" pads the 21-cell window by mirroring twice.
    (tmp_path / "tiny.radar.yaml").write_text(TINY)
    tiny = RadarProfile.from_file(tmp_path / "tiny.radar.yaml")
    radar = SimulatedRadar(tiny, KIT, fidelity="analytic", noise=False)
    ranges = np.array([0.29, 1.99, 4.39, 5.99, 7.52])
    dopplers = np.array([0.1, -2.4, 3.3, -4.0, 1.0])
    frames = np.arange(ranges.size)  # each alone in its frame
    got = radar._leakage(frames, ranges, dopplers, np.ones(ranges.size))
    want = np.concatenate([brute_force_estimate(tiny, ranges[[f]], dopplers[[f]], np.ones(1))
                           for f in frames])
    np.testing.assert_allclose(got, want, rtol=2e-3)


def truck_and_walker(separation_bins, walker_rcs=-15.0):
    """A 30 dBsm truck at 20 m and a walker ``separation_bins`` range bins beyond, same speed."""
    bin_m = SimulatedRadar(AWR, KIT)._range_bin_m
    walker_m = 20.0 + separation_bins * bin_m
    tracks = scene_tracks([0.0, 1.0], [0.0, 1.0], [20.0, walker_m], [-1.0, -1.0], radar=AWR,
                          rcs=[30.0, walker_rcs])
    return build_schedule(tracks, KIT, AWR), walker_m


@pytest.mark.parametrize(("separation_bins", "seen"),
                         [(4.0, False), (12.0, False), (16.5, True), (20.1, True)])
def test_a_strong_target_masks_a_weak_one_in_its_training_cells_in_every_fidelity(
        separation_bins, seen):
    schedule, walker_m = truck_and_walker(separation_bins)
    snr = {}
    for fidelity in ("adc", "analytic", "auto"):
        radar = SimulatedRadar(AWR, KIT, fidelity=fidelity, rng=np.random.default_rng(1))
        det = radar.process(schedule)[0]
        walker = np.abs(det.range_m - walker_m) < 0.5
        truck = np.abs(det.range_m - 20.0) < 0.5
        assert walker.any() == seen, fidelity
        assert truck.sum() == 1, fidelity
        snr[fidelity] = det.snr_db[walker], det.snr_db[truck][0]
    if seen:  # the walker's SNR over the estimate its training cells give, as the cube's
        assert snr["analytic"][0][0] == pytest.approx(snr["adc"][0][0], abs=1.0)
    # The truck's SNR is bounded by its own window sidelobes in its training cells (58 dB
    # here, where the thermal noise alone gives 82 dB), as in the cube.
    assert snr["analytic"][1] == pytest.approx(snr["adc"][1], abs=1.5)
    assert snr["auto"][1] == snr["analytic"][1]
    assert snr["adc"][1] < 65.0


def test_an_os_cfar_estimate_at_the_peaks_is_the_rank_filter_there():
    rng = np.random.default_rng(5)
    radar = SimulatedRadar(AWR, KIT, cfar="os")
    power = rng.exponential(size=(AWR.chirp_loops, AWR.adc_samples))
    power[10, 3] = power[40, 250] = 1e4  # targets by the mirrored range ends
    peaks = power == ndimage.maximum_filter(power, size=3, mode="wrap")
    at_peaks = radar._noise_floor(power, peaks)
    everywhere = radar._noise_floor(power)
    np.testing.assert_array_equal(at_peaks[peaks], everywhere[peaks])
    assert np.isinf(at_peaks[~peaks]).all()


def test_a_crowded_frame_read_by_the_analytic_model_reads_each_target_alone():
    # A third target in the truck's cell crowds the frame: the analytic model cannot tell the
    # two apart, and reads every target of the frame as if alone (the run fails with
    # crowded_in_analytic unless the scene expects it); the cube masks the walker.
    bin_m = SimulatedRadar(AWR, KIT)._range_bin_m
    tracks = scene_tracks([0.0, 1.0, -1.0], [0.0, 1.0, -1.0],
                          [20.0, 20.0 + 4.0 * bin_m, 20.05], [-1.0, -1.0, -1.0], radar=AWR,
                          rcs=[30.0, -15.0, 30.0])
    schedule = build_schedule(tracks, KIT, AWR)
    walker_m = 20.0 + 4.0 * bin_m
    analytic = SimulatedRadar(AWR, KIT, fidelity="analytic", rng=np.random.default_rng(1))
    det = analytic.process(schedule)[0]
    assert analytic.frames_crowded_analytic == 1
    assert (np.abs(det.range_m - walker_m) < 0.5).sum() == 1
    auto = SimulatedRadar(AWR, KIT, fidelity="auto", rng=np.random.default_rng(1))
    det = auto.process(schedule)[0]
    assert auto.frames_adc == 1 and not (np.abs(det.range_m - walker_m) < 0.5).any()


@pytest.mark.parametrize(("separation_bins", "axis", "seen"),
                         [(30.5, "range", False), (27.0, "range", False),
                          (28.0, "doppler", True)])
def test_a_target_120_db_over_the_noise_masks_one_beyond_the_near_pairs(separation_bins, axis,
                                                                        seen):
    # A 40 dBsm target 3 m away (the attenuator at its end: 120 dB over the noise) puts its
    # far sidelobes into the training cells of a -36 dBsm one 27-30 bins away: the cube loses
    # it (or, 28 Doppler bins away, sees it 14 dB weaker over its estimate); the analytic
    # model, summing pairs within 26 bins only, reported it at the noise's level.
    bin_m = SimulatedRadar(AWR, KIT)._range_bin_m
    bin_mps = AWR.wavelength_m / 2.0 / (AWR.chirp_loops * AWR.loop_time_s)
    near_m = 3.0 + 0.3 * bin_m
    if axis == "range":
        ranges, speeds = [near_m, near_m + separation_bins * bin_m], [0.0, 0.0]
    else:
        ranges, speeds = [near_m, near_m], [0.3 * bin_mps, (0.3 + separation_bins) * bin_mps]
    tracks = scene_tracks([0.0, 1.0], [0.0, 1.0], ranges, speeds, radar=AWR,
                          rcs=[40.0, -36.0])
    schedule = build_schedule(tracks, KIT, AWR)
    snr = {}
    for fidelity in ("adc", "analytic", "auto"):
        det = SimulatedRadar(AWR, KIT, fidelity=fidelity,
                             rng=np.random.default_rng(2)).process(schedule)[0]
        weak = ((np.abs(det.range_m - ranges[1]) < 0.5)
                & (np.abs(det.radial_velocity_mps - speeds[1]) < 0.5))
        assert weak.any() == seen, fidelity
        snr[fidelity] = det.snr_db[weak]
    if seen:
        assert snr["analytic"][0] == pytest.approx(snr["adc"][0], abs=1.5)
        assert snr["auto"][0] == snr["analytic"][0]
