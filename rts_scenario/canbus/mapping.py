"""What a radar's CAN messages mean: a DBC plus a mapping file.

A mapping (``*.mapping.yaml``) names, in the DBC, the frame header message (cycle counter and
detection count) and the detection message(s), and which signal carries which quantity, in
polar form (range, azimuth, elevation) or cartesian form (distance long/lat/up, relative
velocity long/lat). Signals are read through the DBC's own scaling; ``scale``/``offset`` per
quantity convert further units (e.g. km/h). rts-scenario's own messages use the same mechanism
(``rts_scenario/data/can/rts_detections.mapping.yaml``).
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import cantools

from ..located_yaml import Document, load_yaml, validate

QUANTITIES = ("range_m", "azimuth_deg", "elevation_deg", "radial_velocity_mps", "x_m", "y_m",
              "z_m", "vx_mps", "vy_mps", "rcs_dbsm", "snr_db")

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
                "messages": {"type": "array", "minItems": 1, "maxItems": 2,
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


def _can_db(db: object) -> cantools.database.can.Database:
    assert isinstance(db, cantools.database.can.Database)
    return db


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

    @classmethod
    def builtin(cls) -> CanMapping:
        """rts-scenario's own detection messages."""
        folder = resources.files("rts_scenario").joinpath("data/can")
        text = folder.joinpath("rts_detections.mapping.yaml").read_text()
        doc = load_yaml("<mapping rts-detections>", text)
        dbc = folder.joinpath("rts_detections.dbc").read_text()
        return cls._build(doc, _can_db(cantools.database.load_string(dbc, database_format="dbc")))

    @classmethod
    def from_file(cls, path: str | Path) -> CanMapping:
        """Load a ``*.mapping.yaml`` and the DBC it names (relative to it)."""
        path = Path(path)
        doc = load_yaml(path)
        validate(doc, MAPPING_SCHEMA)
        dbc_path = path.parent / doc.data["dbc"]
        try:
            db = _can_db(cantools.database.load_file(dbc_path, database_format="dbc"))
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
        names = {m.name: m for m in self.db.messages}
        def need(key: tuple[str | int, ...], message: str, signals: list[str | None]) -> None:
            if message not in names:
                raise doc.error(key, f"message {message!r} is not in the DBC; messages: "
                                     f"{', '.join(sorted(names))}")
            have = {s.name for s in names[message].signals}
            for sig in signals:
                if sig is not None and sig not in have:
                    raise doc.error(key, f"signal {sig!r} is not in message {message!r}; "
                                         f"signals: {', '.join(sorted(have))}")
        need(("header", "message"), self.header,
             [self.counter, *self.count, self.timestamp, self.header_checksum])
        detection_signals = [self.index, self.frame_counter, self.checksum]
        for m in (*self.messages, *([self.fd_message] if self.fd_message else [])):
            have = {s.name for s in names.get(m, self.db.messages[0]).signals}
            need(("detection", "messages"), m,
                 [s for s in detection_signals if s in have or s == self.index])
        carriers = [*self.messages, *([self.fd_message] if self.fd_message else [])]
        carried = set().union(*({s.name for s in names[m].signals} for m in carriers))
        for q, f in self.fields.items():
            if f.signal not in carried:
                raise doc.error(("detection", q), f"signal {f.signal!r} is not in the detection "
                                                  f"message(s) {', '.join(carriers)}")
        required = {"polar": ("range_m", "azimuth_deg"), "cartesian": ("x_m", "y_m")}[self.form]
        missing = [q for q in required if q not in self.fields]
        if missing:
            raise doc.error(("detection", "form"),
                            f"form {self.form!r} needs {', '.join(missing)}")
