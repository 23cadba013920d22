"""Detections over CAN: python-can transport, cantools encoding, frame reassembly.

The simulated radar publishes each frame in a mapping's protocol (rts-scenario's own by
default: a header message with frame counter, detection count and time, then two classic CAN
messages per detection or one CAN FD message, each with an end-to-end checksum); a detection no
signal can carry is left out and counted (`DetectionPublisher.unsendable`).
`DetectionReceiver` is a python-can listener that decodes any radar's messages through a
`CanMapping` and reassembles them into `Detections` (one per radar cycle), counting everything
that goes wrong on the way. It keeps only the few cycles still being assembled: memory does not
grow with the length of a run.
"""

from __future__ import annotations

import threading
import zlib
from collections import Counter, OrderedDict, deque
from dataclasses import dataclass, field
from typing import Any

import can
import cantools
import numpy as np

from ..detections import Detections
from ..errors import CheckError, OutputError
from .mapping import CanMapping, PartKey, checksum_byte, multiplexer, page_signals

DEFAULT_INTERFACE = "virtual"
DEFAULT_CHANNEL = "rts-scenario"


def open_bus(interface: str = DEFAULT_INTERFACE, channel: str = DEFAULT_CHANNEL, *,
             fd: bool = False, **options: Any) -> can.BusABC:
    """Open a python-can bus, with one clear error if the interface or channel is unusable."""
    valid = sorted(can.interfaces.VALID_INTERFACES)
    if interface not in valid:
        raise CheckError(f"CAN interface {interface!r} unknown; valid interfaces: "
                         f"{', '.join(valid)}")
    try:
        return can.Bus(interface=interface, channel=channel, fd=fd, **options)
    except (can.CanError, OSError, ImportError, ValueError, TypeError) as exc:
        raise CheckError(f"cannot open CAN interface {interface!r} channel {channel!r}: "
                         f"{exc}") from None


def _checksum(data: bytes, position: int) -> int:
    """Low 8 bits of the CRC-32 of the payload without its checksum byte."""
    return zlib.crc32(data[:position] + data[position + 1 :]) & 0xFF


def _limits(sig: cantools.database.can.Signal) -> tuple[float, float]:
    """Return a signal's physical range as the DBC states it (ours states every one)."""
    assert sig.minimum is not None and sig.maximum is not None
    return float(sig.minimum), float(sig.maximum)


def _checksum_byte(message: cantools.database.can.Message, name: str) -> int:
    pos = checksum_byte(message, name)
    assert pos is not None  # the mapping checked it
    return pos


