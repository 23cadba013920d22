"""The simulated bench against the independent near-field reference (tests/nearfield_reference.py).

The reference derives the FMCW beat phase of spherical paths radar TX -> FE receive antenna ->
RTS -> FE transmit antenna -> radar RX from first principles and shares no code with the
package; these tests compare where the simulated radar sees things with where it says a radar
must see them.
"""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from nearfield_reference import FmcwChirp, seen_direction_of_fe

import rts_scenario as rs
from rts_scenario.arrays import direction_cosines
from rts_scenario.kinematics import Tracks
from rts_scenario.located_yaml import load_yaml
from rts_scenario.radar import RadarProfile
from rts_scenario.radar.simulate import SimulatedRadar, near_field_warning
from rts_scenario.rig import RtsDelayModel
from rts_scenario.schedule import build_schedule

AWR = RadarProfile.preset("awr1843boost")
KIT = rs.Rig.preset("kit-table1")
LAB = rs.Rig.from_file(Path(__file__).parents[1] / "scenarios/rigs/lab-2x3.rig.yaml")


def raised_awr() -> RadarProfile:
    """The AWR1843BOOST layout with its TX row 5 mm above the RX row (reference point: the
    virtual array's centroid), another TX order and sampling from 2 us into the ramp."""
    ant = AWR.antennas
    lift = 0.005
    text = (
        "rts_radar: 1\nname: awr-raised-tx\nfc_hz: 77.0e+9\nbandwidth_hz: 1.0e+9\n"
        "ramp_time_s: 25.0e-6\nidle_time_s: 5.0e-6\nadc_start_s: 2.0e-6\nadc_samples: 256\n"
        "sample_rate_hz: 20.0e+6\nchirp_loops: 64\ntx_order: [0, 2, 1]\nframe_period_s: 0.05\n"
        f"array:\n  tx_y_m: {ant.tx_y_m.tolist()}\n  tx_z_m: {(ant.tx_z_m + lift / 2).tolist()}\n"
        f"  rx_y_m: {ant.rx_y_m.tolist()}\n  rx_z_m: {(ant.rx_z_m - lift / 2).tolist()}\n")
    return RadarProfile.from_document(load_yaml("<raised>", text))


def chirp_of(profile: RadarProfile) -> FmcwChirp:
    slot = {t: i for i, t in enumerate(profile.tx_order)}
    return FmcwChirp(fc_hz=profile.fc_hz, bandwidth_hz=profile.bandwidth_hz,
                     ramp_time_s=profile.ramp_time_s, sample_rate_hz=profile.sample_rate_hz,
                     n_samples=profile.adc_samples, adc_start_s=profile.adc_start_s,
                     idle_time_s=profile.idle_time_s,
                     tx_slot=tuple(slot[t] for t in range(len(profile.tx_order))))


def layout(profile: RadarProfile) -> tuple[np.ndarray, ...]:
    a = profile.antennas
    return a.tx_y_m, a.tx_z_m, a.rx_y_m, a.rx_z_m


def tracks(az, el, *, radar, range_m=12.3, v=0.0, rcs=10.0):
    """One target per frame (arrays broadcast over frames)."""
    az, el = np.atleast_1d(az).astype(float), np.atleast_1d(el).astype(float)
    f = az.size
    one = np.ones((f, 1), bool)

    def full(x):
        return np.broadcast_to(np.asarray(x, float).reshape(-1, 1), (f, 1)).copy()

    return Tracks(names=("t",), t_s=np.arange(f) * 0.05, range_m=full(range_m),
                  radial_velocity_mps=full(v), doppler_hz=full(-2 * np.asarray(v) /
                                                               radar.wavelength_m),
                  rcs_dbsm=full(rcs), az_deg=az[:, None], el_deg=el[:, None],
                  position_m=np.zeros((f, 1, 3)), present=one, in_coverage=one, in_range=one,
                  in_velocity=one)


def first(dets, name):
    return np.array([getattr(d, name)[0] for d in dets])


@pytest.mark.parametrize("fidelity", ["adc", "analytic"])
@pytest.mark.parametrize("raised", [False, True])
def test_one_fe_is_seen_where_the_reference_says(fidelity, raised):
    profile = raised_awr() if raised else AWR
    dets = []
    want = []
    for fe in (0, 3):
        # Plane-wave responses: a target at the FE's nominal direction is that FE alone.
        sch = build_schedule(tracks(KIT.az_deg[fe], KIT.el_deg[fe], radar=profile), KIT, profile,
                             fe_responses="plane-wave")
        assert sch.active[0, 0].sum() == 1  # that FE alone, at full level
        dets.append(SimulatedRadar(profile, KIT, fidelity=fidelity, noise=False).process(sch)[0])
        want.append(seen_direction_of_fe(
            KIT.az_deg[fe], KIT.el_deg[fe], KIT.distance_m[fe], *layout(profile),
            chirp=chirp_of(profile), tau_s=sch.delay_s[0, 0, sch.fe[0, 0] == fe][0]))
    az, el = np.array([d.az_deg[0] for d in dets]), np.array([d.el_deg[0] for d in dets])
    want_az, want_el = np.array(want).T
    np.testing.assert_allclose(az, want_az, atol=0.005)
    np.testing.assert_allclose(el, want_el, atol=0.005)
    if not raised:
        # Visibly not the mechanical direction: at 1 m the board's TX group beside the RX group
        # (TX1 half a wavelength above TX0 and TX2) moves it ~0.17-0.2 deg in elevation.
        lift = el - KIT.el_deg[[0, 3]]
        assert np.all((np.abs(lift) > 0.15) & (np.abs(lift) < 0.25))


