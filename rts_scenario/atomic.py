"""Files replaced whole: a reader sees the old file or the new one, never half of one."""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from collections.abc import Iterator
from contextlib import AbstractContextManager
from pathlib import Path
from typing import IO, Any, BinaryIO, Literal, TextIO, cast, overload


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


class Draft:
    """A file written over a long time (a run's detections): a draft beside ``path`` until done.

    ``file`` (UTF-8 text, ``newline`` as `open`'s) is a draft in ``path``'s folder, so a process
    killed while writing leaves no file named ``path`` that looks whole, and runs writing the
    same path at once each write their own. What ``path`` held before is removed at the start:
    it is not this run's. `keep` names the draft ``path``; `cut_short` names it
    ``path.partial``. What is not a regular file (``/dev/null``, a pipe) is written into, and
    so is a file whose folder takes no new file (then `cut_short` renames it, which such a
    folder may refuse: the `OSError` is raised).
    """

    def __init__(self, path: str | Path, newline: str | None = None) -> None:
        self.path = Path(path)
        target = _replaced(path)
        self._target = target
        self._draft: str | None = None
        # The first error writing (`write`): the file is then cut short whatever follows.
        self.error: OSError | None = None
        if target is not None:
            permissions = _permissions(target)
            try:
                handle, self._draft = _open_draft(target, "w", newline)
            except OSError:
                pass  # a folder that takes no new file: written into
            else:
                self.file = cast(TextIO, handle)
                try:
                    _chmod(handle, self._draft, permissions)
                    target.unlink(missing_ok=True)
                except BaseException:
                    self.discard()
                    raise
                return
        self.file = open(path, "w", encoding="utf-8", newline=newline)

    @property
    def name(self) -> Path:
        """The file being written: the draft, or ``path`` itself where it is written into."""
        return self.path if self._draft is None else Path(self._draft)

    def write(self, text: str) -> int:
        """Write ``text`` to ``file``, unless a write failed before: then nothing, silently.

        A failing write (a full disk) is kept in `error` and not raised, so that the work
        whose by-product this file is goes on (a run's verdicts stand); whoever ends the draft
        asks `error`, and `cut_short` names what was written as not whole.
        """
        if self.error is None:
            try:
                return self.file.write(text)
            except OSError as exc:
                self.error = exc
        return len(text)

    def keep(self) -> Path:
        """Close the file and name it ``path``; return that."""
        return self._close_as(self._target)

    @property
    def partial(self) -> Path | None:
        """What `cut_short` names the file: ``path.partial``, beside the file ``path`` names.

        None where ``path`` is not a regular file (written into).
        """
        return None if self._target is None else self._target.with_name(
            self._target.name + ".partial")

    def cut_short(self) -> Path:
        """Close the file and name it `partial` (``path`` not a regular file: itself)."""
        return self._close_as(self.partial)

    def discard(self) -> None:
        """Close the file and remove the draft (nothing written stays)."""
        self.file.close()
        if self._draft is not None:
            with contextlib.suppress(OSError):
                os.unlink(self._draft)

    def _close_as(self, name: Path | None) -> Path:
        try:
            self.file.close()  # closed even where its last flush fails
        except OSError:
            if name == self._target:
                raise  # not whole: not named ``path``
            # Cut short anyway: what the flush could not write is lost with the rest.
        if name is None or (self._draft is None and name == self._target):
            return self.path
        os.replace(self.path if self._draft is None else self._draft, name)
        if name == self._target:
            return self.path
        # As the caller named it, unless ``path`` is (or runs through) a link: the draft was
        # beside the file the link names, and so is what it became.
        given = self.path.with_name(self.path.name + ".partial")
        same = os.path.abspath(self.path) == str(self._target)
        return given if same else name


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
    permissions = _permissions(target)
    file, draft = _open_draft(target, mode)
    try:
        with file:
            yield file
            file.flush()
            _chmod(file, draft, permissions)
        os.replace(draft, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(draft)
        raise


def _chmod(file: IO[Any], path: str, permissions: int) -> None:
    """Give the open draft ``file`` (at ``path``) ``permissions``.

    By its path where there is no ``os.fchmod`` (Windows before Python 3.13).
    """
    if hasattr(os, "fchmod"):
        os.fchmod(file.fileno(), permissions)
    else:
        os.chmod(path, permissions)


def _permissions(target: Path) -> int:
    """Return the permissions of ``target``, or those a new file gets (the umask)."""
    try:
        return target.stat().st_mode & 0o7777
    except FileNotFoundError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask


def _replaced(path: str | Path) -> Path | None:
    """Return the file a draft is renamed over for ``path`` (links followed); None: write into."""
    try:
        found = os.stat(path)
    except FileNotFoundError:
        found = None
    if found is not None and not stat.S_ISREG(found.st_mode):
        return None
    return Path(os.path.realpath(path))


def _open_draft(target: Path, mode: str, newline: str | None = None) -> tuple[IO[Any], str]:
    """Create a draft for ``target`` in its folder: the draft open in ``mode``, and its path."""
    fd, draft = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".draft")
    if "b" in mode:
        return os.fdopen(fd, mode), draft
    return os.fdopen(fd, mode, encoding="utf-8", newline=newline), draft
