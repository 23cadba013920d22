"""Calibration on the honest bench: the acceptance figures (run: pytest tests/benchmarks ...).

AWR1843BOOST on kit-table1 (FEs 1 m away, near field, IF delay model), Bartlett and TI-style
radars, channel errors injected within +-180 deg and +-1 dB (and +-6 dB on the analytic radar: a
swept channel may then arrive as strong as its reference), 20 seeds, noise off: the largest
error of the recovered relative phases and gains, and the largest detected angle error on the
kit grid after calibration (exact weights for Bartlett, estimator-aware for TI). Printed, and
kept in the benchmark JSON's ``extra_info``.
"""

import numpy as np
import pytest

import rts_scenario as rs
from rts_scenario.calibration import calibrate, grid_errors, simulated_measure
from rts_scenario.radar import RadarProfile
from rts_scenario.radar.simulate import ChannelErrors

SEEDS = range(20)


def sweep(estimator: str, fidelity: str, gain_db: float) -> dict[str, float]:
    radar, rig = RadarProfile.preset("awr1843boost"), rs.Rig.preset("kit-table1")
    method = "exact" if estimator == "bartlett" else "estimator"
    worst = {"phase_deg": 0.0, "gain_db": 0.0, "before_deg": 0.0, "after_deg": 0.0}
    for seed in SEEDS:
        errors = ChannelErrors.random(4, np.random.default_rng(seed), phase_deg=180.0,
                                      gain_db=gain_db)
        measure = simulated_measure(radar, rig, errors, fidelity=fidelity, estimator=estimator)
        before = grid_errors(rig, radar, measure, method, estimator)
        result = calibrate(rig, radar, measure, estimator=estimator)
        phase = np.mod(errors.phase_deg - errors.phase_deg[0] + 180.0, 360.0) - 180.0
        gain = errors.gain_db - errors.gain_db[0]
        calibrated = result.apply(rig)
        after = grid_errors(calibrated, radar, simulated_measure(
            radar, calibrated, errors, fidelity=fidelity, estimator=estimator), method, estimator)
        for key, value in (
            ("phase_deg", np.abs(np.mod(result.phase_deg - phase + 180.0, 360.0) - 180.0).max()),
            ("gain_db", np.abs(result.gain_db - gain).max()),
            ("before_deg", np.nanmax(np.hypot(before[:, 0], before[:, 1]))),
            ("after_deg", np.nanmax(np.hypot(after[:, 0], after[:, 1])))):
            worst[key] = max(worst[key], float(value))
    return worst


@pytest.mark.parametrize(("fidelity", "gain_db"), [("analytic", 1.0), ("adc", 1.0),
                                                    ("analytic", 6.0)])
@pytest.mark.parametrize("estimator", ["bartlett", "ti"])
def test_calibration_accuracy(benchmark, estimator, fidelity, gain_db):
    benchmark.group = "calibration, awr1843boost on kit-table1, 20 seeds"
    worst = benchmark.pedantic(sweep, args=(estimator, fidelity, gain_db), rounds=1,
                               iterations=1)
    benchmark.extra_info.update(worst)
    print(f"\ncalibration {estimator:8s} {fidelity:8s} +-{gain_db:g} dB: "
          f"phase {worst['phase_deg']:.4f} deg, "
          f"gain {worst['gain_db']:.4f} dB, grid before {worst['before_deg']:.2f} deg, "
          f"after {worst['after_deg']:.5f} deg (max over {len(SEEDS)} seeds)")
    assert worst["phase_deg"] <= 0.5
    assert worst["gain_db"] <= 0.05
    assert worst["after_deg"] <= 0.01
