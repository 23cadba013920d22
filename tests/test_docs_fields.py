"""The JSON keys, CSV columns and file layouts the docs name are the ones the commands write.

Outside tools read these files by the names the docs give. Each test runs a command on a short
shipped scene (or writes the file the command writes), collects the keys actually written
(nested, as dotted paths, ``[]`` for the items of a list) and compares them with the keys the
docs name, parsed from the docs as they are written: a table's first column, an inline
``{"key", "key": {...}}`` layout, or a key list in backticks.
"""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
import typing
from pathlib import Path
from typing import Any

import pytest

import rts_scenario.cli as cli

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
SCENE = ROOT / "scenarios" / "gantry_stopped_car.scenario.yaml"  # 4 s, two targets

IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


# --- reading the docs ---------------------------------------------------------------------

def doc(name: str) -> str:
    return (DOCS / name).read_text(encoding="utf-8")


def section(text: str, heading: str) -> str:
    """The text under the markdown heading that contains ``heading``, to the next heading."""
    m = re.search(rf"^#+ [^\n]*{re.escape(heading)}[^\n]*\n(.*?)(?=^#+ |\Z)", text,
                  re.M | re.S)
    assert m, f"no heading with {heading!r}"
    return m.group(1)


def table(text: str, first_column: str) -> list[tuple[list[str], str]]:
    """Rows of the first table whose header starts with ``| first_column |``.

    Each row: the names in backticks in its first cell, and its other cells' text.
    """
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines)
                 if re.match(rf"\|\s*{re.escape(first_column)}\s*\|", line))
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        cells = line.strip().strip("|").split("|", 1)
        names = re.findall(r"`([^`]+)`", cells[0])
        rows.append(([n.strip() for n in names], cells[1] if len(cells) > 1 else ""))
    return rows


def spans(text: str) -> list[str]:
    """The inline backtick spans of ``text`` (fenced code blocks left out)."""
    return re.findall(r"`([^`]+)`", re.sub(r"```.*?```", "", text, flags=re.S))


def backticked(text: str) -> set[str]:
    """Every identifier inside a backtick span (keys and values alike)."""
    return {word for span in spans(text) for word in IDENT.findall(span)}


def named(text: str) -> set[str]:
    """The names ``text`` gives in backticks: a span that is one name, or a layout's keys."""
    out = set()
    for span in spans(text):
        if re.fullmatch(r"[a-z][a-z0-9_]*", span):
            out.add(span)
        elif span.startswith("{"):
            out |= set(re.findall(r'(?:^|[{,])\s*"([a-z][a-z0-9_]*)"', span))
    return out


_TOKEN = re.compile(r'"(?:[^"\\]|\\.)*"|[{}\[\]:,|]|[^\s{}\[\]:,|"]+')


def layout(text: str) -> dict[str, Any]:
    """The keys of a documented layout, ``{"a", "b": {"c"}, "d": [{"e"}, ...], "f": 1}``.

    Real JSON parses too. A value that is an object gives its keys; a list of objects gives the
    union of their keys under ``"[]"``; ``"..."`` and bare words stand for more of the same.
    """
    tokens = _TOKEN.findall(text)
    pos = 0

    def value() -> Any:
        nonlocal pos
        if tokens[pos] == "{":
            return obj()
        if tokens[pos] == "[":
            pos += 1
            items: dict[str, Any] = {}
            while tokens[pos] != "]":
                item = value()
                if isinstance(item, dict):
                    items = merge(items, item)
                if tokens[pos] == ",":
                    pos += 1
            pos += 1
            return {"[]": items} if items else None
        depth = 0  # a scalar, or alternatives: "a" | "b"
        while depth or tokens[pos] not in (",", "}", "]"):
            depth += tokens[pos] in "{[" and 1 or tokens[pos] in "}]" and -1 or 0
            pos += 1
        return None

    def obj() -> dict[str, Any]:
        nonlocal pos
        pos += 1  # {
        out: dict[str, Any] = {}
        while tokens[pos] != "}":
            key = tokens[pos].strip('"')
            pos += 1
            sub = None
            if tokens[pos] == ":":
                pos += 1
                sub = value()
            if key not in ("...", "…"):
                out[key] = merge(out.get(key) or {}, sub) if isinstance(sub, dict) else sub
            if tokens[pos] == ",":
                pos += 1
        pos += 1
        return out

    assert tokens[0] == "{", text[:60]
    return obj()


