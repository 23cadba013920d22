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

import logging
import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import cantools

from ..located_yaml import Document, format_key_path, load_yaml, validate

QUANTITIES = ("range_m", "azimuth_deg", "elevation_deg", "radial_velocity_mps", "x_m", "y_m",
              "z_m", "vx_mps", "vy_mps", "rcs_dbsm", "snr_db")

# Classic messages per detection (a radar's general, quality and extended-information messages).
MAX_MESSAGES = 8

_SIGNAL: dict[str, Any] = {
    "oneOf": [
        {"type": "string"},
        {"type": "object", "additionalProperties": False, "required": ["signal"],
         "properties": {"signal": {"type": "string"}, "scale": {"type": "number"},
                        "offset": {"type": "number"}}},
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
                "count": {"type": "array", "minItems": 1, "items": {"type": "string"}},
                "timestamp": {"type": "string"}, "checksum": {"type": "string"},
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
                "checksum": {"type": "string"},
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
                    "level": "a level in dB", "area": "an area"}

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


@dataclass(frozen=True)
class Field:
    """A quantity read from a signal: ``value * scale + offset``."""

    signal: str
    scale: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True, eq=False)
class CanMapping:
    """A DBC and the meaning of its signals for the checker."""

    name: str
    db: cantools.database.can.Database
    header: str
    counter: str
    count: tuple[str, ...]
    timestamp: str | None
    header_checksum: str | None
    messages: tuple[str, ...]
    fd_message: str | None
    frame_counter: str | None
    index: str
    checksum: str | None
    form: str
    fields: dict[str, Field]

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

    def needed_parts(self, fd: bool = False) -> frozenset[PartKey]:
        """Return the parts a detection needs: those carrying a mapped quantity."""
        mapped = {f.signal for f in self.fields.values()}
        return frozenset((message.frame_id, page) for message, page in self.parts(fd)
                         if mapped & set(page_signals(message, page)))

    @classmethod
    def builtin(cls) -> CanMapping:
        """rts-scenario's own detection messages."""
        folder = resources.files("rts_scenario").joinpath("data/can")
        text = folder.joinpath("rts_detections.mapping.yaml").read_text()
        doc = load_yaml("<mapping rts-detections>", text)
        dbc = folder.joinpath("rts_detections.dbc").read_text()
        return cls._build(doc, _load_dbc(
            lambda: cantools.database.load_string(dbc, database_format="dbc")))

    @classmethod
    def from_file(cls, path: str | Path) -> CanMapping:
        """Load a ``*.mapping.yaml`` and the DBC it names (relative to it)."""
        path = Path(path)
        doc = load_yaml(path)
        validate(doc, MAPPING_SCHEMA)
        dbc_path = path.parent / doc.data["dbc"]
        try:
            with open(dbc_path, "rb") as file:
                # DBC tools write cp1252 (cantools' default); a byte order mark says UTF-8.
                encoding = ("utf-8-sig" if file.read(3) == b"\xef\xbb\xbf" else None)
            db = _load_dbc(lambda: cantools.database.load_file(dbc_path, database_format="dbc",
                                                               encoding=encoding))
        except (OSError, cantools.database.UnsupportedDatabaseFormatError) as exc:
            raise doc.error(("dbc",), f"cannot load DBC {dbc_path}: {exc}") from None
        return cls._build(doc, db)

    @classmethod
    def _build(cls, doc: Document, db: cantools.database.can.Database) -> CanMapping:
        validate(doc, MAPPING_SCHEMA)
        d = doc.data
        head, det = d["header"], d["detection"]
        fields = {q: Field(v) if isinstance(v, str) else Field(v["signal"], v.get("scale", 1.0),
                                                               v.get("offset", 0.0))
                  for q, v in det.items() if q in QUANTITIES}
        mapping = cls(
            name=d["name"], db=db, header=head["message"], counter=head["counter"],
            count=tuple(head["count"]), timestamp=head.get("timestamp"),
            header_checksum=head.get("checksum"), messages=tuple(det["messages"]),
            fd_message=det.get("fd_message"), frame_counter=det.get("frame_counter"),
            index=det["index"], checksum=det.get("checksum"), form=det["form"], fields=fields,
        )
        mapping._check(doc)
        return mapping

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
        header = {s.name for s in message_of(("header", "message"), self.header).signals}
        for key, name in self._named():
            if key[0] == "header" and name not in header:
                raise doc.error(key, f"signal {name!r} is not in message {self.header!r}; "
                                     f"signals: {', '.join(sorted(header))}")
        carriers = [*self.messages, *([self.fd_message] if self.fd_message else [])]
        for m in self.messages:
            message_of(("detection", "messages"), m)
        if self.fd_message:
            message_of(("detection", "fd_message"), self.fd_message)
        carried = set().union(*({s.name for s in names[m].signals} for m in carriers))
        for key, name in self._named():
            if key[0] == "detection" and name not in carried:
                raise doc.error(key, f"signal {name!r} is not in the detection message(s) "
                                     f"{', '.join(carriers)}; signals: "
                                     f"{', '.join(sorted(carried))}")
        for m in carriers:  # the index joins a detection's messages: every one carries it
            have = {s.name for s in names[m].signals}
            if self.index not in have:
                raise doc.error(("detection", "index"),
                                f"signal {self.index!r} is not in message {m!r}; signals: "
                                f"{', '.join(sorted(have))}")
        for key, message_names, checksum in (
                (("header", "checksum"), [self.header], self.header_checksum),
                (("detection", "checksum"), carriers, self.checksum)):
            for m in message_names:
                if checksum in {s.name for s in names[m].signals} and \
                        checksum_byte(names[m], checksum) is None:
                    sig = names[m].get_signal_by_name(checksum)
                    raise doc.error(key, f"signal {checksum!r} of message {m!r} must fill one "
                                         f"whole byte to be a checksum (8 unsigned bits from a "
                                         f"byte's bit 0 Intel or bit 7 Motorola, in every "
                                         f"page), got {sig.length} bits from bit {sig.start} "
                                         f"{sig.byte_order.replace('_', '-')}")
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
                known = _UNITS.get(sig.unit.strip().lower().replace(" ", ""))
                if known is None or known == (dimension, 1.0):
                    continue
                where = (f"signal {f.signal!r} of message {name!r} is in {sig.unit.strip()} "
                         f"(its DBC unit)")
                if known[0] == dimension and known[1] is not None:
                    raise doc.error(("detection", q),
                                    f"{where}, {q} in {unit}: give {{signal: {f.signal}, "
                                    f"scale: {known[1]:.6g}}} to convert it")
                how = ("map a signal in dB" if dimension == "level"
                       else f"map a signal in {unit} (or give a scale that converts it)")
                raise doc.error(("detection", q),
                                f"{where}, not {_DIMENSION_NAMES[dimension]}: {q} is in "
                                f"{unit}; {how}")

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
