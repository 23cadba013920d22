"""Which files are scenes: the one rule of the pytest plugin and `rts-scenario sweep`.

Kept apart from both, and light to import: the plugin asks it of every file pytest collects.
"""

from __future__ import annotations

from fnmatch import fnmatch
from pathlib import Path

from .errors import RtsError
from .file_kinds import holds_scene

# The plugin's ini option naming the scene files (a glob matched against a file's name), and
# its default.
PATTERN_OPTION = "rts_scenario_pattern"
DEFAULT_PATTERN = "*.scenario.yaml"


def check_pattern(pattern: str, where: object = None) -> None:
    """Refuse an ``rts_scenario_pattern`` that names no scene files (``where``: its file).

    A glob of file names that can end in ``.yaml`` or ``.yml``, as far as its text after its
    last wildcard tells (``*.scn.yaml``, ``fine.*``): empty, it matched nothing and every scene
    failed as misnamed; ``*.py`` took test modules for scenes.

    Raises
    ------
    RtsError
        Naming the setting, its file, the value and what is allowed.
    """
    name = pattern.strip()
    # What follows the last wildcard must end as a YAML file's name does, or be the end of one.
    tail = name[max(name.rfind(c) for c in "*?]") + 1:].lower()
    yaml_end = tail.endswith((".yaml", ".yml")) or any(s.endswith(tail) for s in (".yaml",
                                                                                   ".yml"))
    if name and not any(sep in name for sep in "/\\") and yaml_end:
        return
    source = f"{where}: " if where else ""
    raise RtsError(f"{source}{PATTERN_OPTION} = {pattern!r}: must be a glob of scene file names "
                   f"that can end in .yaml or .yml, without a folder (default {DEFAULT_PATTERN})")


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


__all__ = ["DEFAULT_PATTERN", "PATTERN_OPTION", "check_pattern", "misnamed_scene",
           "scene_file_kind"]
