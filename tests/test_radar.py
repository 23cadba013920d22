import numpy as np
import pytest

import rts_scenario as rs
from rts_scenario.arrays import direction_cosines
from rts_scenario.evaluation import evaluation_grid
from rts_scenario.kinematics import Tracks
from rts_scenario.outputs import open_output
from rts_scenario.radar import RadarProfile
from rts_scenario.radar.simulate import ChannelErrors, SimulatedRadar
from rts_scenario.schedule import build_schedule

PAPER = RadarProfile.preset("paper")
AWR = RadarProfile.preset("awr1843boost")
KIT = rs.Rig.preset("kit-table1")


def tracks(az, el, *, radar=PAPER, range_m=12.3, v=-2.0, rcs=10.0):
    """One target, one frame per direction."""
    az, el = np.atleast_1d(az).astype(float), np.atleast_1d(el).astype(float)
    f = az.size
    one = np.ones((f, 1), bool)
    full = lambda x: np.broadcast_to(np.asarray(x, float).reshape(-1, 1), (f, 1)).copy()  # noqa
    return Tracks(names=("t",), t_s=np.arange(f) * 0.05, range_m=full(range_m),
                  radial_velocity_mps=full(v),
                  doppler_hz=full(-2 * np.asarray(v) / radar.wavelength_m),
                  rcs_dbsm=full(rcs), az_deg=az[:, None], el_deg=el[:, None],
                  position_m=np.zeros((f, 1, 3)), present=one, in_coverage=one, in_range=one,
                  in_velocity=one)


def scene_tracks(az, el, range_m, v, radar=PAPER, rcs=10.0):
    """K targets in one frame."""
    az, el = np.asarray(az, float)[None], np.asarray(el, float)[None]
    k = az.shape[1]
    full = lambda x: np.broadcast_to(np.asarray(x, float), (1, k)).copy()  # noqa
    ones = np.ones((1, k), bool)
    return Tracks(names=tuple(f"t{i}" for i in range(k)), t_s=np.zeros(1), range_m=full(range_m),
                  radial_velocity_mps=full(v),
                  doppler_hz=full(-2 * np.asarray(v, float) / radar.wavelength_m),
                  rcs_dbsm=full(rcs), az_deg=az, el_deg=el, position_m=np.zeros((1, k, 3)),
                  present=ones, in_coverage=ones, in_range=ones, in_velocity=ones)


def first(dets, field):
    return np.array([getattr(d, field)[0] for d in dets])


@pytest.mark.parametrize("fidelity", ["adc", "analytic"])
@pytest.mark.parametrize("fe", range(4))
def test_single_echo_on_an_fe(fidelity, fe):
    # Plane-wave FE responses: the set angle is then the FE's own direction, played by that FE
    # alone (with the bench's modeled responses that FE alone is seen slightly elsewhere).
    sch = build_schedule(tracks(KIT.az_deg[fe], KIT.el_deg[fe], range_m=20.0, v=3.0), KIT,
                         PAPER, fe_responses="plane-wave")
    assert sch.active[0, 0].sum() == 1  # one channel: a plain point echo from that FE
    det = SimulatedRadar(PAPER, KIT, fidelity=fidelity, noise=False).process(sch)[0]
    assert det.count == 1
    assert det.az_deg[0] == pytest.approx(KIT.az_deg[fe], abs=0.01)
    assert det.el_deg[0] == pytest.approx(KIT.el_deg[fe], abs=0.01)
    assert det.range_m[0] == pytest.approx(20.0, abs=0.02)
    assert det.radial_velocity_mps[0] == pytest.approx(3.0, abs=0.01)
    assert det.rcs_dbsm[0] == pytest.approx(10.0, abs=0.2)


