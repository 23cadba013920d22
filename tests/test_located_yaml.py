"""YAML's own errors in plain words: tabs and a key indented out of line."""

from __future__ import annotations

import errno
import os
import re
from pathlib import Path

import pytest
import yaml

from rts_scenario import located_yaml
from rts_scenario.errors import ScenarioError
from rts_scenario.located_yaml import load_yaml

# The documented bound (scenarios/README.md).
MAX_NODES = 1_000_000


class _PurePython(yaml.SafeLoader):
    """PyYAML's own parser, used where libyaml is not installed."""


@pytest.fixture(params=["libyaml", "python"])
def parser(request, monkeypatch):
    """Both of PyYAML's parsers: their messages and marks differ."""
    if request.param == "python":
        monkeypatch.setattr(located_yaml, "_Loader", _PurePython)
    elif not hasattr(yaml, "CSafeLoader"):
        pytest.skip("libyaml is not installed")
    return request.param


def error_of(text: str) -> ScenarioError:
    with pytest.raises(ScenarioError) as caught:
        load_yaml("x.yaml", text)
    return caught.value


INDENT_TAB = "a tab indents this line; YAML indents with spaces"


@pytest.mark.parametrize(("text", "line", "column", "message"), [
    ("radar:\n\tprofile: awr1843boost\n", 2, 1, INDENT_TAB),
    ("radar:\n  profile: x\n\testimator: y\n", 3, 1, INDENT_TAB),
    ("radar:\n  \tprofile: x\n", 2, 3, INDENT_TAB),
    ("\tname: x\n", 1, 1, INDENT_TAB),
    ("targets:\n\t- a\n", 2, 1, INDENT_TAB),
    ("targets:\n  -\tname: a\n", 2, 4, "a tab after '-' on this line; YAML separates with spaces"),
])
def test_a_tab_is_named_where_it_is(parser, text, line, column, message):
    error = error_of(text)
    assert (error.detail, error.line, error.column) == (message, line, column)
    assert str(error) == f"x.yaml:{line}:{column}: {message}"


@pytest.mark.parametrize(("text", "line", "column", "starts"), [
    # An unclosed quote is found at the end of the file; the line to fix is where it opens.
    ("a: 1\nname: \"short\nb: 2\nc: 3\n", 2, 7, "while scanning a quoted scalar"),
    # A key without its colon: the parser gives up on the line after it.
    ("a: 1\nrig wide\nb: 2\n", 2, 1, "while scanning a simple key"),
    # An unclosed bracket, found at the end of the file.
    ("a: 1\nname: [cut-in, b\n", 2, 7, "while parsing a flow sequence"),
])
def test_a_broken_construct_is_placed_where_it_begins(parser, text, line, column, starts):
    error = error_of(text)
    assert (error.line, error.column) == (line, column), str(error)
    assert error.detail.startswith("invalid YAML: ")
    assert error.detail.endswith(f"({starts} that begins here)"), error.detail
    assert re.search(r" at line \d+, column \d+ \(", error.detail)


def test_a_flow_collection_broken_within_the_file_is_placed_at_the_line_that_breaks_it(parser):
    # A comma left out at the end of line 4 of a list over four lines: the parser stops on
    # line 5, the list opened on line 2; the line to fix is 4.
    error = error_of("a: 1\nt: [{x: 1},\n  {x: 2},\n  {x: 3}\n  {x: 4}]\nb: 2\n")
    assert (error.line, error.column) == (4, 9), str(error)
    assert error.detail.endswith("(while parsing a flow sequence from line 2, column 4): a "
                                 "comma left out at the end of this line, or that bracket "
                                 "left open?")
    # A bracket left open that the parser read on past: the line that opened it.
    error = error_of("a: 1\nname: [cut-in\nb: 2\n")
    assert (error.line, error.column) == (2, 14), str(error)
    assert "(while parsing a flow sequence from line 2, column 7)" in error.detail


def test_an_alias_without_its_anchor_says_so():
    error = error_of("a: *prof\n")
    assert (error.line, error.column) == (1, 4)
    assert error.detail == ("alias *prof: no anchor &prof before it (an alias repeats a node "
                            "anchored earlier in the file)")
    recursive = error_of("a: &loop [1, *loop]\n")
    assert "refers to a node that contains it (recursive data is not allowed)" in str(recursive)


def test_a_value_its_tag_cannot_read_names_its_line_and_key():
    error = error_of("name: x\nduration_s: !!int abc\n")
    assert (error.line, error.column, error.key_path) == (2, 13, "duration_s")
    assert error.detail.startswith("invalid YAML value int 'abc': ")


