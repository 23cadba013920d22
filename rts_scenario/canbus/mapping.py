"""What a radar's CAN messages mean: a DBC plus a mapping file.

A mapping (``*.mapping.yaml``) names, in the DBC, the frame header message (cycle counter and
detection count) and the detection message(s), and which signal carries which quantity, in
polar form (range, azimuth, elevation) or cartesian form (distance long/lat/up, relative
velocity long/lat). Signals are read through the DBC's own scaling; ``scale``/``offset`` per
quantity convert further units (e.g. km/h). rts-scenario's own messages use the same mechanism
(``rts_scenario/data/can/rts_detections.mapping.yaml``). docs/can-mapping.md describes the file.

A detection is carried by *parts*: each detection message, or each multiplexer page of a
multiplexed one. The parts that carry a mapped quantity are the ones a detection needs; the
others (an extended-information page the mapping does not read) are sent by the simulated radar
as the protocol has them and skipped by the receiver.
"""

from __future__ import annotations

import hashlib
import logging
import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Any, NamedTuple

import cantools

from ..detections import SMALLEST_COUNTER_MODULUS
from ..file_kinds import load_kind
from ..located_yaml import Document, format_key_path, load_yaml, validate

QUANTITIES = ("range_m", "azimuth_deg", "elevation_deg", "radial_velocity_mps", "x_m", "y_m",
              "z_m", "vx_mps", "vy_mps", "rcs_dbsm", "snr_db")
# The quantities the checker checks (polar names), as a reason names them (`not_carried`).
_CHECKED_WORDS = {"range_m": "range", "radial_velocity_mps": "radial velocity",
                  "azimuth_deg": "azimuth", "elevation_deg": "elevation", "rcs_dbsm": "RCS"}

# Classic messages per detection (a radar's general, quality and extended-information messages).
MAX_MESSAGES = 8
# The most bytes a classic CAN message carries (a CAN FD message, up to 64).
CLASSIC_BYTES = 8
# Why a cycle counter takes `SMALLEST_COUNTER_MODULUS` values at least.
_TOO_FEW_VALUES = ("with fewer, the header after one lost cycle cannot be told from a copy of a "
                   "cycle before")

_SIGNAL: dict[str, Any] = {
    "oneOf": [
        {"type": "string"},
        {"type": "object", "additionalProperties": False, "required": ["signal"],
         "properties": {"signal": {"type": "string"}, "scale": {"type": "number"},
                        "offset": {"type": "number"}}},
    ]
}

# The header's measurement time: a signal in seconds, or {signal, scale} (seconds per unit of
# the signal's DBC value, e.g. 0.001 for ms). No offset: the radar's time starts where it will.
_TIMESTAMP: dict[str, Any] = {
    "oneOf": [
        {"type": "string"},
        {"type": "object", "additionalProperties": False, "required": ["signal"],
         "properties": {"signal": {"type": "string"},
                        "scale": {"type": "number", "exclusiveMinimum": 0}}},
    ]
}

# Checksum schemes: rts-scenario's own (the low byte of the CRC-32 of the other bytes, the
# default), CRC-8 SAE J1850 of the other bytes, AUTOSAR E2E profiles 2 and 5 (with a data ID).
CHECKSUM_SCHEMES = ("crc32-low-byte", "crc8-sae-j1850", "autosar-e2e-p2", "autosar-e2e-p5")
DEFAULT_CHECKSUM_SCHEME = "crc32-low-byte"
# The data ID a scheme takes: its largest value, and whether a list of 16 (one per value of the
# counter in byte 1's low nibble, profile 2's DataIDList) is allowed.
_DATA_ID = {"autosar-e2e-p2": (0xFF, True), "autosar-e2e-p5": (0xFFFF, False)}

_DATA_ID_VALUE: dict[str, Any] = {
    "oneOf": [
        {"type": "integer", "minimum": 0, "maximum": 0xFFFF},
        {"type": "array", "minItems": 16, "maxItems": 16,
         "items": {"type": "integer", "minimum": 0, "maximum": 0xFF}},
    ]
}

_CHECKSUM: dict[str, Any] = {
    "oneOf": [
        {"type": "string"},
        {"type": "object", "additionalProperties": False, "required": ["signal"],
         "properties": {"signal": {"type": "string"}, "scheme": {"enum": list(CHECKSUM_SCHEMES)},
                        "data_id": {"oneOf": [
                            *_DATA_ID_VALUE["oneOf"],
                            {"type": "object", "minProperties": 1,
                             "additionalProperties": _DATA_ID_VALUE}]}}},
    ]
}

MAPPING_SCHEMA: dict[str, Any] = {
    "type": "object",
    "additionalProperties": False,
    "required": ["rts_can_mapping", "name", "dbc", "header", "detection"],
    "properties": {
        "rts_can_mapping": {"enum": [1]},
        "name": {"type": "string"},
        "description": {"type": "string"},
        "dbc": {"type": "string"},
        "header": {
            "type": "object", "additionalProperties": False,
            "required": ["message", "counter", "count"],
            "properties": {
                "message": {"type": "string"}, "counter": {"type": "string"},
                "counter_max": {"oneOf": [{"type": "integer", "minimum": 1},
                                          {"const": "dbc"}]},
                "counter_min": {"oneOf": [{"type": "integer", "minimum": 0},
                                          {"const": "dbc"}]},
                "count": {"type": "array", "minItems": 1, "items": {"type": "string"}},
                "timestamp": _TIMESTAMP, "checksum": _CHECKSUM,
            },
        },
        "detection": {
            "type": "object", "additionalProperties": False,
            "required": ["messages", "index", "form"],
            "properties": {
                "messages": {"type": "array", "minItems": 1, "maxItems": MAX_MESSAGES,
                             "items": {"type": "string"}},
                "fd_message": {"type": "string"},
                "frame_counter": {"type": "string"},
                "index": {"type": "string"},
                "checksum": _CHECKSUM,
                "form": {"enum": ["polar", "cartesian"]},
                **{q: _SIGNAL for q in QUANTITIES},
            },
        },
    },
}


