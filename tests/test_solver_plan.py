"""The solver plan: built from values only, cached by value in memory and on disk."""

import ast
import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest

import rts_scenario as rs
from rts_scenario.arrays import angles_from_cosines
from rts_scenario.peak_search import find_peak, snapshot
from rts_scenario.solver import plan as plan_module
from rts_scenario.solver import solver_plan
from rts_scenario.solver.plan import clear_memory_cache, plan_cache_dir, plan_key

# Targets well inside kit-table1's quad and inside every shifted rig below.
AZ_DEG, EL_DEG = (g.ravel() for g in np.meshgrid(np.linspace(-2.0, 2.0, 5),
                                                 np.linspace(-5.0, 5.0, 5)))
# Exact weights put the Bartlett peak on the set angle to ~1e-8 deg (rounding of the
# stationarity solve and of the independent peak search); a stale plan misses by 0.003..1 deg.
PEAK_TOL_DEG = 1e-6


def synthesized(sol: rs.WeightSolution, rig: rs.Rig, array: rs.VirtualArray):
    """Bartlett peak of each target's four echoes, searched independently of the solver."""
    fes = rig.quads[sol.quad]
    x = snapshot(array, sol.weights, rig.az_deg[fes], rig.el_deg[fes])
    return find_peak(array, x, az_range_deg=(rig.az_deg.min() - 10, rig.az_deg.max() + 10),
                     el_range_deg=(rig.el_deg.min() - 10, rig.el_deg.max() + 10))


def assert_on_target(sol: rs.WeightSolution, rig: rs.Rig, array: rs.VirtualArray) -> None:
    assert sol.feasible.all(), sol.counts()
    peak_az, peak_el = synthesized(sol, rig, array)
    np.testing.assert_allclose(peak_az, AZ_DEG, rtol=0, atol=PEAK_TOL_DEG)
    np.testing.assert_allclose(peak_el, EL_DEG, rtol=0, atol=PEAK_TOL_DEG)


@pytest.mark.parametrize("change", [
    {"az_deg": [-4.4, 5.5, -2.4, 4.8]},  # every FE 1 deg further in azimuth
    {"el_deg": [-7.8, -6.7, 9.4, 10.9]},  # every FE 1 deg higher
])
def test_replaced_rig_gets_its_own_plan(kit_rig, array, change):
    before = rs.solve_weights(AZ_DEG, EL_DEG, rig=kit_rig, array=array, method="exact")
    moved = dataclasses.replace(kit_rig, **change)
    after = rs.solve_weights(AZ_DEG, EL_DEG, rig=moved, array=array, method="exact")
    assert_on_target(after, moved, array)
    assert np.abs(after.weights - before.weights).max() > 1e-3


@pytest.mark.parametrize("change", ["wavelength", "positions"])
def test_replaced_array_gets_its_own_plan(kit_rig, array, change):
    before = rs.solve_weights(AZ_DEG, EL_DEG, rig=kit_rig, array=array, method="exact")
    if change == "wavelength":
        other = dataclasses.replace(array, wavelength_m=array.wavelength_m * 1.05)
    else:
        other = dataclasses.replace(array, z_m=array.z_m * 1.2)
    after = rs.solve_weights(AZ_DEG, EL_DEG, rig=kit_rig, array=other, method="exact")
    assert_on_target(after, kit_rig, other)
    assert np.abs(after.weights - before.weights).max() > 1e-3


def test_rig_and_array_carry_no_cache():
    assert all(not f.name.startswith("_") for f in dataclasses.fields(rs.Rig))
    assert all(not f.name.startswith("_") for f in dataclasses.fields(rs.VirtualArray))
    array = rs.VirtualArray.preset("paper")
    assert array.is_centrosymmetric
    shifted = dataclasses.replace(array, z_m=array.z_m + array.wavelength_m / 3)
    assert not shifted.is_centrosymmetric


def test_kinematics_does_not_import_the_solver():
    source = Path(rs.__file__).with_name("kinematics.py").read_text()
    imported = [node.module or "" for node in ast.walk(ast.parse(source))
                if isinstance(node, ast.ImportFrom)]
    assert "quads" in imported
    assert not [name for name in imported if "solver" in name]


