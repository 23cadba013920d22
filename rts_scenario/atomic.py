"""Files replaced whole: a reader sees the old file or the new one, never half of one."""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from collections.abc import Iterator
from contextlib import AbstractContextManager
from pathlib import Path
from typing import IO, Any, BinaryIO, Literal, TextIO, overload


@overload
def open_atomic(path: str | Path, mode: Literal["w"] = "w") -> AbstractContextManager[TextIO]:
    ...


@overload
def open_atomic(path: str | Path, mode: Literal["wb"]) -> AbstractContextManager[BinaryIO]:
    ...


def open_atomic(path: str | Path, mode: str = "w") -> AbstractContextManager[IO[Any]]:
    """Open a draft beside ``path`` (``mode`` ``"w"``, UTF-8 text, or ``"wb"``), renamed over it.

    What the ``with`` block writes replaces ``path`` when the block ends. A block that fails
    (a full disk, a file size limit, an interrupt) leaves what ``path`` held before and removes
    the draft. The file keeps its permissions, or gets those a new file gets; a link is
    followed, and the file it names is replaced. What is not a regular file (``/dev/null``,
    ``/dev/stdout``, a named pipe) is written into, never replaced: a rename would put a file
    in a device's place, and a pipe has no folder to draft in.
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"mode: 'w' or 'wb', got {mode!r}")
    return _replacing(path, mode)


def write_atomic(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` through a draft beside it (`open_atomic`)."""
    with open_atomic(path) as file:
        file.write(text)


def check_draft(path: str | Path) -> None:
    """Make and remove the draft `open_atomic` would make for ``path`` (which need not exist).

    Raises the `OSError` making it raises (a folder that takes no new file), so that a caller
    can find it before the work whose result goes to ``path``. For a folder, a draft of a file
    in it; nothing for a device or a pipe, which are written into.
    """
    target = (Path(os.path.realpath(path)) / "new" if os.path.isdir(path)
              else _replaced(path))
    if target is not None:
        file, draft = _open_draft(target, "wb")
        file.close()
        os.unlink(draft)


@contextlib.contextmanager
def _replacing(path: str | Path, mode: str) -> Iterator[IO[Any]]:
    target = _replaced(path)
    if target is None:
        with open(path, mode, encoding=None if "b" in mode else "utf-8") as file:
            yield file
        return
    try:
        permissions = target.stat().st_mode & 0o7777
    except FileNotFoundError:
        umask = os.umask(0)
        os.umask(umask)
        permissions = 0o666 & ~umask
    file, draft = _open_draft(target, mode)
    try:
        with file:
            yield file
            file.flush()
            os.fchmod(file.fileno(), permissions)
        os.replace(draft, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(draft)
        raise


def _replaced(path: str | Path) -> Path | None:
    """Return the file a draft is renamed over for ``path`` (links followed); None: write into."""
    try:
        found = os.stat(path)
    except FileNotFoundError:
        found = None
    if found is not None and not stat.S_ISREG(found.st_mode):
        return None
    return Path(os.path.realpath(path))


def _open_draft(target: Path, mode: str) -> tuple[IO[Any], str]:
    """Create a draft for ``target`` in its folder: the draft open in ``mode``, and its path."""
    fd, draft = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".draft")
    return os.fdopen(fd, mode, encoding=None if "b" in mode else "utf-8"), draft
