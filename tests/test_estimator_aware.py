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


def test_a_user_estimator_installed_as_an_entry_point(tmp_path, monkeypatch):
    """An estimator from another package: scenes name it, estimator-aware weights aim at it,
    calibration fits with it."""
    import sys
    from importlib.metadata import EntryPoint
    from pathlib import Path

    import numpy as np
    import pytest

    import rts_scenario.registry as registry
    from rts_scenario.calibration import calibrate, simulated_measure
    from rts_scenario.pipeline import RunOptions, run_scene
    from rts_scenario.radar import RadarProfile
    from rts_scenario.radar.angle import ESTIMATOR_ENTRY_POINT_GROUP
    from rts_scenario.radar.simulate import ChannelErrors
    from rts_scenario.scenario import load_scenario
    from rts_scenario.scenario.loader import scenario_schema

    # A TI-style radar with a finer azimuth FFT (its own interpolation bias).
    (tmp_path / "lab_estimators.py").write_text(
        "from rts_scenario.radar.angle import TiStyle\n\n"
        "class FineTi(TiStyle):\n"
        "    def __init__(self, array):\n"
        "        super().__init__(array, fft_size=256)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "lab_estimators", raising=False)
    plugin = EntryPoint(name="fine-ti", value="lab_estimators:FineTi",
                        group=ESTIMATOR_ENTRY_POINT_GROUP)
    real = registry.entry_points
    monkeypatch.setattr(registry, "entry_points", lambda *, group: [plugin] if group ==
                        ESTIMATOR_ENTRY_POINT_GROUP else real(group=group))
    scenario_schema.cache_clear()
    try:
        path = Path(__file__).resolve().parents[1] / "scenarios" / "cut_in.scenario.yaml"
        scene = load_scenario(path, {"radar.estimator": "fine-ti", "radar.noise": False,
                                     "radar.fidelity": "analytic"})
        aware = run_scene(scene, RunOptions(method="estimator")).report
        assert aware.passed and aware.errors["az_deg"].max < 0.01
        with pytest.raises(rs.RtsError, match="fine-ti"):  # the error lists it as valid
            load_scenario(path, {"radar.estimator": "music"})
        awr = RadarProfile.preset("awr1843boost")
        errors = ChannelErrors.random(4, np.random.default_rng(1), phase_deg=180.0, gain_db=1.0)
        result = calibrate(KIT, awr, simulated_measure(awr, KIT, errors, estimator="fine-ti"),
                           estimator="fine-ti")
        want = np.mod(errors.phase_deg - errors.phase_deg[0] + 180.0, 360.0) - 180.0
        assert np.abs(np.mod(result.phase_deg - want + 180.0, 360.0) - 180.0).max() < 0.5
    finally:
        scenario_schema.cache_clear()
