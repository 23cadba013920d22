"""Which files are scenes: the one rule of the pytest plugin and `rts-scenario sweep`.

Kept apart from both, and light to import: the plugin asks it of every file pytest collects.
"""

from __future__ import annotations

from fnmatch import fnmatch
from pathlib import Path

from .file_kinds import holds_scene

# The plugin's ini option naming the scene files (a glob matched against a file's name), and
# its default.
PATTERN_OPTION = "rts_scenario_pattern"
DEFAULT_PATTERN = "*.scenario.yaml"


def scene_file_kind(path: Path, pattern: str = DEFAULT_PATTERN) -> str | None:
    """Say what ``path`` is to the pytest plugin and the sweep: ``scene``, ``misnamed`` or None.

    A file whose name matches ``pattern`` (the project's ``rts_scenario_pattern``) is a scene
    file. One that holds a scene (`holds_scene`) under another name, whatever the pattern, is
    ``misnamed``: a failing item, an erred run, never a scene left out unseen (a project picks
    the scenes a run runs by their marks, ``-m``, or its folders, ``norecursedirs``).
    """
    if fnmatch(path.name, pattern):
        return "scene"
    return "misnamed" if holds_scene(path) else None


def misnamed_scene(name: str, pattern: str = DEFAULT_PATTERN) -> str:
    """Say that the file ``name`` holds a scene but is not named as ``pattern`` says.

    Where ``pattern`` is a suffix (``*.scenario.yaml``), the file's name before its first dot
    with that suffix is the name to give it.
    """
    stem = Path(name).name.split(".", 1)[0]
    suffix = pattern[1:] if pattern.startswith("*") else ""
    rename = (f"rename it {stem}{suffix}" if suffix and not any(c in suffix for c in "*?[")
              else "rename it to match that pattern")
    named = (pattern if pattern == DEFAULT_PATTERN
             else f"{pattern} (the project's {PATTERN_OPTION})")
    return (f"{name} holds a scene (its rts_scenario key) but is not named {named}, so it does "
            f"not run as one; {rename}")


__all__ = ["DEFAULT_PATTERN", "PATTERN_OPTION", "misnamed_scene", "scene_file_kind"]