# DBC units rts-scenario recognises: (dimension, factor to the quantity's own unit; None where
# no scale converts it). Others (and none) are taken as the quantity's own.
_UNITS: dict[str, tuple[str, float | None]] = {
    "m": ("length", 1.0), "km": ("length", 1000.0), "cm": ("length", 0.01),
    "mm": ("length", 0.001), "ft": ("length", 0.3048), "in": ("length", 0.0254),
    "deg": ("angle", 1.0), "°": ("angle", 1.0), "degree": ("angle", 1.0),
    "degrees": ("angle", 1.0), "rad": ("angle", 180.0 / math.pi),
    "mrad": ("angle", 0.18 / math.pi),
    "m/s": ("velocity", 1.0), "mps": ("velocity", 1.0), "km/h": ("velocity", 1.0 / 3.6),
    "kph": ("velocity", 1.0 / 3.6), "kmh": ("velocity", 1.0 / 3.6), "mph": ("velocity", 0.44704),
    "cm/s": ("velocity", 0.01),
    "s": ("time", 1.0), "sec": ("time", 1.0), "ms": ("time", 0.001), "us": ("time", 1e-6),
    "µs": ("time", 1e-6), "μs": ("time", 1e-6), "ns": ("time", 1e-9),
    "db": ("level", 1.0), "dbsm": ("level", 1.0), "dbm2": ("level", 1.0),
    "dbm²": ("level", 1.0), "dbm^2": ("level", 1.0),
    "m2": ("area", None), "m²": ("area", None), "m^2": ("area", None),
}
# Each quantity's dimension and unit.
_QUANTITY_UNITS = {
    "range_m": ("length", "m"), "x_m": ("length", "m"), "y_m": ("length", "m"),
    "z_m": ("length", "m"), "azimuth_deg": ("angle", "deg"), "elevation_deg": ("angle", "deg"),
    "radial_velocity_mps": ("velocity", "m/s"), "vx_mps": ("velocity", "m/s"),
    "vy_mps": ("velocity", "m/s"), "rcs_dbsm": ("level", "dB"), "snr_db": ("level", "dB"),
}
_DIMENSION_NAMES = {"length": "a length", "angle": "an angle", "velocity": "a velocity",
                    "level": "a level in dB", "area": "an area", "time": "a time"}

Message = cantools.database.can.Message
# A part of a detection: a message's frame id and its multiplexer page (None: not multiplexed).
PartKey = tuple[int, int | None]


def _can_db(db: object) -> cantools.database.can.Database:
    assert isinstance(db, cantools.database.can.Database)
    return db


@contextmanager
def _quiet_cantools() -> Iterator[None]:
    """Hold back cantools' "Overwriting message" warnings: `CanMapping` reports the clash."""
    logger = logging.getLogger("cantools.database.can.database")
    before = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(before)


def _printable(text: str, limit: int = 300) -> str:
    """``text`` with what a terminal cannot show as text escaped, and cut at ``limit``."""
    shown = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    return shown if len(shown) <= limit else shown[:limit] + "..."


def _load_dbc(load: Callable[[], object]) -> cantools.database.can.Database:
    with _quiet_cantools():
        return _can_db(load())


def pages(message: Message) -> list[int | None]:
    """Return a message's multiplexer pages in order ([None] for a plain message)."""
    ids = sorted({i for sg in message.signals for i in (sg.multiplexer_ids or [])})
    return list(ids) if message.is_multiplexed() and ids else [None]


def page_signals(message: Message,
                 page: int | None = None) -> dict[str, cantools.database.can.Signal]:
    """Return the signals a message (one multiplexer page of it) carries."""
    return {sg.name: sg for sg in message.signals
            if page is None or sg.multiplexer_ids is None or page in sg.multiplexer_ids}


def multiplexer(message: Message) -> str | None:
    """Return the name of a message's (top-level) multiplexer signal, if it has one."""
    return next((sg.name for sg in message.signals
                 if sg.is_multiplexer and sg.multiplexer_ids is None), None)


def _float_ulp(value: float, bits: int) -> float:
    """Return the unit in the last place of ``value`` in a float of ``bits`` (32: else 64).

    0 for an infinite value (a float signal without DBC ends: none to be at).
    """
    if not math.isfinite(value):
        return 0.0
    if bits != 32:
        return math.ulp(value)
    _, exponent = math.frexp(value or 2.0**-126)
    return 2.0 ** (exponent - 24)


def signal_range(sig: cantools.database.can.Signal) -> tuple[float, float]:
    """Return a signal's physical range: what its bits carry, within the DBC's stated range."""
    if sig.conversion.is_float:
        low, high = -math.inf, math.inf
    else:
        raw_low = -(1 << (sig.length - 1)) if sig.is_signed else 0
        raw_high = (1 << (sig.length - 1)) - 1 if sig.is_signed else (1 << sig.length) - 1
        low, high = sorted((raw_low * sig.scale + sig.offset, raw_high * sig.scale + sig.offset))
    if sig.minimum is not None:
        low = max(low, float(sig.minimum))
    if sig.maximum is not None:
        high = min(high, float(sig.maximum))
    return float(low), float(high)


