"""The plots' data (`Envelope`, `PlotData`: bounded whatever the scene's length) and drawing."""

from pathlib import Path

import numpy as np
import pytest
from scene_helpers import write_scene

from rts_scenario import cli
from rts_scenario.kinematics import compute_tracks
from rts_scenario.plot_data import Envelope, PlotData
from rts_scenario.scenario import load_scenario

RATE_HZ = 20.0


def cycles(plot: PlotData, n: int, batch: int = 37, spike_at: int | None = None,
           missed_at: int | None = None) -> None:
    """Feed ``plot`` ``n`` judged cycles of 2 targets, small errors, in batches of ``batch``.

    Target 1's range error at cycle ``spike_at`` is 5 m (far out of any tolerance); at cycle
    ``missed_at`` target 0 is checkable and not detected.
    """
    rng = np.random.default_rng(7)
    for first in range(0, n, batch):
        rows = np.arange(first, min(first + batch, n))
        errors = {key: rng.normal(0.0, 0.01, (rows.size, 2)) for key in plot.errors}
        errors["range_m"][rows == spike_at, 1] = 5.0
        detected = np.ones((rows.size, 2), dtype=bool)
        detected[rows == missed_at, 0] = False
        plot.add_cycles(rows / RATE_HZ, np.ones_like(detected), detected, errors)


def test_plot_data_for_a_scene_ten_times_as_long_holds_as_many_points():
    # A 30-minute scene held every frame's errors, positions and channels until the plots
    # were drawn: peak memory grew with the scene under --plot.
    short, long = PlotData(2, buckets=64), PlotData(2, buckets=64)
    cycles(short, 1000)
    cycles(long, 10_000)
    assert long.nbytes == short.nbytes
    for plot in (short, long):
        t, err = plot.errors["range_m"].samples()
        assert 64 < np.count_nonzero(~np.isnan(t[:, 0])) <= 2 * 64
    assert long.errors["range_m"].stride > short.errors["range_m"].stride


def test_an_error_out_of_tolerance_and_a_miss_stay_after_thinning():
    plot = PlotData(2, buckets=64)
    cycles(plot, 10_000, spike_at=6_543, missed_at=8_021)
    t, err = plot.errors["range_m"].samples()
    assert plot.errors["range_m"].stride > 1  # thinned
    kept = err[:, 1] == 5.0
    np.testing.assert_array_equal(t[kept, 1], [6_543 / RATE_HZ])
    t_missed, _ = plot.missed.samples()
    np.testing.assert_array_equal(t_missed[~np.isnan(t_missed[:, 0]), 0], [8_021 / RATE_HZ])
    assert np.isnan(t_missed[:, 1]).all()


@pytest.mark.parametrize("batch", [1, 13, 400])
def test_an_envelope_keeps_each_bucket_s_extremes(batch):
    # Against every bucket's least and greatest value taken from all the samples at once.
    rng = np.random.default_rng(3)
    n, buckets = 2_345, 16
    values = rng.normal(size=(n, 3))
    values[rng.random((n, 3)) < 0.2] = np.nan  # no sample there (a target absent)
    envelope = Envelope(3, buckets=buckets)
    for first in range(0, n, batch):
        envelope.add(np.arange(first, min(first + batch, n)) / RATE_HZ, values[first:first + batch])
    stride = envelope.stride
    assert stride == 256  # the least power of two that fits 2345 samples in 16 buckets
    padded = np.full((-(-n // stride) * stride, 3), np.nan)
    padded[:n] = values
    per_bucket = padded.reshape(-1, stride, 3)
    t, kept = envelope.samples()
    np.testing.assert_array_equal(np.nanmin(kept.reshape(-1, 2, 3), axis=1),
                                  np.nanmin(per_bucket, axis=1))
    np.testing.assert_array_equal(np.nanmax(kept.reshape(-1, 2, 3), axis=1),
                                  np.nanmax(per_bucket, axis=1))
    # Each value kept with its own time.
    has = ~np.isnan(t)
    rows = np.rint(t[has] * RATE_HZ).astype(int)
    np.testing.assert_array_equal(values[rows, np.nonzero(has)[1]], kept[has])


def test_an_envelope_by_time_keeps_a_path_s_first_and_last_sample_in_order():
    n = 5_000
    t = np.arange(n) / RATE_HZ
    x = np.where((t >= 10.0) & (t < 200.0), t, np.nan)[:, None]  # present from 10 s to 200 s
    envelope = Envelope(1, by_time=True, buckets=32)
    for first in range(0, n, 64):
        envelope.add(t[first:first + 64], x[first:first + 64])
    kept_t, kept = envelope.samples()
    path = kept_t[~np.isnan(kept_t)]
    assert path[0] == 10.0 and path[-1] == t[np.flatnonzero(t < 200.0)[-1]]
    assert np.all(np.diff(path) > 0)
    np.testing.assert_array_equal(kept[~np.isnan(kept)], path)


def test_a_stationary_target_is_drawn_where_it_stands(tmp_path, monkeypatch):
    # A stationary target was in the legend, drawn as a line of no length: nowhere to be seen.
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt

    from rts_scenario import plots

    drawn = {}

    def no_drawing(fig, path):  # what is drawn is the question, not the pixels
        drawn[path.name] = fig.axes
        return path

    monkeypatch.setattr(plots, "_save", no_drawing)
    scene = write_scene(tmp_path, [
        {"name": "parked", "kind": "car", "rcs": {"rcs_dbsm": 10.0},
         "motion": {"type": "stationary", "position_m": [30.0, 2.0, 0.6]}}],
        name="parked.scenario.yaml", duration_s=0.5)
    assert cli.main(["run", str(scene), "--plot", str(tmp_path / "p")]) in (0, 1)
    x_m, y_m = compute_tracks(load_scenario(scene)).position_m[0, 0, :2]
    top = drawn["test-scene.png"][0]
    marks = np.concatenate([c.get_offsets() for c in top.collections])
    assert np.any(np.all(np.isclose(marks, [y_m, x_m]), axis=1))
    plt.close("all")


def test_a_scene_without_targets_gets_its_plots(tmp_path):
    # An empty bench: series of no column; taking their samples raised (exit 3, no verdict).
    root = Path(__file__).resolve().parents[1]
    assert cli.main(["run", str(root / "scenarios" / "empty_bench.scenario.yaml"), "--plot",
                     str(tmp_path / "plots")]) == 0
    assert sorted(p.name for p in (tmp_path / "plots").iterdir()) == [
        "empty-bench-errors.png", "empty-bench-scene.png", "empty-bench-schedule.png"]


def test_an_envelope_of_no_column_takes_any_number_of_samples():
    # A scene without targets longer than its buckets: merging them raised (exit 3).
    envelope = Envelope(0, buckets=4)
    for start in range(0, 40, 7):
        envelope.add(np.arange(start, start + 7) * 0.05, np.zeros((7, 0)))
    t, v = envelope.samples()
    assert envelope.stride > 1 and t.shape[1] == v.shape[1] == 0
