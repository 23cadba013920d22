"""The output contract: write batches of schedule frames, close safely, use as a context."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

from ..errors import OutputError
from ..schedule import Schedule

if TYPE_CHECKING:
    import numpy as np

    from ..detections import Detections
    from ..radar.profile import RadarProfile
    from ..radar.simulate import ChannelErrors
    from ..rig import Rig
    from ..scenario.model import RadarOptions

_O = TypeVar("_O", bound="Output")


@dataclass(frozen=True)
class RunContext:
    """What a run offers the output it opens (`Output.for_run`).

    ``open_publisher`` returns a sink for radar cycles (a list at a time, in order) that the
    run's checker will receive (it
    opens the publishing side of the detection bus; the run closes it).
    """

    rig: Rig
    radar: RadarProfile
    radar_options: RadarOptions
    open_publisher: Callable[[], Callable[[list[Detections]], None]]
    rng: np.random.Generator
    errors: ChannelErrors | None = None


class Output(ABC):
    """Where a schedule goes: a file, the RTS over the network, a simulated radar, a plugin.

    Subclasses implement `_write` and `_close`; the base keeps the contract: writing after
    `close` is an error, `close` is safe to call twice, and outputs are context managers.
    """

    name: ClassVar[str] = "output"
    # Whether a radar cycle measured at a frame's time surely sees that frame: true of an
    # output that applies each frame exactly at its time (the simulated radar). An RTS
    # applies a frame after it arrives (transport, its own update), so a cycle measured at the
    # frame's time may still show the frame before (docs/bench.md, the ambiguity window).
    applies_frames_on_time: ClassVar[bool] = False
    # The scene's frame period (s), set by a run before its first frame: how long the RTS
    # holds a batch's last frame when the batch does not tell (a batch of one frame, a scene
    # of one frame). None where no run set it.
    frame_period_s: float | None = None

    def __init__(self) -> None:
        self._closed = False

    @classmethod
    def for_run(cls: type[_O], argument: str, context: RunContext) -> _O:
        """Open this output for a run (``argument``: the text after ``NAME:`` in the spec).

        Outputs that need to know the rig or the radar override this; the default ignores the
        context.
        """
        return cls(argument) if argument else cls()  # type: ignore[call-arg]

    @property
    def closed(self) -> bool:
        """Whether `close` has been called."""
        return self._closed

    def write(self, batch: Schedule) -> None:
        """Send a batch of consecutive frames (a `Schedule`, e.g. ``schedule.frames(a, b)``)."""
        if self._closed:
            raise OutputError(f"{self.name}: write after close")
        self._write(batch)

    def sent_t_s(self, batch: Schedule) -> np.ndarray:
        """Return the scene times at which the frames of ``batch`` (just written) went out.

        An output that delivers each frame exactly at its time (the simulated radar, a file
        replayed by its times) returns ``batch.t_s``, the default; one that paces frames
        in real time returns when it really sent each (`rts_scenario.outputs.udp.UdpOutput`):
        the RTS cannot apply a frame before it has it, and the checker finds the frame each
        radar cycle saw by these times.
        """
        return batch.t_s

    def rts_status(self, settle_s: float = 0.0) -> dict[str, int] | None:
        """Return the RTS's own counters of what it received and applied, if it reports them.

        None (the default) when the output has no RTS that reports: a lost frame then shows
        only in what the radar measured. ``settle_s``: at the end of a stream, how long to
        wait for the RTS's last report.
        """
        return None

    def rts_unreachable(self) -> dict[str, Any] | None:
        """Return what the network said of datagrams nothing received, if it said anything.

        None (the default) when the output sends nothing over a network, or nothing came back
        (`rts_scenario.outputs.udp.UdpOutput.rts_unreachable`).
        """
        return None

    def rts_rig(self) -> tuple[int, bytes] | None:
        """Return the FE count and geometry digest the RTS says it plays, if it says.

        None (the default) when the output has no RTS that says (`Rig.geometry_digest`).
        """
        return None

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
