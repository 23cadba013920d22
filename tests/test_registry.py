import json
import sys
from importlib.metadata import EntryPoint

import pytest

import rts_scenario.registry as registry
from rts_scenario.errors import OutputError, RtsError
from rts_scenario.registry import Registry


def test_unknown_name_lists_the_valid_names():
    reg = Registry("widget", {"b": "json:dumps", "a": "json:loads", "c": "json:JSONDecoder"},
                   error=OutputError)
    assert reg.names() == ["b", "a", "c"]  # built-ins in their declared order
    with pytest.raises(OutputError, match=r"^unknown widget 'x'; valid widgets: b, a, c$"):
        reg.get("x")


def test_builtins_are_imported_only_when_selected(tmp_path, monkeypatch):
    (tmp_path / "rts_registry_probe.py").write_text("class Probe:\n    pass\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "rts_registry_probe", raising=False)
    reg = Registry("widget", {"probe": "rts_registry_probe:Probe",
                              "missing": "rts_no_such_module_xyz:Thing",
                              "typo": "rts_registry_probe:Prob"})
    assert reg.names() == ["probe", "missing", "typo"]
    assert "rts_registry_probe" not in sys.modules
    assert reg.get("probe").__name__ == "Probe"
    assert "rts_registry_probe" in sys.modules
    with pytest.raises(RtsError,
                       match="widget 'missing' cannot be loaded: .*rts_no_such_module_xyz"):
        reg.get("missing")
    with pytest.raises(RtsError, match="widget 'typo' cannot be loaded: .*Prob"):
        reg.get("typo")


def test_entry_points_extend_the_builtins(monkeypatch):
    group = "rts_scenario.test-widgets"
    plugin = EntryPoint(name="decoder", value="json:JSONDecoder", group=group)
    shadow = EntryPoint(name="dumps", value="json:loads", group=group)
    broken = EntryPoint(name="broken", value="rts_no_such_module_xyz:Driver", group=group)
    seen = []

    def fake_entry_points(*, group):
        seen.append(group)
        return [plugin, shadow, broken]

    monkeypatch.setattr(registry, "entry_points", fake_entry_points)
    reg = Registry("widget", {"dumps": "json:dumps"}, entry_point_group=group)
    assert reg.names() == ["dumps", "broken", "decoder"]  # built-ins, then plugins
    assert seen == [group]
    assert reg.get("decoder") is json.JSONDecoder
    assert reg.get("dumps") is json.dumps  # a built-in wins over a plugin of the same name
    with pytest.raises(RtsError, match="widget 'broken' cannot be loaded"):
        reg.get("broken")


def test_without_a_group_no_entry_points_are_read(monkeypatch):
    monkeypatch.setattr(registry, "entry_points",
                        lambda **_: pytest.fail("read entry points without a group"))
    assert Registry("widget", {"a": "json:dumps"}).names() == ["a"]


def test_builtins_must_name_module_and_attribute():
    with pytest.raises(ValueError, match="built-in widget 'a': expected 'module:attr'"):
        Registry("widget", {"a": "json"})


def test_estimators_and_outputs_use_the_registry():
    from rts_scenario.arrays import VirtualArray
    from rts_scenario.radar.angle import ESTIMATORS, Bartlett2D, make_estimator

    assert ESTIMATORS == ("bartlett", "ti")
    assert isinstance(make_estimator("bartlett", VirtualArray.preset("paper")), Bartlett2D)
    with pytest.raises(RtsError, match="unknown angle estimator 'music'; "
                                       "valid angle estimators: bartlett, ti"):
        make_estimator("music", VirtualArray.preset("paper"))


def test_solver_methods_and_fidelities_share_the_registry_shape():
    from rts_scenario.radar.simulate import FIDELITIES
    from rts_scenario.solver import METHODS

    assert list(METHODS) == ["paper", "exact"] and "exact" in METHODS and "music" not in METHODS
    assert list(FIDELITIES) == ["auto", "adc", "analytic"]
    from rts_scenario.errors import SolverError

    with pytest.raises(SolverError, match="unknown method 'fast'; valid methods: paper, exact"):
        METHODS.get("fast")
