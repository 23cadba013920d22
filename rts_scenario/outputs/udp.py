"""Schedule streaming to the RTS over UDP, and a reference receiver (a simulated RTS endpoint).

Protocol (version 1, all fields big-endian; see docs/udp-protocol.md)::

    header  28 bytes  magic "RTSS" | version u8 | kind u8 (0 full frame, 1 delta)
                      | sequence u32 (per datagram) | frame u32 | part u16 | parts u16
                      | t_s f64 (scene time) | entries u16
    entry   28 bytes  target u16 | channel u8 | flags u8 (bit 0: active) | fe i16 | status u16
                      | attenuation_db f32 | delay_s f64 | doppler_hz f32 | phase_rad f32
    trailer  4 bytes  CRC-32 (zlib) of header and entries

A frame is split into as many datagrams (parts) as needed to keep each under 1400 bytes. A full
frame lists every active channel; a delta lists the channels of entries that changed since the
previous frame (inactive ones with flag 0), and a full frame is sent every ``keyframe_every``
frames so a receiver that lost a delta can resynchronize.
"""

from __future__ import annotations

import contextlib
import errno
import ipaddress
import os
import platform
import select
import socket
import struct
import sys
import threading
import time
import zlib
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import OutputError
from ..hostclock import monotonic_s, wall_s
from ..schedule import Schedule
from .base import Output

MAGIC = b"RTSS"
VERSION = 1
KIND_FULL = 0
KIND_DELTA = 1
HEADER = struct.Struct("!4sBBIIHHdH")
TRAILER = struct.Struct("!I")
ENTRY = np.dtype([("target", ">u2"), ("channel", "u1"), ("flags", "u1"), ("fe", ">i2"),
                  ("status", ">u2"), ("attenuation_db", ">f4"), ("delay_s", ">f8"),
                  ("doppler_hz", ">f4"), ("phase_rad", ">f4")])
# The schedule's fields as an entry carries them (`Schedule.changed`: a delta lists what
# changed on the wire, the same however the frames came in batches).
AS_SENT = {name: ENTRY[name].newbyteorder("=") for name in
           ("attenuation_db", "delay_s", "doppler_hz", "phase_rad")}
# The RTS's status reply (optional): its counters after each datagram it handled.
STATUS_MAGIC = b"RTSR"
STATUS_COUNTERS = ("datagrams", "corrupted", "malformed", "duplicates", "reordered", "stale",
                   "frames_applied", "lost_frames", "unsynced_frames")
STATUS = struct.Struct("!4sB" + "I" * len(STATUS_COUNTERS))
# The RTS's rig reply (optional): how many FEs it has and a digest of their geometry
# (`rts_scenario.rig.Rig.geometry_digest`).
RIG_MAGIC = b"RTSI"
RIG_REPLY = struct.Struct("!4sBH32s")
# The receiver sends it with the status reply to a stream's first datagram and every this many
# after (one that arrives is enough; a lost one is sent again).
RIG_REPLY_EVERY = 32
# The sender reads the replies every this many frames (they would fill its socket's buffer).
STATUS_DRAIN_FRAMES = 32
# The receiver tells a duplicate from a new datagram this many sequence numbers back from the
# newest (bounded memory); an older datagram is dropped as stale.
# After this long without a datagram (s), a full frame's first datagram opens a new stream
# from any sender: a run ends with a drain of its radar's last cycles and a wait for the RTS's
# last report, longer than this; a copy of a datagram does not come this late on a bench.
STREAM_QUIET_S = 0.25
# States the receiver keeps for `UdpReceiver.snapshot` at a past moment: 12.8 s of 20 Hz frames.
STATE_HISTORY = 256
SEQUENCE_WINDOW = 4096
MAX_DATAGRAM = 1400
MAX_ENTRIES = (MAX_DATAGRAM - HEADER.size - TRAILER.size) // ENTRY.itemsize
# What the fields number: targets (``target`` u16), frames (``frame`` u32), FEs (``fe`` i16);
# ``sequence`` counts modulo 2^32.
MAX_TARGETS = 1 << 16
MAX_FRAMES = 1 << 32
MAX_FRONT_ENDS = 1 << 15
SEQUENCE_MODULUS = 1 << 32

PACING = ("realtime", "fast")
MODES = ("full", "delta")

# A datagram nothing receives comes back as an ICMP error (port unreachable: nothing listens on
# that port; host or network unreachable). Linux tells an unconnected socket of it only with
# IP_RECVERR (IPV6_RECVERR) set, and then queues each error, with the address it is about, on
# the socket's error queue; the next send or read fails once, and that send does not go out.
_RECVERR: dict[int, tuple[int, int]] = {
    socket.AF_INET: (socket.IPPROTO_IP, getattr(socket, "IP_RECVERR", 11)),
    socket.AF_INET6: (socket.IPPROTO_IPV6, getattr(socket, "IPV6_RECVERR", 25))}
_MSG_ERRQUEUE = getattr(socket, "MSG_ERRQUEUE", 0x2000)
_MSG_DONTWAIT = getattr(socket, "MSG_DONTWAIT", 0x40)
# ``struct sock_extended_err``: ee_errno u32, ee_origin u8, ee_type u8, ee_code u8, ...
_EXTENDED_ERR = struct.Struct("=IBBB")
_ICMP_ERRORS = frozenset({errno.ECONNREFUSED, errno.EHOSTUNREACH, errno.ENETUNREACH})


def frame_entries(schedule: Schedule, pos: int, changed: NDArray[np.bool_] | None) -> np.ndarray:
    """Return frame ``pos``'s entries as a structured array (all active, or the changed)."""
    if changed is None:
        k, c = np.nonzero(schedule.active[pos])
    else:
        k, c = np.nonzero(np.broadcast_to(changed[pos][:, None], schedule.active[pos].shape))
    out = np.zeros(k.size, dtype=ENTRY)
    out["target"] = k
    out["channel"] = c
    out["flags"] = schedule.active[pos, k, c]
    out["fe"] = schedule.fe[pos, k, c]
    out["status"] = schedule.status[pos, k]
    for name in ("attenuation_db", "delay_s", "doppler_hz", "phase_rad"):
        out[name] = np.nan_to_num(getattr(schedule, name)[pos, k, c], nan=0.0)
    return out


