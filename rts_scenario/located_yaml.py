"""Safe YAML loading that remembers where every value came from, and schema validation.

Every error names the file, line, column and key path of the offending value, as
``file:line:col: key.path: message``.
"""

from __future__ import annotations

import datetime
import functools
import hashlib
import json
import math
import os
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from .errors import ScenarioError, SettingError
from .settings import cache_dir

if TYPE_CHECKING:
    import jsonschema

KeyPath = tuple[str | int, ...]


def format_key_path(path: KeyPath) -> str:
    """Render ``("targets", 2, "speed_mps")`` as ``targets[2].speed_mps``."""
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out


@dataclass(frozen=True)
class Document:
    """A loaded YAML document with the position of every node.

    Attributes
    ----------
    data : object
        Plain Python data (dicts, lists, str, int, float, bool, None).
    file : str
        Path the document was read from.
    marks : dict
        Key path -> (line, column), both 1-based, for every mapping value and list item.
    """

    data: Any
    file: str
    marks: dict[KeyPath, tuple[int, int]]

    def error(self, path: KeyPath, message: str) -> ScenarioError:
        """Return a `ScenarioError` located at the nearest known node of ``path``."""
        probe = tuple(path)
        while probe not in self.marks and probe:
            probe = probe[:-1]
        line, column = self.marks.get(probe, (None, None))
        return ScenarioError(
            message, file=self.file, line=line, column=column,
            key_path=format_key_path(path) or None,
        )


# libyaml's parser when present (an order of magnitude faster), the pure-Python one otherwise;
# both compose nodes with their marks and construct only plain data.
_SafeBase: Any = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class _Loader(_SafeBase):
    """Safe loader; duplicate keys are errors instead of silently overwriting."""


# YAML 1.1 (PyYAML's rules) reads a float only with a dot and a signed exponent, so ``1e6`` and
# ``76.5e9`` would be strings; YAML 1.2's core schema reads them as the numbers engineers mean.
# Plain integers and YAML 1.1 floats keep their resolvers, which come first.
_FLOAT_12 = re.compile(r"^[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)[eE][-+]?[0-9]+$")
_Loader.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT_12, list("-+.0123456789"))


_MAP_TAG = "tag:yaml.org,2002:map"
_SEQ_TAG = "tag:yaml.org,2002:seq"
_MERGE_TAG = "tag:yaml.org,2002:merge"
_INT_TAG = "tag:yaml.org,2002:int"
_FLOAT_TAG = "tag:yaml.org,2002:float"

# Plain scalars YAML 1.1 and YAML 1.2 read differently, and neither as the other guesses: a
# leading zero (010: octal 8, or 10; 09: a string, or 9), base 60 (1:30: 90, or a string),
# digits with underscores (1_0.0: 10.0, or a string), binary (0b1000: 8, or a string), YAML
# 1.2's octal (0o17: a string, or 15) and YAML 1.1's words for booleans (no: false, or a
# string).
_LEADING_ZERO = re.compile(r"^[-+]?0[0-9_]+$")
_OCTAL_12 = re.compile(r"^0o[0-7]+$")
_BOOL_TAG = "tag:yaml.org,2002:bool"


def _ambiguous_number(node: yaml.ScalarNode, value: Any) -> str | None:
    """Why a plain scalar is a number or a boolean only in one YAML version, or None."""
    if node.style:  # quoted or a block scalar: a string in both (plain: None, or "" in libyaml)
        return None
    text = node.value
    if _LEADING_ZERO.match(text):
        digits = text.replace("_", "")
        as_12 = int(digits, 10)
        as_11 = f"octal {value}" if isinstance(value, int) else "a string"
        return (f"{text}: a number with a leading zero reads as {as_11} in YAML 1.1 and as "
                f"{as_12} in YAML 1.2; write it without the leading zero (or quote it for a "
                f"string)")
    if node.tag in (_INT_TAG, _FLOAT_TAG) and ":" in text:
        return (f"{text}: reads as the base-60 number {value:g} in YAML 1.1 and as a string in "
                f"YAML 1.2; write the number ({value:g}), or quote it for a string")
    if node.tag in (_INT_TAG, _FLOAT_TAG) and "_" in text:
        return (f"{text}: a number with underscores reads as {value!r} in YAML 1.1 and as a "
                f"string in YAML 1.2; write it without them ({value!r}), or quote it for a "
                f"string")
    if node.tag == _INT_TAG and text.lstrip("+-").startswith("0b"):
        return (f"{text}: reads as the binary number {value} in YAML 1.1 and as a string in "
                f"YAML 1.2; write the number ({value}), or quote it for a string")
    if _OCTAL_12.match(text):
        number = int(text[2:], 8)
        return (f"{text}: reads as a string in YAML 1.1 and as the octal number {number} in "
                f"YAML 1.2; write the number ({number}), or quote it for a string")
    if node.tag == _BOOL_TAG and text.lower() not in ("true", "false"):
        word = "true" if value else "false"
        return (f"{text}: reads as {word} in YAML 1.1 and as the string {text!r} in YAML 1.2; "
                f"write {word}, or quote it for a string")
    return None