@pytest.mark.parametrize("model", ["if", "rf"])
def test_fe_antenna_offsets_and_delay_model_follow_the_reference(model):
    rx_off, tx_off = np.array([0.04, -0.03]), np.array([-0.02, 0.05])
    rig = dataclasses.replace(KIT, rx_offset_m=np.tile(rx_off, (4, 1)),
                              tx_offset_m=np.tile(tx_off, (4, 1)),
                              rts=RtsDelayModel(delay_model=model))
    radar = SimulatedRadar(AWR, rig, noise=False)
    az, el = radar.fe_directions()
    for fe in range(4):
        want = seen_direction_of_fe(rig.az_deg[fe], rig.el_deg[fe], rig.distance_m[fe],
                                    *layout(AWR), chirp=chirp_of(AWR), fe_rx_offset_m=rx_off,
                                    fe_tx_offset_m=tx_off, delay_model=model)
        np.testing.assert_allclose([az[fe], el[fe]], want, atol=0.005)
    # Half the antennas' offset, seen from 1 m: about 0.6 deg in azimuth, 1.1 deg in elevation.
    assert np.all(np.abs(az - rig.az_deg) > 0.4) and np.all(np.abs(el - rig.el_deg) > 0.8)


def test_analytic_and_adc_agree_with_folding_and_range_doppler_coupling():
    # 30 m/s (folded by one Doppler span: the TDM compensation goes wrong, in both), 64.5 m/s
    # (folded by three: right again) and 3 m/s; 20 m, and 90 m folded into 15 m.
    v = np.array([30.0, -30.0, 64.5, 3.0, 30.0, 64.5])
    r = np.array([20.0, 20.0, 20.0, 90.0, 90.0, 90.0])
    az = np.array([1.0, -2.0, 3.0, -1.0, 0.5, 2.5])
    el = np.array([4.0, -6.0, 0.0, 2.0, -3.0, 5.0])
    sch = build_schedule(tracks(az, el, radar=AWR, range_m=r, v=v), KIT, AWR)
    adc = SimulatedRadar(AWR, KIT, fidelity="adc", noise=False).process(sch)
    ana = SimulatedRadar(AWR, KIT, fidelity="analytic", noise=False).process(sch)
    assert [d.count for d in adc] == [d.count for d in ana]
    got = {name: (first(adc, name), first(ana, name))
           for name in ("range_m", "radial_velocity_mps", "az_deg", "el_deg")}
    np.testing.assert_allclose(*got["range_m"], atol=0.01)
    np.testing.assert_allclose(*got["radial_velocity_mps"], atol=0.01)
    # A wrongly compensated target lands far up, where azimuth is a stretched coordinate:
    # compare directions as the angle between them.
    pa = np.stack(direction_cosines(*np.radians([got["az_deg"][0], got["el_deg"][0]])))
    pb = np.stack(direction_cosines(*np.radians([got["az_deg"][1], got["el_deg"][1]])))
    np.testing.assert_array_less(np.degrees(np.hypot(*(pa - pb))), 0.005)
    # The coupling moves a target at 30 m/s by v c0 / (lambda S) = 5.8 cm, in both.
    c0 = 299_792_458.0
    shift = v * c0 / (AWR.wavelength_m * AWR.slope_hz_per_s)
    want_r = np.mod(r + shift, AWR.max_range_m)
    np.testing.assert_allclose(got["range_m"][1], want_r, atol=0.002)
    assert shift[0] == pytest.approx(0.058, abs=0.001)


