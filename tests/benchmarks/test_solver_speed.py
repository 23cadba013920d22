"""Solver throughput (run: pytest tests/benchmarks --benchmark-json=benchmarks.json)."""

import numpy as np
import pytest

import rts_scenario as rs

N = 1_000_000


@pytest.fixture(scope="module")
def targets():
    rng = np.random.default_rng(0)
    return rng.uniform(-3.0, 3.0, N), rng.uniform(-6.0, 6.0, N)


@pytest.mark.parametrize("array_name", ["paper", "awr1843boost"])
@pytest.mark.parametrize("method", ["paper", "exact"])
def test_solve_weights_1e6(benchmark, targets, method, array_name):
    rig = rs.Rig.preset("kit-table1")
    array = rs.VirtualArray.preset(array_name)
    az, el = targets
    rs.solve_weights(az[:64], el[:64], rig=rig, array=array, method=method)
    benchmark.group = f"solve_weights N=1e6 {array_name}"
    benchmark.extra_info["targets"] = N
    sol = benchmark.pedantic(
        rs.solve_weights, args=(az, el), kwargs={"rig": rig, "array": array, "method": method},
        rounds=3, iterations=1,
    )
    assert sol.feasible.all()
    benchmark.extra_info["target_frames_per_s"] = N / benchmark.stats.stats.min


def test_solve_weights_wide_grid(benchmark):
    rig = rs.Rig.preset("wide-3x5")
    array = rs.VirtualArray.preset("awr1843boost")
    rng = np.random.default_rng(1)
    az, el = rng.uniform(-20, 20, N), rng.uniform(-8, 8, N)
    rs.solve_weights(az[:64], el[:64], rig=rig, array=array)
    benchmark.group = "solve_weights N=1e6 wide-3x5 grid"
    sol = benchmark.pedantic(rs.solve_weights, args=(az, el),
                             kwargs={"rig": rig, "array": array}, rounds=3, iterations=1)
    assert sol.feasible.all()
    benchmark.extra_info["target_frames_per_s"] = N / benchmark.stats.stats.min
