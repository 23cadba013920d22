"""The simulated radar and the RTS delay grid against hand-derived FMCW physics.

The radar's tests play nothing the solver or the schedule builder computed: the RTS settings
are written by hand from the scene (delay ``2 R / c0`` less the air path and
the RTS latency, Doppler ``-2 v / lambda``, level from the rig's reference by the radar
equation ``A = A_ref - (sigma - sigma_ref) + 40 log10(R / R_ref)``), and what the radar must
measure is derived from the textbook FMCW relations:

* beat frequency of a chirp of slope S delayed by T: ``S T - fD`` (the Doppler adds to it: the
  range-Doppler coupling), sampled at fs, so it folds modulo fs; range ``c0 f_b / (2 S)``;
* Doppler sampled once per TDM loop, folding modulo ``1 / T_loop``; velocity ``-fD lambda / 2``;
* a plane wave from direction u reaches virtual element p earlier by ``u . p / c0``: its phase
  there leads by ``2 pi f u . p / c0`` at the frequency f the radar receives at that instant.

The schedule builder's delay grid and the peak search (the instrument behind the solver's
figures) are checked with the independent near-field model (tests/nearfield_reference.py); the
superposition gain the schedule's level uses, by hand.
"""

import dataclasses

import numpy as np
import pytest
from nearfield_reference import array_snapshot, bartlett_direction, virtual_positions
from test_fe_response import bench_rig, calibrated, played_snapshot
from test_honest_bench import chirp_of, layout, tracks

import rts_scenario as rs
from rts_scenario.arrays import direction_cosines
from rts_scenario.evaluation import evaluation_grid
from rts_scenario.radar import RadarProfile
from rts_scenario.radar.simulate import SimulatedRadar
from rts_scenario.rig import RtsDelayModel
from rts_scenario.schedule import Schedule, build_schedule

C0 = 299_792_458.0
AWR = RadarProfile.preset("awr1843boost")
KIT = rs.Rig.preset("kit-table1")
FAR_M = 1e4  # FEs this far away: plane waves but for ~1e-6 rad of parallax (see below)


def far_rig(delay_model="if", latency_s=3e-9):
    """kit-table1's FE directions 10 km away (a test may play negative RTS delays)."""
    return rs.Rig.from_angles(KIT.az_deg, KIT.el_deg, distance_m=FAR_M, name="kit-far",
                              limits=rs.HardwareLimits(delay_min_s=-1.0, latency_s=latency_s),
                              reference=rs.Reference(range_m=10.0, rcs_dbsm=10.0,
                                                     attenuation_db=40.0),
                              rts=RtsDelayModel(delay_model=delay_model))


def chirp(profile):
    """Slope, sampling, loop time and nominal wavelength, from the profile's raw fields."""
    slope = profile.bandwidth_hz / profile.ramp_time_s
    slot_s = profile.ramp_time_s + profile.idle_time_s
    return slope, slot_s, len(profile.tx_order) * slot_s, C0 / (profile.fc_hz
                                                                + profile.bandwidth_hz / 2)


def played(rig, fe, range_m, v_mps, rcs_dbsm, profile=AWR, phase_rad=0.0):
    """One echo per frame on FE ``fe`` alone at full level, its settings written by hand."""
    range_m, v_mps, rcs_dbsm = np.broadcast_arrays(*(np.atleast_1d(np.asarray(x, float))
                                                     for x in (range_m, v_mps, rcs_dbsm)))
    f = range_m.size
    ref = rig.reference
    wavelength = chirp(profile)[3]

    def channels(value):
        out = np.full((f, 1, 4), np.nan)
        out[:, 0, 0] = value
        return out

    fes = np.full((f, 1, 4), -1)
    fes[:, 0, 0] = fe
    active = np.zeros((f, 1, 4), bool)
    active[:, 0, 0] = True
    weight = np.zeros((f, 1, 4))
    weight[:, 0, 0] = 1.0
    return Schedule(
        t_s=np.arange(f) * 0.05, frame_index=np.arange(f), names=("t",),
        quad=np.zeros((f, 1), np.int64), fe=fes, weight=weight,
        attenuation_db=channels(ref.attenuation_db - (rcs_dbsm - ref.rcs_dbsm)
                                + 40.0 * np.log10(range_m / ref.range_m)),
        delay_s=channels(2.0 * range_m / C0 - 2.0 * rig.distance_m[fe] / C0
                         - rig.limits.latency_s),
        doppler_hz=channels(-2.0 * v_mps / wavelength), phase_rad=channels(phase_rad),
        active=active, status=np.zeros((f, 1), np.uint16), angle_error_deg=np.zeros((f, 1, 2)))