def _construct(node: yaml.Node, path: KeyPath, marks: dict[KeyPath, tuple[int, int]],
               loader: _Loader, file: str) -> Any:
    marks.setdefault(path, (node.start_mark.line + 1, node.start_mark.column + 1))
    expected = _SEQ_TAG if isinstance(node, yaml.SequenceNode) else None
    if isinstance(node, yaml.MappingNode):
        expected = _MAP_TAG
    if expected is not None and node.tag != expected:
        raise ScenarioError(
            f"invalid YAML: tag {node.tag!r} is not allowed (plain data only)", file=file,
            line=node.start_mark.line + 1, column=node.start_mark.column + 1,
            key_path=format_key_path(path) or None,
        )
    if isinstance(node, yaml.MappingNode):
        # YAML's merge keys (``<<: *anchor``): flattening puts the merged pairs first; the keys
        # written in the mapping itself follow and override them, as YAML says.
        written = sum(1 for key_node, _ in node.value if key_node.tag != _MERGE_TAG)
        loader.flatten_mapping(node)
        first_written = len(node.value) - written
        out: dict[str, Any] = {}
        merged: set[str] = set()
        for index, (key_node, value_node) in enumerate(node.value):
            key = loader.construct_object(key_node, deep=True)
            if not isinstance(key, str):
                raise ScenarioError(
                    f"keys must be strings, got {key!r}", file=file,
                    line=key_node.start_mark.line + 1, column=key_node.start_mark.column + 1,
                    key_path=format_key_path(path) or None,
                )
            if key in out:
                if key not in merged:
                    raise ScenarioError(
                        "duplicate key", file=file, line=key_node.start_mark.line + 1,
                        column=key_node.start_mark.column + 1,
                        key_path=format_key_path((*path, key)),
                    )
                # A merged value overridden (by one written here, or merged from a mapping
                # listed before it: flattening puts those later) leaves no marks behind.
                for old in [m for m in marks if m[:len(path) + 1] == (*path, key)]:
                    del marks[old]
            if index < first_written:
                merged.add(key)
            else:
                merged.discard(key)
            # A key's errors point at the key, where a reader looks for it.
            marks[(*path, key)] = (key_node.start_mark.line + 1, key_node.start_mark.column + 1)
            out[key] = _construct(value_node, (*path, key), marks, loader, file)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [
            _construct(item, (*path, i), marks, loader, file) for i, item in enumerate(node.value)
        ]
    try:
        value = loader.construct_object(node, deep=True)
    except (ValueError, TypeError, OverflowError) as exc:  # a tag's value it cannot read
        raise ScenarioError(f"invalid YAML value {node.tag.rsplit(':', 1)[-1]} "
                            f"{getattr(node, 'value', '')!r}: {exc}", file=file,
                            line=node.start_mark.line + 1, column=node.start_mark.column + 1,
                            key_path=format_key_path(path) or None) from None
    if isinstance(node, yaml.ScalarNode):
        ambiguous = _ambiguous_number(node, value)
        if ambiguous is not None:
            raise ScenarioError(ambiguous, file=file, line=node.start_mark.line + 1,
                                column=node.start_mark.column + 1,
                                key_path=format_key_path(path) or None)
    return value


# Bounds that keep a hostile or broken file from exhausting memory, time or the C stack: a
# scene is a few kilobytes; an alias "bomb" of 2 kB would otherwise expand to 10^9 nodes, and
# deep nesting overflows the C composer's stack.
MAX_DOCUMENT_BYTES = 4 * 1024 * 1024
MAX_NODES = 1_000_000
MAX_DEPTH = 64


