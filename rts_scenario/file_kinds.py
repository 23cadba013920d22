"""The kinds of file the tool reads, told apart by name, by their version key and by content.

A file of one kind given where another belongs (a rig file as a scene, a scene as
``--mapping``), or a file of another tool's format (a DBC, an OpenSCENARIO file, a CAN log), is
refused with what it is and where it goes, instead of listing its keys as unknown or quoting
the YAML parser.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from .errors import ScenarioError
from .located_yaml import Document, load_yaml

# suffix -> (what it is, its version key, where it goes)
KINDS = {
    ".scenario.yaml": ("a scene", "rts_scenario",
                       "run, validate and sweep take it"),
    ".rig.yaml": ("a rig file", "rts_rig",
                  "a scene names its rig under rig:, survey and calibrate take it as RIG, "
                  "emulate as --rig"),
    ".radar.yaml": ("a radar profile", "rts_radar",
                    "a scene names its radar under radar.profile, emulate, survey and calibrate "
                    "take it as --radar"),
    ".mapping.yaml": ("a CAN mapping", "rts_can_mapping",
                      "run and check take it as --mapping"),
}

# How a scene is named where it is the wrong kind ("a scene file", not "a scene").
_AS_OTHER = {".scenario.yaml": "a scene file"}

_CAN_MAPPING_WAY = ("--mapping takes a CAN mapping that names a DBC and which of its signals "
                    "carry what (docs/can-mapping.md)")
_CAN_LOG_WAY = "rts-scenario check SCENE --log LOG checks it against its scene"

# Other tools' files: suffix -> (what it is, a pattern of its content (None: not told by
# content), where it goes). Content is looked at only in a file that is no YAML mapping.
FOREIGN: dict[str, tuple[str, re.Pattern[str] | None, str]] = {
    ".dbc": ("a DBC file",
             re.compile(r'^(?:VERSION\s+"|NS_\s*:|BU_\s*:|BO_\s+\d+\s+\w+\s*:)', re.MULTILINE),
             _CAN_MAPPING_WAY),
    ".arxml": ("an AUTOSAR CAN database", re.compile(r"<AUTOSAR[\s>]"), _CAN_MAPPING_WAY),
    ".kcd": ("a KCD CAN database", re.compile(r"<NetworkDefinition[\s>]"), _CAN_MAPPING_WAY),
    ".sym": ("a SYM CAN database", re.compile(r"^FormatVersion\s*=", re.MULTILINE),
             _CAN_MAPPING_WAY),
    ".xosc": ("an OpenSCENARIO file", re.compile(r"<OpenSCENARIO[\s>]"), ""),
    # Logs python-can reads and writes; .csv, .log and .db are other things as often.
    **{suffix: ("a CAN log", None, _CAN_LOG_WAY) for suffix in (".asc", ".blf", ".mf4", ".trc")},
}

# A scene fragment holds targets and, at most, a description (the scene format's fragment).
_FRAGMENT_KEYS = {"description", "targets"}
_FRAGMENT = ("a scene fragment", "only targets and a description",
             "a scene lists it under include: (scenarios/README.md, Fragments)")
# How much of a file is read to tell its format by content.
_SNIFF_BYTES = 8192
# How many mapping files beside a DBC are read for the one that names it.
_MAX_SIBLINGS = 64
_DBC_KEY = re.compile(r"""^dbc:[ \t]*(["']?)(.+?)\1[ \t]*(?:#.*)?$""", re.MULTILINE)


def kind_name(suffix: str) -> str:
    """Return what a file of the kind ``suffix`` is ("a rig file"), as errors name it."""
    if suffix in FOREIGN:
        return FOREIGN[suffix][0]
    return _AS_OTHER.get(suffix, KINDS[suffix][0])


def kind_by_name(name: str | Path) -> str | None:
    """Return the suffix of the kind a file's name says it is (``.rig.yaml``, ``.dbc``)."""
    text = str(name).lower()
    return next((suffix for suffix in (*KINDS, *FOREIGN) if text.endswith(suffix)), None)


def read_only_kind(name: str | Path) -> tuple[str, str] | None:
    """Return ``(suffix, what it is)`` of a kind the tool reads and never writes, by name.

    Scenes, rigs, profiles, mappings, CAN databases and OpenSCENARIO files: an output so named
    would replace an input another run needs (`run --record` writes CAN logs).
    """
    suffix = kind_by_name(name)
    if suffix is None or FOREIGN.get(suffix, ("",))[0] == "a CAN log":
        return None
    return suffix, KINDS[suffix][0] if suffix in KINDS else FOREIGN[suffix][0]


def _head(file: str | Path) -> str:
    try:
        with open(file, "rb") as stream:
            return stream.read(_SNIFF_BYTES).decode("latin-1")
    except OSError:
        return ""


def _named_by(file: str | Path, dbc: Path) -> list[str]:
    """Return the CAN mappings beside ``dbc`` that name it."""
    folder = Path(file).parent
    found = []
    for mapping in sorted(folder.glob("*.mapping.yaml"))[:_MAX_SIBLINGS]:
        match = _DBC_KEY.search(_head(mapping))
        if match is not None and (folder / match.group(2)).resolve() == dbc:
            found.append(str(mapping))
    return found


def _where_it_goes(file: str | Path, suffix: str) -> str:
    """Where a file of the kind ``suffix`` goes, with the ways forward this file has."""
    if suffix in KINDS:
        return KINDS[suffix][2]
    goes = FOREIGN[suffix][2]
    if suffix == ".xosc":
        stem = Path(file).name.removesuffix(Path(file).suffix)
        return (f"rts-scenario import {file} --radar P --rig R --output {stem}.scenario.yaml "
                f"converts it to a scene (docs/import.md)")
    if suffix == ".dbc":
        naming = _named_by(file, Path(file).resolve())
        if naming:
            goes += f": {', '.join(naming)} names this one"
    elif goes == _CAN_MAPPING_WAY:
        goes += f"; cantools convert {file} RADAR.dbc writes it as a DBC"
    return goes


def identify(file: str | Path, data: Any, expected: str | None = None,
             ) -> tuple[str, str, str] | None:
    """Tell what ``file`` (its YAML ``data``) is when it is not of the kind ``expected``.

    A file with the expected kind's version key (``rts_scenario: 1``) is taken as that kind
    whatever its name. Otherwise its name (``*.rig.yaml``, ``*.dbc``), another kind's version
    key (``rts_rig: 1``), a fragment's keys, or, for a file that is no YAML mapping, its content
    (a DBC's ``BO_`` lines, an ``<OpenSCENARIO>`` root) tells what it is. ``expected``: a suffix
    of `KINDS`, or ``None`` for a file that is no YAML kind (a CAN log).

    Returns
    -------
    tuple of str or None
        ``(what it is, how that shows, where it goes)``, or ``None`` for a file of the expected
        kind or of no known kind (left to the schema, the parser or the reader).
    """
    keys = set(data) if isinstance(data, dict) else set()
    if expected is not None and KINDS[expected][1] in keys:
        return None
    by_name = kind_by_name(file)
    if by_name is not None and by_name != expected:
        return kind_name(by_name), f"*{by_name}", _where_it_goes(file, by_name)
    by_key = next((suffix for suffix, (_, key, _) in KINDS.items()
                   if suffix != expected and key in keys), None)
    if by_key is not None:
        return kind_name(by_key), f"its {KINDS[by_key][1]} key", _where_it_goes(file, by_key)
    if by_name is None and "targets" in keys and keys <= _FRAGMENT_KEYS:
        return _FRAGMENT
    if not isinstance(data, dict):
        head = _head(file)
        by_content = next((suffix for suffix, (_, pattern, _) in FOREIGN.items()
                           if pattern is not None and pattern.search(head)), None)
        if by_content is not None:
            return kind_name(by_content), "by its content", _where_it_goes(file, by_content)
    return None


def refuse_other_kind(file: str | Path, data: Any, expected: str) -> None:
    """Raise a `ScenarioError` when ``file`` is another kind than ``expected`` (a suffix).

    ``data``: the file's YAML data (``None`` when it is not YAML). See `identify`.
    """
    found = identify(file, data, expected)
    if found is None:
        return
    what, evidence, goes = found
    message = f"{file} is {what} ({evidence}), not {KINDS[expected][0]} (*{expected}); {goes}"
    error = ScenarioError(message)
    error.file = str(file)  # the message names it first
    raise error


def other_than_fragment(file: str | Path, data: Any) -> str | None:
    """Say what ``file``, listed under a scene's ``include:``, is instead of a fragment.

    ``data``: its YAML data. ``None`` when it may be a fragment (left to the fragment schema).

    Returns
    -------
    str or None
        ``a rig file (its rts_rig key), not a scene fragment (...); where it goes``.
    """
    found = identify(file, data)
    if found is None or found == _FRAGMENT:
        return None
    what, evidence, goes = found
    return f"{what} ({evidence}), not {_FRAGMENT[0]} ({_FRAGMENT[1]}); {goes}"


def load_kind(path: str | Path, expected: str) -> Document:
    """Load ``path`` as a file of the kind ``expected`` (a suffix of `KINDS`).

    Raises
    ------
    ScenarioError
        The file is of another kind (naming it and where it goes), or is no valid YAML.
    """
    try:
        doc = load_yaml(path)
    except ScenarioError:
        if Path(path).is_file():
            refuse_other_kind(path, None, expected)
        raise
    refuse_other_kind(path, doc.data, expected)
    return doc


__all__ = ["FOREIGN", "KINDS", "identify", "kind_by_name", "kind_name", "load_kind",
           "other_than_fragment", "read_only_kind", "refuse_other_kind"]


# A scene's version key, at the start of a line (a key of the file's top-level mapping), with
# its value on that line: the format version, a scalar. A section of that name holding a
# mapping or a list (a project's own settings) is no scene.
_SCENE_KEY = re.compile(rb"^(?:rts_scenario|\"rts_scenario\"|'rts_scenario')[ \t]*:[ \t]*[^\s#{\[]",
                        re.MULTILINE)
# How much of a YAML file is read to find it (a scene starts with it, after its comments).
_HEAD_BYTES = 65536


def holds_scene(path: Path) -> bool:
    """Whether ``path``, a ``.yaml``/``.yml`` file, holds a scene (its ``rts_scenario`` key).

    The key at the top level with a value on its line, as a scene gives its format version:
    `sweep` and the pytest plugin take such a file under another name than
    ``*.scenario.yaml`` for a misnamed scene.
    """
    if path.suffix.lower() not in (".yaml", ".yml"):
        return False
    try:
        with path.open("rb") as file:
            head = file.read(_HEAD_BYTES)
    except OSError:
        return False
    # As YAML reads it: after a byte-order mark (some editors write one), the key quoted or not.
    return _SCENE_KEY.search(head.removeprefix(b"\xef\xbb\xbf")) is not None