def wrap(rad):
    return np.mod(np.asarray(rad) + np.pi, 2 * np.pi) - np.pi


def hann_straddle_db(offset):
    """Loss in dB of a Hann-windowed DFT ``offset`` bins off a tone (first principles: the DFT
    of the window's samples against a tone on the bin)."""
    n = 256
    w = np.hanning(n + 2)[1:-1]
    x = np.exp(2j * np.pi * (8.0 + offset) * np.arange(n) / n) * w
    return -20.0 * np.log10(np.abs(np.fft.fft(x)[8]) / w.sum())


@pytest.mark.parametrize("model", ["if", "rf"])
def test_beat_cube_has_the_fmcw_tones_and_the_plane_wave_phases_of_the_total_delay(model):
    # FE 3 (az 3.8, el 9.9 deg) 10 km away, a target at 33.3 m receding at 4 m/s.
    rig = far_rig(model)
    fe, range_m, v = 3, 33.3, 4.0
    sch = played(rig, fe, range_m, v, 10.0, phase_rad=0.7)
    sim = SimulatedRadar(AWR, rig, fidelity="adc", noise=False)
    x = sim.cube(sim.echoes(sch))  # [loop, virtual element, sample]
    slope, slot_s, loop_s, wavelength = chirp(AWR)
    fs, fd = AWR.sample_rate_hz, -2.0 * v / wavelength
    # Virtual element v = t * n_rx + r sits at p_t + p_r; the plane wave from u shortens its
    # round trip by u . p / c0 against the reference point (the centroid, where it is 2 R / c0).
    a = AWR.antennas
    py = (a.tx_y_m[:, None] + a.rx_y_m[None, :]).ravel()
    pz = (a.tx_z_m[:, None] + a.rx_z_m[None, :]).ravel()
    az, el = np.radians(KIT.az_deg[fe]), np.radians(KIT.el_deg[fe])
    lead_s = (np.cos(el) * np.sin(az) * py + np.sin(el) * pz) / C0
    total_s = 2.0 * range_m / C0 - lead_s  # (M,)
    # Fast time: one sample turns the phase by -2 pi (S T - fD) / fs (folded into (-pi, pi]).
    step = np.angle(x[:, :, 1:] / x[:, :, :-1])
    np.testing.assert_allclose(wrap(step + 2 * np.pi * (slope * total_s - fd)[None, :, None]
                                    / fs), 0.0, atol=1e-8)
    # Slow time: one TDM loop turns it by 2 pi fD T_loop.
    np.testing.assert_allclose(wrap(np.angle(x[1:] / x[:-1]) - 2 * np.pi * fd * loop_s), 0.0,
                               atol=1e-8)
    # Across the elements at sample n: the plane wave's lead at the frequency received then,
    # f0 + S (t_n - T), plus the Doppler turned between the TX slots (the TX fire in turn).
    slot = np.array([list(AWR.tx_order).index(t) for t in AWR.tx_index], float)
    for n in (0, 100, 255):
        t_n = AWR.adc_start_s + n / fs
        f_rx = AWR.fc_hz + slope * (t_n - 2.0 * range_m / C0)
        want = 2 * np.pi * (f_rx * lead_s + fd * slot * slot_s)
        got = np.angle(x[0, :, n] / x[0, 0, n])
        # Left out of the hand formula: S dT^2 / 2 and the wave's curvature, < 1e-6 rad.
        np.testing.assert_allclose(wrap(got - (want - want[0])), 0.0, atol=1e-5)
    # The phase common to the elements: at the reference point's path (T = 2 R / c0, of which
    # the RTS delays tau), -2 pi [f0 T_air + f_x tau + S t_n T - S T^2 / 2] + RTS phase, with
    # f_x the IF of a digital RTS or the carrier for an RF delay line, plus the Doppler ramp at
    # the RTS output (t_n less the down leg).
    tau = 2.0 * range_m / C0 - 2.0 * FAR_M / C0
    f_x = 500e6 if model == "if" else AWR.fc_hz
    t_total = 2.0 * range_m / C0
    n = 0
    t_n = AWR.adc_start_s + n / fs
    common = (-2 * np.pi * (AWR.fc_hz * 2 * FAR_M / C0 + f_x * tau + slope * t_n * t_total
                            - slope * t_total**2 / 2) + 0.7 + 2 * np.pi * fd * (t_n - FAR_M / C0))
    centroid = np.angle(np.mean(x[0, :, n] * np.exp(-2j * np.pi * (
        (AWR.fc_hz + slope * (t_n - t_total)) * lead_s + fd * slot * slot_s))))
    # 1e-5 s of a 10 km leg at fD: the Doppler term alone is known to fD * 1e-12 s; the
    # carrier term f0 * T to f0 * 1e-16 s of rounding in T (1e-3 rad).
    assert abs(wrap(centroid - common)) < 1e-2


