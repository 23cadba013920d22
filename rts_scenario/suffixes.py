"""File-name suffixes of the files the tool reads and writes.

A module of constants only, importing nothing: the command line names a scene's "not run"
entries with them even when a stop came while the library was still being imported.
"""

# A scene file's name ends so (`rts_scenario.scenario.load_scenario`).
SCENE_SUFFIX = ".scenario.yaml"

__all__ = ["SCENE_SUFFIX"]
