"""The output contract: write batches of schedule frames, close safely, use as a context."""

from __future__ import annotations

from abc import ABC, abstractmethod
from types import TracebackType
from typing import ClassVar

from ..errors import OutputError
from ..schedule import Schedule


class Output(ABC):
    """Where a schedule goes: a file, the RTS over the network, a simulated radar, a plugin.

    Subclasses implement `_write` and `_close`; the base keeps the contract: writing after
    `close` is an error, `close` is safe to call twice, and outputs are context managers.
    """

    name: ClassVar[str] = "output"

    def __init__(self) -> None:
        self._closed = False

    @property
    def closed(self) -> bool:
        """Whether `close` has been called."""
        return self._closed

    def write(self, batch: Schedule) -> None:
        """Send a batch of consecutive frames (a `Schedule`, e.g. ``schedule.frames(a, b)``)."""
        if self._closed:
            raise OutputError(f"{self.name}: write after close")
        self._write(batch)

    def close(self) -> None:
        """Flush and release resources; further calls do nothing."""
        if not self._closed:
            self._closed = True
            self._close()

    def __enter__(self) -> Output:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    @abstractmethod
    def _write(self, batch: Schedule) -> None:
        """Deliver the batch."""

    def _close(self) -> None:  # noqa: B027 - outputs without resources need no cleanup
        """Release resources (once)."""