@pytest.mark.parametrize("estimator", ["bartlett", "ti"])
def test_adc_and_analytic_agree(estimator):
    az, el = evaluation_grid()
    sch = build_schedule(tracks(az, el, radar=AWR), KIT, AWR)
    adc = SimulatedRadar(AWR, KIT, fidelity="adc", estimator=estimator, noise=False).process(sch)
    ana = SimulatedRadar(AWR, KIT, fidelity="analytic", estimator=estimator,
                         noise=False).process(sch)
    for name, tol in (("az_deg", 0.01), ("el_deg", 0.01), ("range_m", 0.01),
                      ("radial_velocity_mps", 0.01), ("rcs_dbsm", 0.1)):
        np.testing.assert_allclose(first(adc, name), first(ana, name), atol=tol, err_msg=name)


@pytest.mark.parametrize("fidelity", ["adc", "analytic"])
def test_closed_loop_exact_hits_the_set_angle_and_paper_shows_its_error(fidelity):
    az, el = evaluation_grid()
    errors = {}
    for method in ("exact", "paper"):
        sch = build_schedule(tracks(az, el), KIT, PAPER, method=method)
        dets = SimulatedRadar(PAPER, KIT, fidelity=fidelity, noise=False).process(sch)
        errors[method] = (first(dets, "az_deg") - az, first(dets, "el_deg") - el)
    exact_az, exact_el = errors["exact"]
    assert max(np.abs(exact_az).max(), np.abs(exact_el).max()) <= 0.02
    paper_az, paper_el = errors["paper"]
    # The solver's own figure for the paper method (DESIGN.md 5.2): ~0.23 / 0.33 deg rms.
    assert np.sqrt(np.mean(paper_az**2)) == pytest.approx(0.23, rel=0.1)
    assert np.sqrt(np.mean(paper_el**2)) == pytest.approx(0.33, rel=0.1)


@pytest.mark.parametrize("fidelity, cube, alone", [("analytic", 0, 1), ("auto", 1, 0),
                                                    ("adc", 1, 0)])
def test_targets_sharing_a_cell_read_alone_in_analytic_fidelity_are_counted(fidelity, cube,
                                                                             alone):
    # The analytic model reads each target at its own cell, as if alone: a scene forcing
    # analytic passed a crowded bench that auto and adc failed, without a word. Such frames
    # are counted (the run fails with crowded_in_analytic unless the scene expects it).
    rig = rs.Rig.preset("wide-3x5")
    sch = build_schedule(scene_tracks([-15.0, 15.0], [0.0, 2.0], 15.0, -1.0, radar=AWR), rig,
                         AWR)
    sim = SimulatedRadar(AWR, rig, fidelity=fidelity, noise=False)
    sim.process(sch)
    assert (sim.frames_adc, sim.frames_crowded_analytic) == (cube, alone)
    # Apart (40 m and 15 m): no frame is crowded, none counted.
    far = build_schedule(scene_tracks([-15.0, 15.0], [0.0, 2.0], [15.0, 40.0], -1.0,
                                      radar=AWR), rig, AWR)
    sim = SimulatedRadar(AWR, rig, fidelity=fidelity, noise=False)
    sim.process(far)
    assert sim.frames_crowded_analytic == 0


def test_an_os_cfar_goes_through_the_cube_whatever_the_fidelity():
    # The analytic model detects as a CA-CFAR does: cfar os was ignored outside the cube.
    rig = rs.Rig.preset("wide-3x5")
    sch = build_schedule(scene_tracks([-15.0], [0.0], 15.0, -1.0, radar=AWR), rig, AWR)
    for fidelity in ("analytic", "auto"):
        sim = SimulatedRadar(AWR, rig, fidelity=fidelity, cfar="os", noise=False)
        sim.process(sch)
        assert sim.frames_adc == sch.n_frames and sim.frames_analytic == 0
        ca = SimulatedRadar(AWR, rig, fidelity=fidelity, cfar="ca", noise=False)
        ca.process(sch)
        assert ca.frames_adc == 0


