"""A command's start-up: its imports with Python's cyclic garbage collector paused.

Importing the modules a run needs (numpy, python-can, cantools, jsonschema and this package's)
makes a few hundred thousand objects that live as long as the process. The collector would
scan them over and over while they are made, and again in its first full collections after:
tens of milliseconds of a command's start, for nothing. `command_imports` pauses it during the
imports and then moves what exists into the permanent generation (`gc.freeze`), where it is
never scanned again, as Python's documentation suggests for objects made at start-up.

Only in the command's own process (`mark_command_process`, called by its entry point): a
program or test session that calls the command's functions many times keeps its collector as
it set it, and its own objects are never frozen.
"""

from __future__ import annotations

import contextlib
import gc
from collections.abc import Iterator

_state = {"command": False, "done": False}


def mark_command_process() -> None:
    """Say that this process is an ``rts-scenario`` command's own (its entry point's call)."""
    _state["command"] = True


@contextlib.contextmanager
def command_imports() -> Iterator[None]:
    """Run the body (the command's imports) with the collector paused, then freeze what exists.

    Once per process, and only where `mark_command_process` was called; elsewhere the body runs
    as it is. The collector is enabled again after it, if it was before.
    """
    if not _state["command"] or _state["done"]:
        yield
        return
    _state["done"] = True
    enabled = gc.isenabled()
    try:
        gc.disable()
        yield
    finally:
        # Enabled first: a stop between the two leaves it running, the objects only unfrozen.
        if enabled:
            gc.enable()
        gc.freeze()


__all__ = ["command_imports", "mark_command_process"]
