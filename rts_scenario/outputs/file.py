"""Schedule files: ``.npz`` (every array, lossless) and ``.csv`` (one row per entry).

CSV format (version 1): comment lines first, then a header row and one row per frame x
target x channel::

    # rts-scenario schedule v1
    # targets: lead-car,truck-left
    frame,t_s,target,channel,quad,fe,active,status,weight,attenuation_db,delay_s,doppler_hz,...

Columns (docs/cli.md lists them for outside tools): ``frame`` (index in the scene), ``t_s``,
``target`` (index into the ``targets`` line), ``channel`` (0..3, the quad's FE in paper order),
``quad`` (the target's, -1 when not synthesized) and ``fe`` (rig index, -1 when the channel is
off), ``active`` (0/1), ``status`` (`rts_scenario.schedule.Status` bit flags of the
target-frame), ``weight``, ``attenuation_db``, ``delay_s``, ``doppler_hz``, ``phase_rad``
(those four empty when the channel is off) and ``angle_error_az_deg``, ``angle_error_el_deg``
(predicted error left by the attenuator's and phase shifter's quantization). Floats are written
with 17 significant digits, so reading a file back gives the same schedule.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import fields
from pathlib import Path
from types import TracebackType
from typing import TextIO

import numpy as np

from .. import interrupts
from ..atomic import Draft
from ..errors import OutputError
from ..schedule import Schedule
from .base import Output

CSV_COLUMNS = ("frame", "t_s", "target", "channel", "quad", "fe", "active", "status", "weight",
               "attenuation_db", "delay_s", "doppler_hz", "phase_rad", "angle_error_az_deg",
               "angle_error_el_deg")
_MAGIC = "# rts-scenario schedule v1"
# CSV rows formatted at once: their text, not the schedule's length, bounds the memory.
CSV_CHUNK_ROWS = 16_384


class FileOutput(Output):
    """Write the batches to ``path`` as they come (``.npz`` or ``.csv``).

    Memory does not grow with the schedule: a ``.csv`` is written batch by batch; a ``.npz``
    (one array per field) goes to a private temporary folder, one raw file per field, and is
    zipped from there on close. Either is written to a draft beside ``PATH`` (`atomic.Draft`:
    exports to one ``PATH`` at once each write their own) and named ``PATH`` once closed whole:
    a schedule cut short (an error or Ctrl-C inside ``with``) is named ``PATH.partial``, and
    what ``PATH`` held before is removed as the first batch comes. A link is followed.
    """

    name = "file"

    def __init__(self, path: str | Path) -> None:
        super().__init__()
        self.path = Path(path)
        if str(path).endswith(("/", os.sep)):
            raise OutputError(f"file:{path}: names a folder (it ends in a slash); give a file "
                              f"path (.npz or .csv)")
        if self.path.suffix not in (".npz", ".csv"):
            raise OutputError(
                f"file:{path}: unknown format {self.path.suffix!r}; valid: .npz, .csv"
            )
        if not self.path.parent.is_dir():
            raise OutputError(f"file:{path}: folder {self.path.parent} does not exist")
        self._draft: Draft | None = None
        self._csv: TextIO | None = None
        self._spill: _Spill | None = None
        self._cut_short = False

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        # Left by an exception: what was written is not the whole schedule.
        self._cut_short = exc_type is not None
        self.close()

    def _write(self, batch: Schedule) -> None:
        if self.path.suffix == ".csv" and not batch.names:
            # One row per entry: frames without targets would leave no trace.
            raise OutputError(f"file:{self.path}: a schedule without targets has no rows for a "
                              f".csv to hold its frames in; use .npz")
        with _writing(self.path):
            if self._draft is None:
                # What PATH held before is removed as the draft is made: it is not this
                # schedule, whether that ends whole or not.
                self._draft = draft = Draft(self.path)
                if draft.partial is not None:  # nor is an earlier export's cut short one
                    draft.partial.unlink(missing_ok=True)
                if self.path.suffix == ".csv":
                    self._csv = draft.file
                    draft.file.write(f"{_MAGIC}\n# targets: {','.join(batch.names)}\n")
                    draft.file.write(",".join(CSV_COLUMNS) + "\n")
                else:
                    draft.file.close()  # zipped into on close (`_Spill.zip_to`)
            if self._csv is not None:
                _write_csv_rows(batch, self._csv)
            else:
                if self._spill is None:
                    self._spill = _Spill(batch)
                self._spill.add(batch)

    def _close(self) -> None:
        draft = self._draft
        if draft is None:
            return
        with _writing(self.path):
            whole = False
            try:
                if self._spill is not None:
                    self._spill.zip_to(draft.name)
                # A stop whose interrupt numpy swallowed (it does inside some of its calls) ran
                # the export on to its end: stopped all the same, it is cut short.
                whole = not self._cut_short and not interrupts.seen()
            finally:
                if self._spill is not None:
                    self._spill.close()
                try:
                    if whole:
                        draft.keep()
                except OSError:
                    whole = False  # not whole where its last write failed: cut short
                    raise
                finally:
                    if not whole:
                        draft.cut_short()


@contextmanager
def _writing(path: Path) -> Iterator[None]:
    """Turn an operating system's error writing ``path`` into an `OutputError`."""
    try:
        yield
    except OSError as exc:
        # Named as the user gave it, whether PATH or its draft beside it failed.
        raise OutputError(f"{path}: cannot write: {exc.strerror or exc}") from None