def test_two_targets_in_one_cell():
    rig = rs.Rig.preset("wide-3x5")
    # Same range and velocity, 30 deg apart: one range-Doppler cell, two angle peaks.
    sch = build_schedule(scene_tracks([-15.0, 15.0], [0.0, 2.0], 15.0, -1.0, radar=AWR), rig,
                         AWR)
    sim = SimulatedRadar(AWR, rig, fidelity="auto", noise=False)
    det = sim.process(sch)[0]
    assert sim.frames_adc == 1  # sharing a cell needs the cube
    assert det.count == 2
    order = np.argsort(det.az_deg)
    # Each peak is pulled a little by the other's sidelobes.
    np.testing.assert_allclose(det.az_deg[order], [-15.0, 15.0], atol=0.5)
    np.testing.assert_allclose(det.range_m, 15.0, atol=0.05)
    # 4 deg apart: below the array's resolution, one merged detection between them.
    sch = build_schedule(scene_tracks([-2.0, 2.0], [0.0, 0.0], 15.0, -1.0, radar=AWR), rig, AWR)
    det = SimulatedRadar(AWR, rig, fidelity="adc", noise=False).process(sch)[0]
    assert det.count == 1 and abs(det.az_deg[0]) < 0.5


def test_noise_statistics_follow_the_snr():
    # One echo on FE 3, many frames: estimated SNR close to the true one, angle scatter
    # shrinking like 1 / sqrt(SNR).
    n = 400
    spreads = {}
    # Weak enough that the own sidelobes in the CFAR's training cells do not count (0.3 dB).
    for rcs in (-25.0, -5.0):
        sch = build_schedule(tracks(np.full(n, KIT.az_deg[3]), np.full(n, KIT.el_deg[3]),
                                    range_m=25.0, rcs=rcs), KIT, PAPER,
                             fe_responses="plane-wave")
        assert sch.status[0, 0] == 0 and sch.active[0, 0].tolist() == [False] * 3 + [True]
        sim = SimulatedRadar(PAPER, KIT, fidelity="analytic", rng=np.random.default_rng(3))
        dets = sim.process(sch)
        snr = first(dets, "snr_db")
        az = first(dets, "az_deg")
        # Predicted SNR after both FFTs and over all channels, from the profile's noise level.
        amp = 10 ** (-sch.attenuation_db[0, 0, 3] / 20)
        win_r, win_d = np.hanning(PAPER.adc_samples + 2)[1:-1], np.hanning(
            PAPER.chirp_loops + 2)[1:-1]
        gain = win_r.sum() * win_d.sum()
        noise = 10 ** (PAPER.noise_level_db / 10) * (win_r**2).sum() * (win_d**2).sum()
        expected = 10 * np.log10(amp**2 * gain**2 / noise)
        assert np.median(snr) == pytest.approx(expected, abs=1.0)
        spreads[rcs] = (np.std(az), expected)
    (s_low, e_low), (s_high, e_high) = spreads[-25.0], spreads[-5.0]
    ratio = s_low / s_high
    assert ratio == pytest.approx(10 ** ((e_high - e_low) / 20), rel=0.25)


def test_adc_noise_floor_matches_the_profile():
    sch = build_schedule(tracks([0.0], [0.0], range_m=20.0, rcs=-10.0), KIT, PAPER)
    snrs = []
    for seed in range(20):
        sim = SimulatedRadar(PAPER, KIT, fidelity="adc", rng=np.random.default_rng(seed))
        d = sim.process(sch)[0]
        assert d.count == 1
        snrs.append(d.snr_db[0])
    sim = SimulatedRadar(PAPER, KIT, fidelity="analytic", rng=np.random.default_rng(0))
    ana = np.median([sim.process(sch)[0].snr_db[0] for _ in range(20)])
    # CFAR's noise estimate vs the analytic model: the same SNR within a few dB
    # (CA over chi-square-distributed cells; Hann straddle).
    assert np.median(snrs) == pytest.approx(ana, abs=3.0)


def test_channel_errors_move_the_angle_and_cfar_variants_detect():
    az, el = np.array([0.5]), np.array([1.0])
    sch = build_schedule(tracks(az, el), KIT, PAPER)
    errors = ChannelErrors.random(4, np.random.default_rng(1), phase_deg=60.0, gain_db=1.0)
    clean = SimulatedRadar(PAPER, KIT, fidelity="adc", noise=False).process(sch)[0]
    bent = SimulatedRadar(PAPER, KIT, fidelity="adc", noise=False, errors=errors,
                          cfar="os").process(sch)[0]
    assert abs(clean.az_deg[0] - 0.5) < 0.01
    assert abs(bent.az_deg[0] - 0.5) + abs(bent.el_deg[0] - 1.0) > 0.1


