"""What a recorded run keeps of what it played, so that a re-check judges the same scene.

A log's sidecar (`rts_scenario.pipeline.write_log_sidecar`) keeps two records of the run:

- **The ground truth's checksums** (`TruthChecksums`), one per target: a re-check rebuilds the
  truth from the scene file, and a scene edited since the recording (a moved target, another
  RCS, a renamed one) would judge the log against a scene that never played. The checksums
  tell, and name the targets that differ.
- **The statuses the RTS played** (`StatusRecorder`, read back by `StatusRecord`): which target
  played in which frame, and which limit kept it out. A re-check judges by them, not by a
  schedule rebuilt by the version at hand (an update that moves a coverage edge by a rounding
  would judge other target-frames than played).

Both are written batch by batch as the run goes and read back batch by batch: the memory
they take does not grow with the scene's length beyond the compressed statuses (a few bytes
per frame where statuses change, nearly nothing where they do not).
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import zlib
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .kinematics import Tracks
from .schedule.model import Status

# The truth quantities a checksum covers, and the step each is rounded to first: finer than
# any tolerance a scene can set, coarse enough that another machine's rounding does not move
# a value across a step (that takes a value within about 1e-10 of a step's edge).
TRUTH_QUANTA: dict[str, float] = {"range_m": 1e-3, "radial_velocity_mps": 1e-3,
                                  "rcs_dbsm": 1e-2, "az_deg": 1e-3, "el_deg": 1e-3}
# The flags a checksum covers (whether each target-frame could be checked at all).
TRUTH_FLAGS = ("present", "in_range", "in_velocity")
# Where the steps' edges lie, in quanta past a multiple of the quantum (sqrt(5) - 2): far
# from the halves, quarters, tenths... a scene of round numbers puts values on (a car at
# 2.778 m/s is 9.0285 m away in a frame: exactly a millimetre's middle), so that no such
# value lies within an ulp of an edge.
TRUTH_STEP_EDGE = 5**0.5 - 2
TRUTH_ENCODING = ("per target: the sum modulo 2**64 over frames and quantities of splitmix64 "
                  "of each quantity rounded to its quantum (steps' edges sqrt(5) - 2 quanta past "
                  "its multiples), its index and its frame's")
STATUS_ENCODING = "uint16 little-endian per frame and target (frame-major), zlib, base64"

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
# Stands for a value that is not a number (and for every value of an absent target-frame).
_ABSENT = np.int64(-(2**62))


def _splitmix64(x: NDArray[Any]) -> NDArray[np.uint64]:
    """Splitmix64's output function, elementwise (wrapping uint64 arithmetic)."""
    z = x + _GOLDEN
    z = (z ^ (z >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    return z ^ (z >> np.uint64(31))


class TruthChecksums:
    """Per target, a checksum of its ground truth over the frames added so far.

    A sum over frames of a well-mixed hash of each frame's values: it does not depend on how
    the frames are split into batches, or on their order, and one value rounded to another
    step changes it.
    """

    def __init__(self, names: Iterable[str]) -> None:
        self.names = tuple(names)
        self._sums = np.zeros(len(self.names), dtype=np.uint64)

    def add(self, tracks: Tracks, frames: NDArray[np.int64] | NDArray[np.intp]) -> None:
        """Take a batch's tracks, frames ``frames`` (indices in the scene)."""
        present = tracks.present
        columns = [np.where(present, np.floor(getattr(tracks, name) / quantum
                                              - TRUTH_STEP_EDGE), np.nan)
                   for name, quantum in TRUTH_QUANTA.items()]
        columns += [getattr(tracks, name).astype(np.float64) for name in TRUTH_FLAGS]
        values = np.stack(columns, axis=-1)  # (F, K, Q)
        keys = np.where(np.isfinite(values), values, 0.0).astype(np.int64)
        keys = np.where(np.isfinite(values), keys, _ABSENT).astype(np.uint64)
        # Each value's place: its quantity and its frame, mixed in before the value.
        index = np.arange(values.shape[-1], dtype=np.uint64)
        frame = np.asarray(frames, dtype=np.int64).astype(np.uint64)
        place = _splitmix64((frame[:, None, None] * np.uint64(values.shape[-1]) + index)
                            .astype(np.uint64))
        hashed = _splitmix64(keys ^ place)
        with np.errstate(over="ignore"):
            self._sums += hashed.sum(axis=(0, 2), dtype=np.uint64)

    def to_dict(self) -> dict[str, Any]:
        """Plain data for a sidecar (``truth``)."""
        return {"encoding": TRUTH_ENCODING, "quanta": dict(TRUTH_QUANTA),
                "targets": {name: f"{int(s):016x}"
                            for name, s in zip(self.names, self._sums, strict=True)}}

    def differing(self, record: Mapping[str, Any]) -> list[str] | None:
        """Names of the targets whose truth differs from ``record`` (`to_dict`'s).

        Targets on one side only differ too. ``None``: the record was made another way
        (another encoding or quanta) and cannot tell.
        """
        if (record.get("encoding") != TRUTH_ENCODING
                or record.get("quanta") != TRUTH_QUANTA):
            return None
        recorded = dict(record.get("targets") or {})
        mine = self.to_dict()["targets"]
        return [name for name in [*mine, *(n for n in recorded if n not in mine)]
                if mine.get(name) != recorded.get(name)]


class StatusRecorder:
    """The statuses a run played, compressed batch by batch (`STATUS_ENCODING`).

    ``names``: the targets' names, in the order of the statuses' columns (the scene's).
    """

    def __init__(self, n_targets: int, names: Iterable[str] | None = None) -> None:
        self.n_targets = int(n_targets)
        self.names = None if names is None else list(names)
        self.frames = 0
        self._packer = zlib.compressobj(9)
        self._packed: list[bytes] = []

    def add(self, status: NDArray[np.uint16]) -> None:
        """Take a batch's statuses, shape ``(F, K)``."""
        status = np.asarray(status)
        self.frames += status.shape[0]
        self._packed.append(self._packer.compress(status.astype("<u2").tobytes()))

    def to_dict(self) -> dict[str, Any]:
        """Plain data for a sidecar (``statuses``); call once."""
        data = b"".join([*self._packed, self._packer.flush()])
        out: dict[str, Any] = {"frames": self.frames, "targets": self.n_targets}
        if self.names is not None:
            out["names"] = list(self.names)
        return {**out, "encoding": STATUS_ENCODING,
                "data": base64.b64encode(data).decode("ascii")}


class StatusRecord:
    """A `StatusRecorder`'s record, read back batch by batch.

    ``names``: the scene's targets, in its order. Where the record names its columns and they
    are the same targets listed in another order (a scene file whose targets were reordered
    since), each target gets its own column; otherwise the columns are taken in order (a
    target renamed since fails the re-check by the ground truth's checksums).

    Raises
    ------
    ValueError
        The record is not one `StatusRecorder` writes, or not of ``n_frames`` frames and
        ``n_targets`` targets (the message names the field).
    """

    def __init__(self, record: Mapping[str, Any], n_frames: int, n_targets: int,
                 names: Iterable[str] | None = None) -> None:
        if record.get("encoding") != STATUS_ENCODING:
            raise ValueError(f"encoding: must be {STATUS_ENCODING!r}, got "
                             f"{record.get('encoding')!r}")
        if record.get("frames") != n_frames or record.get("targets") != n_targets:
            names = None if names is None else list(names)
            recorded, mine = record.get("names"), names
            added = ([n for n in mine if n not in recorded]
                     if isinstance(recorded, list) and mine is not None else [])
            gone = ([n for n in recorded if n not in mine]
                    if isinstance(recorded, list) and mine is not None else [])
            which = "".join(f"; {label}: {', '.join(map(repr, found))}" for label, found in (
                ("not in the recording", added), ("not in the scene", gone)) if found)
            raise ValueError(f"holds {record.get('frames')} frames of {record.get('targets')} "
                             f"targets, the scene has {n_frames} of {n_targets}{which}: not the "
                             f"scene file that was recorded (edited since?)")
        try:
            self._data = base64.b64decode(str(record.get("data", "")), validate=True)
        except binascii.Error as exc:
            raise ValueError(f"data: not base64 ({exc})") from None
        self.n_targets = n_targets
        recorded = record.get("names")
        if recorded is not None and (not isinstance(recorded, list) or len(recorded) != n_targets
                                     or len(set(map(str, recorded))) != n_targets):
            raise ValueError(f"names: must list the {n_targets} targets' distinct names, got "
                             f"{recorded!r}")
        # Which recorded column is each scene target's (None: the columns in order).
        self._columns: list[int] | None = None
        wanted = None if names is None else list(names)
        if recorded is not None and wanted is not None and set(recorded) == set(wanted) \
                and list(recorded) != wanted:
            self._columns = [list(recorded).index(name) for name in wanted]
        self._unpacker = zlib.decompressobj()
        self._tail = self._data
        self._valid = int(np.uint16(sum(Status)))

    def take(self, n_frames: int) -> NDArray[np.uint16]:
        """Return the next ``n_frames`` frames' statuses, shape ``(n_frames, K)``."""
        size = 2 * n_frames * self.n_targets
        try:
            raw = self._unpacker.decompress(self._tail, size)
        except zlib.error as exc:
            raise ValueError(f"data: not zlib-compressed ({exc})") from None
        self._tail = self._unpacker.unconsumed_tail
        if len(raw) != size:
            raise ValueError(f"data: ends {size - len(raw)} bytes early")
        status = np.frombuffer(raw, dtype="<u2").reshape(n_frames, self.n_targets)
        if np.any(status & ~np.uint16(self._valid)):
            raise ValueError(f"data: holds values that are no status (flags must lie within "
                             f"{self._valid:#x})")
        if self._columns is not None:
            status = status[:, self._columns]
        return status.astype(np.uint16)

    def finish(self) -> None:
        """Check that the record held nothing beyond the frames taken."""
        try:
            rest = self._unpacker.decompress(self._tail) + self._unpacker.flush()
        except zlib.error as exc:
            raise ValueError(f"data: not zlib-compressed ({exc})") from None
        if rest:
            raise ValueError("data: holds more frames than it says")
        if not self._unpacker.eof:
            raise ValueError("data: ends early: the compressed record is cut short")
        if self._unpacker.unused_data:
            raise ValueError(f"data: holds {len(self._unpacker.unused_data)} bytes after the "
                             f"record's end")


class PlayedRecord:
    """Everything a recorded run keeps of what it played, batch by batch, for its sidecar.

    The digest of the statuses (``status_sha256``, what sidecars of older versions compare),
    the ground truth's checksums (`TruthChecksums`) and the statuses (`StatusRecorder`).
    """

    def __init__(self, names: Iterable[str]) -> None:
        names = tuple(names)
        self._digest = hashlib.sha256()
        self._truth = TruthChecksums(names)
        self._statuses = StatusRecorder(len(names), names)

    def add(self, frames: NDArray[np.int64] | NDArray[np.intp], tracks: Tracks,
            status: NDArray[np.uint16]) -> None:
        """Take a batch: its frames (indices in the scene), tracks and played statuses."""
        self._digest.update(status.tobytes())
        self._truth.add(tracks, frames)
        self._statuses.add(status)

    def sidecar_fields(self) -> dict[str, Any]:
        """Return the sidecar's ``status_sha256``, ``truth`` and ``statuses``; call once."""
        return {"status_sha256": self._digest.hexdigest(), "truth": self._truth.to_dict(),
                "statuses": self._statuses.to_dict()}


__all__ = ["STATUS_ENCODING", "TRUTH_ENCODING", "TRUTH_QUANTA", "TRUTH_STEP_EDGE",
           "PlayedRecord", "StatusRecord", "StatusRecorder", "TruthChecksums"]
