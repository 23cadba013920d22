"""Estimator-aware weights: the radar's own estimator reads the set angle."""

import numpy as np

import rts_scenario as rs
from rts_scenario.evaluation import evaluation_grid
from rts_scenario.solver.estimator_aware import estimator_weights

KIT = rs.Rig.preset("kit-table1")


def test_for_a_bartlett_radar_the_exact_weights_are_already_right(array):
    az, el = evaluation_grid()
    exact = rs.solve_weights(az, el, rig=KIT, array=array, method="exact")
    aware = estimator_weights(az, el, rig=KIT, array=array, estimator="bartlett")
    assert aware.method == "estimator" and np.all(aware.feasible == exact.feasible)
    np.testing.assert_allclose(aware.weights, exact.weights, atol=1e-4)


def test_ti_weights_differ_from_bartlett_weights_and_converge(array):
    az, el = evaluation_grid()
    aware = estimator_weights(az, el, rig=KIT, array=array, estimator="ti")
    exact = rs.solve_weights(az, el, rig=KIT, array=array, method="exact")
    assert aware.feasible.all()
    assert np.abs(aware.weights - exact.weights).max() > 1e-3


def test_unknown_estimator_lists_the_valid_ones():
    import pytest

    with pytest.raises(rs.RtsError, match="valid angle estimators: bartlett, ti"):
        estimator_weights([0.0], [0.0], rig=KIT, array=rs.VirtualArray.preset("paper"),
                          estimator="music")


def test_a_run_with_estimator_aware_weights_for_a_ti_radar():
    from pathlib import Path

    from rts_scenario.pipeline import RunOptions, run_scene
    from rts_scenario.scenario import load_scenario

    path = Path(__file__).resolve().parents[1] / "scenarios" / "cut_in.scenario.yaml"
    scene = load_scenario(path, {"radar.estimator": "ti", "radar.noise": False,
                                 "radar.fidelity": "analytic"})
    aware = run_scene(scene, RunOptions(method="estimator")).report
    exact = run_scene(scene, RunOptions(method="exact")).report
    assert aware.passed and exact.passed
    # The TI-style estimator reads Bartlett-exact weights off; aimed weights land on the angle.
    assert aware.errors["az_deg"].max < 0.01 < exact.errors["az_deg"].max