def test_simulated_radar_output_and_bad_options():
    sch = build_schedule(tracks([0.0, 1.0], [0.0, 2.0]), KIT, PAPER)
    got = []
    with open_output("simulated-radar", profile=PAPER, rig=KIT, noise=False,
                     sink=got.extend) as out:
        out.write(sch)
    assert [d.cycle for d in got] == [0, 1] and all(d.count == 1 for d in got)
    with pytest.raises(rs.RtsError,
                       match="unknown fidelity .exact.; valid fidelities: auto, adc, analytic"):
        SimulatedRadar(PAPER, KIT, fidelity="exact")
    with pytest.raises(rs.RtsError,
                       match="estimator .music.; valid angle estimators: bartlett, ti"):
        SimulatedRadar(PAPER, KIT, estimator="music")


# Targets beyond the radar's unambiguous range (75 m) and radial velocity (+-10.7 m/s): folded
# by one or more range spans and one to three Doppler spans (three TDM loops' worth: 3 TX).
BEYOND_RANGE_M = np.array([90.0, 140.0, 100.0, 80.0, 60.0, 170.0])
BEYOND_V_MPS = np.array([-30.0, 25.0, 15.0, -12.0, 66.5, -70.0])


def far_field(rig):
    """``rig``'s FE directions in the far field: 10 km away, the RTS delay advancing the echo.

    The plane-wave world the solver assumes (no FE antenna offsets, the preset arrays are
    centred on the reference point): the simulated radar then sees each FE exactly where the
    rig says, and a test can look at what it is about without the near-field error of a 1 m
    bench. Only a test can build it: no RTS has a negative delay.
    """
    return rs.Rig.grid(rig.az_deg.reshape(rig.rows, rig.columns),
                       rig.el_deg.reshape(rig.rows, rig.columns), 1e4, name=f"{rig.name}-far",
                       limits=rs.HardwareLimits(delay_min_s=-1.0))


def beyond_schedule(radar=AWR, rig=KIT):
    """One target per frame at (BEYOND_RANGE_M, BEYOND_V_MPS), seen from az 2, el -3 deg."""
    n = BEYOND_RANGE_M.size
    return build_schedule(tracks(np.full(n, 2.0), np.full(n, -3.0), radar=radar,
                                 range_m=BEYOND_RANGE_M, v=BEYOND_V_MPS), rig, radar)


def folded_truth(profile, range_m, v_mps):
    """Range and velocity as an FMCW TDM-MIMO radar measures them, from its sampling alone.

    The beat frequency S 2R/c0 - fD (fD = -2 v / lambda: range-Doppler coupling, the echo's
    Doppler shift adds to its beat) of complex samples taken at fs aliases modulo fs: the range
    R + v c0 / (lambda S) wraps modulo c0 fs / (2 S). The Doppler is sampled once per TDM loop
    (every TX once), so it wraps modulo 1 / T_loop: the velocity wraps modulo
    lambda / (2 T_loop) = 2 v_max.
    """
    c0 = 299_792_458.0
    slope = profile.bandwidth_hz / profile.ramp_time_s
    r_unamb = c0 * profile.sample_rate_hz / (2.0 * slope)
    t_loop = len(profile.tx_order) * (profile.ramp_time_s + profile.idle_time_s)
    wavelength = c0 / (profile.fc_hz + profile.bandwidth_hz / 2.0)
    v_span = wavelength / (2.0 * t_loop)
    coupled_m = range_m + v_mps * c0 / (wavelength * slope)
    return (np.mod(coupled_m, r_unamb), np.mod(v_mps + v_span / 2, v_span) - v_span / 2,
            r_unamb, v_span)


