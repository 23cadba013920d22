"""Hundreds of targets: crowding found without pairwise arrays, estimators in bounded blocks.

References are brute force: every pair compared on the circular range and Doppler axes, and
the estimator run on each snapshot alone.
"""

import numpy as np
import pytest

from rts_scenario.arrays import VirtualArray, direction_cosines
from rts_scenario.radar.angle import Bartlett2D
from rts_scenario.radar.simulate import _close_pairs


def brute_force_close(frame, r, d, n_r, n_d, within):
    def circular(x, n):
        return np.abs(np.mod(x[:, None] - x[None, :] + n / 2, n) - n / 2)

    near = ((frame[:, None] == frame[None, :]) & (circular(r, n_r) < within)
            & (circular(d, n_d) < within))
    np.fill_diagonal(near, False)
    return np.flatnonzero(near.any(axis=1))


@pytest.mark.parametrize("seed", range(6))
def test_close_pairs_match_every_pair_compared(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 600))
    n_r, n_d = 256, 64
    frame = rng.integers(0, 5, n)
    # Clusters, entries at both ends of the range axis and of the Doppler axis, exact ties.
    r = np.mod(rng.choice([rng.uniform(0, n_r, n), rng.normal(1.0, 2.0, n)], axis=0), n_r)
    r[: n // 10] = rng.choice([0.0, 0.5, n_r - 0.5, n_r - 2.0], n // 10)
    d = np.mod(rng.uniform(-n_d / 2, n_d / 2, n) + n_d / 2, n_d) - n_d / 2
    d[n // 10 : n // 5] = rng.choice([-n_d / 2, n_d / 2 - 1.0, 0.0], n // 5 - n // 10)
    got = _close_pairs(frame, r, d, n_r, n_d, 2.5)
    np.testing.assert_array_equal(got, brute_force_close(frame, r, d, n_r, n_d, 2.5))


def test_close_pairs_cost_grows_with_the_entries_not_their_square():
    rng = np.random.default_rng(1)
    n = 200_000  # a 10,000 x 10,000 pair array would be 40 GB of booleans
    frame = np.repeat(np.arange(100), n // 100)
    r, d = rng.uniform(0, 4096, n), rng.uniform(-64, 64, n)
    got = _close_pairs(frame, r, d, 4096, 128, 2.5)
    # Two entries of a frame are close with probability about (5 / 4096) * (5 / 128).
    expected = n * (2000 - 1) * (5 / 4096) * (5 / 128)
    assert 0.8 * expected < got.size < 1.2 * expected


def test_bartlett_in_blocks_is_bartlett_on_each_snapshot():
    array = VirtualArray.preset("awr1843boost")
    estimator = Bartlett2D(array)
    rng = np.random.default_rng(2)
    d = 2 * Bartlett2D.BLOCK + 37
    u, s = rng.uniform(-0.5, 0.5, d), rng.uniform(-0.3, 0.3, d)
    k = array.wavenumber_rad_per_m
    x = np.exp(1j * k * (np.outer(u, array.y_m) + np.outer(s, array.z_m)))
    x += 0.05 * (rng.standard_normal(x.shape) + 1j * rng.standard_normal(x.shape))
    whole = estimator(x)
    for i in rng.choice(d, 25, replace=False):
        alone = estimator(x[i : i + 1])
        rows = whole.source == i
        np.testing.assert_allclose(whole.az_deg[rows], alone.az_deg, atol=1e-9)
        np.testing.assert_allclose(whole.el_deg[rows], alone.el_deg, atol=1e-9)
    assert np.all(np.diff(whole.source) >= 0) and whole.source[-1] == d - 1


def brute_force_assignment(frame_of, values, truth, tol, gate):
    """Dense per frame: every detection against every target, the Hungarian method."""
    from scipy.optimize import linear_sum_assignment

    total, matched = 0.0, 0
    for f in np.unique(frame_of):
        rows = np.flatnonzero(frame_of == f)
        norm = (values[rows][:, None, :] - truth[f][None, :, :]) / tol
        cost = (norm**2).sum(-1)
        ok = (np.abs(norm) <= gate).all(-1)
        r, k = linear_sum_assignment(np.where(ok, cost, 1e9))
        good = ok[r, k]
        total += cost[r, k][good].sum()
        matched += int(good.sum())
    return total, matched


@pytest.mark.parametrize("seed", range(5))
def test_association_by_range_gates_matches_the_dense_hungarian(seed):
    from rts_scenario.check import _assign, _range_candidates

    rng = np.random.default_rng(seed)
    n_frames, n_targets = 7, int(rng.integers(1, 120))
    tol = np.array([0.5, 0.3])  # range, azimuth
    # Targets in clumps (so detections compete), detections near some of them plus clutter.
    truth = np.stack([rng.choice([20.0, 21.0, 40.0], (n_frames, n_targets))
                      + rng.uniform(0, 2.0, (n_frames, n_targets)),
                      rng.uniform(-2, 2, (n_frames, n_targets))], axis=-1)
    frame_of, values = [], []
    for f in range(n_frames):
        picked = rng.choice(n_targets, int(rng.integers(0, n_targets + 1)), replace=True)
        values.append(truth[f, picked] + rng.normal(0, 0.4, (picked.size, 2)) * tol)
        frame_of += [f] * picked.size
        clutter = int(rng.integers(0, 5))
        values.append(np.stack([rng.uniform(0, 60, clutter), rng.uniform(-3, 3, clutter)], 1))
        frame_of += [f] * clutter
    frame_of, values = np.array(frame_of, dtype=np.int64), np.concatenate(values)
    det, target = _range_candidates(frame_of, values[:, 0], truth[..., 0], 3.0 * tol[0])
    norm = (values[det] - truth[frame_of[det], target]) / tol
    inside = (np.abs(norm) <= 3.0).all(-1)
    det, target, cost = det[inside], target[inside], (norm[inside] ** 2).sum(-1)
    pair = _assign(frame_of, det, target, cost, n_targets)
    # A detection at most once, a target-frame at most once.
    assert np.unique(det[pair]).size == pair.size
    assert np.unique(frame_of[det[pair]] * n_targets + target[pair]).size == pair.size
    total, matched = brute_force_assignment(frame_of, values, truth, tol, 3.0)
    assert pair.size == matched
    assert cost[pair].sum() == pytest.approx(total, rel=1e-9, abs=1e-9)


@pytest.mark.parametrize("name", ["awr1843boost", "paper"])
def test_bartlett_grid_spectrum_and_peaks_match_the_direct_sums(name):
    """The spectrum factored by height levels is the direct beam sum; its local maxima are
    those of an 8-neighbour comparison; the refined peak is where the beam is largest."""
    array = VirtualArray.preset(name)
    estimator = Bartlett2D(array)
    rng = np.random.default_rng(3)
    k = array.wavenumber_rad_per_m
    # Two plane waves of different strength inside the grid, a little noise.
    x = sum(amp * np.exp(1j * k * (np.outer(rng.uniform(-0.6, 0.6, 40), array.y_m)
                                   + np.outer(rng.uniform(-0.4, 0.4, 40), array.z_m)))
            for amp in (1.0, 0.4))
    x = x + 0.01 * (rng.standard_normal(x.shape) + 1j * rng.standard_normal(x.shape))
    steer = np.exp(1j * k * (np.outer(estimator.grid_u, array.y_m)
                             + np.outer(estimator.grid_s, array.z_m)))
    direct = np.abs(x @ steer.conj().T) ** 2  # (D, G)
    n_u, n_s = estimator.shape
    level = (x @ estimator._row_beams).reshape(len(x), -1, n_u)
    factored = np.abs(np.matmul(level.transpose(0, 2, 1), estimator._level_phase)) ** 2
    np.testing.assert_allclose(factored.reshape(len(x), -1), direct, rtol=1e-12,
                               atol=1e-12 * direct.max())
    spec = direct.reshape(len(x), n_u, n_s)
    padded = np.pad(spec, ((0, 0), (1, 1), (1, 1)), constant_values=-1.0)
    peaks = np.ones(spec.shape, dtype=bool)
    for du in (-1, 0, 1):
        for ds in (-1, 0, 1):
            peaks &= spec >= padded[:, 1 + du : n_u + 1 + du, 1 + ds : n_s + 1 + ds]
    est = estimator(x)
    strongest = np.where(peaks.reshape(len(x), -1), direct, -1.0).argmax(axis=1)
    first = np.unique(est.source, return_index=True)[1]
    # Refined from the strongest grid peak: the beam there is at least the grid's best.
    u, s = direction_cosines(np.radians(est.az_deg[first]), np.radians(est.el_deg[first]))
    beam = np.abs(np.einsum("dm,dm->d", x[est.source[first]], np.exp(
        1j * k * (np.outer(u, array.y_m) + np.outer(s, array.z_m))).conj())) ** 2
    assert np.all(beam >= direct[est.source[first], strongest[est.source[first]]] * (1 - 1e-9))