def _read_bounded(path: str | Path, file: str) -> str:
    try:
        with open(path, "rb") as stream:
            raw = stream.read(MAX_DOCUMENT_BYTES + 1)
    except OSError as exc:
        raise ScenarioError(f"cannot read file: {exc.strerror or exc}", file=file) from None
    if len(raw) > MAX_DOCUMENT_BYTES:
        raise ScenarioError(_too_big(), file=file)
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        # Where an editor shows it: the line, and the characters before it on that line.
        line_start = raw.rfind(b"\n", 0, exc.start) + 1
        column = len(raw[line_start:exc.start].decode("utf-8")) + 1
        raise ScenarioError(f"not UTF-8 text: {exc.reason} (byte 0x{raw[exc.start]:02x}); save "
                            f"the file as UTF-8", file=file,
                            line=raw.count(b"\n", 0, exc.start) + 1, column=column) from None


def _too_big() -> str:
    return (f"document larger than the limit of {MAX_DOCUMENT_BYTES // (1024 * 1024)} MB "
            f"({MAX_DOCUMENT_BYTES} bytes)")


def _check_bounds(text: str, file: str) -> None:
    """Walk the parser's events once: nesting depth and the size with every alias expanded.

    An alias counts as many nodes as the anchored node it repeats, so the expanded size is
    known before anything is composed or constructed (alias bombs fail here, in microseconds).
    """
    loader = _Loader(text)
    try:
        sizes: dict[str, int] = {}
        # [anchor, nodes counted before it] per open collection: a collection's size is what
        # was counted from its start to its end, itself included; each node is counted once.
        stack: list[tuple[str | None, int]] = []
        total = 0

        def fail(event: Any, message: str) -> ScenarioError:
            return ScenarioError(message, file=file, line=event.start_mark.line + 1,
                                 column=event.start_mark.column + 1)

        while True:
            event = loader.get_event()
            if isinstance(event, yaml.StreamEndEvent):
                return
            if isinstance(event, yaml.CollectionStartEvent):
                if len(stack) >= MAX_DEPTH:
                    raise fail(event, f"nesting deeper than the limit of {MAX_DEPTH} levels")
                stack.append((event.anchor, total))
                total += 1
            elif isinstance(event, yaml.AliasEvent):
                if event.anchor not in sizes:
                    if any(anchor == event.anchor for anchor, _ in stack):
                        raise fail(event, f"alias *{event.anchor} refers to a node that "
                                          f"contains it (recursive data is not allowed)")
                    raise fail(event, f"alias *{event.anchor}: no anchor &{event.anchor} "
                                      f"before it (an alias repeats a node anchored earlier "
                                      f"in the file)")
                total += sizes[event.anchor]
            elif isinstance(event, yaml.ScalarEvent):
                total += 1
                if event.anchor is not None:
                    sizes[event.anchor] = 1
            elif isinstance(event, yaml.CollectionEndEvent):
                anchor, before = stack.pop()
                if anchor is not None:
                    sizes[anchor] = total - before
                continue
            else:
                continue
            if total > MAX_NODES:
                raise fail(event, f"document expands to more than {MAX_NODES:,} YAML nodes "
                                  f"(aliases counted as the nodes they repeat)")
    finally:
        loader.dispose()


# The messages of libyaml and of PyYAML's own parser for a block mapping that ended where a key
# was expected: after a line indented out of line with the keys around it.
_NO_KEY = ("did not find expected key", "expected <block end>, but found '<block mapping start>'")
# A key at the start of a line (after list dashes): plain, up to its colon.
_KEY_LINE = re.compile(r"^( *(?:- +)*)[^\s#\-?:'\"{\[][^#]*?:(?: |$)")


def _spaces(count: int) -> str:
    return f"{count} space" if count == 1 else f"{count} spaces"