class DetectionPublisher:
    """Encode radar cycles in a radar's protocol (rts-scenario's own by default) and send them.

    ``mapping`` names the protocol (a DBC and what its signals mean, `CanMapping`): the header
    that opens a cycle, then each detection's message(s), multiplexer pages or CAN FD message
    (with ``fd``). A detection is sent only if every value fits its signal: a value outside a
    signal's range (a negative range from sub-bin interpolation, a range or velocity beyond what
    the DBC scales to, NaN) cannot be carried, and neither can a detection past the last index
    or count the layout has (rts-scenario's classic messages index 256 detections per cycle,
    CAN FD 1023). Such a detection is left out of its cycle (the header announces only the ones
    sent, so the cycle still arrives complete) and counted, never an error. RCS and SNR saturate
    at their signals' limits instead.

    Attributes
    ----------
    sent : int
        Messages sent.
    unsendable : collections.Counter of str
        Detections left out, by the signal that could not carry them (e.g. ``{"Range": 2}``);
        a detection with several such values counts once, for the first of them.
    unsendable_detections : int
        Detections left out in total (``sum(unsendable.values())``).
    unsendable_reason : str or None
        One line on the first detection left out: cycle, detection, signal, value, range.
    """

    def __init__(self, bus: can.BusABC, *, fd: bool = False,
                 mapping: CanMapping | None = None) -> None:
        self.bus = bus
        self.fd = fd
        self.mapping = mapping or CanMapping.builtin()
        self._layout = _MappedLayout(self.mapping, fd)
        self.sent = 0
        self.unsendable: Counter[str] = Counter()
        self.unsendable_reason: str | None = None

    @property
    def unsendable_detections(self) -> int:
        """Detections left out because no signal could carry them."""
        return sum(self.unsendable.values())

    def _leave_out(self, cycle: int, index: int, signal: str, value: float,
                   allowed: str) -> None:
        self.unsendable[signal] += 1
        if self.unsendable_reason is None:
            self.unsendable_reason = (f"CAN: cycle {cycle} detection {index} not sent: {signal} "
                                      f"{value:g} outside {allowed}")

    def _send(self, message: cantools.database.can.Message, values: dict[str, float],
              checksum: str | None, timestamp: float = 0.0) -> None:
        try:
            data = bytearray(message.encode(values, strict=True))
        except (cantools.database.EncodeError, KeyError, ValueError) as exc:
            raise OutputError(f"CAN {message.name}: {exc}") from None
        if checksum is not None and checksum in {sg.name for sg in message.signals}:
            pos = _checksum_byte(message, checksum)
            data[pos] = _checksum(bytes(data), pos)
        self.bus.send(can.Message(arbitration_id=message.frame_id, data=bytes(data),
                                  is_extended_id=message.is_extended_frame,
                                  is_fd=self.fd or message.is_fd or len(data) > 8,
                                  timestamp=timestamp))
        self.sent += 1

    def publish(self, frame: Detections, bus_time_s: float = 0.0) -> None:
        """Send one cycle: header, then every detection the messages can carry.

        ``bus_time_s`` stamps the cycle's messages (a bus that keeps senders' timestamps, like
        python-can's virtual bus with ``preserve_timestamps``, shows when the radar would have
        sent them).
        """
        layout = self._layout
        m = layout.mapping
        signal_values = layout.signal_values(frame)  # signal -> (D,) values
        # Metadata saturates at the DBC's limits; measured quantities must fit as they are.
        for q in ("rcs_dbsm", "snr_db"):
            if q in m.fields:
                name = m.fields[q].signal
                low, high = _range_of(layout.signals[name])
                signal_values[name] = np.clip(np.nan_to_num(signal_values[name], nan=low,
                                                             neginf=low, posinf=high), low, high)
        fits = np.ones(frame.count, dtype=bool)
        for name, column in signal_values.items():
            sig = layout.signals[name]
            low, high = _range_of(sig)
            inside = (column >= low) & (column <= high)  # NaN is outside
            if not inside.all():
                for i in np.flatnonzero(fits & ~inside):
                    self._leave_out(frame.cycle, int(i), name, float(column[i]),
                                    f"[{low:g}, {high:g}] {sig.unit or ''}".rstrip())
                fits &= inside
        send = np.flatnonzero(fits)
        for i in send[layout.capacity :]:
            self._leave_out(frame.cycle, int(i), layout.capacity_signal, float(layout.capacity),
                            f"the {layout.capacity} detections per cycle it numbers")
        send = send[: layout.capacity]
        header = layout.header
        values = layout.defaults(header)
        values[m.counter] = frame.cycle % layout.counter_modulus
        left = int(send.size)
        for name in m.count:  # the count, spread over the count signals in order
            top = int(_range_of(page_signals(header)[name])[1])
            part = min(left, top)
            values[name] = part
            left -= part
        if m.timestamp is not None:
            low, high = _range_of(page_signals(header)[m.timestamp])
            values[m.timestamp] = float(np.clip(frame.t_s or 0.0, low, high))
        self._send(header, values, m.header_checksum, bus_time_s)
        for index, i in enumerate(send):  # one encoded message (or page) each
            for message, page in layout.parts:
                wanted = layout.names_of(message, page)
                values = layout.defaults(message, page)
                values.update({k: float(v[i]) for k, v in signal_values.items() if k in wanted})
                values[m.index] = index
                if m.frame_counter is not None and m.frame_counter in wanted:
                    values[m.frame_counter] = frame.cycle % layout.frame_counter_modulus
                self._send(message, values, m.checksum, bus_time_s)


