"""Solver throughput (run: pytest tests/benchmarks --benchmark-json=benchmarks.json).

``test_exact_against_paper`` prints, per case and from one run (methods alternated, best of
`ROUNDS`), the paper and exact methods' throughput and their ratio, the exact method's memory
traffic against the copy bandwidth measured alongside, and the exact method's numpy path (the
reference the compiled kernel replaces): ``pytest tests/benchmarks/test_solver_speed.py -s``.
"""

import os
import time

import numpy as np
import pytest
from benchmark_rates import record_rate
from cascade_arrays import compact_cascade, ti_cascade

import rts_scenario as rs
import rts_scenario.solver as solver_module
from rts_scenario import perf
from rts_scenario.solver import compiled
from rts_scenario.solver.plan import build_plan

N = 1_000_000
ROUNDS = 5
# Bytes a solve streams per target: az and el in (float64), weights (4 x float64), quad (int64)
# and reason (uint8) out.
BYTES_PER_TARGET = 8 + 8 + 4 * 8 + 8 + 1
# Acceptance: the exact method at least as fast as the paper's closed form, same run.
EXACT_OVER_PAPER = 1.0


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
    record_rate(benchmark, "target_frames_per_s", N)


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
    record_rate(benchmark, "target_frames_per_s", N)


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
    record_rate(benchmark, "target_frames_per_s", N_CASCADE)


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
    record_rate(benchmark, "target_frames_per_s", N)


def _best_alternating(runs, rounds=ROUNDS):
    """Best wall time of each callable, the callables alternated round by round."""
    best = [np.inf] * len(runs)
    for _ in range(rounds):
        for i, run in enumerate(runs):
            start = time.perf_counter()
            run()
            best[i] = min(best[i], time.perf_counter() - start)
    return best


def _numpy_path(solve):
    def run():
        os.environ[compiled.JIT_ENV] = "off"
        try:
            solve()
        finally:
            del os.environ[compiled.JIT_ENV]
    return run


def _modeled():
    from rts_scenario.radar import RadarProfile
    from rts_scenario.schedule.build import solver_inputs

    return solver_inputs(RadarProfile.preset("awr1843boost"), "modeled")


SPEED_CASES = {
    "kit-table1 paper": ("kit-table1", lambda: (rs.VirtualArray.preset("paper"), None)),
    "kit-table1 awr1843boost": ("kit-table1",
                                lambda: (rs.VirtualArray.preset("awr1843boost"), None)),
    "wide-3x5 awr1843boost": ("wide-3x5", lambda: (rs.VirtualArray.preset("awr1843boost"), None)),
    "kit-table1 modeled awr1843boost": ("kit-table1", _modeled),
}