def _plain_words(error: yaml.MarkedYAMLError, text: str) -> str:
    """PyYAML's message for ``error``, or what went wrong in words that say how to fix it.

    A tab where YAML takes only spaces: both parsers point at it, each with its own words. A
    line indented between the keys of two mappings: the parser says a key is missing; the
    indentations of that mapping's keys and of the line above tell which to line it up with.
    Where a report is ambiguous (a list item at the keys' column: a list, or a key left out?)
    the parser's words stand.
    """
    problem = error.problem or error.context or "invalid YAML"
    mark = error.problem_mark
    if mark is None:
        return f"invalid YAML: {problem}"
    lines = text.splitlines()
    line = lines[mark.line] if mark.line < len(lines) else ""
    before = line[:mark.column]
    if line[mark.column:mark.column + 1] == "\t":
        if not before.strip():
            return "a tab indents this line; YAML indents with spaces"
        return f"a tab after {before.strip()!r} on this line; YAML separates with spaces"
    context = error.context_mark
    if (problem in _NO_KEY and error.context == "while parsing a block mapping"
            and context is not None and not before.strip()
            and mark.column != context.column):
        hint = (f"this line is indented {_spaces(mark.column)}, but the mapping from line "
                f"{context.line + 1} has its keys at {_spaces(context.column)}")
        above = next((i for i in range(mark.line - 1, context.line - 1, -1)
                      if lines[i].strip() and not lines[i].lstrip().startswith("#")), None)
        key = _KEY_LINE.match(lines[above]) if above is not None else None
        if (above is not None and key is not None
                and len(key.group(1)) not in (context.column, mark.column)):
            hint += f" and line {above + 1} above it at {len(key.group(1))}"
        return f"invalid YAML: {hint}; keys of one mapping line up"
    if problem == "but found another document":
        return ("invalid YAML: a second document begins here (after ---); a file holds one "
                "document")
    if _starts_elsewhere(error, text):
        # The error is placed where the construct began (`_error_mark`); where the parser
        # gave up is said.
        return (f"invalid YAML: {problem} at line {mark.line + 1}, column {mark.column + 1} "
                f"({error.context} that begins here)")
    if _flow_line_before(error, text) is not None:
        assert context is not None
        # Placed at the end of the line before the one the parser stopped on (`_error_mark`).
        return (f"invalid YAML: {problem} at line {mark.line + 1}, column {mark.column + 1} "
                f"({error.context} from line {context.line + 1}, column "
                f"{context.column + 1}): a comma left out at the end of this line, or that "
                f"bracket left open?")
    if error.context and context is not None and context.line != mark.line:
        return (f"invalid YAML: {problem} ({error.context} from line {context.line + 1}, "
                f"column {context.column + 1})")
    return f"invalid YAML: {problem}"


def _flow_line_before(error: yaml.MarkedYAMLError, text: str) -> int | None:
    """Return the line (0-based) where a flow collection broken within the file likely breaks.

    The parser stops on the line after the one that lacks its comma (or after the line that
    left a bracket open): the last line with content before the one it stopped on, from the
    collection's first line on. None for other errors.
    """
    context, mark = error.context_mark, error.problem_mark
    if (context is None or mark is None or context.line == mark.line
            or not (error.context or "").startswith("while parsing a flow")
            or not text[mark.index:].strip()):
        return None
    lines = text.splitlines()
    return next((i for i in range(mark.line - 1, context.line - 1, -1)
                 if lines[i].strip() and not lines[i].lstrip().startswith("#")), None)


def _tab_at(error: yaml.MarkedYAMLError, text: str) -> bool:
    """Whether the parser stopped at a tab (said where it is, `_plain_words`)."""
    mark = error.problem_mark
    if mark is None:
        return False
    lines = text.splitlines()
    line = lines[mark.line] if mark.line < len(lines) else ""
    return line[mark.column:mark.column + 1] == "\t"


def _starts_elsewhere(error: yaml.MarkedYAMLError, text: str) -> bool:
    """Whether the parser gave up on a line after the one where the broken construct began.

    An unclosed quote is found only at the end of the file, a key without its colon on the
    line after it: the line to fix is the one where the quoted scalar or the key began. So is
    an unclosed bracket, found at the end of the file; a flow collection broken within the
    file is placed at the end of the line before the parser stopped (`_flow_line_before`).
    """
    context, mark = error.context_mark, error.problem_mark
    if context is None or mark is None or context.line == mark.line:
        return False
    what = error.context or ""
    if what.startswith("while scanning"):
        return True
    return what.startswith("while parsing a flow") and not text[mark.index:].strip()


def _error_mark(error: yaml.MarkedYAMLError, text: str) -> Any:
    """Return the mark an error is placed at: where the broken construct began, else the problem.

    A tab is placed where it is.
    """
    if _tab_at(error, text):
        return error.problem_mark
    if _starts_elsewhere(error, text):
        return error.context_mark
    before = _flow_line_before(error, text)
    if before is not None:
        line = text.splitlines()[before]
        return yaml.Mark("", 0, before, len(line.rstrip()), "", 0)
    return error.problem_mark or error.context_mark