class _Spill:
    """A schedule's arrays, batch after batch, each in a raw file of a temporary folder."""

    def __init__(self, first: Schedule) -> None:
        self.names = first.names
        # Each array's type and shape past the frames, as the first batch has them.
        self.layout = {f.name: (np.asarray(getattr(first, f.name)).dtype,
                                np.shape(getattr(first, f.name))[1:])
                       for f in fields(Schedule) if f.name != "names"}
        self.frames = 0
        self._tmp = tempfile.TemporaryDirectory(prefix="rts-scenario-schedule-")
        self._folder = Path(self._tmp.name)
        self._files = {name: (self._folder / name).open("wb") for name in self.layout}

    def add(self, batch: Schedule) -> None:
        """Append a batch (its arrays must be of the first batch's types and shapes)."""
        for name, (dtype, rest) in self.layout.items():
            values = np.asarray(getattr(batch, name))
            if values.dtype != dtype or values.shape[1:] != rest:
                raise OutputError(f"{name}: a batch of {values.dtype} {values.shape[1:]} after "
                                  f"batches of {dtype} {rest}")
            self._files[name].write(np.ascontiguousarray(values).tobytes())
        self.frames += batch.n_frames

    def zip_to(self, path: Path) -> None:
        """Write the arrays as ``np.savez_compressed`` would, copying from disk."""
        with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED,
                             allowZip64=True) as archive:
            for name, (dtype, rest) in self.layout.items():
                self._files[name].close()
                with archive.open(f"{name}.npy", "w", force_zip64=True) as member, \
                        (self._folder / name).open("rb") as raw:
                    np.lib.format.write_array_header_1_0(member, {
                        "descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False,
                        "shape": (self.frames, *rest)})
                    shutil.copyfileobj(raw, member, 1 << 16)
            with archive.open("names.npy", "w") as member:
                np.lib.format.write_array(member, np.array(self.names, dtype=str))

    def close(self) -> None:
        """Remove the temporary folder."""
        for file in self._files.values():
            file.close()
        self._tmp.cleanup()


def write_schedule(schedule: Schedule, path: str | Path) -> None:
    """Write ``schedule`` to a ``.npz`` or ``.csv`` file."""
    with FileOutput(path) as out:
        out.write(schedule)


def read_schedule(path: str | Path) -> Schedule:
    """Read a schedule written by `write_schedule` (or `FileOutput`)."""
    path = Path(path)
    try:
        if path.suffix == ".npz":
            with np.load(path, allow_pickle=False) as data:
                values = {f.name: data[f.name] for f in fields(Schedule)}
            values["names"] = tuple(str(n) for n in values["names"])
            return Schedule(**values)
        if path.suffix == ".csv":
            return _read_csv(path)
    except OSError as exc:
        raise OutputError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except (KeyError, ValueError) as exc:
        raise OutputError(f"{path}: not a schedule file: {exc}") from None
    raise OutputError(f"{path}: unknown format {path.suffix!r}; valid: .npz, .csv")