def test_100_ps_delay_step_is_played_on_the_grid_and_compensating_at_another_frequency_shows():
    # Targets over both quads at ranges that quantize differently; FE 2 is 1 cm further and
    # FE 1 has a 1.2 ps calibration delay, so the channels' quantization errors differ. The
    # angles a calibrated rig then shows are asserted below
    # (`test_100_ps_delay_step_keeps_the_angle_on_a_calibrated_rig`) and against the
    # independent reference (tests/test_first_principles.py); this rig's calibration is not
    # the simulated bench's, so only the difference the compensation makes is asserted here.
    az, el = np.meshgrid([-8.0, -3.5, 1.0, 5.5, 9.0], [-5.0, 0.0, 5.0])
    az, el = az.ravel(), el.ravel()
    r = 10.0 + 0.0137 * np.arange(az.size)
    seen = {}
    for name, step, model in (("continuous", 0.0, "if"), ("100 ps", 1e-10, "if"),
                              ("rf continuous", 0.0, "rf"), ("rf 100 ps", 1e-10, "rf")):
        rig = dataclasses.replace(LAB, limits=dataclasses.replace(LAB.limits, delay_step_s=step),
                                  rts=RtsDelayModel(delay_model=model))
        sch = build_schedule(tracks(az, el, radar=AWR, range_m=r), rig, AWR)
        assert np.all(sch.status == 0)
        dets = SimulatedRadar(AWR, rig, fidelity="analytic", noise=False).process(sch)
        seen[name] = first(dets, "az_deg"), first(dets, "el_deg")
        if name == "100 ps":  # the schedule really quantized: delays on the 100 ps grid
            on = sch.active
            np.testing.assert_allclose(np.mod(sch.delay_s[on] / 1e-10 + 0.5, 1.0), 0.5,
                                       atol=1e-6)
            # ... and the compensation matters: compensating at the carrier instead of the IF
            # moves the angles by more than a tenth of a degree.
            wrong = build_schedule(tracks(az, el, radar=AWR, range_m=r), dataclasses.replace(
                rig, rts=RtsDelayModel(delay_model="rf")), AWR)
            bad = SimulatedRadar(AWR, rig, fidelity="analytic", noise=False).process(wrong)
            moved = np.hypot(first(bad, "az_deg") - seen[name][0],
                             first(bad, "el_deg") - seen[name][1])
            assert moved.max() > 0.1


@pytest.mark.parametrize("model", ["if", "rf"])
def test_100_ps_delay_step_keeps_the_angle_on_a_calibrated_rig(model, monkeypatch):
    # FEs at different distances quantize differently; the rig is calibrated (the carrier
    # phases of the different air paths are channel phase offsets). Each channel's echo then
    # arrives up to a step from the others: the schedule gives its rounding back in phase (at
    # the IF or the carrier) and in level (the range window weighs the channels differently).
    import rts_scenario.schedule.build as build
    from rts_scenario.calibration import calibrate, simulated_measure
    from rts_scenario.evaluation import evaluation_grid
    from rts_scenario.radar.simulate import ChannelErrors

    az, el = evaluation_grid()
    r = 10.0 + 0.0137 * np.arange(az.size)
    kit = dataclasses.replace(KIT, distance_m=np.array([1.0, 1.013, 0.991, 1.004]),
                              rts=RtsDelayModel(delay_model=model))

    def errors(step, fidelity="analytic"):
        rig = dataclasses.replace(kit, limits=dataclasses.replace(kit.limits,
                                                                  delay_step_s=step))
        rig = calibrate(rig, AWR, simulated_measure(AWR, rig, ChannelErrors.none(4))).apply(rig)
        sch = build_schedule(tracks(az, el, radar=AWR, range_m=r), rig, AWR)
        dets = SimulatedRadar(AWR, rig, fidelity=fidelity, noise=False).process(sch)
        return np.hypot(first(dets, "az_deg") - az, first(dets, "el_deg") - el)

    assert errors(0.0).max() <= 0.002
    assert errors(1e-10).max() <= 0.002
    if model == "if":
        assert errors(1e-10, "adc").max() <= 0.005
        # Without the level correction the window's weighting moves the angle.
        monkeypatch.setattr(build, "_straddle_db", lambda rig, radar, tracks, delay, fe:
                            np.zeros(delay.shape))
        assert errors(1e-10).max() > 0.03


def test_near_field_warning_names_the_effect():
    cascade = RadarProfile.preset("cascade-12x16")
    text = near_field_warning(cascade, KIT)
    assert text is not None
    assert text.startswith("FEs at 1 m are inside radar cascade-12x16's near field "
                           "(Fraunhofer distance 5.48 m): expect ~")
    assert text.endswith(" deg direction errors")
    # The AWR1843BOOST is small (Fraunhofer distance 0.15 m) but its TX group sits beside the
    # RX group: at 1 m it still sees the FEs ~0.2 deg off.
    text = near_field_warning(AWR, KIT)
    assert text is not None and "Fraunhofer distance (0.145 m)" in text
    assert float(text.split("~")[1].split(" ")[0]) == pytest.approx(0.2, abs=0.05)
    # The paper's compact cross of antennas around the reference point: nothing to warn about.
    assert near_field_warning(RadarProfile.preset("paper"), KIT) is None
    far = dataclasses.replace(KIT, distance_m=np.full(4, 100.0))
    assert near_field_warning(cascade, far) is None


def test_cascade_sees_each_fe_where_the_reference_says():
    # 12 TX x 16 RX, 10 cm across: at 1 m deep in its near field (~1.4 deg in elevation with its
    # TX group 2 cm below the RX row).
    cascade = RadarProfile.preset("cascade-12x16")
    az, el = SimulatedRadar(cascade, KIT, noise=False).fe_directions()
    want = np.array([seen_direction_of_fe(KIT.az_deg[fe], KIT.el_deg[fe], KIT.distance_m[fe],
                                          *layout(cascade), chirp=chirp_of(cascade))
                     for fe in range(4)])
    np.testing.assert_allclose(az, want[:, 0], atol=0.005)
    np.testing.assert_allclose(el, want[:, 1], atol=0.005)
    assert np.abs(el - KIT.el_deg).max() > 1.0
