"""The stops (Ctrl-C, SIGTERM) a command saw, whether or not their interrupt got through.

The command line raises `KeyboardInterrupt` for each (`rts_scenario.cli`); a library that
catches every exception (a bare ``except:`` while it imports, numpy inside some of its calls)
can swallow it, and the command then ran on to its end as if never stopped. What is noted here
lets the command still end as stopped (``error: interrupted``, never exit 0) and an output
being written still end as cut short.
"""

from __future__ import annotations

_seen = [False]
_handled = [False]


def note() -> None:
    """Note that a stop came (the signal handler, before it raises `KeyboardInterrupt`)."""
    _seen[0] = True


def handled() -> None:
    """Note that the command caught the `KeyboardInterrupt` and ends as stopped."""
    _handled[0] = True


def seen() -> bool:
    """Whether a stop came since `reset`."""
    return _seen[0]


def swallowed() -> bool:
    """Whether a stop came whose `KeyboardInterrupt` the command never caught."""
    return _seen[0] and not _handled[0]


def reset() -> None:
    """Forget the stops: a command begins."""
    _seen[0] = _handled[0] = False


__all__ = ["handled", "note", "reset", "seen", "swallowed"]