def load_yaml(path: str | Path, text: str | None = None) -> Document:
    """Load one YAML document with a safe loader, keeping line/column marks.

    Documents are bounded: at most `MAX_DOCUMENT_BYTES`, `MAX_NODES` nodes with every alias
    expanded, and `MAX_DEPTH` levels of nesting.

    Raises
    ------
    ScenarioError
        If the file cannot be read, is not valid YAML or exceeds a bound.
    """
    file = str(path)
    if text is None:
        text = _read_bounded(path, file)
    elif len(text.encode("utf-8", "surrogatepass")) > MAX_DOCUMENT_BYTES:
        raise ScenarioError(_too_big(), file=file)
    loader = None
    try:
        _check_bounds(text, file)
        loader = _Loader(text)
        node = loader.get_single_node()
        marks: dict[KeyPath, tuple[int, int]] = {}
        data = None if node is None else _construct(node, (), marks, loader, file)
    except yaml.MarkedYAMLError as exc:
        mark = _error_mark(exc, text)
        line = mark.line + 1 if mark else None
        column = mark.column + 1 if mark else None
        raise ScenarioError(_plain_words(exc, text), file=file, line=line,
                            column=column) from None
    except yaml.reader.ReaderError as exc:
        line = text.count("\n", 0, exc.position) + 1
        raise ScenarioError(f"invalid YAML: {exc.reason} (character {exc.character!r})",
                            file=file, line=line) from None
    except yaml.YAMLError as exc:
        raise ScenarioError(f"invalid YAML: {exc}", file=file) from None
    except (ValueError, TypeError, OverflowError, RecursionError) as exc:
        raise ScenarioError(f"invalid YAML value: {exc}", file=file) from None
    finally:
        if loader is not None:
            loader.dispose()
    return Document(data=data, file=file, marks=marks)


# The top-level keys that carry a file's format version (scene, rig, radar profile, CAN mapping).
VERSION_KEYS = frozenset({"rts_scenario", "rts_rig", "rts_radar", "rts_can_mapping"})


def validate(document: Document, schema: dict[str, Any],
             skip: Iterable[KeyPath] = (), remember: bool = True) -> None:
    """Check ``document`` against a JSON Schema; raise the most relevant error, located.

    ``skip``: key paths whose values are not judged (errors at or below them are left out,
    and a key among them missing is none). ``remember``: keep a document found valid in the
    disk cache, and look it up there first (`_Validated`); not for a document made for one
    run (a file with a run's overrides), which would only push out the files' own.

    Raises
    ------
    ScenarioError
        Naming file, line, key path, the offending value and what is allowed.
    """
    if document.data is None:  # a file with nothing (or only comments) in it
        raise document.error((), "the file is empty: expected a mapping of keys")
    _reject_non_finite(document, document.data, ())
    skipped = [tuple(path) for path in skip]
    known = _Validated.of(document.data, schema, skipped) if remember else None
    if known is not None and known.seen():
        return
    import jsonschema  # here: 27 ms of a command's start, spared where the document is known

    validator = jsonschema.Draft202012Validator(schema)

    def judged(error: jsonschema.ValidationError) -> bool:
        at = tuple(error.absolute_path)
        if error.validator == "required" and isinstance(error.instance, dict):
            missing = [k for k in error.validator_value if k not in error.instance]
            if missing and all((*at, k) in skipped for k in missing):
                return False
        return not any(at[:len(p)] == p for p in skipped)

    errors = [e for e in validator.iter_errors(document.data) if judged(e)]
    # The format version first: a file of another version is not judged by this version's
    # keys (those a later format added are no typos).
    version = next((e for e in errors if e.validator == "enum" and len(e.absolute_path) == 1
                    and e.absolute_path[0] in VERSION_KEYS), None)
    if version is not None:
        raise document.error(tuple(version.absolute_path),
                             f"{_describe(version)} (the file's format version: this version "
                             f"of rts-scenario reads no other)")
    best = jsonschema.exceptions.best_match(errors)
    if best is None:
        if known is not None:
            known.remember()
        return
    path: KeyPath = tuple(best.absolute_path)
    if best.validator == "additionalProperties" and isinstance(best.instance, dict):
        allowed = best.schema.get("properties", {})
        extra = sorted(k for k in best.instance if k not in allowed)
        if extra:
            path = (*path, extra[0])
    raise document.error(path, _describe(best))


