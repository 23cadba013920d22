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

import itertools
import math
import operator
import socket
import sys
import threading
import time
from collections import Counter, OrderedDict, deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import can
import cantools
import numpy as np
from cantools.database.utils import create_encode_decode_formats

from ..detections import Detections, largest_step_back, long_gap_cycles, signed_step
from ..errors import BusError, OutputError
from ..hostclock import HostClockWatch
from .checksums import Seal, Verify, checksum_of
from .mapping import CanMapping, Checksum, PartKey, multiplexer, page_signals
from .mapping import signal_range as _range_of

DEFAULT_INTERFACE = "virtual"
DEFAULT_CHANNEL = "rts-scenario"


def channel_label(channel: Any) -> str | None:
    """Return a message's channel as text, as python-can gives it (``Message.channel``).

    ``run --radar-channel`` and ``check --log-channel`` name channels so (a Vector
    interface's 1, a BLF's channel 0, socketcan's ``vcan1``); None where the interface or
    log does not say.
    """
    return None if channel is None else str(channel)


def open_bus(interface: str = DEFAULT_INTERFACE, channel: str = DEFAULT_CHANNEL, *,
             fd: bool = False, **options: Any) -> can.BusABC:
    """Open a python-can bus, with one clear error if the interface or channel is unusable."""
    valid = sorted(can.interfaces.VALID_INTERFACES)
    if interface not in valid:
        raise BusError(f"CAN interface {interface!r} unknown; valid interfaces: "
                       f"{', '.join(valid)}")
    try:
        bus = can.Bus(interface=interface, channel=channel, fd=fd, **options)
    except (can.CanError, OSError, ImportError, ValueError, TypeError) as exc:
        raise BusError(f"cannot open CAN interface {interface!r} channel {channel!r}: "
                       f"{exc}") from None
    if interface == "udp_multicast":
        _own_group_only(bus)
    return bus


# Linux's IP_MULTICAST_ALL (linux/in.h); Python's socket module does not name it.
_IP_MULTICAST_ALL = 49


def _own_group_only(bus: can.BusABC) -> None:
    """Make a python-can ``udp_multicast`` bus hear its own group only.

    python-can binds every such bus to the same port on every address; Linux then hands it the
    datagrams of every group any socket of the host joined on that port, so two benches on two
    groups of one host would hear each other's radar. Elsewhere (no such option) nothing
    changes.
    """
    sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    if sock is None or not sys.platform.startswith("linux"):
        return
    try:
        if sock.family == socket.AF_INET:
            sock.setsockopt(socket.IPPROTO_IP, _IP_MULTICAST_ALL, 0)
    except OSError:
        pass  # a kernel without it: as python-can opened it


