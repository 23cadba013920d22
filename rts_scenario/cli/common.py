"""What the subcommands share: exit codes, the progress bar, errors of files named by options."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from ..errors import RtsError

EXIT_OK = 0
EXIT_FAIL = 1
EXIT_BAD_INPUT = 2


class Progress:
    """A one-line progress bar on stderr, only when it is a terminal."""

    def __init__(self, label: str) -> None:
        self.label = label
        self.active = sys.stderr.isatty()

    def __call__(self, done: int, total: int) -> None:
        """Show ``done`` of ``total`` frames; short runs (< 200 frames) show nothing."""
        if not self.active or total < 200:
            return
        width = 30
        filled = int(width * done / total)
        sys.stderr.write(f"\r{self.label} [{'#' * filled}{'.' * (width - filled)}] "
                         f"{done}/{total} frames")
        if done >= total:
            sys.stderr.write("\r" + " " * (len(self.label) + width + 24) + "\r")
        sys.stderr.flush()


@contextmanager
def writing(option: str, path: str | Path) -> Iterator[None]:
    """Turn an `OSError` while writing what ``option`` names into an `RtsError` naming both."""
    try:
        yield
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise RtsError(f"{option} {path}: cannot write: {reason}") from exc