def test_a_second_document_is_named_as_such():
    error = error_of("a: 1\n---\nb: 2\n")
    assert error.line == 2
    assert error.detail == ("invalid YAML: a second document begins here (after ---); a file "
                            "holds one document")


@pytest.mark.parametrize(("text", "line", "column", "message"), [
    # PyYAML's own parser refuses tabs after a key and inside a flow, where libyaml takes them.
    ("a:\t1\n", 1, 3, "a tab after 'a:' on this line; YAML separates with spaces"),
    ("a: [1,\n\t2]\n", 2, 1, INDENT_TAB),
])
def test_a_tab_only_the_python_parser_refuses(monkeypatch, text, line, column, message):
    monkeypatch.setattr(located_yaml, "_Loader", _PurePython)
    error = error_of(text)
    assert (error.detail, error.line, error.column) == (message, line, column)


BETWEEN = "radar:\n  profile: x\n mount: y\n"


@pytest.mark.parametrize(("text", "line", "column", "hint"), [
    (BETWEEN, 3, 2, "this line is indented 1 space, but the mapping from line 1 has its keys "
                    "at 0 spaces and line 2 above it at 2"),
    ("a:\n  b:\n    c: 1\n   d: 2\n", 4, 4, "this line is indented 3 spaces, but the mapping "
                                            "from line 2 has its keys at 2 spaces and line 3 "
                                            "above it at 4"),
    ("targets:\n  - name: a\n    motion:\n      type: x\n     speed: 1\n", 5, 6,
     "this line is indented 5 spaces, but the mapping from line 2 has its keys at 4 spaces and "
     "line 4 above it at 6"),
    # Comments and blank lines are no keys; a line above at the mapping's own indentation adds
    # nothing.
    ("a: 1\n # note\n\n c: 2\n", 4, 2, "this line is indented 1 space, but the mapping from "
                                       "line 1 has its keys at 0 spaces"),
])
def test_a_key_out_of_line_names_the_indentations_around_it(parser, text, line, column, hint):
    error = error_of(text)
    assert (error.line, error.column) == (line, column)
    assert error.detail == f"invalid YAML: {hint}; keys of one mapping line up"


@pytest.mark.parametrize("text", [
    "a: b\n- c\n",             # a list item at the keys' column: a list or a key left out?
    "a:\n  b: 1\n  - c\n",
])
def test_an_ambiguous_indentation_keeps_the_parsers_words(parser, text):
    assert "indented" not in error_of(text).detail


def nested_nodes(n_items: int) -> str:
    """A mapping whose list holds ``n_items`` mappings of one key and a 3-list: 3 + 6 n_items
    nodes, four levels deep."""
    return "a:\n" + "".join("  - {p: [1, 2, 3]}\n" for _ in range(n_items))


@pytest.mark.parametrize("bound", [10_000, 10_001, 10_002])
def test_each_node_is_counted_once_whatever_its_depth(monkeypatch, bound):
    # A smaller bound, every offset from it: the root, 'a' and the list, then 6 nodes per item.
    monkeypatch.setattr(located_yaml, "MAX_NODES", bound)
    n_items = (bound - 3) // 6
    assert len(load_yaml("x.yaml", nested_nodes(n_items)).data["a"]) == n_items
    with pytest.raises(ScenarioError, match=rf"^x\.yaml:\d+:\d+: document expands to more than "
                                            rf"{bound:,} YAML nodes"):
        load_yaml("x.yaml", nested_nodes(n_items + 1))


def test_an_alias_counts_as_the_nodes_it_repeats():
    # An anchored list of 10 scalars (11 nodes); root, 'a', the list, and then per alias entry
    # a key and 11 nodes.
    head = "a: &x [1, 2, 3, 4, 5, 6, 7, 8, 9, 10]\n"
    n = (MAX_NODES - 1 - 12) // 12
    assert 1 + 12 + 12 * n <= MAX_NODES < 1 + 12 + 12 * (n + 1)
    load_yaml("x.yaml", head + "".join(f"k{i}: *x\n" for i in range(n)))
    with pytest.raises(ScenarioError, match="more than 1,000,000 YAML nodes"):
        load_yaml("x.yaml", head + "".join(f"k{i}: *x\n" for i in range(n + 1)))