# (range m, velocity m/s): inside the unambiguous cell, beyond the range span (75 m), beyond
# the velocity span (+-10.7 m/s) by one loop's Doppler (the TDM compensation then fails) and by
# three (a whole turn per TX slot: it holds), and both.
CASES = [(20.0, 3.0), (33.3, -7.5), (90.0, -5.0), (140.0, 2.0), (20.0, 3.0 + 21.49),
         (25.0, -4.0 - 3 * 21.49), (100.0, 15.0)]


@pytest.mark.parametrize("model", ["if", "rf"])
@pytest.mark.parametrize("fidelity", ["adc", "analytic"])
def test_hand_played_echo_is_measured_where_fmcw_sampling_puts_it(fidelity, model):
    rig = far_rig(model)
    fe = 3
    r, v = np.array(CASES).T
    rcs = np.array([10.0, -5.0, 20.0, 30.0, 0.0, 5.0, 25.0])
    dets = SimulatedRadar(AWR, rig, fidelity=fidelity, noise=False).process(
        played(rig, fe, r, v, rcs))
    slope, slot_s, loop_s, wavelength = chirp(AWR)
    fs, n, loops = AWR.sample_rate_hz, AWR.adc_samples, AWR.chirp_loops
    # Beat frequency S 2R/c0 + 2v/lambda, folded modulo fs; range = c0 f_b / (2 S).
    beat = np.mod(slope * 2 * r / C0 + 2 * v / wavelength, fs)
    want_r = C0 * beat / (2 * slope)
    # Doppler -2v/lambda folded into [-1/(2 T_loop), 1/(2 T_loop)); v = -fD lambda / 2.
    fd = np.mod(-2 * v / wavelength + 0.5 / loop_s, 1 / loop_s) - 0.5 / loop_s
    want_v = -fd * wavelength / 2
    bin_m = C0 * fs / (2 * slope * n)
    bin_mps = wavelength / (2 * loop_s * loops)
    assert bin_m == pytest.approx(0.2928, abs=1e-4) and bin_mps == pytest.approx(0.3358, abs=1e-4)
    # The parabolic sub-bin fit on a Hann peak's log power is within 0.02 bins (the analytic
    # fidelity has no fit: exact).
    frac = 0.02 if fidelity == "adc" else 1e-6
    # The level: the radar inverts the radar equation at the range it measured (a folded target
    # reads 40 log10(R_measured / R) dB low). Off-bin the adc undoes the Hann straddle loss with
    # its sub-bin estimate: wrong by at most the loss's change over 0.02 bins, on both axes.
    level_db = 2 * max(abs(hann_straddle_db(x + 0.02) - hann_straddle_db(x))
                       for x in np.linspace(0.0, 0.48, 25)) if fidelity == "adc" else 1e-6
    # The TDM compensation uses the sub-bin Doppler estimate, off by up to frac bins, i.e. a
    # phase error 2 pi frac / (L N_tx) per TX slot; the AWR's TX fire in slots along y one
    # wavelength apart: a direction-cosine error of frac / (L N_tx). The analytic fidelity reads
    # the exact Doppler. Both see the FE 10 km away through the parallax of the TX and RX groups
    # (each leg seen from its own group's centre): about lambda / D in direction cosine
    # (0.2 deg at 1 m, tests/test_nearfield_reference.py).
    cosine_tol = 2 * wavelength / FAR_M + (frac / (loops * len(AWR.tx_order))
                                           if fidelity == "adc" else 0.0)
    loops_folded = np.round((-2 * v / wavelength - fd) * loop_s)
    for i, d in enumerate(dets):
        assert d.count >= 1, CASES[i]
        k = int(np.argmax(d.snr_db))
        assert d.range_m[k] == pytest.approx(want_r[i], abs=frac * bin_m), CASES[i]
        assert d.radial_velocity_mps[k] == pytest.approx(want_v[i], abs=frac * bin_mps), CASES[i]
        if loops_folded[i] % len(AWR.tx_order) == 0:
            # (Otherwise the TDM compensation leaves a phase ramp over the TX slots: the radar
            # sees the target elsewhere and weaker, as a real one does.)
            want_rcs = rcs[i] + 40 * np.log10(want_r[i] / r[i])
            # A range off by frac bins changes 40 log10(R) by 40 log10(1 + frac bin / R).
            tol = level_db + 40 * np.log10(1 + frac * bin_m / want_r[i])
            assert d.rcs_dbsm[k] == pytest.approx(want_rcs, abs=tol), CASES[i]
            # A far FE alone is a plane wave from its direction, whatever the RTS delay model.
            # A far FE alone is a plane wave from its direction, whatever the RTS delay model;
            # its phase across the elements is set by the frequency that arrives while the radar
            # samples the sweep's centre t_c: f0 + S (t_c - T), lower by S T than the one it
            # steers with, f0 + S t_c. The direction cosines it reads shrink by that ratio (as
            # for a real target at that range).
            ratio = 1.0 - slope * (2 * r[i] / C0) / AWR.sampled_centre_frequency_hz
            u, s = direction_cosines(np.radians(KIT.az_deg[fe]), np.radians(KIT.el_deg[fe]))
            got_u, got_s = direction_cosines(np.radians(d.az_deg[k]), np.radians(d.el_deg[k]))
            np.testing.assert_allclose([got_u, got_s], [u * ratio, s * ratio], rtol=0,
                                       atol=cosine_tol, err_msg=str(CASES[i]))
            if r[i] > 30.0 and fidelity == "analytic":  # the effect is there: 1e-4 at 33 m
                assert abs(got_s - s) > 10 * cosine_tol