class _Validated:
    """A document found valid, remembered in the disk cache (`settings.cache_dir`).

    By the digest of the document, the schema, the keys skipped and the code that judges
    (this module's text): a file validated once is not judged again while none of them
    changes (a command then spares jsonschema's import, about 27 ms of its start). Empty
    marker files in `VALIDATED_FOLDER`, spread over `VALIDATED_SHARDS` subfolders by the
    digest's first characters, each keeping at most its share of `VALIDATED_KEEP` (the oldest
    half of a full one removed). A folder out of reach is no memo, never an error; one that
    can be read but not written still gives the memos in it.
    """

    def __init__(self, path: Path) -> None:
        self.path = path

    @classmethod
    def of(cls, data: Any, schema: dict[str, Any],
           skipped: list[tuple[Any, ...]]) -> _Validated | None:
        """Return the memo of ``data`` against ``schema``; None where none is kept."""
        if not _plain(data):  # JSON would read a tuple as a list, an int key as a string
            return None
        try:
            folder = cache_dir()
        except SettingError:  # said where the setting is checked (the command, the solver)
            return None
        judge = _judge_digest()
        if folder is None or judge is None:
            return None
        try:
            # Not ASCII-escaped: a character and its two surrogates would read alike.
            text = json.dumps([VALIDATED_FORMAT, judge, schema, skipped, data],
                              sort_keys=True, separators=(",", ":"), ensure_ascii=False)
        except (TypeError, ValueError):  # a schema built in code with what JSON cannot write
            return None
        key = hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()
        shard = int(key[:4], 16) * VALIDATED_SHARDS >> 16  # by its first digits
        return cls(folder / VALIDATED_FOLDER / f"{shard:02x}" / key)

    def seen(self) -> bool:
        """Whether this document was found valid before (and mark it used now)."""
        try:
            os.utime(self.path)
        except FileNotFoundError:
            return False
        except OSError:  # another user's marker, a cache mounted read-only, a folder shut
            return os.path.isfile(self.path)  # False on any error
        return True

    def remember(self) -> None:
        """Remember the document as valid; past its shard's share, forget its oldest half."""
        share = max(1, VALIDATED_KEEP // VALIDATED_SHARDS)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.path.touch()
            with os.scandir(self.path.parent) as entries:
                kept = [entry for entry in entries if entry.is_file()]
            if len(kept) > share:
                kept.sort(key=lambda entry: entry.stat().st_mtime)
                for entry in kept[:len(kept) - max(1, share // 2)]:
                    os.unlink(entry.path)
        except OSError:  # a cache out of reach, or a marker another process removed first
            pass


@functools.lru_cache(maxsize=1)
def _judge_digest() -> str | None:
    """Return the digest of the code that judges: this module's text and the package version.

    None where the text cannot be read (no memo then).
    """
    from ._version import __version__

    try:
        text = Path(__file__).read_bytes()
    except OSError:
        return None
    return hashlib.sha256(text + __version__.encode()).hexdigest()


# The disk cache's folder of documents found valid, its subfolders, how many it keeps, and
# the version of the digest's layout (a change of it leaves the old markers unused).
VALIDATED_FOLDER = "validated"
VALIDATED_SHARDS = 256
VALIDATED_KEEP = 4096
VALIDATED_FORMAT = 2


def _plain(node: Any) -> bool:
    """Whether ``node`` is made of what JSON writes as it is (so its text tells it apart)."""
    if node is None or isinstance(node, (str, int, float)):
        return True
    if isinstance(node, list):
        return all(_plain(item) for item in node)
    if isinstance(node, dict):
        return all(isinstance(key, str) and _plain(value) for key, value in node.items())
    return False


# Integers numpy holds (int64); a larger one reaches it as a Python object and fails there.
_INT_BITS = 64


def _reject_non_finite(document: Document, node: Any, path: KeyPath) -> None:
    """Reject numbers the computation cannot hold, whatever the schema says of the key.

    NaN and infinities pass every JSON Schema bound (all comparisons are false); an integer
    beyond 64 bits passes a key without a bound and fails inside numpy.
    """
    if isinstance(node, float) and not math.isfinite(node):
        raise document.error(path, f"must be a finite number, got {node}")
    if (isinstance(node, int) and not isinstance(node, bool)
            and not -(2 ** (_INT_BITS - 1)) <= node < 2 ** (_INT_BITS - 1)):
        raise document.error(path, f"an integer beyond {_INT_BITS} bits, got {node}; integers "
                                   f"must lie from {-(2 ** (_INT_BITS - 1)):,} to "
                                   f"{2 ** (_INT_BITS - 1) - 1:,}")
    if isinstance(node, dict):
        for key, value in node.items():
            _reject_non_finite(document, value, (*path, key))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            _reject_non_finite(document, value, (*path, i))


# A value quoted in a message is cut to this many characters: a mapping written where a number
# goes would otherwise print whole.
_QUOTED_CHARS = 80


def _quoted(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= _QUOTED_CHARS else f"{text[:_QUOTED_CHARS - 5]} ...{text[-1]}"


def _describe(error: jsonschema.ValidationError) -> str:
    value = error.instance
    kind = error.validator
    schema_value = error.validator_value
    if kind == "additionalProperties":
        allowed = sorted(error.schema.get("properties", {}))
        extra = sorted(set(value) - set(allowed)) if isinstance(value, dict) else []
        return f"unknown key {', '.join(map(repr, extra))}; allowed keys: {', '.join(allowed)}"
    if kind == "enum":
        return f"got {_quoted(value)}; allowed values: {', '.join(map(repr, schema_value))}"
    if kind == "type":
        if isinstance(value, (datetime.date, datetime.datetime)):
            # YAML reads an unquoted 2024-01-01 as a date.
            return (f"must be of type {schema_value}, got a date ({value.isoformat()}); "
                    f"quote it for a string: '{value.isoformat()}'")
        if isinstance(value, bytes):
            return f"must be of type {schema_value}, got binary data (!!binary)"
        return f"must be of type {schema_value}, got {_quoted(value)}"
    if kind == "required":
        message = error.message.replace("is a required property", "is required but missing")
        missing = next((k for k in schema_value if isinstance(value, dict) and k not in value),
                       None)
        allowed = error.schema.get("properties", {}).get(missing, {}).get("enum")
        if allowed:
            message += f"; allowed values: {', '.join(map(repr, allowed))}"
        return message
    if kind in ("minimum", "exclusiveMinimum", "maximum", "exclusiveMaximum"):
        op = {"minimum": ">=", "exclusiveMinimum": ">", "maximum": "<=",
              "exclusiveMaximum": "<"}[str(kind)]
        return f"must be {op} {schema_value}, got {value!r}"
    if kind in ("minItems", "maxItems"):
        bound = "at least" if kind == "minItems" else "at most"
        return f"must have {bound} {schema_value} items, got {len(value)}"
    if kind in ("oneOf", "anyOf"):
        return f"got {_quoted(value)}; allowed: {' or '.join(_allowed(s) for s in schema_value)}"
    return f"{error.message}"


_ARTICLES = {"integer": "an integer", "number": "a number", "string": "a string",
             "boolean": "true or false", "array": "a list", "object": "a mapping",
             "null": "nothing"}


def _allowed(schema: Any) -> str:
    """One alternative of a ``oneOf``/``anyOf`` in words: ``an integer >= 0``, ``'auto'``."""
    if not isinstance(schema, dict):
        return repr(schema)
    if "enum" in schema:
        return " or ".join(map(repr, schema["enum"]))
    if "const" in schema:
        return repr(schema["const"])
    kind = schema.get("type")
    words = (_ARTICLES.get(kind, f"a {kind}") if isinstance(kind, str)
             else "a value" if kind is None else " or ".join(_ARTICLES.get(k, k) for k in kind))
    if "minimum" in schema and "maximum" in schema:
        words += f" within {schema['minimum']}..{schema['maximum']}"
    else:
        words += "".join(f" {op} {schema[key]}" for key, op in (
            ("minimum", ">="), ("exclusiveMinimum", ">"), ("maximum", "<="),
            ("exclusiveMaximum", "<")) if key in schema)
    if "minItems" in schema:
        words += f" of at least {schema['minItems']} items"
    if kind == "object" and schema.get("properties"):
        keys = sorted(schema["properties"])
        words += f" of {', '.join(keys)}"
    return words
