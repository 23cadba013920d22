"""A file of another kind, the tool's own or another tool's, is named as what it is."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from rts_scenario.canbus.mapping import CanMapping
from rts_scenario.errors import ScenarioError
from rts_scenario.radar.profile import RadarProfile
from rts_scenario.rig import Rig
from rts_scenario.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]
DBC = ROOT / "scenarios" / "can" / "cluster_list.dbc"
XOSC = ROOT / "tests" / "data" / "xosc" / "cut_in.xosc"
FRAGMENT = ROOT / "scenarios" / "fragments" / "parked_cars.yaml"
SCENE = ROOT / "scenarios" / "cut_in.scenario.yaml"

CAN_MAPPING_WAY = ("--mapping takes a CAN mapping that names a DBC and which of its signals "
                   "carry what (docs/can-mapping.md)")


def test_a_dbc_as_a_mapping_names_the_mapping_beside_it():
    with pytest.raises(ScenarioError) as caught:
        CanMapping.from_file(DBC)
    assert str(caught.value) == (
        f"{DBC} is a DBC file (*.dbc), not a CAN mapping (*.mapping.yaml); {CAN_MAPPING_WAY}: "
        f"{DBC.with_name('cluster_list.mapping.yaml')} names this one")
    assert caught.value.file == str(DBC)


@pytest.mark.parametrize(("suffix", "what"), [
    (".arxml", "an AUTOSAR CAN database"), (".kcd", "a KCD CAN database"),
    (".sym", "a SYM CAN database"), (".DBC", "a DBC file")])
def test_other_can_databases_are_named_by_suffix(tmp_path, suffix, what):
    path = tmp_path / f"radar{suffix}"
    path.write_text("whatever: it holds\n")
    with pytest.raises(ScenarioError) as caught:
        CanMapping.from_file(path)
    assert str(caught.value).startswith(
        f"{path} is {what} (*{suffix.lower()}), not a CAN mapping (*.mapping.yaml); ")


@pytest.mark.parametrize(("text", "what"), [
    ('<?xml version="1.0"?>\n<AUTOSAR xmlns="http://autosar.org/schema/r4.0">\n</AUTOSAR>\n',
     "an AUTOSAR CAN database"),
    ('<?xml version="1.0"?>\n<NetworkDefinition xmlns="http://kayak.2codeornot2code.org/1.0">'
     '\n</NetworkDefinition>\n', "a KCD CAN database"),
    ('FormatVersion=6.0 // Do not edit this line!\nTitle="radar"\n', "a SYM CAN database"),
    (DBC.read_text(), "a DBC file"),
    (XOSC.read_text(), "an OpenSCENARIO file"),
])
def test_a_file_of_another_format_under_a_yaml_name_is_named_by_its_content(tmp_path, text,
                                                                            what):
    path = tmp_path / "radar.yaml"
    path.write_text(text)
    for load in (CanMapping.from_file, RadarProfile.from_file, Rig.from_file, load_scenario):
        with pytest.raises(ScenarioError, match=f"^{path} is {what} \\(by its content\\), not "):
            load(path)


def test_an_openscenario_file_as_a_scene_says_how_to_import_it():
    with pytest.raises(ScenarioError) as caught:
        load_scenario(XOSC)
    assert str(caught.value) == (
        f"{XOSC} is an OpenSCENARIO file (*.xosc), not a scene (*.scenario.yaml); rts-scenario "
        f"import {XOSC} --radar P --rig R --output cut_in.scenario.yaml converts it to a scene "
        f"(docs/import.md)")


def test_a_fragment_as_a_scene_says_where_it_goes():
    with pytest.raises(ScenarioError) as caught:
        load_scenario(FRAGMENT)
    assert str(caught.value) == (
        f"{FRAGMENT} is a scene fragment (only targets and a description), not a scene "
        f"(*.scenario.yaml); a scene lists it under include: (scenarios/README.md, Fragments)")


def test_a_scene_named_as_one_is_never_a_fragment(tmp_path):
    """Its name says what it is meant to be: the schema says what it lacks."""
    path = tmp_path / "parked.scenario.yaml"
    shutil.copy(FRAGMENT, path)
    with pytest.raises(ScenarioError, match="'rts_scenario' is required but missing"):
        load_scenario(path)


def test_a_yaml_that_is_no_scene_keeps_its_parser_message(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("a: [1,\n")
    with pytest.raises(ScenarioError, match=r"invalid YAML"):
        load_scenario(path)


def test_a_file_of_the_expected_kind_under_a_foreign_name_is_taken(tmp_path):
    """The version key says what a file is, whatever its name."""
    path = tmp_path / "scene.xosc"
    shutil.copy(SCENE, path)
    shutil.copytree(SCENE.parent / "rigs", tmp_path / "rigs")
    shutil.copytree(SCENE.parent / "radars", tmp_path / "radars")
    shutil.copytree(SCENE.parent / "fragments", tmp_path / "fragments")
    assert load_scenario(path).name == "cut-in"
