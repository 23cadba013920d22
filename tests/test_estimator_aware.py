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
