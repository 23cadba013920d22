"""The kinds of file the tool reads, told apart by name and by their version key.

A file of one kind given where another belongs (a rig file as a scene, a scene as
``--mapping``) is refused with what it is and where it goes, instead of listing its keys as
unknown.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from .errors import ScenarioError

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


def kind_name(suffix: str) -> str:
    """Return what a file of the kind ``suffix`` is ("a rig file"), as errors name it."""
    return _AS_OTHER.get(suffix, KINDS[suffix][0])


def kind_by_name(name: str | Path) -> str | None:
    """Return the suffix of the kind a file's name says it is (``.rig.yaml``), or ``None``."""
    text = str(name)
    return next((suffix for suffix in KINDS if text.endswith(suffix)), None)


def refuse_other_kind(file: str | Path, data: Any, expected: str) -> None:
    """Raise a `ScenarioError` when ``file`` is another kind than ``expected`` (a suffix).

    A file with the expected kind's version key (``rts_scenario: 1``) is taken as that kind
    whatever its name; otherwise its name (``*.rig.yaml``), then another kind's version key
    (``rts_rig: 1``), tells what it is. A file of no known kind is left to the schema.
    """
    keys = set(data) if isinstance(data, dict) else set()
    own_key = KINDS[expected][1]
    if own_key in keys:
        return
    by_name = kind_by_name(file)
    found = ((by_name, f"*{by_name}") if by_name is not None and by_name != expected else
             next(((suffix, f"its {key} key") for suffix, (_, key, _) in KINDS.items()
                   if suffix != expected and key in keys), None))
    if found is None:
        return
    suffix, evidence = found
    goes = KINDS[suffix][2]
    message = (f"{file} is {kind_name(suffix)} ({evidence}), not {KINDS[expected][0]} "
               f"(*{expected}); {goes}")
    error = ScenarioError(message)
    error.file = str(file)  # the message names it first
    raise error


__all__ = ["KINDS", "kind_by_name", "kind_name", "refuse_other_kind"]


# A scene's version key, at the start of a line (a key of the file's top-level mapping), with
# its value on that line: the format version, a scalar. A section of that name holding a
# mapping or a list (a project's own settings) is no scene.
_SCENE_KEY = re.compile(rb"^rts_scenario[ \t]*:[ \t]*[^\s#{\[]", re.MULTILINE)
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
    return _SCENE_KEY.search(head) is not None