@pytest.mark.parametrize("raw, line, column", [
    (b"name: caf\xe9\n", 1, 10),  # Latin-1 e acute after 9 characters
    (b"a: 1\nname: \xc3\xa9t\xe9\n", 2, 9),  # after 'name: ' and a UTF-8 e acute and 't'
    (b"a: 1\r\nb: 2\r\nc: \xff\n", 3, 4),  # CRLF lines
])
def test_a_byte_that_is_not_utf8_is_located_by_line_and_column(tmp_path, raw, line, column):
    path = tmp_path / "x.yaml"
    path.write_bytes(raw)
    with pytest.raises(ScenarioError) as info:
        load_yaml(path)
    assert (info.value.line, info.value.column) == (line, column)
    assert str(info.value).startswith(f"{path}:{line}:{column}: not UTF-8 text: ")


# -- documents found valid, remembered ---------------------------------------------------------

SCHEMA = {"type": "object", "properties": {"speed_mps": {"type": "number", "maximum": 100}},
          "required": ["speed_mps"], "additionalProperties": False}


@pytest.fixture
def judged(monkeypatch, tmp_path):
    """The cache in ``tmp_path``; the number of documents jsonschema judged so far."""
    import jsonschema

    monkeypatch.setenv("RTS_SCENARIO_CACHE_DIR", str(tmp_path))
    count = [0]
    validator = jsonschema.Draft202012Validator

    def counted(schema):
        count[0] += 1
        return validator(schema)

    monkeypatch.setattr(jsonschema, "Draft202012Validator", counted)
    return count


def _validate(text: str, schema=SCHEMA, skip=()) -> None:
    located_yaml.validate(load_yaml("x.yaml", text), schema, skip)


def test_a_document_found_valid_is_not_judged_again(judged, tmp_path):
    _validate("speed_mps: 20\n")
    _validate("speed_mps: 20  # a comment changes nothing\n")
    assert judged[0] == 1
    assert len([p for p in (tmp_path / located_yaml.VALIDATED_FOLDER).rglob("*")
                if p.is_file()]) == 1


@pytest.mark.parametrize("text", ["speed_mps: 200\n", "speed_mps: 20\nspeed: 1\n",
                                  "speed_mps: '20'\n", "{}\n"])
def test_a_document_changed_from_a_valid_one_is_judged_and_refused(judged, text):
    _validate("speed_mps: 20\n")
    with pytest.raises(ScenarioError, match="speed"):
        _validate(text)
    with pytest.raises(ScenarioError, match="speed"):  # an error is never remembered
        _validate(text)
    assert judged[0] == 3


def test_a_valid_document_is_judged_again_against_another_schema_or_skip(judged):
    _validate("speed_mps: 20\n")
    with pytest.raises(ScenarioError, match="must be <= 10"):
        _validate("speed_mps: 20\n",
                  {**SCHEMA, "properties": {"speed_mps": {"type": "number", "maximum": 10}}})
    _validate("speed_mps: 20\n", skip=[("speed_mps",)])
    assert judged[0] == 3


def test_a_document_json_would_read_alike_is_not_taken_for_a_known_one(judged):
    # An integer key reads as a string in JSON's text; such a document keeps no memo.
    schema = {"type": "object"}
    located_yaml.validate(located_yaml.Document({1: 2}, "x.yaml", {}), schema)
    located_yaml.validate(located_yaml.Document({1: 2}, "x.yaml", {}), schema)
    assert judged[0] == 2


@pytest.mark.parametrize("setting", ["off", ""])
def test_no_document_is_remembered_without_a_disk_cache(judged, monkeypatch, tmp_path,
                                                       setting):
    monkeypatch.setenv("RTS_SCENARIO_CACHE_DIR", setting)
    monkeypatch.chdir(tmp_path)
    _validate("speed_mps: 20\n")
    _validate("speed_mps: 20\n")
    assert judged[0] == 2
    assert list(tmp_path.iterdir()) == []


def test_a_cache_out_of_reach_judges_every_document(judged, tmp_path, monkeypatch):
    (tmp_path / located_yaml.VALIDATED_FOLDER).write_text("a file where the folder goes")
    _validate("speed_mps: 20\n")
    _validate("speed_mps: 20\n")
    assert judged[0] == 2


def test_the_documents_remembered_are_bounded_and_the_latest_kept(judged, tmp_path,
                                                                  monkeypatch):
    import os

    monkeypatch.setattr(located_yaml, "VALIDATED_SHARDS", 1)
    monkeypatch.setattr(located_yaml, "VALIDATED_KEEP", 4)
    folder = tmp_path / located_yaml.VALIDATED_FOLDER / "00"
    for speed in range(5):
        _validate(f"speed_mps: {speed}\n")
        for k, marker in enumerate(sorted(folder.iterdir(), key=os.path.getmtime)):
            os.utime(marker, (1000.0 + k, 1000.0 + k))  # distinct times, in their order
    assert judged[0] == 5 and len(list(folder.iterdir())) == 2
    _validate("speed_mps: 4\n")  # the latest: still known
    assert judged[0] == 5
    _validate("speed_mps: 0\n")  # the oldest: judged again
    assert judged[0] == 6


