"""Detections over CAN: python-can transport, cantools encoding, frame reassembly.

The simulated radar publishes each frame as a header message (frame counter, detection count,
time) followed by its detections (two classic CAN messages per detection, or one CAN FD
message), each with an end-to-end checksum. `DetectionReceiver` is a python-can listener that
decodes any radar's messages through a `CanMapping` and reassembles them into frames, counting
everything that goes wrong on the way.
"""

from __future__ import annotations

import time
import zlib
from dataclasses import dataclass, field
from typing import Any

import can
import cantools
import numpy as np

from ..errors import CheckError, OutputError
from ..radar.simulate import Detections
from .mapping import CanMapping

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


def _checksum_byte(message: cantools.database.can.Message, name: str) -> int:
    sig = message.get_signal_by_name(name)
    if sig.length != 8 or sig.start % 8 or sig.byte_order != "little_endian":
        raise CheckError(f"{message.name}.{name}: checksums must be whole little-endian bytes")
    return int(sig.start // 8)


class DetectionPublisher:
    """Encode radar frames with rts-scenario's DBC and send them on a bus."""

    def __init__(self, bus: can.BusABC, *, fd: bool = False) -> None:
        self.bus = bus
        self.fd = fd
        self.mapping = CanMapping.builtin()
        db = self.mapping.db
        self._header = db.get_message_by_name("RTS_FrameHeader")
        names = ["RTS_DetectionFD"] if fd else ["RTS_DetectionA", "RTS_DetectionB"]
        self._parts = [db.get_message_by_name(n) for n in names]
        self.sent = 0

    def _send(self, message: cantools.database.can.Message, values: dict[str, float]) -> None:
        try:
            data = bytearray(message.encode({**values, "Checksum": 0}, strict=True))
        except (cantools.database.EncodeError, KeyError) as exc:
            raise OutputError(f"CAN {message.name}: {exc}") from None
        pos = _checksum_byte(message, "Checksum")
        data[pos] = _checksum(bytes(data), pos)
        self.bus.send(can.Message(arbitration_id=message.frame_id, data=bytes(data),
                                  is_extended_id=False, is_fd=self.fd))
        self.sent += 1

    def publish(self, frame: Detections) -> None:
        """Send one frame: header, then every detection."""
        n = frame.count
        if n > 255:
            raise OutputError(f"CAN: frame {frame.frame} has {n} detections; at most 255 fit")
        self._send(self._header, {"FrameCounter": frame.frame & 0xFFFF, "DetectionCount": n,
                                  "TimeStamp": min(frame.t_s, 429496.7295)})
        # Metadata saturates at the DBC's limits; measured quantities must fit as they are.
        snr = np.clip(frame.snr_db, 0.0, 127.5)
        rcs_max = 63.5 if not self.fd else 327.67
        rcs = np.clip(np.nan_to_num(frame.rcs_dbsm, nan=-64.0, neginf=-64.0), -64.0, rcs_max)
        counter8 = frame.frame & 0xFF
        for i in range(n):  # one encoded message per detection (cantools encodes one at a time)
            values = {"FrameCounter8": counter8, "Index": i, "Range": frame.range_m[i],
                      "RadialVelocity": frame.radial_velocity_mps[i],
                      "Azimuth": frame.az_deg[i], "Elevation": frame.el_deg[i],
                      "RCS": rcs[i], "SNR": snr[i]}
            for message in self._parts:
                wanted = {s.name for s in message.signals}
                self._send(message, {k: v for k, v in values.items() if k in wanted})


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
class ReceivedFrame:
    """A frame reassembled from the bus."""

    counter: int
    expected: int
    timestamp_s: float | None
    arrival_s: float
    parts: dict[int, dict[str, float]] = field(default_factory=dict)
    halves: dict[int, int] = field(default_factory=dict)

    def complete(self, halves_per_detection: int) -> bool:
        """All announced detections arrived, whole."""
        return len(self.parts) == self.expected and all(
            self.halves.get(i, 0) == halves_per_detection for i in self.parts)


class DetectionReceiver(can.Listener):
    """Decode detection messages through a mapping and reassemble frames (a can.Listener)."""

    def __init__(self, mapping: CanMapping | None = None) -> None:
        self.mapping = mapping or CanMapping.builtin()
        db = self.mapping.db
        self._header = db.get_message_by_name(self.mapping.header)
        self._detection_ids = {db.get_message_by_name(n).frame_id: db.get_message_by_name(n)
                               for n in (*self.mapping.messages,
                                         *([self.mapping.fd_message]
                                           if self.mapping.fd_message else []))}
        self.stats = BusStats()
        self.frames: dict[int, ReceivedFrame] = {}
        self._current: ReceivedFrame | None = None
        self._latest = -1
        # Detections that came before their frame's header, by frame counter (low 8 bits).
        self._waiting: dict[int, list[tuple[cantools.database.can.Message, dict[str, float]]]]
        self._waiting = {}

    def reset(self) -> None:
        """Forget the frames received so far (a new measurement reuses frame counters)."""
        self.frames = {}
        self._current = None
        self._latest = -1
        self._waiting = {}

    def on_message_received(self, msg: can.Message) -> None:
        """Handle one message (called by python-can's Notifier, or directly)."""
        stats = self.stats
        stats.messages += 1
        if msg.is_error_frame:
            stats.error_frames += 1
            return
        if msg.arbitration_id == self._header.frame_id:
            values = self._decode(self._header, msg, self.mapping.header_checksum)
            if values is not None:
                self._on_header(values)
            return
        message = self._detection_ids.get(msg.arbitration_id)
        if message is None:
            stats.unknown_ids += 1
            return
        values = self._decode(message, msg, self.mapping.checksum)
        if values is not None:
            self._on_detection(message, values)

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

    def _on_header(self, values: dict[str, float]) -> None:
        m = self.mapping
        counter = int(values[m.counter])
        if counter in self.frames:
            self.stats.duplicates += 1
            return
        if self._latest >= 0 and _behind(counter, self._latest):
            self.stats.reordered += 1
        else:
            self._latest = counter
        frame = ReceivedFrame(
            counter=counter, expected=int(sum(values[c] for c in m.count)),
            timestamp_s=values.get(m.timestamp) if m.timestamp else None,
            arrival_s=time.perf_counter())
        self.frames[counter] = frame
        self._current = frame
        for message, values in self._waiting.pop(counter & 0xFF, []):
            self.stats.orphans -= 1
            self._attach(frame, message, values)

    def _on_detection(self, message: cantools.database.can.Message,
                      values: dict[str, float]) -> None:
        m = self.mapping
        frame = self._current
        if m.frame_counter is not None and m.frame_counter in values:
            low = int(values[m.frame_counter])
            if frame is None or (frame.counter & 0xFF) != low:
                # Late part of an earlier frame, or early part of one whose header is late.
                self.stats.reordered += 1
                frame = next((f for c, f in reversed(self.frames.items()) if c & 0xFF == low),
                             None)
                if frame is None:
                    self._waiting.setdefault(low, []).append((message, values))
                    self.stats.orphans += 1  # until its header comes
                    return
        if frame is None:
            self.stats.orphans += 1
            return
        self._attach(frame, message, values)

    def _attach(self, frame: ReceivedFrame, message: cantools.database.can.Message,
                values: dict[str, float]) -> None:
        m = self.mapping
        index = int(values[m.index])
        part = frame.parts.setdefault(index, {})
        if set(values) & set(part) - {m.index, m.frame_counter, m.checksum}:
            self.stats.duplicates += 1
            return
        part.update(values)
        # A CAN FD detection is whole in one message; classic ones come in halves.
        whole = message.name == m.fd_message
        frame.halves[index] = frame.halves.get(index, 0) + (len(m.messages) if whole else 1)

    def detections(self, counter: int) -> dict[str, np.ndarray]:
        """Arrays of the quantities the mapping carries for one received frame (polar)."""
        frame = self.frames[counter]
        m = self.mapping
        rows = [frame.parts[i] for i in sorted(frame.parts)]

        def get(q: str) -> np.ndarray:
            f = m.fields[q]
            return np.array([r.get(f.signal, np.nan) for r in rows]) * f.scale + f.offset

        out: dict[str, np.ndarray] = {}
        if m.form == "polar":
            for q in ("range_m", "azimuth_deg", "elevation_deg", "radial_velocity_mps"):
                if q in m.fields:
                    out[q] = get(q)
        else:
            x, y = get("x_m"), get("y_m")
            z = get("z_m") if "z_m" in m.fields else np.zeros_like(x)
            rng = np.sqrt(x * x + y * y + z * z)
            out["range_m"] = rng
            out["azimuth_deg"] = np.degrees(np.arctan2(y, x))
            if "z_m" in m.fields:
                out["elevation_deg"] = np.degrees(np.arctan2(z, np.hypot(x, y)))
            if "vx_mps" in m.fields and "vy_mps" in m.fields:
                out["radial_velocity_mps"] = (x * get("vx_mps") + y * get("vy_mps")) / np.where(
                    rng > 0, rng, 1.0)
        for q in ("rcs_dbsm", "snr_db"):
            if q in m.fields:
                out[q] = get(q)
        return out

    @property
    def halves_per_detection(self) -> int:
        """Messages per detection: 1 (one message or CAN FD) or 2 (two classic halves)."""
        return len(self.mapping.messages)


def _behind(counter: int, latest: int) -> bool:
    """Whether a 16-bit frame counter is older than the latest seen (with wrap-around)."""
    return 0 < (latest - counter) % 65536 < 32768


__all__ = ["BusStats", "CanMapping", "DetectionPublisher", "DetectionReceiver", "open_bus"]
