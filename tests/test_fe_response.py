"""Modeled FE response vectors (DESIGN.md 5.5b): the exact method on the honest bench.

Measured against the independent reference `nearfield_reference` and on the honest simulated
bench (`SimulatedRadar`: spherical paths, the profile's physical antennas, FE antenna offsets),
never only against the solver itself.
"""

from dataclasses import replace

import numpy as np
import pytest
from nearfield_reference import array_snapshot, bartlett_direction, virtual_positions
from test_honest_bench import chirp_of, layout, tracks

import rts_scenario as rs
from rts_scenario.arrays import direction_cosines, plane_waves
from rts_scenario.evaluation import evaluation_grid
from rts_scenario.propagation import C0_MPS
from rts_scenario.radar import RadarProfile
from rts_scenario.radar.simulate import SimulatedRadar
from rts_scenario.responses import FrontEndModel
from rts_scenario.schedule import build_schedule
from rts_scenario.solver import plan_key

KIT = rs.Rig.preset("kit-table1")
RANGE_M = 12.3

def played_snapshot(sch, f, rig, profile):
    """The independent near-field model's snapshot of what frame ``f`` of ``sch`` plays for
    its first target: each active channel's FE at its place, level, delay, phase and Doppler."""
    on = sch.active[f, 0]
    fe = sch.fe[f, 0, on]
    return array_snapshot(
        *layout(profile), rig.az_deg[fe], rig.el_deg[fe], rig.distance_m[fe],
        chirp=chirp_of(profile), amplitude=10.0 ** (-sch.attenuation_db[f, 0, on] / 20.0),
        tau_s=rig.limits.latency_s + sch.delay_s[f, 0, on], phase_rad=sch.phase_rad[f, 0, on],
        doppler_hz=sch.doppler_hz[f, 0, on], fe_rx_offset_m=rig.rx_offset_m[fe],
        fe_tx_offset_m=rig.tx_offset_m[fe], delay_model=rig.rts.delay_model,
        if_hz=rig.rts.if_frequency_hz)



def bench_rig(**kwargs) -> rs.Rig:
    """kit-table1's angles with distinct FE distances and small FE antenna offsets."""
    return rs.Rig.from_angles(
        KIT.az_deg, KIT.el_deg, distance_m=[0.98, 1.01, 1.03, 0.995],
        rx_offset_m=[[0.010, -0.005], [0.0, 0.012], [-0.008, 0.0], [0.004, 0.004]],
        tx_offset_m=[[-0.010, 0.005], [0.006, -0.010], [0.0, -0.010], [-0.004, 0.007]],
        name="kit-near", **kwargs)


def centroid_phase(x: np.ndarray) -> float:
    """Mean phase over the elements (the phase at the virtual array's centroid), rad.

    Unwrapped against element 0: across the shipped arrays and the rig's FEs the phases of an
    FE's echo span less than pi.
    """
    return float(np.angle(x[0]) + np.mean(np.angle(x / x[0])))


def reference_snapshot(profile, rig, fe, **kwargs):
    return array_snapshot(
        *layout(profile), rig.az_deg[fe], rig.el_deg[fe], rig.distance_m[fe],
        chirp=chirp_of(profile), fe_rx_offset_m=rig.rx_offset_m[fe],
        fe_tx_offset_m=rig.tx_offset_m[fe], delay_model=rig.rts.delay_model,
        if_hz=rig.rts.if_frequency_hz, **kwargs)


def calibrated(profile: RadarProfile, rig: rs.Rig, range_m: float) -> rs.Rig:
    """The rig with the ideal phase calibration for targets at ``range_m``, from the reference.

    Each FE's echo alone, played with the schedule's RTS delay, gets the phase that puts its
    phase at the virtual array's centroid to 0: the channels are then coherent in the sense the
    solver's responses are normalised in.
    """
    phase = []
    for fe in range(rig.n_front_ends):
        tau = 2.0 * range_m / C0_MPS - 2.0 * rig.distance_m[fe] / C0_MPS - rig.limits.latency_s
        x = reference_snapshot(profile, rig, fe, tau_s=rig.limits.latency_s + tau)
        phase.append(-np.degrees(centroid_phase(x)))
    return replace(rig, cal_phase_deg=np.array(phase))


@pytest.mark.parametrize("name", ["paper", "awr1843boost"])
def test_modeled_response_is_the_reference_snapshot_of_the_fe_alone(name):
    profile = RadarProfile.preset(name)
    rig = bench_rig()
    vectors = profile.front_end_model.vectors(rig, np.arange(4), profile.steering_array)
    for fe in range(4):
        # Read where the echo's received frequency is the one the radar steers with (the
        # sampled sweep's centre): T_air = 2 D / c0 after the centre sample.
        shift = 2.0 * rig.distance_m[fe] / C0_MPS * profile.sample_rate_hz
        x = reference_snapshot(profile, rig, fe,
                               reference_sample=chirp_of(profile).centre_sample + shift)
        x = x * np.exp(-1j * centroid_phase(x))
        np.testing.assert_allclose(vectors[:, fe], x, rtol=0, atol=1e-6)
        # At the centre sample itself the received frequency is S T_air (~0.3 MHz) lower: the
        # phases across the aperture (path spread ~3e-11 s) differ by ~2 pi S T_air dT ~ 5e-5
        # rad, a few 1e-6 once the common phase is removed.
        x = reference_snapshot(profile, rig, fe)
        x = x * np.exp(-1j * centroid_phase(x))
        np.testing.assert_allclose(vectors[:, fe], x, rtol=0, atol=2e-5)