def _write_csv_rows(schedule: Schedule, fh: TextIO) -> None:
    """Write a schedule's rows (no header), `CSV_CHUNK_ROWS` at a time."""
    step = max(1, CSV_CHUNK_ROWS // (4 * max(1, len(schedule.names))))
    for start in range(0, schedule.n_frames, step):  # a few chunks per batch
        rows = _csv_rows(schedule.frames(start, min(start + step, schedule.n_frames)))
        if rows.size:
            fh.write("\n".join(rows.tolist()))
            fh.write("\n")


def _csv_rows(schedule: Schedule) -> np.ndarray:
    """Return a schedule's CSV rows, one string per frame x target x channel."""
    n_frames, n_targets = schedule.status.shape
    f, k, c = (g.ravel() for g in np.meshgrid(np.arange(n_frames), np.arange(n_targets),
                                               np.arange(4), indexing="ij"))
    per_entry = {
        "frame": schedule.frame_index[f], "t_s": schedule.t_s[f], "target": k, "channel": c,
        "quad": schedule.quad[f, k], "fe": schedule.fe.ravel(),
        "active": schedule.active.ravel().astype(int), "status": schedule.status[f, k],
        "weight": schedule.weight.ravel(), "attenuation_db": schedule.attenuation_db.ravel(),
        "delay_s": schedule.delay_s.ravel(), "doppler_hz": schedule.doppler_hz.ravel(),
        "phase_rad": schedule.phase_rad.ravel(),
        "angle_error_az_deg": schedule.angle_error_deg[f, k, 0],
        "angle_error_el_deg": schedule.angle_error_deg[f, k, 1],
    }
    integers = {"frame", "target", "channel", "quad", "fe", "active", "status"}
    columns = []
    for name in CSV_COLUMNS:
        values = per_entry[name]
        if name in integers:
            columns.append(values.astype(np.int64).astype(str))
        else:
            text = np.char.mod("%.17g", values)
            columns.append(np.where(np.isnan(values), "", text))
    rows = columns[0].astype(object)
    for col in columns[1:]:
        rows = rows + "," + col
    return rows


def _read_csv(path: Path) -> Schedule:
    with path.open(encoding="utf-8") as fh:
        magic = fh.readline().rstrip("\n")
        targets = fh.readline().rstrip("\n")
        header = fh.readline().rstrip("\n")
        body = fh.read()
    if magic != _MAGIC or not targets.startswith("# targets:") or header != ",".join(CSV_COLUMNS):
        raise ValueError("missing the rts-scenario schedule header")
    names = tuple(n for n in targets[len("# targets:"):].strip().split(",") if n)
    lines = [line for line in body.split("\n") if line]
    cells = np.array([line.split(",") for line in lines], dtype=object).reshape(-1,
                                                                                len(CSV_COLUMNS))
    col = {name: cells[:, i] for i, name in enumerate(CSV_COLUMNS)}

    def floats(name: str) -> np.ndarray:
        return np.array([float(v) if v else np.nan for v in col[name]])

    def ints(name: str) -> np.ndarray:
        return col[name].astype(np.int64)

    n_targets = len(names)
    n_frames = len(lines) // (4 * max(n_targets, 1))
    shape3 = (n_frames, n_targets, 4)

    def entry(values: np.ndarray) -> np.ndarray:
        return values.reshape(shape3)[:, :, 0]

    return Schedule(
        t_s=floats("t_s").reshape(shape3)[:, 0, 0],
        frame_index=ints("frame").reshape(shape3)[:, 0, 0],
        names=names,
        quad=entry(ints("quad")),
        fe=ints("fe").reshape(shape3),
        weight=floats("weight").reshape(shape3),
        attenuation_db=floats("attenuation_db").reshape(shape3),
        delay_s=floats("delay_s").reshape(shape3),
        doppler_hz=floats("doppler_hz").reshape(shape3),
        phase_rad=floats("phase_rad").reshape(shape3),
        active=ints("active").reshape(shape3).astype(bool),
        status=entry(ints("status")).astype(np.uint16),
        angle_error_deg=np.stack([entry(floats("angle_error_az_deg")),
                                  entry(floats("angle_error_el_deg"))], axis=-1),
    )