def merge(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    out = dict(a)
    for k, v in b.items():
        out[k] = merge(out.get(k) or {}, v) if isinstance(v, dict) else out.get(k, v)
    return out


def inline_after(text: str, before: str) -> str:
    """The backtick span ``{...}`` that follows ``before`` in ``text``."""
    i = text.index(before) + len(before)
    m = re.compile(r"`(\{[^`]*\})`").search(text, i)
    assert m, f"no `{{...}}` after {before!r}"
    return m.group(1)


# --- what was written -----------------------------------------------------------------------

def paths(data: Any, prefix: str = "", open_maps: frozenset[str] = frozenset()) -> set[str]:
    """Every key path of ``data``; a key under one of ``open_maps`` (data, not a name) is ``*``."""
    out: set[str] = set()
    if isinstance(data, dict):
        for k, v in data.items():
            p = f"{prefix}.*" if prefix in open_maps else (f"{prefix}.{k}" if prefix else k)
            out.add(p)
            out |= paths(v, p, open_maps)
    elif isinstance(data, list):
        for item in data:
            out |= paths(item, f"{prefix}[]", open_maps)
    return out


def doc_paths(tree: dict[str, Any] | None, prefix: str = "",
              open_maps: frozenset[str] = frozenset()) -> set[str]:
    out: set[str] = set()
    for k, v in (tree or {}).items():
        if k == "[]":
            out |= doc_paths(v, f"{prefix}[]", open_maps)
            continue
        p = f"{prefix}.*" if prefix in open_maps else (f"{prefix}.{k}" if prefix else k)
        out.add(p)
        out |= doc_paths(v, p, open_maps)
    return out


def under_open_map(path: str, open_maps: frozenset[str]) -> bool:
    return any(path.startswith(m + ".") for m in open_maps)


def strings(data: Any) -> set[str]:
    if isinstance(data, dict):
        return set().union(*(strings(v) for v in data.values())) if data else set()
    if isinstance(data, list):
        return set().union(*(strings(v) for v in data)) if data else set()
    return {data} if isinstance(data, str) else set()


def keys(data: Any) -> set[str]:
    if isinstance(data, dict):
        return set(data) | (set().union(*(keys(v) for v in data.values())) if data else set())
    if isinstance(data, list):
        return set().union(*(keys(v) for v in data)) if data else set()
    return set()


def assert_same(written: set[str], documented: set[str], what: str,
                open_maps: frozenset[str] = frozenset(), conditional: frozenset[str] = frozenset()
                ) -> None:
    undocumented = sorted(written - documented)
    unwritten = sorted(p for p in documented - written
                       if p not in conditional and not under_open_map(p, open_maps))
    assert not undocumented and not unwritten, (
        f"{what}: written but not in the docs: {undocumented}; "
        f"in the docs but not written: {unwritten}")


# --- the commands, once -------------------------------------------------------------------

@pytest.fixture(scope="module")
def out(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    tmp = tmp_path_factory.mktemp("docs-fields")
    broken = tmp / "broken.scenario.yaml"
    broken.write_text("rts_scenario: 1\nname: broken\ncolour: red\n", encoding="utf-8")
    # The scene at twice the radar's cycle rate, for 1 s: a scene-wide limit.
    fast = tmp / "fast.scenario.yaml"
    fast.write_text(SCENE.read_text(encoding="utf-8").replace("duration_s: 4.0", "duration_s: 1.0")
                    .replace("frame_rate_hz: 20.0", "frame_rate_hz: 40.0"), encoding="utf-8")
    log = tmp / "drive.blf"
    res: dict[str, Any] = {"tmp": tmp}
    assert cli.main(["run", str(SCENE), "--json", str(tmp / "run.json"), "--record", str(log),
                     "--detections", str(tmp / "det.csv")]) == 0
    # Through a mapping without elevation, which the scene's tolerances name: a quantity not
    # checked (`unchecked_quantities`) and the scene-wide limit quantity_unchecked.
    cli.main(["run", str(fast), str(broken), "--json", str(tmp / "runs.json"), "--mapping",
              str(ROOT / "scenarios" / "can" / "cluster_list.mapping.yaml")])
    # Aligned by the sidecar, and (a copy without it) by the log's timestamps.
    assert cli.main(["check", str(SCENE), "--log", str(log), "--json",
                     str(tmp / "check.json")]) == 0
    bare = tmp / "bare.blf"
    shutil.copy(log, bare)
    assert cli.main(["check", str(SCENE), "--log", str(bare), "--json",
                     str(tmp / "check2.json")]) == 0
    cli.main(["sweep", str(SCENE), str(broken), "--workers", "1", "--json",
              str(tmp / "sweep.json")])
    assert cli.main(["survey", "kit-table1", "--radar", "awr1843boost", "--json",
                     str(tmp / "survey.json")]) == 0
    assert cli.main(["calibrate", "kit-table1", "--inject-phase-deg", "30", "--seed", "1",
                     "--json", str(tmp / "cal.json")]) == 0
    assert cli.main(["schedule", str(SCENE), "--output", f"file:{tmp / 'schedule.csv'}"]) == 0
    for name in ("run", "runs", "check", "check2", "sweep", "survey", "cal"):
        res[name] = json.loads((tmp / f"{name}.json").read_text(encoding="utf-8"))
    res["sidecar"] = json.loads(Path(f"{log}.rts.json").read_text(encoding="utf-8"))
    return res


# --- the run report (docs/report.md, docs/cli.md) -------------------------------------------

def report_rows() -> dict[str, str]:
    rows = {}
    for names, meaning in table(doc("report.md"), "key"):
        for name in names:
            rows[name] = meaning
    return rows


# Where a report's nested keys are data, not names: the scene's limits by name (report.md's
# limits table), the parameters by key path.
REPORT_DATA_KEYS = ("parameters", "scene_limits", "targets[].limits")
# Names report.md's key table gives that a run's JSON need not hold: values these short runs
# do not give, keys of the scene and radar files the text refers to, a key only a clock whose
# bus times bent writes, and the detections' lag (their scenes' targets do not move in range).
# (The limits' names are values too, from report.md's table.)
REPORT_VALUES = {"true", "false", "null", "profile", "bus", "built", "memory", "disk", "off",
                 "frame_period_s", "clock", "parametrize", "latency_change_s", "interface",
                 "detection_lag_s", "detection_lag_error_s", "detection_lag_coupling_s",
                 "range_doppler_coupling", "corrected", "early_s",
                 # Written only where a radar started its count after the scene began.
                 "late_start_s",
                 # Written only where the host's wall clock stepped during the run.
                 "host_clock_steps", "at_s", "within_s", "size_s",
                 # Written only where another sender's stream took the RTS over
                 # (tests/test_outputs.py).
                 "foreign_datagrams",
                 # Written only where the RTS's counters (lost_frames among them) do not
                 # account for every frame at the stream's end (tests/test_outputs.py).
                 "unaccounted_frames", "lost_frames",
                 # Written only where datagrams came back undelivered (tests/test_outputs.py),
                 # and the commands that stop on them.
                 "address", "datagrams", "error", "first_s", "last_s", "calibrate", "survey"}


def _report_entries(out: dict[str, Any]) -> list[dict[str, Any]]:
    return [out["run"], *[e for e in out["runs"] if e["status"] != "error"],
            out["check"], out["check2"]]


def test_report_keys_are_the_documented_ones(out):
    """Every key a run or a re-check writes is in report.md's table, in its row."""
    rows = report_rows()
    limits = {n for names, _ in table(doc("report.md"), "limit") for n in names}
    cli_keys = {n for names, _ in table(section(doc("cli.md"), "with a parametrized scene"),
                                        "key") for n in names}
    check_text = section(doc("cli.md"), "run --record")
    alignment = set(layout(inline_after(check_text, "`alignment`:")))
    problems = []
    for entry in _report_entries(out):
        for key, value in entry.items():
            if key in ("file", "status", "marks") and key in cli_keys:
                continue
            if key in ("log", "alignment") and "alignment" in entry:
                assert key in backticked(check_text)
                continue
            if key not in rows:
                problems.append(f"{entry['scene']}: top-level key {key!r} not in report.md")
                continue
            for path in paths(value, key):
                parts = path.replace("[]", "").split(".")
                if any(path.startswith(d + ".") for d in REPORT_DATA_KEYS):
                    # A limit's name, or what a scene-wide limit says about itself.
                    if parts[-2] in ("limits", "scene_limits") and parts[-1] not in limits:
                        problems.append(f"{path}: not a limit report.md lists")
                    continue
                row = rows["errors"] if path.startswith("targets[].errors.") else rows[key]
                if parts[-1] not in backticked(row):
                    problems.append(f"{path}: written, not named in report.md's `{key}` row")
    for key in out["check"]["alignment"]:
        if key not in alignment:
            problems.append(f"alignment.{key}: written, not in docs/cli.md's `alignment`")
    assert not problems, "\n".join(sorted(set(problems)))


def test_report_documented_keys_are_written(out):
    """Every name report.md's table gives a run's key is written (or is one of its values)."""
    entries = _report_entries(out)
    written = set().union(*(keys(e) | strings(e) for e in entries))
    limits = {n for names, _ in table(doc("report.md"), "limit") for n in names}
    missing = []
    for key, meaning in report_rows().items():
        if not any(key in e for e in entries):
            missing.append(key)
        for name in named(meaning) - REPORT_VALUES - limits - written:
            missing.append(f"{key}: {name}")
    assert not missing, f"named in report.md, never written: {missing}"


def test_error_entry_and_check_alignment_keys(out):
    """A scene that does not load: exactly the keys docs/cli.md names; `alignment` likewise."""
    (error,) = [e for e in out["runs"] if e["status"] == "error"]
    para = section(doc("cli.md"), "with a parametrized scene")
    para = para[para.index("An entry with `status: error`"):]
    para = para[:para.index("\n\n")]
    documented = named(re.sub(r"\([^()]*\)", "", para[para.index("holds only"):]))
    assert set(error) == documented
    check_text = section(doc("cli.md"), "run --record")
    documented_alignment = set(layout(inline_after(check_text, "`alignment`:")))
    bench_text = doc("bench.md")
    i = bench_text.index("JSON's `alignment` (")
    bench_alignment = {n for n in backticked(bench_text[i + 20:bench_text.index(")", i + 20)])}
    for entry in (out["check"], out["check2"]):
        assert set(entry["alignment"]) == documented_alignment == bench_alignment
        assert {"file", "log", "status", "alignment"} <= set(entry)


# --- the log's sidecar ----------------------------------------------------------------------

SIDECAR_OPEN = frozenset({"parameters", "truth.targets"})


def sidecar_doc() -> dict[str, Any]:
    text = section(doc("cli.md"), "run --record")
    tree = layout(inline_after(text, "writes `LOG.rts.json`:"))
    # Sub-layouts given in the prose: `name`: `{...}`.
    for name in ("send_lateness", "truth", "statuses"):
        tree[name] = layout(inline_after(text, f"`{name}`:"))
    return tree


def test_sidecar_keys_are_the_documented_ones(out):
    from rts_scenario.recheck import SIDECAR_SCHEMA

    documented = doc_paths(sidecar_doc(), open_maps=SIDECAR_OPEN)
    sidecar = dict(out["sidecar"])
    playback = sidecar.pop("playback")
    written = paths(sidecar, open_maps=SIDECAR_OPEN) | {"playback"}
    assert_same(written, documented, "LOG.rts.json", SIDECAR_OPEN)
    # `playback`: the report's, as report.md names it.
    assert set(playback) == set(out["run"]["playback"])

    def schema_paths(schema: dict[str, Any], prefix: str = "") -> set[str]:
        found = set()
        for k, sub in schema.get("properties", {}).items():
            p = f"{prefix}.{k}" if prefix else k
            found.add(p)
            if k not in ("playback", "quanta"):
                found |= schema_paths(sub, p)
        return found

    schema = schema_paths(SIDECAR_SCHEMA)
    assert_same(schema, {p for p in documented if not p.startswith("truth.quanta.")
                         and not under_open_map(p, SIDECAR_OPEN)},
                "recheck.SIDECAR_SCHEMA")


# --- sweep ----------------------------------------------------------------------------------

SWEEP_OPEN = frozenset({"runs[].parameters", "runs[].errors", "summary.by_parameter",
                        "summary.by_parameter.*"})


def test_sweep_keys_are_the_documented_ones(out):
    text = section(doc("cli.md"), "`sweep`")
    example = re.search(r"```json\n(.*?)```", text, re.S).group(1)  # type: ignore[union-attr]
    documented = doc_paths(layout(example), open_maps=SWEEP_OPEN)
    # `interrupted` is in the summary only when Ctrl-C stopped the sweep.
    assert "interrupted" in backticked(text)
    written = paths(out["sweep"], open_maps=SWEEP_OPEN)
    assert_same(written, documented, "sweep --json", SWEEP_OPEN)
    run_keys = {n for names, _ in table(text, "key of a run") for n in names}
    assert run_keys == keys(out["sweep"]["runs"]) - keys([r["parameters"] for r in
                                                          out["sweep"]["runs"]]) - keys(
        [r.get("errors", {}) for r in out["sweep"]["runs"]])


# --- survey, calibrate ----------------------------------------------------------------------

# Written only where the host's clock stepped during a measurement (tests/test_host_clock.py
# checks them against these).
HOST_STEPS = frozenset(f"host_clock_steps[].{k}" for k in ("measurement", "at_s", "within_s",
                                                           "size_s", "corrected"))


def test_survey_keys_are_the_documented_ones(out):
    text = section(doc("cli.md"), "`survey`")
    documented = doc_paths(layout(inline_after(text, "`--json` writes")))
    assert_same(paths(out["survey"]), documented, "survey --json", conditional=HOST_STEPS)


def test_calibrate_keys_are_the_documented_ones(out):
    text = section(doc("cli.md"), "`calibrate`")
    example = re.search(r"```json\n(.*?)```", text, re.S).group(1)  # type: ignore[union-attr]
    assert_same(paths(out["cal"]), doc_paths(layout(example)), "calibrate --json",
                conditional=HOST_STEPS)
    assert all(isinstance(s, str) for s in out["cal"]["suspects"])
    assert [c["fe"] for c in out["cal"]["channels"]][0] == 0


# --- bench ----------------------------------------------------------------------------------

def test_bench_keys_are_the_documented_ones(tmp_path):
    """`bench.write_json` with one record of each kind: every section documented, key by key."""
    from rts_scenario import bench, perf

    def one(cls: Any) -> Any:
        sample = {int: 1, float: 1.0, str: "x", bool: True}
        types = typing.get_type_hints(cls)
        return cls(**{f.name: sample[types[f.name]] for f in dataclasses.fields(cls)})

    path = tmp_path / "bench.json"
    bench.write_json([one(bench.BenchRow)], [one(bench.QuantizationRow)], path,
                     one(bench.EndToEndRow), [one(bench.HonestRow)], [one(perf.Figure)])
    data = json.loads(path.read_text())
    text = section(doc("cli.md"), "`bench`")
    top = layout(inline_after(text, "`--json OUT` writes"))
    assert set(data) == set(top)
    for name, of_list, spec in re.findall(r"- `(\w+)`: (a list of )?`(\{[^`]*\})`", text):
        value = data[name][0] if of_list else data[name]
        assert isinstance(data[name], list) == bool(of_list), name
        assert list(value) == list(layout(spec)), name
    documented = set(re.findall(r"- `(\w+)`: (?:a list of )?`\{", text))
    assert documented == set(data)


# --- CSV files ------------------------------------------------------------------------------

def test_detections_csv_columns_are_the_documented_ones(out):
    header = (out["tmp"] / "det.csv").read_text(encoding="utf-8").splitlines()[0].split(",")
    documented = [n for names, _ in table(section(doc("report.md"), "Detections"), "column")
                  for n in names]
    assert header == documented


def test_schedule_csv_columns_are_the_documented_ones(out):
    from rts_scenario.outputs.file import CSV_COLUMNS

    lines = (out["tmp"] / "schedule.csv").read_text(encoding="utf-8").splitlines()
    assert lines[0] == "# rts-scenario schedule v1" and lines[1].startswith("# targets: ")
    text = doc("cli.md")
    assert "`# rts-scenario schedule v1`" in text and "`# targets: NAME,NAME,...`" in text
    documented = [n for names, _ in table(text, "column") for n in names]
    assert lines[2].split(",") == documented == list(CSV_COLUMNS)


def test_rts_status_counters_are_the_documented_ones():
    """`playback.rts` holds the RTS's counters as udp-protocol.md lists them."""
    from rts_scenario.outputs.udp import STATUS_COUNTERS, decode_status, encode_status

    text = doc("udp-protocol.md")
    listed = text[text.index("then u32 counters"):text.index("then a CRC-32")]
    documented = re.findall(r"`(\w+)`", re.sub(r"\([^)]*\)", "", listed))
    counters = decode_status(encode_status(dict.fromkeys(STATUS_COUNTERS, 1)))
    assert counters is not None and list(counters) == documented


# --- the command line (docs/cli.md) ---------------------------------------------------------

def _subcommands() -> dict[str, Any]:
    import argparse

    parser = cli.build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(sub.choices)


def _options(parser: Any) -> list[Any]:
    return [a for a in parser._actions
            if a.option_strings and not {"-h", "--debug"} & set(a.option_strings)]


def synopses(text: str, command: str) -> list[str]:
    """The command lines cli.md gives for ``rts-scenario COMMAND`` (inline spans, code blocks)."""
    chunks = spans(text) + re.findall(r"```sh\n(.*?)```", text, re.S)
    return [c for c in chunks if re.match(rf"rts-scenario {re.escape(command)}(\s|$)", c)]


def test_every_option_of_every_subcommand_is_in_its_synopsis_in_cli_md():
    """A user finds every option of a subcommand on its command line in docs/cli.md."""
    text = doc("cli.md")
    missing = []
    for name, parser in _subcommands().items():
        lines = " ".join(synopses(text, name))
        for action in _options(parser):
            if not any(re.search(rf"{re.escape(o)}(?![\w-])", lines)
                       for o in action.option_strings):
                missing.append(f"{name} {'/'.join(action.option_strings)}")
    assert not missing, f"options not on their subcommand's command line in cli.md: {missing}"


def _default_text(value: Any) -> list[str]:
    if isinstance(value, float) and value.is_integer():
        return [str(int(value)), str(value)]
    if isinstance(value, int):
        return [str(value), f"{value:,}"]
    return [str(value)]


def test_option_defaults_in_cli_md_are_argparse_defaults():
    """Every option with a default says it in cli.md, next to the option, as argparse has it.

    Looked for in the section that gives the subcommand's full command line: ``--opt ... default
    V`` or ``--opt ... `V` (default`` within a sentence, no other option between.
    """
    text = doc("cli.md")
    problems = []
    for name, parser in _subcommands().items():
        synopsis = synopses(text, name)
        if not synopsis:
            continue
        # The section (between level-2 headings) holding the subcommand's command line.
        where = text.index(max(synopsis, key=len))
        start = text.rfind("\n## ", 0, where)
        end = text.find("\n## ", where)
        sect = text[start:end if end > 0 else None]
        for action in _options(parser):
            if action.default in (None, False) or action.nargs == 0:
                continue
            opt = action.option_strings[-1]
            values = _default_text(action.default)
            found = [m.group(1) or m.group(2) for m in re.finditer(
                rf"{re.escape(opt)}(?![\w-])(?:(?!--[a-z])[^.;]){{0,160}}?"
                rf"(?:\bdefault:?\s+`?([\w.,-]+)|`([\w.,-]+)`\s+\(default\b)", sect, re.S)]
            if not found:
                problems.append(f"{name} {opt}: no default in cli.md (argparse: {values[0]})")
            elif not any(f.rstrip(".,`") in values for f in found):
                problems.append(f"{name} {opt}: cli.md says default {found}, argparse "
                                f"{values[0]}")
    assert not problems, "\n".join(problems)


# --- the UDP stream (docs/udp-protocol.md) --------------------------------------------------

_WIRE = {"u8": "B", "u16": "H", "u32": "I", "i16": "h", "f32": "f", "f64": "d"}


def wire_fields(text: str) -> list[tuple[str, str]]:
    """``(name, struct code)`` of a layout "`name` u16, `name` 4 bytes ..." (big-endian)."""
    out = []
    for name, kind in re.findall(r"`(\w+)`\s+(\d+ bytes|[uif]\d+)", text):
        out.append((name, f"{kind.split()[0]}s" if "bytes" in kind else _WIRE[kind]))
    return out


def test_udp_datagram_decoded_by_the_documented_layout():
    """A datagram the sender encodes, read back field by field as udp-protocol.md lays it out."""
    import struct
    import zlib

    import numpy as np

    from rts_scenario.outputs.udp import ENTRY, KIND_DELTA, MAX_ENTRIES, encode_frame

    text = doc("udp-protocol.md")
    rows = {m.group(1): (int(m.group(2)), m.group(3)) for m in re.finditer(
        r"^\| (header|entries|trailer) \| (\d+) bytes[^|]*\| ([^|]*)\|", text, re.M)}
    header, entry = wire_fields(rows["header"][1]), wire_fields(rows["entries"][1])
    head_fmt = ">" + "".join(c for _, c in header)
    entry_fmt = ">" + "".join(c for _, c in entry)
    assert struct.calcsize(head_fmt) == rows["header"][0] == 28
    assert struct.calcsize(entry_fmt) == rows["entries"][0] == ENTRY.itemsize
    assert [n for n, _ in entry] == list(ENTRY.names)
    at_most = int(re.search(r"at most (\d+) entries", text).group(1))  # type: ignore[union-attr]
    assert at_most == MAX_ENTRIES

    entries = np.zeros(at_most + 3, dtype=ENTRY)  # two parts
    entries["target"] = np.arange(entries.size) // 4
    entries["channel"] = np.arange(entries.size) % 4
    entries["flags"] = 1
    entries["fe"] = np.arange(entries.size) % 15 - 1
    entries["status"] = 0x0102
    entries["attenuation_db"] = 12.5
    entries["delay_s"] = 1.234567890123e-7
    entries["doppler_hz"] = -2500.25
    entries["phase_rad"] = -1.5
    datagrams = encode_frame(entries, kind=KIND_DELTA, frame=70000, t_s=3500.05,
                             first_sequence=2**32 - 1)
    seen = []
    for part, datagram in enumerate(datagrams):
        h = dict(zip([n for n, _ in header], struct.unpack_from(head_fmt, datagram), strict=True))
        assert (h["magic"], h["version"], h["kind"]) == (b"RTSS", 1, 1)
        assert (h["sequence"], h["frame"], h["part"], h["parts"]) == (
            (2**32 - 1 + part) % 2**32, 70000, part, 2)
        assert h["t_s"] == 3500.05
        body = len(datagram) - rows["trailer"][0]
        assert body == 28 + h["entries"] * 28 and len(datagram) <= 1400
        assert struct.unpack(">I", datagram[body:]) == (zlib.crc32(datagram[:body]),)
        for i in range(h["entries"]):
            seen.append(struct.unpack_from(entry_fmt, datagram, 28 + 28 * i))
    assert seen == [tuple(e.item()) for e in entries]


def test_udp_replies_decoded_by_the_documented_layout():
    """The status and rig replies, and the rig's geometry digest, as udp-protocol.md gives them."""
    import hashlib
    import struct
    import zlib

    import numpy as np

    from rts_scenario.outputs.udp import STATUS_COUNTERS, encode_rig_reply, encode_status
    from rts_scenario.playback import rts_rig_record
    from rts_scenario.rig import Rig

    text = doc("udp-protocol.md")
    status_text = text[text.index("## Status replies"):text.index("then a CRC-32")]
    fields = wire_fields(status_text)
    assert [n for n, _ in fields] == ["magic", "version"]
    counters = re.findall(r"`(\w+)`", re.sub(r"\([^)]*\)", "",
                                             status_text[status_text.index("u32 counters"):]))
    reply = encode_status({c: i + 1 for i, c in enumerate(STATUS_COUNTERS)})
    fmt = ">4sB" + "I" * len(counters)
    assert len(reply) == struct.calcsize(fmt) + 4
    values = struct.unpack_from(fmt, reply)
    assert values[:2] == (b"RTSR", 1)
    assert dict(zip(counters, values[2:], strict=True)) == {
        c: i + 1 for i, c in enumerate(STATUS_COUNTERS)}
    assert struct.unpack(">I", reply[-4:]) == (zlib.crc32(reply[:-4]),)

    rig_text = text[text.index("## Rig replies"):]
    fields = wire_fields(rig_text[:rig_text.index("then a CRC-32")])
    assert [n for n, _ in fields] == ["magic", "version", "front_ends", "geometry"]
    # A rig with antenna offsets and a direction that rounds to -0: the digest by the doc's words.
    rig = Rig(name="t", az_deg=[-5.4, 4.5, -3.4, 3.8], el_deg=[-8.8, -7.7, 8.4, -4e-10],
              distance_m=[1.0, 1.1, 1.2, 1.3], rows=2, columns=2, cal_delay_s=0.0,
              cal_phase_deg=0.0, cal_gain_db=0.0,
              rx_offset_m=[[0.01, 0.0], [0.0, 0.02], [0.0, 0.0], [-0.03, 0.0]],
              tx_offset_m=[0.0, 0.005])
    expected = hashlib.sha256(struct.pack("<qq", 2, 2))
    values_in_order = [*rig.az_deg, *rig.el_deg, *rig.distance_m,
                       *np.ravel(rig.rx_offset_m), *np.ravel(rig.tx_offset_m)]
    for v in values_in_order:
        r = round(float(v), 9)
        expected.update(struct.pack("<d", 0.0 if r == 0 else r))
    reply = encode_rig_reply(4, rig.geometry_digest())
    fmt = ">" + "".join(c for _, c in fields)
    assert len(reply) == struct.calcsize(fmt) + 4
    assert struct.unpack_from(fmt, reply) == (b"RTSI", 1, 4, expected.digest())
    assert struct.unpack(">I", reply[-4:]) == (zlib.crc32(reply[:-4]),)
    # `playback.rts_rig` holds the keys the doc names for it.
    documented = named(rig_text[rig_text.index("`playback.rts_rig`"):])
    record = rts_rig_record((4, rig.geometry_digest()), rig)
    assert record is not None and set(record) == documented - {"playback"}


# --- per-frame arrays, the .npz schedule, mapping files -------------------------------------

def test_per_frame_arrays_are_the_documented_ones():
    import rts_scenario as rs

    scene = rs.load_scenario(SCENE)
    report = rs.run_scene(scene, rs.RunOptions(record=True)).report
    text = doc("report.md")
    para = text[text.index("`report.per_frame` reads them back ("):]
    para = para[:para.index("\n\n")]
    documented = set(spans(para)) - {"report.per_frame", "frames.adjacent_frame"}
    quantities = {f"error_{q}" for q in report.errors}
    written = set(report.per_frame)
    assert written - quantities == documented - {"error_<quantity>", "(frames, targets)"}
    assert quantities == {f"error_{q}" for q in ("range_m", "radial_velocity_mps", "az_deg",
                                                 "el_deg", "rcs_dbsm")} <= written


def test_npz_schedule_arrays_are_the_documented_ones(out):
    import numpy as np

    path = out["tmp"] / "schedule.npz"
    assert cli.main(["schedule", str(SCENE), "--output", f"file:{path}"]) == 0
    text = doc("cli.md")
    para = text[text.index("A `.npz` holds"):]
    para = para[:para.index("\n\n")]
    documented = {s for s in spans(para) if re.fullmatch(r"[a-z_]+", s)} - {"npz"}
    with np.load(path) as data:
        shapes = {k: data[k].shape for k in data.files}
    assert set(shapes) == documented
    frames, targets = shapes["status"]
    dims = {"frames": frames, "targets": targets}
    for names, shape in re.findall(r"((?:`[a-z_]+`(?:,| and)? )+)`\(([^)]*)\)`", para):
        want = tuple(dims.get(d.strip(), None) or int(d) for d in shape.split(",") if d.strip())
        for name in re.findall(r"`([a-z_]+)`", names):
            assert shapes[name] == want, name


def test_can_mapping_keys_are_the_documented_ones():
    """The keys can-mapping.md's example and its prose give are the loader's schema."""
    import yaml

    from rts_scenario.canbus.mapping import CHECKSUM_SCHEMES, MAPPING_SCHEMA, QUANTITIES

    text = doc("can-mapping.md")
    example = yaml.safe_load(re.search(r"```yaml\n(.*?)```", text, re.S).group(1))  # type: ignore[union-attr]
    props = MAPPING_SCHEMA["properties"]
    assert set(example) == set(props)
    assert set(example["header"]) == set(props["header"]["properties"])
    detection = set(props["detection"]["properties"])
    assert set(example["detection"]) <= detection
    # The cartesian quantities are in the prose; every quantity is named somewhere.
    assert detection - set(example["detection"]) <= set(QUANTITIES)
    assert set(QUANTITIES) <= set(example["detection"]) | backticked(text)
    schemes = {n for names, _ in table(text, "`scheme`") for n in names}
    assert schemes == set(CHECKSUM_SCHEMES)


# --- the pytest plugin (README.md) ----------------------------------------------------------

def test_plugin_options_and_defaults_are_in_the_readme():
    """Every ``--rts-*`` option of the plugin is in the README, with argparse's default."""
    import pytest_rts_scenario

    options: dict[str, Any] = {}

    class Group:
        def addoption(self, name: str, **kwargs: Any) -> None:
            options[name] = kwargs

    class Parser:
        def getgroup(self, *args: Any) -> Group:
            return Group()

        def addini(self, *args: Any, **kwargs: Any) -> None:
            pass

    pytest_rts_scenario.pytest_addoption(Parser())  # type: ignore[arg-type]
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section_text = section(text, "pytest plugin")
    problems = []
    for name, kwargs in options.items():
        if name not in section_text:
            problems.append(f"{name}: not in the README's pytest plugin section")
        default = kwargs.get("default")
        if default is not None and not re.search(
                rf"`{re.escape(name)}`\s+\(default\s+`{re.escape(str(default))}`", section_text):
            problems.append(f"{name}: the README does not give its default {default!r}")
    assert not problems, "\n".join(problems)


def test_time_alignment_line_is_the_documented_lag():
    """The text's `time alignment:` line is `detection_lag_s` and three of its standard errors."""
    import rts_scenario as rs

    report = rs.run_scene(rs.load_scenario(SCENE), rs.RunOptions()).report
    clock = report.to_dict()["radar_clock"]
    m = re.search(r"time alignment: the detections fit the scene ([\d.]+) ms \(\+-([\d.]+) ms\) "
                  r"(before|after) the cycles' times", report.table())
    assert m, report.table()
    lag, error = clock["detection_lag_s"], clock["detection_lag_error_s"]
    assert float(m.group(1)) == round(abs(lag) * 1e3, 1)
    assert float(m.group(2)) == round(3 * error * 1e3, 1)
    assert m.group(3) == ("before" if lag > 0 else "after")
    row = report_rows()["radar_clock"]
    assert re.search(r"`time alignment:` line[^;]*plus or minus three standard errors", row)


def test_sweep_s_exit_codes_are_documented():
    """docs/cli.md has a table of the codes `sweep` exits with, each of them once."""
    from rts_scenario.cli import common

    text = section(doc("cli.md"), "`sweep`")
    lines = text[text.index("| code | `sweep` |"):].splitlines()[2:]
    rows = lines[:next(i for i, line in enumerate(lines) if not line.startswith("|"))]
    documented = [int(line.strip("|").split("|")[0]) for line in rows]
    assert documented == [common.EXIT_OK, common.EXIT_FAIL, common.EXIT_BAD_INPUT,
                          common.EXIT_RUNTIME_ERROR, common.EXIT_NO_RUNS]


def test_udp_status_bits_are_the_schedule_s_status_flags():
    """An RTS reads an entry's `status` bit by bit from the table in udp-protocol.md."""
    from rts_scenario.check import _LIMIT_FLAGS
    from rts_scenario.outputs.udp import ENTRY
    from rts_scenario.schedule import BLOCKING, Status

    text = doc("udp-protocol.md")
    rows = re.findall(r"^\| (\d+) \| (\d+) \| `([A-Z_]+)` \|", text, re.M)
    documented = {name: (int(bit), int(value)) for bit, value, name in rows}
    flags = {f.name: f.value for f in Status if f.value}
    assert set(documented) == set(flags)
    for name, (bit, value) in documented.items():
        assert value == flags[name] == 1 << bit, name
    # Every flag fits the entry's field, and the played ones are the two the doc names.
    assert sum(flags.values()) < 1 << (8 * ENTRY["status"].itemsize)
    played = {f.name for f in Status if f.value and not f & BLOCKING}
    assert played == {"ATTENUATION_CLIPPED", "ANGLE_QUANTIZED"}
    assert all(f"`{name}`" in text for name in played)
    # The report's limits are the flags' names in lower case.
    assert {name.lower() for name in flags} - {"not_present"} == set(_LIMIT_FLAGS)