def encode_frame(entries: np.ndarray, *, kind: int, frame: int, t_s: float,
                 first_sequence: int) -> list[bytes]:
    """Split a frame's entries into datagrams numbered from ``first_sequence``."""
    parts = max(1, -(-entries.size // MAX_ENTRIES))
    out = []
    for part in range(parts):
        chunk = entries[part * MAX_ENTRIES : (part + 1) * MAX_ENTRIES]
        head = HEADER.pack(MAGIC, VERSION, kind, (first_sequence + part) & 0xFFFFFFFF, frame,
                           part, parts, t_s, chunk.size)
        body = head + chunk.tobytes()
        out.append(body + TRAILER.pack(zlib.crc32(body)))
    return out


class UdpOutput(Output):
    """Stream a schedule to ``HOST:PORT``, paced at the frame times or as fast as possible."""

    name = "udp"

    # The address defaults to none so that a spec without one (``udp://``) gets the usage line.
    def __init__(self, address: str = "", *, pacing: str = "realtime", mode: str = "full",
                 keyframe_every: int = 20) -> None:
        super().__init__()
        if pacing not in PACING:
            raise OutputError(f"udp: unknown pacing {pacing!r}; valid: {', '.join(PACING)}")
        if mode not in MODES:
            raise OutputError(f"udp: unknown mode {mode!r}; valid: {', '.join(MODES)}")
        host, _, port = address.rpartition(":")
        # ASCII digits only: str.isdigit also takes digits int() refuses (superscripts).
        if not host or not (port.isascii() and port.isdigit()) or not 0 < int(port) < 65536:
            raise OutputError(f"udp://{address}: expected udp://HOST:PORT with a port 1..65535")
        self.address = (host.strip("[]"), int(port))
        self.pacing = pacing
        self.mode = mode
        self.keyframe_every = max(1, keyframe_every)
        # Resolved once, here: a host that does not resolve is bad input before a run starts,
        # not a failure at its first frame. A name goes to its IPv4 address where it has one
        # (as an RTS listening on 127.0.0.1 is reached by "localhost"), else to its IPv6 one.
        try:
            family, _, _, _, self._sockaddr = _resolve(*self.address)
        except (OSError, UnicodeError) as exc:
            reason = getattr(exc, "strerror", None) or exc
            raise OutputError(f"udp://{address}: unknown host {self.address[0]!r} "
                              f"({reason})") from None
        resolved = ipaddress.ip_address(self._sockaddr[0].split("%")[0])
        if resolved.is_multicast or resolved == ipaddress.IPv4Address("255.255.255.255"):
            # One RTS is addressed: a broadcast fails only at the first frame (a socket may
            # not send there), and a group's members would each play the schedule.
            raise OutputError(f"udp://{address}: {resolved} is a "
                              f"{'multicast' if resolved.is_multicast else 'broadcast'} "
                              f"address; give the RTS's own address")
        try:
            self._socket = socket.socket(family, socket.SOCK_DGRAM)
        except OSError as exc:
            raise OutputError(f"udp://{address}: cannot open a socket: {exc}") from None
        self._error_queue = _enable_icmp_errors(self._socket, family)
        # Datagrams the network sent back (`rts_unreachable`): by error number, and the scene
        # times of the frames being sent when the first and the last were told.
        self._refused: dict[int, int] = {}
        self._refused_s: list[float] = []
        self._sent_frame_t_s: float | None = None  # the last frame out, as errors are told
        self._last_sent: Schedule | None = None  # delta mode: the last frame written
        self._last_frame_index = -1  # the stream's frames go forward (`_check_forward`)
        # Every datagram goes through ``send``; tests swap in a `FaultInjector` around
        # ``transmit``.
        self.send: Callable[[bytes], None] = self.transmit
        # When `transmit` last put a datagram out (perf_counter), None before the first.
        self._transmitted_s: float | None = None
        self._sequence = 0
        self._start: float | None = None
        self._t0 = 0.0
        self.scene_origin_wall_s: float | None = None
        # The same instant on the host's monotonic clock (`rts_scenario.hostclock`).
        self.scene_origin_monotonic_s: float | None = None
        self._frames_sent = 0
        self.entries_sent = 0
        self.datagrams_sent = 0
        self._sent_t_s = np.zeros(0)
        self._rts_status: dict[str, int] | None = None
        self._rts_rig: tuple[int, bytes] | None = None

    def transmit(self, datagram: bytes) -> None:
        """Put one datagram on the network."""
        self._transmitted_s = time.perf_counter()
        for attempt in range(4):
            try:
                self._socket.sendto(datagram, self._sockaddr)
                return
            except OSError as exc:
                # An earlier datagram's error, told at this send, which did not go out.
                told = self._take_errors()
                if not (self._error_queue and attempt < 3
                        and (told or exc.errno in _ICMP_ERRORS)):
                    raise OutputError(f"udp://{self.address[0]}:{self.address[1]}: send "
                                      f"failed: {exc}") from None

    def _write(self, batch: Schedule) -> None:
        self._check_fits(batch)
        self._check_forward(batch)
        # Frame 0 of a batch is a delta against the last frame of the batch before (kept as a
        # copy: one frame, whatever the scene's length).
        changed = (batch.changed(self._last_sent, AS_SENT) if self.mode == "delta" else None)
        if self.mode == "delta" and batch.n_frames:
            self._last_sent = batch.take(np.array([batch.n_frames - 1]))
        self._sent_t_s = batch.t_s.astype(np.float64, copy=True)
        for pos in range(batch.n_frames):  # frames go out one by one, at their own time
            keyframe = changed is None or self._frames_sent % self.keyframe_every == 0
            entries = frame_entries(batch, pos, None if keyframe else changed)
            datagrams = encode_frame(
                entries, kind=KIND_FULL if keyframe else KIND_DELTA,
                frame=int(batch.frame_index[pos]), t_s=float(batch.t_s[pos]),
                first_sequence=self._sequence)
            late = 0.0
            if self.pacing == "realtime":
                late = self._wait_for(float(batch.t_s[pos]))
            self._transmitted_s = None
            for datagram in datagrams:
                self.send(datagram)
            self._sent_frame_t_s = float(batch.t_s[pos])
            if self.pacing == "realtime" and self._transmitted_s is not None \
                    and self._frames_sent == 0:
                self._restart_at(self._transmitted_s)
                late = 0.0
            if self.pacing == "realtime" and self._transmitted_s is not None:
                # The frame is out with its last datagram: a host that holds the sender
                # between its wake-up and that datagram delays the frame as much. (Read as
                # the datagram goes: once it is out, the receiver it wakes may hold the
                # sender a while, which delays nothing.)
                self._sent_t_s[pos] += max(late, self._late_s(float(batch.t_s[pos]),
                                                              self._transmitted_s))
            self._sequence += len(datagrams)
            self.datagrams_sent += len(datagrams)
            self.entries_sent += entries.size
            self._frames_sent += 1
            if self._frames_sent % STATUS_DRAIN_FRAMES == 0:
                self.rts_status()  # the socket's buffer holds a few hundred replies at most

    def _check_forward(self, batch: Schedule) -> None:
        """Refuse frame numbers that do not go forward: the RTS would drop them as stale."""
        if not batch.n_frames:
            return
        index = batch.frame_index.astype(np.int64)
        steps = np.diff(np.r_[self._last_frame_index, index])
        if (steps <= 0).any():
            at = int(np.flatnonzero(steps <= 0)[0])
            before = self._last_frame_index if at == 0 else int(index[at - 1])
            raise OutputError(
                f"udp: frame {int(index[at])} after frame {before}: a stream's frames go "
                f"forward (the RTS drops a frame older than one it applied); a batch of a scene "
                f"keeps the scene's frame numbers: build_schedule(..., frame_index=...)")
        self._last_frame_index = int(index[-1])

    @staticmethod
    def _check_fits(batch: Schedule) -> None:
        """Refuse a batch the protocol's fields cannot number (they would wrap silently)."""
        limits = [("targets", batch.active.shape[1], "target", "u16", MAX_TARGETS)]
        if batch.n_frames:
            limits.append(("frame index", int(batch.frame_index.max()) + 1, "frame", "u32",
                           MAX_FRAMES))
        fe = batch.fe[batch.active]
        if fe.size:
            limits.append(("FE index", int(fe.max()) + 1, "fe", "i16", MAX_FRONT_ENDS))
        for what, count, name, kind, limit in limits:
            if count > limit:
                shown = f"{count} {what}" if what == "targets" else f"{what} {count - 1}"
                raise OutputError(f"udp: {shown}: the stream's `{name}` field ({kind}) numbers "
                                  f"at most {limit} {what.split()[0]}s (0..{limit - 1}; "
                                  f"docs/udp-protocol.md)")

    def sent_t_s(self, batch: Schedule) -> np.ndarray:
        """Return when the frames of ``batch`` went out, in scene time (see `Output.sent_t_s`).

        Paced in real time: each frame's time plus how late it went out (the first frame sets
        the scene's origin). Not paced (``fast``): the frames' times (an
        RTS that buffers the stream plays it by the times in its headers).
        """
        if self._sent_t_s.size != batch.n_frames:
            raise OutputError(f"udp: sent_t_s of a batch of {batch.n_frames} frames, the last "
                              f"written had {self._sent_t_s.size}")
        return self._sent_t_s

    def rts_status(self, settle_s: float = 0.0) -> dict[str, int] | None:
        """Return the RTS's latest status reply (docs/udp-protocol.md), None without any.

        Replies are read off the socket; anything that is not a valid status datagram is
        ignored. ``settle_s``: at the end of a stream, wait up to this long for the reply to
        the last datagram sent. A frame the RTS has not applied by then (``frames_applied``
        against the frames sent) counts as lost, whatever its own count says: a frame whose
        last datagram was lost stays pending in the RTS for ever.
        """
        deadline = time.perf_counter() + settle_s
        while True:
            self._read_replies()
            status = self._rts_status
            if status is None and settle_s == 0.0:
                return None
            # Done early only where the counters account for every frame sent: a reply that
            # counts as many datagrams as were sent need not be the last one's (the RTS also
            # counts a corrupted copy, another's late datagram), so with frames still
            # unaccounted for the last reply is waited for until the deadline.
            if (status is not None and status.get("datagrams", 0) >= self.datagrams_sent
                    and status.get("frames_applied", 0) + status.get("unsynced_frames", 0)
                    >= self._frames_sent) or time.perf_counter() >= deadline:
                break
            time.sleep(0.002)
        if status is None or settle_s == 0.0:
            return status
        out = dict(status)
        unplayed = self._frames_sent - out.get("frames_applied", 0) - out.get("unsynced_frames", 0)
        if unplayed > out.get("lost_frames", 0):
            # The sender's count, not the RTS's: frames its last reply does not account for.
            out["unaccounted_frames"] = unplayed - out.get("lost_frames", 0)
        out["lost_frames"] = max(out.get("lost_frames", 0), unplayed)
        # Counters are per stream: more valid datagrams than this run sent are another
        # sender's stream's (a second run against the RTS took it over), not this run's. Copies
        # and datagrams the RTS could not read (a copy corrupted on the way) are no one's.
        foreign = (out.get("datagrams", 0) - out.get("duplicates", 0) - out.get("corrupted", 0)
                   - out.get("malformed", 0) - self.datagrams_sent)
        if foreign > 0:
            out["foreign_datagrams"] = foreign
        return out

    def rts_rig(self) -> tuple[int, bytes] | None:
        """Return the FE count and geometry digest the RTS said it plays, None if it did not.

        Read with the status replies (`rts_status`).
        """
        self._read_replies()
        return self._rts_rig

    def rts_unreachable(self) -> dict[str, Any] | None:
        """Return what the network said of datagrams nothing received, None where it said nothing.

        ``address``; ``datagrams``: how many came back as ICMP errors (a host answers a
        limited number per second, except on the loopback: at least this many);
        ``error``: the most frequent (``Connection refused``: nothing listens on the port);
        ``first_s``, ``last_s``: the scene times of the last frames sent when the first and the
        last were told (their datagrams went out with them or a little before). Linux only:
        elsewhere an unconnected socket is told nothing, and this is None.
        """
        self._read_replies()
        if not self._refused:
            return None
        most = max(self._refused, key=lambda e: self._refused[e])
        return {"address": f"{self.address[0]}:{self.address[1]}",
                "datagrams": sum(self._refused.values()), "error": os.strerror(most),
                "first_s": self._refused_s[0], "last_s": self._refused_s[-1]}

    def _take_errors(self) -> int:
        """Take the errors waiting on the socket's error queue (see `_RECVERR`); their number.

        Those of datagrams nothing received are counted (`rts_unreachable`); others (a path
        whose MTU is smaller than a datagram) only taken off.
        """
        taken = 0
        while self._error_queue:
            try:
                _, ancillary, _, _ = self._socket.recvmsg(1, 512, _MSG_ERRQUEUE | _MSG_DONTWAIT)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:  # nothing queued after all, or a kernel without the queue
                break
            taken += 1
            for _level, _kind, data in ancillary:
                code = _EXTENDED_ERR.unpack_from(data)[0] if len(data) >= _EXTENDED_ERR.size \
                    else 0
                if code in _ICMP_ERRORS:
                    self._refused[code] = self._refused.get(code, 0) + 1
                    # The datagram went out with this frame or before it.
                    at = self._sent_frame_t_s if self._sent_frame_t_s is not None else 0.0
                    if not self._refused_s:
                        self._refused_s.append(at)
                    self._refused_s[1:] = [at]
        return taken

    def _read_replies(self) -> None:
        """Take every status reply waiting on the socket (the last valid one is kept)."""
        self._take_errors()
        self._socket.setblocking(False)
        try:
            while True:
                try:
                    data = self._socket.recv(65536)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError as exc:  # an earlier datagram's error: counted, read on
                    if exc.errno in (errno.EBADF, errno.ENOTSOCK):  # closed: nothing to read
                        break
                    self._take_errors()
                    continue
                status = decode_status(data)
                if status is not None:
                    self._rts_status = status
                elif (rig := decode_rig_reply(data)) is not None:
                    self._rts_rig = rig
        finally:
            self._socket.setblocking(True)

    def _restart_at(self, at: float) -> None:
        """Start the scene at perf_counter time ``at``: when its first frame went out.

        The RTS (and the radar it starts) begin with that frame's datagram, not with the
        sender's wake-up before it (a loaded host may hold the sender between the two).
        """
        assert self._start is not None
        held = at - self._start
        if held > 0.0:
            self._start = at
            assert self.scene_origin_monotonic_s is not None
            assert self.scene_origin_wall_s is not None
            self.scene_origin_monotonic_s += held
            self.scene_origin_wall_s += held

    def _late_s(self, t_s: float, at: float) -> float:
        """How late perf_counter time ``at`` is for scene time ``t_s`` of the paced stream (s)."""
        assert self._start is not None
        return at - self._start - (t_s - self._t0)

    def _wait_for(self, t_s: float) -> float:
        """Wait until scene time ``t_s``; return how late that is (s)."""
        now = time.perf_counter()
        if self._start is None:
            self._start, self._t0 = now, t_s
            # The bus's clock (python-can stamps messages with time.time()) at scene time 0.
            self.scene_origin_monotonic_s = monotonic_s() - t_s
            self.scene_origin_wall_s = wall_s() - t_s
        due = self._start + (t_s - self._t0)
        # Sleep most of the way, then spin: sleep alone overshoots by up to a few ms.
        if due - now > 0.002:
            time.sleep(due - now - 0.002)
        while (now := time.perf_counter()) < due:
            pass
        return now - due

    def _close(self) -> None:
        self._socket.close()


def _enable_icmp_errors(sock: socket.socket, family: int) -> bool:
    """Have the kernel queue the ICMP errors of ``sock``'s datagrams (Linux; see `_RECVERR`)."""
    if sys.platform != "linux" or family not in _RECVERR:
        return False
    try:
        sock.setsockopt(*_RECVERR[family], 1)
    except OSError:
        return False
    return True


def _resolve(host: str, port: int) -> tuple[Any, ...]:
    """``getaddrinfo``'s first datagram address of ``host``: IPv4 first unless it is IPv6."""
    families = [socket.AF_INET6] if ":" in host else [socket.AF_INET, socket.AF_UNSPEC]
    for family in families[:-1]:
        with contextlib.suppress(socket.gaierror):
            return socket.getaddrinfo(host, port, family, socket.SOCK_DGRAM)[0]
    return socket.getaddrinfo(host, port, families[-1], socket.SOCK_DGRAM)[0]


def encode_status(counters: dict[str, int]) -> bytes:
    """Return the status datagram carrying an RTS's ``counters`` (`STATUS_COUNTERS`)."""
    body = STATUS.pack(STATUS_MAGIC, VERSION,
                       *(min(max(int(counters.get(k, 0)), 0), 0xFFFFFFFF)
                         for k in STATUS_COUNTERS))
    return body + TRAILER.pack(zlib.crc32(body))


def encode_rig_reply(n_front_ends: int, digest: bytes) -> bytes:
    """Return the rig datagram of an RTS with ``n_front_ends`` FEs of geometry ``digest``."""
    body = RIG_REPLY.pack(RIG_MAGIC, VERSION, n_front_ends, digest)
    return body + TRAILER.pack(zlib.crc32(body))


def decode_rig_reply(datagram: bytes) -> tuple[int, bytes] | None:
    """Return the FE count and geometry digest of a rig datagram; None if it is not one."""
    if len(datagram) != RIG_REPLY.size + TRAILER.size:
        return None
    body, (crc,) = datagram[:RIG_REPLY.size], TRAILER.unpack(datagram[RIG_REPLY.size:])
    if zlib.crc32(body) != crc:
        return None
    magic, version, n_front_ends, digest = RIG_REPLY.unpack(body)
    if magic != RIG_MAGIC or version != VERSION:
        return None
    return int(n_front_ends), bytes(digest)


def decode_status(datagram: bytes) -> dict[str, int] | None:
    """Return the counters of a status datagram; None if it is not a valid one."""
    if len(datagram) != STATUS.size + TRAILER.size:
        return None
    body, (crc,) = datagram[:STATUS.size], TRAILER.unpack(datagram[STATUS.size:])
    if zlib.crc32(body) != crc:
        return None
    magic, version, *values = STATUS.unpack(body)
    if magic != STATUS_MAGIC or version != VERSION:
        return None
    return dict(zip(STATUS_COUNTERS, values, strict=True))


@dataclass
class ReceiverStats:
    """What the reference receiver saw."""

    datagrams: int = 0
    corrupted: int = 0
    malformed: int = 0
    duplicates: int = 0
    reordered: int = 0
    stale: int = 0
    frames_applied: int = 0
    entries_applied: int = 0
    lost_datagrams: int = 0
    # Frames not applied: none of whose datagrams came, or not all (``lost_frames``), or
    # one that came after a newer frame was applied (``stale_frames``: reordered, late).
    lost_frames: int = 0
    stale_frames: int = 0
    unsynced_frames: int = 0
    # Of the malformed: entries naming FEs the RTS's rig lacks or that make none of its quads
    # (a run on another rig); not in the status reply (counted there as malformed).
    other_rig: int = 0

    @property
    def clean(self) -> bool:
        """No loss, reordering, duplication, corruption or malformed data."""
        return not (self.corrupted or self.malformed or self.duplicates or self.reordered
                    or self.stale or self.lost_datagrams or self.lost_frames
                    or self.stale_frames or self.unsynced_frames)


# The socket option that stamps each datagram with its arrival (Linux; elsewhere a datagram
# is stamped when it is read).
# Python names no such option; Linux's (asm-generic) value is 35 on the common machines.
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35 if sys.platform == "linux" and (
    platform.machine() in ("x86_64", "i386", "i686", "aarch64", "riscv64", "ppc64le", "s390x")
    or platform.machine().startswith("arm")) else None)
TIMESPEC = struct.Struct("@ll")  # struct timespec: seconds, nanoseconds


def _enable_receive_stamps(sock: socket.socket) -> bool:
    """Ask the kernel to stamp each datagram ``sock`` receives; whether it will."""
    if SO_TIMESTAMPNS is None or not hasattr(sock, "recvmsg"):
        return False
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    except OSError:
        return False
    return True


class UdpReceiver:
    """Reference RTS endpoint: validates, reassembles and applies schedule datagrams.

    Nothing that fails validation is applied; frames are applied complete and in order (a
    datagram of a frame older than one already applied is stale and dropped; a delta after a
    gap waits for the next full frame). `state` holds the applied entry of every
    ``(target, channel)``. One stream at a time: a new sender's first datagram starts the
    next (`handle`), so one receiver serves run after run. Memory does not grow with the
    length of the stream: only with
    ``keep_applied`` does the receiver keep every applied frame (``applied``: frame, scene
    time, entries) and its arrival (``arrival_s``), for a consumer that takes them as they
    come (``rts-listen``) or a test.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 0, *,
                 keep_applied: bool = False, n_front_ends: int | None = None,
                 quads: NDArray[np.integer] | None = None,
                 rig_digest: bytes | None = None) -> None:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._socket = socket.socket(family, socket.SOCK_DGRAM)
        self._socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
        self._socket.bind((host, port))
        # Read without blocking (`poll`): the receiving thread waits for datagrams with
        # `select`, and any thread may take those waiting.
        self._socket.setblocking(False)
        # Each datagram keeps when it reached the socket (the kernel's receive time), not
        # when a thread got round to it: a loaded host wakes the receiving thread late, while
        # an RTS applies a frame as it arrives.
        self._stamped = _enable_receive_stamps(self._socket)
        # One reader at a time takes datagrams off the socket and handles them, in order.
        self._reading = threading.Lock()
        self.address: tuple[str, int] = self._socket.getsockname()[:2]
        self._closed = False
        self.keep_applied = keep_applied
        # The FEs of the rig this RTS plays through, where known: an emitting entry must name
        # one of them (0 .. n_front_ends - 1).
        self.n_front_ends = n_front_ends
        # Its quads' FEs in the paper's channel order (Q, 4), where known: a target's emitting
        # channels must name FEs of one of them, each on its own channel.
        self.quads = None if quads is None else np.asarray(quads, dtype=np.int64).reshape(-1, 4)
        # Its rig's geometry digest (`Rig.geometry_digest`), where known: told to each sender
        # with the status replies, so a run on another rig fails.
        self.rig_digest = rig_digest
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        # The receiving thread applies frames while others read the state (`snapshot`).
        self._lock = threading.Lock()
        # Streams begun so far (a new sender's first datagram starts one) and the current
        # one's sender.
        self.streams = 0
        self._sender: tuple[str, int] | None = None
        self._last_datagram_s = -np.inf  # perf_counter time of the last datagram
        # Called with a stream's number and its final counters when the next one begins (in
        # the receiving thread, under the state's lock: keep it short). The last stream's are
        # `stop`'s.
        self.on_stream_end: Callable[[int, ReceiverStats], None] | None = None
        # Applied frames for a consumer (``keep_applied``), of every stream in turn.
        self.applied: deque[tuple[int, float, np.ndarray]] = deque()
        self.arrival_s: deque[float] = deque()
        self._new_stream()

    def _new_stream(self) -> None:
        """Forget the stream before: its frames, sequence numbers, state and counters."""
        self.stats = ReceiverStats()
        self._table = np.zeros((0, 4), dtype=ENTRY)
        self._live = np.zeros((0, 4), dtype=bool)
        # Sequence numbers within `SEQUENCE_WINDOW` of the newest, and how many were ever new.
        self._seen: set[int] = set()
        self._unique = 0
        self._max_sequence = -1
        self._min_sequence: int | None = None
        # Frames not applied of which a datagram came after a newer frame was (the newest
        # `SEQUENCE_WINDOW` of them: each is counted once).
        self._stale_frames: set[int] = set()
        self._pending: dict[int, dict[int, np.ndarray]] = {}
        self._pending_meta: dict[int, tuple[int, int, float]] = {}
        self._last_frame = -1
        self._first_frame: int | None = None
        self._top_frame = -1
        self._synced = True
        self.current: tuple[int, float, float] | None = None  # frame, t_s, arrival (perf)
        # The stream's first frame applied: frame, t_s, arrival (perf).
        self.first: tuple[int, float, float] | None = None
        # The last `STATE_HISTORY` states applied: arrival (perf), frame, t_s, entries held.
        self._states: deque[tuple[float, int, float, np.ndarray]] = deque(maxlen=STATE_HISTORY)

    def snapshot(self, at: float | None = None) -> tuple[int, float, float, np.ndarray] | None:
        """Return the frame applied last, its scene time and arrival, and the entries it holds.

        ``at`` (a `time.perf_counter` time): the frame applied last at or before it, as the
        state held then (a reader that looks later than it meant to, e.g. a radar whose thread
        woke late, sees what was held at its moment); the oldest state kept if all came after.
        Consistent while the receiving thread applies frames (None before the first frame, or
        where ``at`` is before it).
        """
        with self._lock:
            if self.current is None:
                return None
            if at is None:
                frame, t_s, arrival = self.current
                return frame, t_s, arrival, self._table[self._live].copy()
            states = self._states
            if at < states[0][0] and self.stats.frames_applied <= len(states):
                return None  # before the stream's first frame
            arrivals = [s[0] for s in states]
            k = max(0, int(np.searchsorted(arrivals, at, side="right")) - 1)
            arrival, frame, t_s, entries = states[k]
            return frame, t_s, arrival, entries.copy()

    def start(self) -> UdpReceiver:
        """Receive in a background thread until `stop`."""
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        return self

    def stop(self, drain_s: float = 0.2) -> ReceiverStats:
        """Stop receiving (after ``drain_s`` of quiet), close and count what never arrived."""
        if self._thread is not None:
            deadline = time.perf_counter() + drain_s
            received = self.stats.datagrams
            while time.perf_counter() < deadline:
                time.sleep(0.02)
                if self.stats.datagrams != received:
                    received = self.stats.datagrams
                    deadline = time.perf_counter() + drain_s
            self._stop.set()
            self._thread.join()
            self._thread = None
        if not self._closed:
            self._closed = True
            self._socket.close()
            self._finish()
        return self.stats

    @property
    def state(self) -> np.ndarray:
        """Applied entries of every active ``(target, channel)`` (structured array)."""
        return self._table[self._live]

    def __enter__(self) -> UdpReceiver:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop(drain_s=0.0)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self._socket], [], [], 0.02)
            except (OSError, ValueError):  # closed
                break
            if ready and not self.poll():
                break

    def poll(self) -> bool:
        """Handle every datagram waiting on the socket now, each as of when it arrived.

        Called by the receiving thread as datagrams come, and by a reader of the state that
        must see every frame that arrived before a moment (`snapshot` at it), whichever
        thread the host runs first. Returns False once the socket is closed.
        """
        with self._reading:
            while True:
                try:
                    datagram, sender, arrival = self._receive()
                except (BlockingIOError, InterruptedError):
                    return True
                except ConnectionRefusedError:  # a status reply's sender is gone
                    continue
                except OSError:
                    return False
                self.handle(datagram, sender, arrival_s=arrival)
                self._reply(sender)

    def _receive(self) -> tuple[bytes, tuple[str, int], float]:
        """Take one datagram off the socket: its bytes, sender and arrival (perf_counter)."""
        if not self._stamped:
            datagram, sender = self._socket.recvfrom(65536)
            return datagram, sender, time.perf_counter()
        datagram, ancillary, _, sender = self._socket.recvmsg(65536, 256)
        now = time.perf_counter()
        arrival = now
        for level, kind, data in ancillary:
            if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS \
                    and len(data) >= TIMESPEC.size:
                sec, nsec = TIMESPEC.unpack(data[:TIMESPEC.size])
                # The kernel stamps on the wall clock: how long ago it arrived, on the
                # perf_counter clock (a wall clock stepped in between: taken as just now).
                ago = time.clock_gettime(time.CLOCK_REALTIME) - (sec + nsec * 1e-9)
                if 0.0 <= ago < 1.0:
                    arrival = now - ago
        return datagram, sender, arrival

    def _reply(self, sender: tuple[str, int]) -> None:
        """Tell the sender what this RTS has received and applied so far (a status datagram).

        A UDP sender cannot see loss; these replies let it report lost frames. A sender that
        does not read them loses nothing.
        """
        try:
            self._socket.sendto(encode_status(self.status_counters()), sender)
            if self.rig_digest is not None and self.n_front_ends is not None \
                    and self.stats.datagrams % RIG_REPLY_EVERY == 1:
                self._socket.sendto(encode_rig_reply(self.n_front_ends, self.rig_digest),
                                    sender)
        except OSError:
            pass

    def status_counters(self) -> dict[str, int]:
        """Return the counters a status reply carries (docs/udp-protocol.md).

        Version 1's ``lost_frames`` is every frame not applied (between the first and the last
        seen, nor being assembled): lost on the way or come too late (`ReceiverStats`'
        ``lost_frames`` and ``stale_frames``), which it does not tell apart.
        """
        counters = dict(vars(self.stats))
        counters["lost_frames"] = self._lost_frames_now() + self.stats.stale_frames
        return counters

    def _lost_frames_now(self, pending: int | None = None) -> int:
        """Frames lost so far: between the first and last seen, none applied, pending or late.

        Late: a datagram came after a newer frame was applied (``stale_frames``). Frames are
        applied in order, each once, so counting them is enough. ``pending``: the frames taken
        as still being assembled (default: those that are).
        """
        if self._first_frame is None:
            return 0
        span = self._top_frame - self._first_frame + 1
        return max(0, span - self.stats.frames_applied - self.stats.unsynced_frames
                   - self.stats.stale_frames
                   - (len(self._pending) if pending is None else pending))

    def handle(self, datagram: bytes, sender: tuple[str, int] | None = None, *,
               arrival_s: float | None = None) -> None:
        """Validate and process one datagram (from ``sender``, where known).

        ``arrival_s``: when it arrived (`time.perf_counter` time; default now): a frame is
        applied as its last datagram arrived.

        Each run opens a stream from a sender of its own: a datagram from another sender
        than the current stream's that opens a stream (the first datagram of a full frame,
        sequence 0) starts a new one, and the stream before is forgotten (its frames, state
        and counters). Any other datagram from another sender is the stream before's, late:
        counted as stale and dropped. After `STREAM_QUIET_S` without a datagram, a stream's
        first datagram opens a new one from the same sender too (the next run's socket may
        get the same port), and another sender's first datagram of any full frame opens one
        (the next run's very first datagram may be lost).
        """
        now = time.perf_counter() if arrival_s is None else arrival_s
        quiet = now - self._last_datagram_s > STREAM_QUIET_S
        self._last_datagram_s = now
        if sender is not None and (sender != self._sender or quiet):
            # The same sender again opens a stream only with sequence 0 (its socket was
            # opened again): a slow stream may be quiet between its own frames.
            first = self._opens_stream(datagram, any_sequence=quiet and sender != self._sender)
            if self._sender is None or first:
                with self._lock:
                    if self._sender is not None:
                        self._finish()
                        if self.on_stream_end is not None:
                            self.on_stream_end(self.streams, self.stats)
                        self._new_stream()
                    self._sender = sender
                    self.streams += 1
            elif sender != self._sender:
                self.stats.datagrams += 1
                self.stats.stale += 1
                return
        stats = self.stats
        stats.datagrams += 1
        if len(datagram) < HEADER.size + TRAILER.size:
            stats.malformed += 1
            return
        body, (crc,) = datagram[:-TRAILER.size], TRAILER.unpack(datagram[-TRAILER.size:])
        if zlib.crc32(body) != crc:
            stats.corrupted += 1
            return
        magic, version, kind, seq, frame, part, parts, t_s, count = HEADER.unpack(
            body[:HEADER.size])
        if (magic != MAGIC or version != VERSION or kind not in (KIND_FULL, KIND_DELTA)
                or part >= parts or len(body) != HEADER.size + count * ENTRY.itemsize):
            stats.malformed += 1
            return
        entries = np.frombuffer(body, dtype=ENTRY, offset=HEADER.size, count=count)
        seq = self._unwrap(seq)
        if int(entries["channel"].max(initial=0)) > 3:
            stats.malformed += 1
            return
        if not self._on_this_rig(entries):
            stats.malformed += 1
            stats.other_rig += 1
            return
        if self._pending_meta.get(frame, (kind, parts, t_s)) != (kind, parts, t_s):
            # A part of a frame whose other parts came with another kind, part count or time.
            stats.malformed += 1
            return
        if seq <= self._max_sequence - SEQUENCE_WINDOW:
            # Too old to tell from a copy (the last SEQUENCE_WINDOW numbers are remembered,
            # the newest's among them): its frame was applied or given up long ago.
            stats.stale += 1
            return
        if seq in self._seen:
            stats.duplicates += 1
            return
        if seq < self._max_sequence:
            stats.reordered += 1
        self._seen.add(seq)
        self._unique += 1
        if seq > self._max_sequence:
            self._max_sequence = seq
            if len(self._seen) > 2 * SEQUENCE_WINDOW:
                oldest = seq - SEQUENCE_WINDOW
                self._seen = {s for s in self._seen if s > oldest}
        self._min_sequence = seq if self._min_sequence is None else min(self._min_sequence, seq)
        self._first_frame = frame if self._first_frame is None else min(self._first_frame, frame)
        self._top_frame = max(self._top_frame, frame)
        if frame <= self._last_frame:
            # A frame applied (or given up as unsynced) came whole, so a copy of its datagrams
            # is a duplicate: this one's frame was not applied, and came late.
            stats.stale += 1
            if frame not in self._stale_frames:
                self._stale_frames.add(frame)
                stats.stale_frames += 1
                if len(self._stale_frames) > 2 * SEQUENCE_WINDOW:
                    oldest = self._top_frame - SEQUENCE_WINDOW
                    self._stale_frames = {f for f in self._stale_frames if f >= oldest}
            return
        self._pending.setdefault(frame, {})[part] = entries
        self._pending_meta[frame] = (kind, parts, t_s)
        if len(self._pending[frame]) == parts:
            self._apply(frame, now)

    def _unwrap(self, seq: int) -> int:
        """Return ``seq`` (modulo 2^32) as the stream's count: the nearest to the newest.

        The sender's ``sequence`` wraps at 2^32; a datagram up to 2^31 before or after the
        newest one is taken as that far from it (serial number arithmetic, RFC 1982).
        """
        if self._max_sequence < 0:
            return seq
        ahead = (seq - self._max_sequence + SEQUENCE_MODULUS // 2) % SEQUENCE_MODULUS
        return self._max_sequence + ahead - SEQUENCE_MODULUS // 2

    def _on_this_rig(self, entries: np.ndarray) -> bool:
        """Whether every emitting entry names an FE of this RTS's rig, on a quad of it.

        Channels are 0..3 (checked before). The FE must be one of the rig's where the receiver
        knows it (``n_front_ends``): a sender whose rig has more FEs than this RTS's is
        refused, not played on other FEs. Where it knows the rig's quads, each target's
        emitting channels must name FEs of one quad (on any of its channels: a test pattern
        plays one FE, or a pair of a quad, from channel 0 on): a sender whose rig has as many
        FEs laid out otherwise is refused too.
        """
        on = (entries["flags"] & 1).astype(bool)
        fe = entries["fe"][on].astype(np.int64)
        if fe.size == 0:
            return True
        if int(fe.min()) < 0 or (self.n_front_ends is not None
                                 and int(fe.max()) >= self.n_front_ends):
            return False
        if self.quads is None:
            return True
        target = entries["target"][on].astype(np.int64)
        # fits[e, q]: entry e's FE is one of quad q's; a target must fit one quad with all
        # its entries.
        fits = (self.quads[None, :, :] == fe[:, None, None]).any(axis=2)
        order = np.argsort(target, kind="stable")
        target, fits = target[order], fits[order]
        starts = np.flatnonzero(np.r_[True, target[1:] != target[:-1]])
        return bool(np.logical_and.reduceat(fits, starts, axis=0).any(axis=1).all())

    @staticmethod
    def _opens_stream(datagram: bytes, any_sequence: bool = False) -> bool:
        """Whether a datagram can open a stream: valid, a full frame's first datagram.

        Sequence 0 (a stream's very first), or any with ``any_sequence``.
        """
        if len(datagram) < HEADER.size + TRAILER.size:
            return False
        body, (crc,) = datagram[:-TRAILER.size], TRAILER.unpack(datagram[-TRAILER.size:])
        if zlib.crc32(body) != crc:
            return False
        magic, version, kind, seq, _, part, _, _, _ = HEADER.unpack(body[:HEADER.size])
        return magic == MAGIC and version == VERSION and kind == KIND_FULL \
            and (seq == 0 or any_sequence) and part == 0

    def _apply(self, frame: int, arrival: float) -> None:
        with self._lock:
            self._apply_locked(frame, arrival)

    def _apply_locked(self, frame: int, arrival: float) -> None:
        kind, parts, t_s = self._pending_meta.pop(frame)
        chunks = self._pending.pop(frame)
        entries = np.concatenate([chunks[p] for p in range(parts)])
        # Older incomplete frames can no longer be applied in order.
        for old in [f for f in self._pending if f < frame]:
            del self._pending[old]
            del self._pending_meta[old]
        if kind == KIND_DELTA and (not self._synced or frame != self._last_frame + 1):
            self._synced = False
            self.stats.unsynced_frames += 1
            self._last_frame = frame
            return
        if kind == KIND_FULL:
            self._live[:] = False
            self._synced = True
        target, channel = entries["target"].astype(np.int64), entries["channel"].astype(np.int64)
        if target.size and target.max() >= len(self._table):
            grow = int(target.max()) + 1 - len(self._table)
            self._table = np.concatenate([self._table, np.zeros((grow, 4), dtype=ENTRY)])
            self._live = np.concatenate([self._live, np.zeros((grow, 4), dtype=bool)])
        on = (entries["flags"] & 1).astype(bool)
        self._table[target[on], channel[on]] = entries[on]
        self._live[target, channel] = on
        self._last_frame = frame
        # States stay in order of arrival (`snapshot` searches them).
        if self._states:
            arrival = max(arrival, self._states[-1][0])
        self.current = (frame, t_s, arrival)
        if self.first is None:
            self.first = self.current
        self._states.append((arrival, frame, t_s, self._table[self._live].copy()))
        if self.keep_applied:
            self.applied.append((frame, t_s, entries))
            self.arrival_s.append(arrival)
        self.stats.frames_applied += 1
        self.stats.entries_applied += entries.size

    def _finish(self) -> None:
        stats = self.stats
        if self._min_sequence is not None:
            stats.lost_datagrams = (self._max_sequence - self._min_sequence + 1) - self._unique
        # A frame still being assembled when the stream ends is lost too.
        stats.lost_frames = self._lost_frames_now(pending=0)


class FaultInjector:
    """Test tool: a ``send`` hook for `UdpOutput` that drops, duplicates, reorders or corrupts.

    Probabilities are per datagram; ``rng`` makes runs repeatable. ``log`` counts what was done.
    """

    def __init__(self, send: Callable[[bytes], None], rng: np.random.Generator, *,
                 drop: float = 0.0, duplicate: float = 0.0, reorder: float = 0.0,
                 corrupt: float = 0.0) -> None:
        self._send = send
        self._rng = rng
        self.p = {"drop": drop, "duplicate": duplicate, "reorder": reorder, "corrupt": corrupt}
        self.log = dict.fromkeys(self.p, 0)
        self._held: bytes | None = None

    def __call__(self, datagram: bytes) -> None:
        """Pass ``datagram`` on, or not, as the dice say."""
        roll = self._rng.random(4)
        if roll[0] < self.p["drop"]:
            self.log["drop"] += 1
            return
        if roll[3] < self.p["corrupt"]:
            self.log["corrupt"] += 1
            data = bytearray(datagram)
            data[int(self._rng.integers(len(data)))] ^= 1 << int(self._rng.integers(8))
            datagram = bytes(data)
        if self._held is None and roll[2] < self.p["reorder"]:
            self.log["reorder"] += 1
            self._held = datagram
            return
        self._send(datagram)
        if roll[1] < self.p["duplicate"]:
            self.log["duplicate"] += 1
            self._send(datagram)
        if self._held is not None:
            held, self._held = self._held, None
            self._send(held)

    def flush(self) -> None:
        """Send a datagram still held back for reordering."""
        if self._held is not None:
            held, self._held = self._held, None
            self._send(held)