def _range_of(sig: cantools.database.can.Signal) -> tuple[float, float]:
    """Return a signal's physical range: the DBC's, else what its bits and scale carry."""
    if sig.minimum is not None and sig.maximum is not None:
        return float(sig.minimum), float(sig.maximum)
    raw_low = -(1 << (sig.length - 1)) if sig.is_signed else 0
    raw_high = (1 << (sig.length - 1)) - 1 if sig.is_signed else (1 << sig.length) - 1
    ends = sorted((raw_low * sig.scale + sig.offset, raw_high * sig.scale + sig.offset))
    return float(ends[0]), float(ends[1])


class _MappedLayout:
    """How a mapping's messages carry a cycle: which signal gets which value."""

    def __init__(self, mapping: CanMapping, fd: bool) -> None:
        self.mapping = m = mapping
        db = m.db
        self._defaults: dict[tuple[int, int | None], dict[str, float]] = {}
        self._signal_sets: dict[tuple[int, int | None], set[str]] = {}
        self.header = db.get_message_by_name(m.header)
        self.parts = m.parts(fd)
        self.signals = {sg.name: sg for message, _ in self.parts for sg in message.signals}
        self.counter_modulus = 1 << self.header.get_signal_by_name(m.counter).length
        self.frame_counter_modulus = (1 << self.signals[m.frame_counter].length
                                      if m.frame_counter in self.signals else 1)
        index_top = int(_range_of(self.signals[m.index])[1]) + 1
        count_top = sum(int(_range_of(self.header.get_signal_by_name(c))[1]) for c in m.count)
        self.capacity, self.capacity_signal = min((index_top, m.index),
                                                  (count_top, "+".join(m.count)))

    def names_of(self, message: cantools.database.can.Message,
                 page: int | None = None) -> set[str]:
        """Return the names of the signals a message (page) carries (cached)."""
        key = (message.frame_id, page)
        if key not in self._signal_sets:
            self._signal_sets[key] = set(page_signals(message, page))
        return self._signal_sets[key]

    def defaults(self, message: cantools.database.can.Message,
                 page: int | None = None) -> dict[str, float]:
        """Return a value for every signal: the multiplexer's page, else 0 or its nearest end."""
        key = (message.frame_id, page)
        if key not in self._defaults:
            self._defaults[key] = self._default_values(message, page)
        return dict(self._defaults[key])

    def _default_values(self, message: cantools.database.can.Message,
                        page: int | None) -> dict[str, float]:
        out: dict[str, float] = {}
        for name, sg in page_signals(message, page).items():
            if sg.is_multiplexer and page is not None:
                out[name] = page
                continue
            low, high = _range_of(sg)
            out[name] = float(min(max(0.0, low), high))
        return out

    def signal_values(self, frame: Detections) -> dict[str, np.ndarray]:
        """Each mapped signal's value per detection (the mapping's scale and offset undone)."""
        m = self.mapping
        rng = _column(frame.range_m, frame.count)
        az = np.radians(_column(frame.az_deg, frame.count))
        # A radar that reports no height measures no elevation: its x and y are the range
        # along its azimuth, so the reader gets the range back.
        flat = m.form == "cartesian" and "z_m" not in m.fields
        el = np.radians(_column(None if flat else frame.el_deg, frame.count, 0.0))
        vr = _column(frame.radial_velocity_mps, frame.count)
        if m.form == "polar":
            quantities = {"range_m": rng, "azimuth_deg": np.degrees(az),
                          "elevation_deg": np.degrees(el), "radial_velocity_mps": vr}
        else:
            x = rng * np.cos(el) * np.cos(az)
            y = rng * np.cos(el) * np.sin(az)
            horizontal = np.where(x * x + y * y > 0, x * x + y * y, 1.0)
            # Velocities along the line of sight, scaled so that the receiver's projection
            # (x vx + y vy) / range gives the radial velocity back.
            quantities = {"x_m": x, "y_m": y, "z_m": rng * np.sin(el),
                          "vx_mps": vr * rng * x / horizontal, "vy_mps": vr * rng * y / horizontal}
        quantities["rcs_dbsm"] = _column(frame.rcs_dbsm, frame.count, 0.0)
        quantities["snr_db"] = _column(frame.snr_db, frame.count, 0.0)
        return {f.signal: (quantities[q] - f.offset) / f.scale for q, f in m.fields.items()}