def test_far_fes_without_offsets_are_plane_waves():
    profile = RadarProfile.preset("awr1843boost")
    array = profile.steering_array
    far = rs.Rig.from_angles(KIT.az_deg, KIT.el_deg, distance_m=1e7)
    vectors = profile.front_end_model.vectors(far, np.arange(4), array)
    u, s = direction_cosines(np.radians(far.az_deg), np.radians(far.el_deg))
    # The near-field phase k p^2 / (2 D) is ~1e-8 rad at 10^7 m.
    np.testing.assert_allclose(vectors, plane_waves(array, u, s), rtol=0, atol=1e-7)
    az, el = evaluation_grid()
    modeled = rs.solve_weights(az, el, rig=far, array=array, model=profile.front_end_model)
    plane = rs.solve_weights(az, el, rig=far, array=array)
    np.testing.assert_array_equal(modeled.reason, plane.reason)
    np.testing.assert_allclose(modeled.weights, plane.weights, atol=1e-6)


def test_plan_key_names_the_modeled_geometry():
    profile = RadarProfile.preset("awr1843boost")
    array, model = profile.steering_array, profile.front_end_model
    rig = bench_rig()
    keys = {
        plan_key(rig, array, "exact"),
        plan_key(rig, array, "exact", model),
        plan_key(replace(rig, distance_m=rig.distance_m + 0.01), array, "exact", model),
        plan_key(replace(rig, rx_offset_m=rig.rx_offset_m + 0.001), array, "exact", model),
        plan_key(replace(rig, tx_offset_m=rig.tx_offset_m + 0.001), array, "exact", model),
        plan_key(rig, array, "exact", FrontEndModel(_moved(profile.antennas))),
    }
    assert len(keys) == 6
    # Calibration is not part of the plan.
    assert plan_key(rig, array, "exact", model) == plan_key(
        replace(rig, cal_phase_deg=[1.0, 2.0, 3.0, 4.0]), array, "exact", model)


def _moved(antennas: rs.arrays.Antennas) -> rs.arrays.Antennas:
    return rs.arrays.Antennas(antennas.tx_y_m + 0.001, antennas.tx_z_m, antennas.rx_y_m + 0.001,
                              antennas.rx_z_m)


def test_model_of_another_radar_is_refused():
    with pytest.raises(rs.SolverError, match="same radar profile"):
        rs.solve_weights([0.0], [0.0], rig=bench_rig(),
                         array=RadarProfile.preset("awr1843boost").steering_array,
                         model=RadarProfile.preset("paper").front_end_model)


def bench_errors(profile, rig, fidelity):
    """Schedule the evaluation grid (one target per frame); detected and reference errors."""
    az, el = evaluation_grid()
    sch = build_schedule(tracks(az, el, radar=profile, range_m=RANGE_M), rig, profile,
                         fe_responses="modeled")
    ok = (sch.status[:, 0] == 0)
    dets = SimulatedRadar(profile, rig, fidelity=fidelity, noise=False).process(sch)
    seen = np.full((az.size, 2), np.nan)
    for f in np.flatnonzero(ok):
        d = dets[f]
        strongest = int(np.argmax(d.snr_db))
        seen[f] = d.az_deg[strongest], d.el_deg[strongest]
    ref = np.full((az.size, 2), np.nan)
    vy, vz = virtual_positions(*layout(profile))
    lam = chirp_of(profile).steering_wavelength_m
    for f in np.flatnonzero(ok):
        x = played_snapshot(sch, f, rig, profile)
        ref[f] = bartlett_direction(x, vy, vz, lam, az_range_deg=(-40, 40),
                                    el_range_deg=(-30, 30), grid_step_deg=0.25)
    want = np.column_stack([az, el])
    return ok, np.abs(seen - want), np.abs(ref - want)


@pytest.mark.parametrize("fidelity", ["analytic", "adc"])
@pytest.mark.parametrize("name", ["paper", "awr1843boost"])
def test_exact_weights_put_the_target_on_the_set_angle_on_the_honest_bench(name, fidelity):
    profile = RadarProfile.preset(name)
    rig = calibrated(profile, bench_rig(), RANGE_M)
    ok, detected, reference = bench_errors(profile, rig, fidelity)
    assert ok.all()
    assert detected.max() <= 0.002, detected.max(axis=0)
    assert reference.max() <= 0.002, reference.max(axis=0)


def test_cascade_on_the_honest_bench_is_exact_or_says_why():
    profile = RadarProfile.preset("cascade-12x16")
    rig = calibrated(profile, bench_rig(), RANGE_M)
    az, el = evaluation_grid()
    sol = rs.solve_weights(az, el, rig=rig, array=profile.steering_array,
                           model=profile.front_end_model)
    # Measured: at 1 m the 12x16 cascade (aperture ~17 cm, far field from ~15 m) cannot be
    # given any grid target by these FEs: each gets NO_SOLUTION or SPLIT, and nothing is played.
    assert set(sol.counts()) <= {"NO_SOLUTION", "SPLIT", "OK"}
    ok, detected, reference = bench_errors(profile, rig, "analytic")
    np.testing.assert_array_equal(ok, sol.feasible)
    assert np.all(detected[ok] <= 0.01), detected[ok].max(axis=0)
    assert np.all(reference[ok] <= 0.01), reference[ok].max(axis=0)
