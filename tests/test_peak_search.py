"""The measuring instrument: the independent Bartlett peak search must find known peaks."""

import numpy as np

import rts_scenario as rs
from rts_scenario.peak_search import find_peak, snapshot


def test_single_source_peak_is_its_direction(array):
    az = np.array([-12.3, 0.0, 4.56, 17.0])
    el = np.array([7.7, 0.0, -3.21, -11.0])
    x = snapshot(array, np.eye(4), az, el)
    peak_az, peak_el = find_peak(array, x)
    np.testing.assert_allclose(peak_az, az, atol=1e-6)
    np.testing.assert_allclose(peak_el, el, atol=1e-6)


def test_symmetric_pair_peaks_in_the_middle():
    # Two equal sources mirrored about boresight: by the symmetry of the centro-symmetric
    # paper array the sum peaks exactly on boresight.
    arr = rs.VirtualArray.preset("paper")
    x = snapshot(arr, [[1.0, 1.0]], [-6.0, 6.0], [2.0, 2.0])
    peak_az, peak_el = find_peak(arr, x)
    assert abs(peak_az[0]) < 1e-6
    assert abs(peak_el[0] - 2.0) < 1e-6


def test_finds_the_global_not_the_nearest_peak():
    arr = rs.VirtualArray.preset("awr1843boost")
    # Strong source far from a weak one: the global maximum is the strong one.
    x = snapshot(arr, [[0.3, 1.0]], [-25.0, 20.0], [0.0, 5.0])
    peak_az, peak_el = find_peak(arr, x)
    assert abs(peak_az[0] - 20.0) < 0.5 and abs(peak_el[0] - 5.0) < 2.0