def test_radar_equation_level_sets_the_snr():
    # Absolute level, not through the radar's RCS estimate: the hand-played attenuation of a
    # 0 dBsm target at 40 m is 40 - (0 - 10) + 40 log10(4) = 74.1 dB; after the Hann-windowed
    # range and Doppler FFTs a tone of amplitude a has a sum(w_r) sum(w_d), the noise (variance
    # 10^(-75/10) per complex sample) sum(w_r^2) sum(w_d^2) in power.
    rig = far_rig()
    frames = 300
    sch = played(rig, 3, np.full(frames, 40.0), 1.0, 0.0)
    dets = SimulatedRadar(AWR, rig, fidelity="analytic",
                          rng=np.random.default_rng(11)).process(sch)
    att = 40.0 + 10.0 + 40 * np.log10(4.0)
    win_r = np.hanning(AWR.adc_samples + 2)[1:-1]
    win_d = np.hanning(AWR.chirp_loops + 2)[1:-1]
    want = (-att + 20 * np.log10(win_r.sum() * win_d.sum())
            - (AWR.noise_level_db + 10 * np.log10((win_r**2).sum() * (win_d**2).sum())))
    snr = np.array([d.snr_db[0] for d in dets if d.count])
    assert snr.size > 0.9 * frames
    # The median of the per-detection SNR (12 channels' noise averaged): within 0.5 dB.
    assert np.median(snr) == pytest.approx(want, abs=0.5)