def _column(values: np.ndarray | None, n: int, absent: float = np.nan) -> np.ndarray:
    return np.full(n, absent) if values is None else np.asarray(values, dtype=np.float64)


@dataclass
class BusStats:
    """What the receiver saw on the bus."""

    messages: int = 0
    error_frames: int = 0
    unknown_ids: int = 0
    checksum_errors: int = 0
    decode_errors: int = 0
    duplicates: int = 0
    reordered: int = 0
    orphans: int = 0

    @property
    def clean(self) -> bool:
        """Nothing went wrong."""
        return not (self.error_frames or self.unknown_ids or self.checksum_errors
                    or self.decode_errors or self.duplicates or self.reordered or self.orphans)


@dataclass
class _Assembly:
    """A cycle being reassembled from the bus."""

    counter: int
    expected: int
    timestamp_s: float | None
    bus_t_s: float | None = None
    parts: dict[int, dict[str, float]] = field(default_factory=dict)
    arrived: dict[int, set[PartKey]] = field(default_factory=dict)

    def complete(self, needed: tuple[frozenset[PartKey], ...]) -> bool:
        """All announced detections arrived, each whole in one of the ways it can come."""
        return len(self.parts) == self.expected and all(
            any(need <= self.arrived.get(i, set()) for need in needed) for i in self.parts)


# Cycles kept open for late or reordered parts; older incomplete ones are handed on as such.
OPEN_CYCLES = 16
# Counters remembered to recognise duplicated headers and parts of cycles already handed on.
RECENT_CYCLES = 256


