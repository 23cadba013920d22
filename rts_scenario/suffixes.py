"""File-name suffixes of the files the tool reads and writes.

A module of constants only, importing nothing: the command line names a scene's "not run"
entries with them even when a stop came while the library was still being imported.
"""

# A scene file's name ends so (`rts_scenario.scenario.load_scenario`).
SCENE_SUFFIX = ".scenario.yaml"
# What `run --record` names the sidecar it writes beside a log (`rts_scenario.pipeline`).
LOG_SIDECAR_SUFFIX = ".rts.json"

__all__ = ["LOG_SIDECAR_SUFFIX", "SCENE_SUFFIX"]