def reference_errors(profile, rig, sch, az, el):
    """Angle errors the independent near-field model sees for what ``sch`` plays."""
    vy, vz = virtual_positions(*layout(profile))
    lam = chirp_of(profile).steering_wavelength_m
    out = np.full(az.size, np.nan)
    for f in range(az.size):
        x = played_snapshot(sch, f, rig, profile)
        got = bartlett_direction(x, vy, vz, lam, az_range_deg=(-20, 20), el_range_deg=(-20, 20),
                                 grid_step_deg=0.5)
        out[f] = np.hypot(got[0] - az[f], got[1] - el[f])
    return out


@pytest.mark.parametrize("model", ["if", "rf"])
def test_rts_delay_grid_is_given_back_in_phase_as_the_reference_sees_it(model):
    # FEs at distinct distances (0.98-1.03 m): on a 100 ps grid each channel's delay rounds
    # differently, by up to 50 ps. Unanswered, that turns channel q's phase by 2 pi f_x dtau_q:
    # up to 0.16 rad at a 500 MHz IF, many turns at the carrier, enough to move the angle.
    # The schedule gives the rounding back in phase: the independent model must see the set
    # angle as on a continuous-delay RTS.
    profile = AWR
    step = 1e-10
    range_m = 12.3
    base = dataclasses.replace(bench_rig(), rts=RtsDelayModel(delay_model=model))
    rig = calibrated(profile, base, range_m)
    grid = dataclasses.replace(rig, limits=dataclasses.replace(rig.limits, delay_step_s=step))
    az, el = evaluation_grid()
    scene = tracks(az, el, radar=profile, range_m=range_m)
    smooth = build_schedule(scene, rig, profile)
    stepped = build_schedule(scene, grid, profile)
    on = stepped.active
    assert np.all(stepped.status == 0)
    np.testing.assert_allclose(np.mod(stepped.delay_s[on] / step + 0.5, 1.0), 0.5, atol=1e-6)
    rounding = stepped.delay_s[on] - smooth.delay_s[on]
    assert np.abs(rounding).max() > 0.1 * step  # the grid really moved the delays
    # The phase the rounding costs, from the delay model alone (the beat term S t_c dtau is the
    # same for both models and < 1e-3 rad here).
    f_x = 500e6 if model == "if" else profile.fc_hz
    assert np.abs(2 * np.pi * f_x * rounding).max() > (0.05 if model == "if" else 3.0)
    continuous = reference_errors(profile, rig, smooth, az, el)
    quantized = reference_errors(profile, grid, stepped, az, el)
    assert continuous.max() <= 0.002
    assert quantized.max() <= 0.002
    # Without the phase given back (the continuous schedule's phases on the grid's delays) the
    # same model sees the angle move: the test can tell.
    unanswered = dataclasses.replace(stepped, phase_rad=smooth.phase_rad)
    assert reference_errors(profile, grid, unanswered, az, el).max() > 0.01


def test_peak_search_measures_what_the_independent_model_says_a_radar_sees():
    # The solver's and the schedule's angle figures are measured with `peak_search`, whose
    # snapshot and beamformer share one plane-wave formula: a sign or wavelength slip common to
    # both would pass its own tests. Against the reference: the snapshot of FEs 1 km away (read
    # where the received frequency is the one the radar steers with), and the Bartlett peak of
    # a superposition of two of them.
    from rts_scenario.peak_search import find_peak, snapshot

    profile = AWR
    array = profile.steering_array
    distance = 1e3
    az, el = np.array([-5.4, 4.5, -3.4, 3.8]), np.array([-8.8, -7.7, 8.4, 9.9])
    centre = chirp_of(profile).centre_sample + 2 * distance / C0 * profile.sample_rate_hz
    ref = np.stack([array_snapshot(*layout(profile), az[q], el[q], distance,
                                   chirp=chirp_of(profile), reference_sample=centre)
                    for q in range(4)])
    ours = snapshot(array, np.eye(4), az, el)
    # Equal up to each FE's common phase; the parallax of the TX and RX groups seen from 1 km
    # (~lambda / D in direction cosine) leaves k (lambda / D) |p| < 1e-4 rad.
    ratio = ref / ours
    ratio /= np.abs(ratio)
    np.testing.assert_allclose(np.angle(ratio / ratio[:, :1]), 0.0, atol=1e-4)
    mix = np.array([[0.7, 0.0, 0.0, 1.0]]) * np.exp(-1j * np.angle(ratio[:, 0]))[None, :]
    got = find_peak(array, snapshot(array, np.abs(mix), az, el))
    want = bartlett_direction(mix[0] @ ref, *virtual_positions(*layout(profile)),
                              chirp_of(profile).steering_wavelength_m, az_range_deg=(-20, 20),
                              el_range_deg=(-20, 20))
    # The superposition peaks between them (2-3 deg here); the reference sees it there but for
    # the parallax at 1 km: ~0.2 deg at 1 m (tests/test_nearfield_reference.py) over 1000.
    np.testing.assert_allclose(np.ravel(got), want, atol=5e-4)
    assert np.hypot(*(np.ravel(got) - [3.8, 9.9])) > 1.0