def test_the_documents_remembered_spread_over_shards_each_bounded(judged, tmp_path,
                                                                  monkeypatch):
    # Each new document scans its shard only (a few markers), never all 4,096.
    monkeypatch.setattr(located_yaml, "VALIDATED_KEEP", 512)  # 2 per shard
    for speed in range(600):
        _validate(f"speed_mps: {speed / 10}\n")
    shards = [p for p in (tmp_path / located_yaml.VALIDATED_FOLDER).iterdir()]
    assert len(shards) > 200
    assert all(len(list(shard.iterdir())) <= 2 for shard in shards)


def test_a_string_and_its_surrogate_pair_are_told_apart(judged):
    # One character, or the two UTF-16 halves of it: JSON's ASCII escapes read them alike.
    schema = {"type": "object", "properties": {"name": {"type": "string", "maxLength": 1}}}
    located_yaml.validate(located_yaml.Document({"name": "\U0001F600"}, "x.yaml", {}), schema)
    with pytest.raises(ScenarioError, match="name"):
        located_yaml.validate(located_yaml.Document({"name": "\ud83d\ude00"}, "x.yaml",
                                                    {("name",): (1, 1)}), schema)
    assert judged[0] == 2


def test_a_change_of_the_code_that_judges_judges_again(judged, monkeypatch):
    _validate("speed_mps: 20\n")
    monkeypatch.setattr(located_yaml, "_judge_digest", lambda: "another version")
    _validate("speed_mps: 20\n")
    assert judged[0] == 2


@pytest.mark.parametrize("error", [errno.EPERM, errno.EROFS])
def test_a_cache_that_cannot_be_written_still_gives_its_memos(judged, monkeypatch, error):
    # Another user's markers, or a cache mounted read-only: the marker is there.
    _validate("speed_mps: 20\n")

    def refused(*args, **kwargs):
        raise OSError(error, os.strerror(error))

    monkeypatch.setattr(located_yaml.os, "utime", refused)
    _validate("speed_mps: 20\n")
    assert judged[0] == 1
    _validate("speed_mps: 21\n")  # not there: judged, without an error
    assert judged[0] == 2


def test_a_cache_folder_that_cannot_be_searched_judges_every_document(judged, monkeypatch):
    # A folder shut to this user (a run under sudo with umask 077 made it): neither the
    # marker's time nor its presence can be had; the document is judged, no error.
    _validate("speed_mps: 20\n")
    real_stat = os.stat

    def shut(path, *args, **kwargs):
        if located_yaml.VALIDATED_FOLDER in str(path):
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return real_stat(path, *args, **kwargs)

    def refused(*args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(located_yaml.os, "utime", refused)
    monkeypatch.setattr(located_yaml.os, "stat", shut)
    _validate("speed_mps: 20\n")
    assert judged[0] == 2


def test_a_scene_with_a_run_s_overrides_is_judged_and_not_remembered(judged, tmp_path):
    from rts_scenario.scenario import load_scenario

    cut_in = Path(__file__).parents[1] / "scenarios" / "cut_in.scenario.yaml"
    load_scenario(cut_in)
    before = judged[0]
    load_scenario(cut_in)  # the file, known: not judged again (nor its rig, profile)
    assert judged[0] == before
    markers = len([p for p in tmp_path.rglob("*") if p.is_file()])
    load_scenario(cut_in, {"duration_s": 9.0})
    load_scenario(cut_in, {"duration_s": 9.0})
    assert judged[0] == before + 2
    assert len([p for p in tmp_path.rglob("*") if p.is_file()]) == markers


def test_a_schema_json_cannot_write_is_judged_every_time(judged, tmp_path):
    # A schema built in code with a set in it: no digest, no memo, no error of its own.
    schema = {"type": "object", "properties": {"mode": {"enum": {"fast", "slow"}}}}
    _validate("mode: fast\n", schema)
    _validate("mode: fast\n", schema)
    with pytest.raises(ScenarioError, match="mode"):
        _validate("mode: auto\n", schema)
    assert judged[0] == 3 and not (tmp_path / located_yaml.VALIDATED_FOLDER).exists()