def circular_error(got, want, span):
    """Distance on a circle of circumference ``span`` (a fold at the edge is no error)."""
    return np.abs(np.mod(np.asarray(got) - want + span / 2, span) - span / 2)


@pytest.mark.parametrize("estimator", ["bartlett", "ti"])
def test_analytic_folds_like_adc_beyond_unambiguous_range_and_velocity(estimator):
    sch = beyond_schedule()
    runs = {fid: SimulatedRadar(AWR, KIT, fidelity=fid, estimator=estimator,
                                noise=False).process(sch) for fid in ("adc", "analytic", "auto")}
    assert all(d.count >= 1 for d in runs["adc"])
    for adc, ana, auto in zip(*runs.values(), strict=True):
        # Same detections (a folded TDM Doppler may leave a second angle peak: in both).
        assert adc.count == ana.count
        for name in ("range_m", "radial_velocity_mps", "az_deg", "el_deg", "rcs_dbsm"):
            np.testing.assert_array_equal(getattr(auto, name), getattr(ana, name))
        # The adc's parabolic sub-bin interpolation of a Hann-windowed peak is within 0.02
        # bins (6 mm of 0.29 m, 7 mm/s of 0.34 m/s).
        for name, tol in (("range_m", 0.01), ("radial_velocity_mps", 0.01), ("rcs_dbsm", 0.2)):
            np.testing.assert_allclose(getattr(adc, name), getattr(ana, name), atol=tol,
                                       err_msg=name)
        # The angles come from the same snapshot, compensated with a Doppler 0.02 bins apart.
        # Compared as direction cosines to 2e-4 (0.01 deg at boresight): a wrongly compensated
        # target lands near el 71 deg, where an azimuth is a cosine magnified 1 / cos(el) ~ 3.
        for got, want in zip(direction_cosines(np.radians(adc.az_deg), np.radians(adc.el_deg)),
                             direction_cosines(np.radians(ana.az_deg), np.radians(ana.el_deg)),
                             strict=True):
            np.testing.assert_allclose(got, want, atol=2e-4)


@pytest.mark.parametrize("fidelity", ["adc", "analytic"])
def test_folded_range_and_velocity_follow_the_sampling(fidelity):
    # In the far field: the angles below are about the TDM compensation, not the near field.
    rig = far_field(KIT)
    sch = beyond_schedule(rig=rig)
    dets = SimulatedRadar(AWR, rig, fidelity=fidelity, noise=False).process(sch)
    want_r, want_v, r_unamb, v_span = folded_truth(AWR, BEYOND_RANGE_M, BEYOND_V_MPS)
    assert r_unamb == pytest.approx(74.948, abs=1e-3) and v_span / 2 == pytest.approx(10.745,
                                                                                   abs=1e-3)
    for d, r, v in zip(dets, want_r, want_v, strict=True):
        assert d.count >= 1
        assert np.all((d.range_m >= 0.0) & (d.range_m < r_unamb))
        assert np.all(np.abs(d.radial_velocity_mps) <= v_span / 2)
        assert circular_error(d.range_m, r, r_unamb).max() < 0.01
        assert circular_error(d.radial_velocity_mps, v, v_span).max() < 0.01
    # Folded by a multiple of the TX count in loops, the TDM compensation with the folded
    # Doppler is still right (its TX-slot phase error is a whole turn): the angles hold.
    # Otherwise the radar compensates the wrong Doppler and its angles are off.
    loops_folded = np.round((BEYOND_V_MPS - want_v) / v_span)
    for d, k in zip(dets, loops_folded, strict=True):
        err = np.hypot(d.az_deg[0] - 2.0, d.el_deg[0] + 3.0)
        if k % len(AWR.tx_order) == 0:
            assert err < 0.02
        else:
            assert err > 1.0