def test_key_is_equal_for_equal_values(kit_rig):
    twin = rs.Rig.from_angles([-5.4, 4.5, -3.4, 3.8], [-8.8, -7.7, 8.4, 9.9])
    array = rs.VirtualArray.preset("awr1843boost")
    again = rs.VirtualArray.preset("awr1843boost")
    assert twin is not kit_rig and again is not array
    assert plan_key(twin, array, "exact") == plan_key(kit_rig, again, "exact")
    # The plan does not use distances or calibration: those rigs share it.
    elsewhere = dataclasses.replace(kit_rig, distance_m=kit_rig.distance_m * 2,
                                    cal_phase_deg=kit_rig.cal_phase_deg + 10)
    assert plan_key(elsewhere, array, "exact") == plan_key(kit_rig, array, "exact")


def test_key_changes_with_every_input(kit_rig, monkeypatch):
    array = rs.VirtualArray.preset("awr1843boost")
    base = plan_key(kit_rig, array, "exact")
    az, el = kit_rig.az_deg.copy(), kit_rig.el_deg.copy()
    az[3] += 1e-12
    el[0] -= 1e-12
    # The same FE angles, row-major, in two grid shapes.
    flat_az, flat_el = np.arange(6.0), np.repeat([0.0, 1.0], 3)
    two_by_three = rs.Rig.grid(flat_az.reshape(2, 3), flat_el.reshape(2, 3))
    three_by_two = rs.Rig.grid(flat_az.reshape(3, 2), flat_el.reshape(3, 2))
    keys = [
        plan_key(dataclasses.replace(kit_rig, az_deg=az), array, "exact"),
        plan_key(dataclasses.replace(kit_rig, el_deg=el), array, "exact"),
        plan_key(kit_rig, dataclasses.replace(array, wavelength_m=array.wavelength_m * 1.001),
                 "exact"),
        plan_key(kit_rig, dataclasses.replace(array, y_m=array.y_m * 1.001), "exact"),
        plan_key(kit_rig, dataclasses.replace(array, z_m=array.z_m * 1.001), "exact"),
        plan_key(kit_rig, array, "paper"),
        plan_key(two_by_three, array, "exact"),
        plan_key(three_by_two, array, "exact"),
    ]
    monkeypatch.setattr(plan_module, "SPLIT_MAP_NODES", plan_module.SPLIT_MAP_NODES + 1)
    keys.append(plan_key(kit_rig, array, "exact"))
    assert len(set(keys + [base])) == len(keys) + 1


def test_plan_comes_from_memory_then_disk(kit_rig, tmp_path, monkeypatch):
    monkeypatch.setenv("RTS_SCENARIO_CACHE_DIR", str(tmp_path))
    array = rs.VirtualArray.preset("awr1843boost")
    rig = dataclasses.replace(kit_rig, az_deg=kit_rig.az_deg + 0.125)  # a plan no test made
    clear_memory_cache()
    built = solver_plan(rig, array, "exact")
    assert built.origin == "built"
    assert (tmp_path / built.key).is_file()
    assert solver_plan(rig, array, "exact").origin == "memory"
    clear_memory_cache()
    loaded = solver_plan(rig, array, "exact")
    assert loaded.origin == "disk"
    assert loaded.key == built.key
    assert loaded.seconds >= 0.0 and "(disk)" in loaded.describe()
    fresh = rs.solve_weights(AZ_DEG, EL_DEG, rig=rig, array=array, method="exact",
                             plan=built)
    cached = rs.solve_weights(AZ_DEG, EL_DEG, rig=rig, array=array, method="exact",
                              plan=loaded)
    np.testing.assert_array_equal(cached.weights, fresh.weights)
    np.testing.assert_array_equal(cached.reason, fresh.reason)
    via_cache = rs.solve_weights(AZ_DEG, EL_DEG, rig=rig, array=array, method="exact")
    np.testing.assert_array_equal(via_cache.weights, fresh.weights)


@pytest.mark.parametrize("content", [b"", b"garbage, not a pickle", b"\x80\x05K\x01."])
def test_corrupt_cache_file_is_rebuilt(kit_rig, tmp_path, monkeypatch, content):
    monkeypatch.setenv("RTS_SCENARIO_CACHE_DIR", str(tmp_path))
    array = rs.VirtualArray.preset("paper")
    key = plan_key(kit_rig, array, "paper")
    (tmp_path / key).write_bytes(content)
    clear_memory_cache()
    plan = solver_plan(kit_rig, array, "paper")
    assert plan.origin == "built"
    clear_memory_cache()
    assert solver_plan(kit_rig, array, "paper").origin == "disk"  # overwritten with a good one