def test_superposition_gain_at_the_quad_centre_by_hand():
    # The paper array is a cross: 4 RX along y and 3 TX along z, lambda/2 apart, centred, so a
    # plane wave's response at boresight is a product of two cosine sums,
    # f_q(0, 0) = sum_r cos(k y_r u_q) * sum_t cos(k z_t s_q), and equal weights peak at the
    # centre of a square quad with gain g = |sum_q f_q| / M; each channel then plays
    # A - 20 log10(w_q / g) (DESIGN.md 5.4): here A_ref + 20 log10(g).
    radar = RadarProfile.preset("paper")
    rig = rs.Rig.from_angles([-5, 5, -5, 5], [-8, -8, 8, 8])
    sch = build_schedule(tracks(0.0, 0.0, radar=radar, range_m=10.0), rig, radar,
                         fe_responses="plane-wave")
    # The plane-wave model is the profile's array at its nominal wavelength (DESIGN.md 5.1),
    # which also sets the `paper` array's spacing.
    lam = radar.wavelength_m
    k = 2 * np.pi / lam
    y = (np.arange(4) - 1.5) * lam / 2
    z = (np.arange(3) - 1.0) * lam / 2
    az, el = np.radians(rig.az_deg), np.radians(rig.el_deg)
    u, s = np.cos(el) * np.sin(az), np.sin(el)
    f = np.cos(k * np.outer(u, y)).sum(axis=1) * np.cos(k * np.outer(s, z)).sum(axis=1)
    gain = abs(f.sum()) / 12
    assert 3.0 < gain < 4.0
    np.testing.assert_allclose(sch.weight[0, 0], 1.0, rtol=1e-9)
    np.testing.assert_allclose(sch.attenuation_db[0, 0], 40.0 + 20 * np.log10(gain),
                               atol=1e-9)


def test_a_target_between_cells_is_detected_by_both_fidelities_alike():
    """Half a cell off in range and in Doppler a Hann-windowed peak is 2.9 dB weaker (the
    windows' DFT at half a bin, twice): a target about 2 dB above the detection threshold on its
    cell is below it there, for the cube's CFAR and for the analytic radar alike (which tested
    the loss-free level, and saw it every frame); on its cell both see it every frame."""
    straddle_db = -20 * np.log10(AWR.range_response(0.5)[0] * AWR.doppler_response(0.5)[0])
    assert straddle_db == pytest.approx(2.9, abs=0.05)
    frames, f_mid = 60, AWR.fc_hz + AWR.bandwidth_hz / 2
    for range_bin, doppler_bin, least, most in ((136.0, 3.0, 0.95, 1.0), (136.5, 3.5, 0.0, 0.05)):
        v = doppler_bin * AWR.velocity_resolution_mps
        # Set so that the beat S tau - fD lies on (or half way between) range cells.
        r = range_bin * AWR.range_bin_m - v * f_mid / AWR.slope_hz_per_s
        schedule = played(KIT, 3, np.full(frames, r), v, -26.0)
        for fidelity in ("adc", "analytic"):
            radar = SimulatedRadar(AWR, KIT, fidelity=fidelity, noise=True,
                                   rng=np.random.default_rng(7))
            seen = np.mean([np.any(np.abs(d.range_m - range_bin * AWR.range_bin_m) < 0.6)
                            for d in radar.process(schedule)])
            assert least <= seen <= most, (fidelity, range_bin, seen)