def test_noisy_analytic_stays_within_the_unambiguous_cell():
    # Targets right at the edges: the noise moves them across, the fold brings them back.
    r_unamb = AWR.max_range_m
    v_max = AWR.max_radial_velocity_mps
    n = 200
    sch = build_schedule(tracks(np.full(n, 2.0), np.full(n, -3.0), radar=AWR,
                                range_m=np.where(np.arange(n) % 2, r_unamb, 2 * r_unamb) - 1e-4,
                                v=np.where(np.arange(n) % 2, v_max, -v_max)),
                         KIT, AWR)
    dets = SimulatedRadar(AWR, KIT, fidelity="analytic",
                          rng=np.random.default_rng(5)).process(sch)
    rng_m = np.concatenate([d.range_m for d in dets])
    v = np.concatenate([d.radial_velocity_mps for d in dets])
    assert rng_m.size >= n
    assert np.all((rng_m >= 0.0) & (rng_m < r_unamb))
    assert np.all(np.abs(v) <= v_max)
    # Both sides of each edge occur: the noise really crossed it.
    assert (rng_m < 1.0).any() and (rng_m > r_unamb - 1.0).any()
    assert (v > 0).any() and (v < 0).any()


def test_auto_takes_the_cube_for_targets_folded_onto_one_cell():
    rig = rs.Rig.preset("wide-3x5")
    # 20 m and 20 m + 75 m (the unambiguous range): the same range cell once folded. The
    # far one's RCS makes up for its distance (R^4): two equal echoes.
    far_m = 20.0 + AWR.max_range_m
    sch = build_schedule(scene_tracks([-15.0, 15.0], [0.0, 2.0], [20.0, far_m], -1.0, radar=AWR,
                                      rcs=[10.0, 10.0 + 40.0 * np.log10(far_m / 20.0)]), rig, AWR)
    sim = SimulatedRadar(AWR, rig, fidelity="auto", noise=False)
    det = sim.process(sch)[0]
    assert sim.frames_adc == 1
    assert det.count == 2
    np.testing.assert_allclose(det.range_m, 20.0, atol=0.05)


def test_ca_cfar_box_sums_equal_the_2d_correlation_of_the_training_window():
    from scipy import ndimage

    from rts_scenario.radar.simulate import _box_sum

    rng = np.random.default_rng(0)
    power = rng.exponential(1.0, (64, 256))
    power[30, 100], power[10, 5] = 1e8, 1e5  # strong peaks next to noise cells
    guard, train = 2, 8
    half = guard + train
    window = np.ones((2 * half + 1, 2 * half + 1))
    window[train : train + 2 * guard + 1, train : train + 2 * guard + 1] = 0.0
    padded = np.pad(power, half, mode="reflect")
    want = ndimage.correlate(padded, window, mode="constant")[half:-half, half:-half]
    got = _box_sum(padded, half) - _box_sum(padded[train:-train, train:-train], guard)
    np.testing.assert_allclose(got, want, rtol=1e-8)


def test_adc_noise_drawn_ahead_is_seeded_independent_and_white():
    """The cube's noise, drawn a frame ahead on another thread: the same seed gives the same
    frames whatever the timing; frames differ from each other; its power is the profile's."""
    sch = build_schedule(tracks([0.0, 1.0, 0.5], [0.0, -1.0, 2.0], range_m=20.0), KIT, PAPER)

    def run(seed):
        sim = SimulatedRadar(PAPER, KIT, fidelity="adc", rng=np.random.default_rng(seed))
        return sim, [(d.range_m.tolist(), d.az_deg.tolist()) for d in sim.process(sch)]

    (sim, first), (_, again) = run(5), run(5)
    assert first == again and run(6)[1] != first
    # The draws themselves: unit variance, uncorrelated from one frame to the next.
    a, b = sim._noise.take(200_000), sim._noise.take(200_000)
    assert a.var() == pytest.approx(1.0, abs=0.02) and abs(a.mean()) < 0.01
    assert abs(np.corrcoef(a, b)[0, 1]) < 0.01