class DetectionReceiver(can.Listener):
    """Decode detection messages through a mapping into `Detections` (a can.Listener).

    Finished cycles queue up until `pop` takes them (`flush` also hands on the ones still
    open, as incomplete). Only `OPEN_CYCLES` cycles are assembled at a time.
    """

    def __init__(self, mapping: CanMapping | None = None) -> None:
        self.mapping = mapping or CanMapping.builtin()
        db = self.mapping.db
        self._header = db.get_message_by_name(self.mapping.header)
        m = self.mapping
        self._detection_ids = {message.frame_id: message
                               for fd in (False, True) for message, _ in m.parts(fd)}
        # A detection is whole with every classic part it needs, or its CAN FD message.
        self._needed = tuple({m.needed_parts(False), m.needed_parts(True)})
        self._read = frozenset().union(*self._needed)
        self._multiplexer = {i: multiplexer(message) for i, message in self._detection_ids.items()}
        self.stats = BusStats()
        self._counter_modulus = 1 << self._header.get_signal_by_name(m.counter).length
        detection = {sg.name: sg for n in m.messages for sg in db.get_message_by_name(n).signals}
        # Detection messages carry the low bits of the cycle counter (if any).
        self._low_modulus = (1 << detection[m.frame_counter].length
                             if m.frame_counter in detection else 256)
        # The notifier's thread feeds messages while the run's thread takes cycles.
        self._lock = threading.Lock()
        self.reset()

    def reset(self) -> None:
        """Forget the cycles received so far (a new measurement reuses counters)."""
        with self._lock:
            self._reset()

    def _reset(self) -> None:
        self._open: OrderedDict[int, _Assembly] = OrderedDict()
        self._ready: deque[Detections] = deque()
        self._recent: OrderedDict[int, bool] = OrderedDict()  # counter -> handed on complete
        self._current: _Assembly | None = None
        self._latest = -1
        # Detections that came before their cycle's header, by counter (low 8 bits).
        self._waiting: OrderedDict[int, list[tuple[PartKey, dict[str, float]]]] = OrderedDict()

    @property
    def pending(self) -> int:
        """Cycles handed on and not yet taken by `pop`."""
        return len(self._ready)

    def pop(self) -> list[Detections]:
        """Take the finished cycles, oldest first."""
        out = []
        while self._ready:
            out.append(self._ready.popleft())
        return out

    def flush(self) -> list[Detections]:
        """Hand on every open cycle (incomplete ones marked so) and take all cycles."""
        with self._lock:
            while self._open:
                self._finish(next(iter(self._open)))
            self._current = None
        return self.pop()

    def on_message_received(self, msg: can.Message) -> None:
        """Handle one message (called by python-can's Notifier, or directly)."""
        with self._lock:
            self._receive(msg)

    def _receive(self, msg: can.Message) -> None:
        stats = self.stats
        stats.messages += 1
        if msg.is_error_frame:
            stats.error_frames += 1
            return
        if msg.arbitration_id == self._header.frame_id:
            values = self._decode(self._header, msg, self.mapping.header_checksum)
            if values is not None:
                self._on_header(values, float(msg.timestamp))
            return
        message = self._detection_ids.get(msg.arbitration_id)
        if message is None:
            stats.unknown_ids += 1
            return
        values = self._decode(message, msg, self.mapping.checksum)
        if values is None:
            return
        mux = self._multiplexer[message.frame_id]
        part = (message.frame_id, None if mux is None else int(values[mux]))
        if part in self._read:  # else a page the mapping does not read (extended information)
            self._on_detection(part, values)

    def _decode(self, message: cantools.database.can.Message, msg: can.Message,
                checksum: str | None) -> dict[str, float] | None:
        data = bytes(msg.data)
        if checksum is not None and checksum in {s.name for s in message.signals}:
            pos = _checksum_byte(message, checksum)
            if len(data) <= pos or data[pos] != _checksum(data, pos):
                self.stats.checksum_errors += 1
                return None
        try:
            decoded = message.decode(data, decode_choices=False, scaling=True)
            assert isinstance(decoded, dict)
            return {k: float(v) for k, v in decoded.items()}  # type: ignore[arg-type]
        except (cantools.database.DecodeError, ValueError, KeyError, TypeError):
            self.stats.decode_errors += 1
            return None

    def _on_header(self, values: dict[str, float], bus_t_s: float | None = None) -> None:
        m = self.mapping
        counter = int(values[m.counter])
        if counter in self._open or counter in self._recent:
            self.stats.duplicates += 1
            return
        if self._latest >= 0 and _behind(counter, self._latest, self._counter_modulus):
            self.stats.reordered += 1
        else:
            self._latest = counter
        frame = _Assembly(
            counter=counter, expected=int(sum(values[c] for c in m.count)),
            timestamp_s=values.get(m.timestamp) if m.timestamp else None, bus_t_s=bus_t_s)
        self._open[counter] = frame
        self._current = frame
        for part, early in self._waiting.pop(counter % self._low_modulus, []):
            self.stats.orphans -= 1
            self._attach(frame, part, early)
        if frame.complete(self._needed):
            self._finish(counter)
        while len(self._open) > OPEN_CYCLES:
            self._finish(next(iter(self._open)))

    def _on_detection(self, part: PartKey, values: dict[str, float]) -> None:
        m = self.mapping
        frame = self._current
        if m.frame_counter is not None and m.frame_counter in values:
            low = int(values[m.frame_counter])
            if frame is None or (frame.counter % self._low_modulus) != low:
                # Late part of an earlier cycle, or early part of one whose header is late.
                self.stats.reordered += 1
                frame = next((f for c, f in reversed(self._open.items())
                              if c % self._low_modulus == low),
                             None)
                if frame is None:
                    done = next((whole for c, whole in reversed(self._recent.items())
                                 if c % self._low_modulus == low), None)
                    if done is not None:
                        # Its cycle was handed on: a copy if it was whole, else too late.
                        if done:
                            self.stats.duplicates += 1
                        return
                    self._waiting.setdefault(low, []).append((part, values))
                    self.stats.orphans += 1  # until its header comes
                    while len(self._waiting) > OPEN_CYCLES:
                        self._waiting.popitem(last=False)
                    return
        if frame is None:
            self.stats.orphans += 1
            return
        if frame.counter not in self._open:
            # Its cycle was handed on: a copy if it was whole, else too late to count.
            if self._recent.get(frame.counter, False):
                self.stats.duplicates += 1
            else:
                self.stats.orphans += 1
            return
        self._attach(frame, part, values)
        if frame.complete(self._needed):
            self._finish(frame.counter)

    def _attach(self, frame: _Assembly, part: PartKey, values: dict[str, float]) -> None:
        index = int(values[self.mapping.index])
        arrived = frame.arrived.setdefault(index, set())
        if part in arrived:
            self.stats.duplicates += 1
            return
        arrived.add(part)
        frame.parts.setdefault(index, {}).update(values)

    def _finish(self, counter: int) -> None:
        """Hand on an open cycle as `Detections`."""
        frame = self._open.pop(counter)
        complete = frame.complete(self._needed)
        self._recent[counter] = complete
        while len(self._recent) > RECENT_CYCLES:
            self._recent.popitem(last=False)
        if self._current is frame and not complete:
            self._current = None
        self._ready.append(Detections(cycle=counter, t_s=frame.timestamp_s, complete=complete,
                                      bus_t_s=frame.bus_t_s, **self._quantities(frame)))

    def _quantities(self, frame: _Assembly) -> dict[str, np.ndarray]:
        """Arrays of the quantities the mapping carries (polar, rts-scenario's names)."""
        m = self.mapping
        rows = [frame.parts[i] for i in sorted(frame.parts)]

        def get(q: str) -> np.ndarray:
            f = m.fields[q]
            return np.array([r.get(f.signal, np.nan) for r in rows]) * f.scale + f.offset

        out: dict[str, np.ndarray] = {}
        if m.form == "polar":
            for q, name in (("range_m", "range_m"), ("azimuth_deg", "az_deg"),
                            ("elevation_deg", "el_deg"),
                            ("radial_velocity_mps", "radial_velocity_mps")):
                if q in m.fields:
                    out[name] = get(q)
        else:
            x, y = get("x_m"), get("y_m")
            z = get("z_m") if "z_m" in m.fields else np.zeros_like(x)
            rng = np.sqrt(x * x + y * y + z * z)
            out["range_m"] = rng
            out["az_deg"] = np.degrees(np.arctan2(y, x))
            if "z_m" in m.fields:
                out["el_deg"] = np.degrees(np.arctan2(z, np.hypot(x, y)))
            if "vx_mps" in m.fields and "vy_mps" in m.fields:
                out["radial_velocity_mps"] = (x * get("vx_mps") + y * get("vy_mps")) / np.where(
                    rng > 0, rng, 1.0)
        for q in ("rcs_dbsm", "snr_db"):
            if q in m.fields:
                out[q] = get(q)
        return out


def _behind(counter: int, latest: int, modulus: int) -> bool:
    """Whether a cycle counter is older than the latest seen (with wrap-around)."""
    return 0 < (latest - counter) % modulus < modulus // 2


__all__ = ["BusStats", "CanMapping", "DetectionPublisher", "DetectionReceiver", "open_bus"]