class ListenerBus(can.BusABC):
    """An in-process bus: each message sent goes straight to its listeners, in the sender's thread.

    The simulated radar and the receiver live in one process; python-can's virtual bus would
    copy every message for its queue and hand it over through a notifier's thread. Here the
    message itself is handed to each listener (the receiver, a logger), marked as received on
    ``channel`` with the timestamp the sender gave it. Senders must not change a message after
    sending it (`DetectionPublisher` builds a new one for each).
    """

    def __init__(self, listeners: list[can.Listener], channel: str = DEFAULT_CHANNEL,
                 **kwargs: Any) -> None:
        super().__init__(channel=channel, **kwargs)
        self.channel_info = channel
        self._listeners = listeners

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Hand a message to every listener, now, in this thread."""
        msg.channel = self.channel_info
        msg.is_rx = True
        for listener in self._listeners:
            listener.on_message_received(msg)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        return None, False  # what is sent goes to the listeners, never to a queue


def _limits(sig: cantools.database.can.Signal) -> tuple[float, float]:
    """Return a signal's physical range as the DBC states it (ours states every one)."""
    assert sig.minimum is not None and sig.maximum is not None
    return float(sig.minimum), float(sig.maximum)


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
        Detections left out, by the signal that could not carry them (e.g. ``{"Range": 2}``;
        the index signal, or the count's, for those past the last one it numbers); a detection
        with several such values counts once, for the first of them.
    unsendable_detections : int
        Detections left out in total (``sum(unsendable.values())``).
    unsendable_reason : str or None
        Why, per signal (`unsendable`): how many, the cause, and the first one left out.
    """

    def __init__(self, bus: can.BusABC, *, fd: bool = False,
                 mapping: CanMapping | None = None) -> None:
        self.bus = bus
        self.fd = fd
        self.mapping = mapping or CanMapping.builtin()
        self._layout = _MappedLayout(self.mapping, fd)
        self.sent = 0
        self.unsendable: Counter[str] = Counter()
        # Per signal of `unsendable`: why, and the first detection it left out.
        self._causes: dict[str, tuple[str, str]] = {}

    @property
    def unsendable_detections(self) -> int:
        """Detections left out because no signal could carry them."""
        return sum(self.unsendable.values())

    @property
    def unsendable_reason(self) -> str | None:
        """Say why detections were left out (None: none was), per cause in the order met.

        E.g. ``2 with Range outside [0, 327.675] m (the first: -0.146, cycle 0 detection 1)``
        or ``44 past the 8 per cycle that index Id numbers (0 to 7; the first: cycle 3
        detection 8)``.
        """
        if not self.unsendable:
            return None
        return "; ".join(f"{self.unsendable[signal]} {why} ({first})"
                         for signal, (why, first) in self._causes.items())

    def _leave_out(self, cycle: int, index: int, signal: str, why: str, first: str) -> None:
        """Count a detection left out for ``signal``; keep ``why`` and the first such one."""
        self.unsendable[signal] += 1
        self._causes.setdefault(signal, (why, f"{first}cycle {cycle} detection {index}"))

    def _send(self, codec: _Codec, raw: dict[str, int | float], timestamp: float) -> None:
        """Encode and send one message whose raw values were checked against their signals.

        Every value is inside its signal's range before it gets here (`publish` checks the
        detections' columns at once; the header, indices and defaults are in range by
        construction), so cantools' compiled codec packs it without checking it again.
        """
        try:  # the packer refuses a value its bits cannot carry: never wrapped, never cut
            data = codec.encode(raw)
        except (OverflowError, TypeError, KeyError, ValueError) as exc:
            raise OutputError(f"CAN {codec.message.name}: {exc}") from None
        self.bus.send(can.Message(arbitration_id=codec.frame_id, data=data,
                                  is_extended_id=codec.extended, is_fd=self.fd or codec.is_fd,
                                  timestamp=timestamp, check=False))
        self.sent += 1

    def publish(self, frame: Detections, bus_time_s: float = 0.0) -> None:
        """Send one cycle: header, then every detection the messages can carry.

        ``bus_time_s`` stamps the cycle's messages (a bus that keeps senders' timestamps, like
        python-can's virtual bus with ``preserve_timestamps``, shows when the radar would have
        sent them).
        """
        self.publish_many([frame], [bus_time_s])

    def publish_many(self, frames: Sequence[Detections],
                     bus_times_s: Sequence[float] | np.ndarray | None = None) -> None:
        """Send cycles one after the other, as `publish` does each (``bus_times_s``: theirs).

        The values of all their detections are checked against their signals and converted to
        raw values at once; then each message is packed and sent.
        """
        if not frames:
            return
        layout = self._layout
        m = layout.mapping
        times = (np.zeros(len(frames)) if bus_times_s is None
                 else np.asarray(bus_times_s, dtype=np.float64))
        counts = np.array([f.count for f in frames], dtype=np.int64)
        first = np.concatenate(([0], np.cumsum(counts)[:-1]))
        values = layout.signal_matrix(frames, int(counts.sum()))  # (signals, detections)
        # Metadata saturates at the DBC's limits; measured quantities must fit as they are.
        low, high = layout.low[:, None], layout.high[:, None]
        clipped = np.clip(np.where(np.isnan(values), low, values), low, high)
        values = np.where(layout.saturates[:, None], clipped, values)
        inside = (values >= low) & (values <= high)  # NaN is outside
        fits = inside.all(axis=0)
        cycle_of = np.repeat(np.arange(len(frames)), counts)
        if not fits.all():
            for j in np.flatnonzero(~fits):  # the first signal that cannot carry it
                s = int(np.argmin(inside[:, j]))
                sig = layout.signals[layout.names[s]]
                c = int(cycle_of[j])
                allowed = f"[{layout.low[s]:g}, {layout.high[s]:g}] {sig.unit or ''}".rstrip()
                self._leave_out(frames[c].cycle, int(j - first[c]), sig.name,
                                f"with {sig.name} outside {allowed}",
                                f"the first: {float(values[s, j]):g}, ")
        # Each cycle sends its fitting detections up to the capacity its index and count have.
        fitting = np.cumsum(fits)
        rank = fitting - 1 - np.concatenate(([0], fitting))[first][cycle_of]
        over = fits & (rank >= layout.capacity)
        for j in np.flatnonzero(over):
            c = int(cycle_of[j])
            self._leave_out(frames[c].cycle, int(j - first[c]), layout.capacity_signal,
                            layout.capacity_reason, "the first: ")
        send = fits & ~over
        sent = np.bincount(cycle_of[send], minlength=len(frames))
        index = rank[send]
        # Raw values per part, converted at once, and packed; then each cycle's header and
        # parts in order.
        detection_cycle = cycle_of[send]
        # The low part of the header's counter (a counter wrapping below its width wraps
        # first: its low bits are those of the counter on the bus).
        low_counter = ((np.array([f.cycle for f in frames], dtype=np.int64)
                        % layout.counter_modulus + m.counter_min)
                       % layout.frame_counter_modulus)[detection_cycle].astype(np.float64)
        frame_counter = m.frame_counter if m.frame_counter in layout.signals else None
        parts = []
        for codec in layout.part_codecs:
            columns: dict[str, list[int] | list[float]] = {}
            if frame_counter in codec.signals:  # the cycle's low bits, on every detection
                columns[frame_counter] = codec.raw_column(frame_counter, low_counter)
            for name in codec.carried:
                if name != m.index:
                    columns[name] = codec.raw_column(name, values[layout.row[name], send])
            columns[m.index] = codec.raw_column(m.index, (index + layout.index_first)
                                                .astype(np.float64))
            try:  # the packer refuses a value its bits cannot carry: never wrapped, never cut
                payloads = codec.encode_rows(columns, len(index))
            except (OverflowError, TypeError, KeyError, ValueError) as exc:
                raise OutputError(f"CAN {codec.message.name}: {exc}") from None
            parts.append((codec.frame_id, codec.extended, self.fd or codec.is_fd, payloads))
        header = layout.header_codec
        bus_send, message = self.bus.send, can.Message
        done = 0
        for frame, bus_time, count in zip(frames, times.tolist(), sent.tolist(), strict=True):
            self._send(header, layout.header_values(frame, count), bus_time)
            for i in range(done, done + count):  # one message (or page) each
                for frame_id, extended, is_fd, payloads in parts:
                    bus_send(message(arbitration_id=frame_id, data=payloads[i],
                                     is_extended_id=extended, is_fd=is_fd,
                                     timestamp=bus_time, check=False))
                    self.sent += 1
            done += count


class _Codec:
    """One message (or one multiplexer page of it), packed by cantools' compiled codec.

    Values are raw (the DBC's scale and offset undone), as cantools packs them.
    """

    def __init__(self, message: cantools.database.can.Message, page: int | None,
                 checksum: Checksum | None,
                 mapped: set[str] | frozenset[str] = frozenset()) -> None:
        self.message = message
        self.signals = page_signals(message, page)
        self.signal_list = list(self.signals.values())
        self.formats = create_encode_decode_formats(self.signal_list, message.length)
        # Which byte orders the message uses (a format without signals packs nothing).
        orders = {sg.byte_order for sg in self.signal_list}
        self._big, self._little = "big_endian" in orders, "little_endian" in orders
        self.length = message.length
        self.frame_id = message.frame_id
        self.extended = message.is_extended_frame
        self.is_fd = bool(message.is_fd or message.length > 8)
        sealed = checksum_of(message, checksum)
        self.seal: Seal | None = sealed[0] if sealed is not None else None
        # The mapped signals this part carries, and a value for every other one: the
        # multiplexer's page, else 0 or the signal's nearest end.
        self.carried = tuple(sorted(set(self.signals) & set(mapped)))
        self.defaults: dict[str, int | float] = {}
        for name, sg in self.signals.items():
            low, high = _range_of(sg)
            physical = page if sg.is_multiplexer and page is not None else min(max(0.0, low),
                                                                               high)
            self.defaults[name] = self.raw(name, physical)

    def raw(self, name: str, physical: float) -> int | float:
        """Return a signal's raw value for a physical one (cantools' own conversion)."""
        return self.signals[name].conversion.numeric_scaled_to_raw(physical)

    def raw_column(self, name: str, physical: np.ndarray) -> list[int] | list[float]:
        """Return a signal's raw values for physical ones, as Python numbers.

        The same conversion as `raw` (cantools' ``numeric_scaled_to_raw``: offset and scale
        undone, rounded half to even unless the signal is a float), for a whole column.
        """
        conversion = self.signals[name].conversion
        raw = (np.asarray(physical, dtype=np.float64) - conversion.offset) / conversion.scale
        if conversion.is_float:
            floats: list[float] = raw.tolist()
            return floats
        ints: list[int] = np.rint(raw).astype(np.int64).tolist()
        return ints

    def encode(self, raw: dict[str, int | float]) -> bytearray:
        """Pack raw values (every signal's) into the message's bytes, checksum filled in.

        cantools' compiled formats pack the big- and little-endian signals; their union is the
        message (as `cantools.database.utils.encode_data` combines them).
        """
        formats = self.formats
        if not self._big:  # the little-endian format packs the bytes in reverse
            data = bytearray(formats.little_endian.pack(raw)[::-1])
        elif not self._little:
            data = bytearray(formats.big_endian.pack(raw))
        else:
            packed = (int.from_bytes(formats.big_endian.pack(raw), "big")
                      | int.from_bytes(formats.little_endian.pack(raw), "little"))
            data = bytearray(packed.to_bytes(self.length, "big"))
        if self.seal is not None:
            self.seal(data)
        return data

    def encode_rows(self, columns: dict[str, list[int] | list[float]],
                    n: int) -> list[bytearray]:
        """Pack ``n`` messages as `encode` packs each.

        Message ``i`` takes each column's ``i``-th raw value, and its defaults for the signals
        without a column.
        """
        defaults, encode = self.defaults, self.encode
        pairs = list(columns.items())
        out = []
        for i in range(n):
            raw = defaults.copy()
            for name, column in pairs:
                raw[name] = column[i]
            out.append(encode(raw))
        return out

    def decode(self, data: bytes | bytearray) -> dict[str, int | float]:
        """Unpack a message's raw values (as `cantools.database.utils.decode_data` does).

        Excess bytes (CAN FD padding) are ignored; a short message is a `DecodeError`.
        """
        if len(data) != self.length:
            if len(data) < self.length:
                raise cantools.database.DecodeError(
                    f"Wrong data size: {len(data)} instead of {self.length} bytes")
            data = data[: self.length]
        formats = self.formats
        if not self._big:
            return formats.little_endian.unpack(data[::-1])
        if not self._little:
            return formats.big_endian.unpack(data)
        return {**formats.big_endian.unpack(data), **formats.little_endian.unpack(data[::-1])}


class _MappedLayout:
    """How a mapping's messages carry a cycle: which signal gets which value."""

    def __init__(self, mapping: CanMapping, fd: bool) -> None:
        self.mapping = m = mapping
        db = m.db
        self.header = db.get_message_by_name(m.header)
        self.parts = m.parts(fd)
        self.signals = {sg.name: sg for message, _ in self.parts for sg in message.signals}
        self.counter_modulus = m.counter_modulus
        self.frame_counter_modulus = (1 << self.signals[m.frame_counter].length
                                      if m.frame_counter in self.signals else 1)
        # The index values every part's index signal carries (the parts may give it other
        # widths or ranges), from the highest first value to the lowest last one: detections
        # are numbered from that first value, one more each.
        index_ranges = [_range_of(page_signals(message, page)[m.index])
                        for message, page in self.parts]
        self.index_first = math.ceil(max(low for low, _ in index_ranges) - 1e-9)
        index_last = math.floor(min(high for _, high in index_ranges) + 1e-9)
        index_top = max(index_last - self.index_first + 1, 0)
        count_top = sum(int(_range_of(self.header.get_signal_by_name(c))[1]) for c in m.count)
        if index_top <= count_top:
            self.capacity, self.capacity_signal = index_top, m.index
            self.capacity_reason = (f"past the {index_top} per cycle that index {m.index} "
                                    f"numbers ({self.index_first} to {index_last}, in every "
                                    f"message)")
        else:
            self.capacity, self.capacity_signal = count_top, "+".join(m.count)
            self.capacity_reason = (f"past the {count_top} per cycle that the header's count "
                                    f"{' + '.join(m.count)} announces")
        mapped = {f.signal for f in m.fields.values()}
        self.header_codec = _Codec(self.header, None, m.header_checksum_spec)
        self.count_tops = [int(_range_of(self.header.get_signal_by_name(c))[1]) for c in m.count]
        self.timestamp_range = (_range_of(self.header.get_signal_by_name(m.timestamp))
                                if m.timestamp is not None else (0.0, 0.0))
        # The mapped signals (rows of `signal_matrix`), their ranges, which of them saturate.
        self.names = sorted(mapped)
        self.row = {name: i for i, name in enumerate(self.names)}
        ranges = np.array([_range_of(self.signals[name]) for name in self.names]).reshape(-1, 2)
        self.low, self.high = ranges[:, 0], ranges[:, 1]
        saturating = {m.fields[q].signal for q in ("rcs_dbsm", "snr_db") if q in m.fields}
        self.saturates = np.array([name in saturating for name in self.names], dtype=bool)
        self.part_codecs = [_Codec(message, page, m.checksum_spec, mapped | {m.index})
                            for message, page in self.parts]

    def signal_matrix(self, frames: Sequence[Detections], n: int) -> np.ndarray:
        """Each mapped signal's value (rows: `names`) per detection of the cycles, in order.

        The mapping's scale and offset are undone: the values are the DBC's physical ones.
        """
        m = self.mapping

        def column(name: str, absent: float = np.nan) -> np.ndarray:
            if n == 0:
                return np.zeros(0)
            return np.concatenate([_column(getattr(f, name), f.count, absent) for f in frames])

        rng = column("range_m")
        az = np.radians(column("az_deg"))
        # A radar that reports no height measures no elevation: its x and y are the range
        # along its azimuth, so the reader gets the range back.
        flat = m.form == "cartesian" and "z_m" not in m.fields
        el = np.zeros(n) if flat else np.radians(column("el_deg", 0.0))
        vr = column("radial_velocity_mps")
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
        quantities["rcs_dbsm"] = column("rcs_dbsm", 0.0)
        quantities["snr_db"] = column("snr_db", 0.0)
        out = np.empty((len(self.names), n))
        for q, f in m.fields.items():
            out[self.row[f.signal]] = (quantities[q] - f.offset) / f.scale
        return out

    def header_values(self, frame: Detections, count: int) -> dict[str, int | float]:
        """Return the header's raw values for a cycle announcing ``count`` detections."""
        m, header = self.mapping, self.header_codec
        values = dict(header.defaults)
        values[m.counter] = header.raw(m.counter,
                                       frame.cycle % self.counter_modulus + m.counter_min)
        for name, top in zip(m.count, self.count_tops, strict=True):
            part = min(count, top)  # the count, spread over the count signals in order
            values[name] = header.raw(name, part)
            count -= part
        if m.timestamp is not None:
            low, high = self.timestamp_range  # (NaN stays NaN, as the packer refuses it)
            stamp = float(frame.t_s or 0.0) / m.timestamp_scale  # the signal's unit
            values[m.timestamp] = header.raw(m.timestamp, min(max(stamp, low), high))
        return values


def _column(values: np.ndarray | None, n: int, absent: float = np.nan) -> np.ndarray:
    return np.full(n, absent) if values is None else np.asarray(values, dtype=np.float64)


@dataclass
class BusStats:
    """What the receiver saw on the bus."""

    messages: int = 0
    error_frames: int = 0
    remote_frames: int = 0  # requests for a message: they carry no data
    unknown_ids: int = 0
    checksum_errors: int = 0
    decode_errors: int = 0
    duplicates: int = 0
    reordered: int = 0
    orphans: int = 0
    conflicts: int = 0

    @property
    def clean(self) -> bool:
        """Nothing went wrong."""
        return not (self.error_frames or self.remote_frames or self.unknown_ids
                    or self.checksum_errors or self.decode_errors or self.duplicates
                    or self.reordered or self.orphans or self.conflicts)


class _PartRule:
    """One part (message or page) of a detection the receiver reads, and what it takes."""

    __slots__ = ("key", "needs", "scalings", "whole_alone")

    def __init__(self, key: PartKey, scalings: tuple[tuple[str, float, float], ...],
                 needs: tuple[frozenset[PartKey], ...]) -> None:
        self.key = key
        # The mapped signals whose DBC scale or offset must be applied: (name, scale, offset).
        self.scalings = scalings
        # The ways a detection is whole that this part belongs to; alone, it may be one.
        self.needs = needs
        self.whole_alone = any(need <= {key} for need in needs)


@dataclass
class _Assembly:
    """A cycle being reassembled from the bus."""

    counter: int
    low: int  # the low bits of the counter its detection messages carry
    expected: int
    timestamp_s: float | None
    bus_t_s: float | None = None
    host_t_s: float | None = None
    host_step_s: float = 0.0
    header: dict[str, float] = field(default_factory=dict)  # its raw values
    parts: dict[int, dict[str, float]] = field(default_factory=dict)
    arrived: dict[int, dict[PartKey, dict[str, float]]] = field(default_factory=dict)
    whole: set[int] = field(default_factory=set)  # detections whole so far

    def add(self, index: int, rule: _PartRule, values: dict[str, float]) -> bool | None:
        """Add one part of a detection.

        Returns True if it is new, False if that part had come already with the same values
        (a copy), None if it had come with other values (the first ones are kept).
        """
        part = rule.key
        arrived = self.arrived.get(index)
        if arrived is None:
            self.arrived[index] = {part: values}
            self.parts[index] = values.copy()
            if rule.whole_alone:
                self.whole.add(index)
            return True
        if part in arrived:
            return False if _same(arrived[part], values) else None
        arrived[part] = values
        self.parts[index].update(values)
        if index not in self.whole:
            for need in rule.needs:  # the ways of being whole this part is one of
                if arrived.keys() >= need:
                    self.whole.add(index)
                    break
        return True

    def complete(self) -> bool:
        """All announced detections arrived, each whole in one of the ways it can come."""
        return len(self.parts) == self.expected == len(self.whole)


def _same(known: dict[str, float], values: dict[str, float]) -> bool:
    """Whether every value in ``values`` is the one ``known`` has (NaN equals NaN)."""
    for name, value in values.items():
        old = known.get(name)
        if old is None or not (old == value or (old != old and value != value)):
            return False
    return True


# How the receiver takes a message of one identifier: the message, its checksum's check and
# multiplexer signal (if any), its compiled decoder (None if multiplexed) and its part (the page
# is the multiplexer's value, if any).
_Route = tuple[cantools.database.can.Message, Verify | None, str | None,
               Callable[[bytes | bytearray], dict[str, int | float]] | None, PartKey]

# Cycles kept open for late or reordered parts; older incomplete ones are handed on as such.
OPEN_CYCLES = 16
# Counters remembered to recognise duplicated headers and parts of cycles already handed on.
RECENT_CYCLES = 256
# Without a frame counter, parts after a whole cycle held until the next header places them.
UNPLACED_PARTS = 4096


class DetectionReceiver(can.Listener):
    """Decode detection messages through a mapping into `Detections` (a can.Listener).

    Finished cycles queue up until `pop` takes them (`flush` also hands on the ones still
    open, as incomplete). Only `OPEN_CYCLES` cycles are assembled at a time, and an incomplete
    one is handed on once the header of a cycle `OPEN_CYCLES` later came (a quarter of the
    counter's range, if less), or one whose counter leaves it no longer behind the latest.
    The counters of the cycles handed on are remembered (copies of them are told) while they
    are at or behind the latest counter (`largest_step_back`), whatever order they went in.

    With the radar's ``cycle_s``, a header that reaches the bus more than half the counter's
    range of cycles after the one before (less `GAP_TOLERANCE_CYCLES`, and 2 cycles at least:
    `long_gap_cycles`) starts afresh: every counter remembered is from before that silence,
    so one that comes again is a new cycle, not a copy (an 8-bit counter repeats after 12.8 s
    of 50 ms cycles).

    Each cycle keeps when its header was on the bus (the message's timestamp, on whatever
    clock the interface stamps with) and when the host received it: ``received_at(message)``,
    the host's wall clock (`time.time`) when the message is handed over, by default. With
    ``host_clock`` (a `HostClockWatch`), it reads the host's clocks at each header too: how
    far the wall clock had stepped by then is the cycle's `Detections.host_step_s`.

    An interface may listen on several channels (each message's ``Message.channel``): with
    ``channel`` (as `channel_label` names it), the receiver reads only that channel's messages
    and counts the others (`other_channels`); it counts, per channel, the messages of the
    radar's identifiers it heard (`channels`), so that a run can tell a bus whose radar
    identifiers came on several channels (`channel_reason`).
    """

    def __init__(self, mapping: CanMapping | None = None, cycle_s: float | None = None,
                 received_at: Callable[[can.Message], float] | None = None, *,
                 channel: str | None = None,
                 host_clock: HostClockWatch | None = None,
                 channel_option: str = "--radar-channel") -> None:
        self.mapping = mapping or CanMapping.builtin()
        self.host_clock = host_clock
        self.cycle_s = cycle_s
        self.channel = channel
        # The option that gives ``channel``, named in `channel_reason` (the plugin's is
        # ``--rts-radar-channel``).
        self.channel_option = channel_option
        self.received_at: Callable[[can.Message], float] = (
            received_at or self._wall_receipt)
        db = self.mapping.db
        self._header = db.get_message_by_name(self.mapping.header)
        m = self.mapping
        self._detection_ids = {message.frame_id: message
                               for fd in (False, True) for message, _ in m.parts(fd)}
        # A detection is whole with every classic part it needs, or its CAN FD message.
        self._needed = tuple({m.needed_parts(False), m.needed_parts(True)})
        self._read = frozenset().union(*self._needed)
        # Per identifier: the message, its checksum's check and multiplexer signal (if any).
        def verify(message: cantools.database.can.Message,
                   spec: Checksum | None) -> Verify | None:
            sealed = checksum_of(message, spec)
            return sealed[1] if sealed is not None else None

        layouts = {i: (message, verify(message, m.checksum_spec), multiplexer(message))
                   for i, message in self._detection_ids.items()}
        layouts[self._header.frame_id] = (
            self._header, verify(self._header, m.header_checksum_spec), None)
        # Messages without a multiplexer decode through their compiled codec directly (and are
        # one part: (identifier, None)); cantools picks a multiplexed one's page.
        # Keyed as the DBC numbers them: a 29-bit identifier with bit 31 set.
        self._layouts: dict[int, _Route] = {
            i | (bool(message.is_extended_frame) << 31): (
                message, checksum, mux,
                None if mux is not None else _Codec(message, None, None).decode, (i, None))
            for i, (message, checksum, mux) in layouts.items()}
        self._frame_counter, self._index = m.frame_counter, m.index
        # Parts are scaled to the DBC's physical values as they arrive (`_scaled`); the mapping's
        # own scale and offset are applied when a cycle is handed on.
        self._header_signals = {sg.name: sg for sg in self._header.signals}
        # Control signals (index, low counter) are read by name; they scale alike everywhere.
        self._signals = {sg.name: sg for message in self._detection_ids.values()
                         for sg in message.signals}
        self._identity = {name for name, sg in self._signals.items()
                          if sg.conversion.scale == 1 and sg.conversion.offset == 0}
        fields = {f.signal: f for f in m.fields.values()}
        self._field_names = list(fields)
        self._field_column = {name: i for i, name in enumerate(self._field_names)}
        self._field_getter = (operator.itemgetter(*self._field_names) if len(fields) > 1
                              else lambda row: [row[self._field_names[0]]])
        scale = np.array([f.scale for f in fields.values()], dtype=np.float64)
        offset = np.array([f.offset for f in fields.values()], dtype=np.float64)
        # The mapping's scale and offset per field (None: the DBC's values as they are).
        self._to_quantity = (None if np.all(scale == 1) and np.all(offset == 0)
                             else (scale, offset))
        # The quantities read as they are (all of a polar mapping's): name, column.
        direct = [("rcs_dbsm", "rcs_dbsm"), ("snr_db", "snr_db")]
        if m.form == "polar":
            direct += [("range_m", "range_m"), ("azimuth_deg", "az_deg"),
                       ("elevation_deg", "el_deg"), ("radial_velocity_mps", "radial_velocity_mps")]
        self._direct = [(name, self._field_column[m.fields[q].signal])
                        for q, name in direct if q in m.fields]
        # Per message, the mapped signals whose DBC scale or offset must be applied (messages
        # may scale a signal of the same name differently, e.g. classic and CAN FD).
        scalings = {
            i: tuple((sg.name, sg.conversion.scale, sg.conversion.offset)
                     for sg in message.signals
                     if sg.name in fields and not (sg.conversion.scale == 1
                                                   and sg.conversion.offset == 0))
            for i, message in self._detection_ids.items()}
        # Per part the mapping reads: its scalings and the ways of being whole it is one of.
        self._rules = {part: _PartRule(part, scalings[part[0]],
                                       tuple(need for need in self._needed
                                             if part in need or not need))
                       for part in self._read}
        self.stats = BusStats()
        self._counter_modulus = m.counter_modulus
        # The latest counter and those that can be behind it (`largest_step_back`): any other
        # is ahead of it.
        self._reach = largest_step_back(m.counter_modulus) + 1
        detection = {sg.name: sg for n in m.messages for sg in db.get_message_by_name(n).signals}
        # Detection messages carry the low bits of the cycle counter (if any).
        self._low_modulus = (1 << detection[m.frame_counter].length
                             if m.frame_counter in detection else 256)
        # The notifier's thread feeds messages while the run's thread takes cycles.
        self._lock = threading.Lock()
        self._index_of, self._low_of = (self._whole_number(self._index),
                                        self._whole_number(self._frame_counter))
        self.reset()

    @staticmethod
    def _wall_receipt(message: can.Message) -> float:
        """Return the host's wall clock now: when it received a message (by default)."""
        return time.time()

    def _whole_number(self, name: str | None) -> Callable[[float], int]:
        """Return how a control signal's raw value becomes its physical whole number."""
        if name is None or name in self._identity:
            return int
        return lambda raw: int(self._physical(name, raw))

    def _physical(self, name: str, raw: float) -> float:
        """Return a detection signal's physical value (the DBC's scale and offset applied)."""
        if name in self._identity:
            return raw
        return float(self._signals[name].conversion.raw_to_scaled(raw, False))  # type: ignore[arg-type]

    def reset(self, restart: int | None = None) -> None:
        """Forget the cycles received so far (a new measurement reuses counters).

        ``restart``: the counter (from 0, the mapping's first value subtracted) at which the
        radar's count starts afresh with what comes next: a bench that starts the radar per
        stream (as `emulate` does for each run and measurement) may still deliver the stream
        before's last cycles after this reset. When a header with that counter comes after
        other cycles, those counting on from it without a gap (its header held up behind
        them) are the stream's own, and so are the others if their count leads up to it;
        otherwise the others were measured before the restart: they are dropped (counted in
        `stale_cycles`) and their counters forgotten (a header they made look reordered no
        longer counts so), so the new count is neither taken for late cycles nor for copies.
        A restart not seen within `OPEN_CYCLES` headers (half the counter's range, rounded up,
        if less; its header lost) is no longer waited for.
        """
        with self._lock:
            self._reset(restart)

    def _reset(self, restart: int | None = None) -> None:
        # Per channel, the messages of the radar's identifiers heard (`channels`: those
        # counted in `_heard`, and the current channel's run of them); the messages of other
        # channels than `channel`, not read.
        self._heard: Counter[str | None] = Counter()
        self.other_channels = 0
        # Messages with the identifier of the mapping's header (`mapping_reason`).
        self.headers = 0
        # Bus times of the headers that started the count afresh at ``restart`` (the first
        # header, or one further back than `OPEN_CYCLES` from the header before): a log
        # holding several runs starts it more than once (`rts_scenario.recheck`).
        self._start_counter = restart
        self._last_header_counter: int | None = None
        self.count_starts: list[float] = []
        # The channel of the last message (python-can's object), its label, how many of the
        # radar's messages came on it since it became the current one, and whether it is
        # another channel than `channel`: a bus keeps to one channel object for long runs.
        self._ch: Any = None
        self._ch_label: str | None = None
        self._ch_count = 0
        self._ch_other = self.channel is not None
        self._open: OrderedDict[int, _Assembly] = OrderedDict()
        self._ready: deque[Detections] = deque()
        self._recent: OrderedDict[int, bool] = OrderedDict()  # counter -> handed on whole
        # The last cycles handed on, with their content: a part of one of them that comes
        # again is told apart as a copy or a conflict (of older ones: counted as a copy).
        self._content: OrderedDict[int, _Assembly] = OrderedDict()
        self._current: _Assembly | None = None
        self._latest = -1
        # How far the latest counter may step on before a remembered one may fall out of
        # reach (a lower bound; negative: look, `_forget_out_of_reach`).
        self._slack = -1.0
        self._last_header_t = np.nan  # when the last header reached the bus
        # The counter the radar's count restarts at (`reset`), until it came; the cycles of
        # the stream before dropped at the restart.
        self._restart = restart
        self._headers_before_restart = 0
        # While the restart is awaited: the counters of the cycles begun, in the order their
        # headers came, and whether each was counted as reordered.
        self._begun_before_restart: list[tuple[int, bool]] = []
        self.stale_cycles = 0
        # Detections that came before their cycle's header, by counter (low 8 bits).
        self._waiting: OrderedDict[int, list[tuple[_PartRule, dict[str, float]]]] = OrderedDict()
        # Without a frame counter: parts that came after their cycle was whole, with the
        # cycle's counter, until the next header tells whether one was lost between
        # (`_place_after`).
        self._unplaced: list[tuple[int, _PartRule, dict[str, float]]] = []

    @property
    def pending(self) -> int:
        """Cycles handed on and not yet taken by `pop`."""
        return len(self._ready)

    def pop(self) -> list[Detections]:
        """Take the finished cycles, oldest first.

        None while a restart of the count (`reset`) is still awaited: the cycles before it may
        be the stream before's, dropped when it comes (at most `OPEN_CYCLES` headers later).
        """
        if self._restart is not None:
            return []
        out = []
        while self._ready:
            out.append(self._ready.popleft())
        return out

    @property
    def frame_counted(self) -> bool:
        """Whether detections carry their cycle's frame counter (one before its header waits)."""
        return self._frame_counter is not None

    def forget_waiting(self) -> int:
        """Drop the detections still waiting for their cycle's header; return how many.

        They are no longer counted as orphans or reordered: for a log's first cycle, the
        tail of a cycle before it whose header the log does not hold (`recheck`).
        """
        with self._lock:
            n = sum(len(parts) for parts in self._waiting.values())
            self._waiting.clear()
            self.stats.orphans -= n
            self.stats.reordered -= n
            return n

    def flush(self) -> list[Detections]:
        """Hand on every open cycle (incomplete ones marked so) and take all cycles."""
        with self._lock:
            if self._unplaced:
                self._place_after(None)
            while self._open:
                self._finish(next(iter(self._open)))
            self._current = None
            self._restart = None  # the bus has said all it will: no restart is awaited
        return self.pop()

    def on_message_received(self, msg: can.Message) -> None:
        """Handle one message (called by python-can's Notifier, or directly)."""
        with self._lock:
            self._receive(msg)

    @property
    def channels(self) -> Counter[str | None]:
        """Per channel (`channel_label`), the messages of the radar's identifiers heard."""
        with self._lock:
            out = self._heard.copy()
            if self._ch_count:
                out[self._ch_label] += self._ch_count
        return out

    def _switch_channel(self, channel: Any) -> None:
        """Make ``channel`` (a message's) the current one; count the one before's."""
        if self._ch_count:
            self._heard[self._ch_label] += self._ch_count
        self._ch, self._ch_label, self._ch_count = channel, channel_label(channel), 0
        self._ch_other = self.channel is not None and self._ch_label != self.channel

    def channel_reason(self) -> str | None:
        """Say why the channels the radar's identifiers came on make the cycles untrustworthy.

        Without `channel`: they came on several channels (another radar of the family, or the
        same bus bridged twice), and the cycles mixed theirs. With it: none came on it.
        None where neither happened.
        """
        held = {c: n for c, n in self.channels.items() if n}
        listing = ", ".join(f"{'(none)' if c is None else c} ({n} messages)"
                            for c, n in sorted(held.items(), key=lambda cn: str(cn[0])))
        option = self.channel_option
        what = f"the radar's messages (the identifiers of mapping {self.mapping.name!r})"
        if self.channel is not None:
            if self.channel in held:
                return None
            if held and set(held) == {None}:
                # python-can's udp_multicast and virtual buses name no channel: one channel.
                return (f"{option} {self.channel}: the interface names no channel on "
                        f"its messages (python-can gives Message.channel None; {what}: "
                        f"{held[None]} messages): it reads one channel, which {option} "
                        f"cannot pick; leave {option} out")
            found = f"the channels they came on: {listing}" if held else "none came on any"
            return (f"{option} {self.channel}: none of {what} came on channel "
                    f"{self.channel}; {found}")
        if len(held) <= 1:
            return None
        return (f"{what} came on {len(held)} channels: {listing}: the radar's cycles and "
                f"another bus's were mixed; give {option} CH (the channel as python-can "
                f"gives it)")

    def _receive(self, msg: can.Message) -> None:
        stats = self.stats
        # An 11-bit and a 29-bit identifier of one number are different messages.
        known = self._layouts.get(msg.arbitration_id | (msg.is_extended_id << 31))
        if msg.channel is not self._ch:
            self._switch_channel(msg.channel)
        if self._ch_other:
            self.other_channels += 1  # another bus's
            if known is not None and not (msg.is_error_frame or msg.is_remote_frame):
                self._ch_count += 1
            return
        stats.messages += 1
        if msg.is_error_frame:
            stats.error_frames += 1
            return
        if msg.is_remote_frame:
            stats.remote_frames += 1
            return
        if known is None:
            stats.unknown_ids += 1
            return
        self._ch_count += 1  # a message of the radar's identifiers, on the current channel
        message, checksum, mux, decode, part = known
        if message is self._header:
            self.headers += 1
        data = msg.data
        if checksum is not None and not checksum(data):
            stats.checksum_errors += 1
            return
        try:
            # Raw values: cantools' compiled codec, or (multiplexed) cantools picks the page.
            values = (decode(data) if decode is not None else
                      message.decode(bytes(data), decode_choices=False, scaling=False))
        except (cantools.database.DecodeError, ValueError, KeyError, TypeError):
            stats.decode_errors += 1
            return
        if message is self._header:
            host = self.host_clock
            if host is None:
                received, level = float(self.received_at(msg)), 0.0
            elif self.received_at is self._wall_receipt:
                # The receipt is the watch's own reading: its level is the one it was read at.
                received, level = host.read()
            else:
                received = float(self.received_at(msg))
                level = host.sample()
            self._on_header(values, float(msg.timestamp),  # type: ignore[arg-type]
                            received, level)
            return
        if mux is not None:  # the raw page id
            part = (message.frame_id, int(values[mux]))  # type: ignore[call-overload, arg-type]
        rule = self._rules.get(part)
        if rule is not None:  # else a page the mapping does not read (extended information)
            self._on_detection(rule, values)  # type: ignore[arg-type]

    def _on_header(self, raw: dict[str, float], bus_t_s: float | None = None,
                   host_t_s: float | None = None, host_step_s: float = 0.0) -> None:
        m = self.mapping
        values: dict[str, float] = {
            name: self._header_signals[name].conversion.raw_to_scaled(value, False)  # type: ignore[misc]
            for name, value in raw.items()}
        # The counter from its first value (a counter running 1..14 counts 1 as 0); its low
        # bits, in the detection messages, are the value's on the bus.
        value = int(values[m.counter])
        counter = value - m.counter_min
        if not 0 <= counter < self._counter_modulus:
            # A value the counter never takes (15 of an AUTOSAR counter wrapping after 14, 0
            # of one running 1..14): the message is invalid.
            self.stats.decode_errors += 1
            return
        if counter == self._start_counter:
            last = self._last_header_counter
            # Back by more than reordering or a copy held up on the bus explains (a count
            # that went on across a wrap is a step forward, whatever it skipped).
            if last is None or signed_step(counter, last, self._counter_modulus) < -OPEN_CYCLES:
                self.count_starts.append(float("nan") if bus_t_s is None else bus_t_s)
        self._last_header_counter = counter
        if self._restart is not None:
            if counter == self._restart:
                self._drop_before_restart(self._stale_before_restart(counter))
                self._restart = None
            elif self._headers_before_restart >= min(OPEN_CYCLES, self._reach):
                # The restart's header was lost: the count later coming round to it again is
                # no restart.
                self._restart = None
                self._begun_before_restart = []
            self._headers_before_restart += 1
        if self._unplaced:
            self._place_after(counter)
        if bus_t_s is not None:
            if self.cycle_s is not None and bus_t_s - self._last_header_t > (
                    long_gap_cycles(self._counter_modulus) * self.cycle_s):
                self._after_silence()
            self._last_header_t = bus_t_s
        known = self._open.get(counter) or self._content.get(counter)
        if known is not None or counter in self._recent:
            # The same header again is a copy; another one with this counter is a conflict
            # (the cycle's content is in doubt: it fails the verdict).
            if known is None or _same(known.header, raw):
                self.stats.duplicates += 1
            else:
                self.stats.conflicts += 1
            return
        reordered = self._latest >= 0 and signed_step(counter, self._latest,
                                                      self._counter_modulus) < 0
        if reordered:
            self.stats.reordered += 1
        else:
            self._slack = (self._slack - signed_step(counter, self._latest, self._counter_modulus)
                           if self._latest >= 0 else -1.0)
            self._latest = counter
            self._forget_out_of_reach()
        if self._restart is not None:
            self._begun_before_restart.append((counter, reordered))
        frame = _Assembly(
            counter=counter, low=value % self._low_modulus,
            expected=int(sum(values[c] for c in m.count)),
            timestamp_s=(values[m.timestamp] * m.timestamp_scale
                         if m.timestamp and m.timestamp in values else None), bus_t_s=bus_t_s,
            host_t_s=host_t_s, host_step_s=host_step_s, header=dict(raw))
        self._open[counter] = frame
        self._current = frame
        for rule, early in self._waiting.pop(value % self._low_modulus, []):
            self.stats.orphans -= 1
            self._attach(frame, rule, early)
        if frame.complete():
            self._finish(counter)
        # An incomplete cycle waits for late parts while `OPEN_CYCLES` newer cycles begin (fewer
        # for a narrow counter), then goes on as incomplete: held longer, the counter that
        # names it could come round again and its place among the cycles be lost. So does one
        # the latest counter jumped past (headers lost): no longer behind it, it is out of
        # reach. Not while a restart is awaited: the latest counter may be the stream before's,
        # far from the new count (the wait lasts `OPEN_CYCLES` headers at most, half the
        # counter's range rounded up if less).
        held = min(OPEN_CYCLES, max(1, self._counter_modulus // 4))
        if self._restart is None:
            for old in [c for c in self._open
                        if not -held < signed_step(c, self._latest, self._counter_modulus) <= 0]:
                self._finish(old)
        while len(self._open) > OPEN_CYCLES:
            self._finish(next(iter(self._open)))

    def _on_detection(self, rule: _PartRule, values: dict[str, float]) -> None:
        frame = self._current
        name = self._frame_counter
        low_counter = values.get(name) if name else None
        if low_counter is not None:
            low = self._low_of(low_counter)
            if frame is None or frame.low != low:
                # Late part of an earlier cycle, or early part of one whose header is late.
                self.stats.reordered += 1
                frame = next((f for f in reversed(self._open.values()) if f.low == low), None)
                if frame is None:
                    # Within half the low counter's range: further back, the same low bits
                    # name another cycle (the one whose header is still to come).
                    first = self.mapping.counter_min  # the counters' value 0 on the bus
                    done = next((c for c in itertools.islice(reversed(self._recent),
                                                             self._low_modulus // 2)
                                 if (c + first) % self._low_modulus == low), None)
                    if done is not None:
                        # Its cycle was handed on: a copy, a conflict, or (the cycle went on
                        # incomplete) too late.
                        if self._recent[done]:
                            self._after(done, rule, values)
                        return
                    self._waiting.setdefault(low, []).append((rule, values))
                    self.stats.orphans += 1  # until its header comes
                    while len(self._waiting) > OPEN_CYCLES:
                        self._waiting.popitem(last=False)
                    return
        if frame is None:
            self.stats.orphans += 1
            return
        if frame.counter not in self._open:
            # Its cycle was handed on: a copy or a conflict if it was whole, else too late to
            # count.
            if not self._recent.get(frame.counter, False):
                self.stats.orphans += 1
            elif name is None:
                # No frame counter tells its cycle: the next one's, whose header was lost, or
                # this one's again. The next header says which.
                self._unplaced.append((frame.counter, rule, values))
                if len(self._unplaced) > UNPLACED_PARTS:  # no header for that long
                    self._unplaced.pop(0)
                    self.stats.orphans += 1
            else:
                self._after(frame.counter, rule, values)
            return
        if self._attach(frame, rule, values) and frame.complete():
            self._finish(frame.counter)

    def _scaled(self, rule: _PartRule, values: dict[str, float]) -> int:
        """Scale a part's mapped signals to the DBC's physical values; return its index."""
        for name, scale, offset in rule.scalings:  # raw -> the DBC's physical
            if name in values:
                values[name] = values[name] * scale + offset
        return self._index_of(values[self._index])

    def _attach(self, frame: _Assembly, rule: _PartRule, values: dict[str, float]) -> bool:
        """Add a part to its cycle; return whether it was new (else a copy or a conflict)."""
        added = frame.add(self._scaled(rule, values), rule, values)
        if added:
            return True
        if added is False:
            self.stats.duplicates += 1
        else:
            self.stats.conflicts += 1
        return False

    def _place_after(self, counter: int | None) -> None:
        """Place the parts that came after their whole cycle, without a frame counter.

        ``counter``: the next header's (None: none came). A header more than one cycle on
        (within half the counter's range: not one of an earlier cycle come again) says a
        cycle came without its header: the parts are its,
        detections without a frame header (`BusStats.orphans`; its cycle is missing), not
        messages of the whole cycle come again. Otherwise they are that cycle's again: a
        copy or a conflict (`_after`).
        """
        unplaced, self._unplaced = self._unplaced, []
        for after, rule, values in unplaced:
            if counter is not None and signed_step(counter, after, self._counter_modulus) >= 2:
                self.stats.orphans += 1
            else:
                self._after(after, rule, values)

    def _after(self, counter: int, rule: _PartRule, values: dict[str, float]) -> None:
        """Count a part of a whole cycle already handed on: a copy, or a conflict.

        A conflict (another value, or a detection beyond the count its header announced)
        means the cycle that was checked is not the one the radar sent: it fails the verdict.
        A cycle `OPEN_CYCLES` or more cycles old is no longer held: its part counts as a copy.
        """
        frame = self._content.get(counter)
        if frame is None:
            self.stats.duplicates += 1
            return
        index = self._scaled(rule, values)
        known = frame.arrived.get(index, {}).get(rule.key)
        if known is not None and _same(known, values):
            self.stats.duplicates += 1
        else:
            self.stats.conflicts += 1

    def _after_silence(self) -> None:
        """Hand on the open cycles and forget every counter: the bus was silent too long.

        Detections waiting for their header stay: they may have come just before it.
        """
        if self._unplaced:
            self._place_after(None)
        while self._open:
            self._finish(next(iter(self._open)))
        self._recent.clear()
        self._content.clear()
        self._current = None
        self._latest = -1

    def _stale_before_restart(self, restart: int) -> set[int]:
        """Return which cycles received before the restart's header are the stream before's.

        The cycles right after it, counting on from it without a gap, are the stream's own:
        the restart's header was held up behind them. So are the others if they all count up
        to it (a radar measuring before the stream's start; some may be lost); otherwise
        they are the stream before's.
        """
        limit = min(OPEN_CYCLES, self._reach)
        offsets = {c: signed_step(c, restart, self._counter_modulus)
                   for c in [*(d.cycle for d in self._ready), *self._open]}
        ahead = set(offsets.values())
        run = 0
        while run + 1 < limit and run + 1 in ahead:
            run += 1
        others = {c for c, d in offsets.items() if not 0 < d <= run}
        if all(-limit < offsets[c] < 0 for c in others):
            return set()
        return others

    def _drop_before_restart(self, stale: set[int]) -> None:
        """Drop the cycles received since the reset that are the stream before's (`reset`).

        Their counters are forgotten, and the other headers that came meanwhile are counted
        as reordered or not again, as if the dropped ones had never come.
        """
        begun, self._begun_before_restart = self._begun_before_restart, []
        if not stale:
            return
        self.stale_cycles += (sum(d.cycle in stale for d in self._ready)
                              + sum(c in stale for c in self._open))
        self._ready = deque(d for d in self._ready if d.cycle not in stale)
        for counter in stale:
            self._open.pop(counter, None)
            self._recent.pop(counter, None)
            self._content.pop(counter, None)
        self._unplaced = [u for u in self._unplaced if u[0] not in stale]
        if self._current is not None and self._current.counter in stale:
            self._current = None
        self._latest = -1
        self._slack = -1.0
        for counter, reordered in begun:
            self.stats.reordered -= reordered
            if counter in stale:
                continue
            if self._latest >= 0 and signed_step(counter, self._latest,
                                                 self._counter_modulus) < 0:
                self.stats.reordered += 1
            else:
                self._latest = counter

    def _finish(self, counter: int) -> None:
        """Hand on an open cycle as `Detections`."""
        frame = self._open.pop(counter)
        complete = frame.complete()
        self._recent[counter] = complete
        self._content[counter] = frame
        if self._latest >= 0:  # ahead of the latest (an incomplete one left behind): look
            step = signed_step(counter, self._latest, self._counter_modulus)
            self._slack = min(self._slack, self._reach - 1 + step) if step <= 0 else -1.0
        self._forget_out_of_reach()
        # Bounded: the cycles handed on last are kept.
        while len(self._recent) > RECENT_CYCLES:
            self._recent.popitem(last=False)
        while len(self._content) > OPEN_CYCLES:
            self._content.popitem(last=False)
        if self._current is frame and not complete:
            self._current = None
        self._ready.append(Detections(cycle=counter, t_s=frame.timestamp_s, complete=complete,
                                      bus_t_s=frame.bus_t_s, host_t_s=frame.host_t_s,
                                      host_step_s=frame.host_step_s,
                                      **self._quantities(frame)))

    def _forget_out_of_reach(self) -> None:
        """Forget the cycles handed on that are not at or behind the latest counter.

        Kept are the counters from the latest back by `largest_step_back` at most, whatever
        the order their cycles were handed on in (an incomplete one goes on after the cycles
        that came while it waited): any other counter is ahead of the latest, so its header is
        a new cycle's, not a copy of one remembered.
        """
        if self._latest < 0 or self._slack >= 0:
            return  # none can be out of reach yet: the usual case, no look at each
        latest, modulus = self._latest, self._counter_modulus
        back = self._reach - 1
        slack = np.inf
        for known in (self._recent, self._content):
            for counter in list(known):
                step = signed_step(counter, latest, modulus)
                if -back <= step <= 0:
                    slack = min(slack, back + step)
                else:
                    del known[counter]
        self._slack = slack

    def _quantities(self, frame: _Assembly) -> dict[str, np.ndarray]:
        """Arrays of the quantities the mapping carries (polar, rts-scenario's names)."""
        m = self.mapping
        parts = frame.parts
        rows = [parts[i] for i in sorted(parts)]
        try:  # every mapped signal arrived (a whole cycle)
            raw = np.array(list(map(self._field_getter, rows)), dtype=np.float64)
        except KeyError:
            raw = np.array([[r.get(name, np.nan) for name in self._field_names] for r in rows],
                           dtype=np.float64)
        # The DBC's physical values -> the mapping's quantities, one row per field.
        values = raw.reshape(len(rows), len(self._field_names)).T
        if self._to_quantity is not None:
            scale, offset = self._to_quantity
            values = values * scale[:, None] + offset[:, None]
        out = {name: values[column] for name, column in self._direct}
        if m.form == "polar":
            return out

        def get(q: str) -> np.ndarray:
            return values[self._field_column[m.fields[q].signal]]

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
        return out


def mapping_reason(mapping: CanMapping, headers: int, unknown_ids: int,
                   frames: dict[str, int] | None = None, *,
                   option: str = "--mapping") -> str | None:
    """Why a bus's messages are not the mapping's radar's, or None.

    Where no message had the identifier of the mapping's header (``headers``) and some had
    identifiers the mapping does not know (``unknown_ids``): the radar spoke, in another
    protocol than the one given; its cycles all count as missing. Where the headers came but
    no cycle came whole (the check's ``frames``: none ``received``, some ``incomplete``) and
    messages of unknown identifiers did: another protocol whose status message has the same
    identifier (one radar's two modes, a cluster and an object list), its detections unread.
    ``option``: the option that gives the mapping, as the caller spells it.
    """
    if not unknown_ids:
        return None
    if not headers:
        return (f"no message matched the mapping's header ({mapping.header} of mapping "
                f"{mapping.name!r}); {unknown_ids} messages with identifiers the mapping does "
                f"not know: is {option} the radar's?")
    if frames is None or frames.get("received", 0) or not frames.get("incomplete", 0):
        return None
    return (f"the mapping's header ({mapping.header} of mapping {mapping.name!r}) came, but "
            f"none of its {frames['incomplete']} cycles whole; {unknown_ids} messages with "
            f"identifiers the mapping does not know: is {option} the radar's?")


def with_mapping_hint(reason: str, mapping: CanMapping | None, unknown_ids: int, *,
                      option: str = "--mapping") -> str:
    """``reason`` of the radar's clock, with the mapping named where the bus hints at it.

    A radar read with another protocol's mapping whose header has the same identifier (a
    cluster list read as an object list) has its cycles read whole, their counters from
    another signal: a count far off reads as a radar started late or on another cycle. Where
    messages of identifiers the mapping does not know came too, the reason says so
    (``option``: the option that gives the mapping, as the caller spells it).
    """
    if mapping is None or not unknown_ids:
        return reason
    return (f"{reason}; {unknown_ids} messages with identifiers mapping {mapping.name!r} does "
            f"not know came too: is {option} the radar's (a counter read from another "
            f"protocol's signal reads as this)?")


__all__ = ["BusStats", "CanMapping", "DetectionPublisher", "DetectionReceiver", "ListenerBus",
           "channel_label", "mapping_reason", "open_bus", "with_mapping_hint"]