def test_unwritable_cache_dir_just_means_no_disk_cache(kit_rig, tmp_path, monkeypatch):
    # The user's cache directory, made when a plan is first stored, cannot be made under a
    # file. ($RTS_SCENARIO_CACHE_DIR naming no folder is refused: test_bad_input.py.)
    blocker = tmp_path / "a-file"
    blocker.write_text("not a directory")
    monkeypatch.delenv("RTS_SCENARIO_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocker))
    monkeypatch.setattr(sys, "platform", "linux")
    assert plan_cache_dir() == blocker / "rts-scenario"
    array = rs.VirtualArray.preset("paper")
    clear_memory_cache()
    assert solver_plan(kit_rig, array, "paper").origin == "built"
    clear_memory_cache()
    assert solver_plan(kit_rig, array, "paper").origin == "built"
    sol = rs.solve_weights(AZ_DEG, EL_DEG, rig=kit_rig, array=array, method="paper")
    assert sol.feasible.all()


@pytest.mark.parametrize("setting", ["off", "", "  "])
def test_disk_cache_can_be_switched_off(kit_rig, tmp_path, monkeypatch, setting):
    monkeypatch.setenv("RTS_SCENARIO_CACHE_DIR", setting)
    monkeypatch.chdir(tmp_path)
    assert plan_cache_dir() is None
    clear_memory_cache()
    assert solver_plan(kit_rig, rs.VirtualArray.preset("paper"), "paper").origin == "built"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("platform", "env", "expected"), [
    ("linux", {"XDG_CACHE_HOME": "/xdg"}, Path("/xdg/rts-scenario")),
    ("linux", {}, Path("/home/u/.cache/rts-scenario")),
    ("darwin", {}, Path("/home/u/Library/Caches/rts-scenario")),
    ("win32", {"LOCALAPPDATA": "/local"}, Path("/local/rts-scenario/Cache")),
])
def test_default_cache_dir_per_platform(monkeypatch, platform, env, expected):
    monkeypatch.delenv("RTS_SCENARIO_CACHE_DIR")
    for name in ("XDG_CACHE_HOME", "LOCALAPPDATA"):
        monkeypatch.delenv(name, raising=False)
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    monkeypatch.setattr(Path, "home", classmethod(lambda cls: Path("/home/u")))
    monkeypatch.setattr(sys, "platform", platform)
    assert plan_cache_dir() == expected


def test_plan_of_other_values_is_refused(kit_rig):
    array = rs.VirtualArray.preset("paper")
    plan = solver_plan(kit_rig, array, "paper")
    with pytest.raises(rs.SolverError, match="its method: 'paper'"):
        rs.solve_weights(AZ_DEG, EL_DEG, rig=kit_rig, array=array, method="exact", plan=plan)
    moved = dataclasses.replace(kit_rig, az_deg=kit_rig.az_deg + 1.0)
    with pytest.raises(rs.SolverError, match="built for other values than rig 'kit-table1'"):
        rs.solve_weights(AZ_DEG, EL_DEG, rig=moved, array=array, method="paper", plan=plan)


def test_plan_holds_the_schedule_responses(kit_rig):
    array = rs.VirtualArray.preset("awr1843boost")
    plan = solver_plan(kit_rig, array, "exact")
    assert len(plan.responses) == len(plan.kernels) == len(plan.checks) == len(kit_rig.quads)
    u, s = np.array([0.01]), np.array([-0.02])
    az, el = np.degrees(angles_from_cosines(u, s))
    fes = kit_rig.quads[0]
    expected = array.response(az, el, kit_rig.az_deg[fes], kit_rig.el_deg[fes])
    np.testing.assert_allclose(plan.responses[0].evaluate(u, s, terms=1)[0].T, expected,
                               rtol=1e-12, atol=1e-9)


def test_no_home_is_no_disk_cache_not_an_error(kit_rig, monkeypatch, tmp_path):
    # $HOME unset for a user without an entry (a bare container): Path.home() raises; the
    # scene still loads and solves, with no disk cache.
    monkeypatch.delenv("RTS_SCENARIO_CACHE_DIR")
    for name in ("XDG_CACHE_HOME", "LOCALAPPDATA"):
        monkeypatch.delenv(name, raising=False)

    def no_home(cls):
        raise RuntimeError("Could not determine home directory.")

    monkeypatch.setattr(Path, "home", classmethod(no_home))
    assert plan_cache_dir() is None
    clear_memory_cache()
    scene = rs.load_scenario(Path(__file__).parents[1] / "scenarios" / "cut_in.scenario.yaml")
    assert solver_plan(kit_rig, scene.radar.array, "exact").origin == "built"