def checksum_byte(message: Message, name: str) -> int | None:
    """Return the byte a checksum signal fills, or None if it is not one whole byte.

    A whole byte is 8 bits starting at a byte's bit 0 (Intel) or bit 7 (Motorola: the DBC
    numbers a big-endian signal from its most significant bit).
    """
    sig = message.get_signal_by_name(name)
    first = 0 if sig.byte_order == "little_endian" else 7
    if sig.length != 8 or sig.start % 8 != first or sig.is_signed or sig.multiplexer_ids:
        return None
    return int(sig.start // 8)


def checksum_bytes(message: Message, checksum: Checksum) -> tuple[int, int] | None:
    """Return the bytes (first, how many) a checksum signal fills in its scheme, else None.

    rts-scenario's scheme and CRC-8 SAE J1850 fill one whole byte anywhere (`checksum_byte`);
    AUTOSAR E2E profile 2 fills byte 0, profile 5 bytes 0 and 1 (a 16-bit Intel signal from
    bit 0, low byte first), as the profiles place them.
    """
    if checksum.scheme == "autosar-e2e-p5":
        sig = message.get_signal_by_name(checksum.signal)
        whole = (sig.length == 16 and sig.start == 0 and sig.byte_order == "little_endian"
                 and not sig.is_signed and not sig.multiplexer_ids)
        return (0, 2) if whole else None
    position = checksum_byte(message, checksum.signal)
    if position is None or (checksum.scheme == "autosar-e2e-p2" and position != 0):
        return None
    return position, 1


_PLACEMENT = {
    "crc32-low-byte": "8 unsigned bits from a byte's bit 0 Intel or bit 7 Motorola",
    "crc8-sae-j1850": "8 unsigned bits from a byte's bit 0 Intel or bit 7 Motorola",
    "autosar-e2e-p2": "byte 0: 8 unsigned bits from bit 0 Intel or bit 7 Motorola",
    "autosar-e2e-p5": "bytes 0 and 1: 16 unsigned bits from bit 0 Intel",
}
# Shortest message a scheme protects (cantools' E2E functions need these lengths).
_MIN_LENGTH = {"autosar-e2e-p2": 2, "autosar-e2e-p5": 4}


@dataclass(frozen=True)
class Checksum:
    """A checksum signal and how its value is computed (``scheme``, ``data_id``).

    ``data_id``: the AUTOSAR E2E data ID, one for every message, or per message name; for
    profile 2 also a list of 16 (the DataIDList, picked by the counter in byte 1's low nibble).
    """

    signal: str
    scheme: str = DEFAULT_CHECKSUM_SCHEME
    data_id: int | tuple[int, ...] | dict[str, int | tuple[int, ...]] | None = None

    @classmethod
    def parse(cls, value: str | dict[str, Any] | None) -> Checksum | None:
        """Read a mapping's ``checksum`` entry: a signal, or ``{signal, scheme, data_id}``."""
        if value is None:
            return None
        if isinstance(value, str):
            return cls(value)

        def frozen(v: Any) -> int | tuple[int, ...]:
            return tuple(v) if isinstance(v, list) else int(v)

        data_id = value.get("data_id")
        return cls(value["signal"], value.get("scheme", DEFAULT_CHECKSUM_SCHEME),
                   None if data_id is None else {k: frozen(v) for k, v in data_id.items()}
                   if isinstance(data_id, dict) else frozen(data_id))

    def data_id_of(self, message: str) -> int | tuple[int, ...] | None:
        """Return the data ID of one message."""
        if isinstance(self.data_id, dict):
            return self.data_id.get(message)
        return self.data_id


class SignalEnds(NamedTuple):
    """The lowest and highest values a quantity's signal carries (`CanMapping.limits`)."""

    low: float
    high: float
    step: float  # between two raw values, in the quantity's unit (a float's: 2 ulp at its ends)
    signal: str


@dataclass(frozen=True)
class Field:
    """A quantity read from a signal: ``value * scale + offset``."""

    signal: str
    scale: float = 1.0
    offset: float = 0.0


def digest_of(mapping_text: bytes, dbc_text: bytes) -> str:
    """sha256 of a mapping file's bytes and its DBC's, as `CanMapping.sha256` keeps it."""
    digest = hashlib.sha256(b"rts-scenario mapping\0")
    for part in (mapping_text, dbc_text):
        digest.update(len(part).to_bytes(8, "little"))
        digest.update(part)
    return digest.hexdigest()


@dataclass(frozen=True, eq=False)
class CanMapping:
    """A DBC and the meaning of its signals for the checker."""

    name: str
    db: cantools.database.can.Database
    header: str
    counter: str
    count: tuple[str, ...]
    timestamp: str | None
    messages: tuple[str, ...]
    fd_message: str | None
    frame_counter: str | None
    index: str
    form: str
    fields: dict[str, Field]
    header_checksum_spec: Checksum | None = None
    checksum_spec: Checksum | None = None
    counter_max: int | None = None  # the counter's last value before 0 (None: its width's)
    counter_min: int = 0  # the counter's first value, the one after its last
    timestamp_scale: float = 1.0  # seconds per unit of the timestamp signal's DBC value
    # sha256 of the mapping's text and its DBC's (`digest_of`): what a recording's sidecar
    # keeps, so that a re-check tells a mapping or DBC edited since.
    sha256: str = ""

    @property
    def header_checksum(self) -> str | None:
        """The header's checksum signal, if any."""
        return self.header_checksum_spec.signal if self.header_checksum_spec else None

    @property
    def checksum(self) -> str | None:
        """The detection messages' checksum signal, if any."""
        return self.checksum_spec.signal if self.checksum_spec else None

    @property
    def counter_modulus(self) -> int:
        """How many values the header's counter takes before it comes back to 0.

        ``counter_max + 1`` where the mapping says where it wraps (an AUTOSAR alive counter
        runs 0..14 in 4 bits), else the counter signal's width (an 8-bit counter: 256), less
        ``counter_min`` (a counter running 1..14: 14). The receiver counts a header's counter
        from ``counter_min`` (its value less it) and the publisher writes it so, so that
        every counter past the bus runs from 0.
        """
        if self.counter_max is not None:
            return self.counter_max + 1 - self.counter_min
        return (1 << int(self.db.get_message_by_name(self.header)
                         .get_signal_by_name(self.counter).length)) - self.counter_min

    @property
    def quantities(self) -> set[str]:
        """Quantities a detection carries (polar names, whatever the form)."""
        have = set(self.fields)
        out: set[str] = {q for q in ("rcs_dbsm", "snr_db") if q in have}
        if self.form == "polar":
            out |= {q for q in ("range_m", "azimuth_deg", "elevation_deg",
                                "radial_velocity_mps") if q in have}
        else:
            out |= {"range_m", "azimuth_deg"}
            if "z_m" in have:
                out.add("elevation_deg")
            if {"vx_mps", "vy_mps"} <= have:
                out.add("radial_velocity_mps")
        return out

    def not_carried(self) -> dict[str, str]:
        """Say which checked quantities a detection does not carry, and why (polar names).

        ``{"elevation_deg": "mapping 'cluster-list' carries no elevation, a cartesian one
        without z_m"}``: the checker cannot check them (`rts_scenario.check.unchecked_quantities`).
        A cartesian mapping carries what the reader derives (`quantities`): elevation with
        ``z_m``, radial velocity with both ``vx_mps`` and ``vy_mps``.
        """
        have = self.quantities
        cartesian = {"elevation_deg": ", a cartesian one without z_m",
                     "radial_velocity_mps": ", a cartesian one without both vx_mps and vy_mps"}
        return {q: f"mapping {self.name!r} carries no {word}"
                   + (cartesian.get(q, "") if self.form == "cartesian" else "")
                for q, word in _CHECKED_WORDS.items() if q not in have}

    def parts(self, fd: bool = False) -> list[tuple[Message, int | None]]:
        """Return every message and page of one detection, in sending order.

        ``fd``: the CAN FD message if the mapping has one, else the classic messages.
        """
        names = [self.fd_message] if fd and self.fd_message else list(self.messages)
        out: list[tuple[Message, int | None]] = []
        for name in names:
            message = self.db.get_message_by_name(name)
            out += [(message, page) for page in pages(message)]
        return out

    def steps(self, fd: bool | None = False) -> dict[str, float]:
        """Return the bus step of each mapped quantity (its unit), the coarsest of its signals.

        A signal's raw step times its DBC scale times the field's ``scale``: a radar's report
        of the quantity is a multiple of it (plus offsets), however exact the radar. ``fd``:
        on a CAN FD bus (the FD message where the mapping has one), on a classic one, or
        (None) either: the finer of the two, for a log whose bus is not known.
        """
        if fd is None:
            classic, flexible = self.steps(False), self.steps(True)
            return {q: min(step, flexible.get(q, step)) for q, step in classic.items()}
        names = [self.fd_message] if fd and self.fd_message else list(self.messages)
        out: dict[str, float] = {}
        for quantity, f in self.fields.items():
            for name in names:
                for sig in self.db.get_message_by_name(name).signals:
                    if sig.name == f.signal:
                        step = abs(float(sig.scale) * f.scale)
                        out[quantity] = max(out.get(quantity, 0.0), step)
        return out

    def limits(self, fd: bool | None = False) -> dict[str, SignalEnds]:
        """Return the ends of what a detection's message can carry of each quantity read as is.

        ``{"rcs_dbsm": SignalEnds(low, high, step, signal)}``: the lowest and highest values
        the signal's raw values decode to within its DBC range (`signal_range`), through the
        field's ``scale`` and ``offset``, in the quantity's unit, keyed as
        `rts_scenario.detections.Detections` names the quantities: RCS, and a polar mapping's
        range, radial velocity and angles (a cartesian mapping derives those from several
        signals). A radar reports a value beyond its signal's range at the signal's end, if at
        all: the checker does not judge a reading at an end against a truth beyond it
        (`rts_scenario.check.Checker`). ``fd`` as in `steps`; for a bus not known (None), the
        narrower ends of the two, the coarser step. Messages of one bus that carry a quantity
        with other ranges give the widest.
        """
        if fd is None:
            classic, flexible = self.limits(False), self.limits(True)
            return {q: SignalEnds(max(a.low, b.low), min(a.high, b.high), max(a.step, b.step),
                                  a.signal)
                    for q, a in classic.items() for b in [flexible.get(q, a)]}
        names = [self.fd_message] if fd and self.fd_message else list(self.messages)
        direct = {"rcs_dbsm": "rcs_dbsm"}
        if self.form == "polar":
            direct.update(range_m="range_m", radial_velocity_mps="radial_velocity_mps",
                          azimuth_deg="az_deg", elevation_deg="el_deg")
        out: dict[str, SignalEnds] = {}
        for quantity, name in direct.items():
            f = self.fields.get(quantity)
            if f is None:
                continue
            for message in names:
                for sig in self.db.get_message_by_name(message).signals:
                    if sig.name != f.signal:
                        continue
                    low, high = signal_range(sig)
                    scale, offset = float(sig.scale), float(sig.offset)
                    if not sig.conversion.is_float and math.isfinite(low + high):
                        # The raw values within the range, at their ends (scale may be < 0).
                        raws = sorted(((low - offset) / scale, (high - offset) / scale))
                        low, high = sorted((math.ceil(raws[0] - 1e-9) * scale + offset,
                                            math.floor(raws[1] + 1e-9) * scale + offset))
                    ends = sorted((low * f.scale + f.offset, high * f.scale + f.offset))
                    # A float signal's step: two units in the last place at its ends (its DBC
                    # ends as it stores them, 2.3 as 2.29999995 in 32 bits, are within one).
                    step = (2.0 * _float_ulp(max(abs(low), abs(high)), sig.length)
                            * abs(scale * f.scale) if sig.conversion.is_float
                            else abs(scale * f.scale))
                    was = out.get(name)
                    if was is not None:
                        # Messages of one bus that carry it with other ranges: the widest
                        # (a reading within it is a measurement in one of them).
                        ends = [min(was.low, ends[0]), max(was.high, ends[1])]
                        step = max(step, was.step)
                    out[name] = SignalEnds(ends[0], ends[1], step, f.signal)
        return out

    def _check_counting(self, doc: Document, names: dict[str, Message],
                        carriers: list[str]) -> None:
        """Refuse an index or counter signal that does not count in steps of 1.

        Detections are numbered one by one and cycles counted one by one, in the signals'
        values: a DBC factor other than 1 would give two detections one number (or skip
        counts), and the receiver would join the wrong messages.
        """
        counting = [(("header", "counter"), self.counter, [self.header])]
        counting.append((("detection", "index"), self.index, carriers))
        if self.frame_counter:
            counting.append((("detection", "frame_counter"), self.frame_counter, carriers))
        for key, signal, messages in counting:
            for m in messages:
                for sig in names[m].signals:
                    if sig.name == signal and float(sig.scale) != 1.0:
                        raise doc.error(key, f"signal {signal!r} of message {m!r} counts in "
                                             f"steps of {float(sig.scale):g} (its DBC factor); "
                                             f"it numbers detections or cycles one by one, so "
                                             f"its factor must be 1")

    def needed_parts(self, fd: bool = False) -> frozenset[PartKey]:
        """Return the parts a detection needs: those carrying a mapped quantity."""
        mapped = {f.signal for f in self.fields.values()}
        return frozenset((message.frame_id, page) for message, page in self.parts(fd)
                         if mapped & set(page_signals(message, page)))

    @classmethod
    @lru_cache(maxsize=1)
    def builtin(cls) -> CanMapping:
        """rts-scenario's own detection messages.

        Parsed once per process (a DBC takes about 10 ms; every publisher and receiver without
        a mapping of its own asks for this one) and shared: its `db` is not to be modified.
        """
        folder = resources.files("rts_scenario").joinpath("data/can")
        text = folder.joinpath("rts_detections.mapping.yaml").read_text()
        doc = load_yaml("<mapping rts-detections>", text)
        dbc = folder.joinpath("rts_detections.dbc").read_text()
        mapping = cls._build(doc, _load_dbc(
            lambda: cantools.database.load_string(dbc, database_format="dbc")))
        object.__setattr__(mapping, "sha256", digest_of(text.encode(), dbc.encode()))
        return mapping

    @classmethod
    def from_file(cls, path: str | Path) -> CanMapping:
        """Load a ``*.mapping.yaml`` and the DBC it names (relative to it)."""
        path = Path(path)
        doc = load_kind(path, ".mapping.yaml")
        validate(doc, MAPPING_SCHEMA)
        dbc_path = path.parent / doc.data["dbc"]
        try:
            with open(dbc_path, "rb") as file:
                head = file.read(4096)
            # DBC tools write cp1252 (cantools' default); a byte order mark says UTF-8.
            encoding = "utf-8-sig" if head.startswith(b"\xef\xbb\xbf") else None
            if b"\x00" in head:
                # cantools' error would quote the bytes, garbage on the terminal.
                raise doc.error(("dbc",), f"cannot load DBC {dbc_path}: binary data (a NUL "
                                          f"byte in its first {len(head)} bytes), not a DBC's text")
            db = _load_dbc(lambda: cantools.database.load_file(dbc_path, database_format="dbc",
                                                               encoding=encoding))
            dbc_bytes = dbc_path.read_bytes()
        except (OSError, cantools.database.UnsupportedDatabaseFormatError) as exc:
            raise doc.error(("dbc",), f"cannot load DBC {dbc_path}: "
                                      f"{_printable(str(exc))}") from None
        mapping = cls._build(doc, db)
        try:
            object.__setattr__(mapping, "sha256", digest_of(path.read_bytes(), dbc_bytes))
        except OSError as exc:  # read a moment ago
            raise doc.error((), f"cannot read {path}: {exc.strerror}") from None
        return mapping

    @classmethod
    def _build(cls, doc: Document, db: cantools.database.can.Database) -> CanMapping:
        validate(doc, MAPPING_SCHEMA)
        d = doc.data
        head, det = d["header"], d["detection"]
        fields = {q: Field(v) if isinstance(v, str) else Field(v["signal"], v.get("scale", 1.0),
                                                               v.get("offset", 0.0))
                  for q, v in det.items() if q in QUANTITIES}
        stamp = head.get("timestamp")
        stamp_scale = 1.0
        if isinstance(stamp, dict):
            stamp, stamp_scale = stamp["signal"], float(stamp.get("scale", 1.0))
        mapping = cls(
            name=d["name"], db=db, header=head["message"], counter=head["counter"],
            count=tuple(head["count"]), timestamp=stamp, timestamp_scale=stamp_scale,
            messages=tuple(det["messages"]),
            fd_message=det.get("fd_message"), frame_counter=det.get("frame_counter"),
            index=det["index"], form=det["form"], fields=fields,
            header_checksum_spec=Checksum.parse(head.get("checksum")),
            checksum_spec=Checksum.parse(det.get("checksum")),
        )
        mapping._check(doc)
        mapping._check_counter_width(doc)
        if "counter_max" in head:
            object.__setattr__(mapping, "counter_max", mapping._counter_max(doc))
        if "counter_min" in head:
            object.__setattr__(mapping, "counter_min", mapping._counter_min(doc))
        return mapping

    def _counter_top(self) -> int:
        """Return the largest whole value the header's counter signal carries."""
        sig = self.db.get_message_by_name(self.header).get_signal_by_name(self.counter)
        raw_top = (1 << (sig.length - (1 if sig.is_signed else 0))) - 1
        return int(math.floor(raw_top * sig.scale + sig.offset + 1e-9))

    def _check_counter_width(self, doc: Document) -> None:
        """Refuse a counter signal carrying fewer than `SMALLEST_COUNTER_MODULUS` values."""
        sig = self.db.get_message_by_name(self.header).get_signal_by_name(self.counter)
        values = self._counter_top() + 1
        if values < SMALLEST_COUNTER_MODULUS:
            raise doc.error(("header", "counter"),
                            f"got {self.counter!r}: the {sig.length}-bit signal takes {values} "
                            f"values; a counter must take {SMALLEST_COUNTER_MODULUS} at least: "
                            f"{_TOO_FEW_VALUES}")

    def _counter_min(self, doc: Document) -> int:
        """Return the header's ``counter_min``: given, or the DBC's minimum of the counter."""
        key = ("header", "counter_min")
        value = doc.data["header"]["counter_min"]
        sig = self.db.get_message_by_name(self.header).get_signal_by_name(self.counter)
        if self.counter_max is not None:
            top, said = self.counter_max, f"{self.counter_max} (counter_max)"
        else:
            top = (1 << sig.length) - 1
            said = f"{top} (what the {sig.length}-bit signal {self.counter!r} carries)"
        # The counter takes the values from counter_min to top.
        highest = top + 1 - SMALLEST_COUNTER_MODULUS
        if value == "dbc":
            minimum = sig.minimum
            if (minimum is None or float(minimum) != int(minimum)
                    or not 0 <= minimum <= highest):
                raise doc.error(key, f"dbc: the DBC states no whole minimum from 0 to {highest} "
                                     f"for signal {self.counter!r} of message "
                                     f"{self.header!r} (got {minimum}); give the counter's "
                                     f"first value as a number instead")
            return int(minimum)
        if not value <= highest:
            raise doc.error(key, f"got {value}: the counter must take "
                                 f"{SMALLEST_COUNTER_MODULUS} values at least, from "
                                 f"counter_min to {said}: {_TOO_FEW_VALUES}; allowed: 0 to "
                                 f"{highest}, or dbc (the DBC's minimum)")
        return int(value)

    def _counter_max(self, doc: Document) -> int:
        """Return the header's ``counter_max``: given, or the DBC's maximum of the counter."""
        key = ("header", "counter_max")
        value = doc.data["header"]["counter_max"]
        sig = self.db.get_message_by_name(self.header).get_signal_by_name(self.counter)
        top = self._counter_top()
        lowest = SMALLEST_COUNTER_MODULUS - 1  # from 0 (counter_min is checked after)
        if value == "dbc":
            maximum = sig.maximum
            if (maximum is None or float(maximum) != int(maximum)
                    or not lowest <= maximum <= top):
                raise doc.error(key, f"dbc: the DBC states no whole maximum from {lowest} to "
                                     f"{top} for signal {self.counter!r} of message "
                                     f"{self.header!r} (got {maximum}); give the counter's "
                                     f"last value as a number instead")
            return int(maximum)
        if value > top:
            raise doc.error(key, f"got {value}: the {sig.length}-bit signal {self.counter!r} "
                                 f"counts to {top} at most; allowed: {lowest} to {top}, or dbc "
                                 f"(the DBC's maximum)")
        if value < lowest:
            raise doc.error(key, f"got {value}: the counter must take "
                                 f"{SMALLEST_COUNTER_MODULUS} values at least, from 0 to "
                                 f"counter_max: {_TOO_FEW_VALUES}; allowed: {lowest} to {top}, "
                                 f"or dbc (the DBC's maximum)")
        return int(value)

    def _check(self, doc: Document) -> None:
        """Every named message and signal exists in the DBC; the form has what it needs."""
        _check_dbc(doc, self.db)
        names = {m.name: m for m in self.db.messages}

        def message_of(key: tuple[str | int, ...], message: str) -> Message:
            if message not in names:
                raise doc.error(key, f"message {message!r} is not in the DBC; messages: "
                                     f"{', '.join(sorted(names))}")
            return names[message]

        # Each signal is reported at the key that names it, with the signals it may name.
        head = message_of(("header", "message"), self.header)
        self._check_header_message(doc, head)
        header = {s.name for s in head.signals}
        for key, name in self._named():
            if key[0] == "header" and name not in header:
                raise doc.error(key, f"signal {name!r} is not in message {self.header!r}; "
                                     f"signals: {', '.join(sorted(header))}")
        carriers = [*self.messages, *([self.fd_message] if self.fd_message else [])]
        listed: dict[str, int] = {}
        for i, m in enumerate(self.messages):
            message = message_of(("detection", "messages"), m)
            if m in listed:  # its every page would go out twice
                raise doc.error(("detection", "messages", i),
                                f"message {m!r} is listed twice (entries {listed[m]} and {i}); "
                                f"each message carries its part of a detection once: list it "
                                f"once")
            listed[m] = i
            if not _is_classic(message):
                raise doc.error(("detection", "messages", i),
                                f"message {m!r} is {_frame_kind(message)}: detection.messages "
                                f"are classic CAN messages, of {CLASSIC_BYTES} bytes at most; "
                                f"a CAN FD message goes under fd_message (sent with --can-fd)")
        if self.fd_message:
            message_of(("detection", "fd_message"), self.fd_message)
        carried = set().union(*({s.name for s in names[m].signals} for m in carriers))
        for key, name in self._named():
            if key[0] == "detection" and name not in carried:
                raise doc.error(key, f"signal {name!r} is not in the detection message(s) "
                                     f"{', '.join(carriers)}; signals: "
                                     f"{', '.join(sorted(carried))}")
        self._check_quantities_in_both(doc)
        for m in carriers:  # the index joins a detection's messages: every one carries it
            have = {s.name for s in names[m].signals}
            if self.index not in have:
                raise doc.error(("detection", "index"),
                                f"signal {self.index!r} is not in message {m!r}; signals: "
                                f"{', '.join(sorted(have))}")
        for key, message_names, spec in (
                (("header", "checksum"), [self.header], self.header_checksum_spec),
                (("detection", "checksum"), carriers, self.checksum_spec)):
            if spec is not None:
                self._check_checksum(doc, key, [names[m] for m in message_names
                                                if spec.signal in {s.name
                                                                   for s in names[m].signals}],
                                     spec)
        self._check_counting(doc, names, carriers)
        for fd in (False, True):
            for message, page in self.parts(fd):
                if (message.frame_id, page) in self.needed_parts(fd) and \
                        self.index not in page_signals(message, page):
                    where = f"page {page} of message" if page is not None else "message"
                    raise doc.error(("detection", "index"),
                                    f"signal {self.index!r} is not in {where} "
                                    f"{message.name!r}: every message and page that carries a "
                                    f"detection needs the index that joins them")
        self._check_units(doc)
        required = {"polar": ("range_m", "azimuth_deg"), "cartesian": ("x_m", "y_m")}[self.form]
        missing = [q for q in required if q not in self.fields]
        if missing:
            raise doc.error(("detection", "form"),
                            f"form {self.form!r} needs {', '.join(missing)}")
        self._check_roles(doc)
        for q, f in self.fields.items():
            if f.scale == 0.0:
                raise doc.error(("detection", q, "scale"),
                                f"must not be 0: {q} would read {f.offset:g} whatever the radar "
                                f"sends, and could not be written; got 0")
        dbc = doc.data["dbc"]
        for m in (self.header, *carriers):
            for sig in names[m].signals:
                if sig.scale == 0:
                    group = "header" if m == self.header else "detection"
                    mapped = next((k for k, name in self._named()
                                   if name == sig.name and k[0] == group), ("dbc",))
                    raise doc.error(mapped, f"signal {sig.name!r} of message {m!r} in DBC {dbc} "
                                            f"has factor 0: every raw value reads "
                                            f"{sig.offset:g}, so it carries nothing and cannot "
                                            f"be written; give it a factor other than 0")

    def _check_header_message(self, doc: Document, header: Message) -> None:
        """Refuse a header that is not one plain classic message.

        The header opens every cycle in either mode, and a mapping's detections always have
        their classic messages (``messages`` is required): so the header is classic. A
        multiplexed header would need a page per cycle, and its pages joined: not supported.
        """
        if not _is_classic(header):
            raise doc.error(("header", "message"),
                            f"message {header.name!r} is {_frame_kind(header)}: the header opens "
                            f"every cycle, on classic CAN too (detection.messages are "
                            f"classic), so it is a classic message of {CLASSIC_BYTES} bytes at "
                            f"most")
        mux = multiplexer(header)
        if mux is not None:
            raise doc.error(("header", "message"),
                            f"message {header.name!r} is multiplexed (multiplexer {mux!r}, "
                            f"pages {', '.join(str(p) for p in pages(header))}): a "
                            f"multiplexed header is not supported; the header must be one "
                            f"plain message")

    def _check_quantities_in_both(self, doc: Document) -> None:
        """Refuse a quantity that the classic messages, or the CAN FD message, do not carry.

        Without ``--can-fd`` a detection goes in the classic messages, with it in the
        ``fd_message`` alone (if the mapping has one): each must carry every mapped quantity.
        """
        def carrying(names: list[str], signal: str) -> bool:
            return any(signal in {s.name for s in self.db.get_message_by_name(n).signals}
                       for n in names)

        carriers = [*self.messages, *([self.fd_message] if self.fd_message else [])]
        for q, f in self.fields.items():
            holders = [n for n in carriers if carrying([n], f.signal)]
            if not carrying(list(self.messages), f.signal):
                raise doc.error(("detection", q),
                                f"signal {f.signal!r} is only in fd_message "
                                f"{self.fd_message!r}, in none of the classic messages "
                                f"{', '.join(self.messages)}: without --can-fd a detection "
                                f"goes in those, so each mapped quantity must be in one of "
                                f"them")
            if self.fd_message and not carrying([self.fd_message], f.signal):
                raise doc.error(("detection", q),
                                f"signal {f.signal!r} is in {', '.join(holders)} but not in "
                                f"fd_message {self.fd_message!r}: with --can-fd a detection "
                                f"is that one message, so it must carry every mapped quantity")

    def _check_checksum(self, doc: Document, key: tuple[str, ...], carrying: list[Message],
                        spec: Checksum) -> None:
        """Refuse a checksum signal not where its scheme puts it, or a data ID amiss."""
        scheme = spec.scheme
        for message in carrying:
            if checksum_bytes(message, spec) is None:
                sig = message.get_signal_by_name(spec.signal)
                what = "its bytes" if scheme.startswith("autosar") else "one whole byte"
                raise doc.error(key, f"signal {spec.signal!r} of message {message.name!r} must "
                                     f"fill {what} to be a checksum of scheme {scheme} "
                                     f"({_PLACEMENT[scheme]}, in every page), got "
                                     f"{sig.length} bits from bit {sig.start} "
                                     f"{sig.byte_order.replace('_', '-')}")
            if message.length < _MIN_LENGTH.get(scheme, 1):
                raise doc.error(key, f"message {message.name!r} has {message.length} bytes; a "
                                     f"checksum of scheme {scheme} protects {_MIN_LENGTH[scheme]} "
                                     f"bytes or more")
        if scheme not in _DATA_ID:
            if spec.data_id is not None:
                raise doc.error((*key, "data_id"), f"scheme {scheme} takes no data ID; "
                                                   f"data_id is for autosar-e2e-p2 and "
                                                   f"autosar-e2e-p5")
            return
        top, listed = _DATA_ID[scheme]
        if spec.data_id is None:
            raise doc.error(key, f"scheme {scheme} needs data_id (the data ID of the "
                                 f"messages, 0 to {top}"
                                 f"{', or a list of 16' if listed else ''}; or one per message "
                                 f"name)")
        if isinstance(spec.data_id, dict):
            carried = [m.name for m in carrying]
            for name in spec.data_id:
                if name not in carried:
                    raise doc.error((*key, "data_id", name),
                                    f"message {name!r} carries no checksum {spec.signal!r}; "
                                    f"messages: {', '.join(carried)}")
            for name in carried:
                if name not in spec.data_id:
                    raise doc.error((*key, "data_id"),
                                    f"no data ID for message {name!r}; give one for each of "
                                    f"{', '.join(carried)}")
        for name in [m.name for m in carrying]:
            value = spec.data_id_of(name)
            where = (*key, "data_id", *((name,) if isinstance(spec.data_id, dict) else ()))
            if isinstance(value, tuple) and not listed:
                raise doc.error(where, f"scheme {scheme} takes one data ID (0 to {top}), not "
                                       f"a list (a list of 16 is profile 2's)")
            if isinstance(value, int) and value > top:
                raise doc.error(where, f"got {value}: a data ID of scheme {scheme} is 0 to {top}")

    def _check_units(self, doc: Document) -> None:
        """Refuse a quantity read from a signal the DBC gives in another unit, unconverted.

        A quantity with its own ``scale`` or ``offset`` converts its signal: any unit goes.
        """
        carriers = [*self.messages, *([self.fd_message] if self.fd_message else [])]
        for q, f in self.fields.items():
            if (f.scale, f.offset) != (1.0, 0.0):
                continue
            dimension, unit = _QUANTITY_UNITS[q]
            for name in carriers:
                message = self.db.get_message_by_name(name)
                sig = next((sg for sg in message.signals if sg.name == f.signal), None)
                if sig is None or not sig.unit:
                    continue
                problem = _unit_problem(sig, name, dimension, unit, q)
                if problem is not None:
                    raise doc.error(("detection", q), problem)
        # The header's time, in seconds, alike (its own scale converts any unit).
        if self.timestamp is not None and self.timestamp_scale == 1.0:
            sig = self.db.get_message_by_name(self.header).get_signal_by_name(self.timestamp)
            if sig.unit:
                problem = _unit_problem(sig, self.header, "time", "s", "the timestamp")
                if problem is not None:
                    raise doc.error(("header", "timestamp"), problem)

    def _named(self) -> list[tuple[tuple[str | int, ...], str]]:
        """Every (mapping key, signal) pair, header roles first, in file order."""
        head: list[tuple[tuple[str | int, ...], str | None]] = [
            (("header", "counter"), self.counter),
            *((("header", "count", i), c) for i, c in enumerate(self.count)),
            (("header", "timestamp"), self.timestamp),
            (("header", "checksum"), self.header_checksum)]
        det: list[tuple[tuple[str | int, ...], str | None]] = [
            (("detection", "index"), self.index),
            (("detection", "frame_counter"), self.frame_counter),
            (("detection", "checksum"), self.checksum),
            *((("detection", q), f.signal) for q, f in self.fields.items())]
        return [(k, n) for k, n in (*head, *det) if n is not None]

    def _check_roles(self, doc: Document) -> None:
        """Refuse two keys of the header (or of the detection) naming one signal."""
        seen: dict[tuple[str, str], tuple[str | int, ...]] = {}
        for key, name in self._named():
            first = seen.setdefault((str(key[0]), name), key)
            if first != key:
                raise doc.error(key, f"signal {name!r} is already mapped as "
                                     f"{format_key_path(first)}; each signal carries one "
                                     f"quantity")


def _unit_problem(sig: cantools.database.can.Signal, message: str, dimension: str, unit: str,
                  what: str) -> str | None:
    """Say why a signal's DBC unit is not ``unit`` (of ``dimension``), where it knows one.

    ``what``: the quantity read from it (``range_m``, the timestamp). None: its unit is the
    quantity's, or one rts-scenario does not know (taken as the quantity's).
    """
    given = (sig.unit or "").strip()
    known = _UNITS.get(given.lower().replace(" ", ""))
    if known is None or known == (dimension, 1.0):
        return None
    where = f"signal {sig.name!r} of message {message!r} is in {given} (its DBC unit)"
    if known[0] == dimension and known[1] is not None:
        return (f"{where}, {what} in {unit}: give {{signal: {sig.name}, "
                f"scale: {known[1]:.6g}}} to convert it")
    how = ("map a signal in dB" if dimension == "level"
           else f"map a signal in {unit} (or give a scale that converts it)")
    return f"{where}, not {_DIMENSION_NAMES[dimension]}: {what} is in {unit}; {how}"


def _is_classic(message: Message) -> bool:
    """Whether a message goes on classic CAN: 8 bytes at most, not CAN FD in the DBC."""
    return not message.is_fd and message.length <= CLASSIC_BYTES


def _frame_kind(message: Message) -> str:
    """Say what makes a message CAN FD: its length, or the DBC's frame format."""
    if message.length > CLASSIC_BYTES:
        return f"{message.length} bytes long"
    return f"a CAN FD message in the DBC (its frame format), {message.length} bytes"


def _check_dbc(doc: Document, db: cantools.database.can.Database) -> None:
    """Every message of the DBC has its own name and its own frame ID."""
    by_id: dict[tuple[int, bool], str] = {}
    by_name: set[str] = set()
    for message in db.messages:
        if message.name in by_name:
            raise doc.error(("dbc",), f"DBC {doc.data['dbc']} defines message "
                                      f"{message.name!r} twice; message names must be unique")
        by_name.add(message.name)
        ident = (message.frame_id, bool(message.is_extended_frame))
        if ident in by_id:
            raise doc.error(("dbc",), f"DBC {doc.data['dbc']}: messages {by_id[ident]!r} and "
                                      f"{message.name!r} have the same frame ID "
                                      f"0x{message.frame_id:X}; a receiver could not tell them "
                                      f"apart, every message needs its own ID")
        by_id[ident] = message.name