@pytest.mark.parametrize("loops", [64, 63])
def test_windowed_cube_gives_the_windowed_centred_spectrum(loops):
    """The cube weighted for the FFTs (windows, 1/N, zero Doppler moved to the middle) gives
    what windowing the plain cube, transforming it and centring it (fftshift) gives."""
    import dataclasses

    profile = dataclasses.replace(PAPER, chirp_loops=loops)
    sch = build_schedule(tracks([0.5, -1.0], [1.0, 2.0], range_m=20.0, v=3.0), KIT, profile)
    sim = SimulatedRadar(profile, KIT, fidelity="adc", noise=False)
    echoes = sim.echoes(sch, slice(0, 1))
    plain = sim.cube(echoes)
    win_r = np.hanning(plain.shape[2] + 2)[1:-1]
    win_d = np.hanning(loops + 2)[1:-1]
    expected = np.fft.fftshift(np.fft.fft(
        np.fft.ifft(plain * win_r, axis=2) * plain.shape[2] * win_d[:, None, None], axis=0),
        axes=0)
    got = np.fft.fft(np.fft.ifft(sim.cube(echoes, windowed=True), axis=2), axis=0)
    np.testing.assert_allclose(got, expected, atol=1e-9 * np.abs(expected).max())


def test_the_simulated_rts_sets_the_nearest_phase_step():
    # A 6-bit phase shifter (5.625 deg steps) sent 2.9 deg plays 5.625 deg, sent -2.7 deg
    # plays 0: the echoes are those of the steps, to the last bit; a continuous one plays
    # what it is sent.
    import dataclasses

    from rts_scenario.calibration import pattern_schedule

    kit = rs.Rig.preset("kit-table1")
    radar = RadarProfile.preset("paper")
    stepped = dataclasses.replace(kit, limits=dataclasses.replace(kit.limits,
                                                                  phase_step_deg=5.625))
    pattern = pattern_schedule(kit, radar, [[(0, 1.0, 0.0), (1, 0.5, 0.0)]], 10.0, 40.0)

    def channels(rig, phase_deg):
        sent = dataclasses.replace(pattern, phase_rad=np.radians(
            np.array(phase_deg, dtype=float)[None, None, :]))
        sim = SimulatedRadar(radar, rig, noise=False, rng=np.random.default_rng(0))
        return sim.echoes(sent).channel

    asked = [2.9, -2.7, np.nan, np.nan]
    np.testing.assert_array_equal(channels(stepped, asked),
                                  channels(stepped, [5.625, 0.0, np.nan, np.nan]))
    np.testing.assert_array_equal(channels(kit, asked),
                                  channels(kit, [2.9, -2.7, np.nan, np.nan]))
    turned = channels(kit, asked) / channels(kit, [5.625, 0.0, np.nan, np.nan])
    np.testing.assert_allclose(np.angle(turned[0]), np.radians(2.9 - 5.625), atol=1e-12)


@pytest.mark.parametrize("n", [1, 2, 3, 16, 17, 255, 256, 300])
def test_the_beat_phasors_are_the_powers_of_their_step(n):
    # first * step**k by two short running products and their outer product, against the
    # exponential of each sample's phase.
    from rts_scenario.radar.simulate import _powers

    rng = np.random.default_rng(n)
    cycles = rng.uniform(-0.5, 0.5, (5, 3))
    first = rng.normal(size=(5, 3)) + 1j * rng.normal(size=(5, 3))
    got = _powers(first, np.exp(-2j * np.pi * cycles), n)
    want = first[..., None] * np.exp(-2j * np.pi * cycles[..., None] * np.arange(n))
    assert got.shape == (5, 3, n)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13 * np.abs(first).max())


@pytest.mark.parametrize("shape", [(64, 256), (3, 5), (1, 7), (16, 1)])
def test_the_neighbourhood_maximum_is_scipy_s_maximum_filter_wrapping(shape):
    from scipy import ndimage

    from rts_scenario.radar.simulate import _neighbourhood_max

    power = np.random.default_rng(7).exponential(size=shape)
    power[0, 0] = power[-1, -1] = 5.0  # peaks whose neighbours wrap round both axes
    np.testing.assert_array_equal(_neighbourhood_max(power),
                                  ndimage.maximum_filter(power, size=3, mode="wrap"))