@pytest.mark.parametrize("case", list(SPEED_CASES))
def test_exact_against_paper(benchmark, case, monkeypatch):
    """Exact (compiled kernel) vs paper vs exact's numpy path, one run, alternated.

    The paper method has no modeled-response variant: that case compares the exact method
    with its own numpy path only.
    """
    if compiled.exact_kernel() is None:
        pytest.skip("numba (the 'fast' extra) is not installed: nothing to compare")
    monkeypatch.delenv(compiled.JIT_ENV, raising=False)
    rig_name, inputs = SPEED_CASES[case]
    rig = rs.Rig.preset(rig_name)
    array, model = inputs()
    rng = np.random.default_rng(0 if rig_name == "kit-table1" else 1)
    half_az, half_el = (3.0, 6.0) if rig_name == "kit-table1" else (20.0, 8.0)
    az, el = rng.uniform(-half_az, half_az, N), rng.uniform(-half_el, half_el, N)

    def exact():
        return rs.solve_weights(az, el, rig=rig, array=array, model=model)

    def paper():
        return rs.solve_weights(az, el, rig=rig, array=array, method="paper")

    runs = [exact, _numpy_path(exact)] + ([paper] if model is None else [])
    for run in runs:  # plans built or loaded, the kernel compiled or loaded
        run()
    assert exact().feasible.all()
    copy_bps = perf.streaming_copy_bandwidth(ROUNDS)
    times = _best_alternating(runs)
    copy_bps = max(copy_bps, perf.streaming_copy_bandwidth(ROUNDS))
    exact_s, numpy_s = times[0], times[1]
    solver_bps = BYTES_PER_TARGET * N / exact_s
    line = (f"\n{case}: exact {N / exact_s / 1e6:.2f} M/s (numpy path {N / numpy_s / 1e6:.2f}, "
            f"kernel {numpy_s / exact_s:.1f}x)")
    if model is None:
        paper_s = times[2]
        line += (f"; paper {N / paper_s / 1e6:.2f} M/s; exact/paper {paper_s / exact_s:.2f}x")
    line += (f"; exact streams {solver_bps / 1e9:.2f} GB/s ({BYTES_PER_TARGET} B/target) = "
             f"{100 * solver_bps / copy_bps:.1f} % of copy bandwidth {copy_bps / 1e9:.1f} GB/s "
             f"(np.copyto of 4x the last-level cache, read + written); "
             f"{solver_module.WORKERS} threads")
    print(line)
    benchmark.group = f"solve_weights N=1e6 {case}: exact vs paper"
    benchmark.extra_info.update(
        exact_targets_per_s=N / exact_s, exact_numpy_targets_per_s=N / numpy_s,
        solver_bytes_per_s=solver_bps, copy_bytes_per_s=copy_bps,
    )
    if model is None:
        benchmark.extra_info["paper_targets_per_s"] = N / times[2]
    benchmark.pedantic(exact, rounds=1, iterations=1)
    assert numpy_s / exact_s >= 1.0  # the kernel never loses to the numpy code
    if model is None:
        assert times[2] / exact_s >= EXACT_OVER_PAPER


@pytest.mark.parametrize("rig_name", ["kit-table1", "wide-3x5"])
def test_row_sums_against_element_sums(benchmark, rig_name):
    """The AWR1843BOOST's complex responses summed by rows (`exact.RowFactors`) against the
    same kernel summing element by element (the plan's rows taken away), one run, alternated:
    ``pytest tests/benchmarks/test_solver_speed.py -s -k row_sums``."""
    import dataclasses

    from rts_scenario.solver.exact import RowFactors

    if compiled.exact_kernel() is None:
        pytest.skip("numba (the 'fast' extra) is not installed: nothing to compare")
    rig, array = rs.Rig.preset(rig_name), rs.VirtualArray.preset("awr1843boost")
    plan = rs.solver_plan(rig, array, "exact")
    tables = plan.exact_tables
    assert tables is not None and tables.rows.z.size > 0
    by_elements = dataclasses.replace(plan, exact_tables=dataclasses.replace(
        tables, rows=RowFactors.none(tables.tab_re.shape[0])))
    rng = np.random.default_rng(0 if rig_name == "kit-table1" else 1)
    half_az, half_el = (3.0, 6.0) if rig_name == "kit-table1" else (20.0, 8.0)
    az, el = rng.uniform(-half_az, half_az, N), rng.uniform(-half_el, half_el, N)

    def solve(chosen):
        return lambda: rs.solve_weights(az, el, rig=rig, array=array, plan=chosen)

    rows, elements = solve(plan)(), solve(by_elements)()
    np.testing.assert_array_equal(rows.reason, elements.reason)
    np.testing.assert_allclose(rows.weights, elements.weights, rtol=0, atol=1e-12)
    rows_s, elements_s = _best_alternating([solve(plan), solve(by_elements)])
    print(f"\n{rig_name} awr1843boost: row sums {N / rows_s / 1e6:.2f} M/s, element sums "
          f"{N / elements_s / 1e6:.2f} M/s: {elements_s / rows_s:.3f}x; "
          f"{solver_module.WORKERS} threads")
    benchmark.group = f"solve_weights N=1e6 {rig_name} awr1843boost: rows vs elements"
    benchmark.extra_info.update(rows_targets_per_s=N / rows_s,
                                elements_targets_per_s=N / elements_s)
    benchmark.pedantic(solve(plan), rounds=1, iterations=1)
    assert elements_s / rows_s >= 1.0
