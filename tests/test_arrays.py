import numpy as np
import pytest

import rts_scenario as rs
from rts_scenario.arrays import (
    Antennas,
    angles_from_cosines,
    direction_cosines,
    wavelength_from_chirp,
)

C0 = 299_792_458.0
LAM = C0 / (77e9 + 0.5e9)


def test_wavelength_at_chirp_centre():
    assert wavelength_from_chirp(77e9, 1e9) == pytest.approx(C0 / 77.5e9, rel=1e-15)
    assert rs.VirtualArray.preset("paper").wavelength_m == pytest.approx(LAM, rel=1e-15)


def test_paper_preset_layout():
    arr = rs.VirtualArray.preset("paper")
    # 4 RX along y and 3 TX along z, lambda/2 apart: a 4 x 3 grid, centred.
    ys = sorted(set(np.round(arr.y_m / LAM, 9)))
    zs = sorted(set(np.round(arr.z_m / LAM, 9)))
    assert ys == [-0.75, -0.25, 0.25, 0.75]
    assert zs == [-0.5, 0.0, 0.5]
    assert arr.n_elements == 12
    assert arr.is_centrosymmetric


def test_awr1843boost_preset_layout():
    arr = rs.VirtualArray.preset("awr1843boost")
    pos = {(round(y / LAM, 9), round(z / LAM, 9)) for y, z in zip(arr.y_m, arr.z_m, strict=True)}
    # Before centring: azimuth row y = 0 .. 3.5 lambda at z = 0 (TX0 and TX2), elevated row
    # y = 1 .. 2.5 lambda at z = lambda/2 (TX1). Centroid: y = 1.75 lambda, z = lambda/6.
    azimuth_row = {(round(y - 1.75, 9), round(-1 / 6, 9)) for y in np.arange(8) * 0.5}
    elevated_row = {(round(y - 1.75, 9), round(0.5 - 1 / 6, 9)) for y in 1 + np.arange(4) * 0.5}
    assert pos == azimuth_row | elevated_row
    assert arr.n_elements == 12
    assert not arr.is_centrosymmetric


def uneven_mirror_counts():
    """Three positions 120 deg apart, each twice, and their mirrors once: every element has a
    mirror and the centroid is the origin, but the layout is not its point reflection."""
    ang = np.radians([0.0, 120.0, 240.0])
    y, z = 0.6 * LAM * np.cos(ang), 0.6 * LAM * np.sin(ang)
    return rs.VirtualArray.from_positions(np.r_[y, y, -y], np.r_[z, z, -z], wavelength_m=LAM)


def test_mirrored_positions_with_uneven_counts_are_not_centrosymmetric():
    arr = uneven_mirror_counts()
    # The sum of the steering vectors (the response to a source on the boresight) is complex.
    assert abs(arr.steering_vector(30.0, -40.0).sum().imag) > 1.0
    assert not arr.is_centrosymmetric
    doubled = rs.VirtualArray.from_positions(np.r_[arr.y_m, -arr.y_m], np.r_[arr.z_m, -arr.z_m],
                                             wavelength_m=LAM)
    assert doubled.is_centrosymmetric  # three elements at each position, three at its mirror


def test_custom_array_from_tx_rx_matches_preset():
    half = LAM / 2
    arr = rs.VirtualArray.from_tx_rx(
        [0, 0, 0], [0, half, 2 * half], np.arange(4) * half, [0, 0, 0, 0],
        fc_hz=77e9, bandwidth_hz=1e9,
    )
    ref = rs.VirtualArray.preset("paper")
    np.testing.assert_allclose(arr.y_m, ref.y_m, atol=1e-15)
    np.testing.assert_allclose(arr.z_m, ref.z_m, atol=1e-15)


def test_positions_are_centred():
    arr = rs.VirtualArray.from_positions([1.0, 2.0, 4.0], [0.0, 1.0, 5.0], wavelength_m=0.004)
    assert arr.y_m.mean() == pytest.approx(0.0, abs=1e-15)
    assert arr.z_m.mean() == pytest.approx(0.0, abs=1e-15)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"y_m": [0, 1], "z_m": [0], "wavelength_m": 0.004}, "same length"),
        ({"y_m": [], "z_m": [], "wavelength_m": 0.004}, "at least one element"),
        ({"y_m": [0, np.nan], "z_m": [0, 0], "wavelength_m": 0.004}, "finite"),
        ({"y_m": [0, 1], "z_m": [0, 0], "wavelength_m": -1.0}, "wavelength_m"),
    ],
)
def test_bad_custom_arrays(kwargs, message):
    with pytest.raises(rs.ArrayError, match=message):
        rs.VirtualArray.from_positions(**kwargs)


def test_unknown_preset_lists_valid_names():
    with pytest.raises(rs.ArrayError, match="paper, awr1843boost"):
        rs.VirtualArray.preset("awr9999")


def test_steering_vector_matches_definition(array):
    az, el = 12.3, -4.5
    a = array.steering_vector(az, el)[0]
    k = 2 * np.pi / array.wavelength_m
    phase = k * (array.y_m * np.cos(np.radians(el)) * np.sin(np.radians(az))
                 + array.z_m * np.sin(np.radians(el)))
    np.testing.assert_allclose(a, np.exp(1j * phase), rtol=1e-13)


def test_response_of_source_at_look_direction_is_element_count(array):
    f = array.response([3.0, -7.0], [2.0, 9.0], [3.0, -7.0], [2.0, 9.0])
    np.testing.assert_allclose(np.diag(f), array.n_elements, rtol=1e-13)


