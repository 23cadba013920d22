"""Settings read from the environment, checked in one place (no heavy imports).

The command line checks every one of them once before anything runs; library code reads
them where they apply (`rts_scenario.solver.compiled.mode`), and both refuse a value they do
not know with a `SettingError`.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from .errors import SettingError

# Environment variable choosing when to use the compiled kernels: "auto" (default), "on", "off".
JIT_ENV = "RTS_SCENARIO_JIT"
_JIT_MODES = {"": "auto", "auto": "auto", "on": "on", "1": "on", "yes": "on", "true": "on",
              "off": "off", "0": "off", "no": "off", "false": "off"}


def jit_mode() -> str:
    """``$RTS_SCENARIO_JIT`` as one of "auto", "on", "off" (case and spaces aside).

    Unset or empty is "auto"; 1/yes/true are "on", 0/no/false "off". Any other value raises
    `SettingError` naming the variable, the value and the allowed values.
    """
    raw = os.environ.get(JIT_ENV, "")
    chosen = _JIT_MODES.get(raw.strip().lower())
    if chosen is None:
        raise SettingError(f"{JIT_ENV}={raw!r}: unknown value; allowed: auto, on, off (also "
                           "1/0, yes/no, true/false; unset or empty is auto)")
    return chosen


# Environment variable naming the disk cache's folder (solver plans, documents found valid;
# "off" or empty: none).
CACHE_DIR_ENV = "RTS_SCENARIO_CACHE_DIR"


def cache_dir_setting() -> Path | None | bool:
    """``$RTS_SCENARIO_CACHE_DIR``: its folder, False for "off" or empty, None when unset.

    "off" in any case, spaces aside. Raises `SettingError` naming the variable for a value that
    names no folder: a ``~user`` that does not exist, a path that is not there (a mistyped
    path is not made into a tree of new folders) or something that is not a folder (a file, a
    device).
    """
    raw = os.environ.get(CACHE_DIR_ENV)
    if raw is None:
        return None
    if raw.strip().lower() in ("", "off"):
        return False
    allowed = "an existing folder, or off (or empty) for no disk cache"
    try:
        folder = Path(raw).expanduser()
    except RuntimeError as exc:  # "~nosuchuser": no home to expand it to
        raise SettingError(f"{CACHE_DIR_ENV}={raw!r}: {exc}; allowed: {allowed}") from None
    try:
        exists, is_folder = folder.exists(), folder.is_dir()
    except OSError:  # out of reach (no permission): the plans are then not stored, as before
        return folder
    if not is_folder:
        why = "not a folder" if exists else "no such folder"
        raise SettingError(f"{CACHE_DIR_ENV}={raw!r}: {why}; allowed: {allowed}")
    return folder


def cache_dir() -> Path | None:
    r"""Return the disk cache's folder (solver plans, documents found valid); None: disabled.

    Also None where the user has no home to hold it (no disk cache then, as where it cannot
    be written).

    ``$RTS_SCENARIO_CACHE_DIR`` if set ("off" or empty: disabled; `cache_dir_setting` refuses a
    value naming no folder); else the user's cache directory (made when a plan is first
    stored):
    ``%LOCALAPPDATA%\rts-scenario\Cache`` on Windows, ``~/Library/Caches/rts-scenario`` on
    macOS, ``$XDG_CACHE_HOME/rts-scenario`` or ``~/.cache/rts-scenario`` elsewhere.
    """
    chosen = cache_dir_setting()
    if isinstance(chosen, Path):
        return chosen
    if chosen is False:
        return None
    try:
        if sys.platform == "win32":
            local = os.environ.get("LOCALAPPDATA")
            base = Path(local) if local else Path.home() / "AppData" / "Local"
            return base / "rts-scenario" / "Cache"
        if sys.platform == "darwin":
            return Path.home() / "Library" / "Caches" / "rts-scenario"
        xdg = os.environ.get("XDG_CACHE_HOME")
        return (Path(xdg) if xdg else Path.home() / ".cache") / "rts-scenario"
    except RuntimeError:  # no home: $HOME unset and the user has no entry (a bare container)
        return None


def check_environment() -> None:
    """Raise `SettingError` for the first environment setting whose value is not known."""
    jit_mode()
    cache_dir_setting()


__all__ = ["CACHE_DIR_ENV", "JIT_ENV", "cache_dir", "cache_dir_setting", "check_environment",
           "jit_mode"]
