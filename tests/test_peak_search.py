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


def test_kept_search_grid_gives_the_same_bits_as_a_fresh_one(monkeypatch):
    from rts_scenario import peak_search

    arr = rs.VirtualArray.preset("awr1843boost")
    x = snapshot(arr, [[1.0, 0.4j], [0.7, 0.2]], [[-9.1, 13.0], [3.3, -4.0]],
                 [[2.5, -8.0], [0.0, 6.0]])
    window = {"az_range_deg": (-14.0, 15.0), "el_range_deg": (-12.0, 11.0)}
    peak_search._search_grid.cache_clear()
    first = find_peak(arr, x, **window)
    # An equal array built anew finds its grid kept; the answer is bit for bit the same.
    again = find_peak(rs.VirtualArray.preset("awr1843boost"), x, **window)
    assert peak_search._search_grid.cache_info().hits == 1
    monkeypatch.setattr(peak_search, "_MAX_CACHED_GRID_BYTES", 0)  # every grid built anew
    fresh = find_peak(arr, x, **window)
    assert peak_search._search_grid.cache_info().hits == 1
    for got in (again, fresh):
        np.testing.assert_array_equal(got[0], first[0])
        np.testing.assert_array_equal(got[1], first[1])