def test_response_is_real_for_centrosymmetric_array():
    arr = rs.VirtualArray.preset("paper")
    f = arr.response([1.0, 5.0], [-3.0, 4.0], [-5.4, 4.5, -3.4, 3.8], [-8.8, -7.7, 8.4, 9.9])
    assert np.abs(f.imag).max() < 1e-12 * np.abs(f).max()


def test_source_response_derivatives_match_finite_differences(array, rng):
    src_az, src_el = np.array([-5.4, 4.5, -3.4, 3.8]), np.array([-8.8, -7.7, 8.4, 9.9])
    u_src, s_src = direction_cosines(np.radians(src_az), np.radians(src_el))
    kernel = array.source_response(u_src, s_src)
    u = rng.uniform(-0.3, 0.3, 7)
    s = rng.uniform(-0.3, 0.3, 7)
    f, f_u, f_s, f_uu, f_us, f_ss = kernel.evaluate(u, s)

    def brute(uu, ss):  # a(u, s)^H a(source), written out
        k = array.wavenumber_rad_per_m
        look = np.exp(1j * k * (np.outer(uu, array.y_m) + np.outer(ss, array.z_m)))
        src = np.exp(1j * k * (np.outer(u_src, array.y_m) + np.outer(s_src, array.z_m)))
        return (look.conj() @ src.T).T

    h = 1e-6
    np.testing.assert_allclose(f, brute(u, s), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(f_u, (brute(u + h, s) - brute(u - h, s)) / (2 * h), atol=1e-5)
    np.testing.assert_allclose(f_s, (brute(u, s + h) - brute(u, s - h)) / (2 * h), atol=1e-5)
    h = 1e-4
    np.testing.assert_allclose(
        f_uu, (brute(u + h, s) - 2 * brute(u, s) + brute(u - h, s)) / h**2, atol=1e-3
    )
    np.testing.assert_allclose(
        f_ss, (brute(u, s + h) - 2 * brute(u, s) + brute(u, s - h)) / h**2, atol=1e-3
    )
    np.testing.assert_allclose(
        f_us,
        (brute(u + h, s + h) - brute(u + h, s - h) - brute(u - h, s + h) + brute(u - h, s - h))
        / (4 * h * h),
        atol=1e-3,
    )


def test_direction_cosines_round_trip(rng):
    az = rng.uniform(-80, 80, 100)
    el = rng.uniform(-85, 85, 100)
    back_az, back_el = angles_from_cosines(*direction_cosines(np.radians(az), np.radians(el)))
    np.testing.assert_allclose(np.degrees(back_az), az, atol=1e-9)
    np.testing.assert_allclose(np.degrees(back_el), el, atol=1e-9)


def test_sinc_apertures():
    paper = rs.VirtualArray.preset("paper")
    awr = rs.VirtualArray.preset("awr1843boost")
    # N_rx d_y = 4 * lambda/2 and N_tx d_z = 3 * lambda/2 for the paper's model.
    np.testing.assert_allclose(np.array(paper.sinc_aperture_m()) / LAM, [2.0, 1.5])
    np.testing.assert_allclose(np.array(awr.sinc_aperture_m()) / LAM, [4.0, 1.0])


def test_antenna_presets_are_physical_and_keep_the_virtual_arrays():
    for name in ("paper", "awr1843boost"):
        ant = Antennas.preset(name, LAM)
        virtual = ant.virtual_array(fc_hz=77e9, bandwidth_hz=1e9)
        preset = rs.VirtualArray.preset(name)
        np.testing.assert_allclose(virtual.y_m, preset.y_m, atol=1e-15)
        np.testing.assert_allclose(virtual.z_m, preset.z_m, atol=1e-15)
        # The reference point is the virtual array's centroid: TX and RX centroids opposite.
        assert ant.tx_y_m.mean() + ant.rx_y_m.mean() == pytest.approx(0.0, abs=1e-15)
        assert ant.tx_z_m.mean() + ant.rx_z_m.mean() == pytest.approx(0.0, abs=1e-15)
    awr = Antennas.preset("awr1843boost", LAM)
    # TX group beside the RX group: centroids 10 mm apart; TX0, TX2 at the RX row's height.
    assert awr.rx_y_m.mean() - awr.tx_y_m.mean() == pytest.approx(0.010, abs=1e-12)
    assert awr.tx_z_m[[0, 2]].tolist() == pytest.approx(awr.rx_z_m[:2].tolist(), abs=1e-15)


def test_cascade_preset_is_tis_12_by_16_layout():
    ant = Antennas.preset("cascade-12x16", LAM)
    assert (ant.n_tx, ant.n_rx) == (12, 16)
    virtual = ant.virtual_array(fc_hz=77e9, bandwidth_hz=1e9)
    assert virtual.n_elements == 192
    half = LAM / 2
    azimuth_row = np.isclose(virtual.z_m, virtual.z_m.min())
    cells = np.unique(np.round(virtual.y_m[azimuth_row] / half, 6))
    # 9 TX 2 lambda apart, RX groups at 0..3, 11..14, 46..49, 50..53: 86 contiguous positions.
    assert cells.size == 86 and np.all(np.diff(cells) == pytest.approx(1.0))
    rows = np.unique(np.round((virtual.z_m - virtual.z_m.min()) / half, 6))
    assert rows.tolist() == [0.0, 1.0, 4.0, 6.0]
    assert ant.extent_m > 50 * half


def test_antennas_reject_bad_positions():
    with pytest.raises(rs.ArrayError, match="same length"):
        Antennas([0.0, 1.0], [0.0], [0.0], [0.0])
    with pytest.raises(rs.ArrayError, match="unknown antenna preset 'x'.*cascade-12x16"):
        Antennas.preset("x", LAM)
