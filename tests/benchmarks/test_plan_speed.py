"""Getting a solver plan: built, from memory, from disk (run: pytest tests/benchmarks ...).

The timing line of a run shows which of the three it was (`SolverPlan.describe`).
"""

import pytest

import rts_scenario as rs
from rts_scenario.solver.plan import build_plan, clear_memory_cache, solver_plan

CASES = [("kit-table1", "paper"), ("kit-table1", "awr1843boost"),
         ("wide-3x5", "awr1843boost")]


@pytest.mark.parametrize(("rig_name", "array_name"), CASES)
@pytest.mark.parametrize("origin", ["built", "memory", "disk"])
def test_solver_plan(benchmark, tmp_path, monkeypatch, rig_name, array_name, origin):
    monkeypatch.setenv("RTS_SCENARIO_CACHE_DIR", str(tmp_path))
    rig = rs.Rig.preset(rig_name)
    array = rs.VirtualArray.preset(array_name)
    solver_plan(rig, array, "exact")  # fills both caches
    benchmark.group = f"solver plan {rig_name} {array_name} exact"
    if origin == "built":
        plan = benchmark.pedantic(build_plan, args=(rig, array, "exact"), rounds=3, iterations=1)
        assert plan.origin == "built"
        return
    setup = clear_memory_cache if origin == "disk" else None
    plan = benchmark.pedantic(solver_plan, args=(rig, array, "exact"), setup=setup, rounds=20,
                              iterations=1)
    assert plan.origin == origin
