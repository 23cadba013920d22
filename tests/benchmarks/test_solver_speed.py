"""Solver throughput (run: pytest tests/benchmarks --benchmark-json=benchmarks.json)."""

import numpy as np
import pytest
from cascade_arrays import compact_cascade, ti_cascade

import rts_scenario as rs
from rts_scenario.solver.plan import build_plan

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


# A quad 4 deg x 6 deg wide: narrow enough for the compact cascade to synthesize most targets,
# so the split check over the whole field of view runs on them.
NARROW_AZ_DEG, NARROW_EL_DEG = [-2.0, 2.0, -2.0, 2.0], [-3.0, -3.0, 3.0, 3.0]
N_CASCADE = 100_000


def test_solve_weights_compact_cascade(benchmark):
    rig = rs.Rig.from_angles(NARROW_AZ_DEG, NARROW_EL_DEG, name="narrow")
    array = compact_cascade()
    rng = np.random.default_rng(2)
    az, el = rng.uniform(-1.8, 1.8, N_CASCADE), rng.uniform(-2.7, 2.7, N_CASCADE)
    rs.solve_weights(az[:64], el[:64], rig=rig, array=array)
    benchmark.group = "solve_weights N=1e5 12x16 compact cascade"
    sol = benchmark.pedantic(rs.solve_weights, args=(az, el),
                             kwargs={"rig": rig, "array": array}, rounds=3, iterations=1)
    assert sol.feasible.any() and (sol.reason == rs.Reason.SPLIT).any()
    benchmark.extra_info["target_frames_per_s"] = N_CASCADE / benchmark.stats.stats.min


@pytest.mark.parametrize("rig_name", ["kit-table1", "wide-3x5"])
@pytest.mark.parametrize("make_array", [compact_cascade, ti_cascade])
def test_plan_cascade(benchmark, rig_name, make_array):
    rig = rs.Rig.preset(rig_name)
    array = make_array()
    benchmark.group = f"solver plan {rig_name} 12x16 exact"
    plan = benchmark.pedantic(build_plan, args=(rig, array, "exact"), rounds=2, iterations=1)
    checks = [c for c in plan.checks if c is not None]
    benchmark.extra_info["probes_per_quad"] = max((c.n_probes for c in checks), default=0)
    benchmark.extra_info["probe_bytes"] = sum(
        c.probe_re.nbytes + c.probe_im.nbytes + c.probe_u.nbytes + c.probe_s.nbytes
        + c.bound.nbytes for c in checks)


@pytest.mark.parametrize("fe_responses", ["plane-wave", "modeled"])
def test_solve_weights_modeled_responses_1e6(benchmark, targets, fe_responses):
    """Exact method on the honest bench's FE responses (awr1843boost, kit-table1 at 1 m)."""
    from rts_scenario.radar import RadarProfile
    from rts_scenario.schedule.build import solver_inputs

    rig = rs.Rig.preset("kit-table1")
    array, model = solver_inputs(RadarProfile.preset("awr1843boost"), fe_responses)
    az, el = targets
    kwargs = {"rig": rig, "array": array, "model": model}
    rs.solve_weights(az[:64], el[:64], **kwargs)
    benchmark.group = "solve_weights N=1e6 awr1843boost FE responses"
    sol = benchmark.pedantic(rs.solve_weights, args=(az, el), kwargs=kwargs, rounds=3,
                             iterations=1)
    assert sol.feasible.all()
    benchmark.extra_info["target_frames_per_s"] = N / benchmark.stats.stats.min
